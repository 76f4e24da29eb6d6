"""calib/tracker/pooling.py: decided samples pooled into update windows. The vectorised path
(a batch) and the row-at-a-time path (update(), small batches) close the same windows at the
same samples with the same sums, whatever the run of kinds and servo axes."""

import math

import numpy as np

from gyrocal.calib.model import GyroCalibration
from gyrocal.calib.tracker import BiasTracker, TrackerSettings
from gyrocal.calib.tracker.pooling import KIND_NONE, KIND_REF, KIND_STILL

FS = 200.0


def _tracker():
    st = TrackerSettings(odr_hz=FS, noise_density=1e-4)
    cal = GyroCalibration(scale=(1.01, 0.99, 1.0), bias=(0.0, 0.0, 0.0), scale_std=(1e-4,) * 3,
                          bias_std=(1e-3,) * 3, method="test")
    tr = BiasTracker(st, cal)
    closed = []

    def record(w, log, close, defer=False):  # the window as the Kalman step would get it
        closed.append((w.kind, w.axis, w.count, tuple(w.sum_z), w.sum_omega, w.last, close))

    tr._apply_window = record
    return tr, closed


def _rows(seed, n):
    """Decided rows: runs of still, unused and reference samples (two servo axes)."""
    rng = np.random.default_rng(seed)
    kind = np.repeat(rng.choice([KIND_NONE, KIND_STILL, KIND_REF], 40),
                     rng.integers(1, 120, 40))[:n]
    axes = np.array([[1.0, 0.0, 0.0], [0.0, math.sqrt(0.5), math.sqrt(0.5)]])
    which = np.repeat(rng.integers(0, 2, 40), rng.integers(1, 120, 40))[:n]
    ref = kind == KIND_REF
    S = {"t": np.arange(n) / FS, "m": rng.standard_normal((n, 3)) * 1e-3,
         "temp": np.full(n, np.nan),
         "rr": np.where(ref, rng.uniform(0.5, 1.0, n), np.nan),
         "ra": np.where(ref[:, None], axes[which], np.nan)}
    return S, kind


def test_vectorised_pooling_closes_the_windows_row_by_row_pooling_closes():
    S, kind = _rows(2, 2000)
    n = kind.size
    a, got_a = _tracker()
    a._assemble_and_apply(S, n, kind, 0, True)  # > ROWS_ONE_BY_ONE: the array path
    b, got_b = _tracker()
    for lo in range(0, n, 50):  # the row-at-a-time path, the open window carried across
        hi = min(n, lo + 50)
        b._assemble_and_apply({k: v[lo:hi] for k, v in S.items()}, hi - lo, kind[lo:hi], lo,
                              hi == n)
    assert len(got_a) == len(got_b) > 20
    for wa, wb in zip(got_a, got_b, strict=True):
        assert wa[:3] == wb[:3] and wa[5:] == wb[5:]
        np.testing.assert_allclose(wa[3], wb[3], rtol=1e-12, atol=1e-15)
        assert math.isclose(wa[4], wb[4], rel_tol=1e-12)
    # a window holds one kind, at most update_interval_s of samples, and no unused sample
    U = int(round(a.settings.update_interval_s * FS))
    assert all(w[0] != KIND_NONE and 1 <= w[2] <= U for w in got_a)
    assert sum(w[2] for w in got_a) == int(np.count_nonzero(kind != KIND_NONE))
