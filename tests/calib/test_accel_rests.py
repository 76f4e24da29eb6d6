"""The planner's accelerometer rests (calib.design.plan_accel_rests, issue 15).

Truth is the test's own gimbal kinematics (rotation matrices written here, nothing shared with
calib.kinematics): with servo angles θ the sensor's orientation is R = R_0(θ0) R_1(θ1) R_2(θ2)
about the home axes, gravity in the sensor frame is Rᵀ up, and servo j's axis in the sensor
frame is (R_{j+1} ⋯ R_{S-1})ᵀ a_j (only the servos outside j move it).
"""

import math

import numpy as np
import pytest

from gyrocal.calib.accel import accel_design
from gyrocal.calib.design import (
    ACCEL_MIN_RESTS,
    ACCEL_STD_RATIO_TARGET,
    plan_accel_rests,
    plan_protocol,
    profile_duration,
    protocol_sequence,
    score_full_design,
)
from gyrocal.calib.errors import CalibInputError

AXES = np.eye(3)
UP = np.array([0.0, 0.0, 1.0])


def rot(axis, angle):
    a = np.asarray(axis, float) / np.linalg.norm(axis)
    k = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    return np.eye(3) + math.sin(angle) * k + (1 - math.cos(angle)) * k @ k


def walk(plan, axes=AXES):
    """Run the sequence on the test's gimbal: per rest the gravity direction, per turn
    (servo, its axis in the sensor frame, every servo's angle at its start, direction), the
    moves (servo, from, to) and where the servos end. A move straight after a turn fails."""
    here = np.zeros(len(axes))
    rests, turns, moves = [], [], []
    seq = protocol_sequence(plan, len(axes))
    for k, st in enumerate(seq):
        if st[0] == "still":
            continue
        if st[0] == "move":
            if k and seq[k - 1][0] == "rotate":
                raise AssertionError("a move right after a turn leaves its window no still time")
            moves.append((st[1], here[st[1]], st[2]))
            here[st[1]] = st[2]
        elif st[0] == "rest":
            R = np.eye(3)
            for j in range(len(axes)):
                R = R @ rot(axes[j], here[j])
            rests.append(R.T @ UP)
        else:
            j = st[1]
            Rout = np.eye(3)
            for k in range(j + 1, len(axes)):
                Rout = Rout @ rot(axes[k], here[k])
            turns.append((j, Rout.T @ axes[j], here.copy(), st[2]))
            here[j] += st[2] * 2 * math.pi * plan.turns  # a turn winds the servo a revolution
    return np.array(rests), turns, moves, here


@pytest.fixture(scope="module")
def plans():
    gyro = plan_protocol(servo_max_speed=4.8, full_scale=math.radians(500), time_budget_s=45.0,
                         model="full")
    return gyro, plan_accel_rests(gyro, max_turns=3.0)


def test_the_default_rests_alone_cannot_determine_the_accelerometer(plans):
    gyro, _ = plans
    rests, _, _, _ = walk(gyro)
    assert len(np.unique(np.round(rests, 9), axis=0)) <= 3
    assert not accel_design(rests, 1.0).identifiable


def test_tilted_rests_determine_the_nine_parameters_within_the_stated_bound(plans):
    gyro, plan = plans
    rests, _, _, home = walk(plan)
    assert len(rests) == len(walk(gyro)[0]), "no rest is added, the existing ones are tilted"
    assert len(np.unique(np.round(rests, 9), axis=0)) >= 9
    d = accel_design(rests, window_std=1.0, gravity=1.0)
    assert d.identifiable
    assert d.worst_force_std <= ACCEL_STD_RATIO_TARGET
    assert plan.accel_std_ratio == pytest.approx(d.worst_force_std, rel=0.05)
    assert np.all(home == 0), "the run ends in the home pose"


def test_the_gyro_sees_the_same_turns_so_its_predicted_error_is_unchanged(plans):
    gyro, plan = plans
    _, before, _, _ = walk(gyro)
    _, after, _, _ = walk(plan)
    assert [t[0] for t in after] == [t[0] for t in before]
    for (_, u0, *_), (_, u1, *_) in zip(before, after, strict=True):
        assert np.allclose(u0, u1, atol=1e-12)
    # the design score of the turns as actually posed (inner servos tilted) is the same
    kw = dict(rate=plan.speed, window_std=1e-3, rest_std=1e-3, n_rests=len(walk(plan)[0]))
    assert any(np.any(ang != 0) for *_, ang, _ in after), "some turns start tilted"
    sched = [(j, ang, d) for j, _, ang, d in after]
    nominal = [(j, ang, d) for j, _, ang, d in before]
    s1 = score_full_design(sched, **kw)
    s0 = score_full_design(nominal, **kw)
    assert s1.rate_error_std == pytest.approx(s0.rate_error_std, rel=1e-9)
    assert plan.rate_error_std == gyro.rate_error_std


def test_the_added_time_is_the_moves_it_adds_and_far_below_a_gravity_tour(plans):
    gyro, plan = plans

    def move_time(moves):
        return sum(profile_duration(abs(b - a), plan.speed, plan.accel) + 0.1
                   for _, a, b in moves if abs(b - a) > 1e-12)

    def still(plan):
        return sum(st[1] for st in protocol_sequence(plan) if st[0] == "still")

    assert still(plan) >= 0.15 * sum(1 for st in protocol_sequence(plan) if st[0] == "still")
    added = move_time(walk(plan)[2]) - move_time(walk(gyro)[2]) + still(plan) - still(gyro)
    assert plan.accel_time_s == pytest.approx(added, rel=1e-9)
    assert plan.jig_time_s == pytest.approx(gyro.jig_time_s + added, rel=1e-12)
    assert 0 < plan.accel_time_s < 10.0  # the 14-point tour adds 17-22 s


def test_a_turning_servo_never_passes_the_cable_wrap_limit():
    gyro = plan_protocol(servo_max_speed=4.8, full_scale=math.radians(500), time_budget_s=45.0,
                         model="full")
    def reach(plan):  # the farthest from home a turning servo gets, turns
        return max(max(abs(a[j]), abs(a[j] + d * 2 * math.pi * plan.turns)) / (2 * math.pi)
                   for j, _, a, d in walk(plan)[1])

    plan = plan_accel_rests(gyro, max_turns=float(gyro.turns))
    assert reach(plan) <= gyro.turns + 1e-9, "with no slack, a servo turns only from home"
    loose = plan_accel_rests(gyro, max_turns=gyro.turns + 0.25)
    assert gyro.turns < reach(loose) <= gyro.turns + 0.25 + 1e-9


def test_a_diagonal_plan_gets_tilted_rests_too():
    gyro = plan_protocol(servo_max_speed=4.8, full_scale=math.radians(500), time_budget_s=30.0)
    plan = plan_accel_rests(gyro, max_turns=3.0)
    rests, before, _, home = walk(gyro)
    rests, after, moves, home = walk(plan)
    for (_, u0, *_), (_, u1, *_) in zip(before, after, strict=True):
        assert np.allclose(u0, u1, atol=1e-12)
    # seven rests cannot hold nine parameters and a test: five more at the end
    assert plan.accel_extra_rests == ACCEL_MIN_RESTS - 7 and len(rests) == ACCEL_MIN_RESTS
    assert accel_design(rests, 1.0, 1.0).worst_force_std <= ACCEL_STD_RATIO_TARGET
    assert np.all(home == 0)
    moved = sum(profile_duration(abs(b - a), plan.speed, plan.accel) + 0.1
                for _, a, b in moves if abs(b - a) > 1e-12)
    still = sum(st[1] for st in protocol_sequence(plan) if st[0] == "still")
    assert plan.accel_time_s == pytest.approx(moved + still + plan.accel_extra_rests * plan.rest_s)


def _sequence_time(plan) -> float:
    """The jig time of the plan's steps as the test walks them: a turn its profile and 0.1 s
    settling, a move its travel's profile and 0.1 s (none when the servo is there), rests and
    still time as given; a turn winds its servo by whole revolutions."""
    here, total = np.zeros(3), 0.0
    for st in protocol_sequence(plan):
        if st[0] == "rest":
            total += plan.rest_s
        elif st[0] == "still":
            total += st[1]
        elif st[0] == "rotate":
            total += profile_duration(2 * math.pi * plan.turns, plan.speed, plan.accel) + 0.1
            here[st[1]] += st[2] * 2 * math.pi * plan.turns
        elif abs(st[2] - here[st[1]]) > 1e-12:
            total += profile_duration(abs(st[2] - here[st[1]]), plan.speed, plan.accel) + 0.1
            here[st[1]] = st[2]
    return total


def test_the_planned_jig_time_is_the_time_of_the_steps_the_jig_runs(plans):
    # the gyro's time model once counted three rests per posed pair (the protocol runs two),
    # and an accelerometer move between a servo's turns once went a revolution the long way
    gyro, plan = plans
    assert gyro.jig_time_s == pytest.approx(_sequence_time(gyro), rel=1e-12)
    assert plan.jig_time_s == pytest.approx(_sequence_time(plan), rel=1e-12)
    _, _, moves, _ = walk(plan)
    assert max(abs(b - a) for _, a, b in moves) <= math.pi + 1e-9


def test_a_turn_after_a_pose_move_has_still_time_before_it(plans):
    # the turn's rest-to-rest window reaches 0.15 s back before the motion: it must not read
    # the moved servo's last settling ticks
    for plan in plans:
        seq = protocol_sequence(plan)
        for k, st in enumerate(seq[1:], start=1):
            if st[0] == "rotate":
                assert seq[k - 1][0] in ("rest", "still"), f"step {k} turns right after a move"
                if seq[k - 1][0] == "still":
                    assert seq[k - 1][1] >= 0.15 + 0.03


def test_a_budget_the_accelerometer_s_rests_do_not_fit_says_so_and_what_to_do():
    # 18 s holds the diagonal gyro protocol alone (17.4 s) but not with the rests' moves; 12 s
    # holds neither, and the rests are then not what is blamed
    kw = dict(servo_max_speed=4.8, full_scale=math.radians(500), accel_rests=True, max_turns=3.0)
    assert plan_protocol(time_budget_s=18.0, **{**kw, "accel_rests": False}).jig_time_s <= 18.0
    with pytest.raises(CalibInputError, match=r"the accelerometer's rests take \d+\.\d s .*"
                       r"turn the accelerometer's rests off"):
        plan_protocol(time_budget_s=18.0, **kw)
    with pytest.raises(CalibInputError, match=r"no protocol fits 12 s .*; raise the time "
                       r"budget$"):
        plan_protocol(time_budget_s=12.0, **kw)


def test_the_search_is_cached_for_the_same_steps_whatever_the_predicted_figures(plans):
    """The beam search runs once per protocol (issue 25: ``gyrocal thermal`` planned it for
    each of its runs): a plan that differs only in its noise-scaled predictions (another
    measured noise) reuses it, and the cached result is the search's own."""
    from dataclasses import replace

    from gyrocal.calib import design

    gyro, tilted = plans
    noisier = replace(gyro, scale_std=tuple(2 * x for x in gyro.scale_std),  # type: ignore[arg-type]
                      bias_std=tuple(2 * x for x in gyro.bias_std),  # type: ignore[arg-type]
                      rate_error_std=2 * gyro.rate_error_std, matrix_std=None)
    hits = design._accel_rest_search.cache_info().hits
    again = plan_accel_rests(noisier, max_turns=3.0)
    assert design._accel_rest_search.cache_info().hits == hits + 1
    assert again.accel_moves == tilted.accel_moves and again.jig_time_s == tilted.jig_time_s
    assert again.rate_error_std == noisier.rate_error_std  # its own figures are kept
    extra, fresh = design._accel_rest_search.__wrapped__(
        replace(design._turns_only(gyro), rest_s=0.0), None, None, 3.0, 0.1, 24)
    assert extra == tilted.accel_extra_rests == 0  # the full protocol has rests enough
    assert (tilted.accel_time_s, tilted.accel_std_ratio, tilted.accel_moves) in fresh
    misses = design._accel_rest_search.cache_info().misses
    plan_accel_rests(replace(gyro, turns=gyro.turns + 1), max_turns=4.0)
    info = design._accel_rest_search.cache_info()  # other steps: searched
    assert (info.hits, info.misses) == (hits + 1, misses + 1)


def test_one_plan_searches_once_per_distinct_sequence_of_steps(monkeypatch):
    """Issue 25: with the accelerometer's rests over the budget, :func:`plan_protocol` plans the
    gyro again with a shorter budget; the new protocol may differ only in its rest length,
    which the search does not depend on, so it is searched once (it was searched again: seven
    beam searches, about 0.3 CPU s, per emulated calibration). The accelerometer's moves are
    the same. The gyro's candidates are scored once too, within the whole budget; the shorter
    budget picks among them what scoring only its own candidates picks."""
    import functools
    from dataclasses import replace

    from gyrocal.calib import design

    searched: list = []
    asked: list = []
    uncached = design._accel_rest_search.__wrapped__
    search = functools.lru_cache(maxsize=32)(lambda *a: searched.append(a) or uncached(*a))
    monkeypatch.setattr(design, "_accel_rest_search", search)
    scored: list = []
    score = design._full_candidates.__wrapped__
    monkeypatch.setattr(design, "_full_candidates", functools.lru_cache(maxsize=16)(
        lambda *a: scored.append(a) or score(*a)))
    planned: list = []
    plan_full = design._plan_full_cached.__wrapped__
    monkeypatch.setattr(design, "_plan_full_cached", functools.lru_cache(maxsize=32)(
        lambda *a: planned.append(a) or plan_full(*a)))
    real_moves = design._accel_rest_moves
    monkeypatch.setattr(design, "_accel_rest_moves",
                        lambda plan, *a: asked.append(plan) or real_moves(plan, *a))
    # the emulated jig's servo and gyro, its measured noise (calibrate --sim --sim-seed 3)
    plan = plan_protocol(servo_max_speed=4.796164784480418, full_scale=math.radians(500),
                         time_budget_s=45.0, noise_std=0.0025939367200543072, model="full",
                         accel_rests=True, max_turns=3.0)
    assert len({p.rest_s for p in asked}) == 2  # planned again with another rest length
    assert len({replace(p, rest_s=0.0) for p in asked}) == 1
    assert len(searched) == 1
    assert plan.jig_time_s <= 45.0 and plan.rest_s == asked[-1].rest_s
    # the gyro's candidates scored once, within the whole budget; the shorter budget picks
    # among them the plan that scoring only those within it picks
    assert [a[1] for a in scored] == [45.0] and len(planned) == 2
    shorter = planned[-1][:-1]
    alone = design._plan_full(*shorter, shorter[1])  # scored within the shorter budget only
    assert [a[1] for a in scored] == [45.0, shorter[1]]
    assert alone == design._plan_full(*shorter, 45.0)
    assert (alone.speed, alone.turns, alone.rest_s, alone.poses) == (
        plan.speed, plan.turns, plan.rest_s, plan.poses)
