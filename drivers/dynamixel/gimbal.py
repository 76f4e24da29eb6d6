"""The three-axis gimbal of Dynamixel X-series servos, over dynamixel-sdk (Protocol 2.0).

Motion is **extended-position mode with a velocity-based trapezoidal profile** (Operating Mode 4,
Profile Acceleration and Profile Velocity, hardware reference §5 and §5.1). A turn is one goal
write: Goal Position = start ± N·4096 ticks. Why this mode rather than velocity mode with the
encoder as the stop:

* the servo's own profile generator gives a constant-speed stretch between two symmetric ramps,
  so all but the ramps of an N-turn move are at one speed, and a clean stop exactly on the goal;
* the goal is a bounded multi-turn position, so the servo cannot overshoot past the cable-wrap
  limit even if the host stalls, crashes or is late to poll (in velocity mode the stop would be
  the host's job, late by a poll period and a deceleration);
* the Bus Watchdog still stops a servo whose host has died mid-turn.

The commanded speed is quantized to Profile Velocity's 0.229 rpm; :class:`Motion` reports the
quantized speed. The reference rate of a calibration never uses it: it is the encoder's angle
change over a window divided by the window's duration, both from :meth:`Gimbal.poll`.

Everything is non-blocking so that one loop on one clock can drain the IMU, sample the servos and
step the protocol: :meth:`Gimbal.begin_turn` starts a turn, :meth:`Gimbal.poll` does one sync read
(timestamped at the transaction's midpoint on the caller's clock), checks the safety limits and
tells when the motion has finished. :meth:`Gimbal.run_turn` is a blocking convenience.

Safety (hardware reference §6): the context manager and SIGINT/SIGTERM/SIGHUP handlers (in
place before the first packet of :meth:`Gimbal.open`, deferred during the stop) end every run
with Goal Velocity 0 and Torque Enable 0 on every servo, confirmed by reading it back; the Bus
Watchdog is armed while a servo moves; a software turn limit guards the cables; hardware-error
alerts (status bit 0x80) are read from Hardware Error Status and raised as named errors;
communication failures are retried a bounded number of times and then raised naming the servo,
the instruction and the SDK's result text. dynamixel-sdk's pitfalls are handled: every value is
read as raw bytes and decoded with its control-table record (the SDK returns unsigned values),
and a status with an error but no data (Access Error, where ``read4ByteTxRx`` raises IndexError)
is reported as an error, never as a zero reading.
"""

from __future__ import annotations

import math
import signal
import struct
import termios
from collections import deque
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import serial
from dynamixel_sdk import (
    BROADCAST_ID,
    COMM_SUCCESS,
    GroupSyncRead,
    GroupSyncWrite,
    PacketHandler,
    PortHandler,
)

from gyrocal.drivers import signals
from gyrocal.drivers.buslock import lock_device
from gyrocal.drivers.clock import Clock, SystemClock
from gyrocal.drivers.dynamixel.control_table import (
    ACCELERATION_UNIT_RAD_S2,
    COMPATIBLE_MODELS,
    HARDWARE_ERROR_BITS,
    MODELS,
    OPERATING_MODES,
    POSITION_UNIT_RAD,
    TICK_MODULUS,
    TICKS_PER_TURN,
    VELOCITY_UNIT_RAD_S,
    WATCHDOG_UNIT_S,
    ControlTable,
    ServoModel,
    model_by_name,
)
from gyrocal.drivers.dynamixel.errors import (
    ServoCommunicationError,
    ServoIdentityError,
    ServoLinkLostError,
    ServoPortHungError,
    ServoStatusError,
    ShutdownError,
    StallError,
    TurnLimitError,
    WatchdogTrippedError,
    hardware_error_for,
)
from gyrocal.drivers.errors import CommunicationError, ConfigurationError, SafetyError

__all__ = ["Gimbal", "GimbalSample", "Motion", "ServoInfo", "ServoStatus"]

#: A motion has finished once its servos' encoders have not changed for this long (s).
SETTLE_S = 0.03
_ERRNUM_CRC = 3
_ALERT = 0x80

# Realtime Tick (120) .. Present Position (135): tick u16, Moving u8, Moving Status u8, Present
# PWM s16, Present Current/Load s16, Present Velocity s32, Present Position s32 (§5).
_MOTION_STRUCT = struct.Struct("<HBBhhii")
_POSITION_STRUCT = struct.Struct("<i")
#: Sync-read layouts: (start address, length).
SAMPLE_LAYOUTS: dict[str, tuple[int, int]] = {"motion": (120, _MOTION_STRUCT.size),
                                              "position": (132, _POSITION_STRUCT.size)}


#: How long a cut-short transaction's status packet may still take to arrive, s: the longest
#: Return Delay Time (254 × 2 µs) plus a 30-byte status packet at 57600 baud (5.2 ms), rounded up.
STALE_REPLY_WAIT_S = 0.01
#: How long :meth:`Gimbal.stop` keeps trying to confirm torque off (whole rounds of sync write,
#: write and read-back per unconfirmed servo, each transaction with its own retries) before it
#: gives up and says so: long enough to ride out a host stalled for a second or a burst of
#: noise on the bus, short enough that a user waiting at Ctrl-C is told promptly.
STOP_CONFIRM_S = 2.0
#: The longest a write to the servo port may block, s. dynamixel-sdk opens pyserial with
#: ``timeout=0`` (reads return at once; its status wait is bounded by its packet timeout) but
#: no ``write_timeout``, so a write blocks for ever once the port's output buffer is full: a hung
#: adapter, flow control held off, a frozen emulator on a PTY. A healthy port never fills it (the
#: kit waits for each status packet; its longest packet, ~40 bytes, takes 42 ms at 9600 bps), so
#: 0.5 s is over ten times the longest legitimate wait.
WRITE_TIMEOUT_S = 0.5
#: Pause between two rounds of the stop (lets a starved bus or servo catch up).
STOP_RETRY_PAUSE_S = 0.05


@dataclass(frozen=True)
class ServoInfo:
    """What :meth:`Gimbal.open` learned about one servo.

    Attributes
    ----------
    dxl_id : int
        The ID.
    model_number : int
        Model Number (0).
    model_name : str
        The model's name (``"XM430-W350"``).
    supported : bool
        True for a fully supported model; False for a compatible one accepted with a notice.
    firmware : int
        Firmware Version (6).
    velocity_limit : float
        Velocity Limit (44) read from the device, rad/s (firmware-dependent, hardware
        reference §5).
    no_load_speed : float
        The model's no-load speed at the present input voltage, rad/s (hardware reference §5.3).
    max_speed : float
        The top speed the planner may ask for: the smaller of the two, rad/s.
    voltage_v : float
        Present Input Voltage at open, V.
    temperature_c : float
        Present Temperature at open, °C.
    temperature_limit_c : float
        Temperature Limit (31), °C.
    voltage_limits_v : tuple of float
        (Min, Max) Voltage Limit, V.
    return_delay_s : float
        Return Delay Time (9), s.
    drive_mode : int
        Drive Mode (10) after open.
    """

    dxl_id: int
    model_number: int
    model_name: str
    supported: bool
    firmware: int
    velocity_limit: float
    no_load_speed: float
    max_speed: float
    voltage_v: float
    temperature_c: float
    temperature_limit_c: float
    voltage_limits_v: tuple[float, float]
    return_delay_s: float
    drive_mode: int


@dataclass(frozen=True)
class ServoStatus:
    """A servo's live state (for ``gyrocal doctor`` and reports)."""

    dxl_id: int
    torque_enabled: bool
    moving: bool
    velocity: float
    angle: float
    voltage_v: float
    temperature_c: float
    hardware_error: int
    hardware_error_names: tuple[str, ...]
    bus_watchdog_tripped: bool


@dataclass(frozen=True)
class GimbalSample:
    """One sync read of every servo.

    Attributes
    ----------
    t : float
        Time on the caller's clock at the midpoint of the transaction, s.
    t_start, t_end : float
        The clock before sending the instruction and after the last status arrived.
    ids : tuple of int
        Servo IDs, in the order of the arrays.
    angles : ndarray
        Cumulative, unwrapped shaft angles from the home pose (the positions at
        :meth:`Gimbal.open`), rad, positive in each servo's positive direction.
    ticks : ndarray of int
        Present Position as read (signed multi-turn count).
    velocities : ndarray or None
        Present Velocity, rad/s (None for the ``"position"`` layout).
    servo_time_ms : ndarray or None
        Realtime Tick unwrapped into a cumulative ms count per servo (None for ``"position"``).
    moving : ndarray of bool or None
        Moving (122).
    """

    t: float
    t_start: float
    t_end: float
    ids: tuple[int, ...]
    angles: np.ndarray
    ticks: np.ndarray
    velocities: np.ndarray | None = None
    servo_time_ms: np.ndarray | None = None
    moving: np.ndarray | None = None

    def angle(self, dxl_id: int) -> float:
        """The angle of one servo, rad."""
        return float(self.angles[self.ids.index(dxl_id)])


@dataclass
class Motion:
    """A motion in progress or finished: a turn of one servo, or a return to home.

    Attributes
    ----------
    kind : str
        ``"turn"``, ``"move"`` (one servo to a pose) or ``"return"``.
    servo_ids : tuple of int
        The servos that move.
    turns : int
        Whole turns of a turn (0 for a return).
    direction : int
        +1 or -1 for a turn or a move (0 for a return or a move to where the servo is).
    speed : float
        The commanded (quantized) profile speed, rad/s.
    acceleration : float
        The commanded (quantized) profile acceleration, rad/s².
    start_angles, goal_angles : dict
        Per servo, rad from home.
    goal_ticks : dict
        Per servo, the Goal Position written (multi-turn ticks).
    t_begin : float
        Clock time of the goal write.
    t_end : float or None
        Time of the poll that found it finished.
    finished : bool
        True once every servo is at its goal and still.
    speeds : dict
        Per servo of a ``"turns"`` motion, its commanded (quantized) speed, rad/s; empty for the
        other kinds (``speed`` is then every servo's).
    """

    kind: str
    servo_ids: tuple[int, ...]
    turns: int
    direction: int
    speed: float
    acceleration: float
    start_angles: dict[int, float]
    goal_angles: dict[int, float]
    goal_ticks: dict[int, int]
    t_begin: float
    t_end: float | None = None
    finished: bool = False
    speeds: dict[int, float] = field(default_factory=dict)
    _history: dict[int, deque] = field(default_factory=dict, repr=False)  # servo: (t, ticks)
    _settled: dict[int, tuple[int, float]] = field(default_factory=dict, repr=False)


class Gimbal:
    """Three (or any number of) Dynamixel servos on one bus, driven for gyro calibration.

    Parameters
    ----------
    port : str or PortHandler
        A serial device (``"/dev/ttyUSB0"``) or an existing ``dynamixel_sdk.PortHandler``
        (for example the emulator's :class:`~gyrocal.drivers.emulated.dxl.EmulatedPortHandler`).
    ids : sequence of int
        Servo IDs, base to tip.
    baudrate : int
        Bus speed; the servos must be set to it (factory servos run at 57600).
    clock : Clock or None
        The caller's clock for timestamps and waits; default :class:`SystemClock`. With the
        emulator, pass the emulator's clock.
    max_turns : float
        Software cable-wrap limit: no servo may be commanded (or found) further than this many
        turns from its home position.
    acceleration : float
        Profile acceleration of every motion, rad/s².
    watchdog_s : float
        Bus Watchdog armed while a servo moves, s (20 ms units, 0.02..2.54 s; e-Manual,
        X-series Bus Watchdog (98)). Poll at least this often while a motion runs. The default
        0.3 s is the kit's ``gimbal.watchdog_s``, chosen from ``bench servo_link``
        (hardware_docs/running.md, "The servo link under load").
    retries : int
        Extra attempts of a failed transaction before it is raised.
    sample_layout : str
        ``"motion"`` (Realtime Tick, Moving, velocity and position, 16 bytes per servo) or
        ``"position"`` (Present Position only, 4 bytes: the fastest).
    fast_sync_read : bool
        Use FAST_SYNC_READ (one combined status; firmware ≥ 45, hardware reference §4.4/§4.6).
    return_delay_us : float or None
        If given, write Return Delay Time (EEPROM) at open; None leaves it as it is.
    accept_compatible : bool
        Accept models that share the X-430 control table (listed in
        :data:`~gyrocal.drivers.dynamixel.control_table.COMPATIBLE_MODELS`) with a notice.
    handle_signals : bool
        Turn SIGINT, SIGTERM and SIGHUP into exceptions from the start of :meth:`open` to the
        end of :meth:`close` (main thread only; :mod:`gyrocal.drivers.signals`), so that the stop
        runs; a signal during the stop is deferred until it has finished.
    stall_timeout_s : float
        Window over which a turning servo must keep at least ``min_speed_fraction`` of its
        commanded speed.
    min_speed_fraction : float
        See ``stall_timeout_s``.
    packet_handler : object or None
        A Protocol 2.0 packet handler; default ``dynamixel_sdk.PacketHandler(2.0)``.
    """

    def __init__(
        self,
        port: str | PortHandler,
        ids: Sequence[int] = (1, 2, 3),
        *,
        baudrate: int = 1_000_000,
        clock: Clock | None = None,
        max_turns: float = 3.0,
        acceleration: float = 3.0,
        watchdog_s: float = 0.3,
        retries: int = 3,
        sample_layout: str = "motion",
        fast_sync_read: bool = False,
        return_delay_us: float | None = None,
        accept_compatible: bool = True,
        handle_signals: bool = True,
        stall_timeout_s: float = 1.0,
        min_speed_fraction: float = 0.8,
        packet_handler: object | None = None,
    ) -> None:
        ids = tuple(int(i) for i in ids)
        if not ids or len(set(ids)) != len(ids) or any(not 0 <= i <= 252 for i in ids):
            raise ConfigurationError(
                f"servo IDs must be distinct integers in 0..252, got {ids!r}")
        if sample_layout not in SAMPLE_LAYOUTS:
            raise ConfigurationError(
                f"sample_layout must be one of {sorted(SAMPLE_LAYOUTS)}, got {sample_layout!r}")
        if not (math.isfinite(max_turns) and max_turns > 0):
            raise ConfigurationError(f"max_turns must be a positive number, got {max_turns!r}")
        if not (math.isfinite(acceleration) and acceleration > 0):
            raise ConfigurationError(
                f"acceleration must be a positive number of rad/s², got {acceleration!r}")
        wd_units = round(watchdog_s / WATCHDOG_UNIT_S)
        if not 1 <= wd_units <= 127:
            raise ConfigurationError(
                f"watchdog_s must be 0.02..2.54 s (20 ms steps), got {watchdog_s!r}")
        if int(retries) < 0:
            raise ConfigurationError(f"retries must be >= 0, got {retries!r}")
        self.ids = ids
        self.baudrate = int(baudrate)
        self.clock: Clock = clock if clock is not None else SystemClock()
        self.max_turns = float(max_turns)
        self.acceleration = float(acceleration)
        self.watchdog_units = int(wd_units)
        self.retries = int(retries)
        self.sample_layout = sample_layout
        self.fast_sync_read = bool(fast_sync_read)
        self.return_delay_us = return_delay_us
        self.accept_compatible = bool(accept_compatible)
        self.handle_signals = bool(handle_signals)
        self.stall_timeout_s = float(stall_timeout_s)
        self.min_speed_fraction = float(min_speed_fraction)
        if isinstance(port, str):
            self.port = _CheckedPort(port)
            self._owns_port = True
        else:
            self.port = port
            self._owns_port = False
        self.ph = packet_handler if packet_handler is not None else PacketHandler(2.0)
        self.infos: dict[int, ServoInfo] = {}
        self.models: dict[int, ServoModel] = {}
        self.notices: list[str] = []
        self.home_ticks: dict[int, int] = {}
        self.motion: Motion | None = None
        self.last_sample: GimbalSample | None = None
        #: Transactions that needed a retry (count), for reports.
        self.retry_count = 0
        #: The longest time between two polls while a motion ran (s): the margin to the Bus
        #: Watchdog (:attr:`watchdog_units` × 20 ms) that stops a servo whose host went silent.
        self.worst_poll_interval_s = 0.0
        #: The time since the previous packet of the motion at the latest poll, s (0 at rest).
        self.last_poll_gap_s = 0.0
        self.is_open = False
        #: Whether the last stop read Torque Enable 0 back from every servo (None: no stop yet).
        self.torque_off_confirmed: bool | None = None
        self._tick_state: dict[int, tuple[int, float, float]] = {}
        self._group: GroupSyncRead | None = None
        self._old_handlers: dict[int, object] = {}
        self._last_poll_t: float | None = None
        self._identity: dict[int, tuple[int, str, bool]] = {}

    # =====================================================================================
    # opening and closing
    # =====================================================================================
    def open(self) -> dict[int, ServoInfo]:
        """Open the port, identify every servo, put it in extended-position mode and hold.

        Returns
        -------
        dict
            :class:`ServoInfo` by ID (also in :attr:`infos`); notices in :attr:`notices`.

        Raises
        ------
        CommunicationError
            The port cannot be opened.
        BusInUseError
            Another process holds the servo bus (the message names it).
        ConfigurationError
            The baud rate is not one dynamixel-sdk supports.
        ServoIdentityError
            A servo does not answer a PING or is an unsupported model.
        ServoHardwareError
            A servo reports a hardware error (reboot it first: :meth:`reboot`).
        """
        if self.is_open:
            return self.infos
        self.notices.clear()
        # Handlers first: from the first packet that can switch torque on (in _prepare) to the
        # last of the stop, a signal becomes an exception that runs the stop, never a kill.
        self._install_signal_handlers()
        try:
            self._open_port()
            for dxl_id in self.ids:
                self._identify(dxl_id)
            for dxl_id in self.ids:
                self._prepare(dxl_id)
            self._group = GroupSyncRead(self.port, self.ph, *SAMPLE_LAYOUTS[self.sample_layout])
            for dxl_id in self.ids:
                self._group.addParam(dxl_id)
            self.is_open = True
            self.last_sample = self.sample()
        except BaseException as exc:
            # No with-block calls __exit__ for a failed open(): stop here, and do not let an
            # unconfirmed stop pass silently (the same rule as __exit__).
            with signals.shielded():
                try:
                    self.stop()
                except ShutdownError as shutdown:
                    raise _shutdown_after(exc, shutdown) from exc
                finally:
                    self.is_open = False
                    self._restore_signal_handlers()
                    if self._owns_port:
                        self._close_port()
            raise
        return self.infos

    def _open_port(self) -> None:
        name = self.port.getPortName()
        if self.port.getCFlagBaud(self.baudrate) <= 0:
            raise ConfigurationError(
                f"baud rate {self.baudrate} is not supported by dynamixel-sdk; use one of 9600, "
                "57600, 115200, 1000000, 2000000, 3000000 or 4000000 (the rates the X series "
                "offers) and set the servos to it")
        try:
            if not getattr(self.port, "is_open", False):
                self.port.baudrate = self.baudrate
                ok = self.port.openPort()
            else:
                ok = True
            if ok and self.port.getBaudRate() != self.baudrate:
                ok = self.port.setBaudRate(self.baudrate)
        except (OSError, ValueError) as exc:  # pyserial's SerialException is an OSError
            raise CommunicationError(
                f"cannot open the servo port {name!r}: {exc}. Check that the U2D2 is plugged in, "
                "the device name is right, and you may use it (Linux: the 'dialout' group)."
            ) from exc
        if not ok:
            raise CommunicationError(
                f"cannot open the servo port {name!r} at {self.baudrate} bps")
        ser = getattr(self.port, "ser", None)  # dynamixel-sdk's pyserial object (a real port)
        if ser is not None and hasattr(ser, "fileno"):
            lock_device(ser.fileno(), name)  # one process per bus (BusInUseError)

    def _identify(self, dxl_id: int) -> None:
        try:
            # a hardware alert is read and raised by name in _prepare
            model_number = int(self._transact(dxl_id, "PING",
                                              lambda: self.ph.ping(self.port, dxl_id),
                                              allow_alert=True))
        except ServoCommunicationError as exc:
            raise ServoIdentityError(
                f"servo ID {dxl_id} did not answer a PING at {self.baudrate} bps on "
                f"{self.port.getPortName()!r} ({exc.result_text}). Check its power and cable, and "
                "that its ID and baud rate match the configuration (factory servos: ID 1, "
                "57600 bps; Dynamixel Wizard can scan the bus).") from exc
        if model_number in MODELS:
            model = MODELS[model_number]
            supported = True
        elif model_number in COMPATIBLE_MODELS and self.accept_compatible:
            name, like = COMPATIBLE_MODELS[model_number]
            model = model_by_name(like)
            supported = False
            self.notices.append(
                f"servo {dxl_id} is a {name} (model {model_number}): not tested with gyrocal, "
                f"but its control table matches the {like}'s, which gyrocal uses for it.")
        else:
            known = ", ".join(f"{m.name} ({m.number})" for m in MODELS.values())
            hint = ""
            if model_number in COMPATIBLE_MODELS:
                hint = (f" It is a {COMPATIBLE_MODELS[model_number][0]}, which works with "
                        "accept_compatible=True.")
            raise ServoIdentityError(
                f"servo {dxl_id} is model number {model_number}, which gyrocal does not "
                f"support. Supported: {known}.{hint}")
        self.models[dxl_id] = model
        name = model.name if supported else COMPATIBLE_MODELS[model_number][0]
        self._identity[dxl_id] = (model_number, name, supported)

    def _prepare(self, dxl_id: int) -> None:
        """Torque off, extended-position mode, velocity-based profile, home, hold (§6.1)."""
        status = self._read_item(dxl_id, "Hardware Error Status", allow_alert=True)
        if status:
            raise hardware_error_for(dxl_id, status)
        self._write_item(dxl_id, "Torque Enable", 0)
        self._write_item(dxl_id, "Bus Watchdog", 0)
        drive = self._read_item(dxl_id, "Drive Mode")
        # bit2 time-based profile and bit3 torque-on-by-goal-update must be off (§5, §6.4)
        if drive & 0x0C:
            drive &= ~0x0C
            self._write_item(dxl_id, "Drive Mode", drive)
        if self._read_item(dxl_id, "Operating Mode") != OPERATING_MODES["extended_position"]:
            self._write_item(dxl_id, "Operating Mode", OPERATING_MODES["extended_position"])
        if self.return_delay_us is not None:
            self._write_item(dxl_id, "Return Delay Time",
                             self._table(dxl_id)["Return Delay Time"].from_si(
                                 self.return_delay_us * 1e-6))
        # re-read after the mode switch: Present Position may have been re-based (§5.2, §6.1)
        present = self._read_item(dxl_id, "Present Position")
        self.home_ticks[dxl_id] = present
        model_number, name, supported = self._identity[dxl_id]
        vlimit = self._read_si(dxl_id, "Velocity Limit")
        volts = self._read_si(dxl_id, "Present Input Voltage")
        model = self.models[dxl_id]
        no_load = model.no_load_speed_rad_s_12v * (volts / 12.0 if volts > 0 else 1.0)
        self.infos[dxl_id] = ServoInfo(
            dxl_id=dxl_id,
            model_number=model_number,
            model_name=name,
            supported=supported,
            firmware=self._read_item(dxl_id, "Firmware Version"),
            velocity_limit=vlimit,
            no_load_speed=no_load,
            max_speed=min(vlimit, no_load) if vlimit > 0 else no_load,
            voltage_v=volts,
            temperature_c=self._read_si(dxl_id, "Present Temperature"),
            temperature_limit_c=self._read_si(dxl_id, "Temperature Limit"),
            voltage_limits_v=(self._read_si(dxl_id, "Min Voltage Limit"),
                              self._read_si(dxl_id, "Max Voltage Limit")),
            return_delay_s=self._read_si(dxl_id, "Return Delay Time"),
            drive_mode=drive,
        )
        # hold where it is: Goal Position = Present Position before torque on (§6.1)
        self._write_goal(dxl_id, 0, present)
        self._write_item(dxl_id, "Torque Enable", 1)

    def close(self) -> None:
        """Stop every servo (goal velocity 0, torque off, confirmed) and close the port.

        Raises
        ------
        ShutdownError
            If torque off could not be confirmed on every servo (the message names them).
        """
        with signals.shielded():  # a second signal cannot cut the stop short
            try:
                if self.is_open:
                    self.stop()
            finally:
                self.is_open = False
                self._restore_signal_handlers()
                if self._owns_port:
                    self._close_port()

    def _close_port(self) -> None:
        try:
            if getattr(self.port, "is_open", False):
                if isinstance(self.port, _CheckedPort):
                    self.port.drop_output()  # else close() waits for it to drain (30 s)
                self.port.closePort()
        except (OSError, termios.error, ServoLinkLostError):
            pass

    def __enter__(self) -> Gimbal:
        self.open()
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        try:
            self.close()
        except ShutdownError as shutdown:
            if exc is None:
                raise
            # keep the original error; say that the stop could not be confirmed as well
            raise _shutdown_after(exc, shutdown) from exc

    # ---- signals -------------------------------------------------------------------------
    def _install_signal_handlers(self) -> None:
        """SIGINT, SIGTERM and SIGHUP become exceptions while open (main thread only)."""
        if self.handle_signals and not self._old_handlers:
            self._old_handlers = signals.install()

    def _restore_signal_handlers(self) -> None:
        signals.restore(self._old_handlers)

    # =====================================================================================
    # sampling
    # =====================================================================================
    def sample(self) -> GimbalSample:
        """One sync read of every servo (no safety bookkeeping; see :meth:`poll`).

        Returns
        -------
        GimbalSample
            Timestamped at the transaction's midpoint on :attr:`clock`.

        Raises
        ------
        ServoCommunicationError
            After the bounded retries.
        ServoHardwareError
            A servo's status carries the alert bit (the error is read from Hardware Error
            Status and raised by name).
        """
        self._require_open()
        start, length = SAMPLE_LAYOUTS[self.sample_layout]
        last = ""
        failed_id: int | None = None
        for _attempt in range(self.retries + 1):
            t0 = self.clock.monotonic()
            blocks, result_text, failed_id = self._sync_read_once(start, length)
            t1 = self.clock.monotonic()
            if blocks is not None:
                break
            last = result_text
            self.retry_count += 1
        else:
            what = "FAST_SYNC_READ" if self.fast_sync_read else "SYNC_READ"
            raise ServoCommunicationError(
                failed_id, f"{what} of addresses {start}..{start + length - 1}", last,
                self.retries + 1)
        if any(err for err, _ in blocks.values()):
            self._raise_status_errors(blocks)
        t_mid = 0.5 * (t0 + t1)
        home = self.home_ticks
        if self.sample_layout == "motion":
            tick_list, vel_list, tms_list, moving_list = [], [], [], []
            for dxl_id in self.ids:
                tick, mov, _, _, _, v_raw, present = _MOTION_STRUCT.unpack(blocks[dxl_id][1])
                tick_list.append(present)
                moving_list.append(bool(mov))
                vel_list.append(v_raw * VELOCITY_UNIT_RAD_S)
                tms_list.append(self._unwrap_tick(dxl_id, tick, t_mid))
            vel, tms = np.array(vel_list), np.array(tms_list)
            moving = np.array(moving_list, dtype=bool)
        else:
            tick_list = [_POSITION_STRUCT.unpack(blocks[i][1])[0] for i in self.ids]
            vel = tms = moving = None
        ticks = np.array(tick_list, dtype=np.int64)
        # the same doubles as the int64 arithmetic: an exact difference, then one product
        angles = np.array([(present - home[i]) * POSITION_UNIT_RAD
                           for present, i in zip(tick_list, self.ids, strict=True)])
        s = GimbalSample(t_mid, t0, t1, self.ids, angles, ticks, vel, tms, moving)
        self.last_sample = s
        return s

    def _raise_status_errors(self, blocks: dict[int, tuple[int, bytes]]) -> None:
        """A sync read's statuses carried an error: the first alert is read out and raised by
        name, else the first error is raised."""
        alerts = [i for i, (err, _) in blocks.items() if err & _ALERT]
        if alerts:
            self._raise_alert(alerts[0])
        for i, (err, _) in blocks.items():
            if err & 0x7F:
                raise ServoStatusError(i, "SYNC_READ", err, self.ph.getRxPacketError(err & 0x7F))

    def _sync_read_once(self, start: int, length: int):
        """One sync-read transaction: ``({id: (error, bytes)}, "", None)`` or
        ``(None, result text, id that failed)``."""
        self.port.is_using = False
        ids = list(self.ids)
        if self.fast_sync_read:
            result = self.ph.syncReadTx(self.port, start, length, ids, len(ids), True)
            if result != COMM_SUCCESS:
                return None, self.ph.getTxRxResult(result), None
            raw, result, _ = self.ph.fastSyncReadRx(self.port, BROADCAST_ID,
                                                    (length + 4) * len(ids))
            if result != COMM_SUCCESS:
                return None, self.ph.getTxRxResult(result), None
            blocks = {}
            pos = 0
            for _ in ids:
                if pos + 2 + length > len(raw):
                    return None, "fast sync read status too short", None
                err, dxl_id = raw[pos], raw[pos + 1]
                blocks[dxl_id] = (err, bytes(raw[pos + 2: pos + 2 + length]))
                pos += length + 4
            if set(blocks) != set(ids):
                return None, f"fast sync read answered for IDs {sorted(blocks)}", None
            return blocks, "", None
        result = self._group.txPacket()
        if result != COMM_SUCCESS:
            return None, self.ph.getTxRxResult(result), None
        blocks = {}
        for dxl_id in ids:
            # GroupSyncRead.rxPacket drops each status's error byte; read them ourselves so a
            # hardware alert is never missed.
            data, result, error = self.ph.readRx(self.port, dxl_id, length)
            if result != COMM_SUCCESS:
                self.port.is_using = False
                return None, self.ph.getTxRxResult(result), dxl_id
            if len(data) != length and not error:
                return None, f"status of servo {dxl_id} carried {len(data)} bytes", dxl_id
            blocks[dxl_id] = (error, bytes(data))
        return blocks, "", None

    def _unwrap_tick(self, dxl_id: int, tick: int, t_host: float) -> float:
        """Realtime Tick (0..32767 ms, wrapping, hardware reference §5) → cumulative ms."""
        state = self._tick_state.get(dxl_id)
        if state is None:
            self._tick_state[dxl_id] = (tick, float(tick), t_host)
            return float(tick)
        last_tick, cum, last_t = state
        delta = (tick - last_tick) % TICK_MODULUS
        gap_ms = (t_host - last_t) * 1000.0
        if gap_ms > TICK_MODULUS * 0.75:  # more than one wrap may have passed between reads
            delta += TICK_MODULUS * round((gap_ms - delta) / TICK_MODULUS)
        cum += delta
        self._tick_state[dxl_id] = (tick, cum, t_host)
        return cum

    # =====================================================================================
    # motion
    # =====================================================================================
    @property
    def busy(self) -> bool:
        """True while a motion is in progress."""
        return self.motion is not None and not self.motion.finished

    @property
    def watchdog_s(self) -> float:
        """The Bus Watchdog armed while a servo moves, s (20 ms units, hardware reference §5)."""
        return self.watchdog_units * WATCHDOG_UNIT_S

    @property
    def top_speed(self) -> float:
        """The highest speed every servo can be commanded, rad/s (from the devices' limits)."""
        self._require_open()
        return min(info.max_speed for info in self.infos.values())

    def begin_turn(self, servo_id: int, turns: int, speed: float, direction: int = 1) -> Motion:
        """Start turning one servo by a whole number of turns; the others hold. Non-blocking.

        Parameters
        ----------
        servo_id : int
            The servo to turn.
        turns : int
            Whole turns (>= 1).
        speed : float
            Cruise speed, rad/s (> 0, at most :attr:`top_speed`); quantized to 0.229 rpm.
        direction : int
            +1 (the servo's positive direction) or -1.

        Returns
        -------
        Motion
            The motion, also in :attr:`motion`; poll until ``motion.finished``.

        Raises
        ------
        ConfigurationError
            Bad arguments (the message says which and what is allowed).
        TurnLimitError
            The turn would end beyond :attr:`max_turns` from home.
        SafetyError
            Another motion is still running.
        """
        self._require_open()
        if servo_id not in self.ids:
            raise ConfigurationError(f"servo {servo_id!r} is not on this gimbal (IDs {self.ids})")
        if isinstance(turns, bool) or not float(turns).is_integer() or int(turns) < 1:
            raise ConfigurationError(f"turns must be a whole number >= 1, got {turns!r}")
        if direction not in (1, -1):
            raise ConfigurationError(f"direction must be +1 or -1, got {direction!r}")
        turns = int(turns)
        speed_units, speed_q = self._speed_units(servo_id, speed)
        self._require_idle()
        s = self.sample()
        start = int(s.ticks[self.ids.index(servo_id)])
        goal = start + direction * turns * TICKS_PER_TURN
        self._check_turn_limit(servo_id, goal)
        self._write_item(servo_id, "Bus Watchdog", self.watchdog_units)
        self._write_goal(servo_id, speed_units, goal)
        home = self.home_ticks[servo_id]
        self.motion = Motion(
            kind="turn", servo_ids=(servo_id,), turns=turns, direction=direction, speed=speed_q,
            acceleration=self._accel_units() * ACCELERATION_UNIT_RAD_S2,
            start_angles={servo_id: (start - home) * POSITION_UNIT_RAD},
            goal_angles={servo_id: (goal - home) * POSITION_UNIT_RAD},
            goal_ticks={servo_id: goal}, t_begin=self.clock.monotonic())
        self.motion._history[servo_id] = deque([(s.t, start)])
        self._last_poll_t = self.clock.monotonic()
        return self.motion

    def begin_move(self, servo_id: int, angle: float, speed: float) -> Motion:
        """Start moving one servo to ``angle`` rad from its home position (a pose); the others
        hold. Non-blocking; poll until ``motion.finished`` as for a turn.

        Parameters
        ----------
        servo_id : int
            The servo to move.
        angle : float
            Goal, rad from home (rounded to the nearest encoder tick).
        speed : float
            Cruise speed, rad/s (> 0, at most :attr:`top_speed`).

        Returns
        -------
        Motion
            ``kind`` ``"move"``; finished at once when the servo is already there.

        Raises
        ------
        ConfigurationError
            Bad arguments.
        TurnLimitError
            The goal lies beyond :attr:`max_turns` from home.
        SafetyError
            Another motion is still running.
        """
        self._require_open()
        if servo_id not in self.ids:
            raise ConfigurationError(f"servo {servo_id!r} is not on this gimbal (IDs {self.ids})")
        if not math.isfinite(angle):
            raise ConfigurationError(f"angle must be a finite number of rad, got {angle!r}")
        speed_units, speed_q = self._speed_units(servo_id, speed)
        self._require_idle()
        s = self.sample()
        start = int(s.ticks[self.ids.index(servo_id)])
        home = self.home_ticks[servo_id]
        goal = home + int(round(angle / POSITION_UNIT_RAD))
        self._check_turn_limit(servo_id, goal)
        self.motion = Motion(
            kind="move", servo_ids=(servo_id,), turns=0, direction=int(np.sign(goal - start)),
            speed=speed_q, acceleration=self._accel_units() * ACCELERATION_UNIT_RAD_S2,
            start_angles={servo_id: (start - home) * POSITION_UNIT_RAD},
            goal_angles={servo_id: (goal - home) * POSITION_UNIT_RAD},
            goal_ticks={servo_id: goal}, t_begin=self.clock.monotonic())
        if goal == start:
            self.motion.finished = True
            self.motion.t_end = self.motion.t_begin
        else:
            self._write_item(servo_id, "Bus Watchdog", self.watchdog_units)
            self._write_goal(servo_id, speed_units, goal)
        self._last_poll_t = self.clock.monotonic()
        return self.motion

    def begin_return(self, speed: float | None = None,
                     servo_ids: Sequence[int] | None = None) -> Motion:
        """Start moving servos back to their home positions (all at once). Non-blocking.

        Parameters
        ----------
        speed : float or None
            Cruise speed, rad/s; default the top speed's half.
        servo_ids : sequence of int or None
            The servos to return; default all.
        """
        self._require_open()
        self._require_idle()
        ids = tuple(self.ids if servo_ids is None else (int(i) for i in servo_ids))
        for i in ids:
            if i not in self.ids:
                raise ConfigurationError(f"servo {i!r} is not on this gimbal (IDs {self.ids})")
        if speed is None:
            speed = 0.5 * self.top_speed
        s = self.sample()
        starts, goals, goal_ticks = {}, {}, {}
        speed_q = 0.0
        moving = []
        for i in ids:
            now_ticks = int(s.ticks[self.ids.index(i)])
            units, speed_q = self._speed_units(i, speed)
            starts[i] = (now_ticks - self.home_ticks[i]) * POSITION_UNIT_RAD
            goals[i] = 0.0
            goal_ticks[i] = self.home_ticks[i]
            if now_ticks != self.home_ticks[i]:
                moving.append(i)
                self._write_item(i, "Bus Watchdog", self.watchdog_units)
                self._write_goal(i, units, self.home_ticks[i])
        self.motion = Motion(
            kind="return", servo_ids=tuple(ids), turns=0, direction=0, speed=speed_q,
            acceleration=self._accel_units() * ACCELERATION_UNIT_RAD_S2, start_angles=starts,
            goal_angles=goals, goal_ticks=goal_ticks, t_begin=self.clock.monotonic())
        if not moving:
            self.motion.finished = True
            self.motion.t_end = self.motion.t_begin
        self._last_poll_t = self.clock.monotonic()
        return self.motion

    def begin_turns(self, turns: Mapping[int, tuple[int, float, int]]) -> Motion:
        """Start turning several servos at once, each by whole turns at its own speed (the
        general motion of ``gyrocal verify``). Non-blocking; servos not named hold.

        Parameters
        ----------
        turns : mapping
            ``{servo_id: (turns, speed, direction)}`` as for :meth:`begin_turn`.

        Returns
        -------
        Motion
            Of kind ``"turns"``, also in :attr:`motion`; ``speed`` is the highest quantized
            speed; poll until ``motion.finished``.

        Raises
        ------
        ConfigurationError, TurnLimitError, SafetyError
            As :meth:`begin_turn`, checked for every servo before any moves.
        """
        self._require_open()
        if not turns:
            raise ConfigurationError("begin_turns needs at least one servo")
        plan: dict[int, tuple[int, int, float]] = {}
        for servo_id, (n, speed, direction) in turns.items():
            if servo_id not in self.ids:
                raise ConfigurationError(
                    f"servo {servo_id!r} is not on this gimbal (IDs {self.ids})")
            if isinstance(n, bool) or not float(n).is_integer() or int(n) < 1:
                raise ConfigurationError(f"turns must be a whole number >= 1, got {n!r}")
            if direction not in (1, -1):
                raise ConfigurationError(f"direction must be +1 or -1, got {direction!r}")
            units, speed_q = self._speed_units(servo_id, speed)
            plan[servo_id] = (int(n) * direction, units, speed_q)
        self._require_idle()
        s = self.sample()
        home = self.home_ticks
        starts = {i: int(s.ticks[self.ids.index(i)]) for i in plan}
        goals = {i: starts[i] + plan[i][0] * TICKS_PER_TURN for i in plan}
        for i in plan:
            self._check_turn_limit(i, goals[i])
        for i in plan:
            self._write_item(i, "Bus Watchdog", self.watchdog_units)
            self._write_goal(i, plan[i][1], goals[i])
        self.motion = Motion(
            kind="turns", servo_ids=tuple(plan), turns=max(abs(p[0]) for p in plan.values()),
            direction=0, speed=max(p[2] for p in plan.values()),
            acceleration=self._accel_units() * ACCELERATION_UNIT_RAD_S2,
            start_angles={i: (starts[i] - home[i]) * POSITION_UNIT_RAD for i in plan},
            goal_angles={i: (goals[i] - home[i]) * POSITION_UNIT_RAD for i in plan},
            goal_ticks=goals, t_begin=self.clock.monotonic(),
            speeds={i: p[2] for i, p in plan.items()})
        for i in plan:
            self.motion._history[i] = deque([(s.t, starts[i])])
        self._last_poll_t = self.clock.monotonic()
        return self.motion

    def poll(self) -> GimbalSample:
        """One sync read, then the motion's bookkeeping and the safety checks.

        Returns
        -------
        GimbalSample
            The sample (also :attr:`last_sample`). ``motion.finished`` turns True on the poll
            that finds every moving servo on its goal and still; the Bus Watchdog is then
            disarmed.

        Raises
        ------
        TurnLimitError, StallError, WatchdogTrippedError, ServoHardwareError,
        ServoCommunicationError
            After stopping every servo (goal velocity 0, torque off).
        """
        self._require_open()
        now = self.clock.monotonic()
        gap = now - self._last_poll_t if self.busy and self._last_poll_t is not None else 0.0
        late = gap > self.watchdog_units * WATCHDOG_UNIT_S
        self.last_poll_gap_s = gap
        self.worst_poll_interval_s = max(self.worst_poll_interval_s, gap)
        self._last_poll_t = now
        try:
            s = self.sample()
            self._check_limits(s)
            if self.busy:
                if late:
                    self._check_watchdog()
                self._track_motion(s)
        except Exception as exc:
            self._safe_stop_quietly(exc)
            raise
        return s

    def _track_motion(self, s: GimbalSample) -> None:
        m = self.motion
        done = True
        for i in m.servo_ids:
            k = self.ids.index(i)
            ticks = int(s.ticks[k])
            last = m._settled.get(i)
            if last is None or last[0] != ticks:
                m._settled[i] = last = (ticks, s.t)
            # finished: on the goal (±1 tick), not Moving (122) where it is read, and the
            # encoder unchanged for SETTLE_S (the last ticks of a stop may still move)
            still = s.t - last[1] >= SETTLE_S and (s.moving is None or not bool(s.moving[k]))
            if not (abs(ticks - m.goal_ticks[i]) <= 1 and still):
                done = False
        if m.kind in ("turn", "turns"):
            for i in m.servo_ids:
                m._history[i].append((s.t, int(s.ticks[self.ids.index(i)])))
                self._check_stall(m, s, i)
        if done:
            m.finished = True
            m.t_end = s.t
            for i in m.servo_ids:
                self._write_item(i, "Bus Watchdog", 0)

    def _check_stall(self, m: Motion, s: GimbalSample, i: int) -> None:
        """Turning servo ``i`` must keep ``min_speed_fraction`` of its speed over the last
        ``stall_timeout_s``, once past its acceleration ramp and before its deceleration (each
        servo of a ``"turns"`` motion at its own speed)."""
        speed = m.speeds.get(i, m.speed)
        ramp_t = speed / m.acceleration
        if s.t - m.t_begin < ramp_t + self.stall_timeout_s:
            return
        ticks = int(s.ticks[self.ids.index(i)])
        remaining = abs(m.goal_ticks[i] - ticks) * POSITION_UNIT_RAD
        if remaining <= speed ** 2 / (2 * m.acceleration) + speed * 0.05:
            return
        hist = m._history[i]  # (t, ticks); keep one entry older than the window
        while len(hist) >= 2 and s.t - hist[1][0] > self.stall_timeout_s:
            hist.popleft()
        t_old, ticks_old = hist[0]
        if s.t - t_old < 0.5 * self.stall_timeout_s:
            return
        held = abs(ticks - ticks_old) * POSITION_UNIT_RAD / (s.t - t_old)
        if held < self.min_speed_fraction * speed:
            if self._read_item(i, "Bus Watchdog", allow_alert=True) == -1:
                raise self._watchdog_error(i)
            raise StallError(
                f"servo {i} turns at {held:.3f} rad/s but was commanded {speed:.3f} rad/s "
                f"(below {self.min_speed_fraction:.0%} over {self.stall_timeout_s:g} s): it is "
                "blocked or overloaded. Check that the gimbal turns freely and that no cable "
                "pulls, lower the speed or the load; it has been stopped.")

    def _watchdog_error(self, i: int) -> WatchdogTrippedError:
        return WatchdogTrippedError(
            f"servo {i} stopped: its Bus Watchdog expired because no packet reached it for "
            f"{self.watchdog_units * WATCHDOG_UNIT_S * 1000:.0f} ms. Poll the gimbal more often "
            "during a motion: keep the loop rate (gimbal.sample_hz) up and nothing else on the "
            "bus; the host may be overloaded.")

    def _check_watchdog(self) -> None:
        for i in self.motion.servo_ids:
            if self._read_item(i, "Bus Watchdog", allow_alert=True) == -1:
                raise self._watchdog_error(i)

    def _check_limits(self, s: GimbalSample) -> None:
        margin = 0.05
        for tick, i in zip(s.ticks.tolist(), self.ids, strict=True):
            turns = abs(tick - self.home_ticks[i]) / TICKS_PER_TURN
            if turns > self.max_turns + margin:
                raise TurnLimitError(
                    f"servo {i} is {turns:.2f} turns from home, past the software limit of "
                    f"{self.max_turns:g} turns; it has been stopped. Untwist the cables by hand "
                    "(torque is off) before the next run.")

    def run_turn(self, servo_id: int, turns: int, speed: float, direction: int = 1, *,
                 poll_period_s: float = 0.005,
                 on_sample: Callable[[GimbalSample], None] | None = None,
                 timeout_s: float | None = None) -> Motion:
        """Blocking convenience: :meth:`begin_turn`, then :meth:`poll` until it finishes.

        Parameters
        ----------
        on_sample : callable or None
            Called with every sample.
        timeout_s : float or None
            Give up (stop and raise :class:`StallError`) after this long; default twice the
            planned duration plus 2 s.
        """
        m = self.begin_turn(servo_id, turns, speed, direction)
        if timeout_s is None:
            timeout_s = 2.0 * (turns * 2 * math.pi / m.speed + m.speed / m.acceleration) + 2.0
        return self._wait(m, poll_period_s, on_sample, timeout_s)

    def return_home(self, speed: float | None = None, *, poll_period_s: float = 0.005,
                    on_sample: Callable[[GimbalSample], None] | None = None,
                    timeout_s: float = 60.0) -> Motion:
        """Blocking convenience: :meth:`begin_return`, then :meth:`poll` until it finishes."""
        return self._wait(self.begin_return(speed), poll_period_s, on_sample, timeout_s)

    def _wait(self, m: Motion, period: float, on_sample, timeout_s: float) -> Motion:
        t_end = self.clock.monotonic() + timeout_s
        while not m.finished:
            s = self.poll()
            if on_sample is not None:
                on_sample(s)
            if m.finished:
                break
            if self.clock.monotonic() > t_end:
                error = StallError(
                    f"the {m.kind} of servo(s) {list(m.servo_ids)} did not finish within "
                    f"{timeout_s:g} s; the servos have been stopped. Check that the gimbal "
                    "turns freely.")
                self._safe_stop_quietly(error)
                raise error
            self.clock.sleep(period)
        return m

    # =====================================================================================
    # status, stop, reboot
    # =====================================================================================
    def read_status(self) -> dict[int, ServoStatus]:
        """Each servo's live state (velocity, temperature, voltage, hardware error, …).

        Hardware errors are reported, not raised.
        """
        self._require_open()
        out = {}
        for i in self.ids:
            t = self._table(i)
            ram = self._read_items(i, "Torque Enable", "Hardware Error Status")
            live = self._read_items(i, "Moving", "Present Temperature")
            hw = ram["Hardware Error Status"]
            out[i] = ServoStatus(
                dxl_id=i,
                torque_enabled=bool(ram["Torque Enable"]),
                moving=bool(live["Moving"]),
                velocity=t["Present Velocity"].to_si(live["Present Velocity"]),
                angle=(live["Present Position"] - self.home_ticks[i]) * POSITION_UNIT_RAD,
                voltage_v=t["Present Input Voltage"].to_si(live["Present Input Voltage"]),
                temperature_c=t["Present Temperature"].to_si(live["Present Temperature"]),
                hardware_error=hw,
                hardware_error_names=tuple(b.name for b in HARDWARE_ERROR_BITS
                                           if hw & (1 << b.bit)),
                bus_watchdog_tripped=self._read_item(i, "Bus Watchdog", allow_alert=True) == -1,
            )
        return out

    def _discard_stale_replies(self) -> None:
        """Drop a status packet still in flight from a transaction cut short.

        A signal (or an error) can end a transaction after its instruction went out and before
        its status packet came back. That packet then arrives later: read as the reply to the
        stop's first transaction, it shifts every later reply by one, so a torque read-back
        decodes the previous write's CRC as its value. Waiting out the longest status packet
        (the Return Delay Time, at most 508 µs, e-Manual §2.4.8, plus the packet at the slowest
        baud rate) and clearing the input (dynamixel-sdk ``clearPort``: ``reset_input_buffer``)
        removes it. Output not yet sent (a port that hung with its buffer full) is dropped too,
        so that the stop's packets are the next to go out.
        """
        if not getattr(self.port, "is_open", False):  # never opened: nothing can be in flight
            return
        self.clock.sleep(STALE_REPLY_WAIT_S)
        self.port.clearPort()
        if isinstance(self.port, _CheckedPort):
            self.port.drop_output()

    def stop(self) -> None:
        """Stop every servo: Goal Velocity 0, Torque Enable 0, confirmed by read-back.

        Sync writes reach every servo even if one cannot answer; each servo's torque is then
        read back. The motion in progress (if any) is abandoned.

        Raises
        ------
        ShutdownError
            If a servo's torque could not be confirmed off (the message names it and says what
            to do).
        """
        with signals.shielded():  # a signal during the stop waits until it has finished
            self._stop()

    def _stop(self) -> None:
        self.port.is_using = False
        self.motion = None
        self.torque_off_confirmed = False
        known = [i for i in self.ids if i in self.models]  # identified (open may have failed)
        try:
            self._stop_and_confirm(known)
            self.torque_off_confirmed = True
        except ServoLinkLostError as exc:
            what = ("the servo port hangs" if isinstance(exc, ServoPortHungError)
                    else "the servo link is gone")
            raise ShutdownError(
                f"could NOT confirm torque off on servo(s) {', '.join(map(str, known))}: {what} "
                f"({exc}). The servos stop by themselves when their Bus "
                "Watchdog runs out, if it was armed; switch the servo power off before touching "
                "the gimbal, then check the USB adapter and its cable.") from None

    def _stop_and_confirm(self, known: list[int]) -> None:
        unconfirmed: dict[int, str] = dict.fromkeys(known, "")
        deadline = self.clock.monotonic() + STOP_CONFIRM_S
        rounds = 0
        while unconfirmed:
            rounds += 1
            self._discard_stale_replies()
            for name in ("Goal Velocity", "Torque Enable"):
                try:
                    self._sync_write(name, 0, list(unconfirmed))
                except ServoLinkLostError:
                    raise
                except CommunicationError:
                    pass
            for i in list(unconfirmed):
                why = self._torque_off_confirmed(i)
                if why is None:
                    del unconfirmed[i]
                else:
                    unconfirmed[i] = why
            if not unconfirmed or self.clock.monotonic() >= deadline:
                break
            self.clock.sleep(STOP_RETRY_PAUSE_S)
        if unconfirmed:
            ids = ", ".join(str(i) for i in unconfirmed)
            why = "; ".join(f"servo {i}: {w.rstrip('. ')}" for i, w in unconfirmed.items())
            raise ShutdownError(
                f"could not confirm torque off on servo(s) {ids}: {why} (tried {rounds} "
                f"time(s) within {STOP_CONFIRM_S:g} s). Switch the servo power off before "
                "touching the gimbal, then check its cable and power.")

    def _torque_off_confirmed(self, dxl_id: int) -> str | None:
        """Torque Enable 0 written to one servo and read back as 0 (then its Bus Watchdog
        cleared, e-Manual §2.4.36): None if confirmed, else why not."""
        try:
            self._write_item(dxl_id, "Torque Enable", 0, allow_alert=True)
            if self._read_item(dxl_id, "Torque Enable", allow_alert=True) != 0:
                return "it still reads torque on"
            self._write_item(dxl_id, "Bus Watchdog", 0, allow_alert=True)
        except ServoLinkLostError:
            raise  # the port is gone: no other servo can answer either
        except (CommunicationError, ServoStatusError) as exc:
            return str(exc)
        return None

    def _safe_stop_quietly(self, error: BaseException) -> None:
        """Best-effort :meth:`stop` on the way out with ``error``: a failure of the stop must not
        replace ``error``, so it is added to it as a note (:meth:`close` tries the stop again
        and raises :class:`ShutdownError` if it still cannot confirm torque off)."""
        try:
            if self.is_open:
                self.stop()
        except Exception as exc:
            error.add_note(f"The safe stop after this error failed too: {exc}")

    def reboot(self, servo_id: int) -> None:
        """REBOOT one servo (clears a hardware error), then re-home and hold it.

        The servo forgets its multi-turn count on reboot (hardware reference §5.2), so its home
        is set again to where it is now.
        """
        self._require_open()
        self._require_idle()
        self._transact(servo_id, "REBOOT", lambda: ([], *self.ph.reboot(self.port, servo_id)),
                       allow_alert=True)
        self.clock.sleep(0.5)  # boot time
        self._prepare(servo_id)
        self._tick_state.pop(servo_id, None)

    # =====================================================================================
    # transactions
    # =====================================================================================
    def _table(self, dxl_id: int) -> ControlTable:
        return self.models[dxl_id].table

    def _require_open(self) -> None:
        if not self.is_open:
            raise SafetyError("the gimbal is not open: call open() or use it in a with-block")

    def _require_idle(self) -> None:
        if self.busy:
            raise SafetyError(
                f"a {self.motion.kind} of servo(s) {list(self.motion.servo_ids)} is still "
                "running: poll() until it finishes, or stop() first")

    def _accel_units(self) -> int:
        return max(1, round(self.acceleration / ACCELERATION_UNIT_RAD_S2))

    def _speed_units(self, servo_id: int, speed: float) -> tuple[int, float]:
        if not (isinstance(speed, (int, float)) and math.isfinite(speed) and speed > 0):
            raise ConfigurationError(f"speed must be a positive number of rad/s, got {speed!r}")
        top = self.infos[servo_id].max_speed
        if speed > top * (1 + 1e-9):
            raise ConfigurationError(
                f"speed {speed:.3f} rad/s is above servo {servo_id}'s top speed {top:.3f} rad/s "
                "(its Velocity Limit and no-load speed at the present voltage)")
        units = max(1, round(speed / VELOCITY_UNIT_RAD_S))
        return units, units * VELOCITY_UNIT_RAD_S

    def _check_turn_limit(self, servo_id: int, goal_ticks: int) -> None:
        turns = abs(goal_ticks - self.home_ticks[servo_id]) / TICKS_PER_TURN
        if turns > self.max_turns + 1e-9:
            raise TurnLimitError(
                f"turning servo {servo_id} to {turns:.2f} turns from home would pass the "
                f"software cable-wrap limit of {self.max_turns:g} turns (gimbal.max_turns): "
                "use fewer turns (protocol.turns), or raise gimbal.max_turns if the cabling "
                "allows it.")

    def _raise_alert(self, dxl_id: int) -> None:
        status = self._read_item(dxl_id, "Hardware Error Status", allow_alert=True)
        raise hardware_error_for(dxl_id, status)

    def _transact(self, dxl_id: int, instruction: str, fn, *, allow_alert: bool = False,
                  expect_len: int | None = None):
        """Run ``fn() -> (data, result, error)`` with bounded retries; returns data.

        Raises
        ------
        ServoCommunicationError
            Every attempt failed (no status, a corrupt or short one, or a CRC error reported
            by the servo).
        ServoStatusError
            The servo refused the instruction (status error other than CRC).
        ServoHardwareError
            The status carried the alert bit (unless ``allow_alert``).
        """
        last = ""
        attempts = self.retries + 1
        for _ in range(attempts):
            self.port.is_using = False
            try:
                data, result, error = fn()
            except IndexError:  # the SDK's pitfall on short replies (hardware reference §4.5)
                self.port.is_using = False
                last = "the status packet was too short to decode"
                self.retry_count += 1
                continue
            if result != COMM_SUCCESS:
                self.port.is_using = False
                last = self.ph.getTxRxResult(result)
                self.retry_count += 1
                continue
            if error & 0x7F == _ERRNUM_CRC:  # the instruction was corrupted on the way: resend
                last = self.ph.getRxPacketError(error & 0x7F)
                self.retry_count += 1
                continue
            if error & _ALERT and not allow_alert:
                self._raise_alert(dxl_id)
            if error & 0x7F:
                raise ServoStatusError(dxl_id, instruction, error,
                                       self.ph.getRxPacketError(error & 0x7F))
            if expect_len is not None and len(data) != expect_len:
                last = f"the status carried {len(data)} bytes instead of {expect_len}"
                self.retry_count += 1
                continue
            return data
        raise ServoCommunicationError(dxl_id, instruction, last, attempts)

    def _read_raw(self, dxl_id: int, address: int, length: int, instruction: str, *,
                  allow_alert: bool = False) -> bytes:
        data = self._transact(
            dxl_id, instruction,
            lambda: self.ph.readTxRx(self.port, dxl_id, address, length),
            allow_alert=allow_alert, expect_len=length)
        return bytes(data)

    def _read_item(self, dxl_id: int, name: str, *, allow_alert: bool = False) -> int:
        item = self._table(dxl_id)[name]
        return item.from_bytes(self._read_raw(dxl_id, item.address, item.size, f"READ {name}",
                                              allow_alert=allow_alert))

    def _read_items(self, dxl_id: int, first: str, last: str) -> dict[str, int]:
        """Every item from ``first`` to ``last`` in one READ (alerts reported, not raised),
        decoded by name."""
        table = self._table(dxl_id)
        start, end = table[first].address, table[last].end
        data = self._read_raw(dxl_id, start, end - start, f"READ {first}..{last}",
                              allow_alert=True)
        return {item.name: item.from_bytes(data[item.address - start: item.end - start])
                for item in table.items if start <= item.address and item.end <= end}

    def _read_si(self, dxl_id: int, name: str) -> float:
        item = self._table(dxl_id)[name]
        return item.to_si(self._read_item(dxl_id, name))

    def _write_item(self, dxl_id: int, name: str, raw: int, *, allow_alert: bool = False) -> None:
        item = self._table(dxl_id)[name]
        self._write_raw(dxl_id, item.address, item.to_bytes(raw), f"WRITE {name}={raw}",
                        allow_alert=allow_alert)

    def _write_goal(self, dxl_id: int, velocity_units: int, goal_ticks: int) -> None:
        """Profile Acceleration, Profile Velocity (0 = the Velocity Limit) and Goal Position in
        one WRITE, so the servo starts the new profile from one consistent set."""
        self._write_block(dxl_id, [("Profile Acceleration", self._accel_units()),
                                   ("Profile Velocity", velocity_units),
                                   ("Goal Position", goal_ticks)])

    def _write_block(self, dxl_id: int, values: list[tuple[str, int]]) -> None:
        """Write consecutive items in one WRITE packet (atomic on the servo)."""
        table = self._table(dxl_id)
        data = b""
        address = table[values[0][0]].address
        for name, raw in values:
            item = table[name]
            if item.address != address + len(data):
                raise ValueError(f"{name} does not follow the previous item")
            data += item.to_bytes(raw)
        desc = "WRITE " + ", ".join(f"{n}={v}" for n, v in values)
        self._write_raw(dxl_id, address, data, desc)

    def _write_raw(self, dxl_id: int, address: int, data: bytes, instruction: str, *,
                   allow_alert: bool = False) -> None:
        def fn():
            result, error = self.ph.writeTxRx(self.port, dxl_id, address, len(data), list(data))
            return [], result, error

        self._transact(dxl_id, instruction, fn, allow_alert=allow_alert)

    def _sync_write(self, name: str, raw: int, ids: Sequence[int]) -> None:
        """GroupSyncWrite of one item to servos ``ids`` (no reply, so it reaches a servo that
        cannot answer)."""
        if not ids:
            return
        item = self._table(ids[0])[name]
        group = GroupSyncWrite(self.port, self.ph, item.address, item.size)
        for i in ids:
            group.addParam(i, list(self._table(i)[name].to_bytes(raw)))
        self.port.is_using = False
        result = group.txPacket()
        self.port.is_using = False
        if result != COMM_SUCCESS:
            raise ServoCommunicationError(None, f"SYNC_WRITE {name}={raw}",
                                          self.ph.getTxRxResult(result), 1)


class _CheckedPort(PortHandler):
    """dynamixel-sdk's ``PortHandler`` whose port I/O failures are :class:`ServoLinkLostError`.

    pyserial raises ``SerialException`` (an OSError) from a read or write on a device that went
    away, and ``termios.error`` (not an OSError) from ``reset_input_buffer`` (``tcflush``) and
    ``in_waiting``: an unplugged USB-serial adapter gives EIO on all of them. dynamixel-sdk
    passes them through (``port_handler.py``: ``clearPort``, ``getBytesAvailable``,
    ``readPort``, ``writePort`` call pyserial directly), so they are named here, once. Writes
    are bounded by :data:`WRITE_TIMEOUT_S` (pyserial's ``write_timeout``; dynamixel-sdk sets
    none) and a write that times out is :class:`ServoPortHungError`.
    """

    def setupPort(self, cflag_baud: int) -> bool:
        ok = bool(super().setupPort(cflag_baud))
        self.ser.write_timeout = WRITE_TIMEOUT_S
        return ok

    def drop_output(self) -> None:
        """Discard output not yet sent (``tcflush(TCOFLUSH)``): what a hung port still holds."""
        try:
            self.ser.reset_output_buffer()
        except (OSError, termios.error) as exc:
            raise self._lost(exc) from exc

    def _lost(self, exc: BaseException) -> ServoLinkLostError:
        return ServoLinkLostError(f"the servo port {self.getPortName()!r} failed: {exc} (the USB "
                                  "adapter was unplugged or lost power?)")

    def clearPort(self) -> None:
        try:
            super().clearPort()
        except (OSError, termios.error) as exc:
            raise self._lost(exc) from exc

    def getBytesAvailable(self) -> int:
        try:
            return int(super().getBytesAvailable())
        except (OSError, termios.error) as exc:
            raise self._lost(exc) from exc

    def readPort(self, length: int) -> Any:
        try:
            return super().readPort(length)
        except (OSError, termios.error) as exc:
            raise self._lost(exc) from exc

    def writePort(self, packet: Any) -> int:
        try:
            return int(super().writePort(packet))
        except serial.SerialTimeoutException as exc:
            raise ServoPortHungError(
                f"the servo port {self.getPortName()!r} took no data for {WRITE_TIMEOUT_S:g} s "
                "(a hung USB adapter or driver, or the device on the other end stopped "
                "reading)") from exc
        except (OSError, termios.error) as exc:
            raise self._lost(exc) from exc


def _shutdown_after(cause: BaseException, shutdown: ShutdownError) -> ShutdownError:
    """The error for a failed safe stop on the way out of ``cause``: the cause first, in words
    (the user acts on it), then that torque off could not be confirmed."""
    if isinstance(cause, (KeyboardInterrupt, signals.TerminatedBySignal)):
        signum = getattr(cause, "signum", 2)
        what = f"Stopping on {signal.Signals(signum).name}"
    else:
        what = str(cause).strip() or type(cause).__name__
    if not what.endswith("."):
        what += "."
    return ShutdownError(f"{what} The safe stop then {shutdown}")
