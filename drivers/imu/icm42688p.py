"""Reader for the TDK ICM-42688-P gyro (datasheet DS-000347; facts in
:data:`gyrocal.drivers.imu.chips.ICM42688P`).

Identification: WHO_AM_I (0x75, bank 0) = 0x47. A chip left in another user bank by an earlier
program answers something else there; REG_BANK_SEL (0x76, readable in every bank) then tells,
and the reader selects bank 0 and asks again, as the kernel's regmap does before every access.
Siblings (ICM-42605 0x42, ICM-42686-P 0x44, ...) are named.

Bring-up: DEVICE_CONFIG.SOFT_RESET, wait 1 ms; WHO_AM_I again; INTF_CONFIG0 = big-endian data and
FIFO count, count in bytes (the reset value 0x30); GYRO_CONFIG0 = FS_SEL | ODR; ACCEL_CONFIG0 = ±4 g
(the family's ``accel_range``, 8192 LSB/g) at the same ODR (so that every FIFO packet carries both
sensors of one sample and the timestamp); GYRO_ACCEL_CONFIG0 = the UI filter bandwidth, the
accelerometer's the gyro's (by default the widest below half the ODR); TMST_CONFIG
= TMST_EN | TMST_RES (16 µs units); PWR_MGMT0 = gyro and accelerometer low-noise, then no write for
200 µs; the configuration is read back; wait for the gyro to start (60 ms, the kernel's figure).

Streaming: FIFO_CONFIG1 = ACCEL | GYRO | TEMP gives 16-byte packets (header, accel, gyro, an
8-bit temperature, a 16-bit ODR timestamp); FIFO_CONFIG = stop-on-full starts collection (128
packets, 128 ms at 1 kHz). ``read()`` reads FIFO_COUNT (2 bytes, big-endian, in bytes), pops the
whole packets from FIFO_DATA (0x30) in one ``i2c_rdwr`` burst (or 32-byte block reads), checks
each header (gyro, accelerometer and ODR timestamp present; bit 7 clear), then reads INT_STATUS:
FIFO_FULL means the next sample had no room, so the FIFO is restarted and the loss reported, as
for the MPU-9250 (INT_STATUS clears when read, so a failed read of it is not retried).

Timestamps. Every packet carries the chip's time of its sample in 16 µs units modulo 2^16
(1.05 s); the reader numbers the samples from them
(:class:`~gyrocal.drivers.imu.base.TimestampedFifoReader`, shared with the LSM6DSOX): a jump is
a gap of exactly known size, even one the FIFO never flagged, and after a FIFO restart the first
sample's number comes from its timestamp rather than from the host-clock estimate (which can be
one off). The wrap is resolved with that estimate.
"""

from __future__ import annotations

import errno
from typing import Any

import numpy as np

from gyrocal.drivers.errors import ConfigurationError
from gyrocal.drivers.imu.base import BLOCK_MAX, TimestampedFifoReader, default_band, nearest_rate
from gyrocal.drivers.imu.chips import (
    ICM42688P,
    ICM42688P_BITS,
    ICM42688P_MAX_READER_ODR_HZ,
    ICM42688P_ODR,
    ICM42688P_REG,
    GyroRange,
    icm42688p_bandwidth_hz,
    register_names,
)

__all__ = ["ICM42688PReader"]

R, B = ICM42688P_REG, ICM42688P_BITS
_REG_NAMES = register_names(R)
_PACKET = int(ICM42688P.extra["packet_bytes"])
#: The header of a packet with accelerometer, gyro and the ODR timestamp (the ODR-change bits
#: 1:0 and the 20-bit flag are not used by this configuration and are ignored).
_HEADER_MASK = B.HEADER_MSG | B.HEADER_ACCEL | B.HEADER_GYRO | B.HEADER_TMST_MASK
_HEADER_WANTED = B.HEADER_ACCEL | B.HEADER_GYRO | B.HEADER_TMST_ODR


class ICM42688PReader(TimestampedFifoReader):
    """ICM-42688-P gyro reader over an smbus2-compatible bus.

    Parameters
    ----------
    bus, address, clock, **kwargs
        As for :class:`~gyrocal.drivers.imu.base.ImuReader` (default address 0x68; 0x69 with
        AP_AD0 high).
    """

    family = ICM42688P
    timestamp_tick_s = ICM42688P.extra["timestamp_resolution_s"]
    timestamp_modulus = int(ICM42688P.extra["timestamp_modulus"])
    bank_register = R.REG_BANK_SEL  # user banks 1..4 are "not bank 0"
    bank_mask = 0x07

    def _register_names(self) -> dict[int, str]:
        return _REG_NAMES

    @classmethod
    def offered_rates_hz(cls) -> tuple[float, ...]:
        """The GYRO_ODR rates of :data:`ICM42688P_ODR` the reader streams over I²C."""
        return tuple(sorted(r for r in ICM42688P_ODR if r <= ICM42688P_MAX_READER_ODR_HZ))

    def _choose_rate(self, odr_hz: float, lowpass_hz: float | None) -> tuple[float, float, Any]:
        odr = nearest_rate("ICM-42688-P", (r for r in ICM42688P_ODR
                                           if r <= ICM42688P_MAX_READER_ODR_HZ), odr_hz)
        bands = {code: icm42688p_bandwidth_hz(odr, code) for code in range(8)}
        if lowpass_hz is None:
            widest = default_band(bands.values(), odr)
            code = min(c for c, b in bands.items() if b == widest)
        else:
            near = [c for c, b in bands.items() if abs(b - float(lowpass_hz)) <= 0.5]
            if not near:
                offered = sorted(set(bands.values()), reverse=True)
                raise ConfigurationError(
                    f"lowpass_hz={lowpass_hz!r} is not an ICM-42688-P gyro bandwidth at "
                    f"{odr:g} Hz; choose one of " + ", ".join(f"{b:g}" for b in offered) + " Hz"
                )
            code = min(near)
        return odr, bands[code], (ICM42688P_ODR[odr], code)

    def _bring_up(self, rng: GyroRange, setting: Any) -> None:
        odr_code, filt = setting
        fam, clock = self.family, self._clock
        self._write_byte(R.DEVICE_CONFIG, B.DEVICE_CONFIG_SOFT_RESET)
        clock.sleep(fam.reset_time_s)
        self._write_byte(R.REG_BANK_SEL, 0)
        self._check_identity_again()
        intf = B.INTF_CONFIG0_FIFO_COUNT_ENDIAN | B.INTF_CONFIG0_SENSOR_DATA_ENDIAN
        gyro = (rng.code << B.FS_SEL_SHIFT) | odr_code
        accel = (self.accel_range.code << B.FS_SEL_SHIFT) | odr_code
        # the accelerometer's UI filter at the gyro's bandwidth code: its reset value, 1, is
        # ODR/2 below 400 Hz, which aliases the noise above half the rate in
        filters = (filt << 4) | filt
        tmst = B.TMST_EN | B.TMST_RES_16US
        writes = ((R.INTF_CONFIG0, intf), (R.GYRO_CONFIG0, gyro), (R.ACCEL_CONFIG0, accel),
                  (R.GYRO_ACCEL_CONFIG0, filters), (R.TMST_CONFIG, tmst))
        for reg, value in writes:
            self._write_byte(reg, value)
        low_noise = (B.MODE_LOW_NOISE << B.PWR_MGMT0_GYRO_MODE_SHIFT) | B.MODE_LOW_NOISE
        self._write_byte(R.PWR_MGMT0, low_noise)
        clock.sleep(fam.extra["mode_change_wait_s"])
        for reg, value in (*writes, (R.PWR_MGMT0, low_noise)):
            self._verify(reg, value)
        clock.sleep(fam.startup_time_s)

    def _fifo_prepare(self) -> None:
        self._write_byte(R.FIFO_CONFIG, B.FIFO_MODE_BYPASS << B.FIFO_MODE_SHIFT)
        self._write_byte(R.SIGNAL_PATH_RESET, B.SIGNAL_PATH_RESET_FIFO_FLUSH)
        sources = B.FIFO_CONFIG1_ACCEL_EN | B.FIFO_CONFIG1_GYRO_EN | B.FIFO_CONFIG1_TEMP_EN
        self._write_byte(R.FIFO_CONFIG1, sources)
        self._read_byte(R.INT_STATUS)  # clears a FIFO_FULL left from before

    def _fifo_go(self) -> None:
        self._write_byte(R.FIFO_CONFIG, B.FIFO_MODE_STOP_ON_FULL << B.FIFO_MODE_SHIFT)

    def _disable_fifo(self) -> None:
        self._write_byte(R.FIFO_CONFIG, B.FIFO_MODE_BYPASS << B.FIFO_MODE_SHIFT)
        self._write_byte(R.FIFO_CONFIG1, 0x00)

    def _power_down(self) -> None:
        self._write_byte(R.PWR_MGMT0, 0x00)

    def _fifo_level(self) -> tuple[int, bool, float]:
        hi, lo = self._read_block(R.FIFO_COUNTH, 2)
        return ((hi << 8) | lo) // _PACKET, False, self._clock.monotonic()

    def _overflowed(self) -> bool:
        return bool(self._read_byte(R.INT_STATUS, retry=False) & B.INT_STATUS_FIFO_FULL)

    def _fifo_read(self, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
        data = self._read_stream(R.FIFO_DATA, n * _PACKET, (BLOCK_MAX // _PACKET) * _PACKET)
        packets = np.frombuffer(data, dtype=np.uint8).reshape(n, _PACKET)
        bad = np.flatnonzero(packets[:, 0] & _HEADER_MASK != _HEADER_WANTED)
        if bad.size:
            raise OSError(
                errno.EBADMSG,
                f"FIFO packet {bad[0]} of {n} has header 0x{packets[bad[0], 0]:02X}, not "
                f"0x{_HEADER_WANTED:02X} (accelerometer, gyro, ODR timestamp)",
            )
        accel = packets[:, 1:7].copy().view(">i2").reshape(n, 3)
        gyro = packets[:, 7:13].copy().view(">i2").reshape(n, 3)
        temp = packets[:, 13].view(np.int8).astype(np.float64)
        self._stamps = packets[:, 14:16].copy().view(">u2").reshape(n).astype(np.int64)
        return gyro, accel, temp

    def _temperature_counts(self) -> int:
        hi, lo = self._read_block(R.TEMP_DATA1, 2)
        counts = int.from_bytes(bytes((hi, lo)), "big", signed=True)
        # TEMP_DATA has 132.48 LSB/°C; the family's scale is the FIFO's 2.07 LSB/°C
        scale = self.family.temperature_lsb_per_c / self.family.extra[
            "register_temperature_lsb_per_c"]
        return round(counts * scale)
