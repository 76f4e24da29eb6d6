"""Register-level magnetometer dies: the AK8963 inside the MPU-9250 and the LSM9DS1's magnetometer.

gyrocal does not calibrate magnetometers; these dies exist so that third-party clients see the
chips as they are (a WHO_AM_I, the modes, the status flags, field data that rotates with the
sensor). The true field is a fixed vector in the jig's base frame, turned into the sensor frame by
the motion source's ``orientation(t)`` (sensor → base) when it has one (the emulated gimbal does),
and then into the die's own axes.

Facts used, by source (⚠: one source only):

AK8963 (AKM AK8963 datasheet MS1356-E, §8.3 register map; the MPU-9250 Product Specification
§9.1 axes; the kernel's ``inv_mpu_aux``/``ak8975`` drivers and mpu9250-jmdev agree on the map):

- I²C address 0x0C; WIA (0x00) = 0x48; ST1 (0x02) DRDY bit 0, DOR bit 1; HXL..HZH (0x03–0x08)
  little-endian two's complement; ST2 (0x09) HOFL bit 3, BITM bit 4; CNTL1 (0x0A) MODE[3:0]
  (0 power-down, 1 single, 2 continuous 8 Hz, 6 continuous 100 Hz, 0xF fuse ROM) and BIT (bit 4:
  0 = 14-bit 0.6 µT/LSB, 1 = 16-bit 0.15 µT/LSB); CNTL2 (0x0B) SRST bit 0; ASAX..ASAZ (0x10–0x12)
  readable in fuse-ROM mode, applied as ``H · ((ASA − 128)/256 + 1)``.
- DRDY and DOR return to 0 "when any one of ST2 register or measurement data register (HXL~HZH)
  is read" (§8.3.3, quoted in several open AK8963 drivers); DOR is set when a measurement lands
  while DRDY is still set; HOFL when |X| + |Y| + |Z| exceeds 4912 µT.
- Axes against the accel/gyro die: x_mag = y, y_mag = x, z_mag = −z.
- A single measurement is ready 7.2 ms after it is requested ⚠ (datasheet tSM, max).

AK09916 (the ICM-20948's magnetometer die behind its I²C master; AKM AK09916 datasheet register
map and §9.4.3 as quoted by open drivers: Pimoroni icm20948, SparkFun qwiic_icm20948, Adafruit
adafruit_icm20x, ArduPilot AP_Compass_AK09916.cpp, PX4 ICM20948_AK09916.cpp; the register layout
and burst rules are those of its sibling AK09911, datasheet MS1526-E-01 §7.3, §8.1–8.3 ⚠):

- I²C address 0x0C; WIA1 (0x00) = 0x48 (AKM), WIA2 (0x01) = 0x09; ST1 (0x10) DRDY bit 0, DOR bit
  1; HXL..HZH (0x11–0x16) little-endian two's complement, 0.15 µT/LSB, ±32752 (4912 µT); TMPS
  (0x17) a dummy; ST2 (0x18) HOFL bit 3; CNTL2 (0x31) MODE[4:0] (0 power-down, 1 single, 2/4/6/8
  continuous 10/20/50/100 Hz, 0x10 self-test, not modelled); CNTL3 (0x32) SRST bit 0 (clears
  itself). No fuse ROM: the AK09916 has no ASA registers.
- DRDY and DOR return to 0 "when any one of ST2 register or measurement data register (HXL to
  TMPS) is read".
- A burst runs 0x00→0x03→0x10→…→0x18 and back to 0x00; 0x30→0x32 and back to 0x30 (AK09911 §7.3
  ⚠).
- Axes against the accel/gyro die: x_mag = y, y_mag = x, z_mag = −z, as the AK8963 in the
  MPU-9250 ⚠ (PX4 publishes the ICM-20948's accelerometer as (x, −y, −z) and its AK09916 as
  (y_mag, −x_mag, z_mag) in the same frame: ICM20948.cpp and ICM20948_AK09916.cpp).

LSM9DS1 magnetometer (ST LSM9DS1 datasheet DocID025715, Tables 20 and 108–117; melopero-lsm9ds1
and lsm9ds1-rjg agree):

- I²C address 0x1E (SDO_M high) or 0x1C; WHO_AM_I_M (0x0F) = 0x3D; CTRL_REG1_M (0x20, reset
  0x10) OM bits 6:5, DO bits 4:2 (0.625…80 Hz), FAST_ODR bit 1 (1000/560/300/155 Hz by OM);
  CTRL_REG2_M (0x21) FS bits 6:5 (±4/8/12/16 gauss at 0.14/0.29/0.43/0.58 mgauss/LSB), REBOOT
  bit 3, SOFT_RST bit 2; CTRL_REG3_M (0x22, reset 0x03) MD bits 1:0 (00 continuous, 01 single,
  1x power-down); STATUS_REG_M (0x27) ZYXDA bit 3, ZYXOR bit 7; OUT_X_L_M..OUT_Z_H_M
  (0x28–0x2D) little-endian; INT_CFG_M (0x30) reset 0x08.
- Multi-byte reads auto-increment whether or not SUB(7) is set (the kernel's ``st_magn`` driver
  reads the LIS3MDL-type die without the multi-read bit ⚠; both clients above do too).
- Axes against the accel/gyro die: x_mag = −y, y_mag = −x, z_mag = z ⚠ (SparkFun's LSM9DS1
  examples feed ``(-my, -mx, mz)`` to their AHRS).
"""

from __future__ import annotations

import errno
import math
from collections.abc import Callable

import numpy as np

from gyrocal.drivers.clock import Clock

__all__ = [
    "AK09916_REG",
    "DEFAULT_FIELD_UT",
    "EmulatedAK09916",
    "EmulatedAK8963",
    "EmulatedLSM9DS1Mag",
    "MagneticField",
]

#: A mid-latitude geomagnetic field in the jig's base frame, µT (horizontal 20 µT, vertical 44 µT
#: into the ground with the base z axis up): an illustrative Earth field, not a datasheet figure.
DEFAULT_FIELD_UT = (20.0, 0.0, -44.0)


class MagneticField:
    """The true field in the sensor (accel/gyro die) frame.

    Parameters
    ----------
    motion : object, optional
        Anything with ``orientation(t) -> (N, 3, 3)`` rotation matrices sensor → base (the
        emulated gimbal); without it the sensor frame is the base frame.
    field_ut : array_like, shape (3,)
        The field in the base frame, µT.
    """

    def __init__(self, motion: object | None = None,
                 field_ut: tuple[float, float, float] | np.ndarray = DEFAULT_FIELD_UT) -> None:
        b = np.asarray(field_ut, dtype=float)
        if b.shape != (3,) or not np.all(np.isfinite(b)):
            raise ValueError(f"field_ut must be 3 finite numbers in µT, got {field_ut!r}")
        self.field_ut = b
        self._orientation: Callable[[np.ndarray], np.ndarray] | None = getattr(
            motion, "orientation", None
        )

    def at(self, t: float) -> np.ndarray:
        """The field in the sensor frame at time ``t``, µT, shape (3,)."""
        if self._orientation is None:
            return self.field_ut.copy()
        r = np.asarray(self._orientation(np.array([float(t)])), dtype=float)[0]
        return r.T @ self.field_ut


class _MagDie:
    """Register pointer, measurement grid and data-ready bookkeeping shared by both dies."""

    who_am_i_register: int
    who_am_i: int
    reset_values: dict[int, int]

    def __init__(self, clock: Clock, field: MagneticField | None = None, *,
                 noise_ut: float = 0.0, seed: int = 0) -> None:
        if not noise_ut >= 0:
            raise ValueError(f"noise_ut must be >= 0, got {noise_ut!r}")
        self.clock = clock
        self.field = field if field is not None else MagneticField()
        self.noise_ut = float(noise_ut)
        self._rng = np.random.default_rng([seed, 7])
        self._reset()

    def _reset(self) -> None:
        self._regs = bytearray(128)
        for reg, value in self.reset_values.items():
            self._regs[reg] = value
        self._ptr = 0
        self._data = bytes(6)
        self._period: float | None = None
        self._origin = self.clock.monotonic()
        self._k = 0
        self._single_at: float | None = None
        self.ready = False
        self.overrun = False
        self._overflow = False

    # -- I2CDevice ----------------------------------------------------------------------------

    def i2c_ack(self) -> int | None:
        """Always acknowledge."""
        return None

    def i2c_write(self, data: bytes) -> None:
        """Set the register pointer and write the following bytes, auto-incrementing."""
        self._sync()
        self._ptr = data[0] & 0x7F
        for value in data[1:]:
            self._write(self._ptr, value)
            self._ptr = self._next_pointer(self._ptr)

    def i2c_read(self, length: int) -> bytes:
        """Read ``length`` bytes from the register pointer, auto-incrementing."""
        self._sync()
        out = bytearray()
        for _ in range(length):
            out.append(self._read(self._ptr) & 0xFF)
            self._ptr = self._next_pointer(self._ptr)
        return bytes(out)

    def _next_pointer(self, register: int) -> int:
        """The register a burst reaches after ``register``."""
        return (register + 1) & 0x7F

    # -- measurements -------------------------------------------------------------------------

    def _start(self, period: float | None) -> None:
        """A new continuous rate (``None``: stopped) from now."""
        self._period = period
        self._origin = self.clock.monotonic()
        self._k = 0

    def _sync(self) -> None:
        now = self.clock.monotonic()
        if self._single_at is not None and now >= self._single_at:
            t, self._single_at = self._single_at, None
            self._measured(t)
            self._single_done()
        if self._period is None:
            return
        k = math.floor((now - self._origin) / self._period)
        if k > self._k:
            if k > self._k + 1:  # earlier measurements landed unread: only the latest is kept
                self.ready = True
            self._k = k
            self._measured(self._origin + k * self._period)

    def _measured(self, t: float) -> None:
        b = self._die_axes(self.field.at(t))
        if self.noise_ut:
            b = b + self._rng.standard_normal(3) * self.noise_ut
        if self.ready:
            self.overrun = True
        self.ready = True
        self._data = self._encode(b)

    def _single_done(self) -> None:
        """A single measurement finished (the mode falls back to power-down)."""

    def _die_axes(self, b_sensor: np.ndarray) -> np.ndarray:
        raise NotImplementedError

    def _encode(self, b_die_ut: np.ndarray) -> bytes:
        raise NotImplementedError

    def _write(self, register: int, value: int) -> None:
        raise NotImplementedError

    def _read(self, register: int) -> int:
        raise NotImplementedError


_AK = {"WIA": 0x00, "INFO": 0x01, "ST1": 0x02, "HXL": 0x03, "ST2": 0x09, "CNTL1": 0x0A,
       "CNTL2": 0x0B, "ASTC": 0x0C, "I2CDIS": 0x0F, "ASAX": 0x10}
_AK_PERIOD = {0x2: 1 / 8, 0x6: 1 / 100}
_AK_SINGLE_S = 7.2e-3
_AK_RANGE_UT = 4912.0


class EmulatedAK8963(_MagDie):
    """The AK8963 3-axis magnetometer die of the MPU-9250 (see the module's list of facts).

    Parameters
    ----------
    clock : Clock
        The shared clock.
    field : MagneticField, optional
        The true field (a constant base-frame field when omitted).
    asa : tuple of 3 ints
        The fuse ROM's sensitivity adjustment values ASAX..ASAZ (each chip has its own).
    noise_ut : float
        White measurement noise, µT RMS per axis (0: quantization only).
    seed : int
        Seed of the noise generator.
    """

    who_am_i_register = _AK["WIA"]
    who_am_i = 0x48
    reset_values: dict[int, int] = {}

    def __init__(self, clock: Clock, field: MagneticField | None = None, *,
                 asa: tuple[int, int, int] = (176, 178, 166), noise_ut: float = 0.0,
                 seed: int = 0) -> None:
        if len(asa) != 3 or not all(isinstance(a, int) and 0 <= a <= 255 for a in asa):
            raise ValueError(f"asa must be three integers 0..255, got {asa!r}")
        self.asa = tuple(asa)
        super().__init__(clock, field, noise_ut=noise_ut, seed=seed)

    @property
    def mode(self) -> int:
        """CNTL1.MODE."""
        return self._regs[_AK["CNTL1"]] & 0x0F

    def adjustment(self) -> np.ndarray:
        """The sensitivity adjustment ``(ASA − 128)/256 + 1`` per axis (datasheet §8.3.11)."""
        return (np.array(self.asa, dtype=float) - 128) / 256 + 1

    def _die_axes(self, b_sensor: np.ndarray) -> np.ndarray:
        return np.array([b_sensor[1], b_sensor[0], -b_sensor[2]])

    def _encode(self, b_die_ut: np.ndarray) -> bytes:
        sixteen = bool(self._regs[_AK["CNTL1"]] & 0x10)
        lsb_ut, limit = (0.15, 32760) if sixteen else (0.6, 8190)
        self._overflow = float(np.abs(b_die_ut).sum()) > _AK_RANGE_UT
        counts = np.clip(np.rint(b_die_ut / (lsb_ut * self.adjustment())), -limit, limit)
        return counts.astype("<i2").tobytes()

    def _single_done(self) -> None:
        self._regs[_AK["CNTL1"]] &= 0xF0

    def _write(self, register: int, value: int) -> None:
        if register == _AK["CNTL2"]:
            if value & 0x01:
                self._reset()
            return
        if register == _AK["CNTL1"]:
            self._regs[register] = value & 0x1F
            mode = value & 0x0F
            self._start(_AK_PERIOD.get(mode))
            self._single_at = self.clock.monotonic() + _AK_SINGLE_S if mode == 0x1 else None
            return
        if register in (_AK["ASTC"], _AK["I2CDIS"]):
            self._regs[register] = value

    def _read(self, register: int) -> int:
        if register == _AK["WIA"]:
            return self.who_am_i
        if register == _AK["INFO"]:
            return 0x9A  # a device-information byte; its meaning is not documented
        if register == _AK["ST1"]:
            return int(self.ready) | int(self.overrun) << 1
        if _AK["HXL"] <= register < _AK["HXL"] + 6:
            self.ready = self.overrun = False  # any data register read clears them (§8.3.3)
            return self._data[register - _AK["HXL"]]
        if register == _AK["ST2"]:
            value = (0x08 if self._overflow else 0) | (
                self._regs[_AK["CNTL1"]] & 0x10)
            self.ready = self.overrun = False
            return value
        if _AK["ASAX"] <= register < _AK["ASAX"] + 3:
            # ⚠ readable in fuse-ROM access mode only (datasheet §8.3.11); 0 otherwise
            return self.asa[register - _AK["ASAX"]] if self.mode == 0x0F else 0
        return self._regs[register]


#: AK09916 registers (see the module's list of facts for the sources).
AK09916_REG = {"WIA1": 0x00, "WIA2": 0x01, "ST1": 0x10, "HXL": 0x11, "TMPS": 0x17, "ST2": 0x18,
               "CNTL1": 0x30, "CNTL2": 0x31, "CNTL3": 0x32}
#: CNTL2.MODE → continuous measurement period, s (10, 20, 50, 100 Hz).
_AK09916_PERIOD = {0x02: 1 / 10, 0x04: 1 / 20, 0x06: 1 / 50, 0x08: 1 / 100}
_K = AK09916_REG


class EmulatedAK09916(_MagDie):
    """The AK09916 3-axis magnetometer die of the ICM-20948 (see the module's list of facts).

    Parameters
    ----------
    clock : Clock
        The shared clock.
    field : MagneticField, optional
        The true field (a constant base-frame field when omitted).
    noise_ut : float
        White measurement noise, µT RMS per axis (0: quantization only).
    seed : int
        Seed of the noise generator.
    """

    who_am_i_register = _K["WIA2"]
    who_am_i = 0x09
    reset_values: dict[int, int] = {_K["WIA1"]: 0x48, _K["WIA2"]: 0x09}

    @property
    def mode(self) -> int:
        """CNTL2.MODE."""
        return self._regs[_K["CNTL2"]] & 0x1F

    def _next_pointer(self, register: int) -> int:
        if register == 0x03:
            return _K["ST1"]
        if register == _K["ST2"]:
            return _K["WIA1"]
        if register == _K["CNTL3"]:
            return _K["CNTL1"]
        return (register + 1) & 0x7F

    def _die_axes(self, b_sensor: np.ndarray) -> np.ndarray:
        return np.array([b_sensor[1], b_sensor[0], -b_sensor[2]])

    def _encode(self, b_die_ut: np.ndarray) -> bytes:
        self._overflow = float(np.abs(b_die_ut).sum()) >= _AK_RANGE_UT
        counts = np.clip(np.rint(b_die_ut / 0.15), -32752, 32752)
        return counts.astype("<i2").tobytes()

    def _single_done(self) -> None:
        self._regs[_K["CNTL2"]] = 0

    def _write(self, register: int, value: int) -> None:
        if register == _K["CNTL3"]:
            if value & 0x01:
                self._reset()
            return
        if register == _K["CNTL2"]:
            mode = value & 0x1F
            self._regs[register] = mode
            self._start(_AK09916_PERIOD.get(mode))
            self._single_at = self.clock.monotonic() + _AK_SINGLE_S if mode == 0x01 else None

    def _read(self, register: int) -> int:
        if register == _K["ST1"]:
            return int(self.ready) | int(self.overrun) << 1
        if _K["HXL"] <= register <= _K["ST2"]:
            self.ready = self.overrun = False  # HXL..TMPS or ST2 read ends the data
            if register == _K["ST2"]:
                return 0x08 if self._overflow else 0
            if register == _K["TMPS"]:
                return 0
            return self._data[register - _K["HXL"]]
        return self._regs[register]


_LM = {"WHO_AM_I_M": 0x0F, "CTRL_REG1_M": 0x20, "CTRL_REG2_M": 0x21, "CTRL_REG3_M": 0x22,
       "STATUS_REG_M": 0x27, "OUT_X_L_M": 0x28, "INT_SRC_M": 0x31}
_LM_DO_HZ = (0.625, 1.25, 2.5, 5.0, 10.0, 20.0, 40.0, 80.0)
_LM_FAST_ODR_HZ = (1000.0, 560.0, 300.0, 155.0)  # by OM: low, medium, high, ultra-high
_LM_MGAUSS_PER_LSB = (0.14, 0.29, 0.43, 0.58)
_LM_READ_ONLY = frozenset({0x0F, 0x27, *range(0x28, 0x2E), 0x31})


class EmulatedLSM9DS1Mag(_MagDie):
    """The LSM9DS1's magnetometer die (see the module's list of facts).

    Parameters
    ----------
    clock : Clock
        The shared clock.
    field : MagneticField, optional
        The true field.
    noise_ut : float
        White measurement noise, µT RMS per axis.
    seed : int
        Seed of the noise generator.
    """

    who_am_i_register = _LM["WHO_AM_I_M"]
    who_am_i = 0x3D
    reset_values = {0x20: 0x10, 0x22: 0x03, 0x30: 0x08}

    def _rate_hz(self) -> float | None:
        r1, r3 = self._regs[_LM["CTRL_REG1_M"]], self._regs[_LM["CTRL_REG3_M"]]
        if r3 & 0x03 != 0:
            return None
        if r1 & 0x02:
            return _LM_FAST_ODR_HZ[(r1 >> 5) & 0x03]
        return _LM_DO_HZ[(r1 >> 2) & 0x07]

    def _die_axes(self, b_sensor: np.ndarray) -> np.ndarray:
        return np.array([-b_sensor[1], -b_sensor[0], b_sensor[2]])

    def _encode(self, b_die_ut: np.ndarray) -> bytes:
        fs = (self._regs[_LM["CTRL_REG2_M"]] >> 5) & 0x03
        counts = np.clip(np.rint(b_die_ut * 10.0 / _LM_MGAUSS_PER_LSB[fs]), -32768, 32767)
        return counts.astype("<i2").tobytes()

    def _single_done(self) -> None:
        self._regs[_LM["CTRL_REG3_M"]] |= 0x03

    def _write(self, register: int, value: int) -> None:
        if register in _LM_READ_ONLY:
            return
        if register == _LM["CTRL_REG2_M"] and value & 0x04:  # SOFT_RST
            self._reset()
            return
        if register == _LM["CTRL_REG2_M"]:
            value &= ~0x0C  # REBOOT and SOFT_RST clear themselves
        before = self._rate_hz()
        self._regs[register] = value
        if register == _LM["CTRL_REG3_M"] and value & 0x03 == 0x01:  # single conversion
            hz = _LM_DO_HZ[(self._regs[_LM["CTRL_REG1_M"]] >> 2) & 0x07]
            self._single_at = self.clock.monotonic() + 1.0 / hz
        rate = self._rate_hz()
        if rate != before:
            self._start(None if rate is None else 1.0 / rate)

    def _read(self, register: int) -> int:
        if register == _LM["WHO_AM_I_M"]:
            return self.who_am_i
        if register == _LM["STATUS_REG_M"]:
            return (0x0F if self.ready else 0) | (0xF0 if self.overrun else 0)
        if _LM["OUT_X_L_M"] <= register < _LM["OUT_X_L_M"] + 6:
            if register == _LM["OUT_X_L_M"] + 5:  # the last output byte ends the read
                self.ready = self.overrun = False
            return self._data[register - _LM["OUT_X_L_M"]]
        return self._regs[register]


class AuxPort:
    """Where a die behind a host chip's auxiliary I²C bus appears on the main bus: present only
    while ``visible()`` says so (the MPU-9250's BYPASS_EN with its I²C master off), else absent
    (``EREMOTEIO``), as the pass-through switch disconnects it.

    Parameters
    ----------
    die : I2CDevice
        The die on the auxiliary bus.
    visible : callable
        ``visible() -> bool``.
    """

    def __init__(self, die: _MagDie, visible: Callable[[], bool]) -> None:
        self.die = die
        self._visible = visible

    def i2c_ack(self) -> int | None:
        """Acknowledge only through the bypass switch."""
        return self.die.i2c_ack() if self._visible() else errno.EREMOTEIO

    def i2c_write(self, data: bytes) -> None:
        """Pass the message to the die."""
        self.die.i2c_write(data)

    def i2c_read(self, length: int) -> bytes:
        """Pass the message to the die."""
        return self.die.i2c_read(length)
