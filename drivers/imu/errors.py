"""Errors of the IMU readers, refining :mod:`gyrocal.drivers.errors`."""

from __future__ import annotations

from gyrocal.drivers.errors import BusError, DeviceIdentityError, DriverError

__all__ = ["BusOpenError", "ChipIdentityError", "ImuStateError", "SensorFaultError"]


class BusOpenError(BusError):
    """``/dev/i2c-N`` is missing or not accessible; the message says how to fix it."""


class ChipIdentityError(DeviceIdentityError):
    """The chip at the address is not one the reader drives.

    Parameters
    ----------
    message : str
        What was found and what to do.
    address : int
        The 7-bit I²C address.
    who_am_i : int or None
        The identity byte read, if any.
    """

    def __init__(self, message: str, *, address: int, who_am_i: int | None) -> None:
        super().__init__(message)
        self.address = address
        self.who_am_i = who_am_i


class SensorFaultError(DriverError):
    """The sensor answers but its data are not plausible (for example a stuck axis).

    Parameters
    ----------
    message : str
        What was seen and what to do.
    axis : int or None
        The gyro axis (0 = x, 1 = y, 2 = z) concerned, if one.
    """

    def __init__(self, message: str, *, axis: int | None = None) -> None:
        super().__init__(message)
        self.axis = axis


class ImuStateError(DriverError):
    """A reader method was called in the wrong state (``read()`` before ``start()``, ...)."""
