"""Protocol segments: what the jig was doing when (Recording v1 ``segments.csv``)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gyrocal.calib.errors import CalibInputError

__all__ = ["KINDS", "Segment"]

#: The segment kinds of Recording v1.
KINDS = ("rotate", "rest", "move")


@dataclass(frozen=True)
class Segment:
    """One step of a calibration protocol.

    Attributes
    ----------
    index : int
        Position in the protocol.
    kind : str
        ``"rotate"``, ``"rest"`` or ``"move"`` (a positioning move of one servo to a pose; same
        columns as a rotation, never windowed as a turn).
    motor : int or None
        Dynamixel ID of the turning (or moving) servo; None for a rest.
    direction : int
        +1 or -1 for a rotation or move (the servo's positive direction is +1); 0 for a rest.
    speed : float
        Commanded speed, rad/s (positive); 0 for a rest.
    t_start, t_end : float
        Start and end on the recording clock, s.
    """

    index: int
    kind: str
    motor: int | None
    direction: int
    speed: float
    t_start: float
    t_end: float

    def __post_init__(self) -> None:
        if self.kind not in KINDS:
            raise CalibInputError(
                f"segment {self.index}: kind must be 'rotate', 'rest' or 'move', got {self.kind!r}"
            )
        if not (np.isfinite(self.t_start) and np.isfinite(self.t_end)):
            raise CalibInputError(f"segment {self.index}: t_start and t_end must be finite")
        if self.t_end < self.t_start:
            raise CalibInputError(
                f"segment {self.index}: t_end {self.t_end} is before t_start {self.t_start}"
            )
        if self.kind in ("rotate", "move"):
            if self.motor is None:
                raise CalibInputError(f"segment {self.index}: a {self.kind} needs a motor id")
            if self.direction not in (-1, 1):
                raise CalibInputError(
                    f"segment {self.index}: direction must be +1 or -1, got {self.direction!r}"
                )
            if not (self.speed > 0 and np.isfinite(self.speed)):
                raise CalibInputError(
                    f"segment {self.index}: speed must be positive, got {self.speed!r}"
                )
        elif self.motor is not None or self.direction != 0:
            raise CalibInputError(f"segment {self.index}: a rest has no motor and direction 0")

    @property
    def duration(self) -> float:
        """``t_end - t_start``, s."""
        return self.t_end - self.t_start
