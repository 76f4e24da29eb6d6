"""Argument checks shared by the calib modules (errors name the argument)."""

from __future__ import annotations

import math

import numpy as np

from gyrocal.calib.errors import CalibInputError

__all__ = ["scalar", "vec3"]


def scalar(value: object, name: str, *, nonneg: bool = False, positive: bool = False) -> float:
    """``value`` as a finite float.

    Raises
    ------
    CalibInputError
        Naming ``name``, if ``value`` is not a number, not finite, or breaks ``nonneg`` /
        ``positive``.
    """
    want = "a positive number" if positive else "a non-negative number" if nonneg else "a number"
    try:
        v = float(value)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        raise CalibInputError(f"{name} must be {want}, got {value!r}") from None
    if not math.isfinite(v) or (nonneg and v < 0) or (positive and v <= 0):
        raise CalibInputError(f"{name} must be {want}, got {value!r}")
    return v


def vec3(value: object, name: str, *, nonneg: bool = False, positive: bool = False) -> np.ndarray:
    """``value`` as a finite float array of shape (3,) (a scalar is broadcast).

    Raises
    ------
    CalibInputError
        Naming ``name``, if ``value`` is not numeric, not 1 or 3 numbers, not finite, or breaks
        ``nonneg`` / ``positive``.
    """
    try:
        a = np.broadcast_to(np.asarray(value, dtype=float), (3,)).copy()
    except (TypeError, ValueError):
        raise CalibInputError(f"{name} must be a number or 3 numbers, got {value!r}") from None
    if not np.all(np.isfinite(a)):
        raise CalibInputError(f"{name} must be finite, got {a.tolist()}")
    if nonneg and np.any(a < 0):
        raise CalibInputError(f"{name} must not be negative, got {a.tolist()}")
    if positive and np.any(a <= 0):
        raise CalibInputError(f"{name} must be positive, got {a.tolist()}")
    return a
