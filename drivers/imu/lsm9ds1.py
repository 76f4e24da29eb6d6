"""Reader for the gyroscope of the ST LSM9DS1 (accelerometer/gyroscope die).

Bring-up (hardware reference §2.6, §2.2): CTRL_REG8 = SW_RESET | IF_ADD_INC, wait 10 ms;
WHO_AM_I again; CTRL_REG8 = BDU | IF_ADD_INC (little-endian output); FIFO off; gyro axes on
(CTRL_REG4); no high-pass (CTRL_REG3_G = 0); the LPF2 output (CTRL_REG2_G.OUT_SEL = 10);
CTRL_REG6_XL.FS_XL = ±4 g (0.122 mg/LSB, Table 3); CTRL_REG1_G = ODR_G | FS_G | BW_G; wait for
start-up. With the gyro on, the accelerometer runs at the gyro's rate and shares each FIFO slot
(§2.3): every slot is gyro X, Y, Z then accelerometer X, Y, Z, both of the same sample.

Streaming (§2.7): CTRL_REG9.FIFO_EN and FIFO_CTRL.FMODE = continuous (32 slots, 34 ms at
952 Hz; when full the oldest slot is overwritten and FIFO_SRC.OVRN is set). ``read()`` reads
FIFO_SRC (FSS unread slots, OVRN), then pops the slots through the output registers. By default
one burst of 12·N bytes from OUT_X_L_G (0x18) reads N whole slots, gyro then accelerometer,
because the chip jumps from 0x1D to 0x28 and from 0x2D back to 0x18 while the gyro is on (ST §3.3,
⚠ one source); a slot leaves the FIFO when its last accelerometer byte (0x2D) is read. With
``burst_wrap=False`` each slot is read as 6 bytes at 0x18 and 6 at 0x28, the portable way.
OUT_TEMP is read once per drain (12 bits, 16 LSB/°C, 0 at 25 °C; §2.5). After an overrun the FIFO
holds the newest 32 slots, whose sample numbers cannot be known exactly: they are dropped, the
FIFO is restarted, and everything lost is reported as one gap. FIFO_SRC is read again after each
burst, because a slot overwritten while the burst runs breaks the sequence the same way. A FIFO
found full (FSS = 32, or the depth FSS showed at the last overrun) is treated as overrun too: the
next sample may overwrite the oldest slot before the burst pops it, and popping clears OVRN, so
that loss would never be flagged.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from gyrocal.drivers.errors import ConfigurationError
from gyrocal.drivers.imu.base import BLOCK_MAX, ODR_RELATIVE_TOLERANCE, ImuReader, default_band
from gyrocal.drivers.imu.chips import (
    LSM9DS1,
    LSM9DS1_BITS,
    LSM9DS1_BW_G_CUTOFF_HZ,
    LSM9DS1_ODR,
    LSM9DS1_REG,
    GyroRange,
    register_names,
)

__all__ = ["LSM9DS1Reader"]

R, B = LSM9DS1_REG, LSM9DS1_BITS
_REG_NAMES = register_names(R)
_SLOT = int(LSM9DS1.extra["fifo_sample_bytes"])  # gyro XYZ + accel XYZ, int16 each


class LSM9DS1Reader(ImuReader):
    """LSM9DS1 gyro reader over an smbus2-compatible bus.

    Parameters
    ----------
    bus, address, clock, **kwargs
        As for :class:`~gyrocal.drivers.imu.base.ImuReader` (default address 0x6B; 0x6A with SDO_A/G
        low).
    burst_wrap : bool
        Read many FIFO slots in one burst from 0x18, relying on the register wrap of ST §3.3;
        ``False`` reads each slot in two 6-byte transfers (many more bus transactions).
    """

    family = LSM9DS1
    overflow_keeps_oldest = False  # continuous mode overwrites the oldest slots

    def __init__(
        self, bus: Any, address: int | None = None, *, burst_wrap: bool = True, **kwargs: Any
    ) -> None:
        super().__init__(bus, address, **kwargs)
        self.burst_wrap = bool(burst_wrap)
        self._depth = self.family.fifo_capacity  # FIFO slots, as the chip last reported them

    def _register_names(self) -> dict[int, str]:
        return _REG_NAMES

    @classmethod
    def offered_rates_hz(cls) -> tuple[float, ...]:
        """The CTRL_REG1_G ODR_G rates of :data:`LSM9DS1_ODR`."""
        return tuple(sorted(LSM9DS1_ODR))

    def _choose_rate(self, odr_hz: float, lowpass_hz: float | None) -> tuple[float, float, Any]:
        rates = sorted(LSM9DS1_ODR)
        odr = min(rates, key=lambda r: abs(r - odr_hz))
        if not (odr_hz > 0 and abs(odr - odr_hz) <= ODR_RELATIVE_TOLERANCE * odr_hz):
            raise ConfigurationError(
                f"odr_hz={odr_hz!r} is not an LSM9DS1 gyro output data rate; choose one of "
                + ", ".join(f"{r:g}" for r in rates)
                + " Hz"
            )
        cutoffs = LSM9DS1_BW_G_CUTOFF_HZ[odr]
        if lowpass_hz is None:
            lp = default_band(cutoffs, odr)
        else:
            lp = next((c for c in cutoffs if abs(c - float(lowpass_hz)) <= 0.5), None)
            if lp is None:
                raise ConfigurationError(
                    f"lowpass_hz={lowpass_hz!r} is not an LSM9DS1 gyro bandwidth at {odr:g} Hz; "
                    "choose one of " + ", ".join(f"{c:g}" for c in sorted(set(cutoffs))) + " Hz"
                )
        return odr, lp, (LSM9DS1_ODR[odr], cutoffs.index(lp))

    def _bring_up(self, rng: GyroRange, setting: Any) -> None:
        odr_code, bw = setting
        self._write_byte(R.CTRL_REG8, B.CTRL_REG8_SW_RESET | B.CTRL_REG8_IF_ADD_INC)
        self._clock.sleep(self.family.reset_time_s)
        self._check_identity_again()
        self._write_byte(R.CTRL_REG8, B.CTRL_REG8_BDU | B.CTRL_REG8_IF_ADD_INC)
        self._write_byte(R.CTRL_REG9, 0x00)
        self._write_byte(R.FIFO_CTRL, 0x00)
        self._write_byte(R.CTRL_REG4, B.CTRL_REG4_GYRO_AXES)
        self._write_byte(R.CTRL_REG3_G, 0x00)
        # route the LPF2 output to the data registers and FIFO, so that BW_G (Table 47) is the
        # bandwidth: with the reset OUT_SEL = 00 they carry LPF1 and BW_G does nothing (Fig. 28)
        self._write_byte(R.CTRL_REG2_G, B.OUT_SEL_LPF2)
        self._verify(R.CTRL_REG2_G, B.OUT_SEL_LPF2)
        accel = self.accel_range.code << B.FS_XL_SHIFT  # ODR_XL is the gyro's while it is on
        self._write_byte(R.CTRL_REG6_XL, accel)
        self._verify(R.CTRL_REG6_XL, accel)
        ctrl1 = (odr_code << B.ODR_G_SHIFT) | (rng.code << B.FS_G_SHIFT) | bw
        self._write_byte(R.CTRL_REG1_G, ctrl1)
        self._verify(R.CTRL_REG1_G, ctrl1)
        self._clock.sleep(self.family.startup_time_s)

    def _fifo_prepare(self) -> None:
        self._write_byte(R.CTRL_REG9, B.CTRL_REG9_FIFO_EN)
        self._write_byte(R.FIFO_CTRL, B.FMODE_BYPASS << B.FMODE_SHIFT)  # empties the FIFO

    def _fifo_go(self) -> None:
        self._write_byte(R.FIFO_CTRL, B.FMODE_CONTINUOUS << B.FMODE_SHIFT)

    def _disable_fifo(self) -> None:
        self._write_byte(R.FIFO_CTRL, 0x00)
        self._write_byte(R.CTRL_REG9, 0x00)

    def _power_down(self) -> None:
        self._write_byte(R.CTRL_REG1_G, 0x00)

    def _fifo_level(self) -> tuple[int, bool, float]:
        src = self._read_byte(R.FIFO_SRC)
        n, overrun = src & B.FIFO_SRC_FSS_MASK, bool(src & B.FIFO_SRC_OVRN)
        if overrun and n:
            self._depth = n  # an overrun FIFO is full: FSS is its depth
        # A full FIFO may overwrite its oldest slot before the burst reaches it, and popping a
        # slot clears OVRN, so the loss would never be flagged: treat full as overrun.
        return n, overrun or n >= self._depth, self._clock.monotonic()

    def _overflowed(self) -> bool:
        return bool(self._read_byte(R.FIFO_SRC) & B.FIFO_SRC_OVRN)

    def _fifo_read(self, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
        if self.burst_wrap:
            data = self._read_stream(R.OUT_X_L_G, n * _SLOT, (BLOCK_MAX // _SLOT) * _SLOT)
        else:
            parts = []
            for _ in range(n):
                parts.append(self._read_stream(R.OUT_X_L_G, 6, 6))
                parts.append(self._read_stream(R.OUT_X_L_XL, 6, 6))
            data = b"".join(parts)
        words = np.frombuffer(data, dtype="<i2").reshape(n, 6)
        return words[:, :3], words[:, 3:], None

    def _temperature_counts(self) -> int:
        lo, hi = self._read_block(R.OUT_TEMP_L, 2)
        return int.from_bytes(bytes((lo, hi)), "little", signed=True)
