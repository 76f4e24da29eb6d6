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
