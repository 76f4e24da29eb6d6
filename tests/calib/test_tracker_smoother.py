"""calib/tracker/smoother.py: the replay's Rauch-Tung-Striebel smoother, checked against
filterpy's filter and smoother run on the same update windows (the test extra's oracle)."""

import math

import numpy as np
import pytest

from gyrocal.calib.tracker import BiasTracker, TrackerSettings

FS = 200.0
SIG = 2e-3
K = 3e-4


def test_smoothed_at_the_updates_equals_filterpys_rts_smoother():
    kalman = pytest.importorskip("filterpy.kalman")
    rng = np.random.default_rng(5)
    n = int(12 * FS)
    t = np.arange(n) / FS
    b = 0.01 + np.cumsum(rng.standard_normal((n, 3)) * K / math.sqrt(FS), axis=0)
    m = -b + rng.standard_normal((n, 3)) * SIG
    st = TrackerSettings(odr_hz=FS, noise_density=SIG / math.sqrt(FS), rate_random_walk=(K,) * 3,
                         recover=False, cusum_h=math.inf)
    b0, sd0 = np.array([0.01, 0.01, 0.01]), 2e-3
    tr = BiasTracker(st, initial_bias=b0, initial_bias_std=sd0, keep_states=True)
    r = tr.process(t, m, still=np.ones(n), finish=True)  # every sample still: 50-sample windows
    U = int(st.update_interval_s * FS)
    ends = np.arange(U - 1, n, U)
    np.testing.assert_allclose(r.updates.t, t[ends])
    # filterpy: the same windows, H = -I, R = sigma^2 / U, Q = K^2 dt from one window's end
    kf = kalman.KalmanFilter(dim_x=3, dim_z=3)
    kf.x, kf.P, kf.F, kf.H = b0.copy(), np.eye(3) * sd0**2, np.eye(3), -np.eye(3)
    kf.R = np.eye(3) * SIG**2 / U
    xs, ps, qs = [], [], []
    prev = t[0]
    for e in ends:
        kf.Q = np.eye(3) * K**2 * (t[e] - prev)
        prev = t[e]
        kf.predict()
        kf.update(m[e - U + 1:e + 1].mean(axis=0))
        xs.append(kf.x.copy())
        ps.append(kf.P.copy())
        qs.append(kf.Q.copy())
    xs_, ps_ = np.array(xs), np.array(ps)
    np.testing.assert_allclose(r.bias[ends[1:]], xs_[:-1], rtol=0, atol=1e-12)  # causal
    # filterpy's Qs[k + 1] is the noise into step k + 1
    sx, sp, _, _ = kf.rts_smoother(xs_, ps_, Qs=np.array(qs))
    bias, std = tr.smoothed(t[ends])
    np.testing.assert_allclose(bias, sx, rtol=0, atol=1e-12)
    np.testing.assert_allclose(std, np.sqrt(np.diagonal(sp, axis1=1, axis2=2)), rtol=1e-9)


def test_smoothed_needs_kept_states():
    st = TrackerSettings(odr_hz=FS, noise_density=SIG / math.sqrt(FS))
    tr = BiasTracker(st, initial_bias=np.zeros(3), initial_bias_std=1e-3)
    with pytest.raises(ValueError, match="keep_states=True"):
        tr.smoothed(np.zeros(1))
