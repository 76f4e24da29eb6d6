"""calib/tracker/qbank.py: the bank of filters that estimates the bias random walk ``K`` from
window means alone, on sequences written here from the model (a random walk seen through
white noise)."""

import math

import numpy as np
import pytest

from gyrocal.calib.tracker import TrackerSettings
from gyrocal.calib.tracker.qbank import QBank

DT = 0.25  # s between windows
R = (2e-3) ** 2 / 50  # a 50-sample window's variance


def _bank_on_walk(k_true, n, seed):
    rng = np.random.default_rng(seed)
    st = TrackerSettings(odr_hz=200.0, noise_density=1e-4, adapt_memory_s=1e9)
    bank = QBank(np.zeros(3), np.full(3, 1e-3), st, None)
    b = np.cumsum(rng.standard_normal((n, 3)) * k_true * math.sqrt(DT), axis=0)
    z = -b + rng.standard_normal((n, 3)) * math.sqrt(R)
    for i in range(n):
        for _ in bank.steps(z[i].tolist(), [R] * 3, None, DT):
            pass
    return bank


@pytest.mark.parametrize("k_true", [3e-5, 3e-4])
def test_the_posterior_k_lands_on_the_true_random_walk(k_true):
    bank = _bank_on_walk(k_true, 1500, 3)
    k = np.sqrt(bank.q)
    # 6 minutes of windows pin K to tens of per cent; the grid steps by 1.47x
    assert np.all((k > k_true / 1.6) & (k < k_true * 1.6)), k
    assert np.all(bank.q_std < bank.q)


def test_a_constant_bias_gives_a_small_k_and_widen_reaches_every_filter():
    bank = _bank_on_walk(0.0, 1500, 4)
    assert np.all(np.sqrt(bank.q) < 3e-5)
    before = bank.P00.copy()
    bank.widen(np.array([1e-6, 0.0, 0.0]))
    np.testing.assert_allclose(bank.P00[:, 0], before[:, 0] + 1e-6)
    np.testing.assert_array_equal(bank.P00[:, 1:], before[:, 1:])
