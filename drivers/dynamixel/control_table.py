"""Dynamixel X-series control tables as data (hardware reference §5).

One :class:`ControlItem` record per control-table item: name, address, size, access, EEPROM or
RAM, signedness, and the SI value of one raw count. Per-model facts (model number, defaults that
differ, gear ratio, no-load speed, operating modes) live in :class:`ServoModel` records in
:data:`MODELS`. The gimbal driver and the servo emulator both read these tables; nothing else in
gyrocal spells a control-table address.

Addresses and sizes match the tables that dynamixel-sdk ships (``dynamixel_easy_sdk/control_table``,
checked by the tests where that package is installed); access, defaults and units follow the
hardware reference §5.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass, field

__all__ = [
    "COMPATIBLE_MODELS",
    "HARDWARE_ERROR_BITS",
    "MODELS",
    "OPERATING_MODES",
    "ControlItem",
    "ControlTable",
    "HardwareErrorBit",
    "ServoModel",
    "model_by_name",
    "model_by_number",
]

# --- SI value of one raw count (hardware reference §5) -------------------------------------------
#: Goal/Present Velocity, Velocity Limit, Profile Velocity (velocity-based), Moving Threshold:
#: 0.229 rpm per unit, in rad/s.
VELOCITY_UNIT_RAD_S = 0.229 * 2.0 * math.pi / 60.0
#: Goal/Present Position: pulses (encoder ticks) per output revolution.
TICKS_PER_TURN = 4096
#: Goal/Present Position: one pulse, in rad.
POSITION_UNIT_RAD = 2.0 * math.pi / TICKS_PER_TURN
#: Profile Acceleration (velocity-based profile): 214.577 rev/min² per unit, in rad/s².
ACCELERATION_UNIT_RAD_S2 = 214.577 * 2.0 * math.pi / 3600.0
#: Present Input Voltage, voltage limits: 0.1 V per unit.
VOLTAGE_UNIT_V = 0.1
#: Present Temperature, Temperature Limit: 1 °C per unit.
TEMPERATURE_UNIT_C = 1.0
#: Present/Goal Current, Current Limit (XM only): 2.69 mA per unit, in A.
CURRENT_UNIT_A = 2.69e-3
#: Present Load (XL): 0.1 % of the maximum torque per unit, as a fraction.
LOAD_UNIT = 1e-3
#: Present/Goal PWM, PWM Limit: 0.113 % per unit, as a fraction.
PWM_UNIT = 1.13e-3
#: Realtime Tick: 1 ms per unit, in s.
TICK_UNIT_S = 1e-3
#: Realtime Tick counts 0..32767 and starts again at 0 (hardware reference §5, ⚠ one publisher).
TICK_MODULUS = 32768
#: Bus Watchdog: 20 ms per unit, in s (hardware reference §5 and §6.3).
WATCHDOG_UNIT_S = 20e-3
#: Return Delay Time: 2 µs per unit, in s.
RETURN_DELAY_UNIT_S = 2e-6

#: Operating Mode (11) values (hardware reference §5.1).
OPERATING_MODES: dict[str, int] = {
    "current": 0,
    "velocity": 1,
    "position": 3,
    "extended_position": 4,
    "current_based_position": 5,
    "pwm": 16,
}

#: Baud Rate (8) register values (hardware reference §5, address 8).
BAUD_RATES: dict[int, int] = {
    0: 9600,
    1: 57600,
    2: 115200,
    3: 1_000_000,
    4: 2_000_000,
    5: 3_000_000,
    6: 4_000_000,
    7: 4_500_000,
}


@dataclass(frozen=True)
class ControlItem:
    """One control-table item.

    Parameters
    ----------
    name : str
        The item's name as in the e-manual (``"Present Position"``).
    address : int
        First byte of the item.
    size : int
        1, 2 or 4 bytes, little-endian (hardware reference §4.1).
    access : str
        ``"R"`` (read-only) or ``"RW"``.
    eeprom : bool
        True for EEPROM items, which refuse writes while torque is on (Access Error 7).
    signed : bool
        True if the raw value is two's complement. dynamixel-sdk returns every value unsigned
        (hardware reference §6.5); :meth:`decode` applies the sign.
    unit : float or None
        The SI value of one raw count (rad, rad/s, rad/s², V, °C, A, s or a fraction), or None
        for items without a physical unit.
    minimum, maximum : int or None
        The raw range a write must respect (Data Range Error 4 otherwise); None = the size's range.
    """

    name: str
    address: int
    size: int
    access: str = "RW"
    eeprom: bool = False
    signed: bool = False
    unit: float | None = None
    minimum: int | None = None
    maximum: int | None = None

    @property
    def end(self) -> int:
        """One past the item's last byte."""
        return self.address + self.size

    @property
    def writable(self) -> bool:
        """True if the item may be written."""
        return self.access == "RW"

    def raw_range(self) -> tuple[int, int]:
        """The raw values a write may carry (signed items: two's-complement range)."""
        bits = 8 * self.size
        if self.signed:
            lo, hi = -(1 << (bits - 1)), (1 << (bits - 1)) - 1
        else:
            lo, hi = 0, (1 << bits) - 1
        if self.minimum is not None:
            lo = self.minimum
        if self.maximum is not None:
            hi = self.maximum
        return lo, hi

    def decode(self, unsigned: int) -> int:
        """The raw value with its sign applied, from the unsigned integer the SDK returns.

        Parameters
        ----------
        unsigned : int
            A value in ``0 .. 2**(8*size) - 1`` (what ``readTxRx``/``getData`` give).

        Returns
        -------
        int
            The signed value for signed items (two's complement), else ``unsigned`` unchanged.
        """
        bits = 8 * self.size
        value = int(unsigned) & ((1 << bits) - 1)
        if self.signed and value >= 1 << (bits - 1):
            value -= 1 << bits
        return value

    def encode(self, raw: int) -> int:
        """The unsigned integer carrying ``raw`` on the wire (two's complement if negative)."""
        return int(raw) & ((1 << (8 * self.size)) - 1)

    def from_bytes(self, data: bytes | bytearray | list[int]) -> int:
        """Decode ``size`` little-endian bytes into the signed (if signed) raw value."""
        if len(data) != self.size:
            raise ValueError(f"{self.name} needs {self.size} bytes, got {len(data)}")
        return self.decode(int.from_bytes(bytes(data), "little"))

    def to_bytes(self, raw: int) -> bytes:
        """Encode a raw value as ``size`` little-endian bytes."""
        return self.encode(raw).to_bytes(self.size, "little")

    def to_si(self, raw: int) -> float:
        """The SI value of a (signed) raw value; items without a unit return the raw value."""
        return float(raw) * (self.unit if self.unit is not None else 1.0)

    def from_si(self, value: float) -> int:
        """The nearest raw value to an SI value, checked against the item's range.

        Raises
        ------
        ValueError
            If the value is not finite or is outside the item's raw range.
        """
        if not math.isfinite(value):
            raise ValueError(f"{self.name}: value must be finite, got {value!r}")
        raw = round(value / (self.unit if self.unit is not None else 1.0))
        lo, hi = self.raw_range()
        if not lo <= raw <= hi:
            raise ValueError(
                f"{self.name}: {value!r} is raw {raw}, outside {lo}..{hi}"
            )
        return raw


def _x430_items(*, has_current: bool) -> tuple[ControlItem, ...]:
    """The X-430 control table shared by XM430-W350 and XL430-W250 (hardware reference §5)."""
    v, p = VELOCITY_UNIT_RAD_S, POSITION_UNIT_RAD
    items = [
        ControlItem("Model Number", 0, 2, "R", eeprom=True),
        ControlItem("Model Information", 2, 4, "R", eeprom=True),
        ControlItem("Firmware Version", 6, 1, "R", eeprom=True),
        ControlItem("ID", 7, 1, eeprom=True, maximum=252),
        ControlItem("Baud Rate", 8, 1, eeprom=True, maximum=7),
        ControlItem("Return Delay Time", 9, 1, eeprom=True, maximum=254, unit=RETURN_DELAY_UNIT_S),
        ControlItem("Drive Mode", 10, 1, eeprom=True, maximum=13),
        ControlItem("Operating Mode", 11, 1, eeprom=True, maximum=16),
        ControlItem("Secondary(Shadow) ID", 12, 1, eeprom=True),
        ControlItem("Protocol Type", 13, 1, eeprom=True, minimum=1, maximum=2),
        ControlItem("Homing Offset", 20, 4, eeprom=True, signed=True, unit=p,
                    minimum=-1_044_479, maximum=1_044_479),
        ControlItem("Moving Threshold", 24, 4, eeprom=True, unit=v, maximum=1023),
        ControlItem("Temperature Limit", 31, 1, eeprom=True, unit=TEMPERATURE_UNIT_C, maximum=100),
        ControlItem("Max Voltage Limit", 32, 2, eeprom=True, unit=VOLTAGE_UNIT_V, maximum=160),
        ControlItem("Min Voltage Limit", 34, 2, eeprom=True, unit=VOLTAGE_UNIT_V, maximum=160),
        ControlItem("PWM Limit", 36, 2, eeprom=True, unit=PWM_UNIT, maximum=885),
    ]
    if has_current:
        items.append(ControlItem("Current Limit", 38, 2, eeprom=True, unit=CURRENT_UNIT_A,
                                 maximum=1193))
    items += [
        ControlItem("Velocity Limit", 44, 4, eeprom=True, unit=v, maximum=1023),
        ControlItem("Max Position Limit", 48, 4, eeprom=True, unit=p, maximum=4095),
        ControlItem("Min Position Limit", 52, 4, eeprom=True, unit=p, maximum=4095),
        ControlItem("Shutdown", 63, 1, eeprom=True),
        ControlItem("Torque Enable", 64, 1, maximum=1),
        ControlItem("LED", 65, 1, maximum=1),
        ControlItem("Status Return Level", 68, 1, maximum=2),
        ControlItem("Registered Instruction", 69, 1, "R"),
        ControlItem("Hardware Error Status", 70, 1, "R"),
        ControlItem("Velocity I Gain", 76, 2, maximum=16383),
        ControlItem("Velocity P Gain", 78, 2, maximum=16383),
        ControlItem("Position D Gain", 80, 2, maximum=16383),
        ControlItem("Position I Gain", 82, 2, maximum=16383),
        ControlItem("Position P Gain", 84, 2, maximum=16383),
        ControlItem("Feedforward 2nd Gain", 88, 2, maximum=16383),
        ControlItem("Feedforward 1st Gain", 90, 2, maximum=16383),
        # Bus Watchdog: writes 1..127 in 20 ms units, 0 off; signed because it reads -1 after
        # it has tripped (§5), which a host cannot write.
        ControlItem("Bus Watchdog", 98, 1, signed=True, unit=WATCHDOG_UNIT_S, minimum=0,
                    maximum=127),
        ControlItem("Goal PWM", 100, 2, signed=True, unit=PWM_UNIT, minimum=-885, maximum=885),
    ]
    if has_current:
        items.append(ControlItem("Goal Current", 102, 2, signed=True, unit=CURRENT_UNIT_A,
                                 minimum=-1193, maximum=1193))
    items += [
        ControlItem("Goal Velocity", 104, 4, signed=True, unit=v, minimum=-1023, maximum=1023),
        ControlItem("Profile Acceleration", 108, 4, unit=ACCELERATION_UNIT_RAD_S2, maximum=32767),
        ControlItem("Profile Velocity", 112, 4, unit=v, maximum=32767),
        ControlItem("Goal Position", 116, 4, signed=True, unit=p, minimum=-1_048_575,
                    maximum=1_048_575),
        ControlItem("Realtime Tick", 120, 2, "R", unit=TICK_UNIT_S),
        ControlItem("Moving", 122, 1, "R"),
        ControlItem("Moving Status", 123, 1, "R"),
        ControlItem("Present PWM", 124, 2, "R", signed=True, unit=PWM_UNIT),
        (ControlItem("Present Current", 126, 2, "R", signed=True, unit=CURRENT_UNIT_A)
         if has_current else ControlItem("Present Load", 126, 2, "R", signed=True, unit=LOAD_UNIT)),
        ControlItem("Present Velocity", 128, 4, "R", signed=True, unit=v),
        ControlItem("Present Position", 132, 4, "R", signed=True, unit=p),
        ControlItem("Velocity Trajectory", 136, 4, "R", signed=True, unit=v),
        ControlItem("Position Trajectory", 140, 4, "R", signed=True, unit=p),
        ControlItem("Present Input Voltage", 144, 2, "R", unit=VOLTAGE_UNIT_V),
        ControlItem("Present Temperature", 146, 1, "R", unit=TEMPERATURE_UNIT_C),
        ControlItem("Backup Ready", 147, 1, "R"),
    ]
    # Indirect Address 1..28 (168..223), Indirect Data 1..28 (224..251),
    # Indirect Address 29..56 (578..633), Indirect Data 29..56 (634..661).
    for k in range(28):
        items.append(ControlItem(f"Indirect Address {k + 1}", 168 + 2 * k, 2, maximum=661))
    for k in range(28):
        items.append(ControlItem(f"Indirect Data {k + 1}", 224 + k, 1))
    for k in range(28):
        items.append(ControlItem(f"Indirect Address {k + 29}", 578 + 2 * k, 2, maximum=661))
    for k in range(28):
        items.append(ControlItem(f"Indirect Data {k + 29}", 634 + k, 1))
    return tuple(items)


class ControlTable:
    """A model's control table: items by name and by address.

    Parameters
    ----------
    items : iterable of ControlItem
        The items; they must not overlap.
    """

    def __init__(self, items: Iterable[ControlItem]) -> None:
        self.items: tuple[ControlItem, ...] = tuple(sorted(items, key=lambda i: i.address))
        self._by_name = {i.name: i for i in self.items}
        self._owner: dict[int, ControlItem] = {}
        for item in self.items:
            for a in range(item.address, item.end):
                if a in self._owner:
                    raise ValueError(f"{item.name} overlaps {self._owner[a].name} at {a}")
                self._owner[a] = item
        #: One past the last byte of the table; reads beyond it are an Access Error (§4.5).
        self.size = max(i.end for i in self.items)

    def __getitem__(self, name: str) -> ControlItem:
        try:
            return self._by_name[name]
        except KeyError:
            raise KeyError(
                f"no control-table item {name!r}; known items: {', '.join(self._by_name)}"
            ) from None

    def __contains__(self, name: object) -> bool:
        return name in self._by_name

    def owner(self, address: int) -> ControlItem | None:
        """The item a byte address belongs to, or None for a gap between items."""
        return self._owner.get(address)


@dataclass(frozen=True)
class HardwareErrorBit:
    """One bit of Hardware Error Status (70) and what the user should do about it."""

    bit: int
    name: str
    advice: str


#: Hardware Error Status (70) bits (hardware reference §5, ⚠ one publisher: ROBOTIS e-manual).
#: Bits 1, 6 and 7 are unused.
HARDWARE_ERROR_BITS: tuple[HardwareErrorBit, ...] = (
    HardwareErrorBit(0, "input voltage",
                     "the supply voltage is outside the servo's Min/Max Voltage Limit: check the "
                     "power supply (XM430 wants 12 V, XL430 11.1 V) and its cable, then reboot "
                     "the servo"),
    HardwareErrorBit(2, "overheating",
                     "the servo is hotter than its Temperature Limit: switch it off, let it cool "
                     "for several minutes, lower the speed or the duty cycle, then reboot it"),
    HardwareErrorBit(3, "motor encoder",
                     "the servo's encoder is not working: check that the horn turns freely, power "
                     "the servo off and on; if it persists the servo needs service"),
    HardwareErrorBit(4, "electrical shock",
                     "the servo detected an electrical shock or insufficient power: check the "
                     "supply and the wiring, then reboot the servo"),
    HardwareErrorBit(5, "overload",
                     "the servo cannot deliver the torque the motion needs: check that the gimbal "
                     "turns freely, nothing blocks it and the cables do not pull, reduce the load "
                     "or the acceleration, then reboot the servo"),
)


@dataclass(frozen=True)
class ServoModel:
    """Per-model facts of a supported servo (hardware reference §5).

    Parameters
    ----------
    name : str
        The ROBOTIS model name.
    number : int
        The Model Number (address 0) a PING returns.
    table : ControlTable
        The control table.
    defaults : dict
        Factory values by item name (items not listed default to 0).
    operating_modes : tuple of int
        The Operating Mode values the model accepts.
    gear_ratio : float
        The gearbox ratio (motor turns per output turn).
    no_load_speed_rad_s_12v : float
        The no-load output speed at 12 V, in rad/s.
    wobble_deg : float
        The largest tilt of the link a servo turns, once per revolution (its horn's and
        bracket's runout), degrees: ⚠ assumed (:data:`ASSUMED_WOBBLE_DEG`), no datasheet gives
        it. A full-matrix calibration's σ include what it does to the matrix
        (:mod:`gyrocal.calib.systematics`); the emulated jig nods by it.
    """

    name: str
    number: int
    table: ControlTable
    defaults: dict[str, int] = field(default_factory=dict)
    operating_modes: tuple[int, ...] = (1, 3, 4, 16)
    gear_ratio: float = 1.0
    no_load_speed_rad_s_12v: float = 4.8
    wobble_deg: float = 0.0


#: The link tilt per revolution assumed for every servo model, degrees ⚠ (no datasheet gives a
#: horn's runout; a tenth of a millimetre over a 100 mm link is 0.06°).
ASSUMED_WOBBLE_DEG = 0.05


def _rpm(rpm: float) -> float:
    return rpm * 2.0 * math.pi / 60.0


_COMMON_DEFAULTS = {
    "Model Information": 0,
    "ID": 1,
    "Baud Rate": 1,  # 57600 bps
    "Return Delay Time": 250,  # 500 µs
    "Drive Mode": 0,
    "Operating Mode": 3,
    "Secondary(Shadow) ID": 255,
    "Protocol Type": 2,
    "Homing Offset": 0,
    "Moving Threshold": 10,
    "PWM Limit": 885,
    "Max Position Limit": 4095,
    "Min Position Limit": 0,
    "Shutdown": 52,  # overload + electrical shock + overheating (§5, ⚠ one publisher)
    "Status Return Level": 2,
    "Velocity P Gain": 100,
    "Goal PWM": 885,
}

XM430_W350 = ServoModel(
    name="XM430-W350",
    number=1020,
    table=ControlTable(_x430_items(has_current=True)),
    defaults={
        **_COMMON_DEFAULTS,
        "Model Number": 1020,
        "Firmware Version": 46,
        "Temperature Limit": 80,
        "Max Voltage Limit": 160,
        "Min Voltage Limit": 95,
        "Current Limit": 1193,
        # Firmware-dependent (§5): 200 since firmware 42 (350 before). Read it from the device.
        "Velocity Limit": 200,
        "Velocity I Gain": 1920,
        "Position P Gain": 800,
        "Goal Current": 1193,
    },
    operating_modes=(0, 1, 3, 4, 5, 16),
    gear_ratio=353.5,
    no_load_speed_rad_s_12v=_rpm(46.0),
    wobble_deg=ASSUMED_WOBBLE_DEG,
)

XL430_W250 = ServoModel(
    name="XL430-W250",
    number=1060,
    table=ControlTable(_x430_items(has_current=False)),
    defaults={
        **_COMMON_DEFAULTS,
        "Model Number": 1060,
        "Firmware Version": 46,
        "Temperature Limit": 72,
        "Max Voltage Limit": 140,
        "Min Voltage Limit": 60,
        # Firmware-dependent (§5): 265 since firmware 42 (415 before). Read it from the device.
        "Velocity Limit": 265,
        "Velocity I Gain": 1000,
        "Position D Gain": 4000,
        "Position P Gain": 640,
    },
    operating_modes=(1, 3, 4, 16),
    gear_ratio=258.5,
    no_load_speed_rad_s_12v=_rpm(61.0),
    wobble_deg=ASSUMED_WOBBLE_DEG,
)

#: Fully supported models, by model number.
MODELS: dict[int, ServoModel] = {m.number: m for m in (XM430_W350, XL430_W250)}

#: Other X-series models whose control table has every item the gimbal driver uses at the same
#: address and size (checked against dynamixel-sdk's shipped tables by the tests). The driver
#: accepts them with a notice and uses the table of the model named here.
COMPATIBLE_MODELS: dict[int, tuple[str, str]] = {
    1000: ("XH430-W350", "XM430-W350"),
    1001: ("XD430-T350", "XM430-W350"),
    1010: ("XH430-W210", "XM430-W350"),
    1011: ("XD430-T210", "XM430-W350"),
    1030: ("XM430-W210", "XM430-W350"),
    1040: ("XH430-V350", "XM430-W350"),
    1050: ("XH430-V210", "XM430-W350"),
    1070: ("XC430-W150", "XL430-W250"),
    1080: ("XC430-W240", "XL430-W250"),
    1120: ("XM540-W270", "XM430-W350"),
    1130: ("XM540-W150", "XM430-W350"),
}


def model_by_number(number: int) -> ServoModel | None:
    """The supported model with this Model Number, or None."""
    return MODELS.get(int(number))


def model_by_name(name: str) -> ServoModel:
    """The supported model called ``name`` (case-insensitive, ``-``/``_`` ignored).

    Raises
    ------
    ValueError
        If no supported model has that name (the message lists them).
    """
    key = name.upper().replace("_", "").replace("-", "")
    for m in MODELS.values():
        if m.name.replace("-", "") == key:
            return m
    names = ", ".join(m.name for m in MODELS.values())
    raise ValueError(f"unknown servo model {name!r}; supported models: {names}")
