"""One emulated Dynamixel X-series servo: control table, instructions, motor, faults.

The servo executes Protocol 2.0 instructions against its control table (hardware reference §4, §5)
and drives a :class:`~gyrocal.drivers.emulated.dxl.motor.ServoMotor` on the shared clock. It does
not
frame bytes itself: :class:`~gyrocal.drivers.emulated.dxl.bus.ServoBus` parses instruction packets
and
asks the servos on the bus for their replies.

Behaviour modelled (hardware reference §5, §5.1, §5.2, §6):

* EEPROM items refuse writes while torque is on (Access Error 7); read-only items refuse writes
  (Access Error 7); reads past the end of the table give Access Error with no data.
* Operating Mode changes reset Profile Velocity/Acceleration to 0; switching to Position mode,
  turning torque on in Position mode and REBOOT re-base Present Position into one turn;
  Extended Position and Velocity modes keep the multi-turn count.
* Bus Watchdog: armed by a non-zero value while torque is on; if no instruction packet reaches the
  servo within it, the servo stops, the register reads -1, and goal writes give Data Range
  Error until 0 is written.
* Hardware errors (enabled in Shutdown): torque off, Hardware Error Status set, the Alert bit
  0x80 in every status, cleared only by REBOOT.
* Present Velocity in 0.229 rpm units, Present Position in 4096 ticks per turn, Realtime Tick in
  ms modulo 32768, temperature rising slowly under load.
"""

from __future__ import annotations

import math
import struct
import threading

import numpy as np

from gyrocal.drivers.clock import Clock
from gyrocal.drivers.dynamixel.control_table import (
    ACCELERATION_UNIT_RAD_S2,
    BAUD_RATES,
    OPERATING_MODES,
    POSITION_UNIT_RAD,
    RETURN_DELAY_UNIT_S,
    TICK_MODULUS,
    TICKS_PER_TURN,
    VELOCITY_UNIT_RAD_S,
    WATCHDOG_UNIT_S,
    ServoModel,
    model_by_name,
)
from gyrocal.drivers.emulated.dxl.motor import (
    MotorParams,
    Plan,
    ServoMotor,
    plan_position,
    plan_stop,
    plan_velocity,
)
from gyrocal.drivers.emulated.dxl.protocol import (
    ERR_ACCESS,
    ERR_DATA_LENGTH,
    ERR_DATA_LIMIT,
    ERR_DATA_RANGE,
    ERR_INSTRUCTION,
    ERR_RESULT_FAIL,
    ERRBIT_ALERT,
)

__all__ = ["EmulatedServo"]

_RAM_START = 64  # Torque Enable: the first RAM item
_GOAL_ITEMS = ("Goal PWM", "Goal Current", "Goal Velocity", "Goal Position")
_PROFILE_KIND = {"hold": 0, "step": 0, "rectangular": 1, "triangular": 2, "trapezoidal": 3,
                 "velocity": 0}
#: Per item size: the range a live value is clamped to before its bytes are taken (as
#: two's complement), and the little-endian packer of those bytes.
_LIMITS = {n: (-(1 << (8 * n - 1)), (1 << (8 * n)) - 1) for n in (1, 2, 4)}
_PACK = {1: struct.Struct("<B").pack_into, 2: struct.Struct("<H").pack_into,
         4: struct.Struct("<I").pack_into}


def _put(mem: bytearray, lo: int, hi: int, address: int, size: int, value: int) -> None:
    """Store a live value of ``size`` bytes at ``address`` if it overlaps ``lo..hi``, clamped
    to the item's range (:data:`_LIMITS`)."""
    if address < hi and address + size > lo:
        low, high = _LIMITS[size]
        _PACK[size](mem, address, max(low, min(high, value)) & high)


#: The live items of addresses 120..135 (Realtime Tick, Moving, Moving Status, Present PWM,
#: Present Current, Present Velocity, Present Position; hardware reference §5): address and
#: size of each, their range (:data:`_LIMITS`), and one packer for the whole block.
_LIVE_ITEMS = ((120, 2), (122, 1), (123, 1), (124, 2), (126, 2), (128, 4), (132, 4))
_LIVE_BLOCK = struct.Struct("<HBBHHII")
_I32_MIN, _U32_MAX = _LIMITS[4]

#: Deceleration of a shaft whose torque has been switched off (gearbox friction), rad/s².
_FREE_DECEL = 40.0
#: Deceleration of a stop forced by a stall, rad/s² (a Bus Watchdog trip stops at once).
_STOP_DECEL = 20.0


class EmulatedServo:
    """An emulated X-series servo.

    Parameters
    ----------
    dxl_id : int
        Its ID (0..252).
    model : str or ServoModel
        ``"XM430-W350"`` (model 1020) or ``"XL430-W250"`` (1060).
    clock : Clock
        The shared clock.
    seed : int
        Seed of everything random in this servo (initial shaft angle, ripple, noise, faults).
    baudrate : int
        The baud rate it is configured for (one of the Baud Rate register's values).
    velocity_limit : int or None
        Velocity Limit (44) in 0.229 rpm units; None = the model's current-firmware default
        (firmware-dependent, hardware reference §5).
    firmware : int
        Firmware Version (6).
    return_delay_us : float or None
        Return Delay Time in µs (2 µs units); None = the factory 500 µs.
    supply_voltage : float
        Supply voltage in V (sets the no-load speed and Present Input Voltage).
    ambient_c : float
        Ambient temperature in °C.
    temperature_rise_c : float
        Steady-state temperature rise at the no-load speed, in °C.
    thermal_time_constant_s : float
        Time constant of the temperature.
    motor_params : MotorParams or None
        Motor model parameters.
    initial_ticks : int or None
        The absolute encoder reading at power-up (0..4095), with the shaft on that tick's
        centre; None = a random shaft angle from ``seed`` (anywhere within its tick).
    reboot_time_s : float
        How long the servo hears nothing after a REBOOT, whose status it sends at once. The
        e-Manual gives no figure; 0.4 s is what an XC330 was measured to take ⚠ (ROBOTIS-GIT/
        emanual issue 1698).
    """

    def __init__(
        self,
        dxl_id: int = 1,
        model: str | ServoModel = "XM430-W350",
        *,
        clock: Clock,
        seed: int = 0,
        baudrate: int = 57600,
        velocity_limit: int | None = None,
        firmware: int = 46,
        return_delay_us: float | None = None,
        supply_voltage: float = 12.0,
        ambient_c: float = 25.0,
        temperature_rise_c: float = 20.0,
        thermal_time_constant_s: float = 300.0,
        motor_params: MotorParams | None = None,
        initial_ticks: int | None = None,
        reboot_time_s: float = 0.4,
    ) -> None:
        if not reboot_time_s >= 0:
            raise ValueError(f"reboot_time_s must be >= 0, got {reboot_time_s!r}")
        self.reboot_time_s = float(reboot_time_s)
        self._booting_until = -math.inf
        self.model = model_by_name(model) if isinstance(model, str) else model
        self.table = self.model.table
        if not 0 <= int(dxl_id) <= 252:
            raise ValueError(f"servo ID must be 0..252, got {dxl_id!r}")
        codes = {b: c for c, b in BAUD_RATES.items()}
        if baudrate not in codes:
            raise ValueError(f"baud rate {baudrate} is not one of {sorted(codes)}")
        self.clock = clock
        self.lock: threading.RLock = threading.RLock()
        self.seed = int(seed)
        self._rng = np.random.default_rng([self.seed, 0xD1])
        self.supply_voltage = float(supply_voltage)
        self.ambient_c = float(ambient_c)
        self.temperature_rise_c = float(temperature_rise_c)
        self.thermal_time_constant_s = float(thermal_time_constant_s)
        now = clock.monotonic()
        self.motor = ServoMotor(now, self.model.gear_ratio, motor_params,
                                seed=int(self._rng.integers(2**31)))
        if initial_ticks is None:
            # A shaft at power-up rests anywhere, not on a tick's centre: its reading errs by
            # up to half a tick, like every other still angle.
            self._abs0 = float(self._rng.integers(TICKS_PER_TURN)) + self._rng.uniform(-0.5, 0.5)
        else:
            self._abs0 = float(int(initial_ticks) % TICKS_PER_TURN)
        self._mem = bytearray(self.table.size)
        #: Addresses of the one-byte items every packet reads.
        self._torque_at = self.table["Torque Enable"].address
        self._watchdog_at = self.table["Bus Watchdog"].address
        #: Item name -> (address, end, signed), filled as items are read (:meth:`_get`).
        self._where: dict[str, tuple[int, int, bool]] = {}
        self._factory = {"ID": int(dxl_id), "Baud Rate": codes[baudrate],
                         "Firmware Version": int(firmware)}
        if velocity_limit is not None:
            self._factory["Velocity Limit"] = int(velocity_limit)
        if return_delay_us is not None:
            self._factory["Return Delay Time"] = round(return_delay_us * 1e-6 / RETURN_DELAY_UNIT_S)
        self._load_defaults(eeprom=True)
        self._boot_time = now
        self._turn_offset = 0  # register-domain offset that re-bases the multi-turn count
        self._rebase()
        self._goal_to_present()
        self._temperature = self.ambient_c
        self._thermal_t = now
        self._thermal_angle = 0.0
        self._registered: tuple[int, bytes] | None = None
        self._watchdog_deadline: float | None = None
        self._speed_cap = 1.0
        self._events: list[tuple[float, str, dict]] = []
        # fault knobs
        self.drop_count = 0
        self.corrupt_count = 0
        self.drop_probability = 0.0
        self.corrupt_probability = 0.0
        self.silent_from: float | None = None
        self.deaf_from: float | None = None
        #: counters for tests and reports
        self.packets_received = 0
        self.replies_dropped = 0
        self.replies_corrupted = 0

    # ---- identity ------------------------------------------------------------------------
    @property
    def dxl_id(self) -> int:
        """The ID in the control table (changes if ID (7) is written)."""
        return self._mem[7]

    @property
    def baudrate(self) -> int:
        """The baud rate the servo listens at (Baud Rate (8))."""
        return BAUD_RATES.get(self._mem[8], 57600)

    @property
    def return_delay_s(self) -> float:
        """Return Delay Time (9) in s."""
        return self._mem[9] * RETURN_DELAY_UNIT_S

    def __repr__(self) -> str:
        return f"EmulatedServo(id={self.dxl_id}, model={self.model.name!r})"

    # ---- raw memory ----------------------------------------------------------------------
    def _get(self, name: str) -> int:
        where = self._where.get(name)
        if where is None:  # first use of the item (or an unknown name: the table says so)
            item = self.table[name]
            where = self._where[name] = (item.address, item.end, item.signed)
        address, end, signed = where
        # ControlItem.from_bytes without its checks: little-endian, two's complement if signed
        return int.from_bytes(self._mem[address:end], "little", signed=signed)

    def _set(self, name: str, raw: int) -> None:
        item = self.table[name]
        self._mem[item.address: item.end] = item.to_bytes(raw)

    def _load_defaults(self, *, eeprom: bool, keep: tuple[str, ...] = (),
                       factory: bool = False) -> None:
        """Load the power-up values (RAM, and EEPROM when ``eeprom``): the ones this servo was
        built with, or with ``factory`` the model's factory values (FACTORY_RESET), keeping the
        items named in ``keep``."""
        kept = {name: self._get(name) for name in keep}
        built = self._factory
        if factory:
            built = {"Firmware Version": self._factory["Firmware Version"]}
        for item in self.table.items:
            if item.address < _RAM_START and not eeprom:
                continue
            value = built.get(item.name, self.model.defaults.get(item.name, 0))
            self._mem[item.address: item.end] = item.to_bytes(value)
        # indirect addresses default to 224.. (their own data bytes' addresses are unused)
        for k in range(56):
            name = f"Indirect Address {k + 1}"
            if name in self.table and (eeprom or self.table[name].address >= _RAM_START):
                self._set(name, 224 + k if k < 28 else 634 + k - 28)
        for name, value in kept.items():
            self._set(name, value)

    # ---- conversions between the register domain and the motor ---------------------------
    @property
    def _dir(self) -> int:
        return -1 if self._mem[10] & 0x01 else 1

    def _ticks_internal(self, angle: float) -> float:
        return self._abs0 + angle / POSITION_UNIT_RAD

    def _position_register(self, angle: float) -> int:
        raw = self._dir * round(self._ticks_internal(angle))
        return raw + self._turn_offset + self._get("Homing Offset")

    def _angle_for_register(self, position: int) -> float:
        raw = position - self._get("Homing Offset") - self._turn_offset
        return (self._dir * raw - self._abs0) * POSITION_UNIT_RAD

    def _rebase(self) -> None:
        """Re-base Present Position into one turn (§5.2: mode → Position, torque on in Position,
        power-up and REBOOT)."""
        angle = self.motor.angle_at(self.clock.monotonic())
        raw = self._dir * round(self._ticks_internal(angle))
        self._turn_offset = -TICKS_PER_TURN * math.floor(raw / TICKS_PER_TURN)

    def _goal_to_present(self) -> None:
        """At power-up and after REBOOT, Goal Position holds the present position, so turning
        torque on does not move the horn (a goal written before torque-on still does, §6.1)."""
        self._set("Goal Position",
                  self._position_register(self.motor.angle_at(self.clock.monotonic())))

    # ---- time-driven behaviour -------------------------------------------------------------------
    def _max_speed(self) -> float:
        return self.model.no_load_speed_rad_s_12v * self.supply_voltage / 12.0

    def advance_to(self, t: float) -> None:
        """Apply every timed event (watchdog, scheduled faults) due by ``t``."""
        wd = self._watchdog_deadline
        try:
            event_due = self._events[0][0] <= t
        except IndexError:  # no event (read without the lock: another thread may pop one)
            event_due = False
        if not event_due and (wd is None or wd > t):
            return  # nothing due (the usual case); whatever is due is applied under the lock
        with self.lock:
            while True:
                due = []
                if self._watchdog_deadline is not None and self._watchdog_deadline <= t:
                    due.append((self._watchdog_deadline, "watchdog", {}))
                if self._events and self._events[0][0] <= t:
                    due.append(self._events[0])
                if not due:
                    return
                te, kind, args = min(due, key=lambda e: e[0])
                if kind == "watchdog":
                    self._trip_watchdog(te)
                else:
                    self._events.pop(0)
                    self._fire(te, kind, args)

    def true_motion(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """True shaft angle (rad, from power-up, motor's positive direction) and rate at ``t``.

        This is what the jig turns into the sensor's rate; the encoder reads the same angle.
        """
        t = np.asarray(t, dtype=float).reshape(-1)
        with self.lock:
            if t.size:
                self.advance_to(float(t.max()))
            return self.motor.motion(t)

    def peek_motion(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`true_motion` as it stands now, without its side effects: no timed event is
        applied and no grid cell is frozen, so a later command or event may still change what
        it returned (:meth:`motion_revision` then moves)."""
        with self.lock:
            return self.motor.motion(np.asarray(t, dtype=float).reshape(-1), freeze=False)

    def motion_revision(self) -> int:
        """Moves whenever the motor is commanded: a :meth:`peek_motion` from before may be
        out of date."""
        return self.motor.revision

    def next_due(self) -> float:
        """The time of the next timed event (Bus Watchdog, scheduled fault), ``inf`` for none:
        a :meth:`true_motion` reaching it applies it first."""
        with self.lock:
            due = math.inf if self._watchdog_deadline is None else self._watchdog_deadline
            return min(due, self._events[0][0]) if self._events else due

    def touch(self, t: float) -> None:
        """What :meth:`true_motion` does besides returning the motion, for times whose latest
        is ``t``: apply the events due by then, and freeze the grid through ``t``."""
        with self.lock:
            self.advance_to(t)
            self.motor.sample(t)

    def _schedule(self, t: float, kind: str, **args) -> None:
        with self.lock:
            self._events.append((float(t), kind, args))
            self._events.sort(key=lambda e: e[0])

    def _fire(self, t: float, kind: str, args: dict) -> None:
        if kind == "alert":
            self._hardware_error(t, int(args["bits"]), force=bool(args.get("force", True)))
        elif kind == "stall":
            self._speed_cap = float(args["fraction"])
            self._replan(t)
            after = args.get("overload_after_s")
            if after is not None:
                self._events.append((t + float(after), "alert", {"bits": 1 << 5, "force": False}))
                self._events.sort(key=lambda e: e[0])
        elif kind == "unstall":
            self._speed_cap = 1.0
            self._replan(t)

    def _trip_watchdog(self, t: float) -> None:
        self._watchdog_deadline = None
        self._set("Bus Watchdog", -1)
        if self._get("Torque Enable"):
            # "the DYNAMIXEL stops" at once (e-Manual, X-series, Bus Watchdog (98)): no ramp
            self.motor.command(t, lambda t0, p0, v0: plan_stop(t0, p0, v0, math.inf))

    def _hardware_error(self, t: float, bits: int, *, force: bool) -> None:
        if not force:
            bits &= self._get("Shutdown")
        if not bits:
            return
        self._set("Hardware Error Status", self._get("Hardware Error Status") | bits)
        self._torque_off(t)

    def _torque_off(self, t: float) -> None:
        self._set("Torque Enable", 0)
        self._watchdog_deadline = None
        self.motor.command(t, lambda t0, p0, v0: plan_stop(t0, p0, v0, _FREE_DECEL))

    def _update_thermal(self, t: float) -> None:
        dt = t - self._thermal_t
        if dt < 0.5:  # the temperature changes over minutes: update at most twice a second
            return
        angle = self.motor.angle_at(t)
        speed = abs(angle - self._thermal_angle) / dt
        target = self.ambient_c + self.temperature_rise_c * min(speed / self._max_speed(), 2.0)
        self._temperature += (target - self._temperature) * (
            1.0 - math.exp(-dt / self.thermal_time_constant_s))
        self._thermal_t, self._thermal_angle = t, angle
        limit = self._get("Temperature Limit")
        if self._temperature > limit:
            self._hardware_error(t, 1 << 2, force=False)

    # ---- fault knobs ---------------------------------------------------------------------
    def drop_replies(self, count: int = 1) -> None:
        """Drop the next ``count`` status packets this servo would send (it still executes)."""
        self.drop_count += int(count)

    def corrupt_replies(self, count: int = 1) -> None:
        """Send the next ``count`` status packets with a wrong CRC."""
        self.corrupt_count += int(count)

    def go_silent(self, at: float | None = None, *, deaf: bool = False) -> None:
        """Stop answering from time ``at`` (default now). With ``deaf`` it also stops executing
        instructions (a cut cable); without, it still executes them (a dead TX line)."""
        t = self.clock.monotonic() if at is None else float(at)
        self.silent_from = t
        if deaf:
            self.deaf_from = t

    def raise_alert_at(self, t: float, bits: int = 1 << 5) -> None:
        """Raise a hardware error at time ``t``: Hardware Error Status |= ``bits`` (default
        overload), torque off, Alert bit in every status until REBOOT."""
        self._schedule(t, "alert", bits=bits, force=True)

    def stall_at(self, t: float, speed_fraction: float = 0.0,
                 overload_after_s: float | None = None) -> None:
        """From time ``t`` the motor reaches only ``speed_fraction`` of any commanded speed
        (0 = blocked). With ``overload_after_s`` the servo raises an Overload alert that long
        after the stall begins (if Shutdown enables it), as a real blocked servo does."""
        if not 0.0 <= speed_fraction <= 1.0:
            raise ValueError(f"speed_fraction must be in 0..1, got {speed_fraction!r}")
        self._schedule(t, "stall", fraction=speed_fraction, overload_after_s=overload_after_s)

    def clear_stall_at(self, t: float) -> None:
        """End a stall at time ``t``."""
        self._schedule(t, "unstall")

    # ---- called by the bus ---------------------------------------------------------------
    def hears(self, now: float, baudrate: int | None) -> bool:
        """True if a packet sent at ``baudrate`` at time ``now`` reaches this servo."""
        if self.deaf_from is not None and now >= self.deaf_from:
            return False
        if now < self._booting_until:  # rebooting
            return False
        return baudrate is None or baudrate == self.baudrate

    def answers(self, now: float) -> bool:
        """True unless the servo has gone silent."""
        return self.silent_from is None or now < self.silent_from

    def note_instruction(self, now: float) -> None:
        """An instruction packet addressed to this servo arrived: restart the Bus Watchdog."""
        with self.lock:
            self.advance_to(now)
            self.packets_received += 1
            mem = self._mem
            wd = mem[self._watchdog_at]  # one signed byte: 1..127 armed, 0 off, 255 (-1) tripped
            if 0 < wd < 128 and mem[self._torque_at]:
                self._watchdog_deadline = now + wd * WATCHDOG_UNIT_S

    def status_level_allows(self, kind: str) -> bool:
        """Status Return Level (68): 0 = PING only, 1 = PING and READ, 2 = all (§4.5)."""
        level = self._mem[68]
        return kind == "ping" or (kind == "read" and level >= 1) or level >= 2

    def reply_fault(self) -> str | None:
        """Consume a fault for the next reply: ``"drop"``, ``"corrupt"`` or None."""
        if self.drop_count > 0:
            self.drop_count -= 1
            self.replies_dropped += 1
            return "drop"
        if self.corrupt_count > 0:
            self.corrupt_count -= 1
            self.replies_corrupted += 1
            return "corrupt"
        if self.drop_probability and self._rng.random() < self.drop_probability:
            self.replies_dropped += 1
            return "drop"
        if self.corrupt_probability and self._rng.random() < self.corrupt_probability:
            self.replies_corrupted += 1
            return "corrupt"
        return None

    def error_byte(self, error: int = 0) -> int:
        """The status error byte: ``error`` plus the Alert bit if a hardware error is latched."""
        return (error & 0x7F) | (ERRBIT_ALERT if self._mem[70] else 0)

    # ---- instructions --------------------------------------------------------------------
    def ping(self) -> bytes:
        """PING status parameters: model number (LE) and firmware version."""
        return bytes(self._mem[0:2]) + bytes([self._mem[6]])

    def read(self, address: int, length: int) -> tuple[int, bytes]:
        """READ: ``(error, data)``; Access Error with no data past the table's end (§4.5)."""
        with self.lock:
            now = self.clock.monotonic()
            if length < 1 or address < 0 or address + length > self.table.size:
                return ERR_ACCESS, b""
            self.advance_to(now)
            self._refresh(now, address, length)
            end = address + length
            if not (end > 224 and address <= 251 or end > 634 and address <= 661):
                return 0, bytes(self._mem[address:end])
            out = bytearray(self._mem[address:end])  # Indirect Data: each byte its target's
            for i in range(length):
                target = self._indirect_target(address + i)
                if target is not None:
                    self._refresh(now, target, 1)
                    out[i] = self._mem[target]
            return 0, bytes(out)

    def _indirect_target(self, address: int) -> int | None:
        if 224 <= address <= 251:
            k = address - 224
            base = 168
        elif 634 <= address <= 661:
            k = address - 634
            base = 578
        else:
            return None
        target = self._mem[base + 2 * k] | (self._mem[base + 2 * k + 1] << 8)
        if 224 <= target <= 251 or 634 <= target <= 661 or target >= self.table.size:
            return None
        return target

    @property
    def secondary_id(self) -> int | None:
        """Secondary(Shadow) ID (address 12), or None when deactivated (253–255; e-Manual)."""
        value = self._get("Secondary(Shadow) ID")
        return value if value < 253 else None

    def in_ram(self, address: int, length: int) -> bool:
        """Whether ``length`` bytes from ``address`` are all in the RAM area (address 64 on)
        and not indirect data bytes that point into EEPROM."""
        for a in range(address, address + length):
            t = self._indirect_target(a)
            if (a if t is None else t) < _RAM_START:
                return False
        return True

    def write(self, address: int, data: bytes, *, apply: bool = True) -> int:
        """WRITE: the status error number (0 = done). ``apply=False`` only validates."""
        with self.lock:
            now = self.clock.monotonic()
            self.advance_to(now)
            n = len(data)
            if n < 1 or address < 0 or address + n > self.table.size:
                return ERR_ACCESS
            # resolve indirect data bytes to their target addresses
            targets = []
            for i in range(n):
                a = address + i
                t = self._indirect_target(a)
                targets.append(a if t is None else t)
            new = bytearray(self._mem)
            touched = []
            covered: dict[str, int] = {}
            for a, b in zip(targets, data, strict=True):
                item = self.table.owner(a)
                if item is None:
                    return ERR_ACCESS
                if not item.writable:
                    return ERR_ACCESS
                if item.eeprom and self._mem[64]:
                    return ERR_ACCESS
                new[a] = b
                covered[item.name] = covered.get(item.name, 0) + 1
                if item not in touched:
                    touched.append(item)
            # "Data Length Error: ... when you attempt to use only 2 bytes of an item that has
            # been defined as 4 bytes" (e-Manual, Protocol 2.0, Status Packet, Error)
            if any(covered[item.name] < item.size for item in touched):
                return ERR_DATA_LENGTH
            for item in touched:
                value = item.from_bytes(new[item.address: item.end])
                err = self._check(item.name, value, new)
                if err:
                    return err
            if not apply:
                return 0
            old = bytes(self._mem)
            self._mem[:] = new
            self._after_write(now, touched, old)
            return 0

    def _check(self, name: str, value: int, new: bytearray) -> int:
        item = self.table[name]
        lo, hi = item.raw_range()
        if not lo <= value <= hi:
            return ERR_DATA_RANGE
        if name == "Operating Mode" and value not in self.model.operating_modes:
            return ERR_DATA_RANGE
        if name in _GOAL_ITEMS and self._get("Bus Watchdog") == -1:
            return ERR_DATA_RANGE
        if name == "Goal Velocity":
            limit = self.table["Velocity Limit"].from_bytes(new[44:48])
            if abs(value) > limit:
                return ERR_DATA_LIMIT
        if name == "Goal Position" and new[11] == OPERATING_MODES["position"]:
            lo_p = self.table["Min Position Limit"].from_bytes(new[52:56])
            hi_p = self.table["Max Position Limit"].from_bytes(new[48:52])
            if not lo_p <= value <= hi_p:
                return ERR_DATA_LIMIT
        if name == "Torque Enable" and value == 1 and self._mem[70]:
            return ERR_RESULT_FAIL
        return 0

    def _after_write(self, now: float, touched: list, old: bytes) -> None:
        names = {item.name for item in touched}
        changed = {n for n in names
                   if old[self.table[n].address: self.table[n].end]
                   != self._mem[self.table[n].address: self.table[n].end]}
        mode = self._mem[11]
        if "Operating Mode" in changed:
            self._set("Profile Velocity", 0)
            self._set("Profile Acceleration", 0)
            if "Goal PWM" in self.table:
                self._set("Goal PWM", self._get("PWM Limit"))
            if "Goal Current" in self.table:
                self._set("Goal Current", self._get("Current Limit"))
            if mode == OPERATING_MODES["position"]:
                self._rebase()
        if "Bus Watchdog" in names:
            wd = self._get("Bus Watchdog")
            self._watchdog_deadline = (now + wd * WATCHDOG_UNIT_S
                                       if wd > 0 and self._mem[64] else None)
        if "Torque Enable" in changed:
            if self._mem[64]:
                if mode == OPERATING_MODES["position"]:
                    self._rebase()
                wd = self._get("Bus Watchdog")
                if wd > 0:
                    self._watchdog_deadline = now + wd * WATCHDOG_UNIT_S
                self._replan(now)
            else:
                self._torque_off(now)
        elif self._mem[64] and names & {"Goal Position", "Goal Velocity"}:
            self._replan(now)

    def _profile(self) -> tuple[float, float]:
        """(vmax rad/s, accel rad/s²) of the position profile (§5: 108/112, Drive Mode bit2)."""
        limit = min(self._get("Velocity Limit") * VELOCITY_UNIT_RAD_S or math.inf,
                    self._max_speed())
        pv = self._get("Profile Velocity")
        pa = self._get("Profile Acceleration")
        vmax = min(pv * VELOCITY_UNIT_RAD_S, limit) if pv else limit
        accel = pa * ACCELERATION_UNIT_RAD_S2 if pa else math.inf
        return vmax * self._speed_cap, accel

    def _replan(self, now: float) -> None:
        """Give the motor a new plan for the current mode, goal and profile."""
        if not self._mem[64]:
            return
        mode = self._mem[11]
        if self._speed_cap == 0.0:
            self.motor.command(now, lambda t0, p0, v0: plan_stop(t0, p0, v0, _STOP_DECEL))
            return
        if mode == OPERATING_MODES["velocity"]:
            target = self._dir * self._get("Goal Velocity") * VELOCITY_UNIT_RAD_S
            cap = self._max_speed()
            target = max(-cap, min(cap, target)) * self._speed_cap
            pa = self._get("Profile Acceleration")
            accel = pa * ACCELERATION_UNIT_RAD_S2 if pa else math.inf
            self.motor.command(now, lambda t0, p0, v0: plan_velocity(t0, p0, v0, target, accel))
        elif mode in (OPERATING_MODES["position"], OPERATING_MODES["extended_position"],
                      OPERATING_MODES["current_based_position"]):
            goal_register = self._get("Goal Position")
            centre = self._angle_for_register(goal_register)
            band = self.motor.params.hold_band * POSITION_UNIT_RAD
            vmax, accel = self._profile()
            time_based = bool(self._mem[10] & 0x04)  # 112 = total ms, 108 = accel ms

            def make(t0: float, p0: float, v0: float) -> Plan:
                if v0 == 0.0 and self._position_register(p0) == goal_register:
                    # already resting where Present Position reads the goal (torque on with
                    # Goal = Present, a rewrite of the same goal): the loop has nothing to do
                    return plan_position(t0, p0, v0, p0, vmax, accel)
                # the loop stops once the encoder reads the goal: anywhere in its tick
                # (MotorParams.hold_band)
                goal = centre + (float(self._rng.uniform(-band / 2, band / 2)) if band else 0.0)
                if not time_based:
                    return plan_position(t0, p0, v0, goal, vmax, accel)
                total = self._get("Profile Velocity") * 1e-3
                acc_t = min(self._get("Profile Acceleration") * 1e-3, total / 2.0)
                if total <= 0 or goal == p0:
                    return plan_position(t0, p0, v0, goal, vmax, math.inf)
                v = min(abs(goal - p0) / (total - acc_t), self._max_speed())
                return plan_position(t0, p0, v0, goal, v, v / acc_t if acc_t > 0 else math.inf)

            self.motor.command(now, make)
        else:  # current / PWM modes: no position control is emulated; hold where it is
            self.motor.command(now, lambda t0, p0, v0: plan_stop(t0, p0, v0, _FREE_DECEL))

    def _refresh(self, now: float, address: int, length: int) -> None:
        """Write the live values of read-only items in ``address..+length`` into memory."""
        lo, hi = address, address + length
        if hi <= 120 or lo >= 148:
            return
        angle, rate = self.motor.sample(now)
        mem = self._mem
        torque = mem[64]
        d = -1 if mem[10] & 0x01 else 1  # Drive Mode's direction bit (_dir)
        # _position_register(angle), inline
        present = (d * round(self._abs0 + angle / POSITION_UNIT_RAD) + self._turn_offset
                   + self._get("Homing Offset"))
        vel_units = round(d * rate / VELOCITY_UNIT_RAD_S)
        plan = self.motor.plan
        running = bool(torque) and now < plan.end_time  # plan.running(now)
        speed_frac = min(abs(rate) / self._max_speed(), 1.5)
        if lo <= 120 and hi >= 136:  # the whole motion block (a gimbal's sample): one pack
            tick, moving, status, pwm, current, vel, pos = self._live_values(
                now, torque, present, vel_units, running, speed_frac, plan)
            # fitted as _put fits them: the first five are within their sizes' ranges by
            # construction (tick < 32768, status < 64, |PWM| <= 885, |current| <= 275)
            _LIVE_BLOCK.pack_into(mem, 120, tick, moving, status, pwm & 0xFFFF,
                                  current & 0xFFFF, max(_I32_MIN, min(_U32_MAX, vel)) & _U32_MAX,
                                  max(_I32_MIN, min(_U32_MAX, pos)) & _U32_MAX)
        else:
            self._put_live(now, lo, hi, torque, present, vel_units, running, speed_frac, plan)
        if hi > 136 and lo < 144:
            tp, tv = self.motor.trajectory(now)
            _put(mem, lo, hi, 136, 4, round(d * tv / VELOCITY_UNIT_RAD_S))
            _put(mem, lo, hi, 140, 4, self._position_register(tp))
        if hi > 144:
            _put(mem, lo, hi, 144, 2, round((self.supply_voltage - 0.3 * speed_frac) * 10.0))
            self._update_thermal(now)
            _put(mem, lo, hi, 146, 1, round(self._temperature))

    def _live_values(self, now: float, torque: int, present: int, vel_units: int,
                     running: bool, speed_frac: float, plan: Plan) -> tuple[int, ...]:
        """The live items of addresses 120..135 as the servo computes them: Realtime Tick,
        Moving, Moving Status, Present PWM, Present Current, Present Velocity, Present
        Position (hardware reference §5), before they are fitted to their sizes."""
        mem = self._mem
        sign = 1 if vel_units >= 0 else -1
        moving = abs(vel_units) > int.from_bytes(mem[24:28], "little") or running
        goal = int.from_bytes(mem[116:120], "little", signed=True)
        in_position = (not running) and (abs(present - goal) <= 1 if mem[11] in (3, 4, 5)
                                         else True)
        return (int(math.floor((now - self._boot_time) * 1000.0)) % TICK_MODULUS,
                int(moving),
                int(in_position) | (int(running) << 1) | (_PROFILE_KIND.get(plan.kind, 0) << 4),
                round(sign * 885 * min(speed_frac + 0.05, 1.0)) if torque else 0,
                round(sign * (50 + 150 * speed_frac)) if torque else 0,
                vel_units, present)

    def _put_live(self, now: float, lo: int, hi: int, *args) -> None:
        """Store the live items of 120..135 that overlap ``lo..hi`` (a partial read)."""
        values = self._live_values(now, *args)
        for (address, size), v in zip(_LIVE_ITEMS, values, strict=True):
            _put(self._mem, lo, hi, address, size, v)

    def reg_write(self, address: int, data: bytes) -> int:
        """REG_WRITE: validate and hold the write until ACTION (§4.4)."""
        err = self.write(address, data, apply=False)
        if err:
            return err
        self._registered = (address, bytes(data))
        self._mem[69] = 1
        return 0

    def action(self) -> int:
        """ACTION: apply the held REG_WRITE (Instruction Error if none)."""
        if self._registered is None:
            return ERR_INSTRUCTION
        address, data = self._registered
        self._registered = None
        self._mem[69] = 0
        return self.write(address, data)

    def reboot(self) -> None:
        """REBOOT: torque off, hardware error cleared, RAM to defaults, position re-based; the
        servo then hears nothing for :attr:`reboot_time_s`."""
        with self.lock:
            now = self.clock.monotonic()
            self.advance_to(now)
            self._torque_off(now)
            self._load_defaults(eeprom=False)
            self._registered = None
            self._watchdog_deadline = None
            self._boot_time = now
            self._booting_until = now + self.reboot_time_s
            self._rebase()
            self._goal_to_present()

    def factory_reset(self, option: int, *, dry_run: bool = False) -> int:
        """FACTORY_RESET: 0xFF all, 0x01 all but ID, 0x02 all but ID and baud rate (§4.4).

        The control table returns to the model's factory values (e-Manual, Protocol 2.0,
        Factory Reset): ID 1 and Baud Rate 57600 bps unless kept, whatever this servo was
        configured with. ``dry_run`` only returns the error it would give.
        """
        if option not in (0xFF, 0x01, 0x02):
            return ERR_DATA_RANGE
        if self._mem[64]:
            return ERR_ACCESS
        if dry_run:
            return 0
        keep = () if option == 0xFF else (("ID",) if option == 0x01 else ("ID", "Baud Rate"))
        self._load_defaults(eeprom=True, keep=keep, factory=True)
        if option == 0xFF:
            self._set("ID", 1)
        return 0

    def clear_multi_turn(self, params: bytes) -> int:
        """CLEAR (0x10) with ``01 44 58 4C 22``: re-base the multi-turn count while stopped."""
        if params != bytes([0x01, 0x44, 0x58, 0x4C, 0x22]):
            return ERR_DATA_LENGTH if len(params) != 5 else ERR_DATA_RANGE
        now = self.clock.monotonic()
        _, rate = self.motor.motion(np.array([now]))
        if abs(rate[0]) > 1e-6 or self.motor.plan.running(now):
            return ERR_RESULT_FAIL
        self._rebase()
        return 0

    # ---- convenience for tests and tools -------------------------------------------------
    def register(self, name: str) -> int:
        """The current (signed) value of a control-table item, read as a host would."""
        item = self.table[name]
        err, data = self.read(item.address, item.size)
        if err:
            raise ValueError(f"{name} cannot be read: error {err}")
        return item.from_bytes(data)

    def set_register(self, name: str, value: int) -> None:
        """Set an item directly (bypassing access rules): to prepare a scenario in tests."""
        with self.lock:
            self._set(name, value)

    def torque_enabled(self) -> bool:
        """True if Torque Enable (64) is 1."""
        return bool(self._mem[64])

    @property
    def temperature_c(self) -> float:
        """The modelled temperature in °C."""
        return self._temperature
