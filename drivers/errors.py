"""The drivers' error hierarchy.

Every failure a driver can meet is a :class:`DriverError`; its message says what went wrong and
what to do next. A bus error is never returned as a zero reading.
"""

from __future__ import annotations

__all__ = [
    "BusError",
    "CommunicationError",
    "ConfigurationError",
    "DeviceIdentityError",
    "DriverError",
    "HardwareAlertError",
    "SafetyError",
]


class DriverError(Exception):
    """Base class of every error raised by ``drivers``."""


class ConfigurationError(DriverError, ValueError):
    """A setting the device cannot do (the message lists the ones it can)."""


class DeviceIdentityError(DriverError):
    """The device at the address is absent or is not the chip or servo that was expected."""


class BusError(DriverError):
    """A persistent I²C bus error, after bounded retries.

    Parameters
    ----------
    message : str
        What happened and what to do.
    errno : int or None
        The ``errno`` of the last ``OSError``.
    address : int or None
        The 7-bit I²C address.
    register : int or None
        The register being read or written.
    """

    def __init__(
        self,
        message: str,
        *,
        errno: int | None = None,
        address: int | None = None,
        register: int | None = None,
    ) -> None:
        super().__init__(message)
        self.message = message
        self.errno = errno
        self.address = address
        self.register = register

    def __str__(self) -> str:
        return self.message


class CommunicationError(DriverError):
    """A servo did not answer, or answered with a corrupt packet, after bounded retries."""


class HardwareAlertError(DriverError):
    """A servo reported a hardware error (status alert bit 0x80) and shut itself down."""


class SafetyError(DriverError):
    """A motion was refused or stopped because it would break a safety limit."""
