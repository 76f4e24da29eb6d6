"""gyrocal track on the shared emulated calibration run (Calibration v2, posed turns): the
reference axis of a posed turn comes from the calibration's kinematics."""

import json
import re

import numpy as np

from gyrocal.kit.cli import main


def test_track_replays_a_posed_v2_recording_against_the_emulated_truth(paper_full_run, tmp_path,
                                                                        capsys):
    d, code = paper_full_run
    assert code == 0
    rec, cal = d / "recording", d / "calibration.json"
    assert json.loads(cal.read_text())["kinematics"]["chain"]
    # the recording has posed turns: a servo turning while another holds 45 degrees
    out = tmp_path / "track.json"
    assert main(["track", str(rec), "--cal", str(cal), "--out", str(out), "--rows", "3"]) == 0
    text, err = capsys.readouterr()
    truth = np.array(json.loads((rec / "manifest.json").read_text())["truth"]["bias"])
    doc = json.loads(out.read_text())
    bias, std = np.array(doc["bias"]), np.array(doc["bias_std"])
    # the emulated sensor's bias (Calibration v1 sign) inside the 3-sigma band at every sample
    assert np.all(np.abs(bias - truth) <= 3 * std)
    # turns about the posed axes agree with the model: no NIS alarm, no CUSUM shift (with the
    # reference-pose axes, 21 alarms and 17 shifts from the first posed turn on), and the bias
    # random walk estimated from the innovations stays small (3.2e-3 on every axis then)
    assert "0 NIS alarm(s)" in text and "0 bias shift(s)" in text, text
    k = re.search(r"bias random walk estimated from the innovations: ([^ ]+), ([^ ]+), ([^ ]+) ",
                  err)
    assert k is not None, err
    assert max(float(x) for x in k.groups()) < 3e-4, err
    assert "reference-rate" in text and "(0 zero-rate, 0 reference-rate)" not in text


def test_track_applies_the_g_sensitivity_on_the_realistic_emulated_run(full_run, tmp_path,
                                                                      capsys):
    """The default emulated sensor has g-sensitivity (and a low-pass delay, wobble, coloured
    noise); its calibration fits G. Replayed with the specific force from the encoders, the
    tracked bias is the emulator's zero-g bias inside the 3-sigma band; the same calibration
    with its G dropped tracks the bias plus G f of the poses, further from the truth."""
    d, code = full_run
    assert code == 0
    rec, cal = d / "recording", d / "calibration.json"
    doc = json.loads(cal.read_text())
    assert doc["g_sensitivity"] is not None
    truth = np.array(json.loads((rec / "manifest.json").read_text())["truth"]["bias"])
    no_g = tmp_path / "no-g.json"
    no_g.write_text(json.dumps({**doc, "g_sensitivity": None}))
    err = {}
    for name, path in (("with", cal), ("without", no_g)):
        out = tmp_path / f"{name}.json"
        assert main(["track", str(rec), "--cal", str(path), "--out", str(out)]) == 0
        text, notes = capsys.readouterr()
        assert "g-sensitivity is NOT applied" not in notes
        got = json.loads(out.read_text())
        bias, std = np.array(got["bias"]), np.array(got["bias_std"])
        err[name] = bias - truth
        if name == "with":
            assert np.mean(np.abs(bias - truth) <= 3 * std) >= 0.99
            assert "0 NIS alarm(s)" in text, text
    rms = {k: float(np.sqrt(np.mean(v**2))) for k, v in err.items()}
    assert rms["with"] < 0.6 * rms["without"], rms
