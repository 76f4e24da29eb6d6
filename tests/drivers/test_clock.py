import math

import pytest

from gyrocal.drivers.clock import Clock, SystemClock, VirtualClock


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
