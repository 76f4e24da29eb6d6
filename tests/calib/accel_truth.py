"""An independent generator of accelerometer rest windows, written from the contract only.

Contract (hardware_docs/formats.md, ``accelerometer``): a still sensor's true specific force has
the local gravity magnitude; the reading ``a`` of a force ``f`` is ``a = C f − b`` with ``C`` the
sensing matrix (rows: each axis' sensing direction divided by nothing, i.e. scale and direction
in one row) and ``b`` the bias; the calibration ``f = A (a + b)`` holds with ``A`` lower triangular
(x along the sensor's x sensing axis, y in its x-y plane), i.e. ``A⁻¹ = L`` with
``C Cᵀ = L Lᵀ`` (Cholesky). Shares no code with gyrocal.
"""

from __future__ import annotations

import numpy as np


def random_sensing(rng: np.random.Generator, scale_err: float = 0.02,
                   cross: float = 0.01) -> np.ndarray:
    """A sensing matrix: scales 1 ± scale_err, axes tilted by about ``cross`` rad, and a random
    rotation of the whole (the mount), which the calibration cannot see."""
    c = np.diag(1 + scale_err * rng.uniform(-1, 1, 3)) + cross * rng.uniform(-1, 1, (3, 3)) * (
        1 - np.eye(3))
    q, _ = np.linalg.qr(rng.standard_normal((3, 3)))
    return c @ q


def truth_matrix(sensing: np.ndarray) -> np.ndarray:
    """``A`` of the contract's frame for ``sensing``: the inverse of C Cᵀ's Cholesky factor."""
    return np.linalg.inv(np.linalg.cholesky(sensing @ sensing.T))


def fibonacci_directions(n: int) -> np.ndarray:
    """``n`` unit vectors spread over the sphere (golden-angle spiral)."""
    k = np.arange(n) + 0.5
    z = 1 - 2 * k / n
    r = np.sqrt(1 - z * z)
    phi = k * np.pi * (3 - np.sqrt(5))
    return np.column_stack([r * np.cos(phi), r * np.sin(phi), z])


def rest_means(rng: np.random.Generator, sensing: np.ndarray, bias: np.ndarray,
               directions: np.ndarray, gravity: float, sample_std: float,
               samples: int) -> tuple[np.ndarray, np.ndarray]:
    """Each rest's mean reading and its per-axis standard deviation (white noise of
    ``sample_std`` per sample, ``samples`` samples per rest: the mean of the samples)."""
    f = gravity * directions / np.linalg.norm(directions, axis=1, keepdims=True)
    clean = f @ sensing.T - bias
    noise = rng.standard_normal((directions.shape[0], samples, 3)).mean(axis=1) * sample_std
    std = np.full(clean.shape, sample_std / np.sqrt(samples))
    return clean + noise, std
