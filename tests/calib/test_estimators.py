import numpy as np
import pytest
from scipy import stats

from gyrocal.calib.errors import CalibInputError
from gyrocal.calib.estimators import (
    METHODS,
    estimate,
    fit_iterative_ls,
    fit_levenberg_marquardt,
    fit_paired_axis,
    iterative_ls_batch,
    paired_axis_batch,
)
from gyrocal.calib.observations import ObservationSet
from gyrocal.calib.simulate import SimProtocol, draw_mount_axes, draw_sensors, simulate_runs
from tests.calib.helpers import exact_observations

SCALE = np.array([1.07, 0.91, 1.15])
BIAS = np.array([0.06, -0.08, 0.025])


@pytest.mark.parametrize("method", [m for m in METHODS if m != "full-matrix"])  # unposed data
@pytest.mark.parametrize("turns", [1, 3])
def test_noise_free_data_recover_the_truth_to_1e9(method, turns):
    obs, axes = exact_observations(
        SCALE, BIAS, speed=2.0, turns=turns, mount=((0.3, -0.5, 0.8), 0.07)
    )
    opts = {"tol": 1e-13} if method == "iterative-ls" else {}
    res = estimate(obs, method, **opts)
    assert res.success, res.message
    np.testing.assert_allclose(res.scale, SCALE, rtol=0, atol=1e-9)
    np.testing.assert_allclose(res.bias, BIAS, rtol=0, atol=1e-9)
    assert np.all(np.isfinite(res.scale_std)) and np.all(np.isfinite(res.bias_std))
    assert np.all(res.scale_std > 0) and np.all(res.bias_std > 0)


def test_paired_axis_recovers_each_servos_axis():
    obs, axes = exact_observations(SCALE, BIAS, speed=1.5, mount=((1.0, 2.0, -0.5), 0.09))
    res = fit_paired_axis(obs)
    for s, motor in enumerate((1, 2, 3)):
        np.testing.assert_allclose(res.axes[motor], axes[s], atol=1e-9)
    cal = res.to_calibration(source="test")
    # A rigid 0.09 rad mount rotation tilts every servo axis by at most 0.09 rad off its nominal
    for motor in ("1", "2", "3"):
        assert 0 < cal.axes[motor]["misalignment_deg"] <= np.degrees(0.09) + 1e-9


def _noisy_six(seed, noise=0.035):
    rng = np.random.default_rng(seed)
    k, b = draw_sensors(rng, 1)
    axes = draw_mount_axes(rng, 1)
    runs = simulate_runs(rng, k, b, axes, SimProtocol(speed=1.0, turns=1), noise)
    return runs.observation_set(0), k[0], b[0]


@pytest.mark.parametrize("seed", [1, 2, 3, 4, 5])
def test_algorithm1_and_lm_agree_on_the_same_six_observations(seed):
    obs, _, _ = _noisy_six(seed)
    lm = fit_levenberg_marquardt(obs)
    tight = fit_iterative_ls(obs, tol=1e-13)
    assert lm.success and tight.success
    np.testing.assert_allclose(tight.scale, lm.scale, rtol=0, atol=1e-9)
    np.testing.assert_allclose(tight.bias, lm.bias, rtol=0, atol=1e-9)
    # With the paper's tolerance the remaining error is bounded by the contraction factor
    # q = β0 / (ω² - β0) of the fixed-point iteration times the last step (< 1e-6).
    paper = fit_iterative_ls(obs)
    q = paper.extra["beta0"] / (np.mean(obs.rate**2) - paper.extra["beta0"])
    bound = 2 * q / (1 - q) * 1e-6 + 1e-12
    assert np.max(np.abs(paper.extra["beta"] - tight.extra["beta"])) <= bound
    # Same answer means the same uncertainty too (six equations, six unknowns).
    np.testing.assert_allclose(paper.covariance, lm.covariance, rtol=1e-5)


# The paper's Table I: actual values of three simulated gyroscopes.
TABLE_I = [
    ((1.9074, 1.9529, 1.5635), (0.0827, 0.0265, -0.0805)),
    ((1.0979, 1.1052, 0.9851), (-0.1046, 0.1995, 0.1565)),
    ((1.5044, 1.6494, 1.5282), (0.1483, -0.1282, 0.1794)),
]


@pytest.mark.parametrize(("scale", "bias"), TABLE_I)
def test_paper_table1_cases_converge_in_a_few_iterations(scale, bias):
    scale, bias = np.array(scale), np.array(bias)
    obs, _ = exact_observations(scale, bias, speed=1.0, mount=((0.2, 0.9, 0.1), 0.05))
    res = fit_iterative_ls(obs)
    assert res.success and res.extra["condition_met"]
    np.testing.assert_allclose(np.round(res.scale, 4), np.round(scale, 4), atol=1.1e-4)
    np.testing.assert_allclose(np.round(res.bias, 4), np.round(bias, 4), atol=1.1e-4)
    assert res.iterations <= 15
    # The error shrinks geometrically by q = β0 / (ω² − β0) per iteration (fixed-point theory).
    hist = res.extra["history"]
    gamma = np.sum(scale**2 * bias**2)
    err = np.abs(hist[:, 0] - hist[-1, 0])[1:5]
    np.testing.assert_allclose(err[1:] / err[:-1], gamma / (1 - gamma), rtol=0.05)
    # Iteration 1 (β0 = 0) leaves b unchanged and inflates every k by ω/sqrt(ω² − β0): with
    # equal speeds a constant shift of Y is absorbed by scaling β (as Table I shows for b).
    first = hist[0]
    np.testing.assert_allclose(first[3:], bias, atol=1e-9)
    np.testing.assert_allclose(first[:3], scale / np.sqrt(1 - gamma), rtol=1e-9)


def test_batched_algorithm1_matches_the_single_run_version():
    rng = np.random.default_rng(11)
    k, b = draw_sensors(rng, 40)
    runs = simulate_runs(rng, k, b, draw_mount_axes(rng, 40), SimProtocol(turns=2), 0.2)
    kb, bb, it, ok = iterative_ls_batch(runs.mean, runs.rate)
    for i in range(0, 40, 7):
        single = fit_iterative_ls(runs.observation_set(i))
        assert ok[i] == single.success and it[i] == single.iterations
        np.testing.assert_allclose(kb[i], single.scale, atol=1e-12)
        np.testing.assert_allclose(bb[i], single.bias, atol=1e-12)


def _zscores(n_runs, seed, protocol, noise):
    rng = np.random.default_rng(seed)
    k, b = draw_sensors(rng, n_runs)
    runs = simulate_runs(rng, k, b, draw_mount_axes(rng, n_runs), protocol, noise)
    res = paired_axis_batch(
        runs.mean, runs.rate, runs.motor_index, runs.mean_std, runs.rate_std,
        runs.rest_mean, runs.rest_mean_std,
    )
    assert res.converged.all()
    std = np.sqrt(np.einsum("bii->bi", res.covariance)[:, :6])
    err = np.concatenate([res.scale - k, res.bias - b], axis=1)
    return err / std, res


def test_paired_axis_uncertainty_is_honest_and_chi2_is_calibrated():
    z, res = _zscores(600, 7, SimProtocol(speed=2.0, turns=2, rest_s=1.0), 0.05)
    # Each parameter's z-score has unit spread (a 600-run estimate is within ±10 %)...
    np.testing.assert_allclose(z.std(axis=0), 1.0, atol=0.1)
    np.testing.assert_allclose(z.mean(axis=0), 0.0, atol=0.15)
    # ...and the chi-square statistic follows its distribution: p-values are uniform.
    p = stats.chi2.sf(res.chi2, res.dof)
    assert stats.kstest(p, "uniform").pvalue > 0.01


def test_paired_axis_flags_noise_that_was_underestimated():
    rng = np.random.default_rng(5)
    k, b = draw_sensors(rng, 1)
    runs = simulate_runs(rng, k, b, draw_mount_axes(rng, 1), SimProtocol(turns=2), 0.05)
    obs = runs.observation_set(0)
    ok = fit_paired_axis(obs)
    assert ok.consistency.ok
    # Claim the noise is 5x smaller than it is: the residuals are then far too large.
    bad = ObservationSet(
        mean=obs.mean, rate=obs.rate, motor=obs.motor, direction=obs.direction,
        count=obs.count, noise=obs.noise / 5, rest_mean=obs.rest_mean,
        rest_count=obs.rest_count, rest_noise=obs.rest_noise / 5,
    )
    res = fit_paired_axis(bad)
    assert not res.consistency.ok and res.consistency.p_value < 1e-6


@pytest.mark.parametrize("method", ["iterative-ls", "levenberg-marquardt"])
def test_squared_norm_uncertainty_is_honest(method):
    rng = np.random.default_rng(21)
    n = 300
    k, b = draw_sensors(rng, n)
    runs = simulate_runs(rng, k, b, draw_mount_axes(rng, n), SimProtocol(turns=1), 0.035)
    z = []
    for i in range(n):
        r = estimate(runs.observation_set(i), method)
        z.append(np.concatenate([r.scale - k[i], r.bias - b[i]]) / np.concatenate(
            [r.scale_std, r.bias_std]))
    z = np.array(z)
    np.testing.assert_allclose(z.std(axis=0), 1.0, atol=0.15)


def test_paired_axis_is_more_accurate_on_bias_with_the_same_data():
    rng = np.random.default_rng(3)
    n = 400
    k, b = draw_sensors(rng, n)
    runs = simulate_runs(rng, k, b, draw_mount_axes(rng, n), SimProtocol(turns=1), 0.035)
    kb, bb, _, ok = iterative_ls_batch(runs.mean, runs.rate)
    pa = paired_axis_batch(
        runs.mean, runs.rate, runs.motor_index, runs.mean_std, runs.rate_std,
        runs.rest_mean, runs.rest_mean_std,
    )
    rms = lambda e: np.sqrt(np.mean(e**2))  # noqa: E731
    assert ok.all()
    assert rms(pa.bias - b) < 0.65 * rms(bb - b)
    assert rms(pa.scale - k) <= 1.02 * rms(kb - k)


# ------------------------------------------------------------------ bad input
def test_nan_readings_are_refused_when_the_set_is_built():
    obs, _ = exact_observations(SCALE, BIAS)
    mean = obs.mean.copy()
    mean[2, 1] = np.nan
    msg = r"mean contains NaN or inf \(first at index \[2, 1\]\)"
    with pytest.raises(CalibInputError, match=msg):
        ObservationSet(mean=mean, rate=obs.rate, motor=obs.motor, direction=obs.direction,
                       count=obs.count, noise=obs.noise)
    with pytest.raises(CalibInputError, match="rate contains NaN or inf"):
        ObservationSet(mean=obs.mean, rate=np.where(obs.rate > 0, np.inf, obs.rate),
                       motor=obs.motor, direction=obs.direction, count=obs.count, noise=obs.noise)


def test_mismatched_shapes_are_refused():
    obs, _ = exact_observations(SCALE, BIAS)
    with pytest.raises(CalibInputError, match=r"rate must have shape \(6,\)"):
        ObservationSet(mean=obs.mean, rate=obs.rate[:5], motor=obs.motor,
                       direction=obs.direction, count=obs.count, noise=obs.noise)
    with pytest.raises(CalibInputError, match=r"mean must have shape \(n, 3\)"):
        ObservationSet(mean=obs.mean[:, :2], rate=obs.rate, motor=obs.motor,
                       direction=obs.direction, count=obs.count, noise=obs.noise)


def test_direction_must_match_the_reference_sign():
    obs, _ = exact_observations(SCALE, BIAS)
    with pytest.raises(CalibInputError, match="disagrees with direction"):
        ObservationSet(mean=obs.mean, rate=-obs.rate, motor=obs.motor,
                       direction=obs.direction, count=obs.count, noise=obs.noise)


def _subset(obs, keep):
    return ObservationSet(mean=obs.mean[keep], rate=obs.rate[keep], motor=obs.motor[keep],
                          direction=obs.direction[keep], count=obs.count[keep],
                          noise=obs.noise[keep])


@pytest.mark.parametrize("method", list(METHODS))
def test_too_few_windows(method):
    obs, _ = exact_observations(SCALE, BIAS)
    with pytest.raises(CalibInputError, match="at least 6 rotation windows"):
        estimate(_subset(obs, np.arange(4)), method)


@pytest.mark.parametrize("method", list(METHODS))
def test_a_missing_axis(method):
    obs, _ = exact_observations(SCALE, BIAS, turns=2)
    keep = obs.motor != 3  # no turns about z
    with pytest.raises(CalibInputError, match="no window rotates about the sensor's z axis"):
        estimate(_subset(obs, keep), method)


@pytest.mark.parametrize("method", list(METHODS))
def test_windows_from_only_one_direction(method):
    obs, _ = exact_observations(SCALE, BIAS, turns=2)
    keep = ~((obs.motor == 2) & (obs.direction == -1))
    with pytest.raises(CalibInputError, match="servo 2 turned only in the positive direction"):
        estimate(_subset(obs, keep), method)


def test_unknown_method_lists_the_known_ones():
    obs, _ = exact_observations(SCALE, BIAS)
    with pytest.raises(CalibInputError, match="paired-axis, iterative-ls, levenberg-marquardt"):
        estimate(obs, "newton")


def test_algorithm1_reports_a_failed_square_root_instead_of_nan():
    obs, _ = exact_observations([1.0, 1.0, 1.0], [0.0, 0.3, 0.3])
    # The x servo's references far below what the gyro saw: once β0 (0.18, from the y and z
    # biases) exceeds the x windows' ω², the regression needs a negative k_x².
    rate = np.where(obs.motor == 1, obs.rate * 0.2, obs.rate)
    broken = ObservationSet(mean=obs.mean, rate=rate, motor=obs.motor,
                            direction=obs.direction, count=obs.count, noise=obs.noise)
    res = fit_iterative_ls(broken)
    assert not res.success
    assert res.status == "sqrt-failed"
    assert "β1 = -" in res.message
    assert np.all(np.isnan(res.scale))
    with pytest.raises(CalibInputError, match="did not produce a calibration"):
        res.to_calibration()


def test_algorithm1_reports_when_the_papers_convergence_condition_fails():
    # β0 = Σ k² b² well above 0.5 at ω = 1 rad/s: a huge bias.
    obs, _ = exact_observations([1.0, 1.0, 1.0], [0.5, 0.5, 0.3], speed=1.0)
    res = fit_iterative_ls(obs)
    assert not res.success
    assert not res.extra["condition_met"]
    assert "convergence condition 0 <= β0 < 0.5 does not hold" in res.message


def test_noise_pooling_follows_bartletts_test():
    from gyrocal.calib.observations import pool_noise

    rng = np.random.default_rng(4)
    count = np.full(8, 1000)
    sigma = np.array([0.03, 0.05, 0.04])
    x = rng.normal(0, 1, (8, 1000, 3)) * sigma
    est = np.sqrt(np.mean(np.diff(x, axis=1) ** 2, axis=1) / 2)
    out, pooled = pool_noise(est, count)
    assert pooled.all()
    np.testing.assert_allclose(out[0], np.sqrt(np.mean(est**2, axis=0)), rtol=1e-12)
    # One window twice as noisy on y (vibration while turning): y is left alone, x and z pooled.
    est2 = est.copy()
    est2[3, 1] *= 2.0
    out2, pooled2 = pool_noise(est2, count)
    assert pooled2.tolist() == [True, False, True]
    np.testing.assert_array_equal(out2[:, 1], est2[:, 1])
