"""Flight-stack exports in the drivers' frames (issue 31): the error a PX4 or ArduPilot vehicle
is left with after loading gyrocal's parameter files, before (values in the chip's axes, as
gyrocal wrote them until issue 31: ``--driver-axes x,y,z``) and after (the frame the stack's
driver publishes), and with no parameters at all.

For each stack, format and chip: a sensor's raw readings go through the stack's own correction
path written out from its source (tests/kit/flight_stacks.py: the driver's remap, the driver's
rotation, PX4 ``Gyroscope::Correct`` / ``Accelerometer::Correct`` / ``calc_thermal_offsets_3D``,
ArduPilot ``_rotate_and_correct_gyro`` / ``_accel`` / ``TCal::correct_sensor``) with the
parameters ``gyrocal export`` wrote for the calibration a perfect run holds, and the result is
compared with the true rate (or specific force) in the frame the stack publishes.

Sensors:

1. ``emulator``: each chip's errors as ``gyrocal calibrate --sim`` draws them (the paper's scale
   and bias, ±2 % cross-axis terms, the datasheet's temperature coefficients and accelerometer
   errors; tests/kit/flight_stacks.chip_truth), five seeds per chip.
2. ``independent``: tests/calib/fullmodel_truth.draw_truth (gyro: scale ±3 %, cross-axis ±2 %,
   bias ±0.05 rad/s) and an accelerometer drawn as tests/calib/accel_truth.random_sensing does
   (scale ±2 %, cross-axis ±1 %; without its mount rotation) with a zero-g bias within
   ±0.5 m/s², fitted by gyrocal from 14 noiseless rests; no temperature terms (the thermal
   formats are measured on 1 only); five seeds, each exported as every chip.

Figures: ``still`` the largest |error| of a still sensor (deg/s; over 15-45 °C for the thermal
formats, at 25 °C otherwise), ``turning`` the RMS |error| at 1 rad/s in 64 directions (deg/s;
the part the stacks cannot carry, the gyro's scale and cross-axis terms, is in all three
columns), ``accel`` the RMS |error| over 14 gravity directions (m/s²).

Usage: ``python -m bench flightframes``.
"""

from __future__ import annotations

import io
import math
from contextlib import redirect_stderr, redirect_stdout
from pathlib import Path
from tempfile import TemporaryDirectory

import numpy as np

from bench.table import print_table
from gyrocal.kit.cli import main as gyrocal
from tests.calib import accel_truth, fullmodel_truth
from tests.kit.flight_stacks import (
    ACCEL,
    CHIPS,
    DRIVERS,
    GYRO,
    STANDARD_GRAVITY,
    chip_truth,
    read_params,
    truth_calibration,
)

SEEDS = 5
FORMATS = {"px4": ("px4", "px4-thermal", "px4-accel"),
           "ardupilot": ("ardupilot", "ardupilot-thermal", "ardupilot-accel")}
TEMPERATURES = (15.0, 25.0, 35.0, 45.0)
_RNG = np.random.default_rng(31)
DIRECTIONS = _RNG.standard_normal((64, 3))
DIRECTIONS /= np.linalg.norm(DIRECTIONS, axis=1, keepdims=True)
UPS = accel_truth.fibonacci_directions(14)


class _IndependentTruth:
    """A sensor from the independent generators, with the reading methods the paths use."""

    def __init__(self, seed: int) -> None:
        rng = np.random.default_rng([seed, 0xF1])
        self.C, self.b, _, _ = fullmodel_truth.draw_truth(rng)
        # accel_truth.random_sensing's scale and cross-axis draw, without its random mount
        # rotation: the stacks' per-axis correction is checked in the chip's own axes
        self.sensing = np.diag(1 + 0.02 * rng.uniform(-1, 1, 3)) + 0.01 * rng.uniform(
            -1, 1, (3, 3)) * (1 - np.eye(3))
        self.acc_bias = rng.uniform(-0.5, 0.5, 3)  # m/s²

    def reading(self, omega: np.ndarray, temperature: np.ndarray) -> np.ndarray:
        return np.asarray(omega) @ self.C.T - self.b

    def accel_reading(self, up: np.ndarray) -> np.ndarray:
        """In g, as SensorTruth.accel_reading."""
        return (STANDARD_GRAVITY * np.asarray(up) @ self.sensing.T - self.acc_bias) \
            / STANDARD_GRAVITY

    def calibration(self, chip: str):
        from gyrocal.calib.accel import fit_accelerometer
        from gyrocal.calib.model import GyroCalibration

        a = np.linalg.inv(self.C)
        means = STANDARD_GRAVITY * self.accel_reading(UPS)
        acc = fit_accelerometer(means, np.full(means.shape, 1e-6))
        return GyroCalibration(scale=tuple(np.diag(a)), matrix=tuple(map(tuple, a)),
                               bias=tuple(self.b), frame="gyro-x-xy", temperature_c=25.0,
                               sensor={"model": chip}, accelerometer=acc)


def _export(cal_path: Path, fmt: str, *extra: str) -> dict[str, float] | None:
    out, err = io.StringIO(), io.StringIO()
    with redirect_stdout(out), redirect_stderr(err):
        code = gyrocal(["export", str(cal_path), "--format", fmt, *extra])
    return read_params(out.getvalue()) if code == 0 else None


def _figures(stack: str, fmt: str, chip: str, truth, params: dict[str, float]) -> dict:
    driver = DRIVERS[stack, chip]
    if fmt.endswith("-accel"):
        errs = [ACCEL[stack](params, chip, STANDARD_GRAVITY * truth.accel_reading(u[None])[0])
                - driver(STANDARD_GRAVITY * u) for u in UPS]
        return {"accel": float(np.sqrt(np.mean(np.sum(np.square(errs), axis=1))))}
    temps = TEMPERATURES if fmt.endswith("-thermal") else (25.0,)
    still = max(float(np.linalg.norm(GYRO[stack](
        params, chip, truth.reading(np.zeros((1, 3)), np.array([t]))[0], t))) for t in temps)
    turning = [GYRO[stack](params, chip, truth.reading(w[None], np.array([25.0]))[0])
               - driver(w) for w in DIRECTIONS]
    return {"still": math.degrees(still),
            "turning": math.degrees(float(np.sqrt(np.mean(np.sum(np.square(turning), 1)))))}


def _sensors(source: str):
    """(chip, truth, calibration) of each sensor of ``source``."""
    for chip in CHIPS:
        for k in range(SEEDS):
            if source == "emulator":
                truth = chip_truth(chip, seed=100 * (CHIPS.index(chip) + 1) + k)
                yield chip, truth, truth_calibration(truth, chip)
            else:
                truth = _IndependentTruth(k)
                yield chip, truth, truth.calibration(chip)


def _measure(source: str, tmp: Path) -> dict:
    """(stack, fmt, chip) -> {"before"|"after"|"none": [figures per sensor]}."""
    out: dict = {}
    for i, (chip, truth, cal) in enumerate(_sensors(source)):
        path = tmp / f"{source}-{i}.json"
        path.write_text(cal.to_json())
        for stack, formats in FORMATS.items():
            for fmt in formats:
                if fmt.endswith("-thermal") and cal.temperature_model is None:
                    continue
                accel_fmt = fmt if fmt.endswith("-accel") else None
                row = out.setdefault((stack, fmt, chip), {"before": [], "after": [], "none": []})
                for col, extra in (("after", ()), ("before", ("--driver-axes", "x,y,z"))):
                    params = _export(path, fmt, *extra)
                    assert params is not None, (fmt, chip)
                    row[col].append(_figures(stack, accel_fmt or fmt, chip, truth, params))
                row["none"].append(_figures(stack, accel_fmt or fmt, chip, truth, {}))
                if fmt == stack:  # the plain format carries the accelerometer too
                    key = (stack, fmt + " (accel)", chip)
                    acc = out.setdefault(key, {"before": [], "after": [], "none": []})
                    for col, extra in (("after", ()), ("before", ("--driver-axes", "x,y,z"))):
                        params = _export(path, fmt, *extra)
                        acc[col].append(_figures(stack, stack + "-accel", chip, truth, params))
                    acc["none"].append(_figures(stack, stack + "-accel", chip, truth, {}))
    return out


def _print(source: str, results: dict) -> None:
    for stack in FORMATS:
        rows = []
        for (s, fmt, chip), cols in results.items():
            if s != stack:
                continue
            for metric in cols["after"][0]:
                def worst(col: str, metric: str = metric, cols: dict = cols) -> float:
                    return max(f[metric] for f in cols[col])
                unit = "m/s^2" if metric == "accel" else "deg/s"
                rows.append([fmt, chip, f"{metric} ({unit})", worst("none"), worst("before"),
                             worst("after")])
        print_table(["format", "chip", "figure (worst of the sensors)", "no parameters",
                     "before: chip axes", "after: driver axes"], rows,
                    f"{stack}, {source} sensors ({SEEDS} per chip)")


def main(argv: list[str]) -> None:
    with TemporaryDirectory() as d:
        for source in ("emulator", "independent"):
            _print(source, _measure(source, Path(d)))


__all__ = ["main"]
