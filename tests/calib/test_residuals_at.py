"""calib.estimators.residuals_at: the fits' own residuals at a calibration's model (what
``gyrocal report`` draws), on the independent generators (tests/calib/hand_truth.py: the hand
jig with its stop; tests/calib/gsens_truth.py: the gimbal's posed protocol with g-sensitivity).

At the parameters a fit found, the held fit's optimum is the fit's own, so the sum of squares is
the fit's χ² (to rounding); at the generator's truth it is a χ² with the model's degrees of
freedom given back; a calibration that is wrong shows in it."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from gyrocal.calib.errors import CalibInputError
from gyrocal.calib.estimators import fit_full_matrix, residuals_at
from gyrocal.calib.hand import hand_observations
from tests.calib import hand_truth as ht
from tests.calib.fullmodel_truth import POSED, draw_truth
from tests.calib.gsens_truth import GRAVITY_RESTS, HOME_RESTS, POSED_RESTS, gsens_observations


def test_the_hand_jig_s_residuals_are_its_fit_s_chi_square_stop_included():
    """Each turn's axis and each rest's stop error are refitted under the held scale and bias;
    the stop (0.1°, 2.8e-4 of a turn) is in the still-angle terms, one per rest."""
    from gyrocal.calib.estimators import estimate

    rng = np.random.default_rng(23)
    C, bias, mount = ht.draw_sensor(rng)
    t, m, _, truth = ht.hand_session(rng, C, bias, mount)
    obs = hand_observations(t, m)[0].observations
    fit = estimate(obs, "paired-axis")
    res = residuals_at(obs, fit.bias, scale=fit.scale)
    assert res.method == "paired-axis"
    assert res.chi2 == pytest.approx(fit.consistency.chi2, rel=1e-6)
    assert res.windows.shape == (obs.n_windows, 3) and res.rests.shape == (obs.n_rests, 3)
    assert res.stills.size == obs.n_still_angles > 0
    # at the generator's truth: χ² on the fit's dof and the six parameters it no longer fits
    at_truth = residuals_at(obs, truth.bias, scale=truth.scale).chi2
    assert at_truth < stats.chi2.ppf(0.999, fit.consistency.dof + 6), at_truth
    # a bias 1e-3 rad/s off on y (a few σ of each of the 15 rests) shows
    off = residuals_at(obs, fit.bias + [0.0, 1e-3, 0.0], scale=fit.scale).chi2
    assert off > 3 * fit.consistency.chi2


def test_the_full_model_s_residuals_are_its_fit_s_chi_square_in_any_output_frame():
    """With g-sensitivity fitted (the poses and rests see gravity): the held fit refits ``G``
    as the fit does; a matrix given in another output frame (``R A``) gives the same sum."""
    rng = np.random.default_rng(31)
    C, bias, links, mount = draw_truth(rng)
    Gs = rng.uniform(-np.radians(0.1), np.radians(0.1), (3, 3))
    obs = gsens_observations(C, bias, Gs, links, mount, POSED,
                             HOME_RESTS + POSED_RESTS + GRAVITY_RESTS, noise=0.05, rng=rng)
    fit = fit_full_matrix(obs)
    assert fit.success and fit.g_sensitivity is not None, fit.message
    res = residuals_at(obs, fit.bias, matrix=fit.matrix)
    assert res.method == "full-matrix"
    assert res.chi2 == pytest.approx(fit.consistency.chi2, rel=1e-6)
    c, s = np.cos(0.3), np.sin(0.3)
    R = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    assert residuals_at(obs, fit.bias, matrix=R @ fit.matrix).chi2 == pytest.approx(res.chi2,
                                                                                    rel=1e-6)
    wrong = residuals_at(obs, fit.bias, matrix=fit.matrix @ np.diag([1.002, 1.0, 1.0]))
    assert wrong.chi2 > 3 * res.chi2  # a scale 2e-3 off (tens of its σ)
    with pytest.raises(CalibInputError, match="not both"):
        residuals_at(obs, fit.bias, scale=np.ones(3), matrix=fit.matrix)
