import numpy as np

from gyrocal.calib.timebase import refit_sample_times


def test_a_stretched_start_is_straightened_with_hindsight():
    # A chip at 199.9 Hz; the reader's timestamps carry a few ms of error in the first seconds
    # (a young period estimate) and 50 µs of jitter, and there is a gap of 3 samples.
    rng = np.random.default_rng(0)
    period = 1 / 199.9
    i = np.concatenate([np.arange(0, 3000), np.arange(3003, 6000)])
    true = 2.0 + i * period
    early = 4e-3 * np.exp(-(true - 2.0) / 2.0)
    t = true + early + rng.normal(0, 5e-5, true.size)
    fitted, fit = refit_sample_times(t)
    assert fit.applied
    assert abs(fit.period_s - period) / period < 1e-5
    # The stretch over the first 4 s is gone: what remains is a tiny constant offset.
    err = fitted - true
    assert np.ptp(err[true < 6.0]) < 2e-4 and np.ptp(t[true < 6.0] - true[true < 6.0]) > 3e-3


def test_irregular_streams_are_left_alone():
    rng = np.random.default_rng(1)
    t = np.cumsum(rng.uniform(0.002, 0.009, 500))  # polled at random times: no fixed period
    out, fit = refit_sample_times(t)
    assert not fit.applied and "not a fixed-rate stream" in fit.reason
    np.testing.assert_array_equal(out, t)
    short, fit = refit_sample_times(t[:10])
    assert not fit.applied and fit.reason == "too few samples"
