"""The emulated accelerometer's errors (issue 15): register-level readings against the truth,
sizes against the MPU-9250 datasheet's Table 2 (written out here), and the manifest's
calibration against its definition ``f = A (a + b)``."""

import math

import numpy as np

from gyrocal.drivers.clock import VirtualClock
from gyrocal.drivers.emulated.accel import AccelTruth, draw_accel_truth
from gyrocal.drivers.emulated.imu_chips import SensorTruth, make_emulated_imu
from gyrocal.drivers.emulated.motion import ConstantRate

# MPU-9250 registers (hardware reference §1.2) and the ±2 g sensitivity (§1.5)
SMPLRT_DIV, CONFIG, FIFO_EN, ACCEL_XOUT_H = 0x19, 0x1A, 0x23, 0x3B
USER_CTRL, PWR_MGMT_1, FIFO_COUNTH, FIFO_R_W = 0x6A, 0x6B, 0x72, 0x74
LSB_PER_G = 16384


def _chip(accel: AccelTruth):
    clock = VirtualClock()
    truth = SensorTruth(noise_density_rad_s_sqrt_hz=0.0, accelerometer=accel)
    bus, addr = make_emulated_imu("mpu9250", clock, ConstantRate(), truth, subsamples=1, seed=5)
    bus.write_byte_data(addr, PWR_MGMT_1, 0x01)
    bus.write_byte_data(addr, SMPLRT_DIV, 0)  # 1 kHz
    bus.write_byte_data(addr, CONFIG, 0x41)
    return clock, bus, addr


def test_still_chip_reads_sensing_times_gravity_minus_bias():
    c = np.array([[1.02, 0.01, -0.015], [0.005, 0.98, 0.012], [-0.01, 0.02, 1.03]])
    b = np.array([0.05, -0.04, 0.07])
    clock, bus, addr = _chip(AccelTruth(c, b, 0.0))
    clock.sleep(0.01)
    raw = bytes(bus.read_i2c_block_data(addr, ACCEL_XOUT_H, 6))
    counts = np.frombuffer(raw, ">i2")
    expect = np.rint((c @ [0, 0, 1.0] - b) * LSB_PER_G)  # the emulator's still pose: +1 g on z
    np.testing.assert_array_equal(counts, expect)


def test_noise_through_the_fifo_has_the_datasheet_density():
    density = 300e-6  # g/√Hz, MPU-9250 Table 2
    clock, bus, addr = _chip(AccelTruth(np.eye(3), (0.0, 0.0, 0.0), density))
    bus.write_byte_data(addr, USER_CTRL, 0x04)
    bus.write_byte_data(addr, FIFO_EN, 0x08)  # accelerometer only: 6-byte frames
    bus.write_byte_data(addr, USER_CTRL, 0x40)
    frames = []
    for _ in range(40):
        clock.sleep(0.05)
        hi, lo = bus.read_i2c_block_data(addr, FIFO_COUNTH, 2)
        n = ((hi << 8) | lo) // 6 * 6
        data = b""
        while len(data) < n:
            data += bytes(bus.read_i2c_block_data(addr, FIFO_R_W, min(30, n - len(data))))
        frames.append(np.frombuffer(data, ">i2").reshape(-1, 3))
    a = np.vstack(frames) / LSB_PER_G
    # per sample at 1 kHz behind the accelerometer DLPF at its reset setting (ACCEL_CONFIG_2
    # A_DLPFCFG 0: 218.1 Hz, register map), the noise entering ahead of it: the bilinear
    # first-order stand-in's N √(1000 k / (1 + k)), k = tan(π 218.1 / 1000): 6.4 mg (9.5 mg
    # unfiltered)
    k = math.tan(math.pi * 218.1 / 1000.0)
    sigma = density * math.sqrt(1000.0 * k / (1 + k))
    assert a.shape[0] > 1500
    np.testing.assert_allclose(a.std(axis=0), sigma, rtol=0.1)
    np.testing.assert_allclose(a.mean(axis=0), [0, 0, 1], atol=5 * sigma / math.sqrt(len(a)))


def test_drawn_errors_stay_within_the_mpu9250_table2_figures():
    for seed in range(50):
        t = draw_accel_truth("mpu9250", seed)
        c = np.asarray(t.sensing)
        assert np.all(np.abs(np.diag(c) - 1) <= 0.03)  # initial tolerance ±3 %
        assert np.all(np.abs(c - np.diag(np.diag(c))) <= 0.02)  # cross-axis ±2 %
        assert np.all(np.abs(t.bias_g) <= [0.060, 0.060, 0.080])  # zero-g ±60/60/80 mg
        assert t.noise_density_g_sqrt_hz == 300e-6
    assert draw_accel_truth("mpu9250", 1) == draw_accel_truth("mpu9250", 1)
    assert draw_accel_truth("mpu9250", 1) != draw_accel_truth("mpu9250", 2)


def test_manifest_calibration_inverts_the_reading():
    t = draw_accel_truth("mpu9250", 7)
    m = t.manifest()
    a_mat = np.array(m["matrix"])
    assert np.all(np.triu(a_mat, 1) == 0) and np.all(np.diag(a_mat) > 0)
    rng = np.random.default_rng(0)
    f = rng.standard_normal((20, 3)) * 9.8  # m/s²
    reading = t.reading(f / 9.80665) * 9.80665  # m/s², as a reader scales counts
    calibrated = (reading + np.array(m["bias_m_s2"])) @ a_mat.T
    # the calibration's frame differs from the force's by a rotation only
    np.testing.assert_allclose(np.linalg.norm(calibrated, axis=1), np.linalg.norm(f, axis=1),
                               rtol=1e-12)
    r, *_ = np.linalg.lstsq(f, calibrated, rcond=None)
    np.testing.assert_allclose(r.T @ r, np.eye(3), atol=1e-12)


def test_sim_jig_accelerometer_sees_gravity_through_its_errors():
    """``build_sim`` with every effect on: the still chip's accelerometer registers read
    ``C f − b`` for the jig's true specific force (gravity in the home pose), with the truth
    the manifest gives; with ``accel-errors`` off they read the force itself."""
    from gyrocal.kit.config import default_config
    from gyrocal.kit.sim import REALISM_EFFECTS, build_sim

    for effects in (None, [e for e in REALISM_EFFECTS if e != "accel-errors"]):
        sim = build_sim(default_config(), seed=4, realism=effects)
        bus, addr = sim.imu_bus, sim.imu_address
        bus.write_byte_data(addr, PWR_MGMT_1, 0x01)
        bus.write_byte_data(addr, SMPLRT_DIV, 4)
        bus.write_byte_data(addr, CONFIG, 0x41)
        sim.clock.sleep(0.05)
        counts = np.frombuffer(bytes(bus.read_i2c_block_data(addr, ACCEL_XOUT_H, 6)), ">i2")
        force = sim.jig.specific_force(np.array([sim.clock.monotonic()]))[0]
        truth = sim.truth_manifest().get("accelerometer")
        if effects is None:
            c, b = np.array(truth["sensing"]), np.array(truth["bias_g"])
            sigma = 300e-6 * math.sqrt(200.0)  # one sample's noise at 200 Hz
            assert not np.allclose(c, np.eye(3))
        else:
            assert truth is None
            c, b, sigma = np.eye(3), np.zeros(3), 0.0
        np.testing.assert_allclose(counts / LSB_PER_G, c @ force - b,
                                   atol=5 * sigma + 1.0 / LSB_PER_G)


# Each chip's accelerometer figures, written out from the datasheets (not read from the chip
# data): scale tolerance, cross-axis, zero-g per axis (g), noise density (g/√Hz).
DATASHEET_ACCEL = {
    # PS-MPU-9250A-01 rev 1.0 Table 2
    "mpu9250": (0.03, 0.02, (0.060, 0.060, 0.080), 300e-6),
    # LSM9DS1 DocID025715 Rev 3 Table 3: LA_TyOff ±90 mg (the rest are stand-ins)
    "lsm9ds1": (0.03, 0.02, (0.090, 0.090, 0.090), 300e-6),
    # ICM-20948 DS-000189 rev 1.3 Table 2: ±0.5 %, ±2 %, board-level ±50 mg, 230 µg/√Hz
    "icm20948": (0.005, 0.02, (0.050, 0.050, 0.050), 230e-6),
    # ICM-42688-P DS-000347 rev 1.2 Table 2: ±0.5 %, ±1 %, ±20 mg, 70 µg/√Hz (z)
    "icm42688p": (0.005, 0.01, (0.020, 0.020, 0.020), 70e-6),
    # LSM6DSO DS12140 Rev 3 Table 2: ±1 %, ±20 mg, 75 µg/√Hz at ±4 g (cross-axis stand-in)
    "lsm6dsox": (0.01, 0.02, (0.020, 0.020, 0.020), 75e-6),
}


def test_each_chip_draws_within_its_own_datasheet_figures():
    """Every supported chip's emulated accelerometer uses its own datasheet's figures, not the
    MPU-9250's: the draws stay inside them and, over seeds, reach near their edges."""
    for model, (scale, cross, zero_g, density) in DATASHEET_ACCEL.items():
        draws = [draw_accel_truth(model, seed) for seed in range(60)]
        c = np.array([t.sensing for t in draws])
        b = np.array([t.bias_g for t in draws])
        diag = np.diagonal(c, axis1=1, axis2=2) - 1
        off = c - np.einsum("nii->ni", c)[:, :, None] * np.eye(3)
        assert np.all(np.abs(diag) <= scale + 1e-15), model
        assert np.all(np.abs(off) <= cross + 1e-15), model
        assert np.all(np.abs(b) <= np.array(zero_g) + 1e-15), model
        # uniform draws: 180 terms reach past 90 % of the figure
        assert np.abs(diag).max() > 0.9 * scale and np.abs(b).max(axis=0).min() > 0.8 * min(
            zero_g), model
        assert all(t.noise_density_g_sqrt_hz == density for t in draws), model


def test_sim_manifest_truth_is_the_chips_own():
    """``--sim`` with each chip: the manifest's accelerometer truth is drawn from that chip's
    figures (ICM-42688-P: 70 µg/√Hz, zero-g within ±20 mg), in m/s²."""
    from gyrocal.kit.config import default_config
    from gyrocal.kit.sim import build_sim

    for model in ("icm42688p", "icm20948", "lsm6dsox"):
        cfg = default_config()
        cfg["imu"]["model"] = model
        sim = build_sim(cfg, seed=3)
        truth = sim.truth.manifest()["accelerometer"]
        _, _, zero_g, density = DATASHEET_ACCEL[model]
        assert math.isclose(truth["noise_density_m_s2_sqrt_hz"], density * 9.80665)
        assert np.all(np.abs(truth["bias_g"]) <= np.array(zero_g))
