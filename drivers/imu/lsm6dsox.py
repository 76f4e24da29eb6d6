"""Reader for the gyro of the ST LSM6DSOX (and LSM6DSO, which shares its identity; datasheet
DS12814, FIFO application note AN5272; facts in :data:`gyrocal.drivers.imu.chips.LSM6DSOX`).

Identification: WHO_AM_I (0x0F) = 0x6C, which the LSM6DSO, LSM6DSOX, LSM6DSO32 and LSM6DSO32X
share; the reader says so once (a :class:`~gyrocal.drivers.imu.base.ChipNotice`). A chip left
on its embedded-functions or sensor-hub page (FUNC_CFG_ACCESS bits 7/6, readable on every page)
answers something else at 0x0F; the reader then switches back to the main page and asks again.
Siblings (LSM6DSL 0x6A, LSM6DSR/ISM330DHCX 0x6B, ...) are named; the LSM9DS1 (0x68 at the same
register and addresses) is recognised as the chip to configure instead.

Bring-up: CTRL3_C = SW_RESET | IF_INC, wait; WHO_AM_I again; CTRL3_C = BDU | IF_INC; FIFO
bypass; the high-pass off (CTRL7_G); CTRL4_C.LPF1_SEL_G and CTRL6_C.FTYPE for the gyro chain's
bandwidth (AN5192 Table 14, :data:`~gyrocal.drivers.imu.chips.LSM6DSOX_GYRO_FILTER`: by default
the widest not above half the rate, LPF1 off where it ties); CTRL1_XL = ODR_XL (the gyro's rate
code; DS12814 CTRL1_XL and CTRL2_G share the codes) | FS_XL ±4 g (0.122 mg/LSB, Table 2);
CTRL10_C.TIMESTAMP_EN; CTRL2_G = ODR_G | FS_G (or FS_125); the configuration is read back; wait
for the gyro to settle.

Streaming: FIFO_CTRL3 = BDR_GY | BDR_XL, both the ODR, and FIFO_CTRL4 = DEC_TS_BATCH 01 | FIFO
mode (stop when full), so every sample takes three 7-byte words (AN5272 §9, tagged FIFO): a
TIMESTAMP word and the sample's GYRO_NC and XL_NC words, told apart by their tags (170 samples
in the 512 words, 204 ms at 833 Hz; 307 ms without the accelerometer). ``read()`` reads
FIFO_STATUS1/2 (DIFF_FIFO, in words, and the overrun flags), pops whole triples from
FIFO_DATA_OUT_TAG (0x78) in one ``i2c_rdwr`` burst (or 28-byte block reads: the output window
wraps from 0x7E to 0x78), checks every tag, and reads FIFO_STATUS2 again (FIFO_OVR_LATCHED
clears when read, so a failed read of it is not retried). OUT_TEMP is read once per drain
(256 LSB/°C, 0 at 25 °C).

Timestamps: the 32-bit timestamp counts the chip's time in 25 µs LSBs, and the sample period is
a whole number of them, so the reader numbers the samples from the timestamps
(:class:`~gyrocal.drivers.imu.base.TimestampedFifoReader`, shared with the ICM-42688-P): a jump
is a gap of exactly known size, and after a FIFO restart the first sample's number is exact.
The counter wraps only after 29.8 hours.
"""

from __future__ import annotations

import errno
from typing import Any

import numpy as np

from gyrocal.drivers.errors import ConfigurationError
from gyrocal.drivers.imu.base import (
    BLOCK_MAX,
    ODR_RELATIVE_TOLERANCE,
    TimestampedFifoReader,
    default_band,
)
from gyrocal.drivers.imu.chips import (
    LSM6DSOX,
    LSM6DSOX_BITS,
    LSM6DSOX_GYRO_FILTER,
    LSM6DSOX_MAX_READER_ODR_HZ,
    LSM6DSOX_ODR,
    LSM6DSOX_REG,
    GyroRange,
    register_names,
)

__all__ = ["LSM6DSOXReader"]

R, B = LSM6DSOX_REG, LSM6DSOX_BITS
_REG_NAMES = register_names(R)
_WORD = int(LSM6DSOX.extra["word_bytes"])
#: Words per sample: TIMESTAMP, GYRO_NC, XL_NC.
_PER_SAMPLE = int(LSM6DSOX.extra["fifo_sample_bytes"]) // _WORD


class LSM6DSOXReader(TimestampedFifoReader):
    """LSM6DSOX / LSM6DSO gyro reader over an smbus2-compatible bus.

    Parameters
    ----------
    bus, address, clock, **kwargs
        As for :class:`~gyrocal.drivers.imu.base.ImuReader` (default address 0x6A; 0x6B with
        SA0 high).
    """

    family = LSM6DSOX
    timestamp_tick_s = LSM6DSOX.extra["timestamp_resolution_s"]
    timestamp_modulus = int(LSM6DSOX.extra["timestamp_modulus"])
    bank_register = R.FUNC_CFG_ACCESS  # bits 7/6: embedded-functions or sensor-hub page
    bank_mask = B.FUNC_CFG_PAGES

    def _register_names(self) -> dict[int, str]:
        return _REG_NAMES

    @classmethod
    def offered_rates_hz(cls) -> tuple[float, ...]:
        """The actual rates (6667 Hz / 2^k) of :data:`LSM6DSOX_ODR` codes 2 and up that the
        reader streams over I²C."""
        return tuple(sorted(actual for code, (_, actual) in LSM6DSOX_ODR.items()
                            if code >= 2 and actual <= LSM6DSOX_MAX_READER_ODR_HZ))

    def _choose_rate(self, odr_hz: float, lowpass_hz: float | None) -> tuple[float, float, Any]:
        offered = {code: (nominal, actual) for code, (nominal, actual) in LSM6DSOX_ODR.items()
                   if code >= 2 and actual <= LSM6DSOX_MAX_READER_ODR_HZ}
        code = min(offered, key=lambda c: abs(offered[c][1] - odr_hz))
        actual = offered[code][1]
        if not (odr_hz > 0 and abs(actual - odr_hz) <= ODR_RELATIVE_TOLERANCE * odr_hz):
            raise ConfigurationError(
                f"odr_hz={odr_hz!r} is not an LSM6DSOX gyro output data rate gyrocal can "
                "stream over I²C; choose one of "
                + ", ".join(f"{n:g}" for n, _ in sorted(offered.values())) + " Hz"
            )
        rows = LSM6DSOX_GYRO_FILTER[code]
        if lowpass_hz is None:
            widest = default_band((r.bandwidth_hz for r in rows), actual)
            row = min((r for r in rows if r.bandwidth_hz == widest), key=lambda r: r.code)
        else:
            near = [r for r in rows if abs(r.bandwidth_hz - float(lowpass_hz)) <= 0.5]
            if not near:
                bands = sorted({r.bandwidth_hz for r in rows}, reverse=True)
                raise ConfigurationError(
                    f"lowpass_hz={lowpass_hz!r} is not an LSM6DSOX gyro bandwidth at "
                    f"{offered[code][0]:g} Hz; choose one of "
                    + ", ".join(f"{b:g}" for b in bands) + " Hz")
            row = min(near, key=lambda r: (abs(r.bandwidth_hz - float(lowpass_hz)), r.code))
        return actual, row.bandwidth_hz, (code, row.code)

    def _bring_up(self, rng: GyroRange, setting: Any) -> None:
        code, filt = setting  # ODR_G, and LPF1_SEL_G · 8 + FTYPE (LSM6DSOX_GYRO_FILTER)
        fam = self.family
        self._write_byte(R.CTRL3_C, B.CTRL3_C_SW_RESET | B.CTRL3_C_IF_INC)
        self._clock.sleep(fam.reset_time_s)
        self._check_identity_again()
        fs = B.FS_125 if rng.code == 0b100 else rng.code << B.FS_G_SHIFT
        writes = (
            (R.CTRL3_C, B.CTRL3_C_BDU | B.CTRL3_C_IF_INC),
            (R.FIFO_CTRL4, B.FIFO_MODE_BYPASS),
            (R.CTRL4_C, B.LPF1_SEL_G if filt & 0x08 else 0x00),
            (R.CTRL6_C, filt & B.FTYPE_MASK),
            (R.CTRL7_G, 0x00),
            (R.CTRL1_XL, (code << B.ODR_SHIFT) | (self.accel_range.code << B.FS_XL_SHIFT)),
            (R.CTRL10_C, B.CTRL10_C_TIMESTAMP_EN),
            (R.CTRL2_G, (code << B.ODR_SHIFT) | fs),
        )
        for reg, value in writes:
            self._write_byte(reg, value)
        for reg, value in writes:
            self._verify(reg, value)
        self._clock.sleep(fam.startup_time_s)

    def _bdr(self) -> int:
        return self._read_byte(R.CTRL2_G) >> B.ODR_SHIFT

    def _fifo_prepare(self) -> None:
        self._write_byte(R.FIFO_CTRL4, B.FIFO_MODE_BYPASS)  # empties the FIFO
        bdr = self._bdr()
        self._write_byte(R.FIFO_CTRL3, (bdr << B.BDR_GY_SHIFT) | bdr)  # BDR_XL in bits 3:0
        self._read_byte(R.FIFO_STATUS2)  # clears an overrun latched from before

    def _fifo_go(self) -> None:
        self._write_byte(R.FIFO_CTRL4, (B.DEC_TS_EVERY_BATCH << B.DEC_TS_BATCH_SHIFT)
                         | B.FIFO_MODE_FIFO)

    def _disable_fifo(self) -> None:
        self._write_byte(R.FIFO_CTRL4, B.FIFO_MODE_BYPASS)
        self._write_byte(R.FIFO_CTRL3, 0x00)

    def _power_down(self) -> None:
        self._write_byte(R.CTRL2_G, 0x00)

    def _fifo_level(self) -> tuple[int, bool, float]:
        s1, s2 = self._read_block(R.FIFO_STATUS1, 2)
        words = ((s2 & B.FIFO_STATUS2_DIFF_HIGH_MASK) << 8) | s1
        lost = bool(s2 & (B.FIFO_STATUS2_OVR_LATCHED | B.FIFO_STATUS2_FULL_IA))
        return words // _PER_SAMPLE, lost, self._clock.monotonic()

    def _overflowed(self) -> bool:
        status = self._read_byte(R.FIFO_STATUS2, retry=False)
        return bool(status & B.FIFO_STATUS2_OVR_LATCHED)

    def _fifo_read(self, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
        chunk = (BLOCK_MAX // _WORD) * _WORD  # four words
        data = self._read_stream(R.FIFO_DATA_OUT_TAG, n * _PER_SAMPLE * _WORD, chunk)
        words = np.frombuffer(data, dtype=np.uint8).reshape(n, _PER_SAMPLE, _WORD)
        tags = words[:, :, 0] >> B.TAG_SENSOR_SHIFT
        gyro_first = tags[:, 1] == B.TAG_GYRO
        second = np.where(gyro_first, tags[:, 2], tags[:, 1])
        first = np.where(gyro_first, tags[:, 1], tags[:, 2])
        ok = (tags[:, 0] == B.TAG_TIMESTAMP) & (first == B.TAG_GYRO) & (second == B.TAG_ACCEL)
        if not ok.all():
            i = int(np.flatnonzero(~ok)[0])
            raise OSError(
                errno.EBADMSG,
                f"FIFO sample {i} of {n} has the tags "
                + ", ".join(f"0x{t:02X}" for t in tags[i])
                + "; expected a TIMESTAMP (0x04) word, then GYRO_NC (0x01) and XL_NC (0x02)",
            )
        self._stamps = words[:, 0, 1:5].copy().view("<u4").reshape(n).astype(np.int64)
        data6 = words[:, 1:, 1:7].copy().view("<i2").reshape(n, 2, 3)
        pick = np.where(gyro_first, 0, 1)
        rows = np.arange(n)
        return data6[rows, pick], data6[rows, 1 - pick], None

    def _temperature_counts(self) -> int:
        lo, hi = self._read_block(R.OUT_TEMP_L, 2)
        return int.from_bytes(bytes((lo, hi)), "little", signed=True)
