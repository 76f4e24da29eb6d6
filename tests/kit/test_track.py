"""gyrocal track: replay of a Recording v1 against the simulated truth, and --sim."""

import json
import sys

import numpy as np
import pytest

from gyrocal.calib.noise_sim import NoiseModel, sim_calibration, simulate_session
from gyrocal.kit.cli import main
from tests.kit.simrec import write_session

MODEL = NoiseModel(rate_random_walk=1e-5)


@pytest.fixture(scope="module")
def random_rec(tmp_path_factory):
    """A 150 s simulated session (30,000 samples) and its calibration, replayed by the tests
    below. It was 300 s; the checks hold with the same margins on half of it (300 s -> 150 s):
    every sample within 3 sigma in every replay; the smoothed RMS 0.555 -> 0.491 of the causal;
    the late still mean 2.7e-5 -> 2.3e-5 from the readings (atol 2e-4); without a calibration
    the last bias 1.0e-4 -> 8.5e-5 off (< 1e-3); the stale calibration's move 1.6e-4 -> 4.2e-4
    off (atol 2e-3), its late bias 1.8e-4 -> 1.3e-4 (< 1e-3)."""
    d = tmp_path_factory.mktemp("track")
    s = simulate_session(np.random.default_rng(21), 150.0, model=MODEL)
    rec = write_session(d / "rec", s)
    cal = sim_calibration(np.random.default_rng(22), s)
    (d / "cal.json").write_text(cal.to_json())
    return s, rec, d / "cal.json"


def run_json(capsys, *argv):
    code = main(["track", *argv, "--json"])
    out, err = capsys.readouterr()
    assert code == 0, err
    return json.loads(out), err


def test_json_document_per_sample_in_calibration_sign_convention(random_rec, capsys):
    s, rec, cal = random_rec
    doc, err = run_json(capsys, str(rec), "--cal", str(cal), "--tempco",
                        "--noise-density", "1.75e-4", "--rate-random-walk", "1e-5")
    assert set(doc) == {"t", "bias", "bias_std", "still"}
    n = s.n
    assert len(doc["t"]) == len(doc["bias"]) == len(doc["bias_std"]) == len(doc["still"]) == n
    bias, std = np.array(doc["bias"]), np.array(doc["bias_std"])
    assert bias.shape == (n, 3) and std.shape == (n, 3)
    np.testing.assert_allclose(doc["t"], s.t, atol=1e-9)
    # The truth is in the Calibration v1 convention (m = g/k - b): the tracked bias matches it,
    # i.e. bias = -(mean still reading), not +.
    z = (bias - s.true_bias) / std
    assert np.all(np.mean(np.abs(z) <= 3, axis=0) > 0.99)
    still = np.array(doc["still"])
    assert still.any() and not np.any(still & ~s.still)
    late = still & (s.t > 100)
    np.testing.assert_allclose(bias[late].mean(0), -s.rate[late].mean(0), atol=2e-4)


@pytest.fixture(scope="module")
def cal_only(random_rec):
    """``(document, stderr)`` of ``gyrocal track REC --cal CAL --json`` (nothing else given:
    the smoothed replay with the noise estimated), read by two tests below."""
    import contextlib
    import io

    _, rec, cal = random_rec
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main(["track", str(rec), "--cal", str(cal), "--json"])
    assert code == 0, err.getvalue()
    return json.loads(out.getvalue()), err.getvalue()


def test_defaults_without_noise_flags_still_track(random_rec, cal_only):
    s, _, _ = random_rec
    doc, err = cal_only
    assert "noise density estimated" in err
    assert "bias random walk estimated from the innovations" in err
    assert "temperature coefficient" in err  # on by default: the recording has temperatures
    bias, std = np.array(doc["bias"]), np.array(doc["bias_std"])
    z = (bias - s.true_bias) / std
    # nothing given but the calibration: the estimated random walk keeps the band honest
    assert np.all(np.mean(np.abs(z) <= 3, axis=0) > 0.99)


def test_replay_is_smoothed_unless_causal(random_rec, cal_only, capsys):
    # A whole recording is at hand: the smoothed estimate (default) must beat the causal
    # filter's against the simulated truth, with a band that still holds it.
    s, rec, cal = random_rec
    smooth, _ = cal_only
    causal, _ = run_json(capsys, str(rec), "--cal", str(cal), "--causal")
    rms = {}
    for name, doc in (("smooth", smooth), ("causal", causal)):
        e = np.array(doc["bias"]) - s.true_bias
        rms[name] = float(np.sqrt(np.mean(e**2)))
        assert np.mean(np.abs(e) <= 3 * np.array(doc["bias_std"])) > 0.99, name
    assert rms["smooth"] < 0.8 * rms["causal"], rms
    # the smoothed band is narrower on average (information from after each sample)
    assert np.mean(smooth["bias_std"]) < np.mean(causal["bias_std"])


def test_without_calibration_starts_from_the_first_still_second(random_rec, capsys):
    s, rec, _ = random_rec
    doc, err = run_json(capsys, str(rec))
    assert "no --cal" in err
    bias = np.array(doc["bias"])
    assert np.all(np.abs(bias[-1] - s.true_bias[-1]) < 1e-3)


def test_still_from_segments(tmp_path, capsys):
    # A jig session: the recording's rest segments say when the sensor was still.
    s = simulate_session(np.random.default_rng(26), 150.0, model=MODEL, motion="jig")
    rec = write_session(tmp_path / "rec", s)
    (tmp_path / "cal.json").write_text(sim_calibration(np.random.default_rng(27), s).to_json())
    doc, _ = run_json(capsys, str(rec), "--cal", str(tmp_path / "cal.json"), "--still",
                      "segments", "--tempco", "--no-reference")
    still = np.array(doc["still"])
    assert still.sum() > 0.5 * s.still.sum() and not np.any(still & ~s.still)
    z = (np.array(doc["bias"]) - s.true_bias) / np.array(doc["bias_std"])
    assert np.all(np.mean(np.abs(z) <= 3, axis=0) > 0.98)


def test_reference_rates_from_the_encoders(tmp_path, capsys):
    # Rests too short for the detector: only the servo turns (encoder rate about the axes the
    # calibration knows) can keep the bias right.
    s = simulate_session(np.random.default_rng(23), 240.0, model=MODEL, motion="jig",
                         still_s=(0.3, 0.5), motion_s=(5.0, 8.0))
    rec = write_session(tmp_path / "rec", s)
    calib = sim_calibration(np.random.default_rng(24), s)
    doc = calib.to_dict()
    for v in doc["axes"].values():
        v["std_deg"] = 1e-3
    (tmp_path / "cal.json").write_text(json.dumps(doc))
    common = [str(rec), "--cal", str(tmp_path / "cal.json"), "--tempco",
              "--noise-density", "1.75e-4", "--rate-random-walk", "1e-5"]
    assert main(["track", *common]) == 0
    text = capsys.readouterr().out
    assert "reference-rate" in text and " 0 reference-rate" not in text
    with_ref, _ = run_json(capsys, *common)
    without, _ = run_json(capsys, *common, "--no-reference")
    e_ref = np.sqrt(np.mean((np.array(with_ref["bias"]) - s.true_bias) ** 2, axis=0))
    e_none = np.sqrt(np.mean((np.array(without["bias"]) - s.true_bias) ** 2, axis=0))
    assert np.all(e_ref < 0.5 * e_none), (e_ref, e_none)
    z = (np.array(with_ref["bias"]) - s.true_bias) / np.array(with_ref["bias_std"])
    assert np.all(np.mean(np.abs(z) <= 3, axis=0) > 0.99)


def test_sim_text_and_plot(tmp_path, capsys):
    png = tmp_path / "bias.png"
    assert main(["track", "--sim", "--duration", "120", "--tempco", "--step-at", "60",
                 "--plot", str(png)]) == 0
    out = capsys.readouterr().out
    assert "vs truth" in out and "NIS alarm(s) at t = 6" in out
    assert png.stat().st_size > 10_000
    # an existing plot is refused up front (nothing tracked), and replaced with --force
    first = png.read_bytes()
    argv = ["track", "--sim", "--duration", "30", "--plot", str(png)]
    assert main(argv) == 2
    out, err = capsys.readouterr()
    assert "--force" in err and out == "" and png.read_bytes() == first
    assert main([*argv, "--force"]) == 0
    assert png.read_bytes() != first
    assert [p.name for p in tmp_path.iterdir()] == ["bias.png"]  # no temporary file left


def test_plot_without_matplotlib_says_what_to_install(random_rec, tmp_path, capsys, monkeypatch):
    s, rec, cal = random_rec
    monkeypatch.setitem(sys.modules, "matplotlib", None)
    code = main(["track", str(rec), "--cal", str(cal), "--plot", str(tmp_path / "x.png")])
    assert code == 2
    assert "pip install 'gyrocal[plot]'" in capsys.readouterr().err


def test_out_file_is_atomic_and_not_overwritten(random_rec, tmp_path, capsys):
    s, rec, cal = random_rec
    out = tmp_path / "track.json"
    assert main(["track", str(rec), "--cal", str(cal), "--out", str(out)]) == 0
    assert set(json.loads(out.read_text())) == {"t", "bias", "bias_std", "still"}
    capsys.readouterr()
    assert main(["track", str(rec), "--cal", str(cal), "--out", str(out)]) == 2
    assert "--force" in capsys.readouterr().err


@pytest.mark.parametrize(
    "argv, match",
    [
        ([], "RECORDING or --sim"),
        (["--sim", "."], "RECORDING or --sim"),  # an existing directory with --sim
        (["--sim", "--causal"], "--causal applies to a recording"),
        (["{rec}", "--cal", "{missing}"], "does not exist"),
        (["{rec}", "--update-interval", "0"], "update_interval_s"),
        (["{rec}", "--noise", "{rec}/manifest.json"], "not a gyrocal noise document"),
    ],
)
def test_bad_usage_exits_2_with_a_message(random_rec, tmp_path, capsys, argv, match):
    _, rec, _ = random_rec
    argv = [a.format(rec=rec, missing=tmp_path / "nope.json") for a in argv]
    assert main(["track", *argv]) == 2
    assert match in capsys.readouterr().err


def test_tempco_needs_temperatures(tmp_path, capsys):
    s = simulate_session(np.random.default_rng(25), 30.0, model=MODEL)
    rec = write_session(tmp_path / "rec", s, temperature=False)
    assert main(["track", str(rec), "--tempco"]) == 2
    assert "--tempco needs a temperature" in capsys.readouterr().err


def test_json_decimates_on_request_and_on_long_sessions_and_says_so(random_rec, capsys,
                                                                    monkeypatch):
    s, rec, cal = random_rec
    import gyrocal.kit.commands.track as cmd

    # the 150 s session (30,000 samples) is a long one once JSON_MAX_ROWS is 1000
    monkeypatch.setattr(cmd, "JSON_MAX_ROWS", 1000)
    common = [str(rec), "--cal", str(cal), "--rate-random-walk", "1e-5"]
    # --every 0: every row all the same, the reference for the decimated rows below
    full, err = run_json(capsys, *common, "--every", "0")
    assert "decimated" not in err and len(full["t"]) == s.n
    doc, err = run_json(capsys, *common, "--every", "2")
    assert "decimated to one row every 2 s" in err and doc["decimated_every_s"] == 2.0
    assert len(doc["t"]) == 75
    # each row is the full document's row at the same sample
    idx = np.searchsorted(full["t"], doc["t"])
    np.testing.assert_allclose(np.array(full["bias"])[idx], doc["bias"], rtol=0, atol=0)
    # still: true when any sample of the interval was still
    fs = np.array(full["still"])
    assert doc["still"][0] == bool(fs[: idx[0] + 1].any())
    # long sessions are decimated by default, and say so
    doc, err = run_json(capsys, *common)
    assert "decimated" in err and 500 < len(doc["t"]) <= 1000
    assert main(["track", str(rec), "--every", "-1"]) == 2
    assert "--every must be" in capsys.readouterr().err


def test_a_stale_calibration_is_said_on_stderr_and_in_the_json(random_rec, tmp_path, capsys):
    """A calibration whose bias is 20 mrad/s off (0.6 deg/s: a power cycle's worth on an
    MPU-9250) while claiming its fit's sigma: track follows the sensor from the first rest and
    says how far the bias moved (issue 30), in the notes and as bias_moved in --json."""
    from dataclasses import replace

    from gyrocal.calib.model import GyroCalibration

    s, rec, cal_path = random_rec
    cal = GyroCalibration.from_json(cal_path.read_text())
    off = np.array([0.02, -0.02, 0.02])
    stale = tmp_path / "stale.json"
    stale.write_text(replace(cal, bias=tuple(np.asarray(cal.bias) + off)).to_json())
    doc, err = run_json(capsys, str(rec), "--cal", str(stale), "--rate-random-walk", "1e-5",
                        "--causal", "--every", "1")
    assert "the bias moved by" in err and "recalibrate" in err
    moved = doc["bias_moved"]
    assert moved["axes"] == ["x", "y", "z"]
    np.testing.assert_allclose(moved["moved"], -off, atol=2e-3)
    i = np.searchsorted(s.t, np.array(doc["t"]) - 1e-9)
    late = s.t[i] > 60  # the causal estimate, long after the first rest
    assert np.all(np.abs(np.array(doc["bias"])[late] - s.true_bias[i][late]) < 1e-3)
