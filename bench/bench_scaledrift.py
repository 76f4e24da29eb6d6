"""The scale's temperature drift within one calibration run (issue 13), per chip.

A run on a die that warms takes each axis's scale at the temperature of its own turns, not at the
run's mean temperature that the calibration reports (the bias is referred to the mean; the scale's
coefficient cannot be measured within one run). How large is that against the scale's standard
deviation, for each chip's datasheet sensitivity change?

Data: the independent Recording v1 generator (tests/kit/contract_recording, no gyrocal code), the
paper's protocol (two turns each way about each servo at π rad/s, 1 s rests: about 30 s), white
noise 2.5e-3 rad/s per sample at 200 Hz (the MPU-9250's 0.01 °/s/√Hz), a die warming from
power-on like the emulator's default (4 °C above ambient, τ = 180 s): a run started 1 s after
power-on (the steepest part) and one started 10 min later. Each chip's scale coefficient is its
datasheet's largest, written out here with the sign alternating by axis (datasheets give ±):

* MPU-9250 ±4 % over −40…85 °C (PS-MPU-9250A-01 §3.1): 6.4e-4 per °C;
* ICM-20948 ±3 % over −40…85 °C (DS-000189 Table 1 ⚠): 4.8e-4 per °C;
* LSM9DS1 not given; ±2 % over −40…85 °C assumed ⚠: 3.2e-4 per °C;
* ICM-42688-P ±0.005 %/°C (DS-000347 Table 1 ⚠): 5e-5 per °C;
* LSM6DSOX: the LSM6DSO32's ±0.005 %/°C ⚠: 5e-5 per °C.

Columns: the die's change during the run, the largest offset of a servo's turns from the run's
mean temperature, the largest error of a scale against the truth at the run's mean (relative),
that error in units of the scale's stated σ, and whether gyrocal's note flagged it.
Usage: ``python -m bench scaledrift``.
"""

from __future__ import annotations

import json
import tempfile
from pathlib import Path

import numpy as np

from bench.table import print_table

PER_C = {"mpu9250": 0.04 / 62.5, "icm20948": 0.03 / 62.5, "lsm9ds1": 0.02 / 62.5,
         "icm42688p": 5e-5, "lsm6dsox": 5e-5}
SCALE = np.array([1.01, 0.99, 1.02])


def _die(t: np.ndarray) -> np.ndarray:
    return 22.0 + 4.0 * (1.0 - np.exp(-np.asarray(t) / 180.0))


def _row(chip: str, t0: float, tmp: Path) -> list[object]:
    from gyrocal.kit.pipeline import estimate_recording
    from gyrocal.kit.recording import load_recording
    from gyrocal.kit.thermal import turn_temperature_offsets
    from tests.kit.contract_recording import write_recording

    k = PER_C[chip] * np.array([1.0, -1.0, 1.0])
    flat = np.array([[0.01, 0.0], [-0.02, 0.0], [0.005, 0.0]])
    d = tmp / f"{chip}-{t0:g}"
    write_recording(d, scale=SCALE, noise=2.5e-3, seed=7, thermal={
        "die": _die, "t0": t0, "bias_coeffs": flat, "scale_coeff": k})
    man = json.loads((d / "manifest.json").read_text())
    man["sensor"]["model"] = chip  # the generator writes an MPU-9250; the note reads the model
    (d / "manifest.json").write_text(json.dumps(man))
    rec = load_recording(d)
    est = estimate_recording(rec, "paired-axis")
    cal = est.calibration
    temps = rec.imu_temp[np.isfinite(rec.imu_temp)]
    off = turn_temperature_offsets(rec.imu_t, rec.imu_temp, est.extracted.windows,
                                   cal.temperature_c)
    at_mean = SCALE * (1.0 + k * (cal.temperature_c - 25.0))
    err = np.abs(np.asarray(cal.scale) / at_mean - 1.0)
    sigma = np.asarray(cal.scale_std) / np.abs(np.asarray(cal.scale))
    flagged = any("drifts with the die temperature" in n for n in est.notes)
    return [chip, f"{PER_C[chip]:.1e}", f"{t0:g}", float(np.ptp(temps)),
            max(abs(v) for v in off.values()), float(err.max()),
            float(np.max(err / sigma)), "yes" if flagged else "no"]


def main(argv: list[str]) -> None:
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for chip in PER_C:
            for t0 in (1.0, 600.0):
                rows.append(_row(chip, t0, Path(tmp)))
    print_table(
        ["chip", "scale change /°C", "run start s", "ΔT in run °C", "max |δ| °C",
         "scale err at mean", "err / σ", "flagged"],
        rows, title="scale drift within one run (independent generator; the die warming "
                    "from power-on, 4 °C with τ = 180 s)")
