"""Register-level emulated MPU-9250 and LSM9DS1 (accelerometer/gyroscope die) for an
:class:`~gyrocal.drivers.emulated.smbus.EmulatedSMBus`.

Each chip keeps a register file with the reset values of the hardware reference (§1.9, §2.8),
answers WHO_AM_I, takes the configuration registers the readers write, and samples its gyro on its
own clock: sample ``k`` of a configuration is taken at ``t0 + k / (odr · (1 + clock_ppm·1e-6))`` on
the shared clock, where ``t0`` is when the rate was last set. Whenever the bus touches the chip at
time ``T`` it generates every sample with time ``≤ T`` in one vectorised step: it asks the
:class:`~gyrocal.drivers.emulated.motion.MotionSource` for the true rate at those times (in order,
never
later than ``T``, as its contract requires), turns the rates into readings through
:class:`SensorTruth`, quantizes and clips them to the configured range, and pushes them into the
FIFO with the chip's FIFO semantics (size, overflow flag, stop-when-full or overwrite; §1.7,
§2.7). On a motion source that can be looked ahead on (the emulated gimbal:
:meth:`GimbalJig.lookahead <gyrocal.drivers.emulated.jig.GimbalJig.lookahead>`) the chip computes
its samples for :attr:`_EmulatedImu.lookahead_s` ahead in one vectorised step and hands them
out as the clock reaches them; they are those it would have computed then, to the last bit (the
same motion, the same draws of each random stream in the same order; the coloured noise as
drains of one sample each take it, computed again after a drain of several), and a command to a
servo, a timed event due or a register write makes it compute again.

:class:`SensorRealism` adds what makes a chip imperfect beyond its calibration errors:
coloured noise, the MPU-9250's DLPF delay, g-sensitivity and an accelerometer that sees the
specific force of a motion source that has one (:meth:`GimbalJig.specific_force
<gyrocal.drivers.emulated.jig.GimbalJig.specific_force>`); without it the accelerometer reads a
constant 1 g along +z.

:class:`ChipFaults` holds the fault knobs: NACKs at random or in bursts, a chip that stops
answering, a smaller FIFO (to provoke overflows), a wrong WHO_AM_I and a stuck axis.
"""

from __future__ import annotations

import errno
import importlib
import math
from abc import ABC, abstractmethod
from collections import deque
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from gyrocal.drivers.clock import Clock
from gyrocal.drivers.emulated.accel import AccelTruth
from gyrocal.drivers.emulated.i2c_master import AuxI2CMaster, MasterLayout
from gyrocal.drivers.emulated.iir import lfilter
from gyrocal.drivers.emulated.magnetometers import (
    AuxPort,
    EmulatedAK8963,
    EmulatedLSM9DS1Mag,
    MagneticField,
)
from gyrocal.drivers.emulated.motion import ConstantRate, MotionSource
from gyrocal.drivers.emulated.noise import ColouredNoise, Normals
from gyrocal.drivers.emulated.self_test import (
    FACTORY_SELF_TEST_CODES,
    SelfTestLayout,
    self_test_counts,
)
from gyrocal.drivers.emulated.smbus import EmulatedSMBus, I2CDevice
from gyrocal.drivers.imu.chips import (
    GYRO_OFFSET_COUNTS_PER_CODE_FS0,
    LSM9DS1,
    LSM9DS1_ACCEL_AA_AUTO_HZ,
    LSM9DS1_ACCEL_AA_FILTER,
    LSM9DS1_ACCEL_HR_DIVISOR,
    LSM9DS1_BITS,
    LSM9DS1_BW_G_CUTOFF_HZ,
    LSM9DS1_LPF1_CUTOFF_HZ,
    LSM9DS1_ODR,
    LSM9DS1_REG,
    MPU9250,
    MPU9250_ACCEL_FILTER,
    MPU9250_BITS,
    MPU9250_GYRO_FILTER,
    MPU9250_REG,
    ChipFamily,
    FilterSetting,
)

__all__ = [
    "ChipFaults",
    "EmulatedLSM9DS1",
    "EmulatedMPU9250",
    "SensorRealism",
    "SensorTruth",
    "filter_steps",
    "make_emulated_imu",
]

#: The MPU-9250 datasheet's typical rate noise spectral density, 0.01 °/s/√Hz, in rad/s/√Hz
#: (its chip-table row, :attr:`~gyrocal.drivers.imu.chips.GyroErrors.noise_density_dps_sqrt_hz`).
TYPICAL_NOISE_DENSITY_RAD_S_SQRT_HZ = MPU9250.gyro_errors.noise_density_rad_s_sqrt_hz
#: How far a restarted output filter's start is forgotten before the samples handed out: its
#: impulse response decays to this fraction (the filter then runs on as on silicon, whatever
#: the client's polling interval).
_FILTER_MEMORY = 1e-7

_Vec3 = tuple[float, float, float]


def _vec3(name: str, value: Any) -> _Vec3:
    v = np.broadcast_to(np.asarray(value, dtype=float), (3,))
    if not np.all(np.isfinite(v)):
        raise ValueError(f"{name} must be finite, got {value!r}")
    return (float(v[0]), float(v[1]), float(v[2]))


_ZERO33 = ((0.0, 0.0, 0.0), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0))


@dataclass(frozen=True)
class SensorRealism:
    """The imperfections of a real chip beyond its calibration errors, each off by default.

    Parameters
    ----------
    bias_instability_rad_s : float
        Bias instability ``B`` (rad/s): a flat Allan floor of ``0.664 B``, generated as a sum of
        Gauss–Markov processes (:mod:`gyrocal.drivers.emulated.noise`).
    rate_random_walk_rad_s_sqrt_s : float
        Rate random walk ``K`` (rad/s/√s): ``σ_A(τ) = K sqrt(τ/3)``.
    dlpf_delay : bool
        Whether the run has the chips' output filters on (``--sim``'s ``dlpf`` effect), for the
        manifest: the chip's own ``output_filter`` knob (on by default) turns the filter, a
        low-pass at the configured bandwidth with, on the MPU-9250, the CONFIG table's delay
        (a first-order filter at the cutoff plus a pure delay making up the rest; the filter's
        order is not published ⚠).
    g_sensitivity_rad_s_per_g : (3, 3)
        Rate error per g of specific force, ``m += G f`` (MPU-9250 datasheet: typical
        0.1 °/s/g, "Linear Acceleration Sensitivity").
    specific_force : bool
        The accelerometer sees the motion source's specific force, gravity in the sensor's
        true orientation plus the lever-arm accelerations, when the motion source has
        ``specific_force(t)``; otherwise +1 g on z. The g-sensitivity always sees the true
        specific force when the motion source has one: a gyro's g-sensitivity does not depend
        on what the accelerometer is shown, so turning ``gravity`` off alone leaves it physical.
    """

    bias_instability_rad_s: float = 0.0
    rate_random_walk_rad_s_sqrt_s: float = 0.0
    dlpf_delay: bool = False
    g_sensitivity_rad_s_per_g: Any = _ZERO33
    specific_force: bool = False

    def __post_init__(self) -> None:
        for name in ("bias_instability_rad_s", "rate_random_walk_rad_s_sqrt_s"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0):
                raise ValueError(f"{name} must be finite and >= 0, got {v!r}")
        g = np.asarray(self.g_sensitivity_rad_s_per_g, dtype=float)
        if g.shape != (3, 3) or not np.all(np.isfinite(g)):
            raise ValueError("g_sensitivity_rad_s_per_g must be a finite 3×3 matrix, got "
                             f"{self.g_sensitivity_rad_s_per_g!r}")
        object.__setattr__(self, "g_sensitivity_rad_s_per_g",
                           tuple(tuple(float(x) for x in row) for row in g))

    def manifest(self) -> dict[str, Any]:
        """The realism lines of a simulated manifest's ``truth``."""
        return {"bias_instability_rad_s": self.bias_instability_rad_s,
                "rate_random_walk_rad_s_sqrt_s": self.rate_random_walk_rad_s_sqrt_s,
                "dlpf_delay": self.dlpf_delay,
                "g_sensitivity_rad_s_per_g": [list(r) for r in self.g_sensitivity_rad_s_per_g],
                "specific_force": self.specific_force}


@dataclass(frozen=True)
class SensorTruth:
    """The true errors of an emulated gyro, in the calibration model's convention.

    The calibration model is the paper's Eq. 1, ``g = scale ∘ (m + bias)``, with ``g`` the true
    rate and ``m`` the reading (both rad/s). The emulated chip therefore reads

    ``m = (misalignment @ g) / scale(T) − bias(T) + n``,  elementwise per axis,

    with ``bias(T) = bias + bias_temp_coeff_rad_s_per_c · dT + bias_temp_quad_rad_s_per_c2 · dT²``
    and ``scale(T) = scale · (1 + scale_temp_coeff_per_c · dT)``, ``dT = T − reference_
    temperature_c`` at the chip temperature ``T`` (issue 13; drivers.emulated.thermal draws
    datasheet-range coefficients and the die temperature), and white noise ``n`` of per-sample
    standard deviation
    ``σ = noise_density_rad_s_sqrt_hz · sqrt(rate)`` at the rate the chip's output filter runs
    at (the angle-random-walk convention: the mean of the samples over ``τ`` seconds then has
    deviation ``density / sqrt(τ)``), or ``noise_sigma_rad_s`` when given; the noise enters
    ahead of the chip's filter, so the filter narrows it as on silicon. ``m`` is then divided
    by the datasheet sensitivity, rounded to counts and clipped to int16. With
    ``misalignment`` the identity, a perfect calibration recovers ``scale`` and ``bias``
    exactly; the paper's six-parameter model cannot absorb a non-identity ``misalignment``.

    Parameters
    ----------
    scale : float or (3,)
        Per-axis scale factor (dimensionless, near 1).
    bias : float or (3,)
        Per-axis bias at the reference temperature, rad/s.
    misalignment : (3, 3)
        Sensor-internal axis non-orthogonality, applied to the true rate first.
    noise_density_rad_s_sqrt_hz : float or (3,), optional
        White-noise density; the emulated chip's datasheet figure
        (:attr:`~gyrocal.drivers.imu.chips.GyroErrors.noise_density_dps_sqrt_hz`) when None.
    noise_sigma_rad_s : float or (3,), optional
        Per-sample noise standard deviation at the filter's input, overriding the density.
    bias_temp_coeff_rad_s_per_c : float or (3,)
        Bias change per °C.
    bias_temp_quad_rad_s_per_c2 : float or (3,)
        Quadratic bias change per °C².
    scale_temp_coeff_per_c : float or (3,)
        Relative scale change per °C.
    reference_temperature_c : float
        Temperature at which the bias is ``bias``.
    temperature_c : float or callable
        Chip temperature: a constant, or ``f(t) -> °C`` vectorised over an array of clock times.
    clock_ppm : float
        The chip oscillator's error: it samples at ``odr · (1 + clock_ppm·1e-6)``.
    realism : SensorRealism
        Coloured noise, DLPF delay, g-sensitivity, specific force (all off by default).
    accelerometer : AccelTruth, optional
        The accelerometer's errors (:mod:`gyrocal.drivers.emulated.accel`); an ideal
        accelerometer when None.
    """

    scale: Any = (1.0, 1.0, 1.0)
    bias: Any = (0.0, 0.0, 0.0)
    misalignment: Any = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))
    noise_density_rad_s_sqrt_hz: Any = None
    noise_sigma_rad_s: Any = None
    bias_temp_coeff_rad_s_per_c: Any = (0.0, 0.0, 0.0)
    reference_temperature_c: float = 25.0
    temperature_c: float | Callable[[np.ndarray], np.ndarray] = 25.0
    clock_ppm: float = 0.0
    realism: SensorRealism = SensorRealism()
    bias_temp_quad_rad_s_per_c2: Any = (0.0, 0.0, 0.0)
    scale_temp_coeff_per_c: Any = (0.0, 0.0, 0.0)
    accelerometer: AccelTruth | None = None

    def __post_init__(self) -> None:
        put = object.__setattr__
        put(self, "scale", _vec3("scale", self.scale))
        if any(s == 0.0 for s in self.scale):
            raise ValueError(f"scale must be non-zero on every axis, got {self.scale!r}")
        put(self, "bias", _vec3("bias", self.bias))
        m = np.asarray(self.misalignment, dtype=float)
        if m.shape != (3, 3) or not np.all(np.isfinite(m)):
            raise ValueError(f"misalignment must be a finite 3×3 matrix, got {self.misalignment!r}")
        put(self, "misalignment", tuple(tuple(float(x) for x in row) for row in m))
        if self.noise_density_rad_s_sqrt_hz is not None:
            put(self, "noise_density_rad_s_sqrt_hz",
                _vec3("noise", self.noise_density_rad_s_sqrt_hz))
        if self.noise_sigma_rad_s is not None:
            put(self, "noise_sigma_rad_s", _vec3("noise_sigma_rad_s", self.noise_sigma_rad_s))
        for name in ("noise_density_rad_s_sqrt_hz", "noise_sigma_rad_s"):
            v = getattr(self, name)
            if v is not None and min(v) < 0:
                raise ValueError(f"{name} must be >= 0, got {v!r}")
        put(
            self,
            "bias_temp_coeff_rad_s_per_c",
            _vec3("bias_temp_coeff_rad_s_per_c", self.bias_temp_coeff_rad_s_per_c),
        )
        for name in ("bias_temp_quad_rad_s_per_c2", "scale_temp_coeff_per_c"):
            put(self, name, _vec3(name, getattr(self, name)))
        if not (math.isfinite(self.clock_ppm) and self.clock_ppm > -1e6):  # a positive rate
            raise ValueError(f"clock_ppm must be finite and above -1e6, got {self.clock_ppm!r}")
        if not callable(self.temperature_c) and not math.isfinite(self.temperature_c):
            raise ValueError(
                f"temperature_c must be finite or callable, got {self.temperature_c!r}"
            )
        # arrays for the per-sample arithmetic
        put(self, "_scale_a", np.asarray(self.scale))
        put(self, "_bias_a", np.asarray(self.bias))
        put(self, "_mis_t", np.asarray(self.misalignment).T.copy())
        put(self, "_coeff_a", np.asarray(self.bias_temp_coeff_rad_s_per_c))
        put(self, "_quad_a", np.asarray(self.bias_temp_quad_rad_s_per_c2))
        put(self, "_scale_tc_a", np.asarray(self.scale_temp_coeff_per_c))
        #: No temperature terms: scale(T) and bias(T) are the constants (exactly, as the
        #: general formulas give them with zero coefficients), so the reading skips them.
        put(self, "_isothermal", not any(any(c) for c in (
            self.bias_temp_coeff_rad_s_per_c, self.bias_temp_quad_rad_s_per_c2,
            self.scale_temp_coeff_per_c)))

    def sigma_rad_s(self, rate_hz: float, density: float = TYPICAL_NOISE_DENSITY_RAD_S_SQRT_HZ
                    ) -> np.ndarray:
        """Per-sample white-noise standard deviation (3,) of samples at ``rate_hz`` (the chip
        draws it at its filter's input rate): ``density`` stands in for an unset
        :attr:`noise_density_rad_s_sqrt_hz` (the chip passes its datasheet's)."""
        if self.noise_sigma_rad_s is not None:
            return np.asarray(self.noise_sigma_rad_s)
        n = self.noise_density_rad_s_sqrt_hz
        return np.asarray(density if n is None else n) * math.sqrt(rate_hz)

    def temperature_at(self, t: np.ndarray) -> np.ndarray:
        """Chip temperature in °C at clock times ``t``."""
        t = np.asarray(t, dtype=float)
        if callable(self.temperature_c):
            return np.broadcast_to(np.asarray(self.temperature_c(t), dtype=float), t.shape)
        return np.full(t.shape, float(self.temperature_c))

    def bias_at(self, temperature_c: np.ndarray) -> np.ndarray:
        """Bias (N, 3) in rad/s at the given temperatures."""
        dt = np.asarray(temperature_c, dtype=float)[:, None] - self.reference_temperature_c
        return self._bias_a + (self._coeff_a + self._quad_a * dt) * dt  # type: ignore[attr-defined]

    def scale_at(self, temperature_c: np.ndarray) -> np.ndarray:
        """Scale (N, 3) at the given temperatures."""
        dt = np.asarray(temperature_c, dtype=float)[:, None] - self.reference_temperature_c
        return self._scale_a * (1.0 + self._scale_tc_a * dt)  # type: ignore[attr-defined]

    def reading(self, omega: np.ndarray, temperature_c: np.ndarray) -> np.ndarray:
        """The noiseless reading ``m`` (N, 3) in rad/s for true rates ``omega`` (N, 3)."""
        mis_t = self._mis_t  # type: ignore[attr-defined]
        if self._isothermal:  # type: ignore[attr-defined]
            return (np.asarray(omega) @ mis_t) / self._scale_a - self._bias_a  # type: ignore[attr-defined]
        return (np.asarray(omega) @ mis_t) / self.scale_at(temperature_c) - self.bias_at(
            temperature_c)

    def manifest(self) -> dict[str, list[Any]]:
        """The ``"truth"`` object of a simulated Recording v1 manifest (``misalignment`` in this
        class's convention, rows of the 3×3 matrix)."""
        out: dict[str, Any] = {"scale": list(self.scale), "bias": list(self.bias),
                               "misalignment": [list(r) for r in self.misalignment]}
        temperature = self.temperature_manifest()
        if temperature is not None:
            out["temperature"] = temperature
        if self.accelerometer is not None:
            out["accelerometer"] = self.accelerometer.manifest()
        return out

    def temperature_manifest(self) -> dict[str, Any] | None:
        """``truth.temperature``: the reference, the coefficients and the die temperature's
        description (issue 13), or None for a sensor without temperature terms at a constant
        temperature."""
        coeffs = (self.bias_temp_coeff_rad_s_per_c, self.bias_temp_quad_rad_s_per_c2,
                  self.scale_temp_coeff_per_c)
        if not callable(self.temperature_c) and not any(any(c) for c in coeffs):
            return None
        die = getattr(self.temperature_c, "manifest", None)
        return {"reference_c": self.reference_temperature_c,
                # per axis, ascending powers of (T - reference_c), as Calibration's
                # temperature_model
                "bias_coeffs": [list(c) for c in zip(self.bias, *coeffs[:2], strict=True)],
                "scale_coeff_per_c": list(self.scale_temp_coeff_per_c),
                "die": die() if die is not None else (
                    None if callable(self.temperature_c) else float(self.temperature_c))}

    def accel_reading(self, force_g: np.ndarray, rng: np.random.Generator | None = None,
                      odr_hz: float | None = None) -> np.ndarray:
        """The accelerometer's reading (N, 3) in g for the true specific force ``force_g``:
        through :attr:`accelerometer`'s scale, cross-axis, bias and (with ``rng`` and
        ``odr_hz``) white noise, or the force itself for an ideal accelerometer."""
        if self.accelerometer is None:
            return np.asarray(force_g, dtype=float)
        return self.accelerometer.reading(force_g, rng, odr_hz)


@dataclass
class ChipFaults:
    """Fault knobs of an emulated chip (mutable, so a test can break a chip mid-run).

    Parameters
    ----------
    nack_probability : float
        Chance that the chip refuses any one I²C message.
    nack_errno : int
        The errno of a refusal: ``EREMOTEIO`` (a NACK, nothing moved) by default; ``EIO`` or
        ``ETIMEDOUT`` model a transfer that failed part-way, which a reader cannot tell from one
        that popped FIFO bytes. The emulator refuses before any byte moves either way.
    nack_bursts : sequence of (start_s, duration_s)
        Clock intervals during which every message is refused with ``nack_errno``.
    dead_after_s : float, optional
        From this clock time on the chip never answers (``EREMOTEIO``).
    who_am_i : int, optional
        A wrong identity byte to answer instead of the real one.
    stuck_axis : int, optional
        Gyro axis (0, 1, 2) that outputs ``stuck_counts`` from ``stuck_from_s`` on.
    stuck_counts : int
        The value of the stuck axis.
    stuck_from_s : float
        When the axis sticks.
    fifo_capacity : int, optional
        A smaller FIFO than the datasheet's (bytes for the MPU-9250, slots for the LSM9DS1), to
        provoke overflows at ordinary drain intervals.
    """

    nack_probability: float = 0.0
    nack_errno: int = errno.EREMOTEIO
    nack_bursts: tuple[tuple[float, float], ...] = ()
    dead_after_s: float | None = None
    who_am_i: int | None = None
    stuck_axis: int | None = None
    stuck_counts: int = 0
    stuck_from_s: float = 0.0
    fifo_capacity: int | None = None


class _Peeking:
    """A :class:`~gyrocal.drivers.emulated.noise.Normals` seen through ``standard_normal``
    without using it up: counts what was asked for."""

    def __init__(self, normals: Normals) -> None:
        self.normals = normals
        self.used = 0

    def standard_normal(self, shape: int | tuple[int, ...]) -> np.ndarray:
        n = math.prod(shape) if isinstance(shape, tuple) else int(shape)
        self.used += n
        return self.normals.peek(self.used)[self.used - n:].reshape(shape)


@dataclass
class _Ahead:
    """Samples computed ahead (:meth:`_EmulatedImu._look_ahead`) from sample ``k_first`` of the
    grid: their times ``t``, the latest time each read the motion at (``t_read``), the reading
    before the coloured noise ``m`` (the true rate through the filter and the sensor's errors,
    the g-sensitivity, the white noise), the accelerometer's counts, the die temperature and
    its counts; the filter's state after each (``lpf``), and the accelerometer's normals each
    used. From sample ``coloured_from`` on (up to ``coloured_hi``), the coloured noise as
    one-sample drains would give it from the state ``coloured_start`` (its states after each
    sample) and the gyro counts with it."""

    token: tuple[Any, ...]
    k_first: int
    t: np.ndarray
    t_read: np.ndarray
    m: np.ndarray
    accel: np.ndarray
    temperature: np.ndarray
    temp: np.ndarray
    lpf: np.ndarray | None
    fc: tuple[float, int] | None
    accel_draws: int
    start_lpf: Any
    sensitivity: float
    next: int = 0
    coloured_from: int = -1
    coloured_start: tuple[Any, Any] | None = None
    #: The samples ``coloured_lo`` … ``coloured_hi − 1`` the coloured noise and the counts
    #: below are for (their rows 0, 1, ...).
    coloured_lo: int = 0
    coloured_hi: int = 0
    gyro: np.ndarray | None = None
    gm: np.ndarray | None = None
    walk: np.ndarray | None = None
    frames: bytes | None = None
    noise_draws: int = 3
    accel_lpf: np.ndarray | None = None
    accel_key: tuple[float, int, float] | None = None
    start_accel_lpf: Any = None


def filter_steps(bandwidth_hz: float, odr_hz: float) -> int:
    """Filter steps per output sample for a chip whose output filter runs at its output rate:
    1 while the bandwidth is below half that rate; a bandwidth at or above it (the ICM-42688-P's
    GYRO_UI_FILT_BW 0 and 1 below 400 Hz, DS-000347; the LSM6DSOX's LPF2 at 1.67 kHz, AN5192
    Table 14), which no filter at the output rate has, runs at the smallest power-of-two
    multiple of the output rate that holds it below a quarter of the filter's rate, and the
    output is its last step (as silicon, whose filters run at an internal rate and are
    decimated: the noise above half the output rate aliases in). The internal rates are not
    published (⚠ a stand-in; the LSM6DSOX's 1.67 kHz lands on its 6.67 kHz base rate).

    Parameters
    ----------
    bandwidth_hz : float
        The filter's −3 dB bandwidth.
    odr_hz : float
        The output data rate.
    """
    if bandwidth_hz < 0.5 * odr_hz:
        return 1
    steps = 2
    while bandwidth_hz >= 0.25 * steps * odr_hz:
        steps *= 2
    return steps


def _memory(k: float, order: int, steps: int) -> int:
    """Output samples (of ``steps`` filter steps each) before a restarted cascade of ``order``
    sections of :func:`_cascade`'s ``k`` forgets its start to :data:`_FILTER_MEMORY`: each
    section's pole decays that far in turn (an upper bound)."""
    pole = abs((1.0 - k) / (1.0 + k))
    if pole <= _FILTER_MEMORY:
        return 1
    return math.ceil(order * math.log(_FILTER_MEMORY) / math.log(pole) / steps) + 1


def _cascade(x6: np.ndarray, head: int, skipped: int, state: Any, key: Any, k: float,
             order: int, stages: bool) -> tuple[np.ndarray, Any, list[np.ndarray] | None]:
    """``order`` equal bilinear first-order low-passes ``b (1 + z⁻¹) / (1 + a z⁻¹)``, ``b = k /
    (1 + k)``, ``a = (k − 1) / (k + 1)``, along the first axis of ``x6`` (rows, or rows of
    internal samples; its last axis a signal's three columns, then its white noise's three),
    from ``state`` = ``(key, (order + 1, 6) last input and sections' outputs)``; restarted (the
    signal at rest on its first row, the noise at zero) when the state is for another ``key``
    or none, and after ``skipped`` rows not given (the first ``head`` rows, then the rest).
    Returns the output, the state after it and, with ``stages``, the input and every
    section's output."""
    b, a = k / (1 + k), (k - 1) / (k + 1)
    out = np.empty_like(x6)
    every = [np.empty_like(x6) for _ in range(order + 1)] if stages else None
    parts = [(0, head), (head, x6.shape[0])] if skipped else [(0, x6.shape[0])]
    for i, (lo, hi) in enumerate(parts):
        if hi <= lo:
            continue
        x = x6[lo:hi].reshape(-1, x6.shape[-1])
        if state is None or state[0] != key or (i == 1 and skipped):
            rest = x[0].copy()
            rest[3:] = 0.0  # the signal at rest, the noise at zero
            prev = np.repeat(rest[None, :], order + 1, axis=0)
        else:
            prev = state[1]
        ys = [x]
        for n in range(order):
            zi = (b * prev[n] - a * prev[n + 1])[None, :]
            y, _ = lfilter([b, b], [1.0, a], ys[-1], zi=zi)
            ys.append(y)
        out[lo:hi] = ys[-1].reshape(x6[lo:hi].shape)
        if every is not None:
            for v, y in zip(every, ys, strict=True):
                v[lo:hi] = y.reshape(x6[lo:hi].shape)
        state = (key, np.stack([y[-1] for y in ys]))
    return out, state, every


@dataclass
class _Sample:
    """The latest sample, for the output registers."""

    gyro: np.ndarray = field(default_factory=lambda: np.zeros(3, dtype=np.int64))
    accel: np.ndarray = field(default_factory=lambda: np.zeros(3, dtype=np.int64))
    temp: int = 0


class _EmulatedImu(ABC):
    """Shared machinery: register pointer, the write and reset rules, fault knobs, the sample
    clock and sample generation."""

    family: ChipFamily
    default_who_am_i: int
    temperature_count_limits: tuple[int, int] = (-32768, 32767)
    #: Register values after a power-on or software reset (the others are 0).
    reset_values: Mapping[int, int]
    #: Registers that ignore writes.
    read_only: frozenset[int]
    #: The self-clearing software-reset bit, as (register, mask).
    soft_reset: tuple[int, int]

    def __init__(
        self,
        clock: Clock,
        motion: MotionSource | None = None,
        truth: SensorTruth | None = None,
        *,
        faults: ChipFaults | None = None,
        seed: int = 0,
        subsamples: int = 8,
    ) -> None:
        if int(subsamples) < 1:
            raise ValueError(f"subsamples must be at least 1, got {subsamples!r}")
        self.clock = clock
        #: True-rate evaluations averaged per output sample (see :meth:`_true_rate`).
        self.subsamples = int(subsamples)
        self.motion: MotionSource = motion if motion is not None else ConstantRate()
        self.truth = truth if truth is not None else SensorTruth()
        self.faults = faults if faults is not None else ChipFaults()
        self._noise_rng = Normals(np.random.default_rng([seed, 0]))
        self._fault_rng = np.random.default_rng([seed, 1])
        # its own: the gyro's draws stay
        self._accel_rng = Normals(np.random.default_rng([seed, 3]))
        #: How far ahead of the clock samples are computed on a motion source that allows it
        #: (0: each when the clock reaches it). A look-ahead costs about 4 ms of CPU besides
        #: 40 µs a sample, and a servo command drops what is left of it: at a calibration's
        #: 200 Hz, 1.28 s (256 samples) took 49 look-aheads and 0.68 CPU s where 0.25 s took
        #: 194 and 1.15 s (seed 3; the samples are the same either way).
        self.lookahead_s = 1.28
        #: At most this many samples are computed ahead at once: at the power-on rate (8 kHz on
        #: the MPU-9250) 0.25 s is 2,000 samples, and the driver's configuring drains them a
        #: few at a time and then changes the rate (a seed-3 calibration computed 6,000 there
        #: and used 85); 256 leaves every rate up to 200 Hz its full look-ahead.
        self.lookahead_max = 256
        self._ahead: _Ahead | None = None
        r = self.truth.realism
        self._coloured = ColouredNoise(r.bias_instability_rad_s, r.rate_random_walk_rad_s_sqrt_s,
                                       Normals(np.random.default_rng([seed, 2])))
        self._lpf: tuple[float, np.ndarray] | None = None
        self._accel_lpf: tuple[Any, np.ndarray] | None = None
        self._created = clock.monotonic()
        self._power_on_reset()

    # -- I2CDevice ----------------------------------------------------------------------------

    def i2c_ack(self) -> int | None:
        """Refuse per the fault knobs, else acknowledge."""
        f = self.faults
        now = self.clock.monotonic()
        if f.dead_after_s is not None and now >= f.dead_after_s:
            return errno.EREMOTEIO
        for start, duration in f.nack_bursts:
            if start <= now < start + duration:
                return f.nack_errno
        if f.nack_probability > 0 and self._fault_rng.random() < f.nack_probability:
            return f.nack_errno
        return None

    def i2c_write(self, data: bytes) -> None:
        """Set the register pointer and write the following bytes, auto-incrementing."""
        self._sync()
        if not data:
            return
        if len(data) > 1:
            self._ahead = None  # a register write may change what the samples are
        self._ptr = self._mask(data[0])
        for value in data[1:]:
            self._write_register(self._ptr, value)
            self._ptr = self._next_pointer(self._ptr)

    def i2c_read(self, length: int) -> bytes:
        """Read ``length`` bytes from the register pointer."""
        self._sync()
        fast = self._read_fast(length)
        if fast is not None:
            return fast
        out = bytearray()
        for _ in range(length):
            out.append(self._read_register(self._ptr) & 0xFF)
            self._ptr = self._next_pointer(self._ptr)
        return bytes(out)

    # -- chip specifics (subclasses) ------------------------------------------------------------

    def _mask(self, register: int) -> int:
        return register & 0x7F

    def _next_pointer(self, register: int) -> int:
        return (register + 1) & 0x7F

    def _read_fast(self, length: int) -> bytes | None:
        return None

    def _power_on_reset(self) -> None:
        """Restore the reset values (power-on and software reset); start a new sample grid."""
        self._regs = bytearray(128)
        for reg, value in self.reset_values.items():
            self._regs[reg] = value
        self._ptr = 0
        self._latest = _Sample()
        #: :attr:`samples_taken` at each FIFO enable: the FIFO's first sample is the next one.
        self.fifo_enables: list[int] = []
        self._accel_lpf = None
        self._reset_state()
        self._restart_sampling()

    def _write_register(self, register: int, value: int) -> None:
        """Write one register. Read-only registers ignore it; the software-reset bit restores
        the reset values; a write that changes the output data rate starts a new sample grid,
        and one that turns the FIFO on records where the FIFO's samples begin."""
        if register in self.read_only:
            return
        reset_register, reset_bit = self.soft_reset
        if register == reset_register and value & reset_bit:
            self._power_on_reset()  # the reset bit clears itself
            return
        fifo_was_on, odr_before = self._fifo_on(), self._odr_hz()
        self._store(register, value)
        if self._odr_hz() != odr_before:
            self._restart_sampling()
        if self._fifo_on() and not fifo_was_on:
            self.fifo_enables.append(self._k)

    @property
    def fifo_capacity(self) -> int:
        """FIFO size in bytes (MPU-9250) or slots (LSM9DS1): the datasheet's, or the knob's."""
        cap = self.faults.fifo_capacity
        return self.family.fifo_capacity if cap is None else cap

    @property
    def fifo_level(self) -> int:
        """What the FIFO holds now, in the unit of :attr:`fifo_capacity`."""
        self._sync()
        return len(self._fifo)

    @abstractmethod
    def _reset_state(self) -> None:
        """Empty the FIFO and clear the chip's flags and latches (part of a reset)."""

    @abstractmethod
    def _store(self, register: int, value: int) -> None:
        """Store a written value, with the register's own side effects (FIFO reset...)."""

    @abstractmethod
    def _fifo_on(self) -> bool:
        """Whether new samples go into the FIFO."""

    @abstractmethod
    def _read_register(self, register: int) -> int:
        """One register byte as the host reads it (with read side effects)."""

    @abstractmethod
    def _odr_hz(self) -> float | None:
        """The configured output data rate, or ``None`` when the gyro is off."""

    @abstractmethod
    def _sensitivity_rad_s_per_lsb(self) -> float:
        """The configured gyro sensitivity."""

    @abstractmethod
    def _accel_counts_1g(self) -> float:
        """Accelerometer counts of 1 g at the configured range (the datasheet sensitivity,
        unrounded)."""

    def _temperature_counts(self, temperature_c: np.ndarray) -> np.ndarray:
        """Temperature register counts for temperatures in °C (§1.6, §2.5)."""
        fam = self.family
        counts = np.rint((temperature_c - fam.temperature_offset_c) * fam.temperature_lsb_per_c)
        return np.clip(counts, *self.temperature_count_limits).astype(np.int64)

    @abstractmethod
    def _head_tail(self, n: int) -> tuple[int, int]:
        """How many of ``n`` new samples the FIFO needs from the front and from the back."""

    @abstractmethod
    def _ingest(self, gyro: np.ndarray, accel: np.ndarray, temp: np.ndarray, head: int,
                skipped: int) -> None:
        """Push generated samples: the first ``head`` rows, then ``skipped`` samples that were
        not generated (they can only be dropped or overwritten), then the rest."""

    # -- the sample clock -----------------------------------------------------------------------

    @property
    def who_am_i(self) -> int:
        """The identity byte the chip answers (the fault knob's, if set)."""
        return self.faults.who_am_i if self.faults.who_am_i is not None else self.default_who_am_i

    @property
    def true_period_s(self) -> float | None:
        """The chip's real sample period on the shared clock (``None`` when off)."""
        return self._period

    def sample_time(self, k: np.ndarray | int) -> np.ndarray:
        """Shared-clock time of sample ``k`` (1, 2, ...) of the current configuration."""
        p = self.true_period_s
        if p is None:
            raise RuntimeError("the gyro is off")
        return self._origin + p * np.asarray(k, dtype=float)

    @property
    def samples_taken(self) -> int:
        """Samples taken since the rate was last set (the index of the latest)."""
        return self._k

    def _restart_sampling(self) -> None:
        """The rate or power state changed: start a new sample grid now."""
        self._origin = self.clock.monotonic()
        self._k = 0
        odr = self._odr_hz()
        self._period = None if odr is None else 1.0 / (odr * (1.0 + self.truth.clock_ppm * 1e-6))
        self._t_last = self._origin
        self._ahead = None

    def _true_rate(self, t: np.ndarray, period: float, peek: bool = False) -> np.ndarray:
        """The true rate each output sample carries: its mean over the sample period.

        A real gyro samples internally at kHz rates, low-pass filters (the DLPF) and decimates
        to the output rate, so fast motion (a servo's commutation ripple) does not alias into
        the output. The emulator stands in for that with the mean of ``subsamples`` evaluations
        spread over ``(t - period, t]`` (a boxcar, which nulls every multiple of the output
        rate). Sub-sample times are increasing across samples and calls, as the
        :class:`~gyrocal.drivers.emulated.motion.MotionSource` contract requires.
        """
        S = self.subsamples
        rate = self.motion.rate
        if peek:
            rate = self._peek_rate
        if S == 1:
            return np.asarray(rate(t), dtype=float)
        offsets = period * ((np.arange(S) + 0.5) / S - 1.0)  # midpoints of S slices
        # nothing before the sample grid's start (a delayed output's first samples reach back
        # past it, where an earlier configuration read the motion), so the times stay in order
        ts = np.maximum((t[:, None] + offsets[None, :]).reshape(-1), self._origin)
        w = np.asarray(rate(ts), dtype=float).reshape(t.size, S, 3)
        return w.mean(axis=1)

    def _peek_rate(self, t: np.ndarray) -> np.ndarray:
        return self.motion.rate(t, peek=True)  # type: ignore[call-arg]

    def _sync(self) -> None:
        """Generate every sample with time ≤ now: from the samples computed ahead when they
        hold (:meth:`_release_ahead`), else here."""
        period = self._period
        if period is None:
            return
        now = self.clock.monotonic()
        if now < self._origin + (self._k + 1) * period:
            return  # the next sample is not due (the guard below would stop there too)
        k_end = math.floor((now - self._origin) / period)
        while self._origin + k_end * period > now:  # guard the floor against rounding
            k_end -= 1
        n = k_end - self._k
        if n <= 0:
            return
        head, tail = self._head_tail(n)
        head, tail = min(head, n), min(tail, n)
        # a filter runs on between the samples handed out: the tail starts early enough for
        # its start to be forgotten (all of them when that reaches the head; the usual drain
        # of a few samples needs no tail, and no filter memory worked out)
        warm = 0 if head + tail >= n else self._filter_memory(period)
        if head + tail + warm >= n and self._release_ahead(n, period):
            return
        self._ahead = None
        if head + tail + warm >= n:
            ks = np.arange(self._k + 1, k_end + 1)
            head, skipped, warm = n, 0, 0
        else:
            ks = np.concatenate((np.arange(self._k + 1, self._k + 1 + head),
                                 np.arange(k_end - tail - warm + 1, k_end + 1)))
            skipped = n - head - tail - warm
        t = self._origin + period * ks
        # a delayed output reaches no further back than the sample grid's start
        t_eval = np.maximum(t - self._pure_delay_s(period), self._origin)
        rates = self._internal_rates(t_eval, period)
        white = self._noise_rng.standard_normal(rates.shape) * self._white_sigma(period)
        omega, white = self._filtered(rates, white, head, skipped)
        odr = 1.0 / period
        force = accel = None
        if self._accel_filter_key(odr) is not None:  # it runs through the run-in rows too
            force = self._specific_force(t_eval)
            accel, self._accel_lpf, _ = self._accel_counts(force, self._accel_rng, odr, head,
                                                           skipped, self._accel_lpf)
        if warm:  # the filter's run-in is not handed out: it joins the samples skipped
            keep = np.r_[0:head, head + warm:t.size]
            t, t_eval, omega, white = t[keep], t_eval[keep], omega[keep], white[keep]
            if accel is not None:
                force, accel = force[keep], accel[keep]  # type: ignore[index]
            skipped += warm
        temperature = self.truth.temperature_at(t)
        m = self.truth.reading(omega, temperature)
        if force is None:
            force = self._specific_force(t_eval)
        realism = self.truth.realism
        if realism.g_sensitivity_rad_s_per_g != _ZERO33:
            m = m + self._true_force(t_eval, force) @ np.asarray(
                realism.g_sensitivity_rad_s_per_g).T
        m = m + white
        if accel is None:
            accel, _, _ = self._accel_counts(force, self._accel_rng, odr, head, skipped, None)
        self._emit(t, m, accel, temperature, head, skipped)

    def _white_sigma(self, period: float) -> np.ndarray:
        """The white noise's per-sample σ (3,) at the filter's input: the density (the truth's,
        else the chip's datasheet figure) times √(the rate the filter runs at)."""
        rate = self._internal_per_output(period) / period
        return self.truth.sigma_rad_s(rate, self.family.gyro_errors.noise_density_rad_s_sqrt_hz)

    def _filter_memory(self, period: float) -> int:
        """Output samples the restarted output filters (the gyro's and the accelerometer's)
        need before their start is forgotten to :data:`_FILTER_MEMORY` (0 without a filter):
        each of a cascade's sections' poles decays that far in turn (an upper bound)."""
        memory = 0
        section, rate = self._filter_section(), self._filter_rate_hz()
        if section is not None and rate is not None:
            memory = _memory(*section, self._internal_per_output(period))
        accel = self._accel_filter_key(1.0 / period)
        if accel is not None:  # the accelerometer's filter, as :meth:`_accel_counts` runs it
            fc, order, rate = accel
            steps = max(1, round(rate * period))
            k = math.tan(math.pi * fc / (steps / period))
            k = k if order == 1 else k / math.sqrt(2.0 ** (1.0 / order) - 1.0)
            memory = max(memory, _memory(k, order, steps))
        return memory

    def _emit(self, t: np.ndarray, m: np.ndarray, accel: np.ndarray, temperature: np.ndarray,
              head: int, skipped: int, gyro: np.ndarray | None = None,
              temp: np.ndarray | None = None) -> None:
        """The last steps of new samples: the coloured noise on the reading ``m`` (rad/s),
        quantized to the configured range (``gyro``: these counts, computed ahead), a stuck
        axis, the temperature's counts; into the FIFO (:meth:`_ingest`) and the output
        registers."""
        if gyro is None:
            if self._coloured.active:
                m = m + self._coloured.draw(np.diff(t, prepend=self._t_last))
            gyro = np.clip(np.rint(m / self._sensitivity_rad_s_per_lsb())
                           + self._gyro_trim_counts(), -32768, 32767)
            gyro = gyro.astype(np.int64)
        self._t_last = float(t[-1])
        f = self.faults
        if f.stuck_axis is not None:
            gyro = gyro.copy()
            gyro[t >= f.stuck_from_s, f.stuck_axis] = f.stuck_counts
        if temp is None:
            temp = self._temperature_counts(temperature)
        self._note_temperature(float(temperature[-1]))
        self._ingest(gyro, accel, temp, head, skipped)
        self._latest = _Sample(gyro[-1].copy(), accel[-1].copy(), int(temp[-1]))
        self._k += gyro.shape[0] + skipped
        self._after_samples()

    def _note_temperature(self, temperature_c: float) -> None:  # noqa: B027 - a hook
        """The die temperature of the newest sample (a chip whose registers show it keeps it)."""

    # -- samples computed ahead -----------------------------------------------------------------

    def _lookahead_token(self) -> tuple[Any, ...] | None:
        """What samples computed ahead depend on besides the chip's registers (a write to them
        drops the samples): equal tokens, equal samples. None when the motion source cannot be
        looked ahead on, or :attr:`lookahead_s` is 0."""
        look = getattr(self.motion, "lookahead", None)
        if look is None or self.lookahead_s <= 0:
            return None
        state = look()
        if state is None:
            return None
        return (state, id(self.motion), id(self.truth), self.subsamples, self._origin,
                self._period, self._created)

    def _release_ahead(self, n: int, period: float) -> bool:
        """Hand out the next ``n`` samples from those computed ahead (computing them first when
        none hold), exactly as :meth:`_sync` would compute them now. False (and nothing done)
        when that cannot be: a motion source without look-ahead, or a servo's timed event due
        by the last time the samples read the motion at (reading it would apply the event)."""
        token = self._lookahead_token()
        if token is None:
            return False
        a = self._ahead
        if (a is None or a.token != token or a.start_lpf is not self._lpf
                or a.start_accel_lpf is not self._accel_lpf
                or a.k_first + a.next != self._k + 1 or a.next + n > a.t.size):
            a = None
        if a is not None:
            t_read = float(a.t_read[a.next + n - 1])
        else:
            t_read = max(self._origin + period * (self._k + n) - self._pure_delay_s(period),
                         self._origin)
        if self.motion.due_by(t_read):  # type: ignore[attr-defined]
            return False
        if a is None:
            count = max(n, min(math.ceil(self.lookahead_s / period), self.lookahead_max))
            a = self._ahead = self._look_ahead(token, self._k + 1, count, period)
        i, j = a.next, a.next + n
        self.motion.touch(t_read)  # type: ignore[attr-defined]
        self._noise_rng.skip(a.noise_draws * n)
        self._accel_rng.skip(a.accel_draws * n)
        if a.lpf is not None:
            self._lpf = a.start_lpf = (a.fc, a.lpf[j - 1])
        if a.accel_lpf is not None:
            self._accel_lpf = a.start_accel_lpf = (a.accel_key, a.accel_lpf[j - 1])
        a.next = j
        gyro = None
        if n == 1:
            c = self._coloured
            start = a.coloured_start
            state = c.state()
            if a.coloured_from != i or j > a.coloured_hi or start is None or any(
                    x is not y for x, y in zip(start, state, strict=True)):
                self._coloured_ahead(a, i)
            r = i - a.coloured_lo  # the sample's row in the coloured arrays
            if a.gm is not None:
                c.resume(a.gm[r], a.walk[r], 1)  # type: ignore[index]
                a.coloured_start = c.state()
            a.coloured_from = j
            gyro = a.gyro[r:r + 1]  # type: ignore[index]
            if a.frames is not None and self.faults.stuck_axis is None:
                size = len(a.frames) // (a.coloured_hi - a.coloured_lo)
                self._t_last = float(a.t[i])
                self._note_temperature(float(a.temperature[i]))
                self._ingest_frames(a.frames[r * size: (r + 1) * size])
                self._latest = _Sample(gyro[-1], a.accel[i], int(a.temp[i]))
                self._k += 1
                self._after_samples()
                return True
        self._emit(a.t[i:j], a.m[i:j], a.accel[i:j], a.temperature[i:j], n, 0, gyro,
                   a.temp[i:j])
        return True

    #: Samples :meth:`_coloured_ahead` computes the coloured noise and counts of at a time:
    #: a drain of several samples draws the noise afresh (:meth:`_emit`) and the samples
    #: after it need them again from the new state, so few are computed beyond the next ones.
    coloured_horizon = 16

    def _coloured_ahead(self, a: _Ahead, i: int) -> None:
        """The coloured noise and the gyro counts of ``a``'s samples from ``i`` on (the next
        :attr:`coloured_horizon`), as drains of one sample each would give them from the
        coloured noise's present state (each step's the same arithmetic however many are
        computed at once)."""
        c = self._coloured
        hi = min(a.t.size, i + self.coloured_horizon)
        m = a.m[i:hi]
        if c.active:
            dt = np.diff(a.t[i:hi], prepend=self._t_last)
            noise, a.gm, a.walk = c.ahead(dt)
            m = m + noise
        else:
            a.gm = a.walk = None
        a.gyro = np.clip(np.rint(m / a.sensitivity) + self._gyro_trim_counts(), -32768,
                         32767).astype(np.int64)
        a.coloured_from, a.coloured_start = i, c.state()
        a.coloured_lo, a.coloured_hi = i, hi
        a.frames = self._frames_ahead(a.gyro, a.accel[i:hi], a.temp[i:hi])

    def _frames_ahead(self, gyro: np.ndarray, accel: np.ndarray, temp: np.ndarray
                      ) -> bytes | None:
        """What :meth:`_ingest` would push into the FIFO for these samples, one drain of one
        sample at a time, the same number of bytes each (for :meth:`_ingest_frames`); None
        when the chip does not say (its :meth:`_ingest` then runs)."""
        return None

    def _ingest_frames(self, data: bytes) -> None:
        """:meth:`_ingest` of one sample, its FIFO bytes given (:meth:`_frames_ahead`)."""
        raise NotImplementedError

    def _look_ahead(self, token: tuple[Any, ...], k_first: int, count: int,
                    period: float) -> _Ahead:
        """Samples ``k_first`` … ``k_first + count − 1`` computed ahead, as :meth:`_sync`
        computes them up to the coloured noise: the motion as the servos plan it now (nothing
        frozen, no event applied), the filter from its present state, the white noise and the
        accelerometer's noise the next values of their streams (left in them until handed
        out)."""
        t = self._origin + period * np.arange(k_first, k_first + count)
        t_eval = np.maximum(t - self._pure_delay_s(period), self._origin)
        start_lpf = self._lpf
        rates = self._internal_rates(t_eval, period, peek=True)
        white = (self._noise_rng.peek(rates.size).reshape(rates.shape)
                 * self._white_sigma(period))
        x = np.concatenate((rates, white), axis=-1)
        out, _, stages = self._lowpass(x, count, 0, start_lpf, stages=True)
        states = None
        if stages is not None:  # filtered: the state after each sample is its last internal one
            states = np.stack([v.reshape(count, -1, 6)[:, -1] for v in stages], axis=1)
        out = out if out.ndim == 2 else out[:, -1]
        omega, white = out[:, :3], out[:, 3:]
        temperature = self.truth.temperature_at(t)
        m = self.truth.reading(omega, temperature)
        force = self._specific_force(t_eval, peek=True)
        realism = self.truth.realism
        if realism.g_sensitivity_rad_s_per_g != _ZERO33:
            m = m + self._true_force(t_eval, force, peek=True) @ np.asarray(
                realism.g_sensitivity_rad_s_per_g).T
        odr = 1.0 / period
        m = m + white
        peeking = _Peeking(self._accel_rng)
        start_accel = self._accel_lpf
        accel, _, accel_states = self._accel_counts(force, peeking, odr, count, 0,  # type: ignore[arg-type]
                                                    start_accel, stages=True)
        return _Ahead(token, k_first, t, t_eval, m, accel, temperature,
                      self._temperature_counts(temperature), states, self._filter_key(),
                      peeking.used // count, start_lpf, self._sensitivity_rad_s_per_lsb(),
                      noise_draws=rates.size // count, accel_lpf=accel_states,
                      accel_key=self._accel_filter_key(odr), start_accel_lpf=start_accel)

    def _true_force(self, t: np.ndarray, accel_force: np.ndarray, peek: bool = False
                    ) -> np.ndarray:
        """The specific force (N, 3) in g the gyro's g-sensitivity sees at ``t``: the motion
        source's true one whenever it has one, whether or not the accelerometer is shown it
        (the ``gravity`` knob is the accelerometer's), else ``accel_force``."""
        spf = getattr(self.motion, "specific_force", None)
        if self.truth.realism.specific_force or spf is None:
            return accel_force
        force = spf(t, peek=True) if peek else spf(t)
        return np.asarray(force, dtype=float).reshape(t.size, 3)

    def _specific_force(self, t: np.ndarray, peek: bool = False) -> np.ndarray:
        """The true specific force (N, 3) in g at ``t``: the motion source's when
        :attr:`SensorRealism.specific_force` is on and it has one, else +1 g on z."""
        spf = getattr(self.motion, "specific_force", None)
        if self.truth.realism.specific_force and spf is not None:
            force = spf(t, peek=True) if peek else spf(t)
            return np.asarray(force, dtype=float).reshape(t.size, 3)
        force = np.zeros((t.size, 3))
        force[:, 2] = 1.0
        return force

    def cutoff_hz(self) -> float | None:
        """The gyro output filter's −3 dB bandwidth, ``None`` for no filter (the chip's
        datasheet figure; each chip says which)."""
        return None

    def filter_setting(self) -> FilterSetting | None:
        """The configured row of the chip's gyro filter table (its bandwidth, the datasheet's
        delay and noise bandwidth where given, the source); ``None`` for a chip without such a
        table or with the filter off."""
        return None

    #: Whether the gyro output filter (:meth:`cutoff_hz`) is emulated (the ``output_filter``
    #: knob of the chips).
    output_filter = True

    def _lowpass_hz(self) -> float | None:
        """The cutoff the emulated output path filters at (``None``: it does not filter)."""
        return self.cutoff_hz() if self.output_filter else None

    def filter_order(self) -> int:
        """The order of the gyro output filter (its first-order sections in cascade): 1 unless
        a chip's register selects another (the ICM-42688-P's GYRO_UI_FILT_ORD)."""
        return 1

    def _filter_key(self) -> tuple[float, int] | None:
        """What the output filter's state belongs to: its cutoff and order (``None``: no
        filter)."""
        fc = self._lowpass_hz()
        return None if fc is None else (fc, self.filter_order())

    def _filter_section(self) -> tuple[float, int] | None:
        """The output filter as ``(k, order)``: ``order`` equal first-order low-passes
        ``b (1 + z⁻¹) / (1 + a z⁻¹)``, ``b = k / (1 + k)``, ``a = (k − 1) / (k + 1)``, each the
        bilinear transform prewarped so that the cascade is exactly −3 dB at the cutoff ``fc``:
        ``k = tan(π fc / rate) / √(2^(1/order) − 1)``; ``None`` without a filter."""
        key, rate = self._filter_key(), self._filter_rate_hz()
        if key is None or rate is None:
            return None
        fc, order = key
        k = math.tan(math.pi * fc / rate)
        return (k if order == 1 else k / math.sqrt(2.0 ** (1.0 / order) - 1.0)), order

    def _pure_delay_s(self, period: float) -> float:
        """A delay of the output beyond its filter's, s (the chip's datasheet delay less the
        filter's and the sub-sample average's group delays)."""
        return 0.0

    #: Whether the chip's filter runs at ``family.extra["internal_rate_hz"]`` ahead of a rate
    #: divider (the InvenSense DLPFs), rather than at the output rate.
    filters_at_internal_rate = False

    def _average_window_s(self, period: float) -> float:
        """The span the true rate is averaged over for one output sample (see
        :meth:`_true_rate`): the output period, or with a filter at the internal rate one
        internal sample only (the filter, not the decimation, is then the anti-alias filter),
        or one step of a filter run faster than the output rate (:func:`filter_steps`)."""
        if self._lowpass_hz() is None:
            return period
        if not self.filters_at_internal_rate:
            return period / self._internal_per_output(period)
        return min(period, 1.0 / self.family.extra["internal_rate_hz"])

    def _internal_per_output(self, period: float) -> int:
        """Internal samples the chip filters per output sample: with a filter at the internal
        rate, the rate divider's ``1 + SMPLRT_DIV`` (register map CONFIG, SMPLRT_DIV; hardware
        reference §1.4); else :func:`filter_steps` (1 unless the bandwidth reaches half the
        output rate)."""
        fc = self._lowpass_hz()
        if fc is None:
            return 1
        if not self.filters_at_internal_rate:
            return filter_steps(fc, 1.0 / period)
        return max(1, round(period * self.family.extra["internal_rate_hz"]))

    def _internal_rates(self, t: np.ndarray, period: float, peek: bool = False) -> np.ndarray:
        """The true rate of each new output sample (n, 3), or, for a chip that filters at its
        internal rate, of the ``D`` internal samples ending at each (n, D, 3): each the mean over
        :meth:`_average_window_s` (:meth:`_true_rate`; ``peek``: looking ahead)."""
        D = self._internal_per_output(period)
        if D == 1:
            return self._true_rate(t, self._average_window_s(period), peek)
        step = period / D
        t_int = (t[:, None] - step * np.arange(D - 1, -1, -1)[None, :]).reshape(-1)
        return self._true_rate(t_int, min(step, self._average_window_s(period)), peek).reshape(
            t.size, D, 3)

    def _filter_rate_hz(self) -> float | None:
        """The rate the output filter runs at: the output rate times the internal samples per
        output sample."""
        odr = self._odr_hz()
        return None if odr is None else odr * self._internal_per_output(1.0 / odr)

    def _filtered(self, omega: np.ndarray, white: np.ndarray, head: int, skipped: int
                  ) -> tuple[np.ndarray, np.ndarray]:
        """The output filter (:meth:`_filter_section`: the chip's order of first-order
        low-passes at its cutoff, :meth:`_lowpass_hz`) on the true rates of new samples and on
        the white noise drawn for them (``white``, the same shape: the noise enters ahead of the
        filter, so the filter narrows it as on silicon; the first ``head`` rows, then
        ``skipped`` not generated, then the rest); returns both filtered, decimated to one row
        per output sample. The filter runs at :meth:`_filter_rate_hz`. Rates given per internal
        sample (n, D, 3) are filtered at the internal rate and decimated to the last of each D
        (the MPU-9250's DLPF runs at 1 kHz before SMPLRT_DIV, register map CONFIG). The chips'
        filter shapes are not published, so this stands in with the datasheet's bandwidth and
        the register's order ⚠. The state carries across calls; it restarts (the rates at rest
        on their first input, the noise at zero) after skipped samples and when the cutoff,
        order or rate changes (:meth:`_sync` runs it in early enough for the restart to be
        forgotten)."""
        x = np.concatenate((omega, white), axis=-1)
        out, state, _ = self._lowpass(x, head, skipped, self._lpf)
        if out is not x:
            self._lpf = state
        out = out if out.ndim == 2 else out[:, -1]
        return out[:, :3], out[:, 3:]

    def _lowpass(self, omega: np.ndarray, head: int, skipped: int, state: Any,
                 stages: bool = False) -> tuple[np.ndarray, Any, list[np.ndarray] | None]:
        """:meth:`_filtered`'s filter from ``state``, without decimating: the filtered rates
        (``omega`` itself when there is no filter), the state after them (the last input and
        each section's last output) and, with ``stages``, the input and each section's output
        (the state after every row; ``None`` without a filter)."""
        section, key = self._filter_section(), self._filter_key()
        if section is None or omega.shape[0] == 0:
            return omega, state, None
        return _cascade(omega, head, skipped, state, key, *section, stages)

    def filter_delay_s(self) -> float | None:
        """Group delay at DC of the emulated output filter, s: ``order / (2 k · rate)`` for
        ``order`` bilinear first-order sections (each its numerator's half sample plus its
        pole's ``(1 − k) / 2k`` samples, :meth:`_filter_section`'s ``k``); ``None`` without
        a filter."""
        section, rate = self._filter_section(), self._filter_rate_hz()
        if section is None or rate is None:
            return None
        k, order = section
        return order / (2.0 * k * rate)

    def output_delay_s(self) -> float | None:
        """The emulated gyro output's delay at DC, s: its filter's group delay
        (:meth:`filter_delay_s`), the per-sample mean's half window and any pure delay (the
        MPU-9250's CONFIG table delay makes up the rest); ``None`` without a filter."""
        filt, period = self.filter_delay_s(), self.true_period_s
        if filt is None or period is None:
            return None
        boxcar = 0.5 * self._average_window_s(period) if self.subsamples > 1 else 0.0
        return filt + boxcar + self._pure_delay_s(period)

    def accel_filter_setting(self) -> FilterSetting | None:
        """The configured row of the chip's accelerometer filter table (its bandwidth, delay
        and noise bandwidth where the datasheet gives them, the source); ``None`` for a chip
        whose accelerometer filter is not emulated or is off."""
        return None

    def accel_filter_order(self) -> int:
        """The accelerometer filter's order: 1 unless a register selects another (the
        ICM-42688-P's ACCEL_UI_FILT_ORD)."""
        return 1

    def _accel_filter_rate_hz(self, odr: float, bandwidth_hz: float) -> float:
        """The rate the accelerometer filter of ``bandwidth_hz`` runs at: the chip's internal
        rate ahead of its divider where the filter runs there (the InvenSense DLPFs), else the
        output rate times :func:`filter_steps`."""
        if self.filters_at_internal_rate:
            return max(odr, float(self.family.extra["internal_rate_hz"]))
        return odr * filter_steps(bandwidth_hz, odr)

    def _accel_filter_key(self, odr: float) -> tuple[float, int, float] | None:
        """The emulated accelerometer filter as ``(bandwidth, order, rate)`` (with the chip's
        ``output_filter`` knob, the ``dlpf`` effect), ``None`` without one or with a bandwidth
        at or above half its rate."""
        setting = self.accel_filter_setting() if self.output_filter else None
        if setting is None:
            return None
        rate = self._accel_filter_rate_hz(odr, setting.bandwidth_hz)
        if setting.bandwidth_hz >= 0.5 * rate:
            return None
        return setting.bandwidth_hz, self.accel_filter_order(), rate

    def _accel_counts(self, force: np.ndarray, rng: Any, odr: float, head: int, skipped: int,
                      state: Any, stages: bool = False
                      ) -> tuple[np.ndarray, Any, np.ndarray | None]:
        """The accelerometer's counts (n, 3) for the true specific force at the output samples:
        its errors (:meth:`SensorTruth.accel_reading`), its filter (:meth:`_accel_filter_key`)
        with the white noise drawn ahead of it at the filter's rate, ``D`` internal samples per
        output sample (the force held over them), decimated to the last of each; without a
        filter, the noise per output sample. Returns the counts, the filter's state after them
        and, with ``stages``, its state after each output sample ((n, order + 1, 6); else
        ``None``)."""
        key = self._accel_filter_key(odr)
        if key is None:
            reading = self.truth.accel_reading(force, rng, odr)
            states = None
        else:
            fc, order, rate = key
            n, steps = force.shape[0], max(1, round(rate / odr))
            clean = self.truth.accel_reading(force)
            acc = self.truth.accelerometer
            density = 0.0 if acc is None else acc.noise_density_g_sqrt_hz
            noise = (rng.standard_normal((n, steps, 3)) * density * math.sqrt(odr * steps)
                     if density > 0 else np.zeros((n, steps, 3)))
            x = np.concatenate((np.repeat(clean[:, None, :], steps, axis=1), noise), axis=-1)
            k = math.tan(math.pi * fc / (odr * steps))
            k = k if order == 1 else k / math.sqrt(2.0 ** (1.0 / order) - 1.0)
            out, state, every = _cascade(x, head, skipped, state, key, k, order, stages)
            last = out[:, -1]
            reading = last[:, :3] + last[:, 3:]
            states = (None if every is None
                      else np.stack([v[:, -1] for v in every], axis=1))
        counts = np.clip(np.rint(reading * self._accel_counts_1g()) + self._accel_trim_counts(),
                         -32768, 32767).astype(np.int64)
        return counts, state, states

    def _gyro_trim_counts(self) -> np.ndarray | float:
        """Counts the chip's registers add to each gyro output (offset registers, self-test
        actuation), at the configured range; 0 unless a chip has such registers."""
        return 0.0

    def _accel_trim_counts(self) -> np.ndarray | float:
        """Counts the chip's registers add to each accelerometer output (self-test)."""
        return 0.0

    def _after_samples(self) -> None:  # noqa: B027 - a hook, empty unless a chip needs it
        """Runs after new samples were taken (the MPU-9250's I²C master cycle)."""


# ---------------------------------------------------------------------------------------------


_MR, _MB = MPU9250_REG, MPU9250_BITS
_MPU_READ_ONLY = frozenset(
    {_MR.INT_STATUS, _MR.FIFO_COUNTH, _MR.FIFO_COUNTL, _MR.FIFO_R_W, _MR.WHO_AM_I,
     _MR.I2C_SLV4_DI, _MR.I2C_MST_STATUS}
    | set(range(_MR.ACCEL_XOUT_H, _MR.GYRO_XOUT_H + 6))
    | set(range(_MR.EXT_SENS_DATA_00, _MR.EXT_SENS_DATA_00 + 24))
)
#: Where the MPU-9250 keeps its gyro and accelerometer self-test (RM-MPU-9250A-00 registers
#: 0-2, 13-15 and 27/28: XGYRO_Cten..ZGYRO_Cten and ax/ay/az_st_en in bits 7:5 of GYRO_CONFIG
#: and ACCEL_CONFIG, beside the FS_SEL fields in bits 4:3).
_MPU_GYRO_SELF_TEST = SelfTestLayout(_MR.SELF_TEST_X_GYRO, _MR.GYRO_CONFIG,
                                     _MB.SELF_TEST_EN_SHIFT, _MR.GYRO_CONFIG, _MB.GYRO_FS_SHIFT)
_MPU_ACCEL_SELF_TEST = SelfTestLayout(_MR.SELF_TEST_X_ACCEL, _MR.ACCEL_CONFIG,
                                      _MB.SELF_TEST_EN_SHIFT, _MR.ACCEL_CONFIG,
                                      _MB.ACCEL_FS_SHIFT)
#: Where the AK8963 sits on the MPU-9250's auxiliary bus (and on the host bus in bypass).
AK8963_ADDRESS = 0x0C
_MPU_VARIANTS = {m.name: m.who_am_i for m in MPU9250.models}
_MPU_MASTER = MasterLayout(
    slv0_addr=_MR.I2C_SLV0_ADDR, slv_stride=3, slv0_do=_MR.I2C_SLV0_DO, do_stride=1,
    slv4_addr=_MR.I2C_SLV4_ADDR, slv4_reg=_MR.I2C_SLV4_REG, slv4_ctrl=_MR.I2C_SLV4_CTRL,
    slv4_do=_MR.I2C_SLV4_DO, slv4_di=_MR.I2C_SLV4_DI, ext_sens_data_00=_MR.EXT_SENS_DATA_00)
_MPU_DLPF_BY_CFG = {f.code: f for f in MPU9250_GYRO_FILTER}


class EmulatedMPU9250(_EmulatedImu):
    """An MPU-9250 (or MPU-9255 / MPU-6500) accel/gyro die on the I²C bus (hardware reference §1).

    128-byte register file, reset values PWR_MGMT_1 = 0x01 and WHO_AM_I, the rest 0 (§1.9).
    Burst reads and writes auto-increment, except at FIFO_R_W (0x74), a data port that pops the
    FIFO; an empty FIFO repeats the last byte read (§1.7). Reading FIFO_COUNTH latches the count
    for FIFO_COUNTL. The FIFO holds 512 bytes of frames in register order (ACCEL, TEMP, GYRO X/Y/Z
    as enabled in FIFO_EN) written whenever USER_CTRL.FIFO_EN is set; FIFO_RST empties it. When it
    is full, CONFIG.FIFO_MODE = 0 overwrites the oldest bytes and FIFO_MODE = 1 drops new ones;
    either way INT_STATUS.FIFO_OFLOW_INT is set. INT_STATUS bit 0 flags new data. Both clear when
    INT_STATUS is read. H_RESET restores the reset values. The rate is 1 kHz / (1 + SMPLRT_DIV)
    with DLPF_CFG 1..6, 8 kHz with DLPF_CFG 0 or 7, 32 kHz with FCHOICE_B ≠ 0 (§1.4).

    Parameters
    ----------
    clock : Clock
        The shared clock.
    motion : MotionSource, optional
        True angular rate in the sensor frame (at rest when omitted).
    truth : SensorTruth, optional
        The sensor's true errors.
    faults : ChipFaults, optional
        Fault knobs.
    seed : int
        Seed of the noise and fault random generators.
    variant : str
        ``"mpu9250"``, ``"mpu9255"`` or ``"mpu6500"``: which WHO_AM_I it answers.
    output_filter : bool
        The gyro DLPF at the CONFIG setting (:meth:`cutoff_hz`, :meth:`delay_s`) and the
        accelerometer's at the ACCEL_CONFIG_2 setting (:meth:`accel_filter_setting`), running
        at the internal 1 kHz ahead of SMPLRT_DIV, the white noise entering ahead of each;
        ``False`` passes the per-sample mean rate and unfiltered accelerometer noise.
    """

    family = MPU9250
    filters_at_internal_rate = True
    reset_values = {
        _MR.PWR_MGMT_1: 0x01,
        **_MPU_GYRO_SELF_TEST.codes_reset(FACTORY_SELF_TEST_CODES[:3]),
        **_MPU_ACCEL_SELF_TEST.codes_reset(FACTORY_SELF_TEST_CODES[3:]),
    }
    read_only = _MPU_READ_ONLY
    soft_reset = (_MR.PWR_MGMT_1, _MB.PWR_MGMT_1_H_RESET)

    def __init__(self, clock: Clock, motion: MotionSource | None = None,
                 truth: SensorTruth | None = None, *, faults: ChipFaults | None = None,
                 seed: int = 0, variant: str = "mpu9250", subsamples: int = 8,
                 output_filter: bool = True) -> None:
        if variant not in _MPU_VARIANTS:
            raise ValueError(f"variant must be one of {', '.join(_MPU_VARIANTS)}, got {variant!r}")
        self.default_who_am_i = _MPU_VARIANTS[variant]
        self.variant = variant
        self.output_filter = bool(output_filter)
        super().__init__(clock, motion, truth, faults=faults, seed=seed, subsamples=subsamples)
        #: Devices on the auxiliary I²C bus, by address: the AK8963 die (none on an MPU-6500).
        self.aux: dict[int, I2CDevice] = {}
        self.master = AuxI2CMaster(_MPU_MASTER, self.aux)
        if variant != "mpu6500":
            self.aux[AK8963_ADDRESS] = EmulatedAK8963(clock, MagneticField(self.motion),
                                                      seed=seed)

    @property
    def bypass_open(self) -> bool:
        """Whether the auxiliary bus is switched onto the host bus: INT_PIN_CFG.BYPASS_EN set
        and the I²C master off (USER_CTRL.I2C_MST_EN clear) (Register Map §4.15, §4.24)."""
        r = self._regs
        return bool(r[_MR.INT_PIN_CFG] & _MB.INT_PIN_CFG_BYPASS_EN) and not (
            r[_MR.USER_CTRL] & _MB.USER_CTRL_I2C_MST_EN)

    def _after_samples(self) -> None:
        """One I²C master cycle at the sample rate (Register Map §4.7–4.13;
        :class:`~gyrocal.drivers.emulated.i2c_master.AuxI2CMaster`) while USER_CTRL.I2C_MST_EN
        is set."""
        if self._regs[_MR.USER_CTRL] & _MB.USER_CTRL_I2C_MST_EN:
            self._mst_status |= self.master.cycle(self._regs, self._regs)

    def filter_setting(self) -> FilterSetting | None:
        """The gyro DLPF's row of :data:`~gyrocal.drivers.imu.chips.MPU9250_GYRO_FILTER`
        CONFIG.DLPF_CFG selects (register map CONFIG table, hardware reference §1.4), for
        DLPF_CFG 1..6 with FCHOICE_B = 00; ``None`` otherwise."""
        r = self._regs
        if r[_MR.GYRO_CONFIG] & _MB.GYRO_FCHOICE_B_MASK or self._odr_hz() is None:
            return None
        return _MPU_DLPF_BY_CFG.get(r[_MR.CONFIG] & _MB.CONFIG_DLPF_MASK)

    def cutoff_hz(self) -> float | None:
        """The gyro DLPF bandwidth (:meth:`filter_setting`); ``None`` without one."""
        setting = self.filter_setting()
        return None if setting is None else setting.bandwidth_hz

    def delay_s(self) -> float | None:
        """The datasheet's gyro delay for the configured DLPF (CONFIG table), s."""
        setting = self.filter_setting()
        return None if setting is None else setting.delay_s

    def accel_filter_setting(self) -> FilterSetting | None:
        """The accelerometer DLPF's row of :data:`~gyrocal.drivers.imu.chips.
        MPU9250_ACCEL_FILTER` ACCEL_CONFIG_2.A_DLPFCFG selects with ACCEL_FCHOICE_B = 0 (reset:
        218.1 Hz), running at the internal 1 kHz ahead of SMPLRT_DIV; ``None`` with it bypassed
        or the chip not sampling."""
        r = self._regs
        if r[_MR.ACCEL_CONFIG_2] & _MB.ACCEL_FCHOICE_B or self._odr_hz() is None:
            return None
        return MPU9250_ACCEL_FILTER[r[_MR.ACCEL_CONFIG_2] & _MB.A_DLPFCFG_MASK]


    def _pure_delay_s(self, period: float) -> float:
        """The CONFIG table's delay less the filter's DC group delay and the sub-sample
        average's (half its window) — what a first-order filter alone does not delay."""
        total, filt = self.delay_s(), self.filter_delay_s()
        if total is None or filt is None:
            return 0.0
        boxcar = 0.5 * self._average_window_s(period) if self.subsamples > 1 else 0.0
        return max(0.0, total - filt - boxcar)

    def _reset_state(self) -> None:
        self._lpf = None
        self._fifo = bytearray()
        self._fifo_last = 0
        self._latched: int | None = None
        self._int_status = 0
        self._mst_status = 0

    def _odr_hz(self) -> float | None:
        r = self._regs
        if r[_MR.PWR_MGMT_1] & _MB.PWR_MGMT_1_SLEEP:
            return None
        if r[_MR.PWR_MGMT_2] & _MB.PWR_MGMT_2_GYRO_DISABLE == _MB.PWR_MGMT_2_GYRO_DISABLE:
            return None
        if r[_MR.GYRO_CONFIG] & _MB.GYRO_FCHOICE_B_MASK:
            return 32000.0
        if r[_MR.CONFIG] & _MB.CONFIG_DLPF_MASK in (0, 7):
            return 8000.0
        return self.family.extra["internal_rate_hz"] / (1 + r[_MR.SMPLRT_DIV])

    def _sensitivity_rad_s_per_lsb(self) -> float:
        fs = (self._regs[_MR.GYRO_CONFIG] & _MB.GYRO_FS_MASK) >> _MB.GYRO_FS_SHIFT
        return self.family.gyro_ranges[fs].sensitivity_rad_s_per_lsb

    def _accel_counts_1g(self) -> int:
        fs = (self._regs[_MR.ACCEL_CONFIG] >> _MB.ACCEL_FS_SHIFT) & 0x03
        return int(self.family.extra["accel_lsb_per_g_2g"]) >> fs

    def _gyro_trim_counts(self) -> np.ndarray | float:
        """XG/YG/ZG_OFFSET (registers 19–24) added to the output, ``X_OFFS_USR · 4 /
        2^FS_SEL`` counts (RM-MPU-9250A-00), plus any self-test actuation
        (:func:`~gyrocal.drivers.emulated.self_test.self_test_counts`)."""
        r = self._regs
        trim = self_test_counts(_MPU_GYRO_SELF_TEST, r, r)
        raw = bytes(r[_MR.XG_OFFSET_H:_MR.XG_OFFSET_H + 6])
        if any(raw):
            fs = (r[_MR.GYRO_CONFIG] & _MB.GYRO_FS_MASK) >> _MB.GYRO_FS_SHIFT
            codes = np.frombuffer(raw, dtype=">i2").astype(float)
            trim = trim + codes * GYRO_OFFSET_COUNTS_PER_CODE_FS0 / 2**fs
        return trim

    def _accel_trim_counts(self) -> np.ndarray | float:
        return self_test_counts(_MPU_ACCEL_SELF_TEST, self._regs, self._regs)

    # FIFO ------------------------------------------------------------------------------------

    def _fifo_on(self) -> bool:
        return bool(self._regs[_MR.USER_CTRL] & _MB.USER_CTRL_FIFO_EN)

    def _frame_bytes(self) -> int:
        en = self._regs[_MR.FIFO_EN]
        n = 6 if en & _MB.FIFO_EN_ACCEL else 0
        n += 2 if en & _MB.FIFO_EN_TEMP else 0
        for bit in (_MB.FIFO_EN_GYRO_X, _MB.FIFO_EN_GYRO_Y, _MB.FIFO_EN_GYRO_Z):
            n += 2 if en & bit else 0
        return n

    def _head_tail(self, n: int) -> tuple[int, int]:
        frame = self._frame_bytes()
        if not self._fifo_on() or frame == 0:
            return 0, 1
        if self._regs[_MR.CONFIG] & _MB.CONFIG_FIFO_MODE:  # stop when full
            room = max(0, self.fifo_capacity - len(self._fifo))
            return room // frame + 2, 1
        return 0, self.fifo_capacity // frame + 2

    def _frames(self, gyro: np.ndarray, accel: np.ndarray, temp: np.ndarray) -> bytes:
        en = self._regs[_MR.FIFO_EN]
        cols = []
        if en & _MB.FIFO_EN_ACCEL:
            cols.append(accel)
        if en & _MB.FIFO_EN_TEMP:
            cols.append(temp[:, None])
        for axis, bit in enumerate((_MB.FIFO_EN_GYRO_X, _MB.FIFO_EN_GYRO_Y, _MB.FIFO_EN_GYRO_Z)):
            if en & bit:
                cols.append(gyro[:, axis : axis + 1])
        if not cols:
            return b""
        return np.hstack(cols).astype(">i2").tobytes()

    def _push(self, data: bytes) -> None:
        if not data:
            return
        cap = self.fifo_capacity
        fifo = self._fifo
        if len(fifo) + len(data) > cap:
            self._int_status |= _MB.INT_STATUS_FIFO_OFLOW
            if self._regs[_MR.CONFIG] & _MB.CONFIG_FIFO_MODE:
                data = data[: max(0, cap - len(fifo))]
            else:
                fifo += data
                del fifo[: len(fifo) - cap]
                return
        fifo += data

    def _frames_ahead(self, gyro: np.ndarray, accel: np.ndarray, temp: np.ndarray
                      ) -> bytes | None:
        return self._frames(gyro, accel, temp) if self._fifo_on() else None

    def _ingest_frames(self, data: bytes) -> None:
        self._int_status |= _MB.INT_STATUS_RAW_DATA_RDY
        self._push(data)

    def _ingest(self, gyro: np.ndarray, accel: np.ndarray, temp: np.ndarray, head: int,
                skipped: int) -> None:
        self._int_status |= _MB.INT_STATUS_RAW_DATA_RDY
        if not self._fifo_on():
            return
        self._push(self._frames(gyro[:head], accel[:head], temp[:head]))
        if skipped:
            self._push(b"\x00" * (skipped * self._frame_bytes()))  # dropped or overwritten
        self._push(self._frames(gyro[head:], accel[head:], temp[head:]))

    # registers -------------------------------------------------------------------------------

    def _next_pointer(self, register: int) -> int:
        # FIFO_R_W is a data port: a burst that reaches it keeps popping the FIFO (§1.7)
        return register if register == _MR.FIFO_R_W else super()._next_pointer(register)

    def _read_fast(self, length: int) -> bytes | None:
        if self._ptr != _MR.FIFO_R_W:
            return None
        fifo = self._fifo
        take = min(length, len(fifo))
        out = bytes(fifo[:take])
        del fifo[:take]
        if take:
            self._fifo_last = out[-1]
        return out + bytes([self._fifo_last]) * (length - take)

    def _read_register(self, register: int) -> int:
        r = _MR
        if register == r.WHO_AM_I:
            return self.who_am_i
        if register == r.INT_STATUS:
            v, self._int_status = self._int_status, 0
            return v
        if self._regs[r.INT_PIN_CFG] & _MB.INT_PIN_CFG_INT_ANYRD_2CLEAR:
            self._int_status = 0  # register 55 INT_ANYRD_2CLEAR: any read clears the status
        if register == r.I2C_MST_STATUS:
            v, self._mst_status = self._mst_status, 0
            return v
        if register == r.FIFO_COUNTH:
            self._latched = len(self._fifo)
            return (self._latched >> 8) & 0x1F
        if register == r.FIFO_COUNTL:
            count = self._latched if self._latched is not None else len(self._fifo)
            self._latched = None
            return count & 0xFF
        if register == r.FIFO_R_W:
            return self._read_fast(1)[0]  # type: ignore[index]
        if r.ACCEL_XOUT_H <= register < r.GYRO_XOUT_H + 6:
            s = self._latest
            words = np.concatenate((s.accel, [s.temp], s.gyro)).astype(">i2").tobytes()
            return words[register - r.ACCEL_XOUT_H]
        return self._regs[register]

    def _store(self, register: int, value: int) -> None:
        if register == _MR.SIGNAL_PATH_RESET:
            return  # self-clearing; the emulated signal paths have no state to reset
        if register == _MR.USER_CTRL:
            if value & _MB.USER_CTRL_FIFO_RST:
                self._fifo.clear()
                self._latched = None
            value &= ~(_MB.USER_CTRL_FIFO_RST | 0x03)  # the reset bits clear themselves
        self._regs[register] = value


# ---------------------------------------------------------------------------------------------


_LR, _LB = LSM9DS1_REG, LSM9DS1_BITS
_LSM_ODR_BY_CODE = {code: hz for hz, code in LSM9DS1_ODR.items()}
#: LSM9DS1 accel/gyro reset values: WHO_AM_I 0x68 (DocID025715 Table 21; ST's lsm9ds1-pid
#: lsm9ds1_reg.h 182 LSM9DS1_IMU_ID; SparkFun's LSM9DS1_Registers.h 109), CTRL_REG4 and
#: CTRL_REG5_XL 0x38 (DocID025715 Tables 21, 62, 64 as the hardware reference transcribes
#: them; SparkFun's SparkFunLSM9DS1.cpp 282 and 311, "Default value: 0x38"), CTRL_REG8 0x04
#: (Table 73; the kernel's st_lsm6dsx and lsm9ds1-rjg), the rest 0.
_LSM_DEFAULTS = {
    _LR.WHO_AM_I: 0x68, _LR.CTRL_REG4: 0x38, _LR.CTRL_REG5_XL: 0x38, _LR.CTRL_REG8: 0x04
}
_LSM_READ_ONLY = frozenset(
    {_LR.WHO_AM_I, _LR.OUT_TEMP_L, _LR.OUT_TEMP_L + 1, _LR.STATUS_REG, _LR.STATUS_REG + 0x10,
     _LR.FIFO_SRC}
    | set(range(_LR.OUT_X_L_G, _LR.OUT_Z_H_G + 1))
    | set(range(_LR.OUT_X_L_XL, _LR.OUT_Z_H_XL + 1))
)
_LSM_ACCEL_MG_PER_LSB = {0b00: 0.061, 0b10: 0.122, 0b11: 0.244, 0b01: 0.732}  # §2.4


class EmulatedLSM9DS1(_EmulatedImu):
    """The accelerometer/gyroscope die of an LSM9DS1 on the I²C bus (hardware reference §2).

    Register file 0x00–0x7F with the reset values of §2.8; the sub-address is masked with 0x7F.
    Reads and writes auto-increment while CTRL_REG8.IF_ADD_INC is set; while the gyro is on the
    pointer jumps from 0x1D to 0x28 and from 0x2D back to 0x18 (ST §3.3), so a burst from 0x18
    reads gyro then accelerometer slot after slot. Output is little-endian (CTRL_REG8.BLE = 1
    swaps the bytes). OUT_TEMP is ``round((T − 25)·16)``, 12 bits sign-extended (§2.5).
    FIFO (§2.7): on while CTRL_REG9.FIFO_EN is set and FIFO_CTRL.FMODE is not bypass; 32 slots of
    gyro + accelerometer (FTH+1 with STOP_ON_FTH). FIFO mode (001) stops when full; continuous
    (110) overwrites the oldest and sets FIFO_SRC.OVRN, which clears when a slot is read.
    Bypass (000) empties the FIFO. The trigger modes 011 and 100 act as continuous and bypass
    (no trigger is emulated). The output registers show the oldest unread slot while the FIFO
    holds one, and reading OUT_Z_H_XL (0x2D) pops it. SW_RESET restores the reset values; BDU is
    accepted but has no effect (the emulated registers never change mid-read).

    Parameters
    ----------
    clock, motion, truth, faults, seed
        As for :class:`EmulatedMPU9250`.
    """

    family = LSM9DS1
    default_who_am_i = 0x68
    temperature_count_limits = (-2048, 2047)  # 12 bits, sign-extended
    reset_values = _LSM_DEFAULTS
    read_only = _LSM_READ_ONLY
    soft_reset = (_LR.CTRL_REG8, _LB.CTRL_REG8_SW_RESET)

    #: The magnetometer die beside it, once :func:`make_emulated_imu` has put one on the bus.
    magnetometer: EmulatedLSM9DS1Mag | None = None

    def __init__(self, clock: Clock, motion: MotionSource | None = None,
                 truth: SensorTruth | None = None, *, output_filter: bool = True,
                 **kwargs: Any) -> None:
        #: Whether the gyro output path filters (see :meth:`cutoff_hz`); ``False`` passes the
        #: per-sample mean rate through unfiltered.
        self.output_filter = bool(output_filter)
        super().__init__(clock, motion, truth, **kwargs)

    def cutoff_hz(self) -> float | None:
        """The gyro output's −3 dB bandwidth (datasheet Figure 28; :meth:`filter_setting`);
        ``None`` with the gyro off."""
        setting = self.filter_setting()
        return None if setting is None else setting.bandwidth_hz

    def filter_setting(self) -> FilterSetting | None:
        """The gyro output filter's setting: the LPF1 cutoff of ST Table 46 with
        CTRL_REG2_G.OUT_SEL = 00, the LPF2 cutoff BW_G selects in Table 47 with OUT_SEL = 1x
        (01 adds only the high-pass, which is off here); the datasheet gives no delay or noise
        bandwidth. ``None`` with the gyro off."""
        odr = self._odr_hz()
        if odr is None:
            return None
        if self._regs[_LR.CTRL_REG2_G] & _LB.OUT_SEL_LPF2:
            code = self._regs[_LR.CTRL_REG1_G] & _LB.BW_G_MASK
            return FilterSetting(code, LSM9DS1_BW_G_CUTOFF_HZ[odr][code], None, None,
                                 "ST DocID025715 Table 47 (BW_G), hardware reference §2.3 ⚠")
        return FilterSetting(0, LSM9DS1_LPF1_CUTOFF_HZ[odr], None, None,
                             "ST DocID025715 Table 46 (LPF1), hardware reference §2.3")

    def accel_filter_setting(self) -> FilterSetting | None:
        """The accelerometer's filter: in high-resolution mode (CTRL_REG7_XL.HR = 1, FDS = 0)
        the digital low-pass at ODR / DCF's divisor (:data:`~gyrocal.drivers.imu.chips.
        LSM9DS1_ACCEL_HR_DIVISOR`, code DCF | 0x10); else the analog anti-aliasing filter,
        BW_XL's with BW_SCAL_ODR = 1 (:data:`~gyrocal.drivers.imu.chips.
        LSM9DS1_ACCEL_AA_FILTER`), else the ODR's (:data:`~gyrocal.drivers.imu.chips.
        LSM9DS1_ACCEL_AA_AUTO_HZ`), while it is below half the ODR: a wider one (408 Hz at
        14.9 and 59.5 Hz) is left to the per-sample mean, the chip's decimation ahead of the
        output being unpublished. With HR on, the anti-aliasing filter (at least 0.42 ODR
        where it acts) is left out beside the digital low-pass (at most ODR/9) ⚠. FDS = 1
        (the high-pass output) is not emulated. ``None`` with the gyro off (the
        accelerometer's own ODR is not emulated)."""
        odr = self._odr_hz()
        if odr is None:
            return None
        reg6, reg7 = self._regs[_LR.CTRL_REG6_XL], self._regs[_LR.CTRL_REG7_XL]
        if reg7 & _LB.XL_HR and not reg7 & _LB.XL_FDS:
            dcf = (reg7 & _LB.DCF_MASK) >> _LB.DCF_SHIFT
            return FilterSetting(0x10 | dcf, odr / LSM9DS1_ACCEL_HR_DIVISOR[dcf], None, None,
                                 "DocID025715 CTRL_REG7_XL DCF ✓✓ (ST lsm9ds1_reg.h; SparkFun "
                                 "LSM9DS1_Settings)")
        if reg6 & _LB.BW_SCAL_ODR:
            setting = LSM9DS1_ACCEL_AA_FILTER[reg6 & _LB.BW_XL_MASK]
        else:
            setting = FilterSetting(0, LSM9DS1_ACCEL_AA_AUTO_HZ[odr], None, None,
                                    "DocID025715 CTRL_REG6_XL BW_SCAL_ODR = 0")
        return setting if setting.bandwidth_hz < 0.5 * odr else None


    def _reset_state(self) -> None:
        self._fifo: deque[bytes] = deque()
        self._ovrn = False
        self._status = 0
        self._lpf = None

    @property
    def fifo_capacity(self) -> int:
        """FIFO depth in slots (at most FTH + 1 with CTRL_REG9.STOP_ON_FTH)."""
        cap = super().fifo_capacity
        if self._regs[_LR.CTRL_REG9] & _LB.CTRL_REG9_STOP_ON_FTH:
            cap = min(cap, (self._regs[_LR.FIFO_CTRL] & _LB.FTH_MASK) + 1)
        return cap

    def _mode(self) -> int:
        return self._regs[_LR.FIFO_CTRL] >> _LB.FMODE_SHIFT

    def _fifo_on(self) -> bool:
        if not self._regs[_LR.CTRL_REG9] & _LB.CTRL_REG9_FIFO_EN:
            return False
        return self._mode() not in (_LB.FMODE_BYPASS, _LB.FMODE_BYPASS_TO_CONT)

    def _gyro_on(self) -> bool:
        return self._odr_hz() is not None

    def _odr_hz(self) -> float | None:
        return _LSM_ODR_BY_CODE.get(self._regs[_LR.CTRL_REG1_G] >> _LB.ODR_G_SHIFT)

    def _sensitivity_rad_s_per_lsb(self) -> float:
        fs = (self._regs[_LR.CTRL_REG1_G] >> _LB.FS_G_SHIFT) & 0x03
        for g in self.family.gyro_ranges:
            if g.code == fs:
                return g.sensitivity_rad_s_per_lsb
        return self.family.gyro_ranges[0].sensitivity_rad_s_per_lsb  # FS_G = 10: not available

    def _accel_counts_1g(self) -> float:
        fs = (self._regs[_LR.CTRL_REG6_XL] >> _LB.FS_XL_SHIFT) & 0x03
        return 1000.0 / _LSM_ACCEL_MG_PER_LSB[fs]

    def _word(self, value: int) -> bytes:
        order = "big" if self._regs[_LR.CTRL_REG8] & _LB.CTRL_REG8_BLE else "little"
        return int(value).to_bytes(2, order, signed=True)

    # FIFO ------------------------------------------------------------------------------------

    def _head_tail(self, n: int) -> tuple[int, int]:
        if not self._fifo_on():
            return 0, 1
        if self._mode() == _LB.FMODE_FIFO:
            return max(0, self.fifo_capacity - len(self._fifo)) + 2, 1
        return 0, self.fifo_capacity + 2

    def _ingest(self, gyro: np.ndarray, accel: np.ndarray, temp: np.ndarray, head: int,
                skipped: int) -> None:
        self._status |= _LB.STATUS_GDA | _LB.STATUS_XLDA | _LB.STATUS_TDA
        if not self._fifo_on():
            return
        slots = np.hstack((gyro, accel)).astype("<i2")
        if self._regs[_LR.CTRL_REG8] & _LB.CTRL_REG8_BLE:
            slots = slots.astype(">i2")
        rows = [row.tobytes() for row in slots]
        self._push(rows[:head])
        self._push([b""] * skipped)
        self._push(rows[head:])

    def _push(self, rows: list[bytes]) -> None:
        cap = self.fifo_capacity
        stop = self._mode() == _LB.FMODE_FIFO
        for row in rows:
            if len(self._fifo) >= cap:
                if stop:
                    return
                self._fifo.popleft()
                self._ovrn = True
            self._fifo.append(row)

    def _pop(self) -> None:
        if self._fifo_on() and self._fifo:
            self._fifo.popleft()
            self._ovrn = False

    def _fifo_src(self) -> int:
        n = len(self._fifo)
        fth = self._regs[_LR.FIFO_CTRL] & _LB.FTH_MASK
        v = min(n, 32) & _LB.FIFO_SRC_FSS_MASK
        v |= _LB.FIFO_SRC_OVRN if self._ovrn else 0
        v |= _LB.FIFO_SRC_FTH if fth and n >= fth else 0
        return v

    # registers -------------------------------------------------------------------------------

    def _next_pointer(self, register: int) -> int:
        if not self._regs[_LR.CTRL_REG8] & _LB.CTRL_REG8_IF_ADD_INC:
            return register
        if register == _LR.OUT_Z_H_G and self._gyro_on():
            return _LR.OUT_X_L_XL
        if register == _LR.OUT_Z_H_XL:
            return _LR.OUT_X_L_G if self._gyro_on() else _LR.OUT_X_L_XL
        return (register + 1) & 0x7F

    def _read_fast(self, length: int) -> bytes | None:
        """Whole slots from 0x18 out of the FIFO in one step (the wrap of ST §3.3)."""
        if (
            self._ptr != _LR.OUT_X_L_G
            or length % 12
            or not self._fifo_on()
            or len(self._fifo) < length // 12
            or not self._gyro_on()
            or not self._regs[_LR.CTRL_REG8] & _LB.CTRL_REG8_IF_ADD_INC
        ):
            return None
        rows = [self._fifo.popleft() for _ in range(length // 12)]
        self._ovrn = False
        self._status &= ~(_LB.STATUS_GDA | _LB.STATUS_XLDA)
        return b"".join(rows)

    def _current_slot(self) -> bytes:
        if self._fifo_on() and self._fifo:
            return self._fifo[0]
        s = self._latest
        return b"".join(self._word(v) for v in (*s.gyro, *s.accel))

    def _read_register(self, register: int) -> int:
        r = _LR
        if register == r.WHO_AM_I:
            return self.who_am_i
        if register in (r.OUT_TEMP_L, r.OUT_TEMP_L + 1):
            self._status &= ~_LB.STATUS_TDA
            return self._word(self._latest.temp)[register - r.OUT_TEMP_L]
        if register in (r.STATUS_REG, r.STATUS_REG + 0x10):
            return self._status
        if r.OUT_X_L_G <= register <= r.OUT_Z_H_G:
            self._status &= ~_LB.STATUS_GDA
            return self._current_slot()[register - r.OUT_X_L_G]
        if r.OUT_X_L_XL <= register <= r.OUT_Z_H_XL:
            self._status &= ~_LB.STATUS_XLDA
            v = self._current_slot()[6 + register - r.OUT_X_L_XL]
            if register == r.OUT_Z_H_XL:
                self._pop()
            return v
        if register == r.FIFO_SRC:
            return self._fifo_src()
        return self._regs[register]

    def _store(self, register: int, value: int) -> None:
        if register == _LR.CTRL_REG8:
            value &= ~_LB.CTRL_REG8_BOOT  # BOOT clears itself
        self._regs[register] = value
        if register == _LR.FIFO_CTRL and self._mode() == _LB.FMODE_BYPASS:
            self._fifo.clear()
            self._ovrn = False


# ---------------------------------------------------------------------------------------------


#: Emulated chips in their own modules (they subclass :class:`_EmulatedImu`), by model name:
#: (module, class), imported when first used.
EMULATED_CHIP_MODULES: dict[str, tuple[str, str]] = {
    "icm42688p": ("gyrocal.drivers.emulated.icm42688p", "EmulatedICM42688P"),
    "lsm6dsox": ("gyrocal.drivers.emulated.lsm6dsox", "EmulatedLSM6DSOX"),
    "icm20948": ("gyrocal.drivers.emulated.icm20948", "EmulatedICM20948"),
}


def make_emulated_imu(
    model: str,
    clock: Clock,
    motion: MotionSource | None = None,
    truth: SensorTruth | None = None,
    *,
    address: int | None = None,
    seed: int = 0,
    faults: ChipFaults | None = None,
    bus: EmulatedSMBus | None = None,
    bus_hz: float = 400_000,
    subsamples: int = 8,
    output_filter: bool = True,
) -> tuple[EmulatedSMBus, int]:
    """An emulated sensor on an emulated bus, ready for a reader, in one call.

    Parameters
    ----------
    model : str
        ``"mpu9250"``, ``"mpu9255"``, ``"mpu6500"``, ``"lsm9ds1"`` or one of
        :data:`EMULATED_CHIP_MODULES`.
    clock : Clock
        The shared clock.
    motion : MotionSource, optional
        True rate in the sensor frame (at rest when omitted).
    truth : SensorTruth, optional
        The sensor's true errors.
    address : int, optional
        Where to attach it; the chip's default address when omitted.
    seed : int
        Seed of the chip's random generators.
    faults : ChipFaults, optional
        Fault knobs.
    bus : EmulatedSMBus, optional
        Attach to this bus instead of a new one.
    bus_hz : float
        SCL frequency of a new bus.
    subsamples : int
        True-rate evaluations averaged into each output sample (the chip's low-pass filter and
        decimation; 1 samples the rate at the instant).
    output_filter : bool
        The chip's gyro output filter (its ``cutoff_hz``: the MPU-9250's and ICM-20948's DLPF,
        the LSM9DS1's LPF1/LPF2, the ICM-42688-P's UI filter); ``False`` turns it off.

    Returns
    -------
    (EmulatedSMBus, int)
        The bus and the address; the chip is ``bus.device(address)``.
    """
    key = str(model).strip().lower().replace("-", "")
    chip: _EmulatedImu
    if key in _MPU_VARIANTS:
        chip = EmulatedMPU9250(clock, motion, truth, faults=faults, seed=seed, variant=key,
                               subsamples=subsamples, output_filter=output_filter)
    elif key == "lsm9ds1":
        chip = EmulatedLSM9DS1(clock, motion, truth, faults=faults, seed=seed,
                               subsamples=subsamples, output_filter=output_filter)
    elif key in EMULATED_CHIP_MODULES:
        module, name = EMULATED_CHIP_MODULES[key]
        cls = getattr(importlib.import_module(module), name)
        chip = cls(clock, motion, truth, faults=faults, seed=seed, subsamples=subsamples,
                   output_filter=output_filter)
    else:
        names = [*_MPU_VARIANTS, "lsm9ds1", *EMULATED_CHIP_MODULES]
        raise ValueError(f"unknown IMU model {model!r}; choose one of {', '.join(names)}")
    if bus is None:
        bus = EmulatedSMBus(clock, bus_hz=bus_hz)
    if address is None:
        address = chip.family.addresses[0]
    bus.attach(address, chip)
    _attach_magnetometer(bus, chip, address, seed)
    return bus, address


def _attach_magnetometer(bus: EmulatedSMBus, chip: _EmulatedImu, address: int,
                         seed: int) -> None:
    """Put the chip's magnetometer die on the host bus where a real board has it: the AK8963
    behind the MPU-9250's bypass switch at 0x0C (the ICM-20948's AK09916 likewise); the
    LSM9DS1's magnetometer at 0x1E beside an accel/gyro at 0x6B (SDO pins tied high, as on the
    common boards), 0x1C beside 0x6A. A die whose address is already taken on a shared bus is
    left off."""
    port: I2CDevice
    aux: dict[int, I2CDevice] | None = getattr(chip, "aux", None)
    if aux is not None:  # the MPU-9250's AK8963, the ICM-20948's AK09916 (both at 0x0C)
        die = aux.get(AK8963_ADDRESS)
        if die is None or AK8963_ADDRESS in bus.addresses:
            return
        bus.attach(AK8963_ADDRESS,
                   AuxPort(die, lambda: chip.bypass_open))  # type: ignore[arg-type, attr-defined]
        return
    if not isinstance(chip, EmulatedLSM9DS1):
        return  # a chip without a magnetometer die
    mag_address = 0x1E if address == 0x6B else 0x1C
    if mag_address in bus.addresses:
        return
    chip.magnetometer = EmulatedLSM9DS1Mag(chip.clock, MagneticField(chip.motion), seed=seed)
    port = chip.magnetometer
    bus.attach(mag_address, port)
