"""Argument checks shared by the calib modules (errors name the argument)."""

from __future__ import annotations

import numpy as np

from calib.errors import CalibInputError

__all__ = ["vec3"]


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
