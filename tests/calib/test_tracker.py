"""The bias tracker against simulated truth (gyrocal.calib.noise_sim): consistency, health,
equivalence."""

import math

import numpy as np
import pytest

from gyrocal.calib.errors import CalibInputError
from gyrocal.calib.model import GyroCalibration
from gyrocal.calib.noise_sim import NoiseModel, sim_calibration, simulate_session
from gyrocal.calib.stationarity import StillSettings, detect_still
from gyrocal.calib.tracker import BiasTracker, TrackerSettings

ODR = 200.0
MODEL = NoiseModel(rate_random_walk=1e-5)


def settings(**kw):
    base = dict(
        odr_hz=ODR,
        noise_density=MODEL.noise_density,
        rate_random_walk=MODEL.rate_random_walk,
        temperature_model=True,
    )
    base.update(kw)
    return TrackerSettings(**base)


def run_session(seed, **sim_kw):
    s = simulate_session(np.random.default_rng(seed), model=MODEL, **sim_kw)
    cal = sim_calibration(np.random.default_rng(1000 + seed), s)
    tr = BiasTracker(settings(), cal)
    r = tr.process(s.t, s.rate, s.temperature_c, finish=True)
    return s, cal, tr, r


def test_thirty_minute_sessions_stay_inside_their_own_3_sigma_band():
    """30 minutes, 10 °C ramp, bias random walk, still periods of 2-5 s between motions.

    A consistent filter keeps its error inside 3σ 99.73 % of the time on average; one session's
    fraction scatters around that because the error is correlated over minutes, so the claim is
    checked on three independent sessions pooled (and each session must stay near it)."""
    fractions, nees = [], []
    for seed in range(3):
        s, _, _, r = run_session(seed, duration_s=1800.0)
        assert s.duration_s == pytest.approx(1800.0)
        assert s.temperature_c[-1] - s.temperature_c[0] == pytest.approx(10.0, abs=0.01)
        z = (r.bias - s.true_bias) / r.bias_std
        fractions.append(np.mean(np.abs(z) <= 3.0, axis=0))
        nees.append(np.mean(z**2, axis=0))
        # the detector never takes a moving sample for a still one, and finds most still time
        assert not np.any(r.still & ~s.still)
        assert r.still.sum() > 0.6 * s.still.sum()
    fractions = np.array(fractions)
    assert np.all(fractions.mean(axis=0) >= 0.99), fractions
    assert np.all(fractions >= 0.97), fractions
    # Normalised estimation error squared near 1: the stated uncertainty is honest, not inflated.
    assert np.all((np.array(nees) > 0.6) & (np.array(nees) < 1.6)), nees


def test_tracker_beats_the_frozen_calibration_on_a_temperature_ramp():
    s, cal, tr, r = run_session(4, duration_s=600.0)
    frozen = np.sqrt(np.mean((np.asarray(cal.bias) - s.true_bias) ** 2, axis=0))
    tracked = np.sqrt(np.mean((r.bias - s.true_bias) ** 2, axis=0))
    assert np.all(tracked < 0.3 * frozen)
    # The temperature coefficient is learnt (truth 3e-4, -2e-4, 1.5e-4 rad/s/°C), to within
    # its stated uncertainty, from a prior of 0 ± 1e-3.
    assert np.all(np.abs(tr.tempco - s.tempco) <= 3 * tr.tempco_std)
    assert np.all(tr.tempco_std < 1e-4)
    # Corrected rate = scale ∘ (m + bias) (paper Eq. 1) with the tracked bias.
    np.testing.assert_allclose(r.corrected, np.asarray(cal.scale) * (s.rate + r.bias))


def test_health_flag_fires_on_a_bias_step_and_the_filter_recovers():
    step = np.array([2e-3, -1e-3, 0.0])
    s, _, _, r = run_session(5, duration_s=600.0, bias_step=(300.0, step))
    alarms = r.updates.t[r.updates.alarm]
    assert np.count_nonzero(alarms < 300.0) <= 1  # at most a rare false alarm before
    after = alarms[alarms >= 300.0]
    assert after.size >= 1 and after[0] < 310.0, alarms  # fires at the first still period
    at = r.updates.applied_at[r.updates.alarm & (r.updates.t >= 300.0)][0]
    assert r.nis_ok[at - 1] and not r.nis_ok[at]  # the per-sample flag shows it
    # With recovery the estimate follows the jump: inside its band again within 10 s.
    late = s.t > after[0] + 10.0
    z = (r.bias[late] - s.true_bias[late]) / r.bias_std[late]
    assert np.mean(np.abs(z) <= 3.0) > 0.98
    # Without the step, the same session raises no alarm.
    _, _, _, r0 = run_session(5, duration_s=600.0)
    assert not r0.updates.alarm.any()


def test_time_since_update_flags_a_stale_estimate():
    s = simulate_session(np.random.default_rng(6), 60.0, model=MODEL, still_s=(5.0, 5.0),
                         motion_s=(40.0, 40.0))
    cal = sim_calibration(np.random.default_rng(7), s)
    tr = BiasTracker(settings(stale_after_s=30.0), cal)
    r = tr.process(s.t, s.rate, s.temperature_c)
    assert r.since_update_s.max() > 30.0
    moving = ~s.still
    # uncertainty grows during the long motion (random walk, K² Δt) ...
    i0 = int(np.flatnonzero(moving)[0])
    i1 = i0 + int(np.argmin(moving[i0:])) - 1  # last sample of the first (40 s) motion
    i0 += int(ODR)  # one second in: the still samples' delayed updates are all applied
    assert np.all(r.bias_std[i1] > r.bias_std[i0])
    expected = np.sqrt(r.bias_std[i0] ** 2 + 1e-10 * (s.t[i1] - s.t[i0]))
    # (temperature-model terms add to the random walk's K² Δt, never subtract)
    assert np.all(r.bias_std[i1] >= expected * 0.999)
    # ... and the streaming health object reports the stale state at the end of the motion
    tr2 = BiasTracker(settings(stale_after_s=30.0), cal)
    tr2.process(s.t[: i1 + 1], s.rate[: i1 + 1], s.temperature_c[: i1 + 1])
    h = tr2.health
    assert h.stale and not h.ok and h.since_update_s > 30.0


def test_streaming_batch_and_chunks_agree():
    s = simulate_session(np.random.default_rng(8), 30.0, model=MODEL, motion="jig",
                         still_s=(2.0, 3.0), motion_s=(3.0, 4.0))
    cal = sim_calibration(np.random.default_rng(9), s)
    kw = dict(reference_rate=s.reference_rate, reference_axis=s.reference_axis)
    st = settings(reference_axis_std=1e-4)
    batch = BiasTracker(st, cal).process(s.t, s.rate, s.temperature_c, **kw)
    # 613-sample chunks pool with array operations, 10-sample ones a row at a time (as a FIFO
    # drain hands them over): the same windows, the same log, the same estimates
    for size in (613, 10):
        chunked = BiasTracker(st, cal)
        parts = []
        for a in range(0, s.n, size):
            b = min(a + size, s.n)
            parts.append(chunked.process(s.t[a:b], s.rate[a:b], s.temperature_c[a:b],
                                         reference_rate=s.reference_rate[a:b],
                                         reference_axis=s.reference_axis[a:b]))
        np.testing.assert_allclose(np.vstack([p.bias for p in parts]), batch.bias, rtol=0,
                                   atol=1e-15)
        np.testing.assert_allclose(np.vstack([p.bias_std for p in parts]), batch.bias_std,
                                   rtol=1e-12)
        for f in ("t", "count", "applied_at", "alarm", "shift"):
            np.testing.assert_array_equal(
                np.concatenate([getattr(p.updates, f) for p in parts]),
                getattr(batch.updates, f))
        np.testing.assert_allclose(np.concatenate([p.updates.nis for p in parts]),
                                   batch.updates.nis, rtol=1e-9)
    stream = BiasTracker(st, cal)
    bias, std, corr = [], [], []
    for i in range(s.n):
        ref = s.reference_rate[i]
        c = stream.update(s.rate[i], s.t[i], s.temperature_c[i],
                          reference_rate=None if np.isnan(ref) else float(ref),
                          reference_axis=None if np.isnan(ref) else s.reference_axis[i])
        bias.append(stream.bias)
        std.append(stream.bias_std)
        corr.append(c)
    np.testing.assert_allclose(np.array(bias), batch.bias, rtol=0, atol=1e-15)
    np.testing.assert_allclose(np.array(std), batch.bias_std, rtol=1e-12)
    np.testing.assert_allclose(np.array(corr), batch.corrected, rtol=0, atol=1e-14)
    assert stream.health.updates == batch.updates.t.size > 0
    assert set(batch.updates.kind) == {"still", "reference"}


def test_feed_with_reference_rates_ends_in_the_batch_state():
    """feed() takes the encoder's reference rate too: its blocks go through process() with their
    reference columns, so the filter sees the batch run's samples and ends in its state (same
    reference updates), and each sample is corrected with an estimate at most one block old;
    a reference without its axis, or an axis that is not three numbers, is refused at once."""
    s = simulate_session(np.random.default_rng(8), 30.0, model=MODEL, motion="jig",
                         still_s=(2.0, 3.0), motion_s=(3.0, 4.0))
    cal = sim_calibration(np.random.default_rng(9), s)
    st = settings(reference_axis_std=1e-4, stream_block_s=0.3)
    rr, ra = s.reference_rate, s.reference_axis
    batch_tr = BiasTracker(st, cal)
    batch = batch_tr.process(s.t, s.rate, s.temperature_c, reference_rate=rr,
                             reference_axis=ra, finish=True)
    fed = BiasTracker(st, cal)
    corr = []
    for i in range(s.n):
        ref = {} if np.isnan(rr[i]) else {"reference_rate": float(rr[i]),
                                           "reference_axis": ra[i]}
        corr.append(fed.feed(s.rate[i], s.t[i], s.temperature_c[i], **ref))
    fed.flush(finish=True)
    np.testing.assert_allclose(fed.bias, batch_tr.bias, rtol=0, atol=1e-15)
    np.testing.assert_allclose(fed.bias_std, batch_tr.bias_std, rtol=1e-12)
    assert fed.health.updates == batch.updates.t.size
    assert np.sum(batch.updates.kind == "reference") > 10
    # the same accuracy as the batch run's corrected rates against the true rate
    e_fed = np.sqrt(np.mean((np.array(corr) - s.true_rate) ** 2))
    e_batch = np.sqrt(np.mean((batch.corrected - s.true_rate) ** 2))
    assert abs(e_fed / e_batch - 1) < 0.02, (e_fed, e_batch)
    # without the reference columns the filter would not be in that state
    plain = BiasTracker(st, cal)
    plain.process(s.t, s.rate, s.temperature_c, finish=True)
    assert plain.health.updates != batch.updates.t.size
    tr = BiasTracker(st, cal)
    with pytest.raises(CalibInputError, match="together"):
        tr.feed(s.rate[0], s.t[0], s.temperature_c[0], reference_rate=1.0)
    with pytest.raises(CalibInputError, match="3 numbers"):
        tr.feed(s.rate[0], s.t[0], s.temperature_c[0], reference_rate=1.0,
                reference_axis=(1.0, 0.0))
    with pytest.raises(CalibInputError, match="unit vectors"):
        tr.feed(s.rate[0], s.t[0], s.temperature_c[0], reference_rate=1.0,
                reference_axis=(1.0, 1.0, 0.0))
        tr.flush()


def test_reference_rate_updates_track_the_bias_while_the_servos_turn():
    """Jig session with rests too short for the still detector: only the servo turns (known ω
    from the encoder about known axes, m = ω u ⊘ scale − b) keep the bias right."""
    s = simulate_session(np.random.default_rng(10), 300.0, model=MODEL, motion="jig",
                         still_s=(0.3, 0.5), motion_s=(5.0, 8.0))
    cal = sim_calibration(np.random.default_rng(11), s)
    st = settings(reference_axis_std=1e-5)
    with_ref = BiasTracker(st, cal).process(
        s.t, s.rate, s.temperature_c, reference_rate=s.reference_rate,
        reference_axis=s.reference_axis,
    )
    without = BiasTracker(st, cal).process(s.t, s.rate, s.temperature_c)
    assert with_ref.still.sum() == 0 and without.updates.t.size == 0
    assert np.all(with_ref.updates.kind == "reference") and with_ref.updates.t.size > 100
    err_ref = np.sqrt(np.mean((with_ref.bias - s.true_bias) ** 2, axis=0))
    err_none = np.sqrt(np.mean((without.bias - s.true_bias) ** 2, axis=0))
    assert np.all(err_ref < 0.2 * err_none), (err_ref, err_none)
    z = (with_ref.bias - s.true_bias) / with_ref.bias_std
    assert np.all(np.mean(np.abs(z) <= 3.0, axis=0) > 0.99)


def test_reference_measurement_model_sign():
    # Noise-free: a servo turning at ω about u; the reading is ω u ⊘ scale − b (paper Eq. 1).
    b = np.array([0.01, -0.02, 0.005])
    scale = np.array([1.05, 0.95, 1.0])
    cal = GyroCalibration(scale=tuple(scale), bias=(0.0, 0.0, 0.0), scale_std=(1e-6,) * 3,
                          bias_std=(0.05,) * 3)
    st = TrackerSettings(odr_hz=ODR, noise_density=1e-5, rate_random_walk=0.0,
                         reference_axis_std=0.0, reference_angle_std=0.0)
    tr = BiasTracker(st, cal)
    n = 400
    u = np.array([0.6, 0.0, 0.8])
    omega = np.full(n, 1.5)
    m = omega[:, None] * u / scale - b
    tr.process(np.arange(n) / ODR, m, reference_rate=omega, reference_axis=u, finish=True)
    np.testing.assert_allclose(tr.bias, b, atol=1e-5)


def _full_cal(A, bias_std=0.05, a_std=1e-6):
    A = np.asarray(A)
    return GyroCalibration(scale=tuple(np.diag(A)), bias=(0.0, 0.0, 0.0),
                           scale_std=(a_std,) * 3, bias_std=(bias_std,) * 3,
                           matrix=tuple(map(tuple, A)), matrix_std=((a_std,) * 3,) * 3)


def test_v2_calibration_applies_the_full_matrix():
    # Noise-free, the full model g = A (m + b) with cross-axis terms (Calibration v2): servo
    # turns about three axes give reference-rate updates m − A⁻¹ ω u = −b. The tracker must find
    # b and correct to the true rate; the v1 diagonal of the same A must not.
    A = np.array([[1.02, 0.015, -0.01], [-0.012, 0.98, 0.02], [0.008, -0.018, 1.01]])
    b = np.array([0.01, -0.02, 0.005])
    n = 300
    axes = np.eye(3)
    omega = np.tile(np.repeat([1.5, -1.2, 0.9], n), 1)
    u = np.repeat(axes, n, axis=0)
    g = omega[:, None] * u
    m = g @ np.linalg.inv(A).T - b
    st = TrackerSettings(odr_hz=ODR, noise_density=1e-6, rate_random_walk=0.0,
                         reference_axis_std=0.0, reference_angle_std=0.0)
    t = np.arange(3 * n) / ODR
    full = BiasTracker(st, _full_cal(A))
    r = full.process(t, m, reference_rate=omega, reference_axis=u, finish=True)
    np.testing.assert_allclose(full.bias, b, atol=1e-6)
    np.testing.assert_allclose(r.corrected[-n // 2:], g[-n // 2:], atol=1e-5)
    diag = GyroCalibration(scale=tuple(np.diag(A)), bias=(0.0, 0.0, 0.0),
                           scale_std=(1e-6,) * 3, bias_std=(0.05,) * 3)
    v1 = BiasTracker(st, diag)
    v1.process(t, m, reference_rate=omega, reference_axis=u, finish=True)
    assert np.max(np.abs(v1.bias - b)) > 5e-3  # the cross-axis terms it dropped


def test_v2_reference_variance_matches_monte_carlo_of_the_matrix():
    # One reference window, noise-free readings: the bias error is (A⁻¹ − Â⁻¹) ω u for a
    # calibrated matrix Â drawn around the true A with its stated entry std. Over many draws its
    # spread must match the tracker's bias_std (R to first order; the prior is loose).
    rng = np.random.default_rng(7)
    A = np.array([[1.01, 0.01, 0.0], [-0.01, 0.99, 0.012], [0.0, 0.01, 1.0]])
    b = np.array([-0.004, 0.006, 0.002])
    a_std = 1e-3
    n = 50
    omega = np.full(n, 2.0)
    u = np.ones(3) / math.sqrt(3.0)
    m = (omega[:, None] * u) @ np.linalg.inv(A).T - b
    st = TrackerSettings(odr_hz=ODR, noise_density=1e-9, rate_random_walk=0.0,
                         reference_axis_std=0.0, reference_angle_std=0.0, update_interval_s=1.0)
    errs, stds = [], []
    for _ in range(400):
        A_est = A + rng.standard_normal((3, 3)) * a_std
        tr = BiasTracker(st, _full_cal(A_est, bias_std=1.0, a_std=a_std))
        tr.process(np.arange(n) / ODR, m, reference_rate=omega, reference_axis=u, finish=True)
        errs.append(tr.kf.x - b)  # the state after the window's update
        stds.append(np.sqrt(np.diag(tr.kf.P)))
    ratio = np.std(errs, axis=0) / np.mean(stds, axis=0)
    assert np.all((ratio > 0.85) & (ratio < 1.15)), ratio


def test_seeded_from_calibration_and_sign_convention():
    cal = GyroCalibration(scale=(1.0, 1.0, 1.0), bias=(0.01, -0.02, 0.03),
                          bias_std=(1e-3, 2e-3, 3e-3), temperature_c=30.0)
    tr = BiasTracker(settings(temperature_model=False), cal)
    np.testing.assert_allclose(tr.bias, cal.bias)
    np.testing.assert_allclose(tr.bias_std, cal.bias_std)
    assert tr.t_ref_c == 30.0
    # A still sensor whose bias moved to b reads m ≈ -b: the tracker reports +b.
    rng = np.random.default_rng(12)
    b = np.array([0.012, -0.018, 0.029])
    n = 4000
    m = -b + rng.standard_normal((n, 3)) * settings().noise_std
    tr.process(np.arange(n) / ODR, m, finish=True)
    assert np.all(np.abs(tr.bias - b) < 3 * tr.bias_std)
    assert np.all(tr.bias_std < 1e-4)
    np.testing.assert_allclose(tr.bias_covariance, np.diag(tr.bias_std**2))


def test_external_still_flags_override_the_detector():
    s = simulate_session(np.random.default_rng(13), 120.0, model=MODEL)
    cal = sim_calibration(np.random.default_rng(14), s)
    never = BiasTracker(settings(), cal).process(s.t, s.rate, s.temperature_c,
                                                 still=np.zeros(s.n, bool), finish=True)
    assert never.updates.t.size == 0 and not never.still.any()
    truth = BiasTracker(settings(), cal).process(s.t, s.rate, s.temperature_c,
                                                 still=s.still, finish=True)
    np.testing.assert_array_equal(truth.still, s.still)
    assert truth.decided.all()
    z = (truth.bias - s.true_bias) / truth.bias_std
    assert np.mean(np.abs(z) <= 3) > 0.98


def test_from_noise_uses_the_characterisation():
    from gyrocal.calib.allan import characterise_noise
    from gyrocal.calib.noise_sim import simulate_still

    still = simulate_still(np.random.default_rng(15), 600.0, model=NoiseModel(
        noise_density=2e-4, rate_random_walk=1e-5))
    nc = characterise_noise(still.rate, ODR)
    st = TrackerSettings.from_noise(nc, temperature_model=True)
    assert st.odr_hz == ODR and st.temperature_model
    np.testing.assert_allclose(st.noise_density, nc.noise_density.value)
    np.testing.assert_allclose(st.rate_random_walk, nc.rate_random_walk_or_hi95)
    # the simulated random walk (1e-5 rad/s/sqrt(s)) within the record's resolution
    assert all(0.3e-5 < k < 3e-5 for k in st.rate_random_walk), st.rate_random_walk
    np.testing.assert_allclose(st.noise_std, np.array(nc.noise_density.value) * math.sqrt(ODR))


def test_detect_still_on_its_own():
    s = simulate_session(np.random.default_rng(16), 120.0, model=MODEL)
    still = detect_still(s.rate, MODEL.white_std(ODR), ODR, reference_bias=s.true_bias[0])
    assert not np.any(still & ~s.still) and still.sum() > 0.6 * s.still.sum()
    # A steady turn (no ripple) has a still sensor's variance: the rate test catches it.
    n = 2000
    rng = np.random.default_rng(17)
    steady = np.array([0.05, 0.0, 0.0]) + rng.standard_normal((n, 3)) * MODEL.white_std(ODR)
    assert not detect_still(steady, MODEL.white_std(ODR), ODR).any()
    assert detect_still(steady - [0.05, 0, 0], MODEL.white_std(ODR), ODR)[:-100].mean() > 0.9
    loose = StillSettings(rate_threshold=0.1)
    assert detect_still(steady, MODEL.white_std(ODR), ODR, settings=loose)[:-100].mean() > 0.9


@pytest.mark.parametrize(
    "call, match",
    [
        (lambda tr: tr.process([0.0, 0.1], np.zeros((2, 2))), r"rate must have shape \(2, 3\)"),
        (lambda tr: tr.process([0.0, 0.0], np.zeros((2, 3))), "increase strictly"),
        (lambda tr: tr.process([0.0], [[np.nan, 0, 0]]), "finite"),
        (lambda tr: tr.process([0.0], np.zeros((1, 3)), still=[2]), "True/False"),
        (lambda tr: tr.process([0.0], np.zeros((1, 3)), temperature=[1.0, 2.0]), "temperature"),
        (lambda tr: tr.process([0.0], np.zeros((1, 3)), reference_rate=[1.0]), "together"),
        (lambda tr: tr.process([0.0], np.zeros((1, 3)), reference_rate=[1.0],
                               reference_axis=[1.0, 1.0, 0.0]), "unit vectors"),
        (lambda tr: tr.update([0, 0], 0.0), "3 numbers"),
    ],
)
def test_bad_arguments_are_named(call, match):
    cal = GyroCalibration(scale=(1, 1, 1), bias=(0, 0, 0), scale_std=(1e-4,) * 3,
                          bias_std=(1e-3,) * 3)
    tr = BiasTracker(settings(temperature_model=False), cal)
    with pytest.raises(CalibInputError, match=match):
        call(tr)


def test_setup_errors_are_named():
    with pytest.raises(CalibInputError, match="initial_bias_std"):
        BiasTracker(settings())
    with pytest.raises(CalibInputError, match="bias_std"):
        BiasTracker(settings(), GyroCalibration(scale=(1, 1, 1), bias=(0, 0, 0)))
    with pytest.raises(CalibInputError, match="noise_density"):
        settings(noise_density=(0.0, 1e-4, 1e-4))
    with pytest.raises(CalibInputError, match="nis_alpha"):
        settings(nis_alpha=2.0)
    with pytest.raises(CalibInputError, match="nis_alpha"):
        settings(nis_alpha="small")
    with pytest.raises(CalibInputError, match="t_ref_c"):
        settings(t_ref_c="warm")
    with pytest.raises(CalibInputError, match="reference_axis_std must be a non-negative"):
        settings(reference_axis_std=-1e-3)
    tr = BiasTracker(settings(), initial_bias_std=1e-3)
    with pytest.raises(CalibInputError, match="temperature"):
        tr.process([0.0], np.zeros((1, 3)))
    with pytest.raises(CalibInputError, match="need a calibration"):
        BiasTracker(settings(temperature_model=False), initial_bias_std=1e-3).process(
            [0.0], np.zeros((1, 3)), reference_rate=[1.0], reference_axis=[1.0, 0.0, 0.0])
    tr = BiasTracker(settings(temperature_model=False), initial_bias_std=1e-3)
    tr.process([0.0], np.zeros((1, 3)), finish=True)
    with pytest.raises(CalibInputError, match="finished"):
        tr.process([1.0], np.zeros((1, 3)))
    tr = BiasTracker(settings(temperature_model=False), initial_bias_std=1e-3)
    tr.process([1.0], np.zeros((1, 3)))
    with pytest.raises(CalibInputError, match="not after"):
        tr.process([0.5], np.zeros((1, 3)))


def test_smoothed_beats_the_filter_and_works_in_pieces():
    s = simulate_session(np.random.default_rng(31), 240.0, model=MODEL)
    cal = sim_calibration(np.random.default_rng(32), s)
    tr = BiasTracker(settings(), cal, keep_states=True)
    r = tr.process(s.t, s.rate, s.temperature_c, finish=True)
    b, sd = tr.smoothed(s.t, s.temperature_c)
    e_f = np.sqrt(np.mean((r.bias - s.true_bias) ** 2))
    e_s = np.sqrt(np.mean((b - s.true_bias) ** 2))
    assert e_s < 0.8 * e_f
    assert np.mean(np.abs(b - s.true_bias) <= 3 * sd) > 0.99
    b7, sd7 = tr.smoothed(s.t, s.temperature_c, chunk=997)
    np.testing.assert_allclose(b7, b, rtol=0, atol=1e-15)
    np.testing.assert_allclose(sd7, sd, rtol=1e-12)
    # after the last update the smoother is the filter
    np.testing.assert_allclose(b[-1], r.bias[-1], atol=1e-12)
    with pytest.raises(CalibInputError, match="keep_states"):
        BiasTracker(settings(), cal).smoothed(s.t, s.temperature_c)


@pytest.mark.parametrize("temperature_model", [True, False])
def test_fast_update_matches_one_sample_process_calls(temperature_model):
    """update()'s scalar path does the arithmetic of the general path (a one-sample process()
    call per reading, the implementation it replaced) to 1e-12, through the adaptive process
    noise, a bias step (NIS alarm and CUSUM), external still flags, keep_states and a switch to
    process() and back mid-stream."""
    s = simulate_session(np.random.default_rng(21), 30.0, model=MODEL, still_s=(1.0, 4.0),
                         motion_s=(1.0, 3.0), bias_step=(15.0, (1e-2, -5e-3, 0.0)))
    cal = sim_calibration(np.random.default_rng(22), s)
    st = settings(rate_random_walk=None, temperature_model=temperature_model)
    ext = np.full(s.n, np.nan)
    ext[3000:3400] = 1.0  # the user says still (true: it is)
    ext[3000:3400][~s.still[3000:3400]] = np.nan
    old, new = BiasTracker(st, cal, keep_states=True), BiasTracker(st, cal, keep_states=True)
    ref_c, ref_b, ref_s = [], [], []
    for i in range(s.n):
        e = None if np.isnan(ext[i]) else bool(ext[i])
        r = old.process(s.t[i:i + 1], s.rate[i:i + 1], s.temperature_c[i:i + 1],
                        None if e is None else np.array([float(e)]))
        ref_c.append(r.corrected[0])
        ref_b.append(old.bias)
        ref_s.append(old.bias_std)
    out_c, out_b, out_s = [], [], []
    for i in range(s.n):
        e = None if np.isnan(ext[i]) else bool(ext[i])
        if 5000 <= i < 5100:  # a batch in the middle: the queues change hands both ways
            if i == 5000:
                r = new.process(s.t[i:i + 100], s.rate[i:i + 100], s.temperature_c[i:i + 100])
                out_c.extend(r.corrected)
                out_b.extend(r.bias)
                out_s.extend(r.bias_std)
            continue
        out_c.append(new.update(s.rate[i], s.t[i], s.temperature_c[i], e))
        out_b.append(new.bias)
        out_s.append(new.bias_std)
    np.testing.assert_allclose(np.array(out_c), np.array(ref_c), rtol=0, atol=1e-12)
    np.testing.assert_allclose(np.array(out_b), np.array(ref_b), rtol=0, atol=1e-12)
    np.testing.assert_allclose(np.array(out_s), np.array(ref_s), rtol=1e-12)
    assert new.health == old.health and new.health.alarms + new.shifts >= 1
    assert new.last_decision == old.last_decision
    np.testing.assert_allclose(new.rate_random_walk, old.rate_random_walk, rtol=1e-12)
    np.testing.assert_allclose(new.smoothed(s.t, s.temperature_c)[0],
                               old.smoothed(s.t, s.temperature_c)[0], rtol=0, atol=1e-12)


@pytest.mark.parametrize("temperature_model", [False, True])
def test_fast_update_with_reference_matches_one_sample_process_calls(temperature_model):
    """update() with a reference rate takes the scalar path too, with the arithmetic of a
    one-sample process() call per reading (the path it replaced) to 1e-12: turns about three
    axes (a v2 matrix with cross-axis terms), rests between them, and a process() batch in the
    middle of a turn so that samples awaiting their decision change hands both ways. 20 s
    (4,000 one-sample process() calls) hold turns about all three axes and 68 updates."""
    s = simulate_session(np.random.default_rng(31), 20.0, model=MODEL, motion="jig",
                         still_s=(1.0, 3.0), motion_s=(2.0, 4.0))
    A = np.diag(s.scale) + 0.01 * np.array(
        [[0.0, 1.0, -0.5], [0.8, 0.0, 0.3], [-0.4, 0.6, 0.0]])
    cal = _full_cal(A, bias_std=0.02, a_std=1e-4)
    st = settings(rate_random_walk=None, temperature_model=temperature_model)
    rr, ra = s.reference_rate, s.reference_axis
    turning = np.flatnonzero(np.isfinite(rr))
    assert turning.size > 1000 and len(np.unique(ra[turning], axis=0)) == 3
    mid = int(turning[turning.size // 2])  # the batch starts inside a turn
    old, new = BiasTracker(st, cal, keep_states=True), BiasTracker(st, cal, keep_states=True)
    ref_c, ref_b, ref_s = [], [], []
    for i in range(s.n):
        r = old.process(s.t[i:i + 1], s.rate[i:i + 1], s.temperature_c[i:i + 1],
                        reference_rate=rr[i:i + 1], reference_axis=ra[i:i + 1])
        ref_c.append(r.corrected[0])
        ref_b.append(old.bias)
        ref_s.append(old.bias_std)
    out_c, out_b, out_s = [], [], []
    for i in range(s.n):
        if mid <= i < mid + 150:
            if i == mid:
                r = new.process(s.t[i:i + 150], s.rate[i:i + 150], s.temperature_c[i:i + 150],
                                reference_rate=rr[i:i + 150], reference_axis=ra[i:i + 150])
                out_c.extend(r.corrected)
                out_b.extend(r.bias)
                out_s.extend(r.bias_std)
            continue
        ref = {} if not np.isfinite(rr[i]) else {"reference_rate": float(rr[i]),
                                                 "reference_axis": ra[i]}
        out_c.append(new.update(s.rate[i], s.t[i], s.temperature_c[i], **ref))
        out_b.append(new.bias)
        out_s.append(new.bias_std)
    np.testing.assert_allclose(np.array(out_c), np.array(ref_c), rtol=0, atol=1e-12)
    np.testing.assert_allclose(np.array(out_b), np.array(ref_b), rtol=0, atol=1e-12)
    np.testing.assert_allclose(np.array(out_s), np.array(ref_s), rtol=1e-12)
    hn, ho = vars(new.health), vars(old.health)
    assert hn == pytest.approx(ho, rel=1e-12) and new.health.updates > 50
    assert new.last_decision == old.last_decision
    np.testing.assert_allclose(new.smoothed(s.t, s.temperature_c)[0],
                               old.smoothed(s.t, s.temperature_c)[0], rtol=0, atol=1e-12)


def test_fast_update_refuses_bad_references_as_the_general_path_does():
    s = simulate_session(np.random.default_rng(32), 2.0, model=MODEL)
    cal = sim_calibration(np.random.default_rng(33), s)
    tr = BiasTracker(settings(), cal)
    tr.update(s.rate[0], s.t[0], s.temperature_c[0])
    args = (s.rate[1], s.t[1], s.temperature_c[1])
    with pytest.raises(CalibInputError, match="unit vectors"):
        tr.update(*args, reference_rate=1.0, reference_axis=(1.0, 1.0, 0.0))
    with pytest.raises(CalibInputError, match="together"):
        tr.update(*args, reference_rate=1.0)
    with pytest.raises(CalibInputError, match="cannot be still"):
        tr.update(*args, True, reference_rate=1.0, reference_axis=(1.0, 0.0, 0.0))
    # a NaN rate is no reference: the sample goes on as a plain one
    tr.update(*args, reference_rate=math.nan, reference_axis=(1.0, 1.0, 0.0))
    assert tr.samples == 2


def _g_cal(G, bias_std=0.02):
    A = np.eye(3)
    return GyroCalibration(scale=(1.0, 1.0, 1.0), bias=(0.0, 0.0, 0.0), scale_std=(1e-6,) * 3,
                           bias_std=(bias_std,) * 3, matrix=tuple(map(tuple, A)),
                           matrix_std=((1e-6,) * 3,) * 3,
                           g_sensitivity={"model": "g = matrix @ (m + bias + g_sensitivity @ f)",
                                          "matrix": [list(r) for r in G],
                                          "matrix_std": [[1e-6] * 3] * 3,
                                          "directions": np.eye(3).tolist()})


def test_g_sensitivity_applied_with_the_specific_force():
    """Still sensor in four poses (gravity along +z, +x, -y, -z), reading m = −b − G f + v
    (the model g = A (m + b + G f) at g = 0): given f, the tracker's bias is the zero-g b in
    every pose; without it, the estimate follows b + G f of the pose. update() and process()
    agree on it."""
    rng = np.random.default_rng(41)
    G = np.array([[2e-3, -1e-3, 3e-3], [1e-3, 2.5e-3, -2e-3], [-3e-3, 1e-3, 2e-3]])
    b = np.array([0.01, -0.02, 0.005])
    cal = _g_cal(G)
    poses = np.array([[0, 0, 1.0], [1.0, 0, 0], [0, -1.0, 0], [0, 0, -1.0]])
    n_pose = 2000
    f = np.repeat(poses, n_pose, axis=0)
    sigma = 1e-4
    m = -b - f @ G.T + sigma * rng.standard_normal(f.shape)
    t = np.arange(f.shape[0]) / ODR
    st = TrackerSettings(odr_hz=ODR, noise_density=sigma / math.sqrt(ODR),
                         rate_random_walk=1e-7)
    still = np.ones(t.size)
    with_g = BiasTracker(st, cal)
    r = with_g.process(t, m, still=still, specific_force=f, finish=True)
    without = BiasTracker(st, cal).process(t, m, still=still, finish=True)
    assert with_g.applies_g_sensitivity
    ends = np.arange(1, 5) * n_pose - 1  # the last sample of each pose
    np.testing.assert_allclose(r.bias[ends], np.tile(b, (4, 1)), atol=2e-5)
    assert np.all(np.abs(r.bias[ends] - b) <= 3 * r.bias_std[ends])
    err_without = np.abs(without.bias[ends] - b).max()
    assert err_without > 2e-3  # |G f| of the last poses
    # corrected = A (m + bias + G f) (A = I): the true rate, zero, to the noise
    np.testing.assert_allclose(r.corrected, m + r.bias + f @ G.T, rtol=0, atol=1e-15)
    late = r.corrected.reshape(4, n_pose, 3)[:, n_pose // 2:].mean(axis=1)
    np.testing.assert_allclose(late, 0.0, atol=2e-5)
    # update() (scalar path) and the general one see the same m + G f
    stream = BiasTracker(st, cal)
    out = [stream.update(m[i], t[i], None, True, specific_force=f[i]) for i in range(t.size)]
    np.testing.assert_allclose(stream.bias, r.bias[-1], atol=1e-12)
    np.testing.assert_allclose(np.array(out), r.corrected, atol=1e-12)
    # a calibration without G ignores the force
    plain = BiasTracker(st, sim_calibration(np.random.default_rng(1), simulate_session(
        np.random.default_rng(2), 1.0, model=MODEL)))
    assert not plain.applies_g_sensitivity
    with pytest.raises(CalibInputError, match="specific_force"):
        BiasTracker(st, cal).process(t[:5], m[:5], specific_force=np.ones((4, 3)))


def _textbook_step(kf_x, kf_P, q, w, dt, t_ref, sigma2, A, A_std, st):
    """One window through gyrocal.calib.kalman.KalmanFilter (checked against filterpy in
    test_kalman) with the matrix form of the reference's variance (the module docstring's
    first-order d(A⁻¹) = −A⁻¹ dA A⁻¹): what the written-out per-axis step must equal."""
    from gyrocal.calib.kalman import KalmanFilter

    dim = kf_x.size
    kf = KalmanFilter(dim_x=dim, dim_z=3)
    kf.x, kf.P = kf_x.copy(), kf_P.copy()
    n = w.count
    R = sigma2 / n
    if w.kind == 2:  # a reference window
        Ai = np.linalg.inv(A)
        omega, u = w.sum_omega / n, np.asarray(w.axis)
        g = Ai @ (omega * u)
        R = (R + (Ai**2) @ A_std**2 @ g**2 + (omega * st.reference_axis_std) ** 2
             * (Ai**2).sum(axis=1)
             + (math.sqrt(2.0) * st.reference_angle_std / (n / st.odr_hz) * (Ai @ u)) ** 2)
    H = -np.hstack([np.eye(3)] * (dim // 3))
    if dim == 6:
        H[:, 3:] *= w.sum_temp / n - t_ref
    kf.H, kf.Q, kf.R = H, np.diag(q * dt), np.diag(R)
    kf.predict()
    kf.update(np.asarray(w.sum_z) / n)
    return kf.x, kf.P


@pytest.mark.parametrize("temperature_model", [True, False])
def test_written_out_step_equals_the_textbook_filter(temperature_model):
    """The per-axis Kalman step in floats (x at once, the Joseph-form P in a later slice) gives
    the state and covariance of the matrix filter to 1e-12, on still and reference windows of a
    v2 matrix with cross-axis terms, through the adaptive process noise."""
    s = simulate_session(np.random.default_rng(41), 25.0, model=MODEL, motion="jig",
                         still_s=(1.0, 3.0), motion_s=(2.0, 4.0))
    A = np.diag(s.scale) + 0.01 * np.array([[0.0, 1.0, -0.5], [0.8, 0.0, 0.3], [-0.4, 0.6, 0.0]])
    cal = _full_cal(A, bias_std=0.02, a_std=1e-4)
    st = settings(rate_random_walk=None, temperature_model=temperature_model)
    tr = BiasTracker(st, cal)
    checked = {"still": 0, "reference": 0}
    apply = tr._apply_window

    def checked_apply(w, log, close, defer=False):
        kf = tr.kf  # finishes any earlier step first
        x0, P0, q, t0 = kf.x.copy(), kf.P.copy(), tr._q.copy(), tr._t_state
        widened = tr.health.alarms + tr.shifts
        apply(w, log, close, defer)
        t_ref = tr.t_ref_c if tr.t_ref_c is not None else 0.0
        x, P = _textbook_step(x0, P0, q, w, max(w.t_last - t0, 0.0), t_ref,
                              st.noise_std**2, A, np.full((3, 3), 1e-4), st)
        got = tr.kf
        np.testing.assert_allclose(got.x, x, rtol=0, atol=1e-12 * max(1.0, np.abs(x).max()))
        if tr.health.alarms + tr.shifts == widened:  # (a health test widens P after the step)
            np.testing.assert_allclose(got.P, P, rtol=1e-12, atol=1e-30)
            checked["reference" if w.kind == 2 else "still"] += 1

    tr._apply_window = checked_apply
    for i in range(s.n):
        ref = s.reference_rate[i]
        tr.update(s.rate[i], s.t[i], s.temperature_c[i],
                  reference_rate=None if np.isnan(ref) else float(ref),
                  reference_axis=None if np.isnan(ref) else s.reference_axis[i])
    assert checked["still"] > 5 and checked["reference"] > 5, checked


def test_steps_left_to_later_update_calls_change_nothing_observable():
    """update() applies a window's state at once and leaves the rest of the step to the
    following calls, a slice each; read rarely (not after every sample, which would finish the
    step at once), every estimate, uncertainty, health flag and the estimated random walk equal
    a batch process() of the same samples (the batch path finishes each step at once)."""
    s = simulate_session(np.random.default_rng(43), 30.0, model=MODEL, motion="jig",
                         still_s=(1.0, 3.0), motion_s=(2.0, 4.0),
                         bias_step=(15.0, (1e-2, -5e-3, 0.0)))
    cal = sim_calibration(np.random.default_rng(44), s)
    st = settings(rate_random_walk=None)
    kw = dict(reference_rate=s.reference_rate, reference_axis=s.reference_axis)
    batch = BiasTracker(st, cal).process(s.t, s.rate, s.temperature_c, **kw)
    stream = BiasTracker(st, cal)
    pending_seen = 0
    every = 37
    corrected, bias, bias_std = [], [], []  # compared with the batch's after the loop
    for i in range(s.n):
        ref = s.reference_rate[i]
        corrected.append(stream.update(
            s.rate[i], s.t[i], s.temperature_c[i],
            reference_rate=None if np.isnan(ref) else float(ref),
            reference_axis=None if np.isnan(ref) else s.reference_axis[i]))
        pending_seen += bool(stream._todo)
        if i % every == 0:
            bias.append(stream.bias)
            bias_std.append(stream.bias_std)
    np.testing.assert_allclose(np.array(corrected), batch.corrected, rtol=0, atol=1e-14)
    np.testing.assert_allclose(np.array(bias), batch.bias[::every], rtol=0, atol=1e-15)
    np.testing.assert_allclose(np.array(bias_std), batch.bias_std[::every], rtol=1e-12)
    assert pending_seen > 100  # the steps really were spread over later calls
    h = stream.health
    assert h.updates == batch.updates.t.size and h.alarms == int(batch.updates.alarm.sum())
    assert stream.shifts == int(batch.updates.shift.sum()) >= 1
