"""Deciding when a gyro is still, from its own readings and its noise model.

A window of ``n_w`` consecutive readings ending at sample ``e`` is *quiet* when, on every axis,

* its sample variance is at most ``σ² · χ²_{n_w−1}(1 − α) / (n_w − 1)``: the variance a still
  sensor with white noise ``σ`` exceeds with probability ``α`` (the chi-square law of a sample
  variance); this catches any rotation whose rate changes, and
* the magnitude of its mean, after adding a reference bias (Calibration v1 convention, so a still
  sensor reads ``−bias``), is at most a rate threshold, by default ``5 σ``: this catches a steady
  rotation, which the variance test cannot see. It is loose on purpose: it also bounds how far
  the bias may drift from the reference before the detector stops calling the sensor still.
  The bias tracker (:mod:`gyrocal.calib.tracker`) centres it on its seed (the calibration's
  bias), never on its own estimate, and widens it by the chip's zero-rate tolerance: a
  detector gated on the estimate it feeds never sees a sensor whose bias moved.

Where an accelerometer sits beside the gyro, its readings veto a still decision the gyro makes
(:func:`accel_detector`, :func:`accel_quiet_windows`): a steady turn slower than the rate test's
room passes both gyro tests, but it tilts gravity, and the least-squares slope of the
accelerometer's readings over the samples behind the decision (``accel_window_s``, ending
``lookahead_s`` after the sample) shows it.

A sample ``j`` is *still* when every window ending in ``[j − n_min + 1, j + L]`` is quiet: the
sensor has been quiet for ``min_still_s`` (it has settled), and stays quiet for ``lookahead_s``
after ``j`` (so the start of a motion, which takes a few samples to show in a window, is not
taken for stillness). The decision on ``j`` is therefore known ``L`` samples later; streaming
users get it with that lag.

:func:`quiet_windows` and :func:`run_lengths` are the vectorised pieces; the bias tracker
(:mod:`gyrocal.calib.tracker`) uses them on batches of any size, carrying the last few samples
across
batches, so a recording processed at once and a live stream fed sample by sample decide alike.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable, Iterator
from dataclasses import dataclass

import numpy as np
from scipy.special import chdtri, ndtri

from gyrocal.calib.errors import CalibInputError
from gyrocal.calib.validation import scalar, vec3

__all__ = [
    "StillDetector",
    "StillSettings",
    "AccelStillDetector",
    "StreamingQuiet",
    "accel_detector",
    "accel_quiet_windows",
    "detect_still",
    "first_still_mean",
    "quiet_windows",
    "quiet_fraction",
    "quiet_noise_std",
    "run_lengths",
    "white_noise_std",
]

_BLOCK = 8192  # windows per block of running sums (temporaries of a few hundred kB)


@dataclass(frozen=True)
class StillSettings:
    """Tuning of the still detector (times in seconds, converted at the sample rate).

    Attributes
    ----------
    window_s : float
        Length of the variance/mean window (at least 2 samples).
    min_still_s : float
        How long the sensor must have been quiet before a sample counts as still.
    lookahead_s : float
        How long it must stay quiet after the sample (the decision lag).
    variance_alpha : float
        Probability that a still sensor's window fails the variance test, per axis.
    rate_sigma : float
        Default rate threshold in units of the per-sample noise ``σ``.
    rate_threshold : float or None
        Explicit rate threshold, rad/s (overrides ``rate_sigma``).
    accel_window_s : float or None
        Length of the accelerometer's slope window (:func:`accel_detector`); None (the
        default): ``window_s + min_still_s + lookahead_s``, the span of the readings the gyro's
        windows behind one still decision cover, so the veto adds no settling time (a slow turn
        tilts gravity by ``ω · window`` across it, which must outgrow the noise to show).
    """

    window_s: float = 0.2
    min_still_s: float = 0.5
    lookahead_s: float = 0.2
    variance_alpha: float = 1e-6
    rate_sigma: float = 5.0
    rate_threshold: float | None = None
    accel_window_s: float | None = None

    def __post_init__(self) -> None:
        scalar(self.window_s, "window_s", positive=True)
        if self.accel_window_s is not None:
            scalar(self.accel_window_s, "accel_window_s", positive=True)
        for name in ("min_still_s", "lookahead_s", "rate_sigma"):
            scalar(getattr(self, name), name, nonneg=True)
        if not (0 < scalar(self.variance_alpha, "variance_alpha") < 1):
            raise CalibInputError(f"variance_alpha must be in (0, 1), got {self.variance_alpha!r}")
        if self.rate_threshold is not None:
            scalar(self.rate_threshold, "rate_threshold", positive=True)


@dataclass(frozen=True)
class StillDetector:
    """The still detector's thresholds for one sensor at one sample rate.

    Build it with :meth:`build`. Attributes are in samples and rad/s.

    Attributes
    ----------
    n_window : int
    n_min : int
    n_lookahead : int
    var_limit : ndarray (3,)
        Per-axis limit on the window's sample variance, (rad/s)².
    rate_limit : ndarray (3,)
        Per-axis limit on the magnitude of the window's bias-corrected mean, rad/s.
    """

    n_window: int
    n_min: int
    n_lookahead: int
    var_limit: np.ndarray
    rate_limit: np.ndarray

    @classmethod
    def build(
        cls, noise_std: np.ndarray | float, odr_hz: float, settings: StillSettings | None = None
    ) -> StillDetector:
        """Thresholds from the white-noise level.

        Parameters
        ----------
        noise_std : float or array_like (3,)
            Per-sample white-noise standard deviation of each axis, rad/s (``N √odr``).
        odr_hz : float
            Sample rate, Hz.
        settings : StillSettings, optional

        Returns
        -------
        StillDetector
        """
        s = settings or StillSettings()
        sigma = vec3(noise_std, "noise_std", positive=True)
        fs = scalar(odr_hz, "odr_hz", positive=True)
        n_w = max(2, int(round(s.window_s * fs)))
        n_min = max(1, int(round(s.min_still_s * fs)))
        n_la = int(round(s.lookahead_s * fs))
        dof = n_w - 1
        var_limit = sigma**2 * chdtri(dof, s.variance_alpha) / dof
        if s.rate_threshold is not None:
            rate_limit = np.full(3, float(s.rate_threshold))
        else:
            rate_limit = s.rate_sigma * sigma
        return cls(n_w, n_min, n_la, var_limit, rate_limit)

    @property
    def history(self) -> int:
        """Samples a batch needs from before it to test its first window (``n_window − 1``)."""
        return self.n_window - 1


@dataclass(frozen=True)
class AccelStillDetector:
    """The accelerometer's stillness test, a veto on the gyro's still flag (build it with
    :func:`accel_detector`; use it with :func:`accel_quiet_windows`).

    A window of ``n_window`` accelerometer readings is quiet when, on every axis, the slope of
    its least-squares line is within ``slope_limit`` of zero: a turn at a constant rate, which
    the gyro's tests cannot see (its variance is the noise's, its mean within the seed's rate
    gate), tilts gravity steadily and puts a ramp on the specific force; vibration and noise
    put none (they leave the line's slope at the noise's). The variance is not tested: a
    vibrating sensor is not turning.

    Attributes
    ----------
    n_window : int
        Readings per window.
    slope_limit : ndarray (3,)
        Per-axis limit on the slope, readings' unit per sample.
    """

    n_window: int
    slope_limit: np.ndarray

    @property
    def history(self) -> int:
        """Rows a batch needs from before it to test its first window (``n_window − 1``)."""
        return self.n_window - 1


def accel_detector(
    accel_noise_std: np.ndarray | float, odr_hz: float, settings: StillSettings | None = None
) -> AccelStillDetector:
    """The accelerometer's slope test for one sensor at one sample rate.

    The least-squares slope of ``n`` readings with white noise ``σ_a`` (per sample) has
    standard deviation ``σ_a / sqrt(D)``, ``D = n (n² − 1) / 12`` (the sum of the squared
    sample offsets from the window's middle); the limit is ``z`` of those, ``z`` the normal
    quantile a still sensor's window exceeds with probability ``variance_alpha`` (two-sided).
    A turn at ``ω`` about an axis at an angle ``β`` to gravity moves the specific force at up to
    ``g ω sin β`` per second: at 100 Hz over the default 0.9 s with ``σ_a = 0.02 m/s²`` the
    limit is 0.04 m/s² per second: a horizontal turn at 0.35 °/s is refused (one at 0.25 °/s
    half the time).

    Parameters
    ----------
    accel_noise_std : float or array_like (3,)
        Per-sample white-noise standard deviation of each accelerometer axis, in the unit of
        the readings it will test (m/s²).
    odr_hz : float
        Sample rate, Hz (one accelerometer reading per gyro sample).
    settings : StillSettings, optional
        Its ``accel_window_s`` (or the gyro's windows' span) and ``variance_alpha``.

    Returns
    -------
    AccelStillDetector
    """
    s = settings or StillSettings()
    sigma = vec3(accel_noise_std, "accel_noise_std", positive=True)
    fs = scalar(odr_hz, "odr_hz", positive=True)
    span = (s.window_s + s.min_still_s + s.lookahead_s if s.accel_window_s is None
            else s.accel_window_s)
    n = max(3, int(round(span * fs)))
    d = n * (n * n - 1) / 12.0
    z = float(ndtri(1.0 - s.variance_alpha / 2.0))
    return AccelStillDetector(n, z * sigma / math.sqrt(d))


def accel_quiet_windows(accel: np.ndarray, detector: AccelStillDetector, n_history: int
                        ) -> np.ndarray:
    """Quiet flags of the accelerometer's windows ending at each of the last
    ``len(accel) − n_history`` rows (False where a window would reach before the data).

    The slope of the window ending at row ``e`` is ``Σ (k − k̄) y_k / D`` over its rows, from
    running sums of ``y`` and ``k y`` taken block by block about the block's mean and first row
    (as :func:`quiet_windows` keeps its sums free of cancellation).
    """
    nw = detector.n_window
    x = np.asarray(accel, dtype=float)
    n = x.shape[0] - n_history
    out = np.zeros(n, dtype=bool)
    first = max(0, nw - 1 - n_history)
    d = nw * (nw * nw - 1) / 12.0
    for b in range(first, n, _BLOCK):
        e = min(n, b + _BLOCK)
        rows = x[n_history + b - (nw - 1): n_history + e]
        y = rows - rows.mean(axis=0)
        k = np.arange(rows.shape[0], dtype=float)[:, None]
        c1 = np.zeros((rows.shape[0] + 1, 3))
        ck = np.zeros_like(c1)
        np.cumsum(y, axis=0, out=c1[1:])
        np.cumsum(k * y, axis=0, out=ck[1:])
        s1 = c1[nw:] - c1[:-nw]
        sk = ck[nw:] - ck[:-nw]
        mid = np.arange(nw - 1, rows.shape[0], dtype=float)[:, None] - (nw - 1) / 2.0
        slope = (sk - mid * s1) / d
        out[b:e] = (np.abs(slope) <= detector.slope_limit).all(axis=1)
    return out


def quiet_windows(
    centred: np.ndarray, detector: StillDetector, n_history: int
) -> np.ndarray:
    """Quiet flags of the windows ending at each of the last ``len(centred) − n_history`` rows.

    Parameters
    ----------
    centred : ndarray (h + n, 3)
        Readings plus the reference bias (a still sensor gives zero mean), the first
        ``h = n_history`` rows being the end of the previous batch.
    detector : StillDetector
    n_history : int
        Rows of ``centred`` that precede the batch (at most ``n_window − 1``).

    Returns
    -------
    ndarray (n,) of bool
        False where the window would reach before the start of the data.

    Notes
    -----
    O(N): each window's mean and sample variance come from running sums of the readings and
    their squares, taken block by block about the block's mean (which keeps the subtraction
    ``Σy² − (Σy)²/n`` free of cancellation), instead of being recomputed from the window.
    """
    nw = detector.n_window
    total = centred.shape[0]
    n = total - n_history
    out = np.zeros(n, dtype=bool)
    first = max(0, nw - 1 - n_history)  # first batch row whose window is complete
    if first >= n:
        return out
    x = np.asarray(centred, dtype=float)
    for b in range(first, n, _BLOCK):
        e = min(n, b + _BLOCK)
        # rows of the windows ending at batch rows b..e-1, shifted by their mean so that the
        # running sums stay small (no cancellation in the variance)
        rows = x[n_history + b - (nw - 1) : n_history + e]
        shift = rows.mean(axis=0)
        y = rows - shift
        c1 = np.zeros((rows.shape[0] + 1, 3))
        c2 = np.zeros_like(c1)
        np.cumsum(y, axis=0, out=c1[1:])
        np.cumsum(y * y, axis=0, out=c2[1:])
        s1 = c1[nw:] - c1[:-nw]
        s2 = c2[nw:] - c2[:-nw]
        mean = s1 / nw + shift
        var = np.maximum(s2 - s1 * s1 / nw, 0.0) / (nw - 1)
        ok = (var <= detector.var_limit) & (np.abs(mean) <= detector.rate_limit)
        out[b:e] = ok.all(axis=1)
    return out


class StreamingQuiet:
    """:func:`quiet_windows` one sample at a time in O(1): running sums over a ring of the last
    ``n_window`` centred readings, in Python floats (a 3-vector is too small for numpy's
    per-call cost to pay).

    The sums are taken about a shift (a recent window mean) and started afresh every
    ``n_window`` samples, so rounding does not accumulate and the variance
    ``(Σy² − (Σy)²/n)/(n − 1)`` stays free of cancellation, as in :func:`quiet_windows`; the
    two agree to rounding (about 1e-16 relative), which changes a decision only for a window
    within that of a threshold. The fresh sums are gathered as the samples arrive (about the
    window mean when the gathering began): after ``n_window`` pushes they cover exactly the
    ring, and take over in O(1), so no push pays for re-summing the ring.

    Parameters
    ----------
    detector : StillDetector
    history : ndarray (h, 3), optional
        The centred readings before the first :meth:`push` (the last ``n_window − 1`` are kept).
    """

    def __init__(self, detector: StillDetector, history: np.ndarray | None = None) -> None:
        self.nw = detector.n_window
        self._var = [float(v) for v in detector.var_limit]
        self._rate = [float(v) for v in detector.rate_limit]
        self.ring: deque[tuple[float, float, float]] = deque(maxlen=self.nw)
        if history is not None:
            for r in np.asarray(history, dtype=float)[-(self.nw - 1):] if self.nw > 1 else []:
                self.ring.append((float(r[0]), float(r[1]), float(r[2])))
        n = len(self.ring)
        c = [sum(r[a] for r in self.ring) / n if n else 0.0 for a in range(3)]
        self._c = c
        self._s1 = [sum(r[a] - c[a] for r in self.ring) for a in range(3)]
        self._s2 = [sum((r[a] - c[a]) ** 2 for r in self.ring) for a in range(3)]
        self._restart(c)

    def _restart(self, centre: list[float]) -> None:
        """Begin gathering fresh sums of the next ``n_window`` pushes about ``centre``."""
        self._c_next = list(centre)
        self._t1 = [0.0, 0.0, 0.0]
        self._t2 = [0.0, 0.0, 0.0]
        self._age = 0

    def push(self, x0: float, x1: float, x2: float) -> bool:
        """Add one centred reading; True when the window ending at it is quiet (False while
        fewer than ``n_window`` readings have been seen)."""
        ring = self.ring
        nw = self.nw
        c, s1, s2 = self._c, self._s1, self._s2
        cn, t1, t2 = self._c_next, self._t1, self._t2
        if len(ring) == nw:  # the oldest leaves (three axes written out: the hot loop)
            o0, o1, o2 = ring[0]
            y0, y1, y2 = o0 - c[0], o1 - c[1], o2 - c[2]
            s1[0] -= y0
            s1[1] -= y1
            s1[2] -= y2
            s2[0] -= y0 * y0
            s2[1] -= y1 * y1
            s2[2] -= y2 * y2
        ring.append((x0, x1, x2))
        y0, y1, y2 = x0 - c[0], x1 - c[1], x2 - c[2]
        s1[0] += y0
        s1[1] += y1
        s1[2] += y2
        s2[0] += y0 * y0
        s2[1] += y1 * y1
        s2[2] += y2 * y2
        y0, y1, y2 = x0 - cn[0], x1 - cn[1], x2 - cn[2]
        t1[0] += y0
        t1[1] += y1
        t1[2] += y2
        t2[0] += y0 * y0
        t2[1] += y1 * y1
        t2[2] += y2 * y2
        self._age += 1
        if self._age >= nw:  # the fresh sums now cover exactly the ring: they take over
            self._c, self._s1, self._s2 = c, s1, s2 = cn, t1, t2
            self._restart([s1[a] / nw + c[a] for a in range(3)])
        if len(ring) < nw:
            return False
        var_lim, rate_lim = self._var, self._rate
        for a in range(3):
            mean = s1[a] / nw + c[a]
            var = max(s2[a] - s1[a] * s1[a] / nw, 0.0) / (nw - 1)
            if not (var <= var_lim[a] and abs(mean) <= rate_lim[a]):
                return False
        return True

    def history(self) -> np.ndarray:
        """The last ``n_window − 1`` centred readings (the ``history`` rows of
        :func:`quiet_windows`)."""
        rows = list(self.ring)[-(self.nw - 1):] if self.nw > 1 else []
        return np.array(rows, dtype=float).reshape(-1, 3)


def quiet_fraction(
    n: int, read: Callable[[int, int], np.ndarray], detector: StillDetector, *,
    blocks: int = 8,
) -> float | None:
    """Fraction of the complete windows of rows ``0:n`` that are quiet, read piece by piece.

    The same as ``quiet_windows(read(0, n), detector, 0)[n_window − 1:].mean()``, bit for bit:
    the pieces are cut where :func:`quiet_windows` starts its blocks of running sums (the
    first after ``n_window − 1`` rows, then every ``blocks`` × its block), and each carries the
    last ``n_window − 1`` rows of the one before, so every window's sums are taken over the
    same rows about the same shift. Working memory: one piece.

    Parameters
    ----------
    n : int
        Rows.
    read : callable
        ``read(lo, hi)``: rows ``lo:hi`` as an ``(hi − lo, 3)`` array (centred as
        :func:`quiet_windows` wants them).
    detector : StillDetector
    blocks : int
        Blocks of running sums per piece.

    Returns
    -------
    float or None
        None when ``n < n_window`` (no complete window).
    """
    nw = detector.n_window
    if n < nw:
        return None
    step = max(1, int(blocks)) * _BLOCK
    quiet = 0
    hist = np.empty((0, 3))
    lo = 0
    hi = min(n, nw - 1 + step)
    while lo < n:
        x = read(lo, hi)
        q = quiet_windows(np.concatenate([hist, x]) if hist.shape[0] else x, detector,
                          hist.shape[0])
        quiet += int(np.count_nonzero(q))
        hist = (np.concatenate([hist, x]) if hist.shape[0] else x)[-(nw - 1):] if nw > 1 \
            else np.empty((0, 3))
        lo, hi = hi, min(n, hi + step)
    return quiet / (n - nw + 1)


def run_lengths(quiet: np.ndarray, carry: int = 0) -> np.ndarray:
    """Length of the run of quiet windows ending at each position (0 where not quiet).

    ``carry`` is the run length at the end of the previous batch.
    """
    q = np.asarray(quiet, dtype=bool)
    idx = np.arange(q.size)
    last_false = np.maximum.accumulate(np.where(~q, idx, -1)) if q.size else idx
    return np.where(last_false >= 0, idx - last_false, idx + 1 + int(carry))


def detect_still(
    rate: np.ndarray,
    noise_std: np.ndarray | float,
    odr_hz: float,
    *,
    reference_bias: np.ndarray | None = None,
    settings: StillSettings | None = None,
) -> np.ndarray:
    """Still flags of a whole record (the last ``lookahead`` samples cannot be confirmed: False).

    Parameters
    ----------
    rate : array_like (n, 3)
        Readings, rad/s.
    noise_std : float or array_like (3,)
        Per-sample white-noise standard deviation, rad/s.
    odr_hz : float
        Sample rate, Hz.
    reference_bias : array_like (3,), optional
        Bias (Calibration v1 convention) added before the rate test; default zero.
    settings : StillSettings, optional

    Returns
    -------
    ndarray (n,) of bool
    """
    try:
        m = np.asarray(rate, dtype=float)
    except (TypeError, ValueError):
        raise CalibInputError("rate must be an (n, 3) array of rad/s") from None
    if m.ndim != 2 or m.shape[1] != 3:
        raise CalibInputError(f"rate must have shape (n, 3), got {m.shape}")
    if not np.all(np.isfinite(m)):
        raise CalibInputError("rate contains NaN or inf")
    det = StillDetector.build(noise_std, odr_hz, settings)
    b = np.zeros(3) if reference_bias is None else vec3(reference_bias, "reference_bias")
    quiet = quiet_windows(m + b, det, 0)
    run = run_lengths(quiet)
    n = m.shape[0]
    still = np.zeros(n, dtype=bool)
    L = det.n_lookahead
    if n > L:
        still[: n - L] = run[L:] >= det.n_min + L
    return still


def white_noise_std(rate: np.ndarray) -> np.ndarray:
    """Per-sample white-noise standard deviation of each axis from first differences.

    Robust to motion and drift: ``1.4826 · MAD(Δm) / √2`` (a smooth motion changes little from
    one sample to the next; the median ignores the samples where it does).

    Parameters
    ----------
    rate : array_like (n, 3)
        Readings, rad/s, n >= 3.

    Returns
    -------
    ndarray (3,)
    """
    m = np.asarray(rate, dtype=float)
    if m.ndim != 2 or m.shape[1] != 3 or m.shape[0] < 3:
        raise CalibInputError(f"rate must have shape (n >= 3, 3), got {m.shape}")
    if not np.all(np.isfinite(m)):
        raise CalibInputError("rate contains NaN or inf")
    d = np.diff(m, axis=0)
    mad = np.median(np.abs(d - np.median(d, axis=0)), axis=0)
    sigma = 1.4826 * mad / math.sqrt(2.0)
    if not np.all(sigma > 0):
        raise CalibInputError(
            "the readings do not change from sample to sample on some axis (quantised to "
            "silence?); give the noise density explicitly"
        )
    return sigma


def first_still_mean(
    rate: np.ndarray | None,
    noise_std: np.ndarray | float,
    odr_hz: float,
    settings: StillSettings | None = None,
    *,
    seconds: float = 1.0,
    n: int | None = None,
    read: Callable[[int, int], np.ndarray] | None = None,
) -> np.ndarray | None:
    """Mean reading over the first ``seconds`` whose every window passes the variance test.

    A starting point for the bias when there is no calibration (a still sensor reads
    ``−bias``). The rate test is not applied (there is no bias to test against yet).

    ``n`` and ``read(lo, hi)`` (rows ``lo:hi``) instead of ``rate`` (None) read only as far as
    needed: prefixes that double in length, cut where :func:`quiet_windows` starts a block,
    so the answer is the whole array's, bit for bit.

    Returns
    -------
    ndarray (3,) or None
        None if no such stretch exists.
    """
    det = StillDetector.build(noise_std, odr_hz, settings)
    loose = StillDetector(det.n_window, det.n_min, det.n_lookahead, det.var_limit,
                          np.full(3, np.inf))
    need = max(1, int(round(seconds * float(odr_hz))))
    if read is None:
        m = np.asarray(rate, dtype=float)
        return _first_still(m, loose, need)
    if n is None:
        raise CalibInputError("read needs the session length n")
    k = det.n_window - 1 + 8 * _BLOCK
    while True:
        k = min(n, k)
        got = _first_still(read(0, k), loose, need)
        if got is not None or k >= n:
            return got
        k = det.n_window - 1 + 2 * (k - det.n_window + 1)


def _first_still(m: np.ndarray, loose: StillDetector, need: int) -> np.ndarray | None:
    """:func:`first_still_mean` on the rows ``m``."""
    quiet = quiet_windows(m, loose, 0)
    run = run_lengths(quiet)
    hit = np.flatnonzero(run >= need)
    if hit.size == 0:
        return None
    e = int(hit[0])
    a = e - need - loose.n_window + 2
    return m[max(a, 0) : e + 1].mean(axis=0)


def quiet_noise_std(
    rate: np.ndarray | None, block: int, *, n: int | None = None,
    read: Callable[[int, int], np.ndarray] | None = None,
) -> np.ndarray:
    """Per-sample white-noise standard deviation of each axis from the still stretches.

    :func:`white_noise_std` over a whole session counts the sample-to-sample change of every
    motion; where the sensor moves much of the time it overstates the noise (several times for
    brisk hand-held motion). Here the readings are cut into blocks of ``block`` samples and
    scored by the summed variance of their first differences. The quietest few (2 %, at least
    3) set a reference; every block whose score is within five standard errors of it (a
    variance of ``b`` differences has relative standard error about ``1.2·√(2/b)`` per axis,
    the differences of white noise being correlated at lag one) is taken as still, and
    the standard deviation of their differences pooled, over √2, is the figure (the standard
    deviation, not the median absolute deviation: with a converter step near a tenth of the
    noise the median snaps to whole steps). On an all-still session nearly every block is
    kept, so the choice biases the figure by a per cent or two at most.

    Parameters
    ----------
    rate : array_like (n, 3)
        Readings, rad/s.
    block : int
        Samples per block (at least 8); with fewer than 5 blocks the whole session is used.
    n, read : int, callable, optional
        Instead of ``rate`` (None): the session's length and ``read(lo, hi)`` giving its rows
        ``lo:hi`` as an ``(hi − lo, 3)`` array, so a session held outside memory (a temporary
        file) is worked a few MB at a time, with the same arithmetic as an array.

    Returns
    -------
    ndarray (3,)
    """
    if isinstance(block, bool) or not isinstance(block, (int, np.integer)) or block < 8:
        raise CalibInputError(f"block must be an integer >= 8, got {block!r}")
    if read is None:
        m = np.asarray(rate, dtype=float)
        if m.ndim != 2 or m.shape[1] != 3 or m.shape[0] < 3:
            raise CalibInputError(f"rate must have shape (n >= 3, 3), got {m.shape}")

        def read(lo: int, hi: int) -> np.ndarray:
            return m[lo:hi]

        n = m.shape[0]
    elif n is None or n < 3:
        raise CalibInputError(f"read needs the session length n >= 3, got {n!r}")
    nb = n // block
    if nb < 5:
        return white_noise_std(read(0, n))
    step = max(1, _BLOCK * 8 // block)  # blocks per piece: temporaries of a few MB

    def pieces() -> Iterator[tuple[int, int, np.ndarray]]:
        for a in range(0, nb, step):
            b = min(nb, a + step)
            # within-block differences of blocks a..b-1
            yield a, b, np.diff(read(a * block, b * block).reshape(b - a, block, 3), axis=1)

    score = np.empty(nb)
    for a, b, d in pieces():
        score[a:b] = d.var(axis=1).sum(axis=1)
    order = np.sort(score)
    ref = float(np.median(order[: max(3, int(0.02 * nb))]))
    rel = 1.2 * math.sqrt(2.0 / (block - 1)) / math.sqrt(3.0)
    keep = score <= ref * (1.0 + 5.0 * rel)
    # the standard deviation of the kept differences, pooled: two passes over the pieces
    total, count = np.zeros(3), 0
    for a, b, d in pieces():
        kd = d[keep[a:b]]
        total += kd.sum(axis=(0, 1))
        count += kd.shape[0] * kd.shape[1]
    mean = total / count
    ss = np.zeros(3)
    for a, b, d in pieces():
        ss += ((d[keep[a:b]] - mean) ** 2).sum(axis=(0, 1))
    sigma = np.sqrt(ss / count) / math.sqrt(2.0)
    if not np.all(sigma > 0):
        return white_noise_std(read(0, n))
    return sigma
