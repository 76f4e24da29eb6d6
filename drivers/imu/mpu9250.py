"""Reader for the InvenSense/TDK MPU-9250 gyro (also MPU-9255, and MPU-6500 with a notice).

Bring-up (hardware reference §1.3): H_RESET, wait 100 ms; SIGNAL_PATH_RESET, wait 100 ms;
PWR_MGMT_1 = CLKSEL auto (PLL), wait 10 ms; WHO_AM_I again; all axes on; CONFIG (DLPF_CFG, and
FIFO_MODE = 1 so a full FIFO keeps its oldest data and never tears a frame), SMPLRT_DIV,
GYRO_CONFIG (FS_SEL, FCHOICE_B = 00), ACCEL_CONFIG (±4 g, the family's ``accel_range``; the
accelerometer samples at the same SMPLRT_DIV rate); wait for the gyro to start.

Streaming (§1.7): FIFO_EN = ACCEL | TEMP | GYRO_XYZ gives 14-byte big-endian frames
``AX AY AZ TEMP GX GY GZ`` in register order (register map §4.7 FIFO_EN; ACCEL_XOUT_H 0x3B,
TEMP_OUT_H 0x41, GYRO_XOUT_H 0x43): 36 frames in the 512-byte FIFO, 36 ms at 1 kHz (64 ms
without the accelerometer). ``read()`` latches FIFO_COUNT (2 bytes from
FIFO_COUNTH), pops the whole frames from the FIFO_R_W data port in one ``i2c_rdwr`` burst (or in
32-byte block reads on a bus without it), then reads INT_STATUS. With FIFO_MODE = 1 a full FIFO
drops only newer samples, so if FIFO_OFLOW_INT is set the frames just read are still delivered;
the FIFO is then reset (as the kernel does) and the lost samples are reported as a gap. Reading
INT_STATUS clears it, so a failed read of it (other than a NACK) is not retried: an overflow
cannot be ruled out, and the reader restarts the FIFO and reports a gap just the same.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from gyrocal.drivers.imu.base import BLOCK_MAX, ImuReader, divided_rate, filter_band
from gyrocal.drivers.imu.chips import (
    MPU9250,
    MPU9250_BITS,
    MPU9250_DLPF,
    MPU9250_REG,
    GyroRange,
    register_names,
)

__all__ = ["MPU9250Reader"]

R, B = MPU9250_REG, MPU9250_BITS
_REG_NAMES = register_names(R)


class MPU9250Reader(ImuReader):
    """MPU-9250 / MPU-9255 / MPU-6500 gyro reader over an smbus2-compatible bus.

    Parameters
    ----------
    bus, address, clock, **kwargs
        As for :class:`~gyrocal.drivers.imu.base.ImuReader` (default address 0x68; 0x69 with AD0
        high).
    temperature_in_fifo : bool
        Put TEMP_OUT in every FIFO frame (14-byte frames, 36 in the FIFO). With ``False`` the
        frames are 12 bytes (42 fit, 42 ms at 1 kHz) and TEMP_OUT is read once per drain.
    """

    family = MPU9250

    def __init__(
        self,
        bus: Any,
        address: int | None = None,
        *,
        temperature_in_fifo: bool = True,
        **kwargs: Any,
    ) -> None:
        super().__init__(bus, address, **kwargs)
        self.temperature_in_fifo = bool(temperature_in_fifo)

    def _register_names(self) -> dict[int, str]:
        return _REG_NAMES

    @property
    def frame_bytes(self) -> int:
        """Bytes per FIFO frame: ACCEL X, Y, Z, TEMP (if in the FIFO) and GYRO X, Y, Z, 2
        bytes each."""
        return 14 if self.temperature_in_fifo else 12

    @classmethod
    def offered_rates_hz(cls) -> tuple[float, ...]:
        """1000/(1 + SMPLRT_DIV) Hz for SMPLRT_DIV 0..255 (register map §4.4; the DLPF on)."""
        base = MPU9250.extra["internal_rate_hz"]
        return tuple(base / (1 + div) for div in range(255, -1, -1))

    def _choose_rate(self, odr_hz: float, lowpass_hz: float | None) -> tuple[float, float, Any]:
        actual, div = divided_rate("MPU-9250", MPU9250.extra["internal_rate_hz"], odr_hz,
                                   "SMPLRT_DIV", (0, 1, 2, 3, 4, 7, 9, 19, 49, 99))
        lp = filter_band("MPU-9250", MPU9250_DLPF, lowpass_hz, actual)
        return actual, lp, (div, MPU9250_DLPF[lp])

    def _bring_up(self, rng: GyroRange, setting: Any) -> None:
        div, dlpf = setting
        fam, clock = self.family, self._clock
        self._write_byte(R.PWR_MGMT_1, B.PWR_MGMT_1_H_RESET)
        clock.sleep(fam.reset_time_s)
        self._write_byte(R.SIGNAL_PATH_RESET, B.SIGNAL_PATH_RESET_ALL)
        clock.sleep(fam.reset_time_s)
        self._write_byte(R.PWR_MGMT_1, B.PWR_MGMT_1_CLKSEL_AUTO)
        clock.sleep(fam.extra["wake_time_s"])
        self._check_identity_again()
        self._write_byte(R.PWR_MGMT_2, 0x00)
        config = B.CONFIG_FIFO_MODE | dlpf
        gyro_config = rng.code << B.GYRO_FS_SHIFT  # FCHOICE_B = 00: the DLPF is in use
        writes = ((R.SMPLRT_DIV, div), (R.CONFIG, config), (R.GYRO_CONFIG, gyro_config),
                  (R.ACCEL_CONFIG, self.accel_range.code << B.ACCEL_FS_SHIFT))
        for reg, value in writes:
            self._write_byte(reg, value)
        for reg, value in writes:
            self._verify(reg, value)
        clock.sleep(fam.startup_time_s)

    def _fifo_sources(self) -> int:
        gyro = B.FIFO_EN_GYRO_X | B.FIFO_EN_GYRO_Y | B.FIFO_EN_GYRO_Z | B.FIFO_EN_ACCEL
        return gyro | (B.FIFO_EN_TEMP if self.temperature_in_fifo else 0)

    def _fifo_prepare(self) -> None:
        # the kernel's order (§1.7): reset, choose sources, then enable (in _fifo_go)
        self._write_byte(R.USER_CTRL, B.USER_CTRL_FIFO_RST)
        self._write_byte(R.FIFO_EN, self._fifo_sources())
        self._read_byte(R.INT_STATUS)  # clears a FIFO_OFLOW_INT left from before

    def _fifo_go(self) -> None:
        self._write_byte(R.USER_CTRL, B.USER_CTRL_FIFO_EN)

    def _disable_fifo(self) -> None:
        self._write_byte(R.FIFO_EN, 0x00)
        self._write_byte(R.USER_CTRL, 0x00)

    def _power_down(self) -> None:
        self._write_byte(R.PWR_MGMT_1, B.PWR_MGMT_1_SLEEP | B.PWR_MGMT_1_CLKSEL_AUTO)

    def _fifo_level(self) -> tuple[int, bool, float]:
        hi, lo = self._read_block(R.FIFO_COUNTH, 2)  # reading COUNTH latches both bytes
        # FIFO_OFLOW_INT is asked after the burst (_overflowed), which also covers this drain
        return (((hi & 0x1F) << 8) | lo) // self.frame_bytes, False, self._clock.monotonic()

    def _overflowed(self) -> bool:
        # reading INT_STATUS clears it, so a read that failed after the byte moved is not
        # retried (only NACKs are): the reader restarts the FIFO as after an overflow
        return bool(self._read_byte(R.INT_STATUS, retry=False) & B.INT_STATUS_FIFO_OFLOW)

    def _fifo_read(self, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
        frame = self.frame_bytes
        data = self._read_stream(R.FIFO_R_W, n * frame, (BLOCK_MAX // frame) * frame)
        words = np.frombuffer(data, dtype=">i2").reshape(n, frame // 2)
        if self.temperature_in_fifo:
            return words[:, 4:7], words[:, 0:3], words[:, 3].astype(np.float64)
        return words[:, 3:6], words[:, 0:3], None

    def _temperature_counts(self) -> int:
        hi, lo = self._read_block(R.TEMP_OUT_H, 2)
        return int.from_bytes(bytes((hi, lo)), "big", signed=True)

