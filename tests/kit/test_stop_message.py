"""A run that ends in a servo failure says whether the stop confirmed torque off (issue 27).

An unconfirmed stop is its own error ("could NOT confirm torque off ...", the PTY tests in
``test_signals.py``); a confirmed one is said in the note before the error.
"""

from __future__ import annotations

import json

from gyrocal.kit.cli import main

SHORT = "[gimbal]\nsample_hz = 100.0\n[protocol]\nspeed_dps = 240\nturns = 1\nrest_s = 0.4\n"


def test_a_hardware_alert_says_torque_off_was_confirmed(tmp_path, capsys):
    (tmp_path / "g.toml").write_text(SHORT)
    code = main(["calibrate", "--sim", "--config", str(tmp_path / "g.toml"), "--out",
                 str(tmp_path / "out"), "--quiet", "--no-report", "--sim-realism", "off",
                 "--sim-fault", "alert:1:1"])
    err = capsys.readouterr().err
    assert code == 4, err
    note, error = err.strip().splitlines()[-2:]
    assert note.startswith("gyrocal: note: servos stopped, torque off confirmed on every servo; "
                           "the recording in ")
    assert note.endswith("is kept, marked incomplete")
    assert error.startswith("gyrocal: error: servo 1 reports a hardware error")
    # what the emulated servos hold, not what the driver believes
    servos = json.loads((tmp_path / "out" / "sim-state.json").read_text())["servos"]
    assert all(s["torque_enable"] == 0 for s in servos.values()), servos
