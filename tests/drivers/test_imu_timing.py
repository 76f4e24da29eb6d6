"""SampleClock: sample times reconstructed from drain counts follow the chip's own clock."""

import math

import numpy as np
import pytest

from drivers.imu.timing import SampleClock


def simulate(true_time_of, nominal_period, duration, rng, bracket=20e-6, **kw):
    """Drain at irregular host times; return the fitted clock and the worst error seen."""
    sc = SampleClock(nominal_period, **kw)
    sc.observe(0.0, bracket, 0)  # stream starts at t = 0: sample 0 comes after it
    t, worst, delivered = 0.0, 0.0, 0
    while t < duration:
        t += rng.uniform(0.002, 0.03)
        count = int(np.searchsorted(true_time_of(np.arange(delivered, delivered + 400)), t,
                                    side="right")) + delivered
        sc.observe(t - bracket / 2, t + bracket / 2, count)
        if count > delivered:
            idx = np.arange(delivered, count)
            worst = max(worst, float(np.max(np.abs(sc.time_of(idx) - true_time_of(idx)))))
            delivered = count
    return sc, worst


@pytest.mark.parametrize("ppm", [-10_000, 0, 10_000])
def test_a_chip_clock_one_percent_off_is_followed(ppm):
    p_nominal = 1e-3
    p_true = p_nominal / (1 + ppm * 1e-6)
    phase = 0.37 * p_true
    sc, worst = simulate(lambda k: phase + p_true * np.asarray(k), p_nominal, 60.0,
                         np.random.default_rng(1))
    assert worst < 1e-3  # within a sample period from the very first drain
    assert sc.period_s == pytest.approx(p_true, rel=1e-5)
    assert sc.observations > 1000


def test_a_drifting_chip_clock_is_followed():
    # the chip's rate drifts by 2000 ppm over the minute (a warming oscillator)
    p0 = 1 / 952

    def true_time_of(k):
        k = np.asarray(k, dtype=float)
        return p0 * (k + 1e-3 * k**2 / (60 * 952))  # period grows linearly with time

    sc, worst = simulate(true_time_of, p0, 60.0, np.random.default_rng(2))
    assert worst < 1e-3


def test_count_at_inverts_time_of():
    sc = SampleClock(0.01)
    sc.observe(10.0, 10.0, 0)
    sc.observe(11.0, 11.0, 100)
    t5 = float(sc.time_of(5))
    assert sc.count_at(t5) == 6
    assert sc.count_at(t5 - 1e-9) == 5
    assert sc.count_at(0.0) == 0


def test_wide_brackets_weigh_less():
    # one drain with a 50 ms bracket (a host stall) must not drag the line
    p = 1e-3
    sc = SampleClock(p)
    for i in range(200):
        t = i * 0.0107 + 0.0003
        sc.observe(t, t, math.floor(t / p) + 1)  # samples k·p with k·p <= t
    sc.observe(2.2, 2.25, math.floor(2.2 / p) + 1)  # latched early in a long stall
    assert abs(float(sc.time_of(2200)) - 2.2) < 2e-4


def test_arguments_are_checked():
    with pytest.raises(ValueError, match="nominal_period_s"):
        SampleClock(0.0)
    with pytest.raises(ValueError, match="window_s"):
        SampleClock(1e-3, window_s=0)
    with pytest.raises(ValueError, match="period_tolerance"):
        SampleClock(1e-3, period_tolerance=0)
    sc = SampleClock(1e-3)
    with pytest.raises(RuntimeError, match="observe"):
        sc.time_of(0)
    with pytest.raises(ValueError, match="earlier"):
        sc.observe(1.0, 0.5, 3)
