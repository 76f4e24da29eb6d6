"""The kinds of jig gyrocal calibrates on, one row each: what it is, where its build page is,
and what it cannot determine (issue 29).

Every kind feeds the same estimator (:mod:`gyrocal.calib.estimators`), σ, verdict, report and
exports; a kind differs only in how the sensor is turned and what its turns can see.
``gyrocal calibrate --jig`` takes its choices from :data:`JIG_KINDS`.
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["DEFAULT_JIG", "JIG_KINDS", "JigKind"]


@dataclass(frozen=True)
class JigKind:
    """One kind of jig.

    Attributes
    ----------
    name : str
        The ``--jig`` value.
    description : str
        One line: what turns the sensor.
    hardware_docs : str
        The ``hardware_docs/`` page that says what to build or print and how to run it.
    cannot_determine : str
        What calibrations on this jig leave undetermined, and why (sizes on the page).
    """

    name: str
    description: str
    hardware_docs: str
    cannot_determine: str


#: The jig kinds, by ``--jig`` name.
JIG_KINDS: dict[str, JigKind] = {
    "gimbal": JigKind(
        "gimbal", "three Dynamixel servos in a gimbal turn the sensor about three axes, "
        "posing each other for the full matrix", "mechanical.md",
        "the global rotation of the sensor frame (no turn sees it; fixed by the frame "
        "convention gyro-x-xy)"),
    "single-servo": JigKind(
        "single-servo", "one Dynamixel servo turns a printed cube that the user re-seats on "
        "its faces and edges when prompted", "single-servo.md",
        "the global rotation of the sensor frame (fixed by gyro-x-xy, as on the gimbal); with "
        "the faces only (no V-block edge seats) the three cross-axis terms, up to the "
        "datasheet's cross-axis sensitivity (each seat's axis is a free unknown, so a seat "
        "sees only the rate's magnitude along it); g-sensitivity along any direction the "
        "seats' gravity does not span (the shaft is vertical: a seat sees gravity along its "
        "axis only)"),
}

#: The jig of a run that names none: the three-servo gimbal.
DEFAULT_JIG = "gimbal"
