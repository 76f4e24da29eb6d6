"""The accelerometer fitted from a recording, end to end (issue 15): ``imu.csv``'s ``ax,ay,az``
columns read back, the rests windowed by ``estimate``'s own code, the fit of
:func:`gyrocal.kit.pipeline.estimate_recording`.

Recordings from the independent full-model generator (``tests/kit/contract_fullmodel_recording``:
its own kinematics, schedule and CSV writing, nothing from gyrocal's kit, drivers or calib), with
its gravity tour (13 poses besides home), at 200 Hz, rests of 0.8 s, in two flavours:

(a) the emulated accelerometer's error model (``drivers.emulated.accel``, MPU-9250 Table 2
    errors and its noise density) reading the generator's specific force;
(b) the generator's own accelerometer (``draw_accel``: scale 0.97–1.03, cross terms up to 0.01,
    bias up to 0.3 m/s², 0.03 m/s² white noise per sample), at a local gravity of 9.81 m/s²
    given in the manifest's ``site``.

Per flavour over ``--seeds`` sensors (default 20): the share of the nine parameters within 1σ
and 2σ of the truth (a Gaussian gives 68 % and 95 %), how often the χ² test passes (99 %
expected at its 1 % level), and the RMS over 2000 directions of the calibrated specific force's
error against the truth in the same frame, with the uncalibrated reading's for scale.

Usage: ``python -m bench accelrec [--seeds=N] [--quick]``.
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np

from bench.table import print_table
from gyrocal.calib.design import sphere_points
from gyrocal.drivers.emulated.accel import draw_accel_truth
from gyrocal.kit.pipeline import estimate_recording
from gyrocal.kit.recording import load_recording
from tests.kit.contract_fullmodel_recording import draw_accel, write_recording

G_N = 9.80665
IL = np.tril_indices(3)


def one(seed: int, flavour: str, tmp: Path) -> dict[str, float]:
    """One recording: errors in σ, χ² verdict, RMS force errors (m/s²)."""
    rng = np.random.default_rng([seed, 0xBE])
    if flavour == "emulated":
        emu = draw_accel_truth("mpu9250", seed)
        truth = {"reading": lambda f: emu.reading(f, rng, 200.0)}
        man = emu.manifest()
        A, b, g = np.asarray(man["matrix"]), np.asarray(man["bias_m_s2"]), G_N

        def read(u: np.ndarray) -> np.ndarray:
            return G_N * emu.reading(u)
    else:
        truth = draw_accel(seed)
        A, b, g = truth["matrix"], truth["bias"], 9.81

        def read(u: np.ndarray) -> np.ndarray:
            return np.linalg.solve(A, g * u.T).T - b
    path = tmp / f"{flavour}-{seed}"
    write_recording(path, seed=seed, accel_truth=truth, gravity_m_s2=g)
    acc = estimate_recording(load_recording(path)).calibration.accelerometer
    if acc is None:
        raise RuntimeError(f"seed {seed}: no accelerometer calibration")
    z = np.concatenate([(acc.matrix - A)[IL], acc.bias - b]) / acc.std
    a = read(sphere_points(2000))
    f_true = (a + b) @ A.T
    err = (a + acc.bias) @ acc.matrix.T - f_true
    raw = a - f_true
    return {"z": z, "ok": float(acc.consistency.ok),
            "rms": float(np.sqrt(np.mean(np.sum(err**2, axis=1)))),
            "raw": float(np.sqrt(np.mean(np.sum(raw**2, axis=1))))}


def main(argv: list[str]) -> None:
    opts = dict(a.lstrip("-").split("=", 1) for a in argv if "=" in a)
    seeds = int(opts.get("seeds", 5 if "--quick" in argv else 20))
    rows = []
    with tempfile.TemporaryDirectory() as d:
        for flavour in ("emulated", "independent"):
            res = [one(s, flavour, Path(d)) for s in range(seeds)]
            z = np.abs(np.concatenate([r["z"] for r in res]))
            rms = np.array([r["rms"] for r in res]) / G_N * 1e3
            raw = np.array([r["raw"] for r in res]) / G_N * 1e3
            rows.append([flavour, seeds, f"{np.mean(z < 1):.0%}", f"{np.mean(z < 2):.0%}",
                         f"{np.mean([r['ok'] for r in res]):.0%}",
                         f"{np.median(rms):.3f}", f"{np.max(rms):.3f}",
                         f"{np.median(raw):.1f}"])
    print_table(["data", "sensors", "|err| < 1σ", "|err| < 2σ", "χ² passes",
                 "RMS error mg (median)", "(worst)", "uncalibrated mg (median)"], rows,
                "Accelerometer from the recording's rests (estimate's path), 14 orientations, "
                "0.8 s rests at 200 Hz")
