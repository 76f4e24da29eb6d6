"""The calibration numerics' error hierarchy."""

from __future__ import annotations

__all__ = ["CalibError", "CalibInputError", "CalibrationFormatError"]


class CalibError(Exception):
    """Base class of every error raised by ``calib``."""


class CalibInputError(CalibError, ValueError):
    """An argument is malformed: the message names the argument and what is wrong with it."""


class CalibrationFormatError(CalibError, ValueError):
    """A Calibration v1 document is not of the expected format, version or shape."""
