"""The gyro calibration aligned to the accelerometer's frame (calib.accel.frame_rotation and
align_gyro, issue 15).

Truth is written here from the contracts alone: a gyro reading ``m = C_g ω − b_g`` and an
accelerometer reading ``a = C_a f − b_a`` of the body's rate and specific force; each
calibration in its frame convention is ``A = L⁻¹`` with ``C Cᵀ = L Lᵀ`` (Cholesky: lower
triangular, so ``A C`` is the rotation from the body to that frame, x along the sensor's x axis
and y in its x-y plane); the gimbal turns the body with rotation matrices written here.
"""

import math

import numpy as np
import pytest

from gyrocal.calib.accel import ACCEL_FRAME, FrameRotation, align_gyro, frame_rotation
from gyrocal.calib.errors import CalibInputError
from gyrocal.calib.model import GyroCalibration


def rot(axis, angle):
    a = np.asarray(axis, float) / np.linalg.norm(axis)
    k = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    return np.eye(3) + math.sin(angle) * k + (1 - math.cos(angle)) * k @ k


def sensing(rng, tilt=0.02):
    """Scales 1 ± 3 %, cross-axis ±2 %, and a small proper rotation of the whole (the die on
    the board): a right-handed sensor."""
    c = np.diag(1 + 0.03 * rng.uniform(-1, 1, 3)) + 0.02 * rng.uniform(-1, 1, (3, 3)) * (
        1 - np.eye(3))
    return c @ rot(rng.standard_normal(3), tilt)


def in_frame(c):
    return np.linalg.inv(np.linalg.cholesky(c @ c.T))


def world(rng):
    """A gyro, an accelerometer and a gimbal whose axes are a little off x, y, z."""
    cg, ca = sensing(rng), sensing(rng)
    axes = np.eye(3) + 0.01 * rng.standard_normal((3, 3))
    axes /= np.linalg.norm(axes, axis=1, keepdims=True)
    up = np.array([0.01, -0.02, 1.0])
    return cg, ca, axes, up / np.linalg.norm(up)


def rests(axes, up, angles):
    """Gravity (up) in the body frame with the servos at each row of ``angles``: the body's
    orientation is R_0(θ0) R_1(θ1) R_2(θ2) about the home axes."""
    out = []
    for th in angles:
        R = np.eye(3)
        for j in range(3):
            R = R @ rot(axes[j], th[j])
        out.append(R.T @ up)
    return np.array(out)


ANGLES = np.radians([[0, 0, 0], [90, 0, 0], [0, 45, 0], [45, 90, 0], [0, 90, 90],
                     [-90, 45, 135], [180, 0, 45], [0, -45, 0], [135, 45, -45],
                     [-45, 135, 90], [90, 90, 0], [0, 0, 180]])


def gyro_calibration(ag, bg, axes_gyro, cov=None):
    return GyroCalibration(
        scale=tuple(np.diag(ag)), bias=tuple(bg), matrix=tuple(map(tuple, ag)),
        matrix_std=tuple(map(tuple, np.full((3, 3), 1e-4) * (np.tril(np.ones((3, 3)))))),
        covariance=cov, frame="gyro-x-xy", method="full-matrix",
        kinematics={"chain": [1, 2, 3], "axes": axes_gyro.tolist(),
                    "reference_angles_rad": [0.0, 0.0, 0.0]})


def test_from_true_calibrations_the_aligned_gyro_reads_true_rates_in_the_accel_frame():
    rng = np.random.default_rng(15)
    cg, ca, axes, up = world(rng)
    ag, aa = in_frame(cg), in_frame(ca)
    rg, ra = ag @ cg, aa @ ca  # body -> each calibration's frame
    bg, ba = rng.normal(0, 0.01, 3), rng.normal(0, 0.2, 3)
    f_body = 9.81 * rests(axes, up, ANGLES)
    reading = f_body @ ca.T - ba
    forces = (reading + ba) @ aa.T  # the true accelerometer calibration applied
    axes_gyro = axes @ rg.T  # the gimbal's axes in the gyro's frame, as a full fit gives them
    fr = frame_rotation(forces, ANGLES, axes_gyro, np.zeros(3), 1e-4)
    assert np.allclose(fr.rotation, ra @ rg.T, atol=1e-12, rtol=0)
    assert np.allclose(fr.up, rg @ up, atol=1e-12) and fr.rms_rad < 1e-12
    cal = align_gyro(gyro_calibration(ag, bg, axes_gyro), fr)
    assert cal.frame == ACCEL_FRAME
    omega = rng.normal(0, 2.0, (50, 3))
    m = omega @ cg.T - bg
    assert np.allclose(cal.apply(m), omega @ ra.T, atol=1e-12, rtol=0)
    # the kinematics turned with the frame: the servo axes in the accelerometer's frame
    assert np.allclose(cal.kinematics["axes"], axes @ ra.T, atol=1e-12)
    # and the document round-trips with its frame
    back = GyroCalibration.from_json(cal.to_json())
    assert back.frame == ACCEL_FRAME and np.allclose(back.full_matrix, cal.full_matrix)


def setting(seed):
    """A drawn world, the true rotation between the calibrations' frames, and the rests' true
    gravity directions in the body frame."""
    rng = np.random.default_rng(seed)
    cg, ca, axes, up = world(rng)
    ag, aa = in_frame(cg), in_frame(ca)
    return rng, ag @ cg, aa @ ca, axes, rests(axes, up, ANGLES)


def rotation_z(fr, truth):
    """The fitted rotation's error in its own σ, per axis of the small rotation ``δ``."""
    e = fr.rotation @ truth.T  # exp([δ]×)
    delta = 0.5 * np.array([e[2, 1] - e[1, 2], e[0, 2] - e[2, 0], e[1, 0] - e[0, 1]])
    return delta / np.sqrt(np.diag(fr.covariance))


def test_the_rotation_sigma_covers_its_error_over_noisy_rests():
    rng, rg, ra, axes, dirs = setting(7)
    sd = 2e-3
    z = []
    for _ in range(60):
        noisy = (dirs + rng.normal(0, sd, dirs.shape)) @ ra.T
        z.append(rotation_z(frame_rotation(noisy, ANGLES, axes @ rg.T, np.zeros(3), sd),
                            ra @ rg.T))
    z = np.array(z)
    assert np.all(np.abs(z.mean(axis=0)) < 0.45)
    assert np.all((z.std(axis=0) > 0.7) & (z.std(axis=0) < 1.3)), z.std(axis=0)


def test_the_rotation_sigma_covers_a_wobbling_jig_that_the_rest_noise_does_not_show():
    """Each rest held a pose 0.05° (RMS per axis) off the one its encoders give, while the rests'
    stated noise is 40× smaller: the σ must widen to the scatter the rests show."""
    rng, rg, ra, axes, dirs = setting(11)
    sd, wobble = 2e-5, math.radians(0.05)
    z = []
    for _ in range(80):
        tilt = [rot(w, np.linalg.norm(w)) for w in rng.normal(0, wobble, (len(dirs), 3))]
        seen = np.array([t @ d for t, d in zip(tilt, dirs, strict=True)])
        noisy = (seen + rng.normal(0, sd, dirs.shape)) @ ra.T
        z.append(rotation_z(frame_rotation(noisy, ANGLES, axes @ rg.T, np.zeros(3), sd),
                            ra @ rg.T))
    z = np.array(z)
    assert np.all((z.std(axis=0) > 0.6) & (z.std(axis=0) < 1.4)), z.std(axis=0)
    assert np.mean(np.abs(z) < 3) > 0.97


def test_the_rotation_sigma_carries_the_fitted_axes_uncertainty():
    """The gyro fit's servo axes are off the true ones by their σ (0.03°, tilts drawn here): a
    tilted axis carries every rest's gravity the same wrong way, which the rests' own scatter
    (10× smaller) cannot show; with ``axes_std`` the σ covers the rotation's error."""
    rng, rg, ra, axes, dirs = setting(12)
    sd, ax_sd = 5e-5, math.radians(0.03)
    z = {False: [], True: []}
    for _ in range(60):
        fitted = axes.copy()
        for i, a in enumerate(axes):  # tilt each axis by σ per direction across it
            t1 = np.cross(a, [1.0, 0, 0])
            t1 /= np.linalg.norm(t1)
            t2 = np.cross(a, t1)
            v = a + ax_sd * (rng.standard_normal() * t1 + rng.standard_normal() * t2)
            fitted[i] = v / np.linalg.norm(v)
        noisy = (dirs + rng.normal(0, sd, dirs.shape)) @ ra.T
        for with_axes in (False, True):
            fr = frame_rotation(noisy, ANGLES, fitted @ rg.T, np.zeros(3), sd,
                                np.full(3, ax_sd) if with_axes else None)
            z[with_axes].append(rotation_z(fr, ra @ rg.T))
    covered, blind = np.array(z[True]), np.array(z[False])
    assert np.all((covered.std(axis=0) > 0.6) & (covered.std(axis=0) < 1.4)), covered.std(0)
    assert np.max(blind.std(axis=0)) > 2  # without the axes' σ it is overconfident
    with pytest.raises(CalibInputError, match="axes_std"):
        frame_rotation(dirs, ANGLES, axes, np.zeros(3), sd, [1e-3, -1.0, 0.0])


def test_the_covariance_is_propagated_through_the_rotation():
    rng = np.random.default_rng(3)
    cg, _, axes, _ = world(rng)
    ag = in_frame(cg)
    fixed = np.concatenate([np.tril(np.ones((3, 3))).ravel() == 0, np.zeros(3, bool)])
    L = np.tril(rng.normal(0, 1e-4, (12, 12)))
    cov = L @ L.T
    cov[:, fixed] = 0  # the frame convention fixes the upper triangle
    cov[fixed, :] = 0
    r = rot([0.3, -0.2, 0.5], 0.05)
    rc = np.diag([1e-6, 4e-6, 9e-6])
    cal = align_gyro(gyro_calibration(ag, np.zeros(3), axes, cov),
                     FrameRotation(r, rc, np.array([0, 0, 1.0]), 0.0, 12))
    # Monte Carlo: draw A and the rotation, apply, compare the sample covariance
    n = 20000
    p = rng.multivariate_normal(np.zeros(12), cov, n)
    d = rng.multivariate_normal(np.zeros(3), rc, n)
    samples = np.array([(rot(di, np.linalg.norm(di)) if np.linalg.norm(di) > 0 else np.eye(3))
                        @ r @ (ag + pi[:9].reshape(3, 3)) for pi, di in zip(p, d, strict=True)])
    got = np.asarray(cal.covariance)[:9, :9]
    mc = np.cov(samples.reshape(n, 9).T)
    assert np.allclose(got, mc, atol=0.05 * np.max(np.abs(got)))
    assert np.allclose(np.asarray(cal.covariance)[9:, 9:], cov[9:, 9:])


def test_bad_inputs_are_refused_with_what_to_do():
    rng = np.random.default_rng(1)
    cg, _, axes, up = world(rng)
    ag = in_frame(cg)
    one_axis = np.radians([[0, 0, 0], [0, 0, 90], [0, 0, 180], [0, 0, -90]])
    with pytest.raises(CalibInputError, match="two servo axes"):
        frame_rotation(rests(axes, up, one_axis), one_axis, axes, np.zeros(3), 1e-3)
    with pytest.raises(CalibInputError, match="N >= 3"):
        frame_rotation(np.ones((2, 3)), np.zeros((2, 3)), axes, np.zeros(3), 1e-3)
    diag = GyroCalibration(scale=(1.0, 1.0, 1.0), bias=(0.0, 0.0, 0.0))
    fr = FrameRotation(np.eye(3), np.zeros((3, 3)), up, 0.0, 12)
    with pytest.raises(CalibInputError, match="full model"):
        align_gyro(diag, fr)
    aligned = align_gyro(gyro_calibration(ag, np.zeros(3), axes), fr)
    with pytest.raises(CalibInputError, match="aligned once"):
        align_gyro(aligned, fr)
