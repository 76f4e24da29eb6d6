"""The flight-stack exports in their drivers' frames (issue 31).

Each test feeds an emulated chip's raw readings (its true errors as ``gyrocal calibrate --sim``
draws them: :func:`tests.kit.flight_stacks.chip_truth`) through the stack's own correction path
written out from its source (:mod:`tests.kit.flight_stacks`: the driver's remap, the driver's
rotation, PX4's ``calibration::Gyroscope::Correct`` / ``Accelerometer::Correct`` and
``calc_thermal_offsets_3D``, ArduPilot's ``_rotate_and_correct_gyro`` / ``_accel`` and
``TCal::correct_sensor``), with the parameters gyrocal wrote for the calibration a perfect run
holds, and compares what comes out with the true rate (or specific force) in the frame the stack
publishes.

What a stack has a parameter for comes back exactly (a still sensor reads zero rate at every
temperature); what it has none for (the gyro's scale and cross-axis terms, the accelerometer's
cross-axis terms) is left, no larger than the note on stderr says. The same checks on the values
gyrocal wrote before issue 31 (the chip's axes) fail for every chip whose driver remaps its axes
(all but the LSM6DSOX on both stacks and the ICM-42688-P on ArduPilot).
"""

import numpy as np
import pytest

from gyrocal.kit.cli import main
from tests.kit.flight_stacks import (
    ACCEL,
    CHIPS,
    DRIVERS,
    GYRO,
    STANDARD_GRAVITY,
    chip_truth,
    read_params,
    rotate,
    truth_calibration,
)

STACKS = ("px4", "ardupilot")
#: Rates (rad/s, the chip's axes) the gyro is checked at: still, and turning.
RATES = np.array([[0.0, 0.0, 0.0], [0.6, -1.3, 2.1], [-2.5, 0.4, -0.9]])
#: Gravity directions (the chip's axes) the accelerometer is checked at.
UPS = np.array([[0, 0, 1], [0, 0, -1], [1, 0, 0], [0, -1, 0], [0.6, 0.0, 0.8],
                [-0.36, 0.48, 0.8]])
TOL = 2e-7  # rad/s or relative: the parameter files' 9 significant digits


@pytest.fixture(scope="module")
def sensors(tmp_path_factory):
    """chip -> (truth, calibration, calibration file)."""
    d = tmp_path_factory.mktemp("flight")
    out = {}
    for chip in CHIPS:
        truth = chip_truth(chip)
        cal = truth_calibration(truth, chip)
        (d / f"{chip}.json").write_text(cal.to_json())
        out[chip] = (truth, cal, d / f"{chip}.json")
    return out


def export(capsys, path, fmt, *options):
    code = main(["export", str(path), "--format", fmt, *options])
    out, err = capsys.readouterr()
    assert code == 0, err
    return read_params(out), err


def _true_rate_and_reading(truth, omega, temperature):
    m = truth.reading(omega[None], np.array([temperature]))[0]
    return omega, m


@pytest.mark.parametrize("stack", STACKS)
@pytest.mark.parametrize("chip", CHIPS)
def test_the_plain_gyro_offsets_give_back_the_true_rate(sensors, capsys, stack, chip):
    """``--format px4`` / ``ardupilot``: a still chip reads zero after the stack's correction;
    a turning one reads the true rate in the driver's frame up to the scale and cross-axis part
    the stack cannot carry (at most the note's fraction of the rate)."""
    truth, cal, path = sensors[chip]
    p, err = export(capsys, path, stack)
    driver = DRIVERS[stack, chip]
    bound = float(np.linalg.norm(cal.full_matrix - np.eye(3), 2))
    for omega in RATES:
        _, m = _true_rate_and_reading(truth, omega, 25.0)
        got = GYRO[stack](p, chip, m)
        want = driver(omega)
        err_vec = got - want
        assert np.linalg.norm(err_vec) <= bound * np.linalg.norm(got) + TOL, (omega, err_vec)
        # what is left is exactly the uncarried part: the driver's remap of (m + b) − ω
        np.testing.assert_allclose(err_vec, driver(m + np.asarray(cal.bias) - omega), atol=TOL)
    assert f"{bound:.2e} of the rate" in err


@pytest.mark.parametrize("stack", STACKS)
@pytest.mark.parametrize("chip", CHIPS)
def test_the_thermal_formats_null_a_still_chip_at_every_temperature(sensors, capsys, stack,
                                                                     chip):
    """``--format px4-thermal`` (``TC_G0_*``, with ``CAL_GYRO0`` offsets 0 as its note asks) and
    ``ardupilot-thermal`` (``INS_TCAL1_*`` and ``INS_GYROFFS``): a still chip at 15-45 °C reads
    zero rate after the stack's temperature correction."""
    truth, _, path = sensors[chip]
    p, _ = export(capsys, path, f"{stack}-thermal")
    for temperature in (15.0, 21.0, 25.0, 33.5, 45.0):
        m = truth.reading(np.zeros((1, 3)), np.array([temperature]))[0]
        got = GYRO[stack](p, chip, m, temperature)
        np.testing.assert_allclose(got, 0.0, atol=TOL * 10, err_msg=f"{temperature} degC")


@pytest.mark.parametrize("fmt", ["{stack}", "{stack}-accel"])
@pytest.mark.parametrize("stack", STACKS)
@pytest.mark.parametrize("chip", CHIPS)
def test_the_accelerometer_gives_back_gravity_in_the_drivers_frame(sensors, capsys, fmt, stack,
                                                                   chip):
    """``--format px4`` / ``px4-accel`` (``CAL_ACC0_?OFF``, ``?SCALE``) and ``ardupilot`` /
    ``ardupilot-accel`` (``INS_ACCOFFS``, ``INS_ACCSCAL``): a still chip in six poses reads the
    calibration's per-axis correction ``diag(A) (a + b)`` remapped by the driver, and so gravity
    in the driver's frame up to the cross-axis part the stack cannot carry,
    ``(diag(A) − C⁻¹)(a + b)`` with ``C`` the true sensing matrix."""
    truth, cal, path = sensors[chip]
    p, err = export(capsys, path, fmt.format(stack=stack))
    acc = cal.accelerometer
    diag, b = np.diag(np.diag(acc.matrix)), np.asarray(acc.bias)
    c_inv = np.linalg.inv(np.asarray(truth.accelerometer.sensing))
    b_true = STANDARD_GRAVITY * np.asarray(truth.accelerometer.bias_g)
    driver = DRIVERS[stack, chip]
    for up in UPS / np.linalg.norm(UPS, axis=1, keepdims=True):
        raw = STANDARD_GRAVITY * truth.accel_reading(up[None])[0]
        got = ACCEL[stack](p, chip, raw)
        np.testing.assert_allclose(got, driver(diag @ (raw + b)), atol=1e-5)
        left = np.linalg.norm(got - driver(STANDARD_GRAVITY * up))
        assert left <= np.linalg.norm(diag - c_inv, 2) * np.linalg.norm(raw + b_true) + 1e-5
    assert "no accelerometer cross-axis terms" in err


@pytest.mark.parametrize("stack", STACKS)
@pytest.mark.parametrize("rotation,number", [("ROTATION_YAW_90", "2"),
                                             ("ROTATION_ROLL_90_YAW_90", "18"),
                                             ("ROTATION_PITCH_270", "25")])
def test_the_drivers_rotation_is_applied_and_the_board_rotation_needs_nothing(
        sensors, capsys, stack, rotation, number):
    """``--rotation`` is the rotation the driver applies before the offsets (PX4's ``-R``,
    ArduPilot's hwdef IMU rotation), by name or the stack's enum number; SENS_BOARD_ROT /
    AHRS_ORIENTATION act after them: a still chip reads zero with any of them, and the file
    written without ``--rotation`` leaves the bias for a driver started with one."""
    chip = "lsm6dsox"  # no remap on either stack: only the rotation moves the axes
    truth, _, path = sensors[chip]
    m = truth.reading(np.zeros((1, 3)), np.array([25.0]))[0]
    for given in (rotation, number, rotation.removeprefix("ROTATION_").lower()):
        p, err = export(capsys, path, stack, "--rotation", given)
        assert rotation in err
        for board in ("ROTATION_NONE", "ROTATION_ROLL_180"):
            got = GYRO[stack](p, chip, m, rotation=rotation, board=board)
            np.testing.assert_allclose(got, 0.0, atol=TOL)
    p, _ = export(capsys, path, stack)
    assert np.linalg.norm(GYRO[stack](p, chip, m, rotation=rotation)) > 1e-3


@pytest.mark.parametrize("stack", STACKS)
def test_the_note_names_the_driver_and_its_remap(sensors, capsys, stack):
    _, _, path = sensors["mpu9250"]
    _, err = export(capsys, path, stack)
    if stack == "px4":
        assert "MPU9250_I2C.cpp" in err and "(x, −y, −z) of the chip's axes" in err
        assert "SENS_BOARD_ROT" in err and "change nothing here" in err
    else:
        assert "AP_InertialSensor_Invensense.cpp" in err and "(y, x, −z)" in err
        assert "AHRS_ORIENTATION" in err and "INS_GYR_CAL" in err
    assert "has no gyro scale or cross-axis parameter" in err


@pytest.mark.parametrize("fmt", ["px4", "ardupilot", "px4-accel", "ardupilot-thermal"])
def test_a_chip_without_a_known_driver_is_refused_unless_its_axes_are_given(
        sensors, capsys, tmp_path, fmt):
    """A calibration that does not say its chip (one from another tool) is refused (exit 2,
    naming --driver-axes) rather than written in axes the stack may not use; with
    ``--driver-axes`` it is written in those axes."""
    from dataclasses import replace

    _, cal, _ = sensors["mpu9250"]
    p = tmp_path / "c.json"
    p.write_text(replace(cal, sensor={}).to_json())
    assert main(["export", str(p), "--format", fmt]) == 2
    err = capsys.readouterr().err
    assert "driver is known for the sensor model 'not recorded'" in err
    assert "--driver-axes" in err
    params, err = export(capsys, p, fmt, "--driver-axes", "y,x,-z")
    assert "given with --driver-axes (y, x, −z)" in err
    for bad in ("x,y", "x,x,z", "x,y,w"):
        assert main(["export", str(p), "--format", fmt, "--driver-axes", bad]) == 2
        assert "--driver-axes" in capsys.readouterr().err


def test_a_rotation_that_is_not_a_quarter_turn_is_refused(sensors, capsys):
    _, _, path = sensors["mpu9250"]
    for bad in ("ROTATION_YAW_45", "ROTATION_PITCH_7", "99", "sideways"):
        assert main(["export", str(path), "--format", "ardupilot", "--rotation", bad]) == 2
        assert "quarter-turn" in capsys.readouterr().err


def test_px4_writes_the_gyro_and_accel_ids_and_ardupilot_the_second_imu(sensors, capsys,
                                                                        tmp_path):
    """``CAL_GYRO<n>_ID`` and ``CAL_ACC<n>_ID`` from the chip, bus and address (PX4 Device.hpp:
    I2C 1 | bus 1 << 3 | 0x68 << 8 | MPU9250 0x24 << 16 = 2385929) or --device-id;
    ``--imu-index 2`` writes ArduPilot's ``INS_GYR2OFFS_*`` and ``INS_ACC2OFFS_*``."""
    from dataclasses import replace

    _, cal, _ = sensors["mpu9250"]
    p = tmp_path / "c.json"
    p.write_text(replace(cal, sensor={"model": "mpu9250", "i2c_bus": 1,
                                      "i2c_address": 0x68}).to_json())
    params, _ = export(capsys, p, "px4", "--imu-index", "1")
    assert params["CAL_GYRO1_ID"] == params["CAL_ACC1_ID"] == 2385929
    assert {"CAL_GYRO1_XOFF", "CAL_ACC1_ZSCALE"} <= set(params)
    params, _ = export(capsys, p, "px4", "--device-id", "7")
    assert params["CAL_GYRO0_ID"] == 7
    params, _ = export(capsys, p, "ardupilot", "--imu-index", "2")
    assert {"INS_GYR2OFFS_X", "INS_ACC2OFFS_Y", "INS_ACC2SCAL_Z"} <= set(params)
    assert not any(k.startswith("INS_GYROFFS") for k in params)


def test_a_calibration_without_accelerometer_gets_the_gyro_offsets_only(sensors, capsys,
                                                                        tmp_path):
    from dataclasses import replace

    _, cal, _ = sensors["icm42688p"]
    p = tmp_path / "c.json"
    p.write_text(replace(cal, accelerometer=None, temperature_model=None).to_json())
    params, err = export(capsys, p, "px4")
    assert sorted(params) == ["CAL_GYRO0_XOFF", "CAL_GYRO0_YOFF", "CAL_GYRO0_ZOFF"]
    assert "CAL_GYRO0_ID not written" in err
    params, _ = export(capsys, p, "ardupilot")
    assert sorted(params) == ["INS_GYROFFS_X", "INS_GYROFFS_Y", "INS_GYROFFS_Z"]
    np.testing.assert_allclose([params[f"INS_GYROFFS_{a}"] for a in "XYZ"], -np.asarray(
        cal.bias), rtol=1e-8)  # no remap for the ICM-42688-P on ArduPilot (Invensensev3)


def test_rotate_in_the_model_is_the_stacks_euler_convention():
    """The model's ``rotate`` cases (the stacks' own) agree with gyrocal's table's
    ``Rz(yaw) Ry(pitch) Rx(roll)``, so the two are checked against each other."""
    from gyrocal.kit.consumer_frames import rotation_matrix

    v = np.array([0.3, -1.1, 2.7])
    for name in ("ROTATION_NONE", "ROTATION_YAW_90", "ROTATION_ROLL_180",
                 "ROTATION_ROLL_90_YAW_90", "ROTATION_PITCH_270"):
        np.testing.assert_allclose(rotation_matrix(name) @ v, rotate(name, v), atol=1e-15)


def test_the_table_in_using_md_is_the_code_s_table():
    """hardware_docs/using.md's table of the drivers' axes says what
    ``gyrocal.kit.consumer_frames.DRIVER_FRAMES`` holds, row by row, and has a row for every
    chip of it ("—" where a stack has no driver)."""
    from pathlib import Path

    from gyrocal.kit.consumer_frames import DRIVER_FRAMES

    chips = {r.chip for r in DRIVER_FRAMES}
    text = (Path(__file__).parents[2] / "hardware_docs" / "using.md").read_text()
    rows = {}
    for line in text.splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if len(cells) == 5 and cells[0] in chips:
            rows[cells[0]] = {"px4": cells[2], "ardupilot": cells[4]}
    assert sorted(rows) == sorted(chips)
    for chip, cells in rows.items():
        for stack, cell in cells.items():
            row = next((r for r in DRIVER_FRAMES if r.stack == stack and r.chip == chip), None)
            want = "—" if row is None else row.gyro.replace(",", ", ").replace("-", "−")
            assert cell == want, (chip, stack)
            assert row is None or row.accel == row.gyro


def test_every_row_cites_its_driver_file_commit_and_line_and_the_model_agrees():
    """Each ``DRIVER_FRAMES`` row names the driver source as ``file@commit:line`` (the project's
    rule for consumer facts), and its remap is what the stack's driver, written out
    independently in :data:`tests.kit.flight_stacks.DRIVERS`, does to a reading."""
    import re

    from gyrocal.kit.consumer_frames import DRIVER_FRAMES, axes_matrix

    v = np.array([0.3, -1.1, 2.7])
    for r in DRIVER_FRAMES:
        assert re.search(r"\.(?:cpp|hpp)@[0-9a-f]{7}:\d+", r.source), r
        driver = DRIVERS[r.stack, r.chip]
        np.testing.assert_array_equal(axes_matrix(r.gyro) @ v, driver(v), err_msg=str(r))
        np.testing.assert_array_equal(axes_matrix(r.accel) @ v, driver(v), err_msg=str(r))


def test_an_emulated_run_gives_back_a_still_rate_to_its_own_precision(full_run, capsys):
    """The default ``gyrocal calibrate --sim`` run (an MPU-9250, the shared session run): a
    still chip in zero g (reading ``−bias`` of the emulator's truth) reads zero on both stacks
    within 4 σ of the calibration's own bias, and with the chip-axis values of before
    (``--driver-axes x,y,z``) it did not."""
    from gyrocal.calib.model import GyroCalibration
    from gyrocal.kit.recording import load_recording

    d, code = full_run
    assert code == 0
    cal = GyroCalibration.from_json((d / "calibration.json").read_text())
    raw = -np.asarray(load_recording(d / "recording").truth["bias"])
    for stack in STACKS:
        four_sigma = 4 * np.abs(DRIVERS[stack, "mpu9250"](np.asarray(cal.bias_std)))
        p, _ = export(capsys, d / "calibration.json", stack)
        got = GYRO[stack](p, "mpu9250", raw)
        assert np.all(np.abs(got) <= four_sigma), (stack, got, four_sigma)
        p, _ = export(capsys, d / "calibration.json", stack, "--driver-axes", "x,y,z")
        assert np.max(np.abs(GYRO[stack](p, "mpu9250", raw))) > 10 * np.max(four_sigma)
