"""The exports carry the Calibration's ``accelerometer`` (issue 15): the C header applies both
sensors (compiled and compared with Python), YAML/ROS carry it, Kalibr's intrinsics get its
``M``, PX4 and ArduPilot get their offset and scale parameters, and what has no place is said on
stderr.

The accelerometer calibration is fitted to rests from the independent generator
tests/calib/accel_truth.py; the expected values are the stacks' documented formulas written here
(PX4 ``(raw − off) ⊙ scale``, ArduPilot ``(raw − offs) ⊙ scal``, each after its driver's remap of
the chip's axes, :mod:`tests.kit.flight_stacks`; Kalibr ``a = M f + b``).
"""

import json
import subprocess

import numpy as np
import pytest
import yaml

from gyrocal.calib.accel import fit_accelerometer
from gyrocal.calib.model import Consistency, GyroCalibration
from gyrocal.kit.cli import main
from tests.calib import accel_truth
from tests.kit.c_program import compile_program, needs_gcc
from tests.kit.flight_stacks import (
    ardupilot_accel,
    ardupilot_invensense,
    px4_accel,
    px4_invensense,
)
from tests.kit.ros_readers import noise_file


@pytest.fixture(scope="module")
def cal():
    rng = np.random.default_rng(15)
    sensing = accel_truth.random_sensing(rng)
    bias = rng.normal(0, 0.3, 3)
    means, std = accel_truth.rest_means(rng, sensing, bias, accel_truth.fibonacci_directions(14),
                                        9.80665, 0.03, 200)
    acc = fit_accelerometer(means, std)
    a = np.tril(np.eye(3) + rng.normal(0, 0.02, (3, 3)))
    return GyroCalibration(
        scale=tuple(np.diag(a)), bias=(0.01, -0.02, 0.003), matrix=tuple(map(tuple, a)),
        matrix_std=tuple(map(tuple, np.tril(np.full((3, 3), 1e-4)))), frame="gyro-x-xy",
        method="full-matrix", consistency=Consistency(40.0, 42, 0.5, True),
        sensor={"model": "mpu9250", "odr_hz": 200.0}, accelerometer=acc)


@pytest.fixture
def cal_file(tmp_path, cal):
    p = tmp_path / "cal.json"
    p.write_text(cal.to_json())
    return p


def export(capsys, path, fmt, *options):
    code = main(["export", str(path), "--format", fmt, *options])
    out, err = capsys.readouterr()
    assert code == 0, err
    return out, err


PROGRAM = r"""
#include <stdio.h>
#include <stdlib.h>
#include "cal.h"

int main(int argc, char **argv)
{
    float m[3], g[3], a[3], f[3];
    int i;
    if (argc != 7) return 2;
    for (i = 0; i < 3; ++i) m[i] = strtof(argv[i + 1], NULL);
    for (i = 0; i < 3; ++i) a[i] = strtof(argv[i + 4], NULL);
    gyrocal_apply(m, g);
    gyrocal_accel_apply(a, f);
    gyrocal_accel_apply(a, a); /* in place */
    for (i = 0; i < 3; ++i)
        printf("%.9e %.9e %.9e\n", (double)g[i], (double)f[i], (double)a[i]);
    return 0;
}
"""


@needs_gcc
def test_the_c_header_applies_both_sensors(cal, cal_file, tmp_path, capsys):
    out, _ = export(capsys, cal_file, "c-header")
    assert "f[i] = sum over j of A_ACC[i][j] * (a[j] + b_acc[j])" in out
    compile_program(tmp_path, out, PROGRAM)
    m = np.array([1.3, -2.1, 0.7])
    a = np.array([0.4, -9.7, 1.2])
    run = subprocess.run([str(tmp_path / "apply"), *(repr(float(x)) for x in (*m, *a))],
                         capture_output=True, text=True, check=True)
    res = np.array([[float(x) for x in line.split()] for line in run.stdout.splitlines()])
    m32, a32 = (v.astype(np.float32).astype(float) for v in (m, a))
    np.testing.assert_allclose(res[:, 0], cal.apply(m32), rtol=1e-6)
    expected = cal.accelerometer.apply(a32[None])[0]
    np.testing.assert_allclose(res[:, 1], expected, rtol=1e-6, atol=1e-6)
    np.testing.assert_allclose(res[:, 2], expected, rtol=1e-6, atol=1e-6)
    # the uncalibrated reading is far from it: the test can tell
    assert np.max(np.abs(a32 - expected)) > 1e-2


def test_yaml_and_ros_carry_the_accelerometer(cal, cal_file, capsys):
    out, _ = export(capsys, cal_file, "yaml")
    doc = yaml.safe_load(out)
    assert np.allclose(doc["accelerometer"]["matrix"], cal.accelerometer.matrix, rtol=1e-15)
    assert np.allclose(doc["accelerometer"]["bias"], cal.accelerometer.bias, rtol=1e-15)
    # converted back to JSON it is a valid calibration with the same accelerometer
    back = GyroCalibration.from_dict(json.loads(json.dumps(doc)))
    assert np.array_equal(back.accelerometer.matrix, cal.accelerometer.matrix)
    out, _ = export(capsys, cal_file, "ros")
    params = yaml.safe_load(out)["gyro_calibration"]
    assert np.allclose(np.reshape(params["accel_matrix"], (3, 3)), cal.accelerometer.matrix)
    assert np.allclose(params["accel_bias"], cal.accelerometer.bias)
    assert params["accel_units"] == "m/s^2"


def test_kalibr_gets_the_accelerometer_matrix_and_says_what_has_no_place(cal, cal_file, capsys):
    out, err = export(capsys, cal_file, "kalibr", "--noise", str(noise_file(cal_file.parent)))
    doc = yaml.safe_load(out)["gyrocal_intrinsics"]
    M = np.asarray(doc["accelerometers"]["M"])
    # Kalibr: a_meas = M f + b; gyrocal: f = A (a + b_acc), so a = A^-1 f - b_acc
    f = np.array([0.3, -9.5, 2.0])
    a = np.linalg.solve(cal.accelerometer.matrix, f) - cal.accelerometer.bias
    assert np.allclose(M @ f - cal.accelerometer.bias, a, atol=1e-9)
    assert "fixed accelerometer bias" in err and "not the accelerometer's" in err


def test_px4_and_ardupilot_get_offsets_and_scales_per_their_formulas(cal, cal_file, capsys):
    acc = cal.accelerometer
    raw = np.array([0.5, -9.6, 0.8])
    diag = np.diag(acc.matrix) * (raw + acc.bias)  # gyrocal's model without its cross-axis part
    out, err = export(capsys, cal_file, "px4-accel", "--imu-index", "1")
    p = {r.split("\t")[2]: float(r.split("\t")[3]) for r in out.splitlines()
         if not r.startswith("#")}
    assert sorted(p) == sorted(f"CAL_ACC1_{a}{k}" for a in "XYZ" for k in ("OFF", "SCALE"))
    # through PX4's MPU-9250 driver, which publishes (x, -y, -z), and Accelerometer::Correct
    assert np.allclose(px4_accel(p, "mpu9250", raw, n=1), px4_invensense(diag), rtol=1e-8)
    assert "no accelerometer cross-axis terms" in err
    out, err = export(capsys, cal_file, "ardupilot-accel", "--imu-index", "2")
    q = dict((r.split(",")[0], float(r.split(",")[1])) for r in out.splitlines()
             if not r.startswith("#"))
    assert sorted(q) == sorted([f"INS_ACC2OFFS_{a}" for a in "XYZ"]
                               + [f"INS_ACC2SCAL_{a}" for a in "XYZ"])
    # through ArduPilot's Invensense backend, which builds (y, x, -z), and
    # _rotate_and_correct_accel
    assert np.allclose(ardupilot_accel(q, "mpu9250", raw, n=2), ardupilot_invensense(diag),
                       rtol=1e-8)
    assert "no accelerometer cross-axis terms" in err
    out, _ = export(capsys, cal_file, "ardupilot-accel")
    assert "INS_ACCOFFS_X," in out and "INS_ACCSCAL_Z," in out


def test_a_calibration_without_an_accelerometer_is_refused_for_the_accel_formats(
        tmp_path, capsys):
    p = tmp_path / "g.json"
    p.write_text(GyroCalibration(scale=(1.0, 1.0, 1.0), bias=(0.0, 0.0, 0.0)).to_json())
    for fmt in ("px4-accel", "ardupilot-accel"):
        assert main(["export", str(p), "--format", fmt]) == 2
        assert "needs a calibration with an 'accelerometer'" in capsys.readouterr().err


def test_the_thermal_formats_say_the_accelerometer_goes_elsewhere(cal, tmp_path, capsys):
    from dataclasses import replace

    from gyrocal.calib.thermal import ThermalModel

    tm = ThermalModel(reference_c=30.0, range_c=(20.0, 40.0),
                      bias_coeffs=np.array([[0.01, 1e-4]] * 3),
                      bias_coeffs_covariance=np.array([np.eye(2) * 1e-12] * 3), points=5)
    p = tmp_path / "t.json"
    p.write_text(replace(cal, temperature_model=tm).to_json())
    for fmt, other in (("px4-thermal", "px4-accel"), ("ardupilot-thermal", "ardupilot-accel")):
        _, err = export(capsys, p, fmt)
        assert f"export it with --format {other}" in err


def test_kalibr_writes_the_measured_accelerometer_noise_unless_given(cal, tmp_path, capsys):
    """accelerometer_noise_density: the calibration's measured density (largest axis) when the
    user gives none, --accel-noise-density when given; stderr says which; a placeholder (said
    in the file and on stderr) when the calibration has none, since Kalibr requires it."""
    from dataclasses import replace

    noisy = replace(cal, accelerometer=replace(
        cal.accelerometer, noise_density=np.array([2.1e-3, 2.6e-3, 1.9e-3]),
        noise_density_std=np.array([2e-4, 3e-4, 2e-4]), noise_tau_s=0.1))
    p = tmp_path / "noisy.json"
    p.write_text(noisy.to_json())
    noise = str(noise_file(tmp_path))
    out, err = export(capsys, p, "kalibr", "--noise", noise)
    assert yaml.safe_load(out)["accelerometer_noise_density"] == pytest.approx(2.6e-3, rel=1e-6)
    assert "measured on the run's rests (largest axis, y" in err
    out, err = export(capsys, p, "kalibr", "--accel-noise-density", "5e-3", "--noise", noise)
    assert yaml.safe_load(out)["accelerometer_noise_density"] == pytest.approx(5e-3)
    assert "from --accel-noise-density" in err
    p2 = tmp_path / "plain.json"
    p2.write_text(cal.to_json())
    out, err = export(capsys, p2, "kalibr", "--noise", noise)
    assert yaml.safe_load(out)["accelerometer_noise_density"] == pytest.approx(1e-2)
    assert "NOT MEASURED, a placeholder" in out
    assert "placeholder (the calibration has no measured accelerometer noise)" in err
    assert main(["export", str(p), "--format", "kalibr", "--accel-noise-density", "-1",
                 "--noise", str(noise)]) == 2
    assert "must be a positive number" in capsys.readouterr().err


@pytest.mark.parametrize("model,bus,address,expected", [
    # id = bus_type (I2C 1) | bus << 3 | address << 8 | devtype << 16, worked out by hand from
    # PX4's Device.hpp DeviceStructure and drv_sensor.h: MPU9250 0x24, ICM42688P 0x26
    ("mpu9250", 1, 0x68, 1 + 1 * 8 + 104 * 256 + 36 * 65536),  # 2385929
    ("icm42688p", 3, 0x69, 1 + 3 * 8 + 105 * 256 + 38 * 65536),  # 2517273
])
def test_px4_accel_writes_the_device_id_of_a_known_chip_bus_and_address(
        cal, tmp_path, capsys, model, bus, address, expected):
    from dataclasses import replace

    located = replace(cal, sensor={**cal.sensor, "model": model, "i2c_bus": bus,
                                   "i2c_address": address})
    p = tmp_path / "cal.json"
    p.write_text(located.to_json())
    out, err = export(capsys, p, "px4-accel", "--imu-index", "2")
    rows = {r.split("\t")[2]: r.split("\t")[3:] for r in out.splitlines()
            if not r.startswith("#")}
    assert rows["CAL_ACC2_ID"] == [str(expected), "6"]  # MAV_PARAM_TYPE_INT32
    assert f"device ID {expected} = I2C bus {bus}, address {address:#04x}" in err


def test_px4_accel_without_the_bus_or_with_a_chip_px4_lacks_says_so(cal, tmp_path, capsys):
    from dataclasses import replace

    for sensor, why in (({"model": "mpu9250"}, "does not say which I2C bus"),
                        ({"model": "lsm6dsox", "i2c_bus": 1, "i2c_address": 0x6A},
                         "PX4 has no device type for the sensor model 'lsm6dsox'")):
        p = tmp_path / "cal.json"
        p.write_text(replace(cal, sensor=sensor).to_json())
        out, err = export(capsys, p, "px4-accel")
        assert "CAL_ACC0_ID" not in out
        assert "CAL_ACC0_ID is not written" in err and why in err


def test_a_sim_run_records_where_the_chip_is_and_px4_gets_its_id(full_run, capsys):
    """``gyrocal calibrate --sim`` at the defaults (an MPU-9250 on bus 1 at 0x68) records
    ``sensor.i2c_bus``/``i2c_address`` and px4-accel writes its ID (hand-computed above)."""
    d, _ = full_run
    sensor = json.loads((d / "calibration.json").read_text())["sensor"]
    assert (sensor["i2c_bus"], sensor["i2c_address"]) == (1, 0x68)
    out, _ = export(capsys, d / "calibration.json", "px4-accel")
    assert "1\t1\tCAL_ACC0_ID\t2385929\t6" in out
