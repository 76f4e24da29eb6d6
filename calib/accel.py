r"""Accelerometer calibration against gravity from the rests of a gyro run (issue 15).

Model (imu_tk's, Tedaldi et al. 2014, the multi-position form of the paper's reference
[ye2017efficient]): the calibrated specific force is

.. math:: f = T K (a + b),

with ``a`` the reading (m/s², datasheet sensitivity applied and nothing else), ``b`` the bias
(3), ``K = diag(s)`` the scales and ``T`` a unit triangular non-orthogonality matrix. imu_tk
makes ``T`` upper triangular (its z axis fixed); gyrocal uses the gyro's frame convention
(:data:`gyrocal.calib.estimators.FULL_FRAME`: x along the sensor's x sensing axis, y in the plane
of its x and y axes), in which ``T`` and hence ``A = T K`` are lower triangular:

.. math:: T = \begin{pmatrix} 1 & 0 & 0 \\ \alpha_{yx} & 1 & 0 \\
          \alpha_{zx} & \alpha_{zy} & 1 \end{pmatrix}.

The six entries of ``A`` and ``b`` are the nine parameters fitted here (``s = diag(A)``,
``α_yx = A10/s_x``, ``α_zx = A20/s_x``, ``α_zy = A21/s_y``). Any other calibration matrix ``M``
(``f = M (a + b)`` in another frame) is brought to this convention by
:func:`gyrocal.calib.estimators.matrix_in_frame` of ``M⁻¹``: the rotation between the frames is
one that no gravity-only fit can see.

When the sensor is still, ``|f| = g``, the local gravity magnitude; every rest window gives one
equation

.. math:: r_i = \lVert A (\bar a_i + b) \rVert - g,

and the fit minimises ``Σ (r_i/σ_i)²`` (Levenberg–Marquardt, ``scipy.optimize.least_squares``),
``σ_i² = u_iᵀ A Σ_i Aᵀ u_i`` the variance of ``r_i`` from the window mean's covariance ``Σ_i``
(``u_i`` the unit calibrated force). The parameters' covariance is ``(JᵀJ)⁻¹`` of the whitened
Jacobian at the optimum, and ``χ² = Σ (r_i/σ_i)²`` with ``N − 9`` degrees of freedom is the
consistency test. Nine parameters need at least nine rests whose gravity directions spread over
the sphere (:func:`accel_design` scores a set of directions).

The baseline is the classic six-position method (:func:`six_position`): readings with gravity
along ``±x, ±y, ±z`` of a reference frame, assumed exact, solved for the full ``a = M f + o``.

White noise (:func:`white_noise_density`): the rests also give the accelerometer's white-noise
density in the continuous-time form Kalibr's IMU noise model takes (``σ_c``, m/s²/√Hz, with the
per-sample ``σ_d = σ_c / sqrt(Δt)``). It is read from the non-overlapping Allan variance at
``τ`` inside each rest window (IEEE Std 952-1997 Annex C: ``σ²(τ) = N²/τ`` for white noise, so
``σ_c = N = σ(τ) sqrt(τ)``), not from the sample scatter at the ODR: with the chip's low-pass
at bandwidth ``B`` the samples are correlated and their scatter is ``D sqrt(B_noise)``, which
depends on the filter; at ``τ`` well past the filter's time constant ``1/(2πB)`` the block
means are independent and the figure no longer depends on ``B`` (nor on the ODR). Without a
low-pass it equals ``σ_d sqrt(Δt)``.

Local gravity (:func:`normal_gravity`): WGS-84 normal gravity on the ellipsoid by Somigliana's
closed formula, NIMA TR8350.2 (3rd ed.) Eq. (4-1), with the second-order free-air correction for
height above the ellipsoid, Eq. (4-3). Without a location, :data:`STANDARD_GRAVITY` (9.80665 m/s²,
the CGPM's g_n, the "g" of the accelerometer datasheets) is the documented default; it differs
from the local value by up to 0.3 %, which the fit then puts into the scales.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from gyrocal.calib.design import sphere_points
from gyrocal.calib.errors import CalibInputError, CalibrationFormatError
from gyrocal.calib.estimators import matrix_in_frame
from gyrocal.calib.model import Consistency, _refuse_unknown
from gyrocal.calib.observations import diff_noise, pool_noise
from gyrocal.calib.validation import scalar

__all__ = [
    "ACCEL_FRAME",
    "PARAMETER_NAMES",
    "STANDARD_GRAVITY",
    "TOUR_DIRECTIONS",
    "AccelCalibration",
    "AccelDesign",
    "FrameRotation",
    "accel_design",
    "determined_terms",
    "align_gyro",
    "frame_rotation",
    "GravityTour",
    "fit_accelerometer",
    "gravity_tour",
    "normal_gravity",
    "six_position",
    "still_means",
    "white_noise_density",
    "tour_gravity",
    "in_frame",
]

#: Standard gravity g_n, m/s² (3rd CGPM, 1901): the default local gravity magnitude.
STANDARD_GRAVITY = 9.80665

# WGS-84 (NIMA TR8350.2, Table 3.1 and 3.3): semi-major axis a (m), flattening f, normal gravity
# at the equator γ_e (m/s²), Somigliana's constant k, first eccentricity squared e², and
# m = ω² a² b / GM.
_WGS84_A = 6378137.0
_WGS84_F = 1.0 / 298.257223563
_WGS84_GAMMA_E = 9.7803253359
_WGS84_K = 0.00193185265241
_WGS84_E2 = 0.00669437999013
_WGS84_M = 0.00344978650684

#: Parameters in fit order: the lower triangle of A row by row, then the bias.
PARAMETER_NAMES = ("A00", "A10", "A11", "A20", "A21", "A22", "bx", "by", "bz")
_IU = np.tril_indices(3)

#: Identifier of the accelerometer's frame convention (the gyro's, for the accelerometer's axes).
ACCEL_FRAME = "accel-x-xy"

#: Significance level of the χ² consistency test.
CONSISTENCY_LEVEL = 0.01


def normal_gravity(latitude_deg: float, height_m: float = 0.0) -> float:
    """WGS-84 normal gravity (m/s²) at geodetic latitude and ellipsoidal height.

    Somigliana's formula, NIMA TR8350.2 Eq. (4-1),
    ``γ = γ_e (1 + k sin²φ) / sqrt(1 − e² sin²φ)``, and the free-air correction Eq. (4-3),
    ``γ_h = γ [1 − 2/a (1 + f + m − 2 f sin²φ) h + 3 h²/a²]``.

    Parameters
    ----------
    latitude_deg : float
        Geodetic latitude in degrees, within [-90, 90].
    height_m : float
        Height above the ellipsoid in metres (a few km at most: the series is second order).

    Returns
    -------
    float
        The normal gravity magnitude in m/s².
    """
    lat = scalar(latitude_deg, "latitude_deg")
    h = scalar(height_m, "height_m")
    if not -90.0 <= lat <= 90.0:
        raise CalibInputError(f"latitude_deg must be within [-90, 90], got {latitude_deg!r}")
    if not -1000.0 <= h <= 20000.0:
        raise CalibInputError(f"height_m must be within [-1000, 20000] m, got {height_m!r}")
    s2 = math.sin(math.radians(lat)) ** 2
    g0 = _WGS84_GAMMA_E * (1 + _WGS84_K * s2) / math.sqrt(1 - _WGS84_E2 * s2)
    a = _WGS84_A
    return g0 * (1 - 2 / a * (1 + _WGS84_F + _WGS84_M - 2 * _WGS84_F * s2) * h + 3 * h * h / a**2)


def in_frame(matrix: np.ndarray) -> np.ndarray:
    """The matrix of ``f = M (a + b)`` in :data:`ACCEL_FRAME` (lower triangular, positive
    diagonal): :func:`~gyrocal.calib.estimators.matrix_in_frame` of ``M⁻¹``."""
    m = np.asarray(matrix, dtype=float)
    if m.shape != (3, 3) or not np.all(np.isfinite(m)) or abs(np.linalg.det(m)) < 1e-12:
        raise CalibInputError(f"matrix must be a finite invertible 3x3 array, got {m.tolist()}")
    return matrix_in_frame(np.linalg.inv(m))


@dataclass(frozen=True)
class AccelCalibration:
    """An accelerometer calibration ``f = A (a + b)``, ``A = T K`` lower triangular.

    Attributes
    ----------
    matrix : (3, 3) ndarray
        ``A`` (dimensionless).
    bias : (3,) ndarray
        ``b`` in m/s².
    covariance : (9, 9) ndarray
        Of :data:`PARAMETER_NAMES` (lower triangle of ``A`` row by row, then ``b``).
    gravity : float
        The local gravity magnitude the fit used, m/s².
    consistency : Consistency
        χ² of the whitened residuals against the windows' noise.
    rests : int
        Rest windows used.
    iterations : int
        Function evaluations of the solver.
    converged : bool
        Whether the solver met its tolerance.
    noise_density : (3,) ndarray or None
        White-noise density per axis of the reading, m/s²/√Hz, continuous time (Kalibr's
        ``accelerometer_noise_density``; :func:`white_noise_density`); None when not measured.
        Written as ``noise_density`` (and ``noise_density_std``, ``noise_tau_s``) since the
        accelerometer block's second revision; a document without them still reads.
    noise_density_std : (3,) ndarray or None
        Its standard deviation.
    noise_tau_s : float or None
        The averaging time the density was read at, s.
    fixed : tuple of str
        :data:`PARAMETER_NAMES` the rests could not determine (the design check,
        :func:`determined_terms`): held at zero, with the datasheet's bound as their σ and
        its effect on the fitted terms in theirs (:func:`_held_covariance`).
        Written as ``fixed`` only when not empty; a document without it reads as none fixed.
    """

    matrix: np.ndarray
    bias: np.ndarray
    covariance: np.ndarray
    gravity: float
    consistency: Consistency
    rests: int
    iterations: int
    converged: bool
    noise_density: np.ndarray | None = None
    noise_density_std: np.ndarray | None = None
    noise_tau_s: float | None = None
    fixed: tuple[str, ...] = ()

    @property
    def advice(self) -> str:
        """What rests would determine the :attr:`fixed` terms (empty when none is fixed)."""
        if not self.fixed:
            return ""
        pairs = [_CROSS_AXES[PARAMETER_NAMES.index(n)] for n in self.fixed]
        between = ", ".join(f"+{_AXES[i]} and +{_AXES[j]}" for i, j in pairs)
        return (f"{', '.join(self.fixed)} held at zero (not determined by the rests, or a "
                f"diagonal fit asked for); rests with gravity between {between} (45° from "
                "each), and their opposites, determine them")

    @property
    def std(self) -> np.ndarray:
        """Standard deviations (9,) of :data:`PARAMETER_NAMES`."""
        return np.sqrt(np.clip(np.diag(self.covariance), 0.0, None))

    @property
    def scale(self) -> np.ndarray:
        """``s = diag(K) = diag(A)``."""
        return np.diag(self.matrix).copy()

    @property
    def nonorthogonality(self) -> np.ndarray:
        """``(α_yx, α_zx, α_zy)`` of ``T`` (rad, small angles)."""
        a, s = self.matrix, np.diag(self.matrix)
        return np.array([a[1, 0] / s[0], a[2, 0] / s[0], a[2, 1] / s[1]])

    def apply(self, reading: np.ndarray) -> np.ndarray:
        """Calibrated specific force (N, 3) for readings (N, 3), both m/s²."""
        return (np.asarray(reading, dtype=float) + self.bias) @ self.matrix.T

    def to_dict(self) -> dict[str, Any]:
        """The Calibration document's ``accelerometer`` object."""
        std = self.std
        return {"model": _DOC_MODEL, "frame": ACCEL_FRAME,
                "matrix": self.matrix.tolist(), "bias": self.bias.tolist(),
                "matrix_std": _lower(std[:6]).tolist(), "bias_std": std[6:].tolist(),
                "covariance": self.covariance.tolist(), "gravity_m_s2": self.gravity,
                "consistency": self.consistency.to_dict(), "rests": self.rests,
                "iterations": self.iterations, "converged": self.converged,
                **({} if self.noise_density is None else {
                    "noise_density": np.asarray(self.noise_density).tolist(),
                    "noise_density_std": np.asarray(self.noise_density_std).tolist(),
                    "noise_tau_s": self.noise_tau_s}),
                **({"fixed": list(self.fixed)} if self.fixed else {})}

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> AccelCalibration:
        """Inverse of :meth:`to_dict`; :class:`CalibrationFormatError` on a bad field."""
        if not isinstance(d, Mapping):
            raise CalibrationFormatError("'accelerometer' must be an object")
        _refuse_unknown(d, _DOC_FIELDS, "'accelerometer'")
        if d.get("frame") != ACCEL_FRAME or d.get("model") != _DOC_MODEL:
            raise CalibrationFormatError(f"'accelerometer' must have model {_DOC_MODEL!r} and "
                                         f"frame {ACCEL_FRAME!r}")
        try:
            m = np.asarray(d["matrix"], dtype=float)
            b = np.asarray(d["bias"], dtype=float)
            c = np.asarray(d["covariance"], dtype=float)
            g = float(d["gravity_m_s2"])
            rests, its = d["rests"], d["iterations"]
            conv = d["converged"]
        except KeyError as e:
            raise CalibrationFormatError(f"'accelerometer' lacks the field {e.args[0]!r}") from None
        except (TypeError, ValueError):
            raise CalibrationFormatError("'accelerometer' has a non-numeric matrix, bias, "
                                         "covariance or gravity_m_s2") from None
        if (m.shape != (3, 3) or b.shape != (3,) or c.shape != (9, 9)
                or not all(np.all(np.isfinite(x)) for x in (m, b, c)) or not g > 0):
            raise CalibrationFormatError("'accelerometer' needs a finite 3x3 matrix, 3 biases, "
                                         "a 9x9 covariance and a positive gravity_m_s2")
        if np.any(np.triu(m, 1) != 0) or np.any(np.diag(m) <= 0):
            raise CalibrationFormatError("'accelerometer.matrix' must be lower triangular with "
                                         "a positive diagonal (its frame convention)")
        for name, v in (("rests", rests), ("iterations", its)):
            if isinstance(v, bool) or not isinstance(v, int) or v < 0:
                raise CalibrationFormatError(f"'accelerometer.{name}' must be a non-negative "
                                             "integer")
        if not isinstance(conv, bool):
            raise CalibrationFormatError("'accelerometer.converged' must be true or false")
        fixed = d.get("fixed", [])
        if (not isinstance(fixed, list) or any(f not in PARAMETER_NAMES for f in fixed)
                or any(PARAMETER_NAMES.index(f) not in _CROSS for f in fixed)):
            raise CalibrationFormatError("'accelerometer.fixed' must list cross-axis terms of "
                                         f"{PARAMETER_NAMES}")
        return cls(m, b, c, g, Consistency.from_dict(d["consistency"]), rests, its, conv,
                   *_read_noise(d), fixed=tuple(fixed))


def _read_noise(d: Mapping[str, Any]) -> tuple[Any, Any, Any]:
    """The optional ``noise_density``, ``noise_density_std`` (3 each, m/s²/√Hz, >= 0) and
    ``noise_tau_s`` (> 0) of an ``accelerometer`` object: all three or none."""
    names = ("noise_density", "noise_density_std", "noise_tau_s")
    present = [n in d for n in names]
    if not any(present):
        return None, None, None
    if not all(present):
        raise CalibrationFormatError("'accelerometer' must give noise_density, "
                                     "noise_density_std and noise_tau_s together")
    try:
        n = np.asarray(d["noise_density"], dtype=float)
        s = np.asarray(d["noise_density_std"], dtype=float)
        tau = float(d["noise_tau_s"])
    except (TypeError, ValueError):
        raise CalibrationFormatError("'accelerometer.noise_density', 'noise_density_std' and "
                                     "'noise_tau_s' must be numbers") from None
    if (n.shape != (3,) or s.shape != (3,) or not np.all(np.isfinite(n)) or np.any(n < 0)
            or not np.all(np.isfinite(s)) or np.any(s < 0) or not (math.isfinite(tau)
                                                                   and tau > 0)):
        raise CalibrationFormatError("'accelerometer.noise_density' and 'noise_density_std' "
                                     "need 3 finite values >= 0 each and 'noise_tau_s' a "
                                     "positive number")
    return n, s, tau


_DOC_MODEL = "f = matrix @ (a + bias)"
_DOC_FIELDS = ("model", "frame", "matrix", "bias", "matrix_std", "bias_std", "covariance",
               "gravity_m_s2", "consistency", "rests", "iterations", "converged",
               "noise_density", "noise_density_std", "noise_tau_s", "fixed")


def _lower(v: np.ndarray) -> np.ndarray:
    m = np.zeros((3, 3))
    m[_IU] = v
    return m


def _unpack(p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    return _lower(p[:6]), p[6:]


def _residuals(p: np.ndarray, means: np.ndarray, g: float, sigma: np.ndarray) -> np.ndarray:
    a, b = _unpack(p)
    return (np.linalg.norm((means + b) @ a.T, axis=1) - g) / sigma


def _jacobian(p: np.ndarray, means: np.ndarray, g: float, sigma: np.ndarray) -> np.ndarray:
    """d r_i / d p: with ``f = A (a + b)``, ``u = f/|f|``: d|f|/dA_jk = u_j (a + b)_k,
    d|f|/db = Aᵀ u."""
    a, b = _unpack(p)
    x = means + b
    f = x @ a.T
    u = f / np.linalg.norm(f, axis=1, keepdims=True)
    outer = u[:, :, None] * x[:, None, :]  # (N, 3, 3): d|f|/dA
    jac = np.concatenate([outer[:, _IU[0], _IU[1]], u @ a], axis=1)
    return jac / sigma[:, None]


def _sigma(p: np.ndarray, means: np.ndarray, cov: np.ndarray) -> np.ndarray:
    a, b = _unpack(p)
    f = (means + b) @ a.T
    u = f / np.linalg.norm(f, axis=1, keepdims=True)
    w = u @ a  # (N, 3): Aᵀ u
    return np.sqrt(np.einsum("ni,nij,nj->n", w, cov, w))


def _window_covariance(mean_std: Any, n: int) -> np.ndarray:
    s = np.asarray(mean_std, dtype=float)
    if s.shape == (n, 3):
        if not np.all(np.isfinite(s)) or np.any(s <= 0):
            raise CalibInputError("mean_std must be finite and positive")
        return np.einsum("ni,ij->nij", s**2, np.eye(3))
    if s.shape == (n, 3, 3):
        if not np.all(np.isfinite(s)) or np.any(np.linalg.eigvalsh(s) <= 0):
            raise CalibInputError("mean_std as covariances (N, 3, 3) must be positive definite")
        return s
    raise CalibInputError(f"mean_std must have shape ({n}, 3) (standard deviations of the window "
                          f"means) or ({n}, 3, 3) (their covariances), got {s.shape}")


#: The scatter of a real rest's mean beyond its white noise, relative to gravity, that the
#: design check assumes (real rests scatter by 1.2e-4 g on imu_tk's Xsens session and 3.5e-4 g
#: on imucal's Ferraris session beyond their white noise: :mod:`gyrocal.calib.dispersion`):
#: poses that determine a term only at the white noise of long rests let that scatter,
#: multiplied by the poor geometry, into the fit (scales of 0.55 on imucal's rests).
REAL_SCATTER = 3e-4
#: A cross-axis term is fitted only when the rests determine it to this σ at
#: :data:`REAL_SCATTER`: a quarter of the ±2 % cross-axis sensitivity of a consumer
#: accelerometer (MPU-9250, PS-MPU-9250A-01 Rev 1.0 Table 2), so that the fit can tell it from
#: zero; otherwise it stays zero with that bound as its σ (:data:`CROSS_AXIS_PRIOR`).
CROSS_AXIS_LIMIT = 0.005
#: σ of a cross-axis term the rests cannot determine: each term of the lower-triangular frame
#: (:data:`ACCEL_FRAME`) holds the sum of two of the sensor's cross-axis sensitivities
#: (``c_ij + c_ji``; their difference is a rotation of the frame), each ±2 % as a uniform bound
#: (datasheet above): ``0.02 √(2/3)``.
CROSS_AXIS_PRIOR = 0.02 * math.sqrt(2.0 / 3.0)
#: A scale (relative) or bias (relative to gravity) the rests determine worse than this at
#: :data:`REAL_SCATTER` is refused, naming the poses to add.
SCALE_BIAS_LIMIT = 0.01
_CROSS = (1, 3, 4)  # A10, A20, A21 in PARAMETER_NAMES
_AXES = "xyz"
#: For each cross term, the axes between which gravity must point to determine it.
_CROSS_AXES = {1: (0, 1), 3: (0, 2), 4: (1, 2)}


def _inputs(means: Any, mean_std: Any, gravity: float) -> tuple[np.ndarray, np.ndarray, float]:
    """The checked rest means (N, 3), their covariances (N, 3, 3) and gravity."""
    a = np.asarray(means, dtype=float)
    if a.ndim != 2 or a.shape[1] != 3 or not np.all(np.isfinite(a)):
        raise CalibInputError(f"means must be a finite (N, 3) array, got shape {a.shape}")
    n = a.shape[0]
    if n < 10:
        raise CalibInputError(f"means needs at least 10 rest windows (9 parameters and a "
                              f"consistency test), got {n}; add rests in more orientations")
    cov = _window_covariance(mean_std, n)
    g = scalar(gravity, "gravity", positive=True)
    norms = np.linalg.norm(a, axis=1)
    if np.any(norms < 0.5 * g) or np.any(norms > 1.5 * g):
        raise CalibInputError("means must be readings of a still sensor in m/s² (norms near "
                              f"gravity {g:.3f}); got norms {norms.min():.3g}..{norms.max():.3g}")
    return a, cov, g


def _design_std(p: np.ndarray, a: np.ndarray, g: float, sigma: np.ndarray,
                free: np.ndarray) -> np.ndarray:
    """Predicted σ (9,) of the free parameters (inf where not determined; 0 where fixed)."""
    jac = _jacobian(p, a, g, sigma)[:, free]
    jtj = jac.T @ jac
    out = np.zeros(9)
    if np.linalg.cond(jtj) > 1e14:
        out[free] = np.inf
        return out
    out[free] = np.sqrt(np.clip(np.diag(np.linalg.inv(jtj)), 0.0, None))
    return out


def determined_terms(means: np.ndarray, cov: np.ndarray, gravity: float
                     ) -> tuple[np.ndarray, np.ndarray]:
    """Which of :data:`PARAMETER_NAMES` the rests determine (the design check).

    At the nominal sensor (unit matrix scaled to the rests' mean norm, zero bias) each rest's
    scatter is taken as its white noise or :data:`REAL_SCATTER` of gravity, whichever is
    larger; the cross-axis term with the largest predicted σ is fixed at zero while that σ
    exceeds :data:`CROSS_AXIS_LIMIT`, and the σ are predicted again.

    Returns
    -------
    free : (9,) ndarray of bool
        The parameters to fit.
    std : (9,) ndarray
        Their predicted σ at that scatter (0 for the fixed ones).

    Raises
    ------
    CalibInputError
        When a scale or bias is still not determined to :data:`SCALE_BIAS_LIMIT`, naming the
        rests to add.
    """
    p0 = np.concatenate([_entries(np.eye(3) * gravity / np.linalg.norm(means, axis=1).mean()),
                         np.zeros(3)])
    sigma = np.maximum(_sigma(p0, means, cov), REAL_SCATTER * gravity)
    free = np.ones(9, dtype=bool)
    std = _design_std(p0, means, gravity, sigma, free)
    while True:
        worst = max((i for i in _CROSS if free[i]), key=lambda i: std[i], default=None)
        if worst is None or std[worst] <= CROSS_AXIS_LIMIT:
            break
        free[worst] = False
        std = _design_std(p0, means, gravity, sigma, free)
    limits = np.r_[SCALE_BIAS_LIMIT, 0, SCALE_BIAS_LIMIT, 0, 0, SCALE_BIAS_LIMIT,
                   np.full(3, SCALE_BIAS_LIMIT * gravity)]
    bad = [i for i in (0, 2, 5, 6, 7, 8) if not std[i] <= limits[i]]
    if bad:
        axes = sorted({_AXES[i // 2] if i < 6 else _AXES[i - 6] for i in bad})
        raise CalibInputError(
            "the rests' gravity directions cannot determine the accelerometer's "
            f"{', '.join(PARAMETER_NAMES[i] for i in bad)}; add rests with gravity along "
            + " and ".join(f"+{x} and -{x}" for x in axes))
    return free, std


def fit_accelerometer(
    means: Any, mean_std: Any, gravity: float = STANDARD_GRAVITY, *,
    max_nfev: int = 200, cross_axis: bool = True,
) -> AccelCalibration:
    """Fit ``f = A (a + b)`` to rest windows' mean readings against gravity's magnitude.

    Steps: the design check (:func:`determined_terms`: cross-axis terms the rests cannot
    determine stay zero, with the datasheet's bound as σ, its effect in the fitted terms' σ,
    and are listed in ``fixed``); the
    fit weighted by each rest's white noise; the verdict with the excess between-rest scatter
    (:func:`gyrocal.calib.dispersion.additive`); when that excess is positive, the fit again
    weighted by the white noise plus the excess, whose covariance is reported.

    Parameters
    ----------
    means : (N, 3) array_like
        Each rest window's mean accelerometer reading, m/s² (the mean of the readings: averaged
        first, as the design's rule 1 asks). N ≥ 10 (nine parameters and one degree of freedom
        for the consistency test), with gravity directions spread over the sphere.
    mean_std : (N, 3) or (N, 3, 3) array_like
        Standard deviation of each window mean per axis (white noise: the sample standard
        deviation over sqrt(count)), or each mean's covariance.
    gravity : float
        Local gravity magnitude, m/s²: :data:`STANDARD_GRAVITY` by default, or
        :func:`normal_gravity` of the site.
    max_nfev : int
        Solver's evaluation limit; reaching it gives ``converged`` false, not an error.
    cross_axis : bool
        False fits scales and bias only (a diagonal model, six parameters); the cross-axis
        terms are then ``fixed``.

    Returns
    -------
    AccelCalibration
    """
    from gyrocal.calib.dispersion import additive

    a, cov, g = _inputs(means, mean_std, gravity)
    free, _ = determined_terms(a, cov, g)
    if not cross_axis:
        free[list(_CROSS)] = False
    p = np.concatenate([_entries(np.eye(3) * g / np.linalg.norm(a, axis=1).mean()),
                        np.zeros(3)])
    p, res = _solve(p, a, g, lambda q: _sigma(q, a, cov), free, max_nfev)
    sigma = _sigma(p, a, cov)
    e = np.linalg.norm((a + p[6:]) @ _lower(p[:6]).T, axis=1) - g
    verdict = additive(e, sigma, a.shape[0] - int(free.sum()), g, alpha=CONSISTENCY_LEVEL,
                       names=[f"rest {i}" for i in range(a.shape[0])],
                       jacobian=_jacobian(p, a, g, np.ones(a.shape[0]))[:, free])
    if verdict.tau2 > 0:
        p, res = _solve(p, a, g, lambda q: np.sqrt(_sigma(q, a, cov) ** 2 + verdict.tau2),
                        free, max_nfev)
        sigma = np.sqrt(_sigma(p, a, cov) ** 2 + verdict.tau2)
    covariance = _covariance(p, a, g, sigma, free) + _held_covariance(p, a, g, sigma, free,
                                                                      max_nfev)
    matrix, bias = _unpack(p)
    if np.any(np.diag(matrix) <= 0):  # the sign-flipped twin of the same fit
        flip = np.sign(np.diag(matrix))
        matrix = matrix * flip[:, None]
        j = np.concatenate([flip[_IU[0]], np.ones(3)])
        covariance = covariance * np.outer(j, j)
    return AccelCalibration(matrix, bias, covariance, g, verdict.consistency, a.shape[0],
                            int(res.nfev), bool(res.status > 0),
                            fixed=tuple(PARAMETER_NAMES[i] for i in np.flatnonzero(~free)))


def _solve(p: np.ndarray, a: np.ndarray, g: float, weights: Any, free: np.ndarray,
           max_nfev: int) -> tuple[np.ndarray, Any]:
    """Levenberg–Marquardt on the free parameters, weighted at the start and again at the
    first solution; the fixed ones keep their values in ``p``."""
    from scipy import optimize  # imported where a fit needs it (seconds on a Pi)

    p = p.copy()

    def resid(x: np.ndarray, sigma: np.ndarray) -> np.ndarray:
        p[free] = x
        return _residuals(p, a, g, sigma)

    def jac(x: np.ndarray, sigma: np.ndarray) -> np.ndarray:
        p[free] = x
        return _jacobian(p, a, g, sigma)[:, free]

    res = None
    for _ in range(2):
        sigma = weights(p)
        res = optimize.least_squares(resid, p[free], jac=jac, args=(sigma,), method="lm",
                                     xtol=1e-15, ftol=1e-15, gtol=1e-15, max_nfev=max_nfev)
        p[free] = res.x
    return p, res


def _covariance(p: np.ndarray, a: np.ndarray, g: float, sigma: np.ndarray,
                free: np.ndarray) -> np.ndarray:
    """``(JᵀJ)⁻¹`` of the free parameters (zero on the held ones: :func:`_held_covariance`
    adds their prior and what it does to the others)."""
    jac = _jacobian(p, a, g, sigma)[:, free]
    jtj = jac.T @ jac
    if np.linalg.cond(jtj) > 1e14:
        raise CalibInputError("the rests' gravity directions cannot determine the nine "
                              "accelerometer parameters (too few distinct orientations); "
                              "add rests in other poses")
    out = np.zeros((9, 9))
    out[np.ix_(free, free)] = np.linalg.inv(jtj)
    return out


def _held_covariance(p: np.ndarray, a: np.ndarray, g: float, sigma: np.ndarray,
                     free: np.ndarray, max_nfev: int) -> np.ndarray:
    """What the cross-axis terms held at zero do to the fit, as covariance (9, 9).

    A held term is not known to be zero: the datasheet allows ±2 % (σ
    :data:`CROSS_AXIS_PRIOR`), and the fitted terms take up whatever it is. The rests still
    determine ``|A (a + b)|``, so a scale moves with the held terms at first order where a
    rest's reading leans off its axis (the box's faces are not the sensor's axes) and at
    second order (``A_xx² + A_yx² + A_zx²`` is what gravity along ``x`` fixes) everywhere.
    Each held term is set to ``±σ`` in turn and the fit solved again; with ``d±`` the
    changes of all nine parameters (the held term's own ``±σ`` among them), the held terms'
    part of the covariance is ``Σ ½ (d₊d₊ᵀ + d₋d₋ᵀ)``: ``σ²`` on the held term itself, its
    first-order effect on the others, and the second-order shift's square, for terms of
    variance ``σ²`` (the gyro's diagonal model carries the cross-axis bound the same way,
    :func:`gyrocal.calib.design.choose_model`)."""
    out = np.zeros((9, 9))
    for i in np.flatnonzero(~free):
        for sign in (1.0, -1.0):
            q = p.copy()
            q[i] = p[i] + sign * CROSS_AXIS_PRIOR
            q, _ = _solve(q, a, g, lambda _q: sigma, free, max_nfev)
            d = q - p
            out += 0.5 * np.outer(d, d)
    return out


def _window_bounds(t: Any, accel: Any, spans: Any
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``t`` (N,) and ``accel`` (N, 3) as arrays, checked to match, and each ``[start, end]``
    span's sample range ``[lo, hi)`` (both ends included), for :func:`still_means` and
    :func:`white_noise_density`."""
    tt = np.asarray(t, dtype=float).reshape(-1)
    a = np.asarray(accel, dtype=float)
    if a.shape != (tt.size, 3):
        raise CalibInputError(f"accel must have shape ({tt.size}, 3) to match t, got {a.shape}")
    sp = np.asarray(spans, dtype=float).reshape(-1, 2)
    return (tt, a, np.searchsorted(tt, sp[:, 0], side="left"),
            np.searchsorted(tt, sp[:, 1], side="right"))


def still_means(t: Any, accel: Any, spans: Any, *, min_samples: int = 10
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Each still window's mean accelerometer reading and the standard deviation of that mean,
    the observations :func:`fit_accelerometer` takes.

    The readings are averaged first (the design's rule 1). A window's per-sample noise is
    estimated from first differences (:func:`~gyrocal.calib.observations.diff_noise`, blind to
    slow drift) and pooled over the windows when they agree (Bartlett's test,
    :func:`~gyrocal.calib.observations.pool_noise`); the mean's standard deviation is that over
    the square root of the window's sample count (white noise).

    Parameters
    ----------
    t : (N,) array_like
        Sample times, non-decreasing.
    accel : (N, 3) array_like
        Readings, m/s².
    spans : (K, 2) array_like
        ``[start, end]`` of each still window on the same clock (both ends included).
    min_samples : int
        Windows with fewer samples are left out.

    Returns
    -------
    means : (M, 3) ndarray
    mean_std : (M, 3) ndarray
    used : (M,) ndarray of int
        Indices into ``spans`` of the windows kept.
    """
    _, a, lo, hi = _window_bounds(t, accel, spans)
    used = np.flatnonzero(hi - lo >= max(int(min_samples), 3))
    means = np.array([a[lo[i]:hi[i]].mean(axis=0) for i in used]).reshape(-1, 3)
    if not np.all(np.isfinite(means)):
        raise CalibInputError("accel holds non-finite readings inside the still windows")
    count = (hi - lo)[used]
    # a noise-free (simulated) reading still gets a positive weight
    noise = np.maximum(np.array([diff_noise(a[lo[i]:hi[i]]) for i in used]).reshape(-1, 3),
                       1e-12)
    if used.size > 1:
        noise, _ = pool_noise(noise, count)
    return means, noise / np.sqrt(count)[:, None], used


#: Averaging time of :func:`white_noise_density`, s: long past a low-pass's time constant (the
#: density comes out about 0.5 % low behind a 50 Hz second-order low-pass, 4 % behind 20 Hz;
#: the readers leave the accelerometer's low-pass at its reset setting, wider than 50 Hz ⚠ not
#: checked per chip), and still five blocks in a 0.6 s rest (the planner's shortest).
NOISE_TAU_S = 0.1


def white_noise_density(t: Any, accel: Any, spans: Any, *, tau_s: float = NOISE_TAU_S
                        ) -> tuple[np.ndarray, np.ndarray, float, int]:
    r"""The accelerometer's white-noise density per axis from still windows, continuous time
    (Kalibr's ``accelerometer_noise_density``; module docstring).

    Inside each window the readings are averaged over non-overlapping blocks of ``m`` samples,
    ``m = round(τ / Δt)``; the Allan variance at ``τ = m Δt`` is half the mean squared
    difference of consecutive block means, pooled over the windows' ``K`` differences (IEEE Std
    952-1997 Annex C), and for white noise ``σ²(τ) = N²/τ``:

    .. math:: N = \sqrt{\tau \, \frac{1}{2K} \sum_k (\bar a_{k+1} - \bar a_k)^2}.

    First differences make it blind to a constant offset and nearly so to slow drift. The
    standard deviation is ``N sqrt(3/(4K))``: the differences of independent block means are
    Gaussian with lag-one correlation −1/2, so ``Σ d²`` has variance ``12 K σ⁴`` against mean
    ``2 K σ²`` (``σ²`` a block mean's variance), i.e. a relative variance ``3/K`` of ``N²``.

    Parameters
    ----------
    t : (N,) array_like
        Sample times, s, increasing.
    accel : (N, 3) array_like
        Readings, m/s².
    spans : (W, 2) array_like
        ``[start, end]`` of each still window on the same clock.
    tau_s : float
        Averaging time; it should exceed the low-pass's time constant several times.

    Returns
    -------
    density : (3,) ndarray
        m/s²/√Hz.
    std : (3,) ndarray
        Its standard deviation.
    tau : float
        The averaging time used (``m Δt``), s.
    differences : int
        ``K``.

    Raises
    ------
    CalibInputError
        If the windows hold fewer than three differences of block means in all.
    """
    tt, a, lo, hi = _window_bounds(t, accel, spans)
    tau = scalar(tau_s, "tau_s", positive=True)
    steps = np.diff(tt)
    if steps.size < 1 or not np.all(steps > 0):
        raise CalibInputError("t must hold at least two increasing sample times")
    dt = float(np.median(steps))
    m = max(1, int(round(tau / dt)))
    sq, k = np.zeros(3), 0
    for i0, i1 in zip(lo, hi, strict=True):
        blocks = (i1 - i0) // m
        if blocks < 2:
            continue
        means = a[i0:i0 + blocks * m].reshape(blocks, m, 3).mean(axis=1)
        d = np.diff(means, axis=0)
        sq += (d * d).sum(axis=0)
        k += blocks - 1
    if k < 3:
        raise CalibInputError(f"the still windows hold {k} differences of {m * dt:g} s block "
                              "means; the noise density needs at least 3 (longer rests)")
    if not np.all(np.isfinite(sq)):
        raise CalibInputError("accel holds non-finite readings inside the still windows")
    density = np.sqrt(sq / (2 * k) * m * dt)
    return density, density * math.sqrt(3.0 / (4.0 * k)), m * dt, k


def _entries(m: np.ndarray) -> np.ndarray:
    return np.asarray(m, dtype=float)[_IU]


def six_position(readings: Any, gravity: float = STANDARD_GRAVITY) -> tuple[np.ndarray, np.ndarray]:
    """The classic six-position method: readings with gravity along ``+x, −x, +y, −y, +z, −z``
    of the reference frame, taken as exact; solves ``a = M f + o`` for the full ``M`` and ``o``
    (least squares over the 18 equations) and returns ``(A, b) = (M⁻¹, −o)`` in this module's
    model ``f = A (a + b)`` (not brought to its frame convention).

    Parameters
    ----------
    readings : (6, 3) array_like
        Mean readings (m/s²) in the order +x, −x, +y, −y, +z, −z.
    gravity : float
        Local gravity magnitude, m/s².
    """
    u = np.asarray(readings, dtype=float)
    if u.shape != (6, 3) or not np.all(np.isfinite(u)):
        raise CalibInputError(f"readings must be a finite (6, 3) array, got shape {u.shape}")
    g = scalar(gravity, "gravity", positive=True)
    f = g * np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]])
    x = np.hstack([f, np.ones((6, 1))])  # a_i = M f_i + o
    sol, *_ = np.linalg.lstsq(x, u, rcond=None)
    m, o = sol[:3].T, sol[3]
    return np.linalg.inv(m), -o


@dataclass(frozen=True)
class AccelDesign:
    """How well a set of rest orientations determines the accelerometer's nine parameters.

    Attributes
    ----------
    directions : (N, 3) ndarray
        Unit gravity directions in the sensor frame.
    condition : float
        Condition number of the whitened information matrix (columns scaled to unit norm).
    parameter_std : (9,) ndarray
        Predicted σ of :data:`PARAMETER_NAMES` (matrix entries dimensionless, bias m/s²).
    worst_force_std : float
        Largest predicted σ of the calibrated specific force's magnitude over the sphere of
        gravity directions, m/s² (the G-criterion of the paper's Section II-B for this model).
    identifiable : bool
        Whether every parameter is determined (full rank, finite σ).
    """

    directions: np.ndarray
    condition: float
    parameter_std: np.ndarray
    worst_force_std: float
    identifiable: bool


def accel_design(directions: Any, window_std: float, gravity: float = STANDARD_GRAVITY,
                 n_sphere: int = 2000) -> AccelDesign:
    """Score rest orientations for the accelerometer fit at the ideal sensor (``A = I, b = 0``).

    Parameters
    ----------
    directions : (N, 3) array_like
        Gravity directions in the sensor frame during each rest (normalised here).
    window_std : float
        Standard deviation of one rest window's mean reading per axis, m/s².
    gravity : float
        Local gravity magnitude, m/s².
    n_sphere : int
        Directions searched for the worst prediction σ.
    """
    d = np.asarray(directions, dtype=float)
    if d.ndim != 2 or d.shape[1] != 3 or d.shape[0] < 1 or not np.all(np.isfinite(d)):
        raise CalibInputError(f"directions must be a finite (N, 3) array, got shape {d.shape}")
    nrm = np.linalg.norm(d, axis=1, keepdims=True)
    if np.any(nrm == 0):
        raise CalibInputError("directions must be non-zero vectors")
    s = scalar(window_std, "window_std", positive=True)
    g = scalar(gravity, "gravity", positive=True)
    d = d / nrm
    p0 = np.concatenate([_entries(np.eye(3)), np.zeros(3)])
    sig = np.full(d.shape[0], s)
    jac = _jacobian(p0, g * d, g, sig)
    jtj = jac.T @ jac
    colnorm = np.sqrt(np.clip(np.diag(jtj), 1e-300, None))
    sv = np.linalg.svd(jac / colnorm, compute_uv=False)
    rank_ok = sv.size == 9 and sv[-1] > 1e-9 * sv[0]
    if not rank_ok:
        return AccelDesign(d, math.inf, np.full(9, math.inf), math.inf, False)
    cov = np.linalg.inv(jtj)
    q = g * sphere_points(n_sphere)
    jq = _jacobian(p0, q, g, np.ones(q.shape[0]))
    worst = float(np.sqrt(np.max(np.einsum("ni,ij,nj->n", jq, cov, jq))))
    return AccelDesign(d, float(sv[0] / sv[-1]), np.sqrt(np.diag(cov)), worst, True)


#: Gravity directions a rest tour visits: the six axes (the six-position design) and the eight
#: cube corners, a 14-point design that spreads the quadratic model's regressors over the sphere.
TOUR_DIRECTIONS = np.vstack([
    [[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]],
    np.array([[x, y, z] for x in (1, -1) for y in (1, -1) for z in (1, -1)]) / math.sqrt(3),
]).astype(float)


@dataclass(frozen=True)
class GravityTour:
    """Rests added to a protocol so the accelerometer is determined (:func:`gravity_tour`).

    Attributes
    ----------
    poses_rad : (K, 2) ndarray
        Base and middle servo angles from home of each added rest, in visiting order.
    directions : (K, 3) ndarray
        Gravity's direction in the sensor frame at each (nominal gimbal).
    added_time_s : float
        Jig time the tour adds: one-servo moves (profile plus settling), the rests, and the
        moves back home.
    """

    poses_rad: np.ndarray
    directions: np.ndarray
    added_time_s: float


def tour_gravity(base_rad: np.ndarray, middle_rad: np.ndarray) -> np.ndarray:
    """Gravity's direction in the sensor frame (N, 3) for base and middle servo angles on the
    nominal gimbal (base about sensor x, middle about y, home gravity along +z):
    ``(R_x(φ1) R_y(φ2))ᵀ e_z = (−sin φ2 cos φ1, sin φ1, cos φ2 cos φ1)``."""
    p1, p2 = np.asarray(base_rad, dtype=float), np.asarray(middle_rad, dtype=float)
    return np.column_stack([-np.sin(p2) * np.cos(p1), np.sin(p1), np.cos(p2) * np.cos(p1)])


def gravity_tour(speed: float, accel: float, rest_s: float, settle_s: float = 0.1,
                 directions: np.ndarray | None = None) -> GravityTour:
    """The rests to add, after a protocol's turns, so that gravity visits ``directions``
    (default :data:`TOUR_DIRECTIONS` less the home pose's +z), and the jig time they add.

    The nominal gimbal turns the base about sensor x and the middle about sensor y
    (:func:`tour_gravity`); a direction ``u`` is reached with ``φ1 = asin(u_y)``,
    ``φ2 = atan2(−u_x, u_z)``. The order is greedy by move time from home; each move turns one
    servo (``profile_duration`` at ``speed`` and ``accel``, plus ``settle_s``), then rests
    ``rest_s``; the tour ends by moving both servos home.
    """
    from gyrocal.calib.simulate import profile_duration

    sp = scalar(speed, "speed", positive=True)
    ac = scalar(accel, "accel", positive=True)
    rs = scalar(rest_s, "rest_s", positive=True)
    st = scalar(settle_s, "settle_s", nonneg=True)
    if directions is None:
        d = TOUR_DIRECTIONS[~np.all(np.isclose(TOUR_DIRECTIONS, [0.0, 0.0, 1.0]), axis=1)]
    else:
        d = np.asarray(directions, dtype=float)
        if d.ndim != 2 or d.shape[1] != 3 or not np.all(np.isfinite(d)) or np.any(
                np.linalg.norm(d, axis=1) == 0):
            raise CalibInputError("directions must be non-zero finite vectors, shape (K, 3)")
    u = d / np.linalg.norm(d, axis=1, keepdims=True)
    phi1 = np.arcsin(np.clip(u[:, 1], -1, 1))
    c1 = np.cos(phi1)
    phi2 = np.where(c1 > 1e-9, np.arctan2(-u[:, 0], u[:, 2]), 0.0)

    def move(a: float, b: float) -> float:
        return 0.0 if abs(a - b) < 1e-12 else profile_duration(abs(a - b), sp, ac) + st

    here, left, order, total = np.zeros(2), list(range(len(u))), [], 0.0
    while left:
        costs = [move(here[0], phi1[i]) + move(here[1], phi2[i]) for i in left]
        k = left.pop(int(np.argmin(costs)))
        total += min(costs) + rs
        here = np.array([phi1[k], phi2[k]])
        order.append(k)
    total += move(here[0], 0.0) + move(here[1], 0.0)
    poses = np.column_stack([phi1, phi2])[order]
    return GravityTour(poses, tour_gravity(poses[:, 0], poses[:, 1]), float(total))


# ------------------------------------------------------- the gyro in the accelerometer's frame
@dataclass(frozen=True)
class FrameRotation:
    """The rotation from the gyro calibration's frame to the accelerometer calibration's
    (:func:`frame_rotation`).

    Attributes
    ----------
    rotation : (3, 3) ndarray
        ``R``: a vector in the gyro's frame ``gyro-x-xy`` is ``R v`` in :data:`ACCEL_FRAME`.
    covariance : (3, 3) ndarray
        Of the small rotation vector ``δ`` in ``R̂ = exp([δ]×) R`` (rad²).
    up : (3,) ndarray
        Gravity's direction (up) in the gyro's frame at the kinematics' reference angles.
    rms_rad : float
        RMS angle between the carried and the measured gravity directions over the rests.
    rests : int
        Rests used.
    """

    rotation: np.ndarray
    covariance: np.ndarray
    up: np.ndarray
    rms_rad: float
    rests: int


def _skew(v: np.ndarray) -> np.ndarray:
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def _expm_so3(v: np.ndarray) -> np.ndarray:
    """Rotation matrix of the rotation vector ``v`` (Rodrigues)."""
    a = float(np.linalg.norm(v))
    if a < 1e-300:
        return np.eye(3)
    k = _skew(v / a)
    return np.eye(3) + math.sin(a) * k + (1 - math.cos(a)) * k @ k


def frame_rotation(forces: Any, angles: Any, axes: Any, reference: Any,
                   direction_std: Any, axes_std: Any = None) -> FrameRotation:
    r"""The rotation between the gyro's and the accelerometer's calibrated frames, from rests.

    Each calibration has its own frame convention (``gyro-x-xy``: the gyro's x sensing axis;
    :data:`ACCEL_FRAME`: the accelerometer's), and neither fit sees the rotation between them.
    The rests see it: the gyro fit's kinematics give every servo's axis in the gyro's frame
    (:mod:`gyrocal.calib.kinematics`), so gravity's direction there at rest ``r`` is "up" at the
    reference angles carried by the servos' rotations, ``γ_r = K(θ_r) γ₀``
    (:func:`gyrocal.calib.kinematics.chain_axes` of ``γ₀`` as a joint outside the base); the
    calibrated accelerometer measures it in its own frame, ``v_r = R γ_r``. imu_tk (Tedaldi et
    al. 2014) aligns the gyro to the accelerometer's frame the same way, from gravity seen
    before and after rotations. The fit minimises ``Σ |R K(θ_r) γ₀ − v_r/|v_r||² / σ_r²`` over
    ``R`` and the unit ``γ₀`` (Levenberg–Marquardt, ``scipy.optimize.least_squares``); the
    covariance of the rotation is the ``δ`` block of ``(JᵀJ)⁻¹``, widened by the reduced
    ``χ²/(2N − 5)`` when above one: rests scattered beyond their noise (a pose off the one the
    encoders report by a wobble of the jig) then count as the noise they show. With
    ``axes_std``, the servo axes' own uncertainty (the gyro fit's) is added through the implicit
    derivative of the solution, ``∂p/∂a = −(JᵀJ)⁻¹ Jᵀ ∂r/∂a``: a tilted axis carries every
    rest's gravity the same wrong way, which the rests' scatter cannot show. Rotations about
    at least two non-parallel servo axes are needed (a planned run with accelerometer rests has
    them).

    Parameters
    ----------
    forces : (N, 3) array_like
        Calibrated specific force of each rest in the accelerometer's frame
        (:meth:`AccelCalibration.apply` of the rest's mean reading); only its direction is used.
    angles : (N, S) array_like
        Every servo's encoder angle during each rest, rad, chain order.
    axes : (S, 3) array_like
        The servos' axes in the gyro's frame at ``reference`` (a full calibration's
        ``kinematics``).
    reference : (S,) array_like
        The kinematics' reference angles, rad.
    direction_std : float or (N,) array_like
        Standard deviation of each rest's direction per axis, rad (its mean's σ over ``g``).
    axes_std : (S,) array_like, optional
        Each servo axis's direction σ, rad, in both directions across it (the gyro fit's
        ``axes_std_rad``); without it the axes count as exact.

    Returns
    -------
    FrameRotation

    Raises
    ------
    CalibInputError
        On bad shapes or values, fewer than three rests, or rests whose rotations do not
        determine ``R`` (all about one axis).
    """
    from gyrocal.calib.kinematics import chain_axes

    v = np.asarray(forces, dtype=float)
    th = np.asarray(angles, dtype=float)
    ax = np.asarray(axes, dtype=float)
    ref = np.asarray(reference, dtype=float)
    if v.ndim != 2 or v.shape[1] != 3 or v.shape[0] < 3 or not np.all(np.isfinite(v)):
        raise CalibInputError(f"forces must be a finite (N, 3) array with N >= 3 rests, got "
                              f"shape {v.shape}")
    n = v.shape[0]
    if ax.ndim != 2 or ax.shape[1] != 3 or not np.all(np.isfinite(ax)):
        raise CalibInputError(f"axes must be a finite (S, 3) array, got shape {ax.shape}")
    S = ax.shape[0]
    if th.shape != (n, S) or ref.shape != (S,) or not (np.all(np.isfinite(th))
                                                       and np.all(np.isfinite(ref))):
        raise CalibInputError(f"angles must be finite ({n}, {S}) and reference ({S},), got "
                              f"{th.shape} and {ref.shape}")
    nrm = np.linalg.norm(v, axis=1)
    if np.any(nrm <= 0):
        raise CalibInputError("forces must be non-zero (a still sensor feels gravity)")
    u = v / nrm[:, None]
    sd = np.broadcast_to(np.asarray(direction_std, dtype=float), (n,))
    if not np.all(np.isfinite(sd) & (sd > 0)):
        raise CalibInputError("direction_std must be positive and finite")
    ext_ref = np.concatenate([[0.0], ref])
    th_ext = np.concatenate([np.zeros((n, 1)), th], axis=1)

    def carrier(axes_now: np.ndarray) -> np.ndarray:
        """Carrying is linear: K_r (N, 3, 3), its columns the carried unit vectors."""
        return np.stack([chain_axes(np.vstack([e, axes_now]), ext_ref, th_ext)[:, 0]
                         for e in np.eye(3)], axis=2)

    K = carrier(ax)

    # start: R = I, γ₀ from the rest nearest the reference angles carried back
    k0 = int(np.argmin(np.abs(th - ref).sum(axis=1)))
    back = chain_axes(np.vstack([u[k0], ax]), np.concatenate([[0.0], th[k0]]),
                      np.concatenate([[0.0], ref])[None])[0, 0]
    e1, e2 = _across(back)

    def unpack(p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        g0 = back + p[3] * e1 + p[4] * e2
        return _expm_so3(p[:3]), g0 / np.linalg.norm(g0)

    def resid(p: np.ndarray) -> np.ndarray:
        R, g0 = unpack(p)
        return ((K @ g0 @ R.T - u) / sd[:, None]).ravel()

    from scipy import optimize  # imported where a fit needs it (seconds on a Pi)

    res = optimize.least_squares(resid, np.zeros(5), method="lm", xtol=1e-15, ftol=1e-15,
                                 gtol=1e-15, max_nfev=200)
    # re-centre the rotation vector at the solution so the covariance is that of δ at R̂
    R, g0 = unpack(res.x)

    def resid_at(p: np.ndarray) -> np.ndarray:
        g = g0 + p[3] * e1 + p[4] * e2
        return ((K @ (g / np.linalg.norm(g)) @ (_expm_so3(p[:3]) @ R).T - u)
                / sd[:, None]).ravel()

    def resid_axes(axes_now: np.ndarray) -> np.ndarray:
        return ((carrier(axes_now) @ g0 @ R.T - u) / sd[:, None]).ravel()

    jac = optimize.approx_fprime(np.zeros(5), resid_at, 1e-7)
    jtj = jac.T @ jac
    if np.linalg.cond(jtj) > 1e12:
        raise CalibInputError("the rests do not determine the rotation between the gyro's and "
                              "the accelerometer's frames: they need rotations about two "
                              "servo axes (plan the run with accelerometer rests)")
    # rests that scatter more than their noise says (the jig's wobble: a rest's pose is not
    # quite the one its encoders give) widen the covariance: the one rule of calib.dispersion
    # (the Birge ratio χ²/dof when the white-noise test fails)
    spread = _scatter_factor(res.fun, 2 * n - 5)
    inv = np.linalg.inv(jtj)
    cov = spread * inv[:3, :3]
    if axes_std is not None:
        cov = cov + _axes_covariance(ax, np.asarray(axes_std, dtype=float), jac, inv,
                                     resid_axes)
    ang = np.arcsin(np.clip(np.linalg.norm(np.cross(K @ g0 @ R.T, u), axis=1), 0, 1))
    return FrameRotation(R, cov, g0, float(np.sqrt(np.mean(ang**2))), n)


def _scatter_factor(z: np.ndarray, dof: int) -> float:
    """The variance factor whitened residuals ``z`` on ``dof`` degrees of freedom ask of a
    fit's covariance (:func:`gyrocal.calib.dispersion.multiplicative`: 1 when their χ² passes
    the test, ``χ²/dof`` otherwise); 1 without redundancy."""
    from gyrocal.calib.dispersion import multiplicative

    if dof <= 0:
        return 1.0
    return multiplicative(z, dof, 0.0, alpha=CONSISTENCY_LEVEL).factor


def _across(v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors across the direction ``v`` and each other, ``(t1, v̂ × t1)``."""
    v = v / np.linalg.norm(v)
    t1 = np.cross(v, [1.0, 0, 0] if abs(v[0]) < 0.9 else [0, 1.0, 0])
    t1 /= np.linalg.norm(t1)
    return t1, np.cross(v, t1)


def _axes_covariance(axes: np.ndarray, axes_std: np.ndarray, jac: np.ndarray,
                     inv: np.ndarray, resid: Any) -> np.ndarray:
    """The rotation's covariance from the servo axes' σ (:func:`frame_rotation`): each axis
    tilted in two directions across it, ``δ``'s response by the implicit derivative."""
    from scipy import optimize

    if axes_std.shape != (axes.shape[0],) or not np.all(np.isfinite(axes_std) & (axes_std >= 0)):
        raise CalibInputError(f"axes_std must be {axes.shape[0]} finite non-negative σ, got "
                              f"{axes_std!r}")
    tangents = [_across(a) for a in axes]

    def tilted(q: np.ndarray) -> np.ndarray:
        out = axes.copy()
        for i, (t1, t2) in enumerate(tangents):
            v = axes[i] + q[2 * i] * t1 + q[2 * i + 1] * t2
            out[i] = v / np.linalg.norm(v)
        return out

    jac_a = optimize.approx_fprime(np.zeros(2 * len(axes)), lambda q: resid(tilted(q)), 1e-7)
    dp = -(inv @ jac.T @ jac_a)[:3]
    return (dp * np.repeat(axes_std, 2) ** 2) @ dp.T


def align_gyro(cal: Any, rotation: FrameRotation) -> Any:
    r"""The gyro calibration expressed in the accelerometer's frame (imu_tk's alignment).

    ``g = A (m + b)`` in ``gyro-x-xy`` becomes ``R g = (R A)(m + b)`` in :data:`ACCEL_FRAME`:
    ``A' = R A``; the bias, g-sensitivity (both in the reading's space) and temperature model's
    bias terms are unchanged; the kinematics' axes turn with the frame. The 12×12 covariance of
    ``(A row-major, b)`` is propagated, ``Σ' = T Σ Tᵀ + J Σ_δ Jᵀ`` with ``T = R ⊗ I₃`` on the
    matrix block and ``∂A'/∂δ_l = [e_l]× A'`` for the rotation's own uncertainty (independent of
    the gyro fit's). ``frame`` becomes :data:`ACCEL_FRAME`.

    Parameters
    ----------
    cal : gyrocal.calib.model.GyroCalibration
        A full (v2) calibration in the frame ``gyro-x-xy``.
    rotation : FrameRotation
        From :func:`frame_rotation` (or any rotation with its covariance).

    Returns
    -------
    gyrocal.calib.model.GyroCalibration

    Raises
    ------
    CalibInputError
        A diagonal calibration, one already in another frame, one whose temperature model
        moves its gain, or a rotation that is not one.
    """
    from dataclasses import replace

    from gyrocal.calib.estimators import FULL_FRAME

    R = np.asarray(rotation.rotation, dtype=float)
    if R.shape != (3, 3) or not np.allclose(R @ R.T, np.eye(3), atol=1e-9) or not (
            np.linalg.det(R) > 0):
        raise CalibInputError("rotation must be a proper 3x3 rotation matrix")
    if cal.matrix is None:
        raise CalibInputError("aligning to the accelerometer needs the full model's matrix (a "
                              "v2 calibration); the diagonal model has no frame to turn")
    if cal.frame != FULL_FRAME:
        raise CalibInputError(f"the calibration's frame is {cal.frame!r}; only one in "
                              f"{FULL_FRAME!r} can be aligned (it is aligned once)")
    tm = cal.temperature_model
    if tm is not None and tm.gain_coeffs is not None:
        raise CalibInputError("the calibration's temperature model moves its matrix; align "
                              "the calibration before fitting the temperature model")
    a = R @ np.asarray(cal.matrix, dtype=float)
    if np.any(np.diag(a) <= 0):
        raise CalibInputError("the rotation between the frames is too large for a calibration "
                              "(a scale would turn negative): check the accelerometer's fit")
    cov_doc = None
    std = None
    if cal.covariance is not None:
        c = np.asarray(cal.covariance, dtype=float)
        T = np.eye(12)
        T[:9, :9] = np.kron(R, np.eye(3))
        J = np.zeros((12, 3))
        for ell in range(3):
            J[:9, ell] = (_skew(np.eye(3)[ell]) @ a).ravel()
        cov = T @ c @ T.T + J @ np.asarray(rotation.covariance, dtype=float) @ J.T
        cov_doc = tuple(tuple(float(x) for x in row) for row in cov)
        std = np.sqrt(np.clip(np.diag(cov), 0, None))
    kin = cal.kinematics
    if kin is not None:
        kin = {**kin, "axes": (np.asarray(kin["axes"], dtype=float) @ R.T).tolist()}
    return replace(
        cal, matrix=tuple(tuple(float(x) for x in r) for r in a),
        scale=tuple(float(x) for x in np.diag(a)),
        scale_std=(cal.scale_std if std is None else tuple(float(x) for x in std[[0, 4, 8]])),
        matrix_std=(cal.matrix_std if std is None
                    else tuple(tuple(float(x) for x in r) for r in std[:9].reshape(3, 3))),
        covariance=cov_doc, frame=ACCEL_FRAME, kinematics=kin)
