"""From a recording to a calibration: windows, fit, Calibration v1 (shared by the commands)."""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from gyrocal.calib.errors import CalibInputError
from gyrocal.calib.estimators import FitResult, estimate
from gyrocal.calib.model import GyroCalibration
from gyrocal.calib.windows import ExtractedWindows, extract_observations
from gyrocal.kit.errors import EstimationError, InputError
from gyrocal.kit.recording import Recording, now_iso

__all__ = [
    "PLAUSIBLE_SCALE",
    "Estimate",
    "check_plausible",
    "estimate_recording",
    "extract_recording",
]

#: Scale factors a real MEMS gyro calibration can have: datasheet sensitivity tolerances are a
#: few percent (MPU-9250 ±3 %, PS-MPU-9250A-01 table 1; LSM9DS1 a similar figure), so anything
#: outside 0.5..2 is a unit or setup mistake, not a sensor.
PLAUSIBLE_SCALE = (0.5, 2.0)
#: The gyro's full scale assumed when the recording does not say (the largest of the chips), °/s.
_DEFAULT_FULL_SCALE_DPS = 2000.0


@dataclass(frozen=True, eq=False)
class Estimate:
    """A calibration with what it was computed from."""

    calibration: GyroCalibration
    fit: FitResult
    extracted: ExtractedWindows


def extract_recording(rec: Recording) -> ExtractedWindows:
    """The recording's windows (:func:`gyrocal.calib.windows.extract_observations`).

    Raises
    ------
    InputError
        If the recording cannot be windowed (truncated, a servo without encoder data, ...).
    """
    try:
        return extract_observations(
            rec.imu_t, rec.imu_rate, rec.enc_t, rec.enc_motor, rec.enc_angle, rec.segments,
            imu_temp=rec.imu_temp,
        )
    except CalibInputError as exc:
        raise InputError(f"{rec.path}: {exc}") from None


def estimate_recording(
    rec: Recording, method: str = "paired-axis", *, source: str | None = None
) -> Estimate:
    """Window a recording and fit it with ``method``.

    Raises
    ------
    InputError
        If the recording cannot be windowed (truncated, a servo without encoder data, ...).
    EstimationError
        If the estimator fails (the message says why).
    """
    ex = extract_recording(rec)
    try:
        fit = estimate(ex.observations, method)
    except CalibInputError as exc:
        raise InputError(f"{rec.path}: {exc}") from None
    if not fit.success:
        raise EstimationError(f"{method} failed on {rec.path}: {fit.message}")
    cal = fit.to_calibration(
        sensor=rec.sensor,
        temperature_c=ex.observations.temperature_c,
        created=now_iso(),
        source=source if source is not None else str(rec.path),
    )
    return Estimate(calibration=cal, fit=fit, extracted=ex)


def _scale_cause(k: float) -> str:
    """The likely cause of an implausible scale factor ``k`` (reference rate / gyro rate)."""
    deg = math.pi / 180.0
    if abs(math.log(k / deg)) < math.log(1.5):
        return ("the gyro reads about 57 times the reference: its readings are probably in °/s "
                "where Recording v1 wants rad/s (imu.csv gx,gy,gz)")
    if abs(math.log(k * deg)) < math.log(1.5):
        return ("the reference is about 57 times the gyro: the encoder angles are probably in "
                "degrees where Recording v1 wants radians (encoder.csv angle)")
    if k < 1:
        return ("the gyro reads far more than the encoders turned: check the gyro's units and "
                "the sensitivity (full-scale range) the readings were converted with")
    return ("the gyro reads far less than the encoders turned: check the gyro's units and "
            "sensitivity, and that the sensor is fixed to the turning stage")


def check_plausible(cal: GyroCalibration, sensor: Mapping[str, Any] | None = None, *,
                    allow: bool = False) -> list[str]:
    """Refuse a calibration no real gyro can have: a unit or setup mistake.

    A scale factor outside :data:`PLAUSIBLE_SCALE` (of g = K (m + b), the paper's model; for
    v2 the diagonal of the matrix) or a bias beyond the gyro's full scale (the recording's
    ``sensor.full_scale_dps``) means the readings or the reference are in the wrong units.

    Parameters
    ----------
    cal : GyroCalibration
    sensor : mapping, optional
        The recording's sensor section (its ``full_scale_dps``).
    allow : bool
        Return the problems instead of raising (``--allow-implausible``).

    Returns
    -------
    list of str
        The problems found (empty when plausible).

    Raises
    ------
    EstimationError
        If a problem is found and ``allow`` is false (exit 6), naming the likely cause.
    """
    lo, hi = PLAUSIBLE_SCALE
    matrix = getattr(cal, "matrix", None)
    k = np.diag(np.asarray(matrix, dtype=float)) if matrix is not None else np.asarray(
        cal.scale, dtype=float)
    b = np.asarray(cal.bias, dtype=float)
    fs_dps = (sensor or {}).get("full_scale_dps")
    if not isinstance(fs_dps, (int, float)) or isinstance(fs_dps, bool) or not (
            math.isfinite(fs_dps) and fs_dps > 0):
        fs_dps = _DEFAULT_FULL_SCALE_DPS
    fs = math.radians(fs_dps)
    problems = []
    bad = [j for j in range(3) if not (math.isfinite(k[j]) and lo <= k[j] <= hi)]
    if bad:
        causes = dict.fromkeys(  # one line per distinct cause, in axis order
            _scale_cause(k[j]) if math.isfinite(k[j]) and k[j] > 0
            else "the fit did not find a usable scale: check the recording" for j in bad)
        values = ", ".join(f"{'xyz'[j]} = {k[j]:.4g}" for j in bad)
        problems.append(f"scale {values} outside {lo:g}..{hi:g}: " + "; ".join(causes))
    bad = [j for j in range(3) if not (math.isfinite(b[j]) and abs(b[j]) <= fs)]
    if bad:
        values = ", ".join(f"{'xyz'[j]} = {b[j]:.4g}" for j in bad)
        problems.append(
            f"bias {values} rad/s beyond the gyro's full scale (±{fs_dps:g}°/s = "
            f"±{fs:.3g} rad/s): check the gyro's units (rad/s) and the sensitivity the "
            "readings were converted with")
    if problems and not allow:
        raise EstimationError(
            "implausible calibration, not written: " + "; ".join(problems)
            + ". If the sensor really is like this, pass --allow-implausible.")
    return problems
