"""Exports of a calibration's temperature model to the flight stacks (issue 13).

Both stacks correct only the gyro's bias against temperature; neither has a gyro scale factor or
cross-axis matrix, so those parts of the calibration are not carried (a note says so).

PX4 (``--format px4-thermal``), parameters ``TC_G<n>_*`` of the thermal compensation
(PX4-Autopilot ``src/modules/temperature_compensation``; ``TemperatureCompensation::
calc_thermal_offsets_3D`` and ``Gyroscope::Correct``):

    ``offset = X0 + X1·dT + X2·dT² + X3·dT³``, ``dT = clamp(T, TMIN, TMAX) − TREF``,
    ``corrected = raw − offset − CAL_GYRO<n>_?OFF``  (rad/s).

gyrocal's model reads ``raw + b(T)``, so ``X_k = −c_k`` with ``TREF`` the model's reference and
``TMIN``/``TMAX`` its covered range. Written as a QGroundControl parameter file.

ArduPilot (``--format ardupilot-thermal``), ``INS_TCAL<n>_*`` (``AP_InertialSensor_tempcal.cpp``,
``TCal::correct_sensor``, and ``AP_InertialSensor_Backend::_rotate_and_correct_gyro``):

    ``P(x) = (GYR1 + (GYR2 + GYR3·x)·x)·x · 1e-6``,  ``T`` and ``CALTEMP`` clamped to
    ``[TMIN, TMAX]``,
    ``corrected = raw − P(T − 35) + P(CALTEMP − 35) − INS_GYROFFS``  (rad/s; 35 °C is the fixed
    ``TEMP_REFERENCE``).

gyrocal's ``b(T)`` is re-expanded in powers of ``T − 35``; ``GYRk = −e_k·1e6`` (no constant
term), ``INS_GYR<n>_CALTEMP`` the model's reference and ``INS_GYROFFS`` (``INS_GYR<n>OFFS`` for
n > 1) ``−b(reference)``. Written as a Mission Planner parameter file (``NAME,VALUE``).

Both stacks add these terms after their driver has remapped the chip's axes (and turned them by
the driver's rotation): every per-axis vector above is written in that frame
(:mod:`gyrocal.kit.consumer_frames`, ``--driver-axes``, ``--rotation``), and a note on stderr
names the mapping.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

from gyrocal.kit.errors import InputError
from gyrocal.kit.exports import Exporter, ExportOption, g_sensitivity_note, register
from gyrocal.kit.px4_ids import (
    MAV_INT32,
    MAV_REAL32,
    device_id_arg,
    px4_device_id,
    qgc_params,
)

if TYPE_CHECKING:  # numpy stays out of 'gyrocal export --help'
    from gyrocal.kit.consumer_frames import FrameMapping

__all__ = ["ARDUPILOT_TEMP_REFERENCE_C", "AXES_OPTION", "DEVICE_ID_OPTION", "INDEX_OPTION",
           "ROTATION_OPTION",
           "ardupilot_gyro_offsets", "ardupilot_params", "check_imu_index", "px4_params"]

#: ArduPilot's fixed reference temperature of INS_TCALn (AP_InertialSensor_tempcal.cpp).
ARDUPILOT_TEMP_REFERENCE_C = 35.0
_ARDUPILOT_SCALE = 1.0e6  # its SCALE_FACTOR: the coefficients are stored times 1e6

_ACCEL_ELSEWHERE = ("the calibration's accelerometer is not in these gyro parameters: export "
                    "it with --format {fmt}")


def _model(doc: Mapping[str, Any], fmt: str) -> Any:
    from gyrocal.calib.model import GyroCalibration

    cal = GyroCalibration.from_dict(doc)
    if cal.temperature_model is None:
        raise InputError(f"--format {fmt} needs a calibration with a temperature_model; fit one "
                         "with 'gyrocal thermal'")
    return cal


def px4_params(cal: Any, frame: FrameMapping, instance: int = 0,
               device_id: int = 0) -> list[tuple[str, float, int]]:
    """PX4's ``TC_G<instance>_*`` (and ``TC_G_ENABLE``) for ``cal``'s temperature model, in the
    ``frame`` PX4 subtracts them in: ``(name, value, MAV_PARAM_TYPE)``."""
    tm = cal.temperature_model
    p = f"TC_G{instance}_"
    out: list[tuple[str, float, int]] = [("TC_G_ENABLE", 1, MAV_INT32),
                                         (p + "ID", device_id, MAV_INT32),
                                         (p + "TMIN", tm.range_c[0], MAV_REAL32),
                                         (p + "TMAX", tm.range_c[1], MAV_REAL32),
                                         (p + "TREF", tm.reference_c, MAV_REAL32)]
    for k in range(4):
        chip = [-float(tm.bias_coeffs[axis, k]) if k <= tm.bias_order else 0.0
                for axis in range(3)]
        out += [(f"{p}X{k}_{axis}", v, MAV_REAL32)
                for axis, v in enumerate(frame.vector(chip))]
    return out


def _about(reference: float, coeffs: Any, order: int) -> list[float]:
    """Coefficients of ``Σ c_k u^k`` (``u = T − reference``) in powers of ``x = T − 35``."""
    s = ARDUPILOT_TEMP_REFERENCE_C - reference  # u = x + s
    e = [0.0] * 4
    for k in range(order + 1):
        for j in range(k + 1):
            e[j] += float(coeffs[k]) * math.comb(k, j) * s ** (k - j)
    return e


def ardupilot_gyro_offsets(bias: Any, frame: FrameMapping, imu: int = 1
                           ) -> list[tuple[str, float]]:
    """ArduPilot's ``INS_GYROFFS_*`` (``INS_GYR<imu>OFFS_*`` for imu > 1) removing the chip-frame
    ``bias`` (gyrocal's reading is ``raw + bias``; ArduPilot's ``gyro -= offset``), in
    ``frame``."""
    offs = "INS_GYROFFS_" if imu == 1 else f"INS_GYR{imu}OFFS_"
    return [(offs + name, v) for name, v in
            zip("XYZ", frame.vector([-float(b) for b in bias]), strict=True)]


def ardupilot_params(cal: Any, frame: FrameMapping, imu: int = 1) -> list[tuple[str, float]]:
    """ArduPilot's ``INS_TCAL<imu>_*``, gyro offsets and calibration temperature for ``cal``'s
    temperature model, in the ``frame`` ArduPilot applies them in."""
    tm = cal.temperature_model
    t = f"INS_TCAL{imu}_"
    out: list[tuple[str, float]] = [(t + "ENABLE", 1), (t + "TMIN", tm.range_c[0]),
                                    (t + "TMAX", tm.range_c[1])]
    e = [_about(tm.reference_c, tm.bias_coeffs[axis], tm.bias_order) for axis in range(3)]
    for k in (1, 2, 3):
        coeffs = frame.vector([-e[axis][k] * _ARDUPILOT_SCALE for axis in range(3)])
        out += [(f"{t}GYR{k}_{name}", v) for name, v in zip("XYZ", coeffs, strict=True)]
    out.append((f"INS_GYR{imu}_CALTEMP", tm.reference_c))
    return out + ardupilot_gyro_offsets(tm.at(tm.reference_c).bias, frame, imu)


def check_imu_index(value: Any, lo: int, hi: int, what: str) -> int:
    """``--imu-index`` (default ``lo``) within a flight stack's ``lo..hi`` instances."""
    v = lo if value is None else value
    if not lo <= v <= hi:
        raise InputError(f"--imu-index {v} is outside {lo}..{hi} for {what}")
    return int(v)


def _render_px4(doc: Mapping[str, Any], options: Mapping[str, Any]) -> tuple[str, list[str]]:
    from gyrocal.kit.consumer_frames import frame_mapping, gyro_model_note

    cal = _model(doc, "px4-thermal")
    inst = check_imu_index(options.get("imu_index"), 0, 3, "PX4's TC_G0..TC_G3")
    dev = options.get("device_id")
    how = None
    if dev is None:
        dev, how = px4_device_id(doc.get("sensor"))
    frame = frame_mapping("px4", doc.get("sensor"), options)
    rows = px4_params(cal, frame, inst, 0 if dev is None else int(dev))
    text = qgc_params("gyro thermal compensation written by gyrocal from a temperature_model",
                      rows)
    notes = [frame.note, gyro_model_note(cal, "px4"),
             *g_sensitivity_note(cal, "PX4's TC_G parameters"),
             f"the whole bias is in TC_G{inst}_X0_*: set CAL_GYRO{inst}_XOFF/YOFF/ZOFF to 0, or "
             "the bias is removed twice"]
    if dev is None:
        notes.append(f"TC_G{inst}_ID is 0 ({how}): set it to the gyro's device ID "
                     f"(CAL_GYRO{inst}_ID on the vehicle) with --device-id, or PX4 will not use "
                     "these parameters")
    elif how is not None:
        notes.append(f"TC_G{inst}_ID from the calibration: {how}")
    if cal.accelerometer is not None:
        notes.append(_ACCEL_ELSEWHERE.format(fmt="px4-accel"))
    return text, notes


def _render_ardupilot(doc: Mapping[str, Any], options: Mapping[str, Any]
                      ) -> tuple[str, list[str]]:
    from gyrocal.kit.consumer_frames import frame_mapping, gyro_model_note

    cal = _model(doc, "ardupilot-thermal")
    imu = check_imu_index(options.get("imu_index"), 1, 3, "ArduPilot's INS_TCAL1..3")
    lines = ["# ArduPilot gyro temperature calibration written by gyrocal from a "
             "temperature_model"]
    frame = frame_mapping("ardupilot", doc.get("sensor"), options)
    lines += [f"{name},{value + 0.0:.9g}" for name, value in ardupilot_params(cal, frame, imu)]
    notes = [frame.note, gyro_model_note(cal, "ardupilot"),
             *g_sensitivity_note(cal, "ArduPilot's INS_TCAL parameters"),
             "with INS_GYR_CAL = 1 (the default) ArduPilot re-measures the gyro offsets at "
             "every boot and overwrites INS_GYROFFS and the CALTEMP; the temperature terms then "
             "still apply about the boot temperature"]
    if cal.accelerometer is not None:
        notes.append(_ACCEL_ELSEWHERE.format(fmt="ardupilot-accel"))
    return "\n".join(lines) + "\n", notes


AXES_OPTION = ExportOption(
    "driver_axes", str,
    "flight-stack formats: the axes the stack's driver publishes, in the chip's terms (e.g. "
    "x,-y,-z), instead of the built-in table's row for the calibration's chip; x,y,z writes the "
    "chip's own axes")
ROTATION_OPTION = ExportOption(
    "rotation", str,
    "flight-stack formats: the rotation the stack's driver applies before the offsets, a "
    "ROTATION_* name or number of the stack's enum (PX4: the driver's -R; ArduPilot: the IMU "
    "line's rotation in the board's hwdef); default ROTATION_NONE. SENS_BOARD_ROT and "
    "AHRS_ORIENTATION act after the offsets and need nothing here")


DEVICE_ID_OPTION = ExportOption("device_id", device_id_arg,
                                "px4 / px4-thermal: the gyro's device ID for CAL_GYROn_ID, "
                                "CAL_ACCn_ID and TC_Gn_ID (CAL_GYROn_ID on the vehicle; default "
                                "from the calibration's chip, bus and address)")
INDEX_OPTION = ExportOption("imu_index", int,
                            "flight-stack formats: which sensor of the vehicle (PX4 CAL_GYROn, "
                            "CAL_ACCn, TC_Gn: 0-3, default 0; ArduPilot INS_GYROFFS, INS_GYR2OFFS, "
                            "INS_TCAL2, ...: 1-3, default 1)")
register(Exporter(
    name="px4-thermal", accepts=("gyrocal-calibration",),
    description="PX4 gyro thermal compensation parameters TC_Gn_* (QGroundControl .params)",
    render=_render_px4, suffix=".params",
    options=(INDEX_OPTION, DEVICE_ID_OPTION, AXES_OPTION, ROTATION_OPTION),
))
register(Exporter(
    name="ardupilot-thermal", accepts=("gyrocal-calibration",),
    description="ArduPilot gyro temperature calibration INS_TCALn_* (Mission Planner .param)",
    render=_render_ardupilot, suffix=".param", options=(INDEX_OPTION, AXES_OPTION, ROTATION_OPTION),
))
