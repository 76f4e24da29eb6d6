"""Exports of a calibration with g-sensitivity (``g = A (m + b + G f)``, Calibration v2).

Truth: the model written out here by hand, ``g[i] = Σ_j A[i][j] (m[j] + b[j] + Σ_k G[j][k] f[k])``;
each export is read back by a third-party reader (the C compiler, PyYAML's safe loader), and the
Kalibr file through Kalibr's own gyro equation (ethz-asl/kalibr,
``kalibr_imu_camera_calibration/IccSensors.py``, ``addGyroscopeErrorTerms``:
``w_meas = M w + A a + b`` with ``a`` the specific force in m/s²).
"""

import re
import subprocess

import numpy as np
import pytest
import yaml

from gyrocal.calib.model import GyroCalibration
from gyrocal.kit.cli import main
from tests.kit.c_program import compile_program, needs_gcc
from tests.kit.ros_readers import noise_file
from tests.kit.test_export_thermal import make_cal as thermal_cal
from tests.kit.test_export_v2 import A, B, make_full

#: rad/s per g, a few times the MPU-9250's typical 0.1 °/s/g (1.7e-3 rad/s/g).
G = [[1.7e-3, -4.0e-4, 2.5e-4], [3.0e-4, -1.2e-3, 6.0e-4], [-5.0e-4, 8.0e-4, 2.2e-3]]
G_STD = [[1e-4] * 3] * 3
GSENS = {"matrix": G, "matrix_std": G_STD, "directions": np.eye(3).tolist()}


def truth(m, f):
    return [sum(A[i][j] * (m[j] + B[j] + sum(G[j][k] * f[k] for k in range(3)))
                for j in range(3)) for i in range(3)]


def export(capsys, tmp_path, cal, fmt, *options):
    p = tmp_path / "cal.json"
    p.write_text(cal.to_json())
    rc = main(["export", str(p), "--format", fmt, *options])
    out, err = capsys.readouterr()
    assert rc == 0, err
    assert "Traceback" not in err
    return out, err


C_MAIN = r"""
#include <stdio.h>
#include <stdlib.h>
#include "cal.h"

int main(int argc, char **argv)
{
    float m[3], f[3], g[3], h[3];
    int i;
    if (argc != 7) return 2;
    for (i = 0; i < 3; ++i) m[i] = strtof(argv[i + 1], NULL);
    for (i = 0; i < 3; ++i) f[i] = strtof(argv[i + 4], NULL);
    gyrocal_apply_force(m, f, g);
    gyrocal_apply(m, h);
    gyrocal_apply_force(m, f, m); /* in place */
    for (i = 0; i < 3; ++i) printf("%.9e %.9e %.9e\n", (double)g[i], (double)m[i], (double)h[i]);
    return 0;
}
"""


@needs_gcc
def test_c_header_applies_g_sensitivity_given_the_specific_force(capsys, tmp_path):
    cal = make_full(g_sensitivity=GSENS, sensor={"model": "mpu9250", "odr_hz": 200.0})
    out, err = export(capsys, tmp_path, cal, "c-header")
    assert err == ""
    compile_program(tmp_path, out, C_MAIN)
    rng = np.random.default_rng(3)
    for m, f in [([1.3, -2.1, 0.7], [0.0, 0.0, 1.0]), ([0.0, 0.0, 0.0], [0.6, -0.8, 0.0]),
                 (list(rng.normal(size=3)), list(rng.normal(size=3)))]:
        m32 = [float(np.float32(x)) for x in m]
        f32 = [float(np.float32(x)) for x in f]
        run = subprocess.run([str(tmp_path / "apply"), *map(repr, m32), *map(repr, f32)],
                             capture_output=True, text=True, check=True)
        res = np.array([[float(x) for x in line.split()] for line in run.stdout.splitlines()])
        np.testing.assert_allclose(res[:, 0], truth(m32, f32), rtol=1e-6, atol=1e-7)
        np.testing.assert_allclose(res[:, 1], truth(m32, f32), rtol=1e-6, atol=1e-7)
        np.testing.assert_allclose(res[:, 0], cal.apply(m32, specific_force=f32),
                                   rtol=1e-6, atol=1e-7)
        # gyrocal_apply leaves G out (as the header says), and that differs by ~|A G f|
        np.testing.assert_allclose(res[:, 2], truth(m32, [0.0, 0.0, 0.0]), rtol=1e-6,
                                   atol=1e-7)
        assert np.max(np.abs(res[:, 0] - res[:, 2])) > 2e-4
    assert "#define GYROCAL_GSENS_XY (-0.0004f)" in out
    assert "gyrocal_apply() leaves G out" in out


def test_yaml_and_ros_carry_g_sensitivity_as_data(capsys, tmp_path):
    cal = make_full(g_sensitivity=GSENS)
    out, err = export(capsys, tmp_path, cal, "yaml")
    doc = yaml.safe_load(out)
    assert doc["g_sensitivity"]["matrix"] == G and doc["g_sensitivity"]["matrix_std"] == G_STD
    assert GyroCalibration.from_dict(doc).g_sensitivity == cal.g_sensitivity
    assert "g = matrix @ (m + bias + g_sensitivity.matrix @ f)" in out and err == ""
    out, err = export(capsys, tmp_path, cal, "ros", "--noise", str(noise_file(tmp_path)))
    p = yaml.safe_load(out)["gyro_calibration"]
    assert p["g_sensitivity"] == [x for row in G for x in row]
    assert p["g_sensitivity_std"] == [x for row in G_STD for x in row]
    assert p["model"] == "omega = matrix * (omega_raw + bias + g_sensitivity * f)"
    # the ROS file's model, written out from its comment, gives the calibrated rate
    m, f = np.array([0.4, -1.1, 2.0]), np.array([0.1, 0.2, 0.97])
    mat = np.reshape(p["matrix"], (3, 3))
    gs = np.reshape(p["g_sensitivity"], (3, 3))
    np.testing.assert_allclose(mat @ (m + np.array(p["bias"]) + gs @ f), truth(m, f),
                               atol=1e-15)
    assert "linear_acceleration_covariance is all zeros" in err  # no accelerometer


def test_kalibr_gets_the_g_sensitivity_in_its_units_and_sign(capsys, tmp_path):
    cal = make_full(g_sensitivity=GSENS)
    out, err = export(capsys, tmp_path, cal, "kalibr", "--noise", str(noise_file(tmp_path)))
    k = yaml.safe_load(out)["gyrocal_intrinsics"]
    M, Ak = np.array(k["gyroscopes"]["M"]), np.array(k["gyroscopes"]["A"])
    # Kalibr's measurement of a true rate w with specific force a (m/s²), its bias b = -bias:
    w, a = np.array([0.3, -0.2, 1.5]), np.array([1.0, -2.0, 9.5])
    meas = M @ w + Ak @ a - np.array(B)
    # gyrocal's model applied to that reading with f = a / g0 gives the true rate back
    np.testing.assert_allclose(cal.apply(meas, specific_force=a / 9.80665), w, atol=1e-12)
    assert "gyroscopes.A: the g-sensitivity" in out
    assert "accelerometers.M: the identity (the calibration has no accelerometer)" in out


def test_targets_without_a_place_for_g_say_so(capsys, tmp_path):
    base = thermal_cal()
    cal = GyroCalibration.from_dict({**base.to_dict(), "g_sensitivity": GSENS})
    for fmt, name in (("px4-thermal", "PX4's TC_G parameters"),
                      ("ardupilot-thermal", "ArduPilot's INS_TCAL parameters")):
        _, err = export(capsys, tmp_path, cal, fmt)
        assert f"{name} has no place for the gyro's g-sensitivity" in err
        # the figure is the largest change of a calibrated axis over unit specific forces
        # (searched here), to the note's two digits
        f = np.random.default_rng(5).normal(size=(100_000, 3))
        f /= np.linalg.norm(f, axis=1, keepdims=True)
        searched = np.max(np.abs(f @ (np.asarray(cal.full_matrix) @ np.array(G)).T))
        said = float(re.search(r"off by up to ([0-9.e+-]+) rad/s per g", err).group(1))
        assert said == pytest.approx(searched, rel=0.05)
        _, err = export(capsys, tmp_path, base, fmt)  # no G: no such note
        assert "g-sensitivity" not in err
    out, err = export(capsys, tmp_path, cal, "c-header")
    assert "gyrocal_apply_at() (the temperature model) leaves the g-sensitivity out" in err
