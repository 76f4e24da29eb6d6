"""The emulated accelerometer's true errors (issue 15): scale, cross-axis, zero-g bias and white
noise, per the chips' datasheets (the chip data's ``accel_errors``), drawn by seed.

The emulated accelerometer reads, in g,

``a = C f − b + n``,

with ``f`` the true specific force in the sensor frame (in g; the jig's
:meth:`~gyrocal.drivers.emulated.jig.GimbalJig.specific_force`), ``C`` the sensing matrix (its
diagonal the scale factors, its off-diagonal terms the cross-axis sensitivities), ``b`` the
zero-g bias and ``n`` white noise of per-sample standard deviation ``density · sqrt(odr)``
(independent samples, no low-pass; a chip with an emulated accelerometer filter draws it at the
filter's rate ahead of the filter instead, ``_EmulatedImu._accel_counts``: ``density`` is the
continuous-time white-noise density
``σ_c`` of Kalibr's IMU noise model, ``σ_d = σ_c · sqrt(odr)``; a datasheet's one-sided density
``D``, with ``σ = D · sqrt(B)`` over a noise bandwidth ``B``, would give ``σ_c = D / sqrt(2)``
at ``B = odr/2``, so the emulator is ``sqrt(2)`` noisier than the datasheet's figure: on the
safe side).
A calibration ``f = A (a + b)`` then holds with ``A = C⁻¹``; in the calibration's frame
convention (x along the x sensing axis, y in the x-y plane: ``A`` lower triangular) the same
calibration is ``A = L⁻¹`` with ``C Cᵀ = L Lᵀ`` (Cholesky), which :meth:`AccelTruth.manifest`
writes as ``truth.accelerometer.matrix``.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from gyrocal.drivers.imu.chips import ICM20948, ICM42688P, LSM6DSOX, LSM9DS1, MPU9250

__all__ = ["ACCEL_DATASHEET", "STANDARD_GRAVITY", "AccelTruth", "draw_accel_truth"]

#: g_n, m/s²: the datasheets' "g" (the readers scale counts by it to m/s²).
STANDARD_GRAVITY = 9.80665

#: Accelerometer error sizes per chip model (each term drawn uniformly within ±the figure), from
#: each chip family's datasheet figures in the chip data
#: (:attr:`gyrocal.drivers.imu.chips.ChipFamily.accel_errors`, cited there with ⚠ for what is
#: single-sourced or stood in for).
ACCEL_DATASHEET: dict[str, dict[str, Any]] = {
    fam.name: asdict(fam.accel_errors) for fam in (MPU9250, LSM9DS1, ICM20948, ICM42688P, LSM6DSOX)
}


@dataclass(frozen=True)
class AccelTruth:
    """The true errors of an emulated accelerometer: ``a = C f − b + n`` (module docstring).

    Parameters
    ----------
    sensing : (3, 3)
        ``C``: scale factors on the diagonal, cross-axis sensitivities off it.
    bias_g : (3,)
        Zero-g bias ``b`` in g.
    noise_density_g_sqrt_hz : float
        White-noise density in g/√Hz (per-sample σ = density · sqrt(odr)).
    """

    sensing: Any = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))
    bias_g: Any = (0.0, 0.0, 0.0)
    noise_density_g_sqrt_hz: float = 0.0

    def __post_init__(self) -> None:
        c = np.asarray(self.sensing, dtype=float)
        if c.shape != (3, 3) or not np.all(np.isfinite(c)) or abs(np.linalg.det(c)) < 1e-6:
            raise ValueError("sensing must be a finite invertible 3×3 matrix, got "
                             f"{self.sensing!r}")
        b = np.broadcast_to(np.asarray(self.bias_g, dtype=float), (3,))
        if not np.all(np.isfinite(b)):
            raise ValueError(f"bias_g must be finite, got {self.bias_g!r}")
        d = float(self.noise_density_g_sqrt_hz)
        if not (math.isfinite(d) and d >= 0):
            raise ValueError(f"noise_density_g_sqrt_hz must be finite and >= 0, got {d!r}")
        object.__setattr__(self, "sensing", tuple(tuple(float(x) for x in r) for r in c))
        object.__setattr__(self, "bias_g", tuple(float(x) for x in b))
        object.__setattr__(self, "noise_density_g_sqrt_hz", d)

    def reading(self, force_g: np.ndarray, rng: np.random.Generator | None = None,
                odr_hz: float | None = None) -> np.ndarray:
        """The reading (N, 3) in g for true specific forces ``force_g`` (N, 3) in g; white noise
        is added when ``rng`` and ``odr_hz`` are given and the density is non-zero."""
        f = np.asarray(force_g, dtype=float)
        a = f @ np.asarray(self.sensing).T - np.asarray(self.bias_g)
        if rng is not None and odr_hz is not None and self.noise_density_g_sqrt_hz > 0:
            a = a + rng.standard_normal(a.shape) * (self.noise_density_g_sqrt_hz
                                                    * math.sqrt(odr_hz))
        return a

    def manifest(self) -> dict[str, Any]:
        """``truth.accelerometer`` of a simulated manifest: the sensing matrix and bias as drawn,
        and the calibration they imply in m/s² and the calibration's frame (``matrix`` lower
        triangular, ``f = matrix @ (a + bias_m_s2)``)."""
        c = np.asarray(self.sensing)
        matrix = np.linalg.inv(np.linalg.cholesky(c @ c.T))
        return {"sensing": [list(r) for r in self.sensing], "bias_g": list(self.bias_g),
                "matrix": matrix.tolist(),
                "bias_m_s2": [b * STANDARD_GRAVITY for b in self.bias_g],
                "noise_density_m_s2_sqrt_hz": self.noise_density_g_sqrt_hz * STANDARD_GRAVITY,
                "frame": "accel-x-xy"}


def draw_accel_truth(model: str, seed: int) -> AccelTruth:
    """An accelerometer's errors drawn by ``seed`` within ``model``'s :data:`ACCEL_DATASHEET`
    figures (uniform within ± each figure).

    Raises
    ------
    ValueError
        If ``model`` has no row in :data:`ACCEL_DATASHEET`.
    """
    if model not in ACCEL_DATASHEET:
        raise ValueError(f"no accelerometer figures for chip model {model!r}; known: "
                         + ", ".join(ACCEL_DATASHEET))
    fig = ACCEL_DATASHEET[model]
    rng = np.random.default_rng([int(seed), 0xACCE])
    c = np.diag(1.0 + fig["scale_tolerance"] * rng.uniform(-1, 1, 3))
    c += fig["cross_axis"] * rng.uniform(-1, 1, (3, 3)) * (1.0 - np.eye(3))
    bias = np.asarray(fig["zero_g_g"]) * rng.uniform(-1, 1, 3)
    return AccelTruth(c, bias, fig["noise_g_sqrt_hz"])
