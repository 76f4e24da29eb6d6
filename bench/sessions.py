"""Independent gyro sessions for the bias tracker, written from the contract alone.

This generator shares no code with :mod:`gyrocal.calib.noise_sim` (it imports nothing from
``gyrocal`` but the Calibration v1 type it hands out). It follows the calibration model of the
paper, Eq. (1), in the Calibration v1 convention: a true rate ``g`` is read as

    m = g ⊘ k − b(t) + v,        b(t) = b₀ + c ∘ (T(t) − T₀) + w(t) + Σ steps,

with ``k`` the scale, ``v`` white noise of density ``N`` (per-sample σ = N·√odr), ``w`` a bias
random walk of coefficient ``K`` (increments N(0, K²·Δt)), ``c`` a linear temperature
coefficient, and the reading quantised to the LSB of a 16-bit converter at ±500 °/s. The die
temperature follows the session's profile (ramps up or down, or a cycle) plus 0.01 °C noise,
quantised to 1/333.87 °C (MPU-9250 register map, TEMP_OUT).

Motions are of two kinds: *turns* (one axis at a time, a trapezoidal speed profile of one or two
whole revolutions at 30-120 °/s, as the jig's servos make them) and *hand-held* motion (smooth
random rates, band-limited by a moving average, tapered in and out). Between motions the sensor
rests; the rest lengths and the motion lengths define the session *families* of
:data:`FAMILIES`. A session also carries its rest intervals (as a recording's rest segments
would) and an earlier offline calibration (the truth at ``T₀`` plus a draw of its stated
uncertainty).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from gyrocal.calib.model import GyroCalibration

LSB_RAD_S = math.radians(500.0) / 32768.0
TEMP_LSB_C = 1.0 / 333.87


@dataclass(frozen=True)
class Family:
    """How one family of sessions is drawn (ranges are drawn uniformly per session)."""

    name: str
    odr_hz: float
    duration_s: float
    noise_density: tuple[float, float]  # rad/s/√Hz
    rate_random_walk: tuple[float, float]  # rad/s/√s
    tempco: float  # rad/s/°C, magnitude bound per axis
    temperature: str  # "up", "down" or "cycle"
    temp_span_c: tuple[float, float]
    motion: str  # "turns" or "hand"
    rest_s: tuple[float, float]
    motion_s: tuple[float, float]
    steps: int = 0
    step_size: tuple[float, float] = (1e-3, 3e-3)


FAMILIES: dict[str, Family] = {
    f.name: f
    for f in (
        Family("jig turns, 6-15 s rests", 200.0, 600.0, (1.5e-4, 3e-4), (1e-4, 3e-4), 3e-4,
               "up", (8.0, 20.0), "turns", (6.0, 15.0), (0.0, 0.0)),
        Family("1 kHz hand-held, 2-5 s rests", 1000.0, 300.0, (8e-5, 1.5e-4), (3e-5, 1e-4),
               2e-4, "up", (3.0, 8.0), "hand", (2.0, 5.0), (5.0, 20.0)),
        Family("noisy 100 Hz, rests of minutes", 100.0, 900.0, (4e-4, 8e-4), (3e-5, 1e-4),
               3e-4, "down", (8.0, 15.0), "hand", (60.0, 180.0), (20.0, 60.0)),
        Family("continuous motion, rare rests", 400.0, 900.0, (1e-4, 2e-4), (1e-5, 5e-5), 2e-4,
               "up", (5.0, 10.0), "hand", (3.0, 10.0), (60.0, 150.0)),
        Family("temperature cycle", 200.0, 900.0, (1e-4, 2e-4), (1e-5, 5e-5), 4e-4, "cycle",
               (10.0, 20.0), "turns", (5.0, 12.0), (0.0, 0.0)),
        Family("bias steps", 200.0, 600.0, (1e-4, 2e-4), (1e-5, 3e-5), 2e-4, "up",
               (5.0, 10.0), "turns", (6.0, 15.0), (0.0, 0.0), steps=2),
    )
}


@dataclass(frozen=True, eq=False)
class Session:
    """One generated session and its truth (rad/s, s, °C)."""

    family: str
    odr_hz: float
    t: np.ndarray
    rate: np.ndarray
    temperature_c: np.ndarray
    true_rate: np.ndarray
    true_bias: np.ndarray
    still: np.ndarray
    rests: list[tuple[float, float]]
    noise_density: np.ndarray
    rate_random_walk: np.ndarray
    tempco: np.ndarray
    step_times: list[float]
    calibration: GyroCalibration
    axes: np.ndarray = field(default_factory=lambda: np.eye(3))


def _turn(rng: np.random.Generator, fs: float, axis: np.ndarray) -> np.ndarray:
    """A trapezoidal turn of 1 or 2 revolutions, one way or the other: rate (n, 3)."""
    revs = float(rng.integers(1, 3))
    speed = math.radians(rng.uniform(30.0, 120.0))
    accel = math.radians(300.0)
    t_acc = speed / accel
    angle = 2 * math.pi * revs
    t_flat = angle / speed - t_acc
    total = 2 * t_acc + t_flat
    tt = np.arange(int(math.ceil(total * fs))) / fs
    w = np.minimum(np.minimum(tt / t_acc, 1.0), np.maximum((total - tt) / t_acc, 0.0)) * speed
    sign = 1.0 if rng.random() < 0.5 else -1.0
    return sign * w[:, None] * axis[None, :]


def _hand(rng: np.random.Generator, fs: float, seconds: float) -> np.ndarray:
    """Smooth random rates (moving average of white noise over 0.3 s), tapered: (n, 3)."""
    n = max(int(seconds * fs), 2)
    k = max(int(0.3 * fs), 1)
    raw = rng.standard_normal((n + k, 3))
    kernel = np.ones(k) / k
    sm = np.stack([np.convolve(raw[:, i], kernel, mode="valid")[:n] for i in range(3)], axis=1)
    sm *= rng.uniform(0.3, 1.5) / max(float(np.std(sm)), 1e-12)
    ramp = min(int(0.5 * fs), n // 2)
    taper = np.ones(n)
    taper[:ramp] = 0.5 - 0.5 * np.cos(np.pi * np.arange(ramp) / ramp)
    taper[n - ramp:] = taper[:ramp][::-1]
    return sm * taper[:, None]


def _temperature(fam: Family, rng: np.random.Generator, t: np.ndarray) -> np.ndarray:
    span = rng.uniform(*fam.temp_span_c)
    start = rng.uniform(20.0, 35.0)
    x = t / t[-1]
    if fam.temperature == "up":
        prof = span * (1 - np.exp(-4 * x)) / (1 - math.exp(-4))
    elif fam.temperature == "down":
        prof = span * (np.exp(-3 * x) - 1) / (1 - math.exp(-3))
    else:  # warm up for the first half, cool down in the second
        prof = span * np.sin(np.pi * x)
    temp = start + prof + 0.01 * rng.standard_normal(t.size)
    return np.round(temp / TEMP_LSB_C) * TEMP_LSB_C


def generate(family: str, seed: int, odr_hz: float | None = None) -> Session:
    """One session of ``family`` (a key of :data:`FAMILIES`) from ``seed``, at the family's
    output data rate or at ``odr_hz`` (the same schedule and sensor drawn at another rate: the
    streaming benchmark's jig at 1 kHz)."""
    fam = FAMILIES[family]
    rng = np.random.default_rng(seed)
    fs = fam.odr_hz if odr_hz is None else float(odr_hz)
    # ---- motion schedule: rest, motion, rest, ... until the duration
    axes = np.linalg.qr(rng.standard_normal((3, 3)))[0].T  # three orthonormal servo axes
    pieces: list[np.ndarray] = []
    rests: list[tuple[float, float]] = []
    n_total = int(fam.duration_s * fs)
    n = 0
    first = True
    while n < n_total:
        rest_s = rng.uniform(*fam.rest_s) if not first else max(rng.uniform(*fam.rest_s), 3.0)
        first = False
        k = int(rest_s * fs)
        rests.append((n / fs, (n + k - 1) / fs))
        pieces.append(np.zeros((k, 3)))
        n += k
        if fam.motion == "turns":
            pieces.append(_turn(rng, fs, axes[rng.integers(0, 3)]))
        else:
            pieces.append(_hand(rng, fs, rng.uniform(*fam.motion_s)))
        n += pieces[-1].shape[0]
    g = np.vstack(pieces)[:n_total]
    t = np.arange(n_total) / fs
    rests = [(a, min(b, t[-1])) for a, b in rests if a < t[-1]]
    still = np.all(g == 0.0, axis=1)
    # ---- sensor
    nd = rng.uniform(*fam.noise_density, size=3)
    kw = rng.uniform(*fam.rate_random_walk, size=3)
    c = rng.uniform(-fam.tempco, fam.tempco, size=3)
    scale = 1.0 + rng.uniform(-0.03, 0.03, size=3)
    b0 = rng.uniform(-0.03, 0.03, size=3)
    temp = _temperature(fam, rng, t)
    t0 = float(temp[0])
    walk = np.cumsum(rng.standard_normal((n_total, 3)) * kw * math.sqrt(1.0 / fs), axis=0)
    bias = b0 + c * (temp[:, None] - t0) + walk
    step_times: list[float] = []
    for _ in range(fam.steps):
        ts = float(rng.uniform(0.2, 0.9) * t[-1])
        size = rng.uniform(*fam.step_size) * rng.choice([-1.0, 1.0], size=3)
        size[rng.integers(0, 3)] = 0.0
        bias[t >= ts] += size
        step_times.append(ts)
    white = rng.standard_normal((n_total, 3)) * nd * math.sqrt(fs)
    m = g / scale - bias + white
    m = np.round(m / LSB_RAD_S) * LSB_RAD_S
    # ---- an earlier offline calibration: truth at T0 plus its stated uncertainty
    cal_bstd, cal_kstd = 2e-4, 2e-4
    cal = GyroCalibration(
        scale=tuple(scale + rng.standard_normal(3) * cal_kstd),  # type: ignore[arg-type]
        bias=tuple(b0 + rng.standard_normal(3) * cal_bstd),  # type: ignore[arg-type]
        scale_std=(cal_kstd,) * 3,  # type: ignore[arg-type]
        bias_std=(cal_bstd,) * 3,  # type: ignore[arg-type]
        method="independent generator",
        temperature_c=t0,
        axes={str(i + 1): {"axis": [float(x) for x in axes[i]]} for i in range(3)},
    )
    return Session(
        family=family, odr_hz=fs, t=t, rate=m, temperature_c=temp, true_rate=g, true_bias=bias,
        still=still, rests=rests, noise_density=nd, rate_random_walk=kw, tempco=c,
        step_times=step_times, calibration=cal, axes=axes,
    )


def rest_flags(s: Session, trim_s: float = 0.5) -> np.ndarray:
    """Still flags from the session's rest intervals, as a recording's rest segments give them:
    1 inside a rest (less ``trim_s`` at each end), NaN elsewhere (let the detector decide)."""
    out = np.full(s.t.size, np.nan)
    for a, b in s.rests:
        if b - a > 2 * trim_s:
            out[(s.t >= a + trim_s) & (s.t <= b - trim_s)] = 1.0
    return out
