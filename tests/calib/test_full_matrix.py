"""The full-matrix estimator against an independent generator (tests/calib/fullmodel_truth.py)."""

import itertools

import numpy as np
import pytest

from gyrocal.calib.design import choose_model
from gyrocal.calib.estimators import FULL_FRAME, estimate, fit_full_matrix
from tests.calib.fullmodel_truth import (
    HOME,
    POSED,
    Q,
    body_axis,
    draw_truth,
    posed_observations,
    truth_in_frame,
)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_noise_free_posed_runs_recover_A_and_b_to_1e9(seed):
    rng = np.random.default_rng(seed)
    C, bias, links, mount = draw_truth(rng)
    fit = estimate(posed_observations(C, bias, links, mount, POSED), "full-matrix")
    assert fit.success, fit.message
    assert fit.frame == FULL_FRAME
    np.testing.assert_allclose(fit.matrix, truth_in_frame(C), atol=1e-9)
    np.testing.assert_allclose(fit.bias, bias, atol=1e-9)
    assert fit.matrix[0, 1] == fit.matrix[0, 2] == fit.matrix[1, 2] == 0.0
    np.testing.assert_array_equal(fit.scale, np.diag(fit.matrix))


def test_the_fitted_kinematics_predict_every_window():
    # The axes the fit returns, carried by the poses, reproduce the true rate direction.
    from gyrocal.calib.kinematics import axes_at
    from tests.calib.fullmodel_truth import body_axis

    rng = np.random.default_rng(5)
    C, bias, links, mount = draw_truth(rng)
    fit = fit_full_matrix(posed_observations(C, bias, links, mount, POSED))
    kin = fit.kinematics
    # The frame rotation: ω_frame = Q ω_sensor where C = L Q.
    Qf = np.linalg.solve(np.linalg.inv(truth_in_frame(C)), C)
    pose = np.array([[0.3, -1.2, 2.0], [1.0, 0.5, -0.7]])
    got = axes_at(kin, pose)
    for i, p in enumerate(pose):
        for j in range(3):
            np.testing.assert_allclose(got[i, j], Qf @ body_axis(links, mount, p, j), atol=1e-9)


def test_home_pose_alone_cannot_determine_the_matrix():
    rng = np.random.default_rng(1)
    C, bias, links, mount = draw_truth(rng)
    fit = fit_full_matrix(posed_observations(C, bias, links, mount, HOME))
    assert not fit.success
    assert fit.status == "not-determined"
    assert "two posed pairs" in fit.message


EXTRA = {"middle|inner 90": (1, [0, 0, Q]), "base|middle 90": (0, [0, Q, 0]),
         "base|inner 90": (0, [0, 0, Q]), "middle|inner 45": (1, [0, 0, Q / 2])}


@pytest.mark.parametrize("k", [0, 1, 2])
def test_rank_table_of_method_md(k):
    # hardware_docs/method.md: on a square gimbal the six home turns leave 3 directions
    # unobservable, each posed pair of turns removes two, and any two posed pairs give full rank.
    # Where the rank is short only near the true geometry (a 45° pose), the fit sees the missing
    # direction through rounding-level tilts: it converges with an uncertainty that makes the
    # model choice keep the diagonal model (issue 28).
    rng = np.random.default_rng(2)
    C, bias, links, mount = draw_truth(rng, tilt_rad=0.0, mount_rad=0.0)
    for keys in itertools.combinations(EXTRA, k):
        sched = HOME + [(EXTRA[key][0], np.array(EXTRA[key][1], float), d)
                        for key in keys for d in (1, -1)]
        obs = posed_observations(C, bias, links, mount, sched)
        fit = fit_full_matrix(obs)
        want = max(3 - 2 * k, 0)
        if want:
            if "90" in " ".join(keys) or not keys:  # exact rank at the true, square geometry
                assert fit.status == "not-determined", keys
                assert f"leave {want} combination" in fit.message, (keys, fit.message)
            elif fit.success:
                diag = estimate(obs, "paired-axis")
                choice = choose_model(fit.covariance, fit.matrix, diag.covariance, diag.scale,
                                      0.02)
                assert choice.chosen == "diagonal", (keys, choice)
        else:
            assert fit.success, (keys, fit.message)


def test_noisy_estimates_fall_within_their_uncertainty():
    rng = np.random.default_rng(11)
    z = []
    for _ in range(20):
        C, bias, links, mount = draw_truth(rng)
        fit = fit_full_matrix(posed_observations(C, bias, links, mount, POSED, noise=0.02,
                                                 rng=rng))
        assert fit.success
        err = np.concatenate([(fit.matrix - truth_in_frame(C)).ravel(), fit.bias - bias])
        std = np.sqrt(np.diag(fit.covariance))
        free = std > 0
        assert np.all(std[[1, 2, 5]] == 0)  # fixed by the frame convention
        z.append(err[free] / std[free])
    z = np.array(z)
    assert np.all(np.abs(z) < 4.5)
    assert 0.6 < np.std(z) < 1.4


def test_one_posed_pair_on_a_skewed_gimbal_is_observable_only_through_the_tilt():
    # The missing direction is then seen through the gimbal's small tilts: the fit says so with
    # an uncertainty hundreds of times that of a schedule of full rank (method.md).
    rng = np.random.default_rng(2)
    C, bias, links, mount = draw_truth(rng)
    one = HOME + [(1, np.array([0.0, 0.0, Q]), d) for d in (1, -1)]
    std = [np.sqrt(np.diag(fit_full_matrix(posed_observations(
        C, bias, links, mount, sched, noise=0.01, rng=rng)).covariance)[:9]).max()
        for sched in (one, POSED)]
    assert std[0] > 100 * std[1]


def test_paired_axis_on_a_posed_run_fits_one_axis_per_pose():
    # A sensor with no cross-axis terms (the paper's): the diagonal model holds in every pose, so
    # the paired-axis fit of the full protocol's posed turns recovers scale and bias exactly, its
    # reported axis of each servo being the one of its first (home) pose.
    rng = np.random.default_rng(7)
    _, bias, links, mount = draw_truth(rng)
    scale = np.array([1.03, 0.97, 1.01])
    obs = posed_observations(np.diag(1 / scale), bias, links, mount, POSED)
    np.testing.assert_array_equal(obs.pose_groups(), [0, 0, 1, 1, 2, 2, 3, 3, 4, 4])
    fit = estimate(obs, "paired-axis")
    assert fit.success, fit.message
    np.testing.assert_allclose(fit.scale, scale, atol=1e-9)
    np.testing.assert_allclose(fit.bias, bias, atol=1e-9)
    for s, motor in enumerate((1, 2, 3)):
        home = body_axis(links, mount, np.zeros(3), s)
        np.testing.assert_allclose(fit.axes[motor], home, atol=1e-9)
