"""gyrocal track on the shared emulated calibration run (Calibration v2, posed turns): the
reference axis of a posed turn comes from the calibration's kinematics."""

import json
import re

import numpy as np

from gyrocal.kit.cli import main
from tests.kit.conftest import loop_50_hz_config


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


def test_live_tracking_applies_the_g_sensitivity_from_the_stored_home_pose(full_run, tmp_path,
                                                                          capsys):
    """calibrate writes the home pose "up" refers to (kinematics.home_angles_rad, up_servo);
    track --live then takes f from the servo encoders, and the tracked bias is the emulated
    sensor's zero-g bias. The same calibration without the home pose (a document from before)
    says so and tracks the bias plus G f of the held pose: off by the emulator's own home shift."""
    d, code = full_run
    assert code == 0
    doc = json.loads((d / "calibration.json").read_text())
    manifest = json.loads((d / "recording" / "manifest.json").read_text())
    z_servo = next(m["id"] for m in manifest["gimbal"]["motors"] if m["axis"] == "z")
    assert doc["kinematics"]["up_servo"] == [z_servo, 1]
    assert len(doc["kinematics"]["home_angles_rad"]) == len(doc["kinematics"]["chain"])
    truth = np.array(manifest["truth"]["bias"])
    shift = np.array(manifest["truth"]["realism"]["g-sensitivity"]["home_bias_shift_rad_s"])
    assert np.max(np.abs(shift)) > 5e-4  # large against the tracker's band below
    old = tmp_path / "old.json"
    kin = {k: v for k, v in doc["kinematics"].items() if k not in ("home_angles_rad", "up_servo")}
    old.write_text(json.dumps({**doc, "kinematics": kin}))
    # The jig's loop at 50 Hz (tests/kit/conftest.py LOOP_50_HZ): f is taken from the encoders
    # around each sample at either rate. The final bias, 200 Hz -> 50 Hz, in sigma from the
    # truth: home -0.80 -0.45 -0.17 -> -0.78 -0.52 -0.30 (0.147 -> 0.163 of the home shift's
    # size); old, from truth - shift: -0.90 0.19 -0.14 -> -0.86 0.10 -0.29 (0.135 -> 0.129).
    loop = loop_50_hz_config(tmp_path / "loop")
    final = {}
    for name, path in (("home", d / "calibration.json"), ("old", old)):
        out = tmp_path / f"live-{name}.json"
        assert main(["track", "--live", "--sim", "--sim-seed", "5", "--duration", "6",
                     "--cal", str(path), "--out", str(out), "--config", loop]) == 0
        _, err = capsys.readouterr()
        got = json.loads(out.read_text())
        final[name] = (np.array(got["bias"])[-1], np.array(got["bias_std"])[-1], err)
    size = np.linalg.norm(shift)
    b, sd, err = final["home"]
    assert "g-sensitivity is applied live" in err, err
    assert np.all(np.abs(b - truth) <= 3 * sd), (b - truth, sd)
    assert np.linalg.norm(b - truth) < 0.35 * size, (b - truth, shift)
    b, sd, err = final["old"]
    assert err.count("g-sensitivity is NOT applied live") == 1 and "home pose" in err, err
    # Calibration v1 convention (m = g/k − b + G f): without f the tracker follows b − G f
    assert np.all(np.abs(b - (truth - shift)) <= 3 * sd), (b - truth, shift, sd)
    assert np.linalg.norm(b - (truth - shift)) < 0.35 * size, (b - truth, shift)
