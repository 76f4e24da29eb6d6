"""Exporters: gyrocal's JSON documents rendered in the formats other tools read.

:data:`EXPORTERS` maps a format name (``gyrocal export --format NAME``) to an :class:`Exporter`
that names the document kinds it accepts and renders one of them as text. A new format is one
:func:`register` call with a render function; its options become ``gyrocal export`` flags.

Document kinds (the ``format`` field of the JSON):

``gyrocal-calibration`` (v1)
    Calibration v1 (:class:`calib.model.GyroCalibration`).
``gyrocal-noise`` (v1)
    Noise figures from ``gyrocal noise`` (:class:`calib.allan.NoiseCharacterisation`).
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

from calib.errors import CalibrationFormatError
from kit import __version__
from kit.errors import InputError

__all__ = [
    "DOCUMENT_KINDS",
    "EXPORTERS",
    "ExportOption",
    "Exporter",
    "export",
    "register",
    "validate_document",
]


def _read_calibration(doc: Mapping[str, Any]) -> Any:
    from calib.model import GyroCalibration

    return GyroCalibration.from_dict(doc)


def _read_noise(doc: Mapping[str, Any]) -> Any:
    from calib.allan import NoiseCharacterisation

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
    from calib.allan import NoiseCharacterisation

    nc = NoiseCharacterisation.from_dict(doc)
    notes: list[str] = []
    n_axes = list(nc.noise_density.value)
    k_axes = list(nc.rate_random_walk.value)
    k_hi = list(nc.rate_random_walk.hi95)
    k_used = [k if k > 0 else hi for k, hi in zip(k_axes, k_hi, strict=True)]
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
