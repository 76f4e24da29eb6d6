"""gyrocal report: PNG plots of an emulated-jig recording, the residual arithmetic against the
simulation's truth, and the refusals (missing recording, missing matplotlib, existing files)."""

import sys

import numpy as np
import pytest
from scipy import stats

from gyrocal.calib.model import GyroCalibration
from gyrocal.kit.cli import main
from gyrocal.kit.errors import InputError
from gyrocal.kit.recording import load_recording
from gyrocal.kit.report_plots import (
    boxcar_mean,
    encoder_rate,
    nominal_axis,
    ramp_lag,
    servo_axes,
    window_axes,
    window_residuals,
)
from tests.kit.browser import needs_chromium, render

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


@pytest.fixture(scope="module")
def run_dir(paper_diagonal_run):
    # The paper's sensor and the diagonal protocol: one axis per servo, a version 1 calibration
    # (the full model's posed turns are tested on the shared default run below), the run
    # tests/kit/test_calibrate.py checks against the truth. Its report is what the tests below
    # draw from the same recording and calibration with `gyrocal report`; calibrate's own is
    # tests/kit/test_report_html.py's.
    d, code = paper_diagonal_run
    assert code in (0, 3)
    return d


@pytest.fixture(scope="module")
def extracted(run_dir):
    from gyrocal.kit.pipeline import extract_recording as extract

    rec = load_recording(run_dir / "recording")
    return rec, extract(rec)


def expected_names(rec):
    names = {"overview.png", "rests.png", "residuals.png"}
    for s in rec.segments:
        if s.kind == "rotate":
            names.add(f"turn-{s.index:02d}-servo{s.motor}-{'pos' if s.direction > 0 else 'neg'}"
                      ".png")
    return names


def check_pngs(directory, names, page="report.html"):
    import matplotlib.image as mpimg

    # nothing else (no temporary files) but the HTML page (tests/kit/test_report_html.py), which
    # `gyrocal calibrate` writes beside its plots directory (``page=None``)
    assert {p.name for p in directory.iterdir()} == names | ({page} if page else set())
    for name in names:
        data = (directory / name).read_bytes()
        assert data[:8] == PNG_MAGIC, name
        img = mpimg.imread(directory / name)
        assert img.ndim == 3 and img.shape[0] >= 400 and img.shape[1] >= 800, (name, img.shape)
        assert img[..., :3].std() > 0.05, f"{name} looks blank"


def index_paths(out):
    lines = out.strip().splitlines()
    assert lines[0].startswith("gyrocal report:")
    return [line.split()[0] for line in lines[1:]]


def test_report_with_calibration_one_plot_per_turn(run_dir, paper_diagonal_report):
    # `gyrocal report REC CAL` of run_dir, drawn once for this module and
    # tests/kit/test_report_html.py (tests/kit/conftest.py; exit 0 asserted there), its
    # verification document shown on the page only
    rec = load_recording(run_dir / "recording")
    out_dir, out = paper_diagonal_report
    names = expected_names(rec)
    assert len(names) == 6 + 3  # three servos, each turned both ways
    check_pngs(out_dir, names)
    listed = index_paths(out)
    assert sorted(listed) == sorted(str(out_dir / n) for n in names | {"report.html"})
    assert listed[0].endswith("overview.png") and listed[-2].endswith("residuals.png")
    assert listed[-1].endswith("report.html")
    assert "calibration.json" in out


def test_report_refuses_to_overwrite_then_estimates_with_force(run_dir, tmp_path, capsys):
    rec = load_recording(run_dir / "recording")
    out_dir = tmp_path / "plots"
    out_dir.mkdir()
    (out_dir / "residuals.png").write_bytes(b"keep me")
    args = ["report", str(run_dir / "recording"), "--out", str(out_dir), "--method",
            "iterative-ls"]
    assert main(args) == 2
    err = capsys.readouterr().err
    assert "residuals.png" in err and "--force" in err
    assert [p.name for p in out_dir.iterdir()] == ["residuals.png"]  # nothing written
    assert (out_dir / "residuals.png").read_bytes() == b"keep me"
    # with --force (and no CAL: an estimate from the recording) every plot is written
    code = main([*args, "--force"])
    out, err = capsys.readouterr()
    assert code == 0, err
    assert "iterative-ls estimate from the recording" in out
    check_pngs(out_dir, expected_names(rec))


def test_missing_recording_exits_2(tmp_path, capsys):
    assert main(["report", str(tmp_path / "nope"), "--out", str(tmp_path / "p")]) == 2
    assert "not a directory" in capsys.readouterr().err
    assert not (tmp_path / "p").exists()


def test_bad_calibration_exits_2(run_dir, tmp_path, capsys):
    bad = tmp_path / "cal.json"
    bad.write_text('{"format": "gyrocal-calibration", "version": 1, "scale": [1, 1]}')
    assert main(["report", str(run_dir / "recording"), str(bad), "--out",
                 str(tmp_path / "p")]) == 2
    assert "scale" in capsys.readouterr().err
    assert not (tmp_path / "p").exists()


def test_missing_matplotlib_exits_2_with_the_install_hint(run_dir, tmp_path, capsys,
                                                           monkeypatch):
    # None in sys.modules makes "import matplotlib" raise ImportError, as if not installed
    monkeypatch.setitem(sys.modules, "matplotlib", None)
    monkeypatch.setitem(sys.modules, "matplotlib.pyplot", None)
    code = main(["report", str(run_dir / "recording"), "--out", str(tmp_path / "p")])
    err = capsys.readouterr().err
    assert code == 2
    assert "matplotlib" in err and "pip install 'gyrocal[plot]'" in err
    assert not (tmp_path / "p").exists()


# ------------------------------------------------------------------ the numbers behind the plots
def truth_calibration(rec):
    t = rec.truth
    axes = {m: {"axis": u} for m, u in t["axes"].items()}
    return GyroCalibration(scale=t["scale"], bias=t["bias"], axes=axes)


def test_residuals_against_the_truth_are_standard_normal(extracted):
    rec, ex = extracted
    truth = truth_calibration(rec)
    axes = servo_axes([1, 2, 3], truth, rec.manifest, ex.windows)
    assert {a.source for a in axes.values()} == {"calibration"}
    res = window_residuals(ex, truth, axes)
    n = res.z.size
    assert n == 3 * (len(ex.windows) + len(ex.rests))
    lo, hi = stats.chi2.ppf([1e-3, 1 - 1e-3], n)
    assert lo < res.chi2 < hi, (res.chi2, n)
    assert res.labels[:2] == ["s1-", "s1+"] and res.labels[-1].startswith("rest")


def test_residuals_of_the_fit_match_its_chi_square(run_dir, extracted):
    from gyrocal.kit.pipeline import judged_windows

    rec = extracted[0]
    ex = judged_windows(rec)[0]  # the windows as the fit judged them (σ with the bias's wander)
    cal = GyroCalibration.from_json((run_dir / "calibration.json").read_text())
    res = window_residuals(ex, cal, servo_axes([1, 2, 3], cal, rec.manifest, ex.windows))
    assert res.chi2 == pytest.approx(cal.consistency.chi2, rel=0.05)


def test_fitted_axes_find_the_true_mount_and_residuals_catch_a_wrong_bias(extracted):
    rec, ex = extracted
    truth = truth_calibration(rec)
    bare = GyroCalibration(scale=truth.scale, bias=truth.bias)  # no axes: fitted to the windows
    axes = servo_axes([1, 2, 3], bare, rec.manifest, ex.windows)
    assert {a.source for a in axes.values()} == {"fitted"}
    for m, a in axes.items():
        true_u = np.asarray(rec.truth["axes"][str(m)])
        angle_deg = np.degrees(np.arccos(min(1.0, float(a.axis @ true_u))))
        assert angle_deg < 0.05, (m, angle_deg)  # the mount is ~3 degrees off nominal
    res = window_residuals(ex, bare, axes)
    assert res.chi2 < stats.chi2.ppf(1 - 1e-3, res.z.size)
    # a bias 1e-2 rad/s off on y (some 25 standard errors of a rest mean) shows in every rest
    off = GyroCalibration(scale=truth.scale, bias=np.add(truth.bias, [0.0, 1e-2, 0.0]))
    res_off = window_residuals(ex, off, axes)
    rest = np.array([k == "rest" for k in res_off.kinds])
    assert np.all(res_off.z[rest, 1] > 10) and np.all(np.abs(res_off.z[rest][:, [0, 2]]) < 5)
    # without windows or calibration axes a servo takes its nominal axis from the manifest
    nominal = servo_axes([2], bare, rec.manifest, ())
    assert nominal[2].source == "nominal"
    np.testing.assert_array_equal(nominal[2].axis, [0, 1, 0])
    # a malformed axis in the calibration is an input error, not a silent fallback
    for axis in ([0.0, 0.0, 0.0], [1.0, "y", 0.0], [1.0, 0.0]):
        broken = GyroCalibration(scale=truth.scale, bias=truth.bias, axes={"2": {"axis": axis}})
        with pytest.raises(InputError, match=r"axes\['2'\]\.axis"):
            servo_axes([2], broken, rec.manifest, ex.windows)


def test_window_arithmetic():
    t = np.linspace(0, 10, 2001)
    theta = 0.3 + 2.5 * t
    np.testing.assert_allclose(encoder_rate(t, theta, np.array([5.0]), 0.25), [2.5])
    assert np.isnan(encoder_rate(t, theta, np.array([0.1]), 0.25))[0]
    x = 1.0 + 0.5 * t  # the boxcar mean of a line is its value at the centre
    np.testing.assert_allclose(boxcar_mean(t, x, np.array([4.0, 6.0]), 0.25), [3.0, 4.0])
    np.testing.assert_array_equal(nominal_axis("-y"), [0, -1, 0])
    with pytest.raises(ValueError, match="not x, y or z"):
        nominal_axis("w")


def test_a_turn_with_a_gap_is_planned_without_a_window(run_dir, tmp_path):
    import shutil

    from gyrocal.kit.pipeline import extract_recording as extract
    from gyrocal.kit.report_plots import _gaps, plan_report

    rec_dir = tmp_path / "rec"
    shutil.copytree(run_dir / "recording", rec_dir)
    rec = load_recording(rec_dir)
    seg = [s for s in rec.segments if s.kind == "rotate"][1]
    mid = 0.5 * (seg.t_start + seg.t_end)
    lines = (rec_dir / "imu.csv").read_text().splitlines()
    kept = [lines[0]] + [ln for ln in lines[1:] if not mid < float(ln.split(",")[0]) < mid + 0.1]
    (rec_dir / "imu.csv").write_text("\n".join(kept) + "\n")
    gapped = load_recording(rec_dir)
    ex = extract(gapped)
    assert any(f"segment {seg.index}: gap" in w for w in ex.warnings)
    plan = {p.name: p.description for p in plan_report(gapped, ex)}
    name = f"turn-{seg.index:02d}-servo{seg.motor}-{'pos' if seg.direction > 0 else 'neg'}.png"
    assert "no window" in plan[name]
    assert sum("no window" in d for d in plan.values()) == 1
    (a, b), = _gaps(gapped.imu_t)
    assert a < mid + 0.01 and b > mid + 0.09


# ------------------------------------------------------------------ the full model's posed turns
@pytest.fixture(scope="module")
def full(full_run):
    """The shared default run (full protocol, ±2 % cross-axis sensor) and its windows."""
    from gyrocal.kit.pipeline import extract_recording as extract

    d, code = full_run
    assert code == 0
    rec = load_recording(d / "recording")
    cal = GyroCalibration.from_json((d / "calibration.json").read_text())
    return d, rec, extract(rec), cal


@pytest.fixture(scope="module")
def full_report(full):
    """The report of the shared default run as `gyrocal calibrate --sim` wrote it (the page a
    user of the command gets): ``(plots directory, page)``. `gyrocal calibrate` and `gyrocal
    report` draw it with one function (kit.report_html.write_run_report) from the same windows
    (kit.pipeline.judged_windows); the report command itself is run on :func:`run_dir` above."""
    d = full[0]
    assert (d / "report.html").is_file(), "the shared run wrote no report: is matplotlib there?"
    return d / "plots", d / "report.html"


def test_report_of_a_full_calibration_draws_every_posed_turn(full, full_report):
    _, rec, _, _ = full
    names = expected_names(rec)
    assert len(names) == 10 + 3  # six home turns and two posed pairs
    check_pngs(full_report[0], names, page=None)


def _section(text, tag_id):
    import re

    m = re.search(rf"<(section|table|p) id={tag_id}>.*?</(section|table|p)>", text, re.S)
    assert m, tag_id
    return m.group(0)


def test_the_page_shows_the_full_model_and_the_terminal_s_error_against_truth(full,
                                                                             full_report):
    from gyrocal.kit.report import calibration_table

    _, rec, _, cal = full
    text = full_report[1].read_text(encoding="utf-8")
    summary = _section(text, "summary")
    assert "g = A (m + b + G f)" in summary and "consistent" in summary
    # the largest cross-axis term, found here from the calibration's matrix
    A = np.asarray(cal.matrix)
    off = [(abs(A[j, i]), j, i) for j in range(3) for i in range(3) if i != j]
    _, j, i = max(off)
    assert f"A<sub>{'xyz'[j]}{'xyz'[i]}</sub> = {A[j, i]:+.4f}" in summary
    worst = max(float(a["misalignment_deg"]) for a in cal.axes.values())
    assert f"{worst:.2f}° ±" in summary  # the worst servo axis's misalignment
    # every entry of the matrix, of G and of the accelerometer's matrix, with its σ
    result = _section(text, "result")
    for j in range(3):
        for i in range(j + 1):
            assert f"{A[j, i]:.6f} ± {cal.matrix_std[j][i]:.1e}" in result
    G = _section(text, "g-sensitivity")
    assert f"{cal.g_sensitivity['matrix'][2][1]:.6f}" in G
    assert f"{cal.accelerometer.matrix[2, 0]:.6f}" in _section(text, "accelerometer")
    # the error against the truth: the very numbers the terminal prints for the same files
    # (issue 31: the page said 2.88 where the terminal said 0.72)
    line = next(x for x in calibration_table(cal, rec.truth).splitlines()
                if x.startswith("error against the simulated truth, in σ: matrix"))
    matrix_max, bias = line.split("= ")[1].split(", bias ")
    truth = _section(text, "truth")
    assert f"<td class=n>{matrix_max}</td>" in truth and f"<td class=n>{bias}</td>" in truth
    assert "scale err/σ" not in text


def test_the_page_gives_the_gyro_noise_the_emulated_sensor_has(full, full_report):
    from gyrocal.drivers.emulated.imu_chips import TYPICAL_NOISE_DENSITY_RAD_S_SQRT_HZ as N
    from gyrocal.kit.report_html import gyro_noise

    _, rec, ex, _ = full
    noise = gyro_noise(rec, ex)
    # the emulated MPU-9250's white rate noise is its datasheet's 0.01 °/s/√Hz
    assert np.all(np.abs(noise.gyro - N) < 4 * noise.gyro_std), (noise.gyro, noise.gyro_std)
    table = _section(full_report[1].read_text(encoding="utf-8"), "noise")
    assert f"{noise.gyro[0]:.3e} ± {noise.gyro_std[0]:.1e}" in table


@needs_chromium
def test_a_browser_shows_one_summarised_page_with_the_turns_folded(full_report, tmp_path):
    # issue 31: the default run's page was 11,551 px tall at 1280 px, ten turn plots open
    dom, height, decoded, images = render(full_report[1], tmp_path)
    assert decoded == images == 13
    assert height < 6000, height
    assert '<section id="summary">' in dom and "largest cross-axis term" in dom
    assert dom.index('id="summary"') < dom.index('id="result"') < dom.index("<figure>")
    assert dom.count("<figure>") - dom.split('<details id="turns">')[1].count("<figure>") == 3


def test_the_ramp_lag_is_the_delay_of_a_delayed_reading():
    # a trapezoidal turn (1 rad/s² ramps to 3 rad/s) read 4 ms late: the difference of the
    # boxcar means is -delay x angular acceleration, and the lag fit gives the delay back
    t = np.arange(0.0, 8.0, 0.005)

    def rate(x):
        return np.clip(np.minimum(x - 1.0, 7.0 - x), 0.0, 3.0)

    theta = np.concatenate([[0.0], np.cumsum(np.diff(t) * (rate(t[1:]) + rate(t[:-1])) / 2)])
    ref = encoder_rate(t, theta, t, 0.25)
    diff = boxcar_mean(t, rate(t - 0.004), t, 0.25) - ref
    assert ramp_lag(diff, np.gradient(ref, t)) == pytest.approx(0.004, rel=0.02)
    assert ramp_lag(np.zeros(5), np.zeros(5)) is None  # no ramp, no delay to fit


def test_posed_turns_take_their_axis_from_the_calibration_kinematics(full):
    _, rec, ex, cal = full
    axes = window_axes(ex, cal, rec.manifest)
    assert {a.source for a in axes} == {"kinematics"}
    # The calibration's own residuals: their chi-square is the fit's (up to the still-angle
    # unknowns the fit also carries, a few of its degrees of freedom).
    res = window_residuals(ex, cal, axes)
    assert res.chi2 == pytest.approx(cal.consistency.chi2, rel=0.25), (res.chi2, cal.consistency)
    # One axis per servo (the home one) for every turn leaves the posed turns far off.
    home = window_residuals(ex, cal, servo_axes([1, 2, 3], cal, rec.manifest, ex.windows))
    assert home.chi2 > 100 * res.chi2


def test_a_diagonal_calibration_of_a_posed_run_gets_one_axis_per_pose(full):
    from gyrocal.kit.pipeline import estimate_recording

    _, rec, ex, _ = full
    diag = estimate_recording(rec, "paired-axis").calibration
    assert not diag.is_full
    axes = window_axes(ex, diag, rec.manifest)
    poses = rec.manifest["protocol"]["poses"]
    for motor in {p["turn"] for p in poses}:
        turned = [i for i, w in enumerate(ex.windows) if w.motor == motor]
        assert all(axes[i].source == "fitted" for i in turned)
        distinct = []
        for i in turned:
            if not any(np.allclose(axes[i].axis, u) for u in distinct):
                distinct.append(axes[i].axis)
        mine = [p for p in poses if p["turn"] == motor]
        assert len(distinct) == 1 + len(mine)  # home first, then one axis per pose
        # the moved servo turned the axis by the pose angle (a square gimbal within the
        # mount's few degrees: the axes are nearly orthogonal)
        for p, u in zip(mine, distinct[1:], strict=True):
            angle = np.arccos(np.clip(distinct[0] @ u, -1, 1))
            assert angle == pytest.approx(abs(p["angle_rad"]), abs=np.radians(3)), p


def test_servo_axes_apply_the_g_sensitivity_with_each_window_s_force():
    # A servo about z turned both ways at 1 rad/s, vertical (f = up = +z) in both windows, by a
    # sensor with a bias and g-sensitivity G: m = ω u − b − G f. Written out by hand: with the
    # forces, the fitted axis is exactly u; without them (G f left out) it is still u only
    # because G f cancels between the two directions, so a one-direction servo shows the
    # difference.
    from gyrocal.calib.windows import Window

    G = np.array([[1e-3, 0.0, 4e-3], [0.0, 1e-3, -3e-3], [0.0, 0.0, 2e-3]])
    b = np.array([0.01, -0.02, 0.005])
    u, f = np.array([0.0, 0.0, 1.0]), np.array([0.0, 0.0, 1.0])
    cal = GyroCalibration(scale=(1.0, 1.0, 1.0), bias=tuple(b), matrix=np.eye(3),
                          g_sensitivity={"matrix": G.tolist(), "matrix_std": None,
                                         "directions": np.eye(3).tolist()})

    def window(d):
        m = d * u - b - G @ f
        return Window("steady", 0, 3, d, (0, 1, 2, 3), 1.0, float(d), tuple(m), 100)

    one = (window(1),)
    with_f = servo_axes([3], cal, {}, one, np.array([f]))[3]
    np.testing.assert_allclose(with_f.axis, u, atol=1e-15)
    without = servo_axes([3], cal, {}, one)[3]
    assert np.linalg.norm(without.axis - u) > 4e-3  # G f = (4e-3, -3e-3, 2e-3) off


def test_a_turn_drawn_on_the_reused_figure_is_the_turn_drawn_alone(full, full_report, tmp_path):
    """The turn plots share one figure (kit.report_plots._TurnFigure): the last turn, drawn
    after every other, must be the very pixels of that turn drawn on a figure of its own."""
    import matplotlib.image as mpimg

    from gyrocal.kit import report_plots as rp
    from gyrocal.kit.pipeline import judged_windows
    from gyrocal.kit.plots import require_matplotlib

    _, rec, _, cal = full
    extracted = judged_windows(rec)[0]  # the windows `gyrocal report` draws (its σ as judged)
    plt = require_matplotlib()
    last = [p for p in rp.plan_report(rec, extracted) if p.kind == "turn"][-1]
    motors = sorted({int(s.motor) for s in rec.segments if s.kind == "rotate"})
    forces = rp.window_forces(extracted.observations, cal)
    home = servo_axes(motors, cal, rec.manifest, extracted.windows,
                      None if forces is None else forces[0])
    axes = window_axes(extracted, cal, rec.manifest)
    index = {w.segment: (i, w) for i, w in enumerate(extracted.windows)}
    alone = rp._TurnFigure(plt)
    try:
        path, _ = rp._draw(plt, last, tmp_path, rec, cal, extracted, alone, home, axes, index,
                           False)
    finally:
        alone.close()
    reused = mpimg.imread(full_report[0] / last.name)
    assert reused.shape == mpimg.imread(path).shape
    assert np.array_equal(reused, mpimg.imread(path))


# ------------------------------------------------------------------ the residuals are the fit's
def test_the_drawn_residuals_sum_to_the_fit_s_chi_square_on_both_models(run_dir, extracted,
                                                                         full, tmp_path,
                                                                         monkeypatch):
    """residuals.png's Σz² is the χ² the calibration's verdict reports (to rounding), for the
    diagonal model (the paper's run, paired-axis) and the full one (the default run): the
    report takes its residuals from the fit's own function (calib.estimators.residuals_at),
    the still angles' shared errors included, not a whitening of its own (before, on the
    default run of seed 4242: Σz² 55.3 against χ² 54.4)."""
    pytest.importorskip("matplotlib")
    from gyrocal.kit.pipeline import chip_bias_drift, with_bias_wander
    from tests.kit.report_drawn import drawn_residuals

    diag = GyroCalibration.from_json((run_dir / "calibration.json").read_text())
    drawn = {}
    for (rec, ex), cal, name in ((extracted, diag, "diagonal"), (full[1:3], full[3], "full")):
        judged = with_bias_wander(ex, chip_bias_drift(rec.sensor.get("model"), ex))
        drawn[name] = (drawn_residuals(rec, cal, judged, tmp_path, monkeypatch), cal, ex)
    for name, (res, cal, _) in drawn.items():
        assert res.chi2 == pytest.approx(cal.consistency.chi2, rel=1e-3, abs=0.05), name
    for res, _, ex in drawn.values():  # every window and rest, and each still angle once
        assert res.count == 3 * (len(ex.windows) + len(ex.rests)) + res.kinds.count("still")
