"""gyrocal export --format yaml | ros | c-header: parse back, compile, and agree with the model."""

import json
import re
import subprocess

import numpy as np
import pytest

from gyrocal.calib.allan import characterise_noise
from gyrocal.calib.model import Consistency, GyroCalibration
from gyrocal.calib.noise_sim import NoiseModel, simulate_still
from gyrocal.kit.cli import main
from tests.kit.c_program import compile_program, needs_gcc


def make_calibration():
    """A calibration with every field, negative and tiny values, and awkward text."""
    rng = np.random.default_rng(5)
    a = rng.normal(size=(6, 6)) * 1e-5
    cov = a @ a.T + np.diag([2e-9, 1.4e-9, 1.1e-9, 1.7e-9, 1.8e-9, 2.0e-9])
    return GyroCalibration(
        scale=(1.0548037913894537, 0.9078745066818625, 1.0),
        bias=(-0.001616135137143091, 0.0812908993764018, 1e-05),
        scale_std=tuple(np.sqrt(np.diag(cov)[:3])),
        bias_std=tuple(np.sqrt(np.diag(cov)[3:])),
        covariance=tuple(map(tuple, cov)),
        method="paired-axis",
        iterations=3,
        consistency=Consistency(chi2=23.7, dof=27, p_value=0.646, ok=True),
        sensor={"model": "mpu9250", "odr_hz": 200.0, "full_scale_dps": 500.0,
                "sensitivity_rad_s_per_lsb": 0.00026646248122050834},
        temperature_c=24.9986,
        created="2026-11-21T08:22:46+00:00",
        source='C:\\runs\\"jig #2" */ yes: no',
        axes={"1": {"axis": [0.9993, 0.0166, -0.0321], "misalignment_deg": 2.07,
                    "nearest": "+x", "std_deg": 0.0011}},
    )


@pytest.fixture(scope="module")
def cal():
    return make_calibration()


@pytest.fixture
def cal_file(tmp_path, cal):
    p = tmp_path / "cal.json"
    p.write_text(cal.to_json())
    return p


def export_text(capsys, path, fmt, *options):
    code = main(["export", str(path), "--format", fmt, *options])
    out, err = capsys.readouterr()
    assert code == 0, err
    return out, err


# ------------------------------------------------------------------ a tiny YAML reader
def _value(text):
    """A flow value as the exporters write it: JSON syntax (YAML 1.2 is a superset of JSON)."""
    return json.loads(text)


def _key(text):
    return json.loads(text) if text.startswith('"') else text


def parse_yaml(text):
    """Block mappings by indentation, ``- [..]`` sequences and JSON flow values; comment lines
    skipped. Enough for the fixed structures the exporters write, and strict about the rest."""
    rows = []
    for line in text.splitlines():
        body = line.lstrip(" ")
        if not body or body.startswith("#"):
            continue
        assert "\t" not in line, f"tab in YAML: {line!r}"
        rows.append((len(line) - len(body), body))

    def block(i, indent):
        if rows[i][1].startswith("- "):
            seq = []
            while i < len(rows) and rows[i][0] == indent and rows[i][1].startswith("- "):
                seq.append(_value(rows[i][1][2:]))
                i += 1
            return seq, i
        out = {}
        while i < len(rows) and rows[i][0] == indent:
            body = rows[i][1]
            m = re.match(r'("(?:[^"\\]|\\.)*"|[A-Za-z_][A-Za-z0-9_]*):( (.*))?$', body)
            assert m, f"not a 'key: value' line: {body!r}"
            key = _key(m.group(1))
            assert key not in out, f"duplicate key {key!r}"
            if m.group(3) is not None:
                out[key] = _value(m.group(3))
                i += 1
            else:
                assert i + 1 < len(rows) and rows[i + 1][0] > indent, f"empty value: {body!r}"
                out[key], i = block(i + 1, rows[i + 1][0])
        return out, i

    doc, end = block(0, 0)
    assert end == len(rows), f"unparsed line: {rows[end][1]!r}"
    return doc


def yaml11_floats_ok(text):
    """Every number outside comments reads as a float in YAML 1.1 (PyYAML, ROS 1) too: an
    exponent needs a decimal point there (``1e-05`` would be a string)."""
    body = "\n".join(line for line in text.splitlines() if not line.lstrip().startswith("#"))
    body = re.sub(r'"(?:[^"\\]|\\.)*"', '""', body)  # drop strings
    bad = [t for t in re.findall(r"-?[0-9][0-9.]*[eE][-+]?[0-9]+", body) if "." not in t]
    return not bad


# ------------------------------------------------------------------ yaml
def test_yaml_parses_back_to_the_same_calibration(cal, cal_file, capsys):
    out, _ = export_text(capsys, cal_file, "yaml")
    doc = parse_yaml(out)
    assert doc == cal.to_dict()  # every field, floats exact
    back = GyroCalibration.from_dict(doc)
    np.testing.assert_array_equal(back.apply([0.3, -1.2, 2.0]), cal.apply([0.3, -1.2, 2.0]))
    assert yaml11_floats_ok(out)
    assert "g = scale * (m + bias)" in out and "rad/s" in out and "dimensionless" in out
    assert "# biases, rad/s" in out


def test_yaml_checker_is_not_vacuous():
    assert not yaml11_floats_ok("a: [1e-05]")
    assert yaml11_floats_ok("a: [1.0e-05]\n# 1e-05 in a comment")


# ------------------------------------------------------------------ ros
def test_ros_parameters_structure_and_values(cal, cal_file, capsys):
    out, _ = export_text(capsys, cal_file, "ros", "--frame-id", "gyro_link")
    doc = parse_yaml(out)
    assert list(doc) == ["gyro_calibration"]
    p = doc["gyro_calibration"]
    assert p["frame_id"] == "gyro_link"
    assert p["model"] == "omega = scale * (omega_raw + bias)" and p["bias_convention"] == "add"
    assert p["units"] == "rad/s"
    assert p["scale"] == list(cal.scale) and p["bias"] == list(cal.bias)
    assert p["scale_std"] == list(cal.scale_std) and p["bias_std"] == list(cal.bias_std)
    assert p["parameter_covariance"] == [x for row in cal.covariance for x in row]  # row-major
    assert p["sensor_model"] == "mpu9250" and p["consistent"] is True
    assert p["source"] == cal.source
    assert yaml11_floats_ok(out)
    # ROS 2 parameter files take no nulls, and a double array must not hold an integer
    for v in p.values():
        assert v is not None
        if isinstance(v, list):
            assert all(isinstance(x, float) for x in v)
    assert "ADDED to the raw reading" in out and "must subtract -bias" in out


def test_ros2_parameters_file_for_a_node(cal, cal_file, capsys):
    out, _ = export_text(capsys, cal_file, "ros", "--ros-node", "imu_filter")
    doc = parse_yaml(out)
    p = doc["imu_filter"]["ros__parameters"]["gyro_calibration"]
    assert p["frame_id"] == "imu_link" and p["bias"] == list(cal.bias)


def test_ros_leaves_out_missing_uncertainties_and_says_so(tmp_path, capsys):
    p = tmp_path / "bare.json"
    p.write_text(GyroCalibration(scale=(1, 1, 1), bias=(0.01, -0.02, 0.0)).to_json())
    out, err = export_text(capsys, p, "ros")
    params = parse_yaml(out)["gyro_calibration"]
    assert "bias_std" not in params and "covariance" not in params
    assert params["scale"] == [1.0, 1.0, 1.0]
    assert "no scale_std, bias_std, parameter_covariance" in err


@pytest.mark.parametrize("flags, match", [
    (["--frame-id", "imu link"], "--frame-id"),
    (["--ros-node", "bad node!"], "--ros-node"),
])
def test_ros_bad_options_exit_2(cal_file, capsys, flags, match):
    assert main(["export", str(cal_file), "--format", "ros", *flags]) == 2
    assert match in capsys.readouterr().err


# ------------------------------------------------------------------ c-header
C_PROGRAM = r"""
#include <stdio.h>
#include <stdlib.h>
#include "cal.h"
#include "cal.h" /* the include guard makes a second inclusion harmless */
#include "other.h"

int main(int argc, char **argv)
{
    float m[3], g[3], h[3];
    int i;
    if (argc != 4) return 2;
    for (i = 0; i < 3; ++i) m[i] = strtof(argv[i + 1], NULL);
    gyrocal_apply(m, g);
    other_apply(m, h);
    gyrocal_apply(m, m); /* in place */
    for (i = 0; i < 3; ++i)
        printf("%.9e %.9e %.9e\n", (double)g[i], (double)m[i], (double)h[i]);
    return 0;
}
"""


@needs_gcc
def test_c_header_compiles_and_matches_the_model(cal, cal_file, tmp_path, capsys):
    out, _ = export_text(capsys, cal_file, "c-header")
    other = GyroCalibration(scale=(0.5, 2.0, 1.25), bias=(0.25, -0.125, 3.0))
    (tmp_path / "other.json").write_text(other.to_json())
    out2, _ = export_text(capsys, tmp_path / "other.json", "c-header", "--c-prefix", "other")
    assert "OTHER_CALIBRATION_H" in out2
    (tmp_path / "other.h").write_text(out2)
    compile_program(tmp_path, out, C_PROGRAM)
    m = np.array([1.3, -2.1, 0.7])
    run = subprocess.run([str(tmp_path / "apply"), *(repr(float(x)) for x in m)],
                         capture_output=True, text=True, check=True)
    res = np.array([[float(x) for x in line.split()] for line in run.stdout.splitlines()])
    m32 = m.astype(np.float32).astype(float)  # the program reads the reading as a float
    np.testing.assert_allclose(res[:, 0], cal.apply(m32), rtol=1e-6)
    np.testing.assert_allclose(res[:, 1], cal.apply(m32), rtol=1e-6)
    np.testing.assert_allclose(res[:, 2], other.apply(m32), rtol=1e-6)
    # a wrong model would not pass: g = k*m + b differs by far more than the tolerance
    wrong = np.asarray(cal.scale) * m32 + np.asarray(cal.bias)
    assert np.max(np.abs(res[:, 0] - wrong) / np.abs(wrong)) > 1e-4


def test_c_header_states_model_units_stds_and_provenance(cal, cal_file, capsys):
    out, _ = export_text(capsys, cal_file, "c-header")
    assert "g[i] = k[i] * (m[i] + b[i])" in out and "rad/s" in out
    assert "#ifndef GYROCAL_CALIBRATION_H" in out and out.rstrip().endswith("*/")
    assert re.search(r"#define GYROCAL_BIAS_X \(-0\.00161613514f\) /\* rad/s, std ", out)
    assert "#define GYROCAL_SCALE_Z 1.0f" in out  # a float literal, not the integer 1
    assert "#define GYROCAL_BIAS_Z 1e-05f" in out
    for a, s in zip("xyz", cal.bias_std, strict=True):
        assert f"b_{a} {s:.3g}" in out
    assert f"Created: {cal.created}" in out
    # the source text cannot close the comment early
    assert "*/ yes" not in out and "Source: C:\\runs\\\"jig #2\" * / yes: no" in out


def test_c_header_bad_prefix_exit_2(cal_file, capsys):
    assert main(["export", str(cal_file), "--format", "c-header", "--c-prefix", "9lives"]) == 2
    assert "--c-prefix" in capsys.readouterr().err


# ------------------------------------------------------------------ kinds
@pytest.fixture(scope="module")
def noise_doc():
    s = simulate_still(np.random.default_rng(3), 120.0, model=NoiseModel())
    return characterise_noise(s.rate, 200.0).to_dict()


@pytest.mark.parametrize("fmt", ["c-header", "yaml", "ros"])
def test_noise_document_is_refused_naming_the_accepted_kind(tmp_path, capsys, noise_doc, fmt):
    p = tmp_path / "noise.json"
    p.write_text(json.dumps(noise_doc))
    assert main(["export", str(p), "--format", fmt]) == 2
    err = capsys.readouterr().err
    assert f"--format {fmt} takes a gyrocal-calibration document, not gyrocal-noise" in err


def test_help_lists_the_new_formats(capsys):
    assert main(["export", "--help"]) == 0
    out = capsys.readouterr().out
    for word in ("yaml", "ros", "c-header", "--c-prefix", "--frame-id", "--ros-node"):
        assert word in out
