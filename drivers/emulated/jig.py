"""The jig's physics: a three-axis gimbal of servos carrying the sensor, as a motion source.

A serial chain of servo joints from the base to the tip; the sensor is mounted on the last
link with a small misalignment. With ``R_j(θ)`` the rotation of joint ``j`` about its axis
``a_j`` (a unit vector in the frame of the link before it) and ``R_1..i`` the product of the
first ``i`` joints' rotations, the sensor's orientation in the base frame is
``R_sensor(t) = R_1..n(t) · M · S(t)`` (``M`` the mount misalignment, ``S`` a slip of the mount,
identity until it happens) and its true angular rate in its own frame is

    ω_sensor = R_sensor(t)ᵀ Σ_i R_1..i−1(t) a_i θ̇_i(t)   (+ the slip's own rate while it slips).

With only servo ``i`` turning and the joints after it at home, ``ω_sensor = u_i θ̇_i`` with the
constant axis ``u_i = (R_i+1..n M S)ᵀ a_i``: in the home pose ``u_i = Mᵀ a_i`` (:attr:`home_axes`),
which is the truth a calibration test compares with.

**Wobble** (``wobble_deg``): each joint's link is tilted by ``ψ_i = ε sin θ_i`` about an axis
``e_i ⊥ a_i`` fixed to the turning link, so the joint's rotation is ``R(a_i, θ_i) R(e_i, ψ_i)``:
the turning platform nods once per revolution and is level again in the home pose
(``θ_i = 0``), so :attr:`home_axes` stay the truth (to ``ε²/4`` over a whole turn).

**Specific force** (:meth:`specific_force`): what an accelerometer at the sensor reads, in g, in
the sensor frame: gravity (+1 g along the base's +z) in the sensor's true orientation plus the
lever-arm acceleration ``α × r + ω × (ω × r)`` of a sensor ``r`` (``lever_arm_m``, sensor frame)
away from the point where the joint axes meet.

Joint angles and rates come from the servos' motor models (:meth:`EmulatedServo.true_motion`),
whose angle is the exact integral of their rate, so the sensor's true rate and the encoders are
consistent to the last bit. Everything is vectorised over the requested times.

**Looking ahead**: an emulated chip may compute its samples before the clock reaches them
(:meth:`GimbalJig.rate` and :meth:`GimbalJig.specific_force` with ``peek=True``: the servos'
motion as planned now, nothing frozen, no timed event applied). :meth:`GimbalJig.lookahead`
says what such values depend on (it changes when a servo is commanded or the mount slips), and
:meth:`GimbalJig.due_by` whether a servo's timed event falls before a time; when neither
stops it, :meth:`GimbalJig.touch` does what reading the motion then would have done, and the
values are exactly those of a read at that time.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Protocol

import numpy as np

__all__ = ["STANDARD_GRAVITY", "GimbalJig", "Joint", "Slip", "rotation_matrices",
           "rotvec_to_matrix"]

#: Standard gravity, m/s² (the "g" of :meth:`GimbalJig.specific_force`).
STANDARD_GRAVITY = 9.80665

_NAMED_AXES = {
    "x": (1.0, 0.0, 0.0), "y": (0.0, 1.0, 0.0), "z": (0.0, 0.0, 1.0),
    "-x": (-1.0, 0.0, 0.0), "-y": (0.0, -1.0, 0.0), "-z": (0.0, 0.0, -1.0),
}


class Joint(Protocol):
    """What the jig needs of a servo: its ID and its true shaft motion."""

    @property
    def dxl_id(self) -> int:
        """The servo's ID."""
        ...

    def true_motion(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Shaft angle (rad) and rate (rad/s) at the times ``t``."""
        ...


def _peeks(joint: object) -> bool:
    """Whether a joint can be looked ahead on (an :class:`EmulatedServo`)."""
    return all(hasattr(joint, a) for a in ("peek_motion", "motion_revision", "next_due",
                                           "touch"))


def _skew(a: np.ndarray) -> np.ndarray:
    """The matrix ``K`` with ``K v = a × v``."""
    return np.array([[0.0, -a[2], a[1]], [a[2], 0.0, -a[0]], [-a[1], a[0], 0.0]])


def rotation_matrices(axis: np.ndarray, angle: np.ndarray) -> np.ndarray:
    """Rotations by ``angle`` (N,) about the unit ``axis`` (3,), shape (N, 3, 3) (Rodrigues)."""
    k = _skew(np.asarray(axis, dtype=float))
    th = np.asarray(angle, dtype=float).reshape(-1)
    s = np.sin(th)[:, None, None]
    c = (1.0 - np.cos(th))[:, None, None]
    return np.eye(3)[None] + s * k[None] + c * (k @ k)[None]


def _rotate_back(v: np.ndarray, axis: np.ndarray, skew_t: np.ndarray,
                 angle: np.ndarray) -> np.ndarray:
    """``R(axis, angle)ᵀ v`` for each row of ``v`` (Rodrigues, rotation by ``-angle``);
    ``skew_t`` is ``_skew(axis).T`` so that ``v @ skew_t`` is ``axis × v`` row by row."""
    c = np.cos(angle)[:, None]
    s = np.sin(angle)[:, None]
    return v * c - (v @ skew_t) * s + (v @ axis)[:, None] * axis * (1.0 - c)


def rotvec_to_matrix(rotvec: Sequence[float] | np.ndarray) -> np.ndarray:
    """The rotation matrix of a rotation vector (axis × angle in rad)."""
    rv = np.asarray(rotvec, dtype=float).reshape(3)
    angle = float(np.linalg.norm(rv))
    if angle == 0.0:
        return np.eye(3)
    return rotation_matrices(rv / angle, np.array([angle]))[0]


def _perpendicular(a: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """A random unit vector perpendicular to the unit vector ``a``."""
    v = rng.standard_normal(3)
    v -= (v @ a) * a
    return v / np.linalg.norm(v)


def _random_rotvec(rng: np.random.Generator, angle_rad: float) -> np.ndarray:
    v = rng.standard_normal(3)
    return v / np.linalg.norm(v) * angle_rad


@dataclass(frozen=True)
class Slip:
    """A slip of the sensor's mount: it turns by ``rotvec`` (sensor frame, rad) between
    ``t_start`` and ``t_start + duration_s`` at a constant rate (``duration_s`` 0 = a jump)."""

    t_start: float
    rotvec: np.ndarray
    duration_s: float = 0.01

    def progress(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Fraction of the slip done at ``t`` and its time derivative."""
        if self.duration_s <= 0:
            return (t >= self.t_start).astype(float), np.zeros_like(t)
        s = np.clip((t - self.t_start) / self.duration_s, 0.0, 1.0)
        ds = np.where((t >= self.t_start) & (t < self.t_start + self.duration_s),
                      1.0 / self.duration_s, 0.0)
        return s, ds


class GimbalJig:
    """Servo joints carrying the sensor: a :class:`~gyrocal.drivers.emulated.motion.MotionSource`.

    Parameters
    ----------
    joints : sequence of Joint
        The servos from the base to the tip (normally :class:`EmulatedServo`).
    axes : sequence or None
        Each joint's nominal axis in the home pose, in the sensor's frame before the mount
        misalignment: ``"x"``, ``"-y"``, … or a 3-vector. Default ``x, y, z`` in chain order
        (servo IDs 1, 2, 3 turn about sensor x, y, z).
    tilt_deg : float or sequence of 3-vectors
        Small tilts of the joint axes off the nominal ones: a magnitude in degrees (each axis is
        tilted that much in a random direction from ``seed``), or explicit rotation vectors
        (rad) applied to each nominal axis.
    mount : float or 3-vector
        The sensor's mounting misalignment: a magnitude in degrees (random axis from ``seed``)
        or a rotation vector in rad.
    seed : int
        Seed for the random tilts and mount.
    home_time : float or None
        The time whose joint angles define the home pose (joint angle 0); default the present
        time of the first joint's clock (or 0 for joints without a clock).
    wobble_deg : float
        Once-per-revolution tilt amplitude ``ε`` of every joint's link, degrees (0 = none);
        the tilt axes ``e_i ⊥ a_i`` are drawn from ``seed``.
    lever_arm_m : 3-vector
        The sensor's position relative to the meeting point of the joint axes, in the sensor
        frame, m (for :meth:`specific_force`).
    """

    def __init__(
        self,
        joints: Sequence[Joint],
        *,
        axes: Sequence[str | Sequence[float]] | None = None,
        tilt_deg: float | Sequence[Sequence[float]] = 0.3,
        mount: float | Sequence[float] = 3.0,
        seed: int = 0,
        home_time: float | None = None,
        wobble_deg: float = 0.0,
        lever_arm_m: Sequence[float] = (0.0, 0.0, 0.0),
    ) -> None:
        self.joints = list(joints)
        n = len(self.joints)
        if n == 0:
            raise ValueError("a jig needs at least one joint")
        rng = np.random.default_rng([int(seed), 0x316])
        if axes is None:
            if n > 3:
                raise ValueError("give the axes of a jig with more than three joints")
            axes = ["x", "y", "z"][:n]
        if len(axes) != n:
            raise ValueError(f"{n} joints need {n} axes, got {len(axes)}")
        nominal = []
        for spec in axes:
            if isinstance(spec, str):
                if spec not in _NAMED_AXES:
                    raise ValueError(f"axis {spec!r} is not one of {sorted(_NAMED_AXES)}")
                v = np.array(_NAMED_AXES[spec])
            else:
                v = np.asarray(spec, dtype=float).reshape(3)
                norm = np.linalg.norm(v)
                if not norm > 0:
                    raise ValueError(f"axis {spec!r} must be a non-zero 3-vector")
                v = v / norm
            nominal.append(v)
        if isinstance(tilt_deg, (int, float)):
            tilts = [_random_rotvec(rng, np.deg2rad(float(tilt_deg))) for _ in range(n)]
        else:
            tilts = [np.asarray(t, dtype=float).reshape(3) for t in tilt_deg]
            if len(tilts) != n:
                raise ValueError(f"give one tilt rotation vector per joint ({n})")
        self.axes = np.array([rotvec_to_matrix(tv) @ v for tv, v in zip(tilts, nominal,
                                                                          strict=True)])
        self.axes /= np.linalg.norm(self.axes, axis=1, keepdims=True)
        self._skew_t = [_skew(a).T for a in self.axes]
        if isinstance(mount, (int, float)):
            self.mount_rotvec = _random_rotvec(rng, np.deg2rad(float(mount)))
        else:
            self.mount_rotvec = np.asarray(mount, dtype=float).reshape(3)
        self.mount = rotvec_to_matrix(self.mount_rotvec)
        if not (np.isfinite(wobble_deg) and 0.0 <= wobble_deg < 10.0):
            raise ValueError(f"wobble_deg must be in [0, 10), got {wobble_deg!r}")
        self.wobble_rad = math.radians(float(wobble_deg))
        wob_rng = np.random.default_rng([int(seed), 0x30B])  # its own stream: geometry unchanged
        self.wobble_axes = np.array([_perpendicular(a, wob_rng) for a in self.axes])
        self._wobble_skew_t = [_skew(e).T for e in self.wobble_axes]
        self.lever_arm_m = np.asarray(lever_arm_m, dtype=float).reshape(3)
        if not np.all(np.isfinite(self.lever_arm_m)):
            raise ValueError(f"lever_arm_m must be finite, got {lever_arm_m!r}")
        self.slips: list[Slip] = []
        self._peek_joints: list[Joint] | None = None
        self._can_peek = False
        t_home = home_time
        if t_home is None:
            clock = getattr(self.joints[0], "clock", None)
            t_home = clock.monotonic() if clock is not None else 0.0
        self.home_time = float(t_home)
        self.home_angles = np.array(
            [float(j.true_motion(np.array([self.home_time]))[0][0]) for j in self.joints])

    # ---- truth ---------------------------------------------------------------------------
    @property
    def ids(self) -> list[int]:
        """The joints' servo IDs, base to tip."""
        return [j.dxl_id for j in self.joints]

    @property
    def home_axes(self) -> dict[int, np.ndarray]:
        """Each servo's true rotation axis in the sensor frame in the home pose (before slips).

        A positive turn of servo ``i`` alone, from the home pose, gives the true rate
        ``home_axes[i] · θ̇_i``.
        """
        axes_sensor = self.axes @ self.mount  # rows: Mᵀ a_i
        return {j.dxl_id: axes_sensor[i].copy() for i, j in enumerate(self.joints)}

    def slip_at(self, t: float, rotvec: Sequence[float] | np.ndarray,
                duration_s: float = 0.01) -> Slip:
        """Fault knob: the mount slips at ``t`` by ``rotvec`` (sensor frame, rad) over
        ``duration_s``. After it, every axis in the sensor frame is turned by ``-rotvec``."""
        slip = Slip(float(t), np.asarray(rotvec, dtype=float).reshape(3), float(duration_s))
        self.slips.append(slip)
        self.slips.sort(key=lambda s: s.t_start)
        return slip

    def joint_angles(self, t: np.ndarray, *, peek: bool = False
                     ) -> tuple[np.ndarray, np.ndarray]:
        """Joint angles from home (rad) and rates (rad/s), each shape (N, n_joints); with
        ``peek`` as the servos plan them now (see the module's "Looking ahead")."""
        t = np.asarray(t, dtype=float).reshape(-1)
        th = np.empty((t.size, len(self.joints)))
        rate = np.empty_like(th)
        for i, j in enumerate(self.joints):
            th[:, i], rate[:, i] = j.peek_motion(t) if peek else j.true_motion(t)
        return th - self.home_angles, rate

    # ---- looking ahead ---------------------------------------------------------------------
    def lookahead(self) -> tuple[object, ...] | None:
        """What a look-ahead (``peek=True``) depends on: equal tuples mean equal values. None
        when a joint cannot be looked ahead on."""
        joints = self.joints
        if self._peek_joints is not joints:  # whether they can, once per list of joints
            self._peek_joints, self._can_peek = joints, all(_peeks(j) for j in joints)
        if not self._can_peek:
            return None
        return ([j.motion_revision() for j in joints],  # type: ignore[attr-defined]
                list(map(id, self.slips)), self.wobble_rad, self.lever_arm_m.tobytes(),
                self.mount.tobytes())

    def due_by(self, t: float) -> bool:
        """Whether a servo has a timed event (Bus Watchdog, fault) due by ``t``: a read
        reaching ``t`` would apply it first, so a look-ahead past it does not hold."""
        return any(j.next_due() <= t for j in self.joints)  # type: ignore[attr-defined]

    def touch(self, t: float) -> None:
        """What reading the motion at times whose latest is ``t`` does besides returning it:
        each servo applies its events due by then and freezes its motion through ``t``."""
        for j in self.joints:
            j.touch(t)  # type: ignore[attr-defined]

    def _chain(self, th: np.ndarray) -> list[np.ndarray]:
        """Cumulative rotations R_1..i for i = 0..n (R_1..0 = I), each (N, 3, 3)."""
        n_t = th.shape[0]
        cum = [np.broadcast_to(np.eye(3), (n_t, 3, 3))]
        for i in range(len(self.joints)):
            r = cum[-1] @ rotation_matrices(self.axes[i], th[:, i])
            if self.wobble_rad:
                r = r @ rotation_matrices(self.wobble_axes[i], self.wobble_rad * np.sin(th[:, i]))
            cum.append(r)
        return cum

    def _slip_matrices(self, t: np.ndarray) -> list[tuple[np.ndarray, np.ndarray, Slip]]:
        out = []
        for slip in self.slips:
            s, ds = slip.progress(t)
            angle = float(np.linalg.norm(slip.rotvec))
            if angle == 0:
                continue
            out.append((rotation_matrices(slip.rotvec / angle, s * angle), ds, slip))
        return out

    def _sensor_orientation(self, chain_end: np.ndarray, t: np.ndarray) -> np.ndarray:
        """``R_sensor = R_1..n · M · S(t)`` from the chain's last rotation ``R_1..n``."""
        r = chain_end @ self.mount
        for m, _, _ in self._slip_matrices(t):
            r = r @ m
        return r

    def orientation(self, t: np.ndarray, *, peek: bool = False) -> np.ndarray:
        """The sensor's orientation ``R_sensor(t)`` (sensor → base), shape (N, 3, 3)."""
        t = np.asarray(t, dtype=float).reshape(-1)
        th, _ = self.joint_angles(t, peek=peek)
        return self._sensor_orientation(self._chain(th)[-1], t)

    def rate(self, t: np.ndarray, *, peek: bool = False) -> np.ndarray:
        """True angular rate of the sensor in its own frame, rad/s, shape (len(t), 3)."""
        t = np.asarray(t, dtype=float).reshape(-1)
        if t.size == 0:
            return np.zeros((0, 3))
        return self._rate(t, *self.joint_angles(t, peek=peek))

    def _rate(self, t: np.ndarray, th: np.ndarray, dth: np.ndarray) -> np.ndarray:
        """:meth:`rate` from the joint angles and rates at ``t``."""
        # R_chainᵀ Σ_i R_1..i−1 a_i θ̇_i = Σ_i R_i+1..nᵀ a_i θ̇_i (R_iᵀ a_i = a_i), by the
        # recursion u_i = R_iᵀ (u_i−1 + a_i θ̇_i): vector rotations only, no matrices.
        w = np.zeros((t.size, 3))
        for i in range(len(self.joints)):
            a = self.axes[i]
            w += dth[:, i, None] * a
            w = _rotate_back(w, a, self._skew_t[i], th[:, i])
            if self.wobble_rad:  # the link's tilt R(e, ψ): w ← R(e, ψ)ᵀ w + e ψ̇
                e, eps = self.wobble_axes[i], self.wobble_rad
                w = _rotate_back(w, e, self._wobble_skew_t[i], eps * np.sin(th[:, i]))
                w += (eps * np.cos(th[:, i]) * dth[:, i])[:, None] * e
        w = w @ self.mount  # Mᵀ w for each row
        for m, ds, slip in self._slip_matrices(t):
            w = np.einsum("nji,nj->ni", m, w) + ds[:, None] * slip.rotvec[None, :]
        return w

    def joint_axes_sensor(self, t: np.ndarray) -> np.ndarray:
        """Each joint's axis in the sensor frame at ``t``, shape (N, n_joints, 3)."""
        t = np.asarray(t, dtype=float).reshape(-1)
        th, _ = self.joint_angles(t)
        cum = self._chain(th)
        r_sensor = self._sensor_orientation(cum[-1], t)
        out = np.empty((t.size, len(self.joints), 3))
        for i in range(len(self.joints)):
            a_base = np.einsum("nij,j->ni", cum[i], self.axes[i])
            out[:, i, :] = np.einsum("nji,nj->ni", r_sensor, a_base)
        return out

    def home_gravity(self) -> np.ndarray:
        """Gravity in the sensor frame in the home pose, in g: ``R_homeᵀ (0, 0, 1)`` from the
        joints' home angles (no motor history needed, so it holds however long the jig ran)."""
        home = self._sensor_orientation(self._chain(self.home_angles[None, :])[-1],
                                        np.array([self.home_time]))
        return home[0, 2, :]

    def specific_force(self, t: np.ndarray, dt: float = 2e-4, *, peek: bool = False
                       ) -> np.ndarray:
        """The specific force at the sensor in its own frame, in g, shape (N, 3): gravity
        ``R_sensorᵀ (0, 0, 1)`` plus ``(α × r + ω × (ω × r)) / g₀`` with ``r`` the lever arm
        and ``α`` the backward difference of the rate over ``dt`` (α and ω in the sensor frame:
        ``r`` is fixed there, and ``dω/dt`` is the same in both frames)."""
        t = np.asarray(t, dtype=float).reshape(-1)
        r = self.lever_arm_m
        if not (t.size and np.any(r)):
            return self.orientation(t, peek=peek)[:, 2, :]  # third row of R: Rᵀ e_z
        # one evaluation of the joints for the rates at t - dt and t and the orientation at t
        before = np.maximum(t - dt, self.home_time)  # the joints have no earlier motion
        both = np.column_stack([before, t]).reshape(-1)
        th, dth = self.joint_angles(both, peek=peek)
        w_both = self._rate(both, th, dth).reshape(t.size, 2, 3)
        force = self._gravity(t, th[1::2])
        step = np.where(t > before, t - before, np.inf)[:, None]
        w, alpha = w_both[:, 1], (w_both[:, 1] - w_both[:, 0]) / step
        # α × r + ω × (ω × r), the second as ω (ω·r) − r |ω|²; α × r written out (numpy.cross's
        # products and differences in its order, without its per-call set-up)
        a0, a1, a2 = alpha[:, 0], alpha[:, 1], alpha[:, 2]
        alpha_r = np.column_stack((a1 * r[2] - a2 * r[1], a2 * r[0] - a0 * r[2],
                                   a0 * r[1] - a1 * r[0]))
        acc = alpha_r + w * (w @ r)[:, None] - r * np.einsum("ni,ni->n", w, w)[:, None]
        return force + acc / STANDARD_GRAVITY

    def _gravity(self, t: np.ndarray, th: np.ndarray) -> np.ndarray:
        """Gravity in the sensor frame, ``R_sensorᵀ (0, 0, 1)``, from the joint angles at ``t``:
        the inverse rotations applied to the vector in turn, base first (as :meth:`_rate`),
        rather than the product of the matrices."""
        g = np.zeros((t.size, 3))
        g[:, 2] = 1.0
        for i in range(len(self.joints)):
            g = _rotate_back(g, self.axes[i], self._skew_t[i], th[:, i])
            if self.wobble_rad:
                g = _rotate_back(g, self.wobble_axes[i], self._wobble_skew_t[i],
                                 self.wobble_rad * np.sin(th[:, i]))
        g = g @ self.mount
        for m, _, _ in self._slip_matrices(t):
            g = np.einsum("nji,nj->ni", m, g)
        return g
