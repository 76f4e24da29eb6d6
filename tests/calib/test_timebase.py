import tracemalloc

import numpy as np
import pytest

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


def _polyfit_oracle(t, degree, settle_s=5.0):
    """The refit written directly from its definition (module docstring): whole-period sample
    indices, numpy's least-squares polynomial over the settled samples, applied to all."""
    d = np.diff(t)
    period = np.median(d)
    i = np.concatenate([[0.0], np.cumsum(np.rint(d / period))])
    x = i / i[-1]
    settled = (t - t[0]) >= settle_s
    coeffs = np.polynomial.polynomial.polyfit(x[settled], t[settled], degree)
    fitted = np.polynomial.polynomial.polyval(x, coeffs)
    rms = np.sqrt(np.mean((t - fitted)[settled] ** 2))
    return fitted, coeffs[1] / i[-1], rms


@pytest.mark.parametrize("degree", [1, 2])
def test_block_refit_equals_a_direct_least_squares_fit(degree):
    # Longer than several of the refit's blocks, with gaps, a drifting 1 kHz clock, a reader's
    # early transient and jitter: the block-wise fit must match numpy's polyfit on the whole.
    rng = np.random.default_rng(7)
    i = np.arange(700_000, dtype=float)
    i[250_000:] += 4
    i[600_001:] += 1
    true = 12.0 + 1e-3 * (1 + 3e-5) * i + 4e-16 * i**2
    t = true + 2e-3 * np.exp(-(true - 12.0)) + rng.normal(0, 3e-5, i.size)
    fitted, fit = refit_sample_times(t, degree=degree)
    want, p0, rms = _polyfit_oracle(t, degree)
    assert fit.applied
    np.testing.assert_allclose(fitted, want, rtol=0, atol=1e-11)
    assert abs(fit.period_s - p0) < 1e-15
    assert fit.residual_rms_s == pytest.approx(rms, rel=1e-8)


def test_refit_holds_no_stream_sized_temporaries():
    # Its working memory is its output plus bounded blocks, whatever the length (a 1 h 1 kHz
    # recording's refit once held ten stream-sized arrays: 360 MiB).
    n = 2_000_000
    t = 3.0 + np.arange(n) * 1e-3 + np.random.default_rng(3).normal(0, 2e-5, n)
    tracemalloc.start()
    try:
        fitted, fit = refit_sample_times(t)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert fit.applied
    assert peak < 1.2 * t.nbytes + 24 * 2**20, f"peak {peak / 2**20:.0f} MiB"


@pytest.mark.parametrize("kind", ["uniform", "grid", "few values", "outliers"])
@pytest.mark.parametrize("block", [7, 64, 100_000])
def test_median_step_equals_numpy_median_of_the_steps(kind, block):
    """The bounded-memory median (issue 16: track and the refit no longer hold every step)
    is numpy.median(numpy.diff(t)) exactly, blocks smaller and larger than the stream."""
    from gyrocal.calib.timebase import median_step

    rng = np.random.default_rng(["uniform", "grid", "few values", "outliers"].index(kind))
    for n in (2, 3, 50, 1001, 4000):
        if kind == "uniform":
            d = rng.uniform(0, 1, n - 1)
        elif kind == "grid":
            d = np.round(rng.normal(1e-3, 1e-6, n - 1), 9)
        elif kind == "few values":
            d = rng.choice([1e-3, 2e-3, 0.0, 5e-4], n - 1)
        else:
            d = np.full(n - 1, 5e-3)
            d[rng.integers(0, n - 1, 5)] = rng.uniform(0, 10, 5)
        t = 100.0 + np.concatenate([[0.0], np.cumsum(d)])
        assert median_step(t, block) == float(np.median(np.diff(t)))


def test_median_step_of_fewer_than_two_times_says_so():
    from gyrocal.calib.errors import CalibInputError
    from gyrocal.calib.timebase import median_step

    for t in (np.array([]), np.array([1.0])):
        with pytest.raises(CalibInputError, match="at least two sample times"):
            median_step(t)
