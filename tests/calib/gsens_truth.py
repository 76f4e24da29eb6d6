"""An independent generator of posed observations with g-sensitivity, ``m = C ω − b + G_s f``.

From first principles with scipy's rotations, sharing no code with gyrocal's kinematics,
estimators, simulator or emulator (it reuses only :mod:`fullmodel_truth`'s gimbal, itself
independent). The gimbal stands with servo 3's axis vertical in the home pose (the contract of
``ObservationSet.gravity``), so "up" in the base frame is ``links[2]``. The specific force of a
still sensor is ``f = R(θ)ᵀ up`` (1 g), ``R(θ) = Rot(a_0, θ_0) Rot(a_1, θ_1) Rot(a_2, θ_2) M``; a
turn's window mean is that force averaged over ``n_avg`` evenly spaced angles of one revolution of
the turning servo (numerically, not by the projection formula the estimator uses). The sensor's
g-sensitivity ``G_s`` adds ``G_s f`` to the reading, so the model ``g = A (m + b + G f)`` has
``G = −G_s``.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from gyrocal.calib.observations import ObservationSet


def orientation(links, mount, angles) -> np.ndarray:
    """``R(θ)``: the sensor's orientation in the base frame."""
    R = np.eye(3)
    for a, th in zip(links, angles, strict=True):
        R = R @ Rotation.from_rotvec(np.asarray(a) * th).as_matrix()
    return R @ mount


def body_rate(links, mount, angles, j: int) -> np.ndarray:
    """Unit rate of servo ``j`` turning alone, in the sensor frame."""
    inner = np.eye(3)
    for k in range(j + 1, len(links)):
        inner = inner @ Rotation.from_rotvec(links[k] * angles[k]).as_matrix()
    return (inner @ mount).T @ links[j]


def force_at(links, mount, angles) -> np.ndarray:
    """Specific force of a still sensor at ``angles``, g, sensor frame."""
    return orientation(links, mount, angles).T @ links[2]


def gsens_observations(
    C, bias, Gs, links, mount, schedule, rest_poses, *, speed=3.0, noise=0.0, count=2000,
    n_avg=12, span=(0.0, 2 * np.pi), rng: np.random.Generator | None = None, chain=(1, 2, 3),
) -> ObservationSet:
    """Window and rest means for ``schedule`` (``(servo position, pose (S,), direction)``) and
    rests at ``rest_poses`` (list of (S,) angles); white noise ``noise / sqrt(count)`` per axis
    on every mean when ``noise`` > 0. A turn's window covers the turning servo's angles
    ``pose + span`` (midpoints of ``n_avg`` equal steps; a whole revolution by default): its
    recorded pose is their mean and its ``turn_phase`` the means of cos and sin about it."""
    mean, rate, motor, direction, pose, phase = [], [], [], [], [], []
    for s, p, d in schedule:
        w = d * speed
        phis = span[0] + (span[1] - span[0]) * (np.arange(n_avg) + 0.5) / n_avg
        f = np.mean([force_at(links, mount, np.where(np.arange(3) == s, p[s] + ph, p))
                     for ph in phis], axis=0)
        mean.append(C @ body_rate(links, mount, p, s) * w - bias + Gs @ f)
        rate.append(w)
        motor.append(chain[s])
        direction.append(d)
        pose.append(np.where(np.arange(3) == s, p[s] + phis.mean(), p))
        dev = phis - phis.mean()
        phase.append([np.mean(np.cos(dev)), np.mean(np.sin(dev))])
    mean = np.array(mean)
    rest_mean = np.array([-bias + Gs @ force_at(links, mount, p) for p in rest_poses])
    if noise:
        mean = mean + rng.normal(0, noise / np.sqrt(count), mean.shape)
        rest_mean = rest_mean + rng.normal(0, noise / np.sqrt(count), rest_mean.shape)
    n, r = len(rate), len(rest_poses)
    return ObservationSet(
        mean=mean, rate=np.array(rate), motor=np.array(motor), direction=np.array(direction),
        count=np.full(n, count), noise=np.full((n, 3), noise or 1e-3),
        rest_mean=rest_mean, rest_count=np.full(r, count),
        rest_noise=np.full((r, 3), noise or 1e-3), chain=chain, pose=np.array(pose, float),
        rest_pose=np.array(rest_poses, float), home_pose=np.zeros(3), gravity=(chain[2], 1),
        turn_phase=np.array(phase),
    )


Q = np.pi / 2
HOME_RESTS = [np.zeros(3)] * 7
#: Rests of the posed pairs of ``fullmodel_truth.POSED`` (inner at 90°: gravity unchanged; middle
#: at 90°: gravity along ∓x) and the planner's gravity rest (base at 90°: gravity along ±y).
POSED_RESTS = [np.array([0.0, 0.0, Q])] * 2 + [np.array([0.0, Q, 0.0])] * 2
GRAVITY_RESTS = [np.array([Q, 0.0, 0.0])] * 2
