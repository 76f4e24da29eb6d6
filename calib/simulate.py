"""Vectorised synthetic sensor and protocol for Monte Carlo work (seeded, sample level).

A run is a sensor with true scale ``k`` and bias ``b`` (paper Eq. 1: ``g = k ∘ (m + b)``, so the
reading is ``m = g ⊘ k − b + noise``), mounted with a small misalignment so that each servo's
rotation axis ``u_s`` in the sensor frame is off the sensor axis, and turned by the protocol: for
each servo a rest, ``turns`` whole revolutions one way, a rest, the same the other way. Samples are
drawn at ``odr_hz``; the servo's speed ripples; windows are whole revolutions, so the encoder's
reference (angle change over duration) is the exact mean of the true rate over the window.

The speed ripple is a band-limited process: random-phase sinusoids at the revolution frequency and
its first harmonics plus a few Hz, with total standard deviation ``ripple`` × speed. The paper
describes its rotation noise only as "N(0, 5% ω)"; a physical servo's ripple comes from its control
loop and gearing, not independent per sample.

Everything is a pure function of its arguments and a ``numpy.random.Generator``.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any

import numpy as np

from gyrocal.calib.errors import CalibInputError
from gyrocal.calib.observations import ObservationSet, diff_noise
from gyrocal.calib.segments import Segment
from gyrocal.calib.windows import trapezoid_weight

TWO_PI = 2.0 * np.pi

__all__ = [
    "SensorPreset",
    "SimProtocol",
    "SimulatedRuns",
    "draw_mount_axes",
    "draw_sensors",
    "RawRun",
    "RawRunStream",
    "profile_duration",
    "simulate_raw_run",
    "simulate_runs",
    "stream_raw_run",
]


@dataclass(frozen=True)
class SensorPreset:
    """A distribution of true sensor errors (paper Section III).

    Attributes
    ----------
    scale_range : (float, float)
        Scale factors ~ U(lo, hi) per axis.
    bias_abs_range : (float, float)
        |bias| ~ U(lo, hi) per axis with a random sign (rad/s). ``(0, 0.1)`` is U(-0.1, 0.1).
    """

    scale_range: tuple[float, float] = (0.8, 1.2)
    bias_abs_range: tuple[float, float] = (0.0, 0.1)


#: Paper, normal conditions: k ~ U(0.8, 1.2), b ~ U(-0.1, 0.1) rad/s.
NORMAL = SensorPreset((0.8, 1.2), (0.0, 0.1))
#: Paper, extreme conditions: k ~ U(1.2, 2.0), |b| ~ U(0.1, 0.2) rad/s.
EXTREME = SensorPreset((1.2, 2.0), (0.1, 0.2))


def draw_sensors(
    rng: np.random.Generator, n: int, preset: SensorPreset = NORMAL
) -> tuple[np.ndarray, np.ndarray]:
    """Draw ``n`` sensors' true scale and bias, each of shape ``(n, 3)``."""
    lo, hi = preset.scale_range
    scale = rng.uniform(lo, hi, size=(n, 3))
    blo, bhi = preset.bias_abs_range
    bias = rng.uniform(blo, bhi, size=(n, 3)) * rng.choice([-1.0, 1.0], size=(n, 3))
    return scale, bias


def _rotation_matrices(axis: np.ndarray, angle: np.ndarray) -> np.ndarray:
    """Rodrigues: rotation matrices (n, 3, 3) about unit ``axis`` (n, 3) by ``angle`` (n,)."""
    x, y, z = axis[:, 0], axis[:, 1], axis[:, 2]
    c, s = np.cos(angle), np.sin(angle)
    C = 1 - c
    return np.stack(
        [
            np.stack([c + x * x * C, x * y * C - z * s, x * z * C + y * s], axis=-1),
            np.stack([y * x * C + z * s, c + y * y * C, y * z * C - x * s], axis=-1),
            np.stack([z * x * C - y * s, z * y * C + x * s, c + z * z * C], axis=-1),
        ],
        axis=-2,
    )


def draw_mount_axes(
    rng: np.random.Generator, n: int, misalignment: float = 0.1, n_servos: int = 3
) -> np.ndarray:
    """Rotation axes of the servos in the sensor frame for ``n`` randomly misaligned mounts.

    The mount is a rigid rotation by an angle ~ U(0, ``misalignment``) rad about a random axis
    (the paper's "misalignment U(0 %, 10 %)"), so servo ``s`` (nominally about sensor axis ``s``)
    turns about ``u_s = Rᵀ e_s``.

    Returns
    -------
    numpy.ndarray, shape (n, n_servos, 3)
    """
    if n_servos != 3:
        raise CalibInputError("draw_mount_axes models the three-servo gimbal (n_servos=3)")
    ax = rng.standard_normal((n, 3))
    ax /= np.linalg.norm(ax, axis=1, keepdims=True)
    R = _rotation_matrices(ax, rng.uniform(0.0, misalignment, size=n))
    return np.transpose(R, (0, 2, 1)) @ np.eye(3)  # rows: Rᵀ e_s


@dataclass(frozen=True)
class SimProtocol:
    """A calibration protocol for simulation.

    Attributes
    ----------
    speed : float
        Commanded speed, rad/s.
    turns : int
        Whole revolutions per direction per servo.
    odr_hz : float
        Gyro output data rate.
    rest_s : float
        Rest before each turn (and after the last), s.
    ripple : float
        Speed ripple as a fraction of the speed (standard deviation).
    window : str
        ``"revolution"``: one window per revolution; ``"turn"``: one window per turn.
    """

    speed: float = 1.0
    turns: int = 1
    odr_hz: float = 200.0
    rest_s: float = 3.0
    ripple: float = 0.05
    window: str = "revolution"

    def __post_init__(self) -> None:
        if not (self.speed > 0 and np.isfinite(self.speed)):
            raise CalibInputError(f"speed must be positive, got {self.speed!r}")
        if int(self.turns) != self.turns or self.turns < 1:
            raise CalibInputError(f"turns must be a positive integer, got {self.turns!r}")
        if not self.odr_hz > 0:
            raise CalibInputError(f"odr_hz must be positive, got {self.odr_hz!r}")
        if self.rest_s < 0:
            raise CalibInputError(f"rest_s must not be negative, got {self.rest_s!r}")
        if self.window not in ("revolution", "turn"):
            raise CalibInputError(f"window must be 'revolution' or 'turn', got {self.window!r}")

    @property
    def samples_per_revolution(self) -> int:
        """Gyro samples in one revolution (rounded: windows hold whole samples)."""
        return int(round(2 * np.pi / self.speed * self.odr_hz))

    @property
    def rest_samples(self) -> int:
        """Gyro samples in one rest."""
        return int(round(self.rest_s * self.odr_hz))

    def layout(self, n_servos: int = 3) -> tuple[np.ndarray, np.ndarray, int]:
        """``(motor_index, direction, samples)`` of each rotation window, in protocol order."""
        per_turn = self.turns if self.window == "revolution" else 1
        n_per = self.samples_per_revolution * (1 if self.window == "revolution" else self.turns)
        motor, direction = [], []
        for s in range(n_servos):
            for d in (1, -1):
                motor += [s] * per_turn
                direction += [d] * per_turn
        return np.array(motor), np.array(direction), n_per

    @property
    def n_rests(self) -> int:
        """Rest windows: one before every turn and one at the end (three servos)."""
        return 7 if self.rest_s > 0 else 0

    @property
    def duration_s(self) -> float:
        """Jig time of the rotations and rests (ramps not modelled)."""
        return 6 * self.turns * 2 * np.pi / self.speed + self.n_rests * self.rest_s


@dataclass(frozen=True, eq=False)
class SimulatedRuns:
    """Window statistics of ``B`` simulated runs of one protocol (arrays lead with ``B``)."""

    mean: np.ndarray  # (B, n, 3)
    rate: np.ndarray  # (B, n) signed encoder reference
    motor_index: np.ndarray  # (n,)
    direction: np.ndarray  # (n,)
    count: np.ndarray  # (n,)
    noise: np.ndarray  # (B, n, 3) in-window first-difference noise estimate
    rate_std: np.ndarray  # (B, n)
    rest_mean: np.ndarray  # (B, r, 3)
    rest_count: np.ndarray  # (r,)
    rest_noise: np.ndarray  # (B, r, 3)

    @property
    def mean_std(self) -> np.ndarray:
        """Standard errors of the window means (white-noise estimate)."""
        return self.noise / np.sqrt(self.count)[None, :, None]

    @property
    def rest_mean_std(self) -> np.ndarray:
        """Standard errors of the rest means."""
        return self.rest_noise / np.sqrt(self.rest_count)[None, :, None]

    def observation_set(self, i: int, motor_ids: tuple[int, ...] = (1, 2, 3)) -> ObservationSet:
        """Run ``i`` as an :class:`~gyrocal.calib.observations.ObservationSet` (servo IDs
        ``motor_ids``)."""
        r = self.rest_mean.shape[1]
        return ObservationSet(
            mean=self.mean[i],
            rate=self.rate[i],
            motor=np.asarray(motor_ids)[self.motor_index],
            direction=self.direction,
            count=self.count,
            noise=self.noise[i],
            rate_std=self.rate_std[i],
            rest_mean=self.rest_mean[i] if r else None,
            rest_count=self.rest_count if r else None,
            rest_noise=self.rest_noise[i] if r else None,
        )


def simulate_runs(
    rng: np.random.Generator,
    scale: np.ndarray,
    bias: np.ndarray,
    axes: np.ndarray,
    protocol: SimProtocol,
    noise_std: float | np.ndarray,
    *,
    encoder_ticks: int = 4096,
    dtype: type = np.float32,
) -> SimulatedRuns:
    """Simulate ``B`` runs of ``protocol`` at sample level and reduce them to window statistics.

    Parameters
    ----------
    rng : numpy.random.Generator
        The only source of randomness.
    scale, bias : ndarray, shape (B, 3)
        True parameters (paper Eq. 1).
    axes : ndarray, shape (B, 3, 3)
        Servo axes in the sensor frame (see :func:`draw_mount_axes`).
    protocol : SimProtocol
        What the jig does.
    noise_std : float or ndarray of shape (3,)
        White noise per sample, rad/s.
    encoder_ticks : int
        Encoder resolution per revolution; the reference rate of a window carries the
        quantisation of its two end angles.
    dtype : numpy dtype
        Sample precision (float32 halves the time; window sums are accumulated in float64).

    Returns
    -------
    SimulatedRuns
    """
    scale = np.asarray(scale, dtype=float)
    bias = np.asarray(bias, dtype=float)
    axes = np.asarray(axes, dtype=float)
    B = scale.shape[0]
    if scale.shape != (B, 3) or bias.shape != (B, 3) or axes.shape != (B, 3, 3):
        raise CalibInputError(
            f"scale and bias must be (B, 3) and axes (B, 3, 3); got {scale.shape}, "
            f"{bias.shape}, {axes.shape}"
        )
    sigma = np.broadcast_to(np.asarray(noise_std, dtype=float), (3,))
    motor, direction, n_per = protocol.layout()
    n = motor.size
    w = protocol.speed
    dt = 1.0 / protocol.odr_hz
    t = np.arange(n_per) * dt

    # Band-limited ripple: sinusoids at the revolution frequency and its 2nd and 3rd harmonics,
    # and one at 3-6 Hz (one frequency per call), random phases per window; the per-component
    # amplitude gives a total standard deviation of ripple·ω. Built as coefficients times a
    # sin/cos basis (one matrix product instead of a sine per sample).
    f_rev = w / (2 * np.pi)
    freqs = np.array([f_rev, 2 * f_rev, 3 * f_rev, rng.uniform(3.0, 6.0)])
    n_comp = freqs.size
    arg = 2 * np.pi * freqs[:, None] * t[None, :]
    basis = np.concatenate([np.sin(arg), np.cos(arg)]).astype(dtype)  # (2c, N)
    phase = rng.uniform(0, 2 * np.pi, size=(B, n, n_comp))
    amp = protocol.ripple * np.sqrt(2.0 / n_comp)
    coef = (amp * np.concatenate([np.cos(phase), np.sin(phase)], axis=2)).astype(dtype)
    ripple = (coef.reshape(B * n, 2 * n_comp) @ basis).reshape(B, n, n_per)
    omega = ripple
    omega += dtype(1.0)
    omega *= (direction * w)[None, :, None].astype(dtype)  # (B, n, N): d·ω·(1 + ripple)
    # True mean rate over the window = encoder angle change / duration (whole samples, the rate
    # held over each sample period), plus the quantisation of the two end angles.
    true_mean = omega.mean(axis=2, dtype=np.float64)
    q = 2 * np.pi / encoder_ticks
    duration = n_per * dt
    quant = (rng.uniform(-0.5, 0.5, size=(B, n)) - rng.uniform(-0.5, 0.5, size=(B, n))) * q
    rate = true_mean + quant / duration
    rate_std = np.full((B, n), q / np.sqrt(6.0) / duration)

    u = axes[:, motor, :]  # (B, n, 3)
    c_vec = (u / scale[:, None, :]).astype(dtype)
    mean = np.empty((B, n, 3))
    noise = np.empty((B, n, 3))
    for j in range(3):
        x = rng.standard_normal((B, n, n_per), dtype=dtype)
        x *= dtype(sigma[j])
        x += omega * c_vec[:, :, j, None]
        mean[:, :, j] = x.mean(axis=2, dtype=np.float64) - bias[:, None, j]
        noise[:, :, j] = diff_noise(x, axis=2)
    r = protocol.n_rests
    nr = protocol.rest_samples
    rest_mean = np.empty((B, r, 3))
    rest_noise = np.empty((B, r, 3))
    if r:
        for j in range(3):
            x = rng.standard_normal((B, r, nr), dtype=dtype)
            x *= dtype(sigma[j])
            rest_mean[:, :, j] = x.mean(axis=2, dtype=np.float64) - bias[:, None, j]
            rest_noise[:, :, j] = diff_noise(x, axis=2)
    return SimulatedRuns(
        mean=mean,
        rate=rate,
        motor_index=motor,
        direction=direction,
        count=np.full(n, n_per),
        noise=noise,
        rate_std=rate_std,
        rest_mean=rest_mean,
        rest_count=np.full(r, nr),
        rest_noise=rest_noise,
    )


# ---------------------------------------------------------------------------------- raw streams
@dataclass(frozen=True, eq=False)
class RawRun:
    """One simulated run as raw streams, in the shape of a Recording v1.

    Attributes
    ----------
    imu_t, imu_rate, imu_temp : ndarray
        Gyro sample times (the chip's true sampling instants on the host clock), readings (rad/s)
        and die temperature.
    enc_t, enc_motor, enc_angle : ndarray
        Encoder readings as a host would timestamp them (with jitter), quantised.
    segments : tuple of Segment
    scale, bias : ndarray (3,)
        Truth.
    axes : ndarray (3, 3)
        Servo axes in the sensor frame (row s = servo ``motor_ids[s]``).
    motor_ids : tuple of int
    grid_t : ndarray
        The fine time grid of the true motion.
    grid_rate : ndarray (3, G)
        Each servo's true shaft rate on the grid, rad/s.
    grid_angle : ndarray (3, G)
        Each servo's true shaft angle on the grid, rad.
    """

    imu_t: np.ndarray
    imu_rate: np.ndarray
    imu_temp: np.ndarray
    enc_t: np.ndarray
    enc_motor: np.ndarray
    enc_angle: np.ndarray
    segments: tuple[Segment, ...]
    scale: np.ndarray
    bias: np.ndarray
    axes: np.ndarray
    motor_ids: tuple[int, ...]
    grid_t: np.ndarray
    grid_rate: np.ndarray
    grid_angle: np.ndarray

    def true_weighted_rate(self, motor: int, corners: tuple[float, float, float, float]) -> float:
        """The true mean shaft rate of ``motor`` under a trapezoidal window (fine-grid quadrature),
        for checking window extraction against the truth."""
        s = self.motor_ids.index(motor)
        t = self.grid_t
        w = trapezoid_weight(t, corners)
        return float(np.trapezoid(w * self.grid_rate[s], t) / np.trapezoid(w, t))


def _speed_profile(t: np.ndarray, total: float, speed: float, accel: float) -> np.ndarray:
    """Trapezoidal speed profile (≥ 0) covering ``total`` rad from t = 0; zero outside."""
    t_acc = speed / accel
    if speed * t_acc >= total:  # triangle: never reaches full speed
        t_acc = np.sqrt(total / accel)
        peak = accel * t_acc
        t_flat = 0.0
    else:
        peak = speed
        t_flat = (total - speed * t_acc) / speed
    t_end = 2 * t_acc + t_flat
    v = np.where(t < t_acc, accel * t, peak)
    v = np.where(t > t_acc + t_flat, peak - accel * (t - t_acc - t_flat), v)
    return np.where((t >= 0) & (t <= t_end), np.maximum(v, 0.0), 0.0)


def profile_duration(total: float, speed: float, accel: float) -> float:
    """Duration of :func:`_speed_profile`."""
    t_acc = speed / accel
    if speed * t_acc >= total:
        return 2 * np.sqrt(total / accel)
    return 2 * t_acc + (total - speed * t_acc) / speed


def simulate_raw_run(
    rng: np.random.Generator,
    scale: np.ndarray,
    bias: np.ndarray,
    axes: np.ndarray,
    protocol: SimProtocol,
    noise_std: float,
    *,
    accel: float = 8.0,
    imu_clock_error: float = 0.0,
    enc_rate_hz: float = 100.0,
    enc_jitter_s: float = 0.0,
    imu_jitter_s: float = 0.0,
    encoder_ticks: int = 4096,
    motor_ids: tuple[int, ...] = (1, 2, 3),
    settle_s: float = 0.1,
    grid_hz: float = 10_000.0,
    temperature_c: float = 25.0,
) -> RawRun:
    """Simulate one run as raw streams: rests, then for each servo a turn each way.

    The servo follows a trapezoidal speed profile (acceleration ``accel``) over ``turns`` whole
    revolutions, with ripple proportional to the current speed (``protocol.ripple``, random-phase
    sinusoids at the revolution frequency, its harmonics and 3-6 Hz); its angle is the exact
    integral of its rate on a fine grid. The gyro samples the true rate at its own instants
    (its clock runs ``1 + imu_clock_error`` fast against the host) and reads
    ``m = (ω u_s) ⊘ k − b + noise`` (paper Eq. 1). The encoder is read at ``enc_rate_hz``,
    quantised to ``encoder_ticks`` per revolution and timestamped with Gaussian jitter; the gyro's
    recorded timestamps may carry jitter too (``imu_jitter_s``, clipped to a third of a period so
    the order is kept).

    The run is built by :func:`stream_raw_run` and gathered whole; for long runs use that
    directly.

    Returns
    -------
    RawRun
    """
    stream = stream_raw_run(
        rng, scale, bias, axes, protocol, noise_std, accel=accel,
        imu_clock_error=imu_clock_error, enc_rate_hz=enc_rate_hz, enc_jitter_s=enc_jitter_s,
        imu_jitter_s=imu_jitter_s, encoder_ticks=encoder_ticks, motor_ids=motor_ids,
        settle_s=settle_s, grid_hz=grid_hz, temperature_c=temperature_c,
    )
    imu = [np.concatenate(c) for c in zip(*stream.imu_chunks(), strict=True)]
    enc = [np.concatenate(c) for c in zip(*stream.encoder_chunks(), strict=True)]
    pieces = list(stream._grid())  # each piece starts at the last point of the one before
    grid = [np.concatenate([pieces[0][k], *(p[k][..., 1:] for p in pieces[1:])], axis=-1)
            for k in range(3)]
    return RawRun(
        imu_t=imu[0],
        imu_rate=imu[1],
        imu_temp=imu[2],
        enc_t=enc[0],
        enc_motor=enc[1],
        enc_angle=enc[2],
        segments=stream.segments,
        scale=stream.scale,
        bias=stream.bias,
        axes=stream.axes,
        motor_ids=stream.motor_ids,
        grid_t=grid[0],
        grid_rate=grid[1],
        grid_angle=grid[2],
    )


def _count_below(n_max: int, step: float, offset: float, limit: float, strict: bool) -> int:
    """How many of ``i·step + offset`` (``i < n_max``, as ``np.arange(0, ·, step) + offset``
    computes them) are below ``limit`` (``strict``) or at most it."""
    k = min(n_max, max(0, int((limit - offset) / step) + 2))

    def inside(i: int) -> bool:
        v = float(i) * step + offset
        return v < limit if strict else v <= limit

    while k > 0 and not inside(k - 1):
        k -= 1
    while k < n_max and inside(k):
        k += 1
    return k


def _arange_len(stop: float, step: float) -> int:
    """``len(np.arange(0.0, stop, step))`` without building it."""
    return max(0, math.ceil(stop / step))


@dataclass(frozen=True)
class RawRunStream:
    """:func:`simulate_raw_run`'s run, produced in time-ordered chunks in bounded memory.

    Built by :func:`stream_raw_run`; :meth:`imu_chunks` and :meth:`encoder_chunks` each
    regenerate the fine grid chunk by chunk, so either may be iterated (once each) without
    holding the run. The values equal :func:`simulate_raw_run`'s for the same generator state
    (see the test ``tests/calib/test_simulate_stream.py``).
    """

    segments: tuple[Segment, ...]
    motor_ids: tuple[int, ...]
    scale: np.ndarray
    bias: np.ndarray
    axes: np.ndarray
    n_imu: int
    n_encoder_times: int
    _p: dict[str, Any]

    def _grid(self) -> Iterator[tuple[np.ndarray, np.ndarray, np.ndarray]]:
        """Consecutive grid pieces ``(g, rate (3, k), angle (3, k))``; each starts at the last
        point of the one before, and the values equal the whole grid's bit for bit."""
        p = self._p
        h, ng, size = p["h"], p["ng"], p["grid_chunk"]
        carry = np.zeros((3, 1))
        i0 = 0
        while i0 < ng - 1 or i0 == 0:
            i1 = min(ng, i0 + size)
            g = np.arange(i0, i1, dtype=float) * h
            rate = np.zeros((3, g.size))
            for s, d, t0, freqs, phases in p["turns"]:
                if g[-1] - t0 < 0.0 or g[0] - t0 > p["t_turn"] + 1e-6:
                    continue  # the profile is 0 here: adding d·0 would change nothing
                prof = _speed_profile(g - t0, p["total"], p["speed"], p["accel"])
                rip = sum(p["amp"] * np.sin(TWO_PI * f * (g - t0) + ph)
                          for f, ph in zip(freqs, phases, strict=True))
                rate[s] += d * prof * (1.0 + rip)
            inc = (rate[:, 1:] + rate[:, :-1]) / 2 / p["grid_hz"]
            angle = np.cumsum(np.concatenate([carry, inc], axis=1), axis=1)
            carry = angle[:, -1:]
            yield g, rate, angle
            if i1 >= ng:
                return
            i0 = i1 - 1

    def imu_chunks(self) -> Iterator[tuple[np.ndarray, np.ndarray, np.ndarray]]:
        """``(t, rate (k, 3), temperature (k,))`` in time order, as the run's ``imu_*``."""
        p = self._p
        noise = np.random.Generator(np.random.PCG64())
        noise.bit_generator.state = p["noise_state"]
        jit = np.random.Generator(np.random.PCG64())
        jit.bit_generator.state = p["imu_jitter_state"]
        done = 0
        g_last = p["g_last"]
        for g, rate, _ in self._grid():
            last = g[-1] >= g_last
            upto = _count_below(self.n_imu, p["period"], p["offset"], g[-1], strict=not last)
            if upto > done:
                t = np.arange(done, upto, dtype=float) * p["period"] + p["offset"]
                w = np.stack([np.interp(t, g, rate[s]) for s in range(3)], axis=1)
                gs = w @ self.axes
                m = gs / self.scale - self.bias + noise.standard_normal(gs.shape) * p["noise_std"]
                if p["imu_jitter_s"]:
                    lim = p["period"] / 3
                    t = t + np.clip(jit.normal(0.0, p["imu_jitter_s"], t.size), -lim, lim)
                yield t, m, np.full(t.size, p["temperature_c"])
                done = upto

    def encoder_chunks(self) -> Iterator[tuple[np.ndarray, np.ndarray, np.ndarray]]:
        """``(t, motor, angle)`` rows in the run's order (a sync read of every servo per time)."""
        p = self._p
        step, n = p["enc_step"], self.n_encoder_times
        bounds = self._encoder_bounds()
        jit = np.random.Generator(np.random.PCG64())
        jit.bit_generator.state = p["enc_jitter_state"]
        # Sorting jittered stamps chunk by chunk: a stamp is final once below every later one.
        later_min = [math.inf] * (len(bounds) + 1)
        if p["enc_jitter_s"]:
            pre = np.random.Generator(np.random.PCG64())
            pre.bit_generator.state = p["enc_jitter_state"]
            mins = []
            for a, b in bounds:
                te = np.arange(a, b, dtype=float) * step
                mins.append(float(np.min(te + pre.normal(0.0, p["enc_jitter_s"], te.size)))
                            if b > a else math.inf)
            for c in range(len(bounds) - 1, -1, -1):
                later_min[c] = min(mins[c], later_min[c + 1])
        q = TWO_PI / p["ticks"]
        pool = np.empty(0)
        angles = np.empty((3, 0))
        ids = np.asarray(self.motor_ids)
        for c, (g, _, angle) in enumerate(self._grid()):
            a, b = bounds[c]
            te = np.arange(a, b, dtype=float) * step
            th = np.stack([np.round(np.interp(te, g, angle[s]) / q) * q for s in range(3)])
            angles = np.concatenate([angles, th], axis=1)
            stamp = te + jit.normal(0.0, p["enc_jitter_s"], te.size) if p["enc_jitter_s"] else te
            pool = np.sort(np.concatenate([pool, stamp]))
            k = int(np.searchsorted(pool, later_min[c + 1], side="left"))
            if k:
                ts, pool = pool[:k], pool[k:]
                ang, angles = angles[:, :k], angles[:, k:]
                yield np.repeat(ts, 3), np.tile(ids, k), ang.T.reshape(-1)
        assert pool.size == 0 and n == bounds[-1][1]

    def _encoder_bounds(self) -> list[tuple[int, int]]:
        """The encoder times ``[a, b)`` that fall in each grid piece (as :meth:`_grid` cuts)."""
        p = self._p
        out = []
        done = 0
        for i1 in p["piece_ends"]:
            last = i1 == p["ng"] - 1
            upto = _count_below(self.n_encoder_times, p["enc_step"], 0.0, float(i1) * p["h"],
                                strict=not last)
            out.append((done, upto))
            done = upto
        return out


def stream_raw_run(
    rng: np.random.Generator,
    scale: np.ndarray,
    bias: np.ndarray,
    axes: np.ndarray,
    protocol: SimProtocol,
    noise_std: float,
    *,
    accel: float = 8.0,
    imu_clock_error: float = 0.0,
    enc_rate_hz: float = 100.0,
    enc_jitter_s: float = 0.0,
    imu_jitter_s: float = 0.0,
    encoder_ticks: int = 4096,
    motor_ids: tuple[int, ...] = (1, 2, 3),
    settle_s: float = 0.1,
    grid_hz: float = 10_000.0,
    temperature_c: float = 25.0,
    grid_chunk: int = 1 << 16,
) -> RawRunStream:
    """:func:`simulate_raw_run` for runs of any length: the same model and the same values for
    the same ``rng`` state, produced in chunks of ``grid_chunk`` fine-grid points.

    ``rng`` is left where :func:`simulate_raw_run` leaves it: the draws of each stream (gyro
    noise, encoder jitter, gyro jitter) are located by advancing copies of the generator
    through the earlier streams, in chunks, without keeping them.

    Returns
    -------
    RawRunStream
    """
    scale = np.asarray(scale, dtype=float).reshape(3)
    bias = np.asarray(bias, dtype=float).reshape(3)
    axes = np.asarray(axes, dtype=float).reshape(3, 3)
    total = TWO_PI * protocol.turns
    t_turn = profile_duration(total, protocol.speed, accel)
    segs: list[Segment] = []
    starts = []
    t = 0.0
    idx = 0
    for s, motor in enumerate(motor_ids):
        for d in (1, -1):
            segs.append(Segment(idx, "rest", None, 0, 0.0, t, t + protocol.rest_s))
            t += protocol.rest_s
            idx += 1
            segs.append(Segment(idx, "rotate", motor, d, protocol.speed, t,
                                t + t_turn + settle_s))
            starts.append((s, d, t))
            t += t_turn + settle_s
            idx += 1
    segs.append(Segment(idx, "rest", None, 0, 0.0, t, t + protocol.rest_s))
    t_total = t + protocol.rest_s
    h = 1.0 / grid_hz
    ng = _arange_len(t_total + 1.0 / grid_hz, 1.0 / grid_hz)
    g_last = float(ng - 1) * h
    f_rev = protocol.speed / TWO_PI
    turns = []
    for s, d, t0 in starts:  # the ripple draws, in simulate_raw_run's order
        freqs = [f_rev, 2 * f_rev, 3 * f_rev, rng.uniform(3.0, 6.0)]
        phases = [rng.uniform(0, TWO_PI) for _ in freqs]
        turns.append((s, d, t0, freqs, phases))
    period = 1.0 / (protocol.odr_hz * (1.0 + imu_clock_error))
    offset = rng.uniform(0, period)
    n_imu = _count_below(_arange_len(t_total, period), period, offset, g_last, strict=False)
    n_te = _arange_len(t_total, 1.0 / enc_rate_hz)

    def skip(count: int, width: int = 1) -> None:
        for a in range(0, count, 1 << 16):
            rng.standard_normal((min(count, a + (1 << 16)) - a, width))

    noise_state = rng.bit_generator.state
    skip(n_imu, 3)
    enc_state = rng.bit_generator.state
    if enc_jitter_s:
        skip(n_te)
    imu_jitter_state = rng.bit_generator.state
    if imu_jitter_s:
        skip(n_imu)
    piece_ends = []
    i0 = 0
    while True:
        i1 = min(ng, i0 + grid_chunk)
        piece_ends.append(i1 - 1)
        if i1 >= ng:
            break
        i0 = i1 - 1
    params = {
        "h": h, "ng": ng, "g_last": g_last, "grid_hz": grid_hz, "grid_chunk": grid_chunk,
        "piece_ends": piece_ends, "turns": turns, "total": total, "speed": protocol.speed,
        "accel": accel, "t_turn": t_turn, "amp": protocol.ripple * np.sqrt(2.0 / 4),
        "period": period,
        "offset": offset, "noise_std": noise_std, "noise_state": noise_state,
        "imu_jitter_s": imu_jitter_s, "imu_jitter_state": imu_jitter_state,
        "temperature_c": float(temperature_c), "enc_step": 1.0 / enc_rate_hz,
        "enc_jitter_s": enc_jitter_s, "enc_jitter_state": enc_state, "ticks": encoder_ticks,
    }
    return RawRunStream(tuple(segs), tuple(motor_ids), scale, bias, axes, n_imu, n_te, params)
