"""The hand jig (calib/hand.py): rests and whole turns from the data, the same estimator.

Truth comes from the independent generator (tests/calib/hand_truth.py: scipy rotations, a
speed family and a wobble of its own, nothing shared with the emulator or the code under test).
"""

from __future__ import annotations

import numpy as np
import pytest

from gyrocal.calib.errors import CalibInputError
from gyrocal.calib.estimators import estimate
from gyrocal.calib.hand import (
    AXIS_MOTORS,
    STOP_STD_RAD,
    find_hand_turns,
    hand_observations,
)
from tests.calib import hand_truth as ht


@pytest.fixture(scope="module")
def session():
    rng = np.random.default_rng(7)
    C, bias, mount = ht.draw_sensor(rng)
    t, m, acc, truth = ht.hand_session(rng, C, bias, mount)
    return t, m, acc, truth


def test_the_turns_and_rests_are_found_and_reseats_are_not_turns(session):
    """Six whole turns (each box axis both ways) between rests; the 90° and 180° re-seats are
    motions, not turns (15 rests: the schedule of hand_truth.hand_session)."""
    t, m, _, _ = session
    found = find_hand_turns(t, m)
    assert len(found.rests) == 15
    assert sorted((u.axis, u.direction) for u in found.turns) == [
        (a, d) for a in range(3) for d in (-1, 1)]
    assert len(found.moves) == 8
    assert sorted(round(np.degrees(a) / 90) for *_, a in found.moves) == [1, 1] + [2] * 6


def test_each_turn_window_runs_rest_to_rest_with_360_degrees_over_its_duration(session):
    """The reference of every window is 2π over its weighted duration (∫w = the window's
    length less half its two ramps), whatever the hand's speed profile."""
    t, m, _, _ = session
    ex, _ = hand_observations(t, m)
    assert len(ex.windows) == 6
    for w in ex.windows:
        a, a2, b2, b = w.corners
        assert w.kind == "rest-to-rest" and w.motor in AXIS_MOTORS
        np.testing.assert_allclose(abs(w.rate), 2 * np.pi / (0.5 * ((b - a) + (b2 - a2))),
                                   rtol=1e-12)
    obs = ex.observations
    assert obs.own_axes and obs.still_angle_std == STOP_STD_RAD


def test_the_fit_recovers_the_generators_scale_and_bias_within_sigma(session):
    """A sensor without cross-axis terms on a box mounted 2° off: the diagonal model holds,
    so scale and bias are within 3σ of the truth and the verdict is consistent."""
    t, m, _, truth = session
    ex, _ = hand_observations(t, m)
    fit = estimate(ex.observations, "paired-axis")
    sd = np.sqrt(np.diag(fit.covariance))
    assert fit.success and fit.consistency.ok, fit.consistency
    assert np.all(np.abs(fit.scale - truth.scale) < 3 * sd[:3]), (fit.scale, truth.scale, sd)
    assert np.all(np.abs(fit.bias - truth.bias) < 3 * sd[3:]), (fit.bias, truth.bias, sd)
    assert np.all(sd[:3] < 1e-3)  # a few 1e-4: the stop (2.8e-4 of a turn) and the noise


def test_one_turn_per_axis_suffices_when_rests_measure_the_bias():
    """imucal's session turns each axis once (one way); the rests give the bias, so the
    paired-axis fit takes it (before: "needs at least 6 rotation windows, got 3")."""
    rng = np.random.default_rng(3)
    C, bias, mount = ht.draw_sensor(rng)
    t, m, _, truth = ht.hand_session(rng, C, bias, mount, both_ways=False)
    ex, _ = hand_observations(t, m)
    assert ex.observations.n_windows == 3
    fit = estimate(ex.observations, "paired-axis")
    sd = np.sqrt(np.diag(fit.covariance))
    assert np.all(np.abs(fit.scale - truth.scale) < 3.5 * sd[:3]), (fit.scale, truth.scale)


def test_a_recording_without_a_whole_turn_is_refused_saying_what_to_do():
    rng = np.random.default_rng(1)
    t = np.arange(2000) * 0.01
    m = rng.normal(0, 4e-3, (2000, 3)) + 0.02
    m[800:1000, 2] += np.pi / 2 / 2.0  # a quarter turn in 2 s
    with pytest.raises(CalibInputError, match="no whole turn between two rests"):
        hand_observations(t, m)


def test_a_recording_that_never_rests_is_refused():
    t = np.arange(1000) * 0.01
    m = np.column_stack([np.sin(3 * t), np.cos(2 * t), np.sin(5 * t)]) * 2.0
    with pytest.raises(CalibInputError, match="no rest found"):
        find_hand_turns(t, m)


def test_the_faces_g_sensitivity_is_measured_and_taken_off_the_turns():
    """With the MPU-9250's 0.1 °/s/g on the diagonal, a turn with its axis up reads 1.7e-3
    rad/s more on that axis than the rests on the other faces: without the accelerometer the
    fit is NOT consistent (a term the model leaves out); with it, the rests on six faces give
    G, the verdict is consistent and scale and bias are within 3σ."""
    from gyrocal.calib.hand import rest_g_sensitivity

    rng = np.random.default_rng(5)
    C, bias, mount = ht.draw_sensor(rng)
    G = np.diag(np.full(3, np.radians(0.1)))  # rad/s per g
    t, m, acc, truth = ht.hand_session(rng, C, bias, mount, g_sensitivity=G)
    found = find_hand_turns(t, m)
    G_fit = rest_g_sensitivity(found.t, m, acc, found.rests) * ht.G
    np.testing.assert_allclose(G_fit, G, atol=5e-4)  # rest means carry 2e-4 of noise each
    plain = estimate(hand_observations(t, m)[0].observations, "paired-axis")
    assert not plain.consistency.ok
    fit = estimate(hand_observations(t, m, accel=acc)[0].observations, "paired-axis")
    sd = np.sqrt(np.diag(fit.covariance))
    assert fit.consistency.ok
    assert np.all(np.abs(fit.scale - truth.scale) < 3 * sd[:3])
    assert np.all(np.abs(fit.bias - truth.bias) < 3 * sd[3:])


def test_a_turn_made_in_quarter_steps_with_pauses_is_one_turn():
    """imucal's example notes its operator turned in four 90° steps: with 1.5 s pauses
    (rests of their own) the steps about one axis in one sense add up to one whole turn,
    windowed from the rest before the first to the rest after the last; the half-turn flips to
    the opposite faces stay re-seats."""
    rng = np.random.default_rng(9)
    C, bias, mount = ht.draw_sensor(rng)
    t, m, _, truth = ht.hand_session(rng, C, bias, mount, turn_steps=4)
    found = find_hand_turns(t, m)
    assert sorted((u.axis, u.direction) for u in found.turns) == [
        (a, d) for a in range(3) for d in (-1, 1)]
    assert sorted(round(np.degrees(a) / 90) for *_, a in found.moves) == [1, 1] + [2] * 6
    fit = estimate(hand_observations(t, m)[0].observations, "paired-axis")
    sd = np.sqrt(np.diag(fit.covariance))
    assert fit.consistency.ok and np.all(np.abs(fit.scale - truth.scale) < 3 * sd[:3])


def test_a_bias_at_the_lsm9ds1s_zero_rate_tolerance_still_finds_the_rests():
    """±30 °/s (0.52 rad/s) is the LSM9DS1's zero-rate level: the first pass's rate limit is
    above it, so the rests and turns are found and the bias is recovered within 3σ."""
    rng = np.random.default_rng(13)
    C, _, mount = ht.draw_sensor(rng)
    bias = np.array([0.5, -0.45, 0.3])
    t, m, _, truth = ht.hand_session(rng, C, bias, mount)
    ex, found = hand_observations(t, m)
    assert len(found.turns) == 6
    fit = estimate(ex.observations, "paired-axis")
    assert np.all(np.abs(fit.bias - bias) < 3 * np.sqrt(np.diag(fit.covariance))[3:])
