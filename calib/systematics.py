r"""What the jig's mount wobble does to the full matrix, added to its covariance.

Each link of the gimbal may nod once per revolution: joint ``k``'s link is tilted by
``ψ_k = ε sin(θ_k + φ_k)`` about an axis ``e_k ⊥ a_k`` fixed to the link (``ε`` the jig's
tolerance, ``φ_k`` and the direction of ``e_k`` unknown). Over a turn of joint ``k`` itself the
nod averages out (whole revolutions: :mod:`gyrocal.calib.windows`), but a joint *parked* at an
angle tilts everything outside it by a fixed ``ψ_k`` for the whole posed turn: the axis of a
turning servo ``s`` outside ``k`` (``s < k`` in chain order) is seen in the sensor frame turned
by ``−ψ_k e_k`` (the sensor is inside the tilted link), ``δu_s = ψ_k (u_s × e_k)``, and the
window reads ``δm̄ = ω C δu_s``. The fit, whose kinematics are rigid, takes that for a change
of ``A``: on a geometry where a posed turn carries the off-diagonal terms, by several of their
σ (emulated seed 106: ``A[2,1]`` off by −4.5 σ of the white noise, −2.3 σ of it the
emulator's own nod as propagated here; with the nod's term added to the covariance, −2.6 σ;
with the windows' noise also read without the servo's ripple, the run's largest matrix
``|err/σ|`` is 2.56, ``A[2,1]`` −0.038989 ± 6.0e-4: ``gyrocal calibrate --sim --sim-seed 106``).

With ``e_k = cos β p₁ + sin β p₂`` (``p₁, p₂`` a basis ⊥ ``u_k`` fixed to link ``k``, carried
into the sensor frame like ``u_k``) and ``sin(θ + φ) = sin θ cos φ + cos θ sin φ`` about the
reference angles, the tilt is a sum of four terms ``ε c_q f_q(θ) p_q`` per joint whose
coefficients ``c_q`` (``cos β cos φ``, …) are uncorrelated with variance ``1/4`` each for
``β, φ`` uniform. The fit is linear in so small a change of its data, so each term's effect
``d_q`` on ``(A row-major, b)`` is found by refitting the windows with that term added (every
term at once, :func:`~gyrocal.calib.estimators.full_matrix_batch`), and the wobble adds

    Σ_wobble = (1/4) Σ_q d_q d_qᵀ

to the fit's covariance (:func:`add_wobble`).

The DLPF's group delay ``τ`` is not added: a window's gyro mean over a delayed rate differs
from the encoder's by ``−τ ∫ ẇ ω dt / ∫ w``, and the windows' weight ``w`` ramps only where the
rate is steady (tapered windows) or zero (rest to rest). Measured on emulated seed 106's ten
windows (the encoder's reference with the corners moved by the MPU-9250's 3.9 ms,
``calib.windows.window_rate``, every servo): at most 6e-5 rad/s on the turning axis, 2e-5 of
the rate, and exactly 0 on the others (no other servo moves inside a window).

Turning the emulator's DLPF off on that seed moved ``A[2,1]`` by 4.4e-4 (1.2 σ of the white
noise). That is not the filter acting on the turn: the emulated chip draws its white noise at
the filter's input, ``D`` internal samples per output sample (``_internal_per_output``: 5 for
the MPU-9250's 1 kHz ahead of 200 Hz, 1 without the filter), so with the filter off the same
noise seed draws another realisation of the noise, and every parameter moves by its noise.
On tuning seed 1019 (``gyrocal calibrate --sim --sim-seed 1019`` with and without
``--sim-without dlpf``) the twelve parameters move by −0.78 … +1.11 of their σ, none beyond
what a partly new draw of the noise gives, ``A[2,1]`` by 4.7e-4 (0.78 σ). The filter is
therefore bounded, not modelled: with the wobble term above and the windows' noise read
without the servo's speed ripple (:func:`gyrocal.calib.windows._noise_beside_motion`), the
matrix's 95 % intervals hold the truth 97.8 % (diagonal) and 95.6 % (off-diagonal) of the
time over emulated seeds 1000–1029, the DLPF on, so no term for it is added.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from gyrocal.calib.estimators import FitResult, full_matrix_batch
from gyrocal.calib.kinematics import rotate
from gyrocal.calib.observations import ObservationSet

__all__ = ["add_wobble", "wobble_effects"]


def _basis(u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors perpendicular to ``u`` and to each other."""
    a = np.eye(3)[int(np.argmin(np.abs(u)))]
    p1 = np.cross(u, a)
    p1 /= np.linalg.norm(p1)
    return p1, np.cross(u, p1)


def _carried(axes0: np.ndarray, delta: np.ndarray, k: int, v: np.ndarray) -> np.ndarray:
    """A vector fixed to link ``k`` (``v`` at the reference angles) in the sensor frame at
    angles ``reference + delta`` (n, S): turned by every joint inside ``k``, innermost last
    (:func:`gyrocal.calib.kinematics.chain_axes`' convention, ``Rot(u_j⁰, −Δ_j)``)."""
    out = np.broadcast_to(v, (delta.shape[0], 3)).copy()
    for j in range(k + 1, axes0.shape[0]):
        out = rotate(axes0[j], -delta[:, j], out)
    return out


def wobble_effects(obs: ObservationSet, fit: FitResult, wobble_rad: float) -> np.ndarray:
    """Each wobble term's effect on ``(A row-major, b)`` (module docstring), ``(Q, 12)``.

    Parameters
    ----------
    obs : ObservationSet
        The windows ``fit`` was made from (with ``chain`` and ``pose``).
    fit : FitResult
        A full-matrix fit (``matrix`` and ``kinematics`` set).
    wobble_rad : float
        ``ε``, the largest tilt of a link, rad.

    Returns
    -------
    numpy.ndarray
        ``d_q`` for the four terms of each joint that has a joint outside it; empty (0, 12)
        when ``ε`` is 0 or nothing is posed.
    """
    kin = fit.kinematics or {}
    if wobble_rad <= 0 or fit.matrix is None or obs.pose is None or "axes" not in kin:
        return np.zeros((0, 12))
    axes0 = np.asarray(kin["axes"], dtype=float)
    ref = np.asarray(kin["reference_angles_rad"], dtype=float)
    C = np.linalg.inv(fit.matrix)
    obs = obs.with_pooled_noise()
    idx = np.asarray(obs.motor_index)
    delta = np.asarray(obs.pose, dtype=float) - ref
    u_turn = np.stack([_carried(axes0, delta, s, axes0[s])[i] for i, s in enumerate(idx)])
    shifts = []
    for k in range(1, axes0.shape[0]):
        outside = (idx < k)[:, None]
        for p in _basis(axes0[k]):
            pk = _carried(axes0, delta, k, p)
            for f in (np.sin, np.cos):
                tilt = wobble_rad * f(delta[:, k])[:, None] * pk
                du = np.cross(u_turn, tilt) * outside  # the outer axis turned by −ψ e
                shifts.append(np.asarray(obs.rate)[:, None] * (du @ C.T))
    if not shifts:
        return np.zeros((0, 12))
    res = _refit(obs, fit, np.asarray(shifts))
    A, b = res.matrix, res.bias
    d = np.concatenate([(A[1:] - A[0]).reshape(-1, 9), b[1:] - b[0]], axis=1)
    return d


def _refit(obs: ObservationSet, fit: FitResult, shifts: np.ndarray):  # type: ignore[no-untyped-def]
    """The full-matrix fit of the windows as they are (run 0) and with each of ``shifts``
    (Q, n, 3) added to their means, in one batch, with ``fit``'s g-sensitivity directions."""
    B = shifts.shape[0] + 1
    mean = obs.mean[None] + np.concatenate([np.zeros((1, *obs.mean.shape)), shifts])

    def each(x: np.ndarray | None) -> np.ndarray | None:
        return None if x is None else np.broadcast_to(x, (B, *np.shape(x))).copy()

    force = rest_force = None
    if fit.g_directions is not None and len(fit.g_directions):
        axes0 = np.asarray(fit.kinematics["axes"], dtype=float)  # type: ignore[index]
        f, rf = obs.specific_force(axes0, obs.pose[0])  # type: ignore[index]
        basis = np.asarray(fit.g_directions, dtype=float).T
        force, rest_force = each(f @ basis), each(rf @ basis)
    return full_matrix_batch(
        mean, each(obs.rate), obs.motor_index, obs.pose, each(obs.mean_std), each(obs.rate_std),
        each(obs.rest_mean), each(obs.rest_mean_std), n_servos=len(obs.chain),  # type: ignore[arg-type]
        ref_matrix=obs.reference_matrix(), still_std=obs.still_angle_std,
        pose_still=obs.pose_still, force=force, rest_force=rest_force)


def add_wobble(fit: FitResult, obs: ObservationSet, wobble_rad: float) -> FitResult:
    """``fit`` with the mount wobble's covariance ``(1/4) Σ d_q d_qᵀ`` added (module
    docstring); a fit without the full matrix, or ``wobble_rad`` 0, is returned as it is.

    Parameters
    ----------
    fit : FitResult
        The fit of ``obs``.
    obs : ObservationSet
        Its windows.
    wobble_rad : float
        ``ε``, the jig's largest once-per-revolution tilt of a link, rad.
    """
    if fit.matrix is None or not (math.isfinite(wobble_rad) and wobble_rad > 0):
        return fit
    d = wobble_effects(obs, fit, wobble_rad)
    if not d.size:
        return fit
    cov = np.array(fit.covariance, dtype=float)
    cov[:12, :12] += 0.25 * d.T @ d
    return replace(fit, covariance=cov)
