"""The hand jig through the kit: `--jig` choices, `gyrocal estimate` on a hand Recording v1
written from the independent generator (tests/calib/hand_truth.py), the emulated hand's motion
checked against its own schedule."""

from __future__ import annotations

import argparse
import json
import re

import numpy as np
import pytest

from gyrocal.drivers.emulated.hand import HandMotion, hand_schedule
from gyrocal.kit.cli import main
from gyrocal.kit.jig_kinds import DEFAULT_JIG, JIG_KINDS
from gyrocal.kit.recording import RecordingWriter
from tests.calib import hand_truth as ht


def test_calibrate_offers_the_jig_kinds_of_the_table():
    from gyrocal.kit.commands import calibrate

    p = argparse.ArgumentParser()
    calibrate.add_arguments(p)
    action = next(a for a in p._actions if a.dest == "jig")
    assert tuple(action.choices) == tuple(JIG_KINDS) and action.default == DEFAULT_JIG
    assert DEFAULT_JIG == "gimbal" and {"gimbal", "hand"} <= set(JIG_KINDS)
    assert all(k.name == name for name, k in JIG_KINDS.items())


@pytest.fixture(scope="module")
def hand_recording(tmp_path_factory):
    rng = np.random.default_rng(11)
    C, bias, mount = ht.draw_sensor(rng)
    t, m, acc, truth = ht.hand_session(rng, C, bias, mount)
    root = tmp_path_factory.mktemp("hand") / "rec"
    with RecordingWriter(root, sensor={"model": "mpu9250", "odr_hz": 100.0},
                         gimbal={"motors": []}, protocol={"name": "hand"},
                         extra={"jig": {"kind": "hand"}}, accel=True) as w:
        w.append_imu(t, m, np.full(t.size, np.nan), accel=acc)
        w.finish()
    return root, truth


def test_estimate_reads_a_hand_recording_and_says_what_it_cannot_determine(
        hand_recording, capsys):
    """Calibration v1 (the diagonal model) with the hand jig's reason on stderr; scale and
    bias within 3σ of the generator's truth."""
    root, truth = hand_recording
    assert main(["estimate", str(root), "--json"]) == 0
    out = capsys.readouterr()
    doc = json.loads(out.out)
    assert doc["version"] == 1 and doc["method"] == "paired-axis"
    assert "turn axes are the box's" in out.err and "gimbal's posed protocol" in out.err
    assert np.all(np.abs(np.array(doc["scale"]) - truth.scale) < 3 * np.array(doc["scale_std"]))
    assert np.all(np.abs(np.array(doc["bias"]) - truth.bias) < 3 * np.array(doc["bias_std"]))


def test_a_manifest_naming_an_unknown_jig_is_refused(tmp_path, capsys):
    root = tmp_path / "rec"
    with RecordingWriter(root, sensor={"model": "mpu9250"}, gimbal={"motors": []},
                         protocol={}, extra={"jig": {"kind": "table"}}) as w:
        w.append_imu(np.arange(20) * 0.01, np.zeros((20, 3)))
        w.finish()
    assert main(["estimate", str(root)]) == 2
    assert "jig.kind 'table' is not one of gimbal, hand" in capsys.readouterr().err


def test_the_emulated_hand_turns_whole_turns_and_lays_each_face_up():
    """Each turn of the emulated hand integrates to its drawn angle (2π plus the stop's
    error) about its box axis, whatever its speed profile; at rests the specific force is the
    face laid up, in the sensor frame through the mount."""
    sched = hand_schedule(4)
    motion = HandMotion(sched, mount=(0.02, -0.01, 0.03), wobble_deg=1.0, seed=4)
    axes = motion.box_axes()
    turns = [p for p in sched if p.kind == "turn"]
    assert len(turns) == 6 and len(motion.turn_angles) == 6
    for p, angle in zip(turns, motion.turn_angles, strict=True):
        t = np.linspace(p.t_start, p.t_end, 20001)
        w = motion.rate(t)
        total = np.sum((w[1:] + w[:-1]) / 2 * np.diff(t)[:, None], axis=0)
        np.testing.assert_allclose(total, angle * axes[p.axis], atol=2e-4)
        assert abs(abs(angle) - 2 * np.pi) < np.radians(0.5)
        speed = np.linalg.norm(w, axis=1)
        assert speed.max() > 1.3 * np.mean(speed)  # the speed varies within the turn
    rests = [p for p in sched if p.kind == "rest"]
    assert len({round(p.t_end - p.t_start, 3) for p in rests}) == len(rests)  # varying rests
    ups = {tuple(np.round(motion.specific_force(np.array([(p.t_start + p.t_end) / 2]))[0]
                          @ axes.T).astype(int)) for p in rests}
    assert ups == {(0, 0, 1), (0, 0, -1), (1, 0, 0), (-1, 0, 0), (0, 1, 0), (0, -1, 0)}


def test_noise_on_a_hand_recording_takes_a_rest_the_data_show(hand_recording, capsys):
    """A hand recording has no segments: `gyrocal noise` takes the longest rest the data show
    (before: the whole recording, turns included, as "all"); 4.5 s is too short for the Allan
    curve, which it says."""
    root, _ = hand_recording
    assert main(["noise", str(root)]) == 2
    err = capsys.readouterr().err
    assert "using the longest rest the hand jig's data show" in err and "too short" in err


def test_a_recording_without_turns_or_jig_kind_is_told_about_the_hand_jig(tmp_path, capsys):
    """A hand session written without ``jig.kind`` (another tool's): the gimbal's windowing
    has nothing to window, and the message says how to mark it."""
    root = tmp_path / "rec"
    with RecordingWriter(root, sensor={"model": "mpu9250"}, gimbal={"motors": []},
                         protocol={}) as w:
        w.append_imu(np.arange(200) * 0.01, np.zeros((200, 3)))
        w.finish()
    assert main(["estimate", str(root)]) == 2
    assert '"jig": {"kind": "hand"}' in capsys.readouterr().err


def test_the_report_of_a_hand_recording_names_the_box_axes_not_servos(hand_recording):
    """The report of a hand recording (the independent generator's): its turn axes are the
    box's (no servo on this jig: kit.jig_kinds' ``axis_label``), what calibrates the full model
    is the hand jig's sentence, not ``--protocol full`` (a gimbal's flag), and the next steps
    do not send the user to `gyrocal verify` (which turns a gimbal); the overview has no empty
    servo-angle panel (before: one, with a legend of no entries and matplotlib's warning)."""
    pytest.importorskip("matplotlib")
    from gyrocal.calib.model import GyroCalibration
    from gyrocal.kit import report_plots as rp
    from gyrocal.kit.pipeline import judged_windows, recording_jig
    from gyrocal.kit.plots import require_matplotlib
    from gyrocal.kit.recording import load_recording
    from gyrocal.kit.report_html import render_html

    root, truth = hand_recording
    rec = load_recording(root)
    ex = judged_windows(rec)[0]
    jig = recording_jig(rec)
    axes = {str(m): {"axis": list(np.eye(3)[m - 1]), "misalignment_deg": 0.5,
                     "nearest": f"+{'xyz'[m - 1]}", "std_deg": 0.01} for m in (1, 2, 3)}
    cal = GyroCalibration(scale=truth.scale, bias=truth.bias, axes=axes)
    page = render_html(cal, title="hand", jig=jig)
    summary = page[page.index("<section id=summary>"):page.index("</section>")]
    table = page[page.index("<table id=axes>"):]
    table = table[:table.index("</table>")]
    for name in "xyz":
        assert f"<td>box axis {name}</td>" in table
    assert "servo" not in table and not re.search(r"servo \d", summary)
    assert "--protocol full" not in page
    assert JIG_KINDS["hand"].full_model.split(" (")[0] in summary
    assert "<code>gyrocal verify" not in summary and "second hand session" in summary
    labels = rp.window_residuals(ex, cal, rp.window_axes(ex, cal, rec.manifest), jig).labels
    assert {x for x in labels if not x.startswith("rest")} == {
        f"box {a}{s}" for a in "xyz" for s in "+-"}
    plt = require_matplotlib()
    fig = rp._overview_plot(plt, rec, ex)
    try:
        assert len(fig.axes) == 1
        legend = [t.get_text() for t in fig.axes[0].get_legend().get_texts()]
        assert {f"window, box axis {a}" for a in "xyz"} <= set(legend)
    finally:
        plt.close(fig)


def test_the_g_sensitivity_note_says_what_calibrates_the_full_model_on_each_jig():
    """A diagonal fit with g-sensitivity: the note says the rate error in use and what
    calibrates the full model on the recording's jig (kit.jig_kinds' ``full_model``):
    ``--protocol full`` on a gimbal only, where the flag means something."""
    from gyrocal.calib.estimators import FitResult
    from gyrocal.kit.pipeline import diagonal_g_note

    fit = FitResult("paired-axis", np.ones(3), np.zeros(3), np.eye(6), 3, True, "ok", "",
                    g_sensitivity=np.diag([1e-3, 2e-3, 1e-3]), g_directions=np.eye(3))
    notes = {jig: diagonal_g_note(fit, jig) for jig in JIG_KINDS}
    for jig, note in notes.items():
        assert "0.002 rad/s per g" in note and note.endswith(JIG_KINDS[jig].full_model)
        assert ("--protocol full" in note) == (jig == "gimbal")
    assert "V-block" in notes["single-servo"] and "cannot" in notes["hand"]
    assert diagonal_g_note(fit) == notes["gimbal"]


@pytest.fixture(scope="module")
def hand_estimate(hand_recording):
    """``hand_recording`` loaded and estimated as ``gyrocal estimate`` does."""
    from gyrocal.kit.pipeline import estimate_recording
    from gyrocal.kit.recording import load_recording

    rec = load_recording(hand_recording[0])
    return rec, estimate_recording(rec)


def test_the_text_table_of_a_hand_run_names_the_box_axes_not_servos(hand_estimate):
    """The terminal's table names each turn axis as the hand jig does (kit.jig_kinds'
    ``axis_label``, the name the HTML page gives it): ``box axis x``, never ``servo 1``
    (before: ``servo 1: [...] nearest +x``)."""
    from gyrocal.kit.jig_kinds import axis_label
    from gyrocal.kit.report import calibration_table

    rec, est = hand_estimate
    table = calibration_table(est.calibration, rec.truth, jig="hand")
    assert "servo" not in table
    for m in est.calibration.axes:
        assert f"  {axis_label('hand', int(m))}: [" in table
    assert {axis_label("hand", m) for m in (1, 2, 3)} == {f"box axis {a}" for a in "xyz"}
    assert "  servo 1: [" in calibration_table(est.calibration, rec.truth)  # a gimbal's name


def test_the_drawn_residuals_of_a_hand_run_sum_to_the_fit_s_chi_square(hand_estimate,
                                                                        tmp_path, monkeypatch):
    """residuals.png's Σz² is the fit's χ² on the hand jig, whose rests are each turn's stop:
    the stop's repeatability (0.1°, 2.8e-4 of a turn), which the fit carries as each rest's
    shared still-angle error, is in what the report draws (before: left out, Σz² 43.6 against
    χ² 32.0 here, 99.4 against 26.7 on `gyrocal calibrate --sim --jig hand --sim-seed 4242`);
    the box's turns are labelled with their box axes."""
    pytest.importorskip("matplotlib")
    from tests.kit.report_drawn import drawn_residuals

    rec, est = hand_estimate
    cal = est.calibration
    res = drawn_residuals(rec, cal, est.extracted, tmp_path, monkeypatch)
    assert res.chi2 == pytest.approx(cal.consistency.chi2, rel=1e-3, abs=0.05)
    assert sum(k == "still" for k in res.kinds) > 0
    assert {x[:-1] for x, k in zip(res.labels, res.kinds, strict=True) if k == "rotate"} == {
        f"box {a}" for a in "xyz"}
