"""The tracker without tuning: process noise from the data, bias steps by CUSUM, block
streaming, the white noise from still blocks. Sessions are written here from the model
(m = g/k - b + v, Calibration v1 convention), sharing no code with gyrocal.calib.noise_sim."""

import math

import numpy as np
import pytest

from gyrocal.calib.errors import CalibInputError
from gyrocal.calib.stationarity import quiet_noise_std, white_noise_std
from gyrocal.calib.tracker import BiasTracker, TrackerSettings

FS = 200.0
SIG = 2.5e-3  # per-sample white noise, rad/s


def still_session(seed, seconds, k_rw=0.0, step_at=None, step=None):
    rng = np.random.default_rng(seed)
    n = int(seconds * FS)
    t = np.arange(n) / FS
    b = np.array([0.01, -0.02, 0.005]) + np.cumsum(
        rng.standard_normal((n, 3)) * k_rw * math.sqrt(1 / FS), axis=0)
    if step_at is not None:
        b = b + np.where(t[:, None] >= step_at, step, 0.0)
    return t, -b + rng.standard_normal((n, 3)) * SIG, b


def tracker(**kw):
    st = TrackerSettings(odr_hz=FS, noise_density=SIG / math.sqrt(FS), **kw)
    return BiasTracker(st, initial_bias=[0.01, -0.02, 0.005], initial_bias_std=1e-3)


@pytest.mark.parametrize("seed", [1, 2])
def test_cusum_catches_a_step_the_nis_test_misses_and_the_filter_recovers(seed):
    # 2.5e-4 rad/s is under one innovation standard deviation of a 0.25 s window (3.5e-4):
    # the NIS sum over 8 windows does not see it; the CUSUM does within 30 s (the delay of a
    # shift of 0.7 sigma against k = 0.5, h = 10 scatters from 5 to 30 s).
    step = np.array([2.5e-4, 0.0, -2.5e-4])
    t, m, b = still_session(seed, 240.0, step_at=120.0, step=step)
    flags = np.ones(t.size)
    late = t >= 160.0
    errs = {}
    for h in (10.0, math.inf):
        r = tracker(rate_random_walk=1e-6, cusum_h=h).process(t, m, None, flags, finish=True)
        assert not r.updates.alarm.any()  # NIS: nothing
        errs[h] = np.abs(r.bias - b)[late][:, [0, 2]].mean()
        if h == 10.0:
            shifts = r.updates.t[r.updates.shift]
            assert shifts.size >= 1 and 120.0 < shifts[0] < 150.0
            inside = np.abs(r.bias - b)[late] <= 3 * r.bias_std[late]
            assert inside.mean() > 0.99
    assert errs[10.0] < 0.25 * 2.5e-4  # recovered (to the noise of the data since the step)
    assert errs[math.inf] > 0.4 * 2.5e-4  # without the test the filter is still far off


def test_smoother_does_not_cross_a_detected_step():
    # A 2e-3 rad/s step at 120 s, the random walk estimated: the CUSUM finds it, and the
    # smoothed replay must not drag the estimates before the step towards the new bias (nor
    # the ones after it back): before 110 s and after 135 s it is at least as good as the
    # causal filter, and its band holds the truth. (The first seconds are left out of the
    # error bound: the young bank of random walks is wide there, and so is the band.)
    step = np.array([2e-3, 0.0, -2e-3])
    t, m, b = still_session(4, 240.0, k_rw=2e-5, step_at=120.0, step=step)
    tr = BiasTracker(TrackerSettings(odr_hz=FS, noise_density=SIG / math.sqrt(FS)),
                     initial_bias=[0.01, -0.02, 0.005], initial_bias_std=1e-3, keep_states=True)
    r = tr.process(t, m, None, np.ones(t.size), finish=True)
    assert (r.updates.shift | r.updates.alarm).any()
    bs, sd = tr.smoothed(t)
    for sel in ((t > 5.0) & (t < 110.0), t > 135.0):
        e_s = np.sqrt(np.mean((bs - b)[sel] ** 2))
        e_f = np.sqrt(np.mean((r.bias - b)[sel] ** 2))
        assert e_s <= e_f, (e_s, e_f)
        assert np.max(np.abs(bs - b)[sel]) < 0.1 * 2e-3
    assert np.mean(np.abs(bs - b) <= 3 * sd) > 0.99


def test_no_false_shift_on_a_consistent_stream():
    t, m, _ = still_session(3, 600.0)
    r = tracker(rate_random_walk=1e-6).process(t, m, None, np.ones(t.size), finish=True)
    assert not r.updates.shift.any()
    # (the NIS test's own false-alarm rate, 1e-4 per update, allows one in 2400 updates)
    assert r.updates.alarm.sum() <= 1


def test_random_walk_estimated_from_the_data():
    """No K given. The bank of filters over a grid of K finds a strong walk (3e-4, three times
    the prior) and a weak one (3e-5) within a factor 2 from 20 minutes of 0.25 s windows; the
    filter runs at or above the estimate (posterior mean plus posterior std of q), and the band
    stays honest both ways."""
    t, m, b = still_session(4, 1200.0, k_rw=3e-4)
    tr = tracker()
    r = tr.process(t, m, None, np.ones(t.size), finish=True)
    est = tr.rate_random_walk_estimate
    assert np.all((est > 1.5e-4) & (est < 6e-4)), est
    assert np.mean(np.abs(r.bias - b) <= 3 * r.bias_std) > 0.98
    t, m, b = still_session(4, 1200.0, k_rw=3e-5)
    tr = tracker()
    r = tr.process(t, m, None, np.ones(t.size), finish=True)
    est = tr.rate_random_walk_estimate
    assert np.all((est > 1.5e-5) & (est < 6e-5)), est
    assert np.all((tr.rate_random_walk >= est) & (tr.rate_random_walk < 2 * est))
    assert np.mean(np.abs(r.bias - b) <= 3 * r.bias_std) > 0.99
    # a given figure wins
    fixed = tracker(rate_random_walk=1e-4)
    assert fixed.rate_random_walk_estimate is None
    np.testing.assert_allclose(fixed.rate_random_walk, 1e-4)


def test_feed_blocks_end_in_the_batch_state_and_correct_alike():
    t, m, b = still_session(5, 60.0, k_rw=1e-4)
    batch = tracker().process(t, m, finish=True)
    tr = tracker(stream_block_s=0.3)
    corr = np.array([tr.feed(m[i], t[i]) for i in range(t.size)])
    r = tr.flush(finish=True)
    assert r is not None
    np.testing.assert_allclose(tr.bias, batch.bias[-1], rtol=0, atol=1e-15)
    assert tr.health.updates == batch.updates.t.size
    # each sample corrected with an estimate at most one block old: the same accuracy
    truth = np.zeros_like(m)
    e_feed = np.sqrt(np.mean((corr - truth) ** 2))
    e_batch = np.sqrt(np.mean((batch.corrected - truth) ** 2))
    assert abs(e_feed / e_batch - 1) < 0.01
    with pytest.raises(CalibInputError, match="finished"):
        tr.feed(m[0], t[-1] + 1)
        tr.flush()


def test_process_refuses_while_fed_samples_wait():
    t, m, _ = still_session(6, 1.0)
    tr = tracker()
    tr.feed(m[0], t[0])
    with pytest.raises(CalibInputError, match="flush"):
        tr.process(t[1:], m[1:])


def test_noise_from_still_blocks_despite_motion():
    """A quarter still, the rest brisk motion: the whole-session estimate is far off, the
    still blocks give the truth within 3 %."""
    rng = np.random.default_rng(7)
    n = int(300 * FS)
    g = np.zeros((n, 3))
    moving = (np.arange(n) // int(10 * FS)) % 4 != 0
    walk = np.cumsum(rng.standard_normal((n, 3)) * 0.05, axis=0)
    g[moving] = walk[moving] - walk[moving].mean(axis=0)
    m = g + rng.standard_normal((n, 3)) * SIG
    assert np.all(white_noise_std(m) > 3 * SIG)
    np.testing.assert_allclose(quiet_noise_std(m, int(FS)), SIG, rtol=0.03)
    with pytest.raises(CalibInputError, match="block"):
        quiet_noise_std(m, 2)
