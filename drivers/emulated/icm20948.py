"""Register-level emulated TDK ICM-20948 for an
:class:`~gyrocal.drivers.emulated.smbus.EmulatedSMBus` (datasheet DS-000189; facts in
:data:`gyrocal.drivers.imu.chips.ICM20948`).

What it models:

- Four user banks of 128 registers; REG_BANK_SEL (0x7F, USER_BANK in bits 5:4) is in every bank
  and selects the one the other addresses reach. Bank 0 holds identity, power, data, interrupt
  status and FIFO; bank 2 the gyro and accelerometer configuration; banks 1 and 3 are plain
  memory here.
- WHO_AM_I (bank 0, 0x00) = 0xEA. Reset values PWR_MGMT_1 = 0x41 (asleep, clock auto), GYRO_
  CONFIG_1 = 0x01 (DLPF on, ±250 °/s), the rest 0; PWR_MGMT_1.DEVICE_RESET restores them and
  selects bank 0.
- The gyro samples while awake and not disabled (PWR_MGMT_2), at 1125 Hz / (1 + GYRO_SMPLRT_DIV)
  with GYRO_FCHOICE = 1, 9 kHz with it 0 (⚠), on the chip's own clock; with GYRO_FCHOICE = 1
  its DLPF (GYRO_DLPFCFG's row of :data:`~gyrocal.drivers.imu.chips.ICM20948_GYRO_FILTER`:
  its 3 dB bandwidth, a first-order stand-in ⚠ whose noise bandwidth is within 7 % of the
  table's NBW; DS-000189 gives no delay) runs at 1125 Hz ahead of the divider, the white noise
  entering ahead of it; the accelerometer's DLPF (ACCEL_CONFIG.ACCEL_DLPFCFG with
  ACCEL_FCHOICE = 1, the reset: 246 Hz; :data:`~gyrocal.drivers.imu.chips.
  ICM20948_ACCEL_FILTER`) likewise.
- Data registers (bank 0) big-endian: ACCEL_XOUT_H 0x2D, GYRO_XOUT_H 0x33, TEMP_OUT_H 0x39
  (333.87 LSB/°C, 0 at 21 °C).
- FIFO (512 bytes ⚠): frames of the sources FIFO_EN_2 enables, in register order (accelerometer,
  gyro X/Y/Z, temperature ⚠), big-endian, written while USER_CTRL.FIFO_EN is set; FIFO_RST
  empties it; FIFO_MODE bit 0 set (snapshot) drops new frames when full, clear (stream)
  overwrites the oldest; either way INT_STATUS_2.FIFO_OVERFLOW_INT is set, cleared when read.
  Reading FIFO_COUNTH latches the 13-bit count for FIFO_COUNTL; FIFO_R_W (0x72) is a data port
  that a burst keeps popping, and an empty FIFO repeats the last byte.
- INT_STATUS_1.RAW_DATA_0_RDY_INT is set with every new sample and cleared when read (R/C);
  INT_STATUS_2 likewise for the FIFO overflow.
- Gyro offset: XG_OFFS_USR..ZG_OFFS_USR (bank 2, 0x03–0x08, int16 big-endian) are added to the
  output as the MPU-9250's X_OFFS_USR are, ``X_OFFS_USR · 4 / 2^GYRO_FS_SEL`` counts ⚠
  (:data:`~gyrocal.drivers.imu.chips.GYRO_OFFSET_COUNTS_PER_CODE_FS0`).
- Reset values of bank 2: GYRO_CONFIG_1 = 0x01 and ACCEL_CONFIG = 0x01 (ACCEL_FCHOICE; DS-000189
  ACCEL_CONFIG reset value, also in open register headers that transcribe it).
- Self-test: bank 1 SELF_TEST_X/Y/Z_GYRO (0x02-0x04) and _ACCEL (0x0E-0x10) hold factory codes
  (:data:`~gyrocal.drivers.emulated.self_test.FACTORY_SELF_TEST_CODES`, a stand-in ⚠), and
  bank 2 GYRO_CONFIG_2.XGYRO_CTEN..ZGYRO_CTEN and ACCEL_CONFIG_2.AX_ST_EN..AZ_ST_EN move each
  axis's output by the response its code stands for at the configured range, as on the
  MPU-9250 (:mod:`~gyrocal.drivers.emulated.self_test`).
- The I²C master (USER_CTRL.I2C_MST_EN; bank 3 SLV0–SLV4, bank 0 I2C_MST_STATUS, cleared when
  read, and EXT_SLV_SENS_DATA_00..23; :mod:`~gyrocal.drivers.emulated.i2c_master`) runs one cycle
  per gyro sample, with the AK09916 magnetometer die
  (:class:`~gyrocal.drivers.emulated.magnetometers.EmulatedAK09916`) at 0x0C on its auxiliary
  bus, measuring a true field that turns with the sensor. USER_CTRL.I2C_MST_RST clears itself.
  With LP_CONFIG.I2C_MST_CYCLE set (reset value 0x40) the master is duty-cycled at 1.1 kHz /
  2^I2C_MST_ODR_CONFIG instead (DS-000189 LP_CONFIG, I2C_MST_ODR_CONFIG): a driver that never
  clears it sees that rate whatever its gyro rate.
  With INT_PIN_CFG.BYPASS_EN set and the master off the die answers on the host bus.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from gyrocal.drivers.clock import Clock
from gyrocal.drivers.emulated.banks import UserBanks
from gyrocal.drivers.emulated.i2c_master import AuxI2CMaster, MasterLayout
from gyrocal.drivers.emulated.imu_chips import SensorTruth, _EmulatedImu
from gyrocal.drivers.emulated.magnetometers import EmulatedAK09916, MagneticField
from gyrocal.drivers.emulated.motion import MotionSource
from gyrocal.drivers.emulated.self_test import (
    FACTORY_SELF_TEST_CODES,
    SelfTestLayout,
    self_test_counts,
)
from gyrocal.drivers.emulated.smbus import I2CDevice
from gyrocal.drivers.imu.chips import (
    GYRO_OFFSET_COUNTS_PER_CODE_FS0,
    ICM20948,
    ICM20948_ACCEL_FILTER,
    ICM20948_BITS,
    ICM20948_GYRO_FILTER,
    ICM20948_REG,
    ICM20948_REG1,
    ICM20948_REG2,
    ICM20948_REG3,
    FilterSetting,
)

__all__ = ["AK09916_ADDRESS", "EmulatedICM20948"]

_R, _R1, _R2, _R3, _B = (ICM20948_REG, ICM20948_REG1, ICM20948_REG2, ICM20948_REG3,
                         ICM20948_BITS)
_READ_ONLY = frozenset(
    {_R.WHO_AM_I, _R.I2C_MST_STATUS, _R.INT_STATUS_1, _R.INT_STATUS_2, _R.FIFO_COUNTH,
     _R.FIFO_COUNTL, _R.FIFO_R_W}
    | set(range(_R.ACCEL_XOUT_H, _R.TEMP_OUT_H + 2))
    | set(range(_R.EXT_SLV_SENS_DATA_00, _R.EXT_SLV_SENS_DATA_00 + 24))
)
#: Where the self-test codes (bank 1) and their enable bits and ranges (bank 2) are.
_GYRO_SELF_TEST = SelfTestLayout(_R1.SELF_TEST_X_GYRO, _R2.GYRO_CONFIG_2, _B.GYRO_CTEN_SHIFT,
                                 _R2.GYRO_CONFIG_1, _B.GYRO_FS_SEL_SHIFT)
_ACCEL_SELF_TEST = SelfTestLayout(_R1.SELF_TEST_X_ACCEL, _R2.ACCEL_CONFIG_2,
                                  _B.ACCEL_ST_EN_SHIFT, _R2.ACCEL_CONFIG, _B.ACCEL_FS_SEL_SHIFT)
#: Bank 1 reset values: the factory self-test codes.
_BANK1_RESET = {**_GYRO_SELF_TEST.codes_reset(FACTORY_SELF_TEST_CODES[:3]),
                **_ACCEL_SELF_TEST.codes_reset(FACTORY_SELF_TEST_CODES[3:])}
#: Where the AK09916 sits on the auxiliary bus (and on the host bus in bypass).
AK09916_ADDRESS = 0x0C
_MASTER = MasterLayout(
    slv0_addr=_R3.I2C_SLV0_ADDR, slv_stride=4, slv0_do=_R3.I2C_SLV0_ADDR + 3, do_stride=4,
    slv4_addr=_R3.I2C_SLV4_ADDR, slv4_reg=_R3.I2C_SLV4_REG, slv4_ctrl=_R3.I2C_SLV4_CTRL,
    slv4_do=_R3.I2C_SLV4_DO, slv4_di=_R3.I2C_SLV4_DI, ext_sens_data_00=_R.EXT_SLV_SENS_DATA_00)
#: Bank 2 reset values (DS-000189 register map): GYRO_CONFIG_1 and ACCEL_CONFIG = FCHOICE.
_BANK2_RESET = {_R2.GYRO_CONFIG_1: _B.GYRO_FCHOICE, _R2.ACCEL_CONFIG: _B.ACCEL_FCHOICE}
_DLPF_BY_CFG = {f.code: f for f in ICM20948_GYRO_FILTER}
_GYRO_ORDER = ((_B.FIFO_EN_2_GYRO_X, 0), (_B.FIFO_EN_2_GYRO_Y, 1), (_B.FIFO_EN_2_GYRO_Z, 2))


class EmulatedICM20948(UserBanks, _EmulatedImu):
    """An ICM-20948 on the I²C bus (see the module docstring for what is modelled).

    Parameters
    ----------
    clock, motion, truth, faults, seed, subsamples
        As for :class:`~gyrocal.drivers.emulated.imu_chips.EmulatedMPU9250`.
    output_filter : bool
        The gyro DLPF at the GYRO_CONFIG_1 setting (:meth:`cutoff_hz`), running at the
        internal 1125 Hz ahead of GYRO_SMPLRT_DIV; ``False`` passes the per-sample mean rate
        through unfiltered.
    """

    family = ICM20948
    filters_at_internal_rate = True
    default_who_am_i = 0xEA
    reset_values = {_R.PWR_MGMT_1: 0x41, _R.LP_CONFIG: _B.LP_CONFIG_I2C_MST_CYCLE}
    read_only = _READ_ONLY
    soft_reset = (_R.PWR_MGMT_1, _B.PWR_MGMT_1_DEVICE_RESET)
    bank_register, bank_shift, bank_mask = _R.REG_BANK_SEL, _B.BANK_SHIFT, _B.BANK_MASK
    other_banks = (1, 2, 3)
    bank_reset_values = {1: _BANK1_RESET, 2: _BANK2_RESET}
    fifo_port = _R.FIFO_R_W

    def __init__(self, clock: Clock, motion: MotionSource | None = None,
                 truth: SensorTruth | None = None, *, output_filter: bool = True,
                 **kwargs: Any) -> None:
        self.output_filter = bool(output_filter)
        self._reset_banks()
        super().__init__(clock, motion, truth, **kwargs)
        #: Devices on the auxiliary I²C bus by address: the AK09916 die.
        self.aux: dict[int, I2CDevice] = {
            AK09916_ADDRESS: EmulatedAK09916(clock, MagneticField(self.motion),
                                             seed=kwargs.get("seed", 0))}
        self.master = AuxI2CMaster(_MASTER, self.aux)

    @property
    def bypass_open(self) -> bool:
        """Whether the auxiliary bus is switched onto the host bus: INT_PIN_CFG.BYPASS_EN set
        and USER_CTRL.I2C_MST_EN clear (DS-000189 INT_PIN_CFG, USER_CTRL)."""
        r = self._regs
        return bool(r[_R.INT_PIN_CFG] & _B.INT_PIN_CFG_BYPASS_EN) and not (
            r[_R.USER_CTRL] & _B.USER_CTRL_I2C_MST_EN)

    def _power_on_reset(self) -> None:
        self._reset_banks()
        super()._power_on_reset()

    def _write_register(self, register: int, value: int) -> None:
        if self._select_bank(register, value):
            return
        if not self._bank:
            super()._write_register(register, value)
            return
        odr_before = self._odr_hz()
        self._banks[self._bank][register] = value
        if self._odr_hz() != odr_before:
            self._restart_sampling()

    def _reset_state(self) -> None:
        self._fifo = bytearray()
        self._fifo_last = 0
        self._latched: int | None = None
        self._overflow = False
        self._data_ready = False
        self._mst_status = 0
        self._master_k = -1

    def _after_samples(self) -> None:
        """New samples: INT_STATUS_1's data-ready bit, then, unless the master is duty-cycled
        (:meth:`_master_period`), one I²C master cycle at the gyro's rate."""
        self._data_ready = True
        if self._master_period() is None:
            self._master_cycle()

    def _master_cycle(self) -> None:
        """One I²C master cycle while USER_CTRL.I2C_MST_EN is set (slave registers in bank 3,
        I2C_MST_STATUS and EXT_SLV_SENS_DATA in bank 0)."""
        if self._regs[_R.USER_CTRL] & _B.USER_CTRL_I2C_MST_EN:
            self._mst_status |= self.master.cycle(self._banks[3], self._regs)

    def _master_period(self) -> float | None:
        """The duty-cycled master's period, s: with LP_CONFIG.I2C_MST_CYCLE set (its reset
        value) the master runs at 1.1 kHz / 2^I2C_MST_ODR_CONFIG (DS-000189 LP_CONFIG and
        I2C_MST_ODR_CONFIG); None when it runs at the gyro's rate."""
        if not self._regs[_R.LP_CONFIG] & _B.LP_CONFIG_I2C_MST_CYCLE:
            return None
        n = self._banks[3][_R3.I2C_MST_ODR_CONFIG] & _B.I2C_MST_ODR_CONFIG_MASK
        return 2**n / self.family.extra["i2c_master_duty_base_hz"]

    def _sync(self) -> None:
        super()._sync()
        self._duty_cycled_master()

    def _duty_cycled_master(self) -> None:
        """Run the duty-cycled master once if one of its cycles (on a grid from power-on) has
        begun since the last bus access; repeating a cycle within one access changes nothing
        a host can see, so one stands for several."""
        period = self._master_period()
        if period is None:
            return
        k = math.floor((self.clock.monotonic() - self._created) / period)
        if k != self._master_k:
            self._master_k = k
            self._master_cycle()

    def _gyro_trim_counts(self) -> np.ndarray | float:
        """XG/YG/ZG_OFFS_USR (bank 2) as output counts at the configured range, plus any
        self-test actuation (:func:`~gyrocal.drivers.emulated.self_test.self_test_counts`)."""
        trim = self_test_counts(_GYRO_SELF_TEST, self._banks[1], self._banks[2])
        raw = bytes(self._banks[2][_R2.XG_OFFS_USRH:_R2.XG_OFFS_USRH + 6])
        if not any(raw):
            return trim
        fs = (self._banks[2][_R2.GYRO_CONFIG_1] & _B.GYRO_FS_SEL_MASK) >> _B.GYRO_FS_SEL_SHIFT
        codes = np.frombuffer(raw, dtype=">i2").astype(float)
        return trim + codes * GYRO_OFFSET_COUNTS_PER_CODE_FS0 / 2**fs

    def _accel_trim_counts(self) -> np.ndarray | float:
        """The accelerometer's self-test actuation (ACCEL_CONFIG_2, bank 2)."""
        return self_test_counts(_ACCEL_SELF_TEST, self._banks[1], self._banks[2])

    # -- configuration --------------------------------------------------------------------------

    def _odr_hz(self) -> float | None:
        r, b2 = self._regs, self._banks[2]
        if r[_R.PWR_MGMT_1] & _B.PWR_MGMT_1_SLEEP:
            return None
        if r[_R.PWR_MGMT_2] & _B.PWR_MGMT_2_DISABLE_GYRO == _B.PWR_MGMT_2_DISABLE_GYRO:
            return None
        if not b2[_R2.GYRO_CONFIG_1] & _B.GYRO_FCHOICE:
            return self.family.extra["dlpf_off_rate_hz"]
        return self.family.extra["internal_rate_hz"] / (1 + b2[_R2.GYRO_SMPLRT_DIV])

    def cutoff_hz(self) -> float | None:
        """The gyro DLPF's 3 dB bandwidth GYRO_CONFIG_1.GYRO_DLPFCFG selects with GYRO_FCHOICE
        = 1 (DS-000189 GYRO_CONFIG_1 table, :meth:`filter_setting`); ``None`` with the DLPF
        bypassed or the gyro off."""
        setting = self.filter_setting()
        return None if setting is None else setting.bandwidth_hz

    def filter_setting(self) -> FilterSetting | None:
        """The gyro DLPF's row of :data:`~gyrocal.drivers.imu.chips.ICM20948_GYRO_FILTER` for
        GYRO_CONFIG_1.GYRO_DLPFCFG with GYRO_FCHOICE = 1; ``None`` with the DLPF bypassed or
        the gyro off."""
        cfg = self._banks[2][_R2.GYRO_CONFIG_1]
        if not cfg & _B.GYRO_FCHOICE or self._odr_hz() is None:
            return None
        return _DLPF_BY_CFG[(cfg >> _B.GYRO_DLPFCFG_SHIFT) & 0x07]

    def accel_filter_setting(self) -> FilterSetting | None:
        """The accelerometer DLPF's row of :data:`~gyrocal.drivers.imu.chips.
        ICM20948_ACCEL_FILTER` for ACCEL_CONFIG.ACCEL_DLPFCFG with ACCEL_FCHOICE = 1 (the reset
        value: 246 Hz), at the internal 1125 Hz; ``None`` with it bypassed or the chip not
        sampling."""
        cfg = self._banks[2][_R2.ACCEL_CONFIG]
        if not cfg & _B.ACCEL_FCHOICE or self._odr_hz() is None:
            return None
        return ICM20948_ACCEL_FILTER[(cfg >> _B.ACCEL_DLPFCFG_SHIFT) & 0x07]

    def _sensitivity_rad_s_per_lsb(self) -> float:
        fs = (self._banks[2][_R2.GYRO_CONFIG_1] & _B.GYRO_FS_SEL_MASK) >> _B.GYRO_FS_SEL_SHIFT
        return self.family.gyro_ranges[fs].sensitivity_rad_s_per_lsb

    def _accel_counts_1g(self) -> int:
        fs = (self._banks[2][_R2.ACCEL_CONFIG] >> _B.ACCEL_FS_SEL_SHIFT) & 0x03
        return int(self.family.extra["accel_lsb_per_g_2g"]) >> fs

    # -- FIFO -----------------------------------------------------------------------------------

    def _fifo_on(self) -> bool:
        return bool(self._regs[_R.USER_CTRL] & _B.USER_CTRL_FIFO_EN)

    def _frame_bytes(self) -> int:
        en = self._regs[_R.FIFO_EN_2]
        n = 6 if en & _B.FIFO_EN_2_ACCEL else 0
        n += sum(2 for bit, _ in _GYRO_ORDER if en & bit)
        return n + (2 if en & _B.FIFO_EN_2_TEMP else 0)

    def _head_tail(self, n: int) -> tuple[int, int]:
        frame = self._frame_bytes()
        if not self._fifo_on() or frame == 0:
            return 0, 1
        if self._regs[_R.FIFO_MODE] & _B.FIFO_MODE_SNAPSHOT:
            return max(0, self.fifo_capacity - len(self._fifo)) // frame + 2, 1
        return 0, self.fifo_capacity // frame + 2

    def _frames(self, gyro: np.ndarray, accel: np.ndarray, temp: np.ndarray) -> bytes:
        en = self._regs[_R.FIFO_EN_2]
        cols = [accel] if en & _B.FIFO_EN_2_ACCEL else []
        cols += [gyro[:, axis:axis + 1] for bit, axis in _GYRO_ORDER if en & bit]
        if en & _B.FIFO_EN_2_TEMP:
            cols.append(temp[:, None])
        return np.hstack(cols).astype(">i2").tobytes() if cols else b""

    def _push(self, data: bytes) -> None:
        if not data:
            return
        cap, fifo = self.fifo_capacity, self._fifo
        if len(fifo) + len(data) > cap:
            self._overflow = True
            if self._regs[_R.FIFO_MODE] & _B.FIFO_MODE_SNAPSHOT:
                frame = self._frame_bytes()
                data = data[: max(0, cap - len(fifo)) // frame * frame]
            else:
                fifo += data
                del fifo[: len(fifo) - cap]
                return
        fifo += data

    def _ingest(self, gyro: np.ndarray, accel: np.ndarray, temp: np.ndarray, head: int,
                skipped: int) -> None:
        if not self._fifo_on() or self._regs[_R.FIFO_RST]:
            return
        self._push(self._frames(gyro[:head], accel[:head], temp[:head]))
        if skipped:
            self._push(b"\x00" * (skipped * self._frame_bytes()))  # dropped or overwritten
        self._push(self._frames(gyro[head:], accel[head:], temp[head:]))

    # -- registers ------------------------------------------------------------------------------

    def _popped(self, data: bytes) -> None:
        if data:
            self._fifo_last = data[-1]

    def _fifo_fill(self) -> int:
        return self._fifo_last  # an empty FIFO repeats the last byte read

    def _read_register(self, register: int) -> int:
        banked = self._banked_read(register)
        if banked is not None:
            return banked
        r = _R
        if register == r.WHO_AM_I:
            return self.who_am_i
        if register == r.INT_STATUS_2:
            v = _B.INT_STATUS_2_FIFO_OVERFLOW if self._overflow else 0
            self._overflow = False
            return v
        if register == r.INT_STATUS_1:
            v, self._data_ready = int(self._data_ready), False
            return v * _B.INT_STATUS_1_RAW_DATA_0_RDY
        if register == r.I2C_MST_STATUS:
            v, self._mst_status = self._mst_status, 0
            return v
        if register == r.FIFO_COUNTH:
            self._latched = len(self._fifo)
            return (self._latched >> 8) & 0x1F
        if register == r.FIFO_COUNTL:
            count = self._latched if self._latched is not None else len(self._fifo)
            self._latched = None
            return count & 0xFF
        if register == r.FIFO_R_W:
            return self._read_port_byte()
        if r.ACCEL_XOUT_H <= register < r.TEMP_OUT_H + 2:
            s = self._latest
            words = np.concatenate((s.accel, s.gyro, [s.temp])).astype(">i2").tobytes()
            return words[register - r.ACCEL_XOUT_H]
        return self._regs[register]

    def _store(self, register: int, value: int) -> None:
        if register == _R.FIFO_RST and value & _B.FIFO_RST_ALL:
            self._fifo.clear()
            self._latched = None
        if register == _R.USER_CTRL:
            value &= ~_B.USER_CTRL_I2C_MST_RST  # clears itself
        self._regs[register] = value
