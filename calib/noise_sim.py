"""Synthetic gyro sessions with known noise and bias behaviour (seeded, pure numpy).

The reading follows the calibration model (paper Eq. 1, ``g = scale ∘ (m + bias)``) solved for
``m``, with a bias that moves:

    m(t) = g(t) ⊘ scale − b(t) + w(t),
    b(t) = b0 + c ∘ (T(t) − T_ref) + r(t) + f(t) + step(t),

where ``w`` is white noise of density ``N`` (angle random walk, rad/s/√Hz), ``r`` a rate random walk
of coefficient ``K`` (rad/s/√s), ``f`` flicker (1/f) noise of bias-instability coefficient ``B``
(rad/s), ``c`` a linear temperature coefficient (rad/s/°C) and ``step`` an optional step change.
``b`` is in the Calibration v1 convention (added to the reading), so a still sensor reads ``−b``.

The noise terms follow the power spectral densities of IEEE Std 952-1997, Annex C (two-sided
form, as used there with ``σ²(τ) = 4 ∫ S(f) sin⁴(πfτ)/(πfτ)² df``): white rate noise
``S = N²`` gives ``σ(τ) = N/√τ``; flicker ``S = B²/(2πf)`` gives the floor
``σ = B √(2 ln 2/π) ≈ 0.664 B``; rate random walk ``S = (K/2π)²/f²`` gives ``σ(τ) = K √(τ/3)``.

Two kinds of session:

* :func:`simulate_still` — the sensor at rest at constant temperature, for noise
  characterisation (Allan deviation).
* :func:`simulate_session` — an operating session: still periods of a few seconds between
  motions, a temperature ramp, the bias walking. Motions are either smooth random rotations
  (``motion="random"``: the rate is unknown to a tracker) or servo turns of the jig about known
  axes at a known rate (``motion="jig"``: ``reference_rate``/``reference_axis`` hold what the
  encoders would report).

This is a synthetic sensor, not the emulated jig of ``gyrocal.drivers.emulated``: no registers, no
buses, no servo dynamics beyond a speed profile with ripple. Everything is a pure function of its
arguments and one ``numpy.random.Generator``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from gyrocal.calib.errors import CalibInputError
from gyrocal.calib.model import GyroCalibration
from gyrocal.calib.validation import scalar, vec3

__all__ = [
    "FLICKER_FLOOR",
    "NoiseModel",
    "SimSession",
    "flicker_noise",
    "sim_calibration",
    "simulate_session",
    "simulate_still",
]

#: Allan deviation floor of flicker rate noise per unit bias instability, √(2 ln 2 / π).
FLICKER_FLOOR = math.sqrt(2.0 * math.log(2.0) / math.pi)

#: MPU-9250 temperature sensor resolution, °C per LSB (TEMP_OUT / 333.87 + 21).
_TEMP_LSB_C = 1.0 / 333.87


def _sample_count(duration_s: float, fs: float) -> int:
    """Samples in ``duration_s`` at ``fs`` Hz (at least 16)."""
    n = int(round(scalar(duration_s, "duration_s", positive=True) * fs))
    if n < 16:
        raise CalibInputError(f"duration_s gives only {n} samples at {fs} Hz; give a longer one")
    return n


@dataclass(frozen=True)
class NoiseModel:
    """Stochastic errors of a gyro, per axis (IEEE Std 952 coefficients).

    Attributes
    ----------
    noise_density : tuple of 3 float
        Angle random walk ``N``, rad/s/√Hz (white rate noise). The default, 1.75e-4, is the
        order of the MPU-9250's datasheet figure of 0.01 °/s/√Hz.
    rate_random_walk : tuple of 3 float
        ``K``, rad/s/√s (= rad/s²/√Hz): the bias performs a random walk whose increments over
        ``dt`` have variance ``K² dt``.
    bias_instability : tuple of 3 float
        ``B``, rad/s: coefficient of flicker (1/f) rate noise; the Allan deviation floor is
        ``0.664 B``.
    """

    noise_density: tuple[float, float, float] = (1.75e-4, 1.75e-4, 1.75e-4)
    rate_random_walk: tuple[float, float, float] = (2e-6, 2e-6, 2e-6)
    bias_instability: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def __post_init__(self) -> None:
        for name in ("noise_density", "rate_random_walk", "bias_instability"):
            a = vec3(getattr(self, name), name, nonneg=True)
            object.__setattr__(self, name, tuple(float(x) for x in a))

    def white_std(self, odr_hz: float) -> np.ndarray:
        """Per-sample standard deviation of the white noise at ``odr_hz``: ``N √odr``, rad/s."""
        return np.asarray(self.noise_density) * math.sqrt(scalar(odr_hz, "odr_hz", positive=True))


@dataclass(frozen=True, eq=False)
class SimSession:
    """A simulated session, with the truth next to what the sensor reports.

    Attributes
    ----------
    t : ndarray (n,)
        Sample times, s.
    rate : ndarray (n, 3)
        Readings ``m``, rad/s (what a Recording v1 ``imu.csv`` holds).
    temperature_c : ndarray (n,)
        Die temperature as the sensor reports it (quantised), °C.
    true_rate : ndarray (n, 3)
        True angular rate ``g`` in the sensor frame, rad/s.
    true_bias : ndarray (n, 3)
        True bias ``b(t)`` in the Calibration v1 convention, rad/s.
    still : ndarray (n,) of bool
        True where the sensor is at rest (``true_rate`` exactly zero).
    reference_rate : ndarray (n,)
        Jig sessions: the turning servo's rate from its encoder, rad/s; NaN elsewhere.
    reference_axis : ndarray (n, 3)
        Jig sessions: the turning servo's unit axis in the sensor frame; NaN elsewhere.
    reference_motor : ndarray (n,) of int
        Jig sessions: Dynamixel ID (1..3) of the turning servo; 0 elsewhere.
    odr_hz : float
    scale : ndarray (3,)
        True scale factors.
    tempco : ndarray (3,)
        True temperature coefficient of the bias, rad/s/°C.
    t_ref_c : float
        Temperature at which the bias equals ``b0``, °C.
    axes : ndarray (3, 3)
        Rows: servo axes in the sensor frame (jig sessions; identity otherwise).
    model : NoiseModel
    step_t : float or None
        Time of an injected bias step, s.
    """

    t: np.ndarray
    rate: np.ndarray
    temperature_c: np.ndarray
    true_rate: np.ndarray
    true_bias: np.ndarray
    still: np.ndarray
    reference_rate: np.ndarray
    reference_axis: np.ndarray
    reference_motor: np.ndarray
    odr_hz: float
    scale: np.ndarray
    tempco: np.ndarray
    t_ref_c: float
    axes: np.ndarray
    model: NoiseModel = field(default_factory=NoiseModel)
    step_t: float | None = None

    @property
    def n(self) -> int:
        """Number of samples."""
        return int(self.t.size)

    @property
    def duration_s(self) -> float:
        """Length of the session, s (samples × period)."""
        return self.n / self.odr_hz


def flicker_noise(
    rng: np.random.Generator, n: int, odr_hz: float, bias_instability: np.ndarray
) -> np.ndarray:
    """Flicker (1/f) rate noise by spectral synthesis, shape ``(n, 3)``.

    The one-sided density is ``2 · B²/(2π f) = B²/(π f)`` (the IEEE Std 952 two-sided
    ``B²/(2π f)`` folded onto ``f > 0``) from the record's lowest frequency ``odr/n`` up to the
    Nyquist frequency, with random phases; the DC term is zero.

    Parameters
    ----------
    rng : numpy.random.Generator
    n : int
        Samples.
    odr_hz : float
        Sample rate, Hz.
    bias_instability : array_like, shape (3,)
        ``B`` per axis, rad/s.
    """
    B = vec3(bias_instability, "bias_instability", nonneg=True)
    fs = scalar(odr_hz, "odr_hz", positive=True)
    if n < 2:
        raise CalibInputError(f"n must be at least 2, got {n}")
    f = np.fft.rfftfreq(n, d=1.0 / fs)
    psd1 = np.zeros_like(f)
    psd1[1:] = 1.0 / (math.pi * f[1:])
    # A bin of one-sided density S carries variance S·fs/n; with irfft's 1/n normalisation
    # that needs E|X|² = S·fs·n/2, i.e. a complex normal of per-component scale √(S·fs·n/4).
    amp = np.sqrt(psd1 * fs * n / 4.0)
    if n % 2 == 0:  # the Nyquist bin is real: its single component carries E|X|² = S·fs·n
        amp[-1] *= math.sqrt(2.0)
    spec = rng.standard_normal((f.size, 3)) + 1j * rng.standard_normal((f.size, 3))
    if n % 2 == 0:
        spec[-1] = spec[-1].real
    x = np.fft.irfft(spec * amp[:, None], n=n, axis=0)
    return x * B[None, :]


def _bias_and_noise(
    rng: np.random.Generator, n: int, odr_hz: float, model: NoiseModel
) -> tuple[np.ndarray, np.ndarray]:
    """Random-walk + flicker bias part ``(n, 3)`` and white noise ``(n, 3)``."""
    dt = 1.0 / odr_hz
    K = np.asarray(model.rate_random_walk)
    steps = rng.standard_normal((n, 3)) * (K * math.sqrt(dt))
    steps[0] = 0.0
    walk = np.cumsum(steps, axis=0)
    if np.any(np.asarray(model.bias_instability) > 0):
        walk = walk + flicker_noise(rng, n, odr_hz, np.asarray(model.bias_instability))
    white = rng.standard_normal((n, 3)) * model.white_std(odr_hz)
    return walk, white


def simulate_still(
    rng: np.random.Generator,
    duration_s: float,
    *,
    odr_hz: float = 200.0,
    model: NoiseModel | None = None,
    bias: object = (0.0, 0.0, 0.0),
    scale: object = (1.0, 1.0, 1.0),
    temperature_c: float = 25.0,
) -> SimSession:
    """A sensor at rest at constant temperature, for noise characterisation.

    Parameters
    ----------
    rng : numpy.random.Generator
        The only source of randomness.
    duration_s : float
        Length, s.
    odr_hz : float
        Output data rate, Hz.
    model : NoiseModel, optional
        The noise; default :class:`NoiseModel()`.
    bias : array_like (3,)
        Initial bias ``b0`` (Calibration v1 convention), rad/s.
    scale : array_like (3,)
        True scale factors (irrelevant at rest, kept for the truth record).
    temperature_c : float
        The constant die temperature, °C.

    Returns
    -------
    SimSession
    """
    model = model or NoiseModel()
    fs = scalar(odr_hz, "odr_hz", positive=True)
    n = _sample_count(duration_s, fs)
    b0 = vec3(bias, "bias")
    k = vec3(scale, "scale", positive=True)
    walk, white = _bias_and_noise(rng, n, fs, model)
    true_bias = b0[None, :] + walk
    t = np.arange(n) / fs
    return SimSession(
        t=t,
        rate=-true_bias + white,
        temperature_c=np.full(n, float(temperature_c)),
        true_rate=np.zeros((n, 3)),
        true_bias=true_bias,
        still=np.ones(n, dtype=bool),
        reference_rate=np.full(n, np.nan),
        reference_axis=np.full((n, 3), np.nan),
        reference_motor=np.zeros(n, dtype=np.int64),
        odr_hz=fs,
        scale=k,
        tempco=np.zeros(3),
        t_ref_c=float(temperature_c),
        axes=np.eye(3),
        model=model,
    )


def _taper(n: int, n_ramp: int) -> np.ndarray:
    """A window of ``n`` samples rising and falling over ``n_ramp`` samples (raised cosine)."""
    w = np.ones(n)
    r = min(n_ramp, n // 2)
    if r > 0:
        ramp = 0.5 * (1.0 - np.cos(np.pi * (np.arange(r) + 0.5) / r))
        w[:r] = ramp
        w[n - r :] = ramp[::-1]
    return w


def simulate_session(
    rng: np.random.Generator,
    duration_s: float = 1800.0,
    *,
    odr_hz: float = 200.0,
    model: NoiseModel | None = None,
    motion: str = "random",
    still_s: tuple[float, float] = (2.0, 5.0),
    motion_s: tuple[float, float] = (3.0, 8.0),
    peak_rate: float = 2.0,
    ramp_s: float = 0.3,
    temp_start_c: float = 25.0,
    temp_rise_c: float = 10.0,
    tempco: object = (3e-4, -2e-4, 1.5e-4),
    t_ref_c: float | None = None,
    bias: object = (0.02, -0.015, 0.01),
    scale: object = (1.02, 0.98, 1.01),
    axes: np.ndarray | None = None,
    ripple: float = 0.05,
    bias_step: tuple[float, object] | None = None,
) -> SimSession:
    """An operating session: still periods of a few seconds between motions.

    Parameters
    ----------
    rng : numpy.random.Generator
        The only source of randomness.
    duration_s : float
        Length, s (30 minutes by default).
    odr_hz : float
        Output data rate, Hz.
    model : NoiseModel, optional
        White noise, rate random walk and flicker of the sensor.
    motion : {"random", "jig"}
        ``random``: smooth random rotations about all axes (sums of sinusoids of 0.1–1.5 Hz
        under a raised-cosine envelope), peak about ``peak_rate``. ``jig``: one servo at a
        time turns about its axis at a speed ~ U(0.5, 1)·``peak_rate`` with raised-cosine
        ramps and a speed ripple of ``ripple`` (fraction), both directions; the encoder rate
        is recorded in ``reference_rate``.
    still_s, motion_s : (float, float)
        Durations of still periods and motions ~ U(lo, hi), s. The session starts still.
    peak_rate : float
        Scale of the motions, rad/s.
    ramp_s : float
        Length of the smooth start and end of every motion, s.
    temp_start_c, temp_rise_c : float
        The die warms from ``temp_start_c`` by ``temp_rise_c`` °C over the session (a
        first-order warm-up with time constant ``duration_s/3``, reaching the full rise at the
        end).
    tempco : array_like (3,)
        Temperature coefficient of the bias, rad/s/°C.
    t_ref_c : float, optional
        Temperature at which the bias equals ``bias`` (default ``temp_start_c``).
    bias : array_like (3,)
        Bias ``b0`` at ``t_ref_c``, rad/s (Calibration v1 convention).
    scale : array_like (3,)
        True scale factors.
    axes : ndarray (3, 3), optional
        Rows: the servos' unit axes in the sensor frame (default: a mount rotated by 0.05 rad
        about (1, 2, 3)/√14).
    ripple : float
        Jig speed ripple (standard-deviation fraction of the speed).
    bias_step : (float, array_like (3,)), optional
        ``(t_step, delta)``: add ``delta`` rad/s to the bias from ``t_step`` on.

    Returns
    -------
    SimSession
    """
    model = model or NoiseModel()
    fs = scalar(odr_hz, "odr_hz", positive=True)
    n = _sample_count(duration_s, fs)
    if motion not in ("random", "jig"):
        raise CalibInputError(f"motion must be 'random' or 'jig', got {motion!r}")
    for name, (lo, hi) in (("still_s", still_s), ("motion_s", motion_s)):
        if not (0 < lo <= hi and math.isfinite(hi)):
            raise CalibInputError(f"{name} must be (lo, hi) with 0 < lo <= hi, got {(lo, hi)!r}")
    peak = scalar(peak_rate, "peak_rate", positive=True)
    ramp = scalar(ramp_s, "ramp_s", nonneg=True)
    if not (0 <= ripple < 0.5):
        raise CalibInputError(f"ripple must be in [0, 0.5), got {ripple!r}")
    b0 = vec3(bias, "bias")
    k = vec3(scale, "scale", positive=True)
    c = vec3(tempco, "tempco")
    if axes is None:
        u = np.array([1.0, 2.0, 3.0]) / math.sqrt(14.0)
        ang = 0.05
        K_ = np.array([[0, -u[2], u[1]], [u[2], 0, -u[0]], [-u[1], u[0], 0]])
        R = np.eye(3) + math.sin(ang) * K_ + (1 - math.cos(ang)) * K_ @ K_
        axes = R.T
    axes = np.asarray(axes, dtype=float)
    if axes.shape != (3, 3) or not np.allclose(np.linalg.norm(axes, axis=1), 1.0, atol=1e-9):
        raise CalibInputError("axes must be a (3, 3) array of unit rows")
    if t_ref_c is None:
        t_ref_c = temp_start_c

    t = np.arange(n) / fs
    true_rate = np.zeros((n, 3))
    ref_rate = np.full(n, np.nan)
    ref_axis = np.full((n, 3), np.nan)
    ref_motor = np.zeros(n, dtype=np.int64)
    n_ramp = int(round(ramp * fs))
    i = int(round(rng.uniform(*still_s) * fs))
    turn = 0
    while i < n:
        length = int(round(rng.uniform(*motion_s) * fs))
        j = min(i + length, n)
        m = j - i
        env = _taper(length, n_ramp)[:m]
        tt = np.arange(m) / fs
        if motion == "random":
            freqs = rng.uniform(0.1, 1.5, size=(3, 3))
            phases = rng.uniform(0, 2 * np.pi, size=(3, 3))
            amps = rng.uniform(0.2, 1.0, size=(3, 3)) * peak / 2.0
            w = np.einsum(
                "ak,tak->ta", amps, np.sin(2 * np.pi * freqs[None] * tt[:, None, None] + phases)
            )
            true_rate[i:j] = w * env[:, None]
        else:
            s = turn % 3
            d = 1.0 if (turn // 3) % 2 == 0 else -1.0
            turn += 1
            speed = d * rng.uniform(0.5, 1.0) * peak
            f_rev = abs(speed) / (2 * np.pi)
            # Ripple at the revolution frequency, its second harmonic and a few Hz, scaled so
            # that its total standard deviation is ``ripple``·speed.
            comps = np.array([f_rev, 2 * f_rev, rng.uniform(2.0, 5.0)])
            ph = rng.uniform(0, 2 * np.pi, size=3)
            rip = np.sin(2 * np.pi * comps[None] * tt[:, None] + ph).sum(axis=1) * (
                ripple * math.sqrt(2.0 / 3.0)
            )
            omega = speed * env * (1.0 + rip)
            true_rate[i:j] = omega[:, None] * axes[s][None, :]
            ref_rate[i:j] = omega
            ref_axis[i:j] = axes[s]
            ref_motor[i:j] = s + 1
        i = j + int(round(rng.uniform(*still_s) * fs))
    still = ~np.any(true_rate != 0.0, axis=1)

    tau_th = duration_s / 3.0
    temp_true = temp_start_c + temp_rise_c * (1.0 - np.exp(-t / tau_th)) / (1.0 - math.exp(-3.0))
    temp_read = np.round(temp_true / _TEMP_LSB_C) * _TEMP_LSB_C

    walk, white = _bias_and_noise(rng, n, fs, model)
    true_bias = b0[None, :] + c[None, :] * (temp_true - t_ref_c)[:, None] + walk
    step_t = None
    if bias_step is not None:
        step_t = float(bias_step[0])
        delta = vec3(bias_step[1], "bias_step delta")
        true_bias = true_bias + (t >= step_t)[:, None] * delta[None, :]
    rate = true_rate / k[None, :] - true_bias + white
    return SimSession(
        t=t,
        rate=rate,
        temperature_c=temp_read,
        true_rate=true_rate,
        true_bias=true_bias,
        still=still,
        reference_rate=ref_rate,
        reference_axis=ref_axis,
        reference_motor=ref_motor,
        odr_hz=fs,
        scale=k,
        tempco=c,
        t_ref_c=float(t_ref_c),
        axes=axes,
        model=model,
        step_t=step_t,
    )


def sim_calibration(
    rng: np.random.Generator,
    session: SimSession,
    *,
    bias_std: float = 1e-4,
    scale_std: float = 1e-4,
) -> GyroCalibration:
    """A Calibration v1 of the simulated sensor, as an earlier offline calibration would give it.

    The bias and scale are the truth at ``session.t_ref_c`` (the session's first bias,
    temperature effect removed) plus a draw of their stated uncertainty, so the calibration is
    statistically consistent with the session. Jig sessions carry the servo axes.

    Parameters
    ----------
    rng : numpy.random.Generator
    session : SimSession
    bias_std, scale_std : float
        One-sigma uncertainties the calibration states (and is drawn with).

    Returns
    -------
    GyroCalibration
    """
    b_std = scalar(bias_std, "bias_std", positive=True)
    k_std = scalar(scale_std, "scale_std", positive=True)
    b_true0 = session.true_bias[0] - session.tempco * (session.temperature_c[0] - session.t_ref_c)
    bias = b_true0 + rng.standard_normal(3) * b_std
    scale = session.scale + rng.standard_normal(3) * k_std
    axes = {
        str(s + 1): {"axis": [float(x) for x in session.axes[s]]} for s in range(3)
    }
    return GyroCalibration(
        scale=tuple(scale),  # type: ignore[arg-type]
        bias=tuple(bias),  # type: ignore[arg-type]
        scale_std=(k_std,) * 3,  # type: ignore[arg-type]
        bias_std=(b_std,) * 3,  # type: ignore[arg-type]
        method="simulation",
        sensor={"model": "simulated", "odr_hz": session.odr_hz},
        temperature_c=session.t_ref_c,
        source="simulation",
        axes=axes,
    )
