"""Live progress of a calibration run: an updating line on a terminal, plain lines otherwise."""

from __future__ import annotations

from typing import TextIO

import numpy as np

from gyrocal.drivers.clock import SystemClock
from gyrocal.kit.backlog import RunStatus

__all__ = ["Progress"]


class Progress:
    """Report the runner's progress.

    On a terminal one status line is redrawn (at most ten times a second of wall time) with the
    step, elapsed and remaining jig time and the live gyro and servo rates; events (step starts,
    repeats, lost samples) print above it. Otherwise only events are printed, one per line, with
    the jig time.

    Parameters
    ----------
    stream : file
        Where to write (standard error, normally).
    total_s : float
        Planned jig time, for the remaining-time estimate.
    interactive : bool or None
        Force the terminal mode on or off; by default ``stream.isatty()``.
    """

    def __init__(self, stream: TextIO, total_s: float, interactive: bool | None = None) -> None:
        self.stream = stream
        self.total_s = float(total_s)
        self.interactive = stream.isatty() if interactive is None else bool(interactive)
        self._wall = SystemClock()
        self._last_draw = -1.0
        self._t = 0.0
        self._width = 0

    def event(self, line: str, t: float | None = None) -> None:
        """A step boundary, a repeat or a warning, at jig time ``t`` (default: the last time
        seen)."""
        if t is not None:
            self._t = float(t)
        if self.interactive:
            self.stream.write("\r" + " " * self._width + "\r")
        self.stream.write(f"[{self._t:6.1f} s] {line}\n")
        self.stream.flush()

    def update(self, status: RunStatus) -> None:
        """Redraw the status line from the runner's latest snapshot (from its consumer
        thread, :mod:`gyrocal.kit.backlog`)."""
        self._t = status.t
        if not self.interactive:
            return
        now = self._wall.monotonic()
        if now - self._last_draw < 0.1:
            return
        self._last_draw = now
        t = status.t
        rate = np.asarray(status.rate, dtype=float)
        line = (
            f"step {status.step_index + 1}/{status.n_steps} {status.step_desc:<44.44} "
            f"{t:5.1f}/{self.total_s:4.0f} s, {max(self.total_s - t, 0):4.1f} s left | gyro "
            f"[{rate[0]:+6.2f} {rate[1]:+6.2f} {rate[2]:+6.2f}] rad/s | servo "
            f"{status.speed:4.2f} rad/s"
        )
        self._width = max(self._width, len(line))
        self.stream.write("\r" + line.ljust(self._width))
        self.stream.flush()

    def close(self) -> None:
        """End the status line."""
        if self.interactive and self._width:
            self.stream.write("\r" + " " * self._width + "\r")
            self.stream.flush()
