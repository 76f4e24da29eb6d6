import numpy as np
import pytest

from gyrocal.calib.errors import CalibInputError
from gyrocal.calib.estimators import fit_paired_axis
from gyrocal.calib.segments import Segment
from gyrocal.calib.simulate import SimProtocol, draw_mount_axes, draw_sensors, simulate_raw_run
from gyrocal.calib.windows import extract_observations, trapezoid_weight


def _run(seed, protocol, **kw):
    rng = np.random.default_rng(seed)
    k, b = draw_sensors(rng, 1)
    axes = draw_mount_axes(rng, 1)[0]
    opts = dict(imu_clock_error=0.01, enc_jitter_s=0.003, enc_rate_hz=200.0, imu_jitter_s=0.001)
    opts.update(kw)
    return simulate_raw_run(rng, k[0], b[0], axes, protocol, 0.035, **opts)


def _extract(run, **kw):
    kw.setdefault("window", "auto")
    return extract_observations(run.imu_t, run.imu_rate, run.enc_t, run.enc_motor,
                                run.enc_angle, run.segments, imu_temp=run.imu_temp, **kw)


def _true_mean(run, corners):
    """Noise-free weighted mean reading over a window, from the fine-grid truth (Eq. 1)."""
    lo, hi = np.searchsorted(run.grid_t, [corners[0], corners[3]])
    span = slice(max(lo - 1, 0), hi + 1)  # the weight is 0 outside the window
    t = run.grid_t[span]
    w = trapezoid_weight(t, corners)
    g = run.grid_rate[:, span].T @ run.axes  # sensor-frame true rate
    m = g / run.scale - run.bias
    return np.trapezoid(w[:, None] * m, t, axis=0) / np.trapezoid(w, t)


@pytest.fixture(scope="module")
def three_turns():
    """One run of three 3 rad/s turns per servo with 1 s rests, shared by the tests that fit it
    as it is or damage a copy of one of its parts (read-only: none can change it)."""
    run = _run(6, SimProtocol(speed=3.0, turns=3, rest_s=1.0))
    for value in vars(run).values():
        if isinstance(value, np.ndarray):
            value.flags.writeable = False
    return run


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_multi_turn_windows_are_tapered_and_exact(seed):
    # Accelerating and decelerating turns, 5 % ripple, 3 ms encoder jitter, IMU clock 1 % off.
    run = _run(seed, SimProtocol(speed=3.0, turns=4, rest_s=1.0, ripple=0.05))
    ex = _extract(run, window="tapered")
    assert len(ex.windows) == 6 and ex.warnings == ()
    obs = ex.observations
    for i, w in enumerate(ex.windows):
        assert w.kind == "tapered" and w.revolutions == 3.0
        truth = run.true_weighted_rate(w.motor, w.corners)
        assert abs(w.rate - truth) / abs(truth) < 1e-4
        z = (obs.mean[i] - _true_mean(run, w.corners)) / obs.mean_std[i]
        assert np.all(np.abs(z) < 4.5), z


@pytest.mark.parametrize("seed", [3, 4])
def test_papers_one_turn_protocol_uses_rest_to_rest_windows(seed):
    run = _run(seed, SimProtocol(speed=np.radians(60), turns=1, rest_s=3.0))
    ex = _extract(run)
    assert [w.kind for w in ex.windows] == ["rest-to-rest"] * 6
    for i, w in enumerate(ex.windows):
        a, a2, b2, b = w.corners
        assert a < a2 and b2 < b  # still time on both sides
        truth = run.true_weighted_rate(w.motor, w.corners)
        # One revolution between still angles: the encoder's quantisation of the two still
        # angles (q/√12 each, q = 2π/4096) is a floor of about 1e-4 relative, which rate_std
        # reports.
        obs = ex.observations
        rate_std = np.sqrt(obs.reference_covariance()[i, i])
        q = 2 * np.pi / 4096
        assert rate_std == pytest.approx(np.sqrt(2 / 12) * q * abs(w.rate) / (2 * np.pi), rel=0.01)
        assert abs(w.rate - truth) < 4 * rate_std
        assert abs(w.rate - truth) / abs(truth) < 3e-4
        z = (ex.observations.mean[i] - _true_mean(run, w.corners)) / ex.observations.mean_std[i]
        assert np.all(np.abs(z) < 4.5)


def test_auto_chooses_the_window_with_the_least_predicted_variance():
    protocol = SimProtocol(speed=3.0, turns=3, rest_s=1.0)
    rng = np.random.default_rng(14)
    k, b = draw_sensors(rng, 1)
    axes = draw_mount_axes(rng, 1)[0]
    kinds = {}
    for noise in (0.0025, 0.2):
        run = simulate_raw_run(np.random.default_rng(15), k[0], b[0], axes, protocol, noise,
                               enc_rate_hz=200.0)
        kinds[noise] = {w.kind for w in _extract(run).windows}
    # A quiet gyro: the still angles' quantisation dominates, so the steady revolutions win.
    # A noisy gyro: its noise dominates, so the window with every sample of the turn wins.
    assert kinds == {0.0025: {"tapered"}, 0.2: {"rest-to-rest"}}


def test_a_servos_two_turns_share_the_still_angle_between_them():
    run = _run(3, SimProtocol(speed=np.radians(60), turns=1, rest_s=3.0))
    obs = _extract(run).observations
    # Per servo: start still, (turn -), shared still, (turn +), end still -> 3 angles a servo.
    assert obs.n_still_angles == 9
    for i in range(0, 6, 2):
        assert obs.motor[i] == obs.motor[i + 1]
        assert obs.ref_end[i] == obs.ref_start[i + 1]
        assert len({obs.ref_start[i], obs.ref_end[i], obs.ref_end[i + 1]}) == 3
    C = obs.reference_covariance()
    # The shared angle correlates the two windows negatively (it ends one and starts the other).
    assert C[0, 1] < 0 and C[0, 2] == 0


def test_rests_measure_minus_the_bias():
    run = _run(5, SimProtocol(speed=2.0, turns=3, rest_s=2.0))
    ex = _extract(run)
    obs = ex.observations
    assert obs.n_rests == 7
    z = (obs.rest_mean + run.bias) / obs.rest_mean_std
    assert np.all(np.abs(z) < 4.5)
    np.testing.assert_allclose(ex.noise_correlation, 1.0)
    assert obs.temperature_c == pytest.approx(25.0)


def test_whole_chain_recovers_the_truth(three_turns):
    run = three_turns
    res = fit_paired_axis(_extract(run).observations)
    assert res.success and res.consistency.ok
    assert np.all(np.abs(res.scale - run.scale) < 4 * res.scale_std)
    assert np.all(np.abs(res.bias - run.bias) < 4 * res.bias_std)


def test_coloured_noise_is_corrected_on_the_rests():
    run = _run(7, SimProtocol(speed=3.0, turns=3, rest_s=4.0), enc_jitter_s=0.0)
    rng = np.random.default_rng(70)
    phi = 0.6
    e = rng.normal(0, 0.03, run.imu_rate.shape)
    ar = np.zeros_like(e)
    for i in range(1, e.shape[0]):
        ar[i] = phi * ar[i - 1] + e[i]
    clean = np.stack([np.interp(run.imu_t, run.grid_t, run.grid_rate[s]) for s in range(3)], 1)
    m = clean @ run.axes / run.scale - run.bias + ar
    ex = extract_observations(run.imu_t, m, run.enc_t, run.enc_motor, run.enc_angle,
                              run.segments)
    # Long-run variance of 10-sample block means over the first-difference variance, AR(1).
    B = 10
    lags = np.arange(-B + 1, B)
    block_var = np.sum((B - np.abs(lags)) * phi ** np.abs(lags)) / B**2  # × var(x)
    expected = block_var * B / (1 - phi)
    np.testing.assert_allclose(ex.noise_correlation, expected, rtol=0.2)


def test_a_gap_in_the_gyro_stream_drops_that_turn_with_a_warning(three_turns):
    run = three_turns
    seg = [s for s in run.segments if s.kind == "rotate"][2]
    mid = (seg.t_start + seg.t_end) / 2
    keep = np.abs(run.imu_t - mid) > 0.1
    ex = extract_observations(run.imu_t[keep], run.imu_rate[keep], run.enc_t, run.enc_motor,
                              run.enc_angle, run.segments)
    assert len(ex.windows) == 5
    assert any(f"segment {seg.index}: gap" in w for w in ex.warnings)


def test_a_rest_with_movement_is_skipped(three_turns):
    run = three_turns
    rest = [s for s in run.segments if s.kind == "rest"][1]
    enc_angle = run.enc_angle.copy()
    nudge = (run.enc_t > rest.t_start + 0.4) & (run.enc_t < rest.t_start + 0.6) & (
        run.enc_motor == 2)
    enc_angle[nudge] += 0.05
    ex = extract_observations(run.imu_t, run.imu_rate, run.enc_t, run.enc_motor, enc_angle,
                              run.segments)
    assert ex.observations.n_rests == 6
    assert any("moved during the rest" in w for w in ex.warnings)


# ------------------------------------------------------------------ bad input
def test_truncated_gyro_stream_is_named(three_turns):
    run = three_turns
    cut = run.imu_t < run.imu_t[-1] * 0.6
    with pytest.raises(CalibInputError, match="the recording is truncated"):
        extract_observations(run.imu_t[cut], run.imu_rate[cut], run.enc_t, run.enc_motor,
                             run.enc_angle, run.segments)


def test_missing_servo_encoder_is_named(three_turns):
    run = three_turns
    keep = run.enc_motor != 3
    with pytest.raises(CalibInputError, match="no encoder readings of servo 3"):
        extract_observations(run.imu_t, run.imu_rate, run.enc_t[keep], run.enc_motor[keep],
                             run.enc_angle[keep], run.segments)


def test_turn_against_its_command_is_named(three_turns):
    run = three_turns
    segs = [Segment(s.index, s.kind, s.motor, -s.direction, s.speed, s.t_start, s.t_end)
            if s.kind == "rotate" else s for s in run.segments]
    with pytest.raises(CalibInputError, match="against its command"):
        extract_observations(run.imu_t, run.imu_rate, run.enc_t, run.enc_motor, run.enc_angle,
                             segs)


def test_stalled_servo_is_named(three_turns):
    run = three_turns
    angle = np.where(run.enc_motor == 1, 0.0, run.enc_angle)
    with pytest.raises(CalibInputError, match="stalled"):
        extract_observations(run.imu_t, run.imu_rate, run.enc_t, run.enc_motor, angle,
                             run.segments)


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        (dict(imu_rate=np.zeros((5, 2))), r"imu_rate \(N, 3\)"),
        (dict(imu_t=np.array([0.0, 0.0, 1.0]), imu_rate=np.zeros((3, 3))), "strictly increasing"),
        (dict(enc_angle=np.array([np.nan])), "enc_t, enc_motor and enc_angle"),
    ],
)
def test_malformed_arrays(kwargs, message):
    args = dict(imu_t=np.arange(5.0), imu_rate=np.zeros((5, 3)), enc_t=np.zeros(2),
                enc_motor=np.ones(2), enc_angle=np.zeros(2), segments=())
    args.update(kwargs)
    with pytest.raises(CalibInputError, match=message):
        extract_observations(**args)


def test_trapezoid_weight_at_known_points():
    w = trapezoid_weight(np.array([0.0, 1.0, 1.5, 2.0, 5.0, 6.5, 7.0, 8.0]), (1.0, 2.0, 6.0, 7.0))
    np.testing.assert_allclose(w, [0, 0, 0.5, 1, 1, 0.5, 0, 0])


def test_a_tilted_turns_ripple_is_not_taken_for_noise():
    # A servo whose axis lies between the sensor's x and y (as a posed turn's does) carries its
    # 5 % speed ripple on both: real motion that the encoder reference sees too and that cancels
    # in the window's mean, so no component's noise may include it. The simulator's white noise
    # (noise_std, the truth) is what every window's noise must be; before, the tilted axis's
    # components read up to 1.5x it.
    rng = np.random.default_rng(41)
    k, b = draw_sensors(rng, 1)
    axes = np.array([[0.6, 0.8, 0.0], [-0.8, 0.6, 0.0], [0.0, 0.0, 1.0]])
    noise_std = 0.005
    run = simulate_raw_run(rng, k[0], b[0], axes, SimProtocol(speed=3.0, turns=2, rest_s=1.0,
                                                              ripple=0.05), noise_std)
    obs = _extract(run).observations
    assert obs.noise.shape == (6, 3)
    np.testing.assert_allclose(obs.noise, noise_std, rtol=0.15)


def test_window_sigma_holds_the_scatter_of_filtered_noise():
    # An independent noise generator: white noise through a second-order Butterworth low-pass
    # at 67 Hz (the LSM6DSOX's at 208 Hz, AN5192), DC gain 1, so its long-run variance is the
    # white input's, whatever the filter does to first differences (they read 0.6 of it). On
    # the planned short rests (0.6 s, 0.2 s used of each), every window's and rest's σ must
    # hold the scatter of its mean about the noise-free truth.
    from scipy.signal import butter, lfilter

    run = _run(20, SimProtocol(speed=3.0, turns=3, rest_s=0.6), enc_jitter_s=0.0,
               imu_jitter_s=0.0, imu_clock_error=0.0)
    fs = 1 / np.median(np.diff(run.imu_t))
    filt = butter(2, 67.0 * fs / 208.33, fs=fs)
    clean = np.stack([np.interp(run.imu_t, run.grid_t, run.grid_rate[s]) for s in range(3)], 1)
    m0 = clean @ run.axes / run.scale - run.bias
    z = []
    for k in range(2):
        white = np.random.default_rng(200 + k).normal(0, 0.035, (m0.shape[0] + 200, 3))
        noise = lfilter(*filt, white, axis=0)[200:]
        ex = extract_observations(run.imu_t, m0 + noise, run.enc_t, run.enc_motor,
                                  run.enc_angle, run.segments)
        obs = ex.observations
        z += [(obs.mean[i] - _true_mean(run, w.corners)) / obs.mean_std[i]
              for i, w in enumerate(ex.windows)]
        z += list((obs.rest_mean + run.bias) / obs.rest_mean_std)
    rms = float(np.sqrt(np.mean(np.square(z))))
    # 2 × (6 windows + 7 rests) × 3 axes: an honest σ gives an RMS of 1 ± 0.08
    assert 0.8 < rms < 1.2, rms
