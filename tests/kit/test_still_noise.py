"""The planner's still noise is the noise that sets how well a window's mean is known."""

from types import SimpleNamespace

import numpy as np
from scipy.signal import butter, lfilter

from gyrocal.kit.jig import measure_still_noise

ODR = 208.33


class _Clock:
    """A clock that advances only when slept on."""

    def __init__(self) -> None:
        self.t = 0.0

    def monotonic(self) -> float:
        return self.t

    def sleep(self, s: float) -> None:
        self.t += s


class _FilteredGyro:
    """A still gyro whose white noise (σ per sample) passes a 2nd-order Butterworth low-pass
    before the output (DC gain 1, so the long-run variance is σ²; none with ``cutoff_hz``
    None), read in 20 ms bursts."""

    def __init__(self, clock: _Clock, sigma: float, cutoff_hz: float | None, seed: int) -> None:
        white = np.random.default_rng(seed).normal(0.0, sigma, (int(10 * ODR), 3))
        self.x = (white if cutoff_hz is None
                  else lfilter(*butter(2, cutoff_hz, fs=ODR), white, axis=0))[200:]
        self.clock, self.i, self.t0 = clock, 0, 0.0

    def start(self) -> None:
        self.t0 = self.clock.t

    def stop(self) -> None:
        pass

    def read(self) -> SimpleNamespace:
        n = int((self.clock.t - self.t0) * ODR) - self.i
        out = self.x[self.i:self.i + n]
        self.i += n
        return SimpleNamespace(rate=out)


def test_still_noise_is_the_long_run_noise_of_a_filtered_or_white_gyro():
    # The LSM6DSOX's 67 Hz filter at 208 Hz (AN5192): first differences read about 0.6 of
    # the noise a window's mean has; the planner must get the latter (σ of the white input).
    sigma = 6e-4
    for cutoff in (67.0, None):
        got = []
        for seed in range(3):
            clock = _Clock()
            got.append(measure_still_noise(_FilteredGyro(clock, sigma, cutoff, seed), clock))
        assert all(0.8 * sigma < g < 1.2 * sigma for g in got), (cutoff, np.array(got) / sigma)
