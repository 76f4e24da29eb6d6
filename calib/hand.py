r"""Hand rotations (a Ferraris-style jig): rests and whole turns found in the gyro's own data.

The sensor sits on a box with square faces. The user lays it on a face against a stop (a
straight edge or a block on the table), waits, turns it by hand one whole turn about the vertical
back against the stop, and waits again; once about each box axis, and back the other way. No
encoder times the turn, but the paper's per-revolution averaging carries over: over a window
from rest to rest that holds one whole turn, whatever the speed profile,

.. math:: \int_{a}^{b} ω\,dt = 2π\,u \qquad\Rightarrow\qquad
          \bar ω = \frac{2π}{b - a}\,u ,

so the window's mean rate is known from its duration alone (``u`` the box axis the turn is
about). This module finds the rests (:func:`gyrocal.calib.stationarity.detect_still`, the
still detector the bias tracker uses) and, between two rests, the motions; a motion whose
integrated rotation is within ``turn_tolerance`` of a whole number of turns about one sensor
axis is a turn, any other (laying the box on another face) a move. It then writes what a servo
jig's encoder would have recorded (:func:`reference_tracks`): each box axis a virtual servo
whose angle is constant at each rest and steps by exactly ``±2π n`` across each of its turns,
so that :func:`gyrocal.calib.windows.extract_observations` windows the turns from rest to rest
(the angle inside a turn is never read: ``window="rest-to-rest"``) and the same estimators,
σ, verdict and exports follow. The stop's repeatability is the still angle's prior
(``stop_std_rad``): windows that share a rest share its error, as the encoder's still angles do.

What the hand jig cannot determine (``gyrocal.kit.jig_kinds``, row ``hand``): the turns' axes
are the box's, placed by hand against a stop, so nothing measures them, and a hand does not hold
an axis from one turn to the next (it wobbles). The paired-axis fit takes each turn's axis as a
free unit vector of its own (:attr:`ObservationSet.own_axes`), which absorbs the cross-axis
terms exactly as the gimbal's six home-pose turns do (DESIGN.md fact 5): the result is the
diagonal model (Calibration v1), with the reason, and the bias comes from the rests.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np

from gyrocal.calib.errors import CalibInputError
from gyrocal.calib.segments import Segment
from gyrocal.calib.stationarity import StillSettings, detect_still, white_noise_std
from gyrocal.calib.timebase import refit_sample_times
from gyrocal.calib.windows import ExtractedWindows, extract_observations

__all__ = [
    "AXIS_MOTORS",
    "MOVE_MOTOR",
    "STOP_STD_RAD",
    "HandSettings",
    "HandTurn",
    "HandTurns",
    "find_hand_turns",
    "hand_observations",
    "reference_tracks",
    "rest_g_sensitivity",
]

TWO_PI = 2.0 * np.pi
#: The virtual servo IDs of turns about the sensor's x, y and z axes (one per box axis).
AXIS_MOTORS = (1, 2, 3)
#: The virtual servo that moves while the box is laid on another face (never windowed).
MOVE_MOTOR = 0
#: Repeatability of bringing a box face back against a stop by hand, rad (0.1°: a firm edge
#: and a face of a few centimetres; hardware_docs/hand-jig.md). Over one turn of ``T`` s it is
#: a reference error of ``0.1° / 360° = 2.8e-4`` of the rate.
STOP_STD_RAD = float(np.radians(0.1))
#: The largest motion taken as a step of a turn made in steps, rad (135°: a quarter or a third
#: of a turn is a step, a half-turn flip to the opposite face is not).
_PART_MAX_RAD = float(np.radians(135.0))
#: Encoder counts per turn of the virtual servos (a Dynamixel X's, so the window code's tick
#: thresholds keep their meaning); the virtual angle is exact, its prior is ``stop_std_rad``.
_TICKS = 4096
_Q = TWO_PI / _TICKS


@dataclass(frozen=True)
class HandSettings:
    """Tuning of :func:`find_hand_turns`.

    Attributes
    ----------
    min_rest_s : float
        Shortest still span taken as a rest, s.
    turn_tolerance : float
        A motion is a turn when its integrated rotation is within this fraction of a whole
        number of turns (the gyro's scale error is a few percent; a re-seat is a quarter or
        half turn).
    axis_fraction : float
        ... and its rotation vector lies this close to one sensor axis (cosine; 0.9 is 26°).
    still : StillSettings or None
        The still detector's settings (its defaults when None).
    rate_limit : float
        The first pass's rate threshold, rad/s: above the largest zero-rate tolerance of the
        chips gyrocal reads (the LSM9DS1's ±30 °/s, 0.52 rad/s: ``drivers/imu/chips.py``),
        since the bias is unknown until the first rests are found (DESIGN.md fact 8: the
        detector does not rest on an estimate it feeds). The first pass only sets the median
        reading the second pass's rate test is centred on; its variance test rejects a hand's
        motion, which is never steady.
    """

    min_rest_s: float = 1.0
    turn_tolerance: float = 0.2
    axis_fraction: float = 0.9
    still: StillSettings | None = None
    rate_limit: float = 1.0


@dataclass(frozen=True)
class HandTurn:
    """One whole turn between two rests.

    Attributes
    ----------
    axis : int
        The sensor axis it is about (0, 1, 2 for x, y, z).
    direction : int
        +1 or -1 (the sign of the integrated rotation about that axis).
    revolutions : int
    t_start, t_end : float
        The last still sample before it and the first after it, s.
    angle : tuple of 3 float
        The integrated, bias-corrected, uncalibrated rotation vector, rad.
    """

    axis: int
    direction: int
    revolutions: int
    t_start: float
    t_end: float
    angle: tuple[float, float, float]


@dataclass(frozen=True, eq=False)
class HandTurns:
    """What :func:`find_hand_turns` found.

    Attributes
    ----------
    t : ndarray (N,)
        The sample times it worked on (refitted, :mod:`gyrocal.calib.timebase`).
    rests : tuple of (float, float)
        Still spans, first and last still sample, s.
    turns : tuple of HandTurn
    moves : tuple of (float, float, float)
        The other motions: start, end and integrated angle (rad).
    bias : ndarray (3,)
        The bias (Calibration v1 sign) the rate test used: minus the rests' median reading.
    noise : ndarray (3,)
        Per-sample white noise, rad/s.
    g_sensitivity : ndarray (3, 3) or None
        ``G`` of :func:`rest_g_sensitivity` where :func:`hand_observations` took it off.
    """

    t: np.ndarray
    rests: tuple[tuple[float, float], ...]
    turns: tuple[HandTurn, ...]
    moves: tuple[tuple[float, float, float], ...]
    bias: np.ndarray
    noise: np.ndarray
    g_sensitivity: np.ndarray | None = None


def _still(rate: np.ndarray, noise: np.ndarray, fs: float, s: HandSettings) -> tuple[
        np.ndarray, np.ndarray]:
    """Still flags in two passes: a loose rate limit to find the rests, then the detector's own
    rate test about minus their median reading."""
    base = s.still or StillSettings()
    loose = replace(base, rate_threshold=s.rate_limit)
    first = detect_still(rate, noise, fs, settings=loose)
    if not first.any():
        raise CalibInputError("no rest found in the recording: hold the sensor still on a face "
                              "for a few seconds before and after each turn")
    bias = -np.median(rate[first], axis=0)
    return detect_still(rate, noise, fs, reference_bias=bias, settings=base), bias


def _spans(flags: np.ndarray, t: np.ndarray, min_s: float) -> list[tuple[int, int]]:
    """Runs of True as inclusive sample ranges at least ``min_s`` long."""
    d = np.diff(np.r_[0, flags.astype(np.int8), 0])
    out = []
    for lo, hi in zip(np.flatnonzero(d == 1), np.flatnonzero(d == -1) - 1, strict=True):
        if t[hi] - t[lo] >= min_s:
            out.append((int(lo), int(hi)))
    return out


def _integral(t: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Trapezoidal ``∫ x dt`` over the samples, per column."""
    return np.sum(np.diff(t)[:, None] * (x[1:] + x[:-1]) / 2.0, axis=0)


def _classify(t: np.ndarray, rate: np.ndarray, bias: np.ndarray, lo: int, hi: int,
              s: HandSettings) -> HandTurn | None:
    """The motion from sample ``lo`` (still) to ``hi`` (still) as a turn, or None."""
    angle = _integral(t[lo:hi + 1], rate[lo:hi + 1] + bias)
    size = float(np.linalg.norm(angle))
    n = int(round(size / TWO_PI))
    axis = int(np.argmax(np.abs(angle)))
    if n < 1 or abs(size - n * TWO_PI) > s.turn_tolerance * n * TWO_PI:
        return None
    if abs(angle[axis]) < s.axis_fraction * size:
        return None
    return HandTurn(axis, int(np.sign(angle[axis])), n, float(t[lo]), float(t[hi]),
                    tuple(float(v) for v in angle))  # type: ignore[arg-type]


def find_hand_turns(t: np.ndarray, rate: np.ndarray,
                    settings: HandSettings | None = None) -> HandTurns:
    """Find the rests and the whole turns of a hand-rotation recording.

    Parameters
    ----------
    t : ndarray (N,)
        Sample times, s, increasing.
    rate : ndarray (N, 3)
        Gyro readings, rad/s (datasheet sensitivity only).
    settings : HandSettings, optional

    Returns
    -------
    HandTurns

    Raises
    ------
    CalibInputError
        Malformed arrays, or no rest at all.
    """
    s = settings or HandSettings()
    t = np.asarray(t, dtype=float)
    rate = np.asarray(rate, dtype=float)
    if t.ndim != 1 or rate.shape != (t.size, 3) or t.size < 10:
        raise CalibInputError(f"t must be (N,) and rate (N, 3) with N >= 10; got {t.shape} and "
                              f"{rate.shape}")
    if not (np.all(np.isfinite(t)) and np.all(np.isfinite(rate))) or np.any(np.diff(t) <= 0):
        raise CalibInputError("t and rate must be finite and t strictly increasing")
    t, _ = refit_sample_times(t)
    fs = float(1.0 / np.median(np.diff(t)))
    noise = white_noise_std(rate)
    still, bias = _still(rate, noise, fs, s)
    rests = _spans(still, t, s.min_rest_s)
    if rests:
        bias = -np.mean(np.concatenate([rate[a:b + 1] for a, b in rests]), axis=0)
    turns, moves = _turns_and_moves(t, rate, bias, rests, s)
    return HandTurns(t, tuple((float(t[a]), float(t[b])) for a, b in rests), tuple(turns),
                     tuple(moves), bias, noise)


def _part_key(angle: np.ndarray, s: HandSettings) -> tuple[int, int] | None:
    """``(axis, sign)`` of a motion that may be part of a turn made in steps (under
    :data:`_PART_MAX_RAD`, about one sensor axis), else None."""
    size = float(np.linalg.norm(angle))
    axis = int(np.argmax(np.abs(angle)))
    if not 0 < size < _PART_MAX_RAD or abs(angle[axis]) < s.axis_fraction * size:
        return None
    return axis, int(np.sign(angle[axis]))


def _turns_and_moves(t: np.ndarray, rate: np.ndarray, bias: np.ndarray,
                     rests: Sequence[tuple[int, int]], s: HandSettings
                     ) -> tuple[list[HandTurn], list[tuple[float, float, float]]]:
    """Each motion between two rests is a whole turn (:func:`_classify`) or a move; consecutive
    parts about one axis in one sense, each under :data:`_PART_MAX_RAD`, whose sum reaches a
    whole turn make one turn from the rest before the first to the rest after the last (a turn
    made in steps, as imucal's example session describes its operator's quarter turns)."""
    turns: list[HandTurn] = []
    moves: list[tuple[float, float, float]] = []
    pending: list[tuple[int, int, np.ndarray]] = []  # parts: start, end sample, angle

    def flush() -> None:
        for lo, hi, ang in pending:
            moves.append((float(t[lo]), float(t[hi]), float(np.linalg.norm(ang))))
        pending.clear()

    for (_, a1), (b0, _) in zip(rests[:-1], rests[1:], strict=True):
        turn = _classify(t, rate, bias, a1, b0, s)
        if turn is not None:
            flush()
            turns.append(turn)
            continue
        angle = _integral(t[a1:b0 + 1], rate[a1:b0 + 1] + bias)
        key = _part_key(angle, s)
        if key is None or (pending and _part_key(pending[0][2], s) != key):
            flush()
        if key is None:
            moves.append((float(t[a1]), float(t[b0]), float(np.linalg.norm(angle))))
            continue
        pending.append((a1, b0, angle))
        merged = _classify(t, rate, bias, pending[0][0], b0, s)
        if merged is not None:
            turns.append(merged)
            pending.clear()
    flush()
    return turns, moves


def reference_tracks(found: HandTurns) -> tuple[tuple[Segment, ...], np.ndarray, np.ndarray,
                                                 np.ndarray]:
    """The segments and virtual encoder tracks of the turns (module docstring).

    Each box axis is a virtual servo (:data:`AXIS_MOTORS`), :data:`MOVE_MOTOR` the re-seats and
    the motion before the first rest and after the last. A servo's angle is constant outside its
    own motions and steps by its motion's angle across each (``±2π n`` for a turn), with readings
    at every sample time outside the motions and at least ten ticks apart inside them.

    Returns
    -------
    segments : tuple of Segment
        ``rest`` and ``rotate`` segments, plus a ``move`` segment per re-seat, in time order.
    enc_t, enc_motor, enc_angle : ndarray
        The virtual encoder readings (Recording v1 ``encoder.csv`` columns).
    """
    t = found.t
    motions: list[tuple[float, float, int, float]] = []  # start, end, motor, angle change
    for turn in found.turns:
        motions.append((turn.t_start, turn.t_end, AXIS_MOTORS[turn.axis],
                        turn.direction * turn.revolutions * TWO_PI))
    for m0, m1, ang in found.moves:
        motions.append((m0, m1, MOVE_MOTOR, max(ang, 20 * _Q)))
    if found.rests:
        first, last = found.rests[0][0], found.rests[-1][1]
        for m0, m1 in ((float(t[0]), first), (last, float(t[-1]))):
            if m1 - m0 > 0:
                motions.append((m0, m1, MOVE_MOTOR, 20 * _Q))
    motions.sort()
    inside = np.zeros(t.size, dtype=bool)
    for m0, m1, _, _ in motions:
        inside |= (t > m0) & (t < m1)
    base_t = t[~inside]
    ts, ms, ys = [], [], []
    for motor in (MOVE_MOTOR, *AXIS_MOTORS):
        own = [(m0, m1, d) for m0, m1, mm, d in motions if mm == motor]
        knots_t, knots_y = [float(t[0])], [0.0]
        level = 0.0
        for m0, m1, d in own:
            knots_t += [m0, m1]
            knots_y += [level, level + d]
            level += d
        knots_t.append(float(t[-1]) + 1.0)
        knots_y.append(level)
        extra = [np.linspace(m0, m1, max(8, int(abs(d) / (10 * _Q))))[1:-1] for m0, m1, d in own]
        tt = np.unique(np.concatenate([base_t, *extra])) if extra else base_t
        ts.append(tt)
        ms.append(np.full(tt.size, motor))
        ys.append(np.interp(tt, knots_t, knots_y))
    segments: list[Segment] = []
    events = [(a, "rest", None, 0, 0.0, b) for a, b in found.rests]
    events += [(m0, "rotate" if mm != MOVE_MOTOR else "move", mm, int(np.sign(d)),
                abs(d) / (m1 - m0), m1) for m0, m1, mm, d in motions]
    events.sort(key=lambda e: (e[0], e[5]))
    for i, (a, kind, motor, d, speed, b) in enumerate(events):
        segments.append(Segment(i, kind, motor, d, float(speed), float(a), float(b)))
    return (tuple(segments), np.concatenate(ts), np.concatenate(ms).astype(np.int64),
            np.concatenate(ys))


def rest_g_sensitivity(t: np.ndarray, rate: np.ndarray, accel: np.ndarray,
                       rests: Sequence[tuple[float, float]]) -> np.ndarray | None:
    """The gyro's g-sensitivity ``G`` ((rad/s) per (m/s²)) from the rests on several faces:
    each rest's mean reading is ``c + G ā`` (``ā`` its mean specific force), fitted by least
    squares (imucal's Eq. 9, ``K_ga = (U_p − U_a) / 2g`` from the ± faces, generalised to any
    rests). None when the rests' specific forces do not span three directions (fewer than
    four rests, or all within 30° of a plane).

    A box turned about its vertical axis holds one face up for the whole turn, so ``G ā`` is a
    constant offset of that turn's window (the MPU-9250 allows 0.1 °/s/g, 1.7e-3 rad/s: 1e-3 of
    a 1.7 rad/s turn), which the bias from rests on all six faces does not carry.
    """
    m, a = [], []
    for lo, hi in rests:
        sel = (t >= lo) & (t <= hi)
        m.append(rate[sel].mean(axis=0))
        a.append(accel[sel].mean(axis=0))
    if len(m) < 4:
        return None
    A = np.column_stack([np.ones(len(a)), np.array(a)])
    sv = np.linalg.svd(A[:, 1:] / np.linalg.norm(A[:, 1:], axis=1, keepdims=True),
                       compute_uv=False)
    if sv[-1] < 0.5 * np.sqrt(len(a) / 3.0):  # directions within about 30° of a plane
        return None
    coef = np.linalg.lstsq(A, np.array(m), rcond=None)[0]
    return coef[1:].T


def hand_observations(t: np.ndarray, rate: np.ndarray, *, imu_temp: np.ndarray | None = None,
                      accel: np.ndarray | None = None, stop_std_rad: float = STOP_STD_RAD,
                      settings: HandSettings | None = None) -> tuple[ExtractedWindows, HandTurns]:
    """The observations of a hand-rotation recording: :func:`find_hand_turns`, then
    :func:`reference_tracks` through :func:`gyrocal.calib.windows.extract_observations` with
    rest-to-rest windows only and the stop's repeatability as the still angles' prior.

    With the accelerometer, the g-sensitivity the rests show (:func:`rest_g_sensitivity`) is
    taken off the readings first (``m − G a``): each turn is then read as in free fall, and the
    bias is the zero-g bias, the mean over opposite faces (imucal's ``b_g`` over its six);
    :attr:`HandTurns.g_sensitivity` holds ``G``. Calibration v1 has no term for it.

    Parameters
    ----------
    t, rate : ndarray
        Sample times (s) and gyro readings (rad/s, datasheet sensitivity only).
    imu_temp : ndarray (N,), optional
        Die temperature, °C.
    accel : ndarray (N, 3), optional
        The accelerometer's specific force, m/s², of the same samples.
    stop_std_rad : float
        Repeatability of a face brought back against the stop, rad (:data:`STOP_STD_RAD`).
    settings : HandSettings, optional

    Returns
    -------
    ExtractedWindows, HandTurns

    Raises
    ------
    CalibInputError
        No rest, or no whole turn between two rests.
    """
    if not stop_std_rad > 0:
        raise CalibInputError(f"stop_std_rad must be positive, got {stop_std_rad!r}")
    found = find_hand_turns(t, rate, settings)
    if accel is not None:
        acc = np.asarray(accel, dtype=float)
        if acc.shape != np.shape(rate) or not np.all(np.isfinite(acc)):
            raise CalibInputError(f"accel must be finite with the shape of rate "
                                  f"{np.shape(rate)}, got {acc.shape}")
        G = rest_g_sensitivity(found.t, np.asarray(rate, dtype=float), acc, found.rests)
        if G is not None:
            rate = np.asarray(rate, dtype=float) - acc @ G.T
            found = replace(found, g_sensitivity=G)
    if not found.turns:
        raise CalibInputError(
            f"no whole turn between two rests among {len(found.moves)} motions "
            f"({len(found.rests)} rests found): turn the box one whole turn about a vertical "
            "box axis, from rest against the stop back to rest against it")
    segments, enc_t, enc_motor, enc_angle = reference_tracks(found)
    ex = extract_observations(found.t, rate, enc_t, enc_motor, enc_angle, segments,
                              imu_temp=imu_temp, encoder_ticks=_TICKS, refit_time=False,
                              window="rest-to-rest", still_angle_std=stop_std_rad)
    return replace(ex, observations=replace(ex.observations, own_axes=True)), found
