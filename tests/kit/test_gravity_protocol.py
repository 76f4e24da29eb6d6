"""The kit's side of g-sensitivity: which servo is vertical, and the planner's gravity rests."""

import numpy as np
import pytest

from gyrocal.calib.design import gravity_poses, jig_time, plan_protocol, profile_duration
from gyrocal.kit.pipeline import gravity_servo
from gyrocal.kit.protocol import build_steps


@pytest.mark.parametrize(("axes", "expected"), [
    (["x", "y", "z"], (3, 1)), (["z", "x", "y"], (1, 1)), (["x", "-z", "y"], (2, -1)),
    (["x", "y", "-y"], None),
])
def test_the_vertical_servo_is_the_one_listed_with_axis_z(axes, expected):
    manifest = {"gimbal": {"motors": [{"id": i + 1, "axis": a} for i, a in enumerate(axes)]}}
    assert gravity_servo(manifest) == expected


def test_no_gimbal_in_the_manifest_means_no_gravity():
    assert gravity_servo({}) is None
    assert gravity_servo({"gimbal": {"motors": "?"}}) is None


def test_gravity_rests_cover_the_horizontal_servos_the_poses_leave_still():
    q = np.pi / 2
    # posed pairs moving the middle (y) servo see gravity tilt about y; the base (x) is left
    assert gravity_poses(((0, 1, q), (1, 2, q))) == ((0, q),)
    # poses moving only the vertical (z) servo: both horizontal servos get a rest
    assert gravity_poses(((1, 2, q), (0, 2, q))) == ((0, q), (1, q))
    assert gravity_poses(((2, 1, q), (1, 0, q))) == ()
    # a gimbal whose base is the vertical axis
    assert gravity_poses(((2, 1, q),), axes=np.array([[0, 0, 1.0], [1, 0, 0], [0, 1, 0]])) == (
        (2, q),)


def test_the_full_plan_counts_its_gravity_rests_and_the_steps_run_them():
    plan = plan_protocol(servo_max_speed=4.8, full_scale=np.radians(500), time_budget_s=45.0,
                         model="full")
    assert plan.gravity_poses, "the default poses leave a horizontal servo still"
    angles = tuple(abs(a) for *_, a in plan.poses)
    base = jig_time(plan.speed, plan.turns, plan.rest_s, plan.accel, move_angles=angles)
    extra = sum(plan.rest_s + 2 * (profile_duration(a, plan.speed, plan.accel) + 0.1)
                for _, a in plan.gravity_poses)
    assert plan.jig_time_s == pytest.approx(base + extra, rel=1e-12)
    assert plan.jig_time_s <= 45.0
    steps = build_steps(plan, [1, 2, 3])
    tail = steps[-3 * len(plan.gravity_poses):]
    triples = [tuple(tail[i:i + 3]) for i in range(0, len(tail), 3)]
    for (moved, angle), (go, rest, back) in zip(plan.gravity_poses, triples, strict=True):
        assert (go.kind, go.motor, go.angle) == ("move", moved + 1, angle)
        assert rest.kind == "rest" and rest.rest_s == plan.rest_s
        assert (back.kind, back.motor, back.angle) == ("move", moved + 1, 0.0)
