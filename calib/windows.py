r"""From raw streams to observations: steady windows, encoder reference, gyro means.

Input: the gyro samples ``(t, m)``, each servo's encoder angle ``θ(t)`` (cumulative, unwrapped),
all on one clock, and the protocol segments. Output: an
:class:`~gyrocal.calib.observations.ObservationSet` with one rotation window per turn and one rest
window
per rest, plus a record of every window used.

A rotation window is a trapezoidal weight ``w(t)``: rising from 0 to 1 over ``[a, a+L_a]``, 1 until
``b-L_b``, falling to 0 at ``b``. The gyro mean and the reference are taken with the same weight
on the same clock (DESIGN.md fact 2):

.. math::

    \bar m = \frac{\int w\, m\, dt}{\int w\, dt}, \qquad
    \bar ω = \frac{\int w\, \dot θ\, dt}{\int w\, dt}
           = \frac{\bar θ_{down} - \bar θ_{up}}{\int w\, dt},

the second by parts, with ``θ̄_up``, ``θ̄_down`` the mean encoder angles over the two ramps. The
reference therefore needs no derivative and no single crossing time: jitter of the encoder
timestamps and the encoder's quantisation average over the ramps' samples, and speed ripple cancels
because gyro and encoder see the same motion through the same weight. Nothing uses a nominal figure
(commanded speed, 2π over a nominal period, sample count over the nominal ODR).

Placement. Each turn offers candidate windows, and the one predicting the smallest variance of
the turning axis's mean against its reference (gyro noise over the window's effective samples,
plus the reference's own error) is used:

``tapered`` (at least one whole steady revolution)
    Corners at interpolated encoder crossings inside the steady part of the turn: a box of ``K``
    whole revolutions convolved with a box of the remaining fraction of the steady span (the
    ramps), or, with two steady revolutions or more, ramps of one revolution and a span of
    ``K + 1``. A ``K``-revolution box nulls a once-per-revolution wobble of the mount and every
    harmonic exactly, and the ramp-mean angles average the encoder's quantisation and timestamp
    jitter over the ramp's readings.
``rest-to-rest`` (still time on both sides, as in the paper's one-turn protocol)
    From still time before the motion to still time after it, ramping inside the still margins:
    every sample of the turn is used, and the reference is the change of the still angles over
    the window, each read to ``q/√12`` and shared with the window on its other side.

Rest windows take the gyro samples of a rest segment, after a settling guard, while every encoder
is still. Noise is estimated per axis from first differences; a correlation factor estimated on the
rests (block means against first differences) corrects the standard error of coloured noise (e.g.
a sensor's low-pass filter). On the axis a window turns about, the servo's speed ripple (gear mesh,
control loop) would pass for noise in the first differences; it is real motion that the encoder
sees too and that cancels between the gyro mean and the reference, so that axis takes the noise
measured where the servo cannot reach it: at rest and on the other windows' off-axis components.

Each turn also keeps its readings' once-per-revolution part per unit rate, the coefficients of
``θ̇ cos θ`` and ``θ̇ sin θ`` (:func:`_turn_nod`): what a nod of the turning servo's link shows,
which :mod:`gyrocal.calib.systematics` measures and takes out of the posed windows.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np

from gyrocal.calib.errors import CalibInputError
from gyrocal.calib.observations import ObservationSet, diff_noise
from gyrocal.calib.segments import Segment
from gyrocal.calib.thermal import correct_drift
from gyrocal.calib.timebase import TimebaseFit, refit_sample_times

__all__ = [
    "ExtractedWindows",
    "Window",
    "correlation_factor",
    "extract_observations",
    "trapezoid_weight",
    "weight_grid",
    "window_mean",
    "window_rate",
]

TWO_PI = 2.0 * np.pi


@dataclass(frozen=True)
class Window:
    """One window used for the fit.

    Attributes
    ----------
    kind : str
        ``tapered``, ``rest-to-rest``, ``revolution`` or ``rest``.
    segment : int
        Index of the protocol segment.
    motor : int or None
    direction : int
    corners : tuple of 4 float
        ``(a, a + L_a, b - L_b, b)`` on the recording clock.
    revolutions : float
        Shaft revolutions inside the window (0 for rests).
    rate : float
        Reference rate (0 for rests), rad/s.
    mean : tuple of 3 float
        Gyro mean, rad/s.
    count : int
        Gyro samples inside ``[a, b]``.
    """

    kind: str
    segment: int
    motor: int | None
    direction: int
    corners: tuple[float, float, float, float]
    revolutions: float
    rate: float
    mean: tuple[float, float, float]
    count: int


@dataclass(frozen=True, eq=False)
class ExtractedWindows:
    """What :func:`extract_observations` returns."""

    observations: ObservationSet
    windows: tuple[Window, ...]
    rests: tuple[Window, ...]
    warnings: tuple[str, ...]
    noise_correlation: np.ndarray  # (3,) factor applied to the white-noise standard errors
    timebase: TimebaseFit | None = None  # the gyro time axis refit (None if not attempted)


def _crossing(t: np.ndarray, th: np.ndarray, target: float, direction: int) -> float:
    """Time at which the angle, monotone in ``direction`` over ``t``, reaches ``target``
    (linear interpolation between encoder readings)."""
    return float(np.interp(direction * target, direction * th, t))


def trapezoid_weight(t: np.ndarray, corners: tuple[float, float, float, float]) -> np.ndarray:
    """A window's weight ``w(t)``: 0 → 1 over ``[a, a + L_a]``, 1, then 1 → 0 over
    ``[b - L_b, b]`` for ``corners = (a, a + L_a, b - L_b, b)``; a zero-length ramp is a vertical
    edge (the window includes it)."""
    a, a2, b2, b = corners
    up = np.ones_like(t) if a2 <= a else np.clip((t - a) / (a2 - a), 0.0, 1.0)
    down = np.ones_like(t) if b <= b2 else np.clip((b - t) / (b - b2), 0.0, 1.0)
    return np.where((t >= a) & (t <= b), np.minimum(up, down), 0.0)


def weight_grid(t: np.ndarray, corners: tuple[float, float, float, float]) -> np.ndarray:
    """The sample times strictly inside a window plus its four corners, sorted: the nodes on
    which the piecewise-linear product ``w(t) x(t)`` is integrated exactly."""
    a, b = corners[0], corners[3]
    inside = t[(t > a) & (t < b)]
    return np.unique(np.concatenate([inside, np.asarray(corners, dtype=float)]))


def _weighted_mean(
    t: np.ndarray, x: np.ndarray, corners: tuple[float, float, float, float]
) -> tuple[np.ndarray, float, np.ndarray]:
    """``∫ w x dt / ∫ w dt`` for piecewise-linear ``x`` (N, k); also ``∫w`` and the per-sample
    quadrature weights of the samples inside the window (for the standard error)."""
    g = weight_grid(t, corners)
    w = trapezoid_weight(g, corners)
    xi = np.column_stack([np.interp(g, t, x[:, j]) for j in range(x.shape[1])])
    dt = np.diff(g)
    integ = np.sum(dt[:, None] * (w[:-1, None] * xi[:-1] + w[1:, None] * xi[1:]) / 2, axis=0)
    wint = float(np.sum(dt * (w[:-1] + w[1:]) / 2))
    # Quadrature weight of each original sample (trapezoid, ignoring the edge interpolation).
    a, b = corners[0], corners[3]
    sel = (t >= a) & (t <= b)
    ts = t[sel]
    if ts.size:
        half = np.diff(ts) / 2
        qw = np.zeros(ts.size)
        qw[:-1] += half
        qw[1:] += half
        qw *= trapezoid_weight(ts, corners)
    else:
        qw = np.zeros(0)
    return integ / wint, wint, qw


def _ramp_mean(t: np.ndarray, th: np.ndarray, lo: float, hi: float) -> float:
    """Mean of the piecewise-linear angle over ``[lo, hi]`` (its value at ``lo`` if empty)."""
    if hi <= lo:
        return float(np.interp(lo, t, th))
    g = np.unique(np.concatenate([t[(t > lo) & (t < hi)], [lo, hi]]))
    v = np.interp(g, t, th)
    return float(np.sum(np.diff(g) * (v[:-1] + v[1:]) / 2) / (hi - lo))


def window_mean(t: np.ndarray, x: np.ndarray, corners: tuple[float, float, float, float]
                ) -> tuple[np.ndarray, float]:
    """The window's mean of the samples ``x`` (N, k) at times ``t``: ``∫ w x dt / ∫ w dt`` with
    the trapezoid weight of ``corners`` (module docstring), and the effective number of samples
    ``(Σ q)² / Σ q²`` of its quadrature weights ``q`` (for the standard error of white noise)."""
    mean, _, qw = _weighted_mean(t, np.asarray(x, dtype=float).reshape(len(t), -1), corners)
    n_eff = float(np.sum(qw) ** 2 / np.sum(qw**2)) if qw.size and np.sum(qw**2) > 0 else 0.0
    return mean, n_eff


def window_rate(t: np.ndarray, th: np.ndarray, corners: tuple[float, float, float, float]
                ) -> float:
    """The reference rate of a window: the encoder angle's change across it, by parts
    ``(θ̄_down − θ̄_up) / ∫ w dt`` (module docstring), ``θ̄`` the mean of the piecewise-linear
    angle over each ramp (its value at the corner when the ramp has no length). No derivative
    of the angle is taken, so timestamp jitter and quantisation average over the ramps."""
    a, a2, b2, b = corners
    wint = 0.5 * ((b - a) + (b2 - a2))
    return (_ramp_mean(t, th, b2, b) - _ramp_mean(t, th, a, a2)) / wint


def _ramp_angle_std(t: np.ndarray, th: np.ndarray, lo: float, hi: float, q: float) -> float:
    """Standard error of the mean angle over a ramp ``[lo, hi]`` of a turning servo.

    The per-reading scatter (quantisation and timestamp jitter, independent from reading to
    reading, never below ``q/√12``) divided by the square root of the readings averaged. The
    scatter is estimated from second differences of the residual about a straight line,
    ``std(Δ²r)/√6``, which removes smooth speed ripple: ripple is real motion that the gyro sees
    too and does not bias the reference. A zero-length ramp (one interpolated angle) takes the
    scatter over ±0.1 s undivided.
    """
    floor = q / np.sqrt(12.0)
    point = hi <= lo
    if point:
        lo, hi = lo - 0.1, hi + 0.1
    sel = (t >= lo) & (t <= hi)
    if sel.sum() < 4:
        return floor
    ts, ys = t[sel], th[sel]
    A = np.column_stack([np.ones_like(ts), ts - ts.mean()])
    resid = ys - A @ np.linalg.lstsq(A, ys, rcond=None)[0]
    sd = max(float(np.sqrt(np.mean(np.diff(resid, 2) ** 2) / 6.0)), floor)
    return sd if point else sd / np.sqrt(sel.sum())


def correlation_factor(rest_samples: Sequence[np.ndarray], block: int = 10) -> np.ndarray:
    """Ratio of the long-run variance to the first-difference variance, per axis (1 = white).

    A sensor's low-pass filter correlates its noise from sample to sample, so first differences
    (:func:`~gyrocal.calib.observations.diff_noise`) under-read what sets the variance of a
    window's mean, the long-run variance ``γ₀ + 2 Σ γ_k`` (e.g. the LSM6DSOX's 67 Hz filter at
    208 Hz: 2.7 times). It is estimated by overlapping batch means of ``block`` samples
    pooled over the still samples ``rest_samples`` (each (n, 3); Meketon & Schmeiser 1984:
    ``n b Σ (m_i − x̄)² / ((n − b)(n − b + 1))``, unbiased for white noise), over the pooled
    first-difference variance. Where the three axes' mean factor is within three standard
    errors of 1 *for white noise* (``√(4b / 3m + 3 / N) / √3``, ``m`` the batch count and ``N``
    the samples), every axis takes 1, so white noise is not penalised by estimation noise;
    otherwise each axis keeps its own (a chip filters its three axes with one setting, but
    their noise need not have one shape: 0.85 and 1.08 on x and z of BROAD's rests). The test
    is against white noise's scatter, not the estimate's, which grows with the factor and kept
    a real 2.7 at 1 on 13 rests of 0.2 s, and on the three axes' mean, which kept the
    ICM-42688-P's 1.7 on one or two axes only.
    """
    num = np.zeros(3)
    scale = 0.0
    diff_sq = np.zeros(3)
    n_diff = m_batches = 0
    for x in rest_samples:
        n = x.shape[0]
        if n < 2 * block:
            continue
        c = np.cumsum(np.vstack([np.zeros((1, 3)), x - x.mean(axis=0)]), axis=0)
        means = (c[block:] - c[:-block]) / block
        num += block * np.sum(means**2, axis=0)
        scale += (n - block) * (n - block + 1) / n
        diff_sq += np.sum(np.diff(x, axis=0) ** 2, axis=0) / 2
        n_diff += n - 1
        m_batches += n - block
    if m_batches < 5 * block:
        return np.ones(3)
    tau = (num / scale) / np.maximum(diff_sq / n_diff, 1e-300)
    se_white = np.sqrt((4 * block / (3 * m_batches) + 3 / n_diff) / 3)
    return np.clip(tau, 0.25, 25.0) if abs(np.mean(tau) - 1.0) > 3 * se_white else np.ones(3)


def _check_streams(
    imu_t: np.ndarray, imu_rate: np.ndarray, enc_t: np.ndarray, enc_motor: np.ndarray,
    enc_angle: np.ndarray, imu_temp: np.ndarray | None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray | None]:
    """Stage 1: the raw streams as float arrays of matching shapes, finite, gyro times rising."""
    imu_t = np.asarray(imu_t, dtype=float)
    imu_rate = np.asarray(imu_rate, dtype=float)
    enc_t = np.asarray(enc_t, dtype=float)
    enc_motor = np.asarray(enc_motor)
    enc_angle = np.asarray(enc_angle, dtype=float)
    if imu_t.ndim != 1 or imu_rate.shape != (imu_t.size, 3):
        raise CalibInputError(
            f"imu_t must be (N,) and imu_rate (N, 3); got {imu_t.shape} and {imu_rate.shape}"
        )
    if not (enc_t.shape == enc_motor.shape == enc_angle.shape) or enc_t.ndim != 1:
        raise CalibInputError("enc_t, enc_motor and enc_angle must be 1-D arrays of one length")
    if imu_t.size < 2:
        raise CalibInputError("the gyro stream is empty")
    for name, a in (("imu_t", imu_t), ("imu_rate", imu_rate), ("enc_t", enc_t),
                    ("enc_angle", enc_angle)):
        if not np.all(np.isfinite(a)):
            raise CalibInputError(f"{name} contains NaN or inf")
    if np.any(np.diff(imu_t) <= 0):
        raise CalibInputError("imu_t must be strictly increasing")
    temp = None if imu_temp is None else np.asarray(imu_temp, dtype=float)
    if temp is not None and temp.shape != imu_t.shape:
        raise CalibInputError(f"imu_temp must have shape {imu_t.shape}, got {temp.shape}")
    return imu_t, imu_rate, enc_t, enc_motor, enc_angle, temp


class EncoderTracks:
    """Stage 2: each servo's encoder track, its motion intervals and its still periods.

    A servo's motion intervals are its readings that moved by more than two ticks, merged across
    pauses shorter than 50 ms; the gaps between them are its still periods, numbered once each so
    that the windows on both sides of one still angle share it.

    Parameters
    ----------
    enc_t, enc_motor, enc_angle : ndarray, shape (M,)
        Encoder readings: time, servo ID, cumulative angle in rad.
    q : float
        One encoder tick, rad.
    """

    def __init__(self, enc_t: np.ndarray, enc_motor: np.ndarray, enc_angle: np.ndarray,
                 q: float) -> None:
        self.q = q
        self.track: dict[int, tuple[np.ndarray, np.ndarray]] = {}
        for m in np.unique(enc_motor):
            sel = enc_motor == m
            order = np.argsort(enc_t[sel], kind="stable")
            self.track[int(m)] = (enc_t[sel][order], enc_angle[sel][order])
        self.motion: dict[int, list[tuple[float, float]]] = {}
        for m_id, (t_m, th_m) in self.track.items():
            spans: list[tuple[float, float]] = []
            for i in np.flatnonzero(np.abs(np.diff(th_m)) > 2 * q):
                lo_t, hi_t = float(t_m[i]), float(t_m[i + 1])
                if spans and lo_t - spans[-1][1] < 0.05:
                    spans[-1] = (spans[-1][0], hi_t)
                else:
                    spans.append((lo_t, hi_t))
            self.motion[m_id] = spans
        self._still_ids: dict[tuple[int, int], int] = {}

    def still_angles(self, motor: int, t_start: float, t_end: float) -> tuple[int, int]:
        """Indices of the still periods of ``motor`` just before and just after its motion
        ``[t_start, t_end]`` (one index per still period, shared by the windows around it)."""
        spans = self.motion[motor]
        first = next(i for i, sp in enumerate(spans) if sp[1] >= t_start)
        last = max(i for i, sp in enumerate(spans) if sp[0] <= t_end)
        ids = [self._still_ids.setdefault(key, len(self._still_ids))
               for key in ((motor, first), (motor, last + 1))]  # gap before span i is gap i
        return ids[0], ids[1]

    def still_index(self, motor: int, a: float, b: float) -> int:
        """Index of the still period of ``motor`` that holds over ``[a, b]`` (the numbering of
        :meth:`still_angles`); -1 if the servo moves within it."""
        spans = self.motion[motor]
        gap = sum(1 for sp in spans if sp[1] < a)
        if gap < len(spans) and spans[gap][0] <= b:
            return -1
        return self._still_ids.setdefault((motor, gap), len(self._still_ids))

    def still_all(self, a: float, b: float) -> bool:
        """Whether every servo holds within four ticks over ``[a, b]``."""
        for t, th in self.track.values():
            sel = (t >= a) & (t <= b)
            if sel.any() and np.ptp(th[sel]) > 4 * self.q:
                return False
        return True

    def still_around(self, t0: float, t1: float, lo: float, hi: float) -> tuple[float, float]:
        """Still time before ``t0`` and after ``t1``: back to the last movement of any servo
        (turns and pose moves alike), on to the next one, within ``[lo, hi]``."""
        last_move, next_move = lo, hi
        for spans in self.motion.values():
            for m_lo, m_hi in spans:
                if m_hi < t0 - 0.02:
                    last_move = max(last_move, m_hi)
                if m_lo > t1 + 0.02:
                    next_move = min(next_move, m_lo)
        return t0 - last_move, next_move - t1

    def pose(self, chain: Sequence[int], a: float, b: float) -> tuple[np.ndarray, np.ndarray]:
        """Mean angle of each servo of ``chain`` over ``[a, b]``, rad (chain order), and the
        index of the still period each holds (:meth:`still_index`; -1 for one that moves).

        Raises
        ------
        CalibInputError
            If a servo of the chain has no encoder readings.
        """
        out, still = [], []
        for m in chain:
            if m not in self.track:
                raise CalibInputError(
                    f"no encoder readings of servo {m}, listed in the gimbal chain; its angle "
                    "carries the axes of the servos outside it")
            t, th = self.track[m]
            out.append(_ramp_mean(t, th, a, b))
            still.append(self.still_index(m, a, b))
        return np.array(out), np.array(still, dtype=np.int64)


@dataclass(frozen=True)
class _Turn:
    """A turn's window and its reduced row (stage 3's output)."""

    window: Window
    mean: np.ndarray
    rate: float
    count: int
    noise: np.ndarray
    mean_std: np.ndarray
    rate_std: float
    ref: tuple[int, int, float]  # still angle before, after, 1/∫w (-1, -1, 0 when unused)
    # each component's share of the turning axis's motion (0 on that axis): its noise is
    # measured with the motion taken out (:func:`_noise_beside_motion`)
    follow: np.ndarray
    nod: np.ndarray  # (2, 3) once-per-revolution part per unit rate (:func:`_turn_nod`)
    nod_std: np.ndarray  # (2, 3) its white-noise standard errors


@dataclass(frozen=True)
class _Motion:
    """Where a turn's servo moved: encoder readings around the turn, motion start and end,
    its steady span and the still time around it."""

    ts: np.ndarray
    ys: np.ndarray
    moved: float
    t_move0: float
    t_move1: float
    tt: np.ndarray  # steady readings
    yy: np.ndarray
    steady_revs: float
    still_before: float
    still_after: float


def _turn_motion(seg: Segment, tracks: EncoderTracks, lo: float, hi: float,
                 steady_tolerance: float) -> _Motion:
    """Stage 3a: find the turn's motion, its steady span and the still time around it."""
    q = tracks.q
    if seg.motor not in tracks.track:
        raise CalibInputError(
            f"segment {seg.index}: no encoder readings of servo {seg.motor} in the recording"
        )
    t, th = tracks.track[seg.motor]
    sel = (t >= lo) & (t <= hi)
    ts, ys = t[sel], th[sel]
    if ts.size < 6:
        raise CalibInputError(
            f"segment {seg.index}: only {ts.size} encoder readings of servo {seg.motor}"
        )
    inseg = (ts >= seg.t_start) & (ts <= seg.t_end)
    if inseg.sum() < 3:
        raise CalibInputError(f"segment {seg.index}: no encoder readings during the turn")
    th0 = float(ys[inseg][0])
    th1 = float(ys[inseg][-1])
    moved = th1 - th0
    if abs(moved) < np.pi:
        raise CalibInputError(
            f"segment {seg.index}: servo {seg.motor} turned only {abs(moved):.2f} rad; "
            "it may have stalled (check power and the velocity limit)"
        )
    if np.sign(moved) != seg.direction:
        raise CalibInputError(
            f"segment {seg.index}: servo {seg.motor} turned {moved:+.2f} rad against its "
            f"command (direction {seg.direction:+d}); check the encoder sign convention"
        )
    d = seg.direction
    # Motion start/stop: the angle leaves its start / reaches its end by more than 3 ticks.
    # (only inside the segment: earlier motion, e.g. a failed attempt and its reversal
    # before a repeated turn, is not this turn)
    moving = (d * (ys - th0) > 3 * q) & (d * (th1 - ys) > 3 * q)
    moving &= (ts >= seg.t_start - 0.05) & (ts <= seg.t_end + 0.05)
    if not moving.any():
        raise CalibInputError(f"segment {seg.index}: no motion found in the encoder data")
    i0, i1 = int(np.argmax(moving)), int(moving.size - 1 - np.argmax(moving[::-1]))
    t_move0, t_move1 = float(ts[max(i0 - 1, 0)]), float(ts[min(i1 + 1, ts.size - 1)])
    # Smoothed speed over about 0.1 s, plateau = median speed while moving.
    span = max(1, int(round(0.05 / max(np.median(np.diff(ts)), 1e-6))))
    j = np.arange(ts.size)
    jl, jh = np.clip(j - span, 0, ts.size - 1), np.clip(j + span, 0, ts.size - 1)
    v = d * (ys[jh] - ys[jl]) / np.maximum(ts[jh] - ts[jl], 1e-9)
    plateau = float(np.median(v[i0 : i1 + 1]))
    # Steady span: from the first to the last reading at plateau speed. Ripple dips in between
    # are real motion that gyro and encoder share; only the acceleration ramps are excluded.
    fast = (v >= (1.0 - steady_tolerance) * plateau) & (j >= i0) & (j <= i1)
    if fast.any():
        s0 = int(np.argmax(fast))
        s1 = int(fast.size - 1 - np.argmax(fast[::-1]))
    else:
        s0, s1 = 0, -1
    steady_revs = abs(ys[s1] - ys[s0]) / TWO_PI if s1 > s0 else 0.0
    # Still time around the turn (a pose move or a turn of any servo ends it).
    before, after = tracks.still_around(t_move0, t_move1, lo, hi)
    before = min(before, t_move0 - (seg.t_start - 10.0))
    after = min(after, seg.t_end + 10.0 - t_move1)
    return _Motion(ts, ys, moved, t_move0, t_move1, ts[s0 : s1 + 1], ys[s0 : s1 + 1],
                   float(steady_revs), float(before), float(after))


def _candidates(seg: Segment, mo: _Motion, still_margin_s: float, window: str
                ) -> list[tuple[str, tuple[float, float, float, float], float]]:
    """Stage 3b: the turn's candidate windows (module docstring, "Placement")."""
    d, tt, yy, steady_revs = seg.direction, mo.tt, mo.yy, mo.steady_revs
    candidates: list[tuple[str, tuple[float, float, float, float], float]] = []
    if steady_revs >= 1.0:
        K = int(np.floor(steady_revs))
        frac = steady_revs - K
        c = [_crossing(tt, yy, yy[0] + d * TWO_PI * n, d) for n in (0, frac, K, K + frac)]
        candidates.append(("tapered", (c[0], c[1], c[2], c[3]), float(K)))
    if steady_revs >= 2.0:
        K = int(np.floor(steady_revs)) - 1
        base = yy[0] + d * (steady_revs - (K + 1)) * TWO_PI / 2
        c = [_crossing(tt, yy, base + d * TWO_PI * n, d) for n in (0, 1, K, K + 1)]
        candidates.append(("tapered", (c[0], c[1], c[2], c[3]), float(K)))
    if min(mo.still_before, mo.still_after) >= 0.05:
        ma = min(still_margin_s, mo.still_before)
        mb = min(still_margin_s, mo.still_after)
        candidates.append(("rest-to-rest", (mo.t_move0 - ma, mo.t_move0, mo.t_move1,
                                            mo.t_move1 + mb), abs(mo.moved) / TWO_PI))
    if window != "auto" and any(c[0] == window for c in candidates):
        candidates = [c for c in candidates if c[0] == window]
    if not candidates:
        raise CalibInputError(
            f"segment {seg.index}: servo {seg.motor} made {steady_revs:.2f} steady "
            "revolutions and has no still time around the turn; nothing to window "
            "(turn more, or rest between turns)"
        )
    return candidates


def _gap_inside(imu_t: np.ndarray, a: float, b: float, dt_med: float) -> bool:
    ts = imu_t[(imu_t >= a) & (imu_t <= b)]
    return ts.size < 2 or bool(np.any(np.diff(ts) > 2.5 * dt_med))


def _turn_window(
    seg: Segment, tracks: EncoderTracks, imu_t: np.ndarray, imu_rate: np.ndarray,
    lo: float, hi: float, dt_med: float, *, steady_tolerance: float, still_margin_s: float,
    window: str,
) -> _Turn | None:
    """Stage 3: one turn's window, the candidate predicting the least variance of the turning
    axis's mean against its reference, reduced to a row; None if a gyro gap spoils every
    candidate."""
    q = tracks.q
    mo = _turn_motion(seg, tracks, lo, hi, steady_tolerance)
    candidates = _candidates(seg, mo, still_margin_s, window)
    covered = [c for c in candidates if c[1][0] >= imu_t[0] and c[1][3] <= imu_t[-1]]
    if not covered:
        a, b = candidates[0][1][0], candidates[0][1][3]
        raise CalibInputError(
            f"the window of segment {seg.index} spans {a:.3f}-{b:.3f} s but the gyro stream "
            f"covers {imu_t[0]:.3f}-{imu_t[-1]:.3f} s: the recording is truncated"
        )
    t, th = tracks.track[seg.motor]  # type: ignore[index]
    best = None
    for kind, corners, revs in covered:
        a, a2, b2, b = corners
        if _gap_inside(imu_t, a, b, dt_med):
            continue
        mean, wint, qw = _weighted_mean(imu_t, imu_rate, corners)
        sel = (imu_t >= a) & (imu_t <= b)
        sensor_noise = float(np.min(diff_noise(imu_rate[sel])))  # a non-turning axis
        var_mean = sensor_noise**2 * float(np.sum(qw**2) / np.sum(qw) ** 2)
        if kind == "rest-to-rest":
            var_ref = 2 * q**2 / 12 / wint**2
        else:
            var_ref = (_ramp_angle_std(t, th, a, a2, q) ** 2
                       + _ramp_angle_std(t, th, b2, b, q) ** 2) / wint**2
        score = var_mean + var_ref
        if best is None or score < best[0]:
            best = (score, kind, corners, revs, mean, wint, qw)
    if best is None:
        return None
    _, kind, corners, revs, mean, wint, qw = best
    a, a2, b2, b = corners
    d = seg.direction
    rate = window_rate(t, th, corners)
    if np.sign(rate) != d:
        raise CalibInputError(f"segment {seg.index}: reference rate has the wrong sign")
    if kind == "rest-to-rest":
        # The reference rests on two still angles, each shared with the window on its other
        # side: their reading errors are modelled as shared unknowns (ref_* fields).
        rate_std = 0.0
        ref = (*tracks.still_angles(int(seg.motor), mo.t_move0, mo.t_move1),  # type: ignore[arg-type]
               1.0 / wint)
    else:
        rate_std = float(np.hypot(_ramp_angle_std(t, th, a, a2, q),
                                  _ramp_angle_std(t, th, b2, b, q)) / wint)
        ref = (-1, -1, 0.0)
    inside = (imu_t >= a) & (imu_t <= b)
    x = imu_rate[inside]
    noise, follow = _noise_beside_motion(x)
    mean_std = noise * float(np.sqrt(np.sum(qw**2)) / np.sum(qw))  # white; see _pool_noise
    nod, nod_std = _turn_nod(imu_t[inside], x, t, th)
    win = Window(kind, seg.index, int(seg.motor), d, corners, revs, float(rate),  # type: ignore[arg-type]
                 tuple(float(v) for v in mean), int(x.shape[0]))  # type: ignore[arg-type]
    return _Turn(win, mean, float(rate), int(x.shape[0]), noise, mean_std, rate_std,
                 ref, follow, nod, nod_std)  # type: ignore[arg-type]


def _turn_nod(ts: np.ndarray, x: np.ndarray, t: np.ndarray, th: np.ndarray
              ) -> tuple[np.ndarray, np.ndarray]:
    r"""The once-per-revolution part of a turn's readings ``x`` (n, 3) at times ``ts``: the
    least-squares coefficients of ``θ̇ cos θ`` and ``θ̇ sin θ`` (rows), ``θ`` the turning servo's
    encoder angle (``t``, ``th``) and ``θ̇`` its rate, with a constant and ``θ̇`` beside them
    (the bias, and the turn itself with its speed ripple); and their white-noise standard errors
    from the residuals.

    A link that nods as its servo turns (:mod:`gyrocal.calib.systematics`) shows here: its tilt
    ``T(θ)`` adds ``θ̇ (dT/dθ + u × T)`` to the rate the sensor turns at, once per revolution
    for the nod's first harmonic. The encoder's rate (central differences) carries the servo's
    speed ripple, which the ``θ̇`` column takes out of every component; its quantisation noise
    only dilutes the coefficients by its share of their regressors' variance (1e-4 or less at a
    servo's 4 rad/s over 4096 ticks a turn at 100 Hz)."""
    near = (t >= ts[0] - 0.1) & (t <= ts[-1] + 0.1) if ts.size else np.zeros(t.size, bool)
    t, th = t[near], th[near]
    if t.size > 1:  # one reading per time (a repeated timestamp has no rate of its own)
        t, first = np.unique(t, return_index=True)
        th = th[first]
    if ts.size < 8 or t.size < 3:
        return np.zeros((2, 3)), np.full((2, 3), np.inf)  # not measured
    rate = np.gradient(th, t)
    ang = np.interp(ts, t, th)
    w = np.interp(ts, t, rate)
    X = np.column_stack([np.ones(ts.size), w, w * np.cos(ang), w * np.sin(ang)])
    coef, *_ = np.linalg.lstsq(X, x, rcond=None)
    resid = x - X @ coef
    var = np.sum(resid**2, axis=0) / max(ts.size - X.shape[1], 1)
    try:
        inv = np.diag(np.linalg.inv(X.T @ X))[2:]
    except np.linalg.LinAlgError:
        return np.zeros((2, 3)), np.full((2, 3), np.inf)  # not measured
    return coef[2:], np.sqrt(np.outer(np.maximum(inv, 0.0), var))


def _noise_beside_motion(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per-sample noise of a turning window's samples ``x`` (n, 3) on each component with
    the servo's motion taken out, and each component's share ``c`` of the turning axis's.

    The servo's speed ripple (gear mesh, commutation, its control loop) is real motion along
    the turning axis: every component sees ``(A⁻¹u)_j ω(t)``, and it cancels between the gyro
    mean and the reference (same weight, same motion: module docstring), so it is no noise of
    the window's mean. First differences pass it for noise wherever the axis has a share: on a
    posed turn, whose axis lies between two sensor axes, the second component's differences
    are ten times the white noise (emulated ``--sim``: 3.4e-2 rad/s against 2.5e-3 at the
    rests). So each component ``j`` other than the turning one ``d`` is read as
    ``x_j − c_j x_d``, ``c_j`` the least-squares slope of its first differences on ``d``'s
    (the ripple's share, whatever the bias); what is left is ``x_j``'s noise and ``c_j`` times
    ``d``'s, which :func:`_turning_axis_noise` takes out. ``d`` keeps its own differences
    (replaced there by the noise measured where no servo reaches it).
    """
    dx = np.diff(x, axis=0)
    d = int(np.argmax(np.abs(x.mean(axis=0))))
    ref = dx[:, d]
    den = float(ref @ ref)
    follow = (ref @ dx) / den if den > 0 else np.zeros(3)
    follow[d] = 0.0
    noise = np.maximum(diff_noise(x - np.outer(x[:, d], follow)), 1e-12)
    return noise, follow


def _rest_windows(
    segments: Sequence[Segment], turns: Sequence[_Turn], tracks: EncoderTracks,
    imu_t: np.ndarray, imu_rate: np.ndarray, dt_med: float, rest_guard_s: float,
    warnings: list[str],
) -> tuple[list[Window], list[np.ndarray]]:
    """Stage 4: one window per rest, after a settling guard, clear of every rotation window and
    pose move, while every encoder is still."""
    # Keep clear of every rotation window (a rest-to-rest window's still margins) and every pose
    # move, so that no sample enters two windows (their errors are then independent) and no
    # rest spans a move.
    busy = [(w.window.corners[0], w.window.corners[3]) for w in turns]
    busy += [(s.t_start, s.t_end) for s in segments if s.kind == "move"]
    rest_windows: list[Window] = []
    rest_samples: list[np.ndarray] = []
    for seg in segments:
        if seg.kind != "rest":
            continue
        a, b = seg.t_start + rest_guard_s, seg.t_end - rest_guard_s
        for wa, wb in busy:
            if wb <= a or wa >= b:
                continue
            if wa <= a:
                a = wb
            elif wb >= b:
                b = wa
            else:  # a window inside the rest: keep the longer side
                a, b = (a, wa) if wa - a >= b - wb else (wb, b)
        if b - a < 10 * dt_med:
            continue
        if a < imu_t[0] or b > imu_t[-1]:
            warnings.append(f"rest {seg.index} is not covered by the gyro stream; skipped")
            continue
        if not tracks.still_all(a, b):
            warnings.append(f"rest {seg.index}: a servo moved during the rest; skipped")
            continue
        if _gap_inside(imu_t, a, b, dt_med):
            warnings.append(f"rest {seg.index}: gap in the gyro stream; skipped")
            continue
        x = imu_rate[(imu_t >= a) & (imu_t <= b)]
        rest_samples.append(x)
        rest_windows.append(
            Window("rest", seg.index, None, 0, (a, a, b, b), 0.0, 0.0,
                   tuple(float(v) for v in x.mean(axis=0)), int(x.shape[0]))  # type: ignore[arg-type]
        )
    return rest_windows, rest_samples


def _turning_axis_noise(turns: Sequence[_Turn], rest_samples: Sequence[np.ndarray]
                        ) -> tuple[np.ndarray, np.ndarray]:
    """Stage 5: the turning axis's noise of each window, pooled from the rests and the windows
    turning other axes (module docstring); returns per-window noise and standard errors."""
    noise_rows = np.array([w.noise for w in turns])
    neff = np.array([w.mean_std for w in turns]) / noise_rows  # 1/sqrt(n_eff) per window, axis
    dominant = np.argmax(np.abs(np.array([w.mean for w in turns])), axis=1)
    # a component read beside the turning axis's motion still holds c² times that axis's
    # noise (_noise_beside_motion): out, in the ratio of the two axes' noise at the rests
    at_rest = (np.sqrt(np.mean([diff_noise(x) ** 2 for x in rest_samples], axis=0))
               if rest_samples else np.ones(3))
    for i, w in enumerate(turns):
        ratio = (at_rest[dominant[i]] / np.maximum(at_rest, 1e-300)) ** 2
        noise_rows[i] = noise_rows[i] / np.sqrt(1.0 + w.follow**2 * ratio)
    for j in range(3):
        var, dof = [], []
        for x in rest_samples:
            var.append(float(diff_noise(x)[j]) ** 2)
            dof.append(x.shape[0] - 1)
        for i, w in enumerate(turns):
            if dominant[i] != j:
                var.append(float(noise_rows[i, j]) ** 2)
                dof.append(w.count - 1)
        if dof:
            noise_rows[dominant == j, j] = float(np.sqrt(np.dot(var, dof) / np.sum(dof)))
    return noise_rows, noise_rows * neff


def _assemble(
    turns: Sequence[_Turn], noise: np.ndarray, mean_std: np.ndarray,
    rest_windows: Sequence[Window], rest_samples: Sequence[np.ndarray], tau: np.ndarray,
    temp: np.ndarray | None, q: float, chain: tuple[int, ...] | None,
    pose: np.ndarray | None, pose_still: np.ndarray | None, still_std: float | None = None,
) -> ObservationSet:
    """Stage 6: the observation set (rests with the correlation factor, shared still angles
    renumbered, the chain and poses when asked for)."""
    rest_kw: dict[str, object] = {}
    if rest_windows:
        r_noise = np.array([np.maximum(diff_noise(x), 1e-12) for x in rest_samples])
        r_count = np.array([w.count for w in rest_windows])
        rest_kw = dict(
            rest_mean=np.array([w.mean for w in rest_windows]), rest_count=r_count,
            rest_noise=r_noise,
            rest_mean_std=r_noise / np.sqrt(r_count)[:, None] * np.sqrt(tau),
        )
    t_mean = None
    if temp is not None and np.any(np.isfinite(temp)):
        t_mean = float(np.nanmean(temp))
    refs = [w.ref for w in turns]
    ref_kw: dict[str, object] = {}
    # Still angles used by a reference or a pose, renumbered 0.. (one unknown each).
    used = {i for r in refs for i in r[:2] if i >= 0}
    if pose_still is not None:
        used |= {int(i) for i in pose_still.ravel() if i >= 0}
    renumber = {old: new for new, old in enumerate(sorted(used))}
    if any(r[0] >= 0 for r in refs):
        ref_kw = dict(
            ref_start=np.array([renumber.get(r[0], -1) for r in refs]),
            ref_end=np.array([renumber.get(r[1], -1) for r in refs]),
            ref_gain=np.array([r[2] for r in refs]),
        )
    if used:
        ref_kw["still_angle_std"] = q / np.sqrt(12.0) if still_std is None else still_std
    if pose_still is not None:
        pose_still = np.vectorize(lambda i: renumber.get(int(i), -1), otypes=[np.int64])(
            pose_still)
    return ObservationSet(
        mean=np.array([w.mean for w in turns]),
        rate=np.array([w.rate for w in turns]),
        motor=np.array([w.window.motor for w in turns]),
        direction=np.array([w.window.direction for w in turns]),
        count=np.array([w.count for w in turns]),
        noise=noise,
        mean_std=mean_std * np.sqrt(tau),
        rate_std=np.array([w.rate_std for w in turns]),
        **_nod_fields(turns, tau),
        temperature_c=t_mean,
        chain=chain,
        pose=pose,
        pose_still=pose_still,
        **rest_kw,  # type: ignore[arg-type]
        **ref_kw,  # type: ignore[arg-type]
    )


def _nod_fields(turns: Sequence[_Turn], tau: np.ndarray) -> dict[str, np.ndarray]:
    """The windows' once-per-revolution parts (:attr:`ObservationSet.nod`), their standard
    errors with the correlation factor of the rests' noise (as ``mean_std``); none when a
    window could not be measured (too few samples)."""
    std = np.array([w.nod_std for w in turns]) * np.sqrt(tau)[None, None, :]
    if not np.all(np.isfinite(std) & (std > 0)):
        return {}
    return {"nod": np.array([w.nod for w in turns]), "nod_std": std}


def _turn_phase(turns: Sequence[_Turn], tracks: EncoderTracks, chain: tuple[int, ...],
                pose: np.ndarray) -> np.ndarray:
    """Per window, the weighted means of ``cos φ`` and ``sin φ`` with ``φ`` the turning servo's
    angle less its pose angle (:attr:`ObservationSet.turn_phase`), with the window's weight."""
    out = np.zeros((len(turns), 2))
    for i, w in enumerate(turns):
        t, th = tracks.track[int(w.window.motor)]  # type: ignore[arg-type]
        phi = th - pose[i, chain.index(int(w.window.motor))]  # type: ignore[arg-type]
        out[i], _, _ = _weighted_mean(t, np.column_stack([np.cos(phi), np.sin(phi)]),
                                      w.window.corners)
    return out


def window_temperatures(t: np.ndarray, temp: np.ndarray, windows: Sequence[Window]
                        ) -> np.ndarray:
    """Mean die temperature (°C) over each window's span, from the IMU stream's times ``t``
    and die temperatures ``temp`` (NaN where no sample has one)."""
    out = np.full(len(windows), np.nan)
    for i, w in enumerate(windows):
        a, b = np.searchsorted(t, [w.corners[0], w.corners[3]], side="left")
        x = temp[a:b]
        x = x[np.isfinite(x)]
        if x.size:
            out[i] = float(x.mean())
    return out


def extract_observations(
    imu_t: np.ndarray,
    imu_rate: np.ndarray,
    enc_t: np.ndarray,
    enc_motor: np.ndarray,
    enc_angle: np.ndarray,
    segments: Sequence[Segment],
    *,
    imu_temp: np.ndarray | None = None,
    encoder_ticks: int = 4096,
    steady_tolerance: float = 0.15,
    still_margin_s: float = 0.15,
    rest_guard_s: float = 0.2,
    refit_time: bool = True,
    window: str = "auto",
    chain: Sequence[int] | None = None,
    still_angle_std: float | None = None,
) -> ExtractedWindows:
    """Turn a calibration run's raw streams into observations (DESIGN.md fact 2).

    Stages, each its own function: (1) check the streams and refit the gyro's time axis;
    (2) the encoder tracks, each servo's motion intervals and still periods
    (:class:`EncoderTracks`); (3) one window per turn (:func:`_turn_window`: the turn's motion and
    steady span, the candidate windows, the least predicted variance); (4) one window per rest,
    clear of turns and pose moves; (5) the turning axis's noise pooled from where the servo cannot
    reach it; (6) the observation set. Segments of kind ``move`` are never windowed as turns, and
    no rest window spans one.

    Parameters
    ----------
    imu_t : ndarray, shape (N,)
        Gyro sample times on the recording clock, increasing.
    imu_rate : ndarray, shape (N, 3)
        Gyro readings, rad/s (datasheet sensitivity only).
    enc_t, enc_motor, enc_angle : ndarray, shape (M,)
        Encoder readings: time, servo ID, cumulative angle in rad.
    segments : sequence of Segment
        The protocol's rotate, rest and move segments.
    imu_temp : ndarray, shape (N,), optional
        Die temperature, °C (NaN where absent).
    encoder_ticks : int
        Encoder counts per revolution (4096 for Dynamixel X).
    steady_tolerance : float
        The steady part of a turn runs from the first to the last encoder reading whose smoothed
        speed is above ``1 - steady_tolerance`` times the plateau (the median speed while
        moving).
    still_margin_s : float
        Longest still time taken on each side of a rest-to-rest window (the still angle is
        constant, so a short margin suffices; rest windows exclude it, so no sample is used
        twice).
    rest_guard_s : float
        Settling time skipped at each end of a rest.
    refit_time : bool
        Refit the gyro's time axis over the whole stream first (:mod:`gyrocal.calib.timebase`): a
        reader's early timestamps rest on a young estimate of the chip's period.
    window : str
        ``"auto"`` (the candidate with the least predicted variance), ``"tapered"`` or
        ``"rest-to-rest"`` (that kind where the turn allows it, else whatever it allows).
    chain : sequence of int, optional
        The gimbal's servo IDs, base first. When given, each window's pose (every chain servo's
        mean encoder angle over the window) goes into the observations, for the full model.
    still_angle_std : float, optional
        Prior standard deviation of a still angle, rad; default the encoder's quantisation
        ``q/√12``. A hand jig's reference angles are a stop's, read to its repeatability
        (:mod:`gyrocal.calib.hand`).

    Returns
    -------
    ExtractedWindows

    Raises
    ------
    CalibInputError
        On malformed arrays, a servo without encoder data, a turn the gyro stream does not cover
        (a truncated recording), a turn in the wrong direction, or a turn too short to window.
    """
    if window not in ("auto", "tapered", "rest-to-rest"):
        raise CalibInputError(
            f"window must be 'auto', 'tapered' or 'rest-to-rest', got {window!r}")
    imu_t, imu_rate, enc_t, enc_motor, enc_angle, temp = _check_streams(
        imu_t, imu_rate, enc_t, enc_motor, enc_angle, imu_temp)
    timebase = None
    if refit_time:
        imu_t, timebase = refit_sample_times(imu_t)
    q = TWO_PI / int(encoder_ticks)
    dt_med = float(np.median(np.diff(imu_t)))
    warnings: list[str] = []
    tracks = EncoderTracks(enc_t, enc_motor, enc_angle, q)

    turns: list[_Turn] = []
    rot_segments = [s for s in segments if s.kind == "rotate"]
    for k_seg, seg in enumerate(rot_segments):
        # Neighbouring time for still margins: up to the previous/next rotation of any servo.
        prev_end = max([s.t_end for s in rot_segments[:k_seg]], default=-np.inf)
        next_start = min([s.t_start for s in rot_segments[k_seg + 1:]], default=np.inf)
        turn = _turn_window(
            seg, tracks, imu_t, imu_rate, max(prev_end, seg.t_start - 10.0),
            min(next_start, seg.t_end + 10.0), dt_med, steady_tolerance=steady_tolerance,
            still_margin_s=still_margin_s, window=window)
        if turn is None:
            warnings.append(
                f"segment {seg.index}: gap in the gyro stream inside the window; turn skipped")
        else:
            turns.append(turn)
    rest_windows, rest_samples = _rest_windows(
        segments, turns, tracks, imu_t, imu_rate, dt_med, rest_guard_s, warnings)
    tau = correlation_factor(rest_samples)
    if not turns:
        raise CalibInputError("no rotation windows: the recording has no usable turns")
    noise, mean_std = _turning_axis_noise(turns, rest_samples)
    pose = pose_still = None
    chain_t = None if chain is None else tuple(int(c) for c in chain)
    if chain_t is not None:
        got = [tracks.pose(chain_t, w.window.corners[0], w.window.corners[3]) for w in turns]
        pose = np.array([g[0] for g in got])
        pose_still = np.array([g[1] for g in got])
        for i, w in enumerate(turns):  # the turning servo's own angle does not carry its axis
            pose_still[i, chain_t.index(int(w.window.motor))] = -1  # type: ignore[arg-type]
    obs = _assemble(turns, noise, mean_std, rest_windows, rest_samples, tau, temp, q, chain_t,
                    pose, pose_still, still_angle_std)
    if chain_t is not None:  # where gravity points in each rest, and the home pose
        rest_pose = np.array([tracks.pose(chain_t, w.corners[0], w.corners[3])[0]
                              for w in rest_windows]).reshape(len(rest_windows), len(chain_t))
        home = np.array([tracks.track[m][1][0] for m in chain_t])
        obs = replace(obs, rest_pose=rest_pose, home_pose=home,
                      turn_phase=_turn_phase(turns, tracks, chain_t, pose))  # type: ignore[arg-type]
    if temp is not None:  # a die that warmed during the run: refer the windows to its mean
        obs, note = correct_drift(obs, window_temperatures(imu_t, temp, [w.window for w in turns]),
                                  window_temperatures(imu_t, temp, rest_windows))
        if note is not None:
            warnings.append(note)
    return ExtractedWindows(
        observations=obs,
        windows=tuple(w.window for w in turns),
        rests=tuple(rest_windows),
        warnings=tuple(warnings),
        noise_correlation=tau,
        timebase=timebase,
    )
