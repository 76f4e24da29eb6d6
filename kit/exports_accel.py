"""Exports of a calibration's accelerometer (the Calibration's ``accelerometer`` key, issue 15)
to the flight stacks' accelerometer calibration parameters.

Both stacks correct the accelerometer per axis with an offset and a scale factor, and neither
has a cross-axis matrix:

PX4 (``--format px4-accel``), ``CAL_ACC<n>_XOFF/YOFF/ZOFF`` (m/s²) and ``CAL_ACC<n>_XSCALE/
YSCALE/ZSCALE`` (PX4-Autopilot ``src/lib/sensor_calibration/Accelerometer``, parameters in
``src/modules/sensors``): ``corrected = (raw − offset) ⊙ scale``; with ``CAL_ACC<n>_ID`` when the
calibration says the chip, bus and address (:mod:`gyrocal.kit.px4_ids`). Written as a
QGroundControl parameter file.

ArduPilot (``--format ardupilot-accel``), ``INS_ACCOFFS_X/Y/Z`` and ``INS_ACCSCAL_X/Y/Z`` (the
second and third IMU ``INS_ACC2OFFS_*``/``INS_ACC2SCAL_*``, ``INS_ACC3…``;
``AP_InertialSensor_Backend::_rotate_and_correct_accel``): ``accel −= offset`` then each axis
times its scale (m/s²). Written as a Mission Planner parameter file (``NAME,VALUE``).

gyrocal's ``f = A (a + b)`` (:mod:`gyrocal.calib.accel`) gives ``offset = −b`` and
``scale = diag(A)`` in the chip's axes; the cross-axis terms (``A``'s lower triangle) have no
place, and a note on stderr says how large the error they leave is.

Both stacks subtract the offset and apply the scale after their driver has remapped the chip's
axes and turned them by the driver's rotation, so the offsets are written as ``T (−b)`` and the
scales as ``|T| diag(A)`` with ``T`` from :mod:`gyrocal.kit.consumer_frames` (``--driver-axes``,
``--rotation``); a note on stderr names the mapping.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

from gyrocal.kit.errors import InputError
from gyrocal.kit.exports import Exporter, register
from gyrocal.kit.exports_thermal import (
    AXES_OPTION,
    INDEX_OPTION,
    ROTATION_OPTION,
    check_imu_index,
)
from gyrocal.kit.px4_ids import MAV_INT32, MAV_REAL32, px4_device_id, qgc_params

if TYPE_CHECKING:  # numpy stays out of 'gyrocal export --help'
    from gyrocal.kit.consumer_frames import FrameMapping

__all__ = ["accel_offsets_scales", "ardupilot_accel_params", "cross_axis_note",
           "px4_accel_params"]



def _accelerometer(doc: Mapping[str, Any], fmt: str) -> Any:
    from gyrocal.calib.model import GyroCalibration

    cal = GyroCalibration.from_dict(doc)
    if cal.accelerometer is None:
        raise InputError(f"--format {fmt} needs a calibration with an 'accelerometer' (a run "
                         "whose recording has the accelerometer's columns, fitted by "
                         "'gyrocal calibrate' or 'gyrocal estimate')")
    return cal.accelerometer


def accel_offsets_scales(acc: Any, frame: FrameMapping) -> tuple[list[float], list[float]]:
    """The per-axis ``(offset, scale)`` of ``corrected = (raw − offset) ⊙ scale`` nearest
    ``f = A (a + b)``, in the stack's ``frame``: ``offset = T (−b)``, ``scale = |T| diag(A)``."""
    return (frame.vector([-float(x) for x in acc.bias], "accel"),
            frame.scales([float(acc.matrix[i][i]) for i in range(3)], "accel"))


def px4_accel_params(acc: Any, frame: FrameMapping,
                     instance: int = 0) -> list[tuple[str, float, int]]:
    """PX4's ``CAL_ACC<instance>_?OFF`` and ``_?SCALE`` in ``frame``: ``(name, value,
    MAV_PARAM_TYPE)``."""
    off, scale = accel_offsets_scales(acc, frame)
    p = f"CAL_ACC{instance}_"
    return ([(f"{p}{a}OFF", o, MAV_REAL32) for a, o in zip("XYZ", off, strict=True)]
            + [(f"{p}{a}SCALE", s, MAV_REAL32) for a, s in zip("XYZ", scale, strict=True)])


def ardupilot_accel_params(acc: Any, frame: FrameMapping, imu: int = 1
                           ) -> list[tuple[str, float]]:
    """ArduPilot's ``INS_ACCOFFS_*``/``INS_ACCSCAL_*`` (``INS_ACC<imu>OFFS_*`` for imu > 1) in
    ``frame``."""
    off, scale = accel_offsets_scales(acc, frame)
    n = "" if imu == 1 else str(imu)
    return ([(f"INS_ACC{n}OFFS_{a}", o) for a, o in zip("XYZ", off, strict=True)]
            + [(f"INS_ACC{n}SCAL_{a}", s) for a, s in zip("XYZ", scale, strict=True)])


def cross_axis_note(acc: Any, stack: str) -> str:
    """What the stacks' per-axis accelerometer correction leaves of ``acc``'s cross-axis
    terms."""
    a = acc.matrix
    worst = max(abs(float(a[i][j])) for i in range(3) for j in range(3) if i != j)
    return (f"{stack} has no accelerometer cross-axis terms: the calibration's (up to "
            f"{worst:.2e} of the reading; frame accel-x-xy) are not in these parameters, so "
            f"the corrected force keeps an error of up to about {worst * 9.81:.3f} m/s^2 at 1 g")


def _render_px4(doc: Mapping[str, Any], options: Mapping[str, Any]) -> tuple[str, list[str]]:
    from gyrocal.kit.consumer_frames import frame_mapping

    acc = _accelerometer(doc, "px4-accel")
    inst = check_imu_index(options.get("imu_index"), 0, 3, "PX4's CAL_ACC0..CAL_ACC3")
    frame = frame_mapping("px4", doc.get("sensor"), options)
    dev_id, how = px4_device_id(doc.get("sensor"))
    rows = ([(f"CAL_ACC{inst}_ID", dev_id, MAV_INT32)] if dev_id is not None else []) \
        + px4_accel_params(acc, frame, inst)
    text = qgc_params("accelerometer calibration written by gyrocal from a Calibration's "
                      "accelerometer", rows)
    notes = [frame.note, cross_axis_note(acc, "PX4"),
             f"CAL_ACC{inst}_ID: {how}" if dev_id is not None else
             f"CAL_ACC{inst}_ID is not written: {how}; these parameters then apply to the "
             "accelerometer whose ID the vehicle already has in that slot"]
    return text, notes


def _render_ardupilot(doc: Mapping[str, Any], options: Mapping[str, Any]
                      ) -> tuple[str, list[str]]:
    from gyrocal.kit.consumer_frames import frame_mapping

    acc = _accelerometer(doc, "ardupilot-accel")
    imu = check_imu_index(options.get("imu_index"), 1, 3, "ArduPilot's INS_ACC, INS_ACC2, INS_ACC3")
    lines = ["# ArduPilot accelerometer calibration written by gyrocal from a Calibration's "
             "accelerometer"]
    frame = frame_mapping("ardupilot", doc.get("sensor"), options)
    lines += [f"{name},{value + 0.0:.9g}"
              for name, value in ardupilot_accel_params(acc, frame, imu)]
    return "\n".join(lines) + "\n", [frame.note, cross_axis_note(acc, "ArduPilot")]


register(Exporter(
    name="px4-accel", accepts=("gyrocal-calibration",),
    description="PX4 accelerometer calibration CAL_ACCn_?OFF/?SCALE (QGroundControl .params)",
    render=_render_px4, suffix=".params", options=(INDEX_OPTION, AXES_OPTION, ROTATION_OPTION),
))
register(Exporter(
    name="ardupilot-accel", accepts=("gyrocal-calibration",),
    description="ArduPilot accelerometer calibration INS_ACCOFFS/INS_ACCSCAL (Mission "
                "Planner .param)",
    render=_render_ardupilot, suffix=".param", options=(INDEX_OPTION, AXES_OPTION, ROTATION_OPTION),
))
