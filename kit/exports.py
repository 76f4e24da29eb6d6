"""Exporters: gyrocal's JSON documents rendered in the formats other tools read.

:data:`EXPORTERS` maps a format name (``gyrocal export --format NAME``) to an :class:`Exporter`
that names the document kinds it accepts and renders one of them as text. A new format is one
:func:`register` call with a render function; its options become ``gyrocal export`` flags.

Document kinds (the ``format`` field of the JSON):

``gyrocal-calibration`` (v1)
    Calibration v1 (:class:`gyrocal.calib.model.GyroCalibration`).
``gyrocal-noise`` (v1)
    Noise figures from ``gyrocal noise`` (:class:`gyrocal.calib.allan.NoiseCharacterisation`).
"""

from __future__ import annotations

import json
import math
import re
import sys
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
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
    """The JSON value in the file ``path`` (``-``: standard input).

    Raises
    ------
    InputError
        Naming ``what`` and ``path``: no such file, unreadable, or not JSON.
    """
    if path == "-":
        text, where = sys.stdin.read(), f"{what} on standard input"
    else:
        p = Path(path)
        where = f"{what} {p}"
        if not p.is_file():
            raise InputError(f"{where} does not exist or is not a file; give a gyrocal JSON "
                             "document")
        try:
            text = p.read_text(encoding="utf-8")
        except (OSError, UnicodeDecodeError) as exc:
            raise InputError(f"cannot read {where}: {exc}") from None
    try:
        return json.loads(text)
    except json.JSONDecodeError as exc:
        raise InputError(f"{where} is not valid JSON: {exc}") from None


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


# ---------------------------------------------------------------------------- kalibr
#: Placeholders for the accelerometer fields Kalibr requires (gyrocal does not measure them):
#: deliberately large for a MEMS part, so that Kalibr trusts the accelerometer less, not more.
KALIBR_ACCEL_NOISE_DENSITY = 1.0e-2  # m/s^2/sqrt(Hz)
KALIBR_ACCEL_RANDOM_WALK = 2.0e-4  # m/s^3/sqrt(Hz)


def _fmt(x: float) -> str:
    return f"{x:.6e}"


def _render_kalibr(doc: Mapping[str, Any], options: Mapping[str, Any]) -> tuple[str, list[str]]:
    from gyrocal.calib.allan import NoiseCharacterisation

    nc = NoiseCharacterisation.from_dict(doc)
    notes: list[str] = []
    n_axes = list(nc.noise_density.value)
    k_axes = list(nc.rate_random_walk.value)
    k_used = nc.rate_random_walk_or_hi95
    n_val = max(n_axes)
    k_val = max(k_used)
    if not (n_val > 0 and k_val > 0):
        raise InputError(
            "the noise document has no positive noise density or random walk; Kalibr needs both"
        )
    rostopic = options.get("rostopic") or "/imu0"
    rate = options.get("update_rate")
    rate = float(nc.odr_hz if rate is None else rate)
    if not (rate > 0 and math.isfinite(rate)):
        raise InputError(f"--update-rate must be a positive number of Hz, got {rate!r}")
    acc_n = options.get("accel_noise_density")
    acc_w = options.get("accel_random_walk")
    for name, v in (("--accel-noise-density", acc_n), ("--accel-random-walk", acc_w)):
        if v is not None and not (float(v) > 0 and math.isfinite(float(v))):
            raise InputError(f"{name} must be a positive number, got {v!r}")
    placeholder = acc_n is None or acc_w is None
    if placeholder:
        notes.append(
            "the accelerometer fields are placeholders (gyrocal measures gyroscopes only); "
            "give --accel-noise-density and --accel-random-walk from your accelerometer's "
            "datasheet or Allan analysis"
        )
    acc_n = KALIBR_ACCEL_NOISE_DENSITY if acc_n is None else float(acc_n)
    acc_w = KALIBR_ACCEL_RANDOM_WALK if acc_w is None else float(acc_w)
    unresolved = [ax for ax, k in zip("xyz", k_axes, strict=True) if not k > 0]
    sensor = nc.sensor.get("model", "unknown") if nc.sensor else "unknown"

    def axes(vals: list[float]) -> str:
        return " ".join(f"{a}={_fmt(v)}" for a, v in zip("xyz", vals, strict=True))

    lines = [
        f"# Kalibr IMU configuration (imu.yaml), written by gyrocal {__version__} from a "
        "gyrocal-noise v1 document.",
        f"# Sensor: {sensor}; source: {nc.source or 'unknown'}; record: "
        f"{nc.duration_s:.0f} s at {nc.odr_hz:g} Hz; created: {nc.created or 'unknown'}.",
        "# Gyroscope: measured by overlapping Allan deviation (IEEE Std 952). Kalibr takes one",
        "# value per sensor: each is the largest of the three axes.",
        "#   gyroscope_noise_density: white rate noise N, rad/s/sqrt(Hz) (continuous time);",
        f"#     per axis {axes(n_axes)}",
        "#   gyroscope_random_walk: rate random walk K, rad/s^2/sqrt(Hz) (= rad/s/sqrt(s));",
        f"#     per axis {axes(k_axes)}",
    ]
    if unresolved:
        lines.append(
            f"#     (not resolved on axis {', '.join(unresolved)} by this record: its 95 % upper "
            "bound is used there)"
        )
    if placeholder:
        lines += [
            "# Accelerometer: NOT MEASURED. Kalibr requires both fields (positive); these are",
            "#   placeholders, deliberately large for a MEMS accelerometer. Replace them with",
            "#   your accelerometer's figures (gyrocal export --accel-noise-density N",
            "#   --accel-random-walk W).",
        ]
    else:
        lines.append(
            "# Accelerometer: figures given on the command line (not measured by gyrocal)."
        )
    lines += [
        "#   accelerometer_noise_density in m/s^2/sqrt(Hz), accelerometer_random_walk in "
        "m/s^3/sqrt(Hz).",
        "# Kalibr's documentation advises inflating measured figures for a real installation",
        "# (vibration, temperature changes); these are the still-bench values.",
        f"accelerometer_noise_density: {_fmt(acc_n)}",
        f"accelerometer_random_walk: {_fmt(acc_w)}",
        f"gyroscope_noise_density: {_fmt(n_val)}",
        f"gyroscope_random_walk: {_fmt(k_val)}",
        f"rostopic: {rostopic}",
        f"update_rate: {rate:g}",
    ]
    return "\n".join(lines) + "\n", notes


register(
    Exporter(
        name="kalibr",
        accepts=("gyrocal-noise",),
        description="Kalibr IMU YAML (gyroscope_noise_density, gyroscope_random_walk)",
        render=_render_kalibr,
        options=(
            ExportOption("rostopic", str, "kalibr: the IMU's ROS topic (default /imu0)"),
            ExportOption(
                "update_rate", float, "kalibr: IMU rate in Hz (default the document's odr_hz)"
            ),
            ExportOption(
                "accel_noise_density", float,
                "kalibr: accelerometer white noise, m/s^2/sqrt(Hz) (not measured by gyrocal)",
            ),
            ExportOption(
                "accel_random_walk", float,
                "kalibr: accelerometer bias random walk, m/s^3/sqrt(Hz)",
            ),
        ),
        suffix=".yaml",
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
    return (f"chi2 = {c.chi2:.1f} on {c.dof} dof, p = {c.p_value:.3g} "
            f"({'consistent' if c.ok else 'NOT consistent'} with the measured noise)")


def _sensor_text(sensor: Mapping[str, Any]) -> str:
    if not sensor:
        return "unknown"
    parts = [str(sensor.get("model", "unknown model"))]
    if sensor.get("odr_hz") is not None:
        parts.append(f"{sensor['odr_hz']:g} Hz")
    if sensor.get("full_scale_dps") is not None:
        parts.append(f"+-{sensor['full_scale_dps']:g} dps full scale")
    return ", ".join(parts)


# ---------------------------------------------------------------------------- yaml
def _render_yaml(doc: Mapping[str, Any], options: Mapping[str, Any]) -> tuple[str, list[str]]:
    from gyrocal.calib.model import GyroCalibration

    cal = GyroCalibration.from_dict(doc)
    d = cal.to_dict()  # normalised: every field present, NaN as null
    lines = [
        f"# gyrocal calibration (Calibration v1) as YAML, written by gyrocal {__version__}.",
        "# The same fields as the JSON document; converted back to JSON it is a valid",
        "# Calibration v1 (gyrocal export --format json reads only JSON).",
        "#",
        "# Model (paper Eq. 1), elementwise per sensor axis x, y, z:",
        "#     g = scale * (m + bias)",
        "#   m      raw gyro reading, rad/s (raw counts times the datasheet sensitivity, nothing",
        "#          else)",
        "#   g      calibrated angular rate, rad/s",
        "#   scale  scale factors, dimensionless",
        "#   bias   rad/s, ADDED to the reading before scaling: a still sensor reads m = -bias",
        "#   scale_std, bias_std  one-sigma uncertainties (dimensionless; rad/s)",
        "#   covariance  6x6, of (scale_x, scale_y, scale_z, bias_x, bias_y, bias_z), row by row",
        f"# Sensor: {_sensor_text(cal.sensor)}.",
        f"# Consistency: {_verdict(cal)}.",
    ]
    comments = {
        "scale": "# scale factors (dimensionless)",
        "bias": "# biases, rad/s (added to the reading before scaling)",
        "scale_std": "# one-sigma, dimensionless",
        "bias_std": "# one-sigma, rad/s",
        "covariance": "# order (scale_x, scale_y, scale_z, bias_x, bias_y, bias_z); "
                      "units 1 and rad/s",
        "temperature_c": "# mean die temperature during the calibration, degrees C",
        "axes": "# each servo's rotation axis in the sensor frame (unit vector), its angle to\n"
                "# the nearest sensor axis and that angle's one-sigma, degrees",
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


# ---------------------------------------------------------------------------- ros
_ROS_NODE = re.compile(r"(/\*\*|/?[A-Za-z_][A-Za-z0-9_]*(/[A-Za-z_][A-Za-z0-9_]*)*)\Z")
_ROS_FRAME = re.compile(r"[A-Za-z_/][A-Za-z0-9_/]*\Z")


def _render_ros(doc: Mapping[str, Any], options: Mapping[str, Any]) -> tuple[str, list[str]]:
    from gyrocal.calib.model import GyroCalibration

    cal = GyroCalibration.from_dict(doc)
    frame = options.get("frame_id") or "imu_link"
    if not _ROS_FRAME.match(frame):
        raise InputError(f"--frame-id {frame!r} is not a ROS frame name (letters, digits, _, /)")
    node = options.get("ros_node")
    if node is not None and not _ROS_NODE.match(node):
        raise InputError(f"--ros-node {node!r} is not a ROS node name (e.g. imu_filter, or /**)")
    notes: list[str] = []
    params: dict[str, Any] = {
        "frame_id": frame,
        "model": "omega = scale * (omega_raw + bias)",
        "bias_convention": "add",
        "units": "rad/s",
        "scale": list(cal.scale),
        "bias": list(cal.bias),
    }
    missing = []
    for name in ("scale_std", "bias_std"):
        v = getattr(cal, name)
        if all(math.isfinite(x) for x in v):
            params[name] = list(v)
        else:
            missing.append(name)
    cov = cal.covariance
    if cov is not None and all(math.isfinite(x) for row in cov for x in row):
        params["covariance"] = [x for row in cov for x in row]
    else:
        missing.append("covariance")
    params["method"] = cal.method
    if cal.consistency is not None:
        params["consistent"] = bool(cal.consistency.ok)
    if cal.temperature_c is not None:
        params["temperature_c"] = float(cal.temperature_c)
    if cal.sensor.get("model") is not None:
        params["sensor_model"] = str(cal.sensor["model"])
    for name in ("created", "source"):
        if getattr(cal, name) is not None:
            params[name] = getattr(cal, name)
    if missing:
        notes.append(f"the calibration has no {', '.join(missing)}: left out of the ROS file")
    lines = [
        f"# Gyroscope calibration for ROS, written by gyrocal {__version__} from a Calibration v1 "
        "document.",
        f"# Frame: {frame} (the IMU's frame_id); rates in rad/s as in sensor_msgs/Imu (REP 103).",
        "# Model, elementwise per axis x, y, z of that frame:",
        "#     omega = scale * (omega_raw + bias)",
        "#   omega_raw  the driver's angular_velocity before correction, rad/s",
        "#   omega      the corrected angular_velocity, rad/s",
        "#   scale      dimensionless; scale_std its one-sigma",
        "#   bias       rad/s, ADDED to the raw reading (bias_convention: add); a still sensor",
        "#              reads -bias. A node that subtracts an offset must subtract -bias.",
        "#   bias_std   one-sigma, rad/s",
        "#   covariance row-major 6x6 of (scale_x, scale_y, scale_z, bias_x, bias_y, bias_z)",
        f"# Sensor: {_sensor_text(cal.sensor)}.",
        f"# Consistency: {_verdict(cal)}.",
    ]
    if node is None:
        lines.append("# Load with: rosparam load FILE [namespace] (ROS 1). For a ROS 2 parameters")
        lines.append("# file, export with --ros-node NODE.")
        lines += _yaml_block("gyro_calibration", params)
    else:
        lines.append(f"# ROS 2 parameters file for node {node}: ros2 run ... --ros-args "
                     "--params-file FILE")
        lines += _yaml_block(node, {"ros__parameters": {"gyro_calibration": params}})
    return "\n".join(lines) + "\n", notes


register(
    Exporter(
        name="ros",
        accepts=("gyrocal-calibration",),
        description="YAML parameters for ROS (gyro_calibration: scale, bias in rad/s, stds)",
        render=_render_ros,
        options=(
            ExportOption("frame_id", str, "ros: the IMU's frame_id (default imu_link)"),
            ExportOption("ros_node", str,
                         "ros: write a ROS 2 parameters file for this node (or /** for all)"),
        ),
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


def _c_comment(text: str) -> str:
    """Text that cannot end a C comment early."""
    return str(text).replace("*/", "* /").replace("\n", " ")


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
    sens_ok = isinstance(sens, (int, float)) and not isinstance(sens, bool) and sens > 0
    k_std = "  ".join(f"k_{a} {_std_text(s)}" for a, s in zip("xyz", cal.scale_std, strict=True))
    b_std = "  ".join(f"b_{a} {_std_text(s)}" for a, s in zip("xyz", cal.bias_std, strict=True))
    lines = [
        "/*",
        f" * Gyroscope calibration for firmware, written by gyrocal {__version__} from a "
        "Calibration v1 document.",
        " *",
        " * Model (Calibration v1, the paper's Eq. 1), per sensor axis i = x, y, z:",
        " *",
        " *     g[i] = k[i] * (m[i] + b[i])",
        " *",
        " *   m  raw gyro reading in rad/s: raw counts times the datasheet sensitivity, nothing",
        " *      else" + (f" ({P}_SENSITIVITY_RAD_S_PER_LSB below)" if sens_ok else ""),
        " *   g  calibrated angular rate, rad/s",
        f" *   k  scale factor, dimensionless ({P}_SCALE_X, _Y, _Z)",
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
    lines += [
        f" * Created: {_c_comment(cal.created or 'unknown')}",
        f" * Source: {_c_comment(cal.source or 'unknown')}",
        " *",
        " * One-sigma standard deviations:",
        f" *   {k_std}  (dimensionless)",
        f" *   {b_std}  (rad/s)",
        " */",
        f"#ifndef {guard}",
        f"#define {guard}",
        "",
        "/* Scale factors k, dimensionless. */",
    ]
    for a, k, s in zip("XYZ", cal.scale, cal.scale_std, strict=True):
        lines.append(f"#define {P}_SCALE_{a} {_c_float(k)} /* std {_std_text(s)} */")
    lines.append("")
    lines.append("/* Biases b, rad/s, added to the reading before scaling. */")
    for a, b, s in zip("XYZ", cal.bias, cal.bias_std, strict=True):
        lines.append(f"#define {P}_BIAS_{a} {_c_float(b)} /* rad/s, std {_std_text(s)} */")
    if sens_ok:
        lines += [
            "",
            "/* Datasheet sensitivity the readings were converted with: m = counts * this. */",
            f"#define {P}_SENSITIVITY_RAD_S_PER_LSB {_c_float(float(sens))}",
        ]
    lines += [
        "",
        "/*",
        " * Apply the calibration: g = k * (m + b) on each axis. m_rad_s and g_rad_s are",
        " * {x, y, z} in rad/s; they may be the same array (in place).",
        " */",
        f"static inline void {fn}(const float m_rad_s[3], float g_rad_s[3])",
        "{",
        f"    const float x = {P}_SCALE_X * (m_rad_s[0] + {P}_BIAS_X);",
        f"    const float y = {P}_SCALE_Y * (m_rad_s[1] + {P}_BIAS_Y);",
        f"    const float z = {P}_SCALE_Z * (m_rad_s[2] + {P}_BIAS_Z);",
        "    g_rad_s[0] = x;",
        "    g_rad_s[1] = y;",
        "    g_rad_s[2] = z;",
        "}",
        "",
        f"#endif /* {guard} */",
    ]
    return "\n".join(lines) + "\n", []


register(
    Exporter(
        name="c-header",
        accepts=("gyrocal-calibration",),
        description="a C header for firmware: the six constants and an inline apply function",
        render=_render_c_header,
        options=(
            ExportOption("c_prefix", str,
                         "c-header: prefix of the macros and the function (default GYROCAL: "
                         "GYROCAL_SCALE_X, gyrocal_apply)"),
        ),
        suffix=".h",
    )
)
