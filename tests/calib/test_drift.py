"""The bias's wander within and after a run (calib/drift.py) and where a calibration carries it."""

import json

import numpy as np
import pytest

from gyrocal.calib.drift import BiasDrift, flicker_later_factor, flicker_run_factor
from gyrocal.calib.errors import CalibInputError, CalibrationFormatError
from gyrocal.calib.estimators import FitResult, add_bias_drift
from gyrocal.calib.model import GyroCalibration
from tests.calib.test_model import make_cal, make_full
from tests.kit.contract_fullmodel_recording import flicker_noise


def test_random_walk_run_average_variance_matches_a_direct_simulation():
    # independent truth: random walks drawn step by step, each averaged uniformly over the run
    # and compared with its value at the run's centre
    rng = np.random.default_rng(30)
    K, T, n, walks = 3e-5, 400.0, 400, 20000
    dt = T / n
    w = np.cumsum(rng.standard_normal((walks, n)) * K * np.sqrt(dt), axis=1)
    mid = w[:, n // 2 - 1]  # the walk at t = T/2
    err = w.mean(axis=1) - mid
    want = BiasDrift(0.0, K, T).run_variance
    assert want == pytest.approx(np.full(3, K**2 * T / 12))
    # sample variance of 20000 draws: relative standard error sqrt(2/20000) = 1 %
    assert np.var(err) == pytest.approx(want[0], rel=0.05)
    # about the run's start instead the variance is K² T / 3, four times more: the centre matters
    assert np.var(w.mean(axis=1)) == pytest.approx(4 * want[0], rel=0.05)


def test_flicker_run_average_about_the_hours_average_matches_a_spectral_simulation():
    # independent truth: 1/f noise of Allan floor 0.664 B made in the frequency domain (the
    # independent generator's, not the emulator's Gauss–Markov sum, nor the formula's
    # continuum); each 42 s run's average compared with the average over the hour from its start
    rng = np.random.default_rng(31)
    B, dt, T, H, per = 5e-5, 2.0, 42.0, 3600.0, 8
    x = np.concatenate([flicker_noise(rng, B, 1 / dt, int(per * H / dt)).T
                        for _ in range(100)])  # 300 draws of 8 hours, periodic
    seg = x.reshape(300 * per, int(H / dt))
    err = seg[:, : int(T / dt)].mean(axis=1) - seg.mean(axis=1)
    want = BiasDrift(B, 0.0, T).run_variance[0]
    assert want == pytest.approx(B**2 * flicker_run_factor(T, H))
    assert np.var(err) == pytest.approx(want, rel=0.12)  # 2400 draws, hours apart
    assert not np.var(err) == pytest.approx(B**2, rel=0.3)  # the old B² fell short by 1.7x
    # the simulation is the flicker B names: its Allan deviation at 10 s is the floor
    m = x[:, : 100 * 5].reshape(300, 100, 5).mean(axis=2)
    adev = np.sqrt(0.5 * np.mean(np.diff(m, axis=1) ** 2))
    assert adev == pytest.approx(np.sqrt(2 * np.log(2) / np.pi) * B, rel=0.05)


def test_flicker_factor_falls_with_the_run_and_vanishes_over_the_whole_horizon():
    phi = [flicker_run_factor(T) for T in (10.0, 42.0, 300.0, 1800.0)]
    assert all(a > b > 0 for a, b in zip(phi[:-1], phi[1:], strict=True))
    assert flicker_run_factor(3600.0) == 0.0 == flicker_run_factor(5000.0)
    assert flicker_run_factor(0.0) == flicker_run_factor(1.0)  # a span under 1 s counts as 1 s


def test_run_variance_adds_flicker_and_walk_and_the_hour_after_adds_the_walk():
    d = BiasDrift((1e-5, 2e-5, 3e-5), 2e-6, 60.0)
    B = np.array([1e-5, 2e-5, 3e-5])
    assert d.run_variance == pytest.approx(B**2 * flicker_run_factor(60.0) + 4e-12 * 60 / 12)
    assert d.wander == pytest.approx(np.sqrt(B**2 * flicker_later_factor(60.0)
                                             + 4e-12 * (3600 - 60 / 3)))
    with pytest.raises(CalibInputError, match="span_s"):
        BiasDrift(1e-5, 2e-6, -1.0)
    with pytest.raises(CalibInputError, match="rate_random_walk"):
        BiasDrift(1e-5, (1.0, float("nan"), 1.0), 10.0)


@pytest.mark.parametrize("full", [False, True])
def test_added_variance_lands_on_the_bias_diagonal_only(full):
    n = 12 if full else 6
    cov = np.diag(np.arange(1, n + 1) * 1e-10)
    cov[0, n - 1] = cov[n - 1, 0] = 3e-11
    fit = FitResult(method="m", scale=np.ones(3), bias=np.zeros(3), covariance=cov,
                    iterations=1, success=True, status="converged", message="",
                    matrix=np.eye(3) if full else None)
    d = BiasDrift((4e-5, 5e-5, 6e-5), 1e-6, 100.0)
    out = add_bias_drift(fit, d)
    added = out.covariance - cov
    assert np.allclose(added[-3:, -3:], np.diag(d.run_variance), rtol=1e-12, atol=0)
    added[-3:, -3:] -= np.diag(d.run_variance)
    assert np.all(np.abs(added) < 1e-20)  # rounding of ~1e-9 sums
    assert add_bias_drift(out, d) is out  # not added twice
    cal = out.to_calibration()
    assert cal.bias_drift == d
    assert np.allclose(np.square(cal.bias_std), np.diag(cov)[-3:] + d.run_variance)


@pytest.mark.parametrize("make", [make_cal, make_full])
def test_documents_without_bias_drift_still_read_and_with_it_round_trip(make):
    old = make()  # what the code before bias_drift wrote: no such field
    doc = old.to_dict()
    assert "bias_drift" not in doc
    assert GyroCalibration.from_json(json.dumps(doc)).bias_drift is None
    d = BiasDrift((4e-5, 5e-5, 6e-5), 2e-6, 42.0, source="assumed ⚠")
    doc = make(bias_drift=d).to_dict()
    back = GyroCalibration.from_json(json.dumps(doc))
    assert back.bias_drift == d
    assert doc["bias_drift"]["wander"] == pytest.approx(list(d.wander))
    doc["bias_drift"]["bais_instability"] = doc["bias_drift"].pop("bias_instability")
    with pytest.raises(CalibrationFormatError, match="bias_drift.bais_instability"):
        GyroCalibration.from_dict(doc)


def test_window_variance_bounds_a_windows_flicker_about_the_runs_mean():
    # independent truth: the generator's frequency-domain 1/f noise (not the formula's
    # continuum), 3000 runs of 42 s at 20 Hz; a 0.6 s rest's mean about its run's mean.
    # A window at the run's start is what window_variance states; one mid-run departs less,
    # so the figure bounds every window's
    rng = np.random.default_rng(37)
    B, hz, L, T = 5e-5, 20.0, 0.6, 42.0
    runs = flicker_noise(rng, B, hz, int(T * hz) * 1000).T.reshape(-1, int(T * hz))
    start = runs[:, : int(L * hz)].mean(axis=1) - runs.mean(axis=1)
    mid = runs[:, int(T / 2 * hz): int((T / 2 + L) * hz)].mean(axis=1) - runs.mean(axis=1)
    want = BiasDrift(B, 0.0, T).window_variance([L])
    assert want.shape == (1, 3) and np.all(want == want[0, 0])
    assert np.var(start) == pytest.approx(want[0, 0], rel=0.12)
    assert np.var(mid) < want[0, 0]
    # B² alone, or the run's share B² Φ(T, 1 h), would not be it
    assert not np.var(start) == pytest.approx(B**2, rel=0.3)
    # the rate random walk's share: a Wiener average's about its start, K² T / 3
    K = 2e-6
    assert BiasDrift(0.0, K, T).window_variance([L, 2 * L]) == pytest.approx(K**2 * T / 3)


def test_the_hour_after_matches_flicker_and_a_random_walk_made_independently():
    # independent truth: 1/f noise made in the frequency domain (the independent generator's,
    # not the formula's Gauss–Markov continuum) plus a random walk drawn step by step; a 42 s
    # run's average against the average over the same span an hour later (what the bias is
    # then, averaged as the calibration averaged it)
    rng = np.random.default_rng(38)
    B, K, dt, T, H = 5e-5, 2e-6, 2.0, 42.0, 3600.0
    nT, nH, hours = int(T / dt), int(H / dt), 8
    flick = np.concatenate([flicker_noise(rng, B, 1 / dt, int(hours * H / dt)).T
                            for _ in range(60)])  # 180 draws of 8 hours, periodic
    pairs = flick.reshape(-1, 2 * nH)  # 720 two-hour stretches: the run at each one's start
    walk = np.cumsum(rng.standard_normal(pairs.shape) * K * np.sqrt(dt), axis=1)
    x = pairs + walk
    err = x[:, nH: nH + nT].mean(axis=1) - x[:, :nT].mean(axis=1)
    d = BiasDrift(B, K, T)
    # sample variance of 720 draws: relative standard error sqrt(2/720) = 5 %
    assert np.var(err) == pytest.approx(d.wander[0] ** 2, rel=0.15)
    # each part on its own: the flicker's Ψ and the walk's K² (H − T/3)
    e_f = pairs[:, nH: nH + nT].mean(axis=1) - pairs[:, :nT].mean(axis=1)
    assert np.var(e_f) == pytest.approx(B**2 * flicker_later_factor(T, H), rel=0.15)
    e_w = walk[:, nH: nH + nT].mean(axis=1) - walk[:, :nT].mean(axis=1)
    assert np.var(e_w) == pytest.approx(K**2 * (H - T / 3), rel=0.15)
    # the figure before, sqrt(B² + K² H), is not it
    assert not np.var(err) == pytest.approx(B**2 + K**2 * H, rel=0.3)
