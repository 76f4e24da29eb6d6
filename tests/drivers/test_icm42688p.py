"""The emulated ICM-42688-P at register level and its reader, against datasheet DS-000347.

Register addresses, reset values, sensitivities and the packet layout are written out here from
the datasheet (and the kernel's inv_icm42600 driver, which agrees), not taken from the driver's
tables.
"""

import math
import warnings

import numpy as np
import pytest

from gyrocal.drivers.clock import VirtualClock
from gyrocal.drivers.emulated.imu_chips import ChipFaults, SensorTruth, make_emulated_imu
from gyrocal.drivers.emulated.motion import ConstantRate, FunctionMotion
from gyrocal.drivers.imu import ChipIdentityError, open_imu

DEG = math.pi / 180
QUIET = SensorTruth(noise_density_rad_s_sqrt_hz=0.0)

# bank 0 (DS-000347 register map)
DEVICE_CONFIG, FIFO_CONFIG, TEMP_DATA1, GYRO_DATA_X1 = 0x11, 0x16, 0x1D, 0x25
INT_STATUS, FIFO_COUNTH, FIFO_DATA, SIGNAL_PATH_RESET = 0x2D, 0x2E, 0x30, 0x4B
INTF_CONFIG0, PWR_MGMT0, GYRO_CONFIG0, ACCEL_CONFIG0 = 0x4C, 0x4E, 0x4F, 0x50
TMST_CONFIG, FIFO_CONFIG1, WHO_AM_I, REG_BANK_SEL = 0x54, 0x5F, 0x75, 0x76
# GYRO_FS_SEL code -> LSB/(°/s) (DS-000347 Table 1)
SENSITIVITY = {0: 16.4, 1: 32.8, 2: 65.5, 3: 131.0, 4: 262.0, 5: 524.3, 6: 1048.6, 7: 2097.2}


def icm(truth=QUIET, motion=None, **kw):
    clock = VirtualClock()
    bus, addr = make_emulated_imu("icm42688p", clock, motion or ConstantRate(), truth,
                                  **{"subsamples": 1, "output_filter": False, **kw})
    return clock, bus, addr, bus.device(addr)


def be16(hi, lo):
    return int.from_bytes(bytes((hi, lo)), "big", signed=True)


def gyro_on(bus, addr, fs=0, odr_code=0b0110):
    bus.write_byte_data(addr, GYRO_CONFIG0, (fs << 5) | odr_code)
    bus.write_byte_data(addr, PWR_MGMT0, 0x0F)  # gyro and accelerometer low-noise


def test_identity_reset_values_and_address():
    _, bus, addr, chip = icm()
    assert addr == 0x68 and chip.family.addresses == (0x68, 0x69)
    assert bus.read_byte_data(addr, WHO_AM_I) == 0x47
    # INTF_CONFIG0 0x30 (big-endian), GYRO/ACCEL_CONFIG0 0x06 (±2000 °/s, ±16 g, 1 kHz),
    # TMST_CONFIG 0x23, PWR_MGMT0 0 (off)
    expect = {INTF_CONFIG0: 0x30, GYRO_CONFIG0: 0x06, ACCEL_CONFIG0: 0x06, TMST_CONFIG: 0x23,
              PWR_MGMT0: 0x00, FIFO_CONFIG: 0x00}
    assert {r: bus.read_byte_data(addr, r) for r in expect} == expect
    assert chip.true_period_s is None  # sensors off after reset


def test_bank_switching_and_soft_reset():
    _, bus, addr, chip = icm()
    bus.write_byte_data(addr, REG_BANK_SEL, 1)
    assert chip.bank == 1
    assert bus.read_byte_data(addr, WHO_AM_I) != 0x47  # 0x75 of bank 1 is another register
    bus.write_byte_data(addr, GYRO_CONFIG0, 0xAB)  # lands in bank 1, not in bank 0
    assert bus.read_byte_data(addr, REG_BANK_SEL) == 1
    bus.write_byte_data(addr, REG_BANK_SEL, 0)
    assert bus.read_byte_data(addr, WHO_AM_I) == 0x47
    assert bus.read_byte_data(addr, GYRO_CONFIG0) == 0x06
    bus.write_byte_data(addr, GYRO_CONFIG0, 0x46)
    bus.write_byte_data(addr, REG_BANK_SEL, 2)
    bus.write_byte_data(addr, DEVICE_CONFIG, 0x01)  # bank 2: not the reset register
    assert chip.bank == 2
    bus.write_byte_data(addr, REG_BANK_SEL, 0)
    bus.write_byte_data(addr, DEVICE_CONFIG, 0x01)  # SOFT_RESET
    assert bus.read_byte_data(addr, GYRO_CONFIG0) == 0x06 and chip.bank == 0


@pytest.mark.parametrize("fs", range(8))
def test_gyro_data_registers_carry_the_datasheet_sensitivity(fs):
    full_scale = 2000.0 / 2**fs
    omega = np.array([0.4, -0.3, 0.2]) * full_scale * DEG
    clock, bus, addr, _ = icm(motion=ConstantRate(omega))
    gyro_on(bus, addr, fs=fs)
    clock.sleep(0.01)
    raw = bus.read_i2c_block_data(addr, GYRO_DATA_X1, 6)
    counts = [be16(raw[i], raw[i + 1]) for i in (0, 2, 4)]
    np.testing.assert_array_equal(counts, np.rint(omega / DEG * SENSITIVITY[fs]))


def test_temperature_register_and_fifo_byte():
    truth = SensorTruth(noise_density_rad_s_sqrt_hz=0.0, temperature_c=31.0)
    clock, bus, addr, _ = icm(truth)
    gyro_on(bus, addr)
    clock.sleep(0.01)
    hi, lo = bus.read_i2c_block_data(addr, TEMP_DATA1, 2)
    assert be16(hi, lo) == round(6.0 * 132.48)  # T = TEMP_DATA/132.48 + 25


def start_fifo(bus, addr, sources=0x07, mode=0b01, tmst=0x09):
    bus.write_byte_data(addr, TMST_CONFIG, tmst)
    bus.write_byte_data(addr, FIFO_CONFIG1, sources)
    bus.write_byte_data(addr, FIFO_CONFIG, mode << 6)


def read_fifo(bus, addr):
    hi, lo = bus.read_i2c_block_data(addr, FIFO_COUNTH, 2)
    count = (hi << 8) | lo  # big-endian, in bytes (INTF_CONFIG0 reset value)
    out = b""
    while len(out) < count:
        out += bytes(bus.read_i2c_block_data(addr, FIFO_DATA, min(32, count - len(out))))
    return count, out


def test_fifo_packet_3_bytes_and_timestamps():
    omega = np.array([1.0, -0.5, 0.25])
    truth = SensorTruth(noise_density_rad_s_sqrt_hz=0.0, temperature_c=35.0, clock_ppm=5000)
    clock, bus, addr, _ = icm(truth, ConstantRate(omega))
    gyro_on(bus, addr, fs=2)  # ±500 °/s
    start_fifo(bus, addr)  # accel + gyro + temp, stream, ODR timestamp in 16 µs units
    clock.sleep(0.0105)
    count, data = read_fifo(bus, addr)
    assert count % 16 == 0 and count // 16 in (10, 11)
    p = np.frombuffer(data, dtype=np.uint8).reshape(-1, 16)
    assert np.all(p[:, 0] == 0x68)  # ACCEL | GYRO | ODR timestamp (bits 3:2 = 10)
    accel = p[:, 1:7].copy().view(">i2")
    gyro = p[:, 7:13].copy().view(">i2")
    np.testing.assert_array_equal(accel, np.tile([0, 0, 2048], (len(p), 1)))  # ±16 g: 2048/g
    np.testing.assert_array_equal(gyro, np.tile(np.rint(omega / DEG * 65.5), (len(p), 1)))
    assert np.all(p[:, 13].view(np.int8) == round(10 * 2.07))  # FIFO_TEMP_DATA/2.07 + 25
    stamps = p[:, 14:16].copy().view(">u2").astype(int).ravel()
    # 1 kHz on the chip's own clock: 1000 µs = 62.5 units of 16 µs, whatever its error
    assert set(np.diff(stamps) % 65536) <= {62, 63}
    assert abs(np.mean(np.diff(stamps)) - 62.5) <= 0.5 / (len(stamps) - 1) + 1e-12
    # 1 µs units (TMST_RES = 0): exactly 1000 apart
    _, bus2, addr2, _ = icm(truth, ConstantRate(omega))
    gyro_on(bus2, addr2)
    start_fifo(bus2, addr2, tmst=0x01)
    bus2.clock.sleep(0.0055)
    _, data2 = read_fifo(bus2, addr2)
    stamps2 = np.frombuffer(data2, dtype=np.uint8).reshape(-1, 16)[:, 14:16].copy()
    assert set(np.diff(stamps2.view(">u2").astype(int).ravel()) % 65536) == {1000}


def test_fifo_packet_2_gyro_only_is_8_bytes():
    clock, bus, addr, _ = icm(motion=ConstantRate((0.1, 0.2, 0.3)))
    gyro_on(bus, addr)
    start_fifo(bus, addr, sources=0x06)  # gyro + temp
    clock.sleep(0.0045)
    count, data = read_fifo(bus, addr)
    p = np.frombuffer(data, dtype=np.uint8).reshape(-1, 8)
    assert count == 8 * len(p) and np.all(p[:, 0] == 0x20)  # header: GYRO only


def test_stop_on_full_keeps_2048_bytes_flags_full_and_flush_empties():
    clock, bus, addr, chip = icm(motion=ConstantRate((0.1, 0.2, 0.3)))
    gyro_on(bus, addr)
    start_fifo(bus, addr, mode=0b10)
    clock.sleep(0.2)  # 200 samples, 128 fit
    hi, lo = bus.read_i2c_block_data(addr, FIFO_COUNTH, 2)
    assert (hi << 8) | lo == 2048
    assert bus.read_byte_data(addr, INT_STATUS) & 0x02  # FIFO_FULL_INT
    assert not bus.read_byte_data(addr, INT_STATUS) & 0x02  # cleared by the read
    _, data = read_fifo(bus, addr)
    stamps = np.frombuffer(data, dtype=np.uint8).reshape(-1, 16)[:, 14:16].copy()
    steps = np.diff(stamps.view(">u2").astype(int).ravel()) % 65536
    assert set(steps) <= {62, 63}  # the oldest 128, consecutive
    bus.write_byte_data(addr, SIGNAL_PATH_RESET, 0x02)  # FIFO_FLUSH
    assert chip.fifo_level == 0
    assert bytes(bus.read_i2c_block_data(addr, FIFO_DATA, 4)) == b"\xff" * 4  # empty: bit 7


# ----------------------------------------------------------------------------- the reader


def wave():
    a = 200 * DEG
    return FunctionMotion(lambda t: a * np.column_stack(
        [np.sin(2 * np.pi * 0.7 * t), np.cos(2 * np.pi * 1.3 * t), np.sin(2 * np.pi * 0.3 * t)]))


def test_a_packet_lost_inside_the_fifo_is_a_gap_of_one_without_a_restart():
    motion = wave()
    clock, bus, addr, chip = icm(QUIET, motion)
    reader = open_imu("icm42688p", bus, addr, clock=clock, range_dps=500, odr_hz=1000)
    reader.start()
    batches = []
    for _ in range(50):
        clock.sleep(0.01)
        batches.append(reader.read())
    chip.fifo_level  # noqa: B018 - bring the FIFO up to date
    del chip._fifo[32:48]  # the third packet waiting is lost inside the chip, unflagged
    enables = len(chip.fifo_enables)
    for _ in range(50):
        clock.sleep(0.01)
        batches.append(reader.read())
    gaps = [g for b in batches for g in b.gaps]
    assert len(gaps) == 1 and gaps[0].samples == 1 and "timestamps" in gaps[0].reason
    assert len(chip.fifo_enables) == enables  # no FIFO restart was needed
    index = np.concatenate([b.index for b in batches])
    assert gaps[0].first_index not in index and np.all(np.diff(index) >= 1)
    ks = chip.fifo_enables[0] + 1 + index
    t = np.concatenate([b.t for b in batches])
    expect = np.rint(QUIET.reading(motion.rate(chip.sample_time(ks)), np.full(len(ks), 25.0))
                     / (DEG / 65.5)) * DEG / 65.5
    np.testing.assert_allclose(np.concatenate([b.rate for b in batches]), expect, atol=1e-12)
    assert np.max(np.abs(t - chip.sample_time(ks))) < 0.5e-3


def test_a_chip_left_in_another_bank_is_found():
    clock, bus, addr, _ = icm()
    bus.write_byte_data(addr, REG_BANK_SEL, 3)
    reader = open_imu("icm42688p", bus, addr, clock=clock, range_dps=2000, odr_hz=200)
    # the widest UI filter bandwidth below half of 200 Hz: max(400, 200)/5 = 80 Hz (code 2)
    assert reader.model == "icm42688p" and reader.info.lowpass_hz == 80.0


@pytest.mark.parametrize("who, name", [(0x42, "ICM-42605"), (0x44, "ICM-42686-P"),
                                       (0x40, "ICM-42600")])
def test_a_sibling_is_named(who, name):
    clock, bus, addr, _ = icm(faults=ChipFaults(who_am_i=who))
    with pytest.raises(ChipIdentityError, match=name):
        open_imu("icm42688p", bus, addr, clock=clock, range_dps=2000, odr_hz=1000)


def test_an_icm42688p_where_an_mpu9250_was_configured_is_named():
    clock, bus, addr, _ = icm()
    with pytest.raises(ChipIdentityError, match=r"ICM-42688-P.*use model 'icm42688p'"):
        open_imu("mpu9250", bus, addr, clock=clock, range_dps=2000, odr_hz=1000)


def test_rates_and_filters_offered_and_refused():
    clock, bus, addr, _ = icm()
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        r = open_imu("icm42688p", bus, addr, clock=clock, range_dps=15.625, odr_hz=12.5,
                     lowpass_hz=10)  # max(400, ODR)/40 (GYRO_UI_FILT_BW = 7)
    assert r.info.sensitivity_rad_s_per_lsb == pytest.approx(DEG / 2097.2)
    from gyrocal.drivers.errors import ConfigurationError

    with pytest.raises(ConfigurationError, match="12.5, 25, 50, 100, 200, 500, 1000"):
        open_imu("icm42688p", bus, addr, clock=clock, range_dps=2000, odr_hz=8000)
    with pytest.raises(ConfigurationError, match="bandwidth"):
        open_imu("icm42688p", bus, addr, clock=clock, range_dps=2000, odr_hz=1000, lowpass_hz=7)


def test_the_output_filter_at_half_the_odr_runs_faster_than_the_odr():
    clock, bus, addr, chip = icm(output_filter=True)
    gyro_on(bus, addr)  # 1 kHz, GYRO_UI_FILT_BW reset value 1: max(400, 1000)/4 = 250 Hz
    assert chip.cutoff_hz() == 250.0 and chip._filter_rate_hz() == 1000.0
    bus.write_byte_data(addr, 0x52, 0x17)  # code 7: 1000/40 = 25 Hz
    assert chip.cutoff_hz() == 25.0
    # code 0: ODR/2, which no filter at the ODR has: it runs at 4 kHz, 500 Hz below a quarter
    bus.write_byte_data(addr, 0x52, 0x10)
    assert chip.cutoff_hz() == 500.0 and chip._filter_rate_hz() == 4000.0
