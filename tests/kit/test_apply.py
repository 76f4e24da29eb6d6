"""`gyrocal apply`: calibrated rates of a recording or a stream, against numpy on the raw file."""

import csv
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from gyrocal.calib.model import GyroCalibration
from gyrocal.kit.cli import main

ROOT = Path(__file__).resolve().parents[2]
SCALE, BIAS = (1.02, 0.97, 1.005), (0.011, -0.02, 0.003)


@pytest.fixture(scope="module")
def rec_and_cal(tmp_path_factory):
    d = tmp_path_factory.mktemp("apply")
    assert main(["simulate-recording", str(d / "rec"), "--seed", "4", "--turns", "1"]) == 0
    cal = d / "cal.json"
    cal.write_text(GyroCalibration(scale=SCALE, bias=BIAS).to_json())
    return d / "rec", cal


def _read_csv(path):
    with open(path, newline="") as fh:
        rows = list(csv.reader(fh))
    return rows[0], rows[1:]


def test_a_recording_becomes_calibrated_rates(rec_and_cal, tmp_path, capsys):
    rec, cal = rec_and_cal
    out = tmp_path / "cal.csv"
    assert main(["apply", str(cal), str(rec), "--out", str(out)]) == 0
    header, rows = _read_csv(out)
    raw_header, raw = _read_csv(rec / "imu.csv")
    assert header == raw_header == ["t", "gx", "gy", "gz", "temp"]
    assert len(rows) == len(raw) > 100
    m = np.array([[float(x) for x in r[1:4]] for r in raw])
    g = np.array([[float(x) for x in r[1:4]] for r in rows])
    np.testing.assert_allclose(g, np.array(SCALE) * (m + np.array(BIAS)), rtol=1e-8, atol=1e-12)
    np.testing.assert_allclose([float(r[0]) for r in rows], [float(r[0]) for r in raw], atol=1e-9)


def test_an_existing_output_is_not_replaced_without_force(rec_and_cal, tmp_path, capsys):
    rec, cal = rec_and_cal
    out = tmp_path / "cal.csv"
    out.write_text("mine\n")
    assert main(["apply", str(cal), str(rec), "--out", str(out)]) == 2
    assert "already exists; pass --force" in capsys.readouterr().err
    assert out.read_text() == "mine\n"
    assert main(["apply", str(cal), str(rec), "--out", str(out), "--force"]) == 0
    assert out.read_text().startswith("t,gx,gy,gz,temp\n")
    assert [p.name for p in tmp_path.iterdir()] == ["cal.csv"]  # no temporary left behind


def test_a_stream_is_calibrated_row_by_row_as_it_arrives(rec_and_cal):
    # Write one row, read its calibrated row back before writing the next: a real pipe.
    _, cal = rec_and_cal
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    proc = subprocess.Popen([sys.executable, "-m", "gyrocal.kit", "apply", str(cal), "-"],
                            stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True, env=env)
    try:
        assert proc.stdout.readline() == "t,gx,gy,gz,temp\n"
        for k, m in enumerate(([0.1, 0.2, 0.3], [-1.0, 0.0, 2.5])):
            proc.stdin.write(f"{k * 0.005},{m[0]},{m[1]},{m[2]},25.5\n")
            proc.stdin.flush()
            cells = proc.stdout.readline().strip().split(",")
            np.testing.assert_allclose([float(c) for c in cells[1:4]],
                                       np.array(SCALE) * (np.array(m) + BIAS), rtol=1e-8)
            assert cells[4] == "25.5"
        proc.stdin.close()
        assert proc.wait(timeout=30) == 0
    finally:
        if proc.poll() is None:
            proc.kill()


def test_a_bad_row_names_its_line(rec_and_cal, monkeypatch, capsys):
    import io

    _, cal = rec_and_cal
    monkeypatch.setattr(sys, "stdin", io.StringIO("t,gx,gy,gz,temp\n0,1,2,3,\n0.1,x,2,3,\n"))
    assert main(["apply", str(cal), "-"]) == 2
    err = capsys.readouterr().err
    assert "line 3: not numbers: '0.1,x,2,3,'" in err and "Traceback" not in err


def test_a_temperature_model_is_applied_at_each_rows_temperature():
    # The hook for a calibration that carries a temperature model: its own apply gets the
    # temperatures; rows without one are refused rather than calibrated at a made-up value.
    from gyrocal.kit.apply import calibrated
    from gyrocal.kit.errors import InputError

    class WithTemperature:
        temperature_model = {"reference_c": 25.0}

        def apply(self, m, temperature_c):
            return np.asarray(m) + 1e-3 * (np.asarray(temperature_c)[:, None] - 25.0)

    m = np.zeros((2, 3))
    np.testing.assert_allclose(calibrated(WithTemperature(), m, np.array([25.0, 35.0])),
                               [[0, 0, 0], [0.01, 0.01, 0.01]])
    with pytest.raises(InputError, match="no temperature"):
        calibrated(WithTemperature(), m, np.array([25.0, np.nan]))
