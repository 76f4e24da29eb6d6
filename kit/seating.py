"""The single-servo jig's re-seats: the prompt, the user's answer, and the check from gravity.

Between groups of turns the user seats the sensor's cube on the one servo with another face
(or, in the V-block, edge) up (:data:`gyrocal.calib.design.SEATS`; hardware_docs/single-servo.md).
The runner (:class:`gyrocal.kit.protocol.Runner`) keeps its loop going while it waits (the IMU's
FIFO drained, the servo polled and holding), then averages the accelerometer over
:data:`SEAT_CHECK_S` of still time: a still accelerometer reads +1 g along "up", so the reading's
direction in the sensor frame is the seat's. A seat more than :data:`SEAT_TOLERANCE_DEG` off is
refused with what was seated instead, and the user is asked again.

The hand jig on hardware (:mod:`gyrocal.kit.hand`) prompts its user through the same
:class:`Seater` (each prompt names a face of the box) and checks the face with :func:`check_seat`.

Two users: :class:`TerminalSeater` prints the prompt and waits for Enter on the terminal (Ctrl-C
stops the run with the servo's torque off, as everywhere); :class:`EmulatedSeater` re-seats the
emulated jig's cube (:class:`gyrocal.drivers.emulated.seater.CubeSeater`), so
``gyrocal calibrate --sim --jig single-servo`` runs without input.
"""

from __future__ import annotations

import math
import select
import sys
from collections.abc import Mapping, Sequence
from typing import Any, Protocol, TextIO

import numpy as np

from gyrocal.calib.design import SEATS

__all__ = ["SEAT_CHECK_S", "SEAT_TOLERANCE_DEG", "EmulatedSeater", "Seater", "TerminalSeater",
           "check_seat", "seat_prompt"]

#: Still time after a re-seat over which the accelerometer is averaged for the check, s.
SEAT_CHECK_S = 0.5
#: Largest angle between the measured "up" and the asked seat's, degrees: the seats are 45°
#: apart at least (a face and the edges beside it), so 15° takes a seating error of a few
#: degrees and a tilted table, and refuses every other seat.
SEAT_TOLERANCE_DEG = 15.0


class Seater(Protocol):
    """Who re-seats the cube: asked with :meth:`prompt`, polled with :meth:`ready` from the
    runner's loop."""

    def prompt(self, seat: str, text: str) -> None:
        """Ask for ``seat``; ``text`` is the message to show."""
        ...

    def ready(self) -> bool:
        """Whether the cube has been seated as asked (the user said so)."""
        ...


def seat_prompt(seat: str, number: int, total: int, problem: str | None = None) -> str:
    """What the user reads: which seat, on which part of the adapter, and (on a repeat) what
    was wrong."""
    up, holder = SEATS[seat]
    where = (f"face {seat} up on the flat adapter" if holder == "flat" else
             f"edge {seat} up in the V-block (faces {seat[:2]} and {seat[2:]} on its sides)")
    head = f"{problem}; " if problem else ""
    return (f"{head}seat {number}/{total}: put the cube with {where}, hands off, then press "
            "Enter")


def check_seat(accel: np.ndarray, seat: str,
               tolerance_deg: float = SEAT_TOLERANCE_DEG, *,
               ups: Mapping[str, Sequence[float]] | None = None,
               thing: str = "cube") -> str | None:
    """Whether a still accelerometer's readings (N, 3; any unit) say ``seat`` is up: None if
    they do, else what is wrong (the seat they say instead, or that they say none).

    A still accelerometer reads the specific force, +1 g along "up" (the sensor frame's up is
    the seat's direction: ``ups``, by default the single-servo jig's
    :data:`~gyrocal.calib.design.SEATS`; ``thing`` is what the message says is seated).
    """
    a = np.asarray(accel, dtype=float).reshape(-1, 3)
    a = a[np.all(np.isfinite(a), axis=1)]
    if a.shape[0] < 5:
        return "the accelerometer gave no readings to check the seat with"
    m = a.mean(axis=0)
    if not np.linalg.norm(m) > 0:
        return "the accelerometer reads zero: it cannot check the seat"
    up = m / np.linalg.norm(m)
    seats = {name: v for name, (v, _) in SEATS.items()} if ups is None else ups
    off = {name: math.degrees(math.acos(max(-1.0, min(1.0, float(np.dot(up, v))))))
           for name, v in seats.items()}
    if off[seat] <= tolerance_deg:
        return None
    nearest = min(off, key=off.__getitem__)
    told = (f"{nearest} is up instead ({off[nearest]:.0f}° from it)"
            if off[nearest] <= tolerance_deg else
            f"no seat is up: gravity reads ({up[0]:+.2f}, {up[1]:+.2f}, {up[2]:+.2f})")
    return f"the {thing} is not seated {seat} up ({off[seat]:.0f}° off): {told}"


class TerminalSeater:
    """The user at the terminal: the prompt on ``out``, Enter on ``inp`` (polled, so the
    runner's loop keeps the FIFO drained and the servo polled while the user works)."""

    def __init__(self, inp: TextIO | None = None, out: TextIO | None = None) -> None:
        self.inp = sys.stdin if inp is None else inp
        self.out = sys.stderr if out is None else out
        self._waiting = False

    def prompt(self, seat: str, text: str) -> None:
        """Print ``text`` and wait for Enter."""
        print(f"gyrocal: {text}", file=self.out, flush=True)
        self._waiting = True

    def ready(self) -> bool:
        """True once a line (Enter) has been typed since the prompt."""
        if not self._waiting:
            return True
        r, _, _ = select.select([self.inp], [], [], 0)
        if r:
            if not self.inp.readline():
                from gyrocal.kit.errors import InputError

                raise InputError("the terminal closed while waiting for Enter after a prompt: "
                                 "run the single-servo or hand jig from an interactive "
                                 "terminal")
            self._waiting = False
        return not self._waiting


class EmulatedSeater:
    """The emulated user: re-seats the emulated cube (``cube``, a
    :class:`~gyrocal.drivers.emulated.seater.CubeSeater`) at each prompt."""

    def __init__(self, cube: Any) -> None:
        self.cube = cube

    def prompt(self, seat: str, text: str) -> None:
        """Seat the cube (the emulated hand follows the prompt)."""
        self.cube.begin(SEATS[seat][0])

    def ready(self) -> bool:
        """True when the hand has let go."""
        return bool(self.cube.done())
