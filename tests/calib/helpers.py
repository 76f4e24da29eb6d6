"""Exact (noise-free) observation sets from first principles, independent of
gyrocal.calib.simulate."""

from __future__ import annotations

import numpy as np

from gyrocal.calib.observations import ObservationSet


def rotation(axis, angle):
    axis = np.asarray(axis, float) / np.linalg.norm(axis)
    K = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + np.sin(angle) * K + (1 - np.cos(angle)) * K @ K


def exact_observations(
    scale, bias, *, speed=1.0, turns=1, mount=None, rests=3, noise=0.01, count=1200, speeds=None
) -> tuple[ObservationSet, np.ndarray]:
    """Window means that satisfy m = (ω u) / k - b exactly (paper Eq. 1 solved for m).

    Servo s (ID s + 1) turns about u_s = Rᵀ e_s, the mount rotation R given by ``mount``
    (axis, angle). Returns the set and the true axes (3, 3).
    """
    scale, bias = np.asarray(scale, float), np.asarray(bias, float)
    R = np.eye(3) if mount is None else rotation(*mount)
    axes = R.T  # rows u_s = Rᵀ e_s
    mean, rate, motor, direction = [], [], [], []
    for s in range(3):
        for d in (1, -1):
            for t in range(turns):
                w = d * (speed if speeds is None else speeds[s][t])
                mean.append(w * axes[s] / scale - bias)
                rate.append(w)
                motor.append(s + 1)
                direction.append(d)
    n = len(rate)
    obs = ObservationSet(
        mean=np.array(mean),
        rate=np.array(rate),
        motor=np.array(motor),
        direction=np.array(direction),
        count=np.full(n, count),
        noise=np.full((n, 3), noise),
        rest_mean=np.tile(-bias, (rests, 1)) if rests else None,
        rest_count=np.full(rests, 600) if rests else None,
        rest_noise=np.full((rests, 3), noise) if rests else None,
    )
    return obs, axes
