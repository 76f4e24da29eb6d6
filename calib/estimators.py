r"""Estimators of the six calibration parameters from an observation set.

Three methods over one :class:`~gyrocal.calib.observations.ObservationSet`, shaped like
``scipy.optimize.least_squares``: arguments are validated up front with a
:class:`~gyrocal.calib.errors.CalibInputError` that names what is wrong, and non-convergence is a
status on
the returned :class:`FitResult`, not an exception.

``iterative-ls``
    The paper's Algorithm 1 on the squared-norm regression, Eq. (4)-(7).
``levenberg-marquardt``
    ``scipy.optimize.least_squares(method="lm")`` on the same residuals, the paper's baseline.
``paired-axis``
    Our estimator: every window's full mean vector, with one rotation axis per servo shared by its
    clockwise and counter-clockwise turns, and the rest windows, weighted by the measured noise.

Squared-norm residuals (paper Eq. 3-5), with ``θ = (k, b)`` and window means ``m̄_i``:

.. math:: r_i(θ) = \sum_j k_j^2 (\bar m_{ij} + b_j)^2 - ω_i^2

All three pool each axis's noise estimates over the windows where they are homogeneous before
using them as weights or for uncertainties (:func:`gyrocal.calib.observations.pool_noise`).

Covariance of the squared-norm methods comes from first-order propagation of the window noise: a
perturbation ``δm̄_ij`` of a mean and ``δω_i`` of a reference rate perturb ``r_i`` by
``δ_i = Σ_j 2 k_j^2 (m̄_ij + b_j) δm̄_ij - 2 ω_i δω_i``, with variance ``S_ii``; the estimator's
linear response to ``δ`` then gives a sandwich covariance (see :func:`fit_iterative_ls` and
:func:`fit_levenberg_marquardt`).

The paired-axis model (derived in ``hardware_docs/method.md``): for a window of servo ``s`` with
signed reference rate ``ω_i`` the true rate in the sensor frame is ``ω_i u_s``, ``u_s`` a unit
vector, and by Eq. (1) the expected reading is

.. math:: E[\bar m_i] = ω_i\, u_s ⊘ k - b ,

while a rest window reads ``E[\bar m_r] = -b``. Each ``u_s`` has two free angles. Residuals are
whitened by each window's covariance ``diag(σ²_ij) + σ²_{ω,i} (u_s⊘k)(u_s⊘k)ᵀ`` and the sum of
squares is minimised by Levenberg-Marquardt with an analytic Jacobian; the covariance is
``(J̃ᵀJ̃)⁻¹`` and ``Σ ẽ²`` is chi-square with ``3n + 3r - 6 - 2S`` degrees of freedom.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Any

import numpy as np

from gyrocal.calib import kinematics
from gyrocal.calib.dispersion import SCATTER_TOLERANCE, Dispersion, multiplicative
from gyrocal.calib.drift import BiasDrift
from gyrocal.calib.errors import CalibInputError
from gyrocal.calib.model import Consistency, GyroCalibration
from gyrocal.calib.observations import ObservationSet

if TYPE_CHECKING:
    from collections.abc import Callable

    from scipy import optimize

__all__ = [
    "CONSISTENCY_ALPHA",
    "FULL_FRAME",
    "METHODS",
    "FullMatrixBatch",
    "FitResult",
    "ModelResiduals",
    "add_bias_drift",
    "add_window_wander",
    "estimate",
    "fit_full_matrix",
    "full_matrix_batch",
    "fit_iterative_ls",
    "fit_levenberg_marquardt",
    "fit_paired_axis",
    "iterative_ls_batch",
    "lm_solve",
    "matrix_in_frame",
    "paired_axis_batch",
    "residuals_at",
]

#: The chi-square test's level: a fit is consistent when its p-value is at least this.
CONSISTENCY_ALPHA = 0.01

_AXES = "xyz"


@dataclass(frozen=True, eq=False)
class FitResult:
    """What an estimator returns.

    Attributes
    ----------
    method : str
        ``iterative-ls``, ``levenberg-marquardt`` or ``paired-axis``.
    scale, bias : numpy.ndarray, shape (3,)
        The estimates (model ``g = scale ∘ (m + bias)``, paper Eq. 1); NaN only if the estimator
        failed before producing any estimate.
    covariance : numpy.ndarray, shape (6, 6)
        Covariance of ``(k_x, k_y, k_z, b_x, b_y, b_z)``.
    iterations : int
        Iterations used (least-squares solves for Algorithm 1, function evaluations for LM,
        Levenberg-Marquardt steps for paired-axis).
    success : bool
        Whether the estimator converged to a valid estimate.
    status : str
        ``converged``, ``max-iterations``, ``sqrt-failed``, ``diverged``, ``singular`` or the
        scipy status text.
    message : str
        Human-readable account of ``status``.
    consistency : Consistency or None
        Chi-square test of the residuals, when there are redundant degrees of freedom.
    residuals : numpy.ndarray
        The final residuals (whitened for paired-axis).
    axes : dict or None
        Paired-axis only: ``{motor: unit axis (3,)}`` in the sensor frame.
    axes_std_rad : dict or None
        Paired-axis only: ``{motor: one-sigma angular uncertainty of the axis, rad}``.
    extra : dict
        Method-specific details (Algorithm 1: ``beta``, ``beta0``, ``condition_met``, and
        ``history`` of the (k, b) iterates).
    matrix : numpy.ndarray, shape (3, 3), or None
        Full-matrix only: ``A`` of ``g = A (m + b)`` in the frame ``frame``; ``scale`` is then its
        diagonal and ``covariance`` is 12×12 over ``(A row-major, b)``.
    frame : str or None
        Full-matrix only: the frame convention (:data:`FULL_FRAME`).
    kinematics : dict or None
        Full-matrix only: the gimbal as fitted, ``{"chain", "axes", "reference_angles_rad"}``
        (:mod:`gyrocal.calib.kinematics`).
    g_sensitivity : numpy.ndarray, shape (3, 3), or None
        Full-matrix with gravity known only: ``G`` of ``g = A (m + b + G f)``, rad/s per g of
        specific force ``f`` (sensor frame).
    g_sensitivity_cov : numpy.ndarray, shape (9, 9), or None
        Its covariance, ``G`` row-major.
    g_directions : numpy.ndarray, shape (k, 3), or None
        The directions of specific force the run determined ``G`` along
        (:func:`gravity_directions`); ``G`` is zero along the others, which stay in the bias.
    bias_drift : BiasDrift or None
        The bias instability and rate random walk whose variance over the run
        :func:`add_bias_drift` added to ``covariance``'s bias block; None before.
    mean_gain : numpy.ndarray, shape (Q, 3n + 3r), or None
        Paired-axis and full-matrix only: the first-order change of ``(scale, bias)`` (``Q`` 6)
        or ``(A row-major, b)`` (``Q`` 12) per unit change of each window's and then each
        rest's mean (row-major, rad/s), the fit's own weights: ``−(J̃ᵀJ̃)⁻¹ J̃ᵀ`` carried back
        through each window's whitening, times the root of the verdict's factor, so that
        ``mean_gain Σ mean_gainᵀ`` is the covariance errors of covariance ``Σ`` in the means
        give, on the scale of ``covariance`` (:func:`add_window_wander`).
    """

    method: str
    scale: np.ndarray
    bias: np.ndarray
    covariance: np.ndarray
    iterations: int
    success: bool
    status: str
    message: str
    consistency: Consistency | None = None
    residuals: np.ndarray = field(default_factory=lambda: np.zeros(0))
    axes: dict[int, np.ndarray] | None = None
    axes_std_rad: dict[int, float] | None = None
    extra: dict[str, Any] = field(default_factory=dict)
    matrix: np.ndarray | None = None
    frame: str | None = None
    kinematics: dict[str, Any] | None = None
    g_sensitivity: np.ndarray | None = None
    g_sensitivity_cov: np.ndarray | None = None
    g_directions: np.ndarray | None = None
    bias_drift: BiasDrift | None = None
    mean_gain: np.ndarray | None = None

    @property
    def scale_std(self) -> np.ndarray:
        """One-sigma uncertainty of ``scale`` (the matrix's diagonal for the full model)."""
        idx = [0, 4, 8] if self.matrix is not None else [0, 1, 2]
        return np.sqrt(np.clip(np.diag(self.covariance)[idx], 0, None))

    @property
    def bias_std(self) -> np.ndarray:
        """One-sigma uncertainty of ``bias``."""
        return np.sqrt(np.clip(np.diag(self.covariance)[-3:], 0, None))

    @property
    def matrix_std(self) -> np.ndarray | None:
        """One-sigma uncertainty of each element of ``matrix`` (None for the diagonal model)."""
        if self.matrix is None:
            return None
        return np.sqrt(np.clip(np.diag(self.covariance)[:9], 0, None)).reshape(3, 3)

    def to_calibration(
        self,
        *,
        sensor: dict[str, Any] | None = None,
        temperature_c: float | None = None,
        created: str | None = None,
        source: str | None = None,
    ) -> GyroCalibration:
        """The result as a :class:`~gyrocal.calib.model.GyroCalibration` (Calibration v1).

        Raises
        ------
        CalibInputError
            If the fit did not produce a valid estimate (``success`` is false).
        """
        if not self.success:
            raise CalibInputError(f"{self.method} did not produce a calibration: {self.message}")
        axes = None
        if self.axes is not None:
            axes = {
                str(m): {
                    "axis": [float(x) for x in u],
                    "misalignment_deg": float(_misalignment_deg(u)),
                    "nearest": _nearest_axis(u),
                    "std_deg": float(np.degrees((self.axes_std_rad or {}).get(m, np.nan))),
                }
                for m, u in self.axes.items()
            }
        full: dict[str, Any] = {}
        if self.matrix is not None:
            full = dict(
                matrix=tuple(tuple(float(x) for x in row) for row in self.matrix),
                matrix_std=tuple(tuple(float(x) for x in row) for row in self.matrix_std),  # type: ignore[union-attr]
                frame=self.frame,
                kinematics=self.kinematics,
            )
            if self.g_sensitivity is not None:
                g_std = np.sqrt(np.clip(np.diag(self.g_sensitivity_cov), 0, None))  # type: ignore[arg-type]
                full["g_sensitivity"] = {
                    "matrix": self.g_sensitivity.tolist(),
                    "matrix_std": g_std.reshape(3, 3).tolist(),
                    "directions": np.asarray(self.g_directions).tolist()}
        return GyroCalibration(
            **full,
            scale=tuple(self.scale),  # type: ignore[arg-type]
            bias=tuple(self.bias),  # type: ignore[arg-type]
            scale_std=tuple(self.scale_std),  # type: ignore[arg-type]
            bias_std=tuple(self.bias_std),  # type: ignore[arg-type]
            covariance=tuple(tuple(float(x) for x in r) for r in self.covariance),
            method=self.method,
            iterations=int(self.iterations),
            consistency=self.consistency,
            sensor=dict(sensor or {}),
            temperature_c=temperature_c,
            created=created,
            source=source,
            axes=axes,
            bias_drift=self.bias_drift,
        )


def add_bias_drift(fit: FitResult, drift: BiasDrift) -> FitResult:
    """``fit`` with the bias's wander within the run added to its bias covariance.

    The fit's covariance counts the white noise only, but the bias it estimates is an average
    over rests and windows spread over the run, during which the bias itself wanders (bias
    instability, rate random walk); :attr:`BiasDrift.run_variance` (``B² Φ(T, H) + K² T / 12`` per
    component, :mod:`gyrocal.calib.drift`) is added to the diagonal of the bias block. The
    wander is independent of the white noise and common to every window, so it adds to the bias
    alone (its correlation with the matrix, through the windows' weights, is neglected).

    Parameters
    ----------
    fit : FitResult
        A fit (any method); returned unchanged if it already carries a ``bias_drift``.
    drift : BiasDrift
        The figures and the run's span.

    Returns
    -------
    FitResult
        A new result with ``covariance`` and ``bias_drift`` set.
    """
    if fit.bias_drift is not None:
        return fit
    cov = np.array(fit.covariance, dtype=float)
    idx = np.arange(cov.shape[0] - 3, cov.shape[0])
    cov[idx, idx] += drift.run_variance
    return replace(fit, covariance=cov, bias_drift=drift)


def add_window_wander(fit: FitResult, change: np.ndarray) -> FitResult:
    """``fit`` with the bias's wander between its windows in the covariance as the process in
    time it is, in place of the per-window variance the windows' σ carried.

    A recording's windows are judged with their σ widened by the wander about the run's mean
    (:meth:`BiasDrift.window_variance`, so the χ² test does not blame a rest for it), which
    treats the wander as independent between windows. It is one process: a turn's two
    directions and the rests beside them are seconds apart and share it, so the contrasts the
    matrix comes from cancel most of it. With the fit's own weights (``fit.mean_gain``,
    ``M``), the covariance of the estimates is ``M (Σ_white + Σ_wander) Mᵀ``; the fit stated
    ``M (Σ_white + D) Mᵀ`` with ``D`` the per-window widening, so the result is

        covariance + M (Σ_wander − D) Mᵀ

    with ``Σ_wander`` the wander's covariance between the windows' means about the run's mean
    (:meth:`BiasDrift.window_covariance`; the run's mean itself is common to every window and
    goes whole into the bias: :func:`add_bias_drift`). The weights stay those the fit used
    (not the best for correlated errors, but the covariance is theirs).

    Parameters
    ----------
    fit : FitResult
        A fit whose windows' and rests' σ carried ``D``; returned unchanged without
        ``mean_gain`` (iterative-ls, levenberg-marquardt) or when ``change`` does not match it.
    change : numpy.ndarray, shape (3 (n + r), 3 (n + r))
        ``Σ_wander − D`` over the windows, then the rests, window-major
        (:meth:`BiasDrift.window_covariance_change`).

    Returns
    -------
    FitResult
    """
    gain = fit.mean_gain
    if gain is None or change.shape != (gain.shape[1],) * 2:
        return fit
    cov = np.asarray(fit.covariance, dtype=float) + gain @ change @ gain.T
    return replace(fit, covariance=0.5 * (cov + cov.T))


def _mean_gain(cov: np.ndarray, J: np.ndarray, L: np.ndarray, rest_std: np.ndarray
               ) -> np.ndarray:
    """``−(J̃ᵀJ̃)⁻¹ J̃ᵀ`` carried back to the raw means: ``(B, P, 3n + 3r)``, the first-order
    change of the parameters per unit change of each window's mean (whitened by ``L⁻¹``, ``L``
    (B, n, 3, 3)) and each rest's (whitened by ``1 / rest_std``, (B, r, 3)), row-major."""
    B, n = L.shape[:2]
    r = rest_std.shape[1]
    P = J.shape[-1]
    Jw = J[:, : 3 * n].reshape(B, n, 3, P)
    Linv = np.linalg.inv(L)
    win = np.einsum("bnkp,bnkq->bpnq", Jw, Linv).reshape(B, P, 3 * n)
    Jr = J[:, 3 * n : 3 * n + 3 * r].reshape(B, r, 3, P) / rest_std[..., None]
    rest = np.moveaxis(Jr, 3, 1).reshape(B, P, 3 * r)
    return -cov @ np.concatenate([win, rest], axis=2)


def _nearest_axis(u: np.ndarray) -> str:
    j = int(np.argmax(np.abs(u)))
    return ("+" if u[j] >= 0 else "-") + _AXES[j]


def _misalignment_deg(u: np.ndarray) -> float:
    """Angle between ``u`` and the sensor axis nearest to it, degrees."""
    return float(np.degrees(np.arccos(np.clip(np.max(np.abs(u)), -1.0, 1.0))))


# ---------------------------------------------------------------------------------- validation
def _validate_common(obs: ObservationSet, method: str, min_windows: int,
                     one_way: bool = False) -> None:
    """Refuse a set the method cannot fit. ``one_way``: rests measure the bias, so one turn
    per axis suffices (a hand jig's Ferraris session; DESIGN.md fact 3)."""
    if not isinstance(obs, ObservationSet):
        raise CalibInputError(f"obs must be an ObservationSet, got {type(obs).__name__}")
    if obs.n_windows < min_windows:
        raise CalibInputError(
            f"{method} needs at least {min_windows} rotation windows, got {obs.n_windows}; "
            "turn every servo both ways (the paper's six observations, ±x, ±y, ±z)"
        )
    for m in obs.motors if not one_way else ():
        dirs = set(obs.direction[obs.motor == m].tolist())
        if dirs != {-1, 1}:
            only = "positive" if dirs == {1} else "negative"
            raise CalibInputError(
                f"servo {m} turned only in the {only} direction; every servo must turn both ways "
                "(a clockwise and a counter-clockwise turn share one axis, which is what "
                "separates bias from scale)"
            )
    if np.any(np.abs(obs.rate) < 1e-3):
        i = int(np.flatnonzero(np.abs(obs.rate) < 1e-3)[0])
        raise CalibInputError(f"window {i} has a reference rate of {obs.rate[i]:.2e} rad/s")
    # Every sensor axis must be a large part of some window's rate: 0.6, below the 0.707 of a
    # turn between two axes (the single-servo jig's edge seats, (x + y)/√2, which a degree of
    # seating error can tip below 0.7 on one of them), far above a missing axis's few %.
    unit = obs.mean / np.linalg.norm(obs.mean, axis=1, keepdims=True)
    covered = np.any(np.abs(unit) > 0.6, axis=0)
    if not np.all(covered):
        missing = ", ".join(_AXES[j] for j in np.flatnonzero(~covered))
        raise CalibInputError(
            f"no window rotates about the sensor's {missing} axis; the fit needs a rotation "
            "about each of x, y and z (check which sensor axis each servo turns about)"
        )


# ---------------------------------------------------------------------------------- squared norm
def _design(mean: np.ndarray) -> np.ndarray:
    """Observation matrix with columns ordered as β1..β6 of Eq. (4): m², then m.

    The paper's Eq. (8) prints the linear columns first; this order matches its β definitions.
    """
    return np.concatenate([mean**2, mean], axis=-1)


def _theta_from_beta(beta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    k = np.sqrt(beta[..., :3])
    b = beta[..., 3:] / (2.0 * beta[..., :3])
    return k, b


def _sq_residuals(theta: np.ndarray, mean: np.ndarray, rate: np.ndarray) -> np.ndarray:
    k, b = theta[:3], theta[3:]
    return np.sum(k**2 * (mean + b) ** 2, axis=1) - rate**2


def _sq_jacobian(theta: np.ndarray, mean: np.ndarray, rate: np.ndarray | None = None) -> np.ndarray:
    k, b = theta[:3], theta[3:]
    mb = mean + b
    return np.concatenate([2 * k * mb**2, 2 * k**2 * mb], axis=1)


def _sq_noise_cov(theta: np.ndarray, obs: ObservationSet) -> np.ndarray:
    """``S``: covariance of the squared-norm residuals' noise (n, n): the window means' noise
    (independent) and the references' (correlated where windows share a still angle)."""
    k, b = theta[:3], theta[3:]
    g = 2 * k**2 * (obs.mean + b)
    S = np.diag(np.sum(g**2 * obs.mean_std**2, axis=1))
    two_w = 2 * obs.rate
    return S + np.outer(two_w, two_w) * obs.reference_covariance()


def _sq_consistency(e: np.ndarray, S: np.ndarray, H: np.ndarray, obs: ObservationSet
                    ) -> Dispersion | None:
    """The verdict on residuals ``e = (I - H) δ`` with ``Cov δ = S``: whitened by the
    pseudo-inverse square root of their covariance, so that ``Σ z² = eᵀ Cov(e)⁺ e``."""
    n = e.size
    dof = n - 6
    if dof <= 0:
        return None
    R = np.eye(n) - H
    cov_e = R @ S @ R.T
    chi2 = float(e @ np.linalg.pinv(cov_e, rcond=1e-10, hermitian=True) @ e)
    sd = np.sqrt(np.clip(np.diag(cov_e), 1e-300, None))
    # a squared norm's residual is twice the rate's relative error times ω²
    ratio = float(np.median(sd / (2 * obs.rate**2)))
    return _judged(e / sd, dof, obs, [f"turn {i}" for i in range(n)], chi2, ratio)


def _judged(z: np.ndarray, dof: int, obs: ObservationSet, names: list[str] | None = None,
            chi2: float | None = None, noise_ratio: float | None = None) -> Dispersion:
    """The verdict on whitened residuals ``z`` (:func:`gyrocal.calib.dispersion.multiplicative`),
    the scatter compared with the turn rate: by default a typical window mean's noise over the
    median turn rate. Without ``names`` the residuals are the window-fits' layout: three per
    turn, three per rest, one per still angle."""
    if noise_ratio is None:
        signal = float(np.median(np.abs(obs.rate))) if obs.rate.size else 1.0
        noise = float(np.median(obs.mean_std)) if obs.mean_std.size else 0.0
        noise_ratio = noise / signal if signal > 0 else 0.0
    groups = None
    if names is None:
        names = [f"turn {i}" for i in range(obs.rate.size) for _ in "xyz"]
        rests = 0 if obs.rest_mean is None else obs.rest_mean.shape[0]
        names += [f"rest {i}" for i in range(rests) for _ in "xyz"]
        names += [f"still angle {i}" for i in range(z.size - len(names))]
        groups = np.unique(names, return_inverse=True)[1]
    tolerance = SCATTER_TOLERANCE["hand" if obs.own_axes else "gyro"]
    return multiplicative(z, dof, noise_ratio, alpha=CONSISTENCY_ALPHA, names=names, chi2=chi2,
                          groups=groups, tolerance=tolerance)


def _ils_solve(
    X: np.ndarray, Y: np.ndarray, tol: float, max_iter: int
) -> tuple[np.ndarray, np.ndarray, list[float], str]:
    """Algorithm 1's iterates for one run: ``(beta, [β_Y, v], gammas, status)``.

    ``β⁽ⁿ⁺¹⁾ = (XᵀX)⁻¹Xᵀ(Y − γ⁽ⁿ⁾) = β_Y − γ⁽ⁿ⁾ v`` with ``β_Y = (XᵀX)⁻¹XᵀY`` and
    ``v = (XᵀX)⁻¹Xᵀ1``, so each iteration is a scalar update of ``γ`` and the stopping sum
    ``Σ|β⁽ⁿ⁺¹⁾ − β⁽ⁿ⁾|`` is ``|γ⁽ⁿ⁾ − γ⁽ⁿ⁻¹⁾| Σ|v|``: the paper's iterates, computed without
    re-solving. ``gammas`` lists ``γ⁽ⁿ⁾`` of every update, so iterate ``n + 1`` is
    ``β_Y − gammas[n − 1] v``. Status ``singular`` if ``X`` is rank-deficient.
    """
    rhs = np.stack([Y, np.ones_like(Y)], axis=1)
    try:
        if X.shape[0] == 6:
            sol = np.linalg.solve(X, rhs)
        else:
            sol, _, rank, _ = np.linalg.lstsq(X, rhs, rcond=None)
            if rank < 6:
                raise np.linalg.LinAlgError("rank-deficient")
    except np.linalg.LinAlgError:
        return np.full(6, np.nan), np.full((2, 6), np.nan), [], "singular"
    by = sol[:, 0].tolist()
    v = sol[:, 1].tolist()
    vsum = sum(abs(x) for x in v)
    gamma_prev = gamma = 0.0
    gammas: list[float] = []
    beta = by
    status = "max-iterations"
    it = 1
    while it < max_iter:
        b1, b2, b3 = beta[0], beta[1], beta[2]
        if b1 <= 0 or b2 <= 0 or b3 <= 0:
            status = "sqrt-failed"
            break
        gamma = beta[3] ** 2 / (4 * b1) + beta[4] ** 2 / (4 * b2) + beta[5] ** 2 / (4 * b3)
        if gamma != gamma or abs(gamma) == float("inf"):
            status = "diverged"
            break
        beta = [y - gamma * x for y, x in zip(by, v, strict=True)]
        gammas.append(gamma)
        it += 1
        if abs(gamma - gamma_prev) * vsum <= tol:
            status = "converged"
            break
        gamma_prev = gamma
    if status != "sqrt-failed" and min(beta[0], beta[1], beta[2]) <= 0:
        status = "sqrt-failed"
    return np.array(beta), sol.T, gammas, status


def fit_iterative_ls(
    obs: ObservationSet, *, tol: float = 1e-6, max_iter: int = 100, covariance: bool = True
) -> FitResult:
    r"""The paper's Algorithm 1: iterative least squares on the squared-norm regression.

    With ``X`` the observation matrix (Eq. 8; columns ``m²`` then ``m`` to match β1..β6 of Eq. 4)
    and ``Y = ω²`` (Eq. 7, squares of the window means, Eq. 9), starting from ``β0 = 0``::

        β⁽¹⁾ = (XᵀX)⁻¹ Xᵀ (Y - β0⁽⁰⁾)
        while Σ_j |β_j⁽ⁿ⁺¹⁾ - β_j⁽ⁿ⁾| > tol:
            γ⁽ⁿ⁾ = Σ_j β_{j+3}⁽ⁿ⁾² / (4 β_j⁽ⁿ⁾)
            β⁽ⁿ⁺¹⁾ = (XᵀX)⁻¹ Xᵀ (Y - γ⁽ⁿ⁾)

    and ``k = sqrt(β1..3)``, ``b = β4..6 / (2 β1..3)``. With exactly six windows ``(XᵀX)⁻¹Xᵀ`` is
    ``X⁻¹``; with more it is the least-squares solution of the same equations. Because ``γ`` only
    shifts ``Y`` by a constant, the iterates are computed as ``β_Y − γ v`` (see :func:`_ils_solve`).

    Each step contracts the error by about ``γ / (ω² - γ)`` (a constant shift of ``Y`` is absorbed
    by scaling β), so the paper's condition ``0 <= β0 < 0.5`` (at ``ω = 1 rad/s``) is the condition
    ``γ < ω²/2``; ``extra["condition_met"]`` reports the paper's literal condition.

    Covariance: differentiating the fixed point ``XᵀXβ = Xᵀ(Y - γ(β))`` gives
    ``(XᵀX + Xᵀ1∇γᵀ) dβ = Xᵀδ``, hence ``Cov β = A⁻¹ XᵀSX A⁻ᵀ`` with ``A = XᵀX + Xᵀ1∇γᵀ``, mapped
    to ``(k, b)`` by the Jacobian of the return formulas.

    Parameters
    ----------
    obs : ObservationSet
        At least six rotation windows covering ±x, ±y, ±z; rest windows are not used.
    tol : float
        Stopping tolerance on ``Σ|Δβ|`` (the paper's 1e-6).
    max_iter : int
        Most least-squares solves before giving up with status ``max-iterations``.
    covariance : bool
        Compute the covariance (skip it to time the bare algorithm).

    Returns
    -------
    FitResult
        ``iterations`` counts least-squares solves (the first estimate is iteration 1, as in the
        paper's Table I); ``extra["history"]`` holds ``(k, b)`` after each solve.
    """
    if not (tol > 0 and np.isfinite(tol)):
        raise CalibInputError(f"tol must be a positive number, got {tol!r}")
    if int(max_iter) < 1:
        raise CalibInputError(f"max_iter must be at least 1, got {max_iter!r}")
    _validate_common(obs, "iterative-ls", 6)
    if covariance:
        obs = obs.with_pooled_noise()
    X = _design(obs.mean)
    Y = obs.rate**2
    beta, (by, v), gammas, status = _ils_solve(X, Y, float(tol), int(max_iter))
    iterations = 1 + len(gammas)
    if status == "singular":
        return _failed("iterative-ls", "singular", "the observation matrix X is rank-deficient")
    gamma = gammas[-1] if gammas else 0.0
    condition_met = 0.0 <= gamma < 0.5
    condition = (
        ""
        if condition_met
        else (
            f"; the paper's convergence condition 0 <= β0 < 0.5 does not hold (β0 = {gamma:.3g}; "
            f"the iteration contracts by about β0/(ω² - β0) with mean ω² = {np.mean(Y):.3g})"
        )
    )
    extra = {"beta": beta, "beta0": gamma, "condition_met": condition_met}
    if status == "sqrt-failed":
        bad = ", ".join(f"β{j + 1} = {beta[j]:.4g}" for j in range(3) if beta[j] <= 0)
        return _failed(
            "iterative-ls",
            "sqrt-failed",
            f"k = sqrt(β) needs β1..3 > 0, got {bad}: the windows do not fit g = k(m + b) "
            "(check the axis assignment, that the sensor turned with the servo, and saturation)"
            + condition,
            iterations,
            extra,
        )
    if status == "diverged":
        return _failed(
            "iterative-ls", "diverged", "the iteration diverged" + condition, iterations, extra
        )
    message = {
        "converged": f"converged in {iterations} iterations (tol {tol:g})",
        "max-iterations": f"no convergence in {max_iter} iterations",
    }[status] + condition
    k, b = _theta_from_beta(beta)
    theta = np.concatenate([k, b])
    cov = np.full((6, 6), np.nan)
    consistency = None
    if covariance:
        S = _sq_noise_cov(theta, obs)
        grad_gamma = np.concatenate(
            [-(beta[3:] ** 2) / (4 * beta[:3] ** 2), beta[3:] / (2 * beta[:3])]
        )
        ones = np.ones(X.shape[0])
        A = X.T @ X + np.outer(X.T @ ones, grad_gamma)
        Ainv_Xt = np.linalg.solve(A, X.T)
        cov_beta = Ainv_Xt @ S @ Ainv_Xt.T
        T = np.zeros((6, 6))  # d(k, b) / dβ
        T[[0, 1, 2], [0, 1, 2]] = 1 / (2 * k)
        T[[3, 4, 5], [0, 1, 2]] = -beta[3:] / (2 * beta[:3] ** 2)
        T[[3, 4, 5], [3, 4, 5]] = 1 / (2 * beta[:3])
        cov = T @ cov_beta @ T.T
        # e = (I - H) δ to first order, with H = (X + 1∇γᵀ) A⁻¹ Xᵀ
        e = Y - gamma - X @ beta
        H = (X + np.outer(ones, grad_gamma)) @ Ainv_Xt
        verdict = _sq_consistency(e, S, H, obs)
        if verdict is not None:
            consistency, cov = verdict.consistency, cov * verdict.factor
    # History of iterates: β⁽¹⁾ = β_Y, then β_Y − γ⁽ⁿ⁾ v.
    hist_beta = by[None, :] - np.array([0.0, *gammas])[:, None] * v[None, :]
    hist = np.concatenate(_theta_from_beta(hist_beta), axis=1)
    return FitResult(
        method="iterative-ls",
        scale=k,
        bias=b,
        covariance=cov,
        iterations=iterations,
        success=status == "converged",
        status=status,
        message=message,
        consistency=consistency,
        residuals=_sq_residuals(theta, obs.mean, obs.rate),
        extra={**extra, "history": hist},
    )


def iterative_ls_batch(
    mean: np.ndarray, rate: np.ndarray, *, tol: float = 1e-6, max_iter: int = 100
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Algorithm 1 for ``B`` runs at once (same iterates as :func:`fit_iterative_ls`).

    Parameters
    ----------
    mean : ndarray, shape (B, n, 3)
    rate : ndarray, shape (B, n)

    Returns
    -------
    scale, bias : ndarray, shape (B, 3)
        NaN where the run failed.
    iterations : ndarray of int, shape (B,)
    converged : ndarray of bool, shape (B,)
    """
    X = _design(mean)
    Y = rate**2
    rhs = np.stack([Y, np.ones_like(Y)], axis=2)
    if X.shape[1] == 6:
        sol = np.linalg.solve(X, rhs)
    else:
        sol = np.linalg.pinv(X) @ rhs
    by, v = sol[..., 0], sol[..., 1]
    vsum = np.abs(v).sum(axis=1)
    B = mean.shape[0]
    gamma_prev = np.zeros(B)
    beta = by.copy()
    it = np.ones(B, dtype=np.int64)
    active = np.ones(B, dtype=bool)
    converged = np.zeros(B, dtype=bool)
    failed = np.zeros(B, dtype=bool)
    with np.errstate(divide="ignore", invalid="ignore"):
        for _ in range(int(max_iter) - 1):
            if not active.any():
                break
            bad = active & np.any(beta[:, :3] <= 0, axis=1)
            failed |= bad
            active &= ~bad
            gamma = np.sum(beta[:, 3:] ** 2 / (4 * beta[:, :3]), axis=1)
            new = by - gamma[:, None] * v
            beta = np.where(active[:, None], new, beta)
            it += active
            done = active & (np.abs(gamma - gamma_prev) * vsum <= tol)
            converged |= done
            active &= ~done
            gamma_prev = np.where(active, gamma, gamma_prev)
        ok = converged & np.all(beta[:, :3] > 0, axis=1) & ~failed
        k = np.where(ok[:, None], np.sqrt(np.abs(beta[:, :3])), np.nan)
        b = np.where(ok[:, None], beta[:, 3:] / (2 * beta[:, :3]), np.nan)
    return k, b, it, ok


def _failed(
    method: str,
    status: str,
    message: str,
    iterations: int = 0,
    extra: dict[str, Any] | None = None,
) -> FitResult:
    nan3 = np.full(3, np.nan)
    return FitResult(
        method=method, scale=nan3, bias=nan3.copy(), covariance=np.full((6, 6), np.nan),
        iterations=iterations, success=False, status=status, message=message,
        extra=dict(extra or {}),
    )


def lm_solve(
    mean: np.ndarray,
    rate: np.ndarray,
    x0: np.ndarray | None = None,
    *,
    xtol: float = 1e-14,
    ftol: float = 1e-14,
) -> optimize.OptimizeResult:
    """The bare ``scipy.optimize.least_squares(method="lm")`` call on the Eq. (3) residuals of
    window means ``mean`` (n, 3) and references ``rate`` (n,), from ``x0`` (default k = 1, b = 0).
    No validation: :func:`fit_levenberg_marquardt` is the checked entry point."""
    from scipy import optimize  # only this baseline needs it (about 1 s of import, issue 16)

    if x0 is None:
        x0 = np.array([1.0, 1.0, 1.0, 0.0, 0.0, 0.0])
    return optimize.least_squares(
        _sq_residuals, x0, jac=_sq_jacobian, method="lm", xtol=xtol, ftol=ftol, gtol=1e-15,
        args=(mean, rate),
    )


def fit_levenberg_marquardt(
    obs: ObservationSet,
    *,
    x0: np.ndarray | None = None,
    xtol: float = 1e-14,
    ftol: float = 1e-14,
    covariance: bool = True,
) -> FitResult:
    """The paper's baseline: ``scipy.optimize.least_squares(method="lm")`` on Eq. (3) residuals.

    Minimises ``Σ r_i(θ)²`` with ``r_i = Σ_j k_j²(m̄_ij + b_j)² - ω_i²`` over ``θ = (k, b)`` from
    ``x0`` (default ``k = 1, b = 0``). Covariance is the least-squares sandwich
    ``(JᵀJ)⁻¹ JᵀSJ (JᵀJ)⁻¹`` with ``S`` the residual noise variance (module docstring).

    Parameters
    ----------
    obs : ObservationSet
        At least six rotation windows covering ±x, ±y, ±z; rest windows are not used.
    x0 : array_like, shape (6,), optional
        Starting point ``(k_x, k_y, k_z, b_x, b_y, b_z)``.
    xtol, ftol : float
        Passed to ``least_squares``.
    covariance : bool
        Compute the covariance.

    Returns
    -------
    FitResult
        ``iterations`` is scipy's number of function evaluations.
    """
    _validate_common(obs, "levenberg-marquardt", 6)
    if covariance:
        obs = obs.with_pooled_noise()
    if x0 is None:
        x0 = np.array([1.0, 1.0, 1.0, 0.0, 0.0, 0.0])
    else:
        x0 = np.asarray(x0, dtype=float)
        if x0.shape != (6,) or not np.all(np.isfinite(x0)):
            raise CalibInputError(f"x0 must be 6 finite numbers, got {x0!r}")
    mean, rate = obs.mean, obs.rate
    res = lm_solve(mean, rate, x0, xtol=xtol, ftol=ftol)
    theta = res.x.copy()
    theta[:3] = np.abs(theta[:3])  # r depends on k²: the sign of k is not identified
    ok = bool(res.status > 0) and np.all(np.isfinite(theta))
    cov = np.full((6, 6), np.nan)
    consistency = None
    if covariance and ok:
        J = _sq_jacobian(theta, mean)
        S = _sq_noise_cov(theta, obs)
        JtJ_inv = np.linalg.pinv(J.T @ J)
        cov = JtJ_inv @ J.T @ S @ J @ JtJ_inv
        verdict = _sq_consistency(res.fun, S, J @ JtJ_inv @ J.T, obs)
        if verdict is not None:
            consistency, cov = verdict.consistency, cov * verdict.factor
    return FitResult(
        method="levenberg-marquardt",
        scale=theta[:3],
        bias=theta[3:],
        covariance=cov,
        iterations=int(res.nfev),
        success=ok,
        status="converged" if ok else "not-converged",
        message=str(res.message),
        consistency=consistency,
        residuals=np.asarray(res.fun),
    )


# ---------------------------------------------------------------------------------- paired axis
def _tangent_basis(u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors spanning the plane orthogonal to each unit vector in ``u`` (..., 3)."""
    helper = np.zeros_like(u)
    idx = np.argmin(np.abs(u), axis=-1)
    np.put_along_axis(helper, idx[..., None], 1.0, axis=-1)
    t1 = np.cross(u, helper)
    t1 /= np.linalg.norm(t1, axis=-1, keepdims=True)
    t2 = np.cross(u, t1)
    return t1, t2


@dataclass(frozen=True, eq=False)
class PairedAxisBatch:
    """Results of :func:`paired_axis_batch` for ``B`` independent runs."""

    scale: np.ndarray  # (B, 3)
    bias: np.ndarray  # (B, 3)
    axes: np.ndarray  # (B, S, 3)
    covariance: np.ndarray  # (B, P, P): k, b, two angles per servo, then the still angles
    chi2: np.ndarray  # (B,)
    dof: int
    iterations: np.ndarray  # (B,)
    converged: np.ndarray  # (B,) bool
    residuals: np.ndarray  # (B, 3n + 3r) whitened
    g_sensitivity: np.ndarray | None = None  # (B, 3, k): G along the force's k directions
    g_covariance: np.ndarray | None = None  # (B, 3k, 3k), G row-major
    mean_gain: np.ndarray | None = None  # (B, 6, 3n + 3r): d(k, b) / d(means) (_mean_gain)


def _paired_initial(
    mean: np.ndarray,
    rate: np.ndarray,
    sidx: np.ndarray,
    n_servos: int,
    rest_mean: np.ndarray,
    rest_std: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A closed-form start: per-servo regressions ``m̄ = ω d_s + c_s`` and the rests (a servo
    whose windows all share one rate, such as a single turn, takes ``d_s`` through the rests'
    bias instead)."""
    B = mean.shape[0]
    d = np.zeros((B, n_servos, 3))
    c = np.zeros((B, n_servos, 3))
    if rest_mean.shape[1]:
        wr = 1.0 / rest_std**2
        b_rest = -np.sum(wr * rest_mean, axis=1) / np.sum(wr, axis=1)
    for s in range(n_servos):
        sel = sidx == s
        w = rate[:, sel]  # (B, ns)
        m = mean[:, sel, :]
        wm, mm = w.mean(axis=1), m.mean(axis=1)
        dw = w - wm[:, None]
        spread = np.sum(dw**2, axis=1)
        if rest_mean.shape[1] and np.any(spread <= 1e-12 * np.sum(w**2, axis=1)):
            d[:, s] = np.mean((m + b_rest[:, None, :]) / w[..., None], axis=1)
            c[:, s] = -b_rest
            continue
        d[:, s] = np.einsum("bi,bij->bj", dw, m - mm[:, None, :]) / spread[:, None]
        c[:, s] = mm - d[:, s] * wm[:, None]
    b0 = b_rest if rest_mean.shape[1] else -c.mean(axis=1)
    dom = np.argmax(np.abs(d), axis=2)  # (B, S) dominant sensor axis of each servo
    k0 = np.ones((B, 3))
    for j in range(3):
        hit = dom == j
        with np.errstate(divide="ignore"):
            inv = np.where(hit, 1.0 / np.abs(d[:, :, j]), 0.0)
        cnt = hit.sum(axis=1)
        k0[:, j] = np.where(cnt > 0, inv.sum(axis=1) / np.maximum(cnt, 1), 1.0)
    u0 = k0[:, None, :] * d
    u0 /= np.linalg.norm(u0, axis=2, keepdims=True)
    return k0, b0, u0


def paired_axis_batch(
    mean: np.ndarray,
    rate: np.ndarray,
    motor_index: np.ndarray,
    mean_std: np.ndarray,
    rate_std: np.ndarray,
    rest_mean: np.ndarray,
    rest_std: np.ndarray,
    *,
    ref_matrix: np.ndarray | None = None,
    still_std: float = 0.0,
    force: np.ndarray | None = None,
    rest_force: np.ndarray | None = None,
    max_iter: int = 50,
    xtol: float = 1e-10,
    hold: tuple[np.ndarray, np.ndarray] | None = None,
) -> PairedAxisBatch:
    """The paired-axis fit for ``B`` runs of the same protocol at once (vectorised).

    Parameters
    ----------
    mean : ndarray, shape (B, n, 3)
        Window mean readings.
    rate : ndarray, shape (B, n)
        Signed reference rates.
    motor_index : ndarray of int, shape (n,)
        Servo of each window as an index ``0..S-1`` (same for every run).
    mean_std : ndarray, shape (B, n, 3)
        Standard errors of the window means.
    rate_std : ndarray, shape (B, n)
        Standard errors of the reference rates.
    rest_mean, rest_std : ndarray, shape (B, r, 3)
        Rest-window means and their standard errors (``r`` may be 0).
    ref_matrix : ndarray, shape (n, A), optional
        ``G``: how each window's reference rate changes per radian of error in each of ``A``
        shared still encoder angles (:meth:`ObservationSet.reference_matrix`). Each still angle's
        error becomes an unknown with prior standard deviation ``still_std``, so windows that
        share a still angle get correlated reference errors, as they have.
    still_std : float
        Prior standard deviation of a still angle, rad.
    force, rest_force : ndarray, shape (B, n, k) and (B, r, k), optional
        The mean specific force of each window and rest along ``k`` directions, g
        (:func:`fit_paired_axis`). Given, the model gains g-sensitivity,
        ``E[m̄] = ω u ⊘ k − b − G f`` (``3k`` more parameters, ``G`` row-major, after the
        still angles), as in :func:`full_matrix_batch`.
    max_iter : int
        Most Levenberg-Marquardt steps.
    xtol : float
        Convergence threshold on the largest parameter step (relative to ``1 + max k``); a run
        has also converged when a step changes the cost by less than ``1e-10`` relative, up or
        down (rounding level).
    hold : (ndarray (B, 3), ndarray (B, 3)), optional
        Scale factors and biases to hold (:func:`residuals_at`): only the axes, the still
        angles' errors and ``G`` are fitted.

    Returns
    -------
    PairedAxisBatch
    """
    B, n, _ = mean.shape
    r = rest_mean.shape[1]
    S = int(motor_index.max()) + 1
    G = np.zeros((n, 0)) if ref_matrix is None else np.asarray(ref_matrix, dtype=float)
    n_still = G.shape[1]
    if n_still and not still_std > 0:
        raise CalibInputError("still_std must be positive when ref_matrix has still angles")
    nk = 0 if force is None else np.shape(force)[-1]
    f_win = np.zeros((B, n, 0)) if force is None else np.broadcast_to(force, (B, n, nk))
    f_rest = np.zeros((B, r, 0)) if rest_force is None else np.broadcast_to(rest_force, (B, r, nk))
    P0 = 6 + 2 * S + n_still
    P = P0 + 3 * nk
    k, b, u = _paired_initial(mean, rate, motor_index, S, rest_mean, rest_std)
    if hold is not None:  # the start's axes are k0 ∘ d: the held scales' are k ∘ d
        k_held = np.broadcast_to(np.asarray(hold[0], dtype=float), (B, 3))
        u = k_held[:, None, :] * u / k[:, None, :]
        u /= np.linalg.norm(u, axis=2, keepdims=True)
        k, b = k_held.copy(), np.broadcast_to(np.asarray(hold[1], dtype=float), (B, 3)).copy()
    z = np.zeros((B, n_still))  # still-angle errors (reading minus true), rad
    gs = np.zeros((B, 3, nk))
    var_m = mean_std**2
    var_w = rate_std[:, :, None, None] ** 2
    eye3 = np.eye(3)

    def window_chol(ci: np.ndarray) -> np.ndarray:
        """Each window's noise ``diag(σ²) + σ²_ω c cᵀ`` (``c`` its axis over ``k``), factored."""
        return np.linalg.cholesky(var_m[..., None] * eye3 + var_w * ci[..., :, None]
                                  * ci[..., None, :])

    def evaluate(k, b, u, z, gs, with_jac):
        ui = u[:, motor_index, :]  # (B, n, 3)
        ci = ui / k[:, None, :]
        w = (rate - z @ G.T)[:, :, None]  # the true reference: measured minus its error
        e = mean - (w * ci - b[:, None, :] - np.einsum("bpq,bnq->bnp", gs, f_win))  # (B, n, 3)
        L = window_chol(ci)  # (B, n, 3, 3)
        ew = np.linalg.solve(L, e[..., None])[..., 0]  # whitened: L⁻¹ e
        er = (rest_mean + b[:, None, :] + np.einsum("bpq,brq->brp", gs, f_rest)) / rest_std
        ez = z / still_std if n_still else z
        E = np.concatenate([ew.reshape(B, 3 * n), er.reshape(B, 3 * r), ez], axis=1)
        if not with_jac:
            return E, None, None
        t1, t2 = _tangent_basis(u)  # (B, S, 3)
        J = np.zeros((B, n, 3, P))
        idx = np.arange(3)
        J[:, :, idx, idx] = w * ui / k[:, None, :] ** 2
        J[:, :, idx, 3 + idx] = 1.0
        cols = 6 + 2 * motor_index
        ar = np.arange(n)
        J[:, ar, :, cols] = np.moveaxis(-w * t1[:, motor_index, :] / k[:, None, :], 1, 0)
        J[:, ar, :, cols + 1] = np.moveaxis(-w * t2[:, motor_index, :] / k[:, None, :], 1, 0)
        if n_still:  # d e_i / d z_a = G_ia c_i (the true rate falls by G z)
            J[:, :, :, 6 + 2 * S:P0] = ci[..., None] * G[None, :, None, :]
        for p in range(3 if nk else 0):  # d e_p / d G_pq = f_q
            J[:, :, p, P0 + nk * p : P0 + nk * p + nk] = f_win
        Jw = np.linalg.solve(L, J).reshape(B, 3 * n, P)
        Jr = np.zeros((B, r, 3, P))
        Jr[:, :, idx, 3 + idx] = 1.0 / rest_std
        for p in range(3 if nk else 0):
            Jr[:, :, p, P0 + nk * p : P0 + nk * p + nk] = f_rest / rest_std[:, :, p : p + 1]
        Jz = np.zeros((B, n_still, P))
        Jz[:, np.arange(n_still), 6 + 2 * S + np.arange(n_still)] = (
            1.0 / still_std if n_still else 0.0
        )
        J = np.concatenate([Jw, Jr.reshape(B, 3 * r, P), Jz], axis=1)
        return E, J, (t1, t2)

    def retract(state, step, tb):
        k, b, u, z, gs = state
        t1, t2 = tb
        da = step[:, 6 : 6 + 2 * S : 2][..., None]
        db = step[:, 7 : 6 + 2 * S : 2][..., None]
        u_new = u + da * t1 + db * t2
        u_new /= np.linalg.norm(u_new, axis=2, keepdims=True)
        k_new = k + step[:, :3]
        ok = np.all(k_new > 0, axis=1)  # scale factors stay positive
        k_new = np.where(ok[:, None], k_new, k)
        gs_new = gs + step[:, P0:].reshape(B, 3, nk) if nk else gs
        return (k_new, b + step[:, 3:6], u_new, z + step[:, 6 + 2 * S : P0], gs_new), ok

    state, E, J, iterations, converged = _lm_batch(
        _holding(evaluate, 6 if hold is not None else 0), retract, (k, b, u, z, gs),
        max_iter=max_iter, xtol=xtol,
        step_scale=lambda state: 1.0 + np.max(np.abs(state[0]), axis=1))
    k, b, u, z, gs = state
    cov = np.linalg.pinv(J.transpose(0, 2, 1) @ J, hermitian=True)
    gain = _mean_gain(cov[:, :6], J, window_chol(u[:, motor_index, :] / k[:, None, :]),
                      rest_std)
    return PairedAxisBatch(
        scale=k,
        bias=b,
        axes=u,
        covariance=cov,
        chi2=np.sum(E**2, axis=1),
        dof=3 * n + 3 * r + n_still - P,  # each still-angle unknown has a prior observation
        iterations=iterations,
        converged=converged,
        residuals=E,
        g_sensitivity=gs if nk else None,
        g_covariance=cov[:, P0:, P0:] if nk else None,
        mean_gain=gain,
    )


def fit_paired_axis(obs: ObservationSet, *, max_iter: int = 50, g_sensitivity: bool = True,
                    max_g_std: float | None = None,
                    hold: tuple[np.ndarray, np.ndarray] | None = None) -> FitResult:
    r"""Paired-axis fit: scale, bias and each servo's axis from every window's full mean vector.

    Model (paper Eq. 1 inverted): a window of servo ``s`` at signed reference rate ``ω_i`` reads
    ``E[m̄_i] = ω_i u_s ⊘ k − b`` with ``u_s`` the servo's unit axis in the sensor frame (two free
    angles), and a rest reads ``E[m̄_r] = −b``. The clockwise and counter-clockwise turns of a servo
    share ``u_s``, so their off-axis components pin the bias, and every window informs every bias
    component (DESIGN.md fact 3). Residuals are whitened by each window's noise (module docstring)
    and minimised by Levenberg-Marquardt with an analytic Jacobian, starting from a closed-form
    per-servo regression. Each axis's noise estimates are pooled over the windows where they are
    homogeneous (:func:`gyrocal.calib.observations.pool_noise`), so the weights do not carry the
    estimates' own scatter; each still encoder angle a reference rests on is a shared unknown
    with its quantisation as prior. Covariance ``(J̃ᵀJ̃)⁻¹``; consistency:
    ``Σẽ² ~ χ²(3n + 3r − 6 − 2S)``. A servo turned in several gimbal poses (the full model's
    protocol) has one axis per pose (:meth:`ObservationSet.pose_groups`; ``S`` counts them) and
    ``axes`` reports the first.

    On the home-pose protocols (each servo turned in one pose: the paper's, ``auto``) with
    gravity known (:attr:`ObservationSet.has_gravity`), the model gains the g-sensitivity
    ``G`` along the directions of specific force the run determines
    (:func:`gravity_directions`: the rests, all in the home pose, and the vertical servo's turns
    against the horizontal ones' zero mean force determine ``G γ``, ``γ`` the home "up"), as
    :func:`fit_full_matrix` does, where the data need it (:func:`_g_needed`: a sensor without
    g-sensitivity keeps the paper's model); ``b`` is then the zero-g bias. Without it the rests
    and the horizontal turns disagree on the bias by ``G γ`` (up to 1.7e-3 rad/s on an
    MPU-9250), tens of σ.

    Parameters
    ----------
    obs : ObservationSet
        Rotation windows of every servo in both directions covering ±x, ±y, ±z, and rest windows;
        with rest windows, one turn per servo suffices (the rests measure the bias).
    max_iter : int
        Most Levenberg-Marquardt steps.
    g_sensitivity : bool
        Fit ``G`` where the run determines it (above).
    max_g_std : float, optional
        Largest one-sigma uncertainty of ``G`` along a direction for it to be fitted
        (default :data:`MAX_G_STD`).
    hold : (ndarray (3,), ndarray (3,)), optional
        Scale factors and biases to hold instead of fitting (:func:`residuals_at`).

    Returns
    -------
    FitResult
        With ``axes`` (each servo's unit axis in the sensor frame) and ``axes_std_rad``; with
        ``g_sensitivity`` (3×3, zero along the directions not fitted), its 9×9 covariance and
        ``g_directions`` where ``G`` was fitted; ``extra["g_left_out_per_g"]`` (the largest
        ``‖(k ∘ G)_i‖``, rad/s per g) where ``G`` was determined but not needed.
    """
    motors = obs.motors
    # With rests the bias is measured directly, and one turn per axis determines its scale and
    # its axis's two angles (three readings).
    one_way = obs.rest_mean is not None and obs.n_rests > 0
    _validate_common(obs, "paired-axis", len(motors) if one_way else max(6, 2 * len(motors)),
                     one_way)
    obs = obs.with_pooled_noise()
    # One axis per servo and gimbal pose: a servo turned with the gimbal posed turns about
    # another sensor-frame axis (a recording of the full model's protocol).
    groups = obs.pose_groups()
    first = {int(m): int(groups[i]) for i, m in reversed(list(enumerate(obs.motor)))}
    order = sorted(motors)

    def run(force: tuple[np.ndarray, np.ndarray] | None) -> PairedAxisBatch:
        return paired_axis_batch(
            obs.mean[None], obs.rate[None], groups, obs.mean_std[None], obs.rate_std[None],
            obs.rest_mean[None], obs.rest_mean_std[None],  # type: ignore[index]
            ref_matrix=obs.reference_matrix(), still_std=obs.still_angle_std,
            force=None if force is None else force[0][None],
            rest_force=None if force is None else force[1][None], max_iter=max_iter,
            hold=None if hold is None else (hold[0][None], hold[1][None]))

    res = run(None)
    basis = np.zeros((3, 0))
    extra: dict[str, Any] = {}
    if g_sensitivity and _home_pose_gravity(obs, groups):
        res, basis, extra = _paired_axis_g(obs, res, run, first, max_g_std)
    k, b, cov = res.scale[0], res.bias[0], res.covariance[0]
    ok = bool(res.converged[0]) and np.all(np.isfinite(k)) and np.all(k > 0)
    consistency, factor = None, 1.0
    if res.dof > 0:
        verdict = _judged(res.residuals[0], res.dof, obs)
        consistency, factor = verdict.consistency, verdict.factor
        cov = cov * factor
    # each servo's axis in the first pose it turned in (the home pose of gyrocal's protocols)
    axes = {m: res.axes[0, first[m]].copy() for m in order}
    axes_std = {}
    for m in order:
        i = first[m]
        blk = cov[6 + 2 * i : 8 + 2 * i, 6 + 2 * i : 8 + 2 * i]
        axes_std[m] = float(np.sqrt(max(np.linalg.eigvalsh(blk).max(), 0.0)))
    it = int(res.iterations[0])
    return FitResult(
        method="paired-axis",
        scale=k.copy(),
        bias=b.copy(),
        covariance=cov[:6, :6].copy(),
        iterations=it,
        success=ok,
        status="converged" if ok else "max-iterations",
        message=f"converged in {it} steps" if ok else f"no convergence in {max_iter} steps",
        consistency=consistency,
        residuals=res.residuals[0].copy(),
        axes=axes,
        axes_std_rad=axes_std,
        extra=extra,
        mean_gain=res.mean_gain[0] * np.sqrt(factor),  # type: ignore[index]
        **_g_terms(res, basis, factor),  # type: ignore[arg-type]
    )


def _paired_axis_g(obs: ObservationSet, res: PairedAxisBatch,
                   run: Callable[[tuple[np.ndarray, np.ndarray] | None], PairedAxisBatch],
                   first: dict[int, int], max_g_std: float | None
                   ) -> tuple[PairedAxisBatch, np.ndarray, dict[str, Any]]:
    """:func:`fit_paired_axis`'s g-sensitivity step: the directions the run determines, the
    fit with ``G`` along them where :func:`_g_needed` says the data need it, and the fit to keep
    with its ``G`` basis (``(3, 0)`` without) and ``extra``.

    A run whose die warmed was referred to its mean temperature with a drift slope measured on
    the rests (:func:`gyrocal.calib.thermal.correct_drift`); that slope's error offsets every
    window by ``δβ (T_w − T̄)``, and as the servos turn one after another while the die warms,
    it separates the turns and rests much as ``G γ`` does. So the test compares the two models
    with ``δβ`` free in both (``obs.temp_offset`` as one more regressor), so that the known
    drift is not taken for g-sensitivity; the fits kept are those without ``δβ`` (its
    uncertainty is already in the windows' σ).
    """
    # one pass: the forces of the fitted axes (G moves them far less than their σ)
    axes0 = np.array([res.axes[0, first[int(m)]] for m in obs.chain])  # type: ignore[union-attr,index]
    force = obs.specific_force(axes0, np.asarray(obs.home_pose, dtype=float))
    basis = gravity_directions(*force, obs.mean_std, obs.rest_mean_std,  # type: ignore[arg-type]
                               max_std=MAX_G_STD if max_g_std is None else max_g_std)
    if not basis.shape[1]:
        return res, basis, {}
    g_force = (force[0] @ basis, force[1] @ basis)
    with_g = run(g_force)
    nested = (res, with_g)
    if obs.temp_offset is not None:
        drift = (obs.temp_offset[:, None], obs.rest_temp_offset[:, None])  # type: ignore[index]
        nested = (run(drift), run((np.hstack([g_force[0], drift[0]]),
                                   np.hstack([g_force[1], drift[1]]))))
    if _g_needed(*nested, 3 * basis.shape[1]):
        return with_g, basis, {}
    # what is left in the bias: the size of the G the data did not need
    kG = with_g.scale[0][:, None] * (with_g.g_sensitivity[0] @ basis.T)  # type: ignore[index]
    return res, np.zeros((3, 0)), {"g_left_out_per_g": float(np.max(np.linalg.norm(kG, axis=1)))}


def _g_needed(without: PairedAxisBatch, with_g: PairedAxisBatch, n_terms: int) -> bool:
    """Whether the data need the g-sensitivity terms: the likelihood-ratio test of the nested
    models at :data:`CONSISTENCY_ALPHA`, ``χ²_without − χ²_with`` beyond the ``1 − α`` quantile
    of ``χ²(n_terms)``. A diagonal calibration cannot carry ``G`` (Calibration v1), so terms the
    noise explains are left in the bias rather than fitted."""
    from scipy.special import chdtri

    drop = float(without.chi2[0] - with_g.chi2[0])
    return bool(with_g.converged[0]) and drop > float(chdtri(n_terms, CONSISTENCY_ALPHA))


def _home_pose_gravity(obs: ObservationSet, groups: np.ndarray) -> bool:
    """Whether :func:`fit_paired_axis` can model g-sensitivity: gravity known, the chain's
    every servo turned, each in one pose (its axis then fixes the specific force)."""
    return (obs.has_gravity and obs.chain is not None and obs.home_pose is not None
            and set(obs.chain) == set(int(m) for m in obs.motors)
            and len(np.unique(groups)) == len(obs.motors))


#: The estimators by name.
METHODS = {
    "paired-axis": fit_paired_axis,
    "iterative-ls": fit_iterative_ls,
    "levenberg-marquardt": fit_levenberg_marquardt,
}


def estimate(obs: ObservationSet, method: str = "paired-axis", **options: Any) -> FitResult:
    """Run the estimator named ``method`` (a key of :data:`METHODS`) on ``obs``."""
    try:
        fn = METHODS[method]
    except KeyError:
        raise CalibInputError(
            f"unknown method {method!r}; choose one of {', '.join(METHODS)}"
        ) from None
    return fn(obs, **options)


# ---------------------------------------------------------------------------------- full matrix
#: Identifier of the frame convention of the full model (``hardware_docs/method.md``): x along
#: the gyro's x sensing axis, y in the plane of its x and y sensing axes, z completing a
#: right-handed frame. In it the matrix ``A`` of ``g = A (m + b)`` is lower triangular.
FULL_FRAME = "gyro-x-xy"

_TRIL = (np.array([0, 1, 1, 2, 2, 2]), np.array([0, 0, 1, 0, 1, 2]))


def matrix_in_frame(sensing: np.ndarray) -> np.ndarray:
    """``A`` in the frame :data:`FULL_FRAME` of a sensor whose reading is ``m = C g − b``.

    ``C`` (rows: the sensing axes divided by their scales, in any frame) is written ``C = L Q``
    with ``L`` lower triangular with a positive diagonal and ``Q`` a rotation or reflection (its LQ
    decomposition); ``A = L⁻¹``. For the emulated sensor, ``C = diag(1/scale) @ misalignment``.

    Raises
    ------
    CalibInputError
        If ``sensing`` is not a finite invertible 3×3 matrix.
    """
    C = np.asarray(sensing, dtype=float)
    if C.shape != (3, 3) or not np.all(np.isfinite(C)):
        raise CalibInputError(f"sensing must be a finite 3×3 matrix, got shape {C.shape}")
    _, r = np.linalg.qr(C.T)
    L = r.T * np.sign(np.diag(r))[None, :]
    if np.min(np.abs(np.diag(L))) <= 1e-12 * np.max(np.abs(L)):
        raise CalibInputError("sensing matrix is singular: two sensing axes are parallel")
    return np.linalg.inv(L)


@dataclass(frozen=True, eq=False)
class FullMatrixBatch:
    """Results of :func:`full_matrix_batch` for ``B`` independent runs.

    ``matrix`` is ``A`` of ``g = A (m + b)`` in the frame :data:`FULL_FRAME`; ``covariance`` is
    the 12×12 covariance of ``(A row-major, b)`` (zero rows and columns for the three elements
    the frame fixes at 0); ``axes`` are the servos' axes in that frame at ``reference``.
    """

    matrix: np.ndarray  # (B, 3, 3)
    bias: np.ndarray  # (B, 3)
    axes: np.ndarray  # (B, S, 3)
    axes_std_rad: np.ndarray  # (B, S)
    covariance: np.ndarray  # (B, 12, 12)
    chi2: np.ndarray  # (B,)
    dof: int
    iterations: np.ndarray  # (B,)
    converged: np.ndarray  # (B,) bool
    residuals: np.ndarray  # (B, 3n + 3r + A) whitened
    rank_deficiency: np.ndarray  # (B,) int: unobservable directions of the 9 + 2S model terms
    g_sensitivity: np.ndarray | None = None  # (B, 3, k) G of g = A (m + b + G f), rad/s per g
    g_covariance: np.ndarray | None = None  # (B, 3k, 3k) of G row-major
    g_cross_covariance: np.ndarray | None = None  # (B, 12, 3k): of (A row-major, b) with G
    mean_gain: np.ndarray | None = None  # (B, 12, 3n + 3r): d(A, b) / d(means) (_mean_gain)


def _inner_unrotate(u0: np.ndarray, delta: np.ndarray, j: int, v: np.ndarray) -> np.ndarray:
    """Undo the rotations of the servos inside ``j``: ``v = Rot_{S-1}(−Δ)…Rot_{j+1}(−Δ) x`` →
    ``x``. Shapes: ``u0`` (B, S, 3), ``delta`` (B, n, S), ``v`` (B, n, 3)."""
    for k in range(u0.shape[1] - 1, j, -1):
        v = kinematics.rotate(u0[:, None, k, :], delta[..., k], v)
    return v


def _full_initial(
    mean: np.ndarray, rate: np.ndarray, midx: np.ndarray, delta: np.ndarray, S: int,
    rest_mean: np.ndarray, rest_std: np.ndarray, mean_std: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A closed-form start: bias from the rests, each axis from its windows' mean directions
    (innermost servo first, so each outer window can be carried back to the reference pose), then
    ``(C, b)`` by weighted linear least squares given those axes."""
    B, n, _ = mean.shape
    if rest_mean.shape[1]:
        wr = 1.0 / rest_std**2
        b0 = -np.sum(wr * rest_mean, axis=1) / np.sum(wr, axis=1)
    else:
        b0 = np.zeros((B, 3))
    v = (mean + b0[:, None, :]) / rate[..., None]
    v /= np.linalg.norm(v, axis=2, keepdims=True)
    u0 = np.zeros((B, S, 3))
    for j in range(S - 1, -1, -1):
        sel = midx == j
        x = _inner_unrotate(u0, delta[:, sel], j, v[:, sel])
        s = x.sum(axis=1)
        u0[:, j] = s / np.linalg.norm(s, axis=1, keepdims=True)
    ui = kinematics.chain_axes(u0[:, None], 0.0, delta)[:, np.arange(n), midx]
    # m̄ = C u w − b, rests −b: linear in the six entries of C and b.
    r = rest_mean.shape[1]
    X = np.zeros((B, 3 * n + 3 * r, 9))
    for col, (p, q) in enumerate(zip(*_TRIL, strict=True)):
        X[:, p : 3 * n : 3, col] = ui[..., q] * rate
    for j in range(3):
        X[:, j : 3 * n : 3, 6 + j] = -1.0
        X[:, 3 * n + j :: 3, 6 + j] = -1.0
    y = np.concatenate([mean.reshape(B, -1), rest_mean.reshape(B, -1)], axis=1)
    w = 1.0 / np.concatenate([mean_std.reshape(B, -1), rest_std.reshape(B, -1)], axis=1)
    Xw, yw = X * w[..., None], y * w
    beta = np.linalg.solve(Xw.transpose(0, 2, 1) @ Xw, (Xw.transpose(0, 2, 1) @ yw[..., None]))
    c0 = beta[:, :6, 0]
    b0 = beta[:, 6:, 0]
    return c0, b0, u0


def _tril(c: np.ndarray) -> np.ndarray:
    C = np.zeros(c.shape[:-1] + (3, 3))
    C[..., _TRIL[0], _TRIL[1]] = c
    return C


def _still_owner(G: np.ndarray, pose_still: np.ndarray, midx: np.ndarray, n_still: int
                 ) -> np.ndarray:
    """The servo each still angle (column of ``G``) belongs to, -1 where no window uses it."""
    owner = np.full(n_still, -1, dtype=np.int64)
    for i, k in zip(*np.nonzero(pose_still >= 0), strict=True):
        owner[pose_still[i, k]] = k
    used = np.any(G != 0, axis=tuple(range(G.ndim - 2)) + (G.ndim - 2,)) if G.size else []
    for a in np.flatnonzero(used):
        rows = np.any(np.reshape(G[..., a], (-1, G.shape[-2])) != 0, axis=0)
        owner[a] = midx[np.flatnonzero(rows)[0]]
    return owner


def _gauge_servos(owner: np.ndarray, pose_still: np.ndarray, midx: np.ndarray, S: int,
                  G: np.ndarray | None = None) -> np.ndarray:
    """The servos whose encoder zero is an exact symmetry of the fit (:func:`_still_gauge`).

    Servo ``k``'s angle carries the axis of every servo outside it (``j < k``) in the sensor
    frame. Shifting its still angles by ``δ`` while turning the axes outside it by
    ``Rot(u_k⁰, δ)`` leaves a window of such a servo unchanged only if the window's pose of ``k``
    rests on one of those still angles (``pose_still[i, k] ≥ 0``). A window whose pose of ``k`` is
    its encoder reading as such (``-1``: the servo moved within the window, for instance still
    settling from a pose move, or another tool's schedule moves two servos at once) pins the zero
    through its data instead: there is no flat valley to move along, and a move would change that
    window's axis. Those servos are left out, and so is a servo one of whose still angles
    another servo's window references (``G``, the reference matrix: the single-servo jig's seats
    share the one servo's still angles across a re-seat), since the move would change that
    window's rate.

    Returns
    -------
    ndarray of bool, shape (S,)
    """
    movable = np.zeros(S, dtype=bool)
    used = (np.any(np.reshape(G != 0, (-1,) + G.shape[-2:]), axis=0) if G is not None
            and G.size else None)  # (n, A): which window references which still angle
    for k in range(S):
        if np.any(owner == k):
            movable[k] = bool(np.all(pose_still[midx < k, k] >= 0))
            if movable[k] and used is not None:
                movable[k] = not np.any(used[midx != k][:, owner == k])
    return movable


def _still_gauge(u: np.ndarray, z: np.ndarray, owner: np.ndarray, movable: np.ndarray
                 ) -> tuple[np.ndarray, np.ndarray]:
    """Move along the fit's exact symmetries, one per servo of ``movable``
    (:func:`_gauge_servos`), to where the still angles' priors are least: zero mean reading
    error for each servo.

    Shifting every still angle of servo ``k`` by ``δ`` (its encoder's zero) changes no rate
    reference (each is a difference of that servo's still angles) and, with every axis ``u_m⁰``
    outside it (``m < k``) turned by ``Rot(u_k⁰, δ)``, no axis in any window whose pose of ``k``
    rests on those still angles (:mod:`gyrocal.calib.kinematics`:
    ``Rot(Ra, φ) = R Rot(a, φ) Rᵀ``); ``C``, ``b``, ``G`` and the specific forces (fixed within
    a fit) do not move. Only the priors ``z/σ`` see ``δ``, so the minimum has ``Σ z = 0`` per
    servo. A linear step cannot follow this curved valley once the data are precise (its walls
    rise as ``δ²/σ²_mean``): without this move the fit stalls at noise below about 1e-7 rad/s.
    """
    if not z.shape[1] or not np.any(movable):
        return u, z
    u, z = u.copy(), z.copy()
    for k in np.flatnonzero(movable):
        cols = owner == k
        delta = z[:, cols].mean(axis=1)
        z[:, cols] -= delta[:, None]
        for m in range(k):
            u[:, m] = kinematics.rotate(u[:, k], delta, u[:, m])
    return u, z


def full_matrix_batch(
    mean: np.ndarray,
    rate: np.ndarray,
    motor_index: np.ndarray,
    pose: np.ndarray,
    mean_std: np.ndarray,
    rate_std: np.ndarray,
    rest_mean: np.ndarray,
    rest_std: np.ndarray,
    *,
    n_servos: int | None = None,
    reference: np.ndarray | None = None,
    ref_matrix: np.ndarray | None = None,
    still_std: float = 0.0,
    pose_still: np.ndarray | None = None,
    force: np.ndarray | None = None,
    rest_force: np.ndarray | None = None,
    max_iter: int = 50,
    xtol: float = 1e-12,
    hold: tuple[np.ndarray, np.ndarray] | None = None,
) -> FullMatrixBatch:
    r"""The full-matrix fit for ``B`` runs at once (vectorised); model in :func:`fit_full_matrix`.

    Parameters
    ----------
    mean : ndarray, shape (B, n, 3)
        Window mean readings.
    rate : ndarray, shape (B, n)
        Signed reference rates of the turning servo.
    motor_index : ndarray of int, shape (n,)
        Turning servo of each window as its position in the chain (base = 0).
    pose : ndarray, shape (n, S) or (B, n, S)
        Every servo's encoder angle over each window, chain order, rad.
    mean_std, rate_std, rest_mean, rest_std, still_std, max_iter :
        As in :func:`paired_axis_batch`.
    ref_matrix : ndarray, shape (n, A) or (B, n, A), optional
        As in :func:`paired_axis_batch`, shared by every run or one per run; its ``A`` columns
        are every still angle, those the poses rest on included.
    pose_still : ndarray of int, shape (n, S), optional
        The still angle (column of ``ref_matrix``) each held servo's pose rests on, -1 where the
        pose is exact (:attr:`ObservationSet.pose_still`): its reading error is the same shared
        unknown, so a servo's sub-tick hold error tilts every axis outside it consistently.
    n_servos : int, optional
        Servos in the chain (default: ``pose.shape[-1]``).
    reference : ndarray, shape (S,), optional
        Reference angles of the returned axes (default: the first window's pose).
    force, rest_force : ndarray, shape (B, n, k) and (B, r, k), optional
        The mean specific force of each window and rest, g (sensor frame, or its coordinates
        along ``k`` directions: :meth:`ObservationSet.specific_force`). Given, the model gains
        g-sensitivity, ``E[m̄] = ω C u − b − G f`` (``3k`` more parameters, ``G`` row-major,
        after the still angles).
    xtol : float
        Convergence threshold on the largest parameter step.
    hold : (ndarray (B, 6), ndarray (B, 3)), optional
        The lower triangle of ``C = A⁻¹`` (row-major) and the biases to hold
        (:func:`residuals_at`): only the joint axes, the still angles' errors and ``G`` are
        fitted.

    Returns
    -------
    FullMatrixBatch
    """
    B, n, _ = mean.shape
    r = rest_mean.shape[1]
    pose = np.asarray(pose, dtype=float)
    S = int(n_servos if n_servos is not None else pose.shape[-1])
    midx = np.asarray(motor_index, dtype=np.int64)
    ref = pose.reshape(-1, n, S)[0, 0] if reference is None else np.asarray(reference, float)
    delta = np.broadcast_to(pose - ref, (B, n, S))
    G = np.zeros((n, 0)) if ref_matrix is None else np.asarray(ref_matrix, dtype=float)
    G = np.broadcast_to(G, (B,) + G.shape[-2:])  # one per run, or shared
    n_still = G.shape[-1]
    if n_still and not still_std > 0:
        raise CalibInputError("still_std must be positive when ref_matrix has still angles")
    nk = 0 if force is None else np.shape(force)[-1]
    nG = 3 * nk
    f_win = np.zeros((B, n, 0)) if force is None else np.broadcast_to(force, (B, n, nk))
    f_rest = np.zeros((B, r, 0)) if rest_force is None else np.broadcast_to(rest_force, (B, r, nk))
    P0 = 9 + 2 * S + n_still
    P = P0 + nG
    c, b, u0 = _full_initial(mean, rate, midx, delta, S, rest_mean, rest_std, mean_std)
    if hold is not None:
        c = np.broadcast_to(np.asarray(hold[0], dtype=float), (B, 6)).copy()
        b = np.broadcast_to(np.asarray(hold[1], dtype=float), (B, 3)).copy()
    z = np.zeros((B, n_still))
    gs = np.zeros((B, 3, nk))
    var_m = mean_std**2
    var_w = rate_std[:, :, None, None] ** 2
    eye3 = np.eye(3)
    ar = np.arange(n)
    ps = np.full((n, S), -1, dtype=np.int64) if pose_still is None else np.asarray(pose_still)
    held = ps >= 0
    if np.any(held) and not (still_std > 0 and ps.max() < n_still):
        raise CalibInputError("pose_still needs still_std > 0 and indices below ref_matrix's "
                              "column count")

    def true_delta(z: np.ndarray) -> np.ndarray:
        """The poses less their still angles' reading errors (reading − true)."""
        if not np.any(held):
            return delta
        zp = np.where(held, z[:, np.where(held, ps, 0)], 0.0)  # (B, n, S)
        return delta - zp

    def axes_in_windows(u: np.ndarray, d: np.ndarray) -> np.ndarray:
        return kinematics.chain_axes(u[:, None], 0.0, d)[:, ar, midx]  # (B, n, 3)

    def window_chol(ci: np.ndarray) -> np.ndarray:
        """Each window's noise ``diag(σ²) + σ²_ω c cᵀ`` (``c = C u``), factored."""
        return np.linalg.cholesky(var_m[..., None] * eye3 + var_w * ci[..., :, None]
                                  * ci[..., None, :])

    def evaluate(c, b, u, z, gs, with_jac):
        C = _tril(c)
        d = true_delta(z)
        ui = axes_in_windows(u, d)
        ci = np.einsum("bpq,bnq->bnp", C, ui)
        w = (rate - np.einsum("bna,ba->bn", G, z))[:, :, None]
        e = mean - (w * ci - b[:, None, :] - np.einsum("bpq,bnq->bnp", gs, f_win))
        L = window_chol(ci)
        ew = np.linalg.solve(L, e[..., None])[..., 0]
        er = (rest_mean + b[:, None, :] + np.einsum("bpq,brq->brp", gs, f_rest)) / rest_std
        ez = z / still_std if n_still else z
        E = np.concatenate([ew.reshape(B, 3 * n), er.reshape(B, 3 * r), ez], axis=1)
        if not with_jac:
            return E, None, None
        t1, t2 = _tangent_basis(u)
        J = np.zeros((B, n, 3, P))
        for col, (p, q) in enumerate(zip(*_TRIL, strict=True)):
            J[:, :, p, col] = -w[..., 0] * ui[..., q]
        J[:, :, np.arange(3), 6 + np.arange(3)] = 1.0
        for p in range(3 if nG else 0):  # d e_p / d G_pq = f_q
            J[:, :, p, P0 + nk * p : P0 + nk * p + nk] = f_win
        for t_i, t in enumerate((t1, t2)):  # axis directions along the tangent basis, exact
            du = kinematics.axis_derivatives(u, d, midx, t)  # (B, n, S, 3)
            J[:, :, :, 9 + t_i : 9 + 2 * S : 2] = -w[..., None] * np.einsum(
                "bpq,bnsq->bnps", C, du)
        if n_still:
            J[:, :, :, 9 + 2 * S : P0] = ci[..., None] * G[:, :, None, :]
        dUs = kinematics.pose_derivatives(u, d, midx) if np.any(held) else None
        for k in np.flatnonzero(held.any(axis=0)):  # held poses: d e / d z = w C dU/dΔ_k
            contrib = w * np.einsum("bpq,bnq->bnp", C, dUs[:, :, k])  # (B, n, 3)
            for i in np.flatnonzero(held[:, k]):
                J[:, i, :, 9 + 2 * S + ps[i, k]] += contrib[:, i]
        Jw = np.linalg.solve(L, J).reshape(B, 3 * n, P)
        Jr = np.zeros((B, r, 3, P))
        Jr[:, :, np.arange(3), 6 + np.arange(3)] = 1.0 / rest_std
        for p in range(3 if nG else 0):
            Jr[:, :, p, P0 + nk * p : P0 + nk * p + nk] = f_rest / rest_std[:, :, p : p + 1]
        Jz = np.zeros((B, n_still, P))
        if n_still:
            Jz[:, np.arange(n_still), 9 + 2 * S + np.arange(n_still)] = 1.0 / still_std
        return E, np.concatenate([Jw, Jr.reshape(B, 3 * r, P), Jz], axis=1), (t1, t2)

    def retract(state, step, tb):
        c, b, u, z, gs = state
        t1, t2 = tb
        da = step[:, 9 : 9 + 2 * S : 2][..., None]
        db = step[:, 10 : 9 + 2 * S : 2][..., None]
        u_new = u + da * t1 + db * t2
        u_new /= np.linalg.norm(u_new, axis=2, keepdims=True)
        c_new = c + step[:, :6]
        ok = np.all(c_new[:, [0, 2, 5]] > 0, axis=1)  # the diagonal stays positive
        z_new = z + step[:, 9 + 2 * S : P0]
        u_new, z_new = _still_gauge(u_new, z_new, owner, movable)
        gs_new = gs + step[:, P0:].reshape(B, 3, nk) if nG else gs
        return (c_new, b + step[:, 6:9], u_new, z_new, gs_new), ok

    owner = _still_owner(G, ps, midx, n_still)
    movable = _gauge_servos(owner, ps, midx, S, G)
    state, E, J, iterations, converged = _lm_batch(
        _holding(evaluate, 9 if hold is not None else 0), retract, (c, b, u0, z, gs),
        max_iter=max_iter, xtol=xtol)
    c, b, u0, z, gs = state
    JtJ = J.transpose(0, 2, 1) @ J
    cov = _scaled_pinv(JtJ)
    # Observability of the model terms (C, b, axes) by the singular values of the whitened
    # Jacobian with its columns normalised (the still angles always have their priors).
    Jm = J[:, :, : 9 + 2 * S]
    Jn = Jm / np.maximum(np.linalg.norm(Jm, axis=1, keepdims=True), 1e-300)
    sv = np.linalg.svd(Jn, compute_uv=False)
    deficiency = np.sum(sv < 1e-7 * sv[:, :1], axis=1)
    C = _tril(c)
    A = np.linalg.inv(C)
    # d vec(A) / d c: dA = −A dC A; then the bias.
    T = np.zeros((B, 12, P))
    for col, (p, q) in enumerate(zip(*_TRIL, strict=True)):
        T[:, :9, col] = -(A[:, :, p, None] * A[:, None, q, :]).reshape(B, 9)
    T[:, 9:, 6:9] = eye3
    cov12 = T @ cov @ T.transpose(0, 2, 1)
    ci = np.einsum("bpq,bnq->bnp", _tril(c), axes_in_windows(u0, true_delta(z)))
    gain = T @ _mean_gain(cov, J, window_chol(ci), rest_std)
    ax_std = np.zeros((B, S))
    for s in range(S):
        blk = cov[:, 9 + 2 * s : 11 + 2 * s, 9 + 2 * s : 11 + 2 * s]
        ax_std[:, s] = np.sqrt(np.clip(np.linalg.eigvalsh(blk)[:, -1], 0.0, None))
    return FullMatrixBatch(
        matrix=A, bias=b, axes=u0, axes_std_rad=ax_std, covariance=cov12,
        chi2=np.sum(E**2, axis=1), dof=3 * n + 3 * r + n_still - P, iterations=iterations,
        converged=converged, residuals=E, rank_deficiency=deficiency,
        g_sensitivity=gs if nG else None, g_covariance=cov[:, P0:, P0:] if nG else None,
        g_cross_covariance=T @ cov[:, :, P0:] if nG else None,
        mean_gain=gain,
    )


def _scaled_damped_step(JtJ: np.ndarray, g: np.ndarray, lam: np.ndarray) -> np.ndarray:
    """Marquardt's step ``−(JᵀJ + λ diag JᵀJ)⁻¹ Jᵀe`` solved in unit-column scaling.

    With ``s = sqrt(diag JᵀJ)`` the system is ``(S⁻¹JᵀJS⁻¹ + λ I)(S step) = −S⁻¹Jᵀe``: the same
    step, but the matrix has a unit diagonal: unscaled, its condition number carries the square
    of the columns' spread (window means whitened by σ ≈ 1e-10 next to still angles with a
    4e-4 rad prior), which costs the solve digits it does not need to lose. (The full-matrix
    fit's stall at tiny noise had another cause: :func:`_still_gauge`.) A diagonal entry no
    residual sees is floored at 1e-300 so it is still damped (Moré 1978, "The
    Levenberg-Marquardt algorithm: implementation and theory", §3 on scaling).
    """
    s = np.sqrt(np.maximum(np.einsum("bpp->bp", JtJ), 1e-300))
    Ms = JtJ / (s[:, :, None] * s[:, None, :])
    Ms = Ms + lam[:, None, None] * np.eye(JtJ.shape[-1])
    return -np.linalg.solve(Ms, (g / s)[..., None])[..., 0] / s


def _scaled_pinv(JtJ: np.ndarray) -> np.ndarray:
    """``(JᵀJ)⁺`` computed in unit-column scaling (see :func:`_scaled_damped_step`), so that the
    pseudo-inverse's cut-off acts on the design's real degeneracies and not on the units of its
    columns; columns no residual sees stay zero."""
    d = np.einsum("bpp->bp", JtJ)
    s = np.where(d > 0, np.sqrt(np.where(d > 0, d, 1.0)), 1.0)
    inv = np.linalg.pinv(JtJ / (s[:, :, None] * s[:, None, :]), hermitian=True)
    return inv / (s[:, :, None] * s[:, None, :])


def _holding(evaluate, n_held: int):  # type: ignore[no-untyped-def]
    """``evaluate`` of :func:`_lm_batch` with the Jacobian's first ``n_held`` columns zeroed:
    the step of a parameter no residual sees is zero (:func:`_scaled_damped_step`), so those
    parameters stay where they started (a fit with the model held, :func:`residuals_at`)."""
    if not n_held:
        return evaluate

    def held(*args):  # type: ignore[no-untyped-def]
        E, J, tb = evaluate(*args)
        if J is not None:
            J[..., :n_held] = 0.0
        return E, J, tb

    return held


def _lm_batch(evaluate, retract, state, *, max_iter: int, xtol: float,  # type: ignore[no-untyped-def]
              step_scale=None):
    """Levenberg-Marquardt over a batch of independent problems (the paired-axis and the
    full-matrix fits).

    ``evaluate(*state, with_jac)`` returns whitened residuals ``E`` (B, M), their Jacobian
    (B, M, P) and a tangent basis for ``retract``; ``retract(state, step, tb)`` returns the
    stepped state and which runs' steps are admissible. Marquardt's damping scales the
    diagonal of ``JᵀJ`` (floored at 1e-300 so a parameter no residual sees still gets damped).
    A run has converged when an admissible step is below ``xtol`` (times
    ``step_scale(state)``, per run, when given), changes the cost by less than ``1e-10``
    relative, up or down (rounding level), or is predicted to lower it by under 1e-6.
    """
    E, J, tb = evaluate(*state, True)
    B, _, P = J.shape
    cost = np.sum(E**2, axis=1)
    lam = np.full(B, 1e-3)
    active = np.ones(B, dtype=bool)
    iterations = np.zeros(B, dtype=np.int64)
    converged = np.zeros(B, dtype=bool)

    def pick(mask, new, old):
        return tuple(np.where(mask.reshape((-1,) + (1,) * (o.ndim - 1)), nw, o)
                     for nw, o in zip(new, old, strict=True))

    for _ in range(int(max_iter)):
        if not active.any():
            break
        Jt = J.transpose(0, 2, 1)
        JtJ = Jt @ J
        g = (Jt @ E[..., None])[..., 0]
        step = _scaled_damped_step(JtJ, g, lam)
        new_state, ok = retract(state, step, tb)
        E_new, _, _ = evaluate(*new_state, False)
        cost_new = np.sum(E_new**2, axis=1)
        accept = active & ok & (cost_new <= cost)
        iterations += active
        tol = xtol if step_scale is None else xtol * step_scale(state)
        small = np.max(np.abs(step), axis=1) <= tol
        flat = np.abs(cost - cost_new) <= 1e-10 * (1.0 + cost)
        # The step's predicted decrease of the whitened cost (a χ²): below 1e-6 it moves every
        # parameter by under a thousandth of its σ, while rounding in residuals whitened by
        # σ ≈ 1e-10 already makes the cost itself jitter by more than 1e-10 relative.
        Js = J @ step[..., None]
        predicted = -(np.einsum("bp,bp->b", g, step) + 0.5 * np.sum(Js[..., 0] ** 2, axis=1))
        flat |= predicted <= 1e-6
        state = pick(accept, new_state, state)
        lam = np.where(accept, np.maximum(lam / 3.0, 1e-12), np.minimum(lam * 4.0, 1e12))
        done = active & ok & (small | flat)
        converged |= done
        active &= ~done
        if accept.any():
            E_acc, J_acc, tb_acc = evaluate(*state, True)
            E = np.where(accept[:, None], E_acc, E)
            J = np.where(accept[:, None, None], J_acc, J)
            tb = pick(accept, tb_acc, tb)
            cost = np.sum(E**2, axis=1)
    E, J, _ = evaluate(*state, True)
    return state, E, J, iterations, converged


#: Largest one-sigma uncertainty of g-sensitivity along a direction of gravity for that
#: direction to be fitted, rad/s per g: the MPU-9250's typical 0.1 °/s/g (PS §3.1). Along a
#: direction the run sees less well, a typical ``G`` moves the windows by less than their noise
#: (it adds about 1 to χ² per axis), so it is left in the bias rather than fitted as noise.
MAX_G_STD = 1.75e-3


def fit_full_matrix(
    obs: ObservationSet, *, max_iter: int = 50, g_sensitivity: bool = True,
    max_g_std: float = MAX_G_STD, hold: tuple[np.ndarray, np.ndarray] | None = None,
) -> FitResult:
    r"""Full-matrix fit: ``g = A (m + b)`` with ``A`` a full 3×3 matrix, from a posed protocol.

    Model (derived in ``hardware_docs/method.md``): a window of servo ``s`` at signed reference
    rate ``ω_i``, with every servo of the chain at the encoder angles ``θ_i`` (``obs.pose``),
    reads

    .. math:: E[\bar m_i] = ω_i\, C\, u_s(θ_i) − b, \qquad C = A^{-1},

    where ``u_s(θ)`` is the servo's axis carried into the sensor frame by the servos inside it
    (:func:`gyrocal.calib.kinematics.chain_axes`), and a rest reads ``E[\bar m_r] = −b``. The
    joint axes at the reference pose are nuisance parameters (two angles each; nothing assumes the
    gimbal square). The global rotation of the sensor frame is not observable; it is fixed by
    :data:`FULL_FRAME` (``C`` and hence ``A`` lower triangular, positive diagonal). Residuals are
    whitened by each window's covariance ``diag(σ²_ij) + σ²_{ω,i} (C u)(C u)ᵀ``, each still
    encoder angle a reference rests on or a held servo's pose reads (``obs.pose_still``) is a
    shared unknown with its quantisation as prior (as in :func:`fit_paired_axis`), and the sum of
    squares is minimised by Levenberg-Marquardt.
    Covariance ``(J̃ᵀJ̃)⁻¹`` propagated to ``A`` by ``dA = −A dC A``; consistency
    ``Σẽ² ~ χ²(3n + 3r − 9 − 2S)``.

    Parameters
    ----------
    obs : ObservationSet
        With ``chain`` and ``pose``: windows of every servo in both directions, in poses that make
        the model observable (a servo turned with the servos inside it at two or more angles),
        and rest windows.
    max_iter : int
        Most Levenberg-Marquardt steps.
    g_sensitivity : bool
        When ``obs`` says where gravity points (:attr:`ObservationSet.has_gravity`), fit
        ``g = A (m + b + G f)`` (``hardware_docs/method.md`` §10): ``f`` each window's mean
        specific force from the poses and the fitted gimbal
        (:meth:`ObservationSet.specific_force`), ``E[m̄] = ω C u − b − G f``; ``G`` along the
        directions :func:`gravity_directions` finds determined, ``b`` the zero-g bias.
    max_g_std : float
        Largest one-sigma uncertainty of ``G`` along a direction for it to be fitted
        (:data:`MAX_G_STD`).
    hold : (ndarray (6,), ndarray (3,)), optional
        The lower triangle of ``C = A⁻¹`` (row-major, frame :data:`FULL_FRAME`) and the biases
        to hold instead of fitting (:func:`residuals_at`).

    Returns
    -------
    FitResult
        ``method`` ``"full-matrix"``, with ``matrix``, ``frame``, ``kinematics`` (and
        ``g_sensitivity``, its 9×9 covariance and ``g_directions`` when fitted); ``scale`` is
        ``diag(A)``, ``covariance`` 12×12 (marginal over ``G``). ``success`` is false with
        status ``not-determined`` when the poses cannot determine the full matrix (the message
        says how far off).

    Raises
    ------
    CalibInputError
        If ``obs`` has no chain and pose, or a servo turned in one direction only.
    """
    _validate_common(obs, "full-matrix", 6)
    if obs.chain is None or obs.pose is None:
        raise CalibInputError(
            "full-matrix needs the gimbal chain and each window's pose (a recording whose "
            "manifest lists the servos in chain order, with their encoder angles)")
    never = [m for m in obs.chain if m not in obs.motors]
    if never:
        raise CalibInputError(
            f"servos {never} of the chain never turn; full-matrix needs a turn of every servo "
            "(its axis carries the axes of the servos outside it)")
    obs = obs.with_pooled_noise()

    def run(force: tuple[np.ndarray, np.ndarray] | None) -> FullMatrixBatch:
        return full_matrix_batch(
            obs.mean[None], obs.rate[None], obs.motor_index, obs.pose, obs.mean_std[None],
            obs.rate_std[None], obs.rest_mean[None], obs.rest_mean_std[None],  # type: ignore[index]
            n_servos=len(obs.chain), ref_matrix=obs.reference_matrix(),  # type: ignore[arg-type]
            still_std=obs.still_angle_std, pose_still=obs.pose_still, max_iter=max_iter,
            force=None if force is None else force[0][None],
            rest_force=None if force is None else force[1][None],
            hold=None if hold is None else (hold[0][None], hold[1][None]),
        )

    res = run(None)
    g_note = ""
    basis = np.zeros((3, 0))
    if g_sensitivity and obs.has_gravity:
        # The specific force comes from the poses and the fitted axes, so fit once without it,
        # then with the forces of the last fit's gimbal until its axes settle (G moves them by
        # far less than their uncertainty: one or two passes).
        for _ in range(4):
            force = obs.specific_force(res.axes[0], obs.pose[0])
            basis = gravity_directions(*force, obs.mean_std, obs.rest_mean_std,  # type: ignore[arg-type]
                                       max_std=max_g_std)
            if not basis.shape[1]:
                break
            new = run((force[0] @ basis, force[1] @ basis))
            moved = float(np.max(np.linalg.norm(new.axes[0] - res.axes[0], axis=-1)))
            res = new
            if moved < 1e-10:
                break
        if basis.shape[1] < 3:
            g_note = (f"; g-sensitivity fitted along {basis.shape[1]} of 3 directions of "
                      "gravity (the others are in the bias): rest in more orientations")
    elif g_sensitivity and obs.force is not None:
        # the specific force is measured (the single-servo jig's seats: ObservationSet.by_seat)
        basis = gravity_directions(obs.force, obs.rest_force, obs.mean_std,  # type: ignore[arg-type]
                                   obs.rest_mean_std, max_std=max_g_std)  # type: ignore[arg-type]
        if basis.shape[1]:
            res = run((obs.force @ basis, obs.rest_force @ basis))  # type: ignore[operator]
        if basis.shape[1] < 3:
            g_note = (f"; g-sensitivity fitted along {basis.shape[1]} of 3 directions of "
                      "gravity (the others are in the bias): seat the cube in more orientations")
    A, b, cov = res.matrix[0], res.bias[0], res.covariance[0]
    consistency, factor = None, 1.0
    if res.dof > 0:
        verdict = _judged(res.residuals[0], res.dof, obs)
        consistency, factor = verdict.consistency, verdict.factor
        cov = cov * factor
    it = int(res.iterations[0])
    deficiency = int(res.rank_deficiency[0])
    determined = deficiency == 0 and bool(np.all(np.isfinite(res.covariance[0])))
    ok = bool(res.converged[0]) and bool(np.all(np.isfinite(A))) and determined
    if not determined:
        status = "not-determined"
        what = (f"{deficiency} combination(s)" if deficiency else "a combination (its "
                "uncertainty is not finite)")
        message = (
            f"the poses leave {what} of the matrix and the servo axes "
            "undetermined: turn outer servos with the servos inside them at other angles "
            "(two posed pairs of turns at least; hardware_docs/method.md, observability)")
    elif ok:
        status, message = "converged", f"converged in {it} steps{g_note}"
    else:
        status, message = "max-iterations", f"no convergence in {max_iter} steps"
    ref = obs.pose[0]
    kin = {
        "chain": list(obs.chain),
        "axes": [[float(x) for x in u] for u in res.axes[0]],
        "reference_angles_rad": [float(x) for x in ref],
    }
    if obs.gravity is not None and obs.home_pose is not None:  # the home pose "up" refers to
        kin["home_angles_rad"] = [float(x) for x in obs.home_pose]
        kin["up_servo"] = [int(obs.gravity[0]), int(obs.gravity[1])]
    return FitResult(
        method="full-matrix",
        scale=np.diag(A).copy(),
        bias=b.copy(),
        covariance=cov.copy(),
        iterations=it,
        success=ok,
        status=status,
        message=message,
        consistency=consistency,
        residuals=res.residuals[0].copy(),
        axes={m: res.axes[0, i].copy() for i, m in enumerate(obs.chain)},
        axes_std_rad={m: float(res.axes_std_rad[0, i]) for i, m in enumerate(obs.chain)},
        matrix=A.copy(),
        frame=FULL_FRAME,
        kinematics=kin,
        mean_gain=res.mean_gain[0] * np.sqrt(factor),  # type: ignore[index]
        **_g_terms(res, basis, factor),
    )


def _g_terms(res: FullMatrixBatch | PairedAxisBatch, basis: np.ndarray,
             factor: float = 1.0) -> dict[str, Any]:
    """``G`` (3×3) and its 9×9 covariance from the fit's ``G_k`` along ``basis`` (3, k):
    ``G = G_k Vᵀ``, ``d vec(G) / d vec(G_k) = I₃ ⊗ V``; the covariance times the verdict's
    variance ``factor``."""
    if res.g_sensitivity is None:
        return {}
    T = np.kron(np.eye(3), basis)
    return {"g_sensitivity": res.g_sensitivity[0] @ basis.T,
            "g_sensitivity_cov": factor * T @ res.g_covariance[0] @ T.T,  # type: ignore[index]
            "g_directions": basis.T.copy()}


def gravity_directions(force: np.ndarray, rest_force: np.ndarray, mean_std: np.ndarray,
                       rest_std: np.ndarray, *, max_std: float = MAX_G_STD) -> np.ndarray:
    """The directions of specific force along which a run determines g-sensitivity.

    A window's offset is ``b + G f``: ``G`` is seen only through how ``f`` varies between the
    windows and rests, so the weighted scatter of ``f`` about its weighted mean,
    ``M = Σ wᵢ (fᵢ − f̄)(fᵢ − f̄)ᵀ`` (``wᵢ = 1/σᵢ²`` of the window's best axis), is the information
    each row of ``G`` gets (with ``b`` free). Its eigenvectors whose ``1/√λ`` is at most
    ``max_std`` are returned; along the others ``G`` stays in the bias. All three need gravity
    in three independent directions (rests in three non-coplanar orientations, or two and the
    horizontal turns' zero mean force).

    Parameters
    ----------
    force, rest_force : ndarray, shape (n, 3) and (r, 3)
        Mean specific force per window and rest, g.
    mean_std, rest_std : ndarray, shape (n, 3) and (r, 3)
        Standard errors of the window and rest means, rad/s.
    max_std : float
        Largest predicted one-sigma uncertainty of a fitted direction, rad/s per g.

    Returns
    -------
    ndarray, shape (3, k)
        Orthonormal columns, ``k`` in 0..3, best determined first.
    """
    f = np.concatenate([force, rest_force])
    w = 1.0 / np.min(np.concatenate([mean_std, rest_std]), axis=1) ** 2
    fc = f - (w @ f) / w.sum()
    lam, V = np.linalg.eigh((fc * w[:, None]).T @ fc)
    keep = lam > 1.0 / max_std**2
    return V[:, keep][:, ::-1]


METHODS["full-matrix"] = fit_full_matrix


@dataclass(frozen=True, eq=False)
class ModelResiduals:
    """The whitened residuals of the paired-axis or full-matrix fit (:func:`residuals_at`), in
    the fits' layout: ``Σ`` of their squares is the fit's χ².

    Attributes
    ----------
    windows : ndarray (n, 3)
        Each rotation window's ``L⁻¹ (m̄ − E[m̄])``, ``L`` the Cholesky factor of its
        covariance ``diag(σ²) + σ²_ω (C u)(C u)ᵀ`` (its first component is the x residual over
        its σ; the next ones are what each adds beyond those before it).
    rests : ndarray (r, 3)
        Each rest window's ``(m̄ + b + G f) / σ``.
    stills : ndarray (a,)
        Each still angle's fitted error over its prior σ (an encoder's hold within its tick; the
        hand jig's return to the stop, :data:`gyrocal.calib.hand.STOP_STD_RAD`): windows that
        share a still angle share its error, which the fit estimates.
    method : str
        The fit whose model they are: ``paired-axis`` or ``full-matrix``.
    """

    windows: np.ndarray
    rests: np.ndarray
    stills: np.ndarray
    method: str

    @property
    def chi2(self) -> float:
        """The sum of the squared residuals."""
        return float(np.sum(self.windows**2) + np.sum(self.rests**2) + np.sum(self.stills**2))


def residuals_at(obs: ObservationSet, bias: np.ndarray, *, scale: np.ndarray | None = None,
                 matrix: np.ndarray | None = None) -> ModelResiduals:
    """The fit's own residuals at a calibration's scale (or matrix) and bias: the paired-axis
    fit (:func:`fit_paired_axis`; the full-matrix one, :func:`fit_full_matrix`, for a
    ``matrix``) run with the model held, so that only what the calibration does not carry is
    fitted: the turn axes, each still angle's error and the g-sensitivity where the fit
    would take it. At the parameters the fit found on these observations the fit's own
    optimum is the held one's, so the sum of their squares is the fit's χ²; at another
    calibration's they show where it disagrees with this run.

    Parameters
    ----------
    obs : ObservationSet
        The observations as the fit saw them (``gyrocal.kit.pipeline.judged_windows``).
    bias : ndarray (3,)
    scale : ndarray (3,), optional
        The diagonal model's scale factors (paper Eq. 1); one of ``scale`` and ``matrix``.
    matrix : ndarray (3, 3), optional
        The full model's ``A``, in any output frame (the residuals do not depend on it: the
        matrix is taken into :data:`FULL_FRAME` by :func:`matrix_in_frame`).

    Returns
    -------
    ModelResiduals

    Raises
    ------
    CalibInputError
        As the fit raises for ``obs``, or when neither or both of ``scale`` and ``matrix``.
    """
    if (scale is None) == (matrix is None):
        raise CalibInputError("residuals_at needs the scale factors or the matrix, not both")
    b = np.asarray(bias, dtype=float)
    if matrix is None:
        fit = fit_paired_axis(obs, hold=(np.asarray(scale, dtype=float), b))
    else:
        C = np.linalg.inv(matrix_in_frame(np.linalg.inv(np.asarray(matrix, dtype=float))))
        fit = fit_full_matrix(obs, hold=(C[_TRIL], b))
    n, r = obs.n_windows, obs.n_rests if obs.rest_mean is not None else 0
    e = fit.residuals
    return ModelResiduals(e[:3 * n].reshape(n, 3), e[3 * n:3 * (n + r)].reshape(r, 3),
                          e[3 * (n + r):], fit.method)
