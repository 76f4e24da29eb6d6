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
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["TimebaseFit", "refit_sample_times"]


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
    if t.size < 50:
        return t, TimebaseFit(False, float("nan"), float("nan"), "too few samples")
    d = np.diff(t)
    period = float(np.median(d))
    if not period > 0:
        return t, TimebaseFit(False, period, float("nan"), "timestamps do not increase")
    steps = d / period
    whole = np.rint(steps)
    if np.any(whole < 1) or np.max(np.abs(steps - whole)) > 1 / 3:
        return t, TimebaseFit(False, period, float("nan"),
                              "steps are not whole periods: not a fixed-rate stream")
    i = np.concatenate([[0.0], np.cumsum(whole)])
    x = i / i[-1]  # scaled for conditioning
    settled = (t - t[0]) >= settle_s
    if t[-1] - t[0] < 3 * settle_s:
        settled[:] = True
    coeffs = np.polynomial.polynomial.polyfit(x[settled], t[settled], degree)
    fitted = np.polynomial.polynomial.polyval(x, coeffs)
    resid = (t - fitted)[settled]
    rms = float(np.sqrt(np.mean(resid**2)))
    p0 = float(coeffs[1] / i[-1])
    if rms > period / 4:
        return t, TimebaseFit(False, p0, rms, "residuals too large for a fixed-rate stream")
    return fitted, TimebaseFit(True, p0, rms)
