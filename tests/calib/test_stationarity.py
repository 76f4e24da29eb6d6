"""quiet_windows in O(N) (issue 16) gives the decisions of the windowed implementation it
replaced, which is kept here as the oracle."""

import numpy as np
import pytest
from numpy.lib.stride_tricks import sliding_window_view

from gyrocal.calib import stationarity
from gyrocal.calib.stationarity import (
    StillDetector,
    StillSettings,
    StreamingQuiet,
    quiet_windows,
)


def quiet_windows_oracle(centred, detector, n_history):
    """The O(N x window) implementation before issue 16: every window's mean and variance from
    scratch."""
    nw = detector.n_window
    n = centred.shape[0] - n_history
    out = np.zeros(n, dtype=bool)
    first = max(0, nw - 1 - n_history)
    if first >= n:
        return out
    v = sliding_window_view(centred, nw, axis=0)[n_history + first - (nw - 1):]
    mean = v.mean(axis=-1)
    dev = v - mean[..., None]
    var = np.einsum("wan,wan->wa", dev, dev) / (nw - 1)
    out[first:] = ((var <= detector.var_limit) & (np.abs(mean) <= detector.rate_limit)).all(axis=1)
    return out


def session(rng, n, sigma):
    """Rests and turns with ramps (rates to 6 rad/s) plus white noise, around a large bias."""
    rate = np.zeros((n, 3))
    i = 0
    while i < n:
        rest = int(rng.integers(50, 400))
        turn = int(rng.integers(50, 600))
        ax = int(rng.integers(3))
        peak = rng.uniform(-6, 6)
        ramp = np.minimum(1, np.minimum(np.arange(turn) + 1, turn - np.arange(turn)) / 40)
        rate[i + rest: i + rest + turn, ax] = (peak * ramp)[: max(0, n - i - rest)]
        i += rest + turn
    return rate + rng.normal(scale=sigma, size=(n, 3)) + np.array([3.0, -2.0, 0.5])


@pytest.mark.parametrize("alpha, window_s", [(1e-6, 0.2), (0.5, 0.05), (0.5, 1.0)])
@pytest.mark.parametrize("n_history", [0, 3, "full"])
def test_decisions_equal_the_windowed_oracle(alpha, window_s, n_history, monkeypatch):
    monkeypatch.setattr(stationarity, "_BLOCK", 1000)  # many block boundaries
    rng = np.random.default_rng(7)
    sigma = np.array([2e-3, 3e-3, 1.5e-3])
    det = StillDetector.build(sigma, 200.0, StillSettings(window_s=window_s,
                                                          variance_alpha=alpha))
    centred = session(rng, 12_000, sigma) - np.array([3.0, -2.0, 0.5])
    h = det.history if n_history == "full" else min(n_history, det.history)
    got = quiet_windows(centred, det, h)
    want = quiet_windows_oracle(centred, det, h)
    assert got.shape == want.shape and 0.01 < want.mean() < 0.99
    np.testing.assert_array_equal(got, want)


def test_a_large_offset_costs_no_precision():
    # a sensor still about a bias of 300 rad/s read against a reference of 0: no window is
    # quiet by its mean, and the variance of noise 1e-4 is still resolved (alpha = 0.5).
    rng = np.random.default_rng(3)
    sigma = np.full(3, 1e-4)
    det = StillDetector.build(sigma, 1000.0, StillSettings(variance_alpha=0.5,
                                                           rate_threshold=1e3))
    centred = 300.0 + rng.normal(scale=1e-4, size=(20_000, 3))
    np.testing.assert_array_equal(quiet_windows(centred, det, 0),
                                  quiet_windows_oracle(centred, det, 0))


def test_short_batches():
    det = StillDetector.build(np.full(3, 1e-3), 200.0)
    for total in range(0, det.n_window + 2):
        x = np.zeros((total, 3))
        np.testing.assert_array_equal(quiet_windows(x, det, 0), quiet_windows_oracle(x, det, 0))


@pytest.mark.parametrize("alpha, window_s", [(1e-6, 0.2), (0.5, 0.05), (0.5, 1.0)])
@pytest.mark.parametrize("n_history", [0, 3, "full"])
def test_streaming_quiet_equals_the_windowed_oracle(alpha, window_s, n_history):
    """StreamingQuiet (the tracker's update() path) decides each window like the oracle, one
    sample at a time, starting from some history, through rests and 6 rad/s turns."""
    rng = np.random.default_rng(7)
    sigma = np.array([2e-3, 3e-3, 1.5e-3])
    det = StillDetector.build(sigma, 200.0, StillSettings(window_s=window_s,
                                                          variance_alpha=alpha))
    centred = session(rng, 12_000, sigma) - np.array([3.0, -2.0, 0.5])
    h = det.history if n_history == "full" else min(n_history, det.history)
    want = quiet_windows_oracle(centred, det, h)
    sq = StreamingQuiet(det, centred[:h])
    got = np.array([sq.push(*row) for row in centred[h:]])
    assert 0.01 < want.mean() < 0.99
    np.testing.assert_array_equal(got, want)
    np.testing.assert_array_equal(sq.history(), centred[-det.history:])


def quiet_noise_std_oracle(m, block):
    """quiet_noise_std before it went piece by piece (all differences held at once)."""
    import math

    nb = m.shape[0] // block
    d = np.diff(m[: nb * block].reshape(nb, block, 3), axis=1)
    score = d.var(axis=1).sum(axis=1)
    ref = float(np.median(np.sort(score)[: max(3, int(0.02 * nb))]))
    rel = 1.2 * math.sqrt(2.0 / (block - 1)) / math.sqrt(3.0)
    return d[score <= ref * (1.0 + 5.0 * rel)].reshape(-1, 3).std(axis=0) / math.sqrt(2.0)


@pytest.mark.parametrize("piece", [8, 1000, 8192])
def test_quiet_noise_std_piecewise_equals_the_whole_array_version(piece, monkeypatch):
    monkeypatch.setattr(stationarity, "_BLOCK", piece)  # pieces of 1, 200 and 1638 blocks
    rng = np.random.default_rng(5)
    sigma = np.array([2e-3, 3e-3, 1.5e-3])
    rate = session(rng, 40_000, sigma)
    want = quiet_noise_std_oracle(rate, 40)
    got = stationarity.quiet_noise_std(rate, 40)
    np.testing.assert_allclose(got, want, rtol=1e-12)
