"""The single-servo jig's seats: the same estimators on sessions of an independent generator
(tests/calib/seats_truth.py), and the planner's seat sets (calib.design.plan_seats)."""

import numpy as np
import pytest

from gyrocal.calib.design import SEAT_SETS, SEATS, plan_seats, seat_axes
from gyrocal.calib.errors import CalibInputError
from gyrocal.calib.estimators import FULL_FRAME, estimate
from tests.calib.fullmodel_truth import draw_truth, truth_in_frame
from tests.calib.seats_truth import EDGES, FACES, session


@pytest.mark.parametrize("seed", [0, 1])
def test_faces_and_edges_determine_the_full_matrix_within_its_sigma(seed):
    rng = np.random.default_rng(seed)
    C, bias, _, _ = draw_truth(rng)
    obs, seat, *_ = session({**FACES, **EDGES}, C=C, bias=bias, rng=rng, noise=0.03, count=800)
    fit = estimate(obs.by_seat(seat), "full-matrix")
    assert fit.success, fit.message
    assert fit.frame == FULL_FRAME
    err = np.concatenate([(fit.matrix - truth_in_frame(C)).ravel(), fit.bias - bias])
    std = np.sqrt(np.diag(fit.covariance))
    free = std > 0
    assert np.all(np.abs(err[free]) < 4.5 * std[free]), (err, std)
    assert np.all(err[~free] == 0)  # the frame's three zeros
    assert fit.consistency is not None and fit.consistency.ok


def test_noise_free_seats_recover_the_matrix_whatever_the_seating_error():
    # 3° of seating error per seat and a tilted shaft: the seats' axes are free unknowns, so the
    # matrix comes out exact all the same.
    rng = np.random.default_rng(7)
    C, bias, _, _ = draw_truth(rng)
    obs, seat, *_ = session({**FACES, **EDGES}, C=C, bias=bias, rng=rng,
                              seat_error_rad=np.radians(3), shaft_tilt_rad=0.02)
    fit = estimate(obs.by_seat(seat), "full-matrix")
    assert fit.success, fit.message
    np.testing.assert_allclose(fit.matrix, truth_in_frame(C), atol=1e-9)
    np.testing.assert_allclose(fit.bias, bias, atol=1e-9)


def test_faces_alone_leave_the_matrix_undetermined_and_fit_the_diagonal():
    rng = np.random.default_rng(3)
    scale = np.array([1.02, 0.98, 1.01])
    bias = np.array([0.03, -0.02, 0.01])
    obs, seat, *_ = session(FACES, C=np.diag(1 / scale), bias=bias, rng=rng)
    by_seat = obs.by_seat(seat)
    full = estimate(by_seat, "full-matrix")
    assert not full.success and full.status == "not-determined"
    diag = estimate(by_seat, "paired-axis")
    assert diag.success
    np.testing.assert_allclose(diag.scale, scale, atol=1e-9)
    np.testing.assert_allclose(diag.bias, bias, atol=1e-9)


def test_one_axis_for_all_seats_is_not_a_calibration():
    # Without the seats every window is the one servo's: the fits cannot pair the turns.
    rng = np.random.default_rng(4)
    C, bias, _, _ = draw_truth(rng)
    obs, seat, *_ = session({**FACES, **EDGES}, C=C, bias=bias, rng=rng)
    assert obs.motors == (1,)
    assert obs.by_seat(seat).chain == (1, 2, 3, 4, 5, 6)


def test_by_seat_refuses_a_seat_list_of_the_wrong_length():
    rng = np.random.default_rng(5)
    C, bias, _, _ = draw_truth(rng)
    obs, seat, *_ = session(FACES, C=C, bias=bias, rng=rng)
    with pytest.raises(CalibInputError, match="one seat number"):
        obs.by_seat(seat[:-1])


def test_seat_table_is_unit_and_matches_the_generators_own_directions():
    for name, (up, _) in SEATS.items():
        assert abs(np.linalg.norm(up) - 1) < 1e-12, name
    for name, up in {**FACES, **EDGES}.items():
        np.testing.assert_allclose(SEATS[name][0], up, atol=1e-12)
    with pytest.raises(CalibInputError, match="not one of"):
        seat_axes(("+w",))


def test_planner_full_model_takes_edge_seats_and_diagonal_the_faces():
    full = plan_seats(servo_max_speed=4.8, full_scale=np.radians(500), noise_std=0.02)
    assert full.model == "full"
    assert any(SEATS[s][1] == "V-block" for s in full.seats)
    assert max(max(abs(x) for x in row) for row in full.matrix_std) < 1e-3
    diag = plan_seats(servo_max_speed=4.8, full_scale=np.radians(500), noise_std=0.02,
                      model="diagonal")
    assert diag.seats == SEAT_SETS["faces"] and diag.model == "diagonal"


def test_g_sensitivity_is_fitted_from_the_gravity_each_seat_read():
    # Gravity along the shaft in every seat: G u of each seat is a different bias. With each
    # seat's gravity (the accelerometer's reading at the seat check) the fit models it.
    rng = np.random.default_rng(11)
    C, bias, _, _ = draw_truth(rng)
    G = rng.uniform(-1, 1, (3, 3)) * np.radians(0.1)  # the MPU-9250's 0.1 °/s/g per term
    # a plumb shaft: the windows' force is then exactly the rests' (a tilt t of the shaft
    # leaves G γ − G (u·γ) u ≈ |G| t in each turn's offset: 3e-5 rad/s at 1° and 0.1 °/s/g)
    obs, seat, _, rest_seat, up = session({**FACES, **EDGES}, C=C, bias=bias, rng=rng,
                                          g_sensitivity=G, shaft_tilt_rad=0.0)
    plain = estimate(obs.by_seat(seat), "full-matrix")
    # each seat's G u is a bias of its own: one bias fits none of them (A stays right, as the
    # two turns of a seat share it)
    assert np.max(np.abs(plain.bias - bias)) > 1e-4
    assert not plain.consistency.ok
    fit = estimate(obs.by_seat(seat, rest_seat, up), "full-matrix")
    assert fit.success, fit.message
    np.testing.assert_allclose(fit.matrix, truth_in_frame(C), atol=1e-9)
    np.testing.assert_allclose(fit.bias, bias, atol=1e-9)
    np.testing.assert_allclose(fit.g_sensitivity, G, atol=1e-9)


def test_by_seat_refuses_forces_that_do_not_match_the_seats():
    rng = np.random.default_rng(12)
    C, bias, _, _ = draw_truth(rng)
    obs, seat, _, rest_seat, up = session(FACES, C=C, bias=bias, rng=rng)
    with pytest.raises(CalibInputError, match="seat_force"):
        obs.by_seat(seat, rest_seat, up[:2])


@pytest.mark.parametrize("seed", range(3))
def test_the_six_edges_alone_pass_the_axis_check_and_determine_the_matrix(seed):
    # (x + y)/√2 and its kind: 0.707 on two axes; a degree of seating error and the shaft's
    # tilt tip one below 0.7 (seed 1: z at most 0.69), which the axis check refused before
    rng = np.random.default_rng([seed, 0x51])
    C, bias, _, _ = draw_truth(rng)
    G = rng.uniform(-1, 1, (3, 3)) * np.radians(0.1)
    edges = {s: SEATS[s][0] for s in SEAT_SETS["edges"]}
    obs, seat, _, rest_seat, up = session(
        edges, C=C, bias=bias, rng=rng, speed=4.3, noise=1.7e-3, count=580,
        seat_error_rad=np.radians(1), shaft_tilt_rad=np.radians(0.3), g_sensitivity=G)
    fit = estimate(obs.by_seat(seat, rest_seat, up), "full-matrix")
    assert fit.success, fit.message
    err = np.concatenate([(fit.matrix - truth_in_frame(C)).ravel(), fit.bias - bias])
    std = np.sqrt(np.diag(fit.covariance))
    assert np.all(np.abs(err[std > 0]) < 4.5 * std[std > 0])


@pytest.mark.parametrize("seed", range(3))
def test_still_angles_shared_across_a_reseat_converge(seed):
    # The one servo's still angle between two seats is referenced by turns of both: moving it
    # is no symmetry of the fit (the gimbal's encoder-zero gauge must leave it alone)
    rng = np.random.default_rng([seed, 0x57])
    C, bias, _, _ = draw_truth(rng)
    edges = {s: SEATS[s][0] for s in SEAT_SETS["edges"]}
    obs, seat, *_ = session(edges, C=C, bias=bias, rng=rng, speed=4.3, noise=1.7e-3,
                            count=580, still_std=2 * np.pi / 4096 / np.sqrt(12), turns=1)
    fit = estimate(obs.by_seat(seat), "full-matrix")
    assert fit.success, fit.message
    err = np.concatenate([(fit.matrix - truth_in_frame(C)).ravel(), fit.bias - bias])
    std = np.sqrt(np.diag(fit.covariance))
    assert np.all(np.abs(err[std > 0]) < 4.5 * std[std > 0])
