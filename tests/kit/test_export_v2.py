"""Exports of a full-matrix calibration (Calibration v2) and of hostile text.

Truth here is the known matrix and bias the calibrations are built from, written out by hand
(g[i] = sum_j A[i][j] (m[j] + b[j])); each export is read back with a strict third-party reader
(PyYAML's safe loader, the C compiler), never with gyrocal's own code.
"""

import json
import subprocess

import numpy as np
import pytest
import yaml

from gyrocal.calib.model import Consistency, GyroCalibration
from gyrocal.kit.cli import main
from tests.kit.c_program import compile_program, needs_gcc
from tests.kit.ros_readers import KalibrImuConfig, noise_file

# A ±2 % cross-axis matrix in the gyro-x-xy convention (lower triangular) and a bias, rad/s.
A = [[1.0132, 0.0, 0.0], [0.0187, 0.9871, 0.0], [-0.0164, 0.0119, 1.0043]]
B = [0.0123, -0.0456, 0.0789]
#: Every line break YAML 1.1/1.2 or C knows, a YAML tag that runs a command under PyYAML's unsafe
#: loader, a comment terminator and a trigraph.
HOSTILE = ("mpu9250\nevil: !!python/object/apply:os.system ['touch pwned']\r\u2028x: 1"
           "\u0085y: 2\u2029 */ ??/ \"q\" #")


def make_full(sensor=None, **kw):
    rng = np.random.default_rng(11)
    g = rng.normal(size=(12, 12)) * 1e-5
    base = dict(
        scale=tuple(A[i][i] for i in range(3)), bias=tuple(B),
        bias_std=(1e-5, 2e-5, 3e-5),
        matrix=A, matrix_std=[[4e-5, 0.0, 0.0], [5e-5, 4e-5, 0.0], [6e-5, 5e-5, 4e-5]],
        covariance=g @ g.T, frame="gyro-x-xy",
        kinematics={"chain": [1, 2, 3], "axes": [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0],
                                                 [0.0, 0.0, 1.0]],
                    "reference_angles_rad": [0.0, 0.0, 0.0]},
        method="full-matrix", iterations=5,
        consistency=Consistency(chi2=30.2, dof=33, p_value=0.6, ok=True),
        sensor=sensor if sensor is not None else {"model": HOSTILE, "odr_hz": 200.0},
        temperature_c=25.0, created="2026-11-23T10:00:00+00:00", source=HOSTILE,
    )
    base.update(kw)
    return GyroCalibration(**base)


def truth(m):
    return [sum(A[i][j] * (m[j] + B[j]) for j in range(3)) for i in range(3)]


def export(capsys, tmp_path, cal, fmt, *options, code=0):
    p = tmp_path / "cal.json"
    p.write_text(cal.to_json())
    rc = main(["export", str(p), "--format", fmt, *options])
    out, err = capsys.readouterr()
    assert rc == code, err
    assert "Traceback" not in err
    return out, err


def test_yaml_loads_strictly_to_the_document_and_keeps_the_hostile_name_as_data(capsys, tmp_path):
    cal = make_full()
    out, _ = export(capsys, tmp_path, cal, "yaml")
    doc = yaml.safe_load(out)
    assert doc["matrix"] == A and doc["bias"] == B and doc["version"] == 2
    assert doc["sensor"]["model"] == HOSTILE and doc["source"] == HOSTILE
    assert set(doc) == set(cal.to_dict())  # nothing injected at the top level
    assert doc == json.loads(cal.to_json())
    assert "g = matrix @ (m + bias)" in out
    for line in out.splitlines():
        assert line.startswith(("#", " ", "-")) or line.split(":")[0] in doc, line


def test_ros_carries_the_matrix_row_major(capsys, tmp_path):
    out, err = export(capsys, tmp_path, make_full(), "ros")
    p = yaml.safe_load(out)["gyro_calibration"]
    assert p["matrix"] == [x for row in A for x in row]
    assert p["bias"] == B and p["scale"] == [A[i][i] for i in range(3)]
    assert p["matrix_frame_convention"] == "gyro-x-xy"
    assert len(p["parameter_covariance"]) == 144 and len(p["matrix_std"]) == 9
    assert p["sensor_model"] == HOSTILE and p["source"] == HOSTILE
    assert p["model"] == "omega = matrix * (omega_raw + bias)"
    assert "angular_velocity_covariance is all zeros" in err  # no --noise
    out, _ = export(capsys, tmp_path, make_full(), "ros", "--ros-node", "/imu")
    p2 = yaml.safe_load(out)["/imu"]["ros__parameters"]["gyro_calibration"]
    assert p2["matrix"][3] == A[1][0]


def test_ros_says_which_uncertainties_it_leaves_out(capsys, tmp_path):
    cal = make_full(matrix_std=None, covariance=None)
    out, err = export(capsys, tmp_path, cal, "ros")
    p = yaml.safe_load(out)["gyro_calibration"]
    assert "matrix_std" not in p and "covariance" not in p
    assert "no matrix_std, parameter_covariance: left out" in err


C_MAIN = r"""
#include <stdio.h>
#include <stdlib.h>
#include "cal.h"

int main(int argc, char **argv)
{
    float m[3], g[3];
    int i;
    if (argc != 4) return 2;
    for (i = 0; i < 3; ++i) m[i] = strtof(argv[i + 1], NULL);
    gyrocal_apply(m, g);
    gyrocal_apply(m, m); /* in place */
    for (i = 0; i < 3; ++i) printf("%.9e %.9e\n", (double)g[i], (double)m[i]);
    return 0;
}
"""


@needs_gcc
def test_c_header_applies_the_full_matrix_like_the_equation(capsys, tmp_path):
    out, _ = export(capsys, tmp_path, make_full(sensor={"model": HOSTILE, "odr_hz": "200"}),
                    "c-header")
    compile_program(tmp_path, out, C_MAIN)
    for m in ([1.3, -2.1, 0.7], [0.0, 0.0, 0.0], [-3.0, 0.25, 5.5]):
        run = subprocess.run([str(tmp_path / "apply"), *map(repr, m)], capture_output=True,
                             text=True, check=True)
        res = np.array([[float(x) for x in line.split()] for line in run.stdout.splitlines()])
        m32 = [float(np.float32(x)) for x in m]  # the program reads the reading as a float
        np.testing.assert_allclose(res[:, 0], truth(m32), rtol=1e-6, atol=1e-6)
        np.testing.assert_allclose(res[:, 1], truth(m32), rtol=1e-6, atol=1e-6)
        diagonal = [A[i][i] * (m32[i] + B[i]) for i in range(3)]
        if any(m):  # dropping the cross-axis terms would not pass
            assert np.max(np.abs(res[:, 0] - diagonal)) > 1e-3
    assert "#define GYROCAL_MATRIX_YX 0.0187f" in out
    assert "odr_hz '200' (not a number)" in out


def test_kalibr_intrinsics_invert_the_matrix(capsys, tmp_path):
    out, err = export(capsys, tmp_path, make_full(), "kalibr", "--rostopic", "/imu/data",
                      "--noise", str(noise_file(tmp_path)))
    k = yaml.safe_load(out)
    assert k["rostopic"] == "/imu/data" and k["update_rate"] == 200
    i = k["gyrocal_intrinsics"]  # informative: Kalibr reads none of it
    assert i["kalibr_model"] == "scale-misalignment" and "model" not in k
    # Kalibr's w_meas = M w + b against gyrocal's m = A^-1 g - bias: M A = I.
    np.testing.assert_allclose(np.array(i["gyroscopes"]["M"]) @ np.array(A), np.eye(3),
                               atol=1e-12)
    assert np.allclose(np.triu(i["gyroscopes"]["M"], 1), 0)  # lower triangular, as Kalibr's
    assert i["gyroscopes"]["C_gyro_i"] == np.eye(3).tolist()
    assert i["gyroscopes"]["A"] == np.zeros((3, 3)).tolist()
    assert i["accelerometers"]["M"] == np.eye(3).tolist()
    assert i["gyro_bias_added_rad_s"] == B
    assert "no place for a fixed gyro bias" in err and "re-estimates the IMU intrinsics" in err


def test_kalibr_of_a_v1_calibration_is_diagonal_and_says_so(capsys, tmp_path):
    cal = GyroCalibration(scale=(0.5, 2.0, 1.25), bias=(0.0, 0.0, 0.0),
                          sensor={"model": "mpu9250", "odr_hz": "fast"})
    out, err = export(capsys, tmp_path, cal, "kalibr", "--noise", str(noise_file(tmp_path)))
    k = yaml.safe_load(out)
    M = k["gyrocal_intrinsics"]["gyroscopes"]["M"]
    assert M == [[2.0, 0.0, 0.0], [0.0, 0.5, 0.0], [0.0, 0.0, 0.8]]
    assert k["update_rate"] == 200  # the noise document's rate: the calibration's is no number
    assert "M is diagonal" in err
    KalibrImuConfig(out).printDetails()


@pytest.mark.parametrize("fmt", ["yaml", "ros", "c-header", "kalibr"])
@pytest.mark.parametrize("full", [False, True])
def test_string_numbers_and_hostile_text_in_a_v1_or_v2_calibration(capsys, tmp_path, fmt, full):
    sensor = {"model": HOSTILE, "odr_hz": "200", "full_scale_dps": "2000\nz: 1",
              "evil\nkey": "x"}
    cal = make_full(sensor=sensor) if full else GyroCalibration(
        scale=(1.0, 1.0, 1.0), bias=(0.0, 0.0, 0.0), sensor=sensor, source=HOSTILE)
    extra = ["--noise", str(noise_file(tmp_path))] if fmt == "kalibr" else []
    out, _ = export(capsys, tmp_path, cal, fmt, *extra)
    if fmt == "c-header":
        head, body = out.split("\n */\n", 1)  # the opening comment, then code only
        assert "evil" not in body and "pwned" not in body
        assert not set("\r\u2028\u2029\x85") & set(out)
        assert all(line == "/*" or line.startswith(" *") for line in head.split("\n"))
    else:
        loaded = yaml.safe_load(out)  # raises on an injected tag or a broken line
        if fmt == "yaml":
            assert loaded["sensor"] == sensor
        assert "evil" not in loaded and "x" not in loaded and "y" not in loaded


def test_hostile_rostopic_is_refused(capsys, tmp_path):
    out, err = export(capsys, tmp_path, make_full(), "kalibr", "--rostopic", "/imu\nevil: 1",
                      "--noise", str(noise_file(tmp_path)), code=2)
    assert "is not a ROS topic name" in err
