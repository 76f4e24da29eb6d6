"""End-to-end: `gyrocal calibrate --sim --jig single-servo`, the emulated user re-seating the cube
(one emulated run for the module), and the seat check from gravity."""

import json

import numpy as np
import pytest

from gyrocal.calib.design import SEATS
from gyrocal.calib.estimators import matrix_in_frame
from gyrocal.kit.cli import main
from gyrocal.kit.jig_kinds import JIG_KINDS
from gyrocal.kit.recording import load_recording
from gyrocal.kit.seating import check_seat, seat_prompt
from tests.kit.conftest import LOOP_50_HZ


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    """One run of the single-servo jig on the emulated jig (every realism effect on), one turn
    each way per seat to keep it short; the emulated user seats the cube wrong at the second
    prompt, so the check must refuse it and prompt again. Its loop at 50 Hz
    (:data:`tests.kit.conftest.LOOP_50_HZ`: the same samples for a quarter of the emulated bus
    traffic): at 200 Hz the matrix was 1.79 sigma from the truth at worst and the bias 0.57,
    1.83, 1.64 sigma, at 50 Hz 2.16 and 0.18, 1.13, 0.67, with the same sigmas (1.0e-4 to
    1.3e-4) and the same seat refused."""
    d = tmp_path_factory.mktemp("single")
    cfg = d / "gyrocal.toml"
    cfg.write_text("[protocol]\nturns = 1\nrest_s = 0.8\n" + LOOP_50_HZ)
    code = main(["calibrate", "--sim", "--jig", "single-servo", "--config", str(cfg),
                 "--out", str(d / "out"), "--quiet", "--no-report", "--sim-seed", "4",
                 "--sim-fault", "seat:1"])
    return code, d / "out"


def test_the_single_servo_run_calibrates_the_full_matrix_within_its_sigma(run):
    code, out = run
    assert code == 0
    cal = json.loads((out / "calibration.json").read_text())
    rec = load_recording(out / "recording")
    assert cal["version"] == 2 and rec.complete
    t = rec.truth
    A = matrix_in_frame(np.diag(1 / np.array(t["scale"])) @ np.array(t["misalignment"]))
    std = np.array(cal["matrix_std"])
    err = np.array(cal["matrix"]) - A
    free = std > 0
    assert np.all(np.abs(err[free]) < 4 * std[free]), (err, std)
    berr = np.array(cal["bias"]) - np.array(t["bias"])
    # the zero-g bias against the truth's (g-sensitivity fitted from each seat's gravity)
    assert np.all(np.abs(berr) < 4 * np.array(cal["bias_std"])), (berr, cal["bias_std"])
    assert cal["consistency"]["ok"]
    assert "kinematics" not in cal or cal["kinematics"] is None


def test_each_seat_taken_reads_its_gravity_and_the_wrong_one_was_refused(run):
    _, out = run
    manifest = json.loads((out / "recording" / "manifest.json").read_text())
    p = manifest["protocol"]
    assert manifest["jig"]["kind"] == "single-servo"
    assert [s["seat"] for s in p["seats"]] == p["planned_seats"]
    for s in p["seats"]:
        cos = float(np.dot(s["gravity"], SEATS[s["seat"]][0]))
        assert np.degrees(np.arccos(min(cos, 1.0))) < 5, s  # 1° seating error, 0.3° shaft tilt
    refused = [d for d in p["discarded"] if d["kind"] == "seat"]
    assert [d["seat"] for d in refused] == [p["planned_seats"][1]]


def test_check_seat_says_which_seat_is_up_instead():
    x = np.tile([9.8, 0.0, 0.1], (50, 1))
    assert check_seat(x, "+x") is None
    msg = check_seat(x, "+x+y")
    assert "not seated +x+y up (45° off)" in msg and "+x is up instead" in msg
    msg = check_seat(np.tile([0.0, 0.0, -9.8], (50, 1)), "+z")
    assert "no seat is up" in msg
    assert "no readings" in check_seat(np.zeros((0, 3)), "+z")


def test_prompt_names_the_adapter_part():
    assert "face +y up on the flat adapter" in seat_prompt("+y", 2, 6)
    assert "V-block" in seat_prompt("+x-y", 4, 6, "the cube is not seated")


def test_jig_choices_are_the_jig_kinds(capsys):
    assert main(["calibrate", "--jig", "table"]) == 2
    err = capsys.readouterr().err
    for name in JIG_KINDS:
        assert name in err


def test_single_servo_refuses_a_config_of_several_servos(tmp_path, capsys):
    cfg = tmp_path / "g.toml"
    cfg.write_text('[gimbal]\nids = [3, 4]\naxes = ["x", "y"]\n')
    assert main(["calibrate", "--sim", "--jig", "single-servo", "--config", str(cfg),
                 "--out", str(tmp_path / "o"), "--quiet", "--no-report"]) == 2
    assert "set gimbal.ids = [3]" in capsys.readouterr().err


def test_terminal_seater_waits_for_enter_and_refuses_a_closed_terminal():
    import io
    import os

    from gyrocal.kit.errors import InputError
    from gyrocal.kit.seating import TerminalSeater

    r, w = os.pipe()
    with os.fdopen(r) as inp, os.fdopen(w, "w") as out_w:
        said = io.StringIO()
        seater = TerminalSeater(inp, said)
        seater.prompt("+x", seat_prompt("+x", 1, 3))
        assert "face +x up" in said.getvalue()
        assert not seater.ready()  # nothing typed: the runner's loop goes on
        out_w.write("\n")
        out_w.flush()
        assert seater.ready()
        seater.prompt("+y", seat_prompt("+y", 2, 3))
        out_w.close()
        with pytest.raises(InputError, match="interactive terminal"):
            seater.ready()
