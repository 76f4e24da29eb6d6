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
        for k, m in enumerate(([0.1, 0.2, 0.3], [-1.0, 0.0, 2.5])):
            proc.stdin.write(f"{k * 0.005},{m[0]},{m[1]},{m[2]},25.5\n")
            proc.stdin.flush()
            if k == 0:  # the first row fixes the layout, and the header comes with it
                assert proc.stdout.readline() == "t,gx,gy,gz,temp\n"
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


# ------------------------------------------------------------------ the accelerometer's layout
# A v2 calibration with g-sensitivity and an accelerometer, and the model written out by hand
# (hardware_docs/formats.md, Calibration v2, g_sensitivity and accelerometer):
#   f_cal = A_acc (a + b_acc)                      the calibrated specific force, m/s^2
#   f     = f_cal / gravity                        in g (|f| = 1 at rest: the fit's "up")
#   g     = A (m + b + G f)                        the calibrated rate, rad/s
A = np.array([[1.03, 0.0, 0.0], [0.02, 0.96, 0.0], [-0.01, 0.015, 1.01]])
B = np.array([0.012, -0.03, 0.004])
G = np.array([[2e-3, -5e-4, 3e-4], [4e-4, -1.5e-3, 7e-4], [-6e-4, 9e-4, 2.5e-3]])
A_ACC = np.array([[1.02, 0.0, 0.0], [0.01, 0.98, 0.0], [-0.02, 0.005, 0.99]])
B_ACC = np.array([0.07, -0.08, -0.26])
GRAVITY = 9.80665


def accel_cal(accelerometer=True, g_sensitivity=True):
    from gyrocal.calib.accel import AccelCalibration
    from gyrocal.calib.model import Consistency

    acc = AccelCalibration(matrix=A_ACC, bias=B_ACC, covariance=np.eye(9) * 1e-8,
                           gravity=GRAVITY, consistency=Consistency(2.0, 3, 0.57, True),
                           rests=12, iterations=4, converged=True)
    gs = {"matrix": G.tolist(), "matrix_std": np.full((3, 3), 1e-4).tolist(),
          "directions": np.eye(3).tolist()}
    return GyroCalibration(scale=tuple(np.diag(A)), bias=tuple(B), matrix=tuple(map(tuple, A)),
                           frame="gyro-x-xy", method="full-matrix",
                           g_sensitivity=gs if g_sensitivity else None,
                           accelerometer=acc if accelerometer else None)


def eight_columns(n=40, seed=5):
    rng = np.random.default_rng(seed)
    t = np.arange(n) * 0.005
    m = rng.normal(0, 1.0, (n, 3))
    up = rng.normal(size=(n, 3))
    a = 9.8 * up / np.linalg.norm(up, axis=1, keepdims=True) + rng.normal(0, 0.3, (n, 3))
    temp = 25 + rng.normal(0, 0.1, n)
    rows = [",".join(repr(float(x)) for x in (ti, *mi, tc, *ai))
            for ti, mi, tc, ai in zip(t, m, temp, a, strict=True)]
    return t, m, temp, a, rows


def run_stdin(monkeypatch, capsys, cal, text, code=0):
    import io

    monkeypatch.setattr(sys, "stdin", io.StringIO(text))
    assert main(["apply", str(cal), "-"]) == code
    return capsys.readouterr()


def parsed(out):
    lines = out.splitlines()
    return lines[0], np.array([[float(x) for x in r.split(",")] for r in lines[1:]])


@pytest.mark.parametrize("header", [True, False])
def test_gyrocal_s_own_eight_column_rows_through_stdin_get_g_sensitivity(
        monkeypatch, capsys, tmp_path, header):
    cal = tmp_path / "cal.json"
    cal.write_text(accel_cal().to_json())
    t, m, temp, a, rows = eight_columns()
    text = "\n".join((["t,gx,gy,gz,temp,ax,ay,az"] if header else []) + rows) + "\n"
    res = run_stdin(monkeypatch, capsys, cal, text)
    head, out = parsed(res.out)
    assert head == "t,gx,gy,gz,temp,ax,ay,az" and out.shape == (len(rows), 8)
    f_cal = (a + B_ACC) @ A_ACC.T
    expected = (m + B + (f_cal / GRAVITY) @ G.T) @ A.T
    np.testing.assert_allclose(out[:, 1:4], expected, rtol=1e-8, atol=1e-12)
    np.testing.assert_allclose(out[:, 5:8], f_cal, rtol=1e-8, atol=1e-12)
    np.testing.assert_allclose(out[:, 0], t, atol=1e-12)
    np.testing.assert_allclose(out[:, 4], temp, atol=5e-4)  # written to 6 digits
    # leaving G out would be seen: it moves the rates by ~|A G f| ~ 2e-3 rad/s
    assert np.max(np.abs(out[:, 1:4] - (m + B) @ A.T)) > 1e-3
    assert "g-sensitivity is applied" in res.err and "calibrated by the calibration's" in res.err


def test_without_the_accelerometer_columns_g_sensitivity_is_not_applied_and_said(
        monkeypatch, capsys, tmp_path):
    cal = tmp_path / "cal.json"
    cal.write_text(accel_cal().to_json())
    t, m, temp, _, rows = eight_columns(10)
    text = "t,gx,gy,gz,temp\n" + "\n".join(",".join(r.split(",")[:5]) for r in rows) + "\n"
    res = run_stdin(monkeypatch, capsys, cal, text)
    head, out = parsed(res.out)
    assert head == "t,gx,gy,gz,temp"
    np.testing.assert_allclose(out[:, 1:4], (m + B) @ A.T, rtol=1e-8, atol=1e-12)
    assert "g-sensitivity is NOT applied" in res.err and "no accelerometer columns" in res.err


def test_g_sensitivity_without_an_accelerometer_calibration_uses_the_raw_force(
        monkeypatch, capsys, tmp_path):
    cal = tmp_path / "cal.json"
    cal.write_text(accel_cal(accelerometer=False).to_json())
    _, m, _, a, rows = eight_columns(10)
    res = run_stdin(monkeypatch, capsys, cal, "\n".join(rows) + "\n")
    _, out = parsed(res.out)
    np.testing.assert_allclose(out[:, 1:4], (m + B + (a / 9.80665) @ G.T) @ A.T, rtol=1e-8,
                               atol=1e-12)
    np.testing.assert_allclose(out[:, 5:8], a, rtol=1e-8)  # passed through
    assert "ax,ay,az / 9.80665" in res.err and "pass through unchanged" in res.err


def test_an_eight_column_file_and_a_recording_directory(tmp_path, capsys):
    from gyrocal.kit.recording import RecordingWriter

    cal = tmp_path / "cal.json"
    cal.write_text(accel_cal().to_json())
    t, m, temp, a, rows = eight_columns(12)
    expected = (m + B + ((a + B_ACC) @ A_ACC.T / GRAVITY) @ G.T) @ A.T
    src = tmp_path / "imu.csv"
    src.write_text("t,gx,gy,gz,temp,ax,ay,az\n" + "\n".join(rows) + "\n")
    out = tmp_path / "out.csv"
    assert main(["apply", str(cal), str(src), "--out", str(out)]) == 0
    _, got = parsed(out.read_text())
    np.testing.assert_allclose(got[:, 1:4], expected, rtol=1e-8, atol=1e-12)
    # a recording with the accelerometer's columns, through the recording reader
    with RecordingWriter(tmp_path / "rec", sensor={"model": "mpu9250", "odr_hz": 200.0},
                         gimbal={}, protocol={}, accel=True) as w:
        w.append_imu(t, m, temp, a)
        w.finish()
    out2 = tmp_path / "out2.csv"
    assert main(["apply", str(cal), str(tmp_path / "rec"), "--out", str(out2)]) == 0
    head, got = parsed(out2.read_text())
    assert head == "t,gx,gy,gz,temp,ax,ay,az"
    np.testing.assert_allclose(got[:, 1:4], expected, rtol=1e-8, atol=1e-12)
    assert "g-sensitivity is applied" in capsys.readouterr().err


def test_a_row_of_the_other_layout_is_refused(monkeypatch, capsys, tmp_path):
    cal = tmp_path / "cal.json"
    cal.write_text(accel_cal().to_json())
    _, _, _, _, rows = eight_columns(3)
    text = "t,gx,gy,gz,temp,ax,ay,az\n" + rows[0] + "\n0.1,1,2,3,25\n"
    res = run_stdin(monkeypatch, capsys, cal, text, code=2)
    assert "line 3: expected 't,gx,gy,gz,temp,ax,ay,az' (8 comma-separated fields)" in res.err
    res = run_stdin(monkeypatch, capsys, cal, "t,gx,gy,gz,temp,ax\n", code=2)
    assert "unknown header" in res.err and "Traceback" not in res.err


def test_a_stream_whose_time_goes_backwards_is_refused_by_line(monkeypatch, capsys, tmp_path):
    """The Recording v1 reader's rule (kit.recording: non-decreasing time) holds on a stream
    too; equal times (two samples in one FIFO stamp) pass."""
    cal = tmp_path / "cal.json"
    cal.write_text(GyroCalibration(scale=SCALE, bias=BIAS).to_json())
    rows = "t,gx,gy,gz,temp\n1.0,0,0,0,25\n1.0,0,0,0,25\n0.5,0,0,0,25\n"
    res = run_stdin(monkeypatch, capsys, cal, rows, code=2)
    assert "line 4: time goes backwards (0.5 < 1.0)" in res.err and "Traceback" not in res.err
