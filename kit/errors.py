"""The kit's error hierarchy and the exit codes of the ``gyrocal`` command.

Every error the command line reports is a :class:`GyrocalError` whose class fixes the exit code;
errors from ``drivers`` and ``calib`` are mapped onto these classes by :func:`exit_code_for`.
"""

from __future__ import annotations

from gyrocal.calib.errors import CalibError, CalibInputError, CalibrationFormatError
from gyrocal.drivers.errors import ConfigurationError, DriverError

__all__ = [
    "EXIT_CODES",
    "EstimationError",
    "GyrocalError",
    "HardwareError",
    "InconsistentCalibrationError",
    "InputError",
    "InterruptedRun",
    "OutputExistsError",
    "ProtocolCheckError",
    "exit_code_for",
]

#: Exit codes of ``gyrocal`` (also printed by ``gyrocal --help``).
EXIT_CODES: dict[int, str] = {
    0: "success",
    1: "internal error (a bug: please report it with the traceback)",
    2: "bad usage or bad input (flags, config, files)",
    3: "the calibration finished but is not consistent with the measured noise, or verify "
       "found its error beyond what its uncertainty predicts",
    4: "hardware or communication failure (I2C bus, servo bus, servo hardware alert)",
    5: "a runtime check of the protocol failed twice (speed, saturation, movement), or a step "
       "was disturbed by host load four times in a row (FIFO gap, late servo polls)",
    6: "the estimation failed (too little data, no convergence)",
    129: "hung up (SIGHUP); servos stopped, torque off, recording (if begun) kept",
    130: "interrupted by Ctrl-C (SIGINT); servos stopped, torque off, recording (if begun) kept",
    141: "standard output was closed by its reader (a pipe into head): the output stops there",
    143: "terminated (SIGTERM); servos stopped, torque off, recording (if begun) kept",
}


class GyrocalError(Exception):
    """Base class of the kit's errors; ``exit_code`` is what ``gyrocal`` exits with."""

    exit_code = 1


class InputError(GyrocalError, ValueError):
    """Bad usage or bad input: a flag, a config key, a missing or malformed file."""

    exit_code = 2


class OutputExistsError(InputError):
    """An output file exists and ``--force`` was not given."""


class InconsistentCalibrationError(GyrocalError):
    """The fit's residuals are not consistent with the measured noise."""

    exit_code = 3


class HardwareError(GyrocalError):
    """A hardware or communication failure."""

    exit_code = 4


class ProtocolCheckError(GyrocalError):
    """A runtime check of the protocol failed twice, or host load disturbed a step too often."""

    exit_code = 5


class EstimationError(GyrocalError):
    """The estimator could not produce a calibration."""

    exit_code = 6


class InterruptedRun(GyrocalError):
    """The run was interrupted by a signal; ``exit_code`` is 128 + the signal number."""

    def __init__(self, message: str, signum: int = 2) -> None:
        super().__init__(message)
        self.exit_code = 128 + int(signum)


def exit_code_for(exc: BaseException) -> int:
    """The ``gyrocal`` exit code for an exception raised anywhere in gyrocal.

    Parameters
    ----------
    exc : BaseException
        The exception.

    Returns
    -------
    int
        A key of :data:`EXIT_CODES`.
    """
    if isinstance(exc, GyrocalError):
        return exc.exit_code
    if isinstance(exc, KeyboardInterrupt):
        return 130
    if isinstance(exc, SystemExit) and isinstance(exc.code, int):  # TerminatedBySignal
        return exc.code
    if isinstance(exc, (CalibInputError, CalibrationFormatError, ConfigurationError)):
        return 2
    if isinstance(exc, CalibError):
        return 6
    if isinstance(exc, DriverError):
        return 4
    return 1
