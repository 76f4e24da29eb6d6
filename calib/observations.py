"""Observations: what the estimators see of a calibration run.

A *rotation window* is a stretch of one servo's turn (whole revolutions where possible, DESIGN.md
fact 2) reduced to the mean gyro reading over the window and the encoder's mean rate over the
same window (the paper's Eq. 9: average first, then square). A *rest window* is a stretch with
every servo still: its mean reading is minus the bias.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from gyrocal.calib.errors import CalibInputError

__all__ = ["POSE_TOLERANCE_RAD", "ObservationSet", "diff_noise", "pool_noise"]


def diff_noise(x: np.ndarray, axis: int = 0) -> np.ndarray:
    """White-noise standard deviation of one sample from first differences, ``std(Δx)/√2``.

    Blind to slow motion (drift, a servo's low-frequency ripple); accumulated in float64.
    """
    d = np.diff(x, axis=axis)
    d *= d
    return np.sqrt(d.sum(axis=axis, dtype=np.float64) / (2.0 * d.shape[axis]))


def pool_noise(
    noise: np.ndarray, count: np.ndarray, alpha: float = 0.01
) -> tuple[np.ndarray, np.ndarray]:
    """Pool per-window noise estimates of each axis when they are homogeneous (Bartlett's test).

    Each window's per-sample standard deviation is an estimate with about ``count - 1`` degrees of
    freedom; when Bartlett's test does not reject equal variances across the windows of a run at
    level ``alpha``, the pooled value replaces them for that axis, so the estimator's weights do not
    carry the estimates' own scatter. Heterogeneous axes (e.g. vibration only while turning) keep
    their per-window values.

    Parameters
    ----------
    noise : ndarray, shape (..., k, 3)
        Per-window standard deviations of one sample (``...`` are independent runs).
    count : ndarray of int, shape (k,) or (..., k)
        Samples per window.
    alpha : float
        Test level.

    Returns
    -------
    noise : ndarray, same shape
        With homogeneous axes pooled.
    pooled : ndarray of bool, shape (..., 3)
        Which axes were pooled.
    """
    from scipy.special import chdtrc

    nu = np.broadcast_to(np.asarray(count, dtype=float) - 1.0, noise.shape[:-1])[..., None]
    k = noise.shape[-2]
    if k < 2:
        return noise, np.zeros(noise.shape[:-2] + (3,), dtype=bool)
    s2 = noise**2
    nsum = nu.sum(axis=-2)
    sp2 = (nu * s2).sum(axis=-2) / nsum
    M = nsum * np.log(sp2) - (nu * np.log(s2)).sum(axis=-2)
    C = 1.0 + ((1.0 / nu).sum(axis=-2) - 1.0 / nsum) / (3.0 * (k - 1))
    p = chdtrc(k - 1, M / C)
    pooled = p >= alpha
    out = np.where(pooled[..., None, :], np.sqrt(sp2)[..., None, :], noise)
    return out, pooled


def _ro(a: np.ndarray) -> np.ndarray:
    a = np.array(a, copy=True)
    a.setflags(write=False)
    return a


def _arr(
    value: object, name: str, shape: tuple[int | None, ...], dtype: type = float
) -> np.ndarray:
    try:
        a = np.asarray(value, dtype=dtype)
    except (TypeError, ValueError):
        raise CalibInputError(f"{name} must be numeric, got {value!r}") from None
    if a.ndim != len(shape) or any(
        s is not None and s != d for s, d in zip(shape, a.shape, strict=True)
    ):
        want = str(tuple("n" if s is None else s for s in shape)).replace("'", "")
        raise CalibInputError(f"{name} must have shape {want}, got {a.shape}")
    if a.dtype.kind == "f" and not np.all(np.isfinite(a)):
        bad = np.argwhere(~np.isfinite(a))[0].tolist()
        raise CalibInputError(f"{name} contains NaN or inf (first at index {bad})")
    return a


#: Two turns of one servo share a gimbal pose when every other servo's angle agrees within this,
#: rad, modulo whole turns (:meth:`ObservationSet.pose_groups`): 14 encoder ticks of an X-series
#: servo (4096 a turn), far below any pose step a protocol makes.
POSE_TOLERANCE_RAD = 0.02


@dataclass(frozen=True, eq=False)
class ObservationSet:
    """Rotation windows and rest windows of one calibration run.

    Parameters
    ----------
    mean : array_like, shape (n, 3)
        Mean gyro reading over each rotation window, rad/s (datasheet sensitivity only).
    rate : array_like, shape (n,)
        The encoder's mean rate over the same window, rad/s, signed: positive in the servo's
        positive direction.
    motor : array_like of int, shape (n,)
        Dynamixel ID of the servo that turned.
    direction : array_like of int, shape (n,)
        +1 or -1, the commanded direction; must agree with the sign of ``rate``.
    count : array_like of int, shape (n,)
        Gyro samples in the window.
    noise : array_like, shape (n, 3)
        In-window noise estimate: standard deviation of one sample, rad/s, per axis.
    mean_std : array_like, shape (n, 3), optional
        Standard error of ``mean``; defaults to ``noise / sqrt(count)`` (white noise).
    rate_std : array_like, shape (n,), optional
        Standard error of ``rate`` (encoder quantisation and timing); defaults to 0.
    rest_mean, rest_count, rest_noise, rest_mean_std : optional
        The same for rest windows (shapes (r, 3), (r,), (r, 3), (r, 3)).
    temperature_c : float, optional
        Mean die temperature over the run.
    ref_start, ref_end : array_like of int, shape (n,), optional
        For a window whose reference is the change between two still encoder angles (a
        rest-to-rest window), the index of the still angle it starts and ends at; -1 where the
        reference does not rest on a still angle. Consecutive turns of one servo share the still
        angle between them, so their reference errors are correlated; estimators model each still
        angle's error as one shared unknown with prior ``still_angle_std``.
    ref_gain : array_like, shape (n,), optional
        Change of the reference rate per radian of error in a still angle (``1 / ∫w``).
    still_angle_std : float, optional
        Prior standard deviation of a still encoder angle, rad (``q/√12``).
    chain : sequence of int, optional
        The gimbal's servo IDs in chain order, base first (Recording v1 ``gimbal.motors``).
    pose : array_like, shape (n, S), optional
        Encoder angle of every servo of ``chain`` over each window (its mean over the window),
        rad, cumulative: the pose that carries the turning servo's axis in the sensor frame
        (:mod:`gyrocal.calib.kinematics`). Given together with ``chain``.
    pose_still : array_like of int, shape (n, S), optional
        For each window and servo of the chain, the index of the still angle that servo held
        during the window (the same numbering as ``ref_start``/``ref_end``: one still period of
        one servo is one unknown, its reading error with prior ``still_angle_std``); -1 for the
        turning servo, or where the pose is taken as exact. Default: all -1.
    rest_pose : array_like, shape (r, S), optional
        Every servo's encoder angle over each rest window (chain order), rad: where gravity
        points in the sensor frame during the rest (g-sensitivity, :meth:`specific_force`).
    home_pose : array_like, shape (S,), optional
        Every servo's encoder angle in the home pose (the recording's first readings), rad.
    turn_phase : array_like, shape (n, 2), optional
        Per rotation window, the window-weighted means of ``cos φ`` and ``sin φ``, ``φ`` the
        turning servo's angle less its ``pose`` angle: how far the window is from whole
        revolutions (both 0 over whole revolutions at constant speed; the default).
    nod, nod_std : array_like, shape (n, 2, 3), optional
        Per rotation window, the reading's once-per-revolution part per unit rate: the
        least-squares coefficients of ``θ̇ cos θ`` and ``θ̇ sin θ`` (rows), ``θ`` the turning
        servo's encoder angle, and their standard errors; given together. What a nod of the
        turning servo's link shows (:mod:`gyrocal.calib.systematics` measures and removes it).
    nod_removed : bool
        The nods the windows measure have been taken out of ``mean``
        (:func:`gyrocal.calib.systematics.remove_nod`), so a fit's σ holds the measurement's
        error, not the prior of an unmeasured nod.
    gravity : tuple of int, optional
        ``(servo ID, sign)``: in the home pose, "up" (the specific force of a still sensor, +1 g)
        points along ``sign`` times that servo's positive axis (the gimbal stands with that axis
        vertical). With ``rest_pose`` and ``home_pose`` it lets the full-matrix fit model
        g-sensitivity; without it, none is fitted.
    force, rest_force : array_like, shape (n, 3) and (r, 3), optional
        The mean specific force of each window and rest, g, sensor frame, when it is known
        otherwise than through a gimbal's kinematics (the single-servo jig: gravity read by the
        accelerometer in each seat, :meth:`by_seat`); given together. The full-matrix fit then
        models g-sensitivity with them.
    temp_offset, rest_temp_offset : array_like, shape (n,) and (r,), optional
        Each window's and rest's mean die temperature less the run's mean ``temperature_c``,
        °C, where :func:`gyrocal.calib.thermal.correct_drift` referred the windows to the mean
        with a drift slope measured on the rests; given together. The slope's error then
        offsets every window in proportion to these, which
        :func:`gyrocal.calib.estimators.fit_paired_axis` fits as a nuisance where it tests
        whether the data need g-sensitivity.
    own_axes : bool
        Each rotation window turns about an axis of its own (:meth:`pose_groups`): a hand jig,
        where nothing holds the axis from one turn to the next (:mod:`gyrocal.calib.hand`).

    Raises
    ------
    CalibInputError
        On mismatched shapes, NaN or inf, counts below 2, non-positive noise, a direction that is
        not ±1 or disagrees with the sign of ``rate``.
    """

    mean: np.ndarray
    rate: np.ndarray
    motor: np.ndarray
    direction: np.ndarray
    count: np.ndarray
    noise: np.ndarray
    mean_std: np.ndarray | None = None
    rate_std: np.ndarray | None = None
    rest_mean: np.ndarray | None = None
    rest_count: np.ndarray | None = None
    rest_noise: np.ndarray | None = None
    rest_mean_std: np.ndarray | None = None
    temperature_c: float | None = None
    ref_start: np.ndarray | None = None
    ref_end: np.ndarray | None = None
    ref_gain: np.ndarray | None = None
    still_angle_std: float = 0.0
    chain: tuple[int, ...] | None = None
    pose: np.ndarray | None = None
    pose_still: np.ndarray | None = None
    rest_pose: np.ndarray | None = None
    home_pose: np.ndarray | None = None
    gravity: tuple[int, int] | None = None
    turn_phase: np.ndarray | None = None
    nod: np.ndarray | None = None
    nod_std: np.ndarray | None = None
    nod_removed: bool = False
    force: np.ndarray | None = None
    rest_force: np.ndarray | None = None
    own_axes: bool = False
    temp_offset: np.ndarray | None = None
    rest_temp_offset: np.ndarray | None = None

    def __post_init__(self) -> None:
        mean = _arr(self.mean, "mean", (None, 3))
        n = mean.shape[0]
        rate = _arr(self.rate, "rate", (n,))
        motor = _arr(self.motor, "motor", (n,), dtype=np.int64)
        direction = _arr(self.direction, "direction", (n,), dtype=np.int64)
        count = _arr(self.count, "count", (n,), dtype=np.int64)
        noise = _arr(self.noise, "noise", (n, 3))
        if not np.all(np.isin(direction, (-1, 1))):
            raise CalibInputError("direction must be +1 or -1 for every window")
        wrong = np.flatnonzero(np.sign(rate) != direction)
        if wrong.size:
            i = int(wrong[0])
            raise CalibInputError(
                f"window {i}: reference rate {rate[i]:+.4f} rad/s disagrees with direction "
                f"{direction[i]:+d}; check the encoder sign or the segment table"
            )
        if np.any(count < 2):
            raise CalibInputError("every window needs at least 2 gyro samples")
        if np.any(noise <= 0):
            raise CalibInputError("noise must be positive (a constant signal means a stuck axis)")
        if self.mean_std is None:
            mean_std = noise / np.sqrt(count)[:, None]
        else:
            mean_std = _arr(self.mean_std, "mean_std", (n, 3))
            if np.any(mean_std <= 0):
                raise CalibInputError("mean_std must be positive")
        if self.rate_std is None:
            rate_std = np.zeros(n)
        else:
            rate_std = _arr(self.rate_std, "rate_std", (n,))
            if np.any(rate_std < 0):
                raise CalibInputError("rate_std must not be negative")

        if self.rest_mean is None:
            if any(v is not None for v in (self.rest_count, self.rest_noise, self.rest_mean_std)):
                raise CalibInputError("rest_count/rest_noise given without rest_mean")
            r_mean = np.zeros((0, 3))
            r_count = np.zeros(0, dtype=np.int64)
            r_noise = np.zeros((0, 3))
            r_std = np.zeros((0, 3))
        else:
            r_mean = _arr(self.rest_mean, "rest_mean", (None, 3))
            r = r_mean.shape[0]
            if self.rest_count is None or self.rest_noise is None:
                raise CalibInputError("rest windows need rest_count and rest_noise")
            r_count = _arr(self.rest_count, "rest_count", (r,), dtype=np.int64)
            r_noise = _arr(self.rest_noise, "rest_noise", (r, 3))
            if np.any(r_count < 2):
                raise CalibInputError("every rest window needs at least 2 gyro samples")
            if np.any(r_noise <= 0):
                raise CalibInputError("rest_noise must be positive")
            if self.rest_mean_std is None:
                r_std = r_noise / np.sqrt(r_count)[:, None]
            else:
                r_std = _arr(self.rest_mean_std, "rest_mean_std", (r, 3))
                if np.any(r_std <= 0):
                    raise CalibInputError("rest_mean_std must be positive")
        if self.ref_start is None and self.ref_end is None:
            ref_start = ref_end = np.full(n, -1, dtype=np.int64)
            ref_gain = np.zeros(n)
        else:
            if self.ref_start is None or self.ref_end is None or self.ref_gain is None:
                raise CalibInputError("ref_start, ref_end and ref_gain go together")
            ref_start = _arr(self.ref_start, "ref_start", (n,), dtype=np.int64)
            ref_end = _arr(self.ref_end, "ref_end", (n,), dtype=np.int64)
            ref_gain = _arr(self.ref_gain, "ref_gain", (n,))
            if np.any(ref_start < -1) or np.any(ref_end < -1):
                raise CalibInputError("ref_start and ref_end must be -1 or still-angle indices")
            used = np.concatenate([ref_start[ref_start >= 0], ref_end[ref_end >= 0]])
            if used.size and not (self.still_angle_std > 0):
                raise CalibInputError("still_angle_std must be positive when still angles are used")
        chain, pose, pose_still = self._chain_pose(n, motor)
        temp = self.temperature_c
        if temp is not None:
            temp = float(temp)
            if not np.isfinite(temp):
                raise CalibInputError("temperature_c must be finite")
        for name, v in (
            ("mean", mean), ("rate", rate), ("motor", motor), ("direction", direction),
            ("count", count), ("noise", noise), ("mean_std", mean_std), ("rate_std", rate_std),
            ("rest_mean", r_mean), ("rest_count", r_count), ("rest_noise", r_noise),
            ("rest_mean_std", r_std), ("ref_start", ref_start), ("ref_end", ref_end),
            ("ref_gain", ref_gain),
        ):
            object.__setattr__(self, name, _ro(v))
        object.__setattr__(self, "temperature_c", temp)
        object.__setattr__(self, "chain", chain)
        object.__setattr__(self, "pose", None if pose is None else _ro(pose))
        object.__setattr__(self, "pose_still", None if pose_still is None else _ro(pose_still))
        if pose_still is not None and np.any(pose_still >= 0) and not self.still_angle_std > 0:
            raise CalibInputError("still_angle_std must be positive when pose_still is used")
        self._gravity_fields(r_mean.shape[0])
        self._force_fields(n, r_mean.shape[0])
        self._temp_offset_fields(n, r_mean.shape[0])
        self._nod_fields(n)

    def _nod_fields(self, n: int) -> None:
        """Check and freeze ``nod`` and ``nod_std``."""
        if self.nod is None and self.nod_std is None:
            return
        if self.nod is None or self.nod_std is None:
            raise CalibInputError("nod and nod_std go together")
        nod_std = _arr(self.nod_std, "nod_std", (n, 2, 3))
        if np.any(nod_std <= 0):
            raise CalibInputError("nod_std must be positive")
        object.__setattr__(self, "nod", _ro(_arr(self.nod, "nod", (n, 2, 3))))
        object.__setattr__(self, "nod_std", _ro(nod_std))

    def _temp_offset_fields(self, n: int, r: int) -> None:
        """Check and freeze ``temp_offset`` and ``rest_temp_offset``."""
        if self.temp_offset is None and self.rest_temp_offset is None:
            return
        if self.temp_offset is None or self.rest_temp_offset is None:
            raise CalibInputError("temp_offset and rest_temp_offset go together")
        object.__setattr__(self, "temp_offset", _ro(_arr(self.temp_offset, "temp_offset", (n,))))
        object.__setattr__(self, "rest_temp_offset", _ro(_arr(
            self.rest_temp_offset, "rest_temp_offset", (r,))))

    def _force_fields(self, n: int, r: int) -> None:
        """Check and freeze ``force`` and ``rest_force``."""
        if self.force is None and self.rest_force is None:
            return
        if self.force is None or self.rest_force is None:
            raise CalibInputError("force and rest_force go together")
        object.__setattr__(self, "force", _ro(_arr(self.force, "force", (n, 3))))
        object.__setattr__(self, "rest_force", _ro(_arr(self.rest_force, "rest_force", (r, 3))))

    def _gravity_fields(self, r: int) -> None:
        """Check and freeze ``rest_pose``, ``home_pose`` and ``gravity``."""
        given = [v is not None for v in (self.rest_pose, self.home_pose, self.gravity)]
        if not any(given):
            return
        if self.chain is None:
            raise CalibInputError("rest_pose, home_pose and gravity need chain and pose")
        S = len(self.chain)
        if self.rest_pose is not None:
            object.__setattr__(self, "rest_pose", _ro(_arr(self.rest_pose, "rest_pose", (r, S))))
        if self.home_pose is not None:
            object.__setattr__(self, "home_pose", _ro(_arr(self.home_pose, "home_pose", (S,))))
        if self.turn_phase is not None:
            object.__setattr__(self, "turn_phase", _ro(_arr(
                self.turn_phase, "turn_phase", (self.n_windows, 2))))
        if self.gravity is not None:
            try:
                sid, sign = (int(x) for x in self.gravity)
            except (TypeError, ValueError):
                raise CalibInputError(
                    f"gravity must be (servo ID, ±1), got {self.gravity!r}") from None
            if sid not in self.chain or sign not in (-1, 1):
                raise CalibInputError(
                    f"gravity must name a servo of the chain {self.chain} and a sign ±1, got "
                    f"{self.gravity!r}")
            object.__setattr__(self, "gravity", (sid, sign))

    @property
    def has_gravity(self) -> bool:
        """Whether the set says where gravity points in every window (g-sensitivity can be
        modelled): ``gravity``, ``home_pose`` and, when there are rests, ``rest_pose``."""
        return (self.gravity is not None and self.home_pose is not None and self.pose is not None
                and (self.n_rests == 0 or self.rest_pose is not None))

    def specific_force(self, axes: np.ndarray, reference: np.ndarray
                       ) -> tuple[np.ndarray, np.ndarray]:
        r"""Mean specific force of a still-or-turning sensor in each window, in g, sensor frame.

        "Up" is ``gravity``'s servo axis in the home pose (``γ_h = ±u_k(θ_h)``); in any pose
        ``θ`` it is carried by every servo's rotation from the home pose, like the axis of a joint
        outside the base (:mod:`gyrocal.calib.kinematics`):
        ``γ(θ) = Rot(u_{S-1}, −Δ_{S-1}) ⋯ Rot(u_0, −Δ_0) γ_h`` with ``Δ = θ − θ_h`` and the axes
        at ``θ_h``. A rest sees ``γ(θ_r)``; a turn of servo ``j`` sees
        ``Rot(u_j, −φ) γ`` averaged over its window, ``γ c̄ − (u_j × γ) s̄ + u_j (u_j·γ)(1 − c̄)``
        with ``(c̄, s̄)`` = :attr:`turn_phase`: over whole revolutions the component along the
        turning axis, ``(u_j·γ) u_j``. The lever arm's centripetal
        term ``ω²r⊥/g₀`` is not included (at 40 mm and 3 rad/s it is 0.037 g).

        Parameters
        ----------
        axes : ndarray, shape (S, 3)
            The servos' axes in the sensor frame at ``reference`` (a fit's kinematics).
        reference : ndarray, shape (S,)
            Their reference angles, rad.

        Returns
        -------
        force : ndarray, shape (n, 3)
            Per rotation window.
        rest_force : ndarray, shape (r, 3)
            Per rest window.

        Raises
        ------
        CalibInputError
            If the set does not say where gravity points (:attr:`has_gravity`).
        """
        from gyrocal.calib.kinematics import carried_up, chain_axes

        if not self.has_gravity:
            raise CalibInputError(
                "the observations do not say where gravity points (gravity, home_pose, "
                "rest_pose); g-sensitivity cannot be modelled")
        chain = list(self.chain)  # type: ignore[arg-type]
        sid, sign = self.gravity  # type: ignore[misc]
        axes = np.asarray(axes, dtype=float)

        home = np.asarray(self.home_pose, dtype=float)
        up = sign * chain_axes(axes, reference, home)[chain.index(sid)]

        def carried(theta: np.ndarray) -> np.ndarray:
            return carried_up(axes, reference, home, up, theta)

        pose = np.asarray(self.pose, dtype=float)
        g_win = carried(pose)
        u_win = chain_axes(axes, reference, pose)[np.arange(self.n_windows), self.motor_index]
        c, s = (np.zeros((self.n_windows, 1)),) * 2 if self.turn_phase is None else (
            np.asarray(self.turn_phase)[:, :1], np.asarray(self.turn_phase)[:, 1:])
        force = (g_win * c - np.cross(u_win, g_win) * s
                 + u_win * np.sum(u_win * g_win, axis=1, keepdims=True) * (1 - c))
        rest = (carried(np.asarray(self.rest_pose, dtype=float)) if self.n_rests
                else np.zeros((0, 3)))
        return force, rest

    def _chain_pose(
        self, n: int, motor: np.ndarray
    ) -> tuple[tuple[int, ...] | None, np.ndarray | None, np.ndarray | None]:
        if self.chain is None and self.pose is None:
            if self.pose_still is not None:
                raise CalibInputError("pose_still needs chain and pose")
            return None, None, None
        if self.chain is None or self.pose is None:
            raise CalibInputError("chain and pose go together")
        try:
            chain = tuple(int(c) for c in self.chain)
        except (TypeError, ValueError):
            raise CalibInputError(f"chain must be servo IDs, got {self.chain!r}") from None
        if not chain or len(set(chain)) != len(chain):
            raise CalibInputError(f"chain must list distinct servo IDs, got {chain}")
        missing = sorted(set(motor.tolist()) - set(chain))
        if missing:
            raise CalibInputError(f"servos {missing} turned but are not in the chain {chain}")
        pose = _arr(self.pose, "pose", (n, len(chain)))
        if self.pose_still is None:
            still = np.full(pose.shape, -1, dtype=np.int64)
        else:
            still = _arr(self.pose_still, "pose_still", pose.shape, dtype=np.int64)
            if np.any(still < -1):
                raise CalibInputError("pose_still must be -1 or still-angle indices")
        return chain, pose, still

    def pose_groups(self, tolerance_rad: float = POSE_TOLERANCE_RAD) -> np.ndarray:
        """A group number per rotation window: one group per servo and gimbal pose.

        Two windows are in one group when the same servo turned with every servo outside it
        in :attr:`chain` at the same angle, within ``tolerance_rad`` and modulo whole turns
        (the servo then turned about one axis in the sensor frame: the servos inside it move
        the sensor and the axis together, :func:`gyrocal.calib.kinematics.chain_axes`);
        without poses, one group per servo; with :attr:`own_axes`, one group per window.
        Groups are numbered in the order of their first window.

        Returns
        -------
        ndarray of int, shape (n,)
        """
        if self.own_axes:
            return np.arange(self.n_windows, dtype=np.int64)
        chain = [int(c) for c in (self.chain or ())]
        reps: list[tuple[int, np.ndarray | None]] = []
        out = np.zeros(self.n_windows, dtype=np.int64)
        for i, m in enumerate(int(x) for x in self.motor):
            pose = None
            if self.pose is not None and m in chain:
                pose = np.asarray(self.pose[i], dtype=float)[chain.index(m) + 1:]
            for g, (motor, rep) in enumerate(reps):
                if motor == m and (pose is None or rep is None or np.all(
                        np.abs((pose - rep + np.pi) % (2 * np.pi) - np.pi) < tolerance_rad)):
                    out[i] = g
                    break
            else:
                out[i] = len(reps)
                reps.append((m, pose))
        return out

    @property
    def motor_index(self) -> np.ndarray:
        """Each window's servo as its position in :attr:`chain` (base = 0).

        Raises
        ------
        CalibInputError
            If the set has no chain.
        """
        if self.chain is None:
            raise CalibInputError("the observations carry no gimbal chain")
        order = {m: i for i, m in enumerate(self.chain)}
        return np.array([order[int(m)] for m in self.motor], dtype=np.int64)

    @property
    def n_still_angles(self) -> int:
        """Number of shared still angles the references and poses rest on."""
        m = max(int(self.ref_start.max(initial=-1)), int(self.ref_end.max(initial=-1)))  # type: ignore[union-attr]
        if self.pose_still is not None:
            m = max(m, int(self.pose_still.max(initial=-1)))
        return m + 1

    def reference_covariance(self) -> np.ndarray:
        """Covariance of the reference rates, (n, n): ``diag(rate_std²) + G Q Gᵀ`` with ``G`` the
        rate change per still-angle error (±ref_gain) and ``Q = still_angle_std² I``."""
        G = self.reference_matrix()
        return np.diag(self.rate_std**2) + self.still_angle_std**2 * G @ G.T  # type: ignore[operator]

    def reference_matrix(self) -> np.ndarray:
        """``G`` (n, A): d(reference rate)/d(still-angle reading error)."""
        n, A = self.n_windows, self.n_still_angles
        G = np.zeros((n, A))
        rows = np.arange(n)
        s, e = self.ref_start, self.ref_end
        G[rows[e >= 0], e[e >= 0]] += self.ref_gain[e >= 0]  # type: ignore[index]
        G[rows[s >= 0], s[s >= 0]] -= self.ref_gain[s >= 0]  # type: ignore[index]
        return G

    @property
    def n_windows(self) -> int:
        """Number of rotation windows."""
        return int(self.mean.shape[0])

    @property
    def n_rests(self) -> int:
        """Number of rest windows."""
        return int(self.rest_mean.shape[0])  # type: ignore[union-attr]

    @property
    def motors(self) -> tuple[int, ...]:
        """The servo IDs that turned, in order of first appearance."""
        _, first = np.unique(self.motor, return_index=True)
        return tuple(int(self.motor[i]) for i in sorted(first))

    def by_seat(self, seat: np.ndarray, rest_seat: np.ndarray | None = None,
                seat_force: np.ndarray | None = None) -> ObservationSet:
        """The windows of a single-servo run with each seat of the cube as its own axis.

        On the single-servo jig the user re-seats the sensor between groups of turns of the one
        servo (:data:`gyrocal.calib.design.SEATS`); its axis in the sensor frame differs per
        seat by the seat's turn and its seating error, both unknown to the fit, exactly as each
        servo's axis of a gimbal is. So a window's "servo" becomes its seat number (``seat``,
        one per window, 1-based), and the chain is the seats with no poses (each seat's axis a
        free unit vector; :func:`gyrocal.calib.estimators.fit_full_matrix` and
        :func:`~gyrocal.calib.estimators.fit_paired_axis` then fit them as they fit servos).
        The rests, the references and their still angles are unchanged; the gravity fields
        (a gimbal's) are dropped.

        With ``rest_seat`` (each rest's seat) and ``seat_force`` (``(S, 3)``: the specific force
        in each seat, g, as the accelerometer read it at rest), every window and rest gets its
        seat's force (:attr:`force`): the shaft is vertical, so a turn over whole revolutions
        sees gravity along its axis all the time, as the rests do, and the full-matrix fit
        models g-sensitivity ``G f`` with them (without, ``G u`` of each seat would be a
        different bias per seat).

        Raises
        ------
        CalibInputError
            If ``seat`` is not one positive integer per window, or ``rest_seat`` and
            ``seat_force`` do not match.
        """
        seat = np.asarray(seat)
        if seat.shape != (self.n_windows,) or not np.all(seat == np.round(seat)) or (
                seat.size and seat.min() < 1):
            raise CalibInputError(f"seat must give one seat number (1, 2, ...) per window "
                                  f"({self.n_windows}), got shape {seat.shape}")
        seat = seat.astype(np.int64)
        chain = tuple(int(s) for s in np.unique(seat))
        force: dict[str, Any] = {}
        if seat_force is not None or rest_seat is not None:
            sf = np.asarray(seat_force, dtype=float)
            rs = np.asarray(rest_seat)
            if (sf.ndim != 2 or sf.shape[1] != 3 or rs.shape != (self.n_rests,)
                    or not np.all(np.isfinite(sf))
                    or (rs.size and not 1 <= rs.min() <= rs.max() <= sf.shape[0])
                    or seat.max() > sf.shape[0]):
                raise CalibInputError(
                    f"seat_force must be (seats, 3) finite and rest_seat one seat number per "
                    f"rest ({self.n_rests}) within them, got {sf.shape} and {rs.shape}")
            force = {"force": sf[seat - 1], "rest_force": sf[rs.astype(np.int64) - 1]}
        return replace(self, motor=seat, chain=chain, pose=np.zeros((seat.size, len(chain))),
                       pose_still=None, rest_pose=None, home_pose=None, gravity=None,
                       nod=None, nod_std=None, **force)

    def with_pooled_noise(self, alpha: float = 0.01) -> ObservationSet:
        """The same set with each axis's noise pooled over all windows and rests where they are
        homogeneous (:func:`pool_noise`); standard errors scale with the noise."""
        noise_all = np.concatenate([self.noise, self.rest_noise], axis=0)  # type: ignore[list-item]
        count_all = np.concatenate([self.count, self.rest_count])  # type: ignore[list-item]
        pooled, _ = pool_noise(noise_all, count_all, alpha)
        n = self.n_windows
        ratio = pooled / noise_all
        return replace(
            self, noise=pooled[:n], mean_std=self.mean_std * ratio[:n], rest_noise=pooled[n:],
            rest_mean_std=self.rest_mean_std * ratio[n:],  # type: ignore[operator]
        )
