import json
import shutil

import numpy as np
import pytest

from gyrocal.kit.cli import main


@pytest.fixture(scope="module")
def recording(tmp_path_factory):
    out = tmp_path_factory.mktemp("rec") / "run"
    assert main(["simulate-recording", str(out), "--seed", "11"]) == 0
    return out


def test_estimate_recovers_the_truth_within_its_uncertainty(recording, capsys):
    capsys.readouterr()
    assert main(["estimate", str(recording), "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    truth = json.loads((recording / "manifest.json").read_text())["truth"]
    assert doc["format"] == "gyrocal-calibration" and doc["method"] == "paired-axis"
    for key in ("scale", "bias"):
        err = np.array(doc[key]) - np.array(truth[key])
        assert np.all(np.abs(err) < 4 * np.array(doc[f"{key}_std"]))
    assert doc["consistency"]["ok"] is True
    assert set(doc["axes"]) == {"1", "2", "3"}


@pytest.mark.parametrize("method", ["iterative-ls", "levenberg-marquardt"])
def test_other_methods_and_the_table(recording, capsys, method):
    capsys.readouterr()
    assert main(["estimate", str(recording), "--method", method]) == 0
    out = capsys.readouterr().out
    assert f"gyrocal calibration ({method}" in out
    assert "scale err/σ" in out  # the simulated truth is compared


def test_out_file_is_written_once(recording, tmp_path, capsys):
    cal = tmp_path / "cal.json"
    assert main(["estimate", str(recording), "--out", str(cal)]) == 0
    first = cal.read_text()
    assert json.loads(first)["format"] == "gyrocal-calibration"
    assert main(["estimate", str(recording), "--out", str(cal)]) == 2
    assert "already exists; pass --force" in capsys.readouterr().err
    assert cal.read_text() == first
    assert main(["estimate", str(recording), "--out", str(cal), "--force"]) == 0


def test_missing_and_truncated_recordings_exit_2(recording, tmp_path, capsys):
    assert main(["estimate", str(tmp_path / "nope")]) == 2
    assert "not a directory" in capsys.readouterr().err
    broken = tmp_path / "broken"
    shutil.copytree(recording, broken)
    lines = (broken / "imu.csv").read_text().split("\n")
    (broken / "imu.csv").write_text("\n".join(lines[: len(lines) // 2]) + "\n")
    assert main(["estimate", str(broken)]) == 2
    assert "the recording is truncated" in capsys.readouterr().err
    (broken / "segments.csv").unlink()
    assert main(["estimate", str(broken)]) == 2
    assert "segments.csv is missing" in capsys.readouterr().err


def test_bad_usage_exits_2(capsys, tmp_path):
    assert main(["estimate"]) == 2
    assert main(["estimate", str(tmp_path), "--method", "newton"]) == 2
    assert "invalid choice" in capsys.readouterr().err
    assert main(["estimate", str(tmp_path / "x")]) == 2  # a usage error, before any import
    assert "x is not a directory: give the recording directory" in capsys.readouterr().err
    assert main(["simulate-recording", "x", "--speed", "-1"]) == 2
