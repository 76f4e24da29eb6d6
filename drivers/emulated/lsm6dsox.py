"""Register-level emulated ST LSM6DSOX for an
:class:`~gyrocal.drivers.emulated.smbus.EmulatedSMBus` (datasheet DS12814; facts in
:data:`gyrocal.drivers.imu.chips.LSM6DSOX`).

What it models:

- WHO_AM_I (0x0F) = 0x6C (ST's lsm6dsox-pid lsm6dsox_reg.h 178 LSM6DSOX_ID; SparkFun's
  qwiic_lsm6dso.py 152 WHO_AM_I_VALUE); reset values CTRL3_C = 0x04 (IF_INC; DS12814's
  register table only ⚠), the rest 0 (PIN_CTRL and CTRL9_XL are not modelled).
  CTRL3_C.SW_RESET restores them; BOOT clears itself.
- FUNC_CFG_ACCESS (0x01) bits 7/6 switch the other registers to the embedded-functions or
  sensor-hub page (plain memory here), so a reader that forgets to switch back reads the wrong
  registers, as on the chip.
- The gyro samples at CTRL2_G.ODR_G (6667 Hz / 2^k ⚠, on the chip's own clock) with the range of
  FS_G / FS_125; output registers little-endian; OUT_TEMP 256 LSB/°C about 25 °C; the
  accelerometer reads 1 g on z at CTRL1_XL's range when it is on.
- The free-running timestamp (CTRL10_C.TIMESTAMP_EN) counts the chip's time in 25 µs LSBs from
  reset (TIMESTAMP0..3, 0x40, little-endian); the sample period is a whole number of LSBs.
- The tagged FIFO (512 words of 7 bytes ⚠): while FIFO_CTRL4.FIFO_MODE is not bypass and
  FIFO_CTRL3.BDR_GY is set, each gyro sample writes (if FIFO_CTRL4.DEC_TS_BATCH = 01 and the
  timestamp is on) a TIMESTAMP word (tag 0x04; bytes 1-4 the timestamp, little-endian), then a
  GYRO_NC word (tag 0x01; X, Y, Z little-endian) and, if FIFO_CTRL3.BDR_XL is set and the
  accelerometer is on, an XL_NC word (tag 0x02) of the same sample (AN5272 §9). The tag byte is
  TAG_SENSOR << 3 | TAG_CNT << 1 (TAG_CNT counts the time slots modulo 4; the parity bit is left 0
  ⚠). The batch rate is taken to be the ODR (the chip's decimation by BDR_GY < ODR is not modelled).
  FIFO mode (001) stops when full, continuous (110) drops the oldest word; a lost word sets
  FIFO_OVR_IA while it lasts and FIFO_OVR_LATCHED until FIFO_STATUS2 is read; FIFO_FULL_IA is set
  while the FIFO is full. Bypass empties it. FIFO_STATUS1/2 give DIFF_FIFO (10 bits, words). Reading
  FIFO_DATA_OUT_Z_H (0x7E) pops a word, and with IF_INC the address wraps from 0x7E to 0x78 so a
  burst reads word after word (⚠ the kernel reads four words per transfer this way).
- STATUS_REG (0x1E): XLDA, GDA, TDA set with every new sample (XLDA while the accelerometer is
  on) and each cleared when its output registers are read ⚠ (ST's rule for its STATUS_REG,
  AN5192; the LSM9DS1 model does the same).
- The gyro's output filter is the chain of AN5192 Table 14 (:data:`~gyrocal.drivers.imu.chips.
  LSM6DSOX_GYRO_FILTER`): LPF2 alone, or with CTRL4_C.LPF1_SEL_G set LPF1 + LPF2 at
  CTRL6_C.FTYPE's bandwidth, the white noise entering ahead of it, and a pure delay making the
  output's phase delay at the table's frequency the table's (⚠ AN5192 only); the accelerometer's
  LPF2 at ODR / CTRL8_XL.HPCF_XL's divisor when CTRL1_XL.LPF2_XL_EN is set (HP_SLOPE_XL_EN clear;
  :data:`~gyrocal.drivers.imu.chips.LSM6DSOX_ACCEL_LPF2_DIVISOR`), LPF1's ODR/2 alone being the
  per-sample mean. The filters' shapes are not published: the emulator's first-order stand-in
  at the table's −3 dB bandwidth stands in (⚠); the accelerometer shares the gyro's ODR.
"""

from __future__ import annotations

import math
from collections import deque
from typing import Any

import numpy as np

from gyrocal.drivers.clock import Clock
from gyrocal.drivers.emulated.imu_chips import SensorTruth, _EmulatedImu
from gyrocal.drivers.emulated.motion import MotionSource
from gyrocal.drivers.imu.chips import (
    LSM6DSOX,
    LSM6DSOX_ACCEL_LPF2_DIVISOR,
    LSM6DSOX_BITS,
    LSM6DSOX_GYRO_PHASE_HZ,
    LSM6DSOX_ODR,
    LSM6DSOX_REG,
    FilterSetting,
    lsm6dsox_gyro_filter,
)

__all__ = ["EmulatedLSM6DSOX"]

_R, _B = LSM6DSOX_REG, LSM6DSOX_BITS
_READ_ONLY = frozenset(
    {_R.WHO_AM_I, _R.STATUS_REG, _R.FIFO_STATUS1, _R.FIFO_STATUS2}
    | set(range(_R.OUT_TEMP_L, _R.OUTX_L_A + 6))
    | set(range(_R.TIMESTAMP0, _R.TIMESTAMP0 + 4))
    | set(range(_R.FIFO_DATA_OUT_TAG, _R.FIFO_DATA_OUT_Z_H + 1))
)
#: CTRL1_XL.FS_XL → mg/LSB (DS12814 Table 2): 00 ±2 g, 01 ±16 g, 10 ±4 g, 11 ±8 g.
_ACCEL_MG_PER_LSB = {0b00: 0.061, 0b01: 0.488, 0b10: 0.122, 0b11: 0.244}
_TS_LSB_S = LSM6DSOX.extra["timestamp_resolution_s"]


class EmulatedLSM6DSOX(_EmulatedImu):
    """An LSM6DSOX on the I²C bus (see the module docstring for what is modelled).

    Parameters
    ----------
    clock, motion, truth, faults, seed, subsamples
        As for :class:`~gyrocal.drivers.emulated.imu_chips.EmulatedMPU9250`.
    output_filter : bool
        Whether the gyro and accelerometer output filters are emulated (``--sim``'s ``dlpf``
        effect); ``False`` leaves the per-sample mean.
    """

    family = LSM6DSOX
    default_who_am_i = 0x6C
    reset_values = {_R.CTRL3_C: _B.CTRL3_C_IF_INC}
    read_only = _READ_ONLY
    soft_reset = (_R.CTRL3_C, _B.CTRL3_C_SW_RESET)

    def __init__(self, clock: Clock, motion: MotionSource | None = None,
                 truth: SensorTruth | None = None, *, output_filter: bool = True,
                 **kwargs: Any) -> None:
        self.output_filter = bool(output_filter)
        self._page = bytearray(128)
        self._power_on_t = clock.monotonic()
        super().__init__(clock, motion, truth, **kwargs)

    # -- pages, reset ---------------------------------------------------------------------------

    def _paged(self) -> bool:
        return bool(self._regs[_R.FUNC_CFG_ACCESS] & _B.FUNC_CFG_PAGES)

    def _power_on_reset(self) -> None:
        self._power_on_t = self.clock.monotonic()  # the timestamp counter restarts
        super()._power_on_reset()

    def _write_register(self, register: int, value: int) -> None:
        if self._paged() and register != _R.FUNC_CFG_ACCESS:
            self._page[register] = value
            return
        super()._write_register(register, value)

    def _reset_state(self) -> None:
        self._fifo: deque[bytes] = deque()
        self._ovr_latched = False
        self._ovr_now = False
        self._slot = 0
        self._status = 0
        self._lpf = None

    def _after_samples(self) -> None:
        """New samples: STATUS_REG's GDA and TDA, and XLDA while the accelerometer is on."""
        self._status |= _B.STATUS_GDA | _B.STATUS_TDA
        if self._regs[_R.CTRL1_XL] >> _B.ODR_SHIFT:
            self._status |= _B.STATUS_XLDA

    def _restart_sampling(self) -> None:
        super()._restart_sampling()
        ppm = self.truth.clock_ppm * 1e-6
        self._chip_s0 = (self.clock.monotonic() - self._power_on_t) * (1.0 + ppm)

    # -- configuration --------------------------------------------------------------------------

    def _odr_hz(self) -> float | None:
        entry = LSM6DSOX_ODR.get(self._regs[_R.CTRL2_G] >> _B.ODR_SHIFT)
        return None if entry is None else entry[1]

    def filter_setting(self) -> FilterSetting | None:
        """The gyro chain's row of AN5192 Table 14 for CTRL2_G.ODR_G, CTRL4_C.LPF1_SEL_G and
        CTRL6_C.FTYPE (:func:`~gyrocal.drivers.imu.chips.lsm6dsox_gyro_filter`); ``None``
        with the gyro off."""
        code = self._regs[_R.CTRL2_G] >> _B.ODR_SHIFT
        if code not in LSM6DSOX_ODR:
            return None
        return lsm6dsox_gyro_filter(code, bool(self._regs[_R.CTRL4_C] & _B.LPF1_SEL_G),
                                    self._regs[_R.CTRL6_C] & _B.FTYPE_MASK)

    def _pure_delay_s(self, period: float) -> float:
        """What the table's phase delay at its frequency (AN5192 Table 14, ⚠ one source) has
        beyond the emulated path's there: the first-order stand-in's phase delay at that
        frequency and the per-sample mean's half window (as the MPU-9250's CONFIG-table
        delay is made up)."""
        setting = self.filter_setting() if self.output_filter else None
        section, rate = self._filter_section(), self._filter_rate_hz()
        if setting is None or setting.delay_s is None or section is None or rate is None:
            return 0.0
        f = LSM6DSOX_GYRO_PHASE_HZ[self._regs[_R.CTRL2_G] >> _B.ODR_SHIFT]
        k, order = section
        w = 2.0 * math.pi * f / rate
        a = (k - 1.0) / (k + 1.0)
        # one section b (1 + z⁻¹) / (1 + a z⁻¹): the numerator lags ω/2, the denominator
        # arg(1 + a e^(−jω))
        lag = order * (0.5 * w + math.atan2(-a * math.sin(w), 1.0 + a * math.cos(w)))
        boxcar = 0.5 * self._average_window_s(period) if self.subsamples > 1 else 0.0
        return max(0.0, setting.delay_s - lag / (2.0 * math.pi * f) - boxcar)

    def cutoff_hz(self) -> float | None:
        """The gyro chain's bandwidth (:meth:`filter_setting`); ``None`` with the gyro off."""
        setting = self.filter_setting()
        return None if setting is None else setting.bandwidth_hz

    def accel_filter_setting(self) -> FilterSetting | None:
        """The accelerometer's LPF2 with CTRL1_XL.LPF2_XL_EN set and CTRL8_XL.HP_SLOPE_XL_EN
        clear: ODR / HPCF_XL's divisor (AN5192 Table 10), at the gyro's ODR, which the
        emulated accelerometer shares; ``None`` otherwise (LPF1's ODR/2 is the per-sample
        mean) or with the chip not sampling."""
        odr = self._odr_hz()
        ctrl8 = self._regs[_R.CTRL8_XL]
        if (odr is None or not self._regs[_R.CTRL1_XL] & _B.LPF2_XL_EN
                or ctrl8 & _B.HP_SLOPE_XL_EN):
            return None
        hpcf = ctrl8 >> _B.HPCF_XL_SHIFT
        return FilterSetting(hpcf, odr / LSM6DSOX_ACCEL_LPF2_DIVISOR[hpcf], None, None,
                             "AN5192 Rev 5 Table 10 ✓✓ (LSM6DSO32 DocID032891 Rev 1 Table 65)")

    def _sensitivity_rad_s_per_lsb(self) -> float:
        ctrl2 = self._regs[_R.CTRL2_G]
        code = 0b100 if ctrl2 & _B.FS_125 else (ctrl2 & _B.FS_G_MASK) >> _B.FS_G_SHIFT
        return next(g for g in self.family.gyro_ranges if g.code == code).sensitivity_rad_s_per_lsb

    def _accel_counts_1g(self) -> float:
        if not self._regs[_R.CTRL1_XL] >> _B.ODR_SHIFT:
            return 0.0
        return 1000.0 / _ACCEL_MG_PER_LSB[(self._regs[_R.CTRL1_XL] >> _B.FS_XL_SHIFT) & 3]

    def timestamp_lsb(self, k: np.ndarray) -> np.ndarray:
        """The timestamps (25 µs LSBs, modulo 2^32) of samples ``k`` of the current grid."""
        period = 1.0 / float(self._odr_hz() or 1.0)
        chip_s = self._chip_s0 + period * np.asarray(k, dtype=float)
        return np.floor(chip_s / _TS_LSB_S + 1e-6).astype(np.int64) & 0xFFFFFFFF

    def _timestamp_now(self) -> int:
        ppm = self.truth.clock_ppm * 1e-6
        chip_s = (self.clock.monotonic() - self._power_on_t) * (1.0 + ppm)
        return int(chip_s / _TS_LSB_S) & 0xFFFFFFFF

    # -- FIFO -----------------------------------------------------------------------------------

    def _mode(self) -> int:
        return self._regs[_R.FIFO_CTRL4] & _B.FIFO_MODE_MASK

    def _fifo_on(self) -> bool:
        return self._mode() != _B.FIFO_MODE_BYPASS and bool(
            self._regs[_R.FIFO_CTRL3] >> _B.BDR_GY_SHIFT)

    def _with_timestamps(self) -> bool:
        dec = self._regs[_R.FIFO_CTRL4] >> _B.DEC_TS_BATCH_SHIFT
        return dec == _B.DEC_TS_EVERY_BATCH and bool(
            self._regs[_R.CTRL10_C] & _B.CTRL10_C_TIMESTAMP_EN)

    def _with_accel(self) -> bool:
        return bool(self._regs[_R.FIFO_CTRL3] & 0x0F) and bool(
            self._regs[_R.CTRL1_XL] >> _B.ODR_SHIFT)

    def _words_per_sample(self) -> int:
        return 1 + self._with_timestamps() + self._with_accel()

    def _head_tail(self, n: int) -> tuple[int, int]:
        if not self._fifo_on():
            return 0, 1
        per = self._words_per_sample()
        if self._mode() == _B.FIFO_MODE_FIFO:
            return max(0, self.fifo_capacity - len(self._fifo)) // per + 2, 1
        return 0, self.fifo_capacity // per + 2

    def _words(self, gyro: np.ndarray, accel: np.ndarray, ks: np.ndarray) -> list[bytes]:
        out = []
        stamps = self.timestamp_lsb(ks) if self._with_timestamps() else None
        with_accel = self._with_accel()
        for i in range(gyro.shape[0]):
            cnt = (self._slot & 3) << 1
            self._slot += 1
            if stamps is not None:
                ts = int(stamps[i]).to_bytes(4, "little") + b"\x00\x00"
                out.append(bytes([(_B.TAG_TIMESTAMP << _B.TAG_SENSOR_SHIFT) | cnt]) + ts)
            data = gyro[i].astype("<i2").tobytes()
            out.append(bytes([(_B.TAG_GYRO << _B.TAG_SENSOR_SHIFT) | cnt]) + data)
            if with_accel:
                data = accel[i].astype("<i2").tobytes()
                out.append(bytes([(_B.TAG_ACCEL << _B.TAG_SENSOR_SHIFT) | cnt]) + data)
        return out

    def _push(self, words: list[bytes]) -> None:
        cap, stop = self.fifo_capacity, self._mode() == _B.FIFO_MODE_FIFO
        for w in words:
            if len(self._fifo) >= cap:
                self._ovr_latched = self._ovr_now = True
                if stop:
                    continue
                self._fifo.popleft()
            self._fifo.append(w)

    def _ingest(self, gyro: np.ndarray, accel: np.ndarray, temp: np.ndarray, head: int,
                skipped: int) -> None:
        if not self._fifo_on():
            return
        n = gyro.shape[0]
        k_end = self._k + n + skipped  # _k is still the last sample of the previous sync
        ks = np.concatenate((np.arange(self._k + 1, self._k + 1 + head),
                             np.arange(k_end - (n - head) + 1, k_end + 1)))
        self._push(self._words(gyro[:head], accel[:head], ks[:head]))
        if skipped:  # dropped or overwritten
            self._slot += skipped
            self._push([b"\xff" * 7] * (skipped * self._words_per_sample()))
        self._push(self._words(gyro[head:], accel[head:], ks[head:]))

    def _pop(self) -> None:
        if self._fifo:
            self._fifo.popleft()
            self._ovr_now = False

    def _status2(self) -> int:
        n = len(self._fifo)
        v = (n >> 8) & _B.FIFO_STATUS2_DIFF_HIGH_MASK
        v |= _B.FIFO_STATUS2_OVR_IA if self._ovr_now else 0
        v |= _B.FIFO_STATUS2_FULL_IA if n >= self.fifo_capacity else 0
        v |= _B.FIFO_STATUS2_OVR_LATCHED if self._ovr_latched else 0
        self._ovr_latched = False
        return v

    # -- registers ------------------------------------------------------------------------------

    def _next_pointer(self, register: int) -> int:
        if not self._regs[_R.CTRL3_C] & _B.CTRL3_C_IF_INC:
            return register
        if register == _R.FIFO_DATA_OUT_Z_H and not self._paged():
            return _R.FIFO_DATA_OUT_TAG  # the FIFO output window wraps (⚠)
        return (register + 1) & 0x7F

    def _read_fast(self, length: int) -> bytes | None:
        """Whole words from 0x78 out of the FIFO in one step (the wrap of the output window)."""
        if (self._ptr != _R.FIFO_DATA_OUT_TAG or length % 7 or self._paged()
                or not self._regs[_R.CTRL3_C] & _B.CTRL3_C_IF_INC):
            return None
        words = []
        for _ in range(length // 7):
            words.append(self._fifo[0] if self._fifo else bytes(7))
            self._pop()
        return b"".join(words)

    def _word(self, value: int) -> bytes:
        return int(value).to_bytes(2, "little", signed=True)

    def _read_register(self, register: int) -> int:
        r = _R
        if self._paged() and register != r.FUNC_CFG_ACCESS:
            return self._page[register]
        if register == r.WHO_AM_I:
            return self.who_am_i
        if register == r.FIFO_STATUS1:
            return len(self._fifo) & 0xFF
        if register == r.FIFO_STATUS2:
            return self._status2()
        if r.TIMESTAMP0 <= register < r.TIMESTAMP0 + 4:
            return self._timestamp_now().to_bytes(4, "little")[register - r.TIMESTAMP0]
        if register == r.STATUS_REG:
            return self._status
        if r.OUT_TEMP_L <= register < r.OUTX_L_A + 6:
            self._status &= ~(_B.STATUS_TDA if register < r.OUTX_L_G else
                              _B.STATUS_GDA if register < r.OUTX_L_A else _B.STATUS_XLDA)
            s = self._latest
            words = b"".join(self._word(v) for v in (s.temp, *s.gyro, *s.accel))
            return words[register - r.OUT_TEMP_L]
        if r.FIFO_DATA_OUT_TAG <= register <= r.FIFO_DATA_OUT_Z_H:
            word = self._fifo[0] if self._fifo else bytes(7)
            if register == r.FIFO_DATA_OUT_Z_H:
                self._pop()
            return word[register - r.FIFO_DATA_OUT_TAG]
        return self._regs[register]

    def _store(self, register: int, value: int) -> None:
        if register == _R.CTRL3_C:
            value &= ~_B.CTRL3_C_BOOT  # BOOT clears itself
        self._regs[register] = value
        if register == _R.FIFO_CTRL4 and self._mode() == _B.FIFO_MODE_BYPASS:
            self._fifo.clear()
            self._ovr_now = self._ovr_latched = False
