"""The ROS-world exports read as their consumers read them (issue 31): Kalibr's ``imu.yaml``
through a model of Kalibr's ``ImuParameters`` reader, the ROS parameters' ``sensor_msgs/Imu``
covariances against the noise of an independent still record, and ``--format imu-calib``
through a model of ``imu_calib``'s ``loadCalib``/``applyCalib`` (tests/kit/ros_readers.py,
each rule with its source file and line).

The accelerometer calibration is fitted to rests from the independent generator
tests/calib/accel_truth.py, whose true sensing matrix and bias give the true force.
"""

import json
from dataclasses import replace

import numpy as np
import pytest
import yaml

from gyrocal.calib.accel import fit_accelerometer
from gyrocal.calib.allan import characterise_noise
from gyrocal.calib.model import Consistency, GyroCalibration
from gyrocal.calib.noise_sim import NoiseModel, simulate_still
from gyrocal.kit.cli import main
from tests.calib import accel_truth
from tests.kit.ros_readers import KALIBR_REQUIRED, ImuCalibAccel, KalibrImuConfig

ODR = 200.0
N_TRUE = (1.0e-4, 2.0e-4, 1.5e-4)  # rad/s/sqrt(Hz), the still record's white noise


@pytest.fixture(scope="module")
def still():
    """A 120 s still record (white noise N_TRUE, a slow bias walk) and its noise document."""
    s = simulate_still(np.random.default_rng(31), 120.0, odr_hz=ODR,
                       model=NoiseModel(noise_density=N_TRUE, rate_random_walk=(2e-5,) * 3))
    return s.rate, characterise_noise(s.rate, ODR).with_meta(source="simulation").to_dict()


@pytest.fixture(scope="module")
def truth_and_cal():
    """The accelerometer's true sensing and bias (a = C f − b), and a v2 calibration whose
    accelerometer is fitted to rests drawn from them, with a measured noise density."""
    rng = np.random.default_rng(131)
    sensing = accel_truth.random_sensing(rng)
    bias = rng.normal(0, 0.3, 3)
    means, std = accel_truth.rest_means(rng, sensing, bias, accel_truth.fibonacci_directions(14),
                                        9.80665, 0.03, 200)
    acc = replace(fit_accelerometer(means, std), noise_density=np.array([2.1e-3, 2.6e-3, 1.9e-3]),
                  noise_density_std=np.array([2e-4, 3e-4, 2e-4]), noise_tau_s=0.1)
    a = np.tril(np.eye(3) + rng.normal(0, 0.02, (3, 3)))
    cal = GyroCalibration(
        scale=tuple(np.diag(a)), bias=(0.01, -0.02, 0.003), matrix=tuple(map(tuple, a)),
        matrix_std=tuple(map(tuple, np.tril(np.full((3, 3), 1e-4)))), frame="gyro-x-xy",
        method="full-matrix", consistency=Consistency(40.0, 42, 0.5, True),
        sensor={"model": "mpu9250", "odr_hz": ODR}, accelerometer=acc)
    return sensing, bias, cal


@pytest.fixture
def files(tmp_path, still, truth_and_cal):
    n = tmp_path / "noise.json"
    n.write_text(json.dumps(still[1]))
    c = tmp_path / "cal.json"
    c.write_text(truth_and_cal[2].to_json())
    return c, n


def export(capsys, *args, code=0):
    rc = main(["export", *map(str, args)])
    out, err = capsys.readouterr()
    assert rc == code, err
    assert "Traceback" not in err
    return out, err


# ------------------------------------------------------------------ kalibr
def test_kalibr_of_a_calibration_is_read_by_kalibrs_reader(files, still, capsys):
    cal, noise = files
    out, err = export(capsys, cal, "--format", "kalibr", "--noise", noise)
    data = yaml.safe_load(out)
    # every field Kalibr's ImuParameters reads is written, positive where it checks so
    assert set(KALIBR_REQUIRED) <= set(data)
    details = KalibrImuConfig(out).printDetails()
    doc = still[1]
    assert details["gyro"][2] == pytest.approx(max(doc["noise_density"]["value"]), rel=1e-6)
    assert details["gyro"][1] == pytest.approx(max(doc["rate_random_walk"]["value"]), rel=1e-6)
    assert details["accel"][2] == pytest.approx(2.6e-3, rel=1e-6)  # the measured density
    assert details["update_rate"] == ODR and details["rostopic"] == "/imu0"
    # Kalibr's discrete noise σ_d = σ_c √rate (ConfigReader.py 473) of the largest density ...
    nd = doc["noise_density"]
    i = int(np.argmax(nd["value"]))
    assert details["gyro"][0] == pytest.approx(nd["value"][i] * np.sqrt(ODR), rel=1e-6)
    # ... is the still record's per-sample scatter (independent of Allan), within the 95 %
    # interval the noise document states for that density
    per_sample = np.sqrt(np.var(np.diff(still[0], axis=0), axis=0) / 2)
    assert nd["lo95"][i] * np.sqrt(ODR) <= per_sample[i] <= nd["hi95"][i] * np.sqrt(ODR)
    # nothing else at the top level: the intrinsics are in a block Kalibr does not read
    assert set(data) == {*KALIBR_REQUIRED, "gyrocal_intrinsics"}
    assert "INFORMATIVE ONLY" in out and "re-estimates the IMU intrinsics" in err
    assert "placeholder" in err and "accelerometer_random_walk" in err


def test_the_reader_model_rejects_what_kalibr_rejects(files, capsys):
    cal, noise = files
    out, _ = export(capsys, cal, "--format", "kalibr", "--noise", noise)
    for field in KALIBR_REQUIRED:
        cut = "\n".join(line for line in out.splitlines() if not line.startswith(field + ":"))
        with pytest.raises(RuntimeError, match=f"Field '{field}' missing"):
            KalibrImuConfig(cut).printDetails()
    zero = out.replace("update_rate: 200", "update_rate: 0")
    with pytest.raises(RuntimeError, match="invalid update_rate"):
        KalibrImuConfig(zero).printDetails()


def test_kalibr_of_a_calibration_without_noise_is_refused(files, capsys):
    cal, _ = files
    out, err = export(capsys, cal, "--format", "kalibr", code=2)
    assert out == "" and "give --noise noise.json" in err and "gyrocal noise" in err


def test_kalibr_flags_win_and_the_noise_document_alone_still_loads(files, capsys):
    cal, noise = files
    out, err = export(capsys, cal, "--format", "kalibr", "--noise", noise,
                      "--accel-noise-density", "4e-3", "--accel-random-walk", "3e-4",
                      "--update-rate", "100", "--rostopic", "/imu/data_raw")
    d = KalibrImuConfig(out).printDetails()
    assert d["accel"][1:] == (3e-4, 4e-3) and d["update_rate"] == 100
    assert d["rostopic"] == "/imu/data_raw" and "placeholder" not in err
    out, _ = export(capsys, noise, "--format", "kalibr")
    KalibrImuConfig(out).printDetails()
    assert set(yaml.safe_load(out)) == set(KALIBR_REQUIRED)


# ------------------------------------------------------------------ ros
def test_ros_covariances_are_the_per_sample_noise_of_the_calibrated_reading(
        files, still, truth_and_cal, capsys):
    cal, noise = files
    gc = truth_and_cal[2]
    out, err = export(capsys, cal, "--format", "ros", "--noise", noise)
    p = yaml.safe_load(out)["gyro_calibration"]
    gyro = np.reshape(p["angular_velocity_covariance"], (3, 3))
    accel = np.reshape(p["linear_acceleration_covariance"], (3, 3))
    A, A_acc = gc.full_matrix, gc.accelerometer.matrix
    # truth: the still record's own per-sample variance (half the variance of first
    # differences, blind to the slow bias walk), through the calibration's matrix
    # lies within the noise document's 95 % interval of N, as N^2 * rate
    var = np.var(np.diff(still[0], axis=0), axis=0) / 2
    nd = still[1]["noise_density"]
    assert np.all(np.array(nd["lo95"]) ** 2 * ODR <= var), (var, nd)
    assert np.all(var <= np.array(nd["hi95"]) ** 2 * ODR), (var, nd)
    # and the documented formula exactly: M diag(N^2 * rate) M^T
    n_doc = np.array(nd["value"])
    np.testing.assert_allclose(gyro, A @ np.diag(n_doc**2 * ODR) @ A.T, rtol=1e-12)
    n_acc = gc.accelerometer.noise_density
    np.testing.assert_allclose(accel, A_acc @ np.diag(n_acc**2 * ODR) @ A_acc.T, rtol=1e-12)
    assert np.allclose(gyro, gyro.T) and np.all(np.linalg.eigvalsh(gyro) > 0)
    assert p["covariance_rate_hz"] == ODR
    # the parameters' covariance keeps a name no one takes for a message field
    assert "covariance" not in p and "sensor_msgs/Imu" in out
    assert "not a sensor_msgs/Imu covariance" in out


def test_ros_without_noise_writes_covariance_unknown_and_says_so(files, capsys):
    cal, _ = files
    out, err = export(capsys, cal, "--format", "ros", "--ros-node", "imu_node")
    p = yaml.safe_load(out)["imu_node"]["ros__parameters"]["gyro_calibration"]
    assert p["angular_velocity_covariance"] == [0.0] * 9  # Imu.msg: "covariance unknown"
    assert p["linear_acceleration_covariance"][0] > 0
    assert "angular_velocity_covariance is all zeros" in err and "--noise" in err


# ------------------------------------------------------------------ imu_calib
def test_imu_calib_applies_the_accelerometer_as_the_node_does(files, truth_and_cal, capsys):
    cal, _ = files
    sensing, bias, gc = truth_and_cal
    out, err = export(capsys, cal, "--format", "imu-calib")
    node = ImuCalibAccel(out)
    rng = np.random.default_rng(7)
    f_true = rng.normal(0, 9.8, (50, 3))  # forces in the contract's frame
    raw = np.linalg.solve(accel_truth.truth_matrix(sensing), f_true.T).T - bias  # a = A⁻¹f − b
    corrected = node.apply(raw)
    # against the calibration's own correction f = A (a + b): a round trip, to rounding
    np.testing.assert_allclose(corrected, gc.accelerometer.apply(raw), rtol=0, atol=1e-12)
    # against the generator's true force: within the fit's precision
    assert np.max(np.abs(corrected - f_true)) < 0.02
    assert np.max(np.abs(raw - f_true)) > 0.2  # the raw reading is far off: the test can tell
    assert "calibrate_gyros" in err and "--format ros" in err


def test_imu_calib_needs_an_accelerometer(tmp_path, capsys):
    p = tmp_path / "g.json"
    p.write_text(GyroCalibration(scale=(1.0, 1.0, 1.0), bias=(0.0, 0.0, 0.0)).to_json())
    _, err = export(capsys, p, "--format", "imu-calib", code=2)
    assert "needs a calibration with an 'accelerometer'" in err


# ------------------------------------------------------------------ help
@pytest.mark.parametrize("argv", [["--help"], ["export", "--help"]])
def test_help_describes_calibration_v2_as_the_default(argv, capsys):
    assert main(argv) == 0
    out = " ".join(capsys.readouterr().out.split())  # argparse wraps lines
    assert "g = A (m + b)" in out
    assert ("v2, the full model" if argv[0] == "export" else "Calibration v2;") in out
    assert "scale factors and biases" not in out and "a Calibration v1 from" not in out
    if argv[0] == "export":
        for word in ("imu-calib", "--noise", "kalibr", "re-estimates"):
            assert word in out
