"""Accelerometer calibration from the rests (issue 15): is the default protocol's set of rests
enough, what a gravity tour adds, and the calibrated specific force's error against the
six-position method on the same data.

1. Design: the gravity directions of the default full-model protocol's rests (home pose, the
   posed pairs' poses: inner at 45°, middle at 45°) on the nominal gimbal, with and without a
   gravity tour (``calib.accel.gravity_tour``: 14-point or 10-point), scored by
   ``calib.accel.accel_design`` at the rests' noise (MPU-9250: 300 µg/√Hz, 200 Hz, 0.4 s
   windows): distinct orientations, identifiable, condition, predicted σ of the calibrated
   |f| at its worst direction, and the jig time the tour adds.
2. Accuracy over ``--seeds`` sensors (default 100): RMS over 2000 directions of the error of the
   calibrated specific force (both calibrations brought to the frame ``accel-x-xy``), for our
   fit and for the six-position method fed the tour's ±x, ±y, ±z rests as if they were exact,
   with the sensor mounted ``--mount-deg`` (default 3°) off the jig's axes and each servo axis
   tilted 0.3° (``--sim``'s jig defaults): a common rotation the frame convention removes for
   both methods, and pose-dependent direction errors that the six-position method takes as
   exact and the norm fit does not need.
   Data from (a) the emulator's accelerometer truth (``drivers.emulated.accel``: MPU-9250 Table 2
   errors) and (b) the independent generator ``tests/calib/accel_truth.py`` (shares no code with
   the estimator or the emulator).

3. The planner's own rests (``calib.design.plan_accel_rests`` on the default full plan): the
   protocol's existing rests tilted by moving servos inside the next turning one (no gravity
   tour). Design score and added time as in 1, and the same accuracy as in 2 (our fit only: its
   rests need not include ±x, ±y, ±z), on both generators, the true directions through a jig
   whose three axes are each tilted 0.3° and a sensor mounted ``--mount-deg`` off.

Usage: ``python -m bench accel [--seeds=N] [--mount-deg=D]``.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from bench.table import print_table
from gyrocal.calib.accel import (
    STANDARD_GRAVITY,
    TOUR_DIRECTIONS,
    accel_design,
    fit_accelerometer,
    gravity_tour,
    in_frame,
    six_position,
)
from gyrocal.calib.design import sphere_points
from gyrocal.drivers.emulated.accel import AccelTruth, draw_accel_truth
from tests.calib import accel_truth as indep

ODR_HZ, WINDOW_S, DENSITY_G = 200.0, 0.4, 300e-6
SPEED, ACCEL, REST_S = math.radians(247.0), 10.0, 0.6
N_SAMPLES = int(ODR_HZ * WINDOW_S)
WINDOW_STD = DENSITY_G * math.sqrt(ODR_HZ) / math.sqrt(N_SAMPLES) * STANDARD_GRAVITY
#: The default protocol's rests: 7 in the home pose, 3 with the inner servo at 45° (gravity
#: still along z: the inner axis is vertical at home), 3 with the middle servo at 45°.
DEFAULT_RESTS = np.array([[0, 0, 1.0]] * 10 + [[-math.sin(math.pi / 4), 0,
                                                 math.cos(math.pi / 4)]] * 3)
#: The gyro noise the kit plans with on the emulated MPU-9250 (its still noise as measured
#: before a run, the manifest's ``protocol.planning_noise_std``), rad/s per sample at 200 Hz.
PLANNING_NOISE = 0.0025
SMALL_TOUR = TOUR_DIRECTIONS[[0, 1, 2, 3, 5, 6, 9, 11, 12]]  # axes and a tetrahedron's corners


def _rotation(rng: np.random.Generator, deg: float) -> np.ndarray:
    axis = rng.standard_normal(3)
    axis /= np.linalg.norm(axis)
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    a = math.radians(deg)
    return np.eye(3) + math.sin(a) * k + (1 - math.cos(a)) * k @ k


def _planned() -> tuple[np.ndarray, object]:
    """The default full plan with its accelerometer rests (planned with them within the 45 s
    budget, as ``gyrocal calibrate`` does): every rest's servo angles (N, 3)."""
    from gyrocal.calib.design import plan_protocol, protocol_sequence

    plan = plan_protocol(servo_max_speed=SPEED / 0.9, full_scale=math.radians(500),
                         time_budget_s=45.0, model="full", accel_rests=True, max_turns=3.0,
                         noise_std=PLANNING_NOISE)
    here, angles = np.zeros(3), []
    for st in protocol_sequence(plan):
        if st[0] == "move":
            here[st[1]] = st[2]
        elif st[0] == "rest":
            angles.append(here.copy())
    return np.array(angles), plan


def _designs() -> list[list[object]]:
    from gyrocal.calib.design import rest_gravity

    rows = []
    angles, plan = _planned()
    options = [("default protocol", DEFAULT_RESTS, 0.0),
               ("planned accel rests", rest_gravity(angles), plan.accel_time_s)]
    for name, dirs in (("+ 14-point tour", None), ("+ 10-point tour", SMALL_TOUR)):
        tour = gravity_tour(SPEED, ACCEL, REST_S, directions=dirs)
        options.append((name, np.vstack([DEFAULT_RESTS, tour.directions]), tour.added_time_s))
    for name, dirs, added in options:
        d = accel_design(dirs, WINDOW_STD)
        distinct = len(np.unique(np.round(dirs, 6), axis=0))
        rows.append([name, len(dirs), distinct, d.identifiable, d.condition,
                     1e3 * d.worst_force_std / STANDARD_GRAVITY, added])
    return rows


def _axis_rotation(axis: np.ndarray, angle: float) -> np.ndarray:
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + math.sin(angle) * k + (1 - math.cos(angle)) * k @ k


def _true_directions(poses: np.ndarray, mount: np.ndarray, tilts: list[np.ndarray]) -> np.ndarray:
    """Gravity in the sensor frame at (base, middle) poses on a jig whose base and middle axes
    are the nominal x and y tilted by ``tilts`` and whose sensor is mounted off by ``mount``."""
    a1, a2 = tilts[0] @ [1.0, 0, 0], tilts[1] @ [0, 1.0, 0]
    out = [(_axis_rotation(a1, p1) @ _axis_rotation(a2, p2) @ mount).T @ [0, 0, 1.0]
           for p1, p2 in poses]
    return np.array(out)


def _true_directions3(angles: np.ndarray, mount: np.ndarray, tilts: list[np.ndarray]
                      ) -> np.ndarray:
    """Gravity in the sensor frame with three servos at ``angles`` (N, 3) on a jig whose x, y, z
    axes are tilted by ``tilts`` and whose sensor is mounted off by ``mount``."""
    ax = [t @ e for t, e in zip(tilts, np.eye(3), strict=True)]
    return np.array([(_axis_rotation(ax[0], a[0]) @ _axis_rotation(ax[1], a[1])
                      @ _axis_rotation(ax[2], a[2]) @ mount).T @ [0, 0, 1.0] for a in angles])


def _rest_means(sensing_g: np.ndarray, bias_g: np.ndarray, true_dirs: np.ndarray,
                rng: np.random.Generator, generator: str) -> tuple[np.ndarray, np.ndarray]:
    """The rests' mean readings (m/s²) with gravity along ``true_dirs`` and their standard
    deviations: the emulated chip's reading plus the window mean's noise, or the independent
    generator's (``tests/calib/accel_truth.py``)."""
    g = STANDARD_GRAVITY
    if generator == "emulator":
        means = AccelTruth(sensing_g, bias_g).reading(true_dirs) * g
        means += rng.standard_normal(means.shape) * WINDOW_STD
        return means, np.full(means.shape, WINDOW_STD)
    return indep.rest_means(rng, sensing_g, bias_g * g, true_dirs, g,
                            DENSITY_G * math.sqrt(ODR_HZ) * g, N_SAMPLES)


def _sphere_rms_mg(sensing_g: np.ndarray, bias_g: np.ndarray,
                   *calibrations: Callable[[np.ndarray], np.ndarray]) -> list[float]:
    """RMS calibrated-force error (mg) over 2000 gravity directions of each calibration (a
    function of raw readings, m/s²), against the independent contract's truth
    (:func:`tests.calib.accel_truth.truth_matrix`, not the frame code under test)."""
    g = STANDARD_GRAVITY
    reading = g * sphere_points(2000) @ sensing_g.T - bias_g * g
    truth_f = (reading + bias_g * g) @ indep.truth_matrix(sensing_g).T
    return [1e3 * math.sqrt(np.mean(np.sum((apply(reading) - truth_f) ** 2, axis=1))) / g
            for apply in calibrations]


def _fit_error(sensing_g: np.ndarray, bias_g: np.ndarray, true_dirs: np.ndarray,
               rng: np.random.Generator, generator: str) -> float:
    """RMS calibrated-force error (mg) of our fit on rests in ``true_dirs``."""
    means, std = _rest_means(sensing_g, bias_g, true_dirs, rng, generator)
    return _sphere_rms_mg(sensing_g, bias_g,
                          fit_accelerometer(means, std, STANDARD_GRAVITY).apply)[0]


def _errors(sensing_g: np.ndarray, bias_g: np.ndarray, dirs: np.ndarray, true_dirs: np.ndarray,
            rng: np.random.Generator, generator: str) -> tuple[float, float]:
    """RMS calibrated-force error (mg) of ours and of the six-position method."""
    g = STANDARD_GRAVITY
    means, std = _rest_means(sensing_g, bias_g, true_dirs, rng, generator)
    fit = fit_accelerometer(means, std, g)
    six_rows = [int(np.argmin(np.linalg.norm(dirs - t, axis=1))) for t in TOUR_DIRECTIONS[:6]]
    a6, b6 = six_position(means[six_rows], g)
    ours, six = _sphere_rms_mg(sensing_g, bias_g, fit.apply,
                               lambda reading: (reading + b6) @ in_frame(a6).T)
    return ours, six


def _sensor(generator: str, seed: int, rng: np.random.Generator
            ) -> tuple[np.ndarray, np.ndarray]:
    """A sensor's sensing matrix and bias (g): the emulated MPU-9250's draw for ``seed``, or the
    independent generator's from ``rng``."""
    if generator == "emulator":
        t = draw_accel_truth("mpu9250", seed)
        return np.asarray(t.sensing), np.asarray(t.bias_g)
    return indep.random_sensing(rng, 0.03, 0.02), rng.uniform(-0.06, 0.06, 3)


def main(argv: list[str]) -> None:
    opts = dict(a.split("=", 1) for a in argv if "=" in a)
    try:
        seeds = int(opts.get("--seeds", "100"))
        mount_deg = float(opts.get("--mount-deg", "3"))
    except ValueError:
        seeds, mount_deg = 0, math.nan
    if seeds < 1 or not math.isfinite(mount_deg):
        raise SystemExit("--seeds needs a positive whole number and --mount-deg a number of "
                         f"degrees, got {opts.get('--seeds')!r} and {opts.get('--mount-deg')!r}")
    print_table(["rests", "N", "distinct", "identifiable", "condition", "worst σ|f| mg",
                 "added jig s"], _designs(),
                f"accelerometer design (window σ {1e3 * WINDOW_STD / STANDARD_GRAVITY:.3f} mg, "
                f"{SPEED * 180 / math.pi:.0f}°/s moves, {REST_S} s rests)")
    tour = gravity_tour(SPEED, ACCEL, REST_S)
    dirs = np.vstack([DEFAULT_RESTS, tour.directions])
    poses = np.vstack([np.zeros((10, 2)), [[0.0, math.pi / 4]] * 3, tour.poses_rad])
    rows = []
    for generator in ("emulator", "independent"):
        out = []
        for seed in range(seeds):
            rng = np.random.default_rng([seed, 15])
            c, b = _sensor(generator, seed, rng)
            true_dirs = _true_directions(poses, _rotation(rng, mount_deg),
                                         [_rotation(rng, 0.3), _rotation(rng, 0.3)])
            out.append(_errors(c, b, dirs, true_dirs, rng, generator))
        e = np.array(out)
        rows.append([generator, seeds, float(np.sqrt(np.mean(e[:, 0] ** 2))),
                     float(np.sqrt(np.mean(e[:, 1] ** 2))),
                     float(np.sqrt(np.mean(e[:, 1] ** 2)) / np.sqrt(np.mean(e[:, 0] ** 2)))])
    print_table(["data", "sensors", "ours RMS mg", "six-position RMS mg", "ratio six/ours"],
                rows, f"calibrated specific force error over the sphere, default protocol + "
                      f"14-point tour (+{tour.added_time_s:.1f} s), mount {mount_deg:g}°")
    angles, plan = _planned()
    from gyrocal.calib.design import plan_protocol

    gyro = plan_protocol(servo_max_speed=SPEED / 0.9, full_scale=math.radians(500),
                         time_budget_s=45.0, model="full", noise_std=PLANNING_NOISE)
    print_table(["plan", "jig time s", "accelerometer's moves s", "rest s", "turns",
                 "predicted gyro rate error σ at 1 rad/s"],
                [["gyro alone (--no-accel-rests)", gyro.jig_time_s, 0.0, gyro.rest_s,
                  gyro.turns, gyro.rate_error_std],
                 ["with the accelerometer's rests (default)", plan.jig_time_s,
                  plan.accel_time_s, plan.rest_s, plan.turns, plan.rate_error_std]],
                "what the accelerometer costs the default protocol (45 s budget, both planned)")
    rows = []
    for generator in ("emulator", "independent"):
        out = []
        for seed in range(seeds):
            rng = np.random.default_rng([seed, 16])
            c, b = _sensor(generator, seed, rng)
            true_dirs = _true_directions3(angles, _rotation(rng, mount_deg),
                                          [_rotation(rng, 0.3) for _ in range(3)])
            out.append(_fit_error(c, b, true_dirs, rng, generator))
        e = np.array(out)
        rows.append([generator, seeds, len(angles), float(np.sqrt(np.mean(e**2))),
                     float(np.max(e)), plan.accel_time_s])
    print_table(["data", "sensors", "rests", "ours RMS mg", "worst sensor mg",
                 "accelerometer's moves s (the run grows by less: table above)"],
                rows, "calibrated specific force error over the sphere, the planner's tilted "
                      f"rests (no tour), mount {mount_deg:g}°")
