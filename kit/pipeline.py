"""From a recording to a calibration: windows, fit, Calibration v1 or v2 (shared by the commands).

With the method ``auto`` (the default) the full model ``g = A (m + b)`` is fitted when the
recording's poses determine it (hardware_docs/method.md §9); otherwise the paper's diagonal model
is fitted with the paired-axis estimator, and the estimate carries a note saying that cross-axis
terms were not calibrated and how large the error they leave can be.
"""

from __future__ import annotations

from dataclasses import dataclass

from gyrocal.calib.errors import CalibInputError
from gyrocal.calib.estimators import FitResult, estimate
from gyrocal.calib.model import GyroCalibration
from gyrocal.calib.windows import ExtractedWindows, extract_observations
from gyrocal.kit.errors import EstimationError, InputError
from gyrocal.kit.recording import Recording, now_iso

__all__ = ["AUTO", "CROSS_AXIS_DATASHEET", "Estimate", "estimate_recording", "extract_recording"]

#: The method that chooses the full model when the poses determine it, else the diagonal one.
AUTO = "auto"
#: Cross-axis sensitivity the datasheets allow, by sensor model (fraction of the rate):
#: MPU-9250 product specification (PS-MPU-9250A-01) §3.1, Gyroscope Specifications,
#: "Cross-Axis Sensitivity ±2 %"; for sensors whose datasheet gives no figure (the LSM9DS1's
#: does not) the MPU-9250's is used as the typical MEMS value.
CROSS_AXIS_DATASHEET = {"mpu9250": 0.02}
_CROSS_AXIS_DEFAULT = 0.02


@dataclass(frozen=True, eq=False)
class Estimate:
    """A calibration with what it was computed from, and what the user must know about it."""

    calibration: GyroCalibration
    fit: FitResult
    extracted: ExtractedWindows
    notes: tuple[str, ...] = ()


def extract_recording(rec: Recording) -> ExtractedWindows:
    """The recording's windows (:func:`gyrocal.calib.windows.extract_observations`), with each
    window's pose when the manifest lists the gimbal's chain.

    Raises
    ------
    InputError
        If the recording cannot be windowed (truncated, a servo without encoder data, ...).
    """
    try:
        return extract_observations(
            rec.imu_t, rec.imu_rate, rec.enc_t, rec.enc_motor, rec.enc_angle, rec.segments,
            imu_temp=rec.imu_temp, chain=_chain(rec),
        )
    except CalibInputError as exc:
        raise InputError(f"{rec.path}: {exc}") from None


def _chain(rec: Recording) -> tuple[int, ...] | None:
    """The chain when every servo in it has encoder readings (else poses cannot be read)."""
    chain = rec.chain
    if chain is None or not set(chain) <= set(rec.enc_motor.tolist()):
        return None
    return chain


def diagonal_note(sensor_model: str | None, reason: str) -> str:
    """What a user must know about a diagonal calibration: cross-axis terms are not in it, and
    how large the error they leave can be."""
    frac = CROSS_AXIS_DATASHEET.get(str(sensor_model or "").lower(), _CROSS_AXIS_DEFAULT)
    return (
        f"cross-axis terms were NOT calibrated ({reason}); the diagonal model is exact only "
        f"about the six calibration axes: in other directions the calibrated rate can be off "
        f"by up to the sensor's cross-axis sensitivity, ±{100 * frac:g} % of the rate "
        f"(datasheet). Record with a posed protocol (gyrocal calibrate's default) to calibrate "
        "the full matrix."
    )


def _fit(ex: ExtractedWindows, method: str, sensor_model: str | None,
         path: object) -> tuple[FitResult, tuple[str, ...]]:
    obs = ex.observations
    try:
        if method != AUTO:
            return estimate(obs, method), ()
        if obs.chain is None:
            reason = "the recording's manifest does not list the gimbal's servos in chain order"
        else:
            full = estimate(obs, "full-matrix")
            if full.success:
                return full, ()
            reason = f"the recording's poses do not determine them: {full.message}"
        return estimate(obs, "paired-axis"), (diagonal_note(sensor_model, reason),)
    except CalibInputError as exc:
        raise InputError(f"{path}: {exc}") from None


def estimate_recording(
    rec: Recording, method: str = AUTO, *, source: str | None = None
) -> Estimate:
    """Window a recording and fit it with ``method`` (``auto``: module docstring).

    Raises
    ------
    InputError
        If the recording cannot be windowed (truncated, a servo without encoder data, ...).
    EstimationError
        If the estimator fails (the message says why).
    """
    ex = extract_recording(rec)
    fit, notes = _fit(ex, method, rec.sensor.get("model"), rec.path)
    if not fit.success:
        raise EstimationError(f"{fit.method} failed on {rec.path}: {fit.message}")
    cal = fit.to_calibration(
        sensor=rec.sensor,
        temperature_c=ex.observations.temperature_c,
        created=now_iso(),
        source=source if source is not None else str(rec.path),
    )
    return Estimate(calibration=cal, fit=fit, extracted=ex, notes=notes)
