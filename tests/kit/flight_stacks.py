"""PX4's and ArduPilot's correction of one IMU sample, written out from their source: what each
stack does with the parameter files gyrocal writes (issue 31). Shared by the flight-stack export
tests and ``python -m bench flightframes``; nothing here comes from gyrocal's own frame table.

The path of a gyro sample (the accelerometer's is the same with a scale after the offset):

PX4 (PX4-Autopilot)
    1. the driver reads the chip's x, y, z registers and publishes a remapped vector
       (:data:`DRIVERS`; e.g. ``src/drivers/imu/invensense/mpu9250/MPU9250_I2C.cpp@023e613``,
       ``MPU9250_I2C::ProcessGyro``: "flip y & z to publish right handed with z down" (:564),
       ``gyro.y = -gyro_y``, ``gyro.z = -gyro_z`` (:566-567));
    2. ``PX4Gyroscope::updateFIFO`` turns it by the driver's ``-R`` rotation
       (``src/lib/drivers/gyroscope/PX4Gyroscope.cpp@000f5fd:148``: ``rotate_3i(_rotation,
       …)``);
    3. ``TemperatureCompensation::calc_thermal_offsets_3D`` gives ``_thermal_offset`` from
       ``TC_Gn_*`` (``X0 + X1·dT + X2·dT² + X3·dT³``, ``dT = clamp(T, TMIN, TMAX) − TREF``;
       ``src/modules/temperature_compensation/TemperatureCompensation.cpp@09f282b:283``, the
       clamp :290-301, the polynomial :308);
    4. ``calibration::Gyroscope::Correct``
       (``src/lib/sensor_calibration/Gyroscope.hpp@13db2eb:77``): ``_rotation * (data −
       _thermal_offset − _offset)``, ``_offset`` = ``CAL_GYROn_?OFF``, ``_rotation`` =
       ``SENS_BOARD_ROT``; ``calibration::Accelerometer::Correct`` (``Accelerometer.hpp@011a413
       :84``): ``_rotation * ((data − _thermal_offset − _offset).emult(_scale))``.

ArduPilot (ArduPilot/ardupilot, ``libraries/AP_InertialSensor``)
    1. the backend builds a remapped vector (:data:`DRIVERS`; e.g.
       ``AP_InertialSensor_Invensense.cpp@00356b1:544-546``, ``_accumulate``:
       ``Vector3f(int16_val(data, 1), int16_val(data, 0), -int16_val(data, 2))``);
    2. ``AP_InertialSensor_Backend::_rotate_and_correct_gyro``: ``gyro.rotate(
       _gyro_orientation[instance])`` (the hwdef's rotation for the IMU; :140 of the stored
       ``AP_InertialSensor_Backend.cpp`` that has this step, for which the source index gives
       no commit);
    3. ``_imu.tcal(instance).correct_gyro(T, caltemp, gyro)`` (Backend :152;
       ``AP_InertialSensor_tempcal.cpp@025810d:210``, ``TCal::correct_sensor``: ``v −= P(T − 35)
       − P(CALTEMP − 35)`` (:221, :227; ``TEMP_REFERENCE`` 35.0 :40), ``P(x) = (c1 + (c2 +
       c3·x)·x)·x · 1e-6`` (:204), both temperatures clamped to ``[TMIN, TMAX]`` (:215-216));
    4. ``gyro -= _imu._gyro_offset(instance)`` ("gyro calibration is always assumed to have been
       done in sensor frame", Backend :156), then ``gyro.rotate(_imu._board_orientation)``
       (``AHRS_ORIENTATION``, :159); ``_rotate_and_correct_accel``: ``accel -= _accel_offset``
       (:123), ``accel.x *= accel_scale.x`` (and y, z, :128-130), then the board rotation
       (:134).

Rotations are the stacks' explicit ``rotate`` cases (ArduPilot ``AP_Math/vector3.cpp``
``Vector3<T>::rotate``, PX4 ``rotate_3f``), for the entries the tests use.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

STANDARD_GRAVITY = 9.80665


def _v(*xs: float) -> np.ndarray:
    return np.array(xs, dtype=float)


# ---------------------------------------------------------------------------- the drivers
def px4_invensense(c: np.ndarray) -> np.ndarray:
    """PX4 MPU9250_I2C.cpp@023e613:536-537, :566-567 / MPU9250.cpp ``ProcessGyro``/
    ``ProcessAccel``; MPU6500.cpp@542f41f:547-548, :577-578, ICM20948.cpp@023e613:666-667,
    :696-697 and ICM42688P.cpp@00d281a:723-724, :805-806 the same: ``x = x``, ``y = -y``,
    ``z = -z``."""
    return _v(c[0], -c[1], -c[2])


def px4_lsm9ds1(c: np.ndarray) -> np.ndarray:
    """PX4 src/drivers/imu/st/lsm9ds1/LSM9DS1.cpp ``FIFORead`` (PX4-Autopilot 26d971b, :361-363,
    :389-391): ``gyro.x = gyro_x``, ``gyro.y = gyro_y``, ``gyro.z = -gyro_z`` (accel the
    same)."""
    return _v(c[0], c[1], -c[2])


def px4_lsm6dso(c: np.ndarray) -> np.ndarray:
    """PX4 src/drivers/imu/st/lsm6dso/LSM6DSO.cpp@ed717f0:371-373 ``FIFORead``: ``gyro.x =
    data_x``, … (no remap)."""
    return _v(c[0], c[1], c[2])


def ardupilot_invensense(c: np.ndarray) -> np.ndarray:
    """ArduPilot AP_InertialSensor_Invensense.cpp@00356b1 ``_accumulate`` (the accel words 0, 1,
    2, :544-546; the gyro words 4, 5, 6, :559-561) and AP_InertialSensor_Invensensev2.cpp@0411785
    ``_accumulate`` (:317-319; gyro words 3, 4, 5, :330-332): ``Vector3f(int16_val(data, 1),
    int16_val(data, 0), -int16_val(data, 2))``."""
    return _v(c[1], c[0], -c[2])


def ardupilot_invensensev3(c: np.ndarray) -> np.ndarray:
    """ArduPilot AP_InertialSensor_Invensensev3.cpp@00ab7c1:317 ``accumulate_samples``:
    ``Vector3f gyro{float(d.gyro[0]), float(d.gyro[1]), float(d.gyro[2])}``."""
    return _v(c[0], c[1], c[2])


def ardupilot_lsm9ds1(c: np.ndarray) -> np.ndarray:
    """ArduPilot AP_InertialSensor_LSM9DS1.cpp@08b63b0:497 / :461 ``_read_data_transaction_g``
    / ``_x``:
    ``Vector3f gyro_data(raw_data.x, raw_data.y, -raw_data.z)``."""
    return _v(c[0], c[1], -c[2])


def ardupilot_lsm6dso(c: np.ndarray) -> np.ndarray:
    """ArduPilot AP_InertialSensor_LSM6DSO.cpp@15ffc15 (derived from
    AP_InertialSensor_ASM330.cpp@15ffc15, ``update_transaction_g`` / ``_x`` :398 / :407:
    ``Vector3f gyro_data(raw_data.x, raw_data.y, raw_data.z)``)."""
    return _v(c[0], c[1], c[2])


#: (stack, gyrocal sensor model) -> the driver's remap of the chip's registers.
DRIVERS: dict[tuple[str, str], Callable[[np.ndarray], np.ndarray]] = {
    ("px4", "mpu9250"): px4_invensense, ("px4", "icm20948"): px4_invensense,
    ("px4", "icm42688p"): px4_invensense, ("px4", "lsm9ds1"): px4_lsm9ds1,
    ("px4", "lsm6dsox"): px4_lsm6dso, ("px4", "mpu6500"): px4_invensense,
    ("ardupilot", "mpu9250"): ardupilot_invensense, ("ardupilot", "icm20948"): ardupilot_invensense,
    ("ardupilot", "mpu9255"): ardupilot_invensense, ("ardupilot", "mpu6500"): ardupilot_invensense,
    ("ardupilot", "icm42688p"): ardupilot_invensensev3, ("ardupilot", "lsm9ds1"): ardupilot_lsm9ds1,
    ("ardupilot", "lsm6dsox"): ardupilot_lsm6dso,
}


def rotate(name: str, v: np.ndarray) -> np.ndarray:
    """The stacks' ``rotate`` cases (ArduPilot ``Vector3<T>::rotate``, PX4 ``rotate_3f``)."""
    x, y, z = (float(a) for a in v)
    cases = {
        "ROTATION_NONE": (x, y, z),
        "ROTATION_YAW_90": (-y, x, z),  # tmp = x; x = -y; y = tmp;
        "ROTATION_ROLL_180": (x, -y, -z),  # y = -y; z = -z;
        "ROTATION_ROLL_90_YAW_90": (z, x, y),  # tmp = x; x = z; z = y; y = tmp;
        "ROTATION_PITCH_270": (-z, y, x),  # tmp = z; z = x; x = -tmp;
    }
    return _v(*cases[name])


# ---------------------------------------------------------------------------- the files
def read_params(text: str) -> dict[str, float]:
    """A QGroundControl ``.params`` file (tab-separated ``1 1 NAME VALUE TYPE``) or a Mission
    Planner ``.param`` file (``NAME,VALUE``) as name -> value."""
    out: dict[str, float] = {}
    for line in text.splitlines():
        if not line.strip() or line.startswith("#"):
            continue
        parts = line.split("\t")
        name, value = (parts[2], parts[3]) if len(parts) == 5 else line.split(",")
        out[name] = float(value)
    return out


def _vec(p: dict[str, float], fmt: str, default: float = 0.0) -> np.ndarray:
    """Three parameters by axis; the stack's default (0 for an offset, 1 for a scale) where the
    file has none."""
    return _v(*(p.get(fmt.format(a=a, i=i), default) for i, a in enumerate("XYZ")))


# ---------------------------------------------------------------------------- PX4
def px4_thermal_offset(p: dict[str, float], n: int, temperature: float) -> np.ndarray:
    """``TemperatureCompensation::calc_thermal_offsets_3D`` of ``TC_Gn_*`` (zero without
    them)."""
    t = f"TC_G{n}_"
    if t + "TREF" not in p:
        return np.zeros(3)
    d = min(max(temperature, p[t + "TMIN"]), p[t + "TMAX"]) - p[t + "TREF"]
    return sum((_vec(p, t + f"X{k}_{{i}}") * d**k for k in range(4)), np.zeros(3))


def px4_gyro(p: dict[str, float], chip: str, raw: np.ndarray, temperature: float = 25.0,
             n: int = 0, rotation: str = "ROTATION_NONE",
             board: str = "ROTATION_NONE") -> np.ndarray:
    """PX4's corrected gyro (rad/s) for the chip's reading ``raw`` (steps 1-4 above)."""
    data = rotate(rotation, DRIVERS["px4", chip](raw))
    offset = _vec(p, f"CAL_GYRO{n}_{{a}}OFF")
    return rotate(board, data - px4_thermal_offset(p, n, temperature) - offset)


def px4_accel(p: dict[str, float], chip: str, raw: np.ndarray, n: int = 0,
              rotation: str = "ROTATION_NONE", board: str = "ROTATION_NONE") -> np.ndarray:
    """PX4's corrected accelerometer (m/s²) for the chip's reading ``raw``."""
    data = rotate(rotation, DRIVERS["px4", chip](raw))
    offset, scale = _vec(p, f"CAL_ACC{n}_{{a}}OFF"), _vec(p, f"CAL_ACC{n}_{{a}}SCALE", 1.0)
    return rotate(board, (data - offset) * scale)


# ---------------------------------------------------------------------------- ArduPilot
def ardupilot_tcal(p: dict[str, float], n: int, temperature: float) -> np.ndarray:
    """What ``TCal::correct_sensor`` subtracts for ``INS_TCALn_GYR*`` (zero without them)."""
    t = f"INS_TCAL{n}_"
    if t + "TMIN" not in p:
        return np.zeros(3)
    lo, hi = p[t + "TMIN"], p[t + "TMAX"]
    c = [_vec(p, t + f"GYR{k}_{{a}}") for k in (1, 2, 3)]

    def poly(x: float) -> np.ndarray:
        return (c[0] + (c[1] + c[2] * x) * x) * x * 1e-6

    cal_temp = min(max(p[f"INS_GYR{n}_CALTEMP"], lo), hi)
    return poly(min(max(temperature, lo), hi) - 35.0) - poly(cal_temp - 35.0)


def ardupilot_gyro(p: dict[str, float], chip: str, raw: np.ndarray, temperature: float = 25.0,
                   n: int = 1, rotation: str = "ROTATION_NONE",
                   board: str = "ROTATION_NONE") -> np.ndarray:
    """ArduPilot's corrected gyro (rad/s) for the chip's reading ``raw``."""
    gyro = rotate(rotation, DRIVERS["ardupilot", chip](raw))
    gyro = gyro - ardupilot_tcal(p, n, temperature)
    gyro = gyro - _vec(p, "INS_GYROFFS_{a}" if n == 1 else f"INS_GYR{n}OFFS_{{a}}")
    return rotate(board, gyro)


def ardupilot_accel(p: dict[str, float], chip: str, raw: np.ndarray, n: int = 1,
                    rotation: str = "ROTATION_NONE", board: str = "ROTATION_NONE") -> np.ndarray:
    """ArduPilot's corrected accelerometer (m/s²) for the chip's reading ``raw``."""
    k = "" if n == 1 else str(n)
    accel = rotate(rotation, DRIVERS["ardupilot", chip](raw))
    accel = (accel - _vec(p, f"INS_ACC{k}OFFS_{{a}}")) * _vec(p, f"INS_ACC{k}SCAL_{{a}}", 1.0)
    return rotate(board, accel)


GYRO = {"px4": px4_gyro, "ardupilot": ardupilot_gyro}
ACCEL = {"px4": px4_accel, "ardupilot": ardupilot_accel}


# ---------------------------------------------------------------------------- the sensors
#: The five chips gyrocal reads, and the seed of each one's emulated errors here.
CHIPS = ("mpu9250", "icm20948", "icm42688p", "lsm9ds1", "lsm6dsox")


def chip_truth(model: str, seed: int | None = None):
    """An emulated ``model`` chip's true errors as ``gyrocal calibrate --sim`` draws them (the
    paper's scale and bias, the datasheet's ±2 % cross-axis terms, the datasheet's temperature
    coefficients about 25 °C and accelerometer errors): a ``SensorTruth``."""
    from gyrocal.drivers.emulated.accel import draw_accel_truth
    from gyrocal.drivers.emulated.imu_chips import SensorTruth
    from gyrocal.drivers.emulated.thermal import draw_thermal_coefficients
    from gyrocal.kit.sim import sim_misalignment, sim_truth

    seed = 31 + CHIPS.index(model) if seed is None else seed
    scale, bias = sim_truth(seed)
    return SensorTruth(scale=tuple(scale), bias=tuple(bias), misalignment=sim_misalignment(seed),
                       reference_temperature_c=25.0, accelerometer=draw_accel_truth(model, seed),
                       **{k: tuple(v) for k, v in draw_thermal_coefficients(seed, model).items()})


#: The temperatures the truth's calibration is made at (its temperature model covers them).
CAL_TEMPERATURES = np.linspace(15.0, 45.0, 7)
#: Gravity directions of the accelerometer's rests (the fit's input).
_REST_DIRECTIONS = 14


def truth_calibration(truth, model: str):
    """The calibration a perfect run on ``truth`` holds: ``g = A(T) (m + b(T))`` with
    ``A(T) = misalignment⁻¹ diag(scale(T))`` and ``b(T)`` the true bias (fitted as gyrocal's
    temperature model from exact points), and the accelerometer fitted by
    :func:`gyrocal.calib.accel.fit_accelerometer` to noiseless rests of the true one."""
    from gyrocal.calib.accel import fit_accelerometer
    from gyrocal.calib.model import GyroCalibration
    from gyrocal.calib.thermal import fit_thermal
    from tests.calib.accel_truth import fibonacci_directions

    temps = CAL_TEMPERATURES
    mis_inv = np.linalg.inv(np.asarray(truth.misalignment))
    gain = np.array([mis_inv @ np.diag(s) for s in truth.scale_at(temps)])
    bias = truth.bias_at(temps)
    tm = fit_thermal(temps, bias, np.full(bias.shape, 1e-9), gain, np.full(gain.shape, 1e-9),
                     reference_c=25.0)
    u = fibonacci_directions(_REST_DIRECTIONS)
    means = STANDARD_GRAVITY * truth.accel_reading(u)
    acc = fit_accelerometer(means, np.full(means.shape, 1e-6))
    a25 = gain[np.argmin(np.abs(temps - 25.0))]
    return GyroCalibration(scale=tuple(np.diag(a25)), matrix=tuple(map(tuple, a25)),
                           bias=tuple(truth.bias), temperature_c=25.0, temperature_model=tm,
                           frame="gyro-x-xy", method="full-matrix",
                           sensor={"model": model}, accelerometer=acc)
