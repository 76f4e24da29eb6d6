"""calib.kinematics against hand-written chains: explicit rotation matrices and a numerical
derivative of the sensor's orientation (ω in the body frame from skew(ω) = Rᵀ dR/dt)."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from gyrocal.calib.errors import CalibInputError
from gyrocal.calib.kinematics import axes_at, gravity_up, sensor_rate


def Rx(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])


def Ry(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])


def Rz(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


SQUARE = {"chain": [3, 2, 1], "axes": [[0, 0, 1], [0, 1, 0], [1, 0, 0]],
          "reference_angles_rad": [0.0, 0.0, 0.0]}


def test_square_gimbal_axes_by_hand():
    # Base turns about z, middle about y, inner about x. Inner at 90°: the middle axis (y in the
    # link frame) seen from the sensor is Rx(90°)ᵀ y = -z; middle at 90° then carries base z.
    th = np.array([[0.3, 0.0, np.pi / 2], [0.0, np.pi / 2, 0.0], [1.0, np.pi / 2, np.pi / 2]])
    u = axes_at(SQUARE, th)
    np.testing.assert_allclose(u[0, 2], [1, 0, 0], atol=1e-15)
    np.testing.assert_allclose(u[0, 1], [0, 0, -1], atol=1e-15)
    np.testing.assert_allclose(u[0, 0], [0, 1, 0], atol=1e-15)  # Rx(90)ᵀ z = +y
    np.testing.assert_allclose(u[1, 0], [-1, 0, 0], atol=1e-15)  # Ry(90)ᵀ z = -x
    # Both: (Ry(90) Rx(90))ᵀ z = Rx(90)ᵀ (-x) = -x
    np.testing.assert_allclose(u[2, 0], (Ry(np.pi / 2) @ Rx(np.pi / 2)).T @ [0, 0, 1], atol=1e-15)
    np.testing.assert_allclose(u[2, 0], [-1, 0, 0], atol=1e-15)


def _body_rate(R_of_t, t, h=1e-6):
    R = R_of_t(t)
    dR = (R_of_t(t + h) - R_of_t(t - h)) / (2 * h)
    W = R.T @ dR
    return np.array([W[2, 1], W[0, 2], W[1, 0]])


def test_square_gimbal_rate_against_orientation_derivative():
    rng = np.random.default_rng(1)
    th0, rate = rng.uniform(-3, 3, 3), rng.uniform(-2, 2, 3)

    def R(t):
        a = th0 + rate * t
        return Rz(a[0]) @ Ry(a[1]) @ Rx(a[2])

    for t in (0.0, 0.7, 2.1):
        want = _body_rate(R, t)
        got = sensor_rate(SQUARE, (th0 + rate * t)[None], rate[None])[0]
        np.testing.assert_allclose(got, want, atol=1e-8)


def _skewed_gimbal(rng, link_axes, mount_rotvec, chain):
    """A gimbal that is not square with a sensor mounted askew: link axes ``a_j`` in each link's
    own frame, mount rotation ``M``; the sensor's orientation ``R(θ) = Rot(a0, θ0) Rot(a1, θ1)
    Rot(a2, θ2) M`` (scipy rotations, not the code's), random reference angles, and the axes in
    the sensor frame there (each joint's axis carried to the sensor by the links inside it).
    Returns ``(R, axes, kinematics)``."""
    a = [np.asarray(v, dtype=float) / np.linalg.norm(v) for v in link_axes]
    M = Rotation.from_rotvec(mount_rotvec).as_matrix()

    def R(th):
        out = np.eye(3)
        for aj, tj in zip(a, th, strict=True):
            out = out @ Rotation.from_rotvec(aj * tj).as_matrix()
        return out @ M

    ref = rng.uniform(-1, 1, 3)
    axes = []
    for j in range(3):
        inner = np.eye(3)
        for k in range(j + 1, 3):
            inner = inner @ Rotation.from_rotvec(a[k] * ref[k]).as_matrix()
        axes.append((inner @ M).T @ a[j])
    return R, axes, {"chain": list(chain), "axes": [list(x) for x in axes],
                     "reference_angles_rad": list(ref)}


def test_skewed_gimbal_with_reference_angles():
    # A gimbal that is not square and a sensor mounted askew: link axes a_j in each link's own
    # frame, mount rotation M (sensor to innermost link). Orientation of the sensor relative to
    # the base: Rot(a0, θ0) Rot(a1, θ1) Rot(a2, θ2) M (scipy rotations, not the code's).
    rng = np.random.default_rng(7)
    R, axes, kin = _skewed_gimbal(rng, ([0.05, -0.03, 1], [0.02, 1, 0.04], [1, 0.03, -0.02]),
                                  [0.1, -0.2, 0.05], [1, 2, 3])
    ref = np.array(kin["reference_angles_rad"])
    th0 = rng.uniform(-4, 4, 3) + 2 * np.pi * np.array([3, -1, 2])  # cumulative angles
    rate = rng.uniform(-3, 3, 3)
    for t in (0.0, 0.4):
        want = _body_rate(lambda s: R(th0 + rate * s), t)
        got = sensor_rate(kin, (th0 + rate * t)[None], rate[None])[0]
        np.testing.assert_allclose(got, want, atol=1e-8)
    u = axes_at(kin, np.array([ref, th0]))
    np.testing.assert_allclose(u[0], axes, atol=1e-14)  # at the reference angles: as given
    np.testing.assert_allclose(u[1, 2], axes[2], atol=1e-14)  # innermost: constant
    np.testing.assert_allclose(np.linalg.norm(u, axis=2), 1.0, atol=1e-14)


def test_gravity_up_is_the_world_vertical_seen_from_the_sensor():
    # The skewed gimbal of the test above, standing with servo `index`'s axis vertical in a home
    # pose that is not the reference pose. Truth from scipy rotations only: "up" in the world is
    # ±R(home) u(home); at any pose the sensor sees R(θ)ᵀ of it.
    rng = np.random.default_rng(12)
    R, _, kin = _skewed_gimbal(rng, ([0.04, -0.02, 1], [0.03, 1, -0.05], [1, 0.02, 0.03]),
                               [-0.1, 0.15, 0.2], [7, 8, 9])
    home = rng.uniform(-0.5, 0.5, 3) + 2 * np.pi * np.array([1, 0, -2])
    angles = home + rng.uniform(-7, 7, (20, 3))
    for index, sign in ((0, 1), (2, -1), (1, 1)):
        u_home = axes_at(kin, home[None])[0, index]
        world_up = sign * R(home) @ u_home
        want = np.array([R(th).T @ world_up for th in angles])
        got = gravity_up(kin, angles, home, (kin["chain"][index], sign))
        np.testing.assert_allclose(got, want, atol=1e-12)
    # the base's axis stays vertical whatever the pose: up is its axis in every pose
    got = gravity_up(kin, angles, home, (7, 1))
    np.testing.assert_allclose(got, axes_at(kin, angles)[:, 0], atol=1e-12)
    with pytest.raises(CalibInputError, match="gravity must name a servo of the chain"):
        gravity_up(kin, angles, home, (4, 1))
    with pytest.raises(CalibInputError, match="home must be 3 finite angles"):
        gravity_up(kin, angles, home[:2], (7, 1))


def test_bad_kinematics_and_angles_are_named():
    with pytest.raises(CalibInputError, match="reference_angles_rad"):
        axes_at({"chain": [1], "axes": [[1, 0, 0]]}, np.zeros((1, 1)))
    with pytest.raises(CalibInputError, match="unit vectors"):
        axes_at({**SQUARE, "axes": [[0, 0, 2], [0, 1, 0], [1, 0, 0]]}, np.zeros((1, 3)))
    with pytest.raises(CalibInputError, match=r"\(N, 3\)"):
        axes_at(SQUARE, np.zeros((4, 2)))
    with pytest.raises(CalibInputError, match="rates"):
        sensor_rate(SQUARE, np.zeros((4, 3)), np.zeros((3, 3)))
