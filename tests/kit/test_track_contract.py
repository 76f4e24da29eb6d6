"""gyrocal track on posed full-model recordings from the independent contract generator
(tests/kit/contract_fullmodel_recording.py: scipy rotations and numpy, nothing of gyrocal's), with
a Calibration v2 made from the generator's own truth: the tracked bias must hold the true bias
inside the tracker's 3-sigma band, with NIS alarms near nominal, and the calibration's
g-sensitivity must be applied with the specific force from the encoders."""

import json
import re

import numpy as np
import pytest

from gyrocal.calib.model import GyroCalibration
from gyrocal.kit.cli import main
from tests.kit.contract_fullmodel_recording import write_recording

G_TRUE = np.array([[2.0e-3, -1.5e-3, 1.0e-3], [1.0e-3, 2.5e-3, -2.0e-3],
                   [-1.5e-3, 1.0e-3, 3.0e-3]])


def truth_calibration(truth, *, offset, g=None, temperature_c=None):
    """The generator's truth as a Calibration v2 (``A = C⁻¹`` for ``m = C ω − b``; the servo
    axes at home ``Mᵀ a_j``), its bias moved by ``offset`` (the tracker has to find the rest)
    and loose enough to say so."""
    C = np.diag(1 / truth["scale"]) @ truth["misalignment"]
    A = np.linalg.inv(C)
    M = truth["mount"]
    kw = {}
    if g is not None:
        kw["g_sensitivity"] = {"matrix": g.tolist(), "matrix_std": [[1e-5] * 3] * 3,
                               "directions": np.eye(3).tolist()}
    return GyroCalibration(
        scale=tuple(np.diag(A)), bias=tuple(truth["bias"] + offset), scale_std=(1e-4,) * 3,
        bias_std=(1e-2,) * 3, matrix=tuple(map(tuple, A)), matrix_std=((1e-4,) * 3,) * 3,
        kinematics={"chain": [11, 12, 13], "axes": [(M.T @ a).tolist() for a in truth["links"]],
                    "reference_angles_rad": [0.0, 0.0, 0.0]},
        method="truth of the contract generator", temperature_c=temperature_c, **kw)


def track(rec, cal, tmp_path, capsys, name):
    cal_path = tmp_path / f"{name}.json"
    cal_path.write_text(cal.to_json(), encoding="utf-8")
    out = tmp_path / f"{name}-track.json"
    assert main(["track", str(rec), "--cal", str(cal_path), "--out", str(out)]) == 0
    text, err = capsys.readouterr()
    doc = json.loads(out.read_text())
    return np.array(doc["bias"]), np.array(doc["bias_std"]), text, err


def alarms(text):
    m = re.search(r"(\d+) NIS alarm\(s\)", text)
    assert m is not None, text
    return int(m.group(1))


@pytest.mark.parametrize("seed", [1, 2])
def test_track_holds_the_generators_bias_on_posed_turns(tmp_path, capsys, seed):
    rec = tmp_path / "rec"
    truth = write_recording(rec, seed=seed)
    rng = np.random.default_rng(seed)
    offset = rng.choice([-1.0, 1.0], 3) * rng.uniform(3e-3, 5e-3, 3)
    bias, std, text, err = track(rec, truth_calibration(truth, offset=offset), tmp_path, capsys,
                                 "cal")
    assert "reference-rate" in text and "(0 zero-rate, 0 reference-rate)" not in text
    err_now = np.abs(bias - truth["bias"])
    assert np.mean(err_now <= 3 * std) >= 0.99, np.max(err_now / std, axis=0)
    # the posed turns moved the estimate from the calibration's bias to the truth
    assert np.all(err_now[-1] < 0.2 * np.abs(offset)), (err_now[-1], offset)
    assert alarms(text) <= 1, text
    assert "g-sensitivity" not in err


def test_track_applies_g_sensitivity_from_the_encoders(tmp_path, capsys):
    """The reading carries G f (f: gravity carried by the servos' angles, 1 g): with the
    calibration's G and the specific force from encoder.csv through its kinematics, the band
    holds the zero-g bias; with the same calibration's G dropped, the bias error is larger."""
    rec = tmp_path / "rec"
    truth = write_recording(rec, seed=3, g_sensitivity=G_TRUE)
    offset = np.array([3e-3, -4e-3, 2e-3])
    # the generator's reading gains +G f; the model g = A (m + b + G f) reads m = A⁻¹ g − b − G f
    b_g, s_g, text, err = track(rec, truth_calibration(truth, offset=offset, g=-G_TRUE),
                                tmp_path, capsys, "with-g")
    assert "g-sensitivity is NOT applied" not in err
    e_g = np.abs(b_g - truth["bias"])
    assert np.mean(e_g <= 3 * s_g) >= 0.99, np.max(e_g / s_g, axis=0)
    assert alarms(text) <= 1, text
    b_n, _, text_n, _ = track(rec, truth_calibration(truth, offset=offset), tmp_path, capsys,
                              "without-g")
    e_n = np.abs(b_n - truth["bias"])
    rms_g, rms_n = np.sqrt(np.mean(e_g**2)), np.sqrt(np.mean(e_n**2))
    assert rms_g < 0.5 * rms_n, (rms_g, rms_n)


def test_track_says_when_it_cannot_apply_g_sensitivity(tmp_path, capsys):
    rec = tmp_path / "rec"
    truth = write_recording(rec, seed=4, g_sensitivity=G_TRUE)
    manifest = json.loads((rec / "manifest.json").read_text())
    for m in manifest["gimbal"]["motors"]:
        m["axis"] = "x" if m["axis"] == "z" else m["axis"]  # no servo says where up is
    (rec / "manifest.json").write_text(json.dumps(manifest))
    _, _, _, err = track(rec, truth_calibration(truth, offset=np.zeros(3), g=-G_TRUE), tmp_path,
                         capsys, "cal")
    assert err.count("g-sensitivity is NOT applied") == 1, err
    assert "manifest lists no servo with axis z" in err


def test_track_follows_a_bias_random_walk(tmp_path, capsys):
    """The generator's bias wanders (2e-4 rad/s/√s: about 1.4e-3 rad/s over the session, ten
    times the turns' noise floor); with nothing but the recording and the calibration the
    tracker estimates the walk from its innovations and its band holds the moving truth."""
    rec = tmp_path / "rec"
    truth = write_recording(rec, seed=7, bias_walk=2e-4)
    walk = truth["bias_walk"]
    assert np.ptp(walk, axis=0).max() > 5e-4
    bias, std, text, err = track(rec, truth_calibration(truth, offset=np.zeros(3)), tmp_path,
                                 capsys, "cal")
    e = bias - (truth["bias"] + walk)
    assert np.mean(np.abs(e) <= 3 * std) >= 0.99, np.max(np.abs(e) / std, axis=0)
    assert alarms(text) <= 1, text
    # it follows the walk: better than the calibration's frozen bias
    assert np.sqrt(np.mean(e**2)) < 0.6 * np.sqrt(np.mean(walk**2))
    k = re.search(r"innovations: ([^ ]+), ([^ ]+), ([^ ]+) ", err)
    assert k is not None, err
    assert all(1e-4 < float(x) < 4e-4 for x in k.groups()), k.groups()  # the true 2e-4


def test_track_follows_a_temperature_ramp(tmp_path, capsys):
    """The die warms 25 -> 35 °C over the session and the bias follows (a coefficient of up to
    3e-4 rad/s/°C: 3e-3 rad/s); the recording's temperatures turn the tracker's temperature
    state on, and its band holds the moving truth."""
    rec = tmp_path / "rec"
    c = np.array([3e-4, -2e-4, 1e-4])
    truth = write_recording(rec, seed=8, temp_ramp=(25.0, 35.0), tempco=tuple(c))
    temp = np.loadtxt(rec / "imu.csv", delimiter=",", skiprows=1)[:, 4]
    drift = np.outer(temp - 25.0, c)
    bias, std, text, err = track(rec, truth_calibration(truth, offset=np.zeros(3),
                                                        temperature_c=25.0),
                                 tmp_path, capsys, "cal")
    assert "temperature coefficient" in err
    e = bias - (truth["bias"] + drift)
    assert np.mean(np.abs(e) <= 3 * std) >= 0.99, np.max(np.abs(e) / std, axis=0)
    assert alarms(text) <= 1, text
    assert np.sqrt(np.mean(e**2)) < 0.5 * np.sqrt(np.mean(drift**2))
