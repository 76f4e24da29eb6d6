"""The calibration model and its result document.

The model is the paper's Eq. (1): the true rate ``g`` and the reading ``m`` (both rad/s) satisfy

    g = scale ∘ (m + bias),

elementwise per sensor axis. :class:`GyroCalibration` holds the six parameters with their
uncertainty and how they were obtained, applies them to readings, and round-trips through the
Calibration v1 JSON document (DESIGN.md, "Contracts").
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from gyrocal.calib.errors import CalibInputError, CalibrationFormatError

__all__ = ["FORMAT", "VERSION", "Consistency", "GyroCalibration"]

FORMAT = "gyrocal-calibration"
VERSION = 1
MODEL = "g = scale * (m + bias)"


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
        Whether the residuals are consistent (``p_value`` at or above the test's level).
    """

    chi2: float
    dof: int
    p_value: float
    ok: bool

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form."""
        return {"chi2": self.chi2, "dof": self.dof, "p_value": self.p_value, "ok": self.ok}

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> Consistency:
        """Inverse of :meth:`to_dict`; raises :class:`CalibrationFormatError` on bad fields."""
        if not isinstance(d, Mapping):
            raise CalibrationFormatError("'consistency' must be an object")
        try:
            chi2, dof, p, ok = d["chi2"], d["dof"], d["p_value"], d["ok"]
        except KeyError as exc:
            raise CalibrationFormatError(f"'consistency' lacks the field {exc.args[0]!r}") from None
        if not isinstance(ok, bool):
            raise CalibrationFormatError("'consistency.ok' must be true or false")
        if isinstance(dof, bool) or not isinstance(dof, int) or dof < 0:
            raise CalibrationFormatError("'consistency.dof' must be a non-negative integer")
        for name, v in (("chi2", chi2), ("p_value", p)):
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                raise CalibrationFormatError(f"'consistency.{name}' must be a finite number")
        return cls(chi2=float(chi2), dof=int(dof), p_value=float(p), ok=ok)


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


@dataclass(frozen=True)
class GyroCalibration:
    """Scale factors and biases of a triaxial gyroscope, ``g = scale ∘ (m + bias)`` (paper Eq. 1).

    Attributes
    ----------
    scale : tuple of 3 float
        Dimensionless scale factors ``k_x, k_y, k_z``.
    bias : tuple of 3 float
        Biases ``b_x, b_y, b_z`` in rad/s, added to the reading before scaling.
    scale_std, bias_std : tuple of 3 float
        One-sigma uncertainties.
    covariance : tuple of 6 tuples of 6 float
        Covariance of ``(k_x, k_y, k_z, b_x, b_y, b_z)``.
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

    def __post_init__(self) -> None:
        object.__setattr__(self, "scale", _vec3(self.scale, "scale", positive=True))
        object.__setattr__(self, "bias", _vec3(self.bias, "bias"))
        for name in ("scale_std", "bias_std"):
            a = np.asarray(getattr(self, name), dtype=float)
            if a.shape != (3,):
                raise CalibInputError(f"{name} must be 3 numbers, got shape {a.shape}")
            object.__setattr__(self, name, tuple(float(x) for x in a))
        if self.covariance is not None:
            c = np.asarray(self.covariance, dtype=float)
            if c.shape != (6, 6):
                raise CalibInputError(f"covariance must be 6x6, got shape {c.shape}")
            object.__setattr__(self, "covariance", tuple(tuple(float(x) for x in r) for r in c))

    # ------------------------------------------------------------------ use
    def apply(self, m: np.ndarray | list[float] | tuple[float, ...]) -> np.ndarray:
        """Calibrated rate ``scale ∘ (m + bias)`` (paper Eq. 1) for one reading or many.

        Parameters
        ----------
        m : array_like, shape (3,) or (N, 3)
            Raw readings in rad/s (datasheet sensitivity applied, nothing else).

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
        return np.asarray(self.scale) * (a + np.asarray(self.bias))

    @property
    def covariance_matrix(self) -> np.ndarray | None:
        """The covariance as a 6×6 array (a copy), or None."""
        return None if self.covariance is None else np.array(self.covariance)

    # ------------------------------------------------------------------ Calibration v1
    def to_dict(self) -> dict[str, Any]:
        """The Calibration v1 document as a JSON-ready dict (NaN becomes null)."""

        def num(x: float) -> float | None:
            return None if not math.isfinite(x) else x

        doc: dict[str, Any] = {
            "format": FORMAT,
            "version": VERSION,
            "model": MODEL,
            "scale": list(self.scale),
            "bias": list(self.bias),
            "scale_std": [num(x) for x in self.scale_std],
            "bias_std": [num(x) for x in self.bias_std],
            "covariance": None
            if self.covariance is None
            else [[num(x) for x in r] for r in self.covariance],
            "method": self.method,
            "iterations": self.iterations,
            "consistency": None if self.consistency is None else self.consistency.to_dict(),
            "sensor": dict(self.sensor),
            "temperature_c": self.temperature_c,
            "created": self.created,
            "source": self.source,
        }
        if self.axes is not None:
            doc["axes"] = self.axes
        return doc

    def to_json(self) -> str:
        """The Calibration v1 document as indented JSON text."""
        return json.dumps(self.to_dict(), indent=2, allow_nan=False)

    @classmethod
    def from_dict(cls, doc: Mapping[str, Any]) -> GyroCalibration:
        """Read a Calibration v1 document.

        Raises
        ------
        CalibrationFormatError
            If the format or version is not ``gyrocal-calibration`` v1, or a field is missing or
            malformed; the message names the field.
        """
        if not isinstance(doc, Mapping):
            raise CalibrationFormatError("a calibration document must be a JSON object")
        if doc.get("format") != FORMAT:
            raise CalibrationFormatError(
                f"not a gyrocal calibration: 'format' is {doc.get('format')!r}, "
                f"expected {FORMAT!r}"
            )
        version = doc.get("version")
        if version != VERSION or isinstance(version, bool):
            raise CalibrationFormatError(
                f"calibration version {version!r} is not supported (this gyrocal reads version "
                f"{VERSION}); upgrade gyrocal or re-export the calibration"
            )
        if "model" in doc and doc["model"] != MODEL:
            raise CalibrationFormatError(f"'model' is {doc['model']!r}, expected {MODEL!r}")

        def vec(name: str, required: bool = True) -> tuple[float, ...]:
            if name not in doc or doc[name] is None:
                if required:
                    raise CalibrationFormatError(f"the calibration lacks the field {name!r}")
                return (math.nan,) * 3
            v = doc[name]
            if not isinstance(v, list) or len(v) != 3:
                raise CalibrationFormatError(f"{name!r} must be a list of 3 numbers")
            out = []
            for x in v:
                if x is None and not required:
                    out.append(math.nan)
                elif isinstance(x, bool) or not isinstance(x, (int, float)) or not math.isfinite(x):
                    raise CalibrationFormatError(f"{name!r} must be a list of 3 finite numbers")
                else:
                    out.append(float(x))
            return tuple(out)

        scale, bias = vec("scale"), vec("bias")
        if not all(s > 0 for s in scale):
            raise CalibrationFormatError("'scale' must be positive")
        cov = doc.get("covariance")
        if cov is not None:
            ok = isinstance(cov, list) and len(cov) == 6
            ok = ok and all(isinstance(r, list) and len(r) == 6 for r in cov)
            ok = ok and all(
                x is None or (isinstance(x, (int, float)) and not isinstance(x, bool))
                for r in cov
                for x in r
            )
            if not ok:
                raise CalibrationFormatError("'covariance' must be a 6x6 list of numbers")
            cov = tuple(tuple(math.nan if x is None else float(x) for x in r) for r in cov)
        method = doc.get("method", "unknown")
        if not isinstance(method, str):
            raise CalibrationFormatError("'method' must be a string")
        iterations = doc.get("iterations", 0)
        if isinstance(iterations, bool) or not isinstance(iterations, int) or iterations < 0:
            raise CalibrationFormatError("'iterations' must be a non-negative integer")
        cons = doc.get("consistency")
        consistency = None if cons is None else Consistency.from_dict(cons)
        sensor = doc.get("sensor") or {}
        if not isinstance(sensor, Mapping):
            raise CalibrationFormatError("'sensor' must be an object")
        temp = doc.get("temperature_c")
        if temp is not None and (isinstance(temp, bool) or not isinstance(temp, (int, float))):
            raise CalibrationFormatError("'temperature_c' must be a number or null")
        for name in ("created", "source"):
            if doc.get(name) is not None and not isinstance(doc[name], str):
                raise CalibrationFormatError(f"{name!r} must be a string or null")
        axes = doc.get("axes")
        if axes is not None and not isinstance(axes, Mapping):
            raise CalibrationFormatError("'axes' must be an object")
        return cls(
            scale=scale,  # type: ignore[arg-type]
            bias=bias,  # type: ignore[arg-type]
            scale_std=vec("scale_std", required=False),  # type: ignore[arg-type]
            bias_std=vec("bias_std", required=False),  # type: ignore[arg-type]
            covariance=cov,
            method=method,
            iterations=iterations,
            consistency=consistency,
            sensor=dict(sensor),
            temperature_c=None if temp is None else float(temp),
            created=doc.get("created"),
            source=doc.get("source"),
            axes=None if axes is None else dict(axes),
        )

    @classmethod
    def from_json(cls, text: str) -> GyroCalibration:
        """Parse Calibration v1 JSON text (see :meth:`from_dict`)."""
        try:
            doc = json.loads(text)
        except json.JSONDecodeError as exc:
            raise CalibrationFormatError(f"not valid JSON: {exc}") from None
        return cls.from_dict(doc)
