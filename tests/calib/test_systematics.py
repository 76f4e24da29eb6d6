"""The mount wobble's effect on the full matrix (calib/systematics.py), against the independent
generator's recordings (tests/kit/contract_fullmodel_recording.py: its own kinematics, its own
wobble, no code shared with the emulator or the estimator)."""

import math

import numpy as np
import pytest

from gyrocal.calib.estimators import fit_full_matrix
from gyrocal.calib.systematics import _basis, add_wobble, wobble_effects
from gyrocal.kit.pipeline import extract_recording, jig_wobble_rad
from gyrocal.kit.recording import load_recording
from tests.kit.contract_fullmodel_recording import default_plan_steps, write_recording

EPS = math.radians(0.5)  # ten times the assumed figure: the effect stands far above the noise


def _fit(path):
    obs = extract_recording(load_recording(path)).observations
    return obs, fit_full_matrix(obs)


@pytest.fixture(scope="module")
def pair(tmp_path_factory):
    """The default protocol's schedule (posed turns of the base with the middle, then the inner
    servo, at 45°), written once rigid and once with every link nodding by EPS; same noise."""
    root = tmp_path_factory.mktemp("wobble")
    steps = default_plan_steps(rest=0.5, pose_deg=45.0)
    write_recording(root / "rigid", seed=106, steps=steps, odr=100.0, noise=1.8e-3)
    truth = write_recording(root / "nod", seed=106, steps=steps, odr=100.0, noise=1.8e-3,
                            wobble_rad=EPS)
    return _fit(root / "rigid"), _fit(root / "nod"), truth


def test_wobble_effect_on_the_matrix_is_the_predicted_one(pair):
    (obs, fit), (_, nodding), truth = pair
    d = wobble_effects(obs, fit, EPS)  # (joint 1, 2) x (p1, p2) x (sin, cos) about the reference
    axes0 = np.asarray(fit.kinematics["axes"])
    ref = np.asarray(fit.kinematics["reference_angles_rad"])
    want = np.zeros(12)
    for k in (1, 2):
        e = truth["mount"].T @ truth["wobble_axes"][k]  # the link's nod axis, sensor frame, home
        for pi, p in enumerate(_basis(axes0[k])):
            c = float(p @ e)  # ψ = ε sin(ref + Δ) = ε (cos ref sin Δ + sin ref cos Δ)
            row = ((k - 1) * 2 + pi) * 2
            want += c * (math.cos(ref[k]) * d[row] + math.sin(ref[k]) * d[row + 1])
    got = np.concatenate([(nodding.matrix - fit.matrix).ravel(), nodding.bias - fit.bias])
    sd = np.sqrt(np.diag(fit.covariance))
    free = sd[:9] > 0
    assert np.max(np.abs(got[:9][free]) / sd[:9][free]) > 3  # the wobble moves A by > 3σ
    assert np.allclose(got[:9], want[:9], atol=0.1 * np.max(np.abs(got[:9])))


def test_wobble_widens_the_matrix_sigma_to_cover_it(pair):
    (obs, fit), (_, nodding), _ = pair
    widened = add_wobble(fit, obs, EPS)
    sd0 = np.sqrt(np.diag(fit.covariance))[:9]
    sd1 = np.sqrt(np.diag(widened.covariance))[:9]
    err = np.abs((nodding.matrix - fit.matrix).ravel())
    free = sd0 > 0
    assert np.all(sd1 >= sd0) and np.any(sd1[free] > 2 * sd0[free])
    assert np.all(err[free] <= 3 * sd1[free])  # the nod's own error within 3 of the new σ
    assert add_wobble(fit, obs, 0.0) is fit


def test_the_jig_wobble_comes_from_the_servo_table():
    from gyrocal.drivers.dynamixel.control_table import ASSUMED_WOBBLE_DEG, XM430_W350

    man = {"gimbal": {"motors": [{"id": 1, "model": "XM430-W350"}]}}
    assert jig_wobble_rad(man) == pytest.approx(math.radians(XM430_W350.wobble_deg))
    assert jig_wobble_rad({}) == pytest.approx(math.radians(ASSUMED_WOBBLE_DEG))


def test_the_turns_measure_the_nod_and_removing_it_restores_the_rigid_fit(pair):
    """Each nodding link's own turns measure its nod (the generator's ``ψ = ε sin θ`` about
    ``e``: ``X = ε (cos r e + sin r u × e)`` about the reference angle ``r``, in the fit's
    frame), and the fit of the windows with it taken out lands on the rigid run's fit (same
    noise) where the nod had moved the cross-axis terms by more than 3σ. (The diagonal moves
    by up to 1σ at this tenfold nod through the tilt's second order, ``ψ²/2`` of the rate,
    which is a hundredth of that at the assumed 0.05°.)"""
    from gyrocal.calib.estimators import matrix_in_frame
    from gyrocal.calib.systematics import measure_nods, remove_nod

    (_, rigid), (obs, fit), truth = pair
    nods = measure_nods(obs, fit)
    assert set(nods) == {1, 2}
    sensing = np.diag(1 / truth["scale"]) @ truth["misalignment"]
    to_fit = matrix_in_frame(sensing) @ sensing  # the generator's sensor frame to the fit's
    axes0 = np.asarray(fit.kinematics["axes"])
    ref = np.asarray(fit.kinematics["reference_angles_rad"])
    for k, nod in nods.items():
        u = axes0[k]
        e = to_fit @ truth["mount"].T @ truth["wobble_axes"][k]
        X = EPS * (math.cos(ref[k]) * e + math.sin(ref[k]) * np.cross(u, e))
        want = np.array([X @ p for p in _basis(u)])
        sd = np.sqrt(np.diag(nod.cov))
        assert np.all(np.abs(nod.x - want) < np.maximum(4 * sd, 0.02 * EPS)), (k, nod, want)
        assert np.all(sd < 0.02 * EPS)  # measured to 2 % of the nod
    clean = fit_full_matrix(remove_nod(obs, fit))
    sd = np.sqrt(np.diag(rigid.covariance))[:9]
    free = (sd > 0) & ~np.eye(3, dtype=bool).ravel()
    moved = np.abs((fit.matrix - rigid.matrix).ravel())[free] / sd[free]
    left = np.abs((clean.matrix - rigid.matrix).ravel())[free] / sd[free]
    assert moved.max() > 3 and left.max() < 0.2, (moved, left)
    # taken out, the nod's σ is its measurement's, far below the prior of an unmeasured one
    assert remove_nod(obs, fit).nod_removed and not obs.nod_removed
    measured = add_wobble(clean, remove_nod(obs, fit), EPS)
    prior = add_wobble(clean, obs, EPS)
    assert np.all(np.diag(measured.covariance)[:9] <= np.diag(prior.covariance)[:9])
