"""An independent generator of single-servo sessions: one servo, a cube re-seated by hand.

Built from first principles with scipy's rotations and none of gyrocal's seat table, planner,
kinematics, simulator or emulator: the servo stands with its shaft along the base's +z (tilted
by a small random angle); the user seats the cube so that a chosen sensor direction ``d`` is up,
which puts the sensor at ``R_seat`` with ``R_seat d = z`` (the shortest rotation), then turns it
about the vertical by a random angle and seats it with a random error of ``seat_error_rad``. A
turn of the servo at rate ``w`` is a rate ``w R_sensorᵀ a`` in the sensor frame. The sensor reads
``m = C ω − b`` (``C = diag(1/scale) @ misalignment``, the emulator's ``SensorTruth``
convention); the truth in the frame gyro-x-xy is ``truth_in_frame(C)`` (the LQ decomposition).
The seat directions are written out here, not taken from gyrocal.calib.design.SEATS.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from gyrocal.calib.observations import ObservationSet

R2 = 0.5**0.5
#: The sensor direction each seat puts up (a face, or the edge between two faces).
FACES = {"+x": (1, 0, 0), "+y": (0, 1, 0), "+z": (0, 0, 1)}
EDGES = {"+x+y": (R2, R2, 0), "+y+z": (0, R2, R2), "+z+x": (R2, 0, R2)}


def seat_rotation(up: np.ndarray, rng: np.random.Generator, seat_error_rad: float) -> np.ndarray:
    """The sensor's orientation (sensor → base) with ``up`` (sensor frame) along +z, a random
    yaw about +z and a random seating error."""
    up = np.asarray(up, float) / np.linalg.norm(up)
    z = np.array([0.0, 0.0, 1.0])
    axis = np.cross(up, z)
    s, c = np.linalg.norm(axis), float(up @ z)
    to_z = (Rotation.from_rotvec(axis / s * np.arctan2(s, c)) if s > 1e-12
            else Rotation.identity() if c > 0 else Rotation.from_rotvec([np.pi, 0, 0]))
    yaw = Rotation.from_rotvec(z * rng.uniform(0, 2 * np.pi))
    err = Rotation.from_rotvec(rng.normal(size=3) / np.sqrt(3) * seat_error_rad)
    return (err * yaw * to_z).as_matrix()


def session(seats: dict[str, tuple], *, C: np.ndarray, bias: np.ndarray,
            rng: np.random.Generator, speed: float = 3.0, noise: float = 0.0,
            count: int = 2000, seat_error_rad: float = 0.01, shaft_tilt_rad: float = 0.005,
            servo_id: int = 1, g_sensitivity: np.ndarray | None = None,
            still_std: float = 0.0, turns: int = 2,
            ) -> tuple[ObservationSet, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Window means of turns −, + in each seat and three rests per seat.

    With ``g_sensitivity`` ``G`` (rad/s per g) the sensor reads ``m = C ω − b − G f`` with
    ``f`` the specific force, +1 g along the base's +z in the sensor frame (``R_sensorᵀ z``; a
    turn about the vertical shaft over whole revolutions keeps its component along the axis,
    which is all of it up to the shaft's tilt).

    With ``still_std`` each window's reference is rest to rest: the encoder's still angle
    before and after the turn, each read with an error of ``still_std`` (rad), divided by the
    turn's time (``turns`` revolutions at ``speed``). The one servo's still angles are numbered
    in running order, so a re-seat, which does not move the servo, shares the still angle
    between the last turn of a seat and the first of the next.

    Returns
    -------
    obs : ObservationSet
        Every window is the one servo's (``motor`` = ``servo_id``), no chain: as a recording
        without the seats would give.
    seat : ndarray of int
        Each window's seat number (1-based, in ``seats``' order).
    axes : ndarray (S, 3)
        Each seat's true turning axis in the sensor frame.
    rest_seat : ndarray of int
        Each rest's seat number.
    up : ndarray (S, 3)
        Gravity ("up", g) in the sensor frame in each seat, as a still accelerometer reads it.
    """
    shaft = Rotation.from_rotvec(rng.normal(size=3) * shaft_tilt_rad).apply([0.0, 0.0, 1.0])
    G = np.zeros((3, 3)) if g_sensitivity is None else np.asarray(g_sensitivity, float)
    mean, rate, seat, axes, ups = [], [], [], [], []
    for k, up in enumerate(seats.values(), start=1):
        R = seat_rotation(np.array(up), rng, seat_error_rad)
        u = R.T @ shaft
        g_up = R.T @ np.array([0.0, 0.0, 1.0])
        axes.append(u)
        ups.append(g_up)
        for d in (-1, 1):
            mean.append(C @ u * d * speed - bias - G @ ((u @ g_up) * u))
            rate.append(d * speed)
            seat.append(k)
    n, r = len(rate), 3 * len(seats)
    mean = np.array(mean)
    rest_seat = np.repeat(np.arange(1, len(seats) + 1), 3)
    rest = -bias - np.array(ups)[rest_seat - 1] @ G.T
    if noise:
        mean = mean + rng.normal(0, noise / np.sqrt(count), mean.shape)
        rest = rest + rng.normal(0, noise / np.sqrt(count), rest.shape)
    ref: dict = {}
    if still_std:
        T = 2 * np.pi * turns / speed
        z = rng.normal(0, still_std, n + 1)  # reading − true of each still angle
        ref = {"ref_start": np.arange(n), "ref_end": np.arange(1, n + 1),
               "ref_gain": np.full(n, 1 / T), "still_angle_std": still_std,
               "rate": np.array(rate) + (z[1:] - z[:-1]) / T}
    obs = ObservationSet(
        mean=mean, rate=ref.pop("rate", np.array(rate)), motor=np.full(n, servo_id),
        direction=np.sign(rate).astype(int), count=np.full(n, count),
        noise=np.full((n, 3), noise or 1e-3), rest_mean=rest, rest_count=np.full(r, count),
        rest_noise=np.full((r, 3), noise or 1e-3), **ref)
    return obs, np.array(seat), np.array(axes), rest_seat, np.array(ups)
