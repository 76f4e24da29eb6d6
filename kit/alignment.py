"""The gyro calibration expressed in the calibrated accelerometer's frame (issue 15).

``--align-gyro-to-accel`` (``protocol.align_gyro_to_accel``) turns a full (v2) calibration that
carries the accelerometer's (the Calibration's ``accelerometer`` key) into the accelerometer's
frame ``accel-x-xy``, as imu_tk does, so that both sensors speak one frame: the rotation between
the frames is estimated from the recording's rests (:func:`gyrocal.calib.accel.frame_rotation`:
gravity carried through the fitted gimbal kinematics against the calibrated accelerometer's
reading) and applied to the matrix with its covariance (:func:`gyrocal.calib.accel.align_gyro`).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from gyrocal.kit.errors import InputError

__all__ = ["align_to_accelerometer"]


def align_to_accelerometer(cal: Any, rec: Any, extracted: Any,
                           axes_std_rad: Any = None) -> tuple[Any, str]:
    """``cal`` in the accelerometer's frame, and a note for the user (the rotation's angle and
    σ, the rests' RMS misfit).

    Parameters
    ----------
    cal : GyroCalibration
        A full calibration with ``kinematics`` and ``accelerometer``.
    rec : Recording
        Its recording, with the accelerometer's columns (``imu_accel``, m/s², beside ``imu_t``).
    extracted : ExtractedWindows
        The recording's windows (its rests and their encoder angles, ``observations.rest_pose``).
    axes_std_rad : dict, optional
        Each servo's axis σ from the gyro fit (``FullMatrixFit.axes_std_rad``, keyed by servo
        ID); the rotation's σ then carries the axes' uncertainty too.

    Raises
    ------
    InputError
        What is missing, and what to do.
    """
    from gyrocal.calib.accel import align_gyro, frame_rotation, still_means
    from gyrocal.calib.errors import CalibInputError

    if cal.accelerometer is None:
        raise InputError("--align-gyro-to-accel needs the accelerometer's calibration: the "
                         "recording has no accelerometer columns, or its rests did not "
                         "determine it (record with protocol.accel_rests on)")
    if cal.kinematics is None or cal.matrix is None:
        raise InputError("--align-gyro-to-accel needs the full model (a posed protocol, "
                         "protocol full): the diagonal model has no frame to align")
    accel = getattr(rec, "imu_accel", None)
    pose = getattr(extracted.observations, "rest_pose", None)
    if accel is None or pose is None or not extracted.rests:
        raise InputError("--align-gyro-to-accel needs the recording's accelerometer columns "
                         "and rests with encoder angles")
    spans = [(w.corners[0], w.corners[3]) for w in extracted.rests]
    try:  # the rests' means as the accelerometer's own fit takes them (shorter ones left out)
        means, errs, used = still_means(rec.imu_t, accel, spans)
    except CalibInputError as exc:
        raise InputError(f"cannot align the gyro to the accelerometer: {exc}") from None
    pose = np.asarray(pose)[used]
    forces = cal.accelerometer.apply(means)
    g = np.linalg.norm(forces, axis=1)
    sd = np.max(errs, axis=1) * np.max(np.diag(cal.accelerometer.matrix)) / g
    kin = cal.kinematics
    try:
        ax_std = (None if not axes_std_rad else
                  [axes_std_rad.get(m, 0.0) for m in kin["chain"]])
        fr = frame_rotation(forces, pose, kin["axes"], kin["reference_angles_rad"],
                            np.maximum(sd, 1e-9), ax_std)
        aligned = align_gyro(cal, fr)
    except CalibInputError as exc:
        raise InputError(f"cannot align the gyro to the accelerometer: {exc}") from None
    angle = float(np.degrees(np.arccos(np.clip((np.trace(fr.rotation) - 1) / 2, -1, 1))))
    sigma = float(np.degrees(np.sqrt(np.trace(fr.covariance))))
    return aligned, (f"the gyro calibration is in the accelerometer's frame accel-x-xy: the "
                     f"frames differ by {angle:.3f}° ± {sigma:.3f}° over {fr.rests} rests "
                     f"(RMS misfit {np.degrees(fr.rms_rad):.3f}°)")
