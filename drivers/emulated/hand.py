"""A hand turning a box: the no-servo jig's motion, a :class:`MotionSource` with a specific force.

The sensor is fixed to a box with square faces (its mount misaligned by a small rotation). The
hand lays the box on a face against a stop, rests it, turns it one whole turn about the
vertical box axis and back against the stop, rests, turns it back the other way, rests, and then
lays it on the next face. A hand is irregular, and the emulator draws that from a seed:

* each turn's speed rises and falls unevenly (a raised-sine envelope times a random low-order
  ripple, so the speed varies within the turn, never reverses, and is zero at both ends);
* rests last a random 2–5 s;
* the turn axis wobbles by a small angle about the box axis (a slow random tilt that starts
  and ends at zero, its rate's mean taken off so that the face comes back flat; "up" is held
  during a turn, the accelerometer's rests are what count), and each return to the stop misses
  it by the stop's repeatability.

The true rate and the specific force are tabulated once on a 1 ms grid and interpolated, so the
emulated chip samples them like any other motion source.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gyrocal.drivers.emulated.jig import rotation_matrices, rotvec_to_matrix

__all__ = ["HAND_FACES", "HandMotion", "HandPhase", "hand_schedule", "hand_steps"]

#: The faces laid up, in order, with the turns about the vertical box axis on the first face of
#: each axis (+z, +x, +y) and a rest on the opposite face for the accelerometer's six orientations.
HAND_FACES = ("+z", "-z", "+x", "-x", "+y", "-y")
_AXIS = {"x": 0, "y": 1, "z": 2}
#: Table grid, s.
_DT = 1e-3


@dataclass(frozen=True)
class HandPhase:
    """One step of the hand's schedule.

    Attributes
    ----------
    kind : str
        ``rest``, ``turn`` (one whole turn about the vertical box axis) or ``reseat`` (laying
        the box on another face).
    t_start, t_end : float
        s, from the start of the schedule.
    axis : int
        Box axis of a turn or re-seat (0, 1, 2).
    angle : float
        Signed angle of a turn or re-seat, rad.
    """

    kind: str
    t_start: float
    t_end: float
    axis: int = -1
    angle: float = 0.0


def _up(face: str) -> np.ndarray:
    """The box-frame direction of ``face`` (``"+x"``...)."""
    return (1.0 if face[0] == "+" else -1.0) * np.eye(3)[_AXIS[face[1]]]


def _profile(rng: np.random.Generator, n: int) -> np.ndarray:
    """A hand's speed profile on ``n`` points of ``[0, 1]``: positive inside, zero at the ends,
    integrating to 1 (per unit of the normalised time)."""
    x = np.linspace(0.0, 1.0, n)
    ripple = np.ones(n)
    for k in (1, 2, 3):
        ripple += rng.uniform(0.0, 0.45 / k) * np.sin(2 * np.pi * k * x + rng.uniform(0, 2 * np.pi))
    v = np.sin(np.pi * x) ** 2 * np.maximum(ripple, 0.2)
    return v / np.trapezoid(v, x)


def hand_steps() -> list[tuple[str, str, int]]:
    """The hand jig's protocol without its times, in order (one table for the emulated hand,
    :func:`hand_schedule`, and for the prompts on hardware, :mod:`gyrocal.kit.hand`).

    Returns
    -------
    list of (kind, face, sense)
        ``("face", F, 0)``: lay the box with face ``F`` (of :data:`HAND_FACES`) up against the
        stop and rest; ``("turn", F, ±1)``: with face ``F`` up, turn the box one whole turn
        about its vertical axis (``+1`` positive about ``F``'s axis by the right-hand rule:
        counter-clockwise seen from above) back against the stop, and rest. On each ``+a`` face
        a turn each way, on ``-a`` a rest only (the accelerometer's sixth orientation).
    """
    out: list[tuple[str, str, int]] = []
    for face in HAND_FACES:
        out.append(("face", face, 0))
        if face[0] == "+":
            out += [("turn", face, sense) for sense in (1, -1)]
    return out


def hand_schedule(seed: int, *, turns_s: tuple[float, float] = (2.5, 5.0),
                  rests_s: tuple[float, float] = (2.0, 5.0), reseat_s: float = 2.0,
                  first_rest_s: float = 4.0) -> list[HandPhase]:
    """The hand's schedule, drawn by ``seed``: the steps of :func:`hand_steps` with their
    durations (rests between)."""
    rng = np.random.default_rng([int(seed), 0x4A4D])
    out: list[HandPhase] = []
    t = 0.0

    def add(kind: str, dur: float, axis: int = -1, angle: float = 0.0) -> None:
        nonlocal t
        out.append(HandPhase(kind, t, t + dur, axis, angle))
        t += dur

    add("rest", first_rest_s)  # the box starts on the first face
    prev = None
    for kind, face, sense in hand_steps():
        if kind == "turn":
            add("turn", float(rng.uniform(*turns_s)), _AXIS[face[1]], sense * 2 * np.pi)
            add("rest", float(rng.uniform(*rests_s)))
            continue
        if prev is not None:  # lay the box on this face: 180° to the opposite face, else 90°
            if prev[1] == face[1]:
                add("reseat", reseat_s, (_AXIS[face[1]] + 1) % 3, np.pi)
            else:  # a quarter turn about the third axis, in the sense that lays ``face`` up
                axis = 3 - _AXIS[face[1]] - _AXIS[prev[1]]
                add("reseat", reseat_s, axis, -np.pi / 2 * float(np.dot(
                    np.cross(np.eye(3)[axis], _up(prev)), _up(face))))
            add("rest", float(rng.uniform(*rests_s)))
        prev = face
    return out


class HandMotion:
    """The box's motion: true rate (rad/s) and specific force (g) in the sensor frame.

    Parameters
    ----------
    schedule : list of HandPhase
        :func:`hand_schedule`.
    t0 : float
        Clock time of the schedule's start, s.
    mount : rotation vector (3,), rad
        The sensor's mount on the box: ``v_sensor = M v_box``.
    wobble_deg : float
        Largest tilt of a turn's axis off the box axis, degrees.
    stop_deg : float
        Standard deviation of each return to the stop, degrees (a turn is ``2π`` plus that
        error, drawn per turn).
    seed : int
        Seeds the speed profiles, the wobble and the stop errors.
    """

    def __init__(self, schedule: list[HandPhase], *, t0: float = 0.0,
                 mount: tuple[float, float, float] = (0.0, 0.0, 0.0), wobble_deg: float = 1.0,
                 stop_deg: float = 0.1, seed: int = 0) -> None:
        rng = np.random.default_rng([int(seed), 0x4A4E])
        self.schedule = list(schedule)
        self.t0 = float(t0)
        self.mount = rotvec_to_matrix(np.asarray(mount, dtype=float))
        self.duration = self.schedule[-1].t_end
        n = int(np.ceil(self.duration / _DT)) + 1
        self._t = np.arange(n) * _DT
        w_box = np.zeros((n, 3))
        up_box = np.zeros((n, 3))
        up = np.array([0.0, 0.0, 1.0])  # "up" in the box frame: +z laid up first
        self.turn_angles: list[float] = []
        for ph in self.schedule:
            i0, i1 = int(round(ph.t_start / _DT)), int(round(ph.t_end / _DT))
            sl = slice(i0, i1 + 1)
            up_box[sl] = up
            if ph.kind == "rest":
                continue
            m = i1 - i0 + 1
            v = _profile(rng, m) / ((i1 - i0) * _DT)  # over the grid span the table holds
            e = np.zeros(3)
            e[ph.axis] = 1.0
            angle = ph.angle
            if ph.kind == "turn":
                angle += np.sign(angle) * rng.normal(0.0, np.radians(stop_deg))
                self.turn_angles.append(float(angle))
                x = np.linspace(0.0, 1.0, m)
                tilt = np.radians(wobble_deg) * np.sin(np.pi * x) ** 2
                phase = rng.uniform(0, 2 * np.pi) + 2 * np.pi * rng.uniform(0.5, 1.5) * x
                perp = np.eye(3)[[k for k in range(3) if k != ph.axis]]
                axis = e + tilt[:, None] * (np.cos(phase)[:, None] * perp[0]
                                            + np.sin(phase)[:, None] * perp[1])
                w = angle * v[:, None] * axis  # along e: exactly the turn's angle in all
                off = np.sum(w, axis=0) - np.sum(w[:, ph.axis]) * e  # the box comes back flat
                w_box[sl] = w - np.outer(v / v.sum(), off)
            else:  # a re-seat turns "up" in the box frame
                w_box[sl] = angle * v[:, None] * e
                frac = np.cumsum(v) * _DT
                up_box[sl] = np.einsum("nij,j->ni", rotation_matrices(e, -angle * frac), up)
                up = up_box[i1].copy()
        self._w = w_box @ self.mount.T
        self._f = up_box @ self.mount.T

    def rate(self, t: np.ndarray) -> np.ndarray:
        """True rate in the sensor frame, rad/s, at clock times ``t`` (zero outside)."""
        tt = np.asarray(t, dtype=float).reshape(-1) - self.t0
        k = self._span(tt)
        return np.column_stack([np.interp(tt, self._t[k], self._w[k, j], left=0.0, right=0.0)
                                for j in range(3)])

    def specific_force(self, t: np.ndarray, peek: bool = False) -> np.ndarray:
        """Specific force in the sensor frame, g (+1 up at rest), at clock times ``t``."""
        tt = np.asarray(t, dtype=float).reshape(-1) - self.t0
        k = self._span(tt)
        return np.column_stack([np.interp(tt, self._t[k], self._f[k, j]) for j in range(3)])

    def _span(self, tt: np.ndarray) -> slice:
        """The table rows that ``np.interp`` needs for times ``tt`` (the grid's first or last row
        kept when ``tt`` reaches outside it, so the values there are the whole table's): the
        emulated chip asks for a few samples at a time, and interpolating on the whole table
        each time was most of a session's cost."""
        n = self._t.size
        if tt.size == 0:
            return slice(0, n)
        lo = min(max(int(np.floor(tt.min() / _DT)) - 1, 0), n - 2)
        hi = max(min(int(np.ceil(tt.max() / _DT)) + 2, n), lo + 2)
        return slice(lo, hi)

    def box_axes(self) -> np.ndarray:
        """The box axes in the sensor frame, rows x, y, z (the true turn axes, less wobble)."""
        return self.mount.T.copy()
