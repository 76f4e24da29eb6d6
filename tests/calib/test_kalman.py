"""calib.kalman against filterpy's KalmanFilter (the reference it replaces) and against theory."""

import math

import numpy as np
import pytest

from gyrocal.calib.errors import CalibInputError
from gyrocal.calib.kalman import KalmanFilter


def _drive(kf, rng, steps):
    out = []
    for k in range(steps):
        kf.Q = np.diag(rng.uniform(1e-6, 1e-3, kf.x.size))
        kf.predict()
        kf.H = np.hstack([-np.eye(3), -(k % 5 - 2.0) * np.eye(3)])
        kf.R = np.diag(rng.uniform(1e-4, 1e-2, 3))
        kf.update(rng.standard_normal(3) * 0.1)
        out.append((kf.x.copy(), kf.P.copy(), np.ravel(kf.y).copy(), np.asarray(kf.SI).copy()))
    return out


def test_steps_match_filterpy():
    filterpy_kalman = pytest.importorskip("filterpy.kalman")
    ours, ref = KalmanFilter(6, 3), filterpy_kalman.KalmanFilter(dim_x=6, dim_z=3)
    for kf in (ours, ref):
        kf.x = np.array([0.01, -0.02, 0.03, 1e-3, 0.0, -1e-3])
        kf.P = np.diag([1e-4] * 3 + [1e-6] * 3)
        kf.F = np.eye(6)
    a = _drive(ours, np.random.default_rng(5), 40)
    b = _drive(ref, np.random.default_rng(5), 40)
    for (x, P, y, SI), (xr, Pr, yr, SIr) in zip(a, b, strict=True):
        np.testing.assert_allclose(x, np.ravel(xr), rtol=1e-10, atol=1e-15)
        np.testing.assert_allclose(P, Pr, rtol=1e-10, atol=1e-18)
        np.testing.assert_allclose(y, yr, rtol=1e-10, atol=1e-15)
        np.testing.assert_allclose(SI, SIr, rtol=1e-10)


def test_constant_state_converges_to_the_mean_of_the_readings():
    # Theory: with F = I, Q = 0, H = I and a flat prior, the filter is the running mean of z with
    # variance R/n.
    rng = np.random.default_rng(6)
    kf = KalmanFilter(3, 3)
    kf.P = np.eye(3) * 1e12
    kf.H = np.eye(3)
    kf.R = np.eye(3) * 0.04
    z = rng.standard_normal((200, 3)) * 0.2 + [1.0, -2.0, 0.5]
    for zi in z:
        kf.predict()
        kf.update(zi)
    np.testing.assert_allclose(kf.x, z.mean(axis=0), atol=1e-9)
    np.testing.assert_allclose(np.diag(kf.P), 0.04 / 200, rtol=1e-6)


def test_refuses_an_empty_state():
    with pytest.raises(CalibInputError, match="dim_x"):
        KalmanFilter(0, 3)


def test_rts_smooth_matches_filterpy_and_beats_the_filter():
    filterpy_kalman = pytest.importorskip("filterpy.kalman")
    from gyrocal.calib.kalman import rts_smooth

    # a random walk seen through white noise: the smoother's error must be smaller than the
    # filter's, and its gains identical to filterpy's rts_smoother
    rng = np.random.default_rng(11)
    N, q, r = 400, 1e-4, 1e-2
    truth = np.cumsum(rng.standard_normal((N, 2)) * math.sqrt(q), axis=0)
    z = truth + rng.standard_normal((N, 2)) * math.sqrt(r)
    kf = KalmanFilter(2, 2)
    kf.x, kf.P, kf.H, kf.R = np.zeros(2), np.eye(2), np.eye(2), np.eye(2) * r
    xs, Ps, Qs = [], [], []
    for k in range(N):
        kf.Q = np.eye(2) * q
        if k:
            kf.predict()
        kf.update(z[k])
        xs.append(kf.x.copy())
        Ps.append(kf.P.copy())
        Qs.append(np.eye(2) * q)
    xs, Ps, Qs = np.array(xs), np.array(Ps), np.array(Qs)
    x, P, C = rts_smooth(xs, Ps, Qs)
    xr, Pr, Cr, _ = filterpy_kalman.rts_smoother(xs, Ps, np.broadcast_to(np.eye(2), Ps.shape), Qs)
    np.testing.assert_allclose(x, xr, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(P, Pr, rtol=1e-9, atol=1e-15)
    np.testing.assert_allclose(C[:-1], Cr[:-1], rtol=1e-9)
    err_f = np.sqrt(np.mean((xs - truth) ** 2))
    err_s = np.sqrt(np.mean((x - truth) ** 2))
    assert err_s < 0.85 * err_f
    # the smoothed variance is below the filtered one everywhere but the end
    assert np.all(P[:-1, 0, 0] < Ps[:-1, 0, 0])


def test_rts_smooth_refuses_mismatched_shapes():
    from gyrocal.calib.kalman import rts_smooth

    with pytest.raises(CalibInputError, match="rts_smooth needs"):
        rts_smooth(np.zeros((3, 2)), np.zeros((3, 2, 2)), np.zeros((2, 2, 2)))
