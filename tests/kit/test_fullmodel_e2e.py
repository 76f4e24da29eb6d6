"""End-to-end: the full model on the emulated jig with the datasheet's ±2 % cross-axis terms.

Truth is the emulator's (manifest ``truth``: scale, bias, misalignment); the frame conversion is
the test's own (tests/calib/fullmodel_truth.truth_in_frame), not the code's.
"""

from dataclasses import replace

import numpy as np
import pytest

from gyrocal.calib.design import general_motion_rms, predicted_general_motion_rms
from gyrocal.kit.cli import main
from gyrocal.kit.pipeline import estimate_recording
from gyrocal.kit.recording import load_recording
from tests.calib.fullmodel_truth import truth_in_frame


@pytest.fixture(scope="module")
def rec(tmp_path_factory):
    d = tmp_path_factory.mktemp("full")
    # the estimator on the paper's sensor with cross-axis terms; the realism effects' costs
    # are measured by `python -m bench realism`
    assert main(["calibrate", "--sim", "--sim-seed", "4", "--sim-cross-axis", "0.02",
                 "--sim-realism", "off",
                 "--protocol", "full", "--out", str(d), "--quiet", "--json"]) == 0
    return load_recording(d / "recording")


def _sensing(truth):
    return np.diag(1 / np.asarray(truth["scale"])) @ np.asarray(truth["misalignment"])


def test_sim_draws_cross_axis_terms_within_the_datasheet_bound(rec):
    mis = np.asarray(rec.truth["misalignment"])
    off = mis[~np.eye(3, dtype=bool)]
    assert np.isclose(np.max(np.abs(off)), 0.02) and np.allclose(np.diag(mis), 1.0)
    assert rec.manifest["protocol"]["model"] == "full"
    assert any(s.kind == "move" for s in rec.segments)
    assert rec.manifest["protocol"]["planned_jig_time_s"] <= 45.0


def test_full_model_recovers_the_matrix_and_holds_in_general_motion(rec):
    est = estimate_recording(rec)  # auto
    fit = est.fit
    assert fit.method == "full-matrix" and not est.notes
    assert fit.consistency.ok
    C, b = _sensing(rec.truth), np.asarray(rec.truth["bias"])
    A_true = truth_in_frame(C)
    std = np.sqrt(np.diag(fit.covariance))
    free = std[:9] > 0
    z = (fit.matrix - A_true).ravel()[free] / std[:9][free]
    assert np.all(np.abs(z) < 4), z
    assert np.all(np.abs(fit.bias - b) < 4 * std[9:])
    err = general_motion_rms(fit.matrix, fit.bias, C, b)
    pred = predicted_general_motion_rms(fit.covariance)
    assert err <= 2.5 * pred, (err, pred)
    assert err < 5e-4
    # The paper's diagonal model on the same recording: its error in general motion is the
    # cross-axis error, far beyond what its own covariance predicts.
    diag = estimate_recording(rec, "paired-axis").fit
    err_d = general_motion_rms(np.diag(diag.scale), diag.bias, C, b)
    assert err_d > 10 * predicted_general_motion_rms(diag.covariance), err_d
    assert err_d > 10 * err


def test_a_one_pose_recording_falls_back_to_the_diagonal_model_and_says_so(rec):
    home = []
    for s in rec.segments:  # everything before the first pose move
        if s.kind == "move":
            break
        home.append(s)
    est = estimate_recording(replace(rec, segments=tuple(home)))
    assert est.fit.method == "paired-axis"
    assert len(est.notes) == 1
    assert "cross-axis terms were NOT calibrated" in est.notes[0]
    assert "±2 %" in est.notes[0]
    assert est.calibration.matrix is None  # a v1 document
