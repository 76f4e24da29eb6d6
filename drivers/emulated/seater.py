"""The user of the single-servo jig, emulated: a hand that re-seats the cube when prompted.

On the single-servo jig (hardware_docs/single-servo.md) the sensor sits in a cube on one servo
standing shaft up; between groups of turns the user lifts the cube and seats it so that another
sensor direction points up along the shaft. Here the hand does it on the jig's physics
(:class:`~gyrocal.drivers.emulated.jig.GimbalJig`) as a motion of the mount
(:meth:`~gyrocal.drivers.emulated.jig.GimbalJig.slip_at`, so the gyro sees the hand's turn while
it lasts): the cube ends with the asked direction up along the joint's nominal axis, turned by
a random angle about it, and off by a random seating error (``seat_error_deg``, drawn by
``seed``). ``wrong`` lists attempts (0-based) at which the hand seats the cube the wrong way
(a quarter turn off), for the runner's gravity check.
"""

from __future__ import annotations

import math
from collections.abc import Collection, Sequence

import numpy as np

from gyrocal.drivers.emulated.jig import GimbalJig, rotvec_to_matrix

__all__ = ["CubeSeater", "SEAT_ERROR_DEG"]

#: Seating error of a printed cube on a printed adapter, degrees (RMS angle) ⚠ (assumed).
SEAT_ERROR_DEG = 1.0


def _log(R: np.ndarray) -> np.ndarray:
    """The rotation vector of the rotation matrix ``R`` (its principal logarithm)."""
    c = min(max((float(np.trace(R)) - 1.0) / 2.0, -1.0), 1.0)
    angle = math.acos(c)
    if angle < 1e-12:
        return np.zeros(3)
    if math.pi - angle < 1e-6:  # a half turn: the axis from R + I
        B = (R + np.eye(3)) / 2.0
        axis = B[int(np.argmax(np.diag(B)))]
        return axis / np.linalg.norm(axis) * angle
    w = np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]])
    return w / (2.0 * math.sin(angle)) * angle


def _to_up(up: np.ndarray, shaft: np.ndarray) -> np.ndarray:
    """The shortest rotation ``Q`` with ``Q up = shaft`` (both unit)."""
    axis = np.cross(up, shaft)
    s, c = float(np.linalg.norm(axis)), float(up @ shaft)
    if s < 1e-12:
        if c > 0:
            return np.eye(3)
        perp = np.cross(up, [1.0, 0.0, 0.0] if abs(up[0]) < 0.9 else [0.0, 1.0, 0.0])
        return rotvec_to_matrix(perp / np.linalg.norm(perp) * math.pi)
    return rotvec_to_matrix(axis / s * math.atan2(s, c))


class CubeSeater:
    """An emulated hand that re-seats the cube on the jig's one joint.

    Parameters
    ----------
    jig : GimbalJig
        The jig's physics, with one joint (the servo); its mount is the cube's first seat.
    clock : Clock
        The jig's clock.
    seed : int
        Seeds the turns about the shaft and the seating errors.
    seat_error_deg : float
        RMS seating error, degrees.
    duration_s : float
        How long the hand takes to re-seat the cube.
    wrong : collection of int
        Attempts (0-based, counting every :meth:`begin`) at which the cube is seated wrong.
    """

    def __init__(self, jig: GimbalJig, clock: object, *, seed: int = 0,
                 seat_error_deg: float = SEAT_ERROR_DEG, duration_s: float = 1.5,
                 wrong: Collection[int] = ()) -> None:
        if len(jig.joints) != 1:
            raise ValueError(f"the cube seater needs a one-servo jig, got {len(jig.joints)}")
        self.jig = jig
        self.clock = clock
        self.rng = np.random.default_rng([int(seed), 0x5EA7])
        self.seat_error_rad = math.radians(float(seat_error_deg))
        self.duration_s = float(duration_s)
        self.wrong = wrong  # read at each prompt (the kit arms its faults after building this)
        self.attempts = 0
        self._seated = jig.mount.copy()  # sensor → link: M S of every slip so far
        self._done_at = -math.inf
        #: The joint's nominal axis in the link frame: "up" of the adapter.
        self.shaft = self._nominal_shaft()

    def _nominal_shaft(self) -> np.ndarray:
        a = self.jig.axes[0]
        i = int(np.argmax(np.abs(a)))
        out = np.zeros(3)
        out[i] = math.copysign(1.0, float(a[i]))
        return out

    def begin(self, up: Sequence[float]) -> None:
        """Start seating the cube with the sensor direction ``up`` (sensor frame) up along the
        shaft; :meth:`done` says when the hand has let go."""
        u = np.asarray(up, dtype=float)
        u = u / np.linalg.norm(u)
        if self.attempts in self.wrong:  # a quarter turn off: another face up
            perp = np.cross(u, [0.3, 0.5, 0.8])
            u = rotvec_to_matrix(perp / np.linalg.norm(perp) * math.pi / 2) @ u
        self.attempts += 1
        yaw = rotvec_to_matrix(self.shaft * self.rng.uniform(0.0, 2.0 * math.pi))
        err = rotvec_to_matrix(self.rng.normal(size=3) / math.sqrt(3.0) * self.seat_error_rad)
        target = err @ yaw @ _to_up(u, self.shaft)  # sensor → link
        step = self._seated.T @ target
        now = float(self.clock.monotonic())  # type: ignore[attr-defined]
        self.jig.slip_at(now, _log(step), self.duration_s)
        self._seated = target
        self._done_at = now + self.duration_s

    def done(self) -> bool:
        """Whether the hand has finished the seat it began."""
        return float(self.clock.monotonic()) >= self._done_at  # type: ignore[attr-defined]

    def axis(self) -> np.ndarray:
        """The servo's true axis in the sensor frame in the present seat."""
        a = self._seated.T @ self.jig.axes[0]
        return a / np.linalg.norm(a)
