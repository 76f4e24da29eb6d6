"""The emulated sensor's realism effects against their datasheet figures or physics: the Allan
deviation of the coloured noise (allantools as the oracle), the MPU-9250 DLPF's gain at its
cutoff and delay (register map CONFIG table), g-sensitivity, gravity in a known pose, the
lever arm's centripetal ω²r, the wobble's once-per-revolution period, and the servo encoder's
read latency (Return Delay Time and the packets at the bus baud)."""

import math

import allantools
import numpy as np
import pytest

from gyrocal.drivers.clock import VirtualClock
from gyrocal.drivers.emulated.dxl import make_emulated_gimbal
from gyrocal.drivers.emulated.imu_chips import SensorRealism, SensorTruth, make_emulated_imu
from gyrocal.drivers.emulated.jig import STANDARD_GRAVITY, GimbalJig
from gyrocal.drivers.emulated.motion import ConstantRate, FunctionMotion
from gyrocal.drivers.emulated.noise import ColouredNoise, allan_deviation
from gyrocal.drivers.imu import open_imu
from gyrocal.drivers.imu.chips import MPU9250_DLPF_DELAY_S

B = math.radians(10.0) / 3600.0  # 10 °/h
K = 2e-6


@pytest.mark.parametrize(("b", "k"), [(B, 0.0), (0.0, 1e-5), (B, K)])
def test_coloured_noise_has_its_allan_deviation_at_1_s_and_100_s(b, k):
    dt = 0.05
    n = 400_000  # 20 000 s
    x = ColouredNoise(b, k, np.random.default_rng(7)).draw(np.full(n, dt))[:, 0]
    taus = np.array([1.0, 100.0])
    got_taus, adev, _, _ = allantools.oadev(x, rate=1 / dt, data_type="freq", taus=taus)
    want = allan_deviation(got_taus, 0.0, b, k)
    assert adev[0] == pytest.approx(want[0], rel=0.06)
    assert adev[1] == pytest.approx(want[1], rel=0.25)  # ~200 independent 100 s averages


def test_the_flicker_floor_is_the_bias_instability_figure():
    tau = np.geomspace(1.0, 1000.0, 31)
    floor = allan_deviation(tau, 0.0, B, 0.0)
    # IEEE Std 952 flat floor 0.664 B, within the stand-in's documented ripple
    assert np.all(np.abs(floor / (0.664 * B) - 1) < 0.08)


def test_coloured_noise_continues_across_calls():
    a = ColouredNoise(B, K, np.random.default_rng(3))
    b = ColouredNoise(B, K, np.random.default_rng(3))
    whole = a.draw(np.full(1000, 0.01))
    parts = np.vstack([b.draw(np.full(400, 0.01)), b.draw(np.full(600, 0.01))])
    # the same process; the draws differ only in how the generator's stream is split
    assert whole.shape == parts.shape
    assert abs(parts[399, 0] - parts[400, 0]) < 10 * B


def _mpu(motion, realism, odr=200.0, lowpass=None, noise=1e-3):
    # white noise of a few counts dithers the quantisation (and keeps the reader's stuck-axis
    # check quiet), so averages are unbiased
    clock = VirtualClock()
    truth = SensorTruth(noise_sigma_rad_s=noise, realism=realism)
    bus, addr = make_emulated_imu("mpu9250", clock, motion, truth, subsamples=8)
    reader = open_imu("mpu9250", bus, addr, clock=clock, range_dps=500, odr_hz=odr,
                      lowpass_hz=lowpass)
    reader.start()
    return clock, reader, bus.device(addr)


def _record(clock, reader, seconds):
    t, g = [], []
    while clock.monotonic() < seconds:
        clock.sleep(0.02)
        b = reader.read()
        t.append(b.t)
        g.append(b.rate)
    return np.concatenate(t), np.vstack(g)


def _fit_sine(t, y, f):
    basis = np.column_stack([np.sin(2 * np.pi * f * t), np.cos(2 * np.pi * f * t)])
    (s, c), *_ = np.linalg.lstsq(basis, y, rcond=None)
    return math.hypot(s, c), math.atan2(c, s)  # amplitude, phase lead


@pytest.mark.parametrize("bandwidth", [92.0, 20.0, 5.0])
def test_mpu9250_dlpf_delay_is_the_config_tables(bandwidth):
    amp, f = math.radians(100), 0.5
    motion = FunctionMotion(lambda t: np.column_stack(
        [amp * np.sin(2 * np.pi * f * t), 0 * t, 0 * t]))
    clock, reader, chip = _mpu(motion, SensorRealism(dlpf_delay=True), lowpass=bandwidth)
    assert chip.cutoff_hz() == bandwidth
    t, g = _record(clock, reader, 6.0)
    keep = t > 2.0
    # the emulated chip's true sample times, not the reader's estimates
    _, phase = _fit_sine(t[keep], g[keep, 0], f)
    delay = -phase / (2 * np.pi * f)
    assert delay == pytest.approx(MPU9250_DLPF_DELAY_S[bandwidth], abs=0.25e-3)


@pytest.mark.parametrize("bandwidth", [20.0, 5.0])
def test_mpu9250_dlpf_gain_at_its_cutoff_is_minus_3_db(bandwidth):
    amp = math.radians(100)
    motion = FunctionMotion(lambda t: np.column_stack(
        [amp * np.sin(2 * np.pi * bandwidth * t), 0 * t, 0 * t]))
    clock, reader, _ = _mpu(motion, SensorRealism(dlpf_delay=True), odr=1000.0,
                            lowpass=bandwidth)
    t, g = _record(clock, reader, 3.0)
    keep = t > 1.5
    gain, _ = _fit_sine(t[keep], g[keep, 0], bandwidth)
    # the first-order stand-in is exactly −3 dB at the cutoff; the sub-sample boxcar over one
    # 1 ms period takes sinc(f/1000) off that
    boxcar = np.sinc(bandwidth / 1000.0)
    assert gain / amp == pytest.approx(boxcar / math.sqrt(2), abs=0.01)


def test_mpu9250_dlpf_runs_at_the_internal_1khz_rate_before_decimation():
    # Register map CONFIG/SMPLRT_DIV: the DLPF filters the 1 kHz internal samples and
    # SMPLRT_DIV decimates its output. At 200 Hz out, a 60 Hz input keeps the gain of the
    # 92 Hz filter run at 1 kHz (the first-order bilinear stand-in), not of one run at 200 Hz.
    amp, f, fc = math.radians(100), 60.0, 92.0
    motion = FunctionMotion(lambda t: np.column_stack(
        [amp * np.sin(2 * np.pi * f * t), 0 * t, 0 * t]))
    clock, reader, _ = _mpu(motion, SensorRealism(dlpf_delay=True), odr=200.0, lowpass=fc)
    t, g = _record(clock, reader, 2.0)
    keep = t > 1.0
    gain, _ = _fit_sine(t[keep], g[keep, 0], f)

    def bilinear_gain(rate):
        k = math.tan(math.pi * fc / rate)
        z = np.exp(-2j * np.pi * f / rate)
        return abs(k / (1 + k) * (1 + z) / (1 + (k - 1) / (k + 1) * z))

    expected = bilinear_gain(1000.0) * np.sinc(f / 1000.0)  # boxcar over one 1 ms sample
    assert gain / amp == pytest.approx(expected, abs=0.01)
    assert abs(bilinear_gain(200.0) - expected) > 0.05  # the test tells the two apart


def test_g_sensitivity_adds_its_figure_per_g():
    g_sens = np.zeros((3, 3))
    g_sens[0, 2] = math.radians(0.1)  # 0.1 °/s/g, datasheet typical
    clock, reader, _ = _mpu(ConstantRate(), SensorRealism(g_sensitivity_rad_s_per_g=g_sens))
    _, g = _record(clock, reader, 2.0)
    # at rest with no specific-force model the chip feels +1 g on z (400 samples: σ 5e-5)
    assert g[:, 0].mean() == pytest.approx(math.radians(0.1), abs=2e-4)
    assert abs(g[:, 1].mean()) < 2e-4


class _Fixed:
    """A joint held at a fixed angle, or turning at a fixed rate."""

    def __init__(self, dxl_id, angle=0.0, rate=0.0):
        self.dxl_id, self.angle, self.rate = dxl_id, angle, rate

    def true_motion(self, t):
        t = np.asarray(t, dtype=float)
        return self.angle + self.rate * t, np.full(t.shape, self.rate)


def test_gravity_is_seen_in_the_true_orientation():
    jig = GimbalJig([_Fixed(1, 0.0), _Fixed(2, 0.0), _Fixed(3, 0.0)], tilt_deg=0.0, mount=0.0,
                    home_time=0.0)
    jig.joints[0].angle = math.pi / 2  # 90° about x: +z of the base is +y of the sensor
    f = jig.specific_force(np.array([1.0, 2.0]))
    np.testing.assert_allclose(f, [[0.0, 1.0, 0.0]] * 2, atol=1e-12)
    # and through the chip's accelerometer registers, counts at the reader's ±4 g (8192 LSB/g,
    # PS-MPU-9250A-01 Table 2), and in the reader's batch as specific force in m/s²
    clock = VirtualClock()
    clock.sleep(0.0)
    truth = SensorTruth(noise_sigma_rad_s=0.0, realism=SensorRealism(specific_force=True))
    bus, addr = make_emulated_imu("mpu9250", clock, jig, truth)
    reader = open_imu("mpu9250", bus, addr, clock=clock, range_dps=500, odr_hz=200)
    reader.start()
    clock.sleep(0.1)
    batch = reader.read()
    chip = bus.device(addr)
    np.testing.assert_array_equal(chip._latest.accel, [0, 8192, 0])
    np.testing.assert_allclose(batch.accel, [[0.0, 9.80665, 0.0]] * len(batch), atol=1e-12)


def test_g_sensitivity_sees_the_true_orientation_when_the_accelerometer_is_not_shown_it():
    # the sensor held at 90° about x: the true specific force is +1 g on the sensor's y. With
    # the accelerometer's gravity knob off the accelerometer still reads +1 g on z, but the
    # gyro's g-sensitivity (here only its y column) must see the true +y force
    jig = GimbalJig([_Fixed(1, 0.0), _Fixed(2, 0.0), _Fixed(3, 0.0)], tilt_deg=0.0, mount=0.0,
                    home_time=0.0)
    jig.joints[0].angle = math.pi / 2
    g_sens = np.zeros((3, 3))
    g_sens[0, 1] = math.radians(0.1)  # x rate per g on y
    clock, reader, chip = _mpu(jig, SensorRealism(g_sensitivity_rad_s_per_g=g_sens))
    _, g = _record(clock, reader, 2.0)
    assert g[:, 0].mean() == pytest.approx(math.radians(0.1), abs=2e-4)
    np.testing.assert_array_equal(chip._latest.accel[:2], [0, 0])  # the knob is still off


def test_lever_arm_adds_the_centripetal_omega_squared_r():
    w = 2.0  # rad/s about z
    r = np.array([0.1, 0.0, 0.05])
    jig = GimbalJig([_Fixed(1), _Fixed(2), _Fixed(3, rate=w)], tilt_deg=0.0, mount=0.0,
                    home_time=0.0, lever_arm_m=r)
    f = jig.specific_force(np.array([0.5, 1.3, 2.9]))
    # gravity stays on z (turning about it); the centripetal term points at the axis
    want = np.array([-w**2 * r[0] / STANDARD_GRAVITY, 0.0, 1.0])
    np.testing.assert_allclose(f, np.tile(want, (3, 1)), atol=1e-9)


def test_lever_arm_adds_the_tangential_alpha_cross_r():
    alpha = 3.0  # rad/s² about z, from rest
    r = np.array([0.1, 0.0, 0.0])

    class Accelerating(_Fixed):
        def true_motion(self, t):
            t = np.asarray(t, dtype=float)
            return 0.5 * alpha * t**2, alpha * t

    jig = GimbalJig([_Fixed(1), _Fixed(2), Accelerating(3)], tilt_deg=0.0, mount=0.0,
                    home_time=0.0, lever_arm_m=r)
    t = 0.4
    f = jig.specific_force(np.array([t]))[0]
    w = alpha * t
    # in the sensor frame: tangential α r along +y, centripetal −ω² r along −x
    np.testing.assert_allclose(f, [-w**2 * 0.1 / STANDARD_GRAVITY,
                                   alpha * 0.1 / STANDARD_GRAVITY, 1.0], atol=1e-6)


def test_wobble_nods_once_per_revolution_and_leaves_the_mean_rate():
    w = 2 * math.pi  # one revolution per second about z
    eps = math.radians(0.5)
    jig = GimbalJig([_Fixed(1), _Fixed(2), _Fixed(3, rate=w)], tilt_deg=0.0, mount=0.0,
                    home_time=0.0, wobble_deg=0.5, seed=3)
    t = np.linspace(0.0, 4.0, 4001)[:-1]
    rate = jig.rate(t)
    perp = rate[:, :2]
    spec = np.abs(np.fft.rfft(perp[:, 0] - perp[:, 0].mean()))
    freqs = np.fft.rfftfreq(t.size, t[1] - t[0])
    assert freqs[np.argmax(spec)] == pytest.approx(1.0)  # once per revolution
    assert np.max(np.linalg.norm(perp, axis=1)) == pytest.approx(eps * w, rel=0.01)
    # a whole revolution: the mean rate is the axis (to ε²/4), the pose returns to home
    np.testing.assert_allclose(rate.mean(axis=0), [0.0, 0.0, w], atol=w * eps**2)
    np.testing.assert_allclose(jig.orientation(np.array([1.0]))[0], np.eye(3), atol=1e-12)
    tilt = jig.orientation(np.array([0.25]))[0][:, 2]  # a quarter turn: the full nod
    assert math.acos(tilt[2]) == pytest.approx(eps, rel=1e-6)


def test_encoder_read_latency_is_the_return_delay_and_packets_at_the_baud():
    from gyrocal.drivers.dynamixel import Gimbal

    clock = VirtualClock()
    baud = 57_600  # slow enough that the latency is many encoder ticks at full speed
    port, bus, _ = make_emulated_gimbal(clock, (1, 2, 3), seed=2, baudrate=baud)
    servo = bus.servo(1)
    with Gimbal(port, [1, 2, 3], baudrate=baud, clock=clock) as gimbal:
        for name, value in (("Torque Enable", 0), ("Operating Mode", 1), ("Torque Enable", 1),
                            ("Goal Velocity", 200)):
            item = servo.table[name]
            assert servo.write(item.address, item.to_bytes(value)) == 0
        clock.sleep(2.0)
        sent = port.bytes_sent
        s = gimbal.sample()
        instr_bytes = port.bytes_sent - sent
        # servo 1 samples Present Position when its status starts: after the instruction and
        # its Return Delay Time at the bus baud (e-Manual Return Delay Time (9)); the host
        # stamps the transaction's midpoint, later by the rest of the transaction
        t_sample = s.t_start + instr_bytes * 10 / baud + servo.return_delay_s
        rate = float(servo.true_motion(np.array([t_sample]))[1][0])

        def register(t):
            return servo._position_register(float(servo.true_motion(np.array([t]))[0][0]))

        assert abs(rate) > 3.0
        assert abs(int(s.ticks[0]) - register(t_sample)) <= 1
        latency = s.t - t_sample
        assert latency > 3e-3  # 30-odd bytes at 57600 baud before the midpoint
        assert abs(int(s.ticks[0]) - register(s.t)) > 5  # so the midpoint reads another angle
