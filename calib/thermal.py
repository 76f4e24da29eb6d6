"""The thermal model of a gyro: bias and scale (or the full matrix) against die temperature.

A MEMS gyro's bias moves with temperature by far more than a calibration's precision (issue 13:
the MPU-9250 allows ±30 °/s over −40…85 °C, PS-MPU-9250A-01 §3.1), and the paper's model,
``g = K (m + b)`` (Eq. 1; ``g = A (m + b)`` for the full model), holds at one temperature only.
Given a set of calibrations, each at its own mean die temperature ``T_i`` with its standard
deviations, :func:`fit_thermal` fits

    ``b_j(T) = Σ_k c_jk (T − T_ref)^k``  (k = 0 … p, the same order ``p`` for the three axes),
    ``A(T)  = A_0 + A_1 (T − T_ref)``      (each element; the scale's diagonal for the paper's
                                             diagonal model),

by weighted least squares (weights ``1/σ²`` of each calibration's parameter; the correlations
between one calibration's parameters are not used). The part of each bias variance that the
calibrations share (``bias_common_var``: the bias's wander over a run, whose slow flicker and
random-walk components are common to calibrations made minutes apart,
:attr:`gyrocal.calib.drift.BiasDrift.run_variance`) is not independent scatter: averaging
``n`` calibrations does not shrink it by ``√n``. It is taken out of the weights and added back,
whole, as the variance of the constant coefficient (one offset shared by every calibration
moves ``c_j0`` alone), so ``σ_b(T)`` never falls below it. The bias order ``p`` is chosen by
the data with the Bayesian information criterion, ``BIC(p) = χ²(p) + 3(p + 1)·ln(3n)`` over
the three axes (χ² with the calibrations' stated independent variances), among the orders
that leave at least one redundant calibration (``p ≤ n − 2``; at most
:data:`MAX_BIAS_ORDER`). The consistency check is the χ² of all residuals against the stated
(independent) variances on its degrees of freedom, so a wander that is in fact independent
between calibrations shows as scatter; when it fails (p-value below
:data:`~gyrocal.calib.estimators.CONSISTENCY_ALPHA`) the coefficients' covariances are scaled
by the Birge ratio ``χ²/dof`` so that the stated uncertainty covers the scatter actually seen:
the one rule of :mod:`gyrocal.calib.dispersion` (its ``thermal`` row: any such scatter is "not
consistent"; a single calibration that does not fit the others is named).

The model is valid over the covered range ``[min T_i, max T_i]``: :meth:`ThermalModel.at`
clamps a temperature outside it to the nearest end and says so (``clamped``); it never
extrapolates. The document form (the Calibration's ``temperature_model``, version 1) is
:meth:`ThermalModel.to_dict`; hardware_docs/formats.md describes it.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from gyrocal.calib.errors import CalibInputError, CalibrationFormatError
from gyrocal.calib.model import LIMITS, Consistency, _array, _number, _refuse_unknown

__all__ = ["MAX_BIAS_ORDER", "THERMAL_VERSION", "ThermalModel", "ThermalRangeWarning",
           "ThermalState", "apply_thermal", "fit_thermal"]

#: Version of the ``temperature_model`` object.
THERMAL_VERSION = 1
#: Highest polynomial order of bias(T) the criterion may choose (a cubic; MEMS bias curves over
#: a warm-up are smooth, and higher orders only chase noise between calibrations).
MAX_BIAS_ORDER = 3
_ALPHA = 0.01  # the estimators' CONSISTENCY_ALPHA (calib.estimators imports model, not us)
_FIELDS = ("version", "reference_c", "range_c", "bias_coeffs", "bias_coeffs_std",
           "bias_coeffs_covariance", "matrix_coeffs", "matrix_coeffs_std", "scale_coeffs",
           "scale_coeffs_std", "criterion", "consistency", "points", "kind")
_KINDS = ("calibrations", "static")


class ThermalRangeWarning(UserWarning):
    """A thermal model was evaluated outside the temperatures it was fitted on (clamped)."""


@dataclass(frozen=True)
class ThermalState:
    """The model evaluated at one temperature.

    Attributes
    ----------
    temperature_c : float
        The temperature the model was evaluated at (after clamping).
    requested_c : float
        The temperature asked for.
    clamped : bool
        Whether ``requested_c`` was outside the covered range (then ``temperature_c`` is its
        nearest end).
    bias : (3,) ndarray
        ``b(T)``, rad/s.
    bias_std : (3,) ndarray
        Its standard deviation from the coefficients' covariance (with the offset the
        calibrations share, :func:`fit_thermal`'s ``bias_common_var``).
    gain : (3, 3) ndarray or None
        ``A(T)`` (a diagonal matrix for the diagonal model); None for a bias-only model.
    gain_std : (3, 3) ndarray or None
        Its element-wise standard deviation.
    """

    temperature_c: float
    requested_c: float
    clamped: bool
    bias: np.ndarray
    bias_std: np.ndarray
    gain: np.ndarray | None
    gain_std: np.ndarray | None


@dataclass(frozen=True, eq=False)
class ThermalModel:
    """Bias and gain against die temperature (module docstring), with uncertainties.

    Attributes
    ----------
    reference_c : float
        ``T_ref``: the powers are of ``T − T_ref``.
    range_c : (float, float)
        The covered range of die temperatures.
    bias_coeffs : (3, p + 1) ndarray
        Per axis, ascending powers.
    bias_coeffs_covariance : (3, p + 1, p + 1) ndarray
        Per axis, the coefficients' covariance.
    gain_coeffs : (2, 3, 3) ndarray or None
        ``[A_0, A_1]``; None for a bias-only model (a static warm-up).
    gain_coeffs_std : (2, 3, 3) ndarray or None
    diagonal : bool
        Whether the gain is the paper's diagonal scale (document key ``scale_coeffs``) rather
        than the full matrix (``matrix_coeffs``).
    criterion : dict
        How the bias order was chosen: ``{"name": "BIC", "bias_order", "scores"}``.
    consistency : Consistency or None
        χ² of the residuals against the stated variances (None with no redundancy).
    points : int
        Number of calibrations (or temperature bins) fitted.
    kind : str
        ``"calibrations"`` (spin calibrations) or ``"static"`` (bias from a still warm-up).
    """

    reference_c: float
    range_c: tuple[float, float]
    bias_coeffs: np.ndarray
    bias_coeffs_covariance: np.ndarray
    gain_coeffs: np.ndarray | None = None
    gain_coeffs_std: np.ndarray | None = None
    diagonal: bool = False
    criterion: dict[str, Any] | None = None
    consistency: Consistency | None = None
    points: int = 0
    kind: str = "calibrations"

    @property
    def bias_order(self) -> int:
        """The polynomial order of bias(T)."""
        return int(self.bias_coeffs.shape[1]) - 1

    def at(self, temperature_c: float) -> ThermalState:
        """The model at ``temperature_c``, clamped to :attr:`range_c` (never extrapolated).

        Raises
        ------
        CalibInputError
            If the temperature is not a finite number.
        """
        try:
            req = float(temperature_c)
        except (TypeError, ValueError):
            raise CalibInputError(f"temperature_c must be a number, got {temperature_c!r}"
                                  ) from None
        if not math.isfinite(req):
            raise CalibInputError(f"temperature_c must be finite, got {temperature_c!r}")
        lo, hi = self.range_c
        t = min(max(req, lo), hi)
        p = self.bias_order
        v = (t - self.reference_c) ** np.arange(p + 1)
        bias = self.bias_coeffs @ v
        bias_std = np.sqrt(np.einsum("i,aij,j->a", v, self.bias_coeffs_covariance, v))
        gain = gain_std = None
        if self.gain_coeffs is not None:
            d = t - self.reference_c
            gain = self.gain_coeffs[0] + self.gain_coeffs[1] * d
            if self.gain_coeffs_std is not None:  # the two coefficients' correlation is not
                s = self.gain_coeffs_std           # kept: an upper bound at the range's ends
                gain_std = np.hypot(s[0], s[1] * d)
        return ThermalState(t, req, t != req, bias, bias_std, gain, gain_std)

    def evaluate(self, temperature_c: np.ndarray
                 ) -> tuple[np.ndarray, np.ndarray | None, np.ndarray]:
        """Bias (N, 3) and gain (N, 3, 3) (None for a bias-only model) at many temperatures,
        each clamped to :attr:`range_c`, and which were clamped (N,) (vectorised :meth:`at`).

        Raises
        ------
        CalibInputError
            If a temperature is not finite.
        """
        req = np.atleast_1d(np.asarray(temperature_c, dtype=float))
        if req.ndim != 1 or not np.all(np.isfinite(req)):
            raise CalibInputError("temperature_c must be finite numbers, one per reading; "
                                  "give the die temperature of every reading")
        t = np.clip(req, *self.range_c)
        d = t - self.reference_c
        bias = (d[:, None] ** np.arange(self.bias_order + 1)) @ self.bias_coeffs.T
        gain = None
        if self.gain_coeffs is not None:
            gain = self.gain_coeffs[0] + self.gain_coeffs[1] * d[:, None, None]
        return bias, gain, t != req

    # ------------------------------------------------------------------ the document
    def to_dict(self) -> dict[str, Any]:
        """The ``temperature_model`` object of a Calibration document (version 1)."""
        def num(x: float) -> float | None:
            return float(x) if math.isfinite(x) else None

        def lists(a: np.ndarray) -> Any:
            return [lists(x) for x in a] if a.ndim else num(float(a))

        cov = self.bias_coeffs_covariance
        doc: dict[str, Any] = {
            "version": THERMAL_VERSION,
            "kind": self.kind,
            "reference_c": self.reference_c,
            "range_c": [self.range_c[0], self.range_c[1]],
            "bias_coeffs": lists(self.bias_coeffs),
            "bias_coeffs_std": lists(np.sqrt(np.maximum(np.diagonal(cov, axis1=1, axis2=2), 0))),
            "bias_coeffs_covariance": lists(cov),
        }
        if self.gain_coeffs is not None:
            std = self.gain_coeffs_std
            if self.diagonal:  # per axis, ascending powers, like bias_coeffs
                doc["scale_coeffs"] = lists(np.diagonal(self.gain_coeffs, axis1=1, axis2=2).T)
                doc["scale_coeffs_std"] = None if std is None else lists(
                    np.diagonal(std, axis1=1, axis2=2).T)
            else:  # by power: [A_0, A_1], each 3×3 row-major
                doc["matrix_coeffs"] = lists(self.gain_coeffs)
                doc["matrix_coeffs_std"] = None if std is None else lists(std)
        doc["criterion"] = dict(self.criterion or {})
        doc["consistency"] = None if self.consistency is None else self.consistency.to_dict()
        doc["points"] = self.points
        return doc

    @classmethod
    def from_dict(cls, doc: Any) -> ThermalModel:
        """Read a ``temperature_model`` object strictly (as the rest of the document).

        Raises
        ------
        CalibrationFormatError
            If the version is not 1, a field is unknown or missing, a shape is wrong, the range
            is empty or outside −100…200 °C, or the gain is given both as matrix and scale.
        """
        if not isinstance(doc, Mapping):
            raise CalibrationFormatError("'temperature_model' must be an object")
        _refuse_unknown(doc, _FIELDS, "'temperature_model'")
        if doc.get("version") != THERMAL_VERSION or isinstance(doc.get("version"), bool):
            raise CalibrationFormatError(
                f"'temperature_model.version' is {doc.get('version')!r}; this gyrocal reads "
                f"version {THERMAL_VERSION}: upgrade gyrocal or refit the thermal model")
        for name in ("reference_c", "range_c", "bias_coeffs"):
            if doc.get(name) is None:
                raise CalibrationFormatError(f"'temperature_model' lacks the field {name!r}")
        t_lo, t_hi = LIMITS["temperature_c"]
        ref = _number(doc["reference_c"], "temperature_model.reference_c", t_lo, t_hi)
        rng = _array(doc["range_c"], "temperature_model.range_c", (2,), lo=t_lo, hi=t_hi)
        if rng[0] > rng[1]:
            raise CalibrationFormatError("'temperature_model.range_c' must be [low, high]")
        raw = doc["bias_coeffs"]
        n = len(raw[0]) if isinstance(raw, list) and raw and isinstance(raw[0], list) else 0
        if not 1 <= n <= MAX_BIAS_ORDER + 1:
            raise CalibrationFormatError(
                "'temperature_model.bias_coeffs' must be 3 lists (x, y, z) of 1 to "
                f"{MAX_BIAS_ORDER + 1} coefficients, ascending powers of (T - reference_c)")
        coeffs = _array(raw, "temperature_model.bias_coeffs", (3, n))
        cov_doc = doc.get("bias_coeffs_covariance")
        if cov_doc is not None:
            cov = _array(cov_doc, "temperature_model.bias_coeffs_covariance", (3, n, n),
                         nullable=True)
        else:
            std = doc.get("bias_coeffs_std")
            s = (np.full((3, n), math.nan) if std is None else
                 _array(std, "temperature_model.bias_coeffs_std", (3, n), nullable=True, lo=0))
            cov = np.einsum("ai,ij->aij", s**2, np.eye(n))
        if "matrix_coeffs" in doc and "scale_coeffs" in doc:
            raise CalibrationFormatError(
                "'temperature_model' has both 'matrix_coeffs' and 'scale_coeffs'; keep one")
        gain = gain_std = None
        diagonal = doc.get("scale_coeffs") is not None
        if diagonal:
            k = _array(doc["scale_coeffs"], "temperature_model.scale_coeffs", (3, 2))
            gain = np.stack([np.diag(k[:, 0]), np.diag(k[:, 1])])
            if doc.get("scale_coeffs_std") is not None:
                s = _array(doc["scale_coeffs_std"], "temperature_model.scale_coeffs_std", (3, 2),
                           nullable=True, lo=0)
                gain_std = np.stack([np.diag(s[:, 0]), np.diag(s[:, 1])])
        elif doc.get("matrix_coeffs") is not None:
            gain = _array(doc["matrix_coeffs"], "temperature_model.matrix_coeffs", (2, 3, 3))
            if doc.get("matrix_coeffs_std") is not None:
                gain_std = _array(doc["matrix_coeffs_std"], "temperature_model.matrix_coeffs_std",
                                  (2, 3, 3), nullable=True, lo=0)
        if gain is not None:
            lo, hi = LIMITS["scale"]
            if not np.all((np.diag(gain[0]) >= lo) & (np.diag(gain[0]) <= hi)):
                raise CalibrationFormatError(
                    f"'temperature_model' scale at the reference is outside [{lo:g}, {hi:g}]")
        criterion = doc.get("criterion") or {}
        if not isinstance(criterion, Mapping):
            raise CalibrationFormatError("'temperature_model.criterion' must be an object")
        cons = doc.get("consistency")
        points = doc.get("points", 0)
        if isinstance(points, bool) or not isinstance(points, int) or points < 0:
            raise CalibrationFormatError("'temperature_model.points' must be a count")
        kind = doc.get("kind", "calibrations")
        if kind not in _KINDS:
            raise CalibrationFormatError(
                f"'temperature_model.kind' must be one of {', '.join(_KINDS)}, got {kind!r}")
        return cls(ref, (float(rng[0]), float(rng[1])), coeffs, cov, gain, gain_std, diagonal,
                   dict(criterion), None if cons is None else Consistency.from_dict(cons),
                   points, kind)


def _wls(x: np.ndarray, y: np.ndarray, var: np.ndarray, order: int
         ) -> tuple[np.ndarray, np.ndarray, float, np.ndarray]:
    """Weighted polynomial least squares: coefficients (ascending), their covariance, χ² and
    the residuals whitened by the stated σ."""
    X = x[:, None] ** np.arange(order + 1)
    w = 1.0 / var
    XtW = X.T * w
    cov = np.linalg.inv(XtW @ X)
    c = cov @ (XtW @ y)
    z = (y - X @ c) * np.sqrt(w)
    return c, cov, float(z @ z), z


def _judged(z: np.ndarray, chi2: float, dof: int, temperature_c: np.ndarray
            ) -> tuple[Consistency, float]:
    """The verdict on the calibrations' whitened residuals ``z`` (the bias axes' fits, then
    the gain entries', each over the calibrations in order) and the variance factor the
    coefficients' covariances take: the one rule of :mod:`gyrocal.calib.dispersion`
    (:func:`~gyrocal.calib.dispersion.multiplicative`, its ``thermal`` tolerance: no scatter
    beyond the calibrations' stated σ is ordinary, so any is "not consistent", and the σ are
    widened by the Birge ratio ``χ²/dof`` all the same)."""
    # imported here: calib.windows imports this module for correct_drift, which needs no
    # scipy (a recording alone, issue 25)
    from gyrocal.calib.dispersion import SCATTER_TOLERANCE, multiplicative

    n = temperature_c.size
    names = [f"the calibration at {temperature_c[i % n]:.2f} °C" for i in range(z.size)]
    verdict = multiplicative(z, dof, 1.0, alpha=_ALPHA, tolerance=SCATTER_TOLERANCE["thermal"],
                             names=names, chi2=chi2, groups=np.arange(z.size) % n)
    return verdict.consistency, verdict.factor


def _positive_var(std: np.ndarray, name: str) -> np.ndarray:
    s = np.asarray(std, dtype=float)
    if not np.all(np.isfinite(s)) or np.any(s <= 0):
        raise CalibInputError(f"{name} must be positive and finite (each calibration's stated "
                              "standard deviation); refit the calibrations that lack it")
    return s * s


def _split_common(bvar: np.ndarray, common_var: np.ndarray | None
                  ) -> tuple[np.ndarray, np.ndarray]:
    """Each calibration's independent bias variance, and the variance of the offset the
    calibrations share (per axis: the largest of theirs, so it is not understated)."""
    if common_var is None:
        return bvar, np.zeros(3)
    c = np.broadcast_to(np.asarray(common_var, dtype=float), bvar.shape)
    if not np.all(np.isfinite(c)) or np.any(c < 0) or np.any(c >= bvar):
        raise CalibInputError(
            "bias_common_var must be finite, at least 0 and below each calibration's bias_std² "
            "(the part of its variance the calibrations share)")
    return bvar - c, c.max(axis=0)


def fit_thermal(
    temperature_c: np.ndarray,
    bias: np.ndarray,
    bias_std: np.ndarray,
    gain: np.ndarray | None = None,
    gain_std: np.ndarray | None = None,
    *,
    reference_c: float | None = None,
    kind: str = "calibrations",
    bias_common_var: np.ndarray | None = None,
) -> ThermalModel:
    """Fit bias(T) (order by BIC) and the gain linearly in T (module docstring).

    Parameters
    ----------
    temperature_c : (n,) array_like
        Each calibration's mean die temperature, °C.
    bias, bias_std : (n, 3) array_like
        Each calibration's bias and its standard deviation, rad/s.
    gain, gain_std : (n, 3) or (n, 3, 3) array_like, optional
        Each calibration's scale (the paper's diagonal model) or full matrix, and their
        standard deviations; omitted for a bias-only fit (a static warm-up).
    reference_c : float, optional
        ``T_ref``; the middle of the covered range by default.
    kind : str
        ``"calibrations"`` or ``"static"``, recorded in the model.
    bias_common_var : (n, 3) or (3,) array_like, optional
        The part of each ``bias_std²`` common to all the calibrations (module docstring), rad²/s²;
        each must be below its ``bias_std²``. None: the calibrations' errors are independent.

    Returns
    -------
    ThermalModel

    Raises
    ------
    CalibInputError
        If shapes disagree, a value is not finite, a standard deviation is not positive, a
        common variance is not below its calibration's variance, fewer than two calibrations are
        given, or they span less than 0.1 °C.
    """
    T = np.asarray(temperature_c, dtype=float)
    n = T.size
    if T.ndim != 1 or n < 2:
        raise CalibInputError(f"temperature_c must list at least two calibrations, got {n}")
    if not np.all(np.isfinite(T)):
        raise CalibInputError("temperature_c must be finite: every calibration needs its mean "
                              "die temperature (the recording's temp column)")
    lo, hi = float(T.min()), float(T.max())
    if hi - lo < 0.1:
        raise CalibInputError(
            f"the calibrations span only {hi - lo:.3g} °C ({lo:.2f}…{hi:.2f} °C): a thermal model "
            "needs calibrations at different temperatures (a warm-up, or a changed ambient)")
    if kind not in _KINDS:
        raise CalibInputError(f"kind must be one of {', '.join(_KINDS)}, got {kind!r}")
    b = np.asarray(bias, dtype=float)
    if b.shape != (n, 3) or not np.all(np.isfinite(b)):
        raise CalibInputError(f"bias must be finite with shape ({n}, 3), got {b.shape}")
    bvar = _positive_var(np.broadcast_to(bias_std, (n, 3)), "bias_std")
    bvar, common = _split_common(bvar, bias_common_var)
    ref = 0.5 * (lo + hi) if reference_c is None else float(reference_c)
    x = T - ref

    # bias: one order for the three axes, chosen by BIC among those with redundancy left
    max_p = min(MAX_BIAS_ORDER, n - 2) if n >= 3 else 0
    fits, scores = {}, {}
    for p in range(max_p + 1):
        per_axis = [_wls(x, b[:, j], bvar[:, j], p) for j in range(3)]
        chi2 = sum(f[2] for f in per_axis)
        fits[p] = per_axis
        scores[p] = chi2 + 3 * (p + 1) * math.log(3 * n)
    p = min(scores, key=lambda k: scores[k])
    coeffs = np.array([f[0] for f in fits[p]])
    cov = np.array([f[1] for f in fits[p]])
    chi2, dof = sum(f[2] for f in fits[p]), 3 * (n - p - 1)

    g_coeffs = g_std = None
    diagonal = False
    g_chi2: list[float] = []
    g_z: list[np.ndarray] = []
    if gain is not None:
        g = np.asarray(gain, dtype=float)
        diagonal = g.shape == (n, 3)
        if diagonal:
            g = np.einsum("ni,ij->nij", g, np.eye(3))
        if g.shape != (n, 3, 3) or not np.all(np.isfinite(g)):
            raise CalibInputError(f"gain must be finite with shape ({n}, 3) or ({n}, 3, 3)")
        if gain_std is None:
            raise CalibInputError("gain_std is needed with gain")
        s = np.asarray(gain_std, dtype=float)
        s = np.einsum("ni,ij->nij", s, np.eye(3)) if s.shape == (n, 3) else s
        if s.shape != (n, 3, 3):
            raise CalibInputError(f"gain_std must have the shape of gain, got {s.shape}")
        mask = np.eye(3, dtype=bool) if diagonal else np.ones((3, 3), dtype=bool)
        g_coeffs, g_std = np.zeros((2, 3, 3)), np.zeros((2, 3, 3))
        for i, k in zip(*np.nonzero(mask), strict=True):
            if np.all(s[:, i, k] == 0) and np.ptp(g[:, i, k]) == 0:
                # an entry the frame convention fixes (Calibration v2's ``frame``): exact and
                # the same in every calibration, so it has no temperature terms to fit
                g_coeffs[0, i, k] = g[0, i, k]
                continue
            var = _positive_var(s[:, i, k], f"gain_std[{i}][{k}]")
            c, cv, ch, z = _wls(x, g[:, i, k], var, 1)
            g_coeffs[:, i, k], g_std[:, i, k] = c, np.sqrt(np.diag(cv))
            g_chi2.append(ch)
            g_z.append(z)
        chi2 += sum(g_chi2)
        dof += len(g_chi2) * (n - 2)

    consistency, factor = None, 1.0
    if dof > 0:
        z = np.concatenate([f[3] for f in fits[p]] + g_z)
        consistency, factor = _judged(z, float(chi2), int(dof), T)
        cov = cov * factor
        if g_std is not None:
            g_std = g_std * math.sqrt(factor)
    cov[:, 0, 0] += common  # the shared offset: the constant coefficient's alone
    criterion = {"name": "BIC", "bias_order": p,
                 "scores": {str(k): float(v) for k, v in scores.items()},
                 "gain_order": None if gain is None else 1,
                 "birge_scaled": factor != 1.0}
    return ThermalModel(ref, (lo, hi), coeffs, cov, g_coeffs, g_std, diagonal, criterion,
                        consistency, n, kind)


def apply_thermal(model: ThermalModel, matrix: np.ndarray, m: np.ndarray,
                  temperature_c: float | np.ndarray) -> np.ndarray:
    """Calibrated rates ``A(T) (m + b(T))`` of readings ``m`` ((3,) or (N, 3), rad/s) at die
    temperatures ``temperature_c`` (a number or (N,)), the model clamped to its covered range.

    ``matrix`` is the calibration's own ``A``, used when the model is bias-only (a static
    warm-up fits no gain). Warns :class:`ThermalRangeWarning` once, with the count and the
    range, when any reading's temperature was outside it.
    """
    a = np.asarray(m, dtype=float)
    rows = np.atleast_2d(a)
    temps = np.broadcast_to(np.asarray(temperature_c, dtype=float), rows.shape[:1])
    bias, gain, clamped = model.evaluate(temps)
    x = rows + bias
    out = x @ np.asarray(matrix).T if gain is None else np.einsum("nij,nj->ni", gain, x)
    if np.any(clamped):
        lo, hi = model.range_c
        warnings.warn(
            f"{int(clamped.sum())} reading(s) at die temperatures outside the thermal model's "
            f"range {lo:.1f}…{hi:.1f} °C were corrected at the nearest end of the range (the "
            "model is not extrapolated); calibrate over a wider temperature range",
            ThermalRangeWarning, stacklevel=3)
    return out.reshape(a.shape)


#: Smallest change of the die temperature across one run's windows that :func:`correct_drift`
#: models (the MPU-9250's register resolves 0.003 °C, the LSM9DS1's 0.06 °C).
DRIFT_MIN_SPAN_C = 0.05
#: Rest windows needed to measure the drift (a line through them, with one to spare).
DRIFT_MIN_RESTS = 3


def correct_drift(obs: Any, window_temp_c: np.ndarray, rest_temp_c: np.ndarray
                  ) -> tuple[Any, str | None]:
    """Refer one run's windows to its mean die temperature (issue 13, "within one run").

    A run whose die warms while it records sees a different bias in every window, which the
    paper's constant-bias model (Eq. 1) cannot absorb. The rest windows measure the bias
    directly (``rest_mean = −b(T)`` for a still sensor), so a weighted line through them
    against their temperatures gives the drift ``β = d(rest_mean)/dT`` per axis with its
    standard deviation ``σ_β``. Every window's mean (turns and rests) is then moved to the run's
    mean temperature ``T̄`` (``obs.temperature_c``): ``mean − β (T_w − T̄)``, and its variance
    grows by ``(σ_β (T_w − T̄))²``, so the fit reports the bias at ``T̄`` with the drift's
    uncertainty in it rather than a false tight figure. That uncertainty is one slope's, common
    to every window, so the offsets ``T_w − T̄`` go with the set (``temp_offset``,
    ``rest_temp_offset``) for a fit that must tell the slope's error from another offset
    pattern (the g-sensitivity test of :func:`gyrocal.calib.estimators.fit_paired_axis`). The
    scale's own temperature change
    within a run cannot be measured here: each axis's scale is the one at the temperature of its
    own servo's turns (which do not average out over the run: the servos turn one after
    another); the kit's estimate flags it in a note when the chip's datasheet
    figure makes it larger than the scale's σ.

    Parameters
    ----------
    obs : ObservationSet
    window_temp_c, rest_temp_c : ndarray
        Mean die temperature over each rotation window and each rest window, °C (NaN unknown).

    Returns
    -------
    (ObservationSet, str or None)
        The corrected set (``obs`` itself when nothing was done) and a note for the user: what
        was corrected, or why a temperature change could not be modelled; None when the die
        temperature was steady or unknown.
    """
    from dataclasses import replace

    tw = np.asarray(window_temp_c, dtype=float)
    tr = np.asarray(rest_temp_c, dtype=float)
    t_bar = obs.temperature_c
    known = np.concatenate([tw, tr])
    known = known[np.isfinite(known)]
    if t_bar is None or known.size == 0:
        return obs, None
    span = float(known.max() - known.min())
    if span < DRIFT_MIN_SPAN_C:
        return obs, None
    ok = np.isfinite(tr)
    if (obs.rest_mean is None or int(ok.sum()) < DRIFT_MIN_RESTS or np.any(~np.isfinite(tw))
            or float(np.ptp(tr[ok])) < 0.5 * span):
        return obs, (
            f"the die temperature changed by {span:.2f} °C during the run, but the run has too "
            f"few rests spread over it (at least {DRIFT_MIN_RESTS} needed) to measure the bias "
            "drift: the bias is an average over the run and its uncertainty does not include "
            "the drift; let the sensor warm up first or calibrate with gyrocal thermal")
    x = tr[ok] - t_bar
    beta, beta_std = np.zeros(3), np.zeros(3)
    for j in range(3):
        c, cov, _, _ = _wls(x, obs.rest_mean[ok, j], obs.rest_mean_std[ok, j] ** 2, 1)
        beta[j], beta_std[j] = c[1], math.sqrt(cov[1, 1])
    dw, dr = (tw - t_bar)[:, None], np.where(ok, tr - t_bar, 0.0)[:, None]
    fixed = replace(
        obs,
        mean=obs.mean - beta * dw,
        mean_std=np.hypot(obs.mean_std, beta_std * dw),
        rest_mean=obs.rest_mean - beta * dr,
        rest_mean_std=np.hypot(obs.rest_mean_std, beta_std * dr),
        temp_offset=dw[:, 0],
        rest_temp_offset=dr[:, 0],
    )
    drift = ", ".join(f"{-b:+.2e} ± {s:.1e}" for b, s in zip(beta, beta_std, strict=True))
    return fixed, (
        f"the die temperature changed by {span:.2f} °C during the run; the bias drift measured "
        f"on {int(ok.sum())} rests (x, y, z: {drift} rad/s per °C) was removed and its "
        f"uncertainty added, so the bias is reported at the run's mean temperature "
        f"{t_bar:.2f} °C")
