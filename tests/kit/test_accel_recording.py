"""The accelerometer from a run (issue 15): imu.csv's optional ``ax,ay,az`` columns, written and
read back by both parsers, and the fit of the rests in ``estimate`` against the truth of an
independent generator (tests/kit/contract_fullmodel_recording.py) and of the emulated
accelerometer's error model."""

from __future__ import annotations

import json

import numpy as np
import pytest

from gyrocal.drivers.emulated.accel import draw_accel_truth
from gyrocal.kit.cli import main
from gyrocal.kit.pipeline import estimate_recording, local_gravity
from gyrocal.kit.recording import RecordingError, RecordingWriter, load_recording
from gyrocal.kit.report import calibration_table
from tests.kit.contract_fullmodel_recording import draw_accel, write_recording

SENSOR = {"model": "mpu9250", "odr_hz": 100.0, "full_scale_dps": 500,
          "sensitivity_rad_s_per_lsb": 2.66e-4}
IL = np.tril_indices(3)


def _written(tmp_path, temperature):
    rng = np.random.default_rng(3)
    t = np.arange(50) / 100.0
    rate, accel = rng.normal(size=(50, 3)), rng.normal(size=(50, 3)) * 9.8
    temp = None if temperature is None else np.full(50, temperature)
    with RecordingWriter(tmp_path / "rec", sensor=SENSOR, gimbal={}, protocol={},
                         accel=True) as w:
        w.append_imu(t[:20], rate[:20], temp if temp is None else temp[:20], accel[:20])
        w.append_imu(t[20:], rate[20:], temp if temp is None else temp[20:], accel[20:])
        w.finish()
    return t, rate, accel


@pytest.mark.parametrize("parser", ["decimal", "numpy", "pandas"])
@pytest.mark.parametrize("temperature", [None, 31.5])
def test_accel_columns_round_trip_with_either_parser(tmp_path, monkeypatch, parser, temperature):
    if parser == "pandas":
        pytest.importorskip("pandas")
    monkeypatch.setenv("GYROCAL_CSV_PARSER", parser)
    t, rate, accel = _written(tmp_path, temperature)
    head = (tmp_path / "rec" / "imu.csv").read_text().splitlines()[:2]
    assert head[0] == "t,gx,gy,gz,temp,ax,ay,az"
    assert (",," in head[1]) == (temperature is None)  # an absent temperature is empty
    rec = load_recording(tmp_path / "rec")
    np.testing.assert_allclose(rec.imu_accel, accel, rtol=1e-9)
    np.testing.assert_allclose(rec.imu_rate, rate, rtol=1e-9)
    assert np.all(np.isnan(rec.imu_temp)) == (temperature is None)


def test_a_recording_without_the_columns_has_no_accelerometer(tmp_path):
    with RecordingWriter(tmp_path / "rec", sensor=SENSOR, gimbal={}, protocol={}) as w:
        w.append_imu(np.arange(3) / 100, np.zeros((3, 3)), None, np.ones((3, 3)))  # ignored
        w.finish()
    assert (tmp_path / "rec" / "imu.csv").read_text().startswith("t,gx,gy,gz,temp\n")
    assert load_recording(tmp_path / "rec").imu_accel is None


def test_accel_rows_keep_every_check(tmp_path):
    _written(tmp_path, 30.0)
    path = tmp_path / "rec" / "imu.csv"
    lines = path.read_text().splitlines()
    with RecordingWriter(tmp_path / "w", sensor=SENSOR, gimbal={}, protocol={}, accel=True) as w:
        with pytest.raises(ValueError, match="accel"):
            w.append_imu([0.0], [[0, 0, 0]], [25.0])  # the columns need the readings
    for bad, what in ((lines[5].rsplit(",", 1)[0] + ",", "field 8"),  # empty az
                      (lines[5] + ",1", "8 comma-separated fields"),
                      (lines[5].rsplit(",", 1)[0] + ",inf", "field 8")):
        path.write_text("\n".join([*lines[:5], bad, *lines[6:]]) + "\n")
        with pytest.raises(RecordingError, match=f"imu.csv:6: .*{what}"):
            load_recording(tmp_path / "rec")


@pytest.mark.parametrize("seed", [1, 2])
def test_independent_generator_accelerometer_within_its_sigma(tmp_path, seed):
    """An independent recording (gravity in the true orientation through a known A and b, at
    a local gravity of 9.81 m/s² the manifest gives): the fit lands within 4σ of the truth,
    consistent, and the calibration document carries it."""
    truth = draw_accel(seed)
    write_recording(tmp_path / "rec", seed=seed, accel_truth=truth, gravity_m_s2=9.81)
    est = estimate_recording(load_recording(tmp_path / "rec"))
    acc = est.calibration.accelerometer
    assert acc is not None and acc.gravity == 9.81 and acc.consistency.ok
    err = np.concatenate([(acc.matrix - truth["matrix"])[IL], acc.bias - truth["bias"]])
    assert np.all(np.abs(err) < 4 * acc.std), err / acc.std
    doc = est.calibration.to_dict()["accelerometer"]
    assert doc["gravity_m_s2"] == 9.81 and np.allclose(doc["bias_std"], acc.std[6:])
    # white noise of truth["noise"] m/s² per sample at 200 Hz: Kalibr's continuous-time density
    # is σ_d · sqrt(Δt)
    density = truth["noise"] / np.sqrt(200.0)
    assert np.all(np.abs(acc.noise_density - density) < 4 * acc.noise_density_std)
    assert np.all(acc.noise_density_std < 0.25 * density)
    assert np.allclose(doc["noise_density"], acc.noise_density)
    summary = calibration_table(est.calibration)
    assert "against gravity 9.81000 m/s²" in summary
    assert "accelerometer consistency: consistent" in summary


def test_noise_free_recovery_of_the_emulated_accelerometer_errors(tmp_path):
    """The emulated accelerometer's error model (datasheet scale, cross-axis, bias) read
    without noise at every rest of a tour: the fit returns the calibration its manifest
    states to 1e-9."""
    emulated = draw_accel_truth("mpu9250", 4)
    write_recording(tmp_path / "rec", seed=4, accel_truth={"reading": emulated.reading})
    acc = estimate_recording(load_recording(tmp_path / "rec")).calibration.accelerometer
    want = emulated.manifest()
    assert acc is not None and acc.gravity == 9.80665
    np.testing.assert_allclose(acc.matrix, want["matrix"], atol=1e-9)
    np.testing.assert_allclose(acc.bias, want["bias_m_s2"], atol=1e-9)


def test_too_few_orientations_is_a_note_not_a_calibration(tmp_path):
    write_recording(tmp_path / "rec", seed=5, accel_truth=draw_accel(5), tour=False)
    est = estimate_recording(load_recording(tmp_path / "rec"))
    assert est.calibration.accelerometer is None
    assert any("accelerometer was NOT calibrated" in n for n in est.notes)


def test_local_gravity_from_the_config_keys():
    assert local_gravity({"gravity_m_s2": 9.80665}) == (9.80665, "standard gravity")
    # WGS-84 normal gravity (NIMA TR8350.2 Eq. 4-1): 9.7803253359 at the equator,
    # 9.8321849379 at the poles
    assert local_gravity({"gravity_m_s2": 0, "latitude_deg": 0.0})[0] == pytest.approx(
        9.7803253359, abs=1e-9)
    assert local_gravity({"gravity_m_s2": 0, "latitude_deg": 90.0})[0] == pytest.approx(
        9.8321849379, abs=1e-9)


def test_estimate_flags(tmp_path, capsys):
    write_recording(tmp_path / "rec", seed=1, accel_truth=draw_accel(1), gravity_m_s2=9.81)
    assert main(["estimate", str(tmp_path / "rec"), "--gravity", "12"]) == 2
    assert "--gravity 12.0 must be in 9.7..9.9" in capsys.readouterr().err
    assert main(["estimate", str(tmp_path / "rec"), "--latitude", "52", "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["accelerometer"]["gravity_m_s2"] == pytest.approx(
        local_gravity({"gravity_m_s2": 0, "latitude_deg": 52.0})[0])


def test_default_sim_run_measures_the_emulated_noise_density(full_run):
    """``gyrocal calibrate --sim`` at the defaults: the accelerometer block's noise density is
    the emulated accelerometer's true density (manifest ``truth.accelerometer``, m/s²/√Hz)
    within 4σ on every axis."""
    d, _ = full_run
    acc = json.loads((d / "calibration.json").read_text())["accelerometer"]
    truth = json.loads((d / "recording" / "manifest.json").read_text())["truth"]["accelerometer"]
    dens, std = np.array(acc["noise_density"]), np.array(acc["noise_density_std"])
    assert np.all(np.abs(dens - truth["noise_density_m_s2_sqrt_hz"]) < 4 * std)
    assert np.all(std < 0.2 * dens) and acc["noise_tau_s"] == pytest.approx(0.1, abs=0.005)
