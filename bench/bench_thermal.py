"""Thermal calibration (issue 13): the thermal model against one calibration at the start.

1. Emulated MPU-9250 (``gyrocal thermal --sim``), temperature coefficients drawn by seed within
   the datasheet (PS-MPU-9250A-01 §3.1: ZRO ±30 °/s and sensitivity ±4 % over −40…85 °C; the
   draw of drivers.emulated.thermal), over a 10 °C warm-up: ambient ``ramp:20:26:600`` plus the
   default 4 °C self-heating (τ = 180 s), 8 runs of the default protocol 50 s apart. Across the
   covered range: RMS bias error with the model vs a single calibration at the start
   temperature (the first run), the same for the scale, the jig time, and the static-only
   warm-up (one spin calibration, then the sensor still for the same time, bias only: PX4's and
   ArduPilot's approach).
2. The same comparison on the independent Recording v1 generator (tests/kit/contract_recording,
   no gyrocal code): six calibrations of a 10 °C warm-up, estimated and fitted by gyrocal.

Targets: bias ratio ≤ 0.1, scale ratio ≤ 0.2.
Usage: ``python -m bench thermal [--quick]`` (``--quick``: one emulated sensor).
"""

from __future__ import annotations

import io
import json
import math
import tempfile
import time
from contextlib import redirect_stderr, redirect_stdout
from pathlib import Path

import numpy as np

from bench.table import print_table

WARMUP = ["--sim-temperature", "ramp:20:26:600", "--runs", "8", "--wait", "50"]


def _errors(model_cal, single, truth_of, lo, hi):
    """RMS bias error (rad/s) and RMS relative scale error over [lo, hi]: model vs single."""
    grid = np.linspace(lo, hi, 60)
    tb = np.array([truth_of(T)[1] for T in grid])
    tk = np.array([truth_of(T)[0] for T in grid])
    m = model_cal.temperature_model
    mb = np.array([m.at(T).bias for T in grid])
    if m.gain_coeffs is not None:
        mk = np.array([np.diag(m.at(T).gain) for T in grid])
    else:
        mk = np.tile(np.diag(model_cal.full_matrix), (grid.size, 1))
    sb, sk = np.asarray(single.bias), np.diag(single.full_matrix)

    def rms(x):
        return float(math.sqrt(np.mean(np.square(x))))

    return rms(mb - tb), rms(sb - tb), rms(mk / tk - 1), rms(sk / tk - 1)


def _emulated(seed: int) -> list[list[object]]:
    from gyrocal.calib.model import GyroCalibration
    from gyrocal.kit.cli import main
    from gyrocal.kit.thermal import truth_at

    rows = []
    for mode, extra in (("thermal (spins)", WARMUP), ("static-only", [
            "--sim-temperature", "ramp:20:26:600", "--static", "600"])):
        with tempfile.TemporaryDirectory() as tmp:
            d = Path(tmp) / "run"
            t0 = time.perf_counter()
            with redirect_stdout(io.StringIO()), redirect_stderr(io.StringIO()):
                main(["thermal", "--sim", "--sim-seed", str(seed), "--out", str(d), "--quiet",
                      *extra])
            wall = time.perf_counter() - t0
            cal = GyroCalibration.from_json((d / "calibration.json").read_text())
            single = GyroCalibration.from_json((d / "run-01" / "calibration.json").read_text())
            man = json.loads((d / "run-01" / "recording" / "manifest.json").read_text())
            truth = man["truth"]
            lo, hi = cal.temperature_model.range_c
            jig = _jig_time(d, mode, extra)

            def truth_of(T, truth=truth):
                t = truth_at(truth, T)
                return np.asarray(t["scale"]), np.asarray(t["bias"])

            eb, sb, ek, sk = _errors(cal, single, truth_of, lo, hi)
            rows.append([seed, mode, f"{lo:.1f}…{hi:.1f}", eb, sb, eb / sb, ek, sk, ek / sk,
                         jig, wall])
    return rows


def _jig_time(d: Path, mode: str, extra: list[str]) -> float:
    """Jig time: the runs' recordings plus the waits (or the still time)."""
    total = 0.0
    for man in sorted(d.glob("run-*/recording/manifest.json")):
        imu = np.loadtxt(man.parent / "imu.csv", delimiter=",", skiprows=1, usecols=0)
        total += float(imu[-1] - imu[0])
    if mode == "static-only":
        return total + float(extra[extra.index("--static") + 1])
    runs = len(list(d.glob("run-*")))
    return total + float(extra[extra.index("--wait") + 1]) * (runs - 1)


def _independent(seed: int) -> list[list[object]]:
    """Six calibrations of the independent generator over a 10 °C warm-up, fitted by gyrocal."""
    from gyrocal.kit.pipeline import estimate_recording
    from gyrocal.kit.recording import load_recording
    from gyrocal.kit.thermal import fit_calibrations, thermal_calibration
    from tests.kit.contract_recording import write_recording

    rng = np.random.default_rng([seed, 13])
    # MPU-9250 datasheet-range coefficients written out here: ±30 °/s and ±4 % over 125 °C
    zro, half = math.radians(30.0), 62.5
    coeffs = np.column_stack([rng.uniform(-0.05, 0.05, 3), rng.uniform(-0.75, 0.75, 3) * zro
                              / half, rng.uniform(-0.25, 0.25, 3) * zro / half**2])
    k0, ktc = rng.uniform(0.95, 1.05, 3), rng.uniform(-1, 1, 3) * 0.04 / half

    def die(t):
        return 20.0 + 11.0 * (1.0 - np.exp(-np.asarray(t) / 300.0))

    cals = []
    with tempfile.TemporaryDirectory() as tmp:
        for i in range(6):
            thermal = {"die": die, "t0": 110.0 * i, "bias_coeffs": coeffs, "scale_coeff": ktc}
            rec = load_recording(write_recording(Path(tmp) / f"r{i}", scale=k0, seed=seed * 10 + i,
                                                 noise=0.005, thermal=thermal))
            cals.append(estimate_recording(rec, "paired-axis").calibration)
    cal = thermal_calibration(cals, fit_calibrations(cals), source="independent")
    lo, hi = cal.temperature_model.range_c

    def truth_of(T):
        d = T - 25.0
        return k0 * (1 + ktc * d), coeffs @ d ** np.arange(3)

    eb, sb, ek, sk = _errors(cal, cals[0], truth_of, lo, hi)
    return [[seed, "independent generator", f"{lo:.1f}…{hi:.1f}", eb, sb, eb / sb, ek, sk,
             ek / sk, "", ""]]


def main(argv: list[str]) -> None:
    quick = "--quick" in argv
    rows = []
    for seed in ([1] if quick else [1, 2, 3]):
        rows += _emulated(seed)
    for seed in ([0] if quick else [0, 1, 2]):
        rows += _independent(seed)
    print_table(
        ["seed", "fit", "range °C", "bias RMS model", "bias RMS single", "ratio (≤0.1)",
         "scale RMS model", "scale RMS single", "ratio (≤0.2)", "jig time s", "wall s"],
        rows, title="thermal model vs one calibration at the start temperature, across the "
                    "covered range (RMS over axes and a 60-point grid; rad/s and relative)")
