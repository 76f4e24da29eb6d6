"""Register-level emulated TDK ICM-42688-P for an
:class:`~gyrocal.drivers.emulated.smbus.EmulatedSMBus` (datasheet DS-000347; facts in
:data:`gyrocal.drivers.imu.chips.ICM42688P`).

What it models, register by register (bank 0 unless said):

- REG_BANK_SEL (0x76, in every bank) selects user bank 0..4; banks 1..4 are plain memory here
  (the reader needs none of them), so a reader that forgets to go back to bank 0 reads the
  wrong registers, as on the chip. They hold their datasheet reset values (GYRO_CONFIG_STATIC2
  = 0xA0 and the others of :data:`~gyrocal.drivers.imu.chips.ICM42688P_BANK_RESET`) after
  power-on and SOFT_RESET; what they configure (anti-alias and notch filters, APEX) is not
  emulated. Bank 1 holds the gyro's factory self-test codes at XG/YG/ZG_ST_DATA (0x5F-0x61),
  bank 2 the accelerometer's at XA/YA/ZA_ST_DATA (0x3B-0x3D): one real part's
  (:data:`~gyrocal.drivers.emulated.self_test.ICM42688P_FACTORY_SELF_TEST_CODES`, ⚠).
- SELF_TEST_CONFIG (0x70): each EN_G*_ST / EN_A*_ST bit moves its axis's output by the
  response its code stands for at the configured range, ``2620 / 2^(3 − FS_SEL) ·
  1.01^(code − 1)`` counts (TDK's INV_ST_OTP_EQUATION; :mod:`~gyrocal.drivers.emulated.
  self_test`), added to the output counts as a step (not through the UI filter ⚠, as the
  MPU-9250's and ICM-20948's).
- WHO_AM_I (0x75) = 0x47. DEVICE_CONFIG.SOFT_RESET restores the reset values: INTF_CONFIG0 =
  0x30 (big-endian data and FIFO count, count in bytes), TMST_CONFIG = 0x23,
  GYRO_CONFIG0 = ACCEL_CONFIG0 = 0x06 (±2000 °/s / ±16 g, 1 kHz), GYRO_CONFIG1 = 0x16,
  GYRO_ACCEL_CONFIG0 = 0x11, PWR_MGMT0 = 0 (sensors off).
- The gyro samples while PWR_MGMT0.GYRO_MODE is low-noise (11), at the GYRO_CONFIG0.GYRO_ODR
  rate, on the chip's own clock (:class:`SensorTruth.clock_ppm`); the accelerometer with it.
  With the gyro off and ACCEL_MODE low-noise, the accelerometer samples alone at
  ACCEL_CONFIG0.ACCEL_ODR, and the gyro's data (registers and FIFO) read 0x8000, the value the
  kernel's inv_icm42600_fifo_is_data_valid skips (the accelerometer's data with it off and the
  gyro on are still emulated ⚠).
- The FIFO (2048 bytes) collects while FIFO_CONFIG.FIFO_MODE is stream (01) or stop-on-full
  (1x) and FIFO_CONFIG1 enables the gyro and/or the accelerometer. Packets (DS-000347 FIFO
  packet structure; kernel ``inv_icm42600_buffer.c``): with both sensors, 16 bytes — header,
  accel X/Y/Z, gyro X/Y/Z (int16), temperature (int8, 2.07 LSB/°C about 25 °C) and a 16-bit
  timestamp; with one sensor, 8 bytes — header, that sensor's X/Y/Z, temperature. The header is
  ``ACCEL | GYRO | TMST`` where TMST (bits 3:2) is 10 for the ODR timestamp when
  TMST_CONFIG.TMST_EN is set, 11 for the FSYNC time when FIFO_CONFIG1.TMST_FSYNC_EN is set
  (emulated as 0), 00 otherwise.
- The ODR timestamp counts the chip's own time in 1 µs or, with TMST_CONFIG.TMST_RES, 16 µs
  units from reset, modulo 2^16 (TMST_DELTA_EN: the time since the previous sample instead).
  Because the chip's samples are on the same clock, consecutive timestamps differ by the
  nominal period whatever the oscillator's error.
- When the FIFO is full, stop-on-full drops new packets and stream mode drops the oldest whole
  packet (⚠ the datasheet describes stream mode only as "continuous"); either way
  INT_STATUS.FIFO_FULL_INT is set. INT_STATUS clears when read; DATA_RDY_INT is set with every
  new sample, RESET_DONE_INT after a power-on or software reset. SIGNAL_PATH_RESET.FIFO_FLUSH
  empties the FIFO. Reading FIFO_COUNTH latches the count for FIFO_COUNTL. FIFO_DATA (0x30)
  is a data port: a burst there keeps popping the FIFO, and an empty FIFO reads 0xFF (header
  bit 7: "FIFO empty"; FIFO_DATA's reset value 0xFF, DS-000347 §14.24, in the sources
  :class:`~gyrocal.drivers.imu.chips._ICM42688PRegisters` names for the reset values).
- TEMP_DATA (0x1D, 132.48 LSB/°C), ACCEL_DATA and GYRO_DATA show the latest sample.
- The output is low-passed by the UI filter: GYRO_UI_FILT_BW's bandwidth, GYRO_CONFIG1.
  GYRO_UI_FILT_ORD's order (first, second or third; second at reset), as that many equal
  first-order sections ⚠ (the shape is not published), run at the ODR with the white noise
  entering ahead of it; the accelerometer likewise by ACCEL_UI_FILT_BW (GYRO_ACCEL_CONFIG0 bits
  7:4) and ACCEL_CONFIG1.ACCEL_UI_FILT_ORD (second order at reset, 0x0D).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from gyrocal.drivers.clock import Clock
from gyrocal.drivers.emulated.banks import UserBanks
from gyrocal.drivers.emulated.imu_chips import SensorTruth, _EmulatedImu
from gyrocal.drivers.emulated.motion import MotionSource
from gyrocal.drivers.emulated.self_test import (
    ICM42688P_FACTORY_SELF_TEST_CODES,
    SelfTestLayout,
    self_test_counts,
)
from gyrocal.drivers.imu.chips import (
    ICM42688P,
    ICM42688P_BANK_RESET,
    ICM42688P_BITS,
    ICM42688P_ODR,
    ICM42688P_REG,
    ICM42688P_ST_DATA,
    ICM42688P_UI_FILT_ORDER,
    FilterSetting,
    icm42688p_bandwidth_hz,
)

__all__ = ["EmulatedICM42688P"]

_R, _B, _ST = ICM42688P_REG, ICM42688P_BITS, ICM42688P_ST_DATA
_ODR_BY_CODE = {code: hz for hz, code in ICM42688P_ODR.items()}
_RESET = {
    _R.INTF_CONFIG0: 0x30, _R.TMST_CONFIG: 0x23, _R.GYRO_CONFIG0: 0x06, _R.ACCEL_CONFIG0: 0x06,
    _R.GYRO_CONFIG1: 0x16, _R.GYRO_ACCEL_CONFIG0: 0x11,
    _R.INTF_CONFIG1: 0x91, _R.ACCEL_CONFIG1: 0x0D, _R.DRIVE_CONFIG: 0x05,
    _R.APEX_CONFIG0: 0x82, _R.FSYNC_CONFIG: 0x10, _R.INT_CONFIG1: 0x10, _R.INT_SOURCE0: 0x10,
}
#: Where the self-test codes (gyro: bank 1, accelerometer: bank 2) and SELF_TEST_CONFIG's
#: enable bits (X in the low bit) are, and how FS_SEL counts (011 = ±250 °/s and ±2 g, lower
#: codes wider ranges: TDK's ``2620 / 2^(3 − FS)``; :mod:`~gyrocal.drivers.emulated.self_test`).
_GYRO_SELF_TEST = SelfTestLayout(_ST.XG_ST_DATA, _R.SELF_TEST_CONFIG, _B.SELF_TEST_GYRO_EN_SHIFT,
                                 _R.GYRO_CONFIG0, _B.FS_SEL_SHIFT, x_in_low_bit=True,
                                 fs_mask=0x07, fs_of_base_range=3, fs_code_narrows=True)
_ACCEL_SELF_TEST = SelfTestLayout(_ST.XA_ST_DATA, _R.SELF_TEST_CONFIG,
                                  _B.SELF_TEST_ACCEL_EN_SHIFT, _R.ACCEL_CONFIG0, _B.FS_SEL_SHIFT,
                                  x_in_low_bit=True, fs_mask=0x03, fs_of_base_range=3,
                                  fs_code_narrows=True)
#: Banks 1, 2 and 4's registers that do not reset to 0 (DS-000347 §15 on;
#: :data:`~gyrocal.drivers.imu.chips.ICM42688P_BANK_RESET`), and the factory self-test codes
#: (:data:`~gyrocal.drivers.emulated.self_test.ICM42688P_FACTORY_SELF_TEST_CODES`).
_BANK_RESET = {bank: {address: value for b, address, _, value in ICM42688P_BANK_RESET if b == bank}
               for bank in {row[0] for row in ICM42688P_BANK_RESET}}
_BANK_RESET[_ST.BANK_GYRO].update(
    _GYRO_SELF_TEST.codes_reset(ICM42688P_FACTORY_SELF_TEST_CODES[:3]))
_BANK_RESET[_ST.BANK_ACCEL].update(
    _ACCEL_SELF_TEST.codes_reset(ICM42688P_FACTORY_SELF_TEST_CODES[3:]))
#: The sensor data registers before the first sample (DS-000347 reset value 0x80, 0x00; the
#: kernel's INV_ICM42600_DATA_INVALID).
_DATA_INVALID = -32768
_READ_ONLY = frozenset(
    {_R.WHO_AM_I, _R.INT_STATUS, _R.FIFO_COUNTH, _R.FIFO_COUNTL, _R.FIFO_DATA}
    | set(range(_R.TEMP_DATA1, _R.GYRO_DATA_X1 + 6))
)
#: ACCEL_CONFIG0.ACCEL_FS_SEL → ±g (DS-000347 Table 2): 000 ±16 g ... 011 ±2 g.
_ACCEL_FS_G = {0: 16, 1: 8, 2: 4, 3: 2}


class EmulatedICM42688P(UserBanks, _EmulatedImu):
    """An ICM-42688-P on the I²C bus (see the module docstring for what is modelled).

    Parameters
    ----------
    clock, motion, truth, faults, seed, subsamples
        As for :class:`~gyrocal.drivers.emulated.imu_chips.EmulatedMPU9250`.
    output_filter : bool
        Low-pass the output at the UI filter bandwidth; ``False`` passes the per-sample mean.
    """

    family = ICM42688P
    default_who_am_i = 0x47
    temperature_count_limits = (-128, 127)  # the FIFO's 8-bit temperature
    reset_values = _RESET
    read_only = _READ_ONLY
    soft_reset = (_R.DEVICE_CONFIG, _B.DEVICE_CONFIG_SOFT_RESET)
    bank_register, bank_mask, other_banks = _R.REG_BANK_SEL, 0x07, (1, 2, 3, 4)
    bank_reset_values = _BANK_RESET
    fifo_port = _R.FIFO_DATA

    def __init__(self, clock: Clock, motion: MotionSource | None = None,
                 truth: SensorTruth | None = None, *, output_filter: bool = True,
                 **kwargs: Any) -> None:
        self.output_filter = bool(output_filter)
        self._lpf: tuple[float, np.ndarray] | None = None
        self._reset_banks()
        self._power_on_t = clock.monotonic()
        super().__init__(clock, motion, truth, **kwargs)

    # -- banks, reset ---------------------------------------------------------------------------

    def _power_on_reset(self) -> None:
        self._reset_banks()  # bank 0 selected, banks 1-4 at their reset values
        self._power_on_t = self.clock.monotonic()  # the timestamp counter restarts
        super()._power_on_reset()

    def _write_register(self, register: int, value: int) -> None:
        if self._select_bank(register, value):
            return
        if self._bank:
            if self._bank in self._banks:
                self._banks[self._bank][register] = value
            return
        super()._write_register(register, value)

    def _reset_state(self) -> None:
        self._fifo = bytearray()
        self._latched: int | None = None
        self._int_status = _B.INT_STATUS_RESET_DONE  # a reset has just completed
        self._sampled = False
        self._lpf = None
        self._last_temp_c = 25.0

    def _restart_sampling(self) -> None:
        super()._restart_sampling()
        # the chip time (µs on its own oscillator) at sample 0 of the new grid
        ppm = self.truth.clock_ppm * 1e-6
        self._chip_us0 = (self.clock.monotonic() - self._power_on_t) * 1e6 * (1.0 + ppm)

    # -- configuration --------------------------------------------------------------------------

    def _gyro_on(self) -> bool:
        mode = (self._regs[_R.PWR_MGMT0] & _B.PWR_MGMT0_GYRO_MODE_MASK) >> (
            _B.PWR_MGMT0_GYRO_MODE_SHIFT)
        return mode == _B.MODE_LOW_NOISE

    def _odr_hz(self) -> float | None:
        """The gyro's ODR with the gyro in low-noise mode; else the accelerometer's with it in
        low-noise mode (the gyro's data then invalid); else ``None``."""
        if self._gyro_on():
            return _ODR_BY_CODE.get(self._regs[_R.GYRO_CONFIG0] & _B.ODR_MASK)
        if self._regs[_R.PWR_MGMT0] & _B.PWR_MGMT0_ACCEL_MODE_MASK == _B.MODE_LOW_NOISE:
            return _ODR_BY_CODE.get(self._regs[_R.ACCEL_CONFIG0] & _B.ODR_MASK)
        return None

    def _sensitivity_rad_s_per_lsb(self) -> float:
        fs = self._regs[_R.GYRO_CONFIG0] >> _B.FS_SEL_SHIFT
        return next(g for g in self.family.gyro_ranges if g.code == fs).sensitivity_rad_s_per_lsb

    def _accel_counts_1g(self) -> int:
        return 32768 // _ACCEL_FS_G[(self._regs[_R.ACCEL_CONFIG0] >> _B.FS_SEL_SHIFT) & 0x03]

    def _note_temperature(self, temperature_c: float) -> None:
        self._last_temp_c = temperature_c  # what TEMP_DATA shows

    def _gyro_trim_counts(self) -> np.ndarray | float:
        """The gyro's self-test actuation: SELF_TEST_CONFIG.EN_G*_ST with the bank-1 codes
        (:func:`~gyrocal.drivers.emulated.self_test.self_test_counts`)."""
        return self_test_counts(_GYRO_SELF_TEST, self._banks[_ST.BANK_GYRO], self._regs)

    def _accel_trim_counts(self) -> np.ndarray | float:
        """The accelerometer's self-test actuation: SELF_TEST_CONFIG.EN_A*_ST with the bank-2
        codes (ACCEL_ST_POWER, which TDK's procedure sets with them, is not required ⚠)."""
        return self_test_counts(_ACCEL_SELF_TEST, self._banks[_ST.BANK_ACCEL], self._regs)

    def cutoff_hz(self) -> float | None:
        """The emulated output filter's bandwidth: the UI filter's (GYRO_ACCEL_CONFIG0.
        GYRO_UI_FILT_BW codes 0..7; the low-latency codes are treated as ODR/2); ``None`` with
        the gyro off. A bandwidth of ODR/2 or more (codes 0 and 1 below 400 Hz) runs faster
        than the ODR (:func:`~gyrocal.drivers.emulated.imu_chips.filter_steps`)."""
        odr = self._odr_hz()
        if odr is None:
            return None
        code = self._regs[_R.GYRO_ACCEL_CONFIG0] & _B.GYRO_UI_FILT_BW_MASK
        return icm42688p_bandwidth_hz(odr, code if code <= 7 else 0)

    def accel_filter_setting(self) -> FilterSetting | None:
        """The accelerometer UI filter: GYRO_ACCEL_CONFIG0.ACCEL_UI_FILT_BW's bandwidth (the
        gyro's formula, DS-000347; reset 1) at the ODR, which the emulated accelerometer shares
        with the gyro; ``None`` with the chip not sampling."""
        odr = self._odr_hz()
        if odr is None:
            return None
        code = self._regs[_R.GYRO_ACCEL_CONFIG0] >> _B.ACCEL_UI_FILT_BW_SHIFT
        return FilterSetting(code, icm42688p_bandwidth_hz(odr, code if code <= 7 else 0), None,
                             None, "DS-000347 GYRO_ACCEL_CONFIG0.ACCEL_UI_FILT_BW")

    def accel_filter_order(self) -> int:
        """The accelerometer UI filter's order, ACCEL_CONFIG1.ACCEL_UI_FILT_ORD (the gyro's
        codes, :data:`~gyrocal.drivers.imu.chips.ICM42688P_UI_FILT_ORDER`; second at reset,
        0x0D)."""
        code = (self._regs[_R.ACCEL_CONFIG1] & _B.ACCEL_UI_FILT_ORD_MASK) >> (
            _B.ACCEL_UI_FILT_ORD_SHIFT)
        return ICM42688P_UI_FILT_ORDER.get(code, ICM42688P_UI_FILT_ORDER[0b01])

    def filter_order(self) -> int:
        """The UI filter's order, GYRO_CONFIG1.GYRO_UI_FILT_ORD (:data:`~gyrocal.drivers.imu.
        chips.ICM42688P_UI_FILT_ORDER`; second at reset, 0x16)."""
        code = (self._regs[_R.GYRO_CONFIG1] & _B.GYRO_UI_FILT_ORD_MASK) >> (
            _B.GYRO_UI_FILT_ORD_SHIFT)
        return ICM42688P_UI_FILT_ORDER.get(code, ICM42688P_UI_FILT_ORDER[0b01])

    # -- FIFO -----------------------------------------------------------------------------------

    def _fifo_mode(self) -> int:
        return self._regs[_R.FIFO_CONFIG] >> _B.FIFO_MODE_SHIFT

    def _fifo_on(self) -> bool:
        sources = _B.FIFO_CONFIG1_GYRO_EN | _B.FIFO_CONFIG1_ACCEL_EN
        return self._fifo_mode() != _B.FIFO_MODE_BYPASS and bool(
            self._regs[_R.FIFO_CONFIG1] & sources)

    def packet_bytes(self) -> int:
        """Bytes per FIFO packet for the enabled sources (16 with both, 8 with one)."""
        en = self._regs[_R.FIFO_CONFIG1]
        both = en & _B.FIFO_CONFIG1_GYRO_EN and en & _B.FIFO_CONFIG1_ACCEL_EN
        return 16 if both else 8

    def timestamp_units(self, k: np.ndarray) -> np.ndarray:
        """The 16-bit ODR timestamps of samples ``k`` of the current grid (TMST_CONFIG)."""
        cfg = self._regs[_R.TMST_CONFIG]
        res_us = 16.0 if cfg & _B.TMST_RES_16US else 1.0
        period_us = 1e6 / float(self._odr_hz() or 1.0)
        if cfg & _B.TMST_DELTA_EN:
            return np.full(np.shape(k), math.floor(period_us / res_us) & 0xFFFF, dtype=np.int64)
        chip_us = self._chip_us0 + period_us * np.asarray(k, dtype=float)
        return np.floor(chip_us / res_us).astype(np.int64) & 0xFFFF

    def _packets(self, gyro: np.ndarray, accel: np.ndarray, temp: np.ndarray,
                 ks: np.ndarray) -> bytes:
        en, n = self._regs[_R.FIFO_CONFIG1], gyro.shape[0]
        if n == 0:
            return b""
        big = bool(self._regs[_R.INTF_CONFIG0] & _B.INTF_CONFIG0_SENSOR_DATA_ENDIAN)
        word = ">i2" if big else "<i2"
        has_g, has_a = bool(en & _B.FIFO_CONFIG1_GYRO_EN), bool(en & _B.FIFO_CONFIG1_ACCEL_EN)
        header = (_B.HEADER_GYRO if has_g else 0) | (_B.HEADER_ACCEL if has_a else 0)
        if not self._gyro_on():  # the accelerometer alone samples
            gyro = np.full_like(gyro, _DATA_INVALID)
        cols: list[np.ndarray] = []
        if has_a:
            cols.append(accel.astype(word).view(np.uint8).reshape(n, 6))
        if has_g:
            cols.append(gyro.astype(word).view(np.uint8).reshape(n, 6))
        cols.append(temp.astype(np.int8).view(np.uint8).reshape(n, 1))
        if has_a and has_g:
            stamp = np.zeros(n, dtype=np.int64)
            tmst = self._regs[_R.TMST_CONFIG]
            if en & _B.FIFO_CONFIG1_TMST_FSYNC_EN:
                header |= _B.HEADER_TMST_FSYNC  # no FSYNC input is emulated: the time reads 0
            elif tmst & _B.TMST_EN:
                header |= _B.HEADER_TMST_ODR
                stamp = self.timestamp_units(ks)
            cols.append(stamp.astype(">u2").view(np.uint8).reshape(n, 2))
        head = np.full((n, 1), header, dtype=np.uint8)
        return np.hstack([head, *cols]).tobytes()

    def _head_tail(self, n: int) -> tuple[int, int]:
        if not self._fifo_on():
            return 0, 1
        size = self.packet_bytes()
        if self._fifo_mode() & _B.FIFO_MODE_STOP_ON_FULL:
            return max(0, self.fifo_capacity - len(self._fifo)) // size + 2, 1
        return 0, self.fifo_capacity // size + 2

    def _push(self, data: bytes) -> None:
        if not data:
            return
        cap, size = self.fifo_capacity, self.packet_bytes()
        room = cap - len(self._fifo)
        if len(data) >= room:
            self._int_status |= _B.INT_STATUS_FIFO_FULL
        if len(data) > room:
            if self._fifo_mode() & _B.FIFO_MODE_STOP_ON_FULL:
                data = data[: max(0, room) // size * size]
            else:  # stream: the oldest whole packets make room
                self._fifo += data
                excess = len(self._fifo) - cap
                del self._fifo[: -(-excess // size) * size]
                return
        self._fifo += data

    def _after_samples(self) -> None:
        """New samples: INT_STATUS.DATA_RDY_INT, and the data registers hold data."""
        self._int_status |= _B.INT_STATUS_DATA_RDY
        self._sampled = True

    def _ingest(self, gyro: np.ndarray, accel: np.ndarray, temp: np.ndarray, head: int,
                skipped: int) -> None:
        if not self._fifo_on():
            return
        n = gyro.shape[0]
        k_end = self._k + n + skipped  # _k is still the last sample of the previous sync
        ks = np.concatenate((np.arange(self._k + 1, self._k + 1 + head),
                             np.arange(k_end - (n - head) + 1, k_end + 1)))
        self._push(self._packets(gyro[:head], accel[:head], temp[:head], ks[:head]))
        if skipped:
            self._push(b"\xff" * (skipped * self.packet_bytes()))  # dropped or overwritten
        self._push(self._packets(gyro[head:], accel[head:], temp[head:], ks[head:]))

    # -- registers ------------------------------------------------------------------------------

    def _count(self) -> int:
        n = len(self._fifo)
        if self._regs[_R.INTF_CONFIG0] & _B.INTF_CONFIG0_FIFO_COUNT_REC:
            n //= self.packet_bytes()
        return n

    def _read_register(self, register: int) -> int:
        banked = self._banked_read(register)
        if banked is not None:
            return banked
        r = _R
        if register == r.WHO_AM_I:
            return self.who_am_i
        if register == r.INT_STATUS:
            v, self._int_status = self._int_status, 0
            return v
        big_count = bool(self._regs[r.INTF_CONFIG0] & _B.INTF_CONFIG0_FIFO_COUNT_ENDIAN)
        if register in (r.FIFO_COUNTH, r.FIFO_COUNTL):
            first = r.FIFO_COUNTH if big_count else r.FIFO_COUNTL
            if register == first or self._latched is None:
                self._latched = self._count()
            count = self._latched
            if register != first:
                self._latched = None
            high = register == r.FIFO_COUNTH
            return (count >> 8) & 0xFF if high else count & 0xFF
        if register == r.FIFO_DATA:
            return self._read_port_byte()
        if r.TEMP_DATA1 <= register < r.GYRO_DATA_X1 + 6:
            s = self._latest
            reg_lsb = self.family.extra["register_temperature_lsb_per_c"]
            t = int(np.clip(round((self._last_temp_c - 25.0) * reg_lsb), -32768, 32767))
            big = bool(self._regs[r.INTF_CONFIG0] & _B.INTF_CONFIG0_SENSOR_DATA_ENDIAN)
            gyro = s.gyro if self._gyro_on() else np.full(3, _DATA_INVALID)
            words = np.concatenate(([t], s.accel, gyro)) if self._sampled else np.full(
                7, _DATA_INVALID)
            words = words.astype(">i2" if big else "<i2")
            return words.tobytes()[register - r.TEMP_DATA1]
        return self._regs[register]

    def _store(self, register: int, value: int) -> None:
        if register == _R.SIGNAL_PATH_RESET:
            if value & _B.SIGNAL_PATH_RESET_FIFO_FLUSH:
                self._fifo.clear()
                self._latched = None
            return  # the bits clear themselves
        self._regs[register] = value
