"""The emulated ICM-20948 at register level and its reader, against datasheet DS-000189.

Register addresses by bank, reset values, sensitivities and the DLPF table are written out
here from the datasheet, not taken from the driver's tables.
"""

import math

import numpy as np
import pytest

from gyrocal.drivers.clock import VirtualClock
from gyrocal.drivers.emulated.imu_chips import ChipFaults, SensorTruth, make_emulated_imu
from gyrocal.drivers.emulated.motion import ConstantRate
from gyrocal.drivers.imu import ChipIdentityError, open_imu

DEG = math.pi / 180
QUIET = SensorTruth(noise_density_rad_s_sqrt_hz=0.0)

# bank 0
WHO_AM_I, USER_CTRL, PWR_MGMT_1, INT_STATUS_2 = 0x00, 0x03, 0x06, 0x1B
GYRO_XOUT_H, TEMP_OUT_H, FIFO_EN_2, FIFO_RST, FIFO_MODE = 0x33, 0x39, 0x67, 0x68, 0x69
FIFO_COUNTH, FIFO_R_W, REG_BANK_SEL = 0x70, 0x72, 0x7F
# bank 2
GYRO_SMPLRT_DIV, GYRO_CONFIG_1 = 0x00, 0x01
LSB_PER_DPS = {0: 131.0, 1: 65.5, 2: 32.8, 3: 16.4}  # DS-000189 Table 1


def icm(truth=QUIET, motion=None, **kw):
    clock = VirtualClock()
    bus, addr = make_emulated_imu("icm20948", clock, motion or ConstantRate(), truth,
                                  **{"subsamples": 1, **kw})
    return clock, bus, addr, bus.device(addr)


def be16(hi, lo):
    return int.from_bytes(bytes((hi, lo)), "big", signed=True)


def bank(bus, addr, n):
    bus.write_byte_data(addr, REG_BANK_SEL, n << 4)


def test_identity_reset_values_and_banks():
    _, bus, addr, chip = icm()
    assert addr == 0x68 and bus.read_byte_data(addr, WHO_AM_I) == 0xEA
    assert bus.read_byte_data(addr, PWR_MGMT_1) == 0x41  # asleep, clock auto
    assert chip.true_period_s is None
    bank(bus, addr, 2)
    assert chip.bank == 2 and bus.read_byte_data(addr, REG_BANK_SEL) == 0x20
    assert bus.read_byte_data(addr, GYRO_CONFIG_1) == 0x01  # FCHOICE on, ±250 °/s
    assert bus.read_byte_data(addr, WHO_AM_I) == 0x00  # 0x00 of bank 2 is GYRO_SMPLRT_DIV
    bus.write_byte_data(addr, GYRO_SMPLRT_DIV, 9)
    bank(bus, addr, 0)
    assert bus.read_byte_data(addr, WHO_AM_I) == 0xEA
    bus.write_byte_data(addr, PWR_MGMT_1, 0x80)  # DEVICE_RESET
    bank(bus, addr, 2)
    assert bus.read_byte_data(addr, GYRO_SMPLRT_DIV) == 0


@pytest.mark.parametrize("fs", range(4))
def test_gyro_registers_carry_the_datasheet_sensitivity_and_rate(fs):
    omega = np.array([0.4, -0.3, 0.2]) * 250 * 2**fs * DEG
    clock, bus, addr, chip = icm(motion=ConstantRate(omega))
    bus.write_byte_data(addr, PWR_MGMT_1, 0x01)
    bank(bus, addr, 2)
    bus.write_byte_data(addr, GYRO_SMPLRT_DIV, 4)
    bus.write_byte_data(addr, GYRO_CONFIG_1, (3 << 3) | (fs << 1) | 1)
    bank(bus, addr, 0)
    assert chip.true_period_s == pytest.approx(5 / 1125)  # 1.125 kHz / (1 + 4)
    clock.sleep(0.02)
    raw = bus.read_i2c_block_data(addr, GYRO_XOUT_H, 6)
    counts = [be16(raw[i], raw[i + 1]) for i in (0, 2, 4)]
    np.testing.assert_array_equal(counts, np.rint(omega / DEG * LSB_PER_DPS[fs]))


def test_fifo_frames_snapshot_overflow_and_reset():
    truth = SensorTruth(noise_density_rad_s_sqrt_hz=0.0, temperature_c=31.0)
    omega = np.array([0.5, -0.25, 0.125])
    clock, bus, addr, chip = icm(truth, ConstantRate(omega))
    bus.write_byte_data(addr, PWR_MGMT_1, 0x01)
    bus.write_byte_data(addr, FIFO_MODE, 0x01)  # snapshot
    bus.write_byte_data(addr, FIFO_EN_2, 0x0F)  # gyro X/Y/Z and temperature
    bus.write_byte_data(addr, USER_CTRL, 0x40)  # FIFO_EN
    clock.sleep(0.2)  # 225 frames, 64 fit in 512 bytes
    hi, lo = bus.read_i2c_block_data(addr, FIFO_COUNTH, 2)
    assert ((hi & 0x1F) << 8) | lo == 512
    assert bus.read_byte_data(addr, INT_STATUS_2) & 0x1F
    assert not bus.read_byte_data(addr, INT_STATUS_2)  # cleared when read
    frame = bytes(bus.read_i2c_block_data(addr, FIFO_R_W, 8))
    words = [be16(frame[i], frame[i + 1]) for i in range(0, 8, 2)]
    assert words[:3] == list(np.rint(omega / DEG * 131.0))
    assert words[3] == round(10 * 333.87)  # T = TEMP_OUT/333.87 + 21
    bus.write_byte_data(addr, FIFO_RST, 0x1F)
    bus.write_byte_data(addr, FIFO_RST, 0x00)
    assert chip.fifo_level == 0


def test_the_reader_finds_a_chip_left_in_bank_2_and_leaves_bank_0_selected():
    clock, bus, addr, chip = icm()
    bank(bus, addr, 2)
    r = open_imu("icm20948", bus, addr, clock=clock, range_dps=2000, odr_hz=225)
    assert r.model == "icm20948" and chip.bank == 0
    assert r.info.odr_hz == 225 and r.info.lowpass_hz == 51.2  # DLPFCFG 3 (DS-000189)
    assert r.info.sensitivity_rad_s_per_lsb == pytest.approx(DEG / 16.4)
    bank(bus, addr, 2)
    assert bus.read_byte_data(addr, GYRO_SMPLRT_DIV) == 4
    assert bus.read_byte_data(addr, GYRO_CONFIG_1) == (3 << 3) | (3 << 1) | 1


def test_an_icm20948_where_an_mpu9250_was_configured_is_named():
    clock, bus, addr, _ = icm()
    with pytest.raises(ChipIdentityError, match=r"ICM-20948 \(WHO_AM_I 0xEA.*use model 'icm20948'"):
        open_imu("mpu9250", bus, addr, clock=clock, range_dps=500, odr_hz=1000)


def test_siblings_are_named():
    clock, bus, addr, _ = icm(faults=ChipFaults(who_am_i=0xE1))
    with pytest.raises(ChipIdentityError, match="ICM-20649"):
        open_imu("icm20948", bus, addr, clock=clock, range_dps=500, odr_hz=1125)
