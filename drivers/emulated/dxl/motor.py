"""Motor dynamics of an emulated X-series servo on the shared clock.

The shaft angle is computed on a fixed fine time grid (``dt``, 0.5 ms by default) and is linear
between grid points, so the shaft rate is constant on each grid cell and **the angle is exactly
the integral of the rate** at every instant. The encoder (Present Position) reads this angle
quantized to 4096 ticks per turn, and the jig reads the same rate, so the calibration's
reference (encoder angle change over a window / its duration) and the gyro's truth (mean rate
over the same window) agree exactly apart from the encoder's quantization.

How the angle is made, all vectorised with numpy over blocks of grid points:

1. A :class:`Plan` (the servo's profile generator, hardware reference §5: Profile Acceleration and
   Profile Velocity as the real servo applies them: trapezoidal, triangular or rectangular
   velocity profiles, or a velocity ramp in velocity mode) gives the trajectory angle and rate.
2. The shaft follows the trajectory through two first-order lags (the position loop's tracking
   delay; unit DC gain, no overshoot, so a position move ends exactly on its goal).
3. Speed ripple is added as a bounded position perturbation whose derivative is a relative rate
   error: periodic components at chosen orders per output revolution (once per turn, the gear
   meshes, the motor's commutation) and band-limited noise, about 5 % of the speed as the paper
   observed. Every term is scaled by the trajectory speed, so it vanishes at rest, and it is a
   function of the trajectory angle, so it is periodic in angle the way gear and commutation
   ripple is.

Grid points are computed ahead of the clock (a look-ahead block) and may be recomputed when a
command arrives, but never once anything has read them: reads freeze the grid up to the cell
they used, so a rate handed out to the IMU is never changed afterwards. A read with
``freeze=False`` (an emulated chip computing its samples ahead, see
:class:`~gyrocal.drivers.emulated.jig.GimbalJig`) sees the same points without freezing them;
:attr:`ServoMotor.revision` counts the commands, so such a reader knows when what it saw may
have changed.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from gyrocal.drivers.emulated.iir import compiled, lfilter

__all__ = [
    "MotorParams",
    "Plan",
    "RippleComponent",
    "ServoMotor",
    "plan_hold",
    "plan_position",
    "plan_stop",
    "plan_velocity",
]


# --------------------------------------------------------------------------------------------
# Profiles (the servo's trajectory generator)
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Plan:
    """A piecewise-constant-acceleration trajectory: segments ``(t0, p0, v0, a)``.

    Segment ``i`` runs from ``t0[i]`` to ``t0[i+1]`` (the last one for ever). ``kind`` names the
    profile for Moving Status (hardware reference §5, address 123): ``"hold"``, ``"step"``,
    ``"rectangular"``, ``"triangular"``, ``"trapezoidal"`` or ``"velocity"``.
    """

    t0: np.ndarray
    p0: np.ndarray
    v0: np.ndarray
    a: np.ndarray
    end_time: float
    kind: str = "hold"
    goal: float | None = None

    def evaluate(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Trajectory angle (rad) and rate (rad/s) at the times ``t`` (>= the plan's start)."""
        t = np.asarray(t, dtype=float)
        i = np.searchsorted(self.t0, t, side="right") - 1
        np.clip(i, 0, self.t0.size - 1, out=i)
        tau = t - self.t0[i]
        a = self.a[i]
        v0 = self.v0[i]
        return self.p0[i] + tau * (v0 + 0.5 * a * tau), v0 + a * tau

    def state(self, t: float) -> tuple[float, float]:
        """Trajectory angle and rate at one time (scalar fast path of :meth:`evaluate`)."""
        t0 = self.t0
        i = len(t0) - 1
        while i > 0 and t0[i] > t:
            i -= 1
        tau = t - float(t0[i])
        a, v0 = float(self.a[i]), float(self.v0[i])
        return float(self.p0[i]) + tau * (v0 + 0.5 * a * tau), v0 + a * tau

    def running(self, t: float) -> bool:
        """True while the profile has not reached its end (always True for velocity plans)."""
        return t < self.end_time


def _make_plan(segs: list[tuple[float, float, float, float]], end_time: float, kind: str,
               goal: float | None) -> Plan:
    arr = np.array(segs, dtype=float).reshape(-1, 4)
    return Plan(arr[:, 0].copy(), arr[:, 1].copy(), arr[:, 2].copy(), arr[:, 3].copy(),
                float(end_time), kind, goal)


def plan_hold(t0: float, p0: float) -> Plan:
    """Stand still at ``p0`` from ``t0``."""
    return _make_plan([(t0, p0, 0.0, 0.0)], t0, "hold", p0)


def plan_stop(t0: float, p0: float, v0: float, decel: float) -> Plan:
    """Decelerate from ``v0`` at ``decel`` (rad/s², ``inf`` = at once) and stand still."""
    if v0 == 0.0 or math.isinf(decel):
        return plan_hold(t0, p0)
    dur = abs(v0) / decel
    p1 = p0 + v0 * dur / 2.0
    return _make_plan([(t0, p0, v0, -math.copysign(decel, v0)), (t0 + dur, p1, 0.0, 0.0)],
                      t0 + dur, "step", p1)


def plan_velocity(t0: float, p0: float, v0: float, target: float, accel: float) -> Plan:
    """Velocity mode: ramp from ``v0`` to ``target`` at ``accel`` (``inf`` = a step), then keep it.

    The plan never ends (``end_time`` is infinite) unless ``target`` is zero.
    """
    if math.isinf(accel) or v0 == target:
        segs = [(t0, p0, target, 0.0)]
        t1 = t0
    else:
        dur = abs(target - v0) / accel
        segs = [(t0, p0, v0, math.copysign(accel, target - v0)),
                (t0 + dur, p0 + (v0 + target) * dur / 2.0, target, 0.0)]
        t1 = t0 + dur
    if target == 0.0:
        return _make_plan(segs, t1, "velocity", segs[-1][1])
    return _make_plan(segs, math.inf, "velocity", None)


def plan_position(t0: float, p0: float, v0: float, goal: float, vmax: float,
                  accel: float) -> Plan:
    """Position modes: the servo's profile from ``(p0, v0)`` to rest at ``goal``.

    Parameters
    ----------
    t0, p0, v0 : float
        Start time (s), trajectory angle (rad) and rate (rad/s).
    goal : float
        Goal angle (rad).
    vmax : float
        The profile velocity (rad/s, > 0): the cruise speed.
    accel : float
        The profile acceleration (rad/s², > 0, ``inf`` for none: a rectangular velocity profile).

    Returns
    -------
    Plan
        Trapezoidal when the cruise speed is reached, triangular when not, rectangular for an
        infinite acceleration (the profile shapes of hardware reference §5, addresses 108/112).
    """
    if not vmax > 0.0:
        raise ValueError(f"vmax must be positive, got {vmax!r}")
    segs: list[tuple[float, float, float, float]] = []
    t, p, v = t0, p0, v0
    d = goal - p
    if math.isinf(accel):
        if d == 0.0:
            return plan_hold(t0, goal)
        dur = abs(d) / vmax
        segs.append((t, p, math.copysign(vmax, d), 0.0))
        segs.append((t + dur, goal, 0.0, 0.0))
        return _make_plan(segs, t + dur, "rectangular", goal)
    a = accel
    if v != 0.0:
        stop = v * v / (2.0 * a)
        if (d == 0.0) or (math.copysign(1.0, v) != math.copysign(1.0, d)) or stop > abs(d) + 1e-12:
            dur = abs(v) / a
            segs.append((t, p, v, -math.copysign(a, v)))
            p += math.copysign(stop, v)
            t += dur
            v = 0.0
            d = goal - p
    if abs(d) < 1e-12 and v == 0.0:
        segs.append((t, goal, 0.0, 0.0))
        return _make_plan(segs, t, "step" if len(segs) > 1 else "hold", goal)
    s = math.copysign(1.0, d)
    u = v * s
    dist_left = abs(d)
    if u > vmax:
        dur = (u - vmax) / a
        dist = (u * u - vmax * vmax) / (2.0 * a)
        segs.append((t, p, s * u, -s * a))
        t += dur
        p += s * dist
        dist_left -= dist
        u = vmax
    vpeak2 = a * dist_left + u * u / 2.0
    if vpeak2 <= vmax * vmax:
        vp = math.sqrt(vpeak2)
        d1 = (vp - u) / a
        if d1 > 0:
            segs.append((t, p, s * u, s * a))
            p += s * (vp * vp - u * u) / (2.0 * a)
            t += d1
        d3 = vp / a
        segs.append((t, p, s * vp, -s * a))
        t += d3
        kind = "triangular"
    else:
        d1 = (vmax - u) / a
        if d1 > 0:
            segs.append((t, p, s * u, s * a))
            p += s * (vmax * vmax - u * u) / (2.0 * a)
            t += d1
        dist3 = vmax * vmax / (2.0 * a)
        dist2 = abs(goal - p) - dist3
        d2 = max(dist2, 0.0) / vmax
        segs.append((t, p, s * vmax, 0.0))
        t += d2
        p = goal - s * dist3
        segs.append((t, p, s * vmax, -s * a))
        t += vmax / a
        kind = "trapezoidal"
    segs.append((t, goal, 0.0, 0.0))
    return _make_plan(segs, t, kind, goal)


# --------------------------------------------------------------------------------------------
# The recursions of the motor (per grid point, exactly as lfilter computes them)
# --------------------------------------------------------------------------------------------
def _constant_tail(x: np.ndarray) -> int:
    """Index where the trailing run of bit-identical values of ``x`` begins."""
    bits = x.view(np.int64)
    changes = np.flatnonzero(bits[1:] != bits[:-1])
    return int(changes[-1]) + 1 if changes.size else 0


def _tracking_lags(alpha: float, x: np.ndarray, y1_last: float, y2_last: float
                   ) -> tuple[np.ndarray, np.ndarray]:
    """The two first-order tracking lags in cascade over the trajectory ``x``, from the
    previous grid point's outputs ``y1_last``, ``y2_last``.

    Each lag is ``lfilter([1 - α], [1, -α], ·, zi=[α y_last])`` of
    :mod:`gyrocal.drivers.emulated.iir` (the Direct Form II transposed recursion ``y = z + b₀x``,
    ``z = b₁x − a₁y``) with the same operations in the same order, so the numbers are the same
    to the last bit; both lags run in one loop. While the trajectory holds still (its trailing
    run of identical inputs), the recursion is a monotone map of the state and reaches a fixed
    point; once one step leaves both states unchanged (non-zero, so that the sign of a zero
    cannot differ), every later step repeats it and the rest is filled in without the loop.
    Where :func:`~gyrocal.drivers.emulated.iir.lfilter` runs compiled, the two lags are its
    two calls over every point instead (a fifth of the loop's CPU on a 0.1 s block).
    """
    if compiled():
        b, a = [1.0 - alpha], [1.0, -alpha]
        y1, _ = lfilter(b, a, x, zi=[alpha * y1_last])
        return y1, lfilter(b, a, y1, zi=[alpha * y2_last])[0]
    b0, b1, a1 = 1.0 - alpha, 0.0, -alpha
    z1, z2 = alpha * y1_last, alpha * y2_last
    m = x.size
    out1 = np.empty(m)
    out2 = np.empty(m)
    j0 = _constant_tail(x) if m > 1 else m
    ys1: list[float] = []
    ys2: list[float] = []
    put1, put2 = ys1.append, ys2.append
    for xn in x[:j0].tolist():
        y1 = z1 + b0 * xn
        z1 = xn * b1 - y1 * a1
        y2 = z2 + b0 * y1
        z2 = y1 * b1 - y2 * a1
        put1(y1)
        put2(y2)
    if j0 < m:
        xn = float(x[j0])
        for _ in range(m - j0):
            y1 = z1 + b0 * xn
            n1 = xn * b1 - y1 * a1
            y2 = z2 + b0 * y1
            n2 = y1 * b1 - y2 * a1
            put1(y1)
            put2(y2)
            if n1 == z1 and n2 == z2 and n1 != 0.0 and n2 != 0.0:
                break  # a fixed point: every later step gives y1, y2 again
            z1, z2 = n1, n2
    k = len(ys1)
    out1[:k] = ys1
    out2[:k] = ys2
    if k < m:
        out1[k:] = ys1[-1]
        out2[k:] = ys2[-1]
    return out1, out2


def _resonator(c1: float, c2: float, xi: np.ndarray, u1: float, u2: float) -> np.ndarray:
    """The ripple noise's second-order recursion over ``xi`` from the two previous outputs
    ``u1`` (last) and ``u2``: ``lfilter([1], [1, -c1, -c2], xi, zi=[c1 u1 + c2 u2, c2 u1])``
    with its operations in its order (see :func:`_tracking_lags`); that very call where it runs
    compiled (a third of the loop's CPU)."""
    if compiled():
        return lfilter([1.0], [1.0, -c1, -c2], xi, zi=[c1 * u1 + c2 * u2, c2 * u1])[0]
    b0, b1, b2, a1, a2 = 1.0, 0.0, 0.0, -c1, -c2
    z0, z1 = c1 * u1 + c2 * u2, c2 * u1
    out: list[float] = []
    put = out.append
    for xn in xi.tolist():
        yn = z0 + b0 * xn
        z0 = z1 + xn * b1 - yn * a1
        z1 = xn * b2 - yn * a2
        put(yn)
    return np.array(out)


def _add_unless_idle(p: np.ndarray, scale: np.ndarray, term) -> None:
    """``p += scale * term()``, where ``term()`` gives finite values, or nothing when the sum
    would leave ``p`` as it is: every ``scale`` zero and no ``p`` zero (``±0`` added to a
    non-zero number leaves it unchanged; to a zero it may flip its sign). A shaft at rest
    skips the ripple's sines and the noise's product."""
    if np.any(scale != 0.0) or not np.all(p):
        p += scale * term()


# --------------------------------------------------------------------------------------------
# Motor
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class RippleComponent:
    """One periodic speed-ripple component.

    Parameters
    ----------
    order : float
        Cycles per output revolution (1 = once per turn; a gear mesh = its tooth count; the
        motor's commutation = gear ratio × commutation steps per motor turn).
    amplitude : float
        Peak rate error as a fraction of the speed.
    phase : float
        Phase in rad.
    """

    order: float
    amplitude: float
    phase: float = 0.0


def default_ripple(gear_ratio: float, rng: np.random.Generator) -> tuple[RippleComponent, ...]:
    """Ripple of a geared servo, about 4–5 % peak in total with the default noise.

    Once per output turn (shaft eccentricity), the output gear mesh (29 teeth), an intermediate
    mesh, and the motor's commutation (24 steps per motor turn through the gearbox).
    """
    orders = (1.0, 29.0, 29.0 * 4.3, 24.0 * gear_ratio)
    amps = (0.006, 0.02, 0.012, 0.008)
    return tuple(RippleComponent(o, a, float(rng.uniform(0, 2 * np.pi)))
                 for o, a in zip(orders, amps, strict=True))


@dataclass(frozen=True)
class MotorParams:
    """Parameters of the motor model.

    Parameters
    ----------
    dt : float
        Grid step in s (0.5 ms).
    lag_s : float
        Time constant of each of the two tracking lags, in s.
    ripple : tuple of RippleComponent or None
        Periodic ripple; None = :func:`default_ripple` for the model's gear ratio.
    noise_fraction : float
        RMS of the band-limited rate noise as a fraction of the speed.
    noise_bandwidth_hz : float
        Natural frequency of the noise's second-order shaping filter.
    envelope_speed : float
        Below this trajectory speed (rad/s) the ripple fades out linearly to zero at rest.
    lookahead_s : float
        How far ahead of a read the grid is computed in one block.
    history_s : float
        How much grid history is kept for late readers (the IMU's FIFO, tests).
    hold_band : float
        Where a position move comes to rest within the encoder tick of its goal, as a fraction
        of a tick: the true angle ends at ``goal + U(-hold_band/2, +hold_band/2)`` ticks (the
        position loop stops once Present Position reads the goal, so the shaft may rest
        anywhere in the tick). 0 ends exactly on the tick's centre. A shaft already at rest on
        its goal's tick (torque on with Goal Position = Present Position) stays where it is.
    """

    dt: float = 5e-4
    lag_s: float = 0.006
    ripple: tuple[RippleComponent, ...] | None = None
    noise_fraction: float = 0.02
    noise_bandwidth_hz: float = 5.0
    envelope_speed: float = 0.3
    lookahead_s: float = 0.1
    history_s: float = 120.0
    hold_band: float = 1.0


@dataclass
class _Grid:
    """Grid history: global index of the first kept point and per-point arrays."""

    k0: int = 0
    p: np.ndarray = field(default_factory=lambda: np.zeros(0))
    y1: np.ndarray = field(default_factory=lambda: np.zeros(0))
    y2: np.ndarray = field(default_factory=lambda: np.zeros(0))
    u: np.ndarray = field(default_factory=lambda: np.zeros(0))
    n: int = 0


class ServoMotor:
    """The shaft of one servo: trajectory, tracking lag, ripple and noise on a time grid.

    Parameters
    ----------
    t_start : float
        Clock time of grid point 0 (s).
    gear_ratio : float
        For the default ripple's commutation order.
    params : MotorParams
        Model parameters.
    seed : int
        Seed of the ripple phases and the noise (reproducible runs).

    Notes
    -----
    Angles are in rad from the shaft's angle at ``t_start``, positive in the motor's positive
    direction. Times must be >= ``t_start``.
    """

    _BLOCK = 8192  # noise is drawn per block of grid points, from (seed, block) → reproducible

    def __init__(self, t_start: float, gear_ratio: float = 353.5,
                 params: MotorParams | None = None, seed: int = 0) -> None:
        self.params = params or MotorParams()
        self.dt = float(self.params.dt)
        self.t_start = float(t_start)
        self.seed = int(seed)
        rng = np.random.default_rng([self.seed, 0x5E7])
        ripple = self.params.ripple
        if ripple is None:
            ripple = default_ripple(gear_ratio, rng)
        self.ripple: tuple[RippleComponent, ...] = tuple(ripple)
        self._orders = np.array([c.order for c in self.ripple], dtype=float)
        self._amps = np.array([c.amplitude / c.order for c in self.ripple], dtype=float)
        self._phases = np.array([c.phase for c in self.ripple], dtype=float)
        self._alpha = math.exp(-self.dt / self.params.lag_s) if self.params.lag_s > 0 else 0.0
        # noise: u_k = c1 u_{k-1} + c2 u_{k-2} + g ξ_k (damped oscillator, ζ = 0.7)
        zeta, w = 0.7, 2.0 * math.pi * self.params.noise_bandwidth_hz
        r = math.exp(-zeta * w * self.dt)
        th = w * self.dt * math.sqrt(1.0 - zeta * zeta)
        self._c1, self._c2 = 2.0 * r * math.cos(th), -r * r
        h, _ = lfilter([1.0], [1.0, -self._c1, -self._c2],
                    np.r_[1.0, np.zeros(int(40.0 / (zeta * w * self.dt)))])
        dh = np.diff(np.r_[0.0, h]) / self.dt
        self._g = self.params.noise_fraction / math.sqrt(float(np.sum(dh * dh))) \
            if self.params.noise_fraction > 0 else 0.0
        self._noise_cache: dict[int, np.ndarray] = {}
        self.plan: Plan = plan_hold(self.t_start, 0.0)
        self._grid = _Grid()
        self._frozen = -1  # highest global index a reader has used
        #: Commands so far: grid points not yet frozen may have changed when this moves.
        self.revision = 0
        self._append(np.zeros(1), np.zeros(1), np.zeros(1), np.zeros(1))

    # ---- grid bookkeeping ----------------------------------------------------------------
    def _append(self, p: np.ndarray, y1: np.ndarray, y2: np.ndarray, u: np.ndarray) -> None:
        g = self._grid
        m = p.size
        if g.n + m > g.p.size:
            keep = int(self.params.history_s / self.dt) + 8
            # drop history older than history_s, but never a point a reader may still need
            drop = max(0, min(g.n - keep, self._frozen - g.k0 - 4))
            cap = max(2 * (g.n - drop + m), 4096)
            for name in ("p", "y1", "y2", "u"):
                old = getattr(g, name)
                new = np.empty(cap)
                new[: g.n - drop] = old[drop: g.n]
                setattr(g, name, new)
            g.k0 += drop
            g.n -= drop
        sl = slice(g.n, g.n + m)
        g.p[sl], g.y1[sl], g.y2[sl], g.u[sl] = p, y1, y2, u
        g.n += m

    def _noise(self, k_first: int, m: int) -> np.ndarray:
        out = np.empty(m)
        pos = 0
        while pos < m:
            k = k_first + pos
            b, off = divmod(k, self._BLOCK)
            blk = self._noise_cache.get(b)
            if blk is None:
                blk = np.random.default_rng([self.seed, 0xA015E, b]).standard_normal(self._BLOCK)
                if len(self._noise_cache) > 4:
                    self._noise_cache.pop(min(self._noise_cache))
                self._noise_cache[b] = blk
            take = min(m - pos, self._BLOCK - off)
            out[pos: pos + take] = blk[off: off + take]
            pos += take
        return out

    def _compute(self, m: int) -> None:
        """Compute ``m`` more grid points with the current plan."""
        g = self._grid
        k_first = g.k0 + g.n
        t = self.t_start + (k_first + np.arange(m)) * self.dt
        pt, vt = self.plan.evaluate(t)
        last = g.n - 1
        y1, y2 = _tracking_lags(self._alpha, pt, float(g.y1[last]), float(g.y2[last]))
        speed = np.abs(vt)
        env = np.minimum(speed / self.params.envelope_speed, 1.0) \
            if self.params.envelope_speed > 0 else (speed > 0).astype(float)
        p = y2.copy()
        if self._orders.size:
            _add_unless_idle(p, env, lambda: np.sin(
                np.multiply.outer(pt, self._orders) + self._phases) @ self._amps)
        if self._g > 0:
            xi = self._noise(k_first, m) * self._g
            u1 = float(g.u[last])
            u2 = float(g.u[last - 1]) if last >= 1 else 0.0
            u = _resonator(self._c1, self._c2, xi, u1, u2)
            _add_unless_idle(p, speed, lambda: u)
        else:
            u = np.zeros(m)
        self._append(p, y1, y2, u)

    def _ensure(self, k: int) -> None:
        """Make sure global grid index ``k`` is computed (plus a look-ahead block)."""
        g = self._grid
        have = g.k0 + g.n - 1
        if k <= have:
            return
        ahead = max(1, int(self.params.lookahead_s / self.dt))
        self._compute(k - have + ahead)

    def _index(self, t: float | np.ndarray) -> np.ndarray:
        return np.floor((np.asarray(t, dtype=float) - self.t_start) / self.dt + 1e-9).astype(
            np.int64)

    # ---- public --------------------------------------------------------------------------
    def motion(self, t: Sequence[float] | np.ndarray, *, freeze: bool = True
               ) -> tuple[np.ndarray, np.ndarray]:
        """Shaft angle (rad) and rate (rad/s) at the times ``t``.

        The rate is constant on each grid cell and the angle is its exact integral. Reading
        freezes the grid cells used: later commands never change them. With ``freeze=False``
        the cells are only looked at: a later command may still change them (and moves
        :attr:`revision`).

        Raises
        ------
        ValueError
            If a time is before the motor's start or older than the kept history.
        """
        t = np.asarray(t, dtype=float).reshape(-1)
        if t.size == 0:
            return np.zeros(0), np.zeros(0)
        k = self._index(t)
        kmax = int(k.max())
        self._ensure(kmax + 1)
        g = self._grid
        if int(k.min()) < g.k0:
            raise ValueError(
                f"time {float(t.min()):.6f} s is before the motor's kept history "
                f"(from {self.t_start + g.k0 * self.dt:.6f} s); increase MotorParams.history_s"
            )
        if freeze:
            self._frozen = max(self._frozen, kmax + 1)
        j = k - g.k0
        p0 = g.p[j]
        rate = (g.p[j + 1] - p0) / self.dt
        tk = self.t_start + k * self.dt
        return p0 + (t - tk) * rate, rate

    def sample(self, t: float) -> tuple[float, float]:
        """Shaft angle and rate at one time (scalar fast path of :meth:`motion`)."""
        k = math.floor((t - self.t_start) / self.dt + 1e-9)
        g = self._grid
        if k + 1 > g.k0 + g.n - 1:
            self._ensure(k + 1)
        if k < g.k0:
            return tuple(float(x[0]) for x in self.motion(np.array([t])))  # raises
        if k + 1 > self._frozen:
            self._frozen = k + 1
        j = k - g.k0
        p0 = float(g.p[j])
        rate = (float(g.p[j + 1]) - p0) / self.dt
        return p0 + (t - (self.t_start + k * self.dt)) * rate, rate

    def angle_at(self, t: float) -> float:
        """Shaft angle at one time (see :meth:`motion`)."""
        return self.sample(t)[0]

    def command(self, t: float, make_plan) -> Plan:
        """Replace the trajectory from the first grid point not yet read after ``t``.

        Parameters
        ----------
        t : float
            The time the command arrives.
        make_plan : callable
            ``make_plan(t0, p0, v0) -> Plan``, given the trajectory state at the switch time.

        Returns
        -------
        Plan
            The new plan.
        """
        self.revision += 1
        k_switch = max(int(self._index(t)) + 1, self._frozen + 1, 1)
        self._ensure(k_switch - 1)
        g = self._grid
        # roll back provisional points from k_switch on
        keep = k_switch - g.k0
        if keep < g.n:
            g.n = keep
        t_switch = self.t_start + k_switch * self.dt
        p0, v0 = self.plan.state(t_switch)
        self.plan = make_plan(t_switch, p0, v0)
        return self.plan

    def trajectory(self, t: float) -> tuple[float, float]:
        """The profile's angle and rate at ``t`` (Position/Velocity Trajectory registers)."""
        return self.plan.state(max(t, float(self.plan.t0[0])))
