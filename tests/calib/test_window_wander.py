"""The bias's wander between windows, as the process in time it is (calib.drift.BiasDrift.
window_covariance, calib.estimators.add_window_wander), against an independent synthetic: the
posed run of tests/calib/fullmodel_truth.py laid out in time, with a known rate random walk of
the bias (cumulative sums of Gaussian steps on a 10 ms grid, averaged over each window's
samples) added to the window and rest means."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from gyrocal.calib.drift import BiasDrift
from gyrocal.calib.estimators import (
    add_bias_drift,
    add_window_wander,
    fit_full_matrix,
    full_matrix_batch,
)
from tests.calib.fullmodel_truth import POSED, draw_truth, posed_observations, truth_in_frame

NOISE, COUNT, RESTS = 0.01, 2000, 3  # white noise per window mean: 2.2e-4 rad/s
K = 1e-4  # rad/s/√s: about the run's mean a window's wander is ~2.9e-4 rad/s


def _timeline() -> tuple[np.ndarray, np.ndarray]:
    """Each window's and then each rest's start and end, s: a 1 s rest, then each of POSED's
    pairs as a 1 s turn, 0.5 s, the 1 s turn back, 2 s to the next pair (a rest after the
    third pair and at the end)."""
    turns, rests, t = [], [(0.0, 1.0)], 2.0
    for k in range(len(POSED) // 2):
        turns += [(t, t + 1.0), (t + 1.5, t + 2.5)]
        t += 4.5
        if k == 2:
            rests.append((t, t + 1.0))
            t += 2.0
    rests.append((t, t + 1.0))
    spans = np.array(turns + rests)
    return spans[:, 0], spans[:, 1]


def _walk_means(rng: np.random.Generator, start: np.ndarray, end: np.ndarray, runs: int
                ) -> tuple[np.ndarray, np.ndarray]:
    """``runs`` random walks of ``K`` per axis (from 0 at t = 0), each averaged over every
    window's samples, (runs, N, 3); and the walk at the run's middle, (runs, 3)."""
    dt = 0.01
    t = np.arange(0.0, end.max() + dt, dt)
    walk = np.cumsum(rng.normal(0.0, K * np.sqrt(dt), (runs, t.size, 3)), axis=1)
    means = np.stack([walk[:, (t >= a) & (t <= e)].mean(axis=1)
                      for a, e in zip(start, end, strict=True)], axis=1)
    middle = walk[:, np.searchsorted(t, 0.5 * (start.min() + end.max()))]
    return means, middle


@pytest.fixture(scope="module")
def scatter():
    """The errors of (A, b) over 300 runs of one sensor (the full-matrix fit of all at once,
    ``full_matrix_batch``) and the fit of the first (``fit_full_matrix``: its σ as the
    windows' widened σ state it), with the wander's figures and the timeline."""
    rng = np.random.default_rng(20261128)
    C, bias, links, mount = draw_truth(rng)
    start, end = _timeline()
    drift = BiasDrift(0.0, K, float(end.max() - start.min()))
    widened = np.sqrt((NOISE / np.sqrt(COUNT)) ** 2 + drift.window_variance(end - start))
    n, runs = len(POSED), 300
    exact = posed_observations(C, bias, links, mount, POSED, count=COUNT, rests=RESTS)
    wander, middle = _walk_means(rng, start, end, runs)
    white = rng.normal(0.0, NOISE / np.sqrt(COUNT), wander.shape)
    means = np.concatenate([exact.mean, exact.rest_mean])[None] + wander + white
    obs = replace(exact, mean=means[0, :n], rest_mean=means[0, n:], noise=np.full((n, 3), NOISE),
                  rest_noise=np.full((RESTS, 3), NOISE), mean_std=widened[:n],
                  rest_mean_std=widened[n:])
    fit = fit_full_matrix(obs, g_sensitivity=False)
    res = full_matrix_batch(
        means[:, :n], np.broadcast_to(obs.rate, (runs, n)), obs.motor_index, obs.pose,
        np.broadcast_to(widened[:n], (runs, n, 3)), np.broadcast_to(obs.rate_std, (runs, n)),
        means[:, n:], np.broadcast_to(widened[n:], (runs, RESTS, 3)), n_servos=3,
        ref_matrix=obs.reference_matrix(), still_std=obs.still_angle_std,
        pose_still=obs.pose_still)
    assert np.all(res.converged)
    np.testing.assert_allclose(res.matrix[0], fit.matrix, atol=1e-9)
    errors = np.concatenate([(res.matrix - truth_in_frame(C)).reshape(runs, 9),
                             res.bias - (bias - middle)], axis=1)
    return errors, fit, drift, start, end


def test_the_matrix_scatter_matches_the_wander_between_windows_not_per_window(scatter):
    errors, fit, drift, start, end = scatter
    free = np.sqrt(np.diag(fit.covariance))[:9] > 0  # the frame fixes three elements
    old = np.sqrt(np.diag(fit.covariance))[:9][free]
    judged = add_window_wander(fit, drift.window_covariance_change(start, end))
    new = np.sqrt(np.diag(judged.covariance))[:9][free]
    seen = np.sqrt(np.mean(errors[:, :9][:, free] ** 2, axis=0))
    # 300 runs: each element's RMS within ~4 % (1σ); the six pooled within ~1.7 %
    assert np.sqrt(np.mean((seen / new) ** 2)) == pytest.approx(1.0, abs=0.07)
    assert np.all(np.abs(seen / new - 1.0) < 0.2)
    # the per-window rule (each window's σ widened as if its wander were its own) is too wide
    assert np.sqrt(np.mean((seen / old) ** 2)) < 0.75


def test_the_bias_scatter_about_the_walk_at_the_middle_matches_its_sigma(scatter):
    errors, fit, drift, start, end = scatter
    judged = add_bias_drift(add_window_wander(fit, drift.window_covariance_change(start, end)),
                            drift)
    z = errors[:, 9:] / np.sqrt(np.diag(judged.covariance))[9:]
    assert np.sqrt(np.mean(z**2)) == pytest.approx(1.0, abs=0.1)
