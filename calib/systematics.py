r"""What the jig's mount wobble does to the full matrix: measured and taken out, or bounded.

Each link of the gimbal may nod once per revolution: joint ``k``'s link is tilted by
``ψ_k = ε sin(θ_k + φ_k)`` about an axis ``e_k ⊥ a_k`` fixed to the link (``ε`` the jig's
tolerance, ``φ_k`` and the direction of ``e_k`` unknown). Over a turn of joint ``k`` itself the
nod averages out (whole revolutions: :mod:`gyrocal.calib.windows`), but a joint *parked* at an
angle tilts everything outside it by a fixed ``ψ_k`` for the whole posed turn: the axis of a
turning servo ``s`` outside ``k`` (``s < k`` in chain order) is seen in the sensor frame turned
by ``−ψ_k e_k`` (the sensor is inside the tilted link), ``δu_s = ψ_k (u_s × e_k)``, and the
window reads ``δm̄ = ω C δu_s``. The fit, whose kinematics are rigid, takes that for a change
of ``A``: on a geometry where a posed turn carries the off-diagonal terms, by several of their
σ (emulated seed 106: ``A[2,1]`` off by −4.5 σ of the white noise; the independent
generator's 60° poses with a 0.05° nod, 4.7 σ RMS over the off-diagonal terms of tuning seeds
1000–1018).

**Measured.** The nod shows in the joint's own turns. With the tilt ``T(δ)`` of link ``k`` a
function of its angle ``δ`` (about the reference), the sensor turns at
``θ̇ (u + dT/dδ + u × T)``; for ``T = P sin δ + Q cos δ`` that is
``θ̇ (cos δ X + sin δ u × X)`` with ``X = P + u × Q``: a rate across the axis, once per
revolution, of ``|X| ω`` (4e-3 rad/s for 0.05° at 4.3 rad/s, read to 4e-5 over a turn). The
other part of the first harmonic, ``P − u × Q``, turns against the link and is a fixed tilt of
the joint's axis in the link outside it, which the fit's kinematics already take (each axis is
fitted), and so is the constant; what the fit does not absorb is ``T(δ) = sin δ X/2 −
cos δ (u × X)/2``. So the windows measure each turn's once-per-revolution coefficients of
``θ̇ cos θ`` and ``θ̇ sin θ`` (:attr:`~gyrocal.calib.observations.ObservationSet.nod`),
:func:`measure_nods` fits ``X`` of each joint to its turns across the turning axis (in both
directions: a term of the angle alone, such as gravity turning through the g-sensitivity,
changes sign with the rate relative to the nod), :func:`remove_nod` takes ``T``'s effect
out of the posed windows, and :func:`add_wobble` adds what the measurement's error does.
This holds of any rigid link whose tilt repeats with its servo's angle, whatever its
amplitude, phase or direction (a horn's runout, a bracket's bearing play under a fixed load):
nothing is assumed of ``ε``, and a nod's higher harmonics, which the coverage runs do not
have, are left out. Over the independent generator's seeds 0–199 (``python -m bench coverage
--independent --seeds=200 --walk=2e-6 --flicker=4.8481e-5 --wobble=0.05``) the 95 % intervals
then hold the truth 97.8 % of the time off the diagonal (z RMS 0.90; with the prior, 99.5 % and
0.94) and 96.5 % on it (0.93; 97.5 % and 0.93), with the generator's servos back exactly on
their commanded angles at every rest (now ``--hold-band=0``); with each rest anywhere within
its encoder tick, as a position loop leaves it, 97.2 % (0.95) and 96.0 % (0.97) (94.2 % and
97.0 % on seeds 200–399); with the servos' speed ripple besides (5 % of the speed,
``--ripple=0.05``; both the default since), 96.3 % (0.96) and 96.5 % (0.95) (95.5 % and
97.0 % on seeds 200–399).

**Bounded.** Where a joint's nod is not measured (no pose of the other servos at which it
turned both ways, or a set without the windows' coefficients), ``ε`` of the servo table is a
prior. The default protocol's planner turns each servo's two directions at different angles of
the servos outside it (emulated ``--sim`` seeds 1000–1002: the middle servo's at base angles
π and π/2), so there a term of the angle alone (gravity through the g-sensitivity) cannot be
told from the nod and the prior holds. With
``e_k = cos β p₁ + sin β p₂`` (``p₁, p₂`` a basis ⊥ ``u_k`` fixed to link ``k``, carried
into the sensor frame like ``u_k``) and ``sin(θ + φ) = sin θ cos φ + cos θ sin φ`` about the
reference angles, the tilt is a sum of four terms ``ε c_q f_q(θ) p_q`` per joint whose
coefficients ``c_q`` (``cos β cos φ``, …) are uncorrelated with variance ``1/4`` each for
``β, φ`` uniform. The fit is linear in so small a change of its data, so each term's effect
``d_q`` on ``(A row-major, b)`` is found by refitting the windows with that term added (every
term at once, :func:`~gyrocal.calib.estimators.full_matrix_batch`), and the wobble adds

    Σ_wobble = (1/4) Σ_q d_q d_qᵀ

to the fit's covariance (:func:`add_wobble`). A nod's amplitude is a property of the jig, not
drawn anew each run, so an error it makes is bounded by ``ε``, not Gaussian: over the
independent generator's runs (a 0.05° nod, its direction drawn per run) this prior held the
off-diagonal truth 99.5 % of the time at z RMS 0.94, the reason the nod is measured.

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
from dataclasses import dataclass, replace

import numpy as np

from gyrocal.calib.estimators import FitResult, full_matrix_batch
from gyrocal.calib.kinematics import rotate
from gyrocal.calib.observations import ObservationSet

__all__ = ["Nod", "add_wobble", "measure_nods", "nod_shift", "remove_nod", "wobble_effects"]


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


def _tilt_shifts(obs: ObservationSet, fit: FitResult) -> dict[int, np.ndarray]:
    """Each joint's four unit tilt terms' shifts of the window means, ``{k: (4, n, 3)}``: the
    terms ``f(δ_k) p`` for ``p`` in :func:`_basis` of ``u_k`` and ``f`` in (sin, cos), a tilt of
    1 rad each (module docstring), for every joint ``k`` with a joint outside it."""
    kin = fit.kinematics or {}
    axes0 = np.asarray(kin["axes"], dtype=float)
    ref = np.asarray(kin["reference_angles_rad"], dtype=float)
    C = np.linalg.inv(np.asarray(fit.matrix, dtype=float))
    idx = np.asarray(obs.motor_index)
    delta = np.asarray(obs.pose, dtype=float) - ref
    u_turn = np.stack([_carried(axes0, delta, s, axes0[s])[i] for i, s in enumerate(idx)])
    out = {}
    for k in range(1, axes0.shape[0]):
        outside = (idx < k)[:, None]
        terms = []
        for p in _basis(axes0[k]):
            pk = _carried(axes0, delta, k, p)
            for f in (np.sin, np.cos):
                du = np.cross(u_turn, f(delta[:, k])[:, None] * pk) * outside
                terms.append(np.asarray(obs.rate)[:, None] * (du @ C.T))
        out[k] = np.asarray(terms)
    return out


def _fitted_gimbal(obs: ObservationSet, fit: FitResult) -> bool:
    """Whether ``fit`` is a full-matrix fit of a gimbal whose kinematics carry the tilts."""
    kin = fit.kinematics or {}
    return fit.matrix is not None and obs.pose is not None and "axes" in kin


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
    if wobble_rad <= 0 or not _fitted_gimbal(obs, fit):
        return np.zeros((0, 12))
    shifts = _tilt_shifts(obs, fit)
    if not shifts:
        return np.zeros((0, 12))
    return _effects(obs, fit, wobble_rad * np.concatenate(list(shifts.values())))


def _effects(obs: ObservationSet, fit: FitResult, shifts: np.ndarray) -> np.ndarray:
    """The change of ``(A row-major, b)`` that each of ``shifts`` (Q, n, 3) of the window
    means makes, by refitting (``(Q, 12)``)."""
    res = _refit(obs.with_pooled_noise(), fit, shifts)
    A, b = res.matrix, res.bias
    return np.concatenate([(A[1:] - A[0]).reshape(-1, 9), b[1:] - b[0]], axis=1)


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


@dataclass(frozen=True)
class Nod:
    """A link's nod as its joint's own turns measure it (module docstring, "Measured").

    Attributes
    ----------
    joint : int
        The joint's position in the chain (base 0).
    x : numpy.ndarray, shape (2,)
        ``X = x₁ p₁ + x₂ p₂`` (:func:`_basis` of the joint's axis at the reference angles), rad.
    cov : numpy.ndarray, shape (2, 2)
        Its covariance, widened by ``χ²/dof`` of the turns' agreement where that exceeds 1.
    chi2 : float
        The turns' disagreement with one ``X`` (whitened residuals' sum of squares).
    dof : int
        Its degrees of freedom.
    """

    joint: int
    x: np.ndarray
    cov: np.ndarray
    chi2: float
    dof: int


def _to_reference(h: np.ndarray, var: np.ndarray, r: float) -> tuple[np.ndarray, np.ndarray]:
    """Coefficients ``h`` of ``cos θ``, ``sin θ`` (rows, their variances ``var``) as those of
    ``cos δ``, ``sin δ`` with ``δ = θ − r``."""
    c, s_ = math.cos(r), math.sin(r)
    return (np.stack([h[0] * c + h[1] * s_, h[1] * c - h[0] * s_]),
            np.stack([var[0] * c * c + var[1] * s_ * s_, var[1] * c * c + var[0] * s_ * s_]))


def _nod_equations(obs: ObservationSet, fit: FitResult, k: int, rows: np.ndarray
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The whitened equations of joint ``k``'s windows ``rows`` (module docstring,
    "Measured"): across the turning axis ``C u`` (two unit vectors ``Q``), the reading's
    coefficient of ``cos δ`` (:attr:`ObservationSet.nod`) is ``Qᵀ C X + e_c/ω`` and that of
    ``sin δ`` is ``Qᵀ C (u × X) + e_s/ω``, ``X = x₁ p₁ + x₂ p₂``. Returns the design for
    ``(x₁, x₂)`` (4m, 2), that for the window's nuisance ``(e_c, e_s)`` (4m, 4) and the
    data (4m,)."""
    kin = fit.kinematics or {}
    axes0 = np.asarray(kin["axes"], dtype=float)
    ref = np.asarray(kin["reference_angles_rad"], dtype=float)
    C = np.linalg.inv(np.asarray(fit.matrix, dtype=float))
    delta = np.asarray(obs.pose, dtype=float)[rows] - ref
    u = _carried(axes0, delta, k, axes0[k])
    p1, p2 = (_carried(axes0, delta, k, p) @ C.T for p in _basis(axes0[k]))
    Dx, Dn, y = [], [], []
    for j, i in enumerate(rows):
        g = C @ u[j]
        Q = np.column_stack(_basis(g / np.linalg.norm(g)))
        h, var = _to_reference(np.asarray(obs.nod)[i], np.asarray(obs.nod_std)[i] ** 2,
                               float(ref[k]))
        cols = (np.column_stack([p1[j], p2[j]]), np.column_stack([p2[j], -p1[j]]))
        for row in range(2):  # cos δ, sin δ
            W = np.linalg.inv(np.linalg.cholesky(Q.T @ np.diag(var[row]) @ Q))
            nuisance = np.zeros((2, 4))
            nuisance[:, 2 * row:2 * row + 2] = np.eye(2) / float(obs.rate[i])
            Dx.append(W @ Q.T @ cols[row])
            Dn.append(W @ nuisance)
            y.append(W @ Q.T @ h[row])
    return np.vstack(Dx), np.vstack(Dn), np.concatenate(y)


def _pose_key(obs: ObservationSet, i: int, k: int) -> tuple[int, ...]:
    """Window ``i``'s pose of every joint but ``k``, to a tenth of a degree, modulo turns."""
    pose = np.delete(np.asarray(obs.pose, dtype=float)[i], k)
    return tuple(int(v) % 3600 for v in np.round(np.degrees(np.mod(pose, 2 * np.pi)) * 10))


def measure_nods(obs: ObservationSet, fit: FitResult) -> dict[int, Nod]:
    """Each joint's nod ``X`` measured from its own turns (module docstring, "Measured"), for
    every joint with a joint outside it whose turns determine it: ``{k: Nod}``; empty without
    :attr:`ObservationSet.nod` or a fitted gimbal.

    The turns of one pose (every other joint's angle) share a nuisance ``(e_c, e_s)`` of the
    angle alone (gravity through g-sensitivity also turns once a revolution), which the turns
    in both directions separate from the nod: ``e/ω`` changes sign with the rate, the nod's
    part does not. ``X``'s covariance is widened by ``χ²/dof`` of the fit where that exceeds 1.
    """
    if obs.nod is None or not _fitted_gimbal(obs, fit):
        return {}
    idx = np.asarray(obs.motor_index)
    out = {}
    for k in range(1, len(obs.chain or ())):
        rows = np.flatnonzero(idx == k)
        keys = [_pose_key(obs, int(i), k) for i in rows]
        poses = sorted(set(keys))
        if rows.size <= len(poses):  # no pose turned both ways: the nuisance takes it all
            continue
        Dx, Dn, y = _nod_equations(obs, fit, k, rows)
        J = np.zeros((y.size, 2 + 4 * len(poses)))
        J[:, :2] = Dx
        for j, key in enumerate(keys):
            c = 2 + 4 * poses.index(key)
            J[4 * j:4 * j + 4, c:c + 4] = Dn[4 * j:4 * j + 4]
        dof = y.size - J.shape[1]
        if dof < 1 or np.linalg.matrix_rank(J) < J.shape[1]:
            continue
        coef, *_ = np.linalg.lstsq(J, y, rcond=None)
        chi2 = float(np.sum((y - J @ coef) ** 2))
        cov = np.linalg.inv(J.T @ J)[:2, :2] * max(1.0, chi2 / dof)
        out[k] = Nod(k, coef[:2], cov, chi2, dof)
    return out


def nod_shift(obs: ObservationSet, fit: FitResult, nods: dict[int, Nod]) -> np.ndarray:
    """What the measured nods add to each window mean, ``(n, 3)`` rad/s: joint ``k``'s tilt
    at ``δ`` that the fit does not absorb, ``T(δ) = sin δ X/2 − cos δ (u × X)/2`` (module
    docstring), on the axes of the turns outside it."""
    shift = np.zeros((obs.n_windows, 3))
    if not nods:
        return shift
    shifts = _tilt_shifts(obs, fit)
    for k, nod in nods.items():
        shift += np.tensordot(_nod_terms(nod.x), shifts[k], axes=1)
    return shift


def _nod_terms(x: np.ndarray) -> np.ndarray:
    """The four tilt terms' coefficients (``p₁ sin``, ``p₁ cos``, ``p₂ sin``, ``p₂ cos``,
    :func:`_tilt_shifts`) of ``T(δ) = sin δ X/2 − cos δ (u × X)/2``, ``X = x₁ p₁ + x₂ p₂``
    (``u × p₁ = p₂``, ``u × p₂ = −p₁``)."""
    x1, x2 = float(x[0]), float(x[1])
    return np.array([x1, x2, x2, -x1]) / 2


def remove_nod(obs: ObservationSet, fit: FitResult) -> ObservationSet:
    """``obs`` with the nods its turns measure (:func:`measure_nods`, with the kinematics and
    matrix of ``fit``, a full-matrix fit of it) taken out of the window means, and
    :attr:`~ObservationSet.nod_removed` set; ``obs`` as it is when nothing is measured."""
    nods = measure_nods(obs, fit)
    if not nods:
        return obs
    return replace(obs, mean=np.asarray(obs.mean) - nod_shift(obs, fit, nods), nod_removed=True)


def add_wobble(fit: FitResult, obs: ObservationSet, wobble_rad: float) -> FitResult:
    """``fit`` with the links' nod in its covariance (module docstring): for a joint whose nod
    was measured and taken out of the windows (:func:`remove_nod`), what the measurement's
    error does, ``D Σ_X Dᵀ``; for any other joint the prior ``(1/4) Σ d_q d_qᵀ`` of a nod of
    ``wobble_rad``. A fit without the full matrix is returned as it is.

    Parameters
    ----------
    fit : FitResult
        The fit of ``obs``.
    obs : ObservationSet
        Its windows.
    wobble_rad : float
        ``ε``, the jig's largest once-per-revolution tilt of a link, rad (the prior).
    """
    if not _fitted_gimbal(obs, fit):
        return fit
    eps = wobble_rad if math.isfinite(wobble_rad) and wobble_rad > 0 else 0.0
    nods = measure_nods(obs, fit) if obs.nod_removed else {}
    shifts = _tilt_shifts(obs, fit)
    probe, rows, covs = 1e-3, [], []
    for k, terms in shifts.items():
        if k in nods:  # d(shift)/d(x₁, x₂), with x scaled to a probe tilt
            rows += [probe * np.tensordot(_nod_terms(e), terms, axes=1) for e in np.eye(2)]
            covs.append(nods[k].cov / probe**2)
        elif eps:
            rows += list(probe * terms)
            covs.append(np.eye(4) * 0.25 * (eps / probe) ** 2)
    if not rows:
        return fit
    d = _effects(obs, fit, np.asarray(rows))
    cov = np.array(fit.covariance, dtype=float)
    cov[:12, :12] += d.T @ _block_diag(covs) @ d
    return replace(fit, covariance=cov)


def _block_diag(blocks: list[np.ndarray]) -> np.ndarray:
    n = sum(b.shape[0] for b in blocks)
    out = np.zeros((n, n))
    i = 0
    for b in blocks:
        out[i:i + b.shape[0], i:i + b.shape[0]] = b
        i += b.shape[0]
    return out
