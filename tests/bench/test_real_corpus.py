"""The corpus of real recordings beside BROAD (bench/real_corpus.py, issue 30).

The converters and readers are checked on small files written here in each source's format,
against the values written into them; the excerpts themselves (third-party data, kept in
shared/data, not in the repository) are checked where present and skipped with the reason
where not.
"""

from __future__ import annotations

import hashlib
import json

import numpy as np
import pytest

from bench import real_corpus as rc

#: The excerpts' sha256 as bench/data/README.md states them.
SHA256 = {
    "imutk": "29afa09bb3446e710a2c697a38727d9d0d93ca270de3a66a22d0ea6d17266a49",
    "imucal": "42bef16617e3c1c8bf3a1fe3f680d07fce8e04f2882541de759a9c04f9829007",
    "fusion": "268204a23114d397fe9902f1d4d0f8b2d1db15358a13bec6d44fbc9ce1be71de",
}


def _imutk_sources(tmp_path, n=6000):
    rng = np.random.default_rng(2)
    t = 0.02984 + 0.01 * np.arange(n)
    acc = np.rint(32768 + np.array([300.0, 200.0, 3600.0]) + 3 * rng.standard_normal((n, 3)))
    gyr = np.rint(32768 + 5 * rng.standard_normal((n, 3)))
    for name, x in (("xsens_acc.mat", acc), ("xsens_gyro.mat", gyr)):
        np.savetxt(tmp_path / name, np.column_stack([t, x]), fmt="%15.7e")
    return [tmp_path / "xsens_acc.mat", tmp_path / "xsens_gyro.mat"], t, acc, gyr


def test_the_imutk_converter_is_lossless_reproducible_and_refuses_to_overwrite(tmp_path):
    src, t, acc, gyr = _imutk_sources(tmp_path)
    out, again = tmp_path / "a.csv.xz", tmp_path / "b.csv.xz"
    rc.convert("imutk", src, out)
    rc.convert("imutk", src, again)
    assert out.read_bytes() == again.read_bytes()
    with pytest.raises(FileExistsError):
        rc.convert("imutk", src, out)
    s = rc.load("imutk", out)
    np.testing.assert_allclose(s.t, t, atol=1e-9)
    np.testing.assert_allclose(s.gyro, (gyr - 32768) / 6258.0)
    np.testing.assert_allclose(s.accel / s.accel_scale, acc - 32768)
    # the nominal scale makes the initial rest's mean read gravity (imu_tk's 9.81744)
    assert np.linalg.norm(s.accel[s.t < s.t[0] + 50].mean(axis=0)) == pytest.approx(9.81744)


def test_the_imucal_converter_keeps_the_sections_and_the_steps(tmp_path):
    rng = np.random.default_rng(3)
    n = 300
    acc = rng.integers(-2100, 2100, (n, 3)) * (9.81 / 2048)
    gyr = rng.integers(-300, 300, (n, 3)) * (2000 / 32768)
    lines = ["n_samples,gyr_x,gyr_y,gyr_z,acc_x,acc_y,acc_z"]
    lines += [",".join([str(k)] + [repr(float(v)) for v in (*gyr[k], *acc[k])])
              for k in range(n)]
    (tmp_path / "s.csv").write_text("\n".join(lines) + "\n")
    (tmp_path / "l.json").write_text(json.dumps({"x_p": {"start": 10, "end": 50},
                                                 "z_rot": {"start": 200, "end": 260}}))
    out = tmp_path / "o.csv.xz"
    rc.convert("imucal", [tmp_path / "s.csv", tmp_path / "l.json"], out)
    s = rc.load("imucal", out)
    assert s.sections == (("x_p", 10, 50), ("z_rot", 200, 260))
    np.testing.assert_allclose(s.accel, acc, rtol=1e-12)
    np.testing.assert_allclose(s.gyro, np.radians(gyr), rtol=1e-12)
    assert s.odr_hz == pytest.approx(102.4)
    # a value off the step is refused, not rounded
    lines[5] = ",".join(lines[5].split(",")[:-1] + [repr(float(acc[4, 2]) + 1e-3)])
    (tmp_path / "s.csv").write_text("\n".join(lines) + "\n")
    with pytest.raises(ValueError, match="whole multiples"):
        rc.convert("imucal", [tmp_path / "s.csv", tmp_path / "l.json"], tmp_path / "p.csv.xz")


def test_a_file_that_is_not_an_excerpt_is_refused_with_what_to_do(tmp_path, monkeypatch):
    bad = tmp_path / "x.csv.xz"
    bad.write_bytes(b"not xz")
    with pytest.raises(ValueError, match="rebuild it"):
        rc.load("fusion", bad)
    monkeypatch.setenv("GYROCAL_REAL_DATA", str(tmp_path))
    assert rc.locate("fusion") is None
    with pytest.raises(FileNotFoundError, match="python -m bench.real_corpus fusion"):
        rc.load("fusion")


def test_the_still_rule_finds_the_rests_written_into_a_recording():
    rng = np.random.default_rng(5)
    fs, n = 100.0, 6000
    g = 1e-3 * rng.standard_normal((n, 3))
    a = np.array([0, 0, 9.8]) + 1e-2 * rng.standard_normal((n, 3))
    for lo, hi in ((1000, 1800), (3000, 3500), (4200, 4300)):  # motion
        g[lo:hi] += 0.5 * np.sin(np.arange(hi - lo) / 20.0)[:, None]
        a[lo:hi] += 2.0 * np.cos(np.arange(hi - lo) / 15.0)[:, None]
    spans = rc.still_spans(g, a, fs)
    assert len(spans) == 4
    for (lo, hi), (want_lo, want_hi) in zip(spans, ((0, 1000), (1800, 3000), (3500, 4200),
                                                    (4300, 6000)), strict=True):
        assert want_lo <= lo <= want_lo + 80 and want_hi - 80 <= hi <= want_hi


@pytest.mark.parametrize("name", ["imutk", "imucal", "fusion"])
def test_the_excerpt_is_the_stated_file(name):
    path = rc.locate(name)
    if path is None:
        pytest.skip(rc.missing_reason(name))
    assert hashlib.sha256(path.read_bytes()).hexdigest() == SHA256[name]
    s = rc.load(name, path)
    rows, hz = {"imutk": (51175, 100.0), "imucal": (10376, 102.4), "fusion": (13514, 99.2)}[name]
    assert s.t.size == rows and s.odr_hz == pytest.approx(hz, rel=5e-3)
    assert np.all(np.isfinite(s.gyro)) and np.all(np.isfinite(s.accel))


#: imucal 2.6.0's own gyro calibration of its session: rc.imucal_ferraris_gyro models its
#: equations (imucal/ferraris_calibration.py L210-323, ferraris_calibration_info.py L109-134).
@pytest.mark.skipif(rc.locate("imucal") is None, reason=rc.missing_reason("imucal"))
def test_gyrocal_on_imucals_real_ferraris_session_agrees_with_imucals_own(tmp_path, capsys):
    """imucal's real session as a hand-jig Recording v1 (before: "needs at least 6 rotation
    windows, got 3"): the three turns and 13 rests are found, the scales agree with imucal's
    to 2e-4 and the biases to 3e-5 rad/s (each within one σ), and the verdict holds."""
    from gyrocal.kit.cli import main

    s = rc.load("imucal")
    rc.write_recording(s, tmp_path / "rec")
    assert main(["estimate", str(tmp_path / "rec"), "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    own = rc.imucal_ferraris_gyro(s)
    scale, bias = np.array(doc["scale"]), np.array(doc["bias"])
    assert np.all(np.abs(scale - own.scale) < np.minimum(2e-4, doc["scale_std"])), scale
    own_bias = -np.radians(own.b)
    assert np.all(np.abs(bias - own_bias) < np.minimum(3e-5, doc["bias_std"])), bias
    assert doc["consistency"]["ok"]
    with pytest.raises(FileExistsError):
        rc.write_recording(s, tmp_path / "rec")


@pytest.mark.skipif(rc.locate("imucal") is None, reason=rc.missing_reason("imucal"))
def test_the_model_of_imucals_calibration_is_imucals_own():
    """rc.imucal_ferraris_gyro against imucal's FerrarisCalibration itself (the test extra),
    run as its examples/basic_ferraris.py runs it, on the same labelled session."""
    imucal = pytest.importorskip("imucal")
    pd = pytest.importorskip("pandas")
    s = rc.load("imucal")
    data = pd.DataFrame(np.column_stack([s.accel, np.degrees(s.gyro)]),
                        columns=["acc_x", "acc_y", "acc_z", "gyr_x", "gyr_y", "gyr_z"])
    sections = pd.DataFrame({n: {"start": lo, "end": hi} for n, lo, hi in s.sections}).T
    regions = imucal.ferraris_regions_from_section_list(data, sections)
    cal = imucal.FerrarisCalibration().compute(regions, sampling_rate_hz=rc.IMUCAL_FS_HZ,
                                               from_acc_unit="m/s^2", from_gyr_unit="deg/s")
    own = rc.imucal_ferraris_gyro(s)
    for mine, theirs in ((own.K, cal.K_g), (own.R, cal.R_g), (own.b, cal.b_g),
                         (own.K_ga, cal.K_ga)):
        np.testing.assert_allclose(mine, theirs, rtol=1e-12, atol=1e-15)
