"""gyrocal track: the accelerometer's columns reach the still detector, and the chip's datasheet
zero-rate tolerance sets its rate gate (issue 30, "Tracker recovery")."""

import json
import math

import numpy as np
import pytest

from gyrocal.kit.cli import main
from gyrocal.kit.recording import RecordingWriter
from gyrocal.kit.tracking import chip_zero_rate
from tests.calib.test_tracker_accel_still import ODR, REST1, TURN, session

#: The initial zero-rate tolerance of each chip, ± °/s, written out from the datasheets
#: independently of drivers/imu/chips.py: PS-MPU-9250A-01 Table 1 (Initial ZRO Tolerance);
#: DS-000189 Table 1; DS-000347 Table 1 (ZRO initial tolerance, board-level); LSM9DS1
#: DocID025715 Table 3 (G_TyOff); LSM6DSOX DS12814 Table 2 (G_TyOff).
DATASHEET_ZRO_DPS = {"mpu9250": 5.0, "mpu9255": 5.0, "mpu6500": 5.0, "icm20948": 5.0,
                     "icm42688p": 0.5, "lsm9ds1": 30.0, "lsm6dsox": 1.0}


def write(path, s, *, accel):
    sensor = {"model": "mpu9250", "odr_hz": ODR, "full_scale_dps": 250,
              "sensitivity_rad_s_per_lsb": math.radians(1 / 131)}
    if accel:
        sensor.update(accel_full_scale_g=4.0, accel_sensitivity_m_s2_per_lsb=9.80665 / 8192)
    with RecordingWriter(path, sensor=sensor, gimbal={"motors": []}, protocol={"name": "hand"},
                         accel=accel) as w:
        w.append_imu(s["t"], s["gyro"], None, s["accel"] if accel else None)
        w.finish()
    return path


@pytest.fixture(scope="module")
def recs(tmp_path_factory):
    d = tmp_path_factory.mktemp("track_accel")
    s = session(40)
    return s, write(d / "with", s, accel=True), write(d / "without", s, accel=False)


def track(capsys, rec):
    code = main(["track", str(rec), "--json", "--every", "0", "--causal"])
    out, err = capsys.readouterr()
    assert code == 0, err
    return np.array(json.loads(out)["still"], dtype=bool), err


def turning_inner(s):
    return s["turning"] & (s["t"] > REST1 + 2) & (s["t"] < REST1 + TURN - 2)


def test_without_accelerometer_columns_the_gyro_alone_decides(recs, capsys):
    s, _, without = recs
    still, err = track(capsys, without)
    assert still[turning_inner(s)].mean() > 0.9  # the 2 deg/s turn passes the gyro's gates
    assert "accelerometer" not in err


def test_the_accelerometer_columns_veto_a_slow_turn(recs, capsys):
    s, with_accel, _ = recs
    still, err = track(capsys, with_accel)
    assert still[s["turning"]].mean() < 0.01
    assert still[(s["t"] > 1.5) & (s["t"] < REST1 - 0.5)].mean() > 0.95
    assert "the accelerometer vetoes the still detector" in err
    assert "mpu9250 gyro's zero-rate tolerance, +-5 deg/s" in err


@pytest.mark.parametrize("model", sorted(DATASHEET_ZRO_DPS))
def test_chip_zero_rate_tolerance_is_the_datasheets(model):
    tol, note = chip_zero_rate(model)
    assert tol == pytest.approx(math.radians(DATASHEET_ZRO_DPS[model]), rel=1e-12)
    assert "Table" in note


def test_an_unknown_chip_keeps_the_default():
    assert chip_zero_rate("simulated") == (None, None)
    assert chip_zero_rate(None) == (None, None)


def test_streamed_replay_carries_the_accelerometer_as_the_whole_recording(recs):
    """The temporary-file replay (SpilledImu, spilled_chunks) hands the tracker the same
    accelerometer readings as the recording loaded whole (load_recording's imu_accel)."""
    from gyrocal.kit.recording import load_recording
    from gyrocal.kit.tracking import Batch, SpilledImu, replay_chunks, run_tracker, spilled_chunks
    from tests.calib.test_tracker_accel_still import tracker

    _, with_accel, _ = recs
    rec = load_recording(with_accel)
    whole = run_tracker(tracker(True), replay_chunks(
        Batch(rec.imu_t, rec.imu_rate, accel=rec.imu_accel), None, 1009))
    with SpilledImu(with_accel, []) as imu:
        assert imu.has_accel
        assert np.array_equal(imu.accel(0, imu.n), rec.imu_accel)
        streamed = run_tracker(tracker(True), spilled_chunks(imu, None, 997, accel=True))
    assert np.array_equal(streamed.still, whole.still)
    assert np.allclose(streamed.bias, whole.bias, rtol=0, atol=1e-12)
    assert 0.2 < whole.still.mean() < 0.5  # the rests, not the turn
