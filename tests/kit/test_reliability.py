"""Reliability: --force replaces a run as a whole, outputs that cannot be written give a clear
exit 2, implausible calibrations are refused (exit 6), config numbers are bounded."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from gyrocal.kit.cli import main
from tests.kit.contract_recording import write_recording


def calibrate(out, *extra):
    return main(["calibrate", "--sim", "--out", str(out), "--quiet", *extra])


@pytest.fixture(scope="module")
def contract(tmp_path_factory):
    """Recordings from the independent generator: right units, gyro in °/s, encoders in °."""
    d = tmp_path_factory.mktemp("contract")
    deg = 180 / np.pi
    return {"ok": write_recording(d / "ok"), "dps": write_recording(d / "dps", gyro_unit=deg),
            "deg": write_recording(d / "deg", angle_unit=deg)}


# ---- --force: the whole run or nothing -----------------------------------------------------
def test_a_failed_forced_rerun_leaves_the_old_run_whole(tmp_path, capsys):
    out = tmp_path / "run1"
    assert calibrate(out, "--sim-seed", "4") == 0
    before = {p.relative_to(out): p.read_bytes() for p in out.rglob("*") if p.is_file()}
    capsys.readouterr()
    # servo 1 falls silent 2 s into the new recording: the rerun fails with exit 4
    assert calibrate(out, "--sim-seed", "5", "--force", "--sim-fault", "silent:1:2") == 4
    err = capsys.readouterr().err
    after = {p.relative_to(out): p.read_bytes() for p in out.rglob("*") if p.is_file()}
    assert after == before  # the old calibration with its own recording, untouched
    assert f"the previous run in {out} is untouched" in err
    partial = [p for p in tmp_path.iterdir() if p.name.startswith(".run1.new-")]
    assert len(partial) == 1 and not (partial[0] / "calibration.json").exists()
    manifest = json.loads((partial[0] / "recording" / "manifest.json").read_text())
    assert manifest["complete"] is False
    # a forced rerun that succeeds replaces the run as a whole
    assert calibrate(out, "--sim-seed", "6", "--force") == 0
    cal = json.loads((out / "calibration.json").read_text())
    assert cal["scale"] != json.loads(before[Path("calibration.json")])["scale"]
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".run1.old-")]


@pytest.mark.parametrize("argv", [
    ["init", "{dir}", "--force"],
    ["estimate", "{ok}", "--out", "{dir}", "--force"],
    ["export", "{cal}", "--out", "{dir}", "--force"],
    ["export", "{cal}", "--out", "/proc/version", "--force"],
    ["calibrate", "--sim", "--out", "{file}"],
])
def test_outputs_that_cannot_be_written_exit_2_without_traceback(contract, tmp_path, capsys,
                                                                 argv):
    (tmp_path / "adir").mkdir()
    (tmp_path / "afile").write_text("x")
    cal = tmp_path / "cal.json"
    assert main(["estimate", str(contract["ok"]), "--out", str(cal)]) == 0
    capsys.readouterr()
    subst = {"dir": str(tmp_path / "adir"), "ok": str(contract["ok"]), "cal": str(cal),
             "file": str(tmp_path / "afile")}
    assert main([a.format(**subst) for a in argv]) == 2
    err = capsys.readouterr().err
    assert err.startswith("gyrocal: error: cannot ") or "not a directory" in err
    assert "Traceback" not in err
    assert (tmp_path / "adir").is_dir() and not any((tmp_path / "adir").iterdir())


# ---- plausibility (independent generator) ---------------------------------------------------
def test_right_units_pass_and_recover_the_generator_truth(contract, capsys):
    assert main(["estimate", str(contract["ok"]), "--json"]) == 0
    cal = json.loads(capsys.readouterr().out)
    np.testing.assert_allclose(cal["scale"], [1.01, 0.99, 1.02], atol=1e-3)
    np.testing.assert_allclose(cal["bias"], [0.01, -0.02, 0.005], atol=1e-3)


@pytest.mark.parametrize(("kind", "cause"), [("dps", "in °/s where Recording v1 wants rad/s"),
                                             ("deg", "in degrees where Recording v1 wants")])
def test_unit_mistakes_are_refused_with_their_cause(contract, tmp_path, capsys, kind, cause):
    out = tmp_path / "cal.json"
    assert main(["estimate", str(contract[kind]), "--out", str(out)]) == 6
    err = capsys.readouterr().err
    assert cause in err and "--allow-implausible" in err
    assert not out.exists()
    assert main(["estimate", str(contract[kind]), "--out", str(out),
                 "--allow-implausible"]) in (0, 3)
    assert out.exists() and cause in capsys.readouterr().err
