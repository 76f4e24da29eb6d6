"""score_full_design (issue 10) against an independent Fisher information.

The independent computation shares no code with gyrocal: the gimbal is built with scipy's
rotations (tests/calib/fullmodel_truth.body_axis), parametrised by the lower-triangular C = A⁻¹,
the bias and two tilt angles per link axis (mount fixed: the frame convention), its Jacobian taken
by central finite differences, the axes eliminated by inverting the whole information matrix.
"""

import numpy as np
import pytest

from gyrocal.calib.design import full_schedule, score_full_design
from gyrocal.calib.errors import CalibInputError
from tests.calib.fullmodel_truth import body_axis, independent_fisher

POSES_2 = ((1, 2, np.pi / 2), (0, 1, np.pi / 2))
POSES_45 = ((1, 2, np.pi / 4), (0, 2, np.pi / 4))


@pytest.mark.parametrize("poses", [POSES_2, POSES_45])
def test_predicted_sigma_matches_an_independent_fisher_information(poses):
    rng = np.random.default_rng(11)
    links0 = np.eye(3) + rng.uniform(-0.03, 0.03, (3, 3))  # a gimbal not machined square
    links0 /= np.linalg.norm(links0, axis=1, keepdims=True)
    sched = full_schedule(poses)
    got = score_full_design(sched, rate=2.5, window_std=4e-4, rest_std=3e-4, n_rests=7,
                            axes=links0, n_search=200)
    want, info = independent_fisher(links0, sched, 2.5, 4e-4, 3e-4, 7)
    np.testing.assert_allclose(got.parameter_std, want, rtol=1e-4, atol=1e-12)
    assert got.model == "full"
    sign = np.where(np.arange(12) < 9, -1.0, 1.0)  # dA = −dC
    np.testing.assert_allclose(got.information, sign[:, None] * info * sign[None, :],
                               rtol=1e-3, atol=1e-6 * np.abs(info).max())


def test_g_efficiency_obeys_kiefer_wolfowitz_and_ranks_designs():
    kw = dict(rate=3.0, window_std=1e-3, rest_std=1e-3, n_rests=0, n_search=300)
    scores = {name: score_full_design(full_schedule(p), **kw)
              for name, p in (("90", POSES_2), ("45", POSES_45),
                              ("three 90", POSES_2 + ((0, 2, np.pi / 2),)))}
    for s in scores.values():
        assert 0 < s.g_efficiency <= 1.0 + 1e-9
        # the standardised variance where it is largest is the G-efficiency's bound
        assert s.rate_error_std > 0
    # More posed turns never lose information; 45° poses see the cross terms less than 90°.
    assert scores["three 90"].g_efficiency > scores["90"].g_efficiency
    assert scores["45"].rate_error_std > scores["90"].rate_error_std


def test_home_turns_alone_cannot_determine_the_matrix():
    s = score_full_design(full_schedule(()), rate=3.0, window_std=1e-3, rest_std=1e-3, n_rests=7)
    assert s.g_efficiency == 0.0 and s.max_variance == np.inf


def test_monte_carlo_spread_of_the_estimator_matches_the_score():
    # The estimator on noisy data of the independent generator: its spread over 300 draws is the
    # score's σ (each within ±20 %, the 300-draw sampling error of a σ being about ±8 % at 2σ).
    from gyrocal.calib.estimators import full_matrix_batch

    sched = full_schedule(POSES_2)
    n, B, sigma, rate = len(sched), 300, 2e-3, 3.0
    rng = np.random.default_rng(5)
    mean = np.array([body_axis(list(np.eye(3)), np.eye(3), p, s) * d * rate
                     for s, p, d in sched])
    noisy = mean[None] + rng.normal(0, sigma, (B, n, 3))
    rest = rng.normal(0, sigma, (B, 7, 3))
    midx = np.array([s for s, _, _ in sched])
    pose = np.array([p for _, p, _ in sched])
    signed = np.array([d * rate for _, _, d in sched])
    res = full_matrix_batch(noisy, np.tile(signed, (B, 1)), midx, pose,
                            np.full((B, n, 3), sigma), np.full((B, n), 1e-12), rest,
                            np.full((B, 7, 3), sigma), n_servos=3, reference=np.zeros(3))
    err = np.concatenate([(res.matrix - np.eye(3)).reshape(B, 9), res.bias], axis=1)
    got = score_full_design(sched, rate=rate, window_std=sigma, rest_std=sigma, n_rests=7,
                            n_search=100)
    std = np.array(got.parameter_std)
    free = std > 0
    np.testing.assert_allclose(err[:, free].std(axis=0), std[free], rtol=0.2)


def test_bad_inputs_are_refused():
    with pytest.raises(CalibInputError, match="no turns"):
        score_full_design([], rate=1.0, window_std=1e-3, rest_std=1e-3, n_rests=1)
    with pytest.raises(CalibInputError, match="window_std"):
        score_full_design(full_schedule(POSES_2), rate=1.0, window_std=0.0, rest_std=1e-3,
                          n_rests=1)
    with pytest.raises(CalibInputError, match="fastest turn"):
        score_full_design(full_schedule(POSES_2), rate=3.0, window_std=1e-3, rest_std=1e-3,
                          n_rests=1, radius=1.0)


def test_the_design_s_specific_forces_match_the_independent_generator():
    # tests/calib/gsens_truth.py (scipy rotations, a numeric mean over each revolution) with a
    # unit g-sensitivity on a square gimbal: each window's and rest's mean reading less its rate
    # part is its specific force, what the planner models each turn and rest to see.
    from gyrocal.calib.design import (
        Plan,
        _design_forces,
        full_schedule,
        gravity_poses,
        protocol_sequence,
    )
    from gyrocal.calib.kinematics import chain_axes
    from tests.calib.gsens_truth import gsens_observations

    poses = ((1, 2, np.pi / 2), (0, 1, np.pi / 2), (0, 2, np.pi / 4))
    grav = gravity_poses(poses)
    sched = full_schedule(poses)
    midx = np.array([t[0] for t in sched])
    pose = np.array([t[1] for t in sched])
    u = chain_axes(np.eye(3), np.zeros(3), pose)[np.arange(len(sched)), midx]
    f_win, f_rest, basis = _design_forces(np.eye(3), u, pose, poses, grav, None)
    assert basis.shape == (3, 3)
    # the rests where the protocol the jig runs holds them (calib.design.protocol_sequence;
    # a restated layout once counted three rests per posed pair where the protocol runs two)
    plan = Plan(1.0, 1, 1.0, 10.0, 0.0, (0.0,) * 3, (0.0,) * 3, 0.0, 1.0, poses=poses,
                gravity_poses=grav)
    here, rest_poses = np.zeros(3), []
    for step in protocol_sequence(plan):
        if step[0] == "rest":
            rest_poses.append(here.copy())
        elif step[0] == "move":
            here[step[1]] = step[2]
    links = [np.eye(3)[j] for j in range(3)]
    obs = gsens_observations(np.eye(3), np.zeros(3), np.eye(3), links, np.eye(3), sched,
                             rest_poses, speed=1.0, n_avg=64)
    np.testing.assert_allclose(f_rest @ basis, obs.rest_mean, atol=1e-12)
    want = obs.mean - obs.rate[:, None] * u
    np.testing.assert_allclose(f_win @ basis, want, atol=1e-12)


def test_predicted_uncertainty_with_g_sensitivity_costs_the_bias_and_the_rate():
    # Fitting G (three more unknowns per axis, seen only through how gravity moves between
    # windows) can only lose precision on the same data; the zero-g bias is what G trades with.
    from gyrocal.calib.design import gravity_poses, predict_full_uncertainty

    poses = ((1, 2, np.pi / 2), (0, 1, np.pi / 2), (0, 2, np.pi / 2))
    grav = gravity_poses(poses)
    kw = dict(noise_std=0.01, odr_hz=200.0, reference_rate=1.0)
    cands = [(3.0, 1, 1.0), (2.0, 2, 1.5)]
    ms0, bs0, e0 = predict_full_uncertainty(cands, poses, **kw)
    ms1, bs1, e1 = predict_full_uncertainty(cands, poses, gravity=grav, **kw)
    assert np.all(np.isfinite(e1)) and np.all(e1 > e0)
    assert np.all(bs1 > 1.1 * bs0)
    assert np.all(ms1 >= ms0 - 1e-12)
