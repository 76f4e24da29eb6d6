import math

import numpy as np
import pytest

from gyrocal.drivers.clock import Clock, SystemClock, VirtualClock, waiter_until


def test_virtual_clock_moves_only_when_slept_on():
    clock = VirtualClock(start=2.5)
    assert clock.monotonic() == 2.5
    assert clock.monotonic() == 2.5
    clock.sleep(0.25)
    clock.advance(1.0)
    assert clock.monotonic() == pytest.approx(3.75)


@pytest.mark.parametrize("bad", [-1e-9, math.nan, math.inf])
def test_virtual_clock_refuses_bad_durations(bad):
    clock = VirtualClock()
    with pytest.raises(ValueError, match="non-negative"):
        clock.sleep(bad)
    assert clock.monotonic() == 0.0


def test_both_clocks_satisfy_the_protocol():
    assert isinstance(VirtualClock(), Clock)
    assert isinstance(SystemClock(), Clock)
    sc = SystemClock()
    t0 = sc.monotonic()
    sc.sleep(-1.0)  # no wait, no error
    assert sc.monotonic() >= t0


def _sleep_gap(clock: VirtualClock, t: float) -> None:
    """The bus's wait before sleep_until: the gap from now, clipped at zero."""
    gap = t - clock.monotonic()
    clock.sleep(gap if gap > 0 else 0.0)


def test_sleep_until_lands_where_sleeping_the_gap_lands_stalls_included():
    # Bit-times of a 400 kHz bus from awkward starts, some targets already past, and stalls
    # armed before, at and between the targets (one at the present time: a sleep of zero
    # takes it): the two ways must leave the clock at the same float every time.
    rng = np.random.default_rng(25)
    for _ in range(200):
        start = float(rng.uniform(0, 50))
        a, b = VirtualClock(start), VirtualClock(start)
        for c in (a, b):
            c.stall_at(start, 0.003)
            c.stall_at(start + 1e-4, 0.02)
        t0 = start
        for bits in rng.integers(0, 400, size=12).cumsum():
            target = t0 + float(bits) / 400e3 - (1e-3 if bits % 7 == 0 else 0.0)
            a.sleep_until(target)
            _sleep_gap(b, target)
            assert a.monotonic() == b.monotonic()
        assert not a._stalls and a._next_stall == math.inf


def test_waiter_until_falls_back_to_sleep_on_a_clock_without_it():
    slept = []

    class Plain:
        t = 1.0

        def monotonic(self):
            return self.t

        def sleep(self, s):
            slept.append(s)

    wait = waiter_until(Plain())
    wait(1.5)
    wait(0.5)
    assert slept == [0.5, 0.0]
    clock = VirtualClock()
    assert waiter_until(clock) == clock.sleep_until
