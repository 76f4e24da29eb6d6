"""The kinds of jig gyrocal calibrates on, one row each (plain data: the command line's
``--jig`` choices, the benches' tables and the documents read it).

:class:`JigKind` is a frozen record built on :class:`typing.NamedTuple` rather than a dataclass:
building the parser, ``--help`` and an argument error must not import :mod:`dataclasses`
(``tests/kit/test_cli_imports.py``, issue 25's start-up time), and ``calibrate --jig`` takes its
choices from :data:`JIG_KINDS`.
"""

from __future__ import annotations

from typing import NamedTuple

__all__ = ["DEFAULT_JIG", "JIG_KINDS", "JigKind", "axis_label"]


class JigKind(NamedTuple):
    """One kind of jig.

    Attributes
    ----------
    name : str
        The ``--jig`` value and the Recording v1 manifest's ``jig.kind``.
    description : str
        One line: what turns the sensor and what times the turns.
    hardware_docs : str
        The page of ``hardware_docs/`` that says what to build and how to run it.
    undetermined : str
        What this jig cannot determine, and why (empty when it determines the full model).
    axis_label : str
        How a report names the axis the turns of one motor ID of the recording are about:
        ``{motor}`` is the ID; ``{axis}`` the sensor axis a hand turn's virtual servo stands
        for (:data:`gyrocal.calib.hand.AXIS_MOTORS`: 1, 2, 3 for x, y, z).
    axis_short : str
        The same, short (a tick label of the residuals plot: ``s2+``, ``box y+``).
    full_model : str
        One sentence to a user whose calibration is diagonal: what calibrates the full model
        (the cross-axis terms, and the g-sensitivity a diagonal calibration cannot carry) on
        this jig.
    """

    name: str
    description: str
    hardware_docs: str
    undetermined: str
    axis_label: str
    axis_short: str
    full_model: str


#: The jig kinds by name, the default first.
JIG_KINDS: dict[str, JigKind] = {
    "gimbal": JigKind(
        "gimbal",
        "three Dynamixel servos in a gimbal; the encoders time every revolution, and turns "
        "with another servo posed at a known encoder angle tilt the axes by known rotations",
        "mechanical.md",
        "",
        "servo {motor}",
        "s{motor}",
        "Record with the posed protocol (--protocol full, gyrocal calibrate's default) to "
        "calibrate the full model.",
    ),
    "hand": JigKind(
        "hand",
        "no servo: the sensor on a square box turned by hand one whole turn about each box "
        "axis against a stop, between rests (Ferraris); rests and turns are found in the data "
        "and each turn's mean rate is 360° over its rest-to-rest duration",
        "hand-jig.md",
        "the turn axes are the box's, set by hand against a stop and measured by nothing, so "
        "each turn's axis is fitted as a free direction, which absorbs the cross-axis terms; "
        "the stop's repeatability (0.1° is 2.8e-4 of a turn) limits each turn's reference",
        "box axis {axis}",
        "box {axis}",
        "The hand jig cannot calibrate the full model (nothing measures a hand's axes); a "
        "gimbal's posed protocol (gyrocal calibrate's default) can.",
    ),
    "single-servo": JigKind(
        "single-servo",
        "one Dynamixel servo turns a printed cube that the user re-seats on its faces and "
        "edges when prompted; the encoder times every revolution",
        "single-servo.md",
        "with the faces only (no V-block edge seats) the three cross-axis terms, up to the "
        "datasheet's cross-axis sensitivity (each seat's axis is a free unknown, so a seat "
        "sees only the rate's magnitude along it); g-sensitivity along any direction the "
        "seats' gravity does not span (the shaft is vertical: a seat sees gravity along its "
        "axis only)",
        "servo {motor}",
        "s{motor}",
        "Seat the cube on its edges too, in the V-block (hardware_docs/single-servo.md), to "
        "calibrate the full model.",
    ),
}

#: The jig of a run that does not say (today's users: the gimbal).
DEFAULT_JIG = "gimbal"


def axis_label(jig: str, motor: int, *, short: bool = False) -> str:
    """What a report calls the axis of ``motor``'s turns on a ``jig`` (:attr:`JigKind.axis_label`,
    or :attr:`JigKind.axis_short`): ``servo 2`` (``s2``) on a gimbal, ``box axis y``
    (``box y``) on the hand jig."""
    from gyrocal.calib.hand import AXIS_MOTORS

    axis = "xyz"[AXIS_MOTORS.index(motor)] if motor in AXIS_MOTORS else str(motor)
    kind = JIG_KINDS[jig]
    return (kind.axis_short if short else kind.axis_label).format(motor=motor, axis=axis)
