"""SampleClock: sample times reconstructed from drain counts follow the chip's own clock."""

import math

import numpy as np
import pytest

from gyrocal.drivers.imu.timing import SampleClock


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


def drain_count(t, phase, period):
    """Samples taken by time ``t`` on a grid ``phase + period·k``."""
    return max(0, math.floor((t - phase) / period) + 1)


def period_after_restarts(miscount, p_true=1e-3 * (1 + 3e-3), phase=0.37e-3):
    """Drain for 20 s at irregular times, restarting the numbering every 40 ms from the fit's
    own count plus ``miscount``, as a reader does after a FIFO overflow; the fitted period."""
    rng = np.random.default_rng(3)
    sc = SampleClock(1e-3)
    sc.observe(0.0, 20e-6, 0)
    offset, t, restart_at = 0, 0.0, 0.04  # offset: the numbering's error so far
    while t < 20.0:
        t += rng.uniform(0.002, 0.02)
        if t >= restart_at:
            index = sc.count_at(t) + miscount
            offset = index - drain_count(t, phase, p_true)
            sc.new_segment(index)
            restart_at = t + 0.04
        else:
            sc.observe(t - 20e-6, t, drain_count(t - 10e-6, phase, p_true) + offset)
    return sc.period_s


def test_restart_miscounts_do_not_bend_the_period():
    # Only drains within one segment inform the period, so it comes out the same whatever the
    # miscounts (a miscount of one per restart used to leak in and bend it by 3 %).
    exact, over, under = (period_after_restarts(m) for m in (0, 1, -1))
    assert over == pytest.approx(exact, rel=1e-9) and under == pytest.approx(exact, rel=1e-9)
    assert exact == pytest.approx(1e-3 * (1 + 3e-3), rel=5e-3)


def test_a_new_segment_keeps_a_line_it_knows_well():
    p = 1 / 952
    sc = SampleClock(p)
    rng = np.random.default_rng(4)
    for t in np.cumsum(rng.uniform(0.002, 0.02, 500)):
        sc.observe(t - 20e-6, t, drain_count(t - 10e-6, 0.0, p))
    t = 6.0
    index = sc.count_at(t)
    sc.new_segment(index)
    assert abs(float(sc.time_of(index)) - p * index) < 30e-6  # the anchor is the old line
    sc.observe(t + 0.0123, t + 0.0123, drain_count(t + 0.0123, 0.0, p))  # one drain: little move
    assert abs(float(sc.time_of(index)) - p * index) < 30e-6
