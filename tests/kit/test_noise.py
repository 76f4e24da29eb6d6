"""gyrocal noise: figures from --sim and from a still Recording v1."""

import json

import numpy as np
import pytest

from gyrocal.calib.noise_sim import NoiseModel, simulate_still
from gyrocal.kit.cli import main
from tests.kit.simrec import write_session


def test_sim_json_recovers_the_simulated_density(capsys):
    assert main(["noise", "--sim", "--duration", "600", "--json", "--seed", "3"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["format"] == "gyrocal-noise" and doc["version"] == 1
    nd = doc["noise_density"]
    assert all(lo <= 1.75e-4 <= hi for lo, hi in zip(nd["lo95"], nd["hi95"], strict=True))
    assert doc["sensor"]["model"] == "simulated" and doc["odr_hz"] == 200.0


def test_text_output_out_file_and_plot(tmp_path, capsys):
    out, png = tmp_path / "noise.json", tmp_path / "adev.png"
    assert main(["noise", "--sim", "--duration", "300", "--out", str(out),
                 "--plot", str(png)]) == 0
    text = capsys.readouterr().out
    assert "N rad/s/sqrt(Hz)" in text and "true  N 1.7500e-04" in text
    assert json.loads(out.read_text())["format"] == "gyrocal-noise"
    assert png.stat().st_size > 10_000
    assert main(["noise", "--sim", "--duration", "300", "--out", str(out)]) == 2
    assert "--force" in capsys.readouterr().err
    # the plot is not overwritten without --force either, and the refusal comes first
    out.unlink()
    first = png.read_bytes()
    assert main(["noise", "--sim", "--duration", "300", "--out", str(out),
                 "--plot", str(png)]) == 2
    assert "--force" in capsys.readouterr().err
    assert png.read_bytes() == first and not out.exists()
    assert main(["noise", "--sim", "--duration", "300", "--seed", "1", "--plot", str(png),
                 "--force"]) == 0
    assert png.read_bytes() != first


def test_from_a_still_recording(tmp_path, capsys):
    model = NoiseModel(noise_density=(1e-4, 2e-4, 3e-4), rate_random_walk=1e-5)
    s = simulate_still(np.random.default_rng(5), 600.0, model=model)
    rec = write_session(tmp_path / "rec", s)
    assert main(["noise", str(rec), "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["source"] == str(rec)
    np.testing.assert_allclose(doc["noise_density"]["value"], [1e-4, 2e-4, 3e-4], rtol=0.03)
    assert doc["temperature_c"] == pytest.approx(25.0)


def test_gaps_are_refused_with_the_time(tmp_path, capsys):
    s = simulate_still(np.random.default_rng(6), 120.0)
    rec = write_session(tmp_path / "rec", s)
    p = rec / "imu.csv"
    lines = p.read_text().split("\n")
    del lines[5001:5051]  # 50 samples lost at t = 25 s
    p.write_text("\n".join(lines))
    assert main(["noise", str(rec)]) == 2
    err = capsys.readouterr().err
    assert "gap" in err and "t=24.99" in err


def test_needs_a_source(capsys):
    assert main(["noise"]) == 2
    assert "RECORDING or --sim" in capsys.readouterr().err


def test_a_recording_is_streamed_with_the_figures_of_the_whole_array(tmp_path, capsys,
                                                                     monkeypatch):
    """noise reads the recording block by block into a phase file; its curve and figures equal
    those of the whole record in memory (calib.allan on load_recording's arrays)."""
    from gyrocal.calib.allan import characterise_noise
    from gyrocal.kit import recording, still

    model = NoiseModel(noise_density=2e-4, rate_random_walk=1e-5)
    s = simulate_still(np.random.default_rng(8), 700.0, model=model)  # 140 000 samples
    rec = write_session(tmp_path / "rec", s)
    monkeypatch.setattr(recording, "BLOCK_BYTES", 1 << 16)  # many blocks
    monkeypatch.setattr(still, "PERIOD_SAMPLES", 140_000)  # the median of every interval
    assert main(["noise", str(rec), "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    whole = recording.load_recording(rec)
    odr = 1.0 / float(np.median(np.diff(whole.imu_t)))
    ref = characterise_noise(whole.imu_rate, odr)
    assert doc["n_samples"] == whole.imu_t.size and doc["odr_hz"] == odr
    np.testing.assert_allclose(doc["allan"]["adev"], ref.adev, rtol=1e-12)
    np.testing.assert_allclose(doc["noise_density"]["value"], ref.noise_density.value,
                               rtol=1e-10)
    assert doc["temperature_c"] == pytest.approx(float(np.mean(whole.imu_temp)), rel=1e-12)


def test_a_gap_in_a_later_block_and_a_record_too_short_are_refused(tmp_path, capsys,
                                                                   monkeypatch):
    from gyrocal.kit import recording

    monkeypatch.setattr(recording, "BLOCK_BYTES", 1 << 14)
    s = simulate_still(np.random.default_rng(6), 120.0)
    rec = write_session(tmp_path / "rec", s)
    p = rec / "imu.csv"
    lines = p.read_text().split("\n")
    del lines[20001:20003]  # two samples lost at t = 100 s, far past the first block
    p.write_text("\n".join(lines))
    assert main(["noise", str(rec)]) == 2
    err = capsys.readouterr().err
    assert "gap" in err and "t=99.99" in err and "Traceback" not in err
    del lines[40:]
    p.write_text("\n".join(lines) + "\n")
    assert main(["noise", str(rec)]) == 2
    assert "only 39 samples to analyse" in capsys.readouterr().err


def test_a_recording_in_degrees_per_second_is_refused_by_noise_and_flagged_by_track(
        tmp_path, capsys):
    """An MPU-9250's white noise (0.01 °/s/√Hz, its datasheet's typical) written in °/s where
    rad/s belong: before, `noise` printed N 57× too big without a word and `track` tracked it;
    now `noise` refuses (exit 6, as `estimate` refuses an implausible calibration) unless
    --allow-implausible, and `track` says so in its notes."""
    model = NoiseModel(noise_density=0.01, rate_random_walk=1e-5)  # °/s/√Hz read as rad/s/√Hz
    s = simulate_still(np.random.default_rng(7), 120.0, model=model)
    rec = write_session(tmp_path / "rec", s)
    assert main(["noise", str(rec)]) == 6
    err = capsys.readouterr().err
    assert "look like °/s" in err and "--allow-implausible" in err
    assert main(["noise", str(rec), "--allow-implausible"]) == 0
    assert "look like °/s" in capsys.readouterr().err
    assert main(["track", str(rec)]) == 0
    out = capsys.readouterr()
    assert "look like °/s" in out.out + out.err
    # the same sensor in rad/s is accepted without a word
    rad = simulate_still(np.random.default_rng(7), 120.0,
                         model=NoiseModel(noise_density=1.75e-4, rate_random_walk=1e-5))
    assert main(["noise", str(write_session(tmp_path / "rad", rad))]) == 0
    assert "°/s" not in capsys.readouterr().err
