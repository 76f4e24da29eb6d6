"""The frames the flight stacks apply a calibration in: one row per stack and chip (issue 31).

gyrocal's calibration is in the chip's own axes (the reading ``m`` of ``g = A (m + b)`` is the
chip's x, y, z registers). Neither PX4 nor ArduPilot subtracts an offset from the chip's axes:
each driver first remaps them into the frame it publishes, the stack then turns that by the
rotation the driver was started with, and only then subtracts the offsets (and the temperature
terms) and applies the accelerometer scales:

PX4 (PX4-Autopilot)
    driver ``Process*``/``FIFORead`` remap → ``PX4Gyroscope::updateFIFO`` /
    ``PX4Accelerometer::updateFIFO`` ``rotate_3i(_rotation, …)``, the driver's ``-R`` rotation
    (``src/lib/drivers/gyroscope/PX4Gyroscope.cpp@000f5fd:148``) →
    ``calibration::Gyroscope::Correct``: ``_rotation * (data − _thermal_offset − _offset)``
    (``src/lib/sensor_calibration/Gyroscope.hpp@13db2eb:77``) and
    ``calibration::Accelerometer::Correct``: ``_rotation * ((data − _thermal_offset −
    _offset) ⊙ _scale)`` (``Accelerometer.hpp@011a413:84``), whose ``_rotation``
    (``SENS_BOARD_ROT``, or ``CAL_GYROn_ROT`` / ``CAL_ACCn_ROT`` for an external sensor) turns the
    corrected vector *after* the offsets; ``_thermal_offset`` is
    ``TemperatureCompensation::calc_thermal_offsets_3D``
    (``src/modules/temperature_compensation/TemperatureCompensation.cpp@09f282b:283-308``).

ArduPilot (ArduPilot/ardupilot, ``libraries/AP_InertialSensor``)
    backend remap → ``AP_InertialSensor_Backend::_rotate_and_correct_gyro``: ``gyro.rotate(
    _gyro_orientation)`` (the rotation the board's hwdef gives the IMU at probe) →
    ``TCal::correct_gyro`` (``INS_TCALn_*``) → ``gyro -= _gyro_offset`` (``INS_GYROFFS_*``) →
    ``gyro.rotate(_board_orientation)`` (``AHRS_ORIENTATION``) (``AP_InertialSensor_Backend.cpp``
    :140, :152, :156, :159); ``_rotate_and_correct_accel`` the same (:103, :119) with ``accel -=
    _accel_offset`` (:123) then ``accel ⊙ _accel_scale`` (:128-130) (``INS_ACCOFFS_*``,
    ``INS_ACCSCAL_*``). Lines of the stored version that has the orientation and ``TCal`` steps
    (29096 characters; the source index gives no commit for it: the versions it does date,
    @010cfbe and @ee45378, predate both steps). ``TCal::correct_sensor``:
    ``AP_InertialSensor_tempcal.cpp@025810d:210-227`` (``TEMP_REFERENCE`` 35.0 at :40).

So a parameter for published axis ``i`` belongs to the chip axis the driver puts there, with the
driver's sign: :data:`DRIVER_FRAMES` holds each driver's remap as the published axes in the
chip's terms (``"x,-y,-z"``: published x = chip x, y = −chip y, z = −chip z), with the file,
line and statement it comes from. :data:`ROTATIONS` holds the stacks' ``enum Rotation`` entries that
are whole quarter turns (PX4 ``src/lib/conversion/rotation.h``; ArduPilot
``libraries/AP_Math/rotations.h``; both turn a vector by ``Rz(yaw) Ry(pitch) Rx(roll)``, as their
``rotate`` cases show, e.g. ``ROTATION_ROLL_90_YAW_90``: ``x, y, z ← z, x, y``).
``SENS_BOARD_ROT``, ``CAL_*_ROT`` and ``AHRS_ORIENTATION`` act after the offsets and need
nothing here; the driver's own rotation (PX4 ``-R``, ArduPilot's hwdef ``IMU`` line) acts before
them and is the exports' ``--rotation`` option (``--driver-axes`` replaces the table's row).

Each stack's correction is per axis (an offset, and a scale for the accelerometer), so a
calibration maps into it exactly for the parts the stack has: an offset vector ``o`` becomes
``T o`` and a per-axis scale ``s`` becomes ``|T| s``, with ``T`` the signed permutation
``R · remap``.
"""

from __future__ import annotations

import math
import re
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from gyrocal.kit.errors import InputError

__all__ = ["DRIVER_FRAMES", "ROTATIONS", "STACKS", "DriverFrame", "FrameMapping", "axes_matrix",
           "driver_frame", "frame_mapping", "gyro_model_note", "rotation_matrix"]

#: Stack key -> its name in messages.
STACKS: Mapping[str, str] = {"px4": "PX4", "ardupilot": "ArduPilot"}


@dataclass(frozen=True)
class DriverFrame:
    """What one stack's mainline driver for one chip publishes.

    Attributes
    ----------
    stack, chip : str
        A key of :data:`STACKS`; gyrocal's sensor model (``sensor.model`` of a calibration).
    gyro, accel : str
        The published x, y, z in the chip's axes, e.g. ``"x,-y,-z"``.
    source : str
        The driver file (in the stack's repository, at the stored commit) and the statements.
    note : str
        What else a user of that driver should know (bus, handedness), or "".
    """

    stack: str
    chip: str
    gyro: str
    accel: str
    source: str
    note: str = ""


_PX4 = "PX4-Autopilot"
_AP = "ArduPilot libraries/AP_InertialSensor/"
_PX4_FLIP = "'flip y & z to publish right handed with z down': y = -y, z = -z"
_AP_SWAP = "Vector3f(int16_val(data, 1), int16_val(data, 0), -int16_val(data, 2))"

#: One row per stack and chip: the remap of each mainline driver, read from its source and cited
#: as ``file@commit:line`` (the commit the source index stores; lines counted from its text).
#: PX4 has no row for the MPU-9255: its mpu9250 drivers take only WHO_AM_I 0x71 and its mpu6500
#: driver only 0x70 (the MPU-9255 answers 0x73), so no PX4 driver reads it.
DRIVER_FRAMES: tuple[DriverFrame, ...] = (
    DriverFrame("px4", "mpu9250", "x,-y,-z", "x,-y,-z",
                f"{_PX4} src/drivers/imu/invensense/mpu9250/MPU9250_I2C.cpp@023e613:536-537 "
                "(ProcessAccel) and :566-567 (ProcessGyro), "
                f"{_PX4_FLIP} (gyro.y = -gyro_y, gyro.z = -gyro_z; accel the same); the SPI "
                "driver MPU9250.cpp@02f4ad6:578-579 and :607-608 the same; both take only "
                "WHO_AM_I 0x71 (InvenSense_MPU9250_registers.hpp@033e9ce:62, "
                "MPU9250.cpp@02f4ad6:140)"),
    DriverFrame("px4", "mpu6500", "x,-y,-z", "x,-y,-z",
                f"{_PX4} src/drivers/imu/invensense/mpu6500/MPU6500.cpp@542f41f:547-548 "
                f"(ProcessAccel) and :577-578 (ProcessGyro), {_PX4_FLIP}; WHO_AM_I 0x70 "
                "(MPU6500.cpp@542f41f:113, InvenSense_MPU6500_registers.hpp@0860a61)",
                "an older version (@050fa47, ProcessAccel) published the accelerometer's z from "
                "the chip's y (accel.z = math::negate(accel_y)), so on such firmware no CAL_ACC "
                "value makes its z right"),
    DriverFrame("px4", "icm20948", "x,-y,-z", "x,-y,-z",
                f"{_PX4} src/drivers/imu/invensense/icm20948/ICM20948.cpp@023e613:666-667 "
                f"(ProcessAccel) and :696-697 (ProcessGyro), {_PX4_FLIP}"),
    DriverFrame("px4", "icm42688p", "x,-y,-z", "x,-y,-z",
                f"{_PX4} src/drivers/imu/invensense/icm42688p/ICM42688P.cpp@00d281a:723-724 "
                "(ProcessAccel) and :805-806 (ProcessGyro), under 'correct frame for "
                f"publication' (:718, :800): {_PX4_FLIP}"),
    DriverFrame("px4", "lsm9ds1", "x,y,-z", "x,y,-z",
                f"{_PX4} src/drivers/imu/st/lsm9ds1/LSM9DS1.cpp@26d971b:362-363 and :390-391 "
                "(FIFORead): gyro.y = gyro_y, gyro.z = -gyro_z (accel the same) under the same "
                "'flip y & z' comment",
                "a mirror image of the chip's axes (only z flipped); the driver runs on SPI "
                "(it sets CTRL_REG9 I2C_DISABLE, LSM9DS1.cpp@26d971b:129); an older version "
                "(@050fa47) published the accelerometer's z from the chip's y (accel.z = "
                "math::negate(accel_y)), so on such firmware no CAL_ACC value makes its z "
                "right"),
    DriverFrame("px4", "lsm6dsox", "x,y,z", "x,y,z",
                f"{_PX4} src/drivers/imu/st/lsm6dso/LSM6DSO.cpp@ed717f0:371-373 and :379-381 "
                "(FIFORead): gyro.x/y/z = data_x/y/z (accel the same), no remap; WHO_AM_I 0x6C "
                "(ST_LSM6DSO_Registers.hpp), which the LSM6DSOX shares",
                "the lsm6dso driver is SPI only (lsm6dso_main.cpp: "
                "PRINT_MODULE_USAGE_PARAMS_I2C_SPI_DRIVER(false, true))"),
    *(DriverFrame("ardupilot", chip, "y,x,-z", "y,x,-z",
                  f"{_AP}AP_InertialSensor_Invensense.cpp@00356b1:544-546 (_accumulate, accel "
                  f"{_AP_SWAP}), :559-561 (its gyro, words 5, 4, -6), :607-609 and :635-637 "
                  "(_accumulate_sensor_rate_sampling, the same); _check_whoami takes the "
                  "MPU-9250, MPU-9255 and MPU-6500")
      for chip in ("mpu9250", "mpu9255", "mpu6500")),
    DriverFrame("ardupilot", "icm20948", "y,x,-z", "y,x,-z",
                f"{_AP}AP_InertialSensor_Invensensev2.cpp@0411785:317-319 (_accumulate, accel "
                f"{_AP_SWAP}), :330-332 (its gyro, words 4, 3, -5), :375-377 and :388-390 "
                "(_accumulate_sensor_rate_sampling, the same)"),
    DriverFrame("ardupilot", "icm42688p", "x,y,z", "x,y,z",
                f"{_AP}AP_InertialSensor_Invensensev3.cpp@00ab7c1:316-317 (accumulate_samples): "
                "Vector3f accel{d.accel[0], d.accel[1], d.accel[2]}, gyro{d.gyro[0], d.gyro[1], "
                "d.gyro[2]}, no remap"),
    DriverFrame("ardupilot", "lsm9ds1", "x,y,-z", "x,y,-z",
                f"{_AP}AP_InertialSensor_LSM9DS1.cpp@08b63b0:461 (_read_data_transaction_x) and "
                ":497 (_read_data_transaction_g): Vector3f gyro_data(raw_data.x, raw_data.y, "
                "-raw_data.z) (accel the same)",
                "a mirror image of the chip's axes (only z flipped); the backend is SPI only"),
    DriverFrame("ardupilot", "lsm6dsox", "x,y,z", "x,y,z",
                f"{_AP}AP_InertialSensor_LSM6DSO.cpp@15ffc15:34 (LSM6DSO_WHOAMI 0x6C, which the "
                "LSM6DSOX shares; the class derives from AP_InertialSensor_ASM330, :18-19), "
                "AP_InertialSensor_ASM330.cpp@15ffc15:398 (update_transaction_g) and :407 "
                "(update_transaction_x): Vector3f(raw_data.x, raw_data.y, raw_data.z), no remap"),
)

#: The quarter-turn entries of each stack's ``enum Rotation`` (PX4 rotation.h, ArduPilot
#: rotations.h; values 0-40 are the same in both): name -> value. The name is the rotation:
#: roll, then pitch, then yaw, in degrees. Entries that are not whole quarter turns (45°, 68°, …)
#: cannot map an axis onto an axis and are left out.
_SHARED_ROTATIONS = {
    "ROTATION_NONE": 0, "ROTATION_YAW_90": 2, "ROTATION_YAW_180": 4, "ROTATION_YAW_270": 6,
    "ROTATION_ROLL_180": 8, "ROTATION_ROLL_180_YAW_90": 10, "ROTATION_PITCH_180": 12,
    "ROTATION_ROLL_180_YAW_270": 14, "ROTATION_ROLL_90": 16, "ROTATION_ROLL_90_YAW_90": 18,
    "ROTATION_ROLL_270": 20, "ROTATION_ROLL_270_YAW_90": 22, "ROTATION_PITCH_90": 24,
    "ROTATION_PITCH_270": 25, "ROTATION_PITCH_180_YAW_90": 26, "ROTATION_PITCH_180_YAW_270": 27,
    "ROTATION_ROLL_90_PITCH_90": 28, "ROTATION_ROLL_180_PITCH_90": 29,
    "ROTATION_ROLL_270_PITCH_90": 30, "ROTATION_ROLL_90_PITCH_180": 31,
    "ROTATION_ROLL_270_PITCH_180": 32, "ROTATION_ROLL_90_PITCH_270": 33,
    "ROTATION_ROLL_180_PITCH_270": 34, "ROTATION_ROLL_270_PITCH_270": 35,
    "ROTATION_ROLL_90_PITCH_180_YAW_90": 36, "ROTATION_ROLL_90_YAW_270": 37,
}
ROTATIONS: Mapping[str, Mapping[str, int]] = {
    "px4": {**_SHARED_ROTATIONS, "ROTATION_ROLL_270_YAW_180": 41,
            "ROTATION_ROLL_270_YAW_270": 42, "ROTATION_PITCH_90_YAW_180": 43},
    "ardupilot": dict(_SHARED_ROTATIONS),
}

def axes_matrix(text: str) -> np.ndarray:
    """The 3×3 matrix of a remap written as published axes in the chip's terms (``"y,x,-z"``):
    row ``i`` has ``±1`` in the column of the chip axis published as axis ``i``.

    Raises
    ------
    InputError
        Unless ``text`` is three distinct axes x, y, z, each with an optional sign.
    """
    parts = [p.strip().lower() for p in str(text).split(",")]
    ok = len(parts) == 3 and all(re.fullmatch(r"[+-]?[xyz]", p) for p in parts)
    if not ok or len({p[-1] for p in parts}) != 3:
        raise InputError(f"--driver-axes {text!r}: give the published x, y, z as three distinct "
                         "chip axes with signs, e.g. x,-y,-z or y,x,-z")
    t = np.zeros((3, 3))
    for i, p in enumerate(parts):
        t[i, "xyz".index(p[-1])] = -1.0 if p.startswith("-") else 1.0
    return t


def _axis_rotation(axis: int, degrees: int) -> np.ndarray:
    c, s = round(math.cos(math.radians(degrees))), round(math.sin(math.radians(degrees)))
    i, j = [(1, 2), (2, 0), (0, 1)][axis]
    r = np.eye(3)
    r[i, i], r[i, j], r[j, i], r[j, j] = c, -s, s, c
    return r


def rotation_matrix(name: str) -> np.ndarray:
    """The matrix ``Rz(yaw) Ry(pitch) Rx(roll)`` of a quarter-turn ``ROTATION_*`` name, exact
    (entries 0 and ±1): what the stacks' ``rotate`` does to a vector."""
    angles = {"ROLL": 0, "PITCH": 0, "YAW": 0}
    for axis, deg in re.findall(r"(ROLL|PITCH|YAW)_(\d+)", name):
        angles[axis] = int(deg)
    return (_axis_rotation(2, angles["YAW"]) @ _axis_rotation(1, angles["PITCH"])
            @ _axis_rotation(0, angles["ROLL"]))


def _rotation_name(stack: str, given: Any) -> str:
    """The ``ROTATION_*`` name of ``--rotation`` (a name, with or without ``ROTATION_``, or the
    stack's enum number)."""
    table = ROTATIONS[stack]
    if given is None:
        return "ROTATION_NONE"
    text = str(given).strip().upper()
    if text.lstrip("+").isdigit():
        names = [n for n, v in table.items() if v == int(text)]
        if names:
            return names[0]
    else:
        name = text if text.startswith("ROTATION_") else "ROTATION_" + text
        if name in table:
            return name
    raise InputError(
        f"--rotation {given!r} is not a quarter-turn rotation of {STACKS[stack]}'s enum Rotation "
        "(gyrocal maps each chip axis onto one published axis; a 45 deg turn would mix two); "
        f"give one of {', '.join(f'{n} ({v})' for n, v in table.items())}")


def driver_frame(stack: str, chip: str | None) -> DriverFrame | None:
    """The :data:`DRIVER_FRAMES` row of ``stack`` and ``chip``, None when there is none."""
    return next((r for r in DRIVER_FRAMES if r.stack == stack and r.chip == chip), None)


@dataclass(frozen=True)
class FrameMapping:
    """How a calibration's chip-frame vectors reach one stack's parameters.

    Attributes
    ----------
    stack : str
    gyro, accel : (3, 3) ndarray
        ``T = R · remap`` for each sensor: a chip-frame vector ``v`` is ``T v`` in the frame
        the stack subtracts offsets in.
    note : str
        The mapping used, for stderr.
    """

    stack: str
    gyro: np.ndarray
    accel: np.ndarray
    note: str

    def vector(self, v: Any, sensor: str = "gyro") -> list[float]:
        """An offset-like vector (offsets, temperature coefficients) in the stack's frame."""
        t = self.gyro if sensor == "gyro" else self.accel
        return [float(x) + 0.0 for x in t @ np.asarray(v, dtype=float)]

    def scales(self, s: Any, sensor: str = "accel") -> list[float]:
        """Per-axis scale factors in the stack's frame (each published axis takes its chip
        axis's factor)."""
        t = self.gyro if sensor == "gyro" else self.accel
        return [float(x) for x in np.abs(t) @ np.asarray(s, dtype=float)]


def frame_mapping(stack: str, sensor: Mapping[str, Any] | None,
                  options: Mapping[str, Any]) -> FrameMapping:
    """The mapping for ``stack`` of a calibration whose ``sensor`` (its ``model``) is given,
    with the ``driver_axes`` and ``rotation`` options.

    Raises
    ------
    InputError
        No table row for the chip and no ``--driver-axes``; a bad ``--driver-axes`` or
        ``--rotation``.
    """
    model = str((sensor or {}).get("model") or "") or None
    name = _rotation_name(stack, options.get("rotation"))
    rot = rotation_matrix(name)
    row = driver_frame(stack, model)
    given = options.get("driver_axes")
    if given is not None:
        gyro = accel = axes_matrix(given)
        what = (f"the driver axes given with --driver-axes ({_axes_text(gyro)})"
                + (f"; the table's row for {STACKS[stack]}'s {model} driver says "
                   f"({_pretty(row.gyro)})" if row is not None else ""))
    elif row is None:
        chips = ", ".join(r.chip for r in DRIVER_FRAMES if r.stack == stack)
        raise InputError(
            f"no {STACKS[stack]} driver is known for the sensor model "
            f"{model or 'not recorded'!r} (the table has {chips}): the parameters would be in "
            "the wrong axes. Give --driver-axes with the axes its driver publishes (e.g. "
            "x,-y,-z; x,y,z for the chip's own axes)")
    else:
        gyro, accel = axes_matrix(row.gyro), axes_matrix(row.accel)
        what = (f"{STACKS[stack]}'s {model} driver publishes ({_pretty(row.gyro)}) of the "
                f"chip's axes ({row.source})" + (f"; {row.note}" if row.note else ""))
    after = ("SENS_BOARD_ROT / CAL_GYROn_ROT / CAL_ACCn_ROT turn the corrected vector after the "
             "offsets (Gyroscope::Correct) and change nothing here" if stack == "px4" else
             "AHRS_ORIENTATION turns the corrected vector after the offsets "
             "(_rotate_and_correct_gyro) and changes nothing here")
    note = (f"frame: {what}; then {name} ({ROTATIONS[stack][name]}); the parameters are in that "
            f"frame: published x, y, z = chip ({_axes_text(rot @ gyro)}). {after}")
    return FrameMapping(stack, rot @ gyro, rot @ accel, note)


def _pretty(axes: str) -> str:
    return ", ".join(a.strip().replace("-", "−") for a in axes.split(","))


def _axes_text(t: np.ndarray) -> str:
    out = []
    for row in t:
        j = int(np.argmax(np.abs(row)))
        out.append(("−" if row[j] < 0 else "") + "xyz"[j])
    return ", ".join(out)


def gyro_model_note(cal: Any, stack: str) -> str:
    """What of the gyro model a stack's offsets cannot carry, with its size: the stacks correct
    the gyro by an offset only (no gyro scale or cross-axis parameter in PX4's
    ``calibration::Gyroscope`` or ArduPilot's ``_rotate_and_correct_gyro``), so the rate keeps
    ``(A − I) ω``: up to ``‖A − I‖₂`` of it."""
    a = np.asarray(cal.full_matrix, dtype=float)
    dev = np.abs(a - np.eye(3))
    worst_scale = float(np.max(np.diag(dev)))
    off = dev - np.diag(np.diag(dev))
    parts = f"scale factors (up to {worst_scale:.2e} from 1)"
    if cal.is_full:
        parts += f" and cross-axis terms (up to {float(off.max()):.2e})"
    bound = float(np.linalg.norm(a - np.eye(3), 2))
    return (f"{STACKS[stack]} has no gyro scale or cross-axis parameter: the calibration's "
            f"{parts} are not carried, so the corrected rate keeps an error of up to "
            f"{bound:.2e} of the rate ({math.degrees(bound):.2f} deg/s at 1 rad/s); only the "
            "offsets are written")
