"""gyrocal export: the registry, kalibr and json."""

import json

import numpy as np
import pytest

from gyrocal.calib.allan import characterise_noise
from gyrocal.calib.model import GyroCalibration
from gyrocal.calib.noise_sim import NoiseModel, simulate_still
from gyrocal.kit.cli import main
from gyrocal.kit.errors import InputError
from gyrocal.kit.exports import EXPORTERS, Exporter, export, register


@pytest.fixture(scope="module")
def noise_doc():
    s = simulate_still(np.random.default_rng(8), 900.0,
                       model=NoiseModel(noise_density=(1e-4, 2e-4, 1.5e-4), rate_random_walk=2e-5))
    return characterise_noise(s.rate, 200.0).with_meta(source="simulation").to_dict()


@pytest.fixture
def files(tmp_path, noise_doc):
    n = tmp_path / "noise.json"
    n.write_text(json.dumps(noise_doc))
    c = tmp_path / "cal.json"
    c.write_text(GyroCalibration(scale=(1, 1, 1), bias=(0.01, 0, 0)).to_json())
    return n, c


def parse_yaml_scalars(text):
    out = {}
    for line in text.splitlines():
        if line and not line.startswith("#"):
            k, v = line.split(":", 1)
            out[k.strip()] = v.strip()
    return out


def test_kalibr_fields_units_and_values(files, noise_doc, capsys):
    n, _ = files
    assert main(["export", str(n), "--format", "kalibr", "--rostopic", "/imu/data"]) == 0
    out, err = capsys.readouterr()
    y = parse_yaml_scalars(out)
    assert set(y) == {"accelerometer_noise_density", "accelerometer_random_walk",
                      "gyroscope_noise_density", "gyroscope_random_walk", "rostopic",
                      "update_rate"}
    # Kalibr takes one figure per sensor: the largest axis of the document, which is the
    # simulated sensor's (N = 1e-4, 2e-4, 1.5e-4 rad/s/sqrt(Hz); K = 2e-5 rad/s/sqrt(s)).
    n_kalibr, k_kalibr = float(y["gyroscope_noise_density"]), float(y["gyroscope_random_walk"])
    assert n_kalibr == pytest.approx(max(noise_doc["noise_density"]["value"]), rel=1e-6)
    assert n_kalibr == pytest.approx(2e-4, rel=0.03)
    assert k_kalibr == pytest.approx(max(noise_doc["rate_random_walk"]["value"]), rel=1e-6)
    assert 2e-5 / 2 < k_kalibr < 2e-5 * 2
    assert y["rostopic"] == "/imu/data" and float(y["update_rate"]) == 200.0
    assert "rad/s/sqrt(Hz)" in out and "rad/s^2/sqrt(Hz)" in out
    assert "NOT MEASURED" in out and "is a placeholder" in err
    assert float(y["accelerometer_noise_density"]) > 0


def test_kalibr_takes_the_upper_bound_of_an_unresolved_random_walk(tmp_path, noise_doc, capsys):
    doc = json.loads(json.dumps(noise_doc))
    k = doc["rate_random_walk"]
    k["value"][1] = 0.0  # this record did not resolve K on y
    k["hi95"][1] = 10 * max(k["value"])
    p = tmp_path / "noise.json"
    p.write_text(json.dumps(doc))
    assert main(["export", str(p), "--format", "kalibr"]) == 0
    out = capsys.readouterr().out
    assert float(parse_yaml_scalars(out)["gyroscope_random_walk"]) == pytest.approx(k["hi95"][1])
    assert "not resolved on axis y" in out


def test_kalibr_with_accelerometer_figures(files, capsys):
    n, _ = files
    assert main(["export", str(n), "--format", "kalibr", "--accel-noise-density", "2e-3",
                 "--accel-random-walk", "3e-4"]) == 0
    out, err = capsys.readouterr()
    y = parse_yaml_scalars(out)
    assert float(y["accelerometer_noise_density"]) == 2e-3
    assert "NOT MEASURED" not in out and "placeholder" not in err


def test_json_reemits_either_document(files, noise_doc, capsys):
    n, c = files
    assert main(["export", str(n), "--format", "json"]) == 0
    assert json.loads(capsys.readouterr().out) == noise_doc
    assert main(["export", str(c), "--format", "json"]) == 0
    assert json.loads(capsys.readouterr().out)["format"] == "gyrocal-calibration"


def test_kind_is_checked_against_the_format(files, capsys):
    n, _ = files
    assert main(["export", str(n), "--format", "yaml"]) == 2
    assert "takes a gyrocal-calibration document, not gyrocal-noise" in capsys.readouterr().err


def test_option_of_another_format_is_refused(files, capsys):
    n, _ = files
    assert main(["export", str(n), "--format", "json", "--rostopic", "/x"]) == 2
    assert "--rostopic does not apply to --format json" in capsys.readouterr().err


def test_out_is_atomic_and_refuses_to_overwrite(files, tmp_path, capsys):
    n, _ = files
    out = tmp_path / "imu.yaml"
    assert main(["export", str(n), "--format", "kalibr", "--out", str(out)]) == 0
    first = out.read_text()
    assert "gyroscope_noise_density" in first
    assert main(["export", str(n), "--format", "kalibr", "--out", str(out),
                 "--rostopic", "/other"]) == 2
    assert out.read_text() == first
    assert main(["export", str(n), "--format", "kalibr", "--out", str(out), "--force",
                 "--rostopic", "/other"]) == 0
    assert "/other" in out.read_text()


@pytest.mark.parametrize(
    "content, match",
    [
        ("not json", "not valid JSON"),
        ('{"format": "something-else"}', "gyrocal exports"),
        ('{"format": "gyrocal-noise", "version": 7}', "version 7 is not supported"),
        ('{"format": "gyrocal-calibration", "version": 1, "scale": [1, 1]}', "scale"),
    ],
)
def test_bad_documents_are_named(tmp_path, capsys, content, match):
    p = tmp_path / "doc.json"
    p.write_text(content)
    assert main(["export", str(p), "--format", "json"]) == 2
    assert match in capsys.readouterr().err


def test_registry_is_extensible():
    def render(doc, options):
        return f"bias {doc['bias']}\n", []

    ex = register(Exporter("test-bias", ("gyrocal-calibration",), "a test format", render))
    try:
        assert EXPORTERS["test-bias"] is ex
        doc = GyroCalibration(scale=(1, 1, 1), bias=(0.1, 0.2, 0.3)).to_dict()
        assert export(doc, "test-bias") == ("bias [0.1, 0.2, 0.3]\n", [])
        with pytest.raises(ValueError, match="already registered"):
            register(ex)
        with pytest.raises(InputError, match="unknown export format"):
            export(doc, "nope")
    finally:
        del EXPORTERS["test-bias"]


@pytest.mark.parametrize("fmt", ["yaml", "c-header"])
def test_the_files_say_the_verdict_of_the_dispersion_rule(fmt, tmp_path, capsys):
    """A fit whose σ were widened by excess scatter says so in the exported file (the words of
    Consistency.verdict, in ASCII), not 'consistent with the measured noise' from ok alone."""
    from gyrocal.calib.model import Consistency, GyroCalibration

    widened = Consistency(60.0, 42, 0.03, True, excess=0.2, scatter=2e-5, reason="")
    cal = tmp_path / "cal.json"
    cal.write_text(GyroCalibration(scale=(1.0, 1.0, 1.0), bias=(0.0, 0.0, 0.0),
                                   scale_std=(1e-4,) * 3, bias_std=(1e-4,) * 3,
                                   consistency=widened).to_json())
    assert main(["export", str(cal), "--format", fmt]) == 0
    out = capsys.readouterr().out
    assert "consistent, with 20 % scatter beyond the noise (sigma widened)" in out
    assert "with the measured noise)" not in out
