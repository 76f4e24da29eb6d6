"""The accelerometer fit (calib.accel) against an independent generator (accel_truth)."""

from __future__ import annotations

import numpy as np
import pytest

from gyrocal.calib.accel import (
    STANDARD_GRAVITY,
    AccelCalibration,
    accel_design,
    fit_accelerometer,
    in_frame,
    normal_gravity,
    six_position,
)
from gyrocal.calib.errors import CalibInputError, CalibrationFormatError
from tests.calib.accel_truth import (
    fibonacci_directions,
    random_sensing,
    rest_means,
    truth_matrix,
)

G = 9.80


def _params(matrix: np.ndarray, bias: np.ndarray) -> np.ndarray:
    return np.concatenate([matrix[np.tril_indices(3)], bias])


def test_noise_free_recovery_to_1e9() -> None:
    rng = np.random.default_rng(1)
    c = random_sensing(rng)
    b = rng.uniform(-0.3, 0.3, 3)
    means, std = rest_means(rng, c, b, fibonacci_directions(14), G, 0.0, 1)
    fit = fit_accelerometer(means, np.full(means.shape, 1e-3), G)
    assert np.max(np.abs(fit.matrix - truth_matrix(c))) < 1e-9
    assert np.max(np.abs(fit.bias - b)) < 1e-9
    assert fit.converged and fit.consistency.chi2 < 1e-12


def test_with_noise_within_sigma_and_consistent() -> None:
    rng = np.random.default_rng(2)
    c = random_sensing(rng)
    b = rng.uniform(-0.3, 0.3, 3)
    means, std = rest_means(rng, c, b, fibonacci_directions(20), G, 0.02, 400)
    fit = fit_accelerometer(means, std, G)
    z = (_params(fit.matrix, fit.bias) - _params(truth_matrix(c), b)) / fit.std
    assert np.max(np.abs(z)) < 4.0
    assert fit.consistency.dof == 11 and fit.consistency.ok


def test_monte_carlo_coverage() -> None:
    """Over 200 seeded runs, each parameter's error lies within 1σ about 68 % of the time and
    the χ² test passes about 99 % of the time."""
    rng = np.random.default_rng(3)
    c = random_sensing(rng)
    b = rng.uniform(-0.3, 0.3, 3)
    truth = _params(truth_matrix(c), b)
    dirs = fibonacci_directions(12)
    inside, ok, runs = np.zeros(9), 0, 200
    for _ in range(runs):
        means, std = rest_means(rng, c, b, dirs, G, 0.02, 200)
        fit = fit_accelerometer(means, std, G)
        inside += np.abs(_params(fit.matrix, fit.bias) - truth) < fit.std
        ok += fit.consistency.ok
    cover = inside / runs
    # binomial σ of a 68 % rate over 200 runs is 3.3 %
    assert np.all(np.abs(cover - 0.683) < 0.11), cover
    assert ok >= 0.95 * runs


def test_wrong_gravity_goes_into_the_scales() -> None:
    """Fitting against standard gravity data taken at 9.78 m/s² scales A by g_n/9.78."""
    rng = np.random.default_rng(4)
    c = random_sensing(rng)
    means, _ = rest_means(rng, c, np.zeros(3), fibonacci_directions(12), 9.78, 0.0, 1)
    fit = fit_accelerometer(means, np.full(means.shape, 1e-3))
    assert fit.gravity == STANDARD_GRAVITY
    np.testing.assert_allclose(fit.matrix, truth_matrix(c) * STANDARD_GRAVITY / 9.78, atol=1e-9)


def test_normal_gravity_matches_wgs84_figures() -> None:
    # NIMA TR8350.2 Table 3.4: normal gravity at the equator and at the poles
    assert normal_gravity(0.0) == pytest.approx(9.7803253359, abs=1e-9)
    assert normal_gravity(90.0) == pytest.approx(9.8321849378, abs=1e-9)
    # free-air gradient near the surface ≈ −3.086e-6 s⁻² (TR8350.2 §4.3)
    slope = (normal_gravity(45.0, 100.0) - normal_gravity(45.0, 0.0)) / 100.0
    assert slope == pytest.approx(-3.086e-6, rel=2e-3)


def test_six_position_exact_when_aligned() -> None:
    rng = np.random.default_rng(5)
    c = np.diag([1.02, 0.99, 1.01]) + 0.01 * (1 - np.eye(3)) * rng.uniform(-1, 1, (3, 3))
    b = rng.uniform(-0.3, 0.3, 3)
    dirs = np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1.0]])
    means, _ = rest_means(rng, c, b, dirs, G, 0.0, 1)
    a, bias = six_position(means, G)
    np.testing.assert_allclose(a, np.linalg.inv(c), atol=1e-12)
    np.testing.assert_allclose(bias, b, atol=1e-12)
    np.testing.assert_allclose(in_frame(a), truth_matrix(c), atol=1e-12)


def test_design_scores() -> None:
    good = accel_design(fibonacci_directions(12), 1e-3)
    assert good.identifiable and good.condition < 100
    # four orientations cannot fix nine parameters
    bad = accel_design(fibonacci_directions(4), 1e-3)
    assert not bad.identifiable
    # a design's predicted σ matches the fit's stated σ
    rng = np.random.default_rng(6)
    means, std = rest_means(rng, np.eye(3), np.zeros(3), fibonacci_directions(12), G, 1e-2, 100)
    fit = fit_accelerometer(means, std, G)
    np.testing.assert_allclose(accel_design(fibonacci_directions(12), 1e-3, G).parameter_std,
                               fit.std, rtol=0.05)


def test_round_trip_and_bad_documents() -> None:
    rng = np.random.default_rng(7)
    means, std = rest_means(rng, random_sensing(rng), np.zeros(3), fibonacci_directions(12), G,
                            0.01, 100)
    fit = fit_accelerometer(means, std, G)
    back = AccelCalibration.from_dict(fit.to_dict())
    np.testing.assert_array_equal(back.matrix, fit.matrix)
    np.testing.assert_array_equal(back.covariance, fit.covariance)
    d = fit.to_dict()
    d["matrix"] = np.triu(np.ones((3, 3))).tolist()
    with pytest.raises(CalibrationFormatError, match="lower triangular"):
        AccelCalibration.from_dict(d)
    with pytest.raises(CalibrationFormatError, match="lacks the field 'bias'"):
        AccelCalibration.from_dict({k: v for k, v in fit.to_dict().items() if k != "bias"})


def test_bad_input_names_the_problem() -> None:
    with pytest.raises(CalibInputError, match="at least 10 rest windows"):
        fit_accelerometer(np.tile([0, 0, G], (5, 1)), np.full((5, 3), 1e-3))
    with pytest.raises(CalibInputError, match="near gravity"):
        fit_accelerometer(np.tile([0, 0, 1.0], (12, 1)), np.full((12, 3), 1e-3))
    with pytest.raises(CalibInputError, match="cannot determine"):
        fit_accelerometer(np.tile([0, 0, G], (12, 1)) + 1e-6 * np.arange(36).reshape(12, 3),
                          np.full((12, 3), 1e-3))
    with pytest.raises(CalibInputError, match="mean_std must have shape"):
        fit_accelerometer(np.tile([0, 0, G], (12, 1)), np.ones(3))
    with pytest.raises(CalibInputError, match="latitude_deg"):
        normal_gravity(91.0)


def test_calibration_document_carries_the_accelerometer() -> None:
    """The Calibration v1 document with an ``accelerometer`` object as hardware_docs/formats.md
    describes it, written out here field by field, reads back; an unknown field is refused."""
    from gyrocal.calib.model import GyroCalibration

    cov = np.diag([1e-8] * 6 + [1e-6] * 3)
    accel = {"model": "f = matrix @ (a + bias)", "frame": "accel-x-xy",
             "matrix": [[1.01, 0, 0], [0.002, 0.99, 0], [-0.003, 0.001, 1.02]],
             "bias": [0.1, -0.2, 0.3], "matrix_std": [[1e-4, 0, 0], [1e-4, 1e-4, 0],
                                                      [1e-4, 1e-4, 1e-4]],
             "bias_std": [1e-3] * 3, "covariance": cov.tolist(), "gravity_m_s2": 9.80665,
             "consistency": {"chi2": 3.0, "dof": 3, "p_value": 0.39, "ok": True},
             "rests": 12, "iterations": 7, "converged": True}
    doc = {"format": "gyrocal-calibration", "version": 1, "model": "g = scale * (m + bias)",
           "scale": [1.0, 1.0, 1.0], "bias": [0.0, 0.0, 0.0], "accelerometer": accel}
    cal = GyroCalibration.from_dict(doc)
    assert cal.accelerometer is not None
    np.testing.assert_array_equal(cal.accelerometer.matrix, accel["matrix"])
    np.testing.assert_allclose(cal.accelerometer.apply(np.array([[0, 0, 9.5]])),
                               [[0.1 * 0, 0, 0]] + np.array(accel["matrix"]) @ [0.1, -0.2, 9.8],
                               atol=1e-12)
    assert cal.to_dict()["accelerometer"]["matrix"] == accel["matrix"]
    with pytest.raises(CalibrationFormatError, match="'accelerometer'"):
        GyroCalibration.from_dict({**doc, "accelerometer": {**accel, "scales": [1, 1, 1]}})


def _rot(axis: int, angle: float) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    i, j = (axis + 1) % 3, (axis + 2) % 3  # right-handed about the axis
    r = np.eye(3)
    r[i, i], r[i, j], r[j, i], r[j, j] = c, -s, s, c
    return r


def test_gravity_tour_visits_its_directions_and_costs_its_moves() -> None:
    from gyrocal.calib.accel import TOUR_DIRECTIONS, gravity_tour
    from gyrocal.calib.simulate import profile_duration

    speed, acc, rest = np.radians(247.0), 10.0, 0.6
    tour = gravity_tour(speed, acc, rest)
    # every tour direction but home's +z, each once, reached by base-x then middle-y rotations
    assert len(tour.poses_rad) == len(TOUR_DIRECTIONS) - 1
    for (p1, p2), u in zip(tour.poses_rad, tour.directions, strict=True):
        g = (_rot(0, p1) @ _rot(1, p2)).T @ [0, 0, 1.0]
        np.testing.assert_allclose(u, g, atol=1e-12)
        assert np.min(np.linalg.norm(TOUR_DIRECTIONS - g, axis=1)) < 1e-9
    # the added time is at least the rests plus, per rest, one move's profile
    floor = len(tour.poses_rad) * rest
    assert floor < tour.added_time_s < floor + 2 * len(tour.poses_rad) * (
        profile_duration(np.pi, speed, acc) + 0.1) + 2 * profile_duration(np.pi, speed, acc)
    # with the tour, the default protocol's two directions become a well-conditioned design
    home = np.array([[0, 0, 1.0]] * 10 + [[-np.sqrt(0.5), 0, np.sqrt(0.5)]] * 3)
    assert not accel_design(home, 1e-3).identifiable
    d = accel_design(np.vstack([home, tour.directions]), 1e-3)
    assert d.identifiable and d.condition < 10


def test_terms_held_at_zero_carry_their_prior_into_the_fitted_ones_sigma() -> None:
    """Six faces of a hand-held box (each twice, the box 2° off the sensor's axes): the rests
    do not determine the cross-axis terms, which stay at zero, yet the true ones are up to the
    datasheet's ±2 %; the diagonal and bias σ must cover what that does to them. Before, the
    diagonal's σ held the white noise only (emulated hand jig: A_xx off by 8.5σ)."""
    rng = np.random.default_rng(44)
    faces = np.repeat(np.vstack([np.eye(3), -np.eye(3)]), 2, axis=0)
    z = []
    for _ in range(60):
        axis = rng.normal(size=3)
        mount = _rot_vec(axis / np.linalg.norm(axis) * np.radians(2.0))
        c = np.diag(1 + 0.02 * rng.uniform(-1, 1, 3)) + 0.02 * rng.uniform(-1, 1, (3, 3)) * (
            1 - np.eye(3))
        b = rng.uniform(-0.3, 0.3, 3)
        means, std = rest_means(rng, c, b, faces @ mount.T, G, 0.02, 400)
        fit = fit_accelerometer(means, std, G)
        assert set(fit.fixed) == {"A10", "A20", "A21"}
        err = _params(fit.matrix, fit.bias) - _params(truth_matrix(c), b)
        z.append((err / fit.std)[[0, 2, 5, 6, 7, 8]])  # the diagonal and the bias
    z = np.array(z)
    rms = np.sqrt(np.mean(z**2, axis=0))
    assert np.all((rms > 0.4) & (rms < 1.3)), rms
    assert np.mean(np.abs(z) <= 1.96) > 0.93


def _rot_vec(v: np.ndarray) -> np.ndarray:
    """The rotation matrix of rotation vector ``v`` (Rodrigues)."""
    t = np.linalg.norm(v)
    k = np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]]) / t
    return np.eye(3) + np.sin(t) * k + (1 - np.cos(t)) * k @ k
