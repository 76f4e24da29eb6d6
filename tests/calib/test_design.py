import numpy as np
import pytest

from gyrocal.calib.design import (
    PAPER_DESIGN,
    jig_time,
    paper_plan,
    plan_protocol,
    score_design,
    sphere_points,
)
from gyrocal.calib.errors import CalibInputError
from gyrocal.calib.estimators import fit_paired_axis
from gyrocal.calib.simulate import SimProtocol, simulate_raw_run
from gyrocal.calib.windows import extract_observations


def test_papers_six_point_design_is_g_optimal():
    s = score_design(PAPER_DESIGN)
    # Kiefer-Wolfowitz: max d >= p = 6, with equality for a G-optimal design.
    assert s.max_variance == pytest.approx(6.0, rel=1e-6)
    assert s.g_efficiency == pytest.approx(1.0, rel=1e-6)
    assert np.max(np.abs(s.argmax)) == pytest.approx(1.0, abs=1e-4)  # on an axis


def test_prediction_variance_matches_its_closed_form():
    # For the six-point design, d(u) = 3 + 3 Σ u_j⁴ on the unit sphere.
    F = np.concatenate([PAPER_DESIGN**2, PAPER_DESIGN], axis=1)
    Minv = np.linalg.inv(F.T @ F)
    U = sphere_points(50)
    f = np.concatenate([U**2, U], axis=1)
    d = 6 * np.einsum("ij,jk,ik->i", f, Minv, f)
    np.testing.assert_allclose(d, 3 + 3 * np.sum(U**4, axis=1), rtol=1e-12)


def test_other_designs_score_worse_and_singular_ones_are_flagged():
    diagonal = np.array([[1, 1, 0], [-1, -1, 0], [0, 1, 1], [0, -1, -1], [1, 0, 1], [-1, 0, -1]])
    assert score_design(diagonal).g_efficiency < 0.6
    assert score_design(PAPER_DESIGN[::2]).g_efficiency == 0.0  # one direction per axis
    doubled = score_design(np.vstack([PAPER_DESIGN, PAPER_DESIGN]))
    assert doubled.g_efficiency == pytest.approx(1.0, rel=1e-6)


def test_score_design_validates():
    with pytest.raises(CalibInputError, match="shape"):
        score_design(np.zeros((3, 2)))
    with pytest.raises(CalibInputError, match="non-zero"):
        score_design(np.zeros((6, 3)))


def test_planner_respects_budget_servo_and_range():
    fs = np.radians(250)
    p = plan_protocol(servo_max_speed=6.0, full_scale=fs, time_budget_s=30.0)
    assert p.jig_time_s <= 30.0
    assert p.speed <= 0.9 * fs / 1.25 + 1e-12  # a reading ω/k with k >= 0.8 stays in range
    assert p.turns >= 1 and p.rest_s >= 0.6
    slow = plan_protocol(servo_max_speed=2.0, full_scale=np.radians(2000))
    assert slow.speed <= 1.8 + 1e-12
    assert jig_time(p.speed, p.turns, p.rest_s, p.accel) == pytest.approx(p.jig_time_s)


def test_planner_beats_the_papers_protocol_in_half_the_time():
    ours = plan_protocol(servo_max_speed=4.8, full_scale=np.radians(500))
    paper = paper_plan()
    assert paper.jig_time_s > 50 and ours.jig_time_s <= 30
    assert max(ours.scale_std) < 0.5 * min(paper.scale_std)
    assert ours.rate_error_std < paper.rate_error_std


def test_planner_refuses_an_impossible_budget():
    with pytest.raises(CalibInputError, match="no protocol fits"):
        plan_protocol(servo_max_speed=4.8, full_scale=8.0, time_budget_s=3.0)
    with pytest.raises(CalibInputError, match="servo_max_speed"):
        plan_protocol(servo_max_speed=-1.0, full_scale=8.0)


def test_predicted_uncertainty_matches_a_simulated_run_of_the_plan():
    plan = plan_protocol(servo_max_speed=4.8, full_scale=np.radians(500))
    rng = np.random.default_rng(1)
    run = simulate_raw_run(rng, np.ones(3), np.zeros(3), np.eye(3),
                           SimProtocol(speed=plan.speed, turns=plan.turns, rest_s=plan.rest_s,
                                       ripple=0.0),
                           0.035, accel=plan.accel)
    ex = extract_observations(run.imu_t, run.imu_rate, run.enc_t, run.enc_motor, run.enc_angle,
                              run.segments)
    fit = fit_paired_axis(ex.observations)
    np.testing.assert_allclose(fit.scale_std, plan.scale_std, rtol=0.25)
    np.testing.assert_allclose(fit.bias_std, plan.bias_std, rtol=0.25)
