"""An independent generator of hand-rotation (Ferraris) sessions: raw gyro and accelerometer
streams of a box turned by hand, built from first principles with scipy's rotations.

It shares nothing with gyrocal's emulator (``drivers/emulated/hand.py``) or the code under test
(``calib/hand.py``, ``calib/windows.py``): the box's orientation is integrated sample by sample
from its body rate with ``scipy.spatial.transform.Rotation``, the sensor reads
``m = C ω − b + v`` (``C = diag(1/scale) @ misalignment``, the emulator's ``SensorTruth``
convention; ``v`` white noise, then a 16-bit converter at ±2000 °/s) and its accelerometer
``a = g Rᵀ ẑ`` in the sensor frame. The hand's speed within a turn follows random knots joined
linearly under a half-cosine taper (a different family from the emulator's raised sine times a
low-order ripple); the box tips about a random horizontal axis by up to ``wobble_deg`` during a
turn and comes back flat; each return to the stop misses it by a normal draw of ``stop_deg``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

#: ±2000 °/s over 16 bits, rad/s (the imucal session's step).
LSB_RAD_S = float(np.radians(2000.0 / 32768.0))
G = 9.80665


@dataclass(frozen=True)
class HandTruth:
    """The session's truth: sensing matrix ``C`` (m = C ω − b), bias ``b`` (Calibration v1
    sign), the mount (box → sensor), and each turn's true angle (rad)."""

    C: np.ndarray
    bias: np.ndarray
    mount: np.ndarray
    turn_angles: tuple[float, ...]

    @property
    def scale(self) -> np.ndarray:
        """The diagonal model's scale: ``1 / diag(C)`` (exact when C is diagonal)."""
        return 1.0 / np.diag(self.C)


def draw_sensor(rng: np.random.Generator, cross: float = 0.0, mount_deg: float = 2.0
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(C, bias, mount)``: scales 0.97..1.03, biases ±0.05 rad/s, off-diagonal terms up to
    ``cross``, the sensor mounted on the box rotated by ``mount_deg`` about a random axis."""
    mis = np.eye(3) + rng.uniform(-cross, cross, (3, 3)) * (1 - np.eye(3))
    scale = rng.uniform(0.97, 1.03, 3)
    bias = rng.uniform(-0.05, 0.05, 3)
    ax = rng.normal(size=3)
    mount = Rotation.from_rotvec(ax / np.linalg.norm(ax) * np.radians(mount_deg)).as_matrix()
    return np.diag(1.0 / scale) @ mis, bias, mount


def _taper(n: int, rng: np.random.Generator) -> np.ndarray:
    x = np.linspace(0.0, 1.0, n)
    edge = rng.uniform(0.15, 0.35)
    up = np.clip(x / edge, 0, 1)
    down = np.clip((1 - x) / edge, 0, 1)
    return 0.5 * (1 - np.cos(np.pi * np.minimum(up, down)))


def _speed(n: int, rng: np.random.Generator) -> np.ndarray:
    """A hand's speed on ``n`` samples of a turn, integrating to 1 over the sample index."""
    knots = rng.uniform(0.3, 1.7, 6)
    v = np.interp(np.linspace(0, 5, n), np.arange(6), knots) * _taper(n, rng)
    return v / v.sum()


def hand_session(rng: np.random.Generator, C: np.ndarray, bias: np.ndarray, mount: np.ndarray,
                 *, fs: float = 100.0, noise: float = 4e-3, stop_deg: float = 0.1,
                 wobble_deg: float = 1.0, both_ways: bool = True, turn_s=(2.5, 5.0),
                 rest_s=(2.0, 4.5), g_sensitivity: np.ndarray | None = None,
                 turn_steps: int = 1, step_pause_s: float = 1.5
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray, HandTruth]:
    """A session: rest on +z, turns about box z (+ then −), a 180° flip to −z and back, 90° to
    +x, turns about x, the flip, 90° to +y, turns about y, the flip, rests between.
    ``both_ways=False``: one turn per axis (imucal's session has three). ``g_sensitivity``
    (3×3, rad/s per g) adds ``G f`` to the reading, ``f`` the specific force in g.
    ``turn_steps`` > 1 makes each turn in that many equal steps with ``step_pause_s`` still
    between them (imucal's example: "split up in 4 sections of 90 deg").

    The box's orientation (box → world) is written in the world frame, sample by sample: at a
    rest it holds; a turn is ``Tilt(t) Rot(ẑ, φ(t)) R₀`` (``Tilt`` a small tilt about a
    horizontal axis that starts and ends at zero: the face comes back flat, and the turn ends
    at ``Rot(ẑ, 2π + stop error) R₀`` exactly); a re-seat is ``Rot(h, ψ(t)) R₀`` about a
    horizontal ``h``. The body rate is each step's relative rotation, ``(R_iᵀ R_{i+1})`` as a
    rotation vector over the step.

    Returns
    -------
    t (N,), gyro (N, 3) rad/s, accel (N, 3) m/s², HandTruth
    """
    dt = 1.0 / fs
    z = np.array([0.0, 0.0, 1.0])
    rots: list[Rotation] = [Rotation.from_rotvec(np.zeros((1, 3)))]
    angles: list[float] = []

    def rest(sec: float) -> None:
        rots.append(Rotation.concatenate([rots[-1][-1]] * int(sec * fs)))

    def turn(angle: float, sec: float) -> None:
        n = int(sec * fs)
        phi = angle * np.cumsum(_speed(n, rng))
        start = rots[-1][-1]
        r = Rotation.from_rotvec(np.outer(phi, z)) * start
        h = rng.normal(size=2)
        h = np.r_[h / np.linalg.norm(h), 0.0]
        x = np.linspace(0, 1, n)
        tilt = np.radians(wobble_deg) * np.sin(np.pi * x) * np.sin(
            2 * np.pi * rng.uniform(0.5, 2.0) * x + rng.uniform(0, 2 * np.pi)) * _taper(n, rng)
        tilt[-1] = 0.0
        rots.append(Rotation.from_rotvec(np.outer(tilt, h)) * r)

    def reseat(h: np.ndarray, angle: float) -> None:
        n = int(2.0 * fs)
        psi = angle * np.cumsum(_speed(n, rng))
        rots.append(Rotation.from_rotvec(np.outer(psi, h)) * rots[-1][-1])

    e = np.eye(3)
    rest(4.0)
    for k in range(3):
        for d in ((1, -1) if both_ways else (1,)):
            ang = d * (2 * np.pi + rng.normal(0, np.radians(stop_deg)))
            angles.append(ang)
            for step in range(turn_steps):
                if step:
                    rest(step_pause_s)
                turn(ang / turn_steps, rng.uniform(*turn_s) / turn_steps)
            rest(rng.uniform(*rest_s))
        for _ in range(2):  # the opposite face and back, for the accelerometer
            reseat(e[0], np.pi)
            rest(rng.uniform(*rest_s))
        if k < 2:  # the next box axis up: 90° about a horizontal world axis
            reseat(e[1] if k == 0 else e[0], np.pi / 2)
            rest(rng.uniform(*rest_s))
    R = Rotation.concatenate(rots)
    n = len(R)
    inc = (R[:-1].inv() * R[1:]).as_rotvec()
    w_box = np.vstack([inc / dt, np.zeros((1, 3))])
    up = R.inv().apply(z)
    w_sensor = w_box @ mount.T
    m = w_sensor @ C.T - bias + rng.normal(0, noise, (n, 3))
    if g_sensitivity is not None:
        m += (up @ mount.T) @ np.asarray(g_sensitivity, float).T
    m = np.round(m / LSB_RAD_S) * LSB_RAD_S
    acc = G * up @ mount.T
    t = np.arange(n) * dt
    return t, m, acc, HandTruth(C, bias, mount, tuple(angles))
