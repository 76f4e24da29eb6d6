"""The bias's wander within a calibration run and in the hour after it, from its noise figures.

A calibration's bias is an average of the gyro over rests and windows spread over the run, so a
bias that wanders during the run (bias instability, rate random walk: the two slow terms of the
IEEE Std 952-1997 noise model, Annex C) moves the estimate by more than the white noise the
fit's covariance accounts for. With ``B`` the bias instability (rad/s) and ``K`` the rate
random walk (rad/s/√s) of each axis, and ``T`` the run's span (s):

* **rate random walk.** ``b(t) = b(t_c) + K W(t − t_c)``, ``W`` a standard Wiener process; the
  uniform average of ``b`` over ``[t_c − T/2, t_c + T/2]`` differs from ``b(t_c)`` (the bias at
  the run's centre) by ``K/T ∫ W(s) ds`` over ``[−T/2, T/2]``, of variance

      K²/T² · 2 · (T/2)³ / 3 = K² T / 12

  (the two halves are integrals of independent Wiener processes from 0, each of variance
  ``Var ∫₀^a W(s) ds = a³/3`` with ``a = T/2``).
* **bias instability.** Flicker noise, one-sided spectral density ``h₋₁ / f`` with
  ``h₋₁ = B² / π``: its Allan variance is ``2 ln 2 · h₋₁`` at every ``τ`` (D. W. Allan, J. A.
  Barnes et al., NBS TN 394, 1970; IEEE Std 1139 Table 1), the floor ``σ_A = B·sqrt(2 ln 2 / π)
  ≈ 0.664 B`` of IEEE Std 952 Annex C. Flicker has no finite variance about a long-run mean
  (its power grows as ``ln`` of the longest time looked at), so what the run's average misses is
  stated against a reference interval: the bias's average over the ``horizon`` the calibration
  stands for, from the run's start (``[0, H]``, ``H = max(horizon, T)``). Flicker is the
  continuum of first-order Gauss–Markov processes whose correlation times ``c`` are spread
  uniformly in ``ln c`` with variance ``h₋₁`` per unit of ``ln c`` (a Gauss–Markov process of
  variance ``s²`` has the one-sided density ``4 s² c / (1 + (2π f c)²)``, and
  ``∫ 4 h₋₁ c / (1 + (2π f c)²) d ln c = h₋₁ / f``). For one such process the average over
  ``[0, L]`` has ``∬ e^(−|t−u|/c) dt du = D(L) = 2 c² (L/c − 1 + e^(−L/c))`` (times ``s²``),
  and the averages over ``[0, T]`` and ``[0, H]`` share ``(D(T) + D(H) − D(H − T)) / 2``, so

      Var(avg_T − avg_H) = s² [D(T)/T² + D(H)/H² − (D(T) + D(H) − D(H − T)) / (T H)]

  and the flicker's share is ``B² Φ(T, H)`` with ``Φ = (1/π) ∫ [ … ]/s² d ln c``
  (:func:`flicker_run_factor`, integrated on a grid of ``ln c``; it converges at both ends:
  fast processes average out over ``T``, slow ones are common to the run and the horizon).
  For a 42 s run and an hour ``Φ = 1.71``: the square of ``B`` alone (what the calibration
  assumed before) fell short by that factor.

The added variance of each bias component is therefore ``B² Φ(T, H) + K² T / 12``
(:attr:`BiasDrift.run_variance`).

**The hour after.** What a user meets later is the bias then against the calibration's
estimate, the run's average over ``[0, T]``. Averaged as the run averaged it (over ``T``, so
no instant's unbounded flicker variance enters), the bias a ``horizon`` ``H`` later, over
``[H, H + T]``, differs from it by (one sigma, :attr:`BiasDrift.wander`)

    Var(avg_[H, H+T] − avg_[0, T]) = B² Ψ(T, H) + K² (H − T/3)

* **rate random walk**: each average departs from the walk at its own interval's start by
  ``K² T / 3`` (the Wiener average above), the two starts by ``K² (H − T)``, all independent;
* **flicker**: for one Gauss–Markov process the two averages share
  ``(D(H + T) + D(H − T) − 2 D(H)) / 2`` (over ``T²``; ``D`` as above), so
  ``Var = s² [2 D(T) − D(H + T) − D(H − T) + 2 D(H)] / T²``, and ``Ψ(T, H)`` is its integral
  over ``ln c`` divided by ``π`` (:func:`flicker_later_factor`; ``Ψ = 3.79`` for a 42 s run and
  an hour). ``H`` is at least ``T`` (the later average starts after the run ends).

This replaces ``sqrt(B² + K² H)``, which took ``B²`` for the flicker's variance (it is not the
variance of anything for flicker) and the walk's value at the hour's end against its value at
the calibration's instant (the run averages it).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from gyrocal.calib.errors import CalibInputError, CalibrationFormatError

__all__ = ["HORIZON_S", "BiasDrift", "flicker_later_factor", "flicker_run_factor"]

#: The horizon the calibration states the bias's expected wander over, s (an hour).
HORIZON_S = 3600.0


#: The shortest span the flicker's share is computed for, s: a run's average is over many
#: samples, and a span of 0 (no window) would ask for the flicker's value at one instant,
#: whose variance is unbounded.
_MIN_SPAN_S = 1.0
#: The shortest window :meth:`BiasDrift.window_variance` computes the flicker's share for, s
#: (ten samples at 200 Hz, the fewest a window takes, gyrocal.calib.windows).
_MIN_WINDOW_S = 0.05
#: The grid of ``ln c`` :func:`flicker_run_factor` integrates on: from this far below the run's
#: span to this far above the horizon, in this many points (the integrand falls as ``c/T`` and
#: ``H/c`` outside; the tails beyond are < 1e-5 of ``Φ``).
_LN_C_MARGIN = 12.0
_LN_C_POINTS = 1201
#: Points of the ``ln c`` grid :meth:`BiasDrift.window_covariance` integrates on (a matrix
#: per point; the integrand is smooth in ``ln c``: a step of 0.8 is within 1e-6 of a step
#: of 0.04 on 120 windows over a minute).
_WINDOW_LN_C_POINTS = 41


def _interval_integrals(G: Any, a: np.ndarray, e: np.ndarray) -> np.ndarray:
    """``∬ k(t − u) dt du`` over every pair of intervals ``[a_i, e_i] × [a_j, e_j]`` from
    ``G`` (``G'' = k``, ``G(0) = G'(0) = 0``; :meth:`BiasDrift.window_covariance`)."""
    return (G(e[:, None] - a[None, :]) + G(a[:, None] - e[None, :])
            - G(e[:, None] - e[None, :]) - G(a[:, None] - a[None, :]))


def _about_run(integrals: np.ndarray, length: np.ndarray) -> np.ndarray:
    """The covariance of the first ``N`` intervals' averages about the last one's (the run),
    from the pairs' double integrals (:func:`_interval_integrals`) and the lengths."""
    avg = integrals / np.outer(length, length)
    return avg[:-1, :-1] - avg[:-1, -1:] - avg[-1:, :-1] + avg[-1, -1]


def _avg_integral(L: np.ndarray | float, c: np.ndarray) -> np.ndarray:
    """``D(L) / c² = 2 (x − 1 + e^(−x))`` with ``x = L / c``, without cancellation for small
    ``x`` (module docstring)."""
    x = np.asarray(L, dtype=float) / c
    small = x < 1e-3
    xs = np.where(small, x, 0.0)
    series = xs**2 - xs**3 / 3.0 + xs**4 / 12.0
    return np.where(small, series, 2.0 * (x + np.expm1(-np.where(small, 1.0, x))))


def flicker_run_factor(span_s: float, horizon_s: float = HORIZON_S, *,
                       min_span_s: float = _MIN_SPAN_S) -> float:
    """``Φ(T, H)``: the variance, in units of ``B²``, of a flicker bias's average over a run of
    ``span_s`` about its average over the horizon from the run's start (module docstring).

    Parameters
    ----------
    span_s : float
        ``T``, the run's span, s (taken as at least ``min_span_s``).
    horizon_s : float
        The horizon the calibration stands for, s; ``H = max(horizon_s, T)``.
    min_span_s : float
        The shortest ``T`` computed (a run's 1 s by default; one window's mean is over a
        fraction of a second, :meth:`BiasDrift.window_variance`).

    Returns
    -------
    float
        ``Φ`` (0 when the run spans the whole horizon).
    """
    T = max(float(span_s), min_span_s)
    H = max(float(horizon_s), T)
    if H <= T:
        return 0.0
    ln_c = np.linspace(np.log(T) - _LN_C_MARGIN, np.log(H) + _LN_C_MARGIN, _LN_C_POINTS)
    c = np.exp(ln_c)
    dT, dH, dHT = _avg_integral(T, c), _avg_integral(H, c), _avg_integral(H - T, c)
    per_unit = c**2 * (dT / T**2 + dH / H**2 - (dT + dH - dHT) / (T * H))
    step = ln_c[1] - ln_c[0]  # the trapezoid rule on the even grid
    return float(step * (per_unit.sum() - 0.5 * (per_unit[0] + per_unit[-1])) / math.pi)


def flicker_later_factor(span_s: float, horizon_s: float = HORIZON_S) -> float:
    """``Ψ(T, H)``: the variance, in units of ``B²``, of a flicker bias's average over
    ``[H, H + T]`` about its average over the run ``[0, T]`` (module docstring, "The hour
    after").

    Parameters
    ----------
    span_s : float
        ``T``, the run's span, s (taken as at least 1 s, as :func:`flicker_run_factor`).
    horizon_s : float
        ``H``, how long after the run's start the later average starts, s (at least ``T``).

    Returns
    -------
    float
        ``Ψ``.
    """
    T = max(float(span_s), _MIN_SPAN_S)
    H = max(float(horizon_s), T)
    ln_c = np.linspace(np.log(T) - _LN_C_MARGIN, np.log(H + T) + _LN_C_MARGIN, _LN_C_POINTS)
    c = np.exp(ln_c)
    d = [_avg_integral(L, c) for L in (T, H + T, H - T, H)]
    per_unit = c**2 * (2 * d[0] - d[1] - d[2] + 2 * d[3]) / T**2
    step = ln_c[1] - ln_c[0]  # the trapezoid rule on the even grid
    return float(step * (per_unit.sum() - 0.5 * (per_unit[0] + per_unit[-1])) / math.pi)


def _triple(v: Any, name: str, err: type[Exception]) -> tuple[float, float, float]:
    try:
        a = np.broadcast_to(np.asarray(v, dtype=float), (3,))
    except (TypeError, ValueError):
        raise err(f"{name} must be a number or 3 numbers, got {v!r}") from None
    if not np.all(np.isfinite(a)) or np.any(a < 0):
        raise err(f"{name} must be finite and >= 0, got {v!r}")
    return (float(a[0]), float(a[1]), float(a[2]))


@dataclass(frozen=True)
class BiasDrift:
    """The bias's noise figures a calibration assumed, and what they add to it.

    Parameters
    ----------
    bias_instability : float or 3 floats
        ``B`` per axis, rad/s (IEEE Std 952 flicker coefficient; Allan floor ``0.664 B``).
    rate_random_walk : float or 3 floats
        ``K`` per axis, rad/s/√s (``σ_A(τ) = K sqrt(τ/3)``).
    span_s : float
        The span of the run the bias was averaged over, s (first window's start to the last
        one's end).
    source : str
        Where ``B`` and ``K`` come from (a datasheet, an Allan deviation, an assumption ⚠).
    horizon_s : float
        The time after the calibration :attr:`wander` is stated for, s.
    """

    bias_instability: tuple[float, float, float]
    rate_random_walk: tuple[float, float, float]
    span_s: float
    source: str = ""
    horizon_s: float = HORIZON_S

    def __post_init__(self) -> None:
        self._check(CalibInputError)

    def _check(self, err: type[Exception]) -> None:
        for name in ("bias_instability", "rate_random_walk"):
            object.__setattr__(self, name, _triple(getattr(self, name), name, err))
        for name in ("span_s", "horizon_s"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not (
                    math.isfinite(v) and v >= 0):
                raise err(f"{name} must be a finite number >= 0 (seconds), got {v!r}")
            object.__setattr__(self, name, float(v))
        if not isinstance(self.source, str):
            raise err(f"source must be a string, got {self.source!r}")

    @property
    def flicker_factor(self) -> float:
        """``Φ(T, H)`` of this run's span and horizon (:func:`flicker_run_factor`)."""
        return flicker_run_factor(self.span_s, self.horizon_s)

    @property
    def later_factor(self) -> float:
        """``Ψ(T, H)`` of this run's span and horizon (:func:`flicker_later_factor`)."""
        return flicker_later_factor(self.span_s, self.horizon_s)

    @property
    def run_variance(self) -> np.ndarray:
        """Variance the wander adds to each bias component's estimate, (rad/s)²:
        ``B² Φ(T, H) + K² T / 12`` (module docstring)."""
        B, K = np.asarray(self.bias_instability), np.asarray(self.rate_random_walk)
        return B**2 * self.flicker_factor + K**2 * self.span_s / 12.0

    def window_variance(self, length_s: Any) -> np.ndarray:
        """Variance the wander adds to each window mean about the run's mean, (N, 3) (rad/s)²:
        what a fit's residuals see of it, beside the window's white noise.

        A fit takes one bias for the run, so a window whose mean is over ``L`` seconds departs
        from it by the bias's average over ``L`` about its average over the run's span ``T``:
        ``B² Φ(L, T)`` for the flicker (:func:`flicker_run_factor` with the run's span as the
        horizon; a window at the run's start, the largest share, so a bound) plus ``K² T / 3``
        for the rate random walk (the variance of a Wiener process's average over ``[0, T]``
        about its start, a window at either end). With a quiet gyro (the ICM-42688-P's
        0.0028 °/s/√Hz) a 0.6 s rest's white noise is ~6e-5 rad/s, and ``B = 4.8e-5 rad/s``
        (``Φ(0.6 s, 42 s) = 1.67``) adds as much again.

        Parameters
        ----------
        length_s : array_like, shape (N,)
            Each window's length, s (its first to its last sample).

        Returns
        -------
        numpy.ndarray, shape (N, 3)
        """
        B, K = np.asarray(self.bias_instability), np.asarray(self.rate_random_walk)
        lengths = np.atleast_1d(np.asarray(length_s, dtype=float))
        phi = np.array([flicker_run_factor(L, self.span_s, min_span_s=_MIN_WINDOW_S)
                        for L in lengths])
        return phi[:, None] * B**2 + K**2 * self.span_s / 3.0

    def window_covariance(self, start_s: Any, end_s: Any) -> np.ndarray:
        """Covariance the wander adds to the window means about the run's mean, (3, N, N)
        (rad/s)²: per axis, between every pair of windows, from the wander's autocovariance
        between the windows' times (the truth :meth:`window_variance` bounds one window of).

        The bias is one process in time, so windows seconds apart (a turn's two directions, a
        rest beside a turn) see nearly the same wander and a fit's contrasts between them
        cancel most of it; widening each window's σ by its variance instead treats it as
        independent between windows and overstates what reaches the matrix. With ``ω̄_i`` the
        wander's average over window ``i`` ``[a_i, e_i]`` and ``ω̄_R`` its average over the run
        ``R = [min a, max e]`` (the common part, which a fit's constant bias takes whole and
        :attr:`run_variance` states), this is ``Cov(ω̄_i − ω̄_R, ω̄_j − ω̄_R)``. For a
        stationary kernel ``k`` with ``G'' = k``, ``G(0) = G'(0) = 0``, the double integral of
        ``k(t − u)`` over two intervals is

            I(i, j) = G(e_i − a_j) + G(a_i − e_j) − G(e_i − e_j) − G(a_i − a_j)

        and the covariance is ``I(i,j)/(L_i L_j) − I(i,R)/(L_i T) − I(R,j)/(T L_j) + I(R,R)/T²``.

        * **rate random walk**: ``Cov(W(s), W(t)) = min(s, t) = (s + t − |s − t|)/2`` from any
          start; the ``s + t`` part cancels in the differences about ``R``, leaving the
          stationary ``k(x) = −K² |x|/2``, ``G(x) = −K² |x|³/12``.
        * **bias instability**: the continuum of Gauss–Markov processes of the module
          docstring, ``k_c(x) = e^(−|x|/c)`` with variance ``B²/π`` per unit ``ln c``,
          ``G_c(x) = c² (|x|/c − 1 + e^(−|x|/c))``, integrated over ``ln c`` (the trapezoid
          rule; fast processes average out within a window, slow ones are common to the run).

        Parameters
        ----------
        start_s, end_s : array_like, shape (N,)
            Each window's first and last sample's time, s (any common origin).

        Returns
        -------
        numpy.ndarray, shape (3, N, N)
        """
        a = np.atleast_1d(np.asarray(start_s, dtype=float))
        e = np.atleast_1d(np.asarray(end_s, dtype=float))
        e = np.maximum(e, a + _MIN_WINDOW_S)  # a window's mean is over its samples
        a, e = np.append(a, a.min()), np.append(e, e.max())  # the run R last
        length = e - a
        B, K = np.asarray(self.bias_instability), np.asarray(self.rate_random_walk)
        walk = _about_run(_interval_integrals(lambda x: -np.abs(x) ** 3 / 12.0, a, e), length)
        flicker = np.zeros_like(walk)
        if np.any(B > 0):
            ln_c = np.linspace(np.log(length.min()) - _LN_C_MARGIN,
                               np.log(length[-1]) + _LN_C_MARGIN, _WINDOW_LN_C_POINTS)
            weights = np.full(ln_c.size, ln_c[1] - ln_c[0])
            weights[[0, -1]] *= 0.5
            for c, w in zip(np.exp(ln_c), weights, strict=True):
                G = lambda x, c=c: 0.5 * c**2 * _avg_integral(np.abs(x), c)  # noqa: E731
                flicker += w * _about_run(_interval_integrals(G, a, e), length)
            flicker /= math.pi
        return B[:, None, None] ** 2 * flicker + K[:, None, None] ** 2 * walk

    def window_covariance_change(self, start_s: Any, end_s: Any) -> np.ndarray:
        """What the wander's covariance between the windows' means (:meth:`window_covariance`)
        differs by from the per-window variance their σ carry (:meth:`window_variance`),
        ``(3N, 3N)`` (rad/s)², window-major (``3 i + axis``): ``Σ_wander − D``, the change
        :func:`gyrocal.calib.estimators.add_window_wander` carries through a fit.

        Parameters
        ----------
        start_s, end_s : array_like, shape (N,)
            Each window's first and last sample's time, s.

        Returns
        -------
        numpy.ndarray, shape (3N, 3N)
        """
        start = np.atleast_1d(np.asarray(start_s, dtype=float))
        end = np.atleast_1d(np.asarray(end_s, dtype=float))
        N = start.size
        change = np.zeros((N, 3, N, 3))
        for p, dense in enumerate(self.window_covariance(start, end)):
            change[:, p, :, p] = dense
        widened = self.window_variance(end - start)  # (N, 3)
        change[np.arange(N), :, np.arange(N), :] -= widened[:, :, None] * np.eye(3)
        return change.reshape(3 * N, 3 * N)

    @property
    def wander(self) -> np.ndarray:
        """Expected (one-sigma) departure of each bias component ``horizon_s`` after the
        calibration from the calibration's estimate, both averaged over the run's span, rad/s:
        ``sqrt(B² Ψ(T, H) + K² (H − T/3))`` (module docstring, "The hour after")."""
        B, K = np.asarray(self.bias_instability), np.asarray(self.rate_random_walk)
        T = max(self.span_s, _MIN_SPAN_S)
        H = max(self.horizon_s, T)
        return np.sqrt(B**2 * self.later_factor + K**2 * (H - T / 3.0))

    def note(self) -> str:
        """What the calibration added to the bias's σ, and why, in one sentence."""
        add = np.sqrt(self.run_variance)
        return (f"bias sigma includes the bias's wander within the {self.span_s:.0f} s run, "
                f"sqrt(B^2 Phi + K^2 T/12) = {1e6 * float(add.max()):.0f} urad/s (B "
                f"{1e6 * max(self.bias_instability):.3g} urad/s, Phi "
                f"{self.flicker_factor:.2f} for the run against its {self.horizon_s / 3600:g} h, K "
                f"{max(self.rate_random_walk):.3g} rad/s/sqrt(s): {self.source}); "
                f"{self.horizon_s / 3600:g} h later the bias, averaged as the run averages "
                f"it, may be {1e6 * float(self.wander.max()):.0f} urad/s from this estimate "
                f"(1 sigma, sqrt(B^2 Psi + K^2 (H - T/3)), Psi {self.later_factor:.2f})")

    def to_dict(self) -> dict[str, Any]:
        """The calibration document's ``bias_drift`` object (hardware_docs/formats.md)."""
        return {"bias_instability": list(self.bias_instability),
                "rate_random_walk": list(self.rate_random_walk), "span_s": self.span_s,
                "run_std": [float(x) for x in np.sqrt(self.run_variance)],
                "horizon_s": self.horizon_s, "wander": [float(x) for x in self.wander],
                "source": self.source}

    @classmethod
    def from_dict(cls, doc: Mapping[str, Any]) -> BiasDrift:
        """Read a ``bias_drift`` object (``run_std`` and ``wander`` are recomputed).

        Raises
        ------
        CalibrationFormatError
            If it is not an object, a field is missing, unknown or malformed.
        """
        known = ("bias_instability", "rate_random_walk", "span_s", "run_std", "horizon_s",
                 "wander", "source")
        if not isinstance(doc, Mapping):
            raise CalibrationFormatError("'bias_drift' must be an object")
        unknown = sorted(set(doc) - set(known))
        if unknown:
            raise CalibrationFormatError(f"'bias_drift.{unknown[0]}' is not a known field "
                                         f"(known: {', '.join(known)})")
        missing = [k for k in ("bias_instability", "rate_random_walk", "span_s") if k not in doc]
        if missing:
            raise CalibrationFormatError(f"'bias_drift' lacks {missing[0]!r}")
        self = cls.__new__(cls)
        for k in ("bias_instability", "rate_random_walk", "span_s"):
            object.__setattr__(self, k, doc[k])
        object.__setattr__(self, "source", doc.get("source", ""))
        object.__setattr__(self, "horizon_s", doc.get("horizon_s", HORIZON_S))
        try:
            self._check(CalibrationFormatError)
        except CalibrationFormatError as exc:
            raise CalibrationFormatError(f"'bias_drift': {exc}") from None
        return self
