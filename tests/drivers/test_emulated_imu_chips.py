"""The emulated MPU-9250 and LSM9DS1 at register level, checked against the hardware reference.

Register addresses, reset values and conversion factors are written out here from
shared/hardware-reference.md (§1 MPU-9250, §2 LSM9DS1), not taken from the driver's tables.
"""

import errno
import math

import numpy as np
import pytest
from smbus2 import i2c_msg

from gyrocal.drivers.clock import VirtualClock
from gyrocal.drivers.emulated.imu_chips import (
    ChipFaults,
    EmulatedLSM9DS1,
    EmulatedMPU9250,
    SensorTruth,
    make_emulated_imu,
)
from gyrocal.drivers.emulated.motion import ConstantRate, FunctionMotion

DEG = math.pi / 180
QUIET = SensorTruth(noise_density_rad_s_sqrt_hz=0.0)

# MPU-9250 registers (§1.2)
SMPLRT_DIV, CONFIG, GYRO_CONFIG, FIFO_EN = 0x19, 0x1A, 0x1B, 0x23
INT_STATUS, ACCEL_XOUT_H, TEMP_OUT_H, GYRO_XOUT_H = 0x3A, 0x3B, 0x41, 0x43
USER_CTRL, PWR_MGMT_1, FIFO_COUNTH, FIFO_R_W, WHO_AM_I = 0x6A, 0x6B, 0x72, 0x74, 0x75
# LSM9DS1 A/G registers (§2.2)
L_WHO_AM_I, CTRL_REG1_G, OUT_TEMP_L, OUT_X_L_G = 0x0F, 0x10, 0x15, 0x18
CTRL_REG4, CTRL_REG5_XL, CTRL_REG8, CTRL_REG9 = 0x1E, 0x1F, 0x22, 0x23
OUT_X_L_XL, FIFO_CTRL, FIFO_SRC = 0x28, 0x2E, 0x2F


def mpu(truth=QUIET, motion=None, **kw):
    clock = VirtualClock()
    bus, addr = make_emulated_imu("mpu9250", clock, motion or ConstantRate(), truth,
                                  **{"subsamples": 1, "output_filter": False, **kw})
    return clock, bus, addr, bus.device(addr)


def lsm(truth=QUIET, motion=None, **kw):
    clock = VirtualClock()
    bus, addr = make_emulated_imu("lsm9ds1", clock, motion or ConstantRate(), truth,
                                  **{"subsamples": 1, "output_filter": False, **kw})
    return clock, bus, addr, bus.device(addr)


def mpu_stream(bus, addr, div=0, dlpf=1, fs=0, fifo_en=0xF0, fifo_mode=True):
    """Configure 1 kHz/(1+div) and enable the FIFO with the given sources."""
    bus.write_byte_data(addr, PWR_MGMT_1, 0x01)
    bus.write_byte_data(addr, SMPLRT_DIV, div)
    bus.write_byte_data(addr, CONFIG, (0x40 if fifo_mode else 0) | dlpf)
    bus.write_byte_data(addr, GYRO_CONFIG, fs << 3)
    bus.write_byte_data(addr, USER_CTRL, 0x04)
    bus.write_byte_data(addr, FIFO_EN, fifo_en)
    bus.write_byte_data(addr, USER_CTRL, 0x40)


def be16(hi, lo):
    return int.from_bytes(bytes((hi, lo)), "big", signed=True)


def le16(lo, hi):
    return int.from_bytes(bytes((lo, hi)), "little", signed=True)


# ----------------------------------------------------------------------------- MPU-9250


def test_mpu_reset_values_and_identity():
    _, bus, addr, _ = mpu()
    assert addr == 0x68
    low = bus.read_i2c_block_data(addr, 0x00, 32)
    high = bus.read_i2c_block_data(addr, 0x60, 21)  # 0x60..0x74
    # the self-test registers (0x00-0x02 gyro, 0x0D-0x0F accel) hold factory codes, the rest 0
    self_test = {0x00, 0x01, 0x02, 0x0D, 0x0E, 0x0F}
    assert all(low[i] != 0 for i in self_test)
    assert [v for i, v in enumerate(low) if i not in self_test] == [0] * 26
    assert high == [0x01 if 0x60 + i == PWR_MGMT_1 else 0 for i in range(21)]
    assert bus.read_byte_data(addr, WHO_AM_I) == 0x71
    for variant, who in (("mpu9255", 0x73), ("mpu6500", 0x70)):
        b, a = make_emulated_imu(variant, VirtualClock())
        assert b.read_byte_data(a, WHO_AM_I) == who


def test_mpu_h_reset_restores_defaults():
    _, bus, addr, _ = mpu()
    bus.write_byte_data(addr, SMPLRT_DIV, 9)
    bus.write_byte_data(addr, PWR_MGMT_1, 0x40)
    bus.write_byte_data(addr, PWR_MGMT_1, 0x80)
    assert bus.read_byte_data(addr, SMPLRT_DIV) == 0
    assert bus.read_byte_data(addr, PWR_MGMT_1) == 0x01


def test_mpu_output_registers_are_big_endian_counts_of_the_true_rate():
    omega = np.array([0.5, -1.0, 2.0])  # rad/s
    clock, bus, addr, _ = mpu(motion=ConstantRate(omega), truth=SensorTruth(
        noise_density_rad_s_sqrt_hz=0.0, temperature_c=30.0))
    mpu_stream(bus, addr, fs=1)  # ±500 dps: 65.5 LSB/(°/s)
    clock.sleep(0.01)
    raw = bus.read_i2c_block_data(addr, GYRO_XOUT_H, 6)
    counts = [be16(raw[i], raw[i + 1]) for i in (0, 2, 4)]
    assert counts == [round(w / DEG * 65.5) for w in omega]
    t = bus.read_i2c_block_data(addr, TEMP_OUT_H, 2)
    assert be16(*t) == round((30.0 - 21.0) * 333.87)
    acc = bus.read_i2c_block_data(addr, ACCEL_XOUT_H, 6)
    assert be16(acc[4], acc[5]) == 16384  # 1 g at ±2 g


def test_mpu_fifo_frames_count_latch_and_data_port():
    clock, bus, addr, chip = mpu(motion=ConstantRate((0.1, 0.2, 0.3)))
    mpu_stream(bus, addr, div=9)  # 100 Hz, frames TEMP GX GY GZ = 8 bytes
    clock.sleep(0.1 + 1e-6)
    hi, lo = bus.read_i2c_block_data(addr, FIFO_COUNTH, 2)
    count = (hi << 8) | lo
    assert count == 10 * 8
    data = bus.read_i2c_block_data(addr, FIFO_R_W, 32)  # the data port does not advance
    words = np.frombuffer(bytes(data), ">i2").reshape(4, 4)
    expect = [round(w / DEG * 131) for w in (0.1, 0.2, 0.3)]  # ±250 dps: 131 LSB/(°/s)
    np.testing.assert_array_equal(words[:, 1:], [expect] * 4)
    assert chip.fifo_level == count - 32
    bus.write_byte_data(addr, USER_CTRL, 0x44)  # FIFO_RST clears it and clears itself
    assert chip.fifo_level == 0
    assert bus.read_byte_data(addr, USER_CTRL) == 0x40


def test_mpu_a_burst_that_reaches_the_fifo_port_stays_on_it():
    clock, bus, addr, chip = mpu(motion=ConstantRate((0.1, 0.2, 0.3)))
    mpu_stream(bus, addr, div=9)  # 100 Hz, frames TEMP GX GY GZ = 8 bytes
    clock.sleep(0.05 + 1e-6)
    raw = bus.read_i2c_block_data(addr, FIFO_COUNTH, 2 + 16)  # COUNTH, COUNTL, then 0x74 (§1.7)
    assert (raw[0] << 8) | raw[1] == 5 * 8
    words = np.frombuffer(bytes(raw[2:]), ">i2").reshape(2, 4)
    expect = [round(w / DEG * 131) for w in (0.1, 0.2, 0.3)]  # ±250 dps: 131 LSB/(°/s)
    np.testing.assert_array_equal(words[:, 1:], [expect] * 2)
    assert chip.fifo_level == 5 * 8 - 16


def test_mpu_fifo_count_high_byte_latches_the_low_byte():
    clock, bus, addr, _ = mpu()
    mpu_stream(bus, addr)  # 1 kHz
    clock.sleep(0.0335)
    hi = bus.read_byte_data(addr, FIFO_COUNTH)
    clock.sleep(0.005)  # five more frames arrive
    lo = bus.read_byte_data(addr, 0x73)
    assert ((hi << 8) | lo) == 33 * 8


@pytest.mark.parametrize("fifo_mode", [True, False])
def test_mpu_fifo_overflow_modes_and_flag(fifo_mode):
    # A ramp on x makes every sample distinct, so which ones were kept is visible.
    clock, bus, addr, chip = mpu(motion=FunctionMotion(
        lambda t: np.column_stack([t, 0 * t, 0 * t])))
    mpu_stream(bus, addr, fifo_mode=fifo_mode)  # 1 kHz, 8-byte frames: 64 fit in 512 bytes
    t_enable = clock.monotonic()
    assert bus.read_byte_data(addr, INT_STATUS) & 0x10 == 0
    clock.sleep(0.1)
    hi, lo = bus.read_i2c_block_data(addr, FIFO_COUNTH, 2)
    assert (hi << 8) | lo == 512
    status = bus.read_byte_data(addr, INT_STATUS)
    assert status & 0x10 and status & 0x01
    assert bus.read_byte_data(addr, INT_STATUS) == 0  # cleared by the read
    w, r = i2c_msg.write(addr, [FIFO_R_W]), i2c_msg.read(addr, 512)
    bus.i2c_rdwr(w, r)
    gx = np.frombuffer(bytes(r), ">i2").reshape(64, 4)[:, 1]
    # x rate = t rad/s at the sample instant, 131 LSB/(°/s)
    k0 = chip.fifo_enables[-1]
    times = chip.sample_time(np.arange(k0 + 1, chip.samples_taken + 1))
    assert times[0] > t_enable
    expect = np.rint(times / DEG * 131)
    np.testing.assert_array_equal(gx, expect[:64] if fifo_mode else expect[-64:])


def test_mpu_rates_from_dlpf_and_divider():
    for dlpf, div, fchoice_b, odr in ((1, 0, 0, 1000), (3, 4, 0, 200), (0, 9, 0, 8000),
                                     (7, 0, 0, 8000), (1, 0, 1, 32000)):
        clock, bus, addr, chip = mpu()
        bus.write_byte_data(addr, SMPLRT_DIV, div)
        bus.write_byte_data(addr, CONFIG, dlpf)
        bus.write_byte_data(addr, GYRO_CONFIG, fchoice_b)
        start = chip.samples_taken
        clock.sleep(0.5)
        bus.read_byte_data(addr, WHO_AM_I)
        # the last read's own bus time (about 0.1 ms) adds a few samples at 32 kHz
        assert chip.samples_taken - start == pytest.approx(0.5 * odr, abs=1 + odr * 1e-4)


def test_mpu_sleep_stops_sampling():
    clock, bus, addr, chip = mpu()
    bus.write_byte_data(addr, PWR_MGMT_1, 0x41)
    clock.sleep(0.5)
    bus.read_byte_data(addr, WHO_AM_I)
    assert chip.samples_taken == 0


# ----------------------------------------------------------------------------- sensor truth


def test_truth_model_is_eq1_inverted_with_misalignment_first():
    mis = np.array([[1.0, 0.01, 0.0], [0.0, 1.0, -0.02], [0.005, 0.0, 1.0]])
    truth = SensorTruth(scale=(1.02, 0.97, 1.0), bias=(0.01, -0.02, 0.03), misalignment=mis,
                        noise_density_rad_s_sqrt_hz=0.0)
    g = np.array([[0.5, -0.4, 1.2]])
    m = truth.reading(g, np.array([25.0]))
    # g = scale * (m + bias) holds for the misaligned rate M g
    np.testing.assert_allclose(np.array(truth.scale) * (m + truth.bias), (mis @ g.T).T)
    assert truth.manifest() == {"scale": [1.02, 0.97, 1.0], "bias": [0.01, -0.02, 0.03],
                                "misalignment": mis.tolist()}


def test_truth_validates_its_fields():
    with pytest.raises(ValueError, match="scale"):
        SensorTruth(scale=(1.0, 0.0, 1.0))
    with pytest.raises(ValueError, match="misalignment"):
        SensorTruth(misalignment=np.eye(2))
    with pytest.raises(ValueError, match="noise"):
        SensorTruth(noise_density_rad_s_sqrt_hz=-1.0)
    with pytest.raises(ValueError, match="clock_ppm"):
        SensorTruth(clock_ppm=float("nan"))
    with pytest.raises(ValueError, match="clock_ppm"):
        SensorTruth(clock_ppm=-1e6)  # the chip would not sample at all


def test_counts_follow_scale_bias_and_temperature_drift():
    omega = np.array([1.0, -0.5, 0.25])
    truth = SensorTruth(scale=(1.05, 0.95, 1.0), bias=(0.02, 0.0, -0.01),
                        bias_temp_coeff_rad_s_per_c=(0.001, 0.0, 0.0),
                        reference_temperature_c=25.0, temperature_c=lambda t: 25.0 + 10.0 * t,
                        noise_density_rad_s_sqrt_hz=0.0)
    clock, bus, addr, _ = mpu(truth=truth, motion=ConstantRate(omega))
    mpu_stream(bus, addr, fs=2)  # ±1000 dps, 32.8 LSB/(°/s)
    clock.sleep(2.0)
    now = clock.monotonic()
    raw = bus.read_i2c_block_data(addr, GYRO_XOUT_H, 6)
    counts = np.array([be16(raw[i], raw[i + 1]) for i in (0, 2, 4)])
    temp = 25.0 + 10.0 * now  # within one sample period of the latest sample
    bias = np.array([0.02 + 0.001 * (temp - 25.0), 0.0, -0.01])
    expect = (omega / np.array([1.05, 0.95, 1.0]) - bias) / DEG * 32.8
    np.testing.assert_allclose(counts, expect, atol=1.0)


def test_noise_density_sets_the_per_sample_sigma():
    density = 0.01 * DEG  # rad/s/√Hz
    clock, bus, addr, _ = mpu(truth=SensorTruth(noise_density_rad_s_sqrt_hz=density), seed=3)
    mpu_stream(bus, addr, div=0)  # 1 kHz: sigma = density * sqrt(1000)
    got = []
    for _ in range(100):
        clock.sleep(0.05)
        hi, lo = bus.read_i2c_block_data(addr, FIFO_COUNTH, 2)
        w, r = i2c_msg.write(addr, [FIFO_R_W]), i2c_msg.read(addr, (hi << 8) | lo)
        bus.i2c_rdwr(w, r)
        got.append(np.frombuffer(bytes(r), ">i2").reshape(-1, 4)[:, 1:])
    counts = np.concatenate(got)
    sigma_counts = density * math.sqrt(1000) / DEG * 131
    assert counts.std(axis=0) == pytest.approx([sigma_counts] * 3, rel=0.05)
    assert np.abs(counts.mean(axis=0)).max() < 5 * sigma_counts / math.sqrt(len(counts))


def test_clipping_at_the_configured_range():
    clock, bus, addr, _ = mpu(motion=ConstantRate((10.0, -10.0, 0.0)))  # 573 °/s
    mpu_stream(bus, addr, fs=0)  # ±250
    clock.sleep(0.01)
    raw = bus.read_i2c_block_data(addr, GYRO_XOUT_H, 4)
    assert [be16(raw[0], raw[1]), be16(raw[2], raw[3])] == [32767, -32768]


def test_chip_clock_error_changes_the_sample_count():
    for ppm in (10_000, -10_000):
        clock, bus, addr, chip = mpu(truth=SensorTruth(clock_ppm=ppm))
        mpu_stream(bus, addr, div=0)
        clock.sleep(10.0)
        bus.read_byte_data(addr, WHO_AM_I)
        assert chip.samples_taken == pytest.approx(1000 * (1 + ppm * 1e-6) * 10.0, abs=1)


def test_motion_source_is_asked_in_time_order_and_never_ahead_of_the_clock():
    calls = []

    class Recorder:
        def rate(self, t):
            calls.append((np.array(t), clock.monotonic()))
            return np.zeros((len(t), 3))

    clock = VirtualClock()
    bus, addr = make_emulated_imu("mpu9250", clock, Recorder())
    mpu_stream(bus, addr)
    rng = np.random.default_rng(0)
    for _ in range(200):
        clock.sleep(rng.uniform(0.0, 0.2))  # also long waits: the FIFO overflows
        bus.read_i2c_block_data(addr, FIFO_COUNTH, 2)
    times = np.concatenate([t for t, _ in calls])
    assert np.all(np.diff(times) >= 0)
    assert all(np.all(t <= now) for t, now in calls)


# ----------------------------------------------------------------------------- LSM9DS1


def lsm_stream(bus, addr, odr_code=6, fs=0, fmode=0b001, fifo=True):
    bus.write_byte_data(addr, CTRL_REG1_G, (odr_code << 5) | (fs << 3))
    if fifo:
        bus.write_byte_data(addr, CTRL_REG9, 0x02)
        bus.write_byte_data(addr, FIFO_CTRL, 0x00)
        bus.write_byte_data(addr, FIFO_CTRL, fmode << 5)


def test_lsm_reset_values_and_identity():
    _, bus, addr, _ = lsm()
    assert addr == 0x6B
    assert bus.read_byte_data(addr, L_WHO_AM_I) == 0x68
    assert bus.read_byte_data(addr, CTRL_REG4) == 0x38
    assert bus.read_byte_data(addr, CTRL_REG5_XL) == 0x38
    assert bus.read_byte_data(addr, CTRL_REG8) == 0x04
    assert bus.read_byte_data(addr, CTRL_REG1_G) == 0
    assert bus.read_byte_data(addr, L_WHO_AM_I | 0x80) == 0x68  # sub-address bit 7 ignored


def test_lsm_sw_reset_restores_defaults():
    _, bus, addr, _ = lsm()
    bus.write_byte_data(addr, CTRL_REG1_G, 0xC0)
    bus.write_byte_data(addr, CTRL_REG8, 0x05)
    assert bus.read_byte_data(addr, CTRL_REG1_G) == 0
    assert bus.read_byte_data(addr, CTRL_REG8) == 0x04


def test_lsm_output_is_little_endian_and_ble_swaps_it():
    omega = np.array([0.3, -0.6, 1.5])
    truth = SensorTruth(noise_density_rad_s_sqrt_hz=0.0, temperature_c=31.0)
    clock, bus, addr, _ = lsm(truth=truth, motion=ConstantRate(omega))
    lsm_stream(bus, addr, odr_code=3, fs=1, fifo=False)  # 119 Hz, ±500 dps: 17.50 mdps/LSB
    clock.sleep(0.05)
    expect = [round(w / DEG / 0.0175) for w in omega]
    raw = bus.read_i2c_block_data(addr, OUT_X_L_G, 6)
    assert [le16(raw[i], raw[i + 1]) for i in (0, 2, 4)] == expect
    t = bus.read_i2c_block_data(addr, OUT_TEMP_L, 2)
    assert le16(*t) == round((31.0 - 25.0) * 16)
    bus.write_byte_data(addr, CTRL_REG8, 0x06)  # IF_ADD_INC | BLE
    raw = bus.read_i2c_block_data(addr, OUT_X_L_G, 6)
    assert [be16(raw[i], raw[i + 1]) for i in (0, 2, 4)] == expect


def test_lsm_register_wrap_and_auto_increment():
    clock, bus, addr, _ = lsm(motion=ConstantRate((0.1, 0.2, 0.3)))
    lsm_stream(bus, addr, odr_code=4, fs=0, fifo=False)
    clock.sleep(0.05)
    burst = bus.read_i2c_block_data(addr, OUT_X_L_G, 24)
    gyro = bus.read_i2c_block_data(addr, OUT_X_L_G, 6)
    accel = bus.read_i2c_block_data(addr, OUT_X_L_XL, 6)
    assert burst == (gyro + accel) * 2  # 0x1D → 0x28, 0x2D → 0x18 while the gyro is on
    assert le16(accel[4], accel[5]) == round(1000 / 0.061)  # 1 g at ±2 g
    bus.write_byte_data(addr, CTRL_REG8, 0x00)  # IF_ADD_INC off: the pointer stays
    assert bus.read_i2c_block_data(addr, L_WHO_AM_I, 3) == [0x68] * 3


def test_lsm_fifo_mode_keeps_the_oldest_and_continuous_overwrites():
    ramp = FunctionMotion(lambda t: np.column_stack([t, 0 * t, 0 * t]))
    for fmode in (0b001, 0b110):
        clock, bus, addr, chip = lsm(motion=ramp, bus_hz=0)  # reading takes no time
        lsm_stream(bus, addr, odr_code=6, fs=3, fmode=fmode)  # 952 Hz, ±2000 dps: 70 mdps/LSB
        clock.sleep(0.1)
        src = bus.read_byte_data(addr, FIFO_SRC)
        assert src & 0x3F == 32
        assert bool(src & 0x40) == (fmode == 0b110)  # OVRN only when a slot was overwritten
        gx = []
        for _ in range(32):
            slot = bus.read_i2c_block_data(addr, OUT_X_L_G, 12)  # reading 0x2D pops the slot
            gx.append(le16(slot[0], slot[1]))
        assert bus.read_byte_data(addr, FIFO_SRC) & 0x7F == 0
        k0 = chip.fifo_enables[-1]
        times = chip.sample_time(np.arange(k0 + 1, chip.samples_taken + 1))
        expect = np.rint(times / DEG / 0.070)
        np.testing.assert_array_equal(gx, expect[:32] if fmode == 0b001 else expect[-32:])


def test_lsm_bypass_empties_the_fifo_and_a_burst_pops_many_slots():
    clock, bus, addr, chip = lsm()
    lsm_stream(bus, addr, odr_code=5)  # 476 Hz
    clock.sleep(0.03)
    n = bus.read_byte_data(addr, FIFO_SRC) & 0x3F
    assert n == pytest.approx(0.03 * 476, abs=1)
    assert len(bus.read_i2c_block_data(addr, OUT_X_L_G, 24)) == 24
    assert chip.fifo_level == n - 2
    bus.write_byte_data(addr, FIFO_CTRL, 0x00)
    assert bus.read_byte_data(addr, FIFO_SRC) == 0


def test_lsm_rates():
    for code, odr in ((1, 14.9), (2, 59.5), (3, 119), (4, 238), (5, 476), (6, 952)):
        clock, bus, addr, chip = lsm()
        lsm_stream(bus, addr, odr_code=code, fifo=False)
        clock.sleep(2.0)
        bus.read_byte_data(addr, L_WHO_AM_I)
        assert chip.samples_taken == pytest.approx(2.0 * odr, abs=1)


# ----------------------------------------------------------------------------- fault knobs


def test_nack_probability_refuses_that_share_of_messages():
    _, bus, addr, _ = mpu(faults=ChipFaults(nack_probability=0.2), seed=5)
    failures = 0
    for _ in range(2000):
        try:
            bus.write_byte_data(addr, SMPLRT_DIV, 1)  # one message
        except OSError as e:
            assert e.errno == errno.EREMOTEIO
            failures += 1
    assert failures == pytest.approx(400, abs=60)


def test_nack_bursts_and_a_dead_chip():
    faults = ChipFaults(nack_bursts=((1.0, 0.5),), nack_errno=errno.EIO, dead_after_s=5.0)
    clock, bus, addr, _ = lsm(faults=faults)
    bus.read_byte_data(addr, L_WHO_AM_I)
    clock.sleep(1.2)
    with pytest.raises(OSError) as info:
        bus.read_byte_data(addr, L_WHO_AM_I)
    assert info.value.errno == errno.EIO
    clock.sleep(0.5)
    assert bus.read_byte_data(addr, L_WHO_AM_I) == 0x68
    clock.sleep(4.0)
    with pytest.raises(OSError) as info:
        bus.read_byte_data(addr, L_WHO_AM_I)
    assert info.value.errno == errno.EREMOTEIO


def test_wrong_who_am_i_stuck_axis_and_small_fifo_knobs():
    faults = ChipFaults(who_am_i=0x70, stuck_axis=1, stuck_counts=1234, stuck_from_s=0.0,
                        fifo_capacity=64)
    clock, bus, addr, chip = mpu(motion=ConstantRate((0.1, 0.2, 0.3)), faults=faults)
    assert bus.read_byte_data(addr, WHO_AM_I) == 0x70
    mpu_stream(bus, addr)
    clock.sleep(0.1)
    raw = bus.read_i2c_block_data(addr, GYRO_XOUT_H, 4)
    assert be16(raw[2], raw[3]) == 1234
    assert chip.fifo_level == 64
    assert bus.read_byte_data(addr, INT_STATUS) & 0x10


def test_make_emulated_imu_rejects_unknown_models_and_shares_a_bus():
    with pytest.raises(ValueError, match="lsm9ds1"):
        make_emulated_imu("bmi160", VirtualClock())
    clock = VirtualClock()
    bus, a = make_emulated_imu("mpu9250", clock)
    bus2, b = make_emulated_imu("lsm9ds1", clock, bus=bus)
    # each with its magnetometer die: the AK8963 behind the bypass, the LSM9DS1's at 0x1E
    assert bus2 is bus and bus.addresses == (0x0C, 0x1E, 0x68, 0x6B)
    assert isinstance(bus.device(a), EmulatedMPU9250)
    assert isinstance(bus.device(b), EmulatedLSM9DS1)
    with pytest.raises(ValueError, match="variant"):
        EmulatedMPU9250(clock, variant="mpu6050")


# ----------------------------------------------------------------------------- anti-aliasing
def test_each_sample_carries_the_mean_rate_over_its_period():
    # Default chips stand in for the low-pass filter and decimation of a real gyro: a ramp
    # reads its value half a period earlier, and fast motion at a multiple of the output rate
    # (a servo's commutation ripple) does not alias into the samples.
    ramp = FunctionMotion(lambda t: np.column_stack([t, 0 * t, 0 * t]))
    period = 1e-3
    fast = FunctionMotion(lambda t: np.column_stack(
        [0 * t, 0.5 * np.sin(2 * np.pi * 3 / period * t + 0.3), 0 * t]))
    for motion, check in ((ramp, "ramp"), (fast, "fast")):
        clock = VirtualClock()
        bus, addr = make_emulated_imu("mpu9250", clock, motion,
                                      SensorTruth(noise_density_rad_s_sqrt_hz=0.0),
                                      output_filter=False)
        mpu_stream(bus, addr)  # 1 kHz
        chip = bus.device(addr)
        k0 = chip.fifo_enables[-1]
        clock.sleep(0.04)
        w, r = i2c_msg.write(addr, [FIFO_R_W]), i2c_msg.read(addr, 8 * 32)
        bus.i2c_rdwr(w, r)
        g = np.frombuffer(bytes(r), ">i2").reshape(32, 4)[:, 1:] / 131 * DEG
        times = chip.sample_time(np.arange(k0 + 1, k0 + 33))
        if check == "ramp":
            np.testing.assert_allclose(g[:, 0], times - period / 2, atol=DEG / 131)
        else:
            assert np.max(np.abs(g[:, 1])) <= DEG / 131 + 1e-12  # nulled, not aliased
    with pytest.raises(ValueError, match="subsamples"):
        make_emulated_imu("mpu9250", VirtualClock(), subsamples=0)
