"""An independent generator of posed observations for the full model g = A (m + b).

Built from first principles with scipy's rotations and none of gyrocal's kinematics, simulator or
emulator: a gimbal of link axes ``a_j`` (each in the frame of the link before it) and a sensor
mount ``M``; the sensor's orientation in the base frame is ``Rot(a_0, θ_0) Rot(a_1, θ_1) … M``, so
the rate of servo ``j`` turning alone, in the sensor frame, is ``(Rot_{j+1} … Rot_{S-1} M)ᵀ a_j``.
The sensor reads ``m = C ω − b`` with ``C = diag(1/scale) @ misalignment`` (the emulator's
``SensorTruth`` convention). The truth in the frame convention ``gyro-x-xy`` is ``A = L⁻¹`` with
``C = L Q`` the LQ decomposition (L lower triangular, positive diagonal).
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from gyrocal.calib.observations import ObservationSet


def truth_in_frame(C: np.ndarray) -> np.ndarray:
    """``A`` in the gyro-x-xy frame for the sensing matrix ``C`` (rows: sensing axes / scale)."""
    q, r = np.linalg.qr(np.asarray(C, float).T)
    L = r.T * np.sign(np.diag(r))[None, :]
    return np.linalg.inv(L)


def draw_truth(rng: np.random.Generator, cross: float = 0.02, tilt_rad: float = 0.02,
               mount_rad: float = 0.05):
    """A sensor (C, bias) with off-diagonal terms up to ``cross`` and a skewed gimbal (link axes
    tilted by up to ``tilt_rad`` per component, mount rotated by up to ``mount_rad``)."""
    mis = np.eye(3) + rng.uniform(-cross, cross, (3, 3)) * (1 - np.eye(3))
    scale = rng.uniform(0.97, 1.03, 3)
    bias = rng.uniform(-0.05, 0.05, 3)
    links = [np.eye(3)[j] + rng.uniform(-tilt_rad, tilt_rad, 3) for j in range(3)]
    links = [v / np.linalg.norm(v) for v in links]
    mount = Rotation.from_rotvec(rng.uniform(-mount_rad, mount_rad, 3)).as_matrix()
    return np.diag(1 / scale) @ mis, bias, links, mount


def body_axis(links, mount, angles, j: int) -> np.ndarray:
    """Servo ``j``'s turn axis in the sensor frame at the pose ``angles`` (S,): (3,); or at
    many poses at once, ``angles`` (N, S): (N, 3)."""
    angles = np.asarray(angles, dtype=float)
    if angles.ndim == 2:
        inner = np.broadcast_to(np.eye(3), (angles.shape[0], 3, 3))
        for k in range(j + 1, len(links)):
            inner = inner @ Rotation.from_rotvec(angles[:, k:k + 1] * links[k]).as_matrix()
        return np.einsum("nki,k->ni", inner @ mount, links[j])
    inner = np.eye(3)
    for k in range(j + 1, len(links)):
        inner = inner @ Rotation.from_rotvec(links[k] * angles[k]).as_matrix()
    return (inner @ mount).T @ links[j]


def posed_observations(
    C, bias, links, mount, schedule, *, speed=3.0, noise=0.0, count=2000, rests=3,
    rng: np.random.Generator | None = None, chain=(1, 2, 3),
) -> ObservationSet:
    """Window means for ``schedule``: a list of ``(servo position, pose angles (S,), direction)``.

    With ``noise`` > 0 each mean gets white noise of ``noise / sqrt(count)`` per axis.
    """
    mean, rate, motor, direction, pose = [], [], [], [], []
    for s, p, d in schedule:
        w = d * speed
        mean.append(C @ body_axis(links, mount, p, s) * w - bias)
        rate.append(w)
        motor.append(chain[s])
        direction.append(d)
        pose.append(p)
    mean = np.array(mean)
    rest_mean = np.tile(-bias, (rests, 1))
    if noise:
        mean = mean + rng.normal(0, noise / np.sqrt(count), mean.shape)
        rest_mean = rest_mean + rng.normal(0, noise / np.sqrt(count), rest_mean.shape)
    n = len(rate)
    return ObservationSet(
        mean=mean, rate=np.array(rate), motor=np.array(motor), direction=np.array(direction),
        count=np.full(n, count), noise=np.full((n, 3), noise or 1e-3),
        rest_mean=rest_mean, rest_count=np.full(rests, count),
        rest_noise=np.full((rests, 3), noise or 1e-3), chain=chain, pose=np.array(pose, float),
    )


HOME = [(s, np.zeros(3), d) for s in range(3) for d in (1, -1)]
Q = np.pi / 2
#: Home turns plus two posed pairs: the middle servo with the inner at 90°, the base with the
#: middle at 90° (hardware_docs/method.md: the smallest schedule of full rank).
POSED = HOME + [(1, np.array([0.0, 0.0, Q]), d) for d in (1, -1)] + [
    (0, np.array([0.0, Q, 0.0]), d) for d in (1, -1)]


TRIL = [(0, 0), (1, 0), (1, 1), (2, 0), (2, 1), (2, 2)]


def _perp(a):
    t1 = np.cross(a, [0.3, 0.5, 0.8])
    t1 /= np.linalg.norm(t1)
    return t1, np.cross(a, t1)


def _predict(theta, links0, schedule, rate, n_rests):
    C = np.zeros((3, 3))
    for k, (i, j) in enumerate(TRIL):
        C[i, j] = theta[k]
    b = theta[6:9]
    links = []
    for j, a in enumerate(links0):
        t1, t2 = _perp(a)
        rot = Rotation.from_rotvec(theta[9 + 2 * j] * t1 + theta[10 + 2 * j] * t2)
        links.append(rot.apply(a))
    out = [C @ body_axis(links, np.eye(3), pose, s) * d * rate - b for s, pose, d in schedule]
    out += [-b] * n_rests
    return np.concatenate(out)


def independent_fisher(links0, schedule, rate, sigma, rest_sigma, n_rests):
    """The Cramér–Rao bound of ``(A row-major, b)`` at ``A = I``, ``b = 0`` for a gimbal of link
    axes ``links0`` (mount fixed, the frame convention): the Fisher information of ``(C tril,
    b, two tilts per link)`` by central differences of this module's forward model, the tilts
    eliminated by inversion. Returns ``(std (12,), information (12, 12))``, zero for the three
    elements of ``A`` the frame fixes."""
    theta0 = np.concatenate([[1, 0, 1, 0, 0, 1], np.zeros(3), np.zeros(6)]).astype(float)
    h = 1e-6
    J = np.empty((3 * (len(schedule) + n_rests), theta0.size))
    for p in range(theta0.size):
        e = np.zeros_like(theta0)
        e[p] = h
        J[:, p] = (_predict(theta0 + e, links0, schedule, rate, n_rests)
                   - _predict(theta0 - e, links0, schedule, rate, n_rests)) / (2 * h)
    w = np.concatenate([np.full(3 * len(schedule), 1 / sigma**2),
                        np.full(3 * n_rests, 1 / rest_sigma**2)])
    cov = np.linalg.inv(J.T @ (w[:, None] * J))[:9, :9]
    # A = C⁻¹ = I at the truth: dA = −dC (the sign leaves σ and the information's diagonal
    # alone); the upper triangle is fixed by the frame.
    idx = [3 * i + j for i, j in TRIL] + [9, 10, 11]
    std = np.zeros(12)
    std[idx] = np.sqrt(np.diag(cov))
    info = np.zeros((12, 12))
    info[np.ix_(idx, idx)] = np.linalg.inv(cov)
    return std, info
