"""The outside audit's reproducers (issue 27), one test per cause: ``--force`` never deletes what
gyrocal did not write, ``verify`` takes the estimator's reference and reads through the checked
readers, unit and axis mistakes are refused on every protocol, no user string reaches a
formatter that interprets it, inputs are bounded, and a damaged history row is skipped by name.

Each is cheap: the library function directly, the independent recording generator
(tests/kit/contract_recording.py), or a command that refuses before the jig moves.
"""

from __future__ import annotations

import io
import json
import os
import sqlite3
import stat
import sys

import numpy as np
import pytest

from bench.attacks import jitter_encoder_times
from gyrocal.kit.cli import main
from gyrocal.kit.errors import InputError
from tests.kit.contract_recording import write_recording

DEG = 180 / np.pi


def _error(err: str) -> str:
    lines = [x for x in err.splitlines() if x.startswith("gyrocal: error: ")]
    assert len(lines) == 1 and "Traceback" not in err, err
    return lines[0]


def _gyrocal_run(d, *, extra=()):
    """A directory as ``gyrocal calibrate`` leaves it (the files that mark a run)."""
    (d / "recording").mkdir(parents=True)
    (d / "recording" / "manifest.json").write_text(json.dumps(
        {"format": "gyrocal-recording", "version": 1, "complete": True}))
    (d / "calibration.json").write_text(json.dumps({"format": "gyrocal-calibration"}))
    (d / "report.html").write_text("<html></html>")
    for name in extra:
        (d / name).write_text("mine")
    return d


# ---- 1. --force replaces only a gyrocal run ----------------------------------------------------
def test_force_refuses_a_directory_of_user_files_before_the_jig_moves(tmp_path, capsys):
    d = tmp_path / "d"
    d.mkdir()
    (d / "thesis.tex").write_text("work")
    assert main(["calibrate", "--sim", "--no-report", "--quiet", "--out", str(d),
                 "--force"]) == 2
    err = _error(capsys.readouterr().err)
    assert "does not hold a gyrocal run" in err and str(d) in err
    assert (d / "thesis.tex").read_text() == "work"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["d"]  # no staging directory either


def test_force_refuses_a_run_with_user_files_beside_it_by_name(tmp_path):
    from gyrocal.kit.fileio import check_replaceable_run

    run = _gyrocal_run(tmp_path / "run", extra=["notes.txt"])
    with pytest.raises(InputError, match="holds notes.txt, which gyrocal did not write"):
        check_replaceable_run(run)
    (run / "notes.txt").unlink()
    (run / "plots").mkdir()
    (run / ".calibration.json.x.tmp").write_text("")
    check_replaceable_run(run)  # a whole gyrocal run (with a staging leftover) may be replaced
    (run / ".git").mkdir()
    with pytest.raises(InputError, match=r"holds \.git, which gyrocal did not write"):
        check_replaceable_run(run)
    (run / ".git").rmdir()
    # a plate run: per-sensor run directories and the summary
    plate = tmp_path / "plate"
    _gyrocal_run(plate / "imu0")
    (plate / "summary.json").write_text("{}")
    check_replaceable_run(plate)
    # a calibration.json that is not gyrocal's does not make a run
    fake = tmp_path / "fake"
    fake.mkdir()
    (fake / "calibration.json").write_text('{"format": "something-else"}')
    with pytest.raises(InputError, match="does not hold a gyrocal run"):
        check_replaceable_run(fake)


@pytest.mark.parametrize("kind", ["dot", "parent", "symlink"])
def test_force_refuses_odd_outputs_before_the_jig_moves(tmp_path, monkeypatch, capsys, kind):
    run = _gyrocal_run(tmp_path / "run")
    if kind == "symlink":
        (tmp_path / "link").symlink_to(run)
        monkeypatch.chdir(tmp_path)
        out, says = "link", "is a symbolic link"
    else:
        inner = run / "recording"
        monkeypatch.chdir(run if kind == "dot" else inner)
        out, says = (".", "current directory") if kind == "dot" else ("..", "current directory")
    before = sorted(p.relative_to(tmp_path) for p in tmp_path.rglob("*"))
    assert main(["calibrate", "--sim", "--no-report", "--quiet", "--out", out, "--force"]) == 2
    assert says in _error(capsys.readouterr().err)
    assert sorted(p.relative_to(tmp_path) for p in tmp_path.rglob("*")) == before


def test_a_replaced_run_keeps_the_users_permissions(tmp_path):
    from gyrocal.kit.fileio import replace_dir, staging_dir

    run = _gyrocal_run(tmp_path / "run")
    os.chmod(run, 0o750)
    new = staging_dir(run)
    assert stat.S_IMODE(new.stat().st_mode) == 0o700  # mkdtemp's
    (new / "calibration.json").write_text("{}")
    replace_dir(new, run)
    assert stat.S_IMODE(run.stat().st_mode) == 0o750
    assert (run / "calibration.json").read_text() == "{}"


# ---- 2. verify: the estimator's reference, the checked reader ---------------------------------
@pytest.fixture(scope="module")
def synthetic(tmp_path_factory):
    """The kit's own synthetic recording (gyrocal simulate-recording, jittered encoder stamps)
    and its calibration (gyrocal estimate)."""
    d = tmp_path_factory.mktemp("synthetic")
    assert main(["simulate-recording", str(d / "rec"), "--seed", "0"]) == 0
    assert main(["estimate", str(d / "rec"), "--out", str(d / "cal.json")]) in (0, 3)
    return d


def test_verify_passes_the_kits_own_correct_calibration(synthetic, capsys):
    # np.gradient over jittered stamps made this exit 3, "24.8 × worse than predicted"
    capsys.readouterr()
    assert main(["verify", str(synthetic / "cal.json"), "--recording",
                 str(synthetic / "rec"), "--json"]) == 0
    v = json.loads(capsys.readouterr().out)
    before, after = np.array(v["rms_before"]), np.array(v["rms_diagonal"])
    assert np.all(after < before / 5)
    assert np.all(after <= np.array(v["rms_predicted"]))


@pytest.fixture(scope="module")
def jittered(tmp_path_factory):
    """A recording of the independent generator (no speed ripple: a turn's steady rate is its
    commanded speed, π rad/s) whose encoder stamps are jittered by ±3 ms (seeded), as a host's
    read times are; and the generator's true calibration (no estimator involved)."""
    from gyrocal.calib.model import GyroCalibration

    d = tmp_path_factory.mktemp("jittered")
    rec = write_recording(d / "rec")
    jitter_encoder_times(rec, seed=27, half_width_s=0.003)
    truth = GyroCalibration(scale=(1.01, 0.99, 1.02), bias=(0.01, -0.02, 0.005),
                            scale_std=(1e-4,) * 3, bias_std=(1e-4,) * 3,
                            sensor={"model": "mpu9250"})
    (d / "truth.json").write_text(truth.to_json())
    return d


def test_verify_reference_is_the_true_rate_under_jittered_stamps(jittered, capsys):
    from gyrocal.calib.model import GyroCalibration
    from gyrocal.kit.recording import load_recording
    from gyrocal.kit.verify import _block_rows, _encoders, _kinematics, _turned

    rec = load_recording(jittered / "rec")
    cal = GyroCalibration.from_json((jittered / "truth.json").read_text())
    kin, _ = _kinematics(rec, cal)
    te, ang = _encoders(rec, list(kin["chain"]))
    rows = _block_rows(rec, rec.imu_t, rec.imu_rate, te, ang, _turned(kin, ang), None, 0.5)
    steady = [r[2] for r in rows if r[0] == "one_servo"]
    assert len(steady) >= 12
    # np.gradient over the jittered stamps was off by tens of percent (3.69 for 2.99 rad/s)
    # (±3 ms on the ends of a 0.45 s weight, averaged over a 50 ms ramp each: 0.25 % RMS)
    rel = np.linalg.norm(steady, axis=1) / np.pi - 1
    assert np.sqrt(np.mean(rel**2)) < 4e-3 and np.max(np.abs(rel)) < 1e-2
    # and the generator's true calibration passes
    capsys.readouterr()
    assert main(["verify", str(jittered / "truth.json"), "--recording",
                 str(jittered / "rec")]) == 0


@pytest.mark.parametrize("kind", ["fifo", "zero", "loop", "directory"])
def test_verify_reads_the_calibration_through_the_checked_reader(tmp_path, capsys, kind):
    p = tmp_path / "cal.json"
    if kind == "fifo":
        os.mkfifo(p)  # read_text() on it waited forever
    elif kind == "zero":
        p = "/dev/zero"  # MemoryError
    elif kind == "loop":
        (tmp_path / "a").symlink_to(tmp_path / "b")
        (tmp_path / "b").symlink_to(tmp_path / "a")
        p = tmp_path / "a"
    else:
        p.mkdir()
    assert main(["verify", str(p), "--recording", str(tmp_path)]) == 2
    assert "calibration file" in _error(capsys.readouterr().err)


@pytest.mark.skipif(os.geteuid() == 0, reason="root reads a file without read permission")
def test_verify_refuses_an_unreadable_calibration(tmp_path, capsys):
    p = tmp_path / "cal.json"
    p.write_text("{}")
    p.chmod(0)
    assert main(["verify", str(p), "--recording", str(tmp_path)]) == 2
    assert "Permission denied" in _error(capsys.readouterr().err)


# ---- 3. units and handedness on every protocol ------------------------------------------------
def _rewrite_imu(path, row):
    lines = (path / "imu.csv").read_text().splitlines()
    (path / "imu.csv").write_text("\n".join(
        [lines[0]] + [",".join(row(x.split(","))) for x in lines[1:]]) + "\n")
    return path


@pytest.fixture(scope="module")
def mistakes(tmp_path_factory):
    """Recordings of the independent generator with the audit's mistakes."""
    d = tmp_path_factory.mktemp("mistakes")
    return {
        "ok": write_recording(d / "ok"),
        "degrees": write_recording(d / "degrees", gyro_unit=DEG, angle_unit=DEG),
        "swapped": _rewrite_imu(write_recording(d / "swapped"),
                                lambda r: [r[0], r[2], r[1], r[3], r[4]]),
        "negated": _rewrite_imu(write_recording(d / "negated"),
                                lambda r: [r[0], repr(-float(r[1])), r[2], r[3], r[4]]),
    }


@pytest.mark.parametrize(("kind", "cause"), [
    ("degrees", "the encoder angles are probably in degrees"),
    ("swapped", "servo 1 turns about +y in the sensor frame, the manifest says x; servo 2 "
                "turns about +x"),
    ("negated", "servo 1 turns about -x in the sensor frame, the manifest says x"),
])
def test_unit_and_axis_mistakes_are_refused_with_what_to_check(mistakes, tmp_path, capsys,
                                                               kind, cause):
    out = tmp_path / "cal.json"
    assert main(["estimate", str(mistakes[kind]), "--out", str(out)]) == 6
    err = _error(capsys.readouterr().err)
    assert cause in err and "--allow-implausible" in err and not out.exists()


def test_the_right_recording_passes_the_plan_and_axis_checks(mistakes, capsys):
    from gyrocal.kit.pipeline import check_plausible, estimate_recording
    from gyrocal.kit.recording import load_recording

    rec = load_recording(mistakes["ok"])
    est = estimate_recording(rec)
    assert check_plausible(est.calibration, rec.sensor, recording=rec,
                           extracted=est.extracted) == []


# ---- 4. no user string reaches a formatter that interprets it ---------------------------------
def test_a_dollar_in_a_title_is_drawn_as_written(tmp_path):
    plt = pytest.importorskip("matplotlib.pyplot")
    from gyrocal.kit.plots import literal, save_png

    title = r"run$\foo{$ and $x^2$"
    fig = plt.figure()
    fig.suptitle(title)
    with pytest.raises(ValueError):  # what the report died of (exit 1, after the jig ran)
        fig.savefig(io.BytesIO(), format="png")
    plt.close(fig)
    fig = plt.figure()
    fig.suptitle(literal(title))
    fig.canvas.draw()
    assert fig._suptitle.get_text() == literal(title)
    assert not fig._suptitle._preprocess_math(literal(title))[1]  # no mathtext
    save_png(fig, tmp_path / "t.png")


def test_a_failed_report_keeps_the_calibration_and_says_what_was_written(tmp_path, monkeypatch):
    from gyrocal.kit import report_html

    def broken(*a, **k):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(report_html, "write_run_report", broken)
    note = report_html.write_optional_report(None, None, None, tmp_path / "plots",
                                             title="t", html_path=tmp_path / "report.html")
    assert "the report was not written (" in note and "No space left" in note
    assert "calibration.json and the recording are complete" in note


def test_a_c_comment_opener_in_a_string_stays_inside_the_comment():
    from gyrocal.kit.exports import _c_comment

    text = _c_comment("run /* x */ /*/ a")
    assert "/*" not in text and "*/" not in text


def test_history_list_shows_control_characters_as_escapes(tmp_path, capsys):
    from gyrocal.calib.model import GyroCalibration

    url = f"sqlite:///{tmp_path / 'h.sqlite'}"
    doc = GyroCalibration(scale=(1.0, 1.0, 1.0), bias=(0.0, 0.0, 0.0),
                          method="x\x1b]0;owned\x07\x1b[2J", sensor={"model": "mpu9250"},
                          created="2026-01-01T00:00:00Z")
    (tmp_path / "s\u202egnp.json").write_text(doc.to_json())  # the source: its path
    assert main(["history", "import", str(tmp_path), "--history", url,
                 "--sensor-label", "imu"]) == 0
    capsys.readouterr()
    assert main(["history", "list", "imu", "--history", url]) == 0
    out = capsys.readouterr().out
    assert "\x1b" not in out and "\x07" not in out and "\u202e" not in out
    assert r"x\x1b]0;owned\x07\x1b[2J" in out and r"s\u202egnp.json" in out


# ---- 5. bounded inputs -------------------------------------------------------------------------
def test_a_config_key_of_fifty_thousand_parts_is_refused_before_parsing(tmp_path, capsys):
    cfg = tmp_path / "deep.toml"
    cfg.write_text("a" + ".a" * 49_999 + " = 1\n")  # 100 kB; 20,000 parts took 2.4 GB
    assert main(["calibrate", "--sim", "--config", str(cfg), "--out", str(tmp_path / "o")]) == 2
    assert "a key of 50000 dotted parts" in _error(capsys.readouterr().err)


class _Stdin:
    """Standard input of ``data`` (bytes), with the text and binary views a real one has."""

    def __init__(self, data: bytes) -> None:
        self.buffer = io.BytesIO(data)
        self._text = io.TextIOWrapper(io.BytesIO(data), encoding="utf-8")

    def readline(self, n: int = -1) -> str:
        return self._text.readline(n)

    def read(self, n: int = -1) -> str:
        return self._text.read(n)


@pytest.fixture
def cal_file(tmp_path):
    from gyrocal.calib.model import GyroCalibration

    p = tmp_path / "cal.json"
    p.write_text(GyroCalibration(scale=(1.0, 1.0, 1.0), bias=(0.0, 0.0, 0.0),
                                 sensor={"model": "mpu9250"}).to_json())
    return p


def test_export_of_an_endless_stdin_stops_at_the_bound(cal_file, monkeypatch, capsys):
    from gyrocal.kit.fileio import _MAX_DOCUMENT_BYTES

    monkeypatch.setattr(sys, "stdin", _Stdin(b"\0" * (_MAX_DOCUMENT_BYTES + 10)))
    assert main(["export", "-", "--format", "json"]) == 2
    assert "more than 16777216 bytes" in _error(capsys.readouterr().err)


def test_apply_refuses_a_long_stdin_line_without_echoing_it(cal_file, monkeypatch, capsys):
    monkeypatch.setattr(sys, "stdin", _Stdin(b"1" * 10_000_000))
    assert main(["apply", str(cal_file), "-"]) == 2
    err = capsys.readouterr().err
    assert "line 1: longer than 4096 characters" in _error(err) and len(err) < 400


@pytest.mark.parametrize(("text", "says"), [
    ('{"format": "gyrocal-calibration", "version": ' + "9" * 5000 + "}", "an integer of 5000"),
    ("[" * 200_000 + "]" * 200_000, "nested too deeply"),
    ('{"format": "gyrocal-calibration", "bias": [0, 0, 0], "bias": [1, 1, 1]}',
     "the key 'bias' is given twice"),
])
def test_hostile_calibrations_are_refused_by_export_and_apply(tmp_path, capsys, text, says):
    p = tmp_path / "cal.json"
    p.write_text(text)
    for argv in (["export", str(p), "--format", "json"], ["apply", str(p), "-"]):
        assert main(argv) == 2
        assert says in _error(capsys.readouterr().err)


# ---- 6. history: a damaged row is skipped by name; dates outside the range refused ------------
def _history_with(tmp_path, n=3):
    from tests.kit.test_history import make_doc

    url = f"sqlite:///{tmp_path / 'h.sqlite'}"
    d = tmp_path / "docs"
    d.mkdir()
    for i in range(n):
        (d / f"c{i}.json").write_text(make_doc(100 + i, created=f"2026-01-0{i + 1}T00:00:00Z"))
    assert main(["history", "import", str(d), "--history", url, "--sensor-label", "imu"]) == 0
    return url


@pytest.mark.parametrize("column", ["document", "identity"])
def test_a_damaged_row_is_skipped_and_named(tmp_path, capsys, column):
    url = _history_with(tmp_path)
    con = sqlite3.connect(tmp_path / "h.sqlite")
    if column == "document":
        con.execute("UPDATE calibrations SET document = 'not json' WHERE id = 2")
    else:
        con.execute("UPDATE sensors SET identity = '{broken'")
    con.commit()
    con.close()
    capsys.readouterr()
    for argv in (["list"], ["list", "imu"], ["trend", "imu"],
                 ["export", "imu", str(tmp_path / "out")]):
        assert main(["history", *argv, "--history", url]) == 0, argv
        out, err = capsys.readouterr()
        if column == "document" and argv != ["list"]:
            assert "calibration #2 of sensor 'imu' is damaged (its document is not a JSON " \
                   "object); skipped" in err
            assert "#2" not in out.replace("#1", "").replace("#3", "")
        if column == "identity":
            assert "sensor 'imu': its stored identity is not a JSON object" in err \
                or "its sensor identity is not a JSON object" in err
    if column == "document":
        assert len(list((tmp_path / "out").iterdir())) == 2
        assert main(["history", "show", "2", "--history", url]) == 2
        assert "calibration #2" in _error(capsys.readouterr().err)
        assert main(["history", "show", "3", "--history", url]) == 0


@pytest.mark.parametrize("created", ["0001-01-01T00:00:00+01:00", "9999-12-31T23:59:59-01:00",
                                     "1900-01-01T00:00:00Z", "2500-01-01T00:00:00Z"])
def test_dates_outside_the_plottable_range_are_refused_at_import(tmp_path, capsys, created):
    from tests.kit.test_history import make_doc

    d = tmp_path / "docs"
    d.mkdir()
    (d / "c.json").write_text(make_doc(1, created=created))
    url = f"sqlite:///{tmp_path / 'h.sqlite'}"
    assert main(["history", "import", str(d), "--history", url, "--sensor-label", "imu"]) == 2
    err = capsys.readouterr().err
    assert "'created'" in err and "Traceback" not in err


# ---- smaller items -----------------------------------------------------------------------------
@pytest.mark.parametrize(("damage", "says"), [
    ("duplicate id", "gimbal.motors lists servo id 1 more than once"),
    ("underscore", "field 2 is '1_0.005"),
])
def test_a_recording_with_a_duplicate_servo_id_or_an_underscored_number(tmp_path, capsys,
                                                                        damage, says):
    rec = write_recording(tmp_path / "rec")
    if damage == "duplicate id":  # was exit 1: tuple.index(x): x not in tuple
        m = json.loads((rec / "manifest.json").read_text())
        m["gimbal"]["motors"][1]["id"] = 1
        (rec / "manifest.json").write_text(json.dumps(m))
    else:  # float("1_0.005") is 10.005: read silently
        lines = (rec / "imu.csv").read_text().splitlines()
        row = lines[5].split(",")
        row[1] = "1_0.005"
        lines[5] = ",".join(row)
        (rec / "imu.csv").write_text("\n".join(lines) + "\n")
    assert main(["estimate", str(rec)]) == 2
    assert says in _error(capsys.readouterr().err)


def test_a_truth_with_a_string_does_not_lose_the_written_calibration(tmp_path, capsys):
    # was exit 1 after calibration.json was written (the table compared a string with a float)
    rec = write_recording(tmp_path / "rec")
    m = json.loads((rec / "manifest.json").read_text())
    m["truth"] = {"scale": "abc", "bias": [0, 0, 0]}
    (rec / "manifest.json").write_text(json.dumps(m))
    assert main(["estimate", str(rec), "--out", str(tmp_path / "cal.json")]) == 0
    assert "'truth' is not the simulator's numbers: not compared" in capsys.readouterr().out
    assert (tmp_path / "cal.json").exists()
