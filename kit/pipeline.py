"""From a recording to a calibration: windows, fit, Calibration v1 (shared by the commands)."""

from __future__ import annotations

from dataclasses import dataclass

from gyrocal.calib.errors import CalibInputError
from gyrocal.calib.estimators import FitResult, estimate
from gyrocal.calib.model import GyroCalibration
from gyrocal.calib.windows import ExtractedWindows, extract_observations
from gyrocal.kit.errors import EstimationError, InputError
from gyrocal.kit.recording import Recording, now_iso

__all__ = ["Estimate", "estimate_recording", "extract_recording"]


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
