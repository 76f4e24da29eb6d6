"""The single-servo jig (issue 29): general-motion error, bias error and jig time.

Two sources, side by side, for the full model (the planner's seats with the V-block, protocol
``full``) and the diagonal one (the three faces on the flat adapter, protocol ``auto``):

1. the emulator: ``gyrocal calibrate --sim --jig single-servo`` at its defaults (every realism
   effect on: g-sensitivity, coloured noise, DLPF, wobble, lever arm, clock error), the emulated
   user re-seating the cube with a 1° seating error;
2. the independent generator tests/calib/seats_truth.py (scipy rotations, none of gyrocal's seat
   table, planner or emulator): window means of the plan's seats with the plan's speed and
   turns, white noise of an MPU-9250 at 200 Hz, a 1° seating error, 0.3° of shaft tilt and the
   datasheet's g-sensitivity, fitted by the same estimator (``ObservationSet.by_seat``).

General-motion error: :func:`gyrocal.calib.design.general_motion_rms` per rad/s (the error no
output frame removes). Bias error: ``|b̂ − b|``, rad/s (the zero-g bias against the truth's).
Jig time: the emulated recording's length (its re-seats take the emulated hand 1.5 s and the
check 0.5 s) and the plan's, which counts :data:`gyrocal.calib.design.SEAT_HANDLING_S` per
re-seat (⚠ assumed) for a user at the real jig.

Usage: ``python -m bench single_servo [--seeds=N]`` (default 3). :func:`single_servo_rows` gives
the rows to a table of every jig kind (``bench/bench_jigs.py``).
"""

from __future__ import annotations

import io
import tempfile
from contextlib import redirect_stderr, redirect_stdout
from pathlib import Path

import numpy as np

from bench.table import pooled, print_table

#: Per-sample white noise of the generator's sensor: an MPU-9250's 0.01 °/s/√Hz (PS-MPU-9250A-01
#: §3.1) over its 92 Hz DLPF bandwidth at 200 Hz, rad/s.
NOISE_RAD_S = np.radians(0.01 * np.sqrt(92.0))
ODR_HZ = 200.0

PROTOCOLS = {"full": "full (seats with the V-block)", "auto": "diagonal (three faces)"}


def emulator_run(job: tuple[int, str]) -> dict:
    """One ``gyrocal calibrate --sim --jig single-servo`` run of sensor ``seed`` with
    ``protocol``; its errors against the emulator's truth."""
    from gyrocal.calib.design import general_motion_rms
    from gyrocal.kit.cli import main
    from gyrocal.kit.pipeline import estimate_recording
    from gyrocal.kit.recording import load_recording

    seed, protocol = job
    with tempfile.TemporaryDirectory() as tmp:
        d = Path(tmp) / "run"
        with redirect_stdout(io.StringIO()), redirect_stderr(io.StringIO()):
            code = main(["calibrate", "--sim", "--jig", "single-servo", "--sim-seed", str(seed),
                         "--protocol", protocol, "--out", str(d), "--quiet", "--no-report",
                         "--allow-implausible"])
        rec = load_recording(d / "recording")
        est = estimate_recording(rec)
        t = rec.truth
        C = np.diag(1 / np.asarray(t["scale"])) @ np.asarray(t["misalignment"])
        b = np.asarray(t["bias"])
        cal = est.calibration
        A = np.asarray(cal.matrix) if cal.matrix is not None else np.diag(cal.scale)
        p = rec.manifest["protocol"]
    return {"seed": seed, "protocol": protocol, "code": code, "method": est.fit.method,
            "gm": general_motion_rms(A, np.asarray(cal.bias), C, b),
            "bias": float(np.linalg.norm(np.asarray(cal.bias) - b)),
            "jig_s": float(rec.imu_t[-1] - rec.imu_t[0]), "plan_s": p["planned_jig_time_s"],
            "ok": bool(cal.consistency is not None and cal.consistency.ok),
            "seats": len(p["seats"])}


def generator_run(job: tuple[int, str]) -> dict:
    """One session of the independent generator with the plan's seats, speed and turns."""
    from gyrocal.calib.design import SEATS, general_motion_rms, plan_seats
    from gyrocal.calib.estimators import estimate
    from tests.calib.fullmodel_truth import draw_truth
    from tests.calib.seats_truth import session

    seed, protocol = job
    model = "full" if protocol == "full" else "diagonal"
    plan = plan_seats(servo_max_speed=4.8, full_scale=np.radians(500), noise_std=NOISE_RAD_S,
                      odr_hz=ODR_HZ, model=model)
    rng = np.random.default_rng([seed, 0x51])
    C, bias, _, _ = draw_truth(rng)
    G = rng.uniform(-1, 1, (3, 3)) * np.radians(0.1)
    count = int(plan.turns * 2 * np.pi / plan.speed * ODR_HZ)
    seats = {s: SEATS[s][0] for s in plan.seats}
    obs, seat, _, rest_seat, up = session(
        seats, C=C, bias=bias, rng=rng, speed=plan.speed, noise=NOISE_RAD_S, count=count,
        seat_error_rad=np.radians(1.0), shaft_tilt_rad=np.radians(0.3), g_sensitivity=G)
    by_seat = obs.by_seat(seat, rest_seat, up)
    fit = estimate(by_seat, "full-matrix") if model == "full" else estimate(by_seat,
                                                                            "paired-axis")
    A = fit.matrix if fit.matrix is not None else np.diag(fit.scale)
    return {"seed": seed, "protocol": protocol, "method": fit.method,
            "gm": general_motion_rms(A, fit.bias, C, bias),
            "bias": float(np.linalg.norm(fit.bias - bias)), "plan_s": plan.jig_time_s,
            "ok": bool(fit.consistency is not None and fit.consistency.ok),
            "seats": len(plan.seats)}


def _rms(rows: list[dict], key: str) -> float:
    return float(np.sqrt(np.mean([r[key] ** 2 for r in rows])))


def single_servo_rows(seeds: list[int]) -> list[dict]:
    """One row per protocol and source: ``jig``, ``source``, ``protocol``, RMS general-motion
    error per rad/s (``gm``), RMS bias error (``bias``, rad/s), jig time (``jig_s``: emulated,
    None on the generator; ``plan_s``: the plan's with the user's re-seats), fits consistent."""
    jobs = [(s, p) for p in PROTOCOLS for s in seeds]
    emu = pooled(emulator_run, jobs, lambda r: f"emulator seed {r['seed']} {r['protocol']}: "
                 f"{r['gm']:.2e} per rad/s, bias {r['bias']:.1e} rad/s")
    gen = [generator_run(j) for j in jobs]
    rows = []
    for source, runs in (("emulator", emu), ("independent generator", gen)):
        for p, label in PROTOCOLS.items():
            rs = [r for r in runs if r["protocol"] == p]
            if not rs:
                continue
            rows.append({"jig": "single-servo", "source": source, "protocol": label,
                         "sensors": len(rs), "method": rs[0]["method"], "gm": _rms(rs, "gm"),
                         "bias": _rms(rs, "bias"),
                         "jig_s": (float(np.mean([r["jig_s"] for r in rs]))
                                   if "jig_s" in rs[0] else None),
                         "plan_s": float(np.mean([r["plan_s"] for r in rs])),
                         "consistent": sum(r["ok"] for r in rs)})
    return rows


def main(argv: list[str]) -> None:
    n = 3
    for a in argv:
        if a.startswith("--seeds="):
            n = int(a.split("=", 1)[1])
    rows = single_servo_rows(list(range(n)))
    print_table(
        ["source", "protocol", "sensors", "method", "general-motion RMS per rad/s",
         "bias RMS rad/s", "emulated jig s", "jig s with re-seats (plan)", "χ² consistent"],
        [[r["source"], r["protocol"], r["sensors"], r["method"], r["gm"], r["bias"],
          "" if r["jig_s"] is None else r["jig_s"], r["plan_s"], r["consistent"]]
         for r in rows],
        title=f"The single-servo jig (seeds 0..{n - 1}; MPU-9250 datasheet sensor, ±2 % "
              "cross-axis)")
