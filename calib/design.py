r"""Experimental design: the paper's G-optimal six-point design, design scores, and a planner.

The paper (Section II-B) chooses the six observations ``±x, ±y, ±z`` so as to minimise the maximum
variance of the model's prediction over the design region, the sphere ``|m| = ω``. For the
squared-norm model Eq. (5) with ``β0`` tied to the other parameters, the regressors of a reading
``m`` are ``f(m) = (m_x², m_y², m_z², m_x, m_y, m_z)`` and the standardised prediction variance of
an ``n``-point design with matrix ``F`` (rows ``f(m_i)``) is

.. math:: d(m) = n\, f(m)^T (F^T F)^{-1} f(m).

By the Kiefer-Wolfowitz theorem ``max d >= p`` (here ``p = 6``), with equality for a G-optimal
design; the six-point design reaches it (``d(m) = 3 + 3 Σ m_j⁴/ω⁴``, largest on the axes).

The planner goes beyond the paper's fixed protocol: for a given servo top speed, gyro full-scale
range, noise and time budget it chooses speed, whole turns per direction and rest length so that
the worst-direction standard deviation of a calibrated rate at a reference rate (the same
G-criterion, now in rad/s and for our paired-axis estimator with its rests) is smallest.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from gyrocal.calib.errors import CalibInputError
from gyrocal.calib.model import ModelChoice
from gyrocal.calib.simulate import profile_duration

__all__ = [
    "AUTO_TIME_BUDGET_S",
    "SEATS",
    "SEAT_HANDLING_S",
    "SEAT_SETS",
    "FULL_TIME_BUDGET_S",
    "MIN_REST_S",
    "PAPER_DESIGN",
    "DesignScore",
    "Plan",
    "candidate_pose_sets",
    "full_schedule",
    "gravity_poses",
    "general_motion_rms",
    "choose_model",
    "cross_axis_general_motion_rms",
    "paper_plan",
    "plan_accel_rests",
    "plan_protocol",
    "plan_seats",
    "seat_axes",
    "protocol_sequence",
    "predict_full_uncertainty",
    "predicted_general_motion_rms",
    "predict_uncertainty",
    "score_design",
    "score_full_design",
    "sphere_points",
]

#: The paper's six-point G-optimal design (rows: ±x, ±y, ±z on the unit sphere).
PAPER_DESIGN = np.array(
    [[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]], dtype=float
)


def sphere_points(n: int = 2000) -> np.ndarray:
    """``n`` nearly uniform unit vectors (Fibonacci lattice), shape ``(n, 3)``."""
    i = np.arange(n) + 0.5
    phi = np.arccos(1 - 2 * i / n)
    theta = np.pi * (1 + 5**0.5) * i
    return np.column_stack([np.cos(theta) * np.sin(phi), np.sin(theta) * np.sin(phi), np.cos(phi)])


def _regressors(m: np.ndarray) -> np.ndarray:
    return np.concatenate([m**2, m], axis=-1)


@dataclass(frozen=True)
class DesignScore:
    """Score of a design on the sphere (paper Section II-B).

    Attributes
    ----------
    max_variance : float
        Largest standardised prediction variance ``max d(m)`` over the sphere.
    argmax : tuple of 3 float
        Where it is reached (unit vector).
    g_efficiency : float
        ``p / max d``: 1 for a G-optimal design, smaller is worse; 0 for a singular design.
    d_criterion : float
        ``det(FᵀF/n)^(1/p)`` (larger is better).
    model : str
        ``"paper"`` (the squared-norm model of Eq. (5), :func:`score_design`) or ``"full"``
        (``g = A (m + b)`` on the gimbal, :func:`score_full_design`).
    parameter_std : tuple of 12 float, optional
        Full model: predicted one-sigma uncertainty of ``A`` (row-major, 0 for the three
        elements the frame fixes) and ``b``, rad/s for ``b``.
    information : ndarray, shape (12, 12), optional
        Full model: the Fisher information of ``(A, b)`` with the servo axes eliminated (the
        pseudo-inverse of their covariance; zero rows for the fixed elements).
    rate_error_std : float, optional
        Full model: the largest standard deviation of a calibrated rate component over the
        sphere of ``radius``, rad/s (what :func:`plan_protocol` minimises).
    """

    max_variance: float
    argmax: tuple[float, float, float]
    g_efficiency: float
    d_criterion: float
    model: str = "paper"
    parameter_std: tuple[float, ...] | None = None
    information: np.ndarray | None = None
    rate_error_std: float | None = None


def score_design(points: np.ndarray, radius: float = 1.0, n_search: int = 4000) -> DesignScore:
    """Maximum prediction variance of a design over the sphere of ``radius`` (G-criterion).

    Parameters
    ----------
    points : array_like, shape (n, 3)
        The design's readings (directions are scaled to ``radius``; a zero row is refused).
    radius : float
        Rotation rate of the design region, rad/s.
    n_search : int
        Lattice points searched before local refinement.

    Returns
    -------
    DesignScore
    """
    P = np.asarray(points, dtype=float)
    if P.ndim != 2 or P.shape[1] != 3 or P.shape[0] < 1:
        raise CalibInputError(f"points must have shape (n, 3), got {P.shape}")
    norms = np.linalg.norm(P, axis=1)
    if np.any(norms == 0) or not np.all(np.isfinite(P)):
        raise CalibInputError("design points must be finite and non-zero")
    if not radius > 0:
        raise CalibInputError(f"radius must be positive, got {radius!r}")
    P = P / norms[:, None] * radius
    n, p = P.shape[0], 6
    F = _regressors(P)
    M = F.T @ F
    if np.linalg.matrix_rank(M) < p:
        return DesignScore(np.inf, (np.nan, np.nan, np.nan), 0.0, 0.0)
    Minv = np.linalg.inv(M)

    def d(u: np.ndarray) -> float:
        u = radius * u / np.linalg.norm(u)
        f = _regressors(u)
        return float(n * f @ Minv @ f)

    S = sphere_points(n_search)
    fs = _regressors(radius * S)
    vals = n * np.einsum("ij,jk,ik->i", fs, Minv, fs)
    best = np.argsort(vals)[-5:]
    top, arg = -np.inf, S[best[-1]]
    for i in best:
        from scipy import optimize  # imported where a search needs it (seconds on a Pi)

        res = optimize.minimize(lambda u: -d(u), S[i], method="Nelder-Mead",
                                options={"xatol": 1e-10, "fatol": 1e-12})
        if -res.fun > top:
            top, arg = -res.fun, res.x / np.linalg.norm(res.x)
    det = float(np.linalg.det(M / n))
    return DesignScore(
        max_variance=float(top),
        argmax=(float(arg[0]), float(arg[1]), float(arg[2])),
        g_efficiency=p / float(top),
        d_criterion=max(det, 0.0) ** (1 / p),
    )


# ---------------------------------------------------------------------------------- planning
@dataclass(frozen=True)
class Plan:
    """A calibration protocol: each servo turns ``turns`` revolutions one way, then back.

    Attributes
    ----------
    speed : float
        Commanded speed, rad/s.
    turns : int
        Whole revolutions per direction.
    rest_s : float
        Rest before each turn and after the last, s.
    accel : float
        Profile acceleration assumed, rad/s².
    jig_time_s : float
        Total time the jig moves and rests.
    scale_std, bias_std : tuple of 3 float
        Predicted one-sigma uncertainties (paired-axis estimator).
    rate_error_std : float
        Predicted worst-direction standard deviation of a calibrated rate at ``reference_rate``,
        rad/s (the planner's objective). For a full-model plan with gravity rests, of
        ``A (m + b + G f)`` with g-sensitivity fitted, worst also over a 1 g specific force
        (:func:`predict_full_uncertainty` with ``gravity``), as are ``matrix_std`` and
        ``bias_std`` (the zero-g bias); the plan is chosen on ``A (m + b)``.
    reference_rate : float
        rad/s.
    poses : tuple of (int, int, float)
        The full model's posed pairs of turns, after the home-pose turns: ``(turning servo,
        moved servo, angle)``, servos as chain positions (base = 0), the angle in rad from home.
        Each pair: move the servo to the angle, turn the other both ways, move it back. Empty
        for the diagonal model.
    matrix_std : tuple of 3 tuples of 3 float, or None
        Predicted one-sigma uncertainty of the full model's matrix (None for the diagonal one).
    gravity_poses : tuple of (int, float)
        Rests for the full model's g-sensitivity, after the posed pairs: ``(moved servo,
        angle)``: move the servo (chain position) to the angle, rest, move it back
        (:func:`gravity_poses`).
    accel_moves : tuple of (int, int, float)
        Moves that tilt the protocol's rests for the accelerometer (:func:`plan_accel_rests`):
        ``(rest number, moved servo, angle)``: before the protocol's rest of that number
        (0-based, in :func:`protocol_sequence` order), move the servo (chain position) to the
        angle from home. The run ends with every servo moved home. Empty: no accelerometer rests.
    accel_extra_rests : int
        Rests added at the end of the protocol for the accelerometer, when the gyro protocol
        has fewer than :data:`ACCEL_MIN_RESTS` (its moves tilt them like the others).
    accel_time_s : float
        Jig time the accelerometer's moves and extra rests add (included in ``jig_time_s``), s.
    accel_std_ratio : float or None
        Predicted worst-direction σ of the calibrated specific force's magnitude over the σ of
        one rest window's mean per axis (:attr:`gyrocal.calib.accel.AccelDesign.worst_force_std`
        at ``window_std = 1``); None without accelerometer rests.
    seats : tuple of str
        Single-servo jig only (:func:`plan_seats`): the cube's seats in running order
        (:data:`SEATS` names); per seat the user re-seats the cube, then rest, turn −, rest,
        turn +, and a rest. Empty on the gimbal.
    """

    speed: float
    turns: int
    rest_s: float
    accel: float
    jig_time_s: float
    scale_std: tuple[float, float, float]
    bias_std: tuple[float, float, float]
    rate_error_std: float
    reference_rate: float
    poses: tuple[tuple[int, int, float], ...] = ()
    matrix_std: tuple[tuple[float, ...], ...] | None = None
    gravity_poses: tuple[tuple[int, float], ...] = ()
    accel_moves: tuple[tuple[int, int, float], ...] = ()
    accel_extra_rests: int = 0
    accel_time_s: float = 0.0
    accel_std_ratio: float | None = None
    seats: tuple[str, ...] = ()

    @property
    def model(self) -> str:
        """``"full"`` when the plan has posed turns (or, on the single-servo jig, seats that
        determine the matrix), else ``"diagonal"``."""
        return "full" if self.poses or (self.seats and self.matrix_std) else "diagonal"

    @property
    def speed_dps(self) -> float:
        """``speed`` in degrees per second."""
        return float(np.degrees(self.speed))


def jig_time(
    speed: float, turns: int, rest_s: float, accel: float, settle_s: float = 0.1,
    n_servos: int = 3, move_angles: tuple[float, ...] = (),
    gravity_angles: tuple[float, ...] = (),
) -> float:
    """Jig time of a protocol, step by step as :func:`protocol_sequence` lays it out without
    accelerometer moves: ``2 n_servos`` turns with settling, ``2 n_servos + 1`` rests, and for
    each posed pair (its move angle in ``move_angles``) two moves (there and back) at ``speed``,
    :data:`POSE_SETTLE_S` of still time, two turns and two rests; for each gravity pose
    (``gravity_angles``) a rest and two moves."""
    turn = profile_duration(2 * np.pi * turns, speed, accel) + settle_s
    home = 2 * n_servos * turn + (2 * n_servos + 1) * rest_s
    posed = sum(2 * turn + 2 * rest_s + POSE_SETTLE_S
                + 2 * (profile_duration(abs(a), speed, accel) + settle_s) for a in move_angles)
    gravity = sum(rest_s + 2 * (profile_duration(abs(a), speed, accel) + settle_s)
                  for a in gravity_angles)
    return home + posed + gravity


def gravity_poses(
    poses: tuple[tuple[int, int, float], ...], axes: np.ndarray | None = None,
    up: np.ndarray | None = None,
) -> tuple[tuple[int, float], ...]:
    """Rests the full model adds so that its g-sensitivity ``G`` is determined in full.

    ``g = A (m + b + G f)`` sees ``G`` only through how the specific force ``f`` differs between
    windows (:func:`gyrocal.calib.estimators.gravity_directions`): the home rests see ``f = up``,
    turns about horizontal axes a mean ``f ≈ 0``, so two more directions of gravity are needed.
    A servo whose axis is horizontal in the home pose, moved a quarter turn, puts gravity along
    ``axis × up``; each such servo not already moved by a posed pair (whose rests see it) gets
    one rest at +90°.

    Parameters
    ----------
    poses : tuple of (int, int, float)
        The plan's posed pairs ``(turning, moved, angle)``.
    axes : ndarray, shape (S, 3), optional
        Nominal servo axes in the sensor frame, chain order (default x, y, z).
    up : ndarray, shape (3,), optional
        Nominal "up" in the sensor frame at home (default +z, hardware_docs/mechanical.md).

    Returns
    -------
    tuple of (chain position, angle in rad)
    """
    ax = np.eye(3) if axes is None else np.asarray(axes, dtype=float)
    u = np.array([0.0, 0.0, 1.0]) if up is None else np.asarray(up, dtype=float)
    moved = {m for _, m, _ in poses}
    return tuple((j, float(np.pi / 2)) for j in range(ax.shape[0])
                 if abs(float(ax[j] @ u)) < 0.5 and j not in moved)


#: Still time between a pose move and the turn after it, s: the turn's rest-to-rest window
#: reaches :func:`gyrocal.calib.windows.extract_observations`' ``still_margin_s`` (0.15 s) back
#: before the motion, and the moved servo's last ticks (one at a time, which the motion-span
#: detector does not count as motion) come up to the driver's settle time (30 ms) and a poll
#: before the move is reported finished; without this still time the window read them.
POSE_SETTLE_S = 0.2

#: Shortest rest the planner lays out, s (:func:`plan_protocol`'s ``min_rest_s``): settling
#: plus a bias measurement, and a still window for the accelerometer.
MIN_REST_S = 0.6

#: Shortest time budget the full-model protocol is planned within, s (issue 10's target: the
#: twelve parameters in at most 45 s of jig time).
FULL_TIME_BUDGET_S = 45.0
#: Time budget of the diagonal model's planned protocol when none is given, s (the paper's
#: protocol takes 58 s; method.md §7: a 30 s plan matches it with the paired-axis estimator).
AUTO_TIME_BUDGET_S = 30.0


def full_schedule(
    poses: tuple[tuple[int, int, float], ...], n_servos: int = 3
) -> list[tuple[int, np.ndarray, int]]:
    """The turns of a full-model protocol in the order :func:`gyrocal.kit.protocol.build_steps`
    runs them: ``(turning servo's chain position, every servo's angle from home (S,), direction)``;
    first each servo −, + at home, then each posed pair −, +."""
    out = []
    for s in range(n_servos):
        for d in (-1, 1):
            out.append((s, np.zeros(n_servos), d))
    for turn, moved, angle in poses:
        pose = np.zeros(n_servos)
        pose[moved] = angle
        for d in (-1, 1):
            out.append((turn, pose, d))
    return out


def candidate_pose_sets(n_servos: int = 3) -> list[tuple[tuple[int, int, float], ...]]:
    """Posed pairs the planner considers: two of (middle with inner at θ, base with middle at θ,
    base with inner at θ) for θ = 45° or 90°, and all three at 90° (hardware_docs/method.md §9:
    any two make the twelve terms observable on a square gimbal). Needs three servos."""
    if n_servos != 3:
        raise CalibInputError(f"the full-model planner needs a three-servo chain, got {n_servos}")
    sets = []
    for a in (np.pi / 4, np.pi / 2):
        pairs = [(1, 2, a), (0, 1, a), (0, 2, a)]
        sets += [(pairs[i], pairs[j]) for i, j in ((0, 1), (0, 2), (1, 2))]
    sets.append(((1, 2, np.pi / 2), (0, 1, np.pi / 2), (0, 2, np.pi / 2)))
    return sets  # type: ignore[return-value]


@dataclass(frozen=True)
class _TurnWindow:
    """The window :mod:`gyrocal.calib.windows` would make of a turn, as a model."""

    rate: float  # mean reference rate over the window, rad/s
    n_eff: float  # effective gyro samples
    wint: float  # ∫w, s
    rest_to_rest: bool
    ramp_rate_std: float  # reference std of a tapered window (rad/s); 0 for rest-to-rest


def _turn_window(
    speed: float, turns: int, rest_s: float, accel: float, odr_hz: float, noise_std: float,
    encoder_ticks: int, jitter_s: float, sample_hz: float,
) -> _TurnWindow:
    """The window a turn yields: the candidate with the least predicted variance of the turning
    axis's mean against its reference, as :func:`gyrocal.calib.windows.extract_observations`
    chooses."""
    q = 2 * np.pi / encoder_ticks
    total = 2 * np.pi * turns
    ramp_angle = speed**2 / (2 * accel)
    steady = max(total - 2 * ramp_angle, 0.0) / (2 * np.pi)  # steady revolutions
    period = 2 * np.pi / speed
    reading = np.hypot(q / np.sqrt(12), speed * jitter_s)  # one moving encoder reading
    cands: list[tuple[float, _TurnWindow]] = []

    def tapered(K: float, L: float) -> None:
        # Ramps of L revolutions, flat K - L: ∫w = K revolutions, ∫w² = K - L/3.
        wint = K * period
        n_eff = odr_hz * wint**2 / ((K - L / 3) * period)
        m = max(L * period * sample_hz, 1.0)
        ref = np.sqrt(2) * reading / np.sqrt(m) / wint
        cands.append((noise_std**2 / n_eff + ref**2,
                      _TurnWindow(speed, n_eff, wint, False, float(ref))))

    if steady >= 1:
        tapered(float(np.floor(steady)), steady - np.floor(steady))
    if steady >= 2:  # ramps of one revolution around K - 1 flat ones
        tapered(float(np.floor(steady)) - 1, 1.0)
    t_turn = profile_duration(2 * np.pi * turns, speed, accel)
    margin = min(0.15, rest_s / 2)
    T = t_turn + margin  # two half-weight ramps of `margin` in the still time
    n_eff = odr_hz * T**2 / (t_turn + 2 * margin / 3)
    cands.append((noise_std**2 / n_eff + 2 * q**2 / 12 / T**2,
                  _TurnWindow(total / T, n_eff, T, True, 0.0)))
    return min(cands, key=lambda c: c[0])[1]


def predict_uncertainty(
    speed: float,
    turns: int,
    rest_s: float,
    *,
    noise_std: float,
    odr_hz: float,
    accel: float = 10.0,
    reference_rate: float = 1.0,
    rest_guard_s: float = 0.2,
    encoder_ticks: int = 4096,
    jitter_s: float = 1e-3,
    sample_hz: float = 200.0,
) -> tuple[np.ndarray, np.ndarray, float]:
    """Predicted paired-axis uncertainties of a protocol at nominal truth (k = 1, b = 0).

    The windows, their noise and their references are modelled as :mod:`gyrocal.calib.windows` makes
    them (:func:`_turn_window`): each turn is windowed either rest to rest, its reference resting
    on still encoder angles (``q/√12`` each, shared between a servo's two turns), or inside its
    whole steady revolutions, whose ramp-mean angles average the encoder's quantisation and
    timestamp jitter (``jitter_s``) over the ramp's readings (taken at ``sample_hz``); the one
    with the smaller predicted variance is used, as in :mod:`gyrocal.calib.windows`.

    Returns
    -------
    scale_std, bias_std : ndarray, shape (3,)
    rate_error_std : float
        ``max_u sqrt(var(k·(m + b) − g))`` over unit directions ``u`` at ``reference_rate``:
        the G-criterion of the paper, in rad/s, for the calibrated output.
    """
    from gyrocal.calib.estimators import paired_axis_batch

    win = _turn_window(speed, turns, rest_s, accel, odr_hz, noise_std, encoder_ticks,
                       jitter_s, sample_hz)
    motor = np.repeat(np.arange(3), 2)
    direction = np.tile([1, -1], 3)
    rate = (win.rate * direction)[None, :]
    mean = (rate[0][:, None] * np.eye(3)[motor])[None]
    mean_std = np.full((1, 6, 3), noise_std / np.sqrt(win.n_eff))
    q = 2 * np.pi / encoder_ticks
    if win.rest_to_rest:
        # The reference is the change between still angles: start, shared, end per servo, each
        # read to q/√12 (as gyrocal.calib.windows models it).
        rate_std = np.full((1, 6), 1e-12)
        G = np.zeros((6, 9))
        for s in range(3):
            G[2 * s, 3 * s], G[2 * s, 3 * s + 1] = -1 / win.wint, 1 / win.wint
            G[2 * s + 1, 3 * s + 1], G[2 * s + 1, 3 * s + 2] = -1 / win.wint, 1 / win.wint
        ref = {"ref_matrix": G, "still_std": q / np.sqrt(12)}
        margin = 0.15
    else:
        rate_std = np.full((1, 6), max(win.ramp_rate_std, 1e-12))
        ref = {}
        margin = 0.0
    n_rest = max(int((rest_s - 2 * max(rest_guard_s, margin)) * odr_hz), 0)
    if n_rest >= 10:
        rest_mean = np.zeros((1, 7, 3))
        rest_std = np.full((1, 7, 3), noise_std / np.sqrt(n_rest))
    else:
        rest_mean = np.zeros((1, 0, 3))
        rest_std = np.zeros((1, 0, 3))
    res = paired_axis_batch(mean, rate, motor, mean_std, rate_std, rest_mean, rest_std, **ref)
    C = res.covariance[0, :6, :6]
    U = sphere_points(400) * reference_rate
    # Calibrated output error at true rate g: δ(k ∘ (m + b))_j = δk_j g_j + δb_j (k = 1, b = 0),
    # i.e. gradient row [g_j e_j, e_j] per axis; the error's variance is the sum over axes.
    eye = np.broadcast_to(np.eye(3), (U.shape[0], 3, 3))
    grad = np.concatenate([U[:, :, None] * eye, eye], axis=2)
    var = np.einsum("nip,pq,niq->ni", grad, C, grad).sum(axis=1)
    scale_std = np.sqrt(np.diag(C)[:3])
    bias_std = np.sqrt(np.diag(C)[3:])
    return scale_std, bias_std, float(np.sqrt(var.max()))


def predict_full_uncertainty(
    candidates: list[tuple[float, int, float]],
    poses: tuple[tuple[int, int, float], ...],
    *,
    noise_std: float,
    odr_hz: float,
    accel: float = 10.0,
    reference_rate: float = 1.0,
    axes: np.ndarray | None = None,
    rest_guard_s: float = 0.2,
    encoder_ticks: int = 4096,
    jitter_s: float = 1e-3,
    sample_hz: float = 200.0,
    gravity: tuple[tuple[int, float], ...] | None = None,
    up: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Predicted full-matrix uncertainties of protocols at nominal truth (A = I, b = 0).

    The windows are modelled as in :func:`predict_uncertainty` (:func:`_turn_window`); the turns
    follow :func:`full_schedule`; every still period of every servo is one unknown reading error
    (``q/√12``) shared by the references that rest on it and the poses it holds (a servo holds
    anywhere within its tick, which tilts the axes outside it), as the estimator models it; and
    the fit is :func:`gyrocal.calib.estimators.full_matrix_batch` on noise-free observations of a
    gimbal with the nominal ``axes`` (chain order; default x, y, z), all candidates at once.

    Parameters
    ----------
    candidates : list of (speed, turns, rest_s)
        The protocols to score.
    poses : tuple of (int, int, float)
        Their posed pairs (:attr:`Plan.poses`).
    gravity : tuple of (int, float), optional
        Given, the design fits g-sensitivity, ``g = A (m + b + G f)``
        (:func:`gyrocal.calib.estimators.fit_full_matrix`): these are its gravity rests
        (:attr:`Plan.gravity_poses`, one rest each after the posed pairs). The specific force is
        ``up`` carried to each pose by the chain (:func:`gyrocal.calib.kinematics.carried_up`):
        a rest sees it whole, a turn over whole revolutions its part along the turning axis;
        ``G`` is fitted along the directions in which ``f`` varies (its constant part is in
        ``b``, then the zero-g bias), as the fit keeps the directions it determines.
    up : ndarray (3,), optional
        "Up" in the sensor frame at home (default +z, hardware_docs/mechanical.md).

    Returns
    -------
    matrix_std : ndarray, shape (B, 3, 3)
    bias_std : ndarray, shape (B, 3)
        With ``gravity``, of the zero-g bias.
    rate_error_std : ndarray, shape (B,)
        Worst-direction standard deviation of ``A (m + b)`` at ``reference_rate`` (the
        G-criterion for the calibrated output, as in :func:`predict_uncertainty`); with
        ``gravity``, of ``A (m + b + G f)``, worst also over the direction of a 1 g specific
        force, the correlations of ``G`` with ``A`` and ``b`` included.
    """
    from gyrocal.calib.estimators import full_matrix_batch
    from gyrocal.calib.kinematics import chain_axes

    ax = np.eye(3) if axes is None else np.asarray(axes, dtype=float)
    S = ax.shape[0]
    sched = full_schedule(poses, S)
    n = len(sched)
    midx = np.array([t[0] for t in sched])
    pose = np.array([t[1] for t in sched])
    direction = np.array([t[2] for t in sched], dtype=float)
    u = chain_axes(ax, np.zeros(S), pose)[np.arange(n), midx]
    q = 2 * np.pi / encoder_ticks
    B = len(candidates)
    rate = np.zeros((B, n))
    mean_std = np.zeros((B, n, 3))
    rate_std = np.zeros((B, n))
    # Still angles, numbered as gyrocal.calib.windows does: one per still period of each servo
    # (a turn or a move of that servo ends it). A turn's rest-to-rest reference rests on its
    # servo's periods before and after; every other servo's period carries its pose.
    period = dict.fromkeys(range(S), 0)
    ids: dict[tuple[int, int], int] = {}
    before, after = np.zeros(n, dtype=np.int64), np.zeros(n, dtype=np.int64)
    pose_still = np.full((n, S), -1, dtype=np.int64)
    moves_at = {2 * S + 2 * j: m for j, (_, m, _) in enumerate(poses)}  # moved before turn i
    for i, sv in enumerate(midx):
        if i in moves_at:
            period[moves_at[i]] += 1
        for k in range(S):
            pose_still[i, k] = ids.setdefault((k, period[k]), len(ids))
        before[i] = pose_still[i, sv]
        pose_still[i, sv] = -1
        period[sv] += 1
        after[i] = ids.setdefault((sv, period[sv]), len(ids))
        if i - 2 * S >= 0 and (i - 2 * S) % 2 == 1:  # the move back after a posed pair
            period[poses[(i - 2 * S) // 2][1]] += 1
    n_still = len(ids)
    G = np.zeros((B, n, n_still))
    n_rest = len(_rest_poses(S, poses, gravity or ()))
    rest_std = np.zeros((B, n_rest, 3))
    for c, (speed, turns, rest_s) in enumerate(candidates):
        win = _turn_window(speed, turns, rest_s, accel, odr_hz, noise_std, encoder_ticks,
                           jitter_s, sample_hz)
        rate[c] = win.rate * direction
        mean_std[c] = noise_std / np.sqrt(win.n_eff)
        margin = 0.0
        if win.rest_to_rest:
            rate_std[c] = 1e-12
            G[c, np.arange(n), before] = -1 / win.wint
            G[c, np.arange(n), after] = 1 / win.wint
            margin = 0.15
        else:
            rate_std[c] = max(win.ramp_rate_std, 1e-12)
        m_rest = max(int((rest_s - 2 * max(rest_guard_s, margin)) * odr_hz), 1)
        rest_std[c] = noise_std / np.sqrt(m_rest)
    mean = rate[..., None] * u[None]
    rest_mean = np.zeros_like(rest_std)
    forces = (None if gravity is None
              else _design_forces(ax, u, pose, poses, gravity, up))
    res = full_matrix_batch(mean, rate, midx, pose, mean_std, rate_std, rest_mean, rest_std,
                            n_servos=S, reference=np.zeros(S), ref_matrix=G,
                            still_std=q / np.sqrt(12), pose_still=pose_still,
                            **({} if forces is None else {"force": forces[0],
                                                          "rest_force": forces[1]}))
    cov = res.covariance
    grad = _full_output_gradients(sphere_points(400) * reference_rate)
    var = np.einsum("nip,bpq,niq->bn", grad, cov, grad)
    if forces is not None and res.g_covariance is not None:
        var = _with_g_variance(grad, res, forces[2])
    matrix_std = np.sqrt(np.clip(np.diagonal(cov, axis1=1, axis2=2)[:, :9], 0, None))
    bias_std = np.sqrt(np.clip(np.diagonal(cov, axis1=1, axis2=2)[:, 9:], 0, None))
    return matrix_std.reshape(B, 3, 3), bias_std, np.sqrt(var.max(axis=1))


def _design_forces(axes: np.ndarray, u: np.ndarray, pose: np.ndarray,
                   poses: tuple[tuple[int, int, float], ...],
                   gravity: tuple[tuple[int, float], ...], up: np.ndarray | None
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The mean specific force of each turn (``(u·γ) u`` over whole revolutions) and each rest
    (``γ``) of a :func:`full_schedule` design, in the coordinates of the directions it varies
    along (the ``basis`` rows, also returned): the ``force``/``rest_force`` of
    :func:`gyrocal.calib.estimators.full_matrix_batch`; the rests those of
    :func:`_rest_poses`."""
    from gyrocal.calib.kinematics import carried_up

    S = axes.shape[0]
    zero = np.zeros(S)
    g0 = np.array([0.0, 0.0, 1.0]) if up is None else np.asarray(up, dtype=float)
    gam = carried_up(axes, zero, zero, g0, pose)
    f_win = u * np.sum(u * gam, axis=1, keepdims=True)
    f_rest = carried_up(axes, zero, zero, g0, _rest_poses(S, poses, gravity))
    every = np.concatenate([f_win, f_rest])
    _, sv, vt = np.linalg.svd(every - every.mean(axis=0))
    basis = vt[sv > 1e-6 * max(float(sv[0]), 1e-300)]
    return f_win @ basis.T, f_rest @ basis.T, basis


def _rest_poses(S: int, poses: tuple[tuple[int, int, float], ...],
                gravity: tuple[tuple[int, float], ...]) -> np.ndarray:
    """Every servo's angle from home at each rest of a full-model design, ``(R, S)``, as
    :func:`protocol_sequence` runs them: ``2S + 1`` at home, two per posed pair in its pose,
    one per gravity pose."""
    rest_pose = [np.zeros(S)] * (2 * S + 1)
    for _, moved, angle in poses:
        rest_pose += [np.where(np.arange(S) == moved, angle, 0.0)] * 2
    for moved, angle in gravity:
        rest_pose.append(np.where(np.arange(S) == moved, angle, 0.0))
    return np.array(rest_pose).reshape(-1, S)


def _with_g_variance(grad: np.ndarray, res: Any, basis: np.ndarray) -> np.ndarray:
    """``(B, N)``: the largest variance (summed over the three components, as without ``G``)
    over 1 g specific forces ``f`` in every direction of ``A (m + b + G f)`` at the rates of
    ``grad`` (:func:`_full_output_gradients`), ``G = G_k basis``, with the fit's covariances of
    ``(A, b)``, of ``G_k`` and between them (at ``A = I``: ``∂g_j / ∂G_jk = f_k``)."""
    tg = np.kron(np.eye(3), basis.T)  # vec(G) (9) from vec(G_k) (3k), both row-major
    cg = tg @ res.g_covariance @ tg.T  # (B, 9, 9)
    x = res.g_cross_covariance @ tg.T  # (B, 12, 9)
    v = np.einsum("nip,bpq,niq->bn", grad, res.covariance, grad)  # (B, N)
    gx = np.einsum("nip,bpq->bniq", grad, x)  # (B, N, 3, 9)
    f = sphere_points(50)
    total = v[:, :, None] + np.zeros((1, 1, f.shape[0]))
    for j in range(3):
        blk = slice(3 * j, 3 * j + 3)
        total = total + 2 * np.einsum("bna,ka->bnk", gx[:, :, j, blk], f)
        total = total + np.einsum("ka,bac,kc->bk", f, cg[:, blk, blk], f)[:, None, :]
    return total.max(axis=2)


def _full_output_gradients(U: np.ndarray) -> np.ndarray:
    """``∂(A (m + b))_j / ∂(A row-major, b)`` at ``A = I``, ``b = 0`` for true rates ``U``
    (N, 3): row ``j`` is ``ω`` in the block of ``A``'s row ``j`` and 1 at ``b_j``; shape
    (N, 3, 12)."""
    grad = np.zeros((U.shape[0], 3, 12))
    for i in range(3):
        grad[:, i, 3 * i : 3 * i + 3] = U
        grad[:, i, 9 + i] = 1.0
    return grad


def score_full_design(
    schedule: list[tuple[int, np.ndarray, int]],
    *,
    rate: float | np.ndarray,
    window_std: float | np.ndarray,
    rest_std: float,
    n_rests: int,
    axes: np.ndarray | None = None,
    radius: float | None = None,
    n_search: int = 2000,
) -> DesignScore:
    r"""Information, predicted σ and G-criterion of a gimbal design for the full model
    ``g = A (m + b)`` (issue 10; the paper's Section II-B criterion carried to twelve parameters).

    A design is the turns of :func:`full_schedule` (turning servo, every servo's angle, direction)
    at reference rates ``rate`` and the rests. At the nominal truth (``A = I``, ``b = 0``, servo
    axes ``axes`` at home) a turn's window mean reads ``ω_i C u_s(θ_i) − b`` with noise
    ``window_std`` per axis, a rest ``−b`` with ``rest_std``
    (:func:`gyrocal.calib.estimators.fit_full_matrix`). The Fisher information of ``(C, b)`` and
    the servo axes is ``J̃ᵀJ̃`` of the whitened residuals; eliminating the axes (Schur
    complement) and mapping ``dA = −A dC A`` gives the covariance of the twelve parameters in the
    frame ``gyro-x-xy`` (three elements fixed at 0), computed here as the estimator's own
    covariance at exact data (:func:`gyrocal.calib.estimators.full_matrix_batch`). Encoder
    readings are taken as exact (no still-angle terms; :func:`predict_full_uncertainty` models
    them for the planner).

    G-criterion: a calibrated component ``ĝ_j(ω) = (A (m + b))_j`` has variance
    ``f_j(ω)ᵀ Σ f_j(ω)`` with ``f_j`` the gradient of :func:`_full_output_gradients`; with
    ``W = Σ_i 1/σ²_i`` over every window and rest (the design's total weight), its standardised
    prediction variance is ``d_j(u) = W f_j(ωu)ᵀ Σ f_j(ωu)`` on ``|ω| = radius``. Component
    ``j`` is a regression on its row's free elements of ``A`` and ``b_j``: ``p_j`` = 2, 3, 4
    terms in the frame ``gyro-x-xy``. Known axes would decouple the rows, so by the
    Kiefer–Wolfowitz theorem ``max_u d_j ≥ p_j``; a gimbal's unknown axes only lose
    information. ``g_efficiency = min_j p_j / max_u d_j`` (≤ 1; 0 when the design cannot
    determine ``A``), ``max_variance`` the ``max d_j`` of that component and ``argmax`` its
    direction.

    Parameters
    ----------
    schedule : list of (int, ndarray (S,), int)
        The turns (:func:`full_schedule`).
    rate : float or ndarray (n,)
        Unsigned reference rate of each turn, rad/s.
    window_std : float or ndarray (n,)
        Noise of each turn's window mean, per axis, rad/s.
    rest_std, n_rests :
        Noise of a rest's mean and the number of rests.
    axes : ndarray (S, 3), optional
        The servos' axes in the sensor frame at home, chain order (default x, y, z).
    radius : float, optional
        Rotation rate of the design region, rad/s; at least the largest ``rate`` (the bound
        holds for designs inside the region; default: the largest ``rate``).
    n_search : int
        Directions searched before local refinement.

    Returns
    -------
    DesignScore
        ``model="full"`` with ``parameter_std``, ``information`` and ``rate_error_std``;
        ``d_criterion`` is ``det(I_free / W)^(1/9)`` over the nine free parameters.

    Raises
    ------
    CalibInputError
        On an empty schedule, non-positive noise, rate or radius, or a radius below a rate.
    """
    from gyrocal.calib.estimators import full_matrix_batch
    from gyrocal.calib.kinematics import chain_axes

    if not schedule:
        raise CalibInputError("the schedule has no turns")
    n = len(schedule)
    w = np.broadcast_to(np.asarray(rate, dtype=float), (n,))
    sd = np.broadcast_to(np.asarray(window_std, dtype=float), (n,))
    radius = float(np.max(w)) if radius is None else radius
    for name, v in (("rate", w), ("window_std", sd), ("rest_std", np.array([rest_std])),
                    ("radius", np.array([radius]))):
        if not np.all(np.isfinite(v) & (v > 0)):
            raise CalibInputError(f"{name} must be positive and finite")
    if radius < np.max(w) * (1 - 1e-12):
        raise CalibInputError(
            f"radius {radius:g} rad/s is below the design's fastest turn ({np.max(w):g} rad/s); "
            "score on a region that contains the design (leave radius unset)")
    if int(n_rests) < 0:
        raise CalibInputError(f"n_rests must be at least 0, got {n_rests!r}")
    ax = np.eye(3) if axes is None else np.asarray(axes, dtype=float)
    S = ax.shape[0]
    midx = np.array([t[0] for t in schedule])
    pose = np.array([np.asarray(t[1], dtype=float) for t in schedule])
    signed = w * np.array([t[2] for t in schedule], dtype=float)
    u = chain_axes(ax, np.zeros(S), pose)[np.arange(n), midx]
    mean = (signed[:, None] * u)[None]
    r = int(n_rests)
    res = full_matrix_batch(
        mean, signed[None], midx, pose, np.broadcast_to(sd[:, None], (1, n, 3)).copy(),
        np.full((1, n), 1e-12), np.zeros((1, r, 3)), np.full((1, r, 3), float(rest_std)),
        n_servos=S, reference=np.zeros(S), max_iter=5)
    cov = res.covariance[0]
    weight = float(np.sum(1.0 / sd**2) + r / rest_std**2)
    free = np.diag(cov) > 0
    if res.rank_deficiency[0] or not np.all(np.isfinite(cov)) or free.sum() < 9:
        return DesignScore(np.inf, (np.nan, np.nan, np.nan), 0.0, 0.0, model="full",
                           parameter_std=tuple(np.full(12, np.inf).tolist()),
                           information=np.zeros((12, 12)), rate_error_std=np.inf)
    info = np.zeros((12, 12))
    info[np.ix_(free, free)] = np.linalg.inv(cov[np.ix_(free, free)])

    # Component j regresses on its row's free elements and b_j: p_j terms (2, 3, 4 in gyro-x-xy).
    p_j = free[:9].reshape(3, 3).sum(axis=1) + 1
    weight_j = np.sum(1.0 / sd**2) + r / rest_std**2

    def std_var(v: np.ndarray) -> np.ndarray:
        """(N, 3): each component's standardised variance over its bound, at directions v."""
        g = _full_output_gradients(radius * v / np.linalg.norm(v, axis=-1, keepdims=True))
        return weight_j * np.einsum("nip,pq,niq->ni", g, cov, g) / p_j

    S_pts = sphere_points(n_search)
    vals = std_var(S_pts).max(axis=1)
    top, arg = -np.inf, S_pts[int(np.argmax(vals))]
    for i in np.argsort(vals)[-5:]:
        from scipy import optimize  # imported where a search needs it (seconds on a Pi)

        opt = optimize.minimize(lambda x: -float(std_var(x[None]).max()), S_pts[i],
                                method="Nelder-Mead", options={"xatol": 1e-10, "fatol": 1e-15})
        if -opt.fun > top:
            top, arg = -opt.fun, opt.x / np.linalg.norm(opt.x)
    g_arg = _full_output_gradients(radius * arg[None])
    var_arg = np.einsum("nip,pq,niq->ni", g_arg, cov, g_arg)[0]
    rate_var = max(float(var_arg.max()), float(
        np.einsum("nip,pq,niq->ni", _full_output_gradients(radius * S_pts), cov,
                  _full_output_gradients(radius * S_pts)).max()))
    d_max = float(top) * float(p_j[int(np.argmax(std_var(arg[None])[0]))])
    det = float(np.linalg.det(info[np.ix_(free, free)] / weight))
    return DesignScore(
        max_variance=d_max,
        argmax=(float(arg[0]), float(arg[1]), float(arg[2])),
        g_efficiency=1.0 / float(top),
        d_criterion=max(det, 0.0) ** (1 / 9),
        model="full",
        parameter_std=tuple(float(x) for x in np.sqrt(np.clip(np.diag(cov), 0, None))),
        information=info,
        rate_error_std=float(np.sqrt(rate_var)),
    )


def general_motion_rms(matrix: np.ndarray, bias: np.ndarray, sensing: np.ndarray,
                       true_bias: np.ndarray, rate: float = 1.0) -> float:
    """RMS error of a calibrated rate over all directions at ``rate``, per rad/s, that no choice
    of output frame removes.

    With the sensor reading ``m = C ω − b`` and the calibration ``ĝ = M (m + b̂)``, the error is
    ``(M C − R) ω + M (b̂ − b)`` for the output frame ``R`` (a rotation); over directions
    uniform on the sphere ``E|Eω|² = rate² ‖E‖²_F / 3`` and the bias term adds
    ``|M (b̂ − b)|²``. ``R`` is the rotation nearest ``M C`` (its polar factor), so a correct
    calibration in any frame scores its own error only. The paper's diagonal model is
    ``M = diag(scale)``.
    """
    MC = np.asarray(matrix, float) @ np.asarray(sensing, float)
    U, _, Vt = np.linalg.svd(MC)
    R = U @ np.diag([1.0, 1.0, np.linalg.det(U @ Vt)]) @ Vt
    db = np.asarray(matrix, float) @ (np.asarray(bias, float) - np.asarray(true_bias, float))
    ms = np.sum((MC - R) ** 2) / 3.0 + float(db @ db) / rate**2
    return float(np.sqrt(ms))


def predicted_general_motion_rms(covariance: np.ndarray, rate: float = 1.0,
                                 matrix: np.ndarray | None = None) -> float:
    """The RMS :func:`general_motion_rms` a calibration's own covariance predicts.

    A 6×6 covariance is the diagonal model's (scale, bias), a 12×12 the full one's (matrix
    row-major, bias). To first order the error matrix is ``dA C`` with ``C = A⁻¹`` and the bias
    error is ``A db``; :func:`general_motion_rms` counts only the symmetric part of the first
    (its antisymmetric part is a rotation of the output frame), so the prediction is
    ``sqrt(E‖sym(dA C)‖²_F / 3 + E|A db|² / rate²)``. Without ``matrix`` it is taken at
    ``A = I``.

    Parameters
    ----------
    covariance : ndarray, shape (6, 6) or (12, 12)
    rate : float
        The general motion's rate, rad/s (the bias term is per rad/s of it).
    matrix : ndarray, shape (3, 3), optional
        The calibration's ``A`` (``diag(scale)`` for the diagonal model): the paper's extreme
        sensors (scale up to 2) have ``C`` far from ``I``.
    """
    cov = np.asarray(covariance, dtype=float)
    if cov.shape == (6, 6):  # the diagonal model: A's diagonal entries 0, 4, 8
        idx = [0, 4, 8, 9, 10, 11]
        full = np.zeros((12, 12))
        full[np.ix_(idx, idx)] = cov
        cov = full
    A = np.eye(3) if matrix is None else np.asarray(matrix, dtype=float)
    # vec_r(dA C) = (I ⊗ Cᵀ) vec_r(dA); sym(E) = (E + Eᵀ)/2 = ((I + K)/2) vec_r(E), K the
    # commutation matrix of 3×3 matrices
    K = np.eye(9)[[3 * (k % 3) + k // 3 for k in range(9)]]
    T = 0.5 * (np.eye(9) + K) @ np.kron(np.eye(3), np.linalg.inv(A).T)
    ms = np.trace(T @ cov[:9, :9] @ T.T) / 3.0 + np.trace(A @ cov[9:, 9:] @ A.T) / rate**2
    return float(np.sqrt(max(ms, 0.0)))


def cross_axis_general_motion_rms(cross_axis: float) -> float:
    """The RMS :func:`general_motion_rms` that cross-axis terms a calibration leaves out give.

    With the six off-diagonal terms of ``C`` independent and uniform within the datasheet's
    ``±cross_axis`` (variance ``c²/3`` each), the symmetric part of the off-diagonal matrix
    (its antisymmetric part is a rotation, which no choice of output frame counts) has
    ``E‖·‖²_F = 3 · 2 · (2c²/3)/4 = c²``, so the error is ``c/√3`` per rad/s; a diagonal
    calibration of the six home-pose turns leaves exactly these terms
    (hardware_docs/method.md §9, observability).
    """
    return float(cross_axis) / float(np.sqrt(3.0))


def choose_model(full_covariance: np.ndarray | None, full_matrix: np.ndarray | None,
                 diagonal_covariance: np.ndarray, diagonal_scale: np.ndarray,
                 cross_axis: float, rate: float = 1.0) -> ModelChoice:
    """Which model a recording's calibration should have: the full model when its predicted
    general-motion error is below the diagonal model's, which includes the cross-axis terms
    it leaves out.

    Parameters
    ----------
    full_covariance, full_matrix : ndarray (12, 12) and (3, 3), or None
        The full-model fit's covariance and ``A``; None when it is not determined.
    diagonal_covariance : ndarray, shape (6, 6)
        The diagonal fit's (scale, bias) covariance.
    diagonal_scale : ndarray, shape (3,)
    cross_axis : float
        The cross-axis sensitivity the sensor's datasheet allows, a fraction of the rate
        (:func:`cross_axis_general_motion_rms`).
    rate : float
        Rate of the general motion, rad/s.

    Returns
    -------
    ModelChoice
        Both predicted figures (:func:`predicted_general_motion_rms`); ``chosen`` says which.
    """
    full = None
    if full_covariance is not None and np.all(np.isfinite(full_covariance)):
        full = predicted_general_motion_rms(full_covariance, rate, full_matrix)
    cross = cross_axis_general_motion_rms(cross_axis)
    fit = predicted_general_motion_rms(diagonal_covariance, rate,
                                       np.diag(np.asarray(diagonal_scale, dtype=float)))
    return ModelChoice(full=full, diagonal=float(np.hypot(fit, cross)),
                       diagonal_cross_axis=cross, cross_axis=float(cross_axis))


def _checked_top_speed(model: str, max_scale_error: float, **positive: float) -> float:
    """The planners' top turn rate, rad/s (0.9 of the servo's top speed, and of the rate that
    keeps the gyro in range at ``max_scale_error``), once ``positive`` are all positive finite
    numbers and ``model`` is ``"diagonal"`` or ``"full"``.

    Raises
    ------
    CalibInputError
        Naming the first argument that is not.
    """
    for name, v in positive.items():
        if not (v > 0 and np.isfinite(v)):
            raise CalibInputError(f"{name} must be a positive number, got {v!r}")
    if model not in ("diagonal", "full"):
        raise CalibInputError(f"model must be 'diagonal' or 'full', got {model!r}")
    return min(0.9 * positive["servo_max_speed"],
               0.9 * positive["full_scale"] / max_scale_error)


def plan_protocol(
    *,
    servo_max_speed: float,
    full_scale: float,
    time_budget_s: float = AUTO_TIME_BUDGET_S,
    noise_std: float = 0.035,
    odr_hz: float = 200.0,
    accel: float = 10.0,
    reference_rate: float = 1.0,
    min_rest_s: float = MIN_REST_S,
    max_scale_error: float = 1.25,
    model: str = "diagonal",
    axes: np.ndarray | None = None,
    accel_rests: bool = False,
    max_turns: float | None = None,
) -> Plan:
    """Choose speed, turns and rest length (and, for the full model, poses) within a time budget.

    For ``model="diagonal"`` the paired-axis estimator's six parameters are scored
    (:func:`predict_uncertainty`); for ``model="full"`` the full-matrix estimator's twelve
    (:func:`predict_full_uncertainty`), over the pose sets of :func:`candidate_pose_sets`, with
    the moves' time counted (:func:`jig_time`). Either way the plan minimises the worst-direction
    standard deviation of a calibrated rate at ``reference_rate``. With ``accel_rests``, the
    rests are tilted for the accelerometer (:func:`plan_accel_rests`) and the whole run, their
    moves (and any rests added) included, stays within the budget: the gyro's protocol is
    planned again, each time within its own time less the overshoot, until it does.

    Parameters
    ----------
    servo_max_speed : float
        The servo's usable top speed, rad/s (from its Velocity Limit; the planner keeps 10 %
        headroom so the speed is reached under load).
    full_scale : float
        The gyro's full-scale range, rad/s. A reading is ``ω/k``: with scale factors down to
        ``1/max_scale_error`` (paper: k >= 0.8) the speed stays below
        ``0.9 · full_scale / max_scale_error`` so nothing saturates.
    time_budget_s : float
        Longest jig time.
    noise_std : float
        Gyro white noise per sample at ``odr_hz``, rad/s.
    odr_hz : float
        Gyro output data rate.
    accel : float
        Servo profile acceleration, rad/s².
    reference_rate : float
        Rate at which the calibrated output's worst-direction error is minimised, rad/s.
    min_rest_s : float
        Shortest rest (settling plus a bias measurement).
    max_scale_error : float
        Largest ``1/k`` to allow for when avoiding saturation.
    model : str
        ``"diagonal"`` (the paper's model) or ``"full"`` (g = A (m + b); three servos).
    axes : ndarray, shape (3, 3), optional
        Full model: the servos' nominal axes in the sensor frame, chain order, for planning only
        (default x, y, z); the estimate never uses them.
    accel_rests : bool
        Tilt the rests for the accelerometer within the budget (above; the diagonal protocol's
        seven rests also get the missing ones at its end).
    max_turns : float, optional
        With ``accel_rests``: the cable-wrap limit, turns from home (:func:`plan_accel_rests`).

    Returns
    -------
    Plan

    Raises
    ------
    CalibInputError
        If the arguments are not positive, or no protocol fits the budget.
    """
    top = _checked_top_speed(model, max_scale_error, servo_max_speed=servo_max_speed,
                             full_scale=full_scale, time_budget_s=time_budget_s,
                             noise_std=noise_std, odr_hz=odr_hz, accel=accel,
                             reference_rate=reference_rate)
    budget = time_budget_s
    tilted: Plan | None = None  # the last gyro protocol with the accelerometer's rests
    for _ in range(8):
        best = (_plan_full_cached(top, budget, noise_std, odr_hz, accel, reference_rate,
                                  min_rest_s, _hashable(axes), time_budget_s) if model == "full"
                else _plan_diagonal(top, budget, noise_std, odr_hz, accel, reference_rate,
                                    min_rest_s))
        if best is None:
            break
        if not accel_rests:
            return best
        tilted = plan_accel_rests(best, axes=axes, max_turns=max_turns)
        over = tilted.jig_time_s - time_budget_s
        if over <= 1e-9:
            return tilted
        # below this gyro protocol's own time by the overshoot (the candidates' times jump)
        budget = tilted.jig_time_s - tilted.accel_time_s - over - 1e-6
    if tilted is None:
        raise CalibInputError(
            f"no {'full-model ' if model == 'full' else ''}protocol fits {time_budget_s:g} s "
            f"with speeds up to {top:.2f} rad/s; raise the time budget")
    raise CalibInputError(
        f"the accelerometer's rests take {tilted.accel_time_s:.1f} s (their moves and rests) of "
        f"the {time_budget_s:g} s budget and no {model} protocol fits the rest; raise the time "
        "budget or turn the accelerometer's rests off")


def _plan_diagonal(
    top: float, budget: float, noise_std: float, odr_hz: float, accel: float,
    reference_rate: float, min_rest_s: float,
) -> Plan | None:
    """The best diagonal-model plan over speeds × turns × rests within ``budget``."""
    speeds = np.unique(np.concatenate([np.linspace(0.5, top, 12), [top]]))
    speeds = speeds[speeds <= top]
    best = None
    for speed in speeds:
        for turns in range(1, 9):
            for rest in (min_rest_s, 1.0, 1.5, 2.0, 3.0):
                if rest < min_rest_s:
                    continue
                T = jig_time(speed, turns, rest, accel)
                if T > budget:
                    continue
                ks, bs, err = predict_uncertainty(
                    speed, turns, rest, noise_std=noise_std, odr_hz=odr_hz, accel=accel,
                    reference_rate=reference_rate,
                )
                cand = Plan(
                    float(speed), turns, float(rest), float(accel), float(T),
                    tuple(ks), tuple(bs), err, float(reference_rate),  # type: ignore[arg-type]
                )
                if best is None or cand.rate_error_std < best.rate_error_std * (1 - 1e-9):
                    best = cand
    return best


@functools.lru_cache(maxsize=32)
def _plan_full_cached(
    top: float, budget: float, noise_std: float, odr_hz: float, accel: float,
    reference_rate: float, min_rest_s: float, axes_key: _Key | None, scored_within: float,
) -> Plan | None:
    """:func:`_plan_full` for the same inputs computed once (a plan is immutable): the
    emulated calibrations of one process that measure the same noise plan once."""
    return _plan_full(top, budget, noise_std, odr_hz, accel, reference_rate, min_rest_s,
                      axes_key, scored_within)


@functools.lru_cache(maxsize=16)
def _full_candidates(
    top: float, budget: float, noise_std: float, odr_hz: float, accel: float,
    reference_rate: float, min_rest_s: float, axes_key: _Key | None,
) -> tuple[tuple[Any, ...], ...]:
    """Per pose set of :func:`candidate_pose_sets`, the full-model candidates (speed, turns,
    rest) within ``budget``, their jig times and their predicted figures
    (:func:`predict_full_uncertainty`, each candidate's its own whatever the others), cached:
    :func:`plan_protocol` plans again within a shorter budget when the accelerometer's rests
    overshoot it, and picks among a subset of these."""
    axes = _array(axes_key)
    speeds = np.unique(np.concatenate([np.linspace(min(1.0, top), top, 6), [top]]))
    scored = []
    for poses in candidate_pose_sets(3):
        angles = tuple(abs(p[2]) for p in poses)
        grav = gravity_poses(poses, axes)
        g_angles = tuple(a for _, a in grav)
        timed = [
            ((float(sp), t, float(r)),
             jig_time(sp, t, r, accel, move_angles=angles, gravity_angles=g_angles))
            for sp in speeds for t in (1, 2, 3)
            for r in sorted({min_rest_s, 1.0, 1.5}) if r >= min_rest_s]
        timed = [(c, T) for c, T in timed if T <= budget]
        if not timed:
            continue
        cands = [c for c, _ in timed]
        ms, bs, err = predict_full_uncertainty(
            cands, poses, noise_std=noise_std, odr_hz=odr_hz, accel=accel,
            reference_rate=reference_rate, axes=axes)
        scored.append((poses, grav, tuple(cands), tuple(T for _, T in timed), ms, bs, err))
    return tuple(scored)


def _plan_full(
    top: float, budget: float, noise_std: float, odr_hz: float, accel: float,
    reference_rate: float, min_rest_s: float, axes_key: _Key | None, scored_within: float,
) -> Plan | None:
    """The best full-model plan over pose sets × speeds × turns × rests within ``budget``, of
    the candidates scored within ``scored_within`` (at least ``budget``:
    :func:`_full_candidates`)."""
    axes = _array(axes_key)
    best: Plan | None = None
    for poses, grav, all_cands, times, all_ms, all_bs, all_err in _full_candidates(
            top, max(budget, scored_within), noise_std, odr_hz, accel, reference_rate,
            min_rest_s, axes_key):
        within = [k for k, T in enumerate(times) if T <= budget]
        if not within:
            continue
        cands = [all_cands[k] for k in within]
        ms, bs, err = all_ms[within], all_bs[within], all_err[within]
        i = int(np.argmin(err))
        if best is not None and not err[i] < best.rate_error_std * (1 - 1e-9):
            continue
        sp, t, r = cands[i]
        best = Plan(
            sp, t, r, float(accel), float(times[within[i]]),
            tuple(float(x) for x in np.diag(ms[i])), tuple(float(x) for x in bs[i]),  # type: ignore[arg-type]
            float(err[i]), float(reference_rate),
            poses=tuple((int(a), int(b), float(c)) for a, b, c in poses),
            matrix_std=tuple(tuple(float(x) for x in row) for row in ms[i]),
            gravity_poses=grav,
        )
    if best is None:
        return None
    # The plan is chosen on A (m + b) (the objective of the matrix), then its figures are given
    # for the model it fits, g = A (m + b + G f): with G's uncertainty and its correlations.
    ms, bs, err = predict_full_uncertainty(
        [(best.speed, best.turns, best.rest_s)], best.poses, noise_std=noise_std,
        odr_hz=odr_hz, accel=accel, reference_rate=reference_rate, axes=axes,
        gravity=best.gravity_poses)
    return replace(best, scale_std=tuple(float(x) for x in np.diag(ms[0])),
                   bias_std=tuple(float(x) for x in bs[0]), rate_error_std=float(err[0]),
                   matrix_std=tuple(tuple(float(x) for x in row) for row in ms[0]))


def paper_plan(
    noise_std: float = 0.035, odr_hz: float = 200.0, accel: float = 10.0,
    reference_rate: float = 1.0,
) -> Plan:
    """The paper's protocol (60°/s, one turn each way, 3 s waits) with its predicted accuracy."""
    speed = float(np.radians(60.0))
    ks, bs, err = predict_uncertainty(speed, 1, 3.0, noise_std=noise_std, odr_hz=odr_hz,
                                      accel=accel, reference_rate=reference_rate)
    return Plan(speed, 1, 3.0, accel, jig_time(speed, 1, 3.0, accel), tuple(ks), tuple(bs),
                err, reference_rate)  # type: ignore[arg-type]


# ------------------------------------------------------------- the accelerometer's rests
def _base_sequence(plan: Plan, n_servos: int) -> list[tuple]:
    """The protocol without accelerometer moves, as :func:`protocol_sequence` describes it."""
    seq: list[tuple] = []
    for m in range(n_servos):
        for d in (-1, 1):
            seq += [("rest",), ("rotate", m, d)]
    seq.append(("rest",))
    for turn, moved, angle in plan.poses:
        seq += [("move", moved, float(angle)), ("still", POSE_SETTLE_S), ("rotate", turn, -1),
                ("rest",), ("rotate", turn, 1), ("rest",), ("move", moved, 0.0)]
    for moved, angle in plan.gravity_poses:
        seq += [("move", moved, float(angle)), ("rest",), ("move", moved, 0.0)]
    return seq + [("rest",)] * int(plan.accel_extra_rests)


def protocol_sequence(plan: Plan, n_servos: int = 3) -> list[tuple]:
    """The plan's steps in running order, servos as chain positions (base = 0).

    Each step is ``("rest",)``, ``("rotate", servo, direction)`` (``plan.turns`` whole
    turns), ``("move", servo, angle)`` (to ``angle`` rad from home) or ``("still", seconds)``
    (the jig holds still: no rest of the fit, only still time after a turn or a pose move). Per
    servo: rest, turn −, rest, turn +; a final rest; each posed pair: move a servo to its pose,
    hold still :data:`POSE_SETTLE_S`, turn another −, rest, +, rest, move the first home
    (:func:`full_schedule` is the turns' order); each gravity pose: move, rest, move home;
    then :attr:`Plan.accel_extra_rests` rests. The accelerometer's moves
    (:attr:`Plan.accel_moves`) go right before their rest, after :data:`ACCEL_STILL_S` of still
    time when a turn comes before (the turn's rest-to-rest
    window takes still time after it: :mod:`gyrocal.calib.windows`); the run ends with every
    servo still away from home moved home (lowest chain position first). A move's angle counts
    from home plus the whole turns its servo has made and not yet undone (between a servo's
    turn − and turn +, an accelerometer move to ``a`` goes to ``a − 2π·turns``: the same
    orientation, reached by the planned ``|a − from|`` of travel instead of a turn more).
    :func:`gyrocal.kit.protocol.build_steps` runs this.

    Raises
    ------
    CalibInputError
        If a pose or move names a servo beyond ``n_servos``, or an accelerometer move names a
        rest the protocol does not have.
    """
    seq = _base_sequence(plan, n_servos)
    used = [x[1] for x in seq if x[0] in ("move", "rotate")] + [m for _, m, _ in plan.accel_moves]
    if used and max(used) >= n_servos:
        raise CalibInputError(f"the plan names servo position {max(used)} beyond a chain of "
                              f"{n_servos}")
    before: dict[int, list[tuple]] = {}
    for r, moved, angle in plan.accel_moves:
        before.setdefault(int(r), []).append(("move", int(moved), float(angle)))
    out: list[tuple] = []
    r = 0
    wound = np.zeros(n_servos)  # whole turns each servo has made and not yet undone, rad
    for step in seq:
        if step[0] == "rest":
            moves = before.pop(r, [])
            if moves and out and out[-1][0] == "rotate":
                out.append(("still", ACCEL_STILL_S))  # the turn's window needs still time
            out += [("move", s, a + float(wound[s])) for _, s, a in moves]
            r += 1
        elif step[0] == "rotate":
            wound[step[1]] += step[2] * 2 * np.pi * plan.turns
        out.append(step)
    if before:
        raise CalibInputError(f"accelerometer moves name rests {sorted(before)} of a protocol "
                              f"with {r} rests")
    here = np.zeros(n_servos)
    for step in out:
        if step[0] == "move":
            here[step[1]] = step[2]
        elif step[0] == "rotate":
            here[step[1]] += step[2] * 2 * np.pi * plan.turns
    out += [("move", s, 0.0) for s in range(n_servos) if abs(here[s]) > 1e-12]
    return out


def rest_gravity(angles: np.ndarray, axes: np.ndarray | None = None,
                 up: np.ndarray | None = None) -> np.ndarray:
    """Gravity's direction in the sensor frame (N, 3) with the nominal gimbal's servos at
    ``angles`` (N, S) from home: "up" carried by every servo's rotation, as
    :meth:`gyrocal.calib.observations.ObservationSet.specific_force` carries it
    (:func:`gyrocal.calib.kinematics.chain_axes` of "up" as a joint outside the base).

    Parameters
    ----------
    angles : ndarray, shape (N, S)
        Servo angles from home, chain order, rad.
    axes : ndarray, shape (S, 3), optional
        Nominal servo axes in the sensor frame at home (default x, y, z).
    up : ndarray, shape (3,), optional
        "Up" in the sensor frame at home (default +z, hardware_docs/mechanical.md).
    """
    from gyrocal.calib.kinematics import chain_axes

    th = np.atleast_2d(np.asarray(angles, dtype=float))
    ax = np.eye(th.shape[1]) if axes is None else np.asarray(axes, dtype=float)
    u = np.array([0.0, 0.0, 1.0]) if up is None else np.asarray(up, dtype=float)
    ext = np.vstack([u / np.linalg.norm(u), ax])
    full = np.concatenate([np.zeros((th.shape[0], 1)), th], axis=1)
    return chain_axes(ext, np.zeros(ext.shape[0]), full)[:, 0]


#: The fewest rests a protocol with accelerometer rests has: the nine parameters and three
#: degrees of freedom for the consistency test (:func:`gyrocal.calib.accel.fit_accelerometer`
#: needs ten); protocols with fewer get extra rests at the end.
ACCEL_MIN_RESTS = 12

#: Still time between a turn and an accelerometer move after it, s: a rest-to-rest window of
#: the turn takes up to 0.15 s of still time after it (:func:`gyrocal.calib.windows.
#: extract_observations`' ``still_margin_s``), and the loop reads once more after a turn.
ACCEL_STILL_S = 0.2

#: Angles a servo may be moved to for an accelerometer rest, rad from home: multiples of 45°.
ACCEL_REST_ANGLES = tuple(float(a) for a in np.radians(np.arange(-135.0, 181.0, 45.0)))

#: Bound on the predicted worst-direction σ of the calibrated |f| over one rest window's σ
#: that :func:`plan_accel_rests` aims for: 2, i.e. about 0.8 mg for an MPU-9250 (300 µg/√Hz,
#: 200 Hz) with 1 s rests, against its ±60-80 mg zero-g offset and ±3 % scale (datasheet
#: Table 2). For scale: the 14-point gravity tour (:data:`gyrocal.calib.accel.TOUR_DIRECTIONS`)
#: with one rest each scores 0.81 and adds 17-22 s to a run; the default protocol's own rests
#: (two or three directions) cannot determine the nine parameters at all.
ACCEL_STD_RATIO_TARGET = 2.0


def _accel_rows(d: np.ndarray) -> np.ndarray:
    """Whitened Jacobian rows of the accelerometer fit at the ideal sensor for unit gravity
    directions ``d`` (N, 3), σ = 1 and g = 1 (:func:`gyrocal.calib.accel.accel_design`'s)."""
    il = np.tril_indices(3)
    return np.concatenate([(d[:, :, None] * d[:, None, :])[:, il[0], il[1]], d], axis=1)


def plan_accel_rests(
    plan: Plan,
    *,
    axes: np.ndarray | None = None,
    up: np.ndarray | None = None,
    max_turns: float | None = None,
    settle_s: float = 0.1,
    target_ratio: float = ACCEL_STD_RATIO_TARGET,
    beam: int = 24,
) -> Plan:
    r"""Tilt the protocol's rests so the accelerometer's nine parameters are determined.

    The rests between turns already hold the sensor still; they see gravity in only two or
    three directions. A turning servo's axis in the sensor frame depends only on the servos
    outside it (:func:`gyrocal.calib.kinematics.chain_axes`), so a servo at or inside the
    next turning servo (until that servo's next move) may be moved before a rest without
    changing any turn the gyro fit sees (:func:`predict_full_uncertainty` is unchanged); each
    such move costs its profile time plus ``settle_s``, and :data:`ACCEL_STILL_S` of still time
    first when a turn comes before it; the run ends with a move home of every servo left
    away. The rests'
    gravity directions (:func:`rest_gravity`) are chosen by a beam search over
    :data:`ACCEL_REST_ANGLES` that maximises ``log det`` of the accelerometer fit's
    information minus ``λ`` times the added time, for several ``λ``; of the results, the one
    with the least added time whose predicted worst-direction σ of ``|f|``
    (:func:`gyrocal.calib.accel.accel_design`, the G-criterion of the paper's reference
    [ye2017efficient] for this model) is within ``target_ratio`` times one rest window's σ
    is kept (else the one with the smallest σ). A protocol with fewer than
    :data:`ACCEL_MIN_RESTS` rests (the diagonal model's has seven) gets the missing ones at its
    end, their time counted in ``accel_time_s``.

    Parameters
    ----------
    plan : Plan
        The gyro protocol (its ``accel_moves`` are replaced).
    axes, up : ndarray, optional
        The nominal gimbal (:func:`rest_gravity`).
    max_turns : float, optional
        The cable-wrap limit in turns from home: a servo that turns from a moved angle ``θ``
        keeps ``turns + |θ|/2π`` within it (default: no limit).
    settle_s : float
        Settling after each move, s.
    target_ratio : float
        The σ bound above.
    beam : int
        Beam width.

    Returns
    -------
    Plan
        With ``accel_moves``, ``accel_time_s``, ``accel_std_ratio`` and ``jig_time_s``
        (increased by ``accel_time_s``).

    Raises
    ------
    CalibInputError
        If ``target_ratio`` or ``beam`` is not positive.
    """
    if not target_ratio > 0 or int(beam) < 1:
        raise CalibInputError(f"target_ratio and beam must be positive, got {target_ratio!r}, "
                              f"{beam!r}")
    gyro_time = plan.jig_time_s - plan.accel_time_s
    moves, extra, added, ratio = _accel_rest_moves(
        _turns_only(plan), _hashable(axes), _hashable(up), max_turns, settle_s, target_ratio,
        int(beam))
    return replace(plan, accel_moves=moves, accel_extra_rests=extra, accel_time_s=added,
                   accel_std_ratio=ratio, jig_time_s=float(gyro_time + added))


_Key = tuple[tuple[int, ...], tuple[float, ...]]


def _hashable(a: np.ndarray | None) -> _Key | None:
    """``a`` as its shape and its values (exact floats), a cache key."""
    if a is None:
        return None
    a = np.asarray(a, dtype=float)
    return a.shape, tuple(a.ravel().tolist())


def _array(key: _Key | None) -> np.ndarray | None:
    """The array of :func:`_hashable`."""
    return None if key is None else np.array(key[1], dtype=float).reshape(key[0])


def _turns_only(plan: Plan) -> Plan:
    """``plan`` with only what its sequence of steps depends on (speed, turns, rests, poses):
    the predicted figures, which scale with the measured noise, and its times zeroed."""
    return replace(plan, jig_time_s=0.0, scale_std=(0.0,) * 3, bias_std=(0.0,) * 3,  # type: ignore[arg-type]
                   rate_error_std=0.0, matrix_std=None, accel_moves=(), accel_extra_rests=0,
                   accel_time_s=0.0, accel_std_ratio=None)


def _accel_rest_moves(
    plan: Plan, axes_key: _Key | None, up_key: _Key | None, max_turns: float | None,
    settle_s: float, target_ratio: float, beam: int,
) -> tuple[tuple[tuple[int, int, float], ...], int, float, float]:
    """:func:`plan_accel_rests`' result, ``(accel_moves, accel_extra_rests, accel_time_s,
    accel_std_ratio)``: the beam search's results (:func:`_accel_rest_search`, which does not
    depend on the rest length), each with the time of the rests it adds, and the choice among
    them (the one with the least added time within ``target_ratio``, else the smallest σ)."""
    extra, searched = _accel_rest_search(replace(plan, rest_s=0.0), axes_key, up_key,
                                         max_turns, settle_s, beam)
    results = [(moved + extra * plan.rest_s, ratio, moves) for moved, ratio, moves in searched]
    ok = [x for x in results if x[1] <= target_ratio]
    added, ratio, moves = (min(ok, key=lambda x: (x[0], x[1])) if ok
                           else min(results, key=lambda x: (x[1], x[0])))
    return moves, extra, float(added), float(ratio)


@functools.lru_cache(maxsize=32)
def _accel_rest_search(
    plan: Plan, axes_key: _Key | None, up_key: _Key | None, max_turns: float | None,
    settle_s: float, beam: int,
) -> tuple[int, tuple[tuple[float, float, tuple[tuple[int, int, float], ...]], ...]]:
    """The beam search of :func:`plan_accel_rests`: the rests it adds, and per ``λ`` the
    moves' added time (less the gyro protocol's own moves), the predicted σ ratio and the
    moves. A pure function of the protocol's steps (not of its rest length: a rest is a step
    of the search whatever it lasts) and the nominal gimbal, cached: a plan's predicted figures
    follow the measured noise and its rest length the time budget left after the accelerometer's
    moves (:func:`plan_protocol` plans again with a shorter one), its steps mostly do not, so a
    calibration, the runs of ``gyrocal thermal`` and the emulated calibrations of one process
    search once per distinct sequence of steps."""
    from gyrocal.calib.accel import accel_design

    axes, up = _array(axes_key), _array(up_key)
    S = 3 if axes is None else len(axes)
    n_rests = sum(st[0] == "rest" for st in _base_sequence(plan, S))
    extra = max(ACCEL_MIN_RESTS - n_rests, 0)
    base = _base_sequence(replace(plan, accel_extra_rests=extra), S)
    two_pi = 2 * np.pi

    def move_time(a: float, b: float) -> float:
        return 0.0 if abs(a - b) < 1e-12 else profile_duration(abs(a - b), plan.speed,
                                                               plan.accel) + settle_s

    # Which servos each rest may move (right before it), and how far: until the servo's next
    # move, every turn must be of a servo at or outside it (its angle then changes no turn's
    # axis), and a turn of the servo itself must stay within the cable-wrap limit. A move
    # after a turn waits ACCEL_STILL_S first.
    rests = [i for i, st in enumerate(base) if st[0] == "rest"]
    still = [ACCEL_STILL_S if i and base[i - 1][0] == "rotate" else 0.0 for i in rests]
    limit: list[list[float]] = []
    for i in rests:
        row = []
        for s in range(S):
            lim = np.inf
            for st in base[i + 1:]:
                if st[0] == "move" and st[1] == s:
                    break
                if st[0] == "rotate":
                    if st[1] < s:
                        lim = -1.0
                        break
                    if st[1] == s and max_turns is not None:
                        lim = min(lim, two_pi * (max_turns - plan.turns))
            row.append(lim)
        limit.append(row)

    grid = np.array(ACCEL_REST_ANGLES)
    n_grid = grid.size
    # Every reachable pose's gravity direction and information, once: poses are grid angles.
    combos = np.stack(np.meshgrid(*[grid] * S, indexing="ij"), axis=-1).reshape(-1, S)
    rows_all = _accel_rows(rest_gravity(combos, axes, up))
    info_all = rows_all[:, :, None] * rows_all[:, None, :]
    strides = n_grid ** np.arange(S - 1, -1, -1)

    def index(a: float) -> int:
        k = int(np.argmin(np.abs(grid - a)))
        if abs(grid[k] - a) > 1e-9:
            raise CalibInputError(f"pose angle {np.degrees(a):g}° is not a multiple of 45°; "
                                  "the accelerometer's rests cannot be planned around it")
        return k

    zero = index(0.0)
    eps = 1e-6 * np.eye(9)
    # Each move's time between two grid angles, and each rest's one-servo moves within the
    # limits (servo, grid index), once: the search below asks for them tens of thousands of
    # times.
    grid_moves = [[move_time(a, b) for b in grid] for a in grid]
    reachable = [[(s, k) for s in range(S) for k in range(n_grid)
                  if abs(grid[k]) <= limit[r][s] + 1e-9] for r in range(len(rests))]
    grid_list = grid.tolist()

    def rest_step(states: list[tuple], r: int, lam: float) -> list[tuple]:
        """The beam after rest ``r``: each state as it is or with one servo moved first,
        scored together (one batched log-determinant), the best ``beam`` kept (a stable sort:
        ties keep the order of the states and their options)."""
        options = []  # (state, pose indices, time, the move or None)
        for j, (_, t, here, _, _, _) in enumerate(states):
            options.append((j, here, t, None))
            for s, k in reachable[r]:
                if k != here[s]:
                    options.append((j, here[:s] + (k,) + here[s + 1:],
                                    t + still[r] + grid_moves[here[s]][k], (r, s, grid_list[k])))
        pose = np.array([o[1] for o in options]) @ strides
        ninfo = np.stack([st[4] for st in states])[[o[0] for o in options]] + info_all[pose]
        score = (np.linalg.slogdet(ninfo + eps)[1]
                 - lam * np.array([o[2] for o in options])).tolist()
        kept = sorted(range(len(options)), key=lambda i: -score[i])[:int(beam)]
        return [(score[i], options[i][2], options[i][1],
                 states[options[i][0]][3] + ([options[i][3]] if options[i][3] else []),
                 ninfo[i], states[options[i][0]][5] + [int(pose[i])]) for i in kept]

    def search(lam: float) -> tuple[float, list[tuple[int, int, float]], list[int]]:
        # a state: (score, time, angle indices, moves, information, pose per rest)
        states: list[tuple] = [(0.0, 0.0, (zero,) * S, [], np.zeros((9, 9)), [])]
        r = 0
        for st in base:
            if st[0] == "move":
                k = index(st[2])
                states = [(sc, t + move_time(grid[here[st[1]]], st[2]),
                           here[:st[1]] + (k,) + here[st[1] + 1:], mv, info, seen)
                          for sc, t, here, mv, info, seen in states]
                continue
            if st[0] != "rest":
                continue
            states = rest_step(states, r, lam)
            r += 1
        best = min(((t + sum(move_time(grid[here[s]], 0.0) for s in range(S)), mv, seen)
                    for _, t, here, mv, _, seen in states), key=lambda x: x[0])
        return best

    # The moves the gyro protocol makes anyway (its poses), to subtract from the searched time.
    fixed = 0.0
    here0 = np.zeros(S)
    for st in base:
        if st[0] == "move":
            fixed += move_time(here0[st[1]], st[2])
            here0[st[1]] = st[2]
    results = []
    for lam in (0.0, 0.25, 0.5, 1.0, 2.0, 4.0, 8.0):
        total, moves, seen = search(lam)
        design = accel_design(rest_gravity(combos[seen], axes, up), 1.0, gravity=1.0,
                              n_sphere=500)
        ratio = design.worst_force_std if design.identifiable else np.inf
        results.append((total - fixed, ratio,
                        tuple((int(r), int(s), float(a)) for r, s, a in moves)))
    return extra, tuple(results)


# ------------------------------------------------------------- the single-servo jig's seats
#: The seats of the single-servo jig's cube (hardware_docs/single-servo.md): the servo stands
#: with its shaft vertical, and each seat puts one sensor direction up along it. A face seat
#: (``"+x"``) lays the cube on the flat adapter with that face up; an edge seat (``"+x+y"``)
#: lays it in the adapter's 90° V-block with the edge between the two faces up. Name → (the
#: sensor direction up, unit; the adapter part that holds it).
SEATS: dict[str, tuple[tuple[float, float, float], str]] = {
    "+x": ((1.0, 0.0, 0.0), "flat"),
    "+y": ((0.0, 1.0, 0.0), "flat"),
    "+z": ((0.0, 0.0, 1.0), "flat"),
    "+x+y": ((0.5**0.5, 0.5**0.5, 0.0), "V-block"),
    "+y+z": ((0.0, 0.5**0.5, 0.5**0.5), "V-block"),
    "+z+x": ((0.5**0.5, 0.0, 0.5**0.5), "V-block"),
    "+x-y": ((0.5**0.5, -(0.5**0.5), 0.0), "V-block"),
    "+y-z": ((0.0, 0.5**0.5, -(0.5**0.5)), "V-block"),
    "+z-x": ((-(0.5**0.5), 0.0, 0.5**0.5), "V-block"),
}

#: The seat sets the planner considers. ``faces`` (the flat adapter alone) sees only the
#: diagonal model: a seat's axis is a free unknown (the seating error), so each seat tells the
#: fit one number about the matrix, ``|A⁻¹ v| = 1`` for its mean reading direction ``v``, and
#: axes along x, y, z leave the three off-diagonal terms of ``AᵀA`` unseen. Six seats whose
#: ``u uᵀ`` span the symmetric matrices (faces and edges) determine all six, hence ``A`` in the
#: frame gyro-x-xy (hardware_docs/method.md §9).
SEAT_SETS: dict[str, tuple[str, ...]] = {
    "faces": ("+z", "+x", "+y"),
    "faces-edges": ("+z", "+x", "+y", "+x+y", "+y+z", "+z+x"),
    "edges": ("+x+y", "+y+z", "+z+x", "+x-y", "+y-z", "+z-x"),
    "faces-all-edges": ("+z", "+x", "+y", "+x+y", "+y+z", "+z+x", "+x-y", "+y-z", "+z-x"),
}

#: Time a user takes to re-seat the cube and press Enter, s ⚠ (assumed: lift, turn, seat,
#: confirm); counted in a single-servo plan's ``jig_time_s`` once per seat after the first.
SEAT_HANDLING_S = 10.0

#: Time budget of a single-servo plan's turns and rests (the re-seats not counted), s.
SEAT_TIME_BUDGET_S = 60.0


def seat_axes(seats: tuple[str, ...]) -> np.ndarray:
    """The nominal turning axis of each seat in the sensor frame, ``(S, 3)`` (:data:`SEATS`).

    Raises
    ------
    CalibInputError
        If a seat is not one of :data:`SEATS`.
    """
    bad = [s for s in seats if s not in SEATS]
    if bad:
        raise CalibInputError(f"seat {bad[0]!r} is not one of " + ", ".join(SEATS))
    return np.array([SEATS[s][0] for s in seats], dtype=float)


def seat_jig_time(speed: float, turns: int, rest_s: float, accel: float, n_seats: int,
                  handling_s: float = SEAT_HANDLING_S) -> float:
    """Jig time of a single-servo plan: per seat a rest, turn −, rest, turn + and a final rest
    (:func:`jig_time` with one "servo" per seat and a rest more per seat), and the re-seats."""
    turn = profile_duration(2 * np.pi * turns, speed, accel) + 0.1
    return float(n_seats * (2 * turn + 3 * rest_s) + (n_seats - 1) * handling_s)


def plan_seats(
    *,
    servo_max_speed: float,
    full_scale: float,
    model: str = "full",
    noise_std: float = 0.035,
    odr_hz: float = 200.0,
    accel: float = 10.0,
    reference_rate: float = 1.0,
    time_budget_s: float = SEAT_TIME_BUDGET_S,
    min_rest_s: float = MIN_REST_S,
    max_scale_error: float = 1.25,
) -> Plan:
    """The single-servo jig's plan: which seats of the cube, and speed, turns and rests.

    Each seat's axis is a free unknown of the fit (the cube is seated by hand: its seating
    error), exactly as each gimbal servo's axis is, so the seats are scored as that many
    independent servos with no poses: :func:`predict_uncertainty` for ``model="diagonal"``
    (the three faces, which see only the paper's model) and :func:`predict_full_uncertainty`
    for ``"full"`` over the sets of :data:`SEAT_SETS` that determine the matrix; the plan
    minimises the worst-direction σ of a calibrated rate at ``reference_rate`` within
    ``time_budget_s`` of turns and rests (the re-seats, :data:`SEAT_HANDLING_S` each, come on
    top). Arguments as :func:`plan_protocol`.

    Returns
    -------
    Plan
        With ``seats``; ``matrix_std`` for the full model.

    Raises
    ------
    CalibInputError
        If an argument is not positive, the model unknown, or nothing fits the budget.
    """
    top = _checked_top_speed(model, max_scale_error, servo_max_speed=servo_max_speed,
                             full_scale=full_scale, time_budget_s=time_budget_s,
                             noise_std=noise_std, odr_hz=odr_hz, accel=accel,
                             reference_rate=reference_rate)
    best = _plan_seats_cached(model, float(top), float(time_budget_s), float(noise_std),
                              float(odr_hz), float(accel), float(reference_rate),
                              float(min_rest_s))
    if best is None:
        raise CalibInputError(f"no single-servo protocol fits {time_budget_s:g} s of turns and "
                              f"rests with speeds up to {top:.2f} rad/s; raise the time budget")
    return best


@functools.lru_cache(maxsize=16)
def _plan_seats_cached(model: str, top: float, budget: float, noise_std: float, odr_hz: float,
                       accel: float, reference_rate: float, min_rest_s: float) -> Plan | None:
    """:func:`plan_seats`' search, once per distinct input (a plan is immutable)."""
    speeds = np.unique(np.concatenate([np.linspace(min(1.0, top), top, 6), [top]]))
    rests = sorted({min_rest_s, 1.0, 1.5})
    sets = ["faces"] if model == "diagonal" else [k for k in SEAT_SETS if k != "faces"]
    best: Plan | None = None
    for name in sets:
        seats = SEAT_SETS[name]
        S = len(seats)
        cands = [(float(sp), t, float(r)) for sp in speeds for t in (1, 2, 3) for r in rests
                 if seat_jig_time(sp, t, r, accel, S, 0.0) <= budget]
        if not cands:
            continue
        if model == "diagonal":
            preds = [predict_uncertainty(sp, t, r, noise_std=noise_std, odr_hz=odr_hz,
                                         accel=accel, reference_rate=reference_rate)
                     for sp, t, r in cands]
            err = np.array([p[2] for p in preds])
            i = int(np.argmin(err))
            ks, bs, ms = preds[i][0], preds[i][1], None
        else:
            mstd, bstd, err = predict_full_uncertainty(
                cands, (), noise_std=noise_std, odr_hz=odr_hz, accel=accel,
                reference_rate=reference_rate, axes=seat_axes(seats))
            i = int(np.argmin(err))
            ks, bs = np.diag(mstd[i]), bstd[i]
            ms = tuple(tuple(float(x) for x in row) for row in mstd[i])
        if best is not None and not err[i] < best.rate_error_std * (1 - 1e-9):
            continue
        sp, t, r = cands[i]
        best = Plan(sp, t, r, float(accel), seat_jig_time(sp, t, r, accel, S),
                    tuple(float(x) for x in ks), tuple(float(x) for x in bs),  # type: ignore[arg-type]
                    float(err[i]), float(reference_rate), matrix_std=ms, seats=seats)
    return best
