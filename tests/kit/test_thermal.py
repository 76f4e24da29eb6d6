"""gyrocal thermal (issue 13) on data from the independent Recording v1 generator
(tests/kit/contract_recording.py, which shares no code with gyrocal): calibrations of a sensor
warming up, with known temperature coefficients, fitted back to those coefficients.
"""

import json
import math

import numpy as np
import pytest

from gyrocal.kit.cli import main
from gyrocal.kit.pipeline import estimate_recording
from gyrocal.kit.recording import load_recording
from tests.kit.contract_recording import write_recording

# datasheet-typical magnitudes (MPU-9250: up to ~4e-3 rad/s/°C, ±4 % sensitivity over 125 °C)
BIAS_COEFFS = np.array([[0.010, 2.0e-3, 3.0e-5], [-0.020, -1.5e-3, 0.0], [0.005, 8.0e-4, -2e-5]])
SCALE = np.array([1.01, 0.99, 1.02])
SCALE_TC = np.array([3.0e-4, -2.0e-4, 1.0e-4])


def die(t):
    """A warm-up: 18 °C at power-on, 10 °C of rise with a 250 s time constant."""
    return 18.0 + 10.0 * (1.0 - np.exp(-np.asarray(t) / 250.0))


def truth_bias(T):
    d = np.asarray(T, dtype=float)[..., None] - 25.0
    return BIAS_COEFFS[:, 0] + BIAS_COEFFS[:, 1] * d + BIAS_COEFFS[:, 2] * d**2


def truth_scale(T):
    return SCALE * (1.0 + SCALE_TC * (np.asarray(T, dtype=float)[..., None] - 25.0))


def calibrate(path, t0, seed):
    thermal = {"die": die, "t0": t0, "bias_coeffs": BIAS_COEFFS, "scale_coeff": SCALE_TC}
    rec = load_recording(write_recording(path, scale=SCALE, thermal=thermal, seed=seed,
                                         noise=0.005))
    return estimate_recording(rec, "paired-axis")


@pytest.fixture(scope="module")
def warmup(tmp_path_factory):
    """Six calibrations, one every 70 s of a warm-up, as JSON files in one directory."""
    root = tmp_path_factory.mktemp("warmup")
    (root / "cals").mkdir()
    ests = []
    for i in range(6):
        est = calibrate(root / f"rec{i}", 70.0 * i, seed=100 + i)
        (root / "cals" / f"cal{i}.json").write_text(est.calibration.to_json())
        ests.append(est)
    (root / "cals" / "other.json").write_text('{"not": "a calibration"}')  # passed over
    return root, ests


def fast_jig(tmp_path):
    """Options for a cheap emulated jig in the end-to-end tests: the diagonal protocol of the
    planner (18 s of jig time instead of the full model's 45 s) polled at 50 Hz (a quarter of the
    emulated bus traffic), on a sensor the diagonal model describes exactly (no cross-axis
    terms) and without the realism effects whose truth ``truth_at`` does not carry (g-
    sensitivity, the chip clock's ppm, coloured noise: issue 12's, checked by its own tests).
    What the tests check, the thermal model against the emulator's drawn coefficients, is the
    same; the full matrix's thermal fit is checked on the independent generator and in
    ``bench thermal``."""
    cfg = tmp_path / "fast.toml"
    cfg.write_text('[protocol]\nname = "auto"\ntime_budget_s = 18\n[gimbal]\nsample_hz = 50\n')
    return ("--config", cfg, "--sim-realism", "off", "--sim-cross-axis", "0")


def run_thermal(capsys, *argv):
    code = main(["thermal", *map(str, argv)])
    out = capsys.readouterr()
    return code, out.out, out.err


def test_within_one_run_the_drift_is_modelled_and_the_bias_is_at_the_mean_temperature(warmup):
    _, ests = warmup
    first = ests[0]  # the die warms by about 2.4 °C during the first run
    assert any("die temperature changed" in w for w in first.extracted.warnings)
    for est in ests:
        cal = est.calibration
        z = (np.asarray(cal.bias) - truth_bias(cal.temperature_c)) / np.asarray(cal.bias_std)
        assert np.all(np.abs(z) < 4.0), (cal.temperature_c, z)
        assert cal.consistency.ok


def test_the_drift_within_a_run_is_not_taken_for_g_sensitivity(warmup):
    """The generator's sensor has no g-sensitivity, but during a warm-up the servos turn one
    after another while the bias drifts, so the error of the drift slope measured on the rests
    separates turns and rests as ``G γ`` would; the likelihood-ratio test fits that slope's
    error in both models and leaves ``G`` out (with the drift not in the test, the run at
    20.9 °C had G fitted: a likelihood-ratio drop of 11.9 against 11.3)."""
    _, ests = warmup
    assert [e.fit.g_sensitivity is None for e in ests] == [True] * 6
    assert all("g-sensitivity not fitted" in " ".join(e.notes) for e in ests)


def test_thermal_from_files_holds_the_truth_and_beats_one_calibration(warmup, capsys):
    root, ests = warmup
    code, out, _ = run_thermal(capsys, root / "cals", "--json")
    assert code == 0
    from gyrocal.calib.model import GyroCalibration

    cal = GyroCalibration.from_dict(json.loads(out))
    model = cal.temperature_model
    lo, hi = model.range_c
    temps = [e.calibration.temperature_c for e in ests]
    assert (lo, hi) == (pytest.approx(min(temps)), pytest.approx(max(temps)))
    assert model.points == 6 and model.consistency.ok
    single = ests[0].calibration  # one calibration at the start temperature
    g = np.array([0.7, -0.5, 0.3])  # a true rate, rad/s
    for T in np.linspace(lo, hi, 21):
        st = model.at(T)
        assert np.all(np.abs(st.bias - truth_bias(T)) <= 4 * st.bias_std)
        assert np.all(np.abs(np.diag(st.gain) - truth_scale(T)) <= 4 * np.diag(st.gain_std))
        m = g / truth_scale(T) - truth_bias(T)  # what the sensor reads at T
        err_model = np.linalg.norm(cal.apply(m, temperature_c=T) - g)
        err_single = np.linalg.norm(single.apply(m) - g)
        if T > single.temperature_c + 0.5:  # away from where the single one was made
            assert err_model < err_single
    # across the range the model's bias error is a small fraction of the single one's
    grid = np.linspace(lo, hi, 50)
    rms_model = math.sqrt(np.mean([(model.at(T).bias - truth_bias(T)) ** 2 for T in grid]))
    rms_single = math.sqrt(np.mean([(np.asarray(single.bias) - truth_bias(T)) ** 2
                                    for T in grid]))
    assert rms_model < 0.1 * rms_single


def test_thermal_table_names_the_order_and_the_range(warmup, capsys):
    root, _ = warmup
    code, out, _ = run_thermal(capsys, *sorted((root / "cals").glob("cal*.json")))
    assert code == 0
    assert "chosen by BIC" in out and "consistent" in out and "cal5.json" in out


@pytest.mark.parametrize("argv, what", [
    (["nowhere.json"], "does not exist"),
    (["EMPTY"], "holds no gyrocal calibration"),
    (["ONE", "ONE"], "span only"),
    (["ONE", "--sim"], "not both"),
    (["--sim", "--runs", "1"], "--runs must be 2..1000"),
    (["--sim", "--static", "-5"], "--static a positive number"),
])
def test_bad_inputs_exit_2_with_a_reason(warmup, capsys, tmp_path, argv, what):
    root, _ = warmup
    (tmp_path / "empty").mkdir()
    sub = {"EMPTY": tmp_path / "empty", "ONE": root / "cals" / "cal0.json"}
    code, _, err = run_thermal(capsys, *[sub.get(a, a) for a in argv])
    assert code == 2 and what in err and "Traceback" not in err


def test_a_calibration_without_temperature_is_refused(warmup, capsys, tmp_path):
    root, _ = warmup
    doc = json.loads((root / "cals" / "cal0.json").read_text())
    doc["temperature_c"] = None
    (tmp_path / "c.json").write_text(json.dumps(doc))
    code, _, err = run_thermal(capsys, tmp_path / "c.json", root / "cals" / "cal1.json")
    assert code == 2 and "no temperature_c" in err


def test_track_seeds_its_temperature_coefficient_from_the_thermal_model(warmup, capsys):
    root, _ = warmup
    code, out, _ = run_thermal(capsys, root / "cals", "--json")
    (root / "thermal.json").write_text(out)
    from gyrocal.calib.model import GyroCalibration
    from gyrocal.kit.thermal import tracker_tempco

    cal = GyroCalibration.from_json(out)
    slope, std = tracker_tempco(cal)
    d = cal.temperature_c - 25.0  # the truth's derivative at the calibration's temperature
    truth = BIAS_COEFFS[:, 1] + 2 * BIAS_COEFFS[:, 2] * d
    assert np.all(np.abs(np.array(slope) - truth) <= 3 * np.array(std))
    assert main(["track", str(root / "rec3"), "--cal", str(root / "thermal.json"), "--tempco",
                 "--json"]) == 0
    assert "seeded from the calibration's thermal model" in capsys.readouterr().err


def test_apply_outside_the_covered_range_clamps_and_says_so(warmup, capsys, tmp_path):
    root, _ = warmup
    code, out, _ = run_thermal(capsys, root / "cals", "--json")
    (tmp_path / "thermal.json").write_text(out)
    (tmp_path / "rows.csv").write_text("t,gx,gy,gz,temp\n0.0,0.1,0.2,0.3,24.0\n"
                                       "0.005,0.1,0.2,0.3,60.0\n")
    assert main(["apply", str(tmp_path / "thermal.json"), str(tmp_path / "rows.csv")]) == 0
    res = capsys.readouterr()
    assert "gyrocal: warning: 1 reading(s) at die temperatures outside" in res.err
    rows = [list(map(float, r.split(","))) for r in res.out.splitlines()[1:]]
    from gyrocal.calib.model import GyroCalibration

    cal = GyroCalibration.from_json(out)
    hot = cal.temperature_model.range_c[1]
    m = np.array([0.1, 0.2, 0.3])
    np.testing.assert_allclose(rows[1][1:4], cal.apply(m, temperature_c=hot), rtol=1e-8)


def test_thermal_on_the_emulated_jig_recovers_the_drawn_coefficients(tmp_path, capsys):
    """`gyrocal thermal --sim`: three short runs of a warming emulated MPU-9250; the model holds
    the manifest's truth within its stated uncertainty over the covered range. (Three runs allow
    a line only, p <= n - 2, so the span is kept to about 2 °C, where the drawn curvature stays
    below the bias's uncertainty; the bench runs the 10 °C warm-up with eight.)"""
    from gyrocal.calib.model import GyroCalibration
    from gyrocal.kit.thermal import truth_at

    code, out, err = run_thermal(capsys, "--sim", "--sim-seed", "4", *fast_jig(tmp_path),
                                 "--sim-temperature", "ramp:20:22:240",
                                 "--sim-self-heating", "0.5:120", "--runs", "3", "--wait", "60",
                                 "--out", tmp_path / "w", "--json")
    assert code == 0, err
    cal = GyroCalibration.from_json(out)
    assert json.loads((tmp_path / "w" / "calibration.json").read_text()) == json.loads(out)
    truth = json.loads((tmp_path / "w" / "run-01" / "recording" / "manifest.json").read_text())
    truth = truth["truth"]
    assert truth["temperature"]["die"]["ambient"] == "ramp:20:22:240"
    m = cal.temperature_model
    lo, hi = m.range_c
    assert hi - lo > 1.0 and m.points == 3
    for T in np.linspace(lo, hi, 7):
        st, tt = m.at(T), truth_at(truth, T)
        assert np.all(np.abs(st.bias - tt["bias"]) <= 4 * st.bias_std + 1e-12)
        assert np.all(np.abs(np.diag(st.gain) - tt["scale"]) <= 4 * np.diag(st.gain_std))


def test_static_warmup_fits_bias_only_and_keeps_the_spin_scale(tmp_path, capsys):
    """--static: one spin calibration, then the still sensor while it warms (PX4/ArduPilot).
    A 60 s warm-up (the ambient 20 to 24 °C in 60 s): the die covers 22.1-25.3 °C and the
    model's bias is at most 2.48 sigma from the truth's over it (120 s, 20 to 24 °C in 120 s:
    21.3-26.1 °C, 2.17 sigma; sigma 2.3e-5 and 2.5e-5 rad/s)."""
    from gyrocal.calib.model import GyroCalibration
    from gyrocal.kit.thermal import truth_at

    code, out, err = run_thermal(capsys, "--sim", "--sim-seed", "5", *fast_jig(tmp_path),
                                 "--sim-temperature", "ramp:20:24:60",
                                 "--static", "60", "--out", tmp_path / "s", "--json")
    assert code == 0, err
    cal = GyroCalibration.from_json(out)
    doc = json.loads(out)["temperature_model"]
    assert doc["kind"] == "static" and "scale_coeffs" not in doc and "matrix_coeffs" not in doc
    spin = GyroCalibration.from_json((tmp_path / "s" / "run-01" / "calibration.json").read_text())
    np.testing.assert_allclose(cal.scale, spin.scale)  # the gain is the spin calibration's
    truth = json.loads((tmp_path / "s" / "run-01" / "recording" / "manifest.json").read_text())
    m = cal.temperature_model
    for T in np.linspace(*m.range_c, 5):
        st = m.at(T)
        assert np.all(np.abs(st.bias - truth_at(truth["truth"], T)["bias"])
                      <= 4 * st.bias_std)


def test_bad_sim_temperature_exits_2(capsys, tmp_path):
    for flag, value, what in (("--sim-temperature", "warm", "not numbers"),
                              ("--sim-self-heating", "4:x", "DT or DT:TAU")):
        code = main(["calibrate", "--sim", flag, value, "--out", str(tmp_path / "x"), "--quiet"])
        err = capsys.readouterr().err
        assert code == 2 and what in err and "Traceback" not in err


def test_a_thermal_model_is_not_a_calibration_point(warmup, capsys, tmp_path):
    root, _ = warmup
    code, out, _ = run_thermal(capsys, root / "cals", "--json")
    d = tmp_path / "mixed"
    d.mkdir()
    (d / "thermal.json").write_text(out)
    for i in range(4):
        (d / f"c{i}.json").write_text((root / "cals" / f"cal{i}.json").read_text())
    code, out2, _ = run_thermal(capsys, d, "--json")
    assert code == 0 and json.loads(out2)["temperature_model"]["points"] == 4
    code, _, err = run_thermal(capsys, d / "thermal.json", d / "c0.json")
    assert code == 2 and "is a thermal model" in err


def test_full_model_calibrations_give_a_matrix_model_that_holds_the_truth():
    """fit_calibrations on full-model calibrations (Calibration v2, lower-triangular frame):
    A(T) = A0 + A1 (T − 25) is fitted element by element, the entries the frame fixes at zero
    stay zero, and the thermal Calibration is a v2 document that round-trips. Each calibration
    is the truth at its temperature plus noise of its stated σ (seeded)."""
    from gyrocal.calib.model import GyroCalibration
    from gyrocal.kit.thermal import fit_calibrations, thermal_calibration

    rng = np.random.default_rng(13)
    a0 = np.array([[1.0132, 0.0, 0.0], [0.0187, 0.9871, 0.0], [-0.0164, 0.0119, 1.0043]])
    a1 = np.array([[3e-4, 0.0, 0.0], [1e-5, -2e-4, 0.0], [0.0, 0.0, 1e-4]])
    lower = np.tril(np.ones((3, 3), dtype=bool))
    a_std, b_std = np.where(lower, 5e-5, 0.0), np.full(3, 3e-5)
    temps = np.linspace(18.0, 30.0, 7)
    cals = []
    for t in temps:
        a = (a0 + a1 * (t - 25.0) + rng.normal(0.0, 1.0, (3, 3)) * a_std)
        b = truth_bias(t) + rng.normal(0.0, 1.0, 3) * b_std
        cals.append(GyroCalibration(
            scale=tuple(np.diag(a)), bias=tuple(b), bias_std=tuple(b_std),
            matrix=tuple(map(tuple, a)), matrix_std=tuple(map(tuple, a_std)), frame="gyro-x-xy",
            temperature_c=float(t), method="full-matrix"))
    model = fit_calibrations(cals)
    assert not model.diagonal and model.points == 7
    for t in np.linspace(18.0, 30.0, 5):
        st = model.at(t)
        want = a0 + a1 * (t - 25.0)
        assert np.all(np.abs(st.gain - want)[lower] <= 4 * st.gain_std[lower])
        assert np.all(st.gain[~lower] == 0.0)
        assert np.all(np.abs(st.bias - truth_bias(t)) <= 4 * st.bias_std)
    cal = thermal_calibration(cals, model, source="test")
    back = GyroCalibration.from_json(cal.to_json())
    assert back.is_full and back.temperature_model is not None
    np.testing.assert_allclose(back.temperature_model.at(21.0).gain, model.at(21.0).gain,
                               rtol=1e-12, atol=1e-15)


def test_the_scale_within_a_warming_run_is_that_at_its_turns_temperature_and_is_flagged(
        tmp_path):
    """A run whose die warms by 0.05 °C/s (about 1.5 °C over the run) with MPU-9250-sized scale
    coefficients (datasheet ±4 % over −40…85 °C: up to 6.4e-4 per °C): each axis's scale is the
    one at the mean temperature of its own servo's turns, not at the run's mean, which the
    independent generator's truth shows beyond the scale's σ; the estimate says so in a note.
    A run at a steady temperature gets no such note."""
    from gyrocal.kit.thermal import turn_temperature_offsets

    k = np.array([6.0e-4, -6.0e-4, 4.0e-4])
    flat = np.array([[0.01, 0.0], [-0.02, 0.0], [0.005, 0.0]])
    notes = {}
    for name, rate in (("warming", 0.05), ("steady", 0.0)):
        thermal = {"die": lambda t, r=rate: 20.0 + r * np.asarray(t), "t0": 0.0,
                   "bias_coeffs": flat, "scale_coeff": k}
        rec = load_recording(write_recording(tmp_path / name, scale=SCALE, thermal=thermal,
                                             seed=21, noise=0.002))
        est = estimate_recording(rec, "paired-axis")
        cal = est.calibration
        notes[name] = [n for n in est.notes if "drifts with the die temperature" in n]
        if name == "steady":
            continue
        off = turn_temperature_offsets(rec.imu_t, rec.imu_temp, est.extracted.windows,
                                       cal.temperature_c)
        assert off[1] < -0.3 and off[3] > 0.3  # servo 1 turns first, servo 3 last
        t_axis = cal.temperature_c + np.array([off[1], off[2], off[3]])
        at_turns = SCALE * (1.0 + k * (t_axis - 25.0))
        at_mean = SCALE * (1.0 + k * (cal.temperature_c - 25.0))
        std = np.asarray(cal.scale_std)
        assert np.all(np.abs(np.asarray(cal.scale) - at_turns) <= 4 * std)
        assert np.abs(cal.scale[0] - at_mean[0]) > 4 * std[0]  # the drift is beyond σ
    assert len(notes["warming"]) == 1 and "servo 1 -" in notes["warming"][0]
    assert notes["steady"] == []
