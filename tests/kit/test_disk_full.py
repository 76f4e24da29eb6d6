"""A disk that fills during a run: the failure is named where it happened, and what was written
is said (issue 27).

The disk is simulated (portable, no root, no small filesystem): ``bench.attacks.FullDisk``
gives the recording writer's files and every atomic write (``manifest.json``,
``sim-state.json``, each plot) a shared quota; past it a write fails with ``OSError(ENOSPC)``.
"""

from __future__ import annotations

import json
import re

import pytest

from bench.attacks import FullDisk
from gyrocal.kit import recording
from gyrocal.kit.cli import main
from gyrocal.kit.errors import InputError

SHORT = "[gimbal]\nsample_hz = 100.0\n[protocol]\nspeed_dps = 240\nturns = 1\nrest_s = 0.4\n"


def test_a_disk_full_during_the_recording_names_the_recording(tmp_path, monkeypatch, capsys):
    """It was exit 1 with a traceback ending ``[Errno 28] No space left on device``, no file
    named; and once the manifest could not be written either, the failure to write
    ``manifest.json`` (in the jig's own clean-up) replaced it."""
    (tmp_path / "g.toml").write_text(SHORT)
    FullDisk(monkeypatch.setattr, left=20_000)  # the disk fills a few hundred samples in
    code = main(["calibrate", "--sim", "--config", str(tmp_path / "g.toml"), "--out",
                 str(tmp_path / "out"), "--quiet", "--no-report", "--sim-realism", "off"])
    err = capsys.readouterr().err
    assert code == 2, err
    assert "Traceback" not in err
    last = err.strip().splitlines()[-1]
    rec = tmp_path / "out" / "recording"
    # the writer appends what the loop queued as one batch per file, so whichever of the
    # recording's files crosses the quota first is the one named
    named = re.match(r"gyrocal: error: cannot write the recording's (\w+\.csv) \((.*)\): No "
                     r"space left on device", last)
    assert named and named.group(1) in ("imu.csv", "encoder.csv", "segments.csv"), last
    assert named.group(2) == str(rec / named.group(1)), last
    assert "sim-state.json" not in last and "manifest.json" not in last
    assert "is kept, marked incomplete" in err
    assert json.loads((rec / "manifest.json").read_text())["complete"] is False


def test_a_recording_that_cannot_be_flushed_at_its_end_is_not_marked_complete(tmp_path,
                                                                               monkeypatch):
    disk = FullDisk(monkeypatch.setattr, left=None)
    w = recording.RecordingWriter(tmp_path / "rec", sensor={}, gimbal={}, protocol={})
    w.append_encoder(0.0, [1], [0.0])
    disk.left = -1  # full from here: the flushes at the end, and the manifest
    with pytest.raises(InputError, match=r"cannot write the recording's imu.csv .*No space"):
        w.finish()
    assert all(f._fh.closed for f in (w._imu, w._enc, w._seg))  # every file closed all the same
    assert json.loads((tmp_path / "rec" / "manifest.json").read_text())["complete"] is False
    w.close()  # closed once: nothing more to say


def test_a_disk_full_while_plotting_says_the_calibration_is_complete(tmp_path, monkeypatch):
    pytest.importorskip("matplotlib")
    from gyrocal.kit.pipeline import estimate_recording
    from gyrocal.kit.recording import load_recording
    from gyrocal.kit.report_html import write_optional_report

    assert main(["simulate-recording", str(tmp_path / "rec"), "--seed", "4"]) == 0
    rec = load_recording(tmp_path / "rec")
    est = estimate_recording(rec)
    FullDisk(monkeypatch.setattr, left=None, files_left=1)  # room for one plot
    note = write_optional_report(rec, est.calibration, est.extracted, tmp_path / "plots",
                                 title="t", html_path=tmp_path / "report.html")
    assert len(list((tmp_path / "plots").glob("*.png"))) == 1  # half a plots/
    assert not (tmp_path / "report.html").exists()
    assert note.startswith(f"the report was not written (cannot write {tmp_path / 'plots'}/")
    # the plot that did not fit, named, and what to do about a full disk
    assert ".png: No space left on device; free space on that disk or choose another " \
           "directory)" in note
    assert ("calibration.json and the recording are complete (some of its plots may be "
            "there): `gyrocal report` draws the report again") in note
