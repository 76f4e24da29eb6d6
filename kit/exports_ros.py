"""Exports for the ROS world: Kalibr's IMU file, ROS parameters, and ``imu_calib``'s YAML.

Each format is written for its reader, modelled from that reader's source:

``--format kalibr`` (ethz-asl/kalibr, commit 1f60227)
    ``imu.yaml`` as ``kalibr_common/ConfigReader.py`` (``aslam_offline_calibration/kalibr/
    python/``) reads it: ``ImuParameters`` requires the six fields of :data:`KALIBR_IMU_FIELDS`
    (a missing one is "Field 'NAME' missing", ``catch_keyerror``, lines 183-190; each checked
    positive, lines 450-492), and ``kalibr_calibrate_imu_camera`` reads them all at start
    (``ImuParameters(imu_yaml)`` and ``printDetails()``, lines 150-151). Kalibr never reads IMU
    intrinsics from this file: the IMU model is the ``--imu-models`` flag (same script, lines 87
    and 152-160) and ``IccScaledMisalignedImu`` starts ``M``, ``A`` and ``C_gyro_i`` from the
    identity and zero and estimates them itself (``kalibr_imu_camera_calibration/
    IccSensors.py``, ``addDesignVariables``, lines 948-967; it overwrites ``model``, lines 556
    and 918). gyrocal's intrinsics go under ``gyrocal_intrinsics``, a key Kalibr does not read,
    for comparison with Kalibr's result.

``--format ros``
    The calibration as ROS parameters (``gyro_calibration``), with the covariances a driver puts
    in each ``sensor_msgs/Imu`` message: ``angular_velocity_covariance`` and
    ``linear_acceleration_covariance``, ``float64[9]`` "Row major about x, y, z axes", in
    (rad/s)² and (m/s²)²; all zeros means "covariance unknown" (ros/common_msgs 1.13.1,
    ``sensor_msgs/msg/Imu.msg``, lines 5-8, 21 and 24). See :func:`reading_covariance`.

``--format imu-calib``
    The accelerometer in the form of the ``imu_calib`` package (dpkoch/imu_calib, commit
    59f5d17): ``AccelCalib::loadCalib`` reads the top-level keys ``SM`` (nine numbers,
    ``SM(i/3, i%3)``: row-major) and ``bias`` (three) with yaml-cpp
    (``src/accel_calib/accel_calib.cpp``, lines 73-86), and ``applyCalib`` computes
    ``corrected = SM·raw − bias`` (lines 205 and 216), which the ``apply_calib`` node applies
    to ``linear_acceleration`` (``src/apply_calib.cpp``, lines 98-99). gyrocal's
    ``f = A (a + b)`` is ``A a + A b``: ``SM = A`` and ``bias = −A b``, exactly.
"""

from __future__ import annotations

import math
import re
from collections.abc import Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from gyrocal.kit import __version__
from gyrocal.kit.errors import InputError
from gyrocal.kit.exports import (
    ACCEL_FRAME_TEXT,
    Exporter,
    ExportOption,
    _num_text,
    _one_line,
    _sensor_text,
    _verdict,
    _yaml_block,
    _yaml_float,
    load_document,
    register,
)

if TYPE_CHECKING:
    import numpy as np

# numpy is imported inside the functions: `gyrocal export --help` loads this module and must
# stay light (tests/kit/test_cli_imports.py).

__all__ = [
    "KALIBR_IMU_FIELDS",
    "KalibrField",
    "imu_calib_params",
    "kalibr_intrinsics",
    "reading_covariance",
]


# ---------------------------------------------------------------------------- kalibr
@dataclass(frozen=True)
class KalibrField:
    """One field Kalibr's IMU reader requires.

    Attributes
    ----------
    name : str
        The YAML key.
    unit : str
    check : str
        What the reader checks.
    source : str
        Where (ethz-asl/kalibr 1f60227, ``aslam_offline_calibration/kalibr/python/``).
    """

    name: str
    unit: str
    check: str
    source: str


_CR = "kalibr_common/ConfigReader.py"
#: Every field ``ImuParameters`` reads, in the order gyrocal writes them; a missing one stops
#: Kalibr with "Field 'NAME' missing" (``catch_keyerror``, ConfigReader.py lines 183-190).
KALIBR_IMU_FIELDS: tuple[KalibrField, ...] = (
    KalibrField("accelerometer_noise_density", "m/s^2/sqrt(Hz)", "> 0",
                f"{_CR}:464-474 (getAccelerometerStatistics)"),
    KalibrField("accelerometer_random_walk", "m/s^3/sqrt(Hz)", "> 0",
                f"{_CR}:464-474 (getAccelerometerStatistics)"),
    KalibrField("gyroscope_noise_density", "rad/s/sqrt(Hz)", "> 0",
                f"{_CR}:482-492 (getGyroStatistics)"),
    KalibrField("gyroscope_random_walk", "rad/s^2/sqrt(Hz)", "> 0",
                f"{_CR}:482-492 (getGyroStatistics)"),
    KalibrField("rostopic", "", "a string", f"{_CR}:436-443 (getRosTopic)"),
    KalibrField("update_rate", "Hz", "> 0", f"{_CR}:450-457 (getUpdateRate)"),
)

#: Placeholders for the accelerometer fields Kalibr requires when nothing measured or given
#: them: deliberately large for a MEMS part, so that Kalibr trusts the accelerometer less.
KALIBR_ACCEL_NOISE_DENSITY = 1.0e-2  # m/s^2/sqrt(Hz)
KALIBR_ACCEL_RANDOM_WALK = 2.0e-4  # m/s^3/sqrt(Hz)

_KALIBR_REESTIMATES = (
    "Kalibr re-estimates the IMU intrinsics itself (kalibr_calibrate_imu_camera --imu-models "
    "scale-misalignment starts M and C_gyro_i at the identity and A at zero); it never reads "
    "M, A or C_gyro_i from an input file. The gyrocal_intrinsics block is for comparison with "
    "Kalibr's result only"
)


def _fmt(x: float) -> str:
    return f"{x:.6e}"


_ROS_TOPIC = re.compile(r"[A-Za-z_/~][A-Za-z0-9_/]*\Z")


def _kalibr_topic_and_rate(options: Mapping[str, Any], *odr_hz: Any) -> tuple[str, float | None]:
    """``--rostopic`` (checked: a ROS name) and ``--update-rate`` (default the first of
    ``odr_hz`` that is a positive number; None when there is none)."""
    rostopic = options.get("rostopic") or "/imu0"
    if not _ROS_TOPIC.match(rostopic):
        raise InputError(f"--rostopic {_one_line(rostopic, 60)!r} is not a ROS topic name "
                         "(letters, digits, _, /; e.g. /imu0)")
    return rostopic, _message_rate(options, *odr_hz)


def _message_rate(options: Mapping[str, Any], *odr_hz: Any) -> float | None:
    """``--update-rate``, else the first of ``odr_hz`` that is a positive number, else None."""
    rate = _positive_option(options, "update_rate", " of Hz")
    if rate is not None:
        return rate
    for v in odr_hz:
        if _num_text(v) is not None and v > 0:
            return float(v)
    return None


def _positive_option(options: Mapping[str, Any], name: str, unit: str = "") -> float | None:
    """Option ``name`` as a float, None when not given; :class:`InputError` naming the flag
    unless it is a positive finite number."""
    v = options.get(name)
    if v is None:
        return None
    if not (float(v) > 0 and math.isfinite(float(v))):
        raise InputError(f"--{name.replace('_', '-')} must be a positive number{unit}, "
                         f"got {v!r}")
    return float(v)


def _noise_option(options: Mapping[str, Any]) -> Any:
    """The ``--noise`` document (a ``NoiseCharacterisation``), or None when not given."""
    path = options.get("noise")
    if path is None:
        return None
    return load_document(path, "gyrocal-noise", "--noise document")


def _axes(vals: Any) -> str:
    return " ".join(f"{a}={_fmt(float(v))}" for a, v in zip("xyz", vals, strict=True))


def _kalibr_gyro(nc: Any) -> tuple[float, float, list[str]]:
    """Kalibr's ``gyroscope_noise_density`` and ``gyroscope_random_walk`` from a noise
    document (the largest axis of each; an unresolved ``K`` by its 95 % upper bound), and the
    comment lines saying so."""
    n_axes = [float(x) for x in nc.noise_density.value]
    k_axes = [float(x) for x in nc.rate_random_walk.value]
    n_val, k_val = max(n_axes), max(nc.rate_random_walk_or_hi95)
    if not (n_val > 0 and k_val > 0):
        raise InputError("the noise document has no positive noise density or random walk; "
                         "Kalibr needs both")
    lines = [
        "# Gyroscope: measured by overlapping Allan deviation (IEEE Std 952) on "
        f"{nc.duration_s:.0f} s at {nc.odr_hz:g} Hz",
        f"#   (source: {_one_line(nc.source or 'unknown')}; created: "
        f"{_one_line(nc.created or 'unknown')}). Kalibr takes one value per sensor: each is",
        "#   the largest of the three axes.",
        "#   gyroscope_noise_density: white rate noise N, rad/s/sqrt(Hz) (continuous time);",
        f"#     per axis {_axes(n_axes)}",
        "#   gyroscope_random_walk: rate random walk K, rad/s^2/sqrt(Hz) (= rad/s/sqrt(s));",
        f"#     per axis {_axes(k_axes)}",
    ]
    unresolved = [ax for ax, k in zip("xyz", k_axes, strict=True) if not k > 0]
    if unresolved:
        lines.append(f"#     (not resolved on axis {', '.join(unresolved)} by this record: its "
                     "95 % upper bound is used there)")
    return n_val, k_val, lines


def _kalibr_accel(acc: Any, options: Mapping[str, Any],
                  no_acc: str = "the calibration has no accelerometer"
                  ) -> tuple[float, float, list[str], list[str]]:
    """Kalibr's ``accelerometer_noise_density`` and ``accelerometer_random_walk``, the comment
    lines and the notes: a given flag wins, then the calibration's measured density
    (:func:`gyrocal.calib.accel.white_noise_density`; ``acc`` may be None), else a placeholder
    (said in the file and on stderr)."""
    n_given = _positive_option(options, "accel_noise_density")
    w_given = _positive_option(options, "accel_random_walk")
    lines, notes = ["# Accelerometer (m/s^2/sqrt(Hz) and m/s^3/sqrt(Hz)):"], []
    if n_given is not None:
        n = n_given
        lines.append("#   accelerometer_noise_density from --accel-noise-density.")
        notes.append("accelerometer_noise_density from --accel-noise-density")
    elif acc is not None and acc.noise_density is not None and max(acc.noise_density) > 0:
        dens = [float(x) for x in acc.noise_density]
        i = dens.index(max(dens))
        n, sd = dens[i], float(acc.noise_density_std[i])
        lines += ["#   accelerometer_noise_density: measured on the calibration run's rests",
                  f"#     (Allan deviation at {acc.noise_tau_s:.3g} s, continuous time), the "
                  "largest axis;",
                  f"#     per axis {_axes(dens)}"]
        notes.append(f"accelerometer_noise_density {n:.3e} ± {sd:.1e} m/s^2/sqrt(Hz) measured "
                     f"on the run's rests (largest axis, {'xyz'[i]}; Allan deviation at "
                     f"{acc.noise_tau_s:.3g} s, continuous time)")
    else:
        n = KALIBR_ACCEL_NOISE_DENSITY
        why = no_acc if acc is None else "the calibration has no measured accelerometer noise"
        lines.append("#   accelerometer_noise_density: NOT MEASURED, a placeholder "
                     "(deliberately large for a MEMS part).")
        notes.append(f"accelerometer_noise_density is a placeholder ({why}); give "
                     "--accel-noise-density N from your accelerometer's datasheet or Allan "
                     "analysis")
    if w_given is not None:
        w = w_given
        lines.append("#   accelerometer_random_walk from --accel-random-walk.")
    else:
        w = KALIBR_ACCEL_RANDOM_WALK
        lines += ["#   accelerometer_random_walk: NOT MEASURED (gyrocal does not measure it), a",
                  "#     placeholder, deliberately large; replace it (--accel-random-walk W)."]
        notes.append("accelerometer_random_walk is a placeholder (gyrocal does not measure it); "
                     "give --accel-random-walk W from your accelerometer's datasheet or Allan "
                     "analysis")
    return n, w, lines, notes


def _kalibr_fields(values: Mapping[str, Any]) -> list[str]:
    """The lines of every field in :data:`KALIBR_IMU_FIELDS`, in its order; an error (a bug)
    when one is missing, so that gyrocal never writes a file Kalibr rejects."""
    missing = [f.name for f in KALIBR_IMU_FIELDS if f.name not in values]
    if missing:
        raise AssertionError(f"Kalibr's fields {missing} were not computed")
    out = []
    for f in KALIBR_IMU_FIELDS:
        v = values[f.name]
        out.append(f"{f.name}: {v}" if isinstance(v, str) else
                   f"{f.name}: {v:g}" if f.name == "update_rate" else f"{f.name}: {_fmt(v)}")
    return out


def _render_kalibr(doc: Mapping[str, Any], options: Mapping[str, Any]) -> tuple[str, list[str]]:
    if doc.get("format") == "gyrocal-calibration":
        return _render_kalibr_calibration(doc, options)
    if options.get("noise") is not None:
        raise InputError("--noise goes with a calibration; this document is itself the noise "
                         "document")
    return _render_kalibr_noise(doc, options)


_KALIBR_ADVICE = [
    "# Kalibr's documentation advises inflating measured figures for a real installation",
    "# (vibration, temperature changes); these are the still-bench values.",
]


def _render_kalibr_noise(
    doc: Mapping[str, Any], options: Mapping[str, Any]
) -> tuple[str, list[str]]:
    from gyrocal.calib.allan import NoiseCharacterisation

    nc = NoiseCharacterisation.from_dict(doc)
    n_g, k_g, gyro_lines = _kalibr_gyro(nc)
    rostopic, rate = _kalibr_topic_and_rate(options, nc.odr_hz)
    if rate is None:
        raise InputError("the noise document has no usable odr_hz; give --update-rate HZ")
    n_a, w_a, acc_lines, notes = _kalibr_accel(
        None, options, "a gyrocal-noise document holds the gyro's noise only")
    sensor = _one_line(nc.sensor.get("model", "unknown") if nc.sensor else "unknown")
    lines = [
        f"# Kalibr IMU configuration (imu.yaml), written by gyrocal {__version__} from a "
        "gyrocal-noise v1 document.",
        f"# Sensor: {sensor}.",
        *gyro_lines, *acc_lines, *_KALIBR_ADVICE,
        *_kalibr_fields({"accelerometer_noise_density": n_a, "accelerometer_random_walk": w_a,
                         "gyroscope_noise_density": n_g, "gyroscope_random_walk": k_g,
                         "rostopic": rostopic, "update_rate": rate}),
    ]
    return "\n".join(lines) + "\n", notes


def _render_kalibr_calibration(
    doc: Mapping[str, Any], options: Mapping[str, Any]
) -> tuple[str, list[str]]:
    """Kalibr's ``imu.yaml`` for a calibration: the six fields Kalibr reads (the gyro's noise
    from ``--noise``, the accelerometer's from the calibration or flags), then the calibration's
    intrinsics in Kalibr's ``scale-misalignment`` layout under ``gyrocal_intrinsics``, which
    Kalibr does not read (:func:`kalibr_intrinsics`)."""
    from gyrocal.calib.model import GyroCalibration

    cal = GyroCalibration.from_dict(doc)
    nc = _noise_option(options)
    if nc is None:
        raise InputError(
            "Kalibr's IMU file needs the gyro's noise (gyroscope_noise_density, "
            "gyroscope_random_walk), which a calibration does not hold: measure it with "
            "'gyrocal noise RECORDING --json > noise.json' (the sensor at rest) and give "
            "--noise noise.json")
    n_g, k_g, gyro_lines = _kalibr_gyro(nc)
    n_a, w_a, acc_lines, notes = _kalibr_accel(cal.accelerometer, options)
    rostopic, rate = _kalibr_topic_and_rate(options, cal.sensor.get("odr_hz"), nc.odr_hz)
    if rate is None:
        raise InputError("neither the calibration nor the noise document has a usable odr_hz; "
                         "give --update-rate HZ")
    intrinsics, intr_lines, intr_notes = kalibr_intrinsics(cal)
    lines = [
        f"# Kalibr IMU configuration (imu.yaml), written by gyrocal {__version__} from a "
        f"Calibration v{2 if cal.is_full else 1} document and a gyrocal-noise document.",
        f"# Sensor: {_sensor_text(cal.sensor)}. Consistency: {_verdict(cal)}.",
        "# Kalibr reads the six fields below (kalibr_common/ConfigReader.py, ImuParameters).",
        *gyro_lines, *acc_lines, *_KALIBR_ADVICE,
        *_kalibr_fields({"accelerometer_noise_density": n_a, "accelerometer_random_walk": w_a,
                         "gyroscope_noise_density": n_g, "gyroscope_random_walk": k_g,
                         "rostopic": rostopic, "update_rate": rate}),
        "#",
        "# ---- INFORMATIVE ONLY: Kalibr does not read gyrocal_intrinsics. ----",
        "# Kalibr re-estimates the IMU intrinsics itself: kalibr_calibrate_imu_camera",
        "# --imu-models scale-misalignment starts M and C_gyro_i at the identity and A at zero",
        "# (IccSensors.py, addDesignVariables); it never reads M, A or C_gyro_i from an input",
        "# file. This block is gyrocal's calibration for comparison with Kalibr's result.",
        *intr_lines,
        *_yaml_block("gyrocal_intrinsics", intrinsics),
    ]
    return "\n".join(lines) + "\n", [_KALIBR_REESTIMATES, *notes, *intr_notes]


def kalibr_intrinsics(cal: Any) -> tuple[dict[str, Any], list[str], list[str]]:
    """The calibration in the layout of Kalibr's ``scale-misalignment`` IMU model, the comment
    lines explaining it and the notes on what has no place.

    Kalibr (``kalibr_imu_camera_calibration/IccSensors.py``, ``IccScaledMisalignedImu``)
    models the gyro reading as ``w_meas = M C_gyro_i w_i + A a_i + b`` and writes its result as
    ``gyroscopes: {M, A, C_gyro_i}``, ``accelerometers: {M}`` (``setIntrisicsMatrices``,
    lines 933-939). gyrocal's ``g = matrix (m + bias)`` is ``m = matrix⁻¹ g − bias``: so
    ``M = matrix⁻¹`` with ``C_gyro_i`` the identity (Kalibr's IMU frame is gyrocal's calibrated
    frame). Kalibr's ``A`` is the g-sensitivity in (rad/s)/(m/s²) on the specific force
    ``a_i`` (``addGyroscopeErrorTerms``): ``m = matrix⁻¹ g − bias − G f`` with ``f = a / g₀``
    gives ``A = −G / g₀`` (:data:`gyrocal.calib.accel.STANDARD_GRAVITY`); without it ``A`` is
    zero. The accelerometer's ``a_meas = M_accel a_i + b`` against gyrocal's ``f = A (a + b)``
    gives ``M_accel = A⁻¹``. Kalibr has no fixed bias (it estimates one as a random walk).
    """
    import numpy as np

    from gyrocal.calib.accel import STANDARD_GRAVITY

    eye = np.eye(3).tolist()
    m_gyro = _inverse(cal.full_matrix, "the calibration's matrix")
    acc = cal.accelerometer
    m_accel = eye if acc is None else _inverse(acc.matrix, "the accelerometer's matrix")
    g = cal.g_sensitivity
    a_gyro = ([[0.0] * 3 for _ in range(3)] if g is None else
              [[-float(x) / STANDARD_GRAVITY + 0.0 for x in row] for row in g["matrix"]])
    lines = [
        "# gyrocal's calibration in the layout of Kalibr's scale-misalignment result",
        "# (kalibr_imu_camera_calibration/IccSensors.py):",
        "#     w_meas = M * C_gyro_i * w_i + A * a_i + b",
        "#   gyroscopes.M = inverse(matrix) of gyrocal's g = matrix @ (m + bias); C_gyro_i the",
        "#   identity (Kalibr's IMU frame is gyrocal's calibrated frame, convention "
        f"{_one_line(cal.frame or 'not stated')}).",
        "#   gyroscopes.A: " + ("the g-sensitivity, -G / 9.80665 in (rad/s)/(m/s^2)."
                                if g is not None else "zero (the calibration has no "
                                "g-sensitivity)."),
        "#   accelerometers.M: " + ("inverse of the accelerometer's matrix (frame accel-x-xy)."
                                    if acc is not None else "the identity (the calibration "
                                    "has no accelerometer)."),
        "#   Not in Kalibr's layout: the gyro bias (Kalibr has no fixed bias; it estimates one as",
        "#   a random walk), rad/s, ADDED to the reading: gyro_bias_added_rad_s.",
    ]
    notes = ["Kalibr's IMU file has no place for a fixed gyro bias (Kalibr estimates it as a "
             f"random walk): the bias {[float(b) for b in cal.bias]} rad/s is only in "
             "gyrocal_intrinsics"]
    if acc is not None:
        notes.append("Kalibr's IMU file has no place for a fixed accelerometer bias either: "
                     f"{[float(b) for b in acc.bias]} m/s^2 is not in the file")
    if not cal.is_full:
        notes.append("a version 1 calibration has no cross-axis terms: gyrocal_intrinsics' M "
                     "is diagonal")
    if acc is not None and cal.frame != "accel-x-xy":
        notes.append("the gyro calibration is in its own frame, not the accelerometer's: "
                     "C_gyro_i = identity in gyrocal_intrinsics is then only nominal "
                     "(gyrocal.calib.accel.align_gyro expresses it in the accelerometer's)")
    block = {"kalibr_model": "scale-misalignment",
             "gyroscopes": {"M": m_gyro, "A": a_gyro, "C_gyro_i": eye},
             "accelerometers": {"M": m_accel},
             "gyro_bias_added_rad_s": [float(b) for b in cal.bias]}
    return block, lines, notes


def _inverse(a: Any, what: str) -> list[list[float]]:
    import numpy as np

    m = np.asarray(a, dtype=float)
    if not abs(np.linalg.det(m)) > 0:
        raise InputError(f"{what} is singular: it cannot be inverted for Kalibr")
    return [[float(x) + 0.0 for x in row] for row in np.linalg.inv(m)]


_UPDATE_RATE = ExportOption(
    "update_rate", float, "kalibr / ros: IMU message rate in Hz (default the document's odr_hz)")
_NOISE = ExportOption(
    "noise", str,
    "kalibr / ros: a gyrocal-noise document (gyrocal noise --json) giving the gyro's noise "
    "for a calibration's export")
register(
    Exporter(
        name="kalibr",
        accepts=("gyrocal-noise", "gyrocal-calibration"),
        description="Kalibr imu.yaml (the six fields its reader requires): from a noise "
                    "document, or from a calibration with --noise (its intrinsics informative "
                    "only: Kalibr re-estimates them)",
        render=_render_kalibr,
        options=(
            ExportOption("rostopic", str, "kalibr: the IMU's ROS topic (default /imu0)"),
            _UPDATE_RATE,
            ExportOption("accel_noise_density", float,
                         "kalibr: accelerometer white noise, m/s^2/sqrt(Hz) (for a calibration, "
                         "default its accelerometer's measured noise density)"),
            ExportOption("accel_random_walk", float,
                         "kalibr: accelerometer bias random walk, m/s^3/sqrt(Hz)"),
            _NOISE,
        ),
        suffix=".yaml",
    )
)


# ---------------------------------------------------------------------------- ros
_ROS_NODE = re.compile(r"(/\*\*|/?[A-Za-z_][A-Za-z0-9_]*(/[A-Za-z_][A-Za-z0-9_]*)*)\Z")
_ROS_FRAME = re.compile(r"[A-Za-z_/][A-Za-z0-9_/]*\Z")


def reading_covariance(density: Any, rate_hz: float, matrix: Any) -> np.ndarray:
    """The covariance of one calibrated reading from the raw reading's white-noise density.

    A still reading sampled every ``Δt = 1/rate_hz`` with independent samples of variance
    ``σ²`` has the Allan variance ``σ²(τ) = σ² Δt / τ`` at ``τ = nΔt`` (the mean of ``n``
    samples), so IEEE Std 952's ``σ²(τ) = N²/τ`` gives ``σ² = N² / Δt = N² · rate``: the
    per-sample variance, what ``sensor_msgs/Imu``'s covariances hold for one message. It is
    Kalibr's discrete-time noise ``σ_d = σ_c / sqrt(Δt)`` (``ConfigReader.py`` lines 473 and
    491) squared; with a datasheet's one-sided density ``D = √2 N`` it is ``D² · rate / 2``.
    A chip low-pass narrower than ``rate / 2`` makes the true per-sample variance smaller
    (``N² · 2 B`` over a noise bandwidth ``B``): the figure is then an upper bound.

    The calibrated reading is ``matrix (m + b)``, so its covariance is
    ``matrix diag(σ²) matrixᵀ`` (the axes' noises independent).

    Parameters
    ----------
    density : (3,) array_like
        ``N`` per axis of the raw reading, continuous time (unit/√Hz).
    rate_hz : float
        The rate of the readings (messages), Hz.
    matrix : (3, 3) array_like
        The calibration's matrix applied to the reading.

    Returns
    -------
    (3, 3) ndarray
        Unit² (rad/s)² or (m/s²)².
    """
    import numpy as np

    var = np.asarray(density, dtype=float) ** 2 * float(rate_hz)
    a = np.asarray(matrix, dtype=float)
    return a @ np.diag(var) @ a.T


def _finite_list(rows: Any) -> list[float] | None:
    """``rows`` (a vector or a matrix) flattened row by row, or None if any entry is unknown."""
    flat = [float(x) for r in rows for x in (r if isinstance(r, (list, tuple)) else [r])]
    return flat if all(math.isfinite(x) for x in flat) else None


def _ros_params(cal: Any, frame: str) -> tuple[dict[str, Any], list[str]]:
    """The ``gyro_calibration`` parameters (flat arrays: ROS 2 parameters cannot nest lists),
    and the names of the uncertainties left out because the calibration does not have them."""
    full = cal.is_full
    params: dict[str, Any] = {
        "frame_id": frame,
        "model": "omega = matrix * (omega_raw + bias)" if full
        else "omega = scale * (omega_raw + bias)",
        "bias_convention": "add",
        "units": "rad/s",
    }
    if full:
        params["matrix"] = _finite_list(cal.matrix)
        params["matrix_frame_convention"] = cal.frame or "unknown"
    params["scale"] = list(cal.scale)
    params["bias"] = list(cal.bias)
    missing = []
    if cal.g_sensitivity is not None:
        params["model"] = "omega = matrix * (omega_raw + bias + g_sensitivity * f)"
        params["g_sensitivity"] = _finite_list(cal.g_sensitivity["matrix"])
        g_std = _finite_list(cal.g_sensitivity["matrix_std"])
        if g_std is None:
            missing.append("g_sensitivity_std")
        else:
            params["g_sensitivity_std"] = g_std
    stds = ("matrix_std", "bias_std") if full else ("scale_std", "bias_std")
    for name in (*stds, "covariance"):
        value = getattr(cal, name)
        flat = None if value is None else _finite_list(value)
        key = "parameter_covariance" if name == "covariance" else name
        if flat is None:
            missing.append(key)
        else:
            params[key] = flat
    params["method"] = cal.method
    if cal.consistency is not None:
        params["consistent"] = bool(cal.consistency.ok)
    if cal.accelerometer is not None:
        acc = cal.accelerometer
        params["accel_model"] = "accel = accel_matrix * (accel_raw + accel_bias)"
        params["accel_matrix"] = _finite_list(acc.matrix.tolist())
        params["accel_matrix_frame_convention"] = ACCEL_FRAME_TEXT.split(" ")[0]
        params["accel_bias"] = [float(x) for x in acc.bias]
        params["accel_bias_std"] = [float(x) for x in acc.std[6:]]
        params["accel_units"] = "m/s^2"
        params["accel_consistent"] = bool(acc.consistency.ok)
    if cal.temperature_c is not None:
        params["temperature_c"] = float(cal.temperature_c)
    if cal.sensor.get("model") is not None:
        params["sensor_model"] = str(cal.sensor["model"])
    for name in ("created", "source"):
        if getattr(cal, name) is not None:
            params[name] = getattr(cal, name)
    return params, missing


def _ros_message_covariances(cal: Any, nc: Any, rate: float | None
                             ) -> tuple[dict[str, Any], list[str], list[str]]:
    """``angular_velocity_covariance`` and ``linear_acceleration_covariance`` (nine numbers
    each, :func:`reading_covariance`; all zeros, Imu.msg's "covariance unknown", where the
    noise is not known), the comment lines saying how each was derived, and the notes."""
    zeros = [0.0] * 9
    params: dict[str, Any] = {}
    lines, notes = [], []
    if nc is not None and rate is not None:
        dens = [float(x) for x in nc.noise_density.value]
        cov = reading_covariance(dens, rate, cal.full_matrix)
        params["angular_velocity_covariance"] = [float(x) for x in cov.ravel()]
        lines += ["#   angular_velocity_covariance from the gyro's density (--noise),",
                  "#     rad/s/sqrt(Hz):",
                  f"#     N: {_axes(dens)}"]
    else:
        params["angular_velocity_covariance"] = zeros
        why = ("no --noise document" if nc is None else "no rate (give --update-rate HZ)")
        lines.append(f"#   angular_velocity_covariance: all zeros, 'covariance unknown' ({why})")
        notes.append(f"angular_velocity_covariance is all zeros ('covariance unknown' in "
                     f"sensor_msgs/Imu): {why}; give --noise NOISE.json from 'gyrocal noise "
                     "--json'" + ("" if rate is not None else " and --update-rate HZ"))
    acc = cal.accelerometer
    if acc is not None and acc.noise_density is not None and rate is not None:
        dens = [float(x) for x in acc.noise_density]
        cov = reading_covariance(dens, rate, acc.matrix)
        params["linear_acceleration_covariance"] = [float(x) for x in cov.ravel()]
        lines += ["#   linear_acceleration_covariance from the accelerometer's density measured",
                  "#     on the run's rests, m/s^2/sqrt(Hz):",
                  f"#     N: {_axes(dens)}"]
    else:
        params["linear_acceleration_covariance"] = zeros
        why = ("the calibration has no accelerometer" if acc is None else
               "the calibration has no measured accelerometer noise" if rate is not None
               and acc.noise_density is None else "no rate (give --update-rate HZ)")
        lines.append(f"#   linear_acceleration_covariance: all zeros, 'covariance unknown' "
                     f"({why})")
        notes.append(f"linear_acceleration_covariance is all zeros ('covariance unknown' in "
                     f"sensor_msgs/Imu): {why}")
    return params, lines, notes


_ROS_COVARIANCE_TEXT = [
    "# Per-message covariances for sensor_msgs/Imu (float64[9], row major about x, y, z; copy",
    "# them into every message's fields of the same name), of the CALIBRATED reading:",
    "#     covariance = M diag(N^2 * rate) M^T,  rate = {rate}",
    "#   N the raw reading's white-noise density (continuous time, IEEE Std 952), N^2 * rate the",
    "#   per-sample variance of white noise read at that rate (a chip low-pass narrower than",
    "#   rate/2 makes it smaller: then an upper bound), M the calibration's matrix (matrix, or",
    "#   accel_matrix). Units (rad/s)^2 and (m/s^2)^2.",
]


def _render_ros(doc: Mapping[str, Any], options: Mapping[str, Any]) -> tuple[str, list[str]]:
    from gyrocal.calib.model import GyroCalibration

    cal = GyroCalibration.from_dict(doc)
    frame = options.get("frame_id") or "imu_link"
    if not _ROS_FRAME.match(frame):
        raise InputError(f"--frame-id {frame!r} is not a ROS frame name (letters, digits, _, /)")
    node = options.get("ros_node")
    if node is not None and not _ROS_NODE.match(node):
        raise InputError(f"--ros-node {node!r} is not a ROS node name (e.g. imu_filter, or /**)")
    nc = _noise_option(options)
    rate = _message_rate(options, cal.sensor.get("odr_hz"), None if nc is None else nc.odr_hz)
    params, missing = _ros_params(cal, frame)
    cov_params, cov_lines, notes = _ros_message_covariances(cal, nc, rate)
    params = {**cov_params, **({"covariance_rate_hz": rate} if rate is not None else {}),
              **params}
    if missing:
        notes.append(f"the calibration has no {', '.join(missing)}: left out of the ROS file")
    lines = [
        f"# Gyroscope calibration for ROS, written by gyrocal {__version__} from a Calibration "
        f"v{2 if cal.is_full else 1} document.",
        f"# Frame: {frame} (the IMU's frame_id); rates in rad/s as in sensor_msgs/Imu (REP 103).",
        *[t.format(rate="covariance_rate_hz" if rate is not None else "unknown")
          for t in _ROS_COVARIANCE_TEXT],
        *cov_lines,
        *_ros_model_text(cal),
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


def _ros_model_text(cal: Any) -> list[str]:
    """The comment lines stating the calibration model the ROS parameters hold."""
    if cal.is_full:
        model = [
            "# Model, the full matrix, with i, j over the axes x, y, z of that frame:",
            "#     omega[i] = sum over j of matrix[3*i + j] * (omega_raw[j] + bias[j])",
            "#   matrix     9 numbers, the 3x3 matrix row by row, dimensionless: scale factors on",
            "#              the diagonal (also given as scale), cross-axis terms off it; its frame",
            "#              convention is matrix_frame_convention; matrix_std its one-sigma",
        ]
        cov = ("#   parameter_covariance  12x12 row-major, of the calibration's PARAMETERS "
               "(matrix row by row,\n#              bias_x, bias_y, bias_z): not a "
               "sensor_msgs/Imu covariance")
        if cal.g_sensitivity is not None:
            model[1] = ("#     omega[i] = sum over j of matrix[3*i + j] * (omega_raw[j] + bias[j]"
                        " + sum over k of g_sensitivity[3*j + k] * f[k])")
            model += [
                "#   g_sensitivity  9 numbers, G row by row, rad/s per g; f the specific force",
                "#              in g in the same frame (the accelerometer's linear_acceleration",
                "#              divided by 9.80665: +1 g up when still); g_sensitivity_std its",
                "#              one-sigma; bias is the zero-g bias",
            ]
    else:
        model = [
            "# Model, elementwise per axis x, y, z of that frame:",
            "#     omega = scale * (omega_raw + bias)",
            "#   scale      dimensionless; scale_std its one-sigma",
        ]
        cov = ("#   parameter_covariance  6x6 row-major, of the calibration's PARAMETERS "
               "(scale_x, scale_y,\n#              scale_z, bias_x, bias_y, bias_z): not a "
               "sensor_msgs/Imu covariance")
    return [
        *model,
        "#   omega_raw  the driver's angular_velocity before correction, rad/s",
        "#   omega      the corrected angular_velocity, rad/s",
        "#   bias       rad/s, ADDED to the raw reading (bias_convention: add); a still sensor",
        "#              reads -bias. A node that subtracts an offset must subtract -bias.",
        "#   bias_std   one-sigma, rad/s",
        *cov.split("\n"),
        *([
            "# Accelerometer (from the same run's rests), linear_acceleration in m/s^2:",
            "#     accel[i] = sum over j of accel_matrix[3*i + j] * (accel_raw[j] + accel_bias[j])",
            "#   accel_matrix lower triangular (accel_matrix_frame_convention); accel_bias ADDED",
        ] if cal.accelerometer is not None else []),
    ]


register(
    Exporter(
        name="ros",
        accepts=("gyrocal-calibration",),
        description="YAML parameters for ROS (gyro_calibration: the model, and the "
                    "sensor_msgs/Imu angular_velocity/linear_acceleration covariances)",
        render=_render_ros,
        options=(
            ExportOption("frame_id", str, "ros: the IMU's frame_id (default imu_link)"),
            ExportOption("ros_node", str,
                         "ros: write a ROS 2 parameters file for this node (or /** for all)"),
            _NOISE, _UPDATE_RATE,
        ),
        suffix=".yaml",
    )
)


# ---------------------------------------------------------------------------- imu_calib
def imu_calib_params(acc: Any) -> tuple[list[float], list[float]]:
    """``imu_calib``'s ``SM`` (nine numbers, row-major) and ``bias`` (three, m/s²) for an
    accelerometer calibration ``f = A (a + b)``: ``corrected = SM·raw − bias`` with
    ``SM = A``, ``bias = −A b`` (dpkoch/imu_calib ``src/accel_calib/accel_calib.cpp``, lines
    80 and 205)."""
    import numpy as np

    a = np.asarray(acc.matrix, dtype=float)
    return ([float(x) + 0.0 for x in a.ravel()],
            [float(x) + 0.0 for x in -(a @ np.asarray(acc.bias, dtype=float))])


def _render_imu_calib(doc: Mapping[str, Any], options: Mapping[str, Any]
                      ) -> tuple[str, list[str]]:
    from gyrocal.calib.model import GyroCalibration

    cal = GyroCalibration.from_dict(doc)
    acc = cal.accelerometer
    if acc is None:
        raise InputError("--format imu-calib needs a calibration with an 'accelerometer' (a run "
                         "whose recording has the accelerometer's columns, fitted by "
                         "'gyrocal calibrate' or 'gyrocal estimate')")
    sm, bias = imu_calib_params(acc)
    lines = [
        f"# imu_calib accelerometer calibration (the apply_calib node's calib_file), written by "
        f"gyrocal {__version__}",
        "# from a Calibration's accelerometer. imu_calib applies to linear_acceleration (m/s^2):",
        "#     corrected = SM * raw - bias       (SM row-major 3x3, bias m/s^2, SUBTRACTED)",
        "# which is gyrocal's f = A (a + b) with SM = A and bias = -A b. Frame: the chip's axes",
        "# as gyrocal read them (accel-x-xy convention); the raw message must be in those axes.",
        f"# Local gravity of the fit: {acc.gravity:.6f} m/s^2.",
        f"SM: [{', '.join(_yaml_float(x) for x in sm)}]",
        f"bias: [{', '.join(_yaml_float(x) for x in bias)}]",
    ]
    import numpy as np

    worst = max(abs(x) for x in (np.asarray(cal.full_matrix) - np.eye(3)).ravel())
    notes = [
        "imu_calib calibrates the gyro only by a bias it averages at start-up "
        "(apply_calib's calibrate_gyros, default true: keep the IMU still); the gyro calibration "
        f"(matrix, up to {worst:.2e} from the identity, and bias) is not in this file: use "
        "--format ros for it",
        "the file is in the chip's axes: a driver that remaps the axes before publishing "
        "linear_acceleration needs the same remap of SM and bias",
    ]
    return "\n".join(lines) + "\n", notes


register(
    Exporter(
        name="imu-calib",
        accepts=("gyrocal-calibration",),
        description="the accelerometer for the imu_calib ROS package (SM, bias: corrected = "
                    "SM raw - bias)",
        render=_render_imu_calib,
        suffix=".yaml",
    )
)
