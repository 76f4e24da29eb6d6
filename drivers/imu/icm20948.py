"""Reader for the TDK ICM-20948 gyro, the MPU-9250's successor (datasheet DS-000189; facts in
:data:`gyrocal.drivers.imu.chips.ICM20948`).

Register banks: the ICM-20948 spreads its registers over four user banks selected by
REG_BANK_SEL (0x7F, in every bank). Identity, power, data and FIFO are in bank 0; the gyro's
rate divider and configuration in bank 2. The reader selects bank 2 only to configure the gyro
and returns to bank 0 before anything else, so that every other access reaches bank 0.

Identification: WHO_AM_I (bank 0, register 0x00) = 0xEA. A chip left in another bank by an
earlier program answers something else at 0x00; REG_BANK_SEL then tells, and the reader selects
bank 0 and asks again. The MPU-9250 reader, finding an ICM-20948 where it expected its own chip,
names it ("use model 'icm20948'").

Bring-up: PWR_MGMT_1 = DEVICE_RESET, wait; PWR_MGMT_1 = clock auto (awake), wait; WHO_AM_I
again; PWR_MGMT_2 = all sensors on; bank 2: GYRO_SMPLRT_DIV, GYRO_CONFIG_1 = DLPFCFG | FS_SEL |
FCHOICE, ACCEL_SMPLRT_DIV = the gyro's divider (so both sensors sample at one rate),
ACCEL_CONFIG = ±4 g | ACCEL_FCHOICE (read back); bank 0; wait for the gyro to start (35 ms,
DS-000189 Table 1).

Streaming: FIFO_MODE = snapshot (a full FIFO keeps its oldest frames), FIFO_EN_2 = ACCEL | GYRO
X/Y/Z | TEMP gives 14-byte big-endian frames ``AX AY AZ GX GY GZ TEMP`` in register order
(ACCEL_XOUT_H 0x2D, GYRO_XOUT_H 0x33, TEMP_OUT_H 0x39; 36 in 512 bytes ⚠, 32 ms at 1125 Hz);
USER_CTRL.FIFO_EN starts collection. ``read()`` latches FIFO_COUNT (2 bytes at 0x70), pops the
whole frames from FIFO_R_W (0x72) in one ``i2c_rdwr`` burst (or 32-byte block reads), then reads
INT_STATUS_2 (FIFO_OVERFLOW_INT, cleared when read: a failed read of it is not retried), as the
MPU-9250 reader does.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from gyrocal.drivers.imu.base import BLOCK_MAX, ImuReader, divided_rate, filter_band
from gyrocal.drivers.imu.chips import (
    ICM20948,
    ICM20948_BITS,
    ICM20948_DLPF,
    ICM20948_REG,
    ICM20948_REG2,
    ChipModel,
    GyroRange,
    register_names,
)
from gyrocal.drivers.imu.errors import ChipIdentityError

__all__ = ["ICM20948Reader"]

R, R2, B = ICM20948_REG, ICM20948_REG2, ICM20948_BITS
_REG_NAMES = register_names(R)
_FRAME = int(ICM20948.extra["fifo_frame_bytes"])  # AX AY AZ GX GY GZ TEMP, 2 bytes each
_FIFO_SOURCES = (B.FIFO_EN_2_ACCEL | B.FIFO_EN_2_GYRO_X | B.FIFO_EN_2_GYRO_Y
                 | B.FIFO_EN_2_GYRO_Z | B.FIFO_EN_2_TEMP)


class ICM20948Reader(ImuReader):
    """ICM-20948 gyro reader over an smbus2-compatible bus.

    Parameters
    ----------
    bus, address, clock, **kwargs
        As for :class:`~gyrocal.drivers.imu.base.ImuReader` (default address 0x68; 0x69 with
        AD0 high).
    """

    family = ICM20948

    def _register_names(self) -> dict[int, str]:
        return _REG_NAMES

    def _bank(self, bank: int) -> None:
        self._write_byte(R.REG_BANK_SEL, bank << B.BANK_SHIFT)

    def _identify(self) -> ChipModel:
        try:
            return super()._identify()
        except ChipIdentityError:
            bank = self._read_byte(R.REG_BANK_SEL)
            if not bank & B.BANK_MASK or bank & ~B.BANK_MASK:
                raise
            self._bank(0)  # left in another user bank: back to bank 0
            return super()._identify()

    @classmethod
    def offered_rates_hz(cls) -> tuple[float, ...]:
        """1125/(1 + GYRO_SMPLRT_DIV) Hz for GYRO_SMPLRT_DIV 0..255 (DS-000189; the DLPF on)."""
        base = ICM20948.extra["internal_rate_hz"]
        return tuple(base / (1 + div) for div in range(255, -1, -1))

    def _choose_rate(self, odr_hz: float, lowpass_hz: float | None) -> tuple[float, float, Any]:
        actual, div = divided_rate("ICM-20948", ICM20948.extra["internal_rate_hz"], odr_hz,
                                   "GYRO_SMPLRT_DIV", (0, 1, 2, 4, 9, 24, 99))
        lp = filter_band("ICM-20948", ICM20948_DLPF, lowpass_hz, actual)
        return actual, lp, (div, ICM20948_DLPF[lp])

    def _bring_up(self, rng: GyroRange, setting: Any) -> None:
        div, dlpf = setting
        fam, clock = self.family, self._clock
        self._bank(0)
        self._write_byte(R.PWR_MGMT_1, B.PWR_MGMT_1_DEVICE_RESET)
        clock.sleep(fam.reset_time_s)
        self._write_byte(R.PWR_MGMT_1, B.PWR_MGMT_1_CLKSEL_AUTO)
        clock.sleep(fam.extra["wake_time_s"])
        self._check_identity_again()
        self._write_byte(R.PWR_MGMT_2, 0x00)
        config = (dlpf << B.GYRO_DLPFCFG_SHIFT) | (rng.code << B.GYRO_FS_SEL_SHIFT) | (
            B.GYRO_FCHOICE)
        accel = (self.accel_range.code << B.ACCEL_FS_SEL_SHIFT) | B.ACCEL_FCHOICE
        writes = ((R2.GYRO_SMPLRT_DIV, div), (R2.GYRO_CONFIG_1, config),
                  (R2.ACCEL_SMPLRT_DIV_1, div >> 8), (R2.ACCEL_SMPLRT_DIV_2, div & 0xFF),
                  (R2.ACCEL_CONFIG, accel))
        self._bank(2)
        try:
            for reg, value in writes:
                self._write_byte(reg, value)
            for reg, value in writes:
                self._verify(reg, value)
        finally:
            self._bank(0)
        clock.sleep(fam.startup_time_s)

    def _fifo_prepare(self) -> None:
        self._write_byte(R.USER_CTRL, 0x00)
        self._write_byte(R.FIFO_RST, B.FIFO_RST_ALL)
        self._write_byte(R.FIFO_RST, 0x00)
        self._write_byte(R.FIFO_MODE, B.FIFO_MODE_SNAPSHOT)
        self._write_byte(R.FIFO_EN_2, _FIFO_SOURCES)
        self._read_byte(R.INT_STATUS_2)  # clears an overflow left from before

    def _fifo_go(self) -> None:
        self._write_byte(R.USER_CTRL, B.USER_CTRL_FIFO_EN)

    def _disable_fifo(self) -> None:
        self._write_byte(R.FIFO_EN_2, 0x00)
        self._write_byte(R.USER_CTRL, 0x00)

    def _power_down(self) -> None:
        self._write_byte(R.PWR_MGMT_1, B.PWR_MGMT_1_SLEEP | B.PWR_MGMT_1_CLKSEL_AUTO)

    def _fifo_level(self) -> tuple[int, bool, float]:
        hi, lo = self._read_block(R.FIFO_COUNTH, 2)
        return (((hi & 0x1F) << 8) | lo) // _FRAME, False, self._clock.monotonic()

    def _overflowed(self) -> bool:
        status = self._read_byte(R.INT_STATUS_2, retry=False)
        return bool(status & B.INT_STATUS_2_FIFO_OVERFLOW)

    def _fifo_read(self, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
        data = self._read_stream(R.FIFO_R_W, n * _FRAME, (BLOCK_MAX // _FRAME) * _FRAME)
        words = np.frombuffer(data, dtype=">i2").reshape(n, _FRAME // 2)
        return words[:, 3:6], words[:, 0:3], words[:, 6].astype(np.float64)

    def _temperature_counts(self) -> int:
        hi, lo = self._read_block(R.TEMP_OUT_H, 2)
        return int.from_bytes(bytes((hi, lo)), "big", signed=True)
