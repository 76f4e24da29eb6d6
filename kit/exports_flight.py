"""Plain calibration exports to the flight stacks: the gyro offsets, and the accelerometer's
offsets and scales when the calibration has one (issue 31).

PX4 (``--format px4``), a QGroundControl parameter file: ``CAL_GYRO<n>_ID`` and
``CAL_GYRO<n>_XOFF/YOFF/ZOFF`` (rad/s), applied by ``calibration::Gyroscope::Correct``
(PX4-Autopilot ``src/lib/sensor_calibration/Gyroscope.hpp``):
``corrected = _rotation · (data − _thermal_offset − _offset)``; with an accelerometer also
``CAL_ACC<n>_ID``, ``CAL_ACC<n>_?OFF`` and ``_?SCALE`` (:mod:`gyrocal.kit.exports_accel`). The ID
is the device ID of the calibration's chip, bus and address (:mod:`gyrocal.kit.px4_ids`) or
``--device-id``: PX4 uses a ``CAL_GYRO<n>_*`` slot only for the sensor whose ID it holds.

ArduPilot (``--format ardupilot``), a Mission Planner parameter file: ``INS_GYROFFS_X/Y/Z``
(``INS_GYR2OFFS_*``, ``INS_GYR3OFFS_*`` for the second and third IMU), applied by
``AP_InertialSensor_Backend::_rotate_and_correct_gyro``: ``gyro -= _gyro_offset``; with an
accelerometer also ``INS_ACCOFFS_*`` and ``INS_ACCSCAL_*``.

gyrocal's reading is ``m + b`` before its matrix, so the offset is ``−b``; both stacks subtract it
in the frame their driver publishes, so it is written as ``T (−b)``
(:mod:`gyrocal.kit.consumer_frames`). Neither stack has a gyro scale or cross-axis parameter, nor
a g-sensitivity: notes on stderr say what is left out and how large it is.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

from gyrocal.kit.exports import Exporter, g_sensitivity_note, register
from gyrocal.kit.exports_accel import ardupilot_accel_params, cross_axis_note, px4_accel_params
from gyrocal.kit.exports_thermal import (
    AXES_OPTION,
    DEVICE_ID_OPTION,
    INDEX_OPTION,
    ROTATION_OPTION,
    ardupilot_gyro_offsets,
    check_imu_index,
)
from gyrocal.kit.px4_ids import MAV_INT32, MAV_REAL32, px4_device_id, qgc_params

if TYPE_CHECKING:  # numpy stays out of 'gyrocal export --help'
    from gyrocal.kit.consumer_frames import FrameMapping

__all__ = ["px4_gyro_params"]


def px4_gyro_params(bias: Any, frame: FrameMapping, instance: int = 0
                    ) -> list[tuple[str, float, int]]:
    """PX4's ``CAL_GYRO<instance>_XOFF/YOFF/ZOFF`` removing the chip-frame ``bias`` (PX4:
    ``data − offset``), in ``frame``."""
    off = frame.vector([-float(b) for b in bias])
    return [(f"CAL_GYRO{instance}_{a}OFF", v, MAV_REAL32) for a, v in zip("XYZ", off, strict=True)]


def _calibration(doc: Mapping[str, Any]) -> Any:
    from gyrocal.calib.model import GyroCalibration

    return GyroCalibration.from_dict(doc)


def _temperature_note(cal: Any, thermal_format: str) -> list[str]:
    if cal.temperature_model is None:
        return []
    return [f"the offsets are the bias at the calibration's {cal.temperature_c:g} degC; the "
            f"calibration's temperature model goes to --format {thermal_format}"
            if cal.temperature_c is not None else
            f"the calibration's temperature model goes to --format {thermal_format}"]


def _render_px4(doc: Mapping[str, Any], options: Mapping[str, Any]) -> tuple[str, list[str]]:
    from gyrocal.kit.consumer_frames import frame_mapping, gyro_model_note

    cal = _calibration(doc)
    inst = check_imu_index(options.get("imu_index"), 0, 3, "PX4's CAL_GYRO0..3 / CAL_ACC0..3")
    frame = frame_mapping("px4", doc.get("sensor"), options)
    dev, how = options.get("device_id"), "given with --device-id"
    if dev is None:
        dev, how = px4_device_id(doc.get("sensor"))
    ids = ["CAL_GYRO"] + (["CAL_ACC"] if cal.accelerometer is not None else [])
    rows = [(f"{p}{inst}_ID", dev, MAV_INT32) for p in ids if dev is not None]
    rows += px4_gyro_params(cal.bias, frame, inst)
    notes = [frame.note, gyro_model_note(cal, "px4"),
             *g_sensitivity_note(cal, "PX4's CAL_GYRO parameters"),
             *_temperature_note(cal, "px4-thermal"),
             (f"{' and '.join(f'{p}{inst}_ID' for p in ids)}: {how}" if dev is not None else
              f"{' and '.join(f'{p}{inst}_ID' for p in ids)} not written: {how}; give "
              "--device-id (CAL_GYROn_ID on the vehicle), or these values apply to whichever "
              "sensor the vehicle already has in that slot")]
    if cal.accelerometer is not None:
        rows += px4_accel_params(cal.accelerometer, frame, inst)
        notes.append(cross_axis_note(cal.accelerometer, "PX4"))
    text = qgc_params("gyro offsets" + (" and accelerometer calibration"
                                        if cal.accelerometer is not None else "")
                      + " written by gyrocal from a Calibration", rows)
    return text, notes


def _render_ardupilot(doc: Mapping[str, Any], options: Mapping[str, Any]
                      ) -> tuple[str, list[str]]:
    from gyrocal.kit.consumer_frames import frame_mapping, gyro_model_note

    cal = _calibration(doc)
    imu = check_imu_index(options.get("imu_index"), 1, 3, "ArduPilot's INS_GYR(OFFS), "
                          "INS_GYR2OFFS, INS_GYR3OFFS")
    frame = frame_mapping("ardupilot", doc.get("sensor"), options)
    params = ardupilot_gyro_offsets(cal.bias, frame, imu)
    notes = [frame.note, gyro_model_note(cal, "ardupilot"),
             *g_sensitivity_note(cal, "ArduPilot's INS_GYROFFS parameters"),
             *_temperature_note(cal, "ardupilot-thermal"),
             "with INS_GYR_CAL = 1 (the default) ArduPilot measures the gyro offsets again at "
             "every boot and overwrites these; set INS_GYR_CAL to 0 to keep them"]
    if cal.accelerometer is not None:
        params += ardupilot_accel_params(cal.accelerometer, frame, imu)
        notes.append(cross_axis_note(cal.accelerometer, "ArduPilot"))
    lines = ["# ArduPilot gyro offsets" + (" and accelerometer calibration"
                                           if cal.accelerometer is not None else "")
             + " written by gyrocal from a Calibration"]
    lines += [f"{name},{value + 0.0:.9g}" for name, value in params]
    return "\n".join(lines) + "\n", notes


register(Exporter(
    name="px4", accepts=("gyrocal-calibration",),
    description="PX4 gyro offsets CAL_GYROn_?OFF (and CAL_ACCn_?OFF/?SCALE with an "
                "accelerometer), in the frame of PX4's driver for the chip (QGroundControl "
                ".params)",
    render=_render_px4, suffix=".params",
    options=(INDEX_OPTION, DEVICE_ID_OPTION, AXES_OPTION, ROTATION_OPTION),
))
register(Exporter(
    name="ardupilot", accepts=("gyrocal-calibration",),
    description="ArduPilot gyro offsets INS_GYROFFS_? (and INS_ACCOFFS_?/INS_ACCSCAL_? with an "
                "accelerometer), in the frame of ArduPilot's driver for the chip (Mission "
                "Planner .param)",
    render=_render_ardupilot, suffix=".param",
    options=(INDEX_OPTION, AXES_OPTION, ROTATION_OPTION),
))
