"""Emulated Dynamixel X-series servos speaking Protocol 2.0, byte for byte.

* :mod:`~gyrocal.drivers.emulated.dxl.protocol` — CRC-16, byte stuffing, packet framing.
* :mod:`~gyrocal.drivers.emulated.dxl.servo` — one servo: control table, instructions, faults.
* :mod:`~gyrocal.drivers.emulated.dxl.motor` — its motor dynamics on the shared clock.
* :mod:`~gyrocal.drivers.emulated.dxl.bus` — several servos on one bus.
* :mod:`~gyrocal.drivers.emulated.dxl.port` — the in-process ``PortHandler`` (default transport).
* :mod:`~gyrocal.drivers.emulated.dxl.pty` — the pseudo-terminal transport.

:func:`make_emulated_gimbal` builds the whole emulated gimbal in one call; :func:`make_servo_bus`
only its servos on their bus (to serve them on a :class:`PtyServoBridge`).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import NamedTuple

from gyrocal.drivers.clock import Clock
from gyrocal.drivers.emulated.dxl.bus import PendingReply, ServoBus
from gyrocal.drivers.emulated.dxl.motor import MotorParams, RippleComponent, ServoMotor
from gyrocal.drivers.emulated.dxl.port import EmulatedPortHandler
from gyrocal.drivers.emulated.dxl.pty import PtyServoBridge
from gyrocal.drivers.emulated.dxl.servo import EmulatedServo
from gyrocal.drivers.emulated.jig import GimbalJig

__all__ = [
    "EmulatedGimbal",
    "EmulatedPortHandler",
    "EmulatedServo",
    "GimbalJig",
    "MotorParams",
    "PendingReply",
    "PtyServoBridge",
    "RippleComponent",
    "ServoBus",
    "ServoMotor",
    "make_emulated_gimbal",
    "make_servo_bus",
]


class EmulatedGimbal(NamedTuple):
    """What :func:`make_emulated_gimbal` returns: ``port, bus, jig = make_emulated_gimbal(...)``."""

    port: EmulatedPortHandler
    bus: ServoBus
    jig: GimbalJig


def make_servo_bus(
    clock: Clock,
    ids: Sequence[int] = (1, 2, 3),
    model: str = "XM430-W350",
    seed: int = 0,
    *,
    baudrate: int = 1_000_000,
    velocity_limit: int | None = None,
    return_delay_us: float | None = None,
    motor_params: MotorParams | None = None,
) -> ServoBus:
    """Emulated servos of one model on one bus, with no transport yet.

    The parameters are those of :func:`make_emulated_gimbal`; each servo gets its own random
    stream from ``seed``.
    """
    servos = [
        EmulatedServo(int(i), model, clock=clock, seed=int(seed) * 1000 + k, baudrate=baudrate,
                      velocity_limit=velocity_limit, return_delay_us=return_delay_us,
                      motor_params=motor_params)
        for k, i in enumerate(ids)
    ]
    return ServoBus(servos, clock)


def make_emulated_gimbal(
    clock: Clock,
    ids: Sequence[int] = (1, 2, 3),
    model: str = "XM430-W350",
    seed: int = 0,
    *,
    baudrate: int = 1_000_000,
    velocity_limit: int | None = None,
    return_delay_us: float | None = None,
    axes: Sequence[str | Sequence[float]] | None = None,
    tilt_deg: float | Sequence[Sequence[float]] = 0.3,
    mount: float | Sequence[float] = 3.0,
    motor_params: MotorParams | None = None,
    model_timing: bool = True,
) -> EmulatedGimbal:
    """Build an emulated three-axis gimbal: servos, their bus, the in-process port, the jig.

    Parameters
    ----------
    clock : Clock
        The shared clock (normally a :class:`~gyrocal.drivers.clock.VirtualClock`).
    ids : sequence of int
        Servo IDs from the base to the tip of the gimbal.
    model : str
        ``"XM430-W350"`` or ``"XL430-W250"`` for every servo.
    seed : int
        Seed of every random thing (each servo gets its own stream).
    baudrate : int
        The baud rate the servos are configured for (a jig set up for gyrocal runs at 1 Mbps;
        factory servos run at 57600). The port is created at this rate, not yet opened.
    velocity_limit : int or None
        Velocity Limit (44) of every servo in 0.229 rpm units (firmware-dependent, hardware
        reference §5); None = the model's current default.
    return_delay_us : float or None
        Return Delay Time of every servo in µs; None = factory 500 µs.
    axes, tilt_deg, mount
        The jig's geometry (see :class:`~gyrocal.drivers.emulated.jig.GimbalJig`); by default servo
        IDs ``ids[0..2]`` turn about sensor x, y, z with 0.3° tilts and a 3° mount error.
    motor_params : MotorParams or None
        Motor model parameters for every servo.
    model_timing : bool
        Spend transfer and return-delay time on the clock in the port (default).

    Returns
    -------
    EmulatedGimbal
        ``(port, bus, jig)``: pass ``port`` to :class:`gyrocal.drivers.dynamixel.Gimbal`, ``jig``
        to the
        emulated IMU as its motion source; ``bus.servo(id)`` has the fault knobs.
    """
    bus = make_servo_bus(clock, ids, model, seed, baudrate=baudrate,
                         velocity_limit=velocity_limit, return_delay_us=return_delay_us,
                         motor_params=motor_params)
    port = EmulatedPortHandler(bus, clock, model_timing=model_timing)
    port.baudrate = baudrate
    jig = GimbalJig(bus.servos, axes=axes, tilt_deg=tilt_deg, mount=mount, seed=seed)
    return EmulatedGimbal(port, bus, jig)
