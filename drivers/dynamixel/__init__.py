"""The gimbal of Dynamixel X-series servos, over dynamixel-sdk (Protocol 2.0).

:class:`Gimbal` is what the kit uses; :mod:`~gyrocal.drivers.dynamixel.control_table` holds the
control
tables as data; :mod:`~gyrocal.drivers.dynamixel.errors` the named errors.
"""

from gyrocal.drivers.dynamixel.errors import (
    ElectricalShockError,
    InputVoltageError,
    MotorEncoderError,
    OverheatingError,
    OverloadError,
    ServoCommunicationError,
    ServoHardwareError,
    ServoIdentityError,
    ServoStatusError,
    ShutdownError,
    StallError,
    TerminatedBySignal,
    TurnLimitError,
    WatchdogTrippedError,
)
from gyrocal.drivers.dynamixel.gimbal import Gimbal, GimbalSample, Motion, ServoInfo, ServoStatus

__all__ = [
    "ElectricalShockError",
    "Gimbal",
    "GimbalSample",
    "InputVoltageError",
    "Motion",
    "MotorEncoderError",
    "OverheatingError",
    "OverloadError",
    "ServoCommunicationError",
    "ServoHardwareError",
    "ServoIdentityError",
    "ServoInfo",
    "ServoStatus",
    "ServoStatusError",
    "ShutdownError",
    "StallError",
    "TerminatedBySignal",
    "TurnLimitError",
    "WatchdogTrippedError",
]
