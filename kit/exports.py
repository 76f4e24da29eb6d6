"""Exporters: gyrocal's JSON documents rendered in the formats other tools read.

:data:`EXPORTERS` maps a format name (``gyrocal export --format NAME``) to an :class:`Exporter`
that names the document kinds it accepts and renders one of them as text. A new format is one
:func:`register` call with a render function; its options become ``gyrocal export`` flags. The
formats for other programs live in their own modules, registered at the end of this one:
:mod:`gyrocal.kit.exports_ros` (Kalibr, ROS, imu_calib), :mod:`gyrocal.kit.exports_accel` and
:mod:`gyrocal.kit.exports_thermal` (the flight stacks).

Document kinds (the ``format`` field of the JSON):

``gyrocal-calibration`` (v2, the full matrix, or v1, the diagonal model)
    A Calibration (:class:`gyrocal.calib.model.GyroCalibration`).
``gyrocal-noise`` (v1)
    Noise figures from ``gyrocal noise`` (:class:`gyrocal.calib.allan.NoiseCharacterisation`).
"""

from __future__ import annotations

import json
import math
import re
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

from gyrocal.calib.errors import CalibrationFormatError
from gyrocal.kit import __version__
from gyrocal.kit.errors import InputError

__all__ = [
    "DOCUMENT_KINDS",
    "EXPORTERS",
    "ExportOption",
    "Exporter",
    "export",
    "load_document",
    "read_json",
    "register",
    "validate_document",
]


def _read_calibration(doc: Mapping[str, Any]) -> Any:
    from gyrocal.calib.model import GyroCalibration

    return GyroCalibration.from_dict(doc)


def _read_noise(doc: Mapping[str, Any]) -> Any:
    from gyrocal.calib.allan import NoiseCharacterisation

    return NoiseCharacterisation.from_dict(doc)


#: Document kind -> reader that validates it (raises CalibrationFormatError naming the field).
DOCUMENT_KINDS: dict[str, Callable[[Mapping[str, Any]], Any]] = {
    "gyrocal-calibration": _read_calibration,
    "gyrocal-noise": _read_noise,
}


@dataclass(frozen=True)
class ExportOption:
    """A format-specific option, offered as ``gyrocal export --NAME``.

    Attributes
    ----------
    name : str
        Option name (``rostopic``); the flag is ``--rostopic`` (underscores become dashes).
    type : callable
        Converts the flag's text (``float``, ``str``).
    help : str
    """

    name: str
    type: Callable[[str], Any]
    help: str


@dataclass(frozen=True)
class Exporter:
    """One export format.

    Attributes
    ----------
    name : str
        The ``--format`` value.
    accepts : tuple of str
        Document kinds it renders (keys of :data:`DOCUMENT_KINDS`).
    description : str
        One line for ``--help``.
    render : callable
        ``render(doc, options) -> (text, notes)``: ``doc`` is the validated JSON document,
        ``options`` the given options by name; ``notes`` are messages for the user (stderr).
    options : tuple of ExportOption
    suffix : str
        Usual file suffix.
    """

    name: str
    accepts: tuple[str, ...]
    description: str
    render: Callable[[Mapping[str, Any], Mapping[str, Any]], tuple[str, list[str]]]
    options: tuple[ExportOption, ...] = ()
    suffix: str = ".txt"


#: Format name -> exporter, in ``--help`` order.
EXPORTERS: dict[str, Exporter] = {}


def register(exporter: Exporter) -> Exporter:
    """Add ``exporter`` to :data:`EXPORTERS` (its name must be new, its kinds known)."""
    if exporter.name in EXPORTERS:
        raise ValueError(f"an exporter named {exporter.name!r} is already registered")
    unknown = set(exporter.accepts) - set(DOCUMENT_KINDS)
    if unknown:
        raise ValueError(f"exporter {exporter.name!r} accepts unknown kinds {sorted(unknown)}")
    EXPORTERS[exporter.name] = exporter
    return exporter


def validate_document(doc: Any, where: str = "the document") -> str:
    """Check that ``doc`` is a known gyrocal document; return its kind.

    Raises
    ------
    InputError
        Naming what is wrong (not JSON object, unknown kind, bad version or field).
    """
    if not isinstance(doc, Mapping):
        raise InputError(f"{where} is not a JSON object; give a gyrocal JSON document")
    kind = doc.get("format")
    if kind not in DOCUMENT_KINDS:
        raise InputError(
            f"{where} has 'format' {kind!r}; gyrocal exports "
            f"{', '.join(sorted(DOCUMENT_KINDS))} documents"
        )
    try:
        DOCUMENT_KINDS[kind](doc)
    except CalibrationFormatError as exc:
        raise InputError(f"{where}: {exc}") from None
    return str(kind)


def read_json(path: str, what: str = "document") -> Any:
    """The JSON value in the file ``path`` (``-``: standard input), read through the checked
    reader (:func:`gyrocal.kit.fileio.read_input_bytes`: a regular file, readable, bounded)
    and parsed within bounds: an integer of more than :data:`MAX_INT_DIGITS` digits, nesting
    deeper than Python's recursion allows, or a key given twice in one object (``bias`` twice:
    which one was meant?) is refused.

    Raises
    ------
    InputError
        Naming ``what`` and ``path``: no such file, unreadable, too large, or not JSON.
    """
    from gyrocal.kit.fileio import read_input_bytes

    data, where = read_input_bytes(path, what)
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise InputError(f"{where} is not UTF-8 text (byte {exc.start}); give a gyrocal JSON "
                         "document") from None
    try:
        return json.loads(text, parse_int=_bounded_int, object_pairs_hook=_unique_keys)
    except json.JSONDecodeError as exc:
        raise InputError(f"{where} is not valid JSON: {exc}") from None
    except RecursionError:
        raise InputError(f"{where}: arrays or objects nested too deeply; not a gyrocal "
                         "document") from None
    except ValueError as exc:  # _bounded_int, _unique_keys
        raise InputError(f"{where}: {exc}") from None


#: Most digits an integer in a gyrocal document may have (its integers are versions, counts and
#: servo ids; Python refuses more than 4300 digits with an error of its own).
MAX_INT_DIGITS = 20


def _bounded_int(text: str) -> int:
    digits = len(text.lstrip("-"))
    if digits > MAX_INT_DIGITS:
        raise ValueError(f"an integer of {digits} digits; a gyrocal document has none longer "
                         f"than {MAX_INT_DIGITS}")
    return int(text)


def _unique_keys(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for k, v in pairs:
        if k in out:
            raise ValueError(f"the key {k[:40]!r} is given twice in one object; keep one")
        out[k] = v
    return out


def load_document(path: str, kind: str, what: str) -> Any:
    """Read a ``kind`` document (a key of :data:`DOCUMENT_KINDS`) from ``path``.

    Returns
    -------
    GyroCalibration or NoiseCharacterisation
        What the kind's reader makes of it.

    Raises
    ------
    InputError
        Naming ``what`` and ``path``: unreadable, not JSON, or not a valid document of ``kind``.
    """
    doc = read_json(path, what)
    try:
        return DOCUMENT_KINDS[kind](doc)
    except CalibrationFormatError as exc:
        raise InputError(f"{what} {path}: {exc}") from None


def export(
    doc: Mapping[str, Any], fmt: str, options: Mapping[str, Any] | None = None
) -> tuple[str, list[str]]:
    """Render a gyrocal document in format ``fmt``.

    Parameters
    ----------
    doc : mapping
        A ``gyrocal-calibration`` or ``gyrocal-noise`` JSON document.
    fmt : str
        A key of :data:`EXPORTERS`.
    options : mapping, optional
        Format options by name (see each exporter's ``options``).

    Returns
    -------
    (text, notes)

    Raises
    ------
    InputError
        Unknown format, a document kind the format does not take, or an option it lacks.
    """
    exporter = EXPORTERS.get(fmt)
    if exporter is None:
        raise InputError(f"unknown export format {fmt!r}; choose one of {', '.join(EXPORTERS)}")
    kind = validate_document(doc)
    if kind not in exporter.accepts:
        raise InputError(
            f"--format {fmt} takes a {' or '.join(exporter.accepts)} document, not {kind}"
        )
    opts = dict(options or {})
    known = {o.name for o in exporter.options}
    extra = sorted(set(opts) - known)
    if extra:
        flags = ", ".join("--" + e.replace("_", "-") for e in extra)
        raise InputError(f"{flags} does not apply to --format {fmt}")
    return exporter.render(doc, opts)


# ---------------------------------------------------------------------------- json
def _render_json(doc: Mapping[str, Any], options: Mapping[str, Any]) -> tuple[str, list[str]]:
    return json.dumps(doc, indent=2, allow_nan=False) + "\n", []


register(
    Exporter(
        name="json",
        accepts=("gyrocal-calibration", "gyrocal-noise"),
        description="the document itself, validated and pretty-printed",
        render=_render_json,
        suffix=".json",
    )
)


# ---------------------------------------------------------------------------- shared text helpers
_PLAIN_KEY = re.compile(r"[A-Za-z_][A-Za-z0-9_]*\Z")
#: Plain words a YAML 1.1 reader (PyYAML, ROS 1) would take for a boolean or null.
_YAML_SPECIAL = {"y", "n", "yes", "no", "on", "off", "true", "false", "null"}


def _yaml_float(x: float) -> str:
    """A float as YAML that both YAML 1.1 (PyYAML, ROS 1) and 1.2 (yaml-cpp, ROS 2) read back
    exactly as a float: shortest round-trip digits, always with a decimal point."""
    if not math.isfinite(x):
        raise InputError(f"cannot export the non-finite number {x!r}")
    r = repr(float(x))
    mant, _, exp = r.partition("e")
    if "." not in mant:
        mant += ".0"
    return mant + ("e" + exp if exp else "")


def _yaml_scalar(v: Any) -> str:
    if v is None:
        return "null"
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        return _yaml_float(v)
    if isinstance(v, str):
        return json.dumps(v)  # a JSON string is a YAML double-quoted scalar
    raise InputError(f"cannot export a value of type {type(v).__name__}: {v!r}")


def _yaml_key(k: Any) -> str:
    k = str(k)
    return k if _PLAIN_KEY.match(k) and k.lower() not in _YAML_SPECIAL else json.dumps(k)


def _yaml_flow(v: Any) -> str:
    if isinstance(v, Mapping):
        return "{" + ", ".join(f"{_yaml_key(k)}: {_yaml_flow(x)}" for k, x in v.items()) + "}"
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_yaml_flow(x) for x in v) + "]"
    return _yaml_scalar(v)


def _yaml_block(key: str, v: Any, indent: int = 0) -> list[str]:
    """``key: value`` in block style: mappings nest by indentation, lists of scalars and of
    flat lists are written in flow style (``[a, b, c]``), one row per line for a matrix."""
    pad = " " * indent
    k = _yaml_key(key)
    if isinstance(v, Mapping) and v:
        lines = [f"{pad}{k}:"]
        for kk, vv in v.items():
            lines += _yaml_block(kk, vv, indent + 2)
        return lines
    if isinstance(v, (list, tuple)) and v and all(isinstance(r, (list, tuple)) for r in v):
        return [f"{pad}{k}:"] + [f"{pad}  - {_yaml_flow(r)}" for r in v]
    return [f"{pad}{k}: {_yaml_flow(v)}"]


def _std_text(x: float | None, unit: str = "") -> str:
    if x is None or not math.isfinite(x):
        return "not estimated"
    return f"{x:.3g}{unit}"


def _verdict(cal: Any) -> str:
    c = cal.consistency
    if c is None:
        return "not tested (no redundant observations)"
    return f"chi2 = {c.chi2:.1f} on {c.dof} dof, p = {c.p_value:.3g} ({_verdict_words(c)})"


def _verdict_words(c: Any) -> str:
    """:attr:`gyrocal.calib.model.Consistency.verdict` (consistent, consistent with scatter and
    σ widened, or not consistent with its reason), in ASCII for the files other tools read."""
    return c.verdict.replace("σ", "sigma")


def _one_line(text: Any, limit: int = 200) -> str:
    """``text`` as one line of printable ASCII, safe inside a YAML ``#`` comment or C comment.

    Every line break a YAML or C reader knows (``\\n``, ``\\r``, U+0085, U+2028, U+2029), every
    other control character and every non-ASCII character is written as a backslash escape, so a
    hostile string (``sensor.model`` comes from a recording's manifest) stays in its comment. At
    most ``limit`` characters.
    """
    out = str(text).encode("ascii", "backslashreplace").decode("ascii")
    out = _CONTROL.sub(lambda m: f"\\x{ord(m.group()):02x}", out)
    return out if len(out) <= limit else out[: limit - 3] + "..."


_CONTROL = re.compile(r"[\x00-\x1f\x7f]")


def _num_text(v: Any) -> str | None:
    """A finite JSON number as ``%g`` text; None for anything else (a string, NaN, bool)."""
    ok = isinstance(v, (int, float)) and not isinstance(v, bool)
    if not ok:
        return None
    try:
        return f"{float(v):g}" if math.isfinite(float(v)) else None
    except OverflowError:
        return None


def _sensor_text(sensor: Mapping[str, Any]) -> str:
    """The sensor as one safe comment line: model, ODR, full scale (non-numbers quoted)."""
    if not sensor:
        return "unknown"
    parts = [str(sensor.get("model", "unknown model"))]
    for key, fmt in (("odr_hz", "{} Hz"), ("full_scale_dps", "+-{} dps full scale")):
        v = sensor.get(key)
        if v is not None:
            text = _num_text(v)
            parts.append(fmt.format(text) if text is not None else f"{key} {v!r} (not a number)")
    return _one_line(", ".join(parts))


def _model_lines(cal: Any, prefix: str) -> list[str]:
    """Comment lines stating the model the calibration holds (v1 diagonal or v2 full matrix,
    with g-sensitivity where it has it)."""
    if not cal.is_full:
        return [f"{prefix}Model (paper Eq. 1), elementwise per sensor axis x, y, z:",
                f"{prefix}    g = scale * (m + bias)"]
    if cal.g_sensitivity is not None:
        return [
            f"{prefix}Model (Calibration v2, the full matrix with g-sensitivity), with i, j, k",
            f"{prefix}over the axes x, y, z:",
            f"{prefix}    g = matrix @ (m + bias + g_sensitivity.matrix @ f)",
            f"{prefix}    g[i] = sum over j of matrix[i][j] * (m[j] + bias[j]",
            f"{prefix}                          + sum over k of G[j][k] * f[k])",
            f"{prefix}  matrix  3x3, row by row, dimensionless: scale factors on the diagonal,",
            f"{prefix}          cross-axis sensitivities off it; frame convention "
            f"{_one_line(cal.frame or 'not stated')}",
            f"{prefix}  G       g_sensitivity.matrix, rad/s per g; f the specific force at the",
            f"{prefix}          sensor in g, same frame (the accelerometer's reading: +1 g up when",
            f"{prefix}          still); bias is then the zero-g bias",
        ]
    return [
        f"{prefix}Model (Calibration v2, the full matrix), with i, j over the axes x, y, z:",
        f"{prefix}    g = matrix @ (m + bias)",
        f"{prefix}    g[i] = sum over j of matrix[i][j] * (m[j] + bias[j])",
        f"{prefix}  matrix  3x3, row by row, dimensionless: scale factors on the diagonal,",
        f"{prefix}          cross-axis sensitivities off it; frame convention "
        f"{_one_line(cal.frame or 'not stated')}",
    ]


def g_sensitivity_note(cal: Any, target: str) -> list[str]:
    """The note for a target with no place for a calibration's g-sensitivity (none without
    one): what is lost, at most ``GyroCalibration.g_rate_error_per_g`` per g."""
    if cal.g_sensitivity is None:
        return []
    return [f"{target} has no place for the gyro's g-sensitivity (g_sensitivity.matrix): it is "
            f"not carried, so the rate is off by up to {cal.g_rate_error_per_g:.2g} rad/s per g "
            "of specific "
            "force; apply it where the accelerometer is read (gyrocal export --format "
            "c-header or yaml carries it)"]


# ---------------------------------------------------------------------------- yaml
def _render_yaml(doc: Mapping[str, Any], options: Mapping[str, Any]) -> tuple[str, list[str]]:
    from gyrocal.calib.model import GyroCalibration

    cal = GyroCalibration.from_dict(doc)
    d = cal.to_dict()  # normalised: every field present, NaN as null
    v = d["version"]
    lines = [
        f"# gyrocal calibration (Calibration v{v}) as YAML, written by gyrocal {__version__}.",
        "# The same fields as the JSON document; converted back to JSON it is a valid",
        f"# Calibration v{v} (gyrocal export --format json reads only JSON).",
        "#",
        *_model_lines(cal, "# "),
        "#   m      raw gyro reading, rad/s (raw counts times the datasheet sensitivity, nothing",
        "#          else)",
        "#   g      calibrated angular rate, rad/s",
        "#   scale  scale factors, dimensionless" + (" (the diagonal of matrix)" if v == 2 else ""),
        "#   bias   rad/s, ADDED to the reading before scaling: a still sensor reads m = -bias",
        "#   scale_std, bias_std  one-sigma uncertainties (dimensionless; rad/s)",
        "#   covariance  " + (
            "12x12, of (matrix row by row, bias_x, bias_y, bias_z)" if v == 2
            else "6x6, of (scale_x, scale_y, scale_z, bias_x, bias_y, bias_z), row by row"),
        f"# Sensor: {_sensor_text(cal.sensor)}.",
        f"# Consistency: {_verdict(cal)}.",
    ]
    comments = {
        "scale": "# scale factors (dimensionless)",
        "bias": "# biases, rad/s (added to the reading before scaling)",
        "scale_std": "# one-sigma, dimensionless",
        "bias_std": "# one-sigma, rad/s",
        "covariance": "# order (matrix row by row, bias_x, bias_y, bias_z); units 1 and rad/s"
                      if v == 2 else "# order (scale_x, scale_y, scale_z, bias_x, bias_y, bias_z); "
                      "units 1 and rad/s",
        "temperature_c": "# mean die temperature during the calibration, degrees C",
        "axes": "# each servo's rotation axis in the sensor frame (unit vector), its angle to\n"
                "# the nearest sensor axis and that angle's one-sigma, degrees",
        "matrix": "# g = matrix @ (m + bias); row i gives axis i of g, dimensionless",
        "matrix_std": "# one-sigma of each entry of matrix",
        "kinematics": "# the gimbal as the fit estimated it: servo IDs base first, their axes in\n"
                      "# the sensor frame at the reference encoder angles (rad)",
        "g_sensitivity": "# G of g = matrix @ (m + bias + G f), rad/s per g of specific force f;\n"
                         "# its one-sigma, and the directions of f the run determined it along",
        "accelerometer": "# the accelerometer from the same run's rests: f = matrix @ (a + bias),\n"
                         "# a the reading and f the specific force in m/s^2, bias m/s^2, matrix\n"
                         "# lower triangular (frame accel-x-xy); covariance of (the lower\n"
                         "# triangle row by row, bias); gravity_m_s2 the gravity it was fitted to",
    }
    for key, value in d.items():
        if key in comments:
            lines.append(comments[key])
        lines += _yaml_block(key, value)
    return "\n".join(lines) + "\n", []


register(
    Exporter(
        name="yaml",
        accepts=("gyrocal-calibration",),
        description="the calibration as a plain YAML document (same fields as the JSON)",
        render=_render_yaml,
        suffix=".yaml",
    )
)


# ---------------------------------------------------------------------------- c-header
_C_IDENT = re.compile(r"[A-Za-z_][A-Za-z0-9_]*\Z")


def _c_float(x: float) -> str:
    """A float literal (suffix f) with 9 significant digits: enough to give the nearest float."""
    if not math.isfinite(x):
        raise InputError(f"cannot write the non-finite number {x!r} to a C header")
    s = f"{x:.9g}"
    if "." not in s and "e" not in s:
        s += ".0"
    return f"({s}f)" if s.startswith("-") else s + "f"


def _c_comment(text: Any) -> str:
    """Text that stays inside a C block comment: one line (:func:`_one_line`), no ``*/``, and no
    ``??`` (a trigraph under ``-std=c99``)."""
    return _one_line(text).replace("*/", "* /").replace("/*", "/ *").replace("??", "? ?")


_AXES = "XYZ"


def _c_header_comment(cal: Any, P: str, sens_ok: bool) -> list[str]:
    """The header's opening comment: model, units, provenance, uncertainties."""
    k_std = "  ".join(f"k_{a} {_std_text(s)}" for a, s in zip("xyz", cal.scale_std, strict=True))
    b_std = "  ".join(f"b_{a} {_std_text(s)}" for a, s in zip("xyz", cal.bias_std, strict=True))
    if cal.is_full:
        model = [
            " * Model (Calibration v2, the full matrix), with i, j over the axes x, y, z:",
            " *",
            " *     g[i] = sum over j of A[i][j] * (m[j] + b[j])",
            " *",
            f" *   A  3x3 matrix, dimensionless ({P}_MATRIX_XX, _XY, ... _ZZ: row, column):",
            " *      scale factors on the diagonal, cross-axis sensitivities off it; frame",
            f" *      convention {_c_comment(cal.frame or 'not stated')}",
        ]
    else:
        model = [
            " * Model (Calibration v1, the paper's Eq. 1), per sensor axis i = x, y, z:",
            " *",
            " *     g[i] = k[i] * (m[i] + b[i])",
            " *",
            f" *   k  scale factor, dimensionless ({P}_SCALE_X, _Y, _Z)",
        ]
    if cal.g_sensitivity is not None:
        model += [
            " *",
            " * With g-sensitivity (the document's g_sensitivity), with k over x, y, z too:",
            " *",
            " *     g[i] = sum over j of A[i][j] * (m[j] + b[j] + sum over k of G[j][k] * f[k])",
            " *",
            f" *   G  rad/s per g ({P}_GSENS_XX, _XY, ... _ZZ: row, column); f the specific force",
            " *      at the sensor in g, same frame: the accelerometer's reading (+1 g up when",
            f" *      still). b is then the zero-g bias: apply with {P.lower()}_apply_force();",
            f" *      {P.lower()}_apply() leaves G out (off by up to |A G| x 1 g)",
        ]
    lines = [
        "/*",
        f" * Gyroscope calibration for firmware, written by gyrocal {__version__} from a "
        f"Calibration v{2 if cal.is_full else 1} document.",
        " *",
        *model,
        " *   m  raw gyro reading in rad/s: raw counts times the datasheet sensitivity, nothing",
        " *      else" + (f" ({P}_SENSITIVITY_RAD_S_PER_LSB below)" if sens_ok else ""),
        " *   g  calibrated angular rate, rad/s",
        f" *   b  bias in rad/s ({P}_BIAS_X, _Y, _Z), ADDED to the reading before scaling:",
        " *      a still sensor reads m = -b",
        " *",
        f" * Sensor: {_c_comment(_sensor_text(cal.sensor))}",
        f" * Method: {_c_comment(cal.method)} ({cal.iterations} iterations)",
        f" * Consistency: {_c_comment(_verdict(cal))}",
    ]
    if cal.temperature_c is not None:
        lines.append(f" * Mean die temperature during the calibration: "
                     f"{cal.temperature_c:.1f} degrees C")
    return lines + [
        f" * Created: {_c_comment(cal.created or 'unknown')}",
        f" * Source: {_c_comment(cal.source or 'unknown')}",
        " *",
        " * One-sigma standard deviations:",
        f" *   {k_std}  (dimensionless" + (", the diagonal of A)" if cal.is_full else ")"),
        f" *   {b_std}  (rad/s)",
        " */",
    ]


def _c_constants(cal: Any, P: str) -> list[str]:
    """``#define``s of the scale factors (v1) or the matrix (v2), then the biases."""
    if cal.is_full:
        lines = [f"/* The matrix A, dimensionless: {P}_MATRIX_<row><column>. */"]
        std = cal.matrix_std or ((math.nan,) * 3,) * 3
        for i, row in enumerate(cal.matrix):
            for j, a in enumerate(row):
                lines.append(f"#define {P}_MATRIX_{_AXES[i]}{_AXES[j]} {_c_float(a)} "
                             f"/* std {_std_text(std[i][j])} */")
    else:
        lines = ["/* Scale factors k, dimensionless. */"]
        for a, k, s in zip(_AXES, cal.scale, cal.scale_std, strict=True):
            lines.append(f"#define {P}_SCALE_{a} {_c_float(k)} /* std {_std_text(s)} */")
    lines += ["", "/* Biases b, rad/s, added to the reading before scaling. */"]
    for a, b, s in zip(_AXES, cal.bias, cal.bias_std, strict=True):
        lines.append(f"#define {P}_BIAS_{a} {_c_float(b)} /* rad/s, std {_std_text(s)} */")
    if cal.g_sensitivity is not None:
        lines += ["", f"/* g-sensitivity G, rad/s per g: {P}_GSENS_<row><column>. */"]
        g = cal.g_sensitivity
        for i, row in enumerate(g["matrix"]):
            for j, x in enumerate(row):
                lines.append(f"#define {P}_GSENS_{_AXES[i]}{_AXES[j]} {_c_float(x)} "
                             f"/* std {_std_text(g['matrix_std'][i][j])} */")
    return lines


def _c_apply(cal: Any, P: str, fn: str) -> list[str]:
    """The inline apply function: ``g = A (m + b)``, or ``g = k * (m + b)`` per axis."""
    if cal.is_full:
        what = "g = A * (m + b)"
        body = [f"    const float {c} = m_rad_s[{i}] + {P}_BIAS_{a};"
                for i, (c, a) in enumerate(zip("xyz", _AXES, strict=True))]
        body += [
            f"    g_rad_s[{i}] = {P}_MATRIX_{r}X * x + {P}_MATRIX_{r}Y * y + {P}_MATRIX_{r}Z * z;"
            for i, r in enumerate(_AXES)
        ]
    else:
        what = "g = k * (m + b) on each axis"
        body = [f"    const float {c} = {P}_SCALE_{a} * (m_rad_s[{i}] + {P}_BIAS_{a});"
                for i, (c, a) in enumerate(zip("xyz", _AXES, strict=True))]
        body += [f"    g_rad_s[{i}] = {c};" for i, c in enumerate("xyz")]
    lines = [
        "/*",
        f" * Apply the calibration: {what}. m_rad_s and g_rad_s are",
        " * {x, y, z} in rad/s; they may be the same array (in place).",
        " */",
        f"static inline void {fn}(const float m_rad_s[3], float g_rad_s[3])",
        "{",
        *body,
        "}",
    ]
    if cal.g_sensitivity is None:
        return lines
    rows = [f"    y[{i}] = m_rad_s[{i}] + " + " + ".join(
        f"{P}_GSENS_{r}{c} * f_g[{j}]" for j, c in enumerate(_AXES)) + ";"
        for i, r in enumerate(_AXES)]
    return lines + [
        "",
        "/*",
        " * Apply the calibration with g-sensitivity: g = A * (m + b + G * f). f_g is the",
        " * specific force {x, y, z} in g (the accelerometer's reading, +1 g up when still);",
        " * g_rad_s may be m_rad_s (in place).",
        " */",
        f"static inline void {fn}_force(const float m_rad_s[3], const float f_g[3], "
        "float g_rad_s[3])",
        "{",
        "    float y[3];",
        *rows,
        f"    {fn}(y, g_rad_s);",
        "}",
    ]


def _render_c_header(
    doc: Mapping[str, Any], options: Mapping[str, Any]
) -> tuple[str, list[str]]:
    from gyrocal.calib.model import GyroCalibration

    cal = GyroCalibration.from_dict(doc)
    prefix = options.get("c_prefix") or "GYROCAL"
    if not _C_IDENT.match(prefix):
        raise InputError(f"--c-prefix {prefix!r} is not a C identifier (letters, digits, _)")
    P, fn = prefix.upper(), prefix.lower() + "_apply"
    guard = f"{P}_CALIBRATION_H"
    sens = cal.sensor.get("sensitivity_rad_s_per_lsb")
    sens_ok = _num_text(sens) is not None and sens > 0
    lines = [*_c_header_comment(cal, P, sens_ok), f"#ifndef {guard}", f"#define {guard}", "",
             *_c_constants(cal, P)]
    if sens_ok:
        lines += [
            "",
            "/* Datasheet sensitivity the readings were converted with: m = counts * this. */",
            f"#define {P}_SENSITIVITY_RAD_S_PER_LSB {_c_float(float(sens))}",
        ]
    lines += ["", *_c_apply(cal, P, fn)]
    if cal.accelerometer is not None:
        lines += ["", *_c_accel(cal.accelerometer, P, prefix.lower() + "_accel_apply")]
    if cal.temperature_model is not None:
        lines += ["", *_c_thermal(cal, P, fn)]
    lines += ["", f"#endif /* {guard} */"]
    notes = []
    if cal.g_sensitivity is not None and cal.temperature_model is not None:
        notes.append(f"{fn}_at() (the temperature model) leaves the g-sensitivity out: add "
                     "G f to the reading first, as " + fn + "_force() does")
    return "\n".join(lines) + "\n", notes


def _c_accel(acc: Any, P: str, fn: str) -> list[str]:
    """The accelerometer's calibration (Calibration ``accelerometer``, :mod:`gyrocal.calib.accel`):
    ``f = A (a + b)`` as constants and ``<prefix>_accel_apply``."""
    import numpy as np

    std = acc.std
    a_std = np.zeros((3, 3))
    a_std[np.tril_indices(3)] = std[:6]
    lines = [
        "/*",
        " * The accelerometer, calibrated against gravity from the same run's rests:",
        " *",
        " *     f[i] = sum over j of A_ACC[i][j] * (a[j] + b_acc[j])",
        " *",
        f" *   A_ACC  3x3, dimensionless ({P}_ACCEL_MATRIX_XX ... _ZZ), lower triangular: frame",
        f" *          convention {_c_comment(ACCEL_FRAME_TEXT)}",
        " *   a      raw accelerometer reading in m/s^2 (datasheet sensitivity applied, nothing",
        " *          else); f the calibrated specific force, m/s^2",
        f" *   b_acc  bias in m/s^2 ({P}_ACCEL_BIAS_X, _Y, _Z), ADDED to the reading",
        f" * Local gravity the fit used: {acc.gravity:.6f} m/s^2; consistency: "
        f"{_c_comment(_consistency_text(acc.consistency))}; {acc.rests} rests.",
        " */",
    ]
    for i in range(3):
        for j in range(3):
            lines.append(f"#define {P}_ACCEL_MATRIX_{_AXES[i]}{_AXES[j]} "
                         f"{_c_float(float(acc.matrix[i][j]))} /* std {_std_text(a_std[i, j])} */")
    for i, a in enumerate(_AXES):
        lines.append(f"#define {P}_ACCEL_BIAS_{a} {_c_float(float(acc.bias[i]))} "
                     f"/* m/s^2, std {_std_text(float(std[6 + i]))} */")
    lines.append(f"#define {P}_ACCEL_GRAVITY_M_S2 {_c_float(float(acc.gravity))}")
    body = [f"    const float {c} = a_m_s2[{i}] + {P}_ACCEL_BIAS_{a};"
            for i, (c, a) in enumerate(zip("xyz", _AXES, strict=True))]
    body += [f"    f_m_s2[{i}] = {P}_ACCEL_MATRIX_{r}X * x + {P}_ACCEL_MATRIX_{r}Y * y + "
             f"{P}_ACCEL_MATRIX_{r}Z * z;" for i, r in enumerate(_AXES)]
    return [*lines, "",
            "/* Apply the accelerometer's calibration: f = A_ACC * (a + b_acc), m/s^2; in place "
            "allowed. */",
            f"static inline void {fn}(const float a_m_s2[3], float f_m_s2[3])", "{", *body, "}"]


def _consistency_text(c: Any) -> str:
    if c is None:
        return "not tested"
    return (f"{_verdict_words(c)}: residuals against the measured noise "
            f"(chi2 = {c.chi2:.1f} on {c.dof} dof, p = {c.p_value:.3g})")


#: How the exports name the accelerometer's frame convention.
ACCEL_FRAME_TEXT = "accel-x-xy (x along the accelerometer's x axis, y in its x-y plane)"


def _c_thermal(cal: Any, P: str, fn: str) -> list[str]:
    """The temperature model (Calibration ``temperature_model``, calib.thermal) as constant
    tables and ``<fn>_at(m, die_c, g)``: ``g = A(T) (m + b(T))`` with ``T`` clamped to the
    covered range, ``b`` a polynomial in ``T − reference`` (Horner), ``A`` linear in it."""
    import numpy as np

    tm = cal.temperature_model
    n = tm.bias_order + 1
    lo, hi = tm.range_c

    def arr(values: Any) -> str:
        if np.ndim(values) == 0:
            return _c_float(float(values))
        return "{" + ", ".join(arr(v) for v in values) + "}"

    lines = [
        "/*",
        f" * Temperature model ({tm.kind}; {tm.points} points): bias b(T) a polynomial of order "
        f"{n - 1} in",
        f" * (T - {P}_TEMP_REFERENCE_C), coefficients in ascending powers; "
        + ("the gain A(T) = A0 + A1 (T - reference)."
           if tm.gain_coeffs is not None else "the gain is the constant one above."),
        f" * Valid over {lo:.2f} to {hi:.2f} degrees C of die temperature: outside, T is clamped",
        " * to the nearest end (never extrapolated).",
        " */",
        f"#define {P}_TEMP_REFERENCE_C {_c_float(tm.reference_c)}",
        f"#define {P}_TEMP_MIN_C {_c_float(lo)}",
        f"#define {P}_TEMP_MAX_C {_c_float(hi)}",
        f"#define {P}_BIAS_ORDER {n - 1}",
        f"static const float {P}_BIAS_COEFFS[3][{n}] = {arr(tm.bias_coeffs)};",
    ]
    if tm.gain_coeffs is not None:
        lines.append(f"static const float {P}_GAIN_COEFFS[2][3][3] = {arr(tm.gain_coeffs)};")
        gain = [f"        const float a{i}{j} = {P}_GAIN_COEFFS[0][{i}][{j}] + "
                f"{P}_GAIN_COEFFS[1][{i}][{j}] * d;" for i in range(3) for j in range(3)]
        rows = [f"    g_rad_s[{i}] = a{i}0 * x[0] + a{i}1 * x[1] + a{i}2 * x[2];"
                for i in range(3)]
        body = ["    {", *gain, *["    " + r for r in rows], "    }"]
    else:
        A = cal.full_matrix
        body = [f"    g_rad_s[{i}] = " + " + ".join(f"{_c_float(float(A[i][j]))} * x[{j}]"
                                                    for j in range(3)) + ";" for i in range(3)]
    return lines + [
        "",
        "/* Apply the calibration at die temperature die_c (degrees C); in place allowed. */",
        f"static inline void {fn}_at(const float m_rad_s[3], float die_c, float g_rad_s[3])",
        "{",
        f"    const float t = die_c < {P}_TEMP_MIN_C ? {P}_TEMP_MIN_C"
        f" : (die_c > {P}_TEMP_MAX_C ? {P}_TEMP_MAX_C : die_c);",
        f"    const float d = t - {P}_TEMP_REFERENCE_C;",
        "    float x[3];",
        "    int i, k;",
        "    for (i = 0; i < 3; ++i) {",
        f"        float b = {P}_BIAS_COEFFS[i][{P}_BIAS_ORDER];",
        f"        for (k = {P}_BIAS_ORDER - 1; k >= 0; --k) b = b * d + {P}_BIAS_COEFFS[i][k];",
        "        x[i] = m_rad_s[i] + b;",
        "    }",
        *body,
        "}",
    ]


register(
    Exporter(
        name="c-header",
        accepts=("gyrocal-calibration",),
        description="a C header for firmware: the constants and an inline apply function",
        render=_render_c_header,
        options=(
            ExportOption("c_prefix", str,
                         "c-header: prefix of the macros and the function (default GYROCAL: "
                         "GYROCAL_MATRIX_XX, gyrocal_apply)"),
        ),
        suffix=".h",
    )
)


# ---------------------------------------------------------------------------- flight stacks
from gyrocal.kit import (  # noqa: E402,F401 - register formats
    exports_accel,
    exports_flight,
    exports_ros,
    exports_thermal,
)
