import json

import numpy as np
import pytest

from gyrocal.kit.cli import main


def test_normal_preset_json_has_every_method_and_honest_coverage(capsys):
    code = main(["study", "--preset", "normal", "--sensors", "6", "--reps", "50",
                 "--noise", "0.035", "--workers", "1", "--json"])
    assert code == 0
    doc = json.loads(capsys.readouterr().out)
    level = doc["levels"]["0.035"]
    assert level["runs"] == 300
    methods = level["methods"]
    assert set(methods) == {"iterative-ls", "levenberg-marquardt", "paired-axis"}
    # Algorithm 1 and LM: the same answer, so the same statistics.
    for p in ("k_x", "b_z"):
        assert methods["iterative-ls"][p]["rms"] == pytest.approx(
            methods["levenberg-marquardt"][p]["rms"], rel=1e-6)
    assert methods["paired-axis"]["b_x"]["rms"] < 0.65 * methods["iterative-ls"]["b_x"]["rms"]
    cov = np.array(level["paired_axis_coverage_95"])
    assert np.all((cov > 0.90) & (cov < 0.99))


def test_text_table_and_plots(tmp_path, capsys):
    code = main(["study", "--preset", "extreme", "--sensors", "3", "--reps", "20",
                 "--noise", "0.2", "--workers", "2", "--no-lm", "--plot", str(tmp_path)])
    assert code == 0
    out = capsys.readouterr().out
    assert "whiskers" in out and "paired-axis" in out and "levenberg" not in out.split("\n")[2]
    png = tmp_path / "study-extreme-noise-0.2.png"
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    # The plot is not replaced without --force, and the refusal comes before the Monte Carlo.
    before = png.read_bytes()
    again = ["study", "--preset", "extreme", "--sensors", "3", "--reps", "20", "--noise", "0.2",
             "--workers", "1", "--no-lm", "--plot", str(tmp_path)]
    assert main(again) == 2
    out, err = capsys.readouterr()
    assert "already exists" in err and "--force" in err and out == ""
    assert png.read_bytes() == before
    assert main([*again, "--force"]) == 0


def test_convergence_and_demo_presets(capsys):
    assert main(["study", "--preset", "convergence", "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert [c["converged"] for c in doc["cases"]] == [True, True, True]
    first = doc["cases"][0]
    assert first["actual"] == [1.9074, 1.9529, 1.5635, 0.0827, 0.0265, -0.0805]
    np.testing.assert_allclose(first["iterates"][-1], first["actual"], atol=5e-3)
    assert main(["study", "--preset", "demo", "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    before = np.array(doc["rms_before"])
    for after in doc["rms_after"].values():
        assert np.all(np.array(after) < before)


def test_speed_sweep_mse_falls_with_speed(tmp_path, capsys):
    assert main(["study", "--preset", "speed-sweep", "--sensors", "4", "--reps", "5",
                 "--noise", "0.2", "--no-lm", "--workers", "2", "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)["levels"]["0.2"]
    k_mse = {float(s): np.mean(v["iterative-ls"][:3]) for s, v in doc.items()}
    assert k_mse[0.3] > 5 * k_mse[3.0]  # scale observability grows with speed (paper Fig. 5)


def test_bad_arguments_exit_2(capsys):
    assert main(["study", "--preset", "nope"]) == 2
    assert main(["study", "--reps", "0"]) == 2
    assert "--reps must be at least 1" in capsys.readouterr().err
