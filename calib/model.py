"""The calibration model and its result document.

The paper's Eq. (1) relates the true rate ``g`` and the reading ``m`` (both rad/s) elementwise,

    g = scale ∘ (m + bias),

and the full model of issue 10 generalises it to a 3×3 matrix ``A`` (scale on the diagonal,
cross-axis sensitivity off it):

    g = A (m + bias).

:class:`GyroCalibration` holds either with its uncertainty and how it was obtained, applies it to
readings, and round-trips through the Calibration document: version 1 for the diagonal model,
version 2 when ``matrix`` is set (DESIGN.md, "Contracts"; hardware_docs/formats.md). Loading is
strict: an unknown field, or a number outside its domain (:data:`LIMITS`), is refused with a
message naming the field and what to do.
"""

from __future__ import annotations

import copy
import difflib
import json
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from gyrocal.calib.drift import BiasDrift
from gyrocal.calib.errors import CalibInputError, CalibrationFormatError

if TYPE_CHECKING:
    from gyrocal.calib.accel import AccelCalibration
    from gyrocal.calib.thermal import ThermalModel

__all__ = ["FORMAT", "LIMITS", "MODEL_G", "VERSION", "VERSION_FULL", "Consistency",
           "GSensitivityWarning", "GyroCalibration", "ModelChoice"]

FORMAT = "gyrocal-calibration"
VERSION = 1
VERSION_FULL = 2
MODEL = "g = scale * (m + bias)"
MODEL_FULL = "g = matrix @ (m + bias)"

#: The domain a loaded calibration's numbers must lie in. A scale of 0.1 or 10 is already a unit
#: mistake (°/s read as rad/s gives ≈ 0.017, encoder degrees as radians ≈ 57); no MEMS gyro
#: measures beyond ±4000 °/s ≈ 70 rad/s, so a larger bias is not a bias; a die outside
#: −100…200 °C is not operating.
LIMITS: dict[str, tuple[float, float]] = {
    "scale": (0.1, 10.0),
    "cross_axis": (-1.0, 1.0),
    "bias": (-100.0, 100.0),
    "temperature_c": (-100.0, 200.0),
    "count": (0, 10**9),
}

_CONSISTENCY_FIELDS = ("chi2", "dof", "p_value", "ok")
#: Optional since the over-dispersion rule (DESIGN.md fact 7): absent in older documents.
_CONSISTENCY_EXTRA = ("excess", "scatter", "reason")
_V1_FIELDS = (
    "format", "version", "model", "scale", "bias", "scale_std", "bias_std", "covariance",
    "method", "iterations", "consistency", "sensor", "temperature_c", "created", "source", "axes",
)
_V2_FIELDS = ("matrix", "matrix_std", "frame", "kinematics", "g_sensitivity")
_G_FIELDS = ("model", "matrix", "matrix_std", "directions")
#: ``g_sensitivity.model``: the full model with g-sensitivity, ``f`` the specific force in g.
MODEL_G = "g = matrix @ (m + bias + g_sensitivity @ f)"
#: Largest g-sensitivity term a document may carry, rad/s per g: 50× the MPU-9250's typical
#: 0.1 °/s/g (PS §3.1); more is a unit mistake (°/s, or m/s² for g).
MAX_G_SENSITIVITY = 0.1


class GSensitivityWarning(UserWarning):
    """A calibration with g-sensitivity applied without the specific force: its bias is the
    zero-g bias, so the rate is off by ``A G f`` (up to ~1.7e-3 rad/s at 1 g for an MPU-9250)."""

_THERMAL_FIELDS = ("temperature_model",)  # either version (issue 13; calib.thermal)
_ACCEL_FIELDS = ("accelerometer",)  # either version (issue 15; calib.accel)
_DRIFT_FIELDS = ("bias_drift",)  # either version, optional (issue 30; calib.drift)
_CHOICE_FIELDS = ("model_choice",)  # either version, optional (issue 28; calib.design)
_CHOICE_KEYS = ("full", "diagonal", "diagonal_cross_axis", "cross_axis")
_KINEMATICS_FIELDS = ("chain", "axes", "reference_angles_rad")
#: Optional, together (the gravity reference of ``g_sensitivity``): absent means unknown.
_KINEMATICS_HOME = ("home_angles_rad", "up_servo")
_ACTION = "correct or remove it (see hardware_docs/formats.md)"


def _refuse_unknown(doc: Mapping[str, Any], known: tuple[str, ...], where: str) -> None:
    """Raise naming the first field of ``doc`` not in ``known``, with the nearest known name."""
    for key in doc:
        if key in known:
            continue
        close = difflib.get_close_matches(str(key), known, n=1, cutoff=0.6)
        hint = f"; did you mean {close[0]!r}?" if close else f"; {_ACTION}"
        raise CalibrationFormatError(f"unknown field {key!r} in {where}{hint}")


def _number(x: Any, name: str, lo: float = -math.inf, hi: float = math.inf) -> float:
    """``x`` as a finite float within ``[lo, hi]``, or raise naming ``name``."""
    if isinstance(x, bool) or not isinstance(x, (int, float)):
        raise CalibrationFormatError(f"{name!r} must be a number, got {_excerpt(x)}")
    try:
        v = float(x)
    except OverflowError:
        raise CalibrationFormatError(
            f"{name!r} is an integer of {len(str(x))} digits, outside its domain "
            f"[{lo:g}, {hi:g}]; {_ACTION}"
        ) from None
    if not math.isfinite(v):
        raise CalibrationFormatError(
            f"{name!r} must be a finite number, got {_excerpt(x)}; write null for an unknown value"
        )
    if not lo <= v <= hi:
        raise CalibrationFormatError(
            f"{name!r} is {v:g}, outside its domain [{lo:g}, {hi:g}]; {_ACTION}"
        )
    return v


def _excerpt(x: Any) -> str:
    r = repr(x)
    return r if len(r) <= 40 else r[:37] + "..."


def _array(v: Any, name: str, shape: tuple[int, ...], *, nullable: bool = False,
           lo: float = -math.inf, hi: float = math.inf) -> np.ndarray:
    """A nested JSON list of ``shape`` as floats (null → NaN if ``nullable``), domain-checked."""
    def walk(x: Any, dims: tuple[int, ...], where: str) -> Any:
        if not dims:
            if x is None and nullable:
                return math.nan
            return _number(x, where, lo, hi)
        if not isinstance(x, list) or len(x) != dims[0]:
            kind = (f"a list of {shape[0]} numbers" if len(shape) == 1 else
                    f"a {shape[0]}×{shape[1]} list of lists of numbers")
            raise CalibrationFormatError(f"{name!r} must be {kind}")
        return [walk(e, dims[1:], f"{where}[{i}]") for i, e in enumerate(x)]

    return np.array(walk(v, shape, name), dtype=float)


def _matrix3(value: Any, name: str) -> tuple[tuple[float, ...], ...]:
    try:
        a = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise CalibInputError(f"{name} must be 3x3 numbers, got {value!r}") from None
    if a.shape != (3, 3):
        raise CalibInputError(f"{name} must be 3x3, got shape {a.shape}")
    return tuple(tuple(float(x) for x in r) for r in a)


@dataclass(frozen=True)
class Consistency:
    """A chi-square test of the fit's residuals against the measured noise.

    Attributes
    ----------
    chi2 : float
        Sum of squared whitened residuals.
    dof : int
        Redundant degrees of freedom (equations minus parameters).
    p_value : float
        Probability of a chi-square this large or larger if the model and noise are right.
    ok : bool
        Whether the fit is consistent: ``p_value`` at or above the test's level, or the excess
        scatter ordinary by the rule of :mod:`gyrocal.calib.dispersion` (DESIGN.md fact 7).
    excess : float
        How much more the residuals scatter than the white noise explains, as a fraction
        (``sqrt(χ²/dof) − 1`` before the widening); 0 when the white noise explains them. The
        fit's σ are widened by the excess (between-window) variance when it is positive.
        Written (with ``scatter`` and ``reason``) only when positive; a document without them
        reads as 0.
    scatter : float
        The excess between-window scatter relative to the measured signal (gravity, the turn
        rate), the number the rule compares with its tolerance.
    reason : str
        Why the fit is not consistent (a window that does not fit, or scatter beyond what
        real windows show), empty otherwise.
    """

    chi2: float
    dof: int
    p_value: float
    ok: bool
    excess: float = 0.0
    scatter: float = 0.0
    reason: str = ""

    @property
    def verdict(self) -> str:
        """``consistent``, ``consistent, with X % scatter beyond the noise (σ widened)`` or
        ``not consistent`` (with its reason): the rule of :mod:`gyrocal.calib.dispersion`."""
        if not self.ok:
            return "not consistent" + (f" ({self.reason})" if self.reason else "")
        if self.excess > 0:
            return (f"consistent, with {100 * self.excess:.0f} % scatter beyond the noise "
                    "(σ widened)")
        return "consistent"

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form."""
        d: dict[str, Any] = {"chi2": self.chi2, "dof": self.dof, "p_value": self.p_value,
                             "ok": self.ok}
        if self.excess > 0 or self.reason:
            d.update(excess=self.excess, scatter=self.scatter, reason=self.reason)
        return d

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> Consistency:
        """Inverse of :meth:`to_dict`; raises :class:`CalibrationFormatError` on bad fields.

        ``chi2`` must be non-negative, ``p_value`` within [0, 1], ``dof`` a non-negative integer.
        """
        if not isinstance(d, Mapping):
            raise CalibrationFormatError("'consistency' must be an object")
        _refuse_unknown(d, _CONSISTENCY_FIELDS + _CONSISTENCY_EXTRA, "'consistency'")
        for name in _CONSISTENCY_FIELDS:
            if name not in d:
                raise CalibrationFormatError(f"'consistency' lacks the field {name!r}")
        ok, dof = d["ok"], d["dof"]
        if not isinstance(ok, bool):
            raise CalibrationFormatError("'consistency.ok' must be true or false")
        if isinstance(dof, bool) or not isinstance(dof, int):
            raise CalibrationFormatError("'consistency.dof' must be a non-negative integer")
        _number(dof, "consistency.dof", *LIMITS["count"])
        chi2 = _number(d["chi2"], "consistency.chi2", 0.0)
        p = _number(d["p_value"], "consistency.p_value", 0.0, 1.0)
        excess = _number(d.get("excess", 0.0), "consistency.excess", 0.0)
        scatter = _number(d.get("scatter", 0.0), "consistency.scatter", 0.0)
        reason = d.get("reason", "")
        if not isinstance(reason, str):
            raise CalibrationFormatError("'consistency.reason' must be a string")
        return cls(chi2=chi2, dof=int(dof), p_value=p, ok=ok, excess=excess, scatter=scatter,
                   reason=reason)


@dataclass(frozen=True)
class ModelChoice:
    """Why a calibration has the model it has: each model's predicted error in general motion.

    The full model ``g = A (m + b)`` is kept when its predicted RMS error over all directions of
    a general motion is below the diagonal model's, which also leaves out the cross-axis terms
    (:func:`gyrocal.calib.design.choose_model`). Figures are RMS rate errors per rad/s of a
    motion at 1 rad/s (:func:`gyrocal.calib.design.general_motion_rms`).

    Attributes
    ----------
    full : float or None
        The full model's predicted error, from its covariance; None when the recording cannot
        determine it (no poses, or poses that leave a combination undetermined).
    diagonal : float
        The diagonal model's: its covariance's share and the cross-axis terms' in quadrature.
    diagonal_cross_axis : float
        The cross-axis terms' share of ``diagonal``
        (:func:`gyrocal.calib.design.cross_axis_general_motion_rms`).
    cross_axis : float
        The cross-axis sensitivity the sensor's datasheet allows, a fraction of the rate.
    """

    full: float | None
    diagonal: float
    diagonal_cross_axis: float
    cross_axis: float

    @property
    def chosen(self) -> str:
        """``"full"`` when the full model is determined and predicted better, else
        ``"diagonal"``."""
        return "full" if self.full is not None and self.full < self.diagonal else "diagonal"

    def sentence(self) -> str:
        """Both predicted figures and the choice, as the note, the terminal and the report say
        it."""
        full = ("not determined by this recording" if self.full is None
                else f"{self.full:.2g}")
        diag_fit = math.sqrt(max(self.diagonal**2 - self.diagonal_cross_axis**2, 0.0))
        return (f"model chosen by predicted general-motion error (RMS per rad/s): full "
                f"{full}, diagonal {self.diagonal:.2g} ({diag_fit:.2g} from its uncertainty "
                f"and {self.diagonal_cross_axis:.2g} from the cross-axis terms it leaves out, "
                f"±{100 * self.cross_axis:g} % on the datasheet): the {self.chosen} model")

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form."""
        return {"full": self.full, "diagonal": self.diagonal,
                "diagonal_cross_axis": self.diagonal_cross_axis, "cross_axis": self.cross_axis}

    @classmethod
    def from_dict(cls, d: Any) -> ModelChoice:
        """Inverse of :meth:`to_dict`; raises :class:`CalibrationFormatError` on bad fields."""
        if not isinstance(d, Mapping):
            raise CalibrationFormatError("'model_choice' must be an object")
        _refuse_unknown(d, _CHOICE_KEYS, "'model_choice'")
        for name in _CHOICE_KEYS:
            if name not in d:
                raise CalibrationFormatError(f"'model_choice' lacks the field {name!r}")
        full = None if d["full"] is None else _number(d["full"], "model_choice.full", 0.0)
        return cls(full=full, diagonal=_number(d["diagonal"], "model_choice.diagonal", 0.0),
                   diagonal_cross_axis=_number(d["diagonal_cross_axis"],
                                               "model_choice.diagonal_cross_axis", 0.0),
                   cross_axis=_number(d["cross_axis"], "model_choice.cross_axis", 0.0, 1.0))


def _vec3(value: Any, name: str, *, positive: bool = False) -> tuple[float, float, float]:
    try:
        a = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise CalibInputError(f"{name} must be 3 numbers, got {value!r}") from None
    if a.shape != (3,):
        raise CalibInputError(f"{name} must be 3 numbers, got shape {a.shape}")
    if not np.all(np.isfinite(a)):
        raise CalibInputError(f"{name} must be finite, got {a.tolist()}")
    if positive and not np.all(a > 0):
        raise CalibInputError(f"{name} must be positive, got {a.tolist()}")
    return (float(a[0]), float(a[1]), float(a[2]))


def _std3(value: Any, name: str) -> tuple[float, float, float]:
    a = np.asarray(value, dtype=float)
    if a.shape != (3,):
        raise CalibInputError(f"{name} must be 3 numbers, got shape {a.shape}")
    return (float(a[0]), float(a[1]), float(a[2]))


def _same(a: tuple[float, ...], b: np.ndarray) -> bool:
    return bool(np.allclose(a, b, rtol=1e-12, atol=0.0, equal_nan=True))


@dataclass(frozen=True)
class GyroCalibration:
    """A triaxial gyroscope's calibration: ``g = scale ∘ (m + bias)`` (paper Eq. 1), or the full
    model ``g = matrix @ (m + bias)`` when ``matrix`` is set (Calibration v2).

    Attributes
    ----------
    scale : tuple of 3 float
        Dimensionless scale factors ``k_x, k_y, k_z``; with ``matrix``, its diagonal.
    bias : tuple of 3 float
        Biases ``b_x, b_y, b_z`` in rad/s, added to the reading before scaling.
    scale_std, bias_std : tuple of 3 float
        One-sigma uncertainties (NaN where unknown); with ``matrix_std``, ``scale_std`` is its
        diagonal.
    covariance : tuple of tuples of float or None
        6×6 covariance of ``(k_x, k_y, k_z, b_x, b_y, b_z)``; with ``matrix``, 12×12 covariance of
        the matrix row-major then the bias.
    method : str
        The estimator (``iterative-ls``, ``levenberg-marquardt``, ``paired-axis``, ...).
    iterations : int
        Iterations the estimator used.
    consistency : Consistency or None
        The chi-square verdict, where the estimator has redundant degrees of freedom.
    sensor : dict
        What is known of the sensor (model, odr_hz, full_scale_dps, ...).
    temperature_c : float or None
        Mean die temperature during the calibration.
    created : str or None
        ISO-8601 creation time.
    source : str or None
        Where the data came from (a recording path, ``simulation``, ...).
    axes : dict or None
        Optional diagnostics: each servo's estimated rotation axis in the sensor frame.
    matrix : tuple of 3 tuples of 3 float or None
        The full model's 3×3 matrix ``A``, row-major; None for the diagonal (v1) model.
    matrix_std : tuple of 3 tuples of 3 float or None
        One-sigma uncertainty of each entry of ``matrix``.
    frame : str or None
        Identifier of the frame convention the matrix is expressed in (hardware_docs/method.md).
    kinematics : dict or None
        The gimbal as the full-model fit estimated it: ``chain`` (servo IDs, base first),
        ``axes`` (one unit vector per servo in the sensor frame at the reference angles) and
        ``reference_angles_rad``; input of ``calib.kinematics``. Where the fit knew where
        gravity points, also the home pose "up" refers to: ``home_angles_rad`` (every servo's
        encoder angle there) and ``up_servo`` (``[servo ID, ±1]``: "up" is that servo's axis,
        signed, in the home pose), so the specific force ``f`` of ``g_sensitivity`` follows
        from any later encoder angles (:attr:`gravity_reference`,
        :func:`gyrocal.calib.kinematics.gravity_up`); absent in older documents (unknown).
    temperature_model : ThermalModel or None
        Bias (and scale or matrix) against die temperature (:mod:`gyrocal.calib.thermal`),
        written as the document's ``temperature_model`` in either version.
    g_sensitivity : dict or None
        Full model only: ``{"matrix": G (3×3, rad/s per g), "matrix_std": its one-sigma,
        "directions": the k unit vectors of specific force G was determined along}`` of
        ``g = A (m + bias + G f)`` (:func:`gyrocal.calib.estimators.fit_full_matrix`); ``bias``
        is then the zero-g bias.
    accelerometer : AccelCalibration or None
        The accelerometer's calibration from the same run's rests (:mod:`gyrocal.calib.accel`),
        written as the document's ``accelerometer`` in either version.
    bias_drift : BiasDrift or None
        The bias instability and rate random walk the bias's σ includes (their variance over
        the run) and the bias's expected wander in the hour after the calibration
        (:mod:`gyrocal.calib.drift`), written as the document's ``bias_drift`` in either
        version; None in older documents (σ then has the white noise only).
    model_choice : ModelChoice or None
        Each model's predicted general-motion error, which chose this one (``gyrocal
        estimate``'s method ``auto``), written as the document's ``model_choice`` in either
        version; None for a method given by name, and in older documents.
    """

    scale: tuple[float, float, float]
    bias: tuple[float, float, float]
    scale_std: tuple[float, float, float] = (math.nan, math.nan, math.nan)
    bias_std: tuple[float, float, float] = (math.nan, math.nan, math.nan)
    covariance: tuple[tuple[float, ...], ...] | None = None
    method: str = "unknown"
    iterations: int = 0
    consistency: Consistency | None = None
    sensor: dict[str, Any] = field(default_factory=dict, hash=False)
    temperature_c: float | None = None
    created: str | None = None
    source: str | None = None
    axes: dict[str, Any] | None = field(default=None, hash=False)
    matrix: tuple[tuple[float, ...], ...] | None = None
    matrix_std: tuple[tuple[float, ...], ...] | None = None
    frame: str | None = None
    kinematics: dict[str, Any] | None = field(default=None, hash=False)
    temperature_model: ThermalModel | None = field(default=None, hash=False)
    g_sensitivity: dict[str, Any] | None = field(default=None, hash=False)
    accelerometer: AccelCalibration | None = field(default=None, hash=False)
    bias_drift: BiasDrift | None = field(default=None, hash=False)
    model_choice: ModelChoice | None = field(default=None, hash=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "scale", _vec3(self.scale, "scale", positive=True))
        object.__setattr__(self, "bias", _vec3(self.bias, "bias"))
        for name in ("scale_std", "bias_std"):
            object.__setattr__(self, name, _std3(getattr(self, name), name))
        if self.matrix is None:
            if self.matrix_std is not None or self.kinematics is not None:
                raise CalibInputError("matrix_std and kinematics need a matrix (the full model)")
        else:
            self._init_matrix()
        if self.kinematics is not None:
            try:
                object.__setattr__(self, "kinematics", _read_kinematics(self.kinematics))
            except CalibrationFormatError as exc:
                raise CalibInputError(str(exc)) from None
        if self.g_sensitivity is not None:
            if self.matrix is None:
                raise CalibInputError("g_sensitivity needs a matrix (the full model)")
            try:
                object.__setattr__(self, "g_sensitivity", _read_g(self.g_sensitivity))
            except CalibrationFormatError as exc:
                raise CalibInputError(str(exc)) from None
        if self.covariance is not None:
            n = 6 if self.matrix is None else 12
            c = np.asarray(self.covariance, dtype=float)
            if c.shape != (n, n):
                raise CalibInputError(f"covariance must be {n}x{n}, got shape {c.shape}")
            object.__setattr__(self, "covariance", tuple(tuple(float(x) for x in r) for r in c))

    def _init_matrix(self) -> None:
        """Check ``matrix``/``matrix_std`` and keep ``scale``/``scale_std`` their diagonals."""
        a = _matrix3(self.matrix, "matrix")
        if not np.all(np.isfinite(a)):
            raise CalibInputError("matrix must be finite")
        if not _same(self.scale, np.diag(a)):
            raise CalibInputError(f"scale {list(self.scale)} must be the diagonal of matrix")
        object.__setattr__(self, "matrix", a)
        if self.matrix_std is not None:
            s = _matrix3(self.matrix_std, "matrix_std")
            if not (np.all(np.isnan(self.scale_std)) or _same(self.scale_std, np.diag(s))):
                raise CalibInputError("scale_std must be the diagonal of matrix_std")
            object.__setattr__(self, "matrix_std", s)
            object.__setattr__(self, "scale_std", tuple(float(x) for x in np.diag(s)))

    # ------------------------------------------------------------------ use
    @property
    def full_matrix(self) -> np.ndarray:
        """The model's 3×3 matrix ``A`` (a copy): ``matrix``, or ``diag(scale)`` for v1."""
        return np.diag(self.scale) if self.matrix is None else np.array(self.matrix)

    @property
    def g_rate_error_per_g(self) -> float:
        """The most that leaving out ``G f`` moves a calibrated rate, rad/s per g of specific
        force: ``max_i ‖(A G)_i‖₂`` (for a unit ``f`` along the worst direction of row ``i``);
        0 without :attr:`g_sensitivity`. What a reader or a target that ignores G is off by."""
        if self.g_sensitivity is None:
            return 0.0
        AG = self.full_matrix @ np.asarray(self.g_sensitivity["matrix"], dtype=float)
        return float(np.max(np.linalg.norm(AG, axis=1)))

    @property
    def gravity_reference(self) -> tuple[np.ndarray, tuple[int, int]] | None:
        """``(home encoder angles (S,), (servo ID, sign))`` of the home pose that the
        g-sensitivity's "up" refers to (``kinematics.home_angles_rad``, ``up_servo``), or None
        where the document does not say (older calibrations, fits without gravity)."""
        k = self.kinematics
        if k is None or "home_angles_rad" not in k:
            return None
        sid, sign = k["up_servo"]
        return np.array(k["home_angles_rad"], dtype=float), (int(sid), int(sign))

    @property
    def is_full(self) -> bool:
        """Whether this is the full model (Calibration v2), with cross-axis terms."""
        return self.matrix is not None

    def apply(self, m: np.ndarray | list[float] | tuple[float, ...],
              temperature_c: float | np.ndarray | None = None,
              specific_force: np.ndarray | list[float] | tuple[float, ...] | None = None,
              ) -> np.ndarray:
        """Calibrated rate ``A (m + bias)`` for one reading or many.

        ``A`` is :attr:`full_matrix`, so a v1 calibration gives the paper's Eq. (1),
        ``scale ∘ (m + bias)``. With a :attr:`temperature_model` and the die temperature of the
        readings, ``A(T) (m + b(T))`` instead (:mod:`gyrocal.calib.thermal`; a bias-only model
        keeps ``A``); a temperature outside the model's covered range is clamped to it, with a
        :class:`~gyrocal.calib.thermal.ThermalRangeWarning`.

        Parameters
        ----------
        m : array_like, shape (3,) or (N, 3)
            Raw readings in rad/s (datasheet sensitivity applied, nothing else).
        temperature_c : float or array_like (N,), optional
            Die temperature of the readings, °C; ignored without a temperature model.
        specific_force : array_like, shape (3,) or (N, 3), optional
            The specific force at the sensor in g, sensor frame (an accelerometer's reading beside
            the gyro; +1 g up when still). With :attr:`g_sensitivity` the rate is
            ``A (m + bias + G f)``; without it a :class:`GSensitivityWarning` says that the
            g-sensitivity is not applied. Ignored (with no warning) without ``g_sensitivity``.

        Returns
        -------
        numpy.ndarray
            The calibrated rates, same shape as ``m``.
        """
        a = np.asarray(m, dtype=float)
        if a.ndim not in (1, 2) or a.shape[-1] != 3:
            raise CalibInputError(f"readings must have shape (3,) or (N, 3), got {a.shape}")
        if not np.all(np.isfinite(a)):
            raise CalibInputError("readings contain NaN or inf; drop or repair those samples first")
        if self.g_sensitivity is not None:
            a = a + self._g_offset(specific_force, a.shape)
        if self.temperature_model is not None and temperature_c is not None:
            from gyrocal.calib.thermal import apply_thermal

            return apply_thermal(self.temperature_model, self.full_matrix, a, temperature_c)
        if self.matrix is None:
            return np.asarray(self.scale) * (a + np.asarray(self.bias))
        return (a + np.asarray(self.bias)) @ self.full_matrix.T

    def _g_offset(self, force: Any, shape: tuple[int, ...]) -> np.ndarray | float:
        """``G f`` for :meth:`apply` (0, with a warning, when ``force`` is None)."""
        if force is None:
            import warnings

            warnings.warn(
                "g-sensitivity NOT applied: this calibration's bias is the zero-g bias, so "
                "without the specific force the rate is off by up to |A G| x 1 g; pass "
                "specific_force (the accelerometer's reading, g)", GSensitivityWarning,
                stacklevel=3)
            return 0.0
        f = np.asarray(force, dtype=float)
        if f.shape[-1:] != (3,) or f.ndim > 2 or (f.ndim == 2 and f.shape[0] != (
                shape[0] if len(shape) == 2 else 1)):
            raise CalibInputError(
                f"specific_force must have shape (3,) or one row per reading, got {f.shape}")
        if not np.all(np.isfinite(f)):
            raise CalibInputError("specific_force contains NaN or inf")
        return f @ np.asarray(self.g_sensitivity["matrix"]).T  # type: ignore[index]

    @property
    def covariance_matrix(self) -> np.ndarray | None:
        """The covariance as an array (a copy; 6×6 for v1, 12×12 for v2), or None."""
        return None if self.covariance is None else np.array(self.covariance)

    # ------------------------------------------------------------------ the document
    def to_dict(self) -> dict[str, Any]:
        """The Calibration document as a JSON-ready dict (NaN becomes null).

        Version 1 for the diagonal model; version 2, with ``matrix``, ``matrix_std``, ``frame``
        and ``kinematics``, for the full one (``scale``/``scale_std`` still written as their
        diagonals for version 1 readers).
        """

        def num(x: float) -> float | None:
            return None if not math.isfinite(x) else x

        def grid(rows: tuple[tuple[float, ...], ...] | None) -> list[list[float | None]] | None:
            return None if rows is None else [[num(x) for x in r] for r in rows]

        full = self.matrix is not None
        doc: dict[str, Any] = {
            "format": FORMAT,
            "version": VERSION_FULL if full else VERSION,
            "model": MODEL_FULL if full else MODEL,
            "scale": list(self.scale),
            "bias": list(self.bias),
            "scale_std": [num(x) for x in self.scale_std],
            "bias_std": [num(x) for x in self.bias_std],
            "covariance": grid(self.covariance),
            "method": self.method,
            "iterations": self.iterations,
            "consistency": None if self.consistency is None else self.consistency.to_dict(),
            "sensor": dict(self.sensor),
            "temperature_c": self.temperature_c,
            "created": self.created,
            "source": self.source,
        }
        if self.axes is not None:
            doc["axes"] = copy.deepcopy(self.axes)
        if full:
            doc["matrix"] = grid(self.matrix)
            doc["matrix_std"] = grid(self.matrix_std)
            doc["frame"] = self.frame
            doc["kinematics"] = copy.deepcopy(self.kinematics)
            if self.g_sensitivity is not None:
                g = self.g_sensitivity
                doc["g_sensitivity"] = {"model": MODEL_G, "matrix": grid(g["matrix"]),
                                        "matrix_std": grid(g["matrix_std"]),
                                        "directions": [list(v) for v in g["directions"]]}
        if self.temperature_model is not None:
            doc["temperature_model"] = self.temperature_model.to_dict()
        if self.accelerometer is not None:
            doc["accelerometer"] = self.accelerometer.to_dict()
        if self.bias_drift is not None:
            doc["bias_drift"] = self.bias_drift.to_dict()
        if self.model_choice is not None:
            doc["model_choice"] = self.model_choice.to_dict()
        return doc

    def to_json(self) -> str:
        """The Calibration document (:meth:`to_dict`) as indented JSON text."""
        return json.dumps(self.to_dict(), indent=2, allow_nan=False)

    @classmethod
    def from_dict(cls, doc: Mapping[str, Any]) -> GyroCalibration:
        """Read a Calibration document, version 1 or 2, strictly.

        Raises
        ------
        CalibrationFormatError
            If the format or version is not ``gyrocal-calibration`` v1/v2, a field is unknown
            (the message suggests the nearest known name), missing or malformed, or a number is
            outside its domain (:data:`LIMITS`; probabilities in [0, 1], standard deviations and
            variances non-negative, everything finite); the message names the field.
        """
        if not isinstance(doc, Mapping):
            raise CalibrationFormatError("a calibration document must be a JSON object")
        full = _check_header(doc)
        known = (_V1_FIELDS + _THERMAL_FIELDS + _ACCEL_FIELDS + _DRIFT_FIELDS + _CHOICE_FIELDS
                 + (_V2_FIELDS if full else ()))
        _refuse_unknown(doc, known,
                        f"a version {VERSION_FULL if full else VERSION} calibration")
        kw = _read_model(doc, full)
        try:
            return cls(**kw, **_read_about(doc))
        except CalibInputError as exc:
            raise CalibrationFormatError(str(exc)) from None

    @classmethod
    def from_json(cls, text: str) -> GyroCalibration:
        """Parse Calibration JSON text (see :meth:`from_dict`)."""
        try:
            doc = json.loads(text)
        except json.JSONDecodeError as exc:
            raise CalibrationFormatError(f"not valid JSON: {exc}") from None
        except (ValueError, RecursionError) as exc:  # 5000-digit integers, deep nesting
            raise CalibrationFormatError(f"not a usable JSON document: {str(exc)[:80]}") from None
        return cls.from_dict(doc)


def _check_header(doc: Mapping[str, Any]) -> bool:
    """Check ``format``, ``version`` and ``model``; True for version 2 (the full model)."""
    if doc.get("format") != FORMAT:
        raise CalibrationFormatError(
            f"not a gyrocal calibration: 'format' is {_excerpt(doc.get('format'))}, "
            f"expected {FORMAT!r}"
        )
    version = doc.get("version")
    if isinstance(version, bool) or version not in (VERSION, VERSION_FULL):
        raise CalibrationFormatError(
            f"calibration version {_excerpt(version)} is not supported (this gyrocal reads "
            f"versions {VERSION} and {VERSION_FULL}); upgrade gyrocal or re-export the calibration"
        )
    full = version == VERSION_FULL
    if full and doc.get("matrix") is None:
        raise CalibrationFormatError("a version 2 calibration lacks the field 'matrix'")
    model = MODEL_FULL if full else MODEL
    if "model" in doc and doc["model"] != model:
        raise CalibrationFormatError(
            f"'model' is {_excerpt(doc['model'])}, expected {model!r} in a version {version} "
            "calibration"
        )
    return full


def _read_model(doc: Mapping[str, Any], full: bool) -> dict[str, Any]:
    """The model's numbers: scale, bias, their uncertainties, covariance, matrix, kinematics."""
    def optional(name: str, shape: tuple[int, ...], **kw: Any) -> np.ndarray | None:
        return None if doc.get(name) is None else _array(doc[name], name, shape, **kw)

    kw: dict[str, Any] = {}
    for name in ("scale", "bias"):
        value = optional(name, (3,), lo=LIMITS[name][0], hi=LIMITS[name][1])
        if value is None:
            raise CalibrationFormatError(f"the calibration lacks the field {name!r}")
        kw[name] = tuple(value)
    scale = np.array(kw["scale"])
    for name in ("scale_std", "bias_std"):
        std = optional(name, (3,), nullable=True, lo=0.0)
        kw[name] = (math.nan,) * 3 if std is None else tuple(std)
    n = 12 if full else 6
    cov = optional("covariance", (n, n), nullable=True)
    if cov is not None and np.any(np.diag(cov) < 0):
        raise CalibrationFormatError("'covariance' has a negative variance on its diagonal; "
                                     "a covariance matrix's diagonal is never negative")
    kw["covariance"] = cov
    if full:
        matrix = _array(doc["matrix"], "matrix", (3, 3), lo=-LIMITS["scale"][1],
                        hi=LIMITS["scale"][1])
        off = matrix[~np.eye(3, dtype=bool)]
        if np.any(np.abs(off) > LIMITS["cross_axis"][1]):
            raise CalibrationFormatError(
                f"'matrix' has a cross-axis term beyond ±{LIMITS['cross_axis'][1]:g} "
                f"({np.max(np.abs(off)):g}): the sensor axes would be mislabelled; {_ACTION}")
        if not _same(tuple(scale), np.diag(matrix)):
            raise CalibrationFormatError("'scale' must be the diagonal of 'matrix'")
        kw["matrix"] = matrix
        kw["matrix_std"] = optional("matrix_std", (3, 3), nullable=True, lo=0.0)
        if kw["matrix_std"] is not None:
            kw["scale_std"] = (math.nan,) * 3
        frame = doc.get("frame")
        if frame is not None and not isinstance(frame, str):
            raise CalibrationFormatError("'frame' must be a string or null")
        kw["frame"] = frame
        kw["kinematics"] = doc.get("kinematics")
        kw["g_sensitivity"] = _read_g(doc.get("g_sensitivity"))
    return kw


def _read_g(g: Any) -> dict[str, Any] | None:
    """Check a ``g_sensitivity`` object (model, matrix, matrix_std, directions); None stays
    None. Returns it with tuples."""
    if g is None:
        return None
    if not isinstance(g, Mapping):
        raise CalibrationFormatError("'g_sensitivity' must be an object or null")
    _refuse_unknown(g, _G_FIELDS, "'g_sensitivity'")

    def lists(x: Any) -> Any:  # tuples (a GyroCalibration's own) read as JSON lists
        return [lists(e) for e in x] if isinstance(x, (list, tuple)) else x

    g = {k: lists(v) for k, v in g.items()}
    for name in ("matrix", "directions"):
        if name not in g:
            raise CalibrationFormatError(f"'g_sensitivity' lacks the field {name!r}")
    if g.get("model", MODEL_G) != MODEL_G:
        raise CalibrationFormatError(
            f"'g_sensitivity.model' is {_excerpt(g.get('model'))}, expected {MODEL_G!r}")
    G = _array(g["matrix"], "g_sensitivity.matrix", (3, 3), lo=-MAX_G_SENSITIVITY,
               hi=MAX_G_SENSITIVITY)
    std = (np.full((3, 3), math.nan) if g.get("matrix_std") is None else
           _array(g["matrix_std"], "g_sensitivity.matrix_std", (3, 3), nullable=True, lo=0.0))
    d = g["directions"]
    if not isinstance(d, (list, tuple)) or len(d) > 3:
        raise CalibrationFormatError("'g_sensitivity.directions' must list 0 to 3 unit vectors")
    V = _array(list(d), "g_sensitivity.directions", (len(d), 3)) if d else np.zeros((0, 3))
    if V.size and not np.allclose(V @ V.T, np.eye(len(d)), atol=1e-6):
        raise CalibrationFormatError("'g_sensitivity.directions' must be orthonormal")
    return {"matrix": tuple(tuple(float(x) for x in r) for r in G),
            "matrix_std": tuple(tuple(float(x) for x in r) for r in std),
            "directions": tuple(tuple(float(x) for x in r) for r in V)}


def _read_kinematics(k: Any) -> dict[str, Any] | None:
    """Check a ``kinematics`` object (chain, unit axes, reference angles); None stays None."""
    if k is None:
        return None
    if not isinstance(k, Mapping):
        raise CalibrationFormatError("'kinematics' must be an object or null")
    _refuse_unknown(k, _KINEMATICS_FIELDS + _KINEMATICS_HOME, "'kinematics'")
    for name in _KINEMATICS_FIELDS:
        if name not in k:
            raise CalibrationFormatError(f"'kinematics' lacks the field {name!r}")
    chain = k["chain"]
    if (not isinstance(chain, list) or not chain or len(chain) > 16 or
            any(isinstance(i, bool) or not isinstance(i, int) or not 0 <= i <= 252 for i in chain)
            or len(set(chain)) != len(chain)):
        raise CalibrationFormatError(
            "'kinematics.chain' must list 1 to 16 distinct servo IDs (0-252), base first")
    s = len(chain)
    axes = _array(k["axes"], "kinematics.axes", (s, 3))
    if np.any(np.abs(np.linalg.norm(axes, axis=1) - 1.0) > 1e-6):  # as calib.kinematics
        raise CalibrationFormatError("'kinematics.axes' must be unit vectors, one per servo")
    angles = _array(k["reference_angles_rad"], "kinematics.reference_angles_rad", (s,))
    out = {"chain": list(chain), "axes": axes.tolist(), "reference_angles_rad": angles.tolist()}
    given = [name in k and k[name] is not None for name in _KINEMATICS_HOME]
    if any(given):
        if not all(given):
            raise CalibrationFormatError("'kinematics.home_angles_rad' and 'kinematics.up_servo' "
                                         "go together (the home pose and its 'up'): give both "
                                         "or neither")
        home = _array(k["home_angles_rad"], "kinematics.home_angles_rad", (s,))
        up = k["up_servo"]
        if (not isinstance(up, (list, tuple)) or len(up) != 2
                or any(isinstance(v, bool) or not isinstance(v, int) for v in up)
                or up[0] not in chain or up[1] not in (1, -1)):
            raise CalibrationFormatError(
                f"'kinematics.up_servo' must be [servo ID of the chain {list(chain)}, 1 or -1], "
                f"got {_excerpt(up)}")
        out["home_angles_rad"] = home.tolist()
        out["up_servo"] = [int(up[0]), int(up[1])]
    return out


def _read_about(doc: Mapping[str, Any]) -> dict[str, Any]:
    """The descriptive fields: method, iterations, consistency, sensor, temperature, provenance."""
    method = doc.get("method", "unknown")
    if not isinstance(method, str):
        raise CalibrationFormatError("'method' must be a string")
    iterations = doc.get("iterations", 0)
    if isinstance(iterations, bool) or not isinstance(iterations, int):
        raise CalibrationFormatError("'iterations' must be a non-negative integer")
    _number(iterations, "iterations", *LIMITS["count"])
    cons = doc.get("consistency")
    sensor = doc.get("sensor") or {}
    if not isinstance(sensor, Mapping):
        raise CalibrationFormatError("'sensor' must be an object")
    temp = doc.get("temperature_c")
    if temp is not None:
        temp = _number(temp, "temperature_c", *LIMITS["temperature_c"])
    for name in ("created", "source"):
        if doc.get(name) is not None and not isinstance(doc[name], str):
            raise CalibrationFormatError(f"{name!r} must be a string or null")
    axes = doc.get("axes")
    if axes is not None and not isinstance(axes, Mapping):
        raise CalibrationFormatError("'axes' must be an object")
    return {
        "method": method,
        "iterations": iterations,
        "consistency": None if cons is None else Consistency.from_dict(cons),
        "sensor": dict(sensor),
        "temperature_c": temp,
        "created": doc.get("created"),
        "source": doc.get("source"),
        "axes": None if axes is None else dict(axes),
        "temperature_model": _read_thermal(doc.get("temperature_model")),
        "accelerometer": _read_accel(doc.get("accelerometer")),
        "bias_drift": (None if doc.get("bias_drift") is None
                       else BiasDrift.from_dict(doc["bias_drift"])),
        "model_choice": (None if doc.get("model_choice") is None
                         else ModelChoice.from_dict(doc["model_choice"])),
    }


def _read_thermal(doc: Any) -> ThermalModel | None:
    """The ``temperature_model`` object (:meth:`gyrocal.calib.thermal.ThermalModel.from_dict`),
    or None."""
    if doc is None:
        return None
    from gyrocal.calib.thermal import ThermalModel

    return ThermalModel.from_dict(doc)


def _read_accel(doc: Any) -> AccelCalibration | None:
    """The ``accelerometer`` object (:meth:`gyrocal.calib.accel.AccelCalibration.from_dict`),
    or None."""
    if doc is None:
        return None
    from gyrocal.calib.accel import AccelCalibration

    return AccelCalibration.from_dict(doc)
