"""g-sensitivity in the full model, g = A (m + b + G f), against an independent generator
(tests/calib/gsens_truth.py: scipy rotations, gravity averaged numerically over each turn)."""

import json
import warnings

import numpy as np
import pytest

from gyrocal.calib.errors import CalibInputError
from gyrocal.calib.estimators import fit_full_matrix, gravity_directions
from gyrocal.calib.model import CalibrationFormatError, GSensitivityWarning, GyroCalibration
from tests.calib.fullmodel_truth import POSED, draw_truth, truth_in_frame
from tests.calib.gsens_truth import GRAVITY_RESTS, HOME_RESTS, POSED_RESTS, gsens_observations

#: MPU-9250 typical g-sensitivity, 0.1 °/s/g (PS-MPU-9250A-01 §3.1), in rad/s per g.
G_TYP = np.radians(0.1)
ALL_RESTS = HOME_RESTS + POSED_RESTS + GRAVITY_RESTS


def _g_in_frame(Gs, C):
    """The model's ``G`` for a sensor with g-sensitivity ``Gs``: ``−Gs Qᵀ`` with ``Q = A C`` the
    rotation from the physical frame to the calibration's (gyro-x-xy): ``f`` is taken there."""
    return -Gs @ (truth_in_frame(C) @ C).T


def _truth(seed):
    rng = np.random.default_rng(seed)
    C, bias, links, mount = draw_truth(rng)
    Gs = rng.uniform(-G_TYP, G_TYP, (3, 3))
    return rng, C, bias, Gs, links, mount


@pytest.mark.parametrize("seed", [0, 1])
def test_noise_free_windows_recover_G_A_and_b(seed):
    _, C, bias, Gs, links, mount = _truth(seed)
    obs = gsens_observations(C, bias, Gs, links, mount, POSED, ALL_RESTS)
    fit = fit_full_matrix(obs)
    assert fit.success, fit.message
    assert fit.g_directions.shape == (3, 3)
    np.testing.assert_allclose(fit.g_sensitivity, _g_in_frame(Gs, C), atol=1e-9)
    np.testing.assert_allclose(fit.matrix, truth_in_frame(C), atol=1e-9)
    np.testing.assert_allclose(fit.bias, bias, atol=1e-9)


@pytest.mark.parametrize("span", [(0.0, 1.3 * np.pi), (-0.4, 2 * np.pi + 0.9)])
def test_noise_free_windows_off_whole_revolutions_recover_G(span):
    # A window that is not whole revolutions (a one-turn, rest-to-rest window with its still
    # margins and ramps) sees part of gravity across the axis: turn_phase carries it.
    _, C, bias, Gs, links, mount = _truth(7)
    obs = gsens_observations(C, bias, Gs, links, mount, POSED, ALL_RESTS, span=span, n_avg=40)
    assert np.max(np.abs(obs.turn_phase)) > 0.05
    fit = fit_full_matrix(obs)
    np.testing.assert_allclose(fit.g_sensitivity, _g_in_frame(Gs, C), atol=1e-9)
    np.testing.assert_allclose(fit.bias, bias, atol=1e-9)


def test_without_the_model_the_bias_is_off_by_G_times_gravity():
    # The reason for the term: the rests see gravity, the horizontal turns do not.
    _, C, bias, Gs, links, mount = _truth(3)
    obs = gsens_observations(C, bias, Gs, links, mount, POSED, ALL_RESTS)
    plain = fit_full_matrix(obs, g_sensitivity=False)
    assert plain.g_sensitivity is None
    assert np.max(np.abs(plain.bias - bias)) > 1e-4
    assert plain.consistency.chi2 > 1e3 * plain.consistency.dof  # and the χ² says so


def test_with_noise_G_is_within_its_sigma():
    z = []
    for seed in range(8):
        rng, C, bias, Gs, links, mount = _truth(100 + seed)
        obs = gsens_observations(C, bias, Gs, links, mount, POSED, ALL_RESTS, noise=0.05,
                                 rng=rng)
        fit = fit_full_matrix(obs)
        assert fit.success, fit.message
        sd = np.sqrt(np.diag(fit.g_sensitivity_cov)).reshape(3, 3)
        z.append(((fit.g_sensitivity - _g_in_frame(Gs, C)) / sd).ravel())
        assert fit.consistency.ok
    z = np.concatenate(z)
    assert np.max(np.abs(z)) < 4.5
    assert 0.7 < np.sqrt(np.mean(z**2)) < 1.35


def test_rank_of_gravity_directions_per_protocol():
    # Home rests and horizontal turns: gravity in one direction only; the posed pair with the
    # middle servo at 90° adds a second; the planner's gravity rest (base at 90°) the third.
    _, C, bias, Gs, links, mount = _truth(4)
    for rests, k in ((HOME_RESTS, 1), (HOME_RESTS + POSED_RESTS, 2), (ALL_RESTS, 3)):
        obs = gsens_observations(C, bias, Gs, links, mount, POSED, rests, noise=0.05,
                                 rng=np.random.default_rng(0))
        f = obs.specific_force(np.array([[1.0, 0, 0], [0, 1, 0], [0, 0, 1]]), obs.pose[0])
        assert gravity_directions(*f, obs.mean_std, obs.rest_mean_std).shape == (3, k)
        fit = fit_full_matrix(obs)
        assert fit.g_directions.shape == (k, 3)
        assert (k == 3) == ("g-sensitivity fitted along" not in fit.message)


def test_the_forces_follow_the_contract_of_gravity():
    # Servo 3 (axis z) vertical at home: a rest at home sees +z; the base at +90° about x puts up
    # along +y (Rot(x, 90°)ᵀ z = Rot(x, −90°) z = y); a turn of a horizontal servo averages to 0,
    # of the vertical one to z.
    I3 = np.eye(3)
    links, mount = list(I3), I3
    obs = gsens_observations(np.eye(3), np.zeros(3), np.zeros((3, 3)), links, mount, POSED,
                             [np.zeros(3), np.array([np.pi / 2, 0, 0])])
    f, fr = obs.specific_force(I3, obs.pose[0])
    np.testing.assert_allclose(fr, [[0, 0, 1], [0, 1, 0]], atol=1e-12)
    np.testing.assert_allclose(f[:2], 0, atol=1e-12)  # base (x) turns
    np.testing.assert_allclose(f[4:6], [[0, 0, 1]] * 2, atol=1e-12)  # inner (z) turns


def test_gravity_field_is_checked():
    _, C, bias, Gs, links, mount = _truth(0)
    obs = gsens_observations(C, bias, Gs, links, mount, POSED, HOME_RESTS)
    from dataclasses import replace

    with pytest.raises(CalibInputError, match="gravity must name a servo"):
        replace(obs, gravity=(9, 1))
    with pytest.raises(CalibInputError, match="rest_pose must have shape"):
        replace(obs, rest_pose=np.zeros((2, 3)))
    with pytest.raises(CalibInputError, match="do not say where gravity points"):
        replace(obs, gravity=None).specific_force(np.eye(3), np.zeros(3))


def _calibration(seed=0):
    _, C, bias, Gs, links, mount = _truth(seed)
    rng = np.random.default_rng(seed)
    obs = gsens_observations(C, bias, Gs, links, mount, POSED, ALL_RESTS, noise=0.05, rng=rng)
    return fit_full_matrix(obs).to_calibration(source="test"), Gs


def test_document_round_trip_and_apply_with_specific_force():
    cal, Gs = _calibration()
    doc = json.loads(cal.to_json())
    g = doc["g_sensitivity"]
    assert g["model"] == "g = matrix @ (m + bias + g_sensitivity @ f)"
    assert np.array(g["matrix_std"]).shape == (3, 3) and np.all(np.array(g["matrix_std"]) > 0)
    back = GyroCalibration.from_dict(doc)
    assert back.to_dict() == cal.to_dict()
    m = np.array([[0.1, -0.2, 0.3], [0.0, 0.0, 0.0]])
    f = np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0]])
    A, b, G = back.full_matrix, np.array(back.bias), np.array(g["matrix"])
    expected = (m + b + f @ G.T) @ A.T  # the document's model, written out
    np.testing.assert_allclose(back.apply(m, specific_force=f), expected, rtol=1e-12)
    with warnings.catch_warnings(record=True) as w:
        warnings.simplefilter("always")
        plain = back.apply(m)
    assert any(issubclass(x.category, GSensitivityWarning) and "NOT applied" in str(x.message)
               for x in w)
    np.testing.assert_allclose(plain, (m + b) @ A.T, rtol=1e-12)
    with pytest.raises(CalibInputError, match="specific_force must have shape"):
        back.apply(m, specific_force=[0.0, 1.0])


@pytest.mark.parametrize("edit, match", [
    (lambda g: g.update(matrix=[[1.0, 0, 0], [0, 0, 0], [0, 0, 0]]), "g_sensitivity.matrix"),
    (lambda g: g.update(directions=[[1.0, 0, 0], [1.0, 0, 0]]), "orthonormal"),
    (lambda g: g.update(extra=1), "unknown field 'extra'"),
    (lambda g: g.pop("directions"), "lacks the field 'directions'"),
    (lambda g: g.update(model="g = A m"), "g_sensitivity.model"),
])
def test_bad_g_sensitivity_documents_are_refused(edit, match):
    cal, _ = _calibration(1)
    doc = cal.to_dict()
    edit(doc["g_sensitivity"])
    with pytest.raises(CalibrationFormatError, match=match):
        GyroCalibration.from_dict(doc)


def test_a_v1_document_cannot_carry_g_sensitivity():
    cal, _ = _calibration(2)
    doc = cal.to_dict()
    v1 = {k: v for k, v in doc.items() if k not in ("matrix", "matrix_std", "frame",
                                                      "kinematics")}
    v1.update(version=1, model="g = scale * (m + bias)",
              covariance=None, scale_std=doc["scale_std"])
    with pytest.raises(CalibrationFormatError, match="unknown field 'g_sensitivity'"):
        GyroCalibration.from_dict(v1)


def test_the_rate_error_per_g_is_the_worst_unit_force_found_by_search():
    """``g_rate_error_per_g`` against a brute-force search: the largest change of any calibrated
    axis, ``|A G f|``, over 200,000 random unit specific forces, and 0 without G."""
    rng = np.random.default_rng(11)
    A = np.tril(np.eye(3) + rng.normal(0, 0.02, (3, 3)))
    G = rng.uniform(-1, 1, (3, 3)) * np.radians(0.1)
    cal = GyroCalibration(scale=tuple(np.diag(A)), bias=(0.0, 0.0, 0.0), matrix=A.tolist(),
                          matrix_std=np.zeros((3, 3)).tolist(), frame="gyro-x-xy",
                          g_sensitivity={"matrix": G.tolist(), "matrix_std": None,
                                         "directions": np.eye(3).tolist()})
    f = rng.normal(size=(200_000, 3))
    f /= np.linalg.norm(f, axis=1, keepdims=True)
    searched = np.max(np.abs(f @ (A @ G).T))
    assert searched <= cal.g_rate_error_per_g <= searched * (1 + 1e-4)
    plain = GyroCalibration(scale=(1.0, 1.0, 1.0), bias=(0.0, 0.0, 0.0))
    assert plain.g_rate_error_per_g == 0.0
