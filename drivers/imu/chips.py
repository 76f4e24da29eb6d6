"""Per-chip facts as data: register addresses, identity values, ranges, rates, filters, timings.

Every number here is transcribed from ``shared/hardware-reference.md`` (section given on each
table). The readers (:mod:`gyrocal.drivers.imu.mpu9250`, :mod:`gyrocal.drivers.imu.lsm9ds1`) and
the emulated chips
(:mod:`gyrocal.drivers.emulated.imu_chips`) read them from here; the tests check them against the
datasheet
values written out independently.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import KW_ONLY, asdict, dataclass, field
from types import MappingProxyType
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    import numpy as np

__all__ = [
    "ICM20948",
    "ICM20948_BITS",
    "ICM20948_DLPF",
    "ICM20948_REG",
    "ICM20948_REG1",
    "ICM20948_REG2",
    "ICM20948_REG3",
    "ICM42688P",
    "ICM42688P_BANK_RESET",
    "ICM42688P_BITS",
    "ICM42688P_MAX_READER_ODR_HZ",
    "ICM42688P_ODR",
    "ICM42688P_REG",
    "ICM42688P_ST_DATA",
    "ICM42688P_UI_FILT_DIVISOR",
    "LSM6DSOX",
    "LSM6DSOX_ACCEL_LPF2_DIVISOR",
    "LSM6DSOX_BITS",
    "LSM6DSOX_GYRO_FILTER",
    "LSM6DSOX_GYRO_PHASE_HZ",
    "LSM6DSOX_MAX_READER_ODR_HZ",
    "LSM6DSOX_ODR",
    "LSM6DSOX_REG",
    "LSM9DS1",
    "LSM9DS1_ACCEL_AA_AUTO_HZ",
    "LSM9DS1_ACCEL_AA_FILTER",
    "LSM9DS1_ACCEL_HR_DIVISOR",
    "LSM9DS1_BITS",
    "LSM9DS1_BW_G_CUTOFF_HZ",
    "LSM9DS1_LPF1_CUTOFF_HZ",
    "LSM9DS1_ODR",
    "LSM9DS1_REG",
    "MPU9250",
    "MPU9250_BITS",
    "MPU9250_DLPF",
    "MPU9250_DLPF_DELAY_S",
    "MPU9250_REG",
    "MPU9250_SELF_TEST_BASE_COUNTS",
    "GYRO_OFFSET_COUNTS_PER_CODE_FS0",
    "mpu9250_self_test_otp",
    "ChipFamily",
    "ChipModel",
    "FilterSetting",
    "ICM20948_ACCEL_FILTER",
    "ICM20948_GYRO_FILTER",
    "MPU9250_ACCEL_FILTER",
    "ICM42688P_UI_FILT_ORDER",
    "MPU9250_GYRO_FILTER",
    "AccelErrors",
    "AccelRange",
    "GyroErrors",
    "GyroRange",
    "RAD_PER_DEG",
    "STANDARD_GRAVITY_M_S2",
    "icm42688p_bandwidth_hz",
    "lsm6dsox_gyro_filter",
    "register_names",
]

#: Radians per degree.
RAD_PER_DEG = math.pi / 180.0
#: Standard gravity g_n (3rd CGPM, 1901), m/s²: the "g" of the accelerometer datasheets'
#: sensitivities (LSB/g), so counts / (LSB/g) × g_n is the reading in m/s².
STANDARD_GRAVITY_M_S2 = 9.80665


@dataclass(frozen=True)
class AccelRange:
    """The accelerometer full scale a reader configures (one per chip family).

    Parameters
    ----------
    code : int
        The register field value (MPU-9250 ``ACCEL_FS_SEL``, ST ``FS_XL``, ICM-42688-P
        ``ACCEL_FS_SEL``).
    full_scale_g : float
        The nominal range, ± g.
    lsb_per_g : float
        The datasheet sensitivity in counts per g.
    """

    code: int
    full_scale_g: float
    lsb_per_g: float

    @property
    def sensitivity_m_s2_per_lsb(self) -> float:
        """m/s² per count: the datasheet sensitivity times :data:`STANDARD_GRAVITY_M_S2`."""
        return STANDARD_GRAVITY_M_S2 / self.lsb_per_g


@dataclass(frozen=True)
class AccelErrors:
    """The accelerometer's error sizes a chip's datasheet gives (the emulator draws each term
    uniformly within ± the figure: :func:`gyrocal.drivers.emulated.accel.draw_accel_truth`).

    Parameters
    ----------
    scale_tolerance : float
        Sensitivity (scale factor) initial tolerance, fraction (±).
    cross_axis : float
        Cross-axis sensitivity, fraction (±).
    zero_g_g : tuple of 3 float
        Zero-g offset initial tolerance per axis, g (±).
    noise_g_sqrt_hz : float
        White-noise density at the range the reader sets, g/√Hz (the largest axis's).
    source : str
        The datasheet, its revision and table; what is not in it is named as a stand-in (⚠).
    """

    scale_tolerance: float
    cross_axis: float
    zero_g_g: tuple[float, float, float]
    noise_g_sqrt_hz: float
    source: str

    def __post_init__(self) -> None:
        figs = (self.scale_tolerance, self.cross_axis, self.noise_g_sqrt_hz, *self.zero_g_g)
        if len(self.zero_g_g) != 3 or not all(math.isfinite(x) and x >= 0 for x in figs):
            raise ValueError(f"accelerometer error figures must be finite and >= 0: {self!r}")


#: Bias instability ``B`` (°/h) and rate random walk ``K`` (rad/s/√s) taken for a gyro whose
#: datasheet gives neither (none of the chips here publishes them) ⚠: typical of consumer MEMS
#: gyros (an Allan floor of 0.664·B near 10-100 s, the random walk crossing it near 1000 s), the
#: figures the emulated sensor of ``--sim`` has (:attr:`GyroErrors.bias_instability_deg_h`).
#: Measure a sensor's own with ``gyrocal noise`` on a long still recording.
ASSUMED_BIAS_INSTABILITY_DEG_H = 10.0
ASSUMED_RATE_RANDOM_WALK = 2e-6
ASSUMED_DRIFT_SOURCE = ("assumed typical of consumer MEMS gyros, not in the datasheet "
                        "(drivers/imu/chips.py) ⚠")


@dataclass(frozen=True)
class GyroErrors:
    """The gyro's calibration error sizes a chip's datasheet gives: the emulated sensor of
    ``--sim`` draws its scale, zero-rate offset and cross-axis terms within them
    (:func:`gyrocal.kit.sim.sim_truth`, ``--sim-sensor datasheet``).

    Parameters
    ----------
    scale_tolerance : float
        Sensitivity (scale factor) initial tolerance at 25 °C, fraction (±).
    cross_axis : float
        Cross-axis sensitivity, fraction (±).
    zero_rate_dps : float
        Initial zero-rate output (bias) tolerance, °/s (±).
    source : str
        The datasheet, its revision and table; what is not in it is named as a stand-in (⚠).
    bias_instability_deg_h : float
        Bias instability ``B`` (IEEE Std 952 flicker coefficient), °/h; the calibration's bias
        σ includes its wander over the run (:mod:`gyrocal.calib.drift`).
    rate_random_walk_rad_s_sqrt_s : float
        Rate random walk ``K``, rad/s/√s.
    drift_source : str
        Where ``B`` and ``K`` come from.
    noise_density_dps_sqrt_hz : float
        Rate noise spectral density (white noise, angle random walk), °/s/√Hz: the emulated
        chip's white noise enters ahead of its digital filter at this density, so its Allan
        deviation is ``N / √τ`` (the IEEE Std 952 / Kalibr continuous-time convention, per-sample
        ``σ = N · √rate`` at the filter's input).
    g_sensitivity_dps_per_g : float
        Linear-acceleration (g-) sensitivity, °/s/g: each term of the emulated sensor's 3×3
        matrix is drawn within ± this (:func:`gyrocal.kit.sim.sim_realism`).
    noise_source : str
        Where the noise density and g-sensitivity come from; a stand-in is named as one (⚠).
    """

    scale_tolerance: float
    cross_axis: float
    zero_rate_dps: float
    source: str
    bias_instability_deg_h: float = ASSUMED_BIAS_INSTABILITY_DEG_H
    rate_random_walk_rad_s_sqrt_s: float = ASSUMED_RATE_RANDOM_WALK
    drift_source: str = ASSUMED_DRIFT_SOURCE
    _: KW_ONLY
    noise_density_dps_sqrt_hz: float
    g_sensitivity_dps_per_g: float
    noise_source: str

    def __post_init__(self) -> None:
        figs = (self.scale_tolerance, self.cross_axis, self.zero_rate_dps,
                self.bias_instability_deg_h, self.rate_random_walk_rad_s_sqrt_s,
                self.noise_density_dps_sqrt_hz, self.g_sensitivity_dps_per_g)
        if not all(math.isfinite(x) and x >= 0 for x in figs):
            raise ValueError(f"gyro error figures must be finite and >= 0: {self!r}")

    @property
    def zero_rate_rad_s(self) -> float:
        """The zero-rate offset tolerance in rad/s."""
        return self.zero_rate_dps * RAD_PER_DEG

    @property
    def bias_instability_rad_s(self) -> float:
        """The bias instability ``B`` in rad/s."""
        return self.bias_instability_deg_h * RAD_PER_DEG / 3600.0

    @property
    def noise_density_rad_s_sqrt_hz(self) -> float:
        """The rate noise density in rad/s/√Hz."""
        return self.noise_density_dps_sqrt_hz * RAD_PER_DEG


@dataclass(frozen=True)
class GyroRange:
    """One gyro full-scale setting.

    Parameters
    ----------
    code : int
        The register field value (MPU-9250 ``GYRO_FS_SEL``, LSM9DS1 ``FS_G``).
    full_scale_dps : float
        The nominal range, ± degrees per second.
    lsb_per_dps : float
        The datasheet sensitivity in counts per °/s.
    """

    code: int
    full_scale_dps: float
    lsb_per_dps: float

    @property
    def sensitivity_rad_s_per_lsb(self) -> float:
        """rad/s per count: the factor that turns raw counts into rad/s."""
        return RAD_PER_DEG / self.lsb_per_dps


@dataclass(frozen=True)
class FilterSetting:
    """One setting of a chip's digital low-pass filter: a row of its datasheet's filter table.

    Parameters
    ----------
    code : int
        The register field value that selects it (MPU-9250 ``DLPF_CFG``, ICM-20948
        ``GYRO_DLPFCFG``).
    bandwidth_hz : float
        The −3 dB bandwidth.
    delay_s : float or None
        The datasheet's delay; ``None`` where the datasheet gives none (the emulator then has
        only its filter's own group delay).
    noise_bandwidth_hz : float or None
        The datasheet's noise bandwidth (white noise of one-sided density ``N`` comes out of the
        filter with ``σ = N √NBW``, of two-sided ``N``: ``σ = N √(2 NBW)``); ``None`` where
        the datasheet gives none.
    source : str
        Where the row comes from; ⚠ marks a single source.
    """

    code: int
    bandwidth_hz: float
    delay_s: float | None
    noise_bandwidth_hz: float | None
    source: str


@dataclass(frozen=True)
class ChipModel:
    """A chip accepted by a reader, identified by its WHO_AM_I value.

    Parameters
    ----------
    name : str
        The model name used in configs and the Recording v1 manifest (``"mpu9250"``).
    who_am_i : int
        The value of the family's WHO_AM_I register.
    title : str
        The human name (``"MPU-9250"``).
    notice : str or None
        Said to the user when this chip is found (for chips accepted with a caveat).
    """

    name: str
    who_am_i: int
    title: str
    notice: str | None = None


@dataclass(frozen=True)
class ChipFamily:
    """The facts one reader needs about the chips it drives.

    Parameters
    ----------
    name : str
        Family name (``"mpu9250"``, ``"lsm9ds1"``).
    title : str
        Human name.
    addresses : tuple of int
        Possible 7-bit I²C addresses; the first is the default.
    who_am_i_register : int
        Where the identity byte is.
    models : tuple of ChipModel
        The chips the reader accepts.
    siblings : mapping int -> str
        WHO_AM_I values of related chips the reader does not drive, with what to say about them.
    gyro_ranges : tuple of GyroRange
        The offered full-scale settings.
    fifo_capacity : int
        FIFO size in the unit of ``fifo_capacity_unit``.
    fifo_capacity_unit : str
        ``"bytes"``, ``"samples"`` or ``"words"`` (the LSM6DSOX's 7-byte tagged words).
    reset_time_s : float
        Wait after a software reset.
    startup_time_s : float
        Wait after turning the gyro on before its samples are trusted.
    temperature_offset_c : float
        Temperature at zero counts.
    temperature_lsb_per_c : float
        Counts per °C.
    accel_range : AccelRange
        The accelerometer range the reader sets: ±4 g on every chip, the finest that keeps a
        2 g margin over gravity for the jig's lever-arm accelerations and knocks.
    accel_errors : AccelErrors
        The accelerometer's datasheet error sizes (scale, cross-axis, zero-g, noise density).
    gyro_errors : GyroErrors
        The gyro's datasheet error sizes (scale tolerance, cross-axis, zero-rate offset).
    extra : mapping
        Further chip facts by name.
    """

    name: str
    title: str
    addresses: tuple[int, ...]
    who_am_i_register: int
    models: tuple[ChipModel, ...]
    siblings: Mapping[int, str]
    gyro_ranges: tuple[GyroRange, ...]
    fifo_capacity: int
    fifo_capacity_unit: str
    reset_time_s: float
    startup_time_s: float
    temperature_offset_c: float
    temperature_lsb_per_c: float
    accel_range: AccelRange
    accel_errors: AccelErrors
    gyro_errors: GyroErrors
    extra: Mapping[str, float] = field(default_factory=lambda: MappingProxyType({}))

    def model_for(self, who_am_i: int) -> ChipModel | None:
        """The accepted model with this WHO_AM_I value, or ``None``."""
        for m in self.models:
            if m.who_am_i == who_am_i:
                return m
        return None

    def range_for(self, range_dps: float) -> GyroRange | None:
        """The offered range whose nominal full scale is ``range_dps`` (±0.5 dps), or ``None``."""
        for r in self.gyro_ranges:
            if abs(r.full_scale_dps - range_dps) <= 0.5:
                return r
        return None

    def counts_to_celsius(self, counts: float | np.ndarray) -> float | np.ndarray:
        """Temperature in °C of raw temperature readings (a number or an array)."""
        return self.temperature_offset_c + counts / self.temperature_lsb_per_c


# ---------------------------------------------------------------------------------------------
# InvenSense/TDK MPU-9250 family (hardware reference §1)


@dataclass(frozen=True)
class _MPU9250Registers:
    """MPU-9250 register addresses (hardware reference §1.2) and bits."""

    # RM-MPU-9250A-00 registers 0-2 and 13-15: factory self-test codes (OTP), read-only
    SELF_TEST_X_GYRO: int = 0x00
    SELF_TEST_X_ACCEL: int = 0x0D
    # RM-MPU-9250A-00 registers 19-24: X/Y/Z_OFFS_USR, int16 big-endian H/L pairs (reset 0)
    XG_OFFSET_H: int = 0x13
    SMPLRT_DIV: int = 0x19
    CONFIG: int = 0x1A
    GYRO_CONFIG: int = 0x1B
    ACCEL_CONFIG: int = 0x1C
    ACCEL_CONFIG_2: int = 0x1D
    FIFO_EN: int = 0x23
    I2C_MST_CTRL: int = 0x24
    I2C_SLV0_ADDR: int = 0x25  # SLVn_ADDR/REG/CTRL at 0x25 + 3n for n = 0..3
    I2C_SLV4_ADDR: int = 0x31
    I2C_SLV4_REG: int = 0x32
    I2C_SLV4_DO: int = 0x33
    I2C_SLV4_CTRL: int = 0x34
    I2C_SLV4_DI: int = 0x35
    I2C_MST_STATUS: int = 0x36
    INT_PIN_CFG: int = 0x37
    INT_ENABLE: int = 0x38
    INT_STATUS: int = 0x3A
    ACCEL_XOUT_H: int = 0x3B
    TEMP_OUT_H: int = 0x41
    GYRO_XOUT_H: int = 0x43
    EXT_SENS_DATA_00: int = 0x49  # 24 bytes, to 0x60
    I2C_SLV0_DO: int = 0x63  # SLVn_DO at 0x63 + n for n = 0..3
    SIGNAL_PATH_RESET: int = 0x68
    USER_CTRL: int = 0x6A
    PWR_MGMT_1: int = 0x6B
    PWR_MGMT_2: int = 0x6C
    FIFO_COUNTH: int = 0x72
    FIFO_COUNTL: int = 0x73
    FIFO_R_W: int = 0x74
    WHO_AM_I: int = 0x75


@dataclass(frozen=True)
class _MPU9250Bits:
    """MPU-9250 register bits and fields (hardware reference §1.2, §1.7)."""

    CONFIG_FIFO_MODE: int = 0x40  # 1: stop writing when full; 0: overwrite the oldest (§1.7)
    CONFIG_DLPF_MASK: int = 0x07
    GYRO_FS_SHIFT: int = 3
    GYRO_FS_MASK: int = 0x18
    GYRO_FCHOICE_B_MASK: int = 0x03
    # RM-MPU-9250A-00 registers 27/28: XGYRO_Cten..ZGYRO_Cten and ax/ay/az_st_en, bits 7:5
    # (x, y, z): the axis's self-test actuation on
    SELF_TEST_EN_MASK: int = 0xE0
    SELF_TEST_EN_SHIFT: int = 5
    ACCEL_FS_SHIFT: int = 3
    # ACCEL_CONFIG_2: A_DLPFCFG bits 2:0; ACCEL_FCHOICE_B bit 3 (1: the DLPF bypassed, 4 kHz)
    # (hardware reference §1.2: the bit's position conflicts between sources, bit 3 believed ⚠)
    A_DLPFCFG_MASK: int = 0x07
    ACCEL_FCHOICE_B: int = 0x08
    FIFO_EN_TEMP: int = 0x80
    FIFO_EN_GYRO_X: int = 0x40
    FIFO_EN_GYRO_Y: int = 0x20
    FIFO_EN_GYRO_Z: int = 0x10
    FIFO_EN_ACCEL: int = 0x08
    INT_STATUS_FIFO_OFLOW: int = 0x10
    INT_STATUS_RAW_DATA_RDY: int = 0x01
    USER_CTRL_FIFO_EN: int = 0x40
    USER_CTRL_I2C_MST_EN: int = 0x20
    USER_CTRL_FIFO_RST: int = 0x04
    INT_PIN_CFG_BYPASS_EN: int = 0x02
    # RM-MPU-9250A-00 register 55: 1 = any read clears INT_STATUS, 0 = reading INT_STATUS does
    INT_PIN_CFG_INT_ANYRD_2CLEAR: int = 0x10
    I2C_SLV_READ: int = 0x80  # SLVn_ADDR bit 7: read (1) or write (0)
    I2C_SLV_EN: int = 0x80  # SLVn_CTRL bits: enable, byte swap, no register, group, length
    I2C_SLV_BYTE_SW: int = 0x40
    I2C_SLV_REG_DIS: int = 0x20
    I2C_SLV_LENG_MASK: int = 0x0F
    I2C_MST_STATUS_SLV4_DONE: int = 0x40
    PWR_MGMT_1_H_RESET: int = 0x80
    PWR_MGMT_1_SLEEP: int = 0x40
    PWR_MGMT_1_CLKSEL_AUTO: int = 0x01
    PWR_MGMT_2_GYRO_DISABLE: int = 0x07
    SIGNAL_PATH_RESET_ALL: int = 0x07


MPU9250_REG = _MPU9250Registers()
MPU9250_BITS = _MPU9250Bits()

#: Gyro DLPF settings usable with the FIFO over I²C: FCHOICE_B = 00, DLPF_CFG 1..6, internal
#: rate 1 kHz, so SAMPLE_RATE = 1000 / (1 + SMPLRT_DIV) (hardware reference §1.4), one row per
#: DLPF_CFG: the bandwidth and the delay of the register map's CONFIG table (RM-MPU-9250A-00
#: register 26), ✓✓ with the mpu9250 crate's ``Dlpf`` enum docs (docs.rs/mpu9250, "Gyroscope:
#: bandwidth=41Hz, delay=5.9ms") and libcaer's DAVIS_CONFIG_IMU_GYRO_DLPF. The register map
#: gives no noise bandwidth. DLPF_CFG 0 and 7 and FCHOICE_B != 00 sample at 8 or 32 kHz, more
#: than a 400 kHz I²C bus can carry out of the FIFO, and are not offered.
_MPU_CONFIG_TABLE = "RM-MPU-9250A-00 CONFIG table ✓✓ (mpu9250 crate Dlpf docs)"
MPU9250_GYRO_FILTER: tuple[FilterSetting, ...] = (
    FilterSetting(1, 184.0, 2.9e-3, None, _MPU_CONFIG_TABLE),
    FilterSetting(2, 92.0, 3.9e-3, None, _MPU_CONFIG_TABLE),
    FilterSetting(3, 41.0, 5.9e-3, None, _MPU_CONFIG_TABLE),
    FilterSetting(4, 20.0, 9.9e-3, None, _MPU_CONFIG_TABLE),
    FilterSetting(5, 10.0, 17.85e-3, None, _MPU_CONFIG_TABLE),
    FilterSetting(6, 5.0, 33.48e-3, None, _MPU_CONFIG_TABLE),
)
#: :data:`MPU9250_GYRO_FILTER` as the readers use it: the bandwidth in Hz to DLPF_CFG.
MPU9250_DLPF: Mapping[float, int] = MappingProxyType(
    {f.bandwidth_hz: f.code for f in MPU9250_GYRO_FILTER}
)
#: The gyro's delay for each DLPF bandwidth of :data:`MPU9250_DLPF`, s (from
#: :data:`MPU9250_GYRO_FILTER`).
MPU9250_DLPF_DELAY_S: Mapping[float, float] = MappingProxyType(
    {f.bandwidth_hz: f.delay_s for f in MPU9250_GYRO_FILTER}  # type: ignore[misc]
)

#: Accelerometer DLPF settings with ACCEL_FCHOICE_B = 0, one row per A_DLPFCFG (ACCEL_CONFIG_2
#: bits 2:0, reset 0): the bandwidth and delay of the register map's ACCEL_CONFIG_2 table
#: (RM-MPU-9250A-00 register 29), ✓✓ with the mpu9250 crate's ``Dlpf`` enum docs
#: (docs.rs/mpu9250: "Accelerometer: bandwidth=218.1Hz, delay=1.88ms" ...) and, for the
#: bandwidths, Zephyr's ICM-20689 (same accelerometer block) ``ICM20689_DT_ACCEL_DLPF_*``
#: (218.1, 99.0, 44.8, 21.2, 10.2, 5.1, 420.0 Hz). The accelerometer filters at 1 kHz ahead of
#: SMPLRT_DIV (as the gyro's DLPF).
_MPU_ACCEL_TABLE = "RM-MPU-9250A-00 ACCEL_CONFIG_2 table ✓✓ (mpu9250 crate Dlpf docs)"
MPU9250_ACCEL_FILTER: tuple[FilterSetting, ...] = (
    FilterSetting(0, 218.1, 1.88e-3, None, _MPU_ACCEL_TABLE),
    FilterSetting(1, 218.1, 1.88e-3, None, _MPU_ACCEL_TABLE),
    FilterSetting(2, 99.0, 2.88e-3, None, _MPU_ACCEL_TABLE),
    FilterSetting(3, 44.8, 4.88e-3, None, _MPU_ACCEL_TABLE),
    FilterSetting(4, 21.2, 8.87e-3, None, _MPU_ACCEL_TABLE),
    FilterSetting(5, 10.2, 16.83e-3, None, _MPU_ACCEL_TABLE),
    FilterSetting(6, 5.05, 32.48e-3, None, _MPU_ACCEL_TABLE),
    FilterSetting(7, 420.0, 1.38e-3, None, _MPU_ACCEL_TABLE),
)

#: RM-MPU-9250A-00 registers 19-24 (XG_OFFSET_H .. ZG_OFFSET_L): the offset the output gets,
#: ``OffsetLSB = X_OFFS_USR · 4 / 2^FS_SEL`` counts at GYRO_FS_SEL, "added to the gyroscope
#: sensor value before going into the sensor register" (one step is 0.0305 °/s at every range);
#: Kris Winer's MPU9250 calibrateMPU9250 writes −bias/4 (bias in counts at ±250 °/s) for that
#: reason ("Biases are additive, so change sign"). The ICM-20948's XG_OFFS_USR (DS-000189,
#: bank 2) is taken to be the same ⚠ (its description gives only "gyro offset cancellation";
#: TDK's eMD inv_icm20948_set_offset, Icm20948SelfTest.c, writes −(bias at ±250 °/s) >> 2,
#: "convert from 250dps to 1000dps", i.e. the same 4-count step at ±250 °/s: one vendor source).
GYRO_OFFSET_COUNTS_PER_CODE_FS0 = 4.0

#: MPU-9250 self-test (AN-MPU-9250A-03 "MPU-9250 Accelerometer, Gyroscope and Compass
#: Self-Test Implementation", and the register map's SELF_TEST registers): the factory
#: self-test response of an axis is ``ST_OTP = 2620 / 2^FS · 1.01^(ST_code − 1)`` counts at
#: the self-test range (FS = 0: ±250 °/s, ±2 g), the self-test code being the axis's
#: SELF_TEST_* byte (0: no OTP value). A part passes when its response now, (output with the
#: self-test on) − (output without), is more than 0.5 ST_OTP for the gyro and between 0.5 and
#: 1.5 ST_OTP for the accelerometer (AN-MPU-9250A-03 pass criteria). Checked in two open
#: implementations: TDK InvenSense's own eMD driver for the ICM-20948, whose register-level
#: self-test is the same (Icm20948SelfTest.c in eMD-SmartMotion-ICM20948-1.1.0, as vendored by
#: FredBill1/RT1064_Smartcar: "st_otp = 2620/2^FS * 1.01^(st_value - 1)", the table
#: sSelfTestEquation from 2620 at code 1, and the 0.5 / 1.5 ratio checks in
#: inv_check_accelgyro_self_test), and kriswiner/MPU9250 MPU9250BasicAHRS.ino 987-992
#: (MPU9250SelfTest, at FS = 0, where its ``2620/1<<FS`` is 2620).
MPU9250_SELF_TEST_BASE_COUNTS = 2620.0
MPU9250_SELF_TEST_CODE_RATIO = 1.01


def mpu9250_self_test_otp(code: int, fs: int = 0) -> float:
    """The factory self-test response, counts, that the SELF_TEST code ``code`` stands for at
    range ``fs`` (AN-MPU-9250A-03: ``2620 / 2^FS · 1.01^(code − 1)``; 0 for code 0).

    Parameters
    ----------
    code : int
        The SELF_TEST_* register byte (1..255; 0 means no factory value).
    fs : int
        The range the response is read at, as its doublings above ±250 °/s or ±2 g: the
        MPU-9250's GYRO_FS_SEL or ACCEL_FS_SEL; negative for a narrower range (the
        ICM-42688-P's ``3 − FS_SEL``: TDK eMD Icm426xxSelfTest.c, INV_ST_OTP_EQUATION).

    Returns
    -------
    float
        The response in counts.
    """
    if code == 0:
        return 0.0
    return (MPU9250_SELF_TEST_BASE_COUNTS / 2**fs
            * MPU9250_SELF_TEST_CODE_RATIO ** (code - 1))


MPU6500_NOTICE = (
    "WHO_AM_I 0x70: this is an MPU-6500, the MPU-9250's accel/gyro die without the AK8963 "
    "magnetometer. Many boards sold as 'MPU-9250' carry it. Its gyro and registers are the same, "
    "so gyrocal reads and calibrates it the same way; the sensor is recorded as 'mpu6500'."
)

MPU9250 = ChipFamily(
    name="mpu9250",
    title="MPU-9250",
    addresses=(0x68, 0x69),
    who_am_i_register=MPU9250_REG.WHO_AM_I,
    models=(
        ChipModel("mpu9250", 0x71, "MPU-9250"),
        ChipModel("mpu9255", 0x73, "MPU-9255"),
        ChipModel("mpu6500", 0x70, "MPU-6500", MPU6500_NOTICE),
    ),
    siblings=MappingProxyType(
        {
            0x68: "an MPU-6050 or MPU-9150 (WHO_AM_I 0x68), an older InvenSense part with a "
            "different register map; gyrocal does not drive it",
            0x74: "an MPU-6515 (WHO_AM_I 0x74); gyrocal does not drive it",
        }
    ),
    gyro_ranges=(
        GyroRange(0, 250.0, 131.0),
        GyroRange(1, 500.0, 65.5),
        GyroRange(2, 1000.0, 32.8),
        GyroRange(3, 2000.0, 16.4),
    ),
    fifo_capacity=512,
    fifo_capacity_unit="bytes",
    reset_time_s=0.100,  # §1.3 step 1 (and step 2 after SIGNAL_PATH_RESET)
    startup_time_s=0.070,  # §1.3 step 4: kernel's MPU-6500 gyro start-up (datasheet: 35 ms)
    temperature_offset_c=21.0,  # §1.6
    temperature_lsb_per_c=333.87,
    # PS-MPU-9250A-01 Table 2 (accelerometer): AFS_SEL = 1, ±4 g, 8192 LSB/g (register map
    # ACCEL_CONFIG[4:3])
    accel_range=AccelRange(1, 4.0, 8192.0),
    # PS-MPU-9250A-01 rev 1.0 §3.2 Table 2 ⚠ one source: Initial Tolerance (component-level)
    # ±3 %, Cross-Axis Sensitivity ±2 %, Zero-G Initial Calibration Tolerance X/Y ±60, Z ±80 mg,
    # Noise Power Spectral Density (low-noise mode) 300 µg/√Hz
    accel_errors=AccelErrors(0.03, 0.02, (0.060, 0.060, 0.080), 300e-6,
                             "MPU-9250 PS-MPU-9250A-01 rev 1.0 §3.2 Table 2 ⚠"),
    # PS-MPU-9250A-01 rev 1.0 §3.1 Table 1 (gyroscope): Sensitivity Scale Factor Tolerance
    # ±3 %, Cross-Axis Sensitivity ±2 %, Initial ZRO Tolerance ±5 °/s (25 °C) ⚠ one source (the
    # older MPU-6000/6050 sheet PS-MPU-6000A-00 gives ±20 °/s, which PX4's MPU-9250 self-test
    # comment quotes)
    # Table 1 also: Rate Noise Spectral Density 0.01 °/s/√Hz (Total RMS Noise 0.1 °/s at the
    # 92 Hz DLPF setting) and Linear Acceleration Sensitivity 0.1 °/s/g ✓✓ (the datasheet and
    # the MPU-6500 sheet PS-MPU-6500A-01 Table 1, the same die)
    gyro_errors=GyroErrors(0.03, 0.02, 5.0, "MPU-9250 PS-MPU-9250A-01 rev 1.0 §3.1 Table 1 ⚠",
                           noise_density_dps_sqrt_hz=0.01, g_sensitivity_dps_per_g=0.1,
                           noise_source="MPU-9250 PS-MPU-9250A-01 rev 1.0 §3.1 Table 1 (Rate "
                                        "Noise Spectral Density, Linear Acceleration "
                                        "Sensitivity)"),
    extra=MappingProxyType(
        {
            "internal_rate_hz": 1000.0,  # §1.4, DLPF_CFG 1..6
            # bytes the reader drains per sample: the FIFO frame of ACCEL (6), TEMP (2) and
            # GYRO (6) in register order (§1.7)
            "fifo_sample_bytes": 14.0,
            "wake_time_s": 0.010,  # §1.3 step 3
            "accel_lsb_per_g_2g": 16384.0,  # §1.5
        }
    ),
)


# ---------------------------------------------------------------------------------------------
# ST LSM9DS1 accelerometer + gyroscope die (hardware reference §2)


@dataclass(frozen=True)
class _LSM9DS1Registers:
    """LSM9DS1 accel/gyro register addresses (hardware reference §2.2) and bits."""

    WHO_AM_I: int = 0x0F
    CTRL_REG1_G: int = 0x10
    CTRL_REG2_G: int = 0x11
    CTRL_REG3_G: int = 0x12
    OUT_TEMP_L: int = 0x15
    STATUS_REG: int = 0x17
    OUT_X_L_G: int = 0x18
    OUT_Z_H_G: int = 0x1D
    CTRL_REG4: int = 0x1E
    CTRL_REG5_XL: int = 0x1F
    CTRL_REG6_XL: int = 0x20
    CTRL_REG7_XL: int = 0x21
    CTRL_REG8: int = 0x22
    CTRL_REG9: int = 0x23
    OUT_X_L_XL: int = 0x28
    OUT_Z_H_XL: int = 0x2D
    FIFO_CTRL: int = 0x2E
    FIFO_SRC: int = 0x2F


@dataclass(frozen=True)
class _LSM9DS1Bits:
    """LSM9DS1 register bits and fields (hardware reference §2.2, §2.7)."""

    SUBADDRESS_MASK: int = 0x7F
    ODR_G_SHIFT: int = 5
    FS_G_SHIFT: int = 3
    BW_G_MASK: int = 0x03
    # CTRL_REG2_G.OUT_SEL (ST Table 48/49, Figure 28): 00 the data registers and FIFO carry the
    # LPF1 output; 1x the LPF2 output, whose cutoff BW_G selects (Table 47)
    OUT_SEL_MASK: int = 0x03
    OUT_SEL_LPF2: int = 0x02
    FS_XL_SHIFT: int = 3
    # CTRL_REG6_XL [ODR_XL2:0][FS1:0_XL][BW_SCAL_ODR][BW_XL1:0] and CTRL_REG7_XL
    # [HR][DCF1:0][0][0][FDS][0][HPIS1] (DocID025715 Tables 67-70, as SparkFun's
    # SparkFunLSM9DS1.cpp initAccel comments transcribe them; ST lsm9ds1_reg.h bit fields)
    BW_SCAL_ODR: int = 0x04
    BW_XL_MASK: int = 0x03
    XL_HR: int = 0x80
    DCF_SHIFT: int = 5
    DCF_MASK: int = 0x60
    XL_FDS: int = 0x04
    CTRL_REG4_GYRO_AXES: int = 0x38
    CTRL_REG8_BOOT: int = 0x80
    CTRL_REG8_BDU: int = 0x40
    CTRL_REG8_IF_ADD_INC: int = 0x04
    CTRL_REG8_BLE: int = 0x02
    CTRL_REG8_SW_RESET: int = 0x01
    CTRL_REG9_FIFO_EN: int = 0x02
    CTRL_REG9_STOP_ON_FTH: int = 0x01
    FMODE_SHIFT: int = 5
    FMODE_BYPASS: int = 0b000
    FMODE_FIFO: int = 0b001  # stop collecting when full
    FMODE_CONT_TO_FIFO: int = 0b011
    FMODE_BYPASS_TO_CONT: int = 0b100
    FMODE_CONTINUOUS: int = 0b110  # overwrite the oldest
    FTH_MASK: int = 0x1F
    FIFO_SRC_FTH: int = 0x80
    FIFO_SRC_OVRN: int = 0x40
    FIFO_SRC_FSS_MASK: int = 0x3F
    STATUS_GDA: int = 0x02
    STATUS_XLDA: int = 0x01
    STATUS_TDA: int = 0x04


LSM9DS1_REG = _LSM9DS1Registers()
LSM9DS1_BITS = _LSM9DS1Bits()

#: CTRL_REG1_G.ODR_G code for each gyro output data rate in Hz (hardware reference §2.3).
LSM9DS1_ODR: Mapping[float, int] = MappingProxyType(
    {14.9: 1, 59.5: 2, 119.0: 3, 238.0: 4, 476.0: 5, 952.0: 6}
)

#: LPF1 cutoff in Hz for each gyro ODR (ST Table 46; hardware reference §2.3): the bandwidth of
#: the output with CTRL_REG2_G.OUT_SEL = 00.
LSM9DS1_LPF1_CUTOFF_HZ: Mapping[float, float] = MappingProxyType(
    {14.9: 5.0, 59.5: 19.0, 119.0: 38.0, 238.0: 76.0, 476.0: 100.0, 952.0: 100.0}
)

#: Gyro low-pass cutoff in Hz for each ODR and BW_G code (ST Table 47): the bandwidth of the
#: LPF2 output (CTRL_REG2_G.OUT_SEL = 1x), which the driver selects. The 238 Hz and 952 Hz
#: rows are in the hardware reference (§2.3, ⚠ ST only); the other rows follow ST Table 47 but
#: were not re-checked for the reference (⚠). At 14.9 Hz only LPF1 (5 Hz) acts.
LSM9DS1_BW_G_CUTOFF_HZ: Mapping[float, tuple[float, float, float, float]] = MappingProxyType(
    {
        14.9: (5.0, 5.0, 5.0, 5.0),
        59.5: (16.0, 16.0, 16.0, 16.0),
        119.0: (14.0, 31.0, 31.0, 31.0),
        238.0: (14.0, 29.0, 63.0, 78.0),
        476.0: (21.0, 28.0, 57.0, 100.0),
        952.0: (33.0, 40.0, 58.0, 100.0),
    }
)

#: The accelerometer's analog anti-aliasing filter, CTRL_REG6_XL.BW_XL with BW_SCAL_ODR = 1:
#: 00 408 Hz, 01 211 Hz, 10 105 Hz, 11 50 Hz (DocID025715 CTRL_REG6_XL description) ✓✓ ST's
#: lsm9ds1_reg.h ``lsm9ds1_xl_aa_bw_t`` (LSM9DS1_408Hz = 0x10 .. LSM9DS1_50Hz = 0x13, the 0x10
#: being BW_SCAL_ODR) and SparkFun's LSM9DS1_Settings.ino ("0 = 408 Hz 2 = 105 Hz, 1 = 211 Hz
#: 3 = 50 Hz"). No delay or noise bandwidth is given.
_LSM9DS1_AA = "DocID025715 CTRL_REG6_XL BW_XL ✓✓ (ST lsm9ds1_reg.h; SparkFun LSM9DS1_Settings)"
LSM9DS1_ACCEL_AA_FILTER: tuple[FilterSetting, ...] = (
    FilterSetting(0b00, 408.0, None, None, _LSM9DS1_AA),
    FilterSetting(0b01, 211.0, None, None, _LSM9DS1_AA),
    FilterSetting(0b10, 105.0, None, None, _LSM9DS1_AA),
    FilterSetting(0b11, 50.0, None, None, _LSM9DS1_AA),
)
#: The anti-aliasing bandwidth with BW_SCAL_ODR = 0 (the reset: "bandwidth determined by ODR
#: selection: BW = 408 Hz when ODR = 952 Hz, 50 Hz, 10 Hz; BW = 211 Hz when ODR = 476 Hz; BW =
#: 105 Hz when ODR = 238 Hz; BW = 50 Hz when ODR = 119 Hz", DocID025715, as SparkFun's
#: SparkFunLSM9DS1.cpp initAccel and other open drivers quote it), keyed by the gyro ODR that
#: sets the accelerometer's rate while the gyro is on (ODR code 1, 2, 6: 408 Hz; the
#: accelerometer-only 10 and 50 Hz are codes 1 and 2).
LSM9DS1_ACCEL_AA_AUTO_HZ: Mapping[float, float] = MappingProxyType(
    {14.9: 408.0, 59.5: 408.0, 119.0: 50.0, 238.0: 105.0, 476.0: 211.0, 952.0: 408.0}
)
#: The accelerometer's digital low-pass in high-resolution mode (CTRL_REG7_XL.HR = 1, FDS = 0):
#: DCF[1:0] → the divisor of the ODR that is its cutoff, 00 ODR/50, 01 ODR/100, 10 ODR/9, 11
#: ODR/400 (DocID025715 CTRL_REG7_XL) ✓✓ ST's lsm9ds1_reg.h ``lsm9ds1_xl_lp_bw_t``
#: (LSM9DS1_LP_ODR_DIV_50 = 0x10 .. _DIV_400 = 0x13, 0x10 being HR) and SparkFun's
#: LSM9DS1_Settings.ino ("0 = ODR/50 2 = ODR/9, 1 = ODR/100 3 = ODR/400").
LSM9DS1_ACCEL_HR_DIVISOR: Mapping[int, float] = MappingProxyType(
    {0b00: 50.0, 0b01: 100.0, 0b10: 9.0, 0b11: 400.0}
)

LSM9DS1 = ChipFamily(
    name="lsm9ds1",
    title="LSM9DS1 accelerometer/gyroscope",
    addresses=(0x6B, 0x6A),
    who_am_i_register=LSM9DS1_REG.WHO_AM_I,
    models=(ChipModel("lsm9ds1", 0x68, "LSM9DS1"),),
    siblings=MappingProxyType(
        {
            0x3D: "the LSM9DS1's magnetometer die (WHO_AM_I_M 0x3D, at 0x1C or 0x1E); the "
            "accelerometer/gyroscope die answers at 0x6A or 0x6B",
            0xD4: "an LSM9DS0 gyroscope or an L3GD20 (WHO_AM_I 0xD4), an older ST part with a "
            "different register map; gyrocal does not drive it",
            0x69: "an LSM6DS3 (WHO_AM_I 0x69); gyrocal does not drive it",
            0x6A: "an LSM6DSL or LSM6DS3C (WHO_AM_I 0x6A); gyrocal does not drive it",
        }
    ),
    gyro_ranges=(
        GyroRange(0b00, 245.0, 1000.0 / 8.75),  # §2.4: 8.75 mdps/LSB
        GyroRange(0b01, 500.0, 1000.0 / 17.50),
        GyroRange(0b11, 2000.0, 1000.0 / 70.0),
    ),
    fifo_capacity=32,
    fifo_capacity_unit="samples",
    reset_time_s=0.010,  # §2.6 (⚠ duration not in ST)
    startup_time_s=0.100,  # not in the hardware reference: a conservative wait (⚠)
    temperature_offset_c=25.0,  # §2.5: 16 LSB/°C, 0 at 25 °C
    temperature_lsb_per_c=16.0,
    # LSM9DS1 datasheet Table 3 (LA_So): CTRL_REG6_XL.FS_XL = 10, ±4 g, 0.122 mg/LSB
    accel_range=AccelRange(0b10, 4.0, 1000.0 / 0.122),
    # DocID025715 Rev 3 Table 3: LA_TyOff ±90 mg (typical zero-g offset after soldering) ✓✓ (the
    # datasheet and SparkFun's LSM9DS1 notes quoting it). Table 3 gives no sensitivity tolerance,
    # cross-axis sensitivity or accelerometer noise density: the MPU-9250's Table 2 figures
    # stand in for them ⚠
    accel_errors=AccelErrors(0.03, 0.02, (0.090, 0.090, 0.090), 300e-6,
                             "zero-g: LSM9DS1 DocID025715 Rev 3 Table 3; scale, cross-axis, "
                             "noise: stand-in (not in the datasheet) ⚠"),
    # DocID025715 Rev 3 Table 3: G_TyOff ±30 dps (zero-rate level) ✓✓ (the datasheet and
    # SparkFun's LSM9DS1 notes quoting it). Table 3 gives no gyro sensitivity tolerance or
    # cross-axis figure: the MPU-9250's Table 1 figures stand in ⚠
    # Table 3 gives no rate noise density and no g-sensitivity: the MPU-9250's 0.01 °/s/√Hz and
    # 0.1 °/s/g stand in (a consumer gyro of the same generation) ⚠
    gyro_errors=GyroErrors(0.03, 0.02, 30.0,
                           "zero-rate: LSM9DS1 DocID025715 Rev 3 Table 3 (G_TyOff); scale, "
                           "cross-axis: stand-in (not in the datasheet) ⚠",
                           noise_density_dps_sqrt_hz=0.01, g_sensitivity_dps_per_g=0.1,
                           noise_source="stand-in: the MPU-9250's figures (LSM9DS1 DocID025715 "
                                        "Rev 3 Table 3 gives neither) ⚠"),
    # bytes the reader drains per sample: one FIFO slot, gyro XYZ and accel XYZ int16 (§2.7)
    extra=MappingProxyType({"fifo_sample_bytes": 12.0}),
)


def register_names(registers: object) -> dict[int, str]:
    """Address → name for a register table (``MPU9250_REG`` or ``LSM9DS1_REG``), for messages."""
    return {addr: name for name, addr in asdict(registers).items()}  # type: ignore[call-overload]


# ---------------------------------------------------------------------------------------------
# TDK InvenSense ICM-42688-P (datasheet DS-000347; hardware_docs/chips.md)
#
# Sources: TDK, "ICM-42688-P Datasheet", DS-000347 (tables and registers named below), checked
# against the Linux kernel's drivers/iio/imu/inv_icm42600 (inv_icm42600.h,
# inv_icm42600_buffer.c) and PX4's InvenSense_ICM42688P_registers.hpp. Facts found in one source
# only are marked ⚠.


@dataclass(frozen=True)
class _ICM42688PRegisters:
    """ICM-42688-P user bank 0 register addresses (DS-000347 register map, bank 0;
    kernel inv_icm42600.h). All of these are in bank 0; REG_BANK_SEL is in every bank. The
    reset values noted are DS-000347's: its §14 register descriptions (Rev 1.8, read in a text
    copy: §14.2 DRIVE_CONFIG, §14.21 INT_STATUS, §14.24 FIFO_DATA, §14.35-14.51 INTF_CONFIG1
    .. INT_SOURCE0, §14.58 WHO_AM_I) and the register header ``main/boards/ICM42688.h`` of
    qunkejiang/alpakka_qk, which transcribes the same "Reset value" per register, agree on
    every register the emulator resets (a third, C++ transcription does too). Both give the
    sensor data registers 0x80, 0x00 (0x8000, the kernel's INV_ICM42600_DATA_INVALID, −32768),
    INT_STATUS 0x10 (RESET_DONE) and FIFO_DATA 0xFF."""

    DEVICE_CONFIG: int = 0x11
    DRIVE_CONFIG: int = 0x13  # reset 0x05
    INT_CONFIG: int = 0x14
    FIFO_CONFIG: int = 0x16
    TEMP_DATA1: int = 0x1D  # big-endian TEMP_DATA1/0, then ACCEL X/Y/Z, GYRO X/Y/Z
    ACCEL_DATA_X1: int = 0x1F
    GYRO_DATA_X1: int = 0x25
    INT_STATUS: int = 0x2D
    FIFO_COUNTH: int = 0x2E
    FIFO_COUNTL: int = 0x2F
    FIFO_DATA: int = 0x30
    SIGNAL_PATH_RESET: int = 0x4B
    INTF_CONFIG0: int = 0x4C
    INTF_CONFIG1: int = 0x4D  # reset 0x91 (DS-000347 register map, bank 0)
    PWR_MGMT0: int = 0x4E
    GYRO_CONFIG0: int = 0x4F
    ACCEL_CONFIG0: int = 0x50
    GYRO_CONFIG1: int = 0x51
    GYRO_ACCEL_CONFIG0: int = 0x52
    ACCEL_CONFIG1: int = 0x53  # reset 0x0D (DS-000347 register map, bank 0)
    TMST_CONFIG: int = 0x54
    APEX_CONFIG0: int = 0x56  # reset 0x82
    FIFO_CONFIG1: int = 0x5F
    FIFO_CONFIG2: int = 0x60  # FIFO_WM[7:0]
    FSYNC_CONFIG: int = 0x62  # reset 0x10
    INT_CONFIG1: int = 0x64  # reset 0x10
    INT_SOURCE0: int = 0x65  # reset 0x10 (RESET_DONE_INT1_EN)
    # SELF_TEST_CONFIG (DS-000347 register map, bank 0): ACCEL_ST_POWER bit 6, EN_AZ/AY/AX_ST
    # bits 5:3, EN_GZ/GY/GX_ST bits 2:0 (X in the low bit); TDK eMD Icm426xxDefs.h
    # MPUREG_SELF_TEST_CONFIG 0x70, BIT_GYRO_X_ST_EN 0x01 .. BIT_ST_REGULATOR_EN 0x40
    SELF_TEST_CONFIG: int = 0x70
    WHO_AM_I: int = 0x75
    REG_BANK_SEL: int = 0x76


@dataclass(frozen=True)
class _ICM42688PSelfTestCodes:
    """Where the ICM-42688-P keeps its factory self-test codes, one byte per axis: XG/YG/ZG_ST_DATA
    in user bank 1 and XA/YA/ZA_ST_DATA in user bank 2 (DS-000347 register map, banks 1 and 2;
    TDK eMD Icm426xxDefs.h MPUREG_XG_ST_DATA_B1 0x5F, MPUREG_XA_ST_DATA_B2 0x3B, as vendored by
    VaderMester/ESP32-ICM426XX-driver; kriswiner/ICM42688 ICM42688.h:94-96, 108-110)."""

    BANK_GYRO: int = 1
    XG_ST_DATA: int = 0x5F  # YG, ZG at 0x60, 0x61
    BANK_ACCEL: int = 2
    XA_ST_DATA: int = 0x3B  # YA, ZA at 0x3C, 0x3D


ICM42688P_ST_DATA = _ICM42688PSelfTestCodes()


#: The ICM-42688-P's registers in user banks 1, 2 and 4 whose reset value is not 0, one row each:
#: (bank, address, name, reset value). DS-000347's register descriptions of those banks (§15
#: user bank 1, then banks 2 and 4; their text was not read here) as three open transcriptions
#: of its per-register "Reset value" give them: qunkejiang/alpakka_qk main/src/bsp/ICM42688.h,
#: Witty-Wizard/InertialIO src/ICM42688/Registers.h, and a C++ register-description header
#: (``enum class GYRO_CONFIG_STATIC2_BITS``, "@Reset value: 0xA0"; its repository is not named
#: by the code index). All three agree where they overlap; a row fewer than two give is ⚠.
#: Registers trimmed part by part (GYRO_CONFIG_STATIC6-9, the notch filter's COSWZ;
#: XG/YG/ZG_ST_DATA and XA/YA/ZA_ST_DATA, the self-test codes) have no datasheet value and are
#: not here.
ICM42688P_BANK_RESET: tuple[tuple[int, int, str, int], ...] = (
    (1, 0x03, "SENSOR_CONFIG0", 0x80),  # three transcriptions
    (1, 0x0B, "GYRO_CONFIG_STATIC2", 0xA0),  # AAF and notch filter on; three
    (1, 0x0C, "GYRO_CONFIG_STATIC3", 0x0D),  # GYRO_AAF_DELT; three
    (1, 0x0D, "GYRO_CONFIG_STATIC4", 0xAA),  # GYRO_AAF_DELTSQR[7:0]; three
    (1, 0x0E, "GYRO_CONFIG_STATIC5", 0x80),  # GYRO_AAF_BITSHIFT, DELTSQR[11:8]; three
    (1, 0x13, "GYRO_CONFIG_STATIC10", 0x11),  # GYRO_NF_BW_SEL; three
    (1, 0x7A, "INTF_CONFIG4", 0x83),  # alpakka_qk and InertialIO
    (1, 0x7C, "INTF_CONFIG6", 0x5F),  # alpakka_qk and InertialIO
    (2, 0x03, "ACCEL_CONFIG_STATIC2", 0x30),  # ACCEL_AAF_DELT, AAF on; three
    (2, 0x04, "ACCEL_CONFIG_STATIC3", 0x40),  # ACCEL_AAF_DELTSQR[7:0]; three
    (2, 0x05, "ACCEL_CONFIG_STATIC4", 0x62),  # ACCEL_AAF_BITSHIFT, DELTSQR[11:8]; three
    (4, 0x40, "APEX_CONFIG1", 0xA2),  # ⚠ alpakka_qk alone
    (4, 0x41, "APEX_CONFIG2", 0x85),  # alpakka_qk and InertialIO, as the rows below
    (4, 0x42, "APEX_CONFIG3", 0x51),
    (4, 0x43, "APEX_CONFIG4", 0xA4),
    (4, 0x44, "APEX_CONFIG5", 0x8C),
    (4, 0x45, "APEX_CONFIG6", 0x5C),
    (4, 0x46, "APEX_CONFIG7", 0x45),
    (4, 0x47, "APEX_CONFIG8", 0x5B),
)


@dataclass(frozen=True)
class _ICM42688PBits:
    """ICM-42688-P register bits and fields (DS-000347 register map and FIFO packet
    structure; kernel inv_icm42600.h)."""

    DEVICE_CONFIG_SOFT_RESET: int = 0x01
    FIFO_MODE_SHIFT: int = 6
    FIFO_MODE_BYPASS: int = 0b00
    FIFO_MODE_STREAM: int = 0b01
    FIFO_MODE_STOP_ON_FULL: int = 0b10
    INT_STATUS_DATA_RDY: int = 0x08
    # INT_STATUS.RESET_DONE_INT: set when a reset completes, cleared when read (DS-000347
    # INT_STATUS; the kernel's inv_icm42600_setup refuses a chip without it after SOFT_RESET)
    INT_STATUS_RESET_DONE: int = 0x10
    INT_STATUS_FIFO_FULL: int = 0x02
    SIGNAL_PATH_RESET_FIFO_FLUSH: int = 0x02
    # INTF_CONFIG0 reset 0x30: FIFO count and sensor data big-endian, FIFO count in bytes
    INTF_CONFIG0_FIFO_COUNT_REC: int = 0x40
    INTF_CONFIG0_FIFO_COUNT_ENDIAN: int = 0x20
    INTF_CONFIG0_SENSOR_DATA_ENDIAN: int = 0x10
    PWR_MGMT0_TEMP_DIS: int = 0x20
    PWR_MGMT0_GYRO_MODE_SHIFT: int = 2
    PWR_MGMT0_GYRO_MODE_MASK: int = 0x0C
    PWR_MGMT0_ACCEL_MODE_MASK: int = 0x03
    MODE_LOW_NOISE: int = 0b11
    # SELF_TEST_CONFIG fields (:attr:`_ICM42688PRegisters.SELF_TEST_CONFIG`)
    SELF_TEST_GYRO_EN_SHIFT: int = 0  # EN_GX_ST bit 0, EN_GY_ST bit 1, EN_GZ_ST bit 2
    SELF_TEST_ACCEL_EN_SHIFT: int = 3  # EN_AX_ST bit 3, EN_AY_ST bit 4, EN_AZ_ST bit 5
    SELF_TEST_ACCEL_ST_POWER: int = 0x40
    FS_SEL_SHIFT: int = 5
    ODR_MASK: int = 0x0F
    GYRO_UI_FILT_BW_MASK: int = 0x0F
    GYRO_UI_FILT_ORD_SHIFT: int = 2  # GYRO_CONFIG1 bits 3:2 (:data:`ICM42688P_UI_FILT_ORDER`)
    GYRO_UI_FILT_ORD_MASK: int = 0x0C
    ACCEL_UI_FILT_BW_SHIFT: int = 4  # GYRO_ACCEL_CONFIG0 bits 7:4 (reset 1)
    ACCEL_UI_FILT_ORD_SHIFT: int = 3  # ACCEL_CONFIG1 bits 4:3 (reset 0x0D: 01, second order)
    ACCEL_UI_FILT_ORD_MASK: int = 0x18
    # TMST_CONFIG reset 0x23: TMST_FSYNC_EN | TMST_EN (DS-000347 §14.42; TDK sample code; the
    # transcription named in _ICM42688PRegisters)
    TMST_TO_REGS_EN: int = 0x10
    TMST_RES_16US: int = 0x08
    TMST_DELTA_EN: int = 0x04
    TMST_FSYNC_EN: int = 0x02
    TMST_EN: int = 0x01
    FIFO_CONFIG1_RESUME_PARTIAL_RD: int = 0x40
    FIFO_CONFIG1_TMST_FSYNC_EN: int = 0x08
    FIFO_CONFIG1_TEMP_EN: int = 0x04
    FIFO_CONFIG1_GYRO_EN: int = 0x02
    FIFO_CONFIG1_ACCEL_EN: int = 0x01
    # FIFO packet header (DS-000347 FIFO packet structure; kernel
    # inv_icm42600_buffer.c)
    HEADER_MSG: int = 0x80  # set: the FIFO is empty, the packet is not valid
    HEADER_ACCEL: int = 0x40
    HEADER_GYRO: int = 0x20
    HEADER_20: int = 0x10
    HEADER_TMST_MASK: int = 0x0C
    HEADER_TMST_ODR: int = 0x08  # 10: the packet carries the ODR timestamp
    HEADER_TMST_FSYNC: int = 0x0C  # 11: the packet carries the FSYNC time
    HEADER_ODR_ACCEL: int = 0x02
    HEADER_ODR_GYRO: int = 0x01


ICM42688P_REG = _ICM42688PRegisters()
ICM42688P_BITS = _ICM42688PBits()

#: GYRO_CONFIG0.GYRO_ODR code for each output data rate in Hz (DS-000347 register GYRO_CONFIG0;
#: kernel enum inv_icm42600_odr). Codes 12-14 are low-power accelerometer rates.
ICM42688P_ODR: Mapping[float, int] = MappingProxyType(
    {12.5: 0b1011, 25.0: 0b1010, 50.0: 0b1001, 100.0: 0b1000, 200.0: 0b0111, 500.0: 0b1111,
     1000.0: 0b0110, 2000.0: 0b0101, 4000.0: 0b0100, 8000.0: 0b0011, 16000.0: 0b0010,
     32000.0: 0b0001}
)
#: The fastest rate the reader offers: at 2 kHz the 16-byte packets alone are 288 kbit/s on
#: the wire (9 bits a byte), most of a 400 kHz I²C bus before any addressing or other transfer.
ICM42688P_MAX_READER_ODR_HZ = 1000.0

#: GYRO_ACCEL_CONFIG0.GYRO_UI_FILT_BW code → the UI filter bandwidth as a function of the ODR
#: (DS-000347 "UI filter block" and register GYRO_ACCEL_CONFIG0): 0 is ODR/2, 1..7 are
#: max(400 Hz, ODR) divided by 4, 5, 8, 10, 16, 20, 40. The reset value is 1. The filter's
#: order is :data:`ICM42688P_UI_FILT_ORDER`'s; no noise bandwidth or delay per setting was
#: found (⚠ the emulator has its stand-in filter's own: at 1 kHz, second order, 1.14 ms at code
#: 1 to 8.7 ms at code 7). Searched: DS-000347's §5 (only its contents were reached in an open
#: copy: §5.3 anti-alias filter, §5.5 UI filter block), GYRO_ACCEL_CONFIG0's description as
#: ten open headers found by the code index transcribe it (bandwidth formulas; codes 14 and 15
#: "Low Latency option: Trivial decimation @ ODR of Dec2 filter output", no delay), and TDK's
#: eMD ICM-426xx sources (Icm426xxDefs.h: the bandwidth codes; Icm426xxSelfTest.c).
ICM42688P_UI_FILT_DIVISOR: Mapping[int, float] = MappingProxyType(
    {1: 4.0, 2: 5.0, 3: 8.0, 4: 10.0, 5: 16.0, 6: 20.0, 7: 40.0}
)


#: GYRO_CONFIG1.GYRO_UI_FILT_ORD (bits 3:2) → the UI filter's order: 00 first, 01 second, 10
#: third (DS-000347 register GYRO_CONFIG1; ✓✓ PX4 InvenSense_ICM42688P_registers.hpp
#: ``GYRO_UI_FILT_ORD = Bit3 | Bit2, // 00: 1st Order``, TDK's IIM-423xx eMD defines
#: ``..._UI_FILT_ORD_2ND_ORDER = (0x1 << ..._POS)``, ``_3RD_ORDER = (0x2 << ...)``). The reset
#: value of GYRO_CONFIG1 is 0x16: second order. 11 is reserved (taken as the reset's second
#: order ⚠).
ICM42688P_UI_FILT_ORDER: Mapping[int, int] = MappingProxyType({0b00: 1, 0b01: 2, 0b10: 3})


def icm42688p_bandwidth_hz(odr_hz: float, code: int) -> float:
    """The gyro UI filter bandwidth for GYRO_UI_FILT_BW ``code`` at ``odr_hz`` (DS-000347, register
    GYRO_ACCEL_CONFIG0).

    Parameters
    ----------
    odr_hz : float
        The output data rate.
    code : int
        GYRO_UI_FILT_BW, 0..7.

    Returns
    -------
    float
        The −3 dB bandwidth in Hz.
    """
    if code == 0:
        return odr_hz / 2.0
    return max(400.0, odr_hz) / ICM42688P_UI_FILT_DIVISOR[code]


ICM42688P = ChipFamily(
    name="icm42688p",
    title="ICM-42688-P",
    addresses=(0x68, 0x69),  # DS-000347 I²C address: AP_AD0 low / high
    who_am_i_register=ICM42688P_REG.WHO_AM_I,
    models=(ChipModel("icm42688p", 0x47, "ICM-42688-P"),),
    siblings=MappingProxyType(
        {
            0x40: "an ICM-42600 (WHO_AM_I 0x40), a sibling of the ICM-42688-P with another "
            "noise and range specification; gyrocal does not drive it",
            0x41: "an ICM-42602 (WHO_AM_I 0x41); gyrocal does not drive it",
            0x42: "an ICM-42605 (WHO_AM_I 0x42), the ICM-42688-P's older sibling (same register "
            "map, higher noise); gyrocal does not drive it",
            0x44: "an ICM-42686-P (WHO_AM_I 0x44), the ±4000 °/s sibling; gyrocal does not "
            "drive it",
            0x46: "an ICM-42622 (WHO_AM_I 0x46); gyrocal does not drive it",
            0x5C: "an ICM-42631 (WHO_AM_I 0x5C); gyrocal does not drive it",
        }
    ),
    # GYRO_CONFIG0.GYRO_FS_SEL (DS-000347 Table 1 and the register): 000 = ±2000 °/s
    # (16.4 LSB/°/s) ... 111 = ±15.625 °/s (2097.2 LSB/°/s)
    gyro_ranges=(
        GyroRange(0b000, 2000.0, 16.4),
        GyroRange(0b001, 1000.0, 32.8),
        GyroRange(0b010, 500.0, 65.5),
        GyroRange(0b011, 250.0, 131.0),
        GyroRange(0b100, 125.0, 262.0),
        GyroRange(0b101, 62.5, 524.3),
        GyroRange(0b110, 31.25, 1048.6),
        GyroRange(0b111, 15.625, 2097.2),
    ),
    fifo_capacity=2048,  # DS-000347 FIFO: 2 kB (kernel: INV_ICM42600_FIFO_WATERMARK_MAX)
    fifo_capacity_unit="bytes",
    reset_time_s=0.001,  # DS-000347 DEVICE_CONFIG: wait 1 ms after SOFT_RESET (kernel 1 ms)
    # DS-000347 Table 1: gyro start-up 30 ms from sleep; the kernel waits 60 ms
    # (INV_ICM42600_GYRO_STARTUP_TIME_MS), as gyrocal does
    startup_time_s=0.060,
    # FIFO temperature, 8 bits: T = FIFO_TEMP_DATA / 2.07 + 25 (DS-000347 register TEMP_DATA)
    temperature_offset_c=25.0,
    temperature_lsb_per_c=2.07,
    # DS-000347 Table 2 and ACCEL_CONFIG0.ACCEL_FS_SEL: 010 = ±4 g, 8192 LSB/g
    accel_range=AccelRange(0b010, 4.0, 8192.0),
    # DS-000347 rev 1.2 §3.2 Table 2: sensitivity initial tolerance ±0.5 %, cross-axis ±1 %,
    # zero-g initial tolerance (board-level) ±20 mg ⚠ one source; power spectral density
    # X/Y 65, Z 70 µg/√Hz ✓✓ (Table 2 and the "Features" list of rev 1.7: 70 µg/√Hz)
    accel_errors=AccelErrors(0.005, 0.01, (0.020, 0.020, 0.020), 70e-6,
                             "ICM-42688-P DS-000347 rev 1.2 §3.2 Table 2 (noise X/Y 65, "
                             "Z 70 µg/√Hz) ⚠"),
    # DS-000347 §3.1 Table 1 (gyroscope): Sensitivity Scale Factor Tolerance ±0.5 %,
    # Cross-Axis Sensitivity ±1.25 % ⚠ one source; Initial ZRO Tolerance (board-level)
    # ±0.5 °/s ✓✓ (Table 1 and open code quoting it)
    # Table 1 also: Rate Noise Spectral Density 0.0028 °/s/√Hz (at 10 Hz) ✓✓ (the datasheet's
    # table and its "Features" list); Table 1 has no linear-acceleration sensitivity row and no
    # bias-instability row (read in a text copy of DS-000347's §3.1): the MPU-9250's 0.1 °/s/g
    # stands in ⚠
    gyro_errors=GyroErrors(0.005, 0.0125, 0.5, "ICM-42688-P DS-000347 §3.1 Table 1 ⚠",
                           noise_density_dps_sqrt_hz=0.0028, g_sensitivity_dps_per_g=0.1,
                           noise_source="ICM-42688-P DS-000347 §3.1 Table 1 (Rate Noise Spectral "
                                        "Density); g-sensitivity: stand-in, the MPU-9250's ⚠"),
    extra=MappingProxyType(
        {
            "register_temperature_lsb_per_c": 132.48,  # TEMP_DATA: T = TEMP_DATA/132.48 + 25
            "packet_bytes": 16.0,  # FIFO packet 3: header, accel, gyro, temp, timestamp
            "fifo_sample_bytes": 16.0,  # one packet 3 per sample
            "timestamp_resolution_s": 16e-6,  # TMST_CONFIG.TMST_RES = 1 (kernel: 16 µs)
            "timestamp_modulus": 65536.0,  # 16-bit ODR timestamp in the packet
            "mode_change_wait_s": 200e-6,  # no register writes for 200 µs after PWR_MGMT0
            "accel_lsb_per_g_2g": 16384.0,  # Table 2: ±2 g, 16384 LSB/g
        }
    ),
)


# ---------------------------------------------------------------------------------------------
# ST LSM6DSOX (datasheet DS12814; hardware_docs/chips.md)
#
# Sources: ST, "LSM6DSOX" datasheet DS12814 (tables and registers named below) and application
# note AN5272 (FIFO); checked against the Linux kernel's drivers/iio/imu/st_lsm6dsx
# (st_lsm6dsx_core.c settings for WHO_AM_I 0x6C, st_lsm6dsx_buffer.c tagged FIFO) and ST's
# lsm6dsox_reg.h (STMems standard C drivers). Facts found in one source only are marked ⚠.


@dataclass(frozen=True)
class _LSM6DSOXRegisters:
    """LSM6DSOX register addresses (DS12814 register map; kernel st_lsm6dsx; lsm6dsox_reg.h)."""

    FUNC_CFG_ACCESS: int = 0x01  # bit 7 embedded-functions page, bit 6 sensor-hub page
    FIFO_CTRL1: int = 0x07
    FIFO_CTRL2: int = 0x08
    FIFO_CTRL3: int = 0x09  # BDR_GY[7:4], BDR_XL[3:0]
    FIFO_CTRL4: int = 0x0A  # DEC_TS_BATCH[7:6], ODR_T_BATCH[5:4], FIFO_MODE[2:0]
    WHO_AM_I: int = 0x0F
    CTRL1_XL: int = 0x10
    CTRL2_G: int = 0x11
    CTRL3_C: int = 0x12
    CTRL4_C: int = 0x13
    CTRL6_C: int = 0x15  # FTYPE[2:0]: the gyro LPF1 bandwidth (:data:`LSM6DSOX_GYRO_FILTER`)
    CTRL7_G: int = 0x16
    CTRL8_XL: int = 0x17  # HPCF_XL[7:5], HP_SLOPE_XL_EN[2]: the accelerometer LPF2 / HPF
    CTRL10_C: int = 0x19
    STATUS_REG: int = 0x1E
    OUT_TEMP_L: int = 0x20
    OUTX_L_G: int = 0x22
    OUTX_L_A: int = 0x28
    FIFO_STATUS1: int = 0x3A  # DIFF_FIFO[7:0]
    FIFO_STATUS2: int = 0x3B
    TIMESTAMP0: int = 0x40  # 32 bits, little-endian, to 0x43
    FIFO_DATA_OUT_TAG: int = 0x78
    FIFO_DATA_OUT_Z_H: int = 0x7E


@dataclass(frozen=True)
class _LSM6DSOXBits:
    """LSM6DSOX register bits and fields (DS12814 register descriptions; lsm6dsox_reg.h)."""

    FUNC_CFG_PAGES: int = 0xC0
    ODR_SHIFT: int = 4
    FS_G_SHIFT: int = 2
    FS_G_MASK: int = 0x0C
    FS_125: int = 0x02
    FS_XL_SHIFT: int = 2
    # the filters (AN5192 Rev 5 §3.8, §3.10; LSM6DSO32 DocID032891 Rev 1 Tables 43, 57, 65):
    # CTRL4_C bit 1 routes the gyro through LPF1, CTRL6_C bits 2:0 set its bandwidth; CTRL1_XL
    # bit 1 selects the accelerometer's LPF2 output, CTRL8_XL bits 7:5 its cutoff and bit 2
    # the high-pass path instead
    LPF1_SEL_G: int = 0x02
    FTYPE_MASK: int = 0x07
    LPF2_XL_EN: int = 0x02
    HPCF_XL_SHIFT: int = 5
    HP_SLOPE_XL_EN: int = 0x04
    CTRL3_C_BOOT: int = 0x80
    CTRL3_C_BDU: int = 0x40
    CTRL3_C_IF_INC: int = 0x04
    CTRL3_C_SW_RESET: int = 0x01
    CTRL10_C_TIMESTAMP_EN: int = 0x20
    # STATUS_REG (DS12814 STATUS_REG; lsm6dsox_reg.h lsm6dsox_status_reg_t): new data at the
    # accelerometer, gyro, temperature output; reset when that output is read (AN5192 ⚠)
    STATUS_XLDA: int = 0x01
    STATUS_GDA: int = 0x02
    STATUS_TDA: int = 0x04
    BDR_GY_SHIFT: int = 4
    DEC_TS_BATCH_SHIFT: int = 6
    DEC_TS_EVERY_BATCH: int = 0b01  # a timestamp word with every batch data rate event
    FIFO_MODE_MASK: int = 0x07
    FIFO_MODE_BYPASS: int = 0b000
    FIFO_MODE_FIFO: int = 0b001  # stop collecting when full
    FIFO_MODE_CONTINUOUS: int = 0b110  # overwrite the oldest
    FIFO_STATUS2_WTM_IA: int = 0x80
    FIFO_STATUS2_OVR_IA: int = 0x40
    FIFO_STATUS2_FULL_IA: int = 0x20
    FIFO_STATUS2_OVR_LATCHED: int = 0x08  # cleared when FIFO_STATUS2 is read
    FIFO_STATUS2_DIFF_HIGH_MASK: int = 0x03  # DIFF_FIFO[9:8]
    TAG_SENSOR_SHIFT: int = 3  # FIFO_DATA_OUT_TAG: TAG_SENSOR[7:3], TAG_CNT[2:1], TAG_PARITY[0]
    TAG_GYRO: int = 0x01
    TAG_ACCEL: int = 0x02
    TAG_TEMPERATURE: int = 0x03
    TAG_TIMESTAMP: int = 0x04
    TAG_CFG_CHANGE: int = 0x05


LSM6DSOX_REG = _LSM6DSOXRegisters()
LSM6DSOX_BITS = _LSM6DSOXBits()

#: The chip's internal time base: ODR = 6667 Hz / ODR_coeff and the timestamp's 25 µs LSB both
#: come from one oscillator (AN5192/AN5272 "ODR_Actual" and "TS_Res" ⚠); 40 kHz / 6 makes the
#: sample period a whole number of timestamp LSBs, as the two formulas imply.
LSM6DSOX_BASE_RATE_HZ = 40000.0 / 6.0

#: CTRL2_G.ODR_G code → (the datasheet's nominal rate, the actual rate) in Hz (DS12814 CTRL2_G
#: table; kernel odr_avl; the actual rates are 6667 Hz / 2^k ⚠ application notes only). The
#: reader does not offer 12.5 Hz (code 1), which this rule makes 13 Hz ⚠.
LSM6DSOX_ODR: Mapping[int, tuple[float, float]] = MappingProxyType(
    {code: (nominal, LSM6DSOX_BASE_RATE_HZ / 2 ** (10 - code))
     for code, nominal in ((1, 12.5), (2, 26.0), (3, 52.0), (4, 104.0), (5, 208.0), (6, 416.0),
                           (7, 833.0), (8, 1666.0), (9, 3333.0), (10, 6667.0))}
)
#: The gyro chain's bandwidth in Mode 1/2, high-performance mode (AN5192 Rev 5 Table 14
#: "Gyroscope overall bandwidth selection", LSM6DSO, the LSM6DSOX's gyro and registers), one
#: row per CTRL2_G.ODR_G code: the bandwidth with LPF1 off (LPF2 alone, which the user cannot
#: set), then with CTRL4_C.LPF1_SEL_G = 1 for CTRL6_C.FTYPE 000..111, and each setting's phase
#: delay as the table gives it (degrees at a frequency, Hz). ✓✓ with the LSM6DSO32 datasheet
#: DocID032891 Rev 1 (Table 18, LPF2 alone; Table 60, LPF1 + LPF2: every bandwidth the same);
#: the 6.67 kHz row's FTYPE 000..011 also in Betaflight's LSM6DSO driver (``..._FTYPE_335HZ``,
#: ``_232HZ``, ``_171HZ``, ``_609HZ``: "gyro LPF1 cutoff 335.5hz" ...). At 3.33 and 6.67 kHz
#: AN5192 has FTYPE 1xx "not available" where DocID032891 gives 100.4/100.6, 49.9, 25.1, 12.5
#: Hz: those eight come from the datasheet alone (⚠). The phases are AN5192's only (⚠).
_LSM6DSO_GYRO_BW: dict[int, tuple[tuple[float, float, float], ...]] = {
    # code: ((bandwidth, phase °, at Hz) for LPF1 off, FTYPE 000, 001, ..., 111)
    1: ((4.2, 36, 1.3),) * 6 + ((4.2, 36, 1.3), (4.1, 36, 1.3), (3.9, 36, 1.3)),
    2: ((8.3, 36, 2.5),) * 7 + ((7.8, 36, 2.5), (6.7, 36, 2.5)),
    3: ((16.6, 36, 5),) * 5 + ((16.7, 39, 5), (16.8, 43, 5), (13.4, 45, 5), (9.7, 49, 5)),
    4: ((33.0, 36, 10),) + ((33.0, 38, 10),) * 4 + ((33.0, 43, 10), (31.0, 52, 10),
                                                    (19.0, 55, 10), (11.5, 64, 10)),
    5: ((66.8, 35.09, 20),) + ((67.0, 39, 20),) * 4 + ((62.4, 51.03, 20), (43.2, 68.67, 20),
                                                      (23.1, 74.11, 20), (12.2, 93.61, 20)),
    6: ((135.9, 17.81, 20), (136.6, 22.89, 20), (130.5, 24.98, 20), (120.3, 27.38, 20),
        (137.1, 21.11, 20), (86.7, 33.75, 20), (48.0, 51.39, 20), (24.6, 56.83, 20),
        (12.4, 76.33, 20)),
    7: ((295.5, 9.17, 20), (239.2, 14.25, 20), (192.4, 16.34, 20), (154.2, 18.74, 20),
        (281.8, 12.47, 20), (96.6, 25.11, 20), (49.4, 42.75, 20), (25.0, 48.19, 20),
        (12.5, 67.69, 20)),
    8: ((1108.1, 4.85, 20), (304.2, 9.93, 20), (220.7, 12.02, 20), (166.6, 14.42, 20),
        (453.2, 8.15, 20), (99.6, 20.79, 20), (49.8, 38.43, 20), (25.1, 43.87, 20),
        (12.5, 63.37, 20)),
    9: ((1320.7, 2.69, 20), (328.5, 7.77, 20), (229.6, 9.86, 20), (170.1, 12.26, 20),
        (559.2, 5.99, 20), (100.4, 0, 0), (49.9, 0, 0), (25.1, 0, 0), (12.5, 0, 0)),
    10: ((1441.8, 1.61, 20), (335.5, 6.69, 20), (232.0, 8.78, 20), (171.1, 11.18, 20),
         (609.0, 4.91, 20), (100.6, 0, 0), (49.9, 0, 0), (25.1, 0, 0), (12.5, 0, 0)),
}
_LSM6DSO_TABLE_14 = "AN5192 Rev 5 Table 14 ✓✓ (LSM6DSO32 DocID032891 Rev 1 Tables 18, 60)"
_LSM6DSO_TABLE_60 = "LSM6DSO32 DocID032891 Rev 1 Table 60 ⚠ (AN5192 Table 14: not available)"

#: The frequency at which AN5192 Table 14 gives each ODR code's phase delays, Hz.
LSM6DSOX_GYRO_PHASE_HZ: Mapping[int, float] = MappingProxyType(
    {code: rows[0][2] for code, rows in _LSM6DSO_GYRO_BW.items()})

#: The LSM6DSOX's gyro filter settings, one tuple of rows per CTRL2_G.ODR_G code; a row's code
#: is ``LPF1_SEL_G · 8 + FTYPE`` (0: LPF1 off, the reset; 8..15: LPF1 on, FTYPE 000..111), its
#: bandwidth the whole chain's (:data:`_LSM6DSO_GYRO_BW`) and its delay the table's phase delay
#: at :data:`LSM6DSOX_GYRO_PHASE_HZ` (``φ / (360° f)``, ⚠ AN5192 only; None where no phase is
#: given). The
#: filters are bypassed in the gyro's low-power mode (CTRL7_G.G_HM_MODE = 1, AN5192 Table 15),
#: which gyrocal does not use.
LSM6DSOX_GYRO_FILTER: Mapping[int, tuple[FilterSetting, ...]] = MappingProxyType({
    odr_code: tuple(
        FilterSetting(0 if i == 0 else 8 + i - 1, bw, (phase / (360.0 * f)) if f else None,
                      None, _LSM6DSO_TABLE_14 if f else _LSM6DSO_TABLE_60)
        for i, (bw, phase, f) in enumerate(rows))
    for odr_code, rows in _LSM6DSO_GYRO_BW.items()
})


def lsm6dsox_gyro_filter(odr_code: int, lpf1: bool, ftype: int) -> FilterSetting:
    """The row of :data:`LSM6DSOX_GYRO_FILTER` for CTRL2_G.ODR_G ``odr_code``,
    CTRL4_C.LPF1_SEL_G ``lpf1`` and CTRL6_C.FTYPE ``ftype`` (AN5192 Rev 5 Table 14).

    Parameters
    ----------
    odr_code : int
        ODR_G, 1..10.
    lpf1 : bool
        Whether LPF1 is in the chain.
    ftype : int
        FTYPE[2:0], 0..7 (ignored with LPF1 off).
    """
    code = 8 + (ftype & 0x07) if lpf1 else 0
    return next(r for r in LSM6DSOX_GYRO_FILTER[odr_code] if r.code == code)


#: CTRL8_XL.HPCF_XL → the divisor of the ODR that is the accelerometer's bandwidth with
#: CTRL1_XL.LPF2_XL_EN = 1 and HP_SLOPE_XL_EN = 0 (LPF2 after LPF1; AN5192 Rev 5 Table 10
#: "Accelerometer bandwidth selection in Mode 1/2/3", ✓✓ LSM6DSO32 DocID032891 Rev 1 Table 65,
#: and open drivers' enums: ``ODR_OVER_4`` .. ``ODR_OVER_800`` in TeamSunride's
#: LSM6DSO32_constants.h). With LPF2_XL_EN = 0 the output is LPF1's, ODR/2 in high-performance
#: mode (the same tables), which the emulator's per-sample mean stands for: ST quotes the
#: accelerometer's RMS noise "related to BW = ODR/2" (LSM6DSO DS12140 Table 2 note 10), the
#: noise of a filter whose noise bandwidth is ODR/2, where a first-order stand-in at ODR/2
#: would have π/4 · ODR.
LSM6DSOX_ACCEL_LPF2_DIVISOR: Mapping[int, float] = MappingProxyType(
    {0b000: 4.0, 0b001: 10.0, 0b010: 20.0, 0b011: 45.0, 0b100: 100.0, 0b101: 200.0,
     0b110: 400.0, 0b111: 800.0})

#: The fastest rate the reader streams: two 7-byte FIFO words (timestamp, gyro) per sample are
#: 210 kbit/s on the wire at 1666 Hz, too much of a 400 kHz bus.
LSM6DSOX_MAX_READER_ODR_HZ = 834.0

LSM6DSO_NOTICE = (
    "WHO_AM_I 0x6C: ST gives the LSM6DSO, LSM6DSOX, LSM6DSO32 and LSM6DSO32X one identity, so "
    "the chip cannot tell which it is (the Linux kernel too takes the name from the device "
    "tree). Their gyros, registers and tagged FIFOs are the same, so gyrocal reads any of them "
    "as 'lsm6dsox'; they differ in the accelerometer (the LSM6DSO32's ±32 g) and the machine "
    "learning core, which gyrocal does not use."
)

LSM6DSOX = ChipFamily(
    name="lsm6dsox",
    title="LSM6DSOX",
    addresses=(0x6A, 0x6B),  # DS12814 I²C interface: SA0/SDO low / high
    who_am_i_register=LSM6DSOX_REG.WHO_AM_I,
    models=(ChipModel("lsm6dsox", 0x6C, "LSM6DSOX (or LSM6DSO)", LSM6DSO_NOTICE),),
    siblings=MappingProxyType(
        {
            0x69: "an LSM6DS3 or LSM6DS3H (WHO_AM_I 0x69), an older ST part with an untagged "
            "FIFO; gyrocal does not drive it",
            0x6A: "an LSM6DSL, LSM6DSM, ISM330DLC or LSM6DS3TR-C (WHO_AM_I 0x6A), older ST parts "
            "with an untagged FIFO; gyrocal does not drive them",
            0x6B: "an LSM6DSR, LSM6DSRX, ISM330DHCX or ASM330LHH (WHO_AM_I 0x6B), the LSM6DSOX's "
            "±4000 °/s and industrial siblings; gyrocal does not drive them",
            0x6D: "an LSM6DST (WHO_AM_I 0x6D); gyrocal does not drive it",
            0x70: "an LSM6DSV or LSM6DSV16X (WHO_AM_I 0x70), a newer ST part with another "
            "register map; gyrocal does not drive it",
        }
    ),
    # CTRL2_G.FS_G (and FS_125) with the sensitivities of DS12814 Table 2 (mechanical
    # characteristics): 4.375, 8.75, 17.50, 35, 70 mdps/LSB. Code 0b100 stands for FS_125.
    gyro_ranges=(
        GyroRange(0b100, 125.0, 1000.0 / 4.375),
        GyroRange(0b00, 250.0, 1000.0 / 8.75),
        GyroRange(0b01, 500.0, 1000.0 / 17.50),
        GyroRange(0b10, 1000.0, 1000.0 / 35.0),
        GyroRange(0b11, 2000.0, 1000.0 / 70.0),
    ),
    fifo_capacity=512,  # 7-byte words (kernel max_fifo_size ⚠: DS12814 gives the size in kB)
    fifo_capacity_unit="words",
    reset_time_s=0.050,  # ⚠ the kernel waits after SW_RESET/BOOT; DS12814 gives no figure here
    startup_time_s=0.100,  # ⚠ a conservative wait for the gyro to settle (cf. LSM9DS1)
    temperature_offset_c=25.0,  # DS12814 Table 4: 256 LSB/°C, 0 LSB at 25 °C
    temperature_lsb_per_c=256.0,
    # DS12814 Table 2 (LA_So) and CTRL1_XL.FS_XL: 10 = ±4 g, 0.122 mg/LSB
    accel_range=AccelRange(0b10, 4.0, 1000.0 / 0.122),
    # LSM6DSO DS12140 Rev 3 Table 2 (the LSM6DSOX shares its WHO_AM_I and accelerometer;
    # DS12814's own table not read ⚠ one source): LA_So% sensitivity tolerance ±1 %, LA_TyOff
    # ±20 mg, An 75 µg/√Hz at ±4 g in high-performance mode (70/75/80/110 at ±2/4/8/16 g). ST
    # gives no cross-axis figure: the MPU-9250's ±2 % stands in ⚠
    accel_errors=AccelErrors(0.01, 0.02, (0.020, 0.020, 0.020), 75e-6,
                             "LSM6DSO DS12140 Rev 3 Table 2 (cross-axis: stand-in, not in the "
                             "datasheet) ⚠"),
    # LSM6DSO DS12140 Rev 3 Table 2 (as for the accelerometer; DS12814's own table not read ⚠):
    # G_So% sensitivity tolerance ±1 %, G_TyOff zero-rate level ±1 dps ✓✓ (also the LSM6DSOX
    # table as quoted by open code). ST gives no cross-axis figure: the MPU-9250's ±2 % stands in
    # Rn, rate noise density in high-performance mode, 3.8 mdps/√Hz (DS12814 Table 2; footnote:
    # independent of ODR and FS) ⚠ one named source: open transcriptions of DS12814 Rev 3 and of
    # the LSM6DSO's DS12140 agree on 3.8, but the code index names none of their repositories.
    # ST gives no g-sensitivity: the MPU-9250's 0.1 °/s/g stands in ⚠
    gyro_errors=GyroErrors(0.01, 0.02, 1.0,
                           "LSM6DSO DS12140 Rev 3 Table 2 (cross-axis: stand-in, not in the "
                           "datasheet) ⚠",
                           noise_density_dps_sqrt_hz=0.0038, g_sensitivity_dps_per_g=0.1,
                           noise_source="LSM6DSOX DS12814 Table 2 (Rn, high-performance mode) ⚠; "
                                        "g-sensitivity: stand-in, the MPU-9250's ⚠"),
    extra=MappingProxyType(
        {
            "timestamp_resolution_s": 25e-6,  # DS12814 TIMESTAMP registers: 25 µs LSB (typ.)
            "timestamp_modulus": 2.0**32,
            "word_bytes": 7.0,  # FIFO_DATA_OUT_TAG + 6 data bytes
            # per sample the reader batches a TIMESTAMP, a GYRO_NC and an XL_NC word
            "fifo_sample_bytes": 21.0,
            "accel_mg_per_lsb_2g": 0.061,  # DS12814 Table 2
        }
    ),
)


# ---------------------------------------------------------------------------------------------
# TDK InvenSense ICM-20948 (datasheet DS-000189; hardware_docs/chips.md)
#
# Sources: TDK, "ICM-20948 Datasheet", DS-000189 (register map by user bank, Table 1 gyroscope
# specification, the GYRO_CONFIG_1 DLPF table); checked against SparkFun's ICM-20948 Arduino
# library (ICM_20948_ENUMERATIONS.h) and other open drivers. The Linux kernel has no ICM-20948
# driver, so facts the datasheet and one open driver do not both give are marked ⚠.


@dataclass(frozen=True)
class _ICM20948Bank0:
    """ICM-20948 user bank 0 registers (DS-000189 register map, bank 0, and each register's
    description there; the I²C-master and status rows checked against SparkFun's
    qwiic_icm20948.py AGB0_REG_* and Adafruit's adafruit_icm20x.py)."""

    WHO_AM_I: int = 0x00
    USER_CTRL: int = 0x03
    # reset 0x40: I2C_MST_CYCLE bit 6, ACCEL_CYCLE 5, GYRO_CYCLE 4 (DS-000189 rev 1.3 §8.3,
    # p. 37, "Reset Value: 0x40", as transcribed page by page at manualshelf.com, SparkFun
    # SEN-15335 data sheet, page 37; and an open header transcribing the register table)
    LP_CONFIG: int = 0x05
    PWR_MGMT_1: int = 0x06
    PWR_MGMT_2: int = 0x07
    INT_PIN_CFG: int = 0x0F  # BYPASS_EN bit 1
    I2C_MST_STATUS: int = 0x17  # R/C: NACK bits 4:0, SLV4_DONE bit 6
    INT_STATUS_1: int = 0x1A  # RAW_DATA_0_RDY_INT bit 0, R/C
    INT_STATUS_2: int = 0x1B  # FIFO_OVERFLOW_INT[4:0], cleared when read
    ACCEL_XOUT_H: int = 0x2D
    GYRO_XOUT_H: int = 0x33
    TEMP_OUT_H: int = 0x39
    EXT_SLV_SENS_DATA_00: int = 0x3B  # 24 bytes, to 0x52
    FIFO_EN_2: int = 0x67
    FIFO_RST: int = 0x68
    FIFO_MODE: int = 0x69
    FIFO_COUNTH: int = 0x70
    FIFO_COUNTL: int = 0x71
    FIFO_R_W: int = 0x72
    REG_BANK_SEL: int = 0x7F  # in every bank: USER_BANK[5:4]


@dataclass(frozen=True)
class _ICM20948Bank1:
    """ICM-20948 user bank 1 registers: the factory self-test codes SELF_TEST_X/Y/Z_GYRO and
    SELF_TEST_X/Y/Z_ACCEL (DS-000189 register map, bank 1; TDK eMD-SmartMotion-ICM20948-1.1.0
    Icm20948Defs.h 185-190, REG_SELF_TEST1..6, as vendored by FredBill1/RT1064_Smartcar;
    SparkFun ICM_20948_REGISTERS.h, ICM_20948_SELF_TEST_X_GYRO_t ..)."""

    SELF_TEST_X_GYRO: int = 0x02  # Y, Z at 0x03, 0x04
    SELF_TEST_X_ACCEL: int = 0x0E  # Y, Z at 0x0F, 0x10


ICM20948_REG1 = _ICM20948Bank1()


@dataclass(frozen=True)
class _ICM20948Bank2:
    """ICM-20948 user bank 2 registers (DS-000189 register map, bank 2; XG_OFFS_USRH..ZG_OFFS_
    USRL also in SparkFun's ICM_20948_REGISTERS.h)."""

    GYRO_SMPLRT_DIV: int = 0x00
    GYRO_CONFIG_1: int = 0x01
    GYRO_CONFIG_2: int = 0x02  # XGYRO_CTEN..ZGYRO_CTEN bits 5:3, GYRO_AVGCFG 2:0
    # X/Y/Z_OFFS_USER, int16 big-endian H/L pairs at 0x03..0x08 (reset 0)
    XG_OFFS_USRH: int = 0x03
    ACCEL_SMPLRT_DIV_1: int = 0x10  # bits [11:8] of the accelerometer's rate divider
    ACCEL_SMPLRT_DIV_2: int = 0x11  # bits [7:0]
    # reset 0x01 (ACCEL_FCHOICE): DS-000189 rev 1.3 §10.15, p. 64, "Reset Value: 0x01" as
    # quoted on TDK InvenSense's developer forum ("ICM20948 Accelerometer Configuration
    # Reading", 2023, where a part reads back 0x01), and an open header transcribing the
    # register table ("Reset Value: 0b00000001"). The same header gives GYRO_CONFIG_1 reset 0,
    # where the emulator keeps 0x01 (GYRO_FCHOICE, DS-000189 as read for the emulator) ⚠ the
    # two disagree and no third source was found
    ACCEL_CONFIG: int = 0x14
    ACCEL_CONFIG_2: int = 0x15  # AX_ST_EN_REG..AZ_ST_EN_REG bits 4:2, DEC3_CFG 1:0


@dataclass(frozen=True)
class _ICM20948Bank3:
    """ICM-20948 user bank 3 registers: the auxiliary I²C master (DS-000189 register map, bank
    3, and the register descriptions; SparkFun qwiic_icm20948.py AGB3_REG_*, Pimoroni icm20948
    and Adafruit adafruit_icm20x use the same addresses)."""

    I2C_MST_ODR_CONFIG: int = 0x00  # rate while gyro and accel are off (not modelled)
    I2C_MST_CTRL: int = 0x01  # MULT_MST_EN, I2C_MST_P_NSR, I2C_MST_CLK (stored)
    I2C_MST_DELAY_CTRL: int = 0x02  # (stored)
    I2C_SLV0_ADDR: int = 0x03  # SLVn_ADDR/REG/CTRL/DO at 0x03 + 4n, n = 0..3
    I2C_SLV4_ADDR: int = 0x13
    I2C_SLV4_REG: int = 0x14
    I2C_SLV4_CTRL: int = 0x15  # EN bit 7 (clears when done), INT_EN, REG_DIS, DLY
    I2C_SLV4_DO: int = 0x16
    I2C_SLV4_DI: int = 0x17  # the byte slave 4 read


@dataclass(frozen=True)
class _ICM20948Bits:
    """ICM-20948 register bits and fields (DS-000189 register descriptions)."""

    BANK_SHIFT: int = 4
    BANK_MASK: int = 0x30
    USER_CTRL_FIFO_EN: int = 0x40
    USER_CTRL_I2C_MST_EN: int = 0x20
    USER_CTRL_I2C_MST_RST: int = 0x02  # resets the I²C master, clears itself
    INT_PIN_CFG_BYPASS_EN: int = 0x02  # INT_PIN_CFG: the aux bus on the host bus
    # LP_CONFIG.I2C_MST_CYCLE: the I²C master runs duty-cycled at the I2C_MST_ODR_CONFIG rate
    LP_CONFIG_I2C_MST_CYCLE: int = 0x40
    I2C_MST_ODR_CONFIG_MASK: int = 0x0F
    INT_STATUS_1_RAW_DATA_0_RDY: int = 0x01  # INT_STATUS_1: new sensor register data
    PWR_MGMT_1_DEVICE_RESET: int = 0x80
    PWR_MGMT_1_SLEEP: int = 0x40
    PWR_MGMT_1_CLKSEL_AUTO: int = 0x01
    PWR_MGMT_2_DISABLE_GYRO: int = 0x07
    GYRO_DLPFCFG_SHIFT: int = 3
    GYRO_FS_SEL_SHIFT: int = 1
    GYRO_FS_SEL_MASK: int = 0x06
    GYRO_FCHOICE: int = 0x01  # 1: the DLPF is on and the rate is 1125/(1 + GYRO_SMPLRT_DIV)
    ACCEL_FS_SEL_SHIFT: int = 1
    ACCEL_FCHOICE: int = 0x01  # 1: the accelerometer DLPF is on, rate 1125/(1 + ACCEL_SMPLRT_DIV)
    ACCEL_DLPFCFG_SHIFT: int = 3  # ACCEL_CONFIG bits 5:3 (qwiic_icm20948.py:532-534)
    FIFO_EN_2_ACCEL: int = 0x10
    FIFO_EN_2_GYRO_Z: int = 0x08
    FIFO_EN_2_GYRO_Y: int = 0x04
    FIFO_EN_2_GYRO_X: int = 0x02
    FIFO_EN_2_TEMP: int = 0x01
    FIFO_RST_ALL: int = 0x1F
    FIFO_MODE_SNAPSHOT: int = 0x01  # 1: stop writing when full; 0: stream, overwrite ⚠
    INT_STATUS_2_FIFO_OVERFLOW: int = 0x1F
    # GYRO_CONFIG_2 XGYRO_CTEN (bit 5), YGYRO_CTEN, ZGYRO_CTEN and ACCEL_CONFIG_2 AX_ST_EN_REG
    # (bit 4), AY_, AZ_: each axis's self-test on (DS-000189; TDK eMD Icm20948Defs.h 207 and
    # 223, BIT_GYRO_CTEN 0x38 and BIT_ACCEL_CTEN 0x1C; SparkFun ICM_20948_GYRO_CONFIG_2_t and
    # ICM_20948_ACCEL_CONFIG_2_t)
    GYRO_CTEN_SHIFT: int = 3
    ACCEL_ST_EN_SHIFT: int = 2


ICM20948_REG = _ICM20948Bank0()
ICM20948_REG2 = _ICM20948Bank2()
ICM20948_REG3 = _ICM20948Bank3()
ICM20948_BITS = _ICM20948Bits()

#: Gyro DLPF settings with GYRO_FCHOICE = 1, the internal rate then 1125 Hz, one row per
#: GYRO_DLPFCFG: the 3 dB and noise bandwidths of DS-000189's GYRO_CONFIG_1 table, ✓✓ with
#: SparkFun's qwiic_icm20948.py lines 107-115 (``gyr_d196bw6_n229bw8`` ...: "A is integer part
#: of 3db BW ... X is integer part of nyquist bandwidth", the table's NBW column) and the same
#: names in SparkFun's ICM_20948_ENUMERATIONS.h. No delay per setting is published: each
#: row's ``delay_s`` is None and the emulated delay is its stand-in filter's own (⚠ not a
#: datasheet figure; 0.73 ms at 196.6 Hz to 27.9 ms at 5.7 Hz). Searched: DS-000189's
#: GYRO_CONFIG_1 and ACCEL_CONFIG tables (3 dB bandwidth, NBW and rate columns only), SparkFun's
#: names (bandwidths only), TDK's eMD (Icm20948Defs.h, Icm20948SelfTest.c); one open header
#: (``gyro_config.h``, "ICM-20948 ... Table 35"; its repository is not named by the code
#: index) does print a delay column, but its rows (250,
#: 176, 92 ... Hz; 0.97, 1.9, 2.8 ... ms) are the MPU-9250's CONFIG table under the
#: ICM-20948's name, so it is not used.
_ICM20948_DLPF_TABLE = "DS-000189 GYRO_CONFIG_1 table ✓✓ (qwiic_icm20948.py:107-115)"
ICM20948_GYRO_FILTER: tuple[FilterSetting, ...] = (
    FilterSetting(0, 196.6, None, 229.8, _ICM20948_DLPF_TABLE),
    FilterSetting(1, 151.8, None, 187.6, _ICM20948_DLPF_TABLE),
    FilterSetting(2, 119.5, None, 154.3, _ICM20948_DLPF_TABLE),
    FilterSetting(3, 51.2, None, 73.3, _ICM20948_DLPF_TABLE),
    FilterSetting(4, 23.9, None, 35.9, _ICM20948_DLPF_TABLE),
    FilterSetting(5, 11.6, None, 17.8, _ICM20948_DLPF_TABLE),
    FilterSetting(6, 5.7, None, 8.9, _ICM20948_DLPF_TABLE),
    FilterSetting(7, 361.4, None, 376.5, _ICM20948_DLPF_TABLE),
)
#: :data:`ICM20948_GYRO_FILTER` as the reader uses it: the bandwidth in Hz to GYRO_DLPFCFG.
ICM20948_DLPF: Mapping[float, int] = MappingProxyType(
    {f.bandwidth_hz: f.code for f in ICM20948_GYRO_FILTER}
)

#: Accelerometer DLPF settings with ACCEL_FCHOICE = 1 (its reset value), the internal rate
#: 1125 Hz, one row per ACCEL_DLPFCFG (ACCEL_CONFIG bits 5:3, reset 0): DS-000189's
#: ACCEL_CONFIG table, 3 dB and noise bandwidths, ✓✓ with SparkFun's qwiic_icm20948.py lines
#: 96-104 (``acc_d246bw_n265bw`` ...). No delay is given (searched as for the gyro table).
_ICM20948_ACCEL_TABLE = "DS-000189 ACCEL_CONFIG table ✓✓ (qwiic_icm20948.py:96-104)"
ICM20948_ACCEL_FILTER: tuple[FilterSetting, ...] = (
    FilterSetting(0, 246.0, None, 265.0, _ICM20948_ACCEL_TABLE),
    FilterSetting(1, 246.0, None, 265.0, _ICM20948_ACCEL_TABLE),
    FilterSetting(2, 111.4, None, 136.0, _ICM20948_ACCEL_TABLE),
    FilterSetting(3, 50.4, None, 68.8, _ICM20948_ACCEL_TABLE),
    FilterSetting(4, 23.9, None, 34.4, _ICM20948_ACCEL_TABLE),
    FilterSetting(5, 11.5, None, 17.0, _ICM20948_ACCEL_TABLE),
    FilterSetting(6, 5.7, None, 8.3, _ICM20948_ACCEL_TABLE),
    FilterSetting(7, 473.0, None, 499.0, _ICM20948_ACCEL_TABLE),
)

ICM20948 = ChipFamily(
    name="icm20948",
    title="ICM-20948",
    addresses=(0x68, 0x69),  # DS-000189 I²C interface: AD0 low / high
    who_am_i_register=ICM20948_REG.WHO_AM_I,  # in bank 0
    models=(ChipModel("icm20948", 0xEA, "ICM-20948"),),
    siblings=MappingProxyType(
        {
            0xE0: "an ICM-20648 (WHO_AM_I 0xE0 ⚠), the ICM-20948 without the magnetometer; "
            "gyrocal does not drive it",
            0xE1: "an ICM-20649 (WHO_AM_I 0xE1 ⚠), the ±4000 °/s sibling; gyrocal does not "
            "drive it",
        }
    ),
    # GYRO_CONFIG_1.GYRO_FS_SEL (DS-000189 Table 1): 131, 65.5, 32.8, 16.4 LSB/(°/s)
    gyro_ranges=(
        GyroRange(0, 250.0, 131.0),
        GyroRange(1, 500.0, 65.5),
        GyroRange(2, 1000.0, 32.8),
        GyroRange(3, 2000.0, 16.4),
    ),
    fifo_capacity=512,  # bytes ⚠ (the 13-bit FIFO_COUNT allows more; the DMP's FIFO is larger)
    fifo_capacity_unit="bytes",
    reset_time_s=0.100,  # ⚠ open drivers wait 50-100 ms after DEVICE_RESET; none in DS-000189
    startup_time_s=0.035,  # DS-000189 Table 1: gyro start-up time 35 ms
    temperature_offset_c=21.0,  # DS-000189: T = (TEMP_OUT − RoomTemp_Offset)/333.87 + 21
    temperature_lsb_per_c=333.87,
    # DS-000189 Table 2 and ACCEL_CONFIG.ACCEL_FS_SEL: 01 = ±4 g, 8192 LSB/g
    accel_range=AccelRange(1, 4.0, 8192.0),
    # DS-000189 rev 1.3 §3.2 Table 2: Initial Tolerance (component-level) ±0.5 % and Zero-G
    # Initial Tolerance board-level ±50 mg ✓✓ (the datasheet and open drivers' comments quoting
    # it; component-level ±25 mg, but the sensor sits on a board); Noise Spectral Density 230
    # µg/√Hz ✓✓ (Table 2, and uutzinger/BioMedicalSensorBoard imu_solutions.md 37);
    # Cross-Axis Sensitivity ±2 % ⚠ one source
    accel_errors=AccelErrors(0.005, 0.02, (0.050, 0.050, 0.050), 230e-6,
                             "ICM-20948 DS-000189 rev 1.3 §3.2 Table 2 (cross-axis ⚠)"),
    # DS-000189 rev 1.3 §3.1 Table 1 (gyroscope): Sensitivity Scale Factor Tolerance ±1.5 %,
    # Cross-Axis Sensitivity ±2 % ⚠ one source; Initial ZRO Tolerance (board-level) ±5 °/s ✓✓
    # (Table 1 and open code quoting it)
    # Table 1 also: Rate Noise Spectral Density 0.015 °/s/√Hz ✓✓ (Table 1, and
    # uutzinger/BioMedicalSensorBoard imu_solutions.md 43 at 557d53f, which transcribes the
    # gyro's "0.015 degree/s / Hz" with Table 2's 230 µg/√Hz and ±0.026 %/°C); no
    # linear-acceleration sensitivity row: the MPU-9250's 0.1 °/s/g stands in ⚠
    gyro_errors=GyroErrors(0.015, 0.02, 5.0, "ICM-20948 DS-000189 rev 1.3 §3.1 Table 1 ⚠",
                           noise_density_dps_sqrt_hz=0.015, g_sensitivity_dps_per_g=0.1,
                           noise_source="ICM-20948 DS-000189 rev 1.3 §3.1 Table 1 (Rate Noise "
                                        "Spectral Density); g-sensitivity: stand-in, the "
                                        "MPU-9250's ⚠"),
    extra=MappingProxyType(
        {
            "internal_rate_hz": 1125.0,  # DS-000189 GYRO_SMPLRT_DIV: 1.125 kHz/(1 + div)
            # FIFO frame with ACCEL, GYRO and TEMP enabled in FIFO_EN_2: the data registers in
            # order, ACCEL_XOUT_H (0x2D) .. TEMP_OUT_L (0x3A), 14 bytes (DS-000189 FIFO_EN_2)
            "fifo_frame_bytes": 14.0,
            "fifo_sample_bytes": 14.0,  # one frame per sample
            "dlpf_off_rate_hz": 9000.0,  # GYRO_FCHOICE = 0 ⚠
            # I2C_MST_ODR_CONFIG: the duty-cycled I²C master's rate is 1.1 kHz / 2^ODR_CONFIG
            "i2c_master_duty_base_hz": 1100.0,
            "wake_time_s": 0.010,  # ⚠ as for the MPU-9250
            "accel_lsb_per_g_2g": 16384.0,  # DS-000189 Table 2
        }
    ),
)
