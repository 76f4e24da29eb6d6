"""kit.alignment: the gyro calibration in the accelerometer's frame from a recording's rests.

The recording and windows are stand-ins with the fields the kit reads (``imu_t``, ``imu_accel``;
the rests' time spans and encoder angles); their samples come from the contract's model written
here (tests/calib/test_frame_alignment.py's truth: readings of the body's specific force through
each sensor's sensing matrix), with white noise.
"""

from types import SimpleNamespace

import numpy as np
import pytest

from gyrocal.calib.accel import ACCEL_FRAME, AccelCalibration
from gyrocal.calib.model import Consistency, GyroCalibration
from gyrocal.kit.alignment import align_to_accelerometer
from gyrocal.kit.errors import InputError
from tests.calib.test_frame_alignment import ANGLES, in_frame, rests, world


def recording(rng, noise=0.0):
    cg, ca, axes, up = world(rng)
    ag, aa = in_frame(cg), in_frame(ca)
    ba = rng.normal(0, 0.2, 3)
    f_body = 9.80665 * rests(axes, up, ANGLES)
    t, acc, spans = [], [], []
    for k, f in enumerate(f_body):
        tk = 10.0 * k + np.arange(200) / 200.0
        t.append(tk)
        acc.append(f @ ca.T - ba + rng.normal(0, noise, (200, 3)))
        spans.append(SimpleNamespace(corners=(tk[0], tk[0], tk[-1], tk[-1])))
    rec = SimpleNamespace(imu_t=np.concatenate(t), imu_accel=np.vstack(acc))
    ex = SimpleNamespace(rests=spans, observations=SimpleNamespace(rest_pose=ANGLES))
    acc_cal = AccelCalibration(aa, ba, np.eye(9) * 1e-10, 9.80665,
                               Consistency(5.0, 3, 0.17, True), 12, 5, True)
    cal = GyroCalibration(
        scale=tuple(np.diag(ag)), bias=(0.01, 0.0, -0.02), matrix=tuple(map(tuple, ag)),
        covariance=tuple(map(tuple, np.eye(12) * 1e-10)), frame="gyro-x-xy",
        method="full-matrix", accelerometer=acc_cal,
        kinematics={"chain": [1, 2, 3], "axes": (axes @ (ag @ cg).T).tolist(),
                    "reference_angles_rad": [0.0, 0.0, 0.0]})
    return cal, rec, ex, (cg, ca, aa)


def test_aligned_gyro_reads_true_rates_in_the_accelerometer_frame():
    rng = np.random.default_rng(4)
    cal, rec, ex, (cg, ca, aa) = recording(rng)
    out, note = align_to_accelerometer(cal, rec, ex)
    assert out.frame == ACCEL_FRAME and "accel-x-xy" in note
    omega = rng.normal(0, 1.5, (20, 3))
    m = omega @ cg.T - np.asarray(cal.bias)
    assert np.allclose(out.apply(m), omega @ (aa @ ca).T, atol=1e-10)


def test_with_noise_the_error_is_within_the_stated_sigma():
    rng = np.random.default_rng(9)
    cal, rec, ex, (cg, ca, aa) = recording(rng, noise=0.05)
    out, _ = align_to_accelerometer(cal, rec, ex)
    truth = (aa @ ca) @ np.linalg.inv(np.asarray(cal.matrix) @ cg)
    err = np.asarray(out.matrix) @ np.linalg.inv(np.asarray(cal.matrix)) @ truth.T
    angle = np.arccos(np.clip((np.trace(err) - 1) / 2, -1, 1))
    std = np.sqrt(np.diag(np.asarray(out.covariance)))[:9]
    assert angle < 4 * np.max(std)


def test_what_is_missing_is_said():
    rng = np.random.default_rng(1)
    cal, rec, ex, _ = recording(rng)
    from dataclasses import replace

    with pytest.raises(InputError, match="needs the accelerometer's calibration"):
        align_to_accelerometer(replace(cal, accelerometer=None), rec, ex)
    with pytest.raises(InputError, match="accelerometer columns"):
        align_to_accelerometer(cal, SimpleNamespace(imu_t=rec.imu_t, imu_accel=None), ex)
