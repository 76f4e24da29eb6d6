"""Errors of the Dynamixel gimbal driver, each saying what went wrong and what to do.

They subclass the drivers' hierarchy (:mod:`gyrocal.drivers.errors`), so the kit maps them to exit
codes
without knowing them: communication and hardware alerts are hardware failures, refused motions are
safety errors, and an unexpected servo is an identity error.
"""

from __future__ import annotations

from gyrocal.drivers.dynamixel.control_table import HARDWARE_ERROR_BITS
from gyrocal.drivers.errors import (
    CommunicationError,
    DeviceIdentityError,
    DriverError,
    HardwareAlertError,
    SafetyError,
)
from gyrocal.drivers.signals import TerminatedBySignal  # re-exported: the driver raises it

__all__ = [
    "ElectricalShockError",
    "InputVoltageError",
    "MotorEncoderError",
    "OverheatingError",
    "OverloadError",
    "ServoCommunicationError",
    "ServoHardwareError",
    "ServoIdentityError",
    "ServoLinkLostError",
    "ServoPortHungError",
    "ServoStatusError",
    "ShutdownError",
    "StallError",
    "TerminatedBySignal",
    "TurnLimitError",
    "WatchdogTrippedError",
    "hardware_error_for",
]


class ServoCommunicationError(CommunicationError):
    """A transaction failed after its bounded retries (timeout, corrupt packet, no port).

    Parameters
    ----------
    servo_id : int or None
        The servo addressed (None for a broadcast or group transaction of several servos).
    instruction : str
        What was sent (``"READ Present Position"``, ``"SYNC_READ 120+16"``).
    result_text : str
        dynamixel-sdk's ``getTxRxResult`` (or ``getRxPacketError``) text of the last attempt.
    attempts : int
        How many times it was tried.
    """

    def __init__(self, servo_id: int | None, instruction: str, result_text: str,
                 attempts: int) -> None:
        who = f"servo {servo_id}" if servo_id is not None else "the servo bus"
        super().__init__(
            f"{instruction} to {who} failed {attempts} time(s): {result_text} "
            "Check the servo's power and its bus cable, that the ID and the baud rate match the "
            "configuration, and that no other program uses the port."
        )
        self.servo_id = servo_id
        self.instruction = instruction
        self.result_text = result_text
        self.attempts = attempts


class ServoLinkLostError(CommunicationError):
    """The serial port itself failed (EIO, a vanished device): the USB adapter was unplugged or
    lost power, or its cable broke. Nothing more can be sent to the servos through it."""


class ServoPortHungError(ServoLinkLostError):
    """The serial port stopped taking data: a write did not complete within its timeout (a
    hung USB-serial adapter or driver, flow control held off, a frozen device on the other end
    of a pseudo-terminal). Treated as a lost link: the stop tries once more, bounded, and
    says whether torque off was confirmed."""


class ServoStatusError(DriverError):
    """A servo answered with an error in its status packet (not a hardware alert).

    Parameters
    ----------
    servo_id : int
        The servo.
    instruction : str
        What was sent.
    error : int
        The status error byte.
    error_text : str
        dynamixel-sdk's ``getRxPacketError`` text.
    """

    def __init__(self, servo_id: int, instruction: str, error: int, error_text: str) -> None:
        super().__init__(
            f"servo {servo_id} refused {instruction}: {error_text} (status error 0x{error:02X}). "
            "This is a bug in the command or a servo configured differently from what gyrocal "
            "expects (for example a different firmware); check the servo with Dynamixel Wizard."
        )
        self.servo_id = servo_id
        self.instruction = instruction
        self.error = error
        self.error_text = error_text


class ServoIdentityError(DeviceIdentityError):
    """A configured servo ID did not answer a PING, or answered with an unsupported model."""


class ServoHardwareError(HardwareAlertError):
    """A servo raised its hardware alert (status bit 0x80); it has switched its torque off.

    Parameters
    ----------
    servo_id : int
        The servo.
    status : int
        Hardware Error Status (70) as read from the servo.
    """

    #: Hardware Error Status bit this class stands for (None: several or unknown bits).
    bit: int | None = None

    def __init__(self, servo_id: int, status: int) -> None:
        named = [b for b in HARDWARE_ERROR_BITS if status & (1 << b.bit)]
        if named:
            what = "; ".join(f"{b.name}: {b.advice}" for b in named)
        else:
            what = ("no known bit is set; power the servo off and on and check it with "
                    "Dynamixel Wizard")
        super().__init__(
            f"servo {servo_id} reports a hardware error (Hardware Error Status 0x{status:02X}) "
            f"and has switched its torque off. {what}. A REBOOT instruction (or a power cycle) "
            "clears the error."
        )
        self.servo_id = servo_id
        self.status = status
        self.names = tuple(b.name for b in named)


class InputVoltageError(ServoHardwareError):
    """Hardware Error Status bit 0: input voltage outside the limits."""

    bit = 0


class OverheatingError(ServoHardwareError):
    """Hardware Error Status bit 2: overheating."""

    bit = 2


class MotorEncoderError(ServoHardwareError):
    """Hardware Error Status bit 3: motor encoder failure."""

    bit = 3


class ElectricalShockError(ServoHardwareError):
    """Hardware Error Status bit 4: electrical shock or insufficient power."""

    bit = 4


class OverloadError(ServoHardwareError):
    """Hardware Error Status bit 5: overload."""

    bit = 5


_BY_BIT: dict[int, type[ServoHardwareError]] = {
    cls.bit: cls
    for cls in (InputVoltageError, OverheatingError, MotorEncoderError, ElectricalShockError,
                OverloadError)
    if cls.bit is not None
}


def hardware_error_for(servo_id: int, status: int) -> ServoHardwareError:
    """The named error for a Hardware Error Status value (hardware reference §5).

    A single set bit gives its own class (:class:`OverloadError`, …); several bits give the class
    of the most severe one in the order overload, electrical shock, overheating, encoder,
    voltage; the message lists every bit.
    """
    for bit in (5, 4, 2, 3, 0):
        if status & (1 << bit):
            return _BY_BIT[bit](servo_id, status)
    return ServoHardwareError(servo_id, status)


class TurnLimitError(SafetyError):
    """A motion would turn (or has turned) a servo past the software cable-wrap limit."""


class StallError(SafetyError):
    """A turning servo did not reach or keep its commanded speed; it has been stopped."""


class WatchdogTrippedError(SafetyError):
    """A servo's Bus Watchdog expired (the host was too slow to talk to it) and it stopped."""


class ShutdownError(SafetyError):
    """The safe stop could not confirm torque off on every servo."""
