"""calib.accel.still_means: the still windows' mean readings and the standard deviation of each
mean, against white noise of known σ."""

import numpy as np
import pytest

from gyrocal.calib.accel import still_means
from gyrocal.calib.errors import CalibInputError


def test_means_and_their_sigma_from_white_noise():
    rng = np.random.default_rng(7)
    t = np.arange(20000) / 200.0
    level = np.repeat(rng.normal(0, 5, (10, 3)), 2000, axis=0)
    a = level + rng.normal(0, 0.02, (t.size, 3))
    spans = [(10 * k + 1.0, 10 * k + 6.0) for k in range(10)] + [(3.0, 3.01)]  # last: 3 samples
    means, std, used = still_means(t, a, spans)
    assert used.tolist() == list(range(10))  # the short window is left out
    count = 5 * 200 + 1
    np.testing.assert_allclose(std, 0.02 / np.sqrt(count), rtol=0.05)  # pooled over 10 windows
    truth = level[::2000]
    assert np.all(np.abs(means - truth) < 4 * std)


def test_bad_shapes_are_named():
    with pytest.raises(CalibInputError, match="accel must have shape"):
        still_means(np.arange(5.0), np.zeros((4, 3)), [(0, 1)])
