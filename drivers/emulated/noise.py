"""Coloured gyro noise for the emulated chips: bias instability and rate random walk.

The white noise of a chip (angle random walk) is drawn by the chip itself from its density
(:class:`~gyrocal.drivers.emulated.imu_chips.SensorTruth`); this module adds the two slower terms
of the IEEE Std 952 noise model that an Allan deviation plot shows:

* **bias instability** ``B`` (rad/s): a flat Allan floor ``σ_A = B·sqrt(2 ln 2 / π) ≈ 0.664 B``.
  Flicker noise has no finite-state generator, so it is stood in for by a sum of independent
  first-order Gauss–Markov processes with correlation times spaced a decade apart
  (:data:`FLICKER_TIME_CONSTANTS_S`), of equal variance, scaled so that the Allan deviation of the
  sum has its geometric mean over ``τ`` in ``[T_min, T_max]`` equal to ``0.664 B``. The
  Allan deviation of a Gauss–Markov process of variance ``q²`` and correlation time ``T`` is

      σ_A²(τ) = (2 q² T / τ) · [1 − (T / 2τ)(3 − 4 e^(−τ/T) + e^(−2τ/T))]

  and independent processes add their Allan variances, so :func:`allan_deviation` is exact for
  the generator; its ripple about the floor is −15 %/+4 % over ``[T_min, T_max]`` and
  −7 %/+4 % over 1–1000 s.
* **rate random walk** ``K`` (rad/s/√s): a bias that random-walks, ``σ_A(τ) = K·sqrt(τ/3)``.

Each process is generated exactly in discrete time (``x_k+1 = φ x_k + sqrt(1 − φ²) q w_k`` with
``φ = e^(−Δt/T)``), so the statistics do not depend on the sample rate, and the state carries
across calls.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.signal import lfilter

__all__ = ["FLICKER_TIME_CONSTANTS_S", "ColouredNoise", "allan_deviation",
           "flicker_component_sigma"]

#: Correlation times of the Gauss–Markov processes that stand in for flicker noise, s: a decade
#: apart, so the Allan floor is flat from about 1 s to 1000 s (a calibration run's time scales).
FLICKER_TIME_CONSTANTS_S = (0.5, 5.0, 50.0, 500.0)
#: ``σ_A / B`` of flicker noise (IEEE Std 952-1997, Annex C): sqrt(2 ln 2 / π).
FLICKER_FLOOR = math.sqrt(2.0 * math.log(2.0) / math.pi)


def _gm_avar(tau: np.ndarray, q2: float, T: float) -> np.ndarray:
    x = tau / T
    return (2.0 * q2 * T / tau) * (1.0 - (3.0 - 4.0 * np.exp(-x) + np.exp(-2.0 * x)) / (2.0 * x))


def _unit_flicker_avar(tau: np.ndarray) -> np.ndarray:
    """Allan variance of the flicker stand-in with unit variance per component."""
    return sum(_gm_avar(tau, 1.0, T) for T in FLICKER_TIME_CONSTANTS_S)


def flicker_component_sigma(bias_instability: float) -> float:
    """Standard deviation of each Gauss–Markov component for bias instability ``B``: the scale
    that puts the geometric mean of the Allan deviation over ``[T_min, T_max]`` at ``0.664 B``."""
    T = FLICKER_TIME_CONSTANTS_S
    tau = np.geomspace(T[0], T[-1], 61)
    gmean = float(np.exp(np.mean(0.5 * np.log(_unit_flicker_avar(tau)))))
    return FLICKER_FLOOR * float(bias_instability) / gmean


def allan_deviation(tau: np.ndarray, white_density: float, bias_instability: float,
                    rate_random_walk: float) -> np.ndarray:
    """The exact Allan deviation of the generator at averaging times ``tau`` (s): white noise of
    density ``N`` (rad/s/√Hz; ``σ_A² = N²/τ``), the flicker stand-in and the rate random walk
    (``σ_A² = K² τ / 3``)."""
    tau = np.asarray(tau, dtype=float)
    q = flicker_component_sigma(bias_instability)
    return np.sqrt(white_density**2 / tau + q**2 * _unit_flicker_avar(tau)
                   + rate_random_walk**2 * tau / 3.0)


class ColouredNoise:
    """Bias instability and rate random walk on three axes, generated sample by sample.

    Parameters
    ----------
    bias_instability : float
        ``B`` in rad/s (0 = none).
    rate_random_walk : float
        ``K`` in rad/s/√s (0 = none).
    rng : numpy.random.Generator
        Seeded by the caller.
    """

    def __init__(self, bias_instability: float, rate_random_walk: float,
                 rng: np.random.Generator) -> None:
        if not (bias_instability >= 0 and rate_random_walk >= 0):
            raise ValueError("bias_instability and rate_random_walk must be >= 0, got "
                             f"{bias_instability!r}, {rate_random_walk!r}")
        self.q = flicker_component_sigma(bias_instability)
        self.k = float(rate_random_walk)
        self._rng = rng
        n = len(FLICKER_TIME_CONSTANTS_S)
        # stationary start: each component drawn from its steady-state distribution
        self._gm = rng.standard_normal((n, 3)) * self.q
        self._walk = np.zeros(3)

    @property
    def active(self) -> bool:
        """Whether there is anything to add."""
        return self.q > 0 or self.k > 0

    def draw(self, dt: np.ndarray) -> np.ndarray:
        """The noise (N, 3) at the ends of the ``N`` steps ``dt`` (s, each > 0), continuing from
        the previous call."""
        dt = np.asarray(dt, dtype=float).reshape(-1)
        n = dt.size
        out = np.zeros((n, 3))
        if n == 0 or not self.active:
            return out
        n_gm = _TAU.size if self.q > 0 else 0
        # one draw for every process, in the order they use it: each Gauss–Markov component's
        # (n, 3) steps, then the random walk's
        z = self._rng.standard_normal((n_gm + (self.k > 0), n, 3))
        if n_gm:
            phi = np.exp(-dt[None, :] / _TAU[:, None])  # (component, step)
            w = z[:n_gm] * (self.q * np.sqrt(1.0 - phi**2))[:, :, None]
            # a fixed step (to numpy.allclose's tolerance) filters with the first step's φ
            fixed = np.all(np.abs(phi - phi[:, :1]) <= 1e-8 + 1e-5 * np.abs(phi[:, :1]), axis=1)
            coef = np.where(fixed[:, None], phi[:, :1], phi)
            y = _first_order(coef, w, self._gm)
            self._gm = y[:, -1].copy()
            for j in range(n_gm):
                out += y[j]
        if self.k > 0:
            steps = z[-1] * (self.k * np.sqrt(dt))[:, None]
            walk = self._walk + np.cumsum(steps, axis=0)
            self._walk = walk[-1].copy()
            out += walk
        return out


#: :data:`FLICKER_TIME_CONSTANTS_S` as an array.
_TAU = np.asarray(FLICKER_TIME_CONSTANTS_S)
#: Up to this many steps :func:`_first_order` runs its loop in numpy over the components; longer
#: runs go through one C filter per component.
_LOOP_STEPS = 24


def _first_order(coef: np.ndarray, w: np.ndarray, x0: np.ndarray) -> np.ndarray:
    """``x_k = coef_k x_k−1 + w_k`` from ``x0`` for each component: ``coef`` (J, n), ``w``
    (J, n, 3), ``x0`` (J, 3); returns every ``x_k``, (J, n, 3). A component whose ``coef`` is
    constant goes through ``scipy.signal.lfilter`` on long runs, which computes the same products
    and sums in the same order."""
    J, n = coef.shape
    y = np.empty_like(w)
    if n <= _LOOP_STEPS:
        x = x0
        for i in range(n):
            x = coef[:, i, None] * x + w[:, i]
            y[:, i] = x
        return y
    for j in range(J):
        c = coef[j]
        if np.all(c == c[0]):
            y[j], _ = lfilter([1.0], [1.0, -c[0]], w[j], axis=0, zi=(c[0] * x0[j])[None, :])
        else:
            x = x0[j]
            for i in range(n):
                x = c[i] * x + w[j, i]
                y[j, i] = x
    return y
