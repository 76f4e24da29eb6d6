"""verify's general motion on the emulated jig with a ±2 % cross-axis sensor.

Truth: the emulator's own parameters (manifest ``truth``: scale, bias, misalignment, the servo
axes at home), turned into a calibration by the emulator's documented convention
``m = (misalignment @ g) / scale - bias``, i.e. ``g = misalignment⁻¹ diag(scale) (m + bias)``.
"""

import json

import numpy as np
import pytest

from gyrocal.calib.model import GyroCalibration
from gyrocal.kit.cli import main
from gyrocal.kit.recording import load_recording
from gyrocal.kit.verify import FLAG_RATIO, verify_recording


@pytest.fixture(scope="module")
def general_run(tmp_path_factory):
    """A verify run (protocol and the general-motion sweeps) of a ±2 % cross-axis sensor."""
    d = tmp_path_factory.mktemp("verify")
    diag = GyroCalibration(scale=(1.0, 1.0, 1.0), bias=(0.0, 0.0, 0.0))
    (d / "unit.json").write_text(diag.to_json())
    main(["verify", str(d / "unit.json"), "--sim", "--sim-seed", "5", "--sim-realism", "off",
          "--sim-cross-axis",
          "0.02", "--out", str(d / "run"), "--quiet", "--json"])
    return load_recording(d / "run" / "recording")


def truth_calibrations(rec):
    t = rec.manifest["truth"]
    mis = np.array(t["misalignment"])
    assert np.max(np.abs(mis - np.diag(np.diag(mis)))) == pytest.approx(0.02)
    a = np.linalg.inv(mis) @ np.diag(t["scale"])
    ids = [m["id"] for m in rec.manifest["gimbal"]["motors"]]
    axes = [np.asarray(t["axes"][str(i)]) for i in ids]
    kin = {"chain": ids, "axes": [(u / np.linalg.norm(u)).tolist() for u in axes],
           "reference_angles_rad": [0.0] * len(ids)}
    full = GyroCalibration(scale=tuple(np.diag(a)), bias=tuple(t["bias"]), matrix=a,
                           kinematics=kin, frame="sensor")
    diagonal = GyroCalibration(scale=tuple(t["scale"]), bias=tuple(t["bias"]),
                               scale_std=(1e-5,) * 3, bias_std=(1e-5,) * 3)
    return full, diagonal


def test_the_run_turns_several_servos_at_once(general_run):
    moves = [s for s in general_run.segments if s.kind == "move"]
    assert len(moves) == 6 and len({(s.t_start, s.t_end) for s in moves}) == 2
    assert {s.motor for s in moves} == {1, 2, 3}


def test_the_full_calibration_passes_and_the_diagonal_one_is_flagged(general_run):
    full, diagonal = truth_calibrations(general_run)
    vf = verify_recording(general_run, full)
    assert vf.ok, vf.table()
    assert vf.blocks["several_servos"] >= 4
    assert np.max(vf.rms_full) < 0.05 * np.max(vf.rms_before)
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
