"""The kinds of jig gyrocal calibrates on, one row each (plain data: the command line's
``--jig`` choices, the benches' tables and the documents read it).

:class:`JigKind` is a frozen record built on :class:`typing.NamedTuple` rather than a dataclass:
building the parser, ``--help`` and an argument error must not import :mod:`dataclasses`
(``tests/kit/test_cli_imports.py``, issue 25's start-up time), and ``calibrate --jig`` takes its
choices from :data:`JIG_KINDS`.
"""

from __future__ import annotations

from typing import NamedTuple

__all__ = ["DEFAULT_JIG", "JIG_KINDS", "JigKind"]


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
    """

    name: str
    description: str
    hardware_docs: str
    undetermined: str


#: The jig kinds by name, the default first.
JIG_KINDS: dict[str, JigKind] = {
    "gimbal": JigKind(
        "gimbal",
        "three Dynamixel servos in a gimbal; the encoders time every revolution, and turns "
        "with another servo posed at a known encoder angle tilt the axes by known rotations",
        "mechanical.md",
        "",
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
    ),
}

#: The jig of a run that does not say (today's users: the gimbal).
DEFAULT_JIG = "gimbal"
