"""Reliability: --force replaces a run as a whole, outputs that cannot be written give a clear
exit 2, implausible calibrations are refused (exit 6), config numbers are bounded."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from gyrocal.kit.cli import main
from tests.kit.conftest import LOOP_50_HZ
from tests.kit.contract_recording import write_recording


def calibrate(out, *extra):
    # the paper's sensor: with every realism effect on the χ² verdict fails (exit 3)
    return main(["calibrate", "--sim", "--sim-realism", "off", "--out", str(out), "--quiet",
                 *extra])


@pytest.fixture(scope="module")
def contract(tmp_path_factory):
    """Recordings from the independent generator: right units, gyro in °/s, encoders in °."""
    d = tmp_path_factory.mktemp("contract")
    deg = 180 / np.pi
    return {"ok": write_recording(d / "ok"), "dps": write_recording(d / "dps", gyro_unit=deg),
            "deg": write_recording(d / "deg", angle_unit=deg)}


# ---- --force: the whole run or nothing -----------------------------------------------------
def test_a_failed_forced_rerun_leaves_the_old_run_whole(tmp_path, capsys, full_run):
    # the old run: a copy of the shared `gyrocal calibrate --sim` run with its report
    # (tests/kit/conftest.py). What is checked is how a run directory is replaced, not the
    # estimate: the reruns' planned diagonal protocol in 18 s of jig time, their loop at 50 Hz
    # (a quarter of the emulated bus traffic), writes the same set of files as the full one
    short = tmp_path / "short.toml"
    short.write_text('[protocol]\nname = "auto"\ntime_budget_s = 18.0\n' + LOOP_50_HZ)
    out = tmp_path / "run1"
    assert full_run[1] == 0
    shutil.copytree(full_run[0], out)
    before = {p.relative_to(out): p.read_bytes() for p in out.rglob("*") if p.is_file()}
    assert {"calibration.json", "recording/imu.csv", "report.html"} <= {str(p) for p in before}
    capsys.readouterr()
    # servo 1 falls silent 2 s into the new recording: the rerun fails with exit 4
    assert calibrate(out, "--sim-seed", "5", "--force", "--sim-fault", "silent:1:2",
                     "--config", str(short)) == 4
    err = capsys.readouterr().err
    after = {p.relative_to(out): p.read_bytes() for p in out.rglob("*") if p.is_file()}
    assert after == before  # the old calibration with its own recording, untouched
    assert f"the previous run in {out} is untouched" in err
    partial = [p for p in tmp_path.iterdir() if p.name.startswith(".run1.new-")]
    assert len(partial) == 1 and not (partial[0] / "calibration.json").exists()
    manifest = json.loads((partial[0] / "recording" / "manifest.json").read_text())
    assert manifest["complete"] is False
    # a forced rerun that succeeds replaces the run as a whole: the new run has no report
    # (--no-report), so a report left of the old run would show a merge
    assert calibrate(out, "--sim-seed", "6", "--force", "--config", str(short),
                     "--no-report") == 0
    cal = json.loads((out / "calibration.json").read_text())
    assert cal["scale"] != json.loads(before[Path("calibration.json")])["scale"]
    assert not (out / "report.html").exists() and not (out / "plots").exists()
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".run1.old-")]


@pytest.mark.parametrize("argv", [
    ["init", "{dir}", "--force"],
    ["estimate", "{ok}", "--out", "{dir}", "--force"],
    ["export", "{cal}", "--format", "json", "--out", "{dir}", "--force"],
    ["export", "{cal}", "--format", "json", "--out", "/proc/version", "--force"],
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
    error = [line for line in err.splitlines() if line.startswith("gyrocal: error: ")]
    assert len(error) == 1, err  # notes (e.g. on an uncalibrated cross-axis) may come before
    assert error[0].startswith("gyrocal: error: cannot ") or "a file, not a directory" in err \
        or "is a file" in err
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


# ---- config: every number finite and in range, any file a clear exit 2 ---------------------
BAD_CONFIGS = [
    (b"[protocol]\nrest_s = inf\n", "protocol.rest_s must be a finite number"),
    (b"[protocol]\nrest_s = 1e9\n", "protocol.rest_s must be in 0.1..600"),
    (b"[protocol]\nspeed_dps = 1e-6\n", "protocol.speed_dps must be in 1..2000"),
    (b"[protocol]\nspeed_dps = nan\n", "protocol.speed_dps must be a finite number"),
    (b"[protocol]\nturns = -1\n", "protocol.turns must be in 1..256"),
    (b"[protocol]\nturns = " + b"9" * 401 + b"\n", "an integer of 401 digits"),
    (b"[protocol]\nturns = " + b"9" * 5000 + b"\n", "a value cannot be read"),
    (b"[gimbal]\nids = " + b"[" * 3000 + b"]" * 3000 + b"\n", "nested too deeply"),
    (b'[gimbal]\nport = "\xff\xfe"\n', "is not UTF-8 text"),
    (b"[imu]\nodr_hz = -200.0\n", "imu.odr_hz must be in 1..8000"),
    (b"[gimbal]\nmax_turns = 20\n[protocol]\nturns = 10\nspeed_dps = 30\n",
     "more than protocol.time_budget_s"),
]


@pytest.mark.parametrize(("text", "message"), BAD_CONFIGS)
def test_bad_config_values_exit_2_naming_the_problem(tmp_path, capsys, text, message):
    cfg = tmp_path / "gyrocal.toml"
    cfg.write_bytes(text)
    assert calibrate(tmp_path / "out", "--config", str(cfg)) == 2
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err and len(err) < 600


def test_odr_inf_on_the_command_line_exits_2(tmp_path, capsys):
    assert calibrate(tmp_path / "out", "--odr", "inf") == 2
    assert "imu.odr_hz must be a finite number" in capsys.readouterr().err


def test_signed_axes_mean_the_same_to_the_validator_and_the_jig(tmp_path):
    from gyrocal.kit.config import load_config

    # The names reach the emulated gimbal (its joints turn about -x, y, -z) and the manifest,
    # against which the fit checks each servo's axis (exit 6, "implausible", for a servo whose
    # fitted axis is another signed axis). Any protocol that turns each servo checks that, so
    # the planner's diagonal one in 18 s of jig time does, without a report, and at any loop
    # rate: 50 Hz here (LOOP_50_HZ; exit 0, each fitted axis the configured signed one).
    cfg = tmp_path / "gyrocal.toml"
    cfg.write_text('[gimbal]\naxes = ["-x", "+y", "-z"]\nsample_hz = 50\n'
                   '[protocol]\nname = "auto"\ntime_budget_s = 18.0\n')
    assert load_config(cfg)["gimbal"]["axes"] == ["-x", "y", "-z"]
    out = tmp_path / "out"
    assert calibrate(out, "--config", str(cfg), "--no-report") in (0, 3)
    manifest = json.loads((out / "recording" / "manifest.json").read_text())
    assert [m["axis"] for m in manifest["gimbal"]["motors"]] == ["-x", "y", "-z"]
    assert (out / "calibration.json").exists()
