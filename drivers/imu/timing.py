"""Sample times on the host clock, reconstructed from sample counts and drain times.

An IMU samples on its own oscillator, which may be a per cent away from its nominal output data
rate and drifts with temperature. The FIFO gives samples without times, so each sample's time is
reconstructed from its index: ``t_k = a + P·k``. The two numbers ``a`` (time of sample 0) and
``P`` (the chip's true sample period, measured on the host clock) are fitted to the drains: a
drain that finds ``C`` samples produced so far at a host time ``T`` says that sample ``C-1`` was
taken at or before ``T`` and sample ``C`` after it.

After a FIFO restart the reader numbers the samples on from its own estimate of how many were
lost, which can be a whole sample off. The fit therefore starts a new segment there: the period
is estimated from the drains within each segment only, so a miscount cannot bend it, and the new
segment's offset is re-estimated from its own drains, starting from the old line with the weight
the old line deserves there.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["SampleClock"]


class SampleClock:
    """Online fit of a chip's sample times ``t_k = a + P·k`` on the host clock.

    Each observation is a drain: between host times ``t_before`` and ``t_after`` the chip
    reported that ``count`` samples (indices ``0 .. count-1``) had been produced. With the latch
    time ``T`` in that bracket and sample times ``a + P·k``, ``T = a + P·(count − u)`` with ``u``
    in ``(0, 1]``; for drains at irregular host times ``u`` is uniform, so
    ``E[T] = a + P·(count − ½)`` with variance ``P²/12`` plus the bracket's own
    ``(t_after − t_before)²/12``. ``a`` and ``P`` are the weighted least-squares line through the
    observations, each weighted by its inverse variance and by ``exp(−age / window_s)`` so that the
    fit follows a chip clock that drifts with temperature, with a Gaussian prior on ``P`` (the
    nominal period, relative standard deviation ``period_tolerance``) so that the first drains,
    which say little about the period, fall back on the datasheet rate. A chip clock 1 % off
    nominal is followed within a few drains; afterwards timestamps are typically well under a
    millisecond from the chip's true sample times.

    :meth:`new_segment` marks a restart of the sample numbering (see the module docstring).

    The sums of the fit are updated in O(1) per drain and kept relative to the latest
    observation, so they stay well conditioned however long the stream runs.

    Parameters
    ----------
    nominal_period_s : float
        ``1 / odr_hz`` from the datasheet.
    window_s : float
        Time constant of the exponential forgetting.
    period_tolerance : float
        Prior relative standard deviation of the chip's period about its nominal value.
    """

    def __init__(
        self,
        nominal_period_s: float,
        *,
        window_s: float = 5.0,
        period_tolerance: float = 0.02,
    ) -> None:
        if not (nominal_period_s > 0 and math.isfinite(nominal_period_s)):
            raise ValueError(f"nominal_period_s must be positive, got {nominal_period_s!r}")
        if not window_s > 0:
            raise ValueError(f"window_s must be positive, got {window_s!r}")
        if not period_tolerance > 0:
            raise ValueError(f"period_tolerance must be positive, got {period_tolerance!r}")
        self.nominal_period_s = float(nominal_period_s)
        self.window_s = float(window_s)
        self.period_tolerance = float(period_tolerance)
        # the Gaussian prior on the period, as a weight (inverse variance)
        self._prior = 1.0 / (self.period_tolerance * self.nominal_period_s) ** 2
        self._n = 0
        # weighted sums of the current segment's observations about the reference point
        # (xr, yr) = the latest observation
        self._xr = self._yr = 0.0
        self._s0 = self._s1 = self._s2 = self._t1 = self._t2 = 0.0
        # centred sums of the earlier segments (they only inform the period)
        self._pxx = self._pxy = 0.0
        # the current segment's anchor on the line before the restart, about (xr, yr): it
        # informs the offset only, with weight wa
        self._wa = self._xa = self._ya = 0.0
        self._alpha = 0.0  # the line at x = xr is yr + alpha
        self._p = self.nominal_period_s

    @property
    def period_s(self) -> float:
        """The fitted sample period of the chip in host-clock seconds."""
        return self._p

    @property
    def observations(self) -> int:
        """How many drain observations have been made."""
        return self._n

    def observe(self, t_before: float, t_after: float, count: int) -> None:
        """Add a drain: ``count`` samples had been produced at a time in ``[t_before, t_after]``.

        Parameters
        ----------
        t_before, t_after : float
            Host-clock times read just before and just after the transfer that latched the count.
        count : int
            Samples produced since sample 0 (the index of the next sample to come).
        """
        if t_after < t_before:
            raise ValueError(f"t_after {t_after!r} is earlier than t_before {t_before!r}")
        x, y = float(count) - 0.5, 0.5 * (t_before + t_after)
        if self._n:
            f = math.exp(-max(0.0, y - self._yr) / self.window_s)
            s0, s1, s2, t1, t2 = (f * v for v in (self._s0, self._s1, self._s2, self._t1, self._t2))
            dx, dy = x - self._xr, y - self._yr
            self._s1 = s1 - dx * s0
            self._s2 = s2 - 2.0 * dx * s1 + dx * dx * s0
            self._t1 = t1 - dy * s0
            self._t2 = t2 - dy * s1 - dx * t1 + dx * dy * s0
            self._s0 = s0
            self._pxx, self._pxy, self._wa = f * self._pxx, f * self._pxy, f * self._wa
            self._xa, self._ya = self._xa - dx, self._ya - dy
        self._xr, self._yr = x, y
        width = t_after - t_before
        self._s0 += 1.0 / (self._p**2 / 12.0 + width**2 / 12.0)
        self._n += 1
        self._fit()

    def _centred(self) -> tuple[float, float]:
        """The current segment's centred sums Σw(x−x̄)² and Σw(x−x̄)(y−ȳ)."""
        if not self._s0:
            return 0.0, 0.0
        return (self._s2 - self._s1**2 / self._s0, self._t2 - self._s1 * self._t1 / self._s0)

    def _fit(self) -> None:
        sxx, sxy = self._centred()
        self._p = p = (self._pxy + sxy + self._prior * self.nominal_period_s) / (
            self._pxx + sxx + self._prior
        )
        # the offset: the weighted mean of y − P·x over the segment and its anchor
        self._alpha = ((self._t1 - p * self._s1) + self._wa * (self._ya - p * self._xa)) / (
            self._s0 + self._wa
        )

    def new_segment(self, index: int) -> None:
        """The sample numbering restarts at ``index``, which may be a whole sample off.

        The line so far predicts the time of sample ``index``; it becomes the new segment's
        anchor, weighted by how well the line knows that time. Later observations move the
        offset away from it if they disagree, and only observations within one segment inform
        the period.

        Parameters
        ----------
        index : int
            The stream index the reader gives the first sample after the restart.
        """
        if not self._n:
            raise RuntimeError("SampleClock has no observation yet: observe the stream start first")
        xa = float(index) - self._xr
        weight = self._s0 + self._wa
        x_mean = (self._s1 + self._wa * self._xa) / weight  # where the offset is known best
        sxx, sxy = self._centred()
        slope_weight = self._pxx + sxx + self._prior  # the period's inverse variance
        variance = 1.0 / weight + (xa - x_mean) ** 2 / slope_weight
        self._pxx += sxx
        self._pxy += sxy
        self._s0 = self._s1 = self._s2 = self._t1 = self._t2 = 0.0
        self._wa, self._xa, self._ya = 1.0 / variance, xa, self._alpha + self._p * xa
        self._fit()

    def time_of(self, index: np.ndarray | int) -> np.ndarray:
        """Host-clock times of samples ``index`` (array or scalar) under the current fit."""
        if not self._n:
            raise RuntimeError("SampleClock has no observation yet: observe the stream start first")
        return self._yr + self._alpha + self._p * (np.asarray(index, dtype=float) - self._xr)

    def count_at(self, t: float) -> int:
        """How many samples the chip had produced by host time ``t`` (samples with ``t_k <= t``)."""
        t0 = float(self.time_of(0))
        return max(0, math.floor((t - t0) / self._p + 1e-9) + 1)  # 1e-9: t == t_k counts k
