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
* **bias instability.** Flicker noise has no finite variance about a long-run mean; its size is
  stated as ``B``, the "bias stability" of a datasheet, read as the one-sigma change of the bias
  over the time scales of the Allan floor (IEEE Std 952 Annex C: the floor is
  ``σ_A = B·sqrt(2 ln 2 / π) ≈ 0.664 B``; O. J. Woodman, *An introduction to inertial
  navigation*, UCAM-CL-TR-696, 2007, §3.2.3: bias stability "usually specified as a 1σ value").
  A run of a few hundred seconds is on that floor, so its average carries variance ``B²``.

The added variance of each bias component is therefore ``B² + K² T / 12``
(:attr:`BiasDrift.run_variance`). In the ``horizon`` after the calibration the bias itself moves
by ``sqrt(B² + K² · horizon)`` (one sigma; :attr:`BiasDrift.wander`): what a user should expect
between the calibrated bias and the sensor's an hour later, beside the calibration's own σ.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from gyrocal.calib.errors import CalibInputError, CalibrationFormatError

__all__ = ["HORIZON_S", "BiasDrift"]

#: The horizon the calibration states the bias's expected wander over, s (an hour).
HORIZON_S = 3600.0


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
    def run_variance(self) -> np.ndarray:
        """Variance the wander adds to each bias component's estimate, (rad/s)²:
        ``B² + K² T / 12`` (module docstring)."""
        B, K = np.asarray(self.bias_instability), np.asarray(self.rate_random_walk)
        return B**2 + K**2 * self.span_s / 12.0

    @property
    def wander(self) -> np.ndarray:
        """Expected (one-sigma) wander of each bias component in the ``horizon_s`` after the
        calibration, rad/s: ``sqrt(B² + K² · horizon)``."""
        B, K = np.asarray(self.bias_instability), np.asarray(self.rate_random_walk)
        return np.sqrt(B**2 + K**2 * self.horizon_s)

    def note(self) -> str:
        """What the calibration added to the bias's σ, and why, in one sentence."""
        add = np.sqrt(self.run_variance)
        return (f"bias sigma includes the bias's wander within the {self.span_s:.0f} s run, "
                f"sqrt(B^2 + K^2 T/12) = {1e6 * float(add.max()):.0f} urad/s (B "
                f"{1e6 * max(self.bias_instability):.3g} urad/s, K "
                f"{max(self.rate_random_walk):.3g} rad/s/sqrt(s): {self.source}); in the "
                f"{self.horizon_s / 3600:g} h after it the bias may wander by "
                f"{1e6 * float(self.wander.max()):.0f} urad/s (1 sigma)")

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
