"""The jig's kinematics against independent truth: numerical differentiation of the orientation,
the servos' own angles, and the configured geometry."""

import math

import numpy as np
import pytest

from gyrocal.drivers.clock import VirtualClock
from gyrocal.drivers.emulated.dxl import EmulatedServo
from gyrocal.drivers.emulated.jig import GimbalJig, rotvec_to_matrix
from gyrocal.drivers.emulated.motion import MotionSource


def make(seed=1, **jig_kw):
    clock = VirtualClock()
    servos = [EmulatedServo(i, clock=clock, seed=seed * 10 + i) for i in (1, 2, 3)]
    return clock, servos, GimbalJig(servos, seed=seed, **jig_kw)


def spin(servo, units, accel_units=30):
    for name, value in (("Operating Mode", 1), ("Torque Enable", 1),
                        ("Profile Acceleration", accel_units), ("Goal Velocity", units)):
        item = servo.table[name]
        assert servo.write(item.address, item.to_bytes(value)) == 0


def advance(clock, seconds, servos):
    end = clock.monotonic() + seconds
    while clock.monotonic() < end:
        clock.sleep(0.02)
        for s in servos:
            s.register("Present Position")


def test_it_is_a_motion_source_with_the_contracts_shape():
    clock, servos, jig = make()
    assert isinstance(jig, MotionSource)
    assert jig.rate(np.array([])).shape == (0, 3)
    clock.sleep(0.1)
    np.testing.assert_array_equal(jig.rate(np.array([0.0, 0.05, 0.1])), np.zeros((3, 3)))


def test_default_axes_are_x_y_z_within_tilt_and_mount_error():
    _, _, jig = make(tilt_deg=0.3, mount=3.0)
    for i, e in zip((1, 2, 3), np.eye(3), strict=True):
        u = jig.home_axes[i]
        assert np.linalg.norm(u) == pytest.approx(1.0)
        angle = math.degrees(math.acos(np.clip(u @ e, -1, 1)))
        assert 0.0 < angle <= 3.3 + 1e-9
    # without tilts the home axes are exactly the mount rotation of x, y, z
    _, _, flat = make(tilt_deg=0.0, mount=[0.0, 0.0, math.radians(2.0)])
    np.testing.assert_allclose(flat.home_axes[1], [math.cos(math.radians(2)),
                                                   -math.sin(math.radians(2)), 0], atol=1e-12)


def test_axis_mapping_is_configurable():
    _, _, jig = make(axes=("z", "-x", "y"), tilt_deg=0.0, mount=0.0)
    np.testing.assert_allclose(jig.home_axes[1], [0, 0, 1], atol=1e-12)
    np.testing.assert_allclose(jig.home_axes[2], [-1, 0, 0], atol=1e-12)
    np.testing.assert_allclose(jig.home_axes[3], [0, 1, 0], atol=1e-12)
    with pytest.raises(ValueError, match="axis"):
        make(axes=("x", "y", "w"))


@pytest.mark.parametrize("moving", [1, 2, 3])
def test_one_servo_turning_gives_its_home_axis_times_its_rate(moving):
    clock, servos, jig = make(seed=moving)
    spin(servos[moving - 1], 42)
    advance(clock, 4.0, servos)
    t = np.linspace(0.5, 3.9, 500)
    w = jig.rate(t)
    _, joint_rate = servos[moving - 1].true_motion(t)
    np.testing.assert_allclose(w, np.outer(joint_rate, jig.home_axes[moving]), atol=1e-12)


def test_the_gyro_truth_integrates_to_the_encoder_angle():
    clock, servos, jig = make(seed=4)
    spin(servos[1], 60)
    advance(clock, 5.0, servos)
    a, b = 1.2345, 4.3210
    dt = servos[1].motor.dt
    edges = np.r_[a, np.arange(math.floor(a / dt) + 1, math.ceil(b / dt)) * dt, b]
    mids = 0.5 * (edges[:-1] + edges[1:])
    integral = (jig.rate(mids) * np.diff(edges)[:, None]).sum(axis=0) @ jig.home_axes[2]
    angles, _ = servos[1].true_motion(np.array([a, b]))
    assert integral == pytest.approx(angles[1] - angles[0], rel=1e-10)


def _vee_of_rt_rdot(jig, t, h=1e-5):
    r = jig.orientation(np.array([t - h, t, t + h]))
    omega = r[1].T @ (r[2] - r[0]) / (2 * h)
    return np.array([omega[2, 1], omega[0, 2], omega[1, 0]])


@pytest.mark.parametrize("wobble_deg", [0.0, 2.0])
def test_all_joints_moving_matches_the_derivative_of_the_orientation(wobble_deg):
    clock, servos, jig = make(seed=6, tilt_deg=2.0, mount=5.0, wobble_deg=wobble_deg)
    for s, units in zip(servos, (40, -70, 55), strict=True):
        spin(s, units)
    advance(clock, 3.0, servos)
    dt = servos[0].motor.dt
    for t in (1.00025, 1.73325, 2.50075):  # mid-cell: the rate is constant around t
        assert abs(t / dt - math.floor(t / dt) - 0.5) < 0.1
        np.testing.assert_allclose(jig.rate(np.array([t]))[0], _vee_of_rt_rdot(jig, t),
                                   atol=1e-6)


def test_a_slipping_mount_turns_every_axis_and_shows_a_rate_spike():
    clock, servos, jig = make(seed=7, tilt_deg=0.0, mount=0.0)
    slip = np.radians([0.0, 0.0, 2.0])
    jig.slip_at(1.0, slip, duration_s=0.02)
    spin(servos[0], 42)
    advance(clock, 2.0, servos)
    before = jig.joint_axes_sensor(np.array([0.9]))[0]
    after = jig.joint_axes_sensor(np.array([1.5]))[0]
    turn = rotvec_to_matrix(slip)
    np.testing.assert_allclose(after, before @ turn, atol=1e-12)  # each axis turned by -slip
    # while slipping the sensor turns at slip/duration about the slip axis, on top of servo 1
    t = np.array([1.01])
    _, r1 = servos[0].true_motion(t)
    spike = jig.rate(t)[0] - np.array([1.0, 0.0, 0.0]) @ rotvec_to_matrix(slip * 0.5) * r1[0]
    np.testing.assert_allclose(spike, slip / 0.02, atol=1e-9)
    assert np.degrees(np.arccos(after[0] @ before[0])) == pytest.approx(2.0)
