"""The emulated chips' look-ahead (samples computed ahead on the gimbal, handed out as the clock
reaches them) against the same chip computing each sample when the clock reaches it
(``lookahead_s = 0``, the emulators before the look-ahead): the same readings to the last bit,
whatever the drains (none, one, several samples, a FIFO overflow), the servo commands, the
timed events (a stall) and a mount slip in between. Every realism effect is on, with a die
that warms and temperature coefficients."""

import math

import numpy as np
import pytest

from gyrocal.drivers.clock import VirtualClock
from gyrocal.drivers.emulated.accel import draw_accel_truth
from gyrocal.drivers.emulated.dxl import EmulatedServo
from gyrocal.drivers.emulated.imu_chips import SensorRealism, SensorTruth, make_emulated_imu
from gyrocal.drivers.emulated.jig import GimbalJig
from gyrocal.drivers.emulated.noise import ColouredNoise, Normals
from gyrocal.drivers.emulated.thermal import DieTemperature, parse_ambient
from gyrocal.drivers.imu import open_imu

B = math.radians(10.0) / 3600.0  # bias instability, rad/s
K = 2e-6  # rate random walk, rad/s/√s


def _spin(servo, units):
    writes = [("Goal Velocity", units)]
    if not servo.torque_enabled():
        writes[:0] = [("Operating Mode", 1), ("Torque Enable", 1), ("Profile Acceleration", 40)]
    for name, value in writes:
        item = servo.table[name]
        assert servo.write(item.address, item.to_bytes(value)) == 0


def _run(model, lookahead_s, odr, lookahead_max=256, **open_kw):
    clock = VirtualClock()
    servos = [EmulatedServo(i, clock=clock, seed=40 + i) for i in (1, 2, 3)]
    jig = GimbalJig(servos, seed=4, wobble_deg=0.05, lever_arm_m=(0.02, -0.015, 0.03))
    g_sens = np.random.default_rng(9).uniform(-1, 1, (3, 3)) * math.radians(0.1)
    realism = SensorRealism(bias_instability_rad_s=B, rate_random_walk_rad_s_sqrt_s=K,
                            dlpf_delay=True, g_sensitivity_rad_s_per_g=g_sens,
                            specific_force=True)
    truth = SensorTruth(scale=(1.01, 0.98, 1.02), bias=(0.01, -0.02, 0.005),
                        misalignment=((1, 0.01, -0.01), (0.005, 1, 0.01), (0, -0.01, 1)),
                        realism=realism, clock_ppm=150.0,
                        accelerometer=draw_accel_truth("mpu9250", 4),
                        bias_temp_coeff_rad_s_per_c=(1e-4, -2e-4, 5e-5),
                        scale_temp_coeff_per_c=(2e-4, 0.0, -1e-4),
                        temperature_c=DieTemperature(parse_ambient("ramp:20:30:5")))
    bus, addr = make_emulated_imu(model, clock, jig, truth, seed=5)
    chip = bus.device(addr)
    if lookahead_s is not None:  # None: the chip's own look-ahead
        chip.lookahead_s = lookahead_s
        chip.lookahead_max = lookahead_max
    reader = open_imu(model, bus, addr, clock=clock, range_dps=500, odr_hz=odr, **open_kw)
    reader.start()
    servos[1].stall_at(clock.monotonic() + 0.6, 0.5)
    waits = np.random.default_rng(11).uniform(0.0, 2.4 / odr, 300)
    waits[[110, 230]] = 0.8  # the FIFO overflows
    batches = []
    for i, wait in enumerate(waits):
        clock.sleep(wait)
        if i == 20:
            _spin(servos[0], 80)
        elif i == 45:
            _spin(servos[1], -60)
        elif i == 130:
            _spin(servos[0], 0)
        elif i == 150:
            jig.slip_at(clock.monotonic() + 0.01, (0.001, -0.002, 0.0015), 0.02)
        elif i == 170:
            _spin(servos[2], 120)
        b = reader.read()
        # the servos' motion is frozen where the chip's reads froze it (a later command
        # switches there)
        frozen = [s.motor._frozen for s in servos]
        batches.append((b.t, b.rate, b.accel, b.temperature_c, [g.samples for g in b.gaps],
                        frozen))
    return batches, chip


# The ICM-42688-P's look-ahead is cut at 7 samples (as a rate over 1 kHz is cut at 256):
# blocks then end mid-drain and after drains of several samples.
# The chip's own look-ahead (None: 256 samples at 200 Hz, a calibration's rate) too.
@pytest.mark.parametrize(("model", "odr", "lookahead_s", "cap", "open_kw"), [
    ("mpu9250", 200.0, 0.1, 256, {"lowpass_hz": 92}),
    ("mpu9250", 200.0, None, None, {"lowpass_hz": 92}),
    ("icm42688p", 200.0, 0.1, 7, {}),
])
def test_samples_computed_ahead_are_those_computed_on_time(model, odr, lookahead_s, cap,
                                                           open_kw):
    ahead, chip = _run(model, lookahead_s, odr, cap, **open_kw)
    on_time, _ = _run(model, 0.0, odr, **open_kw)
    assert len(ahead) == len(on_time)
    n_samples = sum(len(b[0]) for b in ahead)
    assert n_samples > 400
    assert any(b[4] for b in ahead)  # the overflows were seen
    for a, b in zip(ahead, on_time, strict=True):
        for x, y in zip(a[:4], b[:4], strict=True):
            assert np.array_equal(x, y, equal_nan=True)
        assert a[4:] == b[4:]


def test_one_step_coloured_noise_ahead_is_the_one_step_draws():
    dt = 0.005 * (1.0 + np.random.default_rng(2).uniform(-1e-9, 1e-9, 40))
    drawn = ColouredNoise(B, K, Normals(np.random.default_rng(3)))
    looked = ColouredNoise(B, K, Normals(np.random.default_rng(3)))
    want = np.vstack([drawn.draw(dt[i:i + 1]) for i in range(dt.size)])
    got, gms, walks = looked.ahead(dt)
    assert np.array_equal(got, want)
    looked.resume(gms[-1], walks[-1], dt.size)
    # the state taken up continues as the drawn one does, a batch of several steps too
    assert np.array_equal(looked.draw(np.full(5, 0.005)), drawn.draw(np.full(5, 0.005)))


def test_normals_hand_out_the_generators_stream_whatever_the_calls():
    n = Normals(np.random.default_rng(8))
    parts = [n.peek(4).copy(), n.standard_normal((2, 3)).ravel()]
    n.skip(5)
    parts.append(n.standard_normal(4000))
    want = np.random.default_rng(8).standard_normal(6 + 5 + 4000)
    assert np.array_equal(parts[0], want[:4])
    assert np.array_equal(np.concatenate((parts[1], parts[2])), np.delete(want, range(6, 11)))
