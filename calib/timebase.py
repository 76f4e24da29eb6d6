"""Refit a gyro stream's time axis with hindsight.

A gyro samples on its own oscillator at a fixed period; a reader timestamps the samples from the
FIFO counts and the drain times as they arrive, so its early timestamps rest on a young estimate of
that period (a few milliseconds off, stretching the first seconds of the stream by up to a few
parts in 10⁴, which is a scale error of the same size: DESIGN.md fact 2). With the whole recording
in hand, the sample index ``i`` of every sample is known (consecutive, except across gaps, whose
sizes the timestamps give), and the best time axis is the least-squares fit ``t_i = a + P·i`` to
all of them at once. A fixed period is the default: over a calibration run a chip clock drifts far
less than a reader's early estimate errs, and a higher degree would bend to follow that transient.
The line is fitted to the samples after the first ``settle_s`` seconds and applied to all of them:
a reader's timestamps are least certain while its clock fit is young, and that transient would
otherwise tilt the line (recordings shorter than three times ``settle_s`` use every sample).

The refit is applied only where its assumptions hold: samples at a fixed period (every step a whole
number of periods within a third of a period) and residuals of the fit small against the period.
Otherwise the recorded times are kept.

The refit works through the stream a block at a time (steps, normal equations of the fit in a
basis scaled to [-1, 1], the fitted times written over the sample indices), so that besides its
input it holds only its output: an hour at 1 kHz is 3.6 million samples, and a whole-stream
least-squares fit would hold about ten arrays of that length at once.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np

from gyrocal.calib.errors import CalibInputError

__all__ = ["TimebaseFit", "median_step", "refit_sample_times"]


@dataclass(frozen=True)
class TimebaseFit:
    """The outcome of :func:`refit_sample_times`.

    Attributes
    ----------
    applied : bool
        Whether the refitted times replace the recorded ones.
    period_s : float
        Fitted sample period at the start of the stream.
    residual_rms_s : float
        RMS of recorded minus refitted times (after the reader's fit settled).
    reason : str
        Why the refit was not applied (empty when it was).
    """

    applied: bool
    period_s: float
    residual_rms_s: float
    reason: str = ""


def refit_sample_times(
    t: np.ndarray, degree: int = 1, settle_s: float = 5.0
) -> tuple[np.ndarray, TimebaseFit]:
    """Least-squares time axis for a stream sampled at a fixed (slowly drifting) period.

    Parameters
    ----------
    t : ndarray, shape (N,)
        Recorded sample times, increasing.
    degree : int
        Polynomial degree in the sample index (1: fixed period, the default; 2: a period drifting
        linearly, for long recordings).
    settle_s : float
        Time over which a reader's clock fit settles; earlier samples do not shape the line.

    Returns
    -------
    times : ndarray, shape (N,)
        The refitted times, or ``t`` unchanged when the stream is not periodic enough.
    fit : TimebaseFit
    """
    t = np.asarray(t, dtype=float)
    n = t.size
    if n < 50:
        return t, TimebaseFit(False, float("nan"), float("nan"), "too few samples")
    period = median_step(t, _BLOCK)
    if not period > 0:
        return t, TimebaseFit(False, period, float("nan"), "timestamps do not increase")
    out = _sample_indices(t, period)
    if out is None:
        return t, TimebaseFit(False, period, float("nan"),
                              "steps are not whole periods: not a fixed-rate stream")
    # t is now known to increase; the settled samples are a suffix.
    first = 0 if t[-1] - t[0] < 3 * settle_s else int(np.searchsorted(t, t[0] + settle_s))
    coeffs = _fit_suffix(out, t, first, degree)
    last = float(out[-1])
    rms = _evaluate(out, t, first, coeffs)  # out: sample indices -> fitted times
    # The period at the first sample: d fitted / d i at i = 0 (u = -1).
    p0 = float(np.polynomial.polynomial.polyval(
        -1.0, np.polynomial.polynomial.polyder(coeffs)) * 2.0 / last)
    if rms > period / 4:
        return t, TimebaseFit(False, p0, rms, "residuals too large for a fixed-rate stream")
    return out, TimebaseFit(True, p0, rms)


#: Samples handled at once by the refit's passes (bounded temporaries: the refit holds only its
#: input and its output, whatever the stream's length).
_BLOCK = 1 << 18


def median_step(t: np.ndarray, block: int = _BLOCK) -> float:
    """``numpy.median(numpy.diff(t))`` exactly, holding some ``block`` steps at a time.

    Up to ``block`` steps the median is taken directly; beyond, the k-th smallest step is
    selected by pivoting: the steps between two bounds are counted a block at a time, a pivot
    is the median of every 64th of them, and the bounds close on the side that holds rank k
    until at most ``block`` steps remain between them (or the pivot is the answer, as it is at
    once for a fixed-rate stream, whose steps are a few distinct values).

    Parameters
    ----------
    t : ndarray, shape (N,)
        Sample times, N >= 2.
    block : int
        Steps held at once.

    Returns
    -------
    float
        The median step, the mean of the two middle steps for an even number of steps (as
        ``numpy.median``).

    Raises
    ------
    CalibInputError
        With fewer than two times.
    """
    t = np.asarray(t, dtype=float)
    m = t.size - 1
    if m < 1:
        raise CalibInputError(f"t must hold at least two sample times for a step, got {t.size}")
    if m <= block:
        return float(np.median(np.subtract(t[1:], t[:-1])))
    lo_k, hi_k = (m - 1) // 2, m // 2
    lo_v = _kth_step(t, lo_k, block)
    if hi_k == lo_k:
        return lo_v
    return float(np.mean([lo_v, _kth_step(t, hi_k, block)]))


def _kth_step(t: np.ndarray, k: int, block: int) -> float:
    """The ``k``-th smallest (from 0) of the steps of ``t``, holding ``block`` steps at once."""
    m = t.size - 1

    def inside(lo: float, hi: float) -> Iterator[np.ndarray]:
        for a in range(0, m, block):
            b = min(a + block, m)
            d = np.subtract(t[a + 1:b + 1], t[a:b])
            yield d[(d > lo) & (d <= hi)]

    lo, hi, below = -np.inf, np.inf, 0  # the step lies in (lo, hi]; `below` steps are <= lo
    while True:
        kept: list[np.ndarray] | None = []
        sample = []
        count = 0
        for s in inside(lo, hi):
            count += s.size
            sample.append(s[::64])
            if kept is not None and count <= block:
                kept.append(s)
            else:
                kept = None
        if kept is not None:
            v = np.concatenate(kept)
            return float(np.partition(v, k - below)[k - below])
        pivot = float(np.median(np.concatenate(sample)))
        lt = le = 0
        for s in inside(lo, hi):
            lt += int(np.count_nonzero(s < pivot))
            le += int(np.count_nonzero(s <= pivot))
        if below + lt <= k < below + le:
            return pivot
        if k < below + lt:
            hi = float(np.nextafter(pivot, -np.inf))
        else:
            below += le
            lo = pivot


def _sample_indices(t: np.ndarray, period: float) -> np.ndarray | None:
    """Each sample's index ``i`` on the chip's clock (steps rounded to whole periods), or None
    when a step is not within a third of a whole number of periods (at least one)."""
    out = np.empty(t.size)
    out[0] = 0.0
    for a in range(0, t.size - 1, _BLOCK):
        b = min(a + _BLOCK, t.size - 1)
        steps = (t[a + 1:b + 1] - t[a:b]) / period
        whole = np.rint(steps)
        if np.any(whole < 1) or np.max(np.abs(steps - whole)) > 1 / 3:
            return None
        out[a + 1:b + 1] = whole
    return np.cumsum(out, out=out)


def _unit(i: np.ndarray, last: float) -> np.ndarray:
    """Sample indices mapped onto [-1, 1] (a well-conditioned polynomial basis)."""
    return i * (2.0 / last) - 1.0


def _fit_suffix(i: np.ndarray, t: np.ndarray, first: int, degree: int) -> np.ndarray:
    """Least-squares polynomial ``t - t[0] = sum_k c_k u^k`` over samples ``first:``, with ``u``
    the sample index mapped onto [-1, 1], from normal equations accumulated block by block
    (their matrix is well conditioned on [-1, 1] for the low degrees used here)."""
    m = degree + 1
    gram = np.zeros((m, m))
    rhs = np.zeros(m)
    for a in range(first, t.size, _BLOCK):
        b = min(a + _BLOCK, t.size)
        v = np.polynomial.polynomial.polyvander(_unit(i[a:b], i[-1]), degree)
        gram += v.T @ v
        rhs += v.T @ (t[a:b] - t[0])
    return np.linalg.solve(gram, rhs)


def _evaluate(i: np.ndarray, t: np.ndarray, first: int, coeffs: np.ndarray) -> float:
    """Overwrite the sample indices ``i`` with the fitted times, block by block (the last
    block last: the mapping needs ``i[-1]``); return the RMS residual over samples ``first:``."""
    last = float(i[-1])
    ss = 0.0
    for a in range(0, t.size, _BLOCK):
        b = min(a + _BLOCK, t.size)
        i[a:b] = t[0] + np.polynomial.polynomial.polyval(_unit(i[a:b], last), coeffs)
        lo = max(a, first)
        if lo < b:
            ss += float(np.sum((t[lo:b] - i[lo:b]) ** 2))
    return float(np.sqrt(ss / (t.size - first)))
