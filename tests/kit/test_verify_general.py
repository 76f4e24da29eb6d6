"""verify's general motion on the emulated jig with a ±2 % cross-axis sensor and every realism
effect (the default ``--sim`` sensor).

Truth: the emulator's own parameters (manifest ``truth``: scale, bias, misalignment, the servo
axes at home, the g-sensitivity), turned into a calibration by the emulator's documented
convention ``m = (misalignment @ g) / scale - bias + G_s f``, i.e.
``g = misalignment⁻¹ diag(scale) (m + bias − G_s f)``.
"""

import json

import numpy as np
import pytest

from gyrocal.calib.model import GyroCalibration
from gyrocal.kit.cli import main
from gyrocal.kit.recording import load_recording
from gyrocal.kit.verify import FLAG_RATIO, verify_recording


@pytest.fixture(scope="module")
def general_run(verify_run):
    """The shared verify run (a short protocol and the general-motion sweeps) of the default
    emulated sensor, ±2 % cross-axis (tests/kit/conftest.py)."""
    return load_recording(verify_run[0] / "run" / "recording")


def test_the_default_full_calibration_passes_and_its_diagonal_part_fails(full_run, verify_run,
                                                                         tmp_path, capsys):
    # `gyrocal calibrate --sim` at the defaults, verified on the same sensor: it passes (exit 0);
    # the paper's diagonal model fitted to the same recording (Calibration v1) fails (exit 3).
    capsys.readouterr()
    assert verify_run[1] == 0, capsys.readouterr().err
    diag = tmp_path / "diagonal.json"
    # (the diagonal model does not hold on the posed turns of a ±2 % sensor: the fit says so,
    # exit 3, and still writes its calibration)
    assert main(["estimate", str(full_run[0] / "recording"), "--method", "paired-axis",
                 "--out", str(diag)]) == 3
    assert "NOT consistent" in capsys.readouterr().out
    rec = str(verify_run[0] / "run" / "recording")
    capsys.readouterr()
    assert main(["verify", str(diag), "--recording", rec, "--json"]) == 3
    out, err = capsys.readouterr()
    v = json.loads(out)
    assert not v["ok"] and np.all(np.isnan(np.array(v["rms_full"], dtype=float)))
    assert "worse than its own uncertainty predicts" in err
    assert main(["verify", str(full_run[0] / "calibration.json"), "--recording", rec,
                 "--json"]) == 0
    vf = json.loads(capsys.readouterr().out)
    assert vf["ok"] and vf["blocks"]["several_servos"] >= 4


def truth_calibrations(rec):
    t = rec.manifest["truth"]
    mis = np.array(t["misalignment"])
    assert np.max(np.abs(mis - np.diag(np.diag(mis)))) == pytest.approx(0.02)
    a = np.linalg.inv(mis) @ np.diag(t["scale"])
    ids = [m["id"] for m in rec.manifest["gimbal"]["motors"]]
    axes = [np.asarray(t["axes"][str(i)]) for i in ids]
    kin = {"chain": ids, "axes": [(u / np.linalg.norm(u)).tolist() for u in axes],
           "reference_angles_rad": [0.0] * len(ids)}
    # The emulator adds G_s f to the reading (m = C g - bias + G_s f), so the model's G is -G_s.
    line = t.get("realism", {}).get("g-sensitivity", "off")
    gs = None if line == "off" else {
        "matrix": (-np.array(line["matrix_rad_s_per_g"])).tolist(),
        "matrix_std": [[0.0] * 3] * 3, "directions": np.eye(3).tolist()}
    full = GyroCalibration(scale=tuple(np.diag(a)), bias=tuple(t["bias"]), matrix=a,
                           kinematics=kin, frame="sensor", g_sensitivity=gs)
    diagonal = GyroCalibration(scale=tuple(t["scale"]), bias=tuple(t["bias"]),
                               scale_std=(1e-5,) * 3, bias_std=(1e-5,) * 3)
    return full, diagonal


def test_the_run_turns_several_servos_at_once_and_tilts_gravity_at_rest(general_run):
    moves = [s for s in general_run.segments if s.kind == "move"]
    spans = [(s.t_start, s.t_end) for s in moves]
    sweeps = [s for s in moves if spans.count((s.t_start, s.t_end)) == 3]
    assert len(sweeps) == 6 and len({(s.t_start, s.t_end) for s in sweeps}) == 2
    assert {s.motor for s in sweeps} == {1, 2, 3}
    # then the gravity pairs: servos 1 and 2 (axes x, y: horizontal at home) a quarter turn
    # each way and back, a rest after each move
    single = [s for s in moves if spans.count((s.t_start, s.t_end)) == 1]
    assert [s.motor for s in single] == [1] * 4 + [2] * 4
    assert [s.direction for s in single] == [1, -1, -1, 1] * 2
    after = [min((r for r in general_run.segments if r.kind == "rest" and r.t_start >= s.t_end),
                 key=lambda r: r.t_start) for s in single]
    assert all(r.t_end - r.t_start >= 1.9 for r in after)


def test_the_full_calibration_passes_and_the_diagonal_one_is_flagged(general_run):
    full, diagonal = truth_calibrations(general_run)
    vf = verify_recording(general_run, full)
    assert vf.ok, vf.table()
    assert vf.blocks["several_servos"] >= 4
    # Uncalibrated, every axis would fail verify (its raw error, the datasheet-sized scale and
    # bias of the default sensor, is more than FLAG_RATIO times the prediction); calibrated, it
    # passes. (On the paper's ±20 % sensor, the default before issue 31, this read
    # rms_full < 0.05 rms_before, a ratio that scaled with the sensor's exaggerated errors.)
    assert np.all(vf.rms_before > FLAG_RATIO * vf.rms_predicted), vf.table()
    # Dropping the cross-axis terms of the very same matrix shows in general motion.
    assert np.max(vf.rms_diagonal) > 3 * np.max(vf.rms_full)
    vd = verify_recording(general_run, diagonal)
    assert not vd.ok and np.max(vd.ratio) > FLAG_RATIO, vd.table()
    assert np.all(np.isnan(vd.rms_full))


def test_the_table_explains_its_figures_and_json_matches_columns(general_run):
    full, _ = truth_calibrations(general_run)
    v = verify_recording(general_run, full)
    text = v.table()
    head = text.split("\n")[1].split()
    assert head == ["axis", "before", "diagonal", "full", "predicted", "at", "rest", "one",
                    "servo", "several", "servos"]
    assert "acceleration ramps are left out" in text
    d = v.to_dict()
    for col in ("rms_before", "rms_diagonal", "rms_full", "rms_predicted", "rms_rest",
                "rms_one_servo", "rms_several_servos"):
        assert len(d[col]) == 3
    assert "rms_after_turning" not in d
    # The overall figure is the RMS of its three kinds, weighted by their blocks.
    n = np.array([v.blocks[k] for k in ("rest", "one_servo", "several_servos")])
    parts = np.array([v.rms_by_kind[k] for k in ("rest", "one_servo", "several_servos")])
    parts = np.nan_to_num(parts)
    np.testing.assert_allclose(np.sqrt((n[:, None] * parts**2).sum(0) / n.sum()), v.rms_full,
                               rtol=1e-12)
    json.dumps(d)


def test_g_sensitivity_is_applied_and_a_fit_without_it_is_caught(full_run, general_run):
    # The shared runs are the realistic default sensor (g-sensitivity up to 0.1 °/s/g per term).
    # The calibration of `gyrocal calibrate --sim` (with G) passes; the full model fitted to the
    # same recording without G fails, and so does the G calibration applied without its G f.
    from gyrocal.calib.estimators import estimate
    from gyrocal.kit.pipeline import extract_recording

    assert general_run.manifest["truth"]["realism"]["g-sensitivity"] != "off"
    cal = GyroCalibration.from_json((full_run[0] / "calibration.json").read_text())
    assert cal.g_sensitivity is not None
    v = verify_recording(general_run, cal)
    assert v.g_sensitivity == "applied" and v.ok, v.table()
    ex = extract_recording(load_recording(full_run[0] / "recording"))
    fit = estimate(ex.observations, "full-matrix", g_sensitivity=False)
    assert fit.success and fit.g_sensitivity is None
    no_g = fit.to_calibration(sensor=cal.sensor)
    vn = verify_recording(general_run, no_g)
    # Caught by the gravity pairs (the blocks' RMS is dominated by the encoder reference's
    # scatter while turning, and a slowly wandering bias at rest, both larger than G f).
    assert vn.gravity_pairs == 4 and not vn.ok, vn.table()
    assert np.max(vn.gravity_ratio) > FLAG_RATIO >= np.max(v.gravity_ratio), vn.table()
    # The same calibration with its G dropped (its bias is then the zero-g bias) fails too.
    dropped = GyroCalibration.from_dict({**cal.to_dict(), "g_sensitivity": None})
    vd = verify_recording(general_run, dropped)
    assert not vd.ok and "g-sensitivity is not modelled" in vd.verdict(), vd.table()
    # G's uncertainty is in the prediction: without its σ the prediction is smaller.
    zero_std = {**cal.to_dict()["g_sensitivity"], "matrix_std": [[0.0] * 3] * 3}
    v0 = verify_recording(general_run, GyroCalibration.from_dict(
        {**cal.to_dict(), "g_sensitivity": zero_std}))
    assert np.all(v0.rms_predicted < v.rms_predicted)
    np.testing.assert_allclose(v0.rms_full, v.rms_full, rtol=1e-12)


def test_gravity_from_the_encoders_matches_the_emulated_jig(general_run):
    # Independent truth: the emulated jig's home gravity (R_homeᵀ e_z), recovered from the
    # manifest's g-sensitivity truth (its G and the bias shift G γ_home it puts in the home
    # pose), is what gyrocal.kit.gravity says at the recording's start with the truth's axes.
    from gyrocal.kit.gravity import specific_force

    full, _ = truth_calibrations(general_run)
    g = {"matrix": [[0.0] * 3] * 3, "matrix_std": [[0.0] * 3] * 3, "directions": []}
    cal = GyroCalibration.from_dict({**full.to_dict(), "g_sensitivity": g})
    t0 = general_run.imu_t[0]
    f = specific_force(general_run, cal, np.array([t0]))[0]
    line = general_run.manifest["truth"]["realism"]["g-sensitivity"]
    home = np.linalg.solve(np.array(line["matrix_rad_s_per_g"]),
                           np.array(line["home_bias_shift_rad_s"]))
    assert abs(np.linalg.norm(home) - 1) < 1e-6
    np.testing.assert_allclose(f, home, atol=0.01)


def test_a_passing_verify_says_so_and_long_blocks_say_what_they_check(full_run, verify_run,
                                                                      capsys):
    # issue 31: a passing verify printed the table and no verdict; `--block 1` said nothing
    # when no turning block was left (running.md, Verification).
    cal = str(full_run[0] / "calibration.json")
    rec = str(verify_run[0] / "run" / "recording")
    capsys.readouterr()
    assert main(["verify", cal, "--recording", rec]) == 0
    out, err = capsys.readouterr()
    assert "\npassed: the calibration holds for this sensor and jig; worst axis " in out
    assert "times what the calibration's uncertainty predicts" in out
    assert "no 0.5 s block" not in err
    v = verify_recording(load_recording(rec), GyroCalibration.from_json(open(cal).read()), 1.0)
    assert v.blocks["several_servos"] == 0  # the sweeps turn steadily for less than 1 s
    assert main(["verify", cal, "--recording", rec, "--block", "1"]) == 0
    err = capsys.readouterr().err
    turning = v.blocks["one_servo"] + v.blocks["several_servos"]
    assert ("no 1 s block lies inside a steady turn" in err) == (turning == 0)
