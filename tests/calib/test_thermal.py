"""calib.thermal: bias(T) and gain(T) from calibrations at several temperatures (issue 13).

The calibrations here are drawn from a known polynomial truth with known noise (written out in
this file), so the fit is judged against the truth and its own stated uncertainty.
"""

import json
import math
import warnings

import numpy as np
import pytest

from gyrocal.calib.errors import CalibInputError, CalibrationFormatError
from gyrocal.calib.model import GyroCalibration
from gyrocal.calib.thermal import ThermalModel, ThermalRangeWarning, fit_thermal

REF = 25.0
BIAS = np.array([[0.01, 2e-3, 3e-5], [0.02, -1e-3, 0.0], [-0.01, 5e-4, -2e-5]])  # per axis
SCALE0, SCALE1 = np.array([1.03, 0.98, 1.01]), np.array([3e-4, -2e-4, 1e-4])
B_STD, K_STD = 4e-5, 2e-5


def truth_bias(T):
    d = np.asarray(T, dtype=float)[:, None] - REF
    return BIAS[:, 0] + BIAS[:, 1] * d + BIAS[:, 2] * d**2


def truth_scale(T):
    return SCALE0 + SCALE1 * (np.asarray(T, dtype=float)[:, None] - REF)


def draw(seed, T, bias_std=B_STD, stated=None):
    rng = np.random.default_rng(seed)
    n = len(T)
    b = truth_bias(T) + rng.normal(0, bias_std, (n, 3))
    k = truth_scale(T) + rng.normal(0, K_STD, (n, 3))
    stated = bias_std if stated is None else stated
    return fit_thermal(T, b, np.full((n, 3), stated), k, np.full((n, 3), K_STD))


@pytest.mark.parametrize("seed", range(6))
def test_fit_holds_the_truth_within_its_stated_uncertainty_over_the_range(seed):
    T = np.linspace(20.0, 32.0, 9)
    model = draw(seed, T)
    assert model.criterion["bias_order"] == 2  # the truth's curvature is 100σ over the range
    assert model.consistency.ok
    grid = np.linspace(20.0, 32.0, 25)
    for t, tb, tk in zip(grid, truth_bias(grid), truth_scale(grid), strict=True):
        st = model.at(t)
        assert not st.clamped
        assert np.all(np.abs(st.bias - tb) <= 4 * st.bias_std)
        assert np.all(np.abs(np.diag(st.gain) - tk) <= 4 * np.diag(st.gain_std))


def test_order_follows_the_data_a_line_gives_a_line():
    rng = np.random.default_rng(7)
    T = np.linspace(20.0, 30.0, 8)
    b = 0.01 + 1e-3 * (T[:, None] - 25.0) + rng.normal(0, B_STD, (8, 3))
    model = fit_thermal(T, b, np.full((8, 3), B_STD))
    assert model.criterion["bias_order"] == 1
    assert model.gain_coeffs is None and model.kind == "calibrations"
    np.testing.assert_allclose(model.bias_coeffs[:, 1], 1e-3, atol=5 * B_STD / 3)


def test_understated_uncertainties_fail_the_check_and_are_scaled_to_the_scatter():
    T = np.linspace(20.0, 32.0, 12)
    model = draw(3, T, bias_std=4e-4, stated=4e-5)  # the calibrations claim 10× too little
    assert not model.consistency.ok and model.criterion["birge_scaled"]
    grid = np.linspace(20.0, 32.0, 13)
    z = [np.abs(model.at(t).bias - tb) / model.at(t).bias_std
         for t, tb in zip(grid, truth_bias(grid), strict=True)]
    assert np.max(z) < 4.0  # the stated uncertainty now covers the scatter


def test_an_offset_the_calibrations_share_is_not_averaged_away():
    """Six calibrations whose bias errors are white scatter plus one offset common to all (the
    bias's wander over a run, slower than the minutes between them): with that share given as
    ``bias_common_var`` the model's σ at every temperature covers the error with unit spread, and
    never falls below the shared σ (counted as independent, the fit divides it by √6 and its σ
    is about half the true spread)."""
    T = np.linspace(20.0, 26.0, 6)
    white, common = 4e-5, 6e-5
    grid = np.linspace(20.0, 26.0, 7)
    z = []
    for seed in range(300):
        rng = np.random.default_rng(seed)
        b = truth_bias(T) + rng.normal(0, white, (6, 3)) + rng.normal(0, common, 3)
        model = fit_thermal(T, b, np.full((6, 3), math.hypot(white, common)),
                            bias_common_var=common**2)
        st = [model.at(t) for t in grid]
        assert all(np.all(s.bias_std >= common) for s in st)
        z.append([(s.bias - tb) / s.bias_std for s, tb in zip(st, truth_bias(grid), strict=True)])
    spread = np.std(np.array(z), axis=0)  # per temperature and axis, over the draws
    assert np.all((spread > 0.8) & (spread < 1.2)), spread


def test_a_common_variance_above_the_stated_one_is_refused():
    T = np.linspace(20.0, 26.0, 4)
    with pytest.raises(CalibInputError, match="bias_common_var"):
        fit_thermal(T, truth_bias(T), np.full((4, 3), 1e-4), bias_common_var=2e-8)


def test_outside_the_range_is_clamped_never_extrapolated():
    model = draw(0, np.linspace(22.0, 28.0, 6))
    hot = model.at(60.0)
    assert hot.clamped and hot.temperature_c == 28.0 and hot.requested_c == 60.0
    np.testing.assert_array_equal(hot.bias, model.at(28.0).bias)
    bias, gain, clamped = model.evaluate(np.array([10.0, 25.0, 40.0]))
    assert clamped.tolist() == [True, False, True]
    np.testing.assert_array_equal(bias[0], model.at(22.0).bias)


def test_calibration_applies_the_model_at_the_die_temperature_and_warns_outside():
    model = draw(1, np.linspace(20.0, 30.0, 7))
    cal = GyroCalibration(scale=(1.0, 1.0, 1.0), bias=(0.0, 0.0, 0.0), temperature_c=25.0,
                          temperature_model=model)
    m = np.array([[0.5, -0.2, 0.1], [0.5, -0.2, 0.1]])
    temps = np.array([21.0, 29.0])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        got = cal.apply(m, temperature_c=temps)
    st = [model.at(t) for t in temps]
    expect = np.array([s.gain @ (mi + s.bias) for s, mi in zip(st, m, strict=True)])
    np.testing.assert_allclose(got, expect, rtol=1e-12)
    np.testing.assert_allclose(cal.apply(m), m)  # without a temperature: the base model
    with pytest.warns(ThermalRangeWarning, match="1 reading"):
        out = cal.apply(m, temperature_c=np.array([25.0, 45.0]))
    np.testing.assert_allclose(out[1], model.at(30.0).gain @ (m[1] + model.at(30.0).bias))


def test_document_round_trip_and_strict_loading():
    model = draw(2, np.linspace(20.0, 30.0, 7))
    cal = GyroCalibration(scale=(1.0, 1.0, 1.0), bias=(0.0, 0.0, 0.0), temperature_model=model)
    doc = json.loads(cal.to_json())
    tm = doc["temperature_model"]
    assert tm["version"] == 1 and tm["range_c"] == [20.0, 30.0] and tm["reference_c"] == 25.0
    assert np.shape(tm["bias_coeffs"]) == (3, 3) and np.shape(tm["scale_coeffs"]) == (3, 2)
    back = GyroCalibration.from_dict(doc).temperature_model
    np.testing.assert_allclose(back.bias_coeffs, model.bias_coeffs)
    np.testing.assert_allclose(back.at(27.0).bias_std, model.at(27.0).bias_std)
    np.testing.assert_allclose(back.at(27.0).gain, model.at(27.0).gain)
    for change, what in [
        ({"version": 2}, "version"),
        ({"bias_coeff": []}, "did you mean 'bias_coeffs'"),
        ({"range_c": [30.0, 20.0]}, "low, high"),
        ({"matrix_coeffs": np.zeros((2, 3, 3)).tolist()}, "both"),
        ({"bias_coeffs": [[0.0] * 6] * 3}, "1 to 4"),
        ({"kind": "guess"}, "kind"),
    ]:
        bad = json.loads(json.dumps(doc))
        bad["temperature_model"].update(change)
        with pytest.raises(CalibrationFormatError, match=what):
            GyroCalibration.from_dict(bad)


@pytest.mark.parametrize("T, what", [([25.0], "at least two"), ([25.0, 25.05], "span only"),
                                     ([25.0, math.nan], "finite")])
def test_unusable_sets_are_refused_with_the_reason(T, what):
    n = len(T)
    with pytest.raises(CalibInputError, match=what):
        fit_thermal(T, np.zeros((n, 3)), np.full((n, 3), 1e-4))


def test_missing_uncertainties_are_refused():
    with pytest.raises(CalibInputError, match="bias_std"):
        fit_thermal([20.0, 30.0], np.zeros((2, 3)), np.full((2, 3), math.nan))


def test_static_bias_only_model_keeps_the_calibrations_matrix():
    T = np.linspace(20.0, 30.0, 30)
    model = fit_thermal(T, truth_bias(T), np.full((30, 3), 1e-5), kind="static")
    assert model.to_dict()["kind"] == "static" and "matrix_coeffs" not in model.to_dict()
    a = np.array([[1.01, 0.002, 0.0], [0.0, 0.99, 0.0], [0.0, 0.0, 1.0]])
    cal = GyroCalibration(scale=tuple(np.diag(a)), bias=(0.0, 0.0, 0.0), matrix=a,
                          temperature_model=model)
    m = np.array([0.3, 0.2, 0.1])
    np.testing.assert_allclose(cal.apply(m, temperature_c=24.0),
                               a @ (m + truth_bias([24.0])[0]), atol=1e-6)
    assert ThermalModel.from_dict(model.to_dict()).gain_coeffs is None


def _run_obs(temps_turn, temps_rest, slope, seed=0, rest_std=2e-5):
    """A run's windows with a bias b(T) = b0 + slope (T - 25) (readings m = g - b)."""
    from gyrocal.calib.observations import ObservationSet

    rng = np.random.default_rng(seed)
    b0 = np.array([0.01, -0.02, 0.03])
    n, r = len(temps_turn), len(temps_rest)
    rate = np.array([1.0, -1.0] * (n // 2))
    g = np.zeros((n, 3))
    g[np.arange(n), np.arange(n) // 2 % 3] = rate
    bias_t = b0 + slope * (np.asarray(temps_turn)[:, None] - 25.0)
    bias_r = b0 + slope * (np.asarray(temps_rest)[:, None] - 25.0)
    obs = ObservationSet(
        mean=g - bias_t + rng.normal(0, 2e-5, (n, 3)), rate=rate,
        motor=np.arange(n) // 2 + 1, direction=rate.astype(int), count=np.full(n, 1000),
        noise=np.full((n, 3), 5e-3), mean_std=np.full((n, 3), 2e-5),
        rest_mean=-bias_r + rng.normal(0, rest_std, (r, 3)), rest_count=np.full(r, 400),
        rest_noise=np.full((r, 3), 5e-3), rest_mean_std=np.full((r, 3), rest_std),
        temperature_c=float(np.mean(np.concatenate([temps_turn, temps_rest]))))
    return obs, b0, g


def test_drift_within_a_run_is_referred_to_the_mean_temperature():
    from gyrocal.calib.thermal import correct_drift

    slope = np.array([3e-3, -2e-3, 1e-3])  # rad/s per °C
    tr = np.linspace(24.0, 25.2, 7)
    tt = (tr[:-1] + tr[1:]) / 2
    obs, b0, g = _run_obs(tt, tr, slope)
    fixed, note = correct_drift(obs, tt, tr)
    assert "changed by 1.20 °C" in note and "7 rests" in note
    t_bar = obs.temperature_c
    b_bar = b0 + slope * (t_bar - 25.0)
    z = (fixed.rest_mean + b_bar) / fixed.rest_mean_std
    assert np.all(np.abs(z) < 4)  # every rest now reads -b(T̄)
    assert np.all(np.abs(fixed.mean - (g - b_bar)) < 4 * fixed.mean_std)
    assert np.all(fixed.mean_std >= obs.mean_std)  # the drift's uncertainty was added
    # before the correction the rests disagree with one bias by far more than their noise
    assert np.max(np.abs(obs.rest_mean + b_bar) / obs.rest_mean_std) > 20


def test_steady_or_unmeasurable_drift():
    from gyrocal.calib.thermal import correct_drift

    obs, _, _ = _run_obs(np.full(6, 25.0), np.full(7, 25.01), np.zeros(3))
    assert correct_drift(obs, np.full(6, 25.0), np.full(7, 25.01)) == (obs, None)
    tr = np.array([24.0, 25.0])  # two rests cannot measure a drift and check it
    obs, _, _ = _run_obs(np.linspace(24, 25, 6), tr, np.full(3, 1e-3))
    same, note = correct_drift(obs, np.linspace(24, 25, 6), tr)
    assert same is obs and "too few rests" in note
