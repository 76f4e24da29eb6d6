"""The one clock everything runs on.

Hardware runs on :class:`SystemClock`; emulation runs on :class:`VirtualClock`, whose time moves
only when somebody sleeps on it. Nothing in gyrocal calls ``time.time()`` or ``time.monotonic()``
directly: it takes a :class:`Clock` and asks it.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from typing import Protocol, runtime_checkable

__all__ = ["Clock", "SystemClock", "VirtualClock", "waiter_until"]

_INF = math.inf


@runtime_checkable
class Clock(Protocol):
    """What gyrocal needs of a clock: a monotonic time in seconds and a way to wait."""

    def monotonic(self) -> float:
        """Seconds on this clock; never decreases."""
        ...

    def sleep(self, seconds: float) -> None:
        """Wait ``seconds`` on this clock."""
        ...


class SystemClock:
    """The host's monotonic clock (``time.monotonic`` / ``time.sleep``)."""

    def monotonic(self) -> float:
        """Seconds from the host's monotonic clock."""
        return time.monotonic()

    #: Waits shorter than this spin on the monotonic clock instead of ``time.sleep``, which
    #: oversleeps by the kernel's timer slack (50 µs and more): a 72 µs I²C byte write must take
    #: 72 µs, not 300.
    spin_below_s = 1e-3

    def sleep(self, seconds: float) -> None:
        """Block for ``seconds`` of wall time (negative values are treated as zero); waits under
        :attr:`spin_below_s` busy-wait so they end on time."""
        if seconds <= 0:
            return
        if seconds >= self.spin_below_s:
            time.sleep(seconds)
            return
        deadline = time.monotonic() + seconds
        while time.monotonic() < deadline:
            pass

    def __repr__(self) -> str:
        return "SystemClock()"


def waiter_until(clock: Clock) -> Callable[[float], None]:
    """A function that waits on ``clock`` until its time ``t``: the clock's own ``sleep_until``
    (:meth:`VirtualClock.sleep_until`) where it has one, else ``sleep`` of the gap from
    ``monotonic`` (nothing when ``t`` is past)."""
    own = getattr(clock, "sleep_until", None)
    if own is not None:
        return own
    monotonic, sleep = clock.monotonic, clock.sleep

    def wait(t: float) -> None:
        gap = t - monotonic()
        sleep(gap if gap > 0 else 0.0)

    return wait


class VirtualClock:
    """A clock that advances only when :meth:`sleep` (or :meth:`advance`) is called.

    Emulated devices read it to decide what has happened by now, and spend time on it for
    the bus transfers they model, so a whole calibration protocol runs in a fraction of its
    jig time and is exactly repeatable.

    Parameters
    ----------
    start : float
        The initial time in seconds.
    """

    def __init__(self, start: float = 0.0) -> None:
        self._t = float(start)
        self._stalls: list[tuple[float, float]] = []
        self._next_stall = math.inf  # the first stall's time (inf: none)

    def monotonic(self) -> float:
        """The current virtual time in seconds."""
        return self._t

    def sleep(self, seconds: float) -> None:
        """Advance the virtual time by ``seconds``.

        Raises
        ------
        ValueError
            If ``seconds`` is negative or not finite.
        """
        seconds = float(seconds)
        if not 0.0 <= seconds < _INF:
            raise ValueError(f"sleep needs a finite, non-negative duration, got {seconds!r}")
        t = self._t + seconds
        if t >= self._next_stall:
            t = self._stall(t)
        self._t = t

    def _stall(self, t: float) -> float:
        """``t`` after every stall due by it (each adds its duration), the next one noted."""
        stalls = self._stalls
        while stalls and stalls[0][0] <= t:
            t += stalls.pop(0)[1]
        self._next_stall = stalls[0][0] if stalls else _INF
        return t

    advance = sleep

    def sleep_until(self, t: float) -> None:
        """Advance the virtual time to ``t`` (no change if it is past), exactly as
        ``sleep(max(t - monotonic(), 0))`` does, stalls included, in one call: an emulated bus
        waits for its bits this way several times per transfer.

        A ``t`` that is not a number waits for nothing (as ``sleep`` of a NaN gap clipped
        at zero would)."""
        now = self._t
        gap = t - now
        now += gap if gap > 0 else 0.0
        if now >= self._next_stall:
            now = self._stall(now)
        self._t = now

    def stall_at(self, t: float, seconds: float) -> None:
        """Model a host that stops running for ``seconds`` at time ``t`` (a scheduler stall
        under load): the first sleep that reaches ``t`` lasts ``seconds`` longer, so nothing
        the process does (a servo poll, a FIFO drain) happens in between.

        Raises
        ------
        ValueError
            If ``seconds`` is negative or not finite, or ``t`` is not finite.
        """
        if not (math.isfinite(t) and math.isfinite(seconds) and seconds >= 0):
            raise ValueError(f"stall_at needs a finite time and duration >= 0, got {t!r}, "
                             f"{seconds!r}")
        self._stalls.append((float(t), float(seconds)))
        self._stalls.sort()
        self._next_stall = self._stalls[0][0]

    def __repr__(self) -> str:
        return f"VirtualClock(t={self._t:.6f})"
