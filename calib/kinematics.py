r"""Serial-chain kinematics of the gimbal: each joint's axis and the rate in the sensor frame.

The gimbal is a chain of servos from the base to the sensor. Servo ``j`` (``j = 0`` the base,
``S - 1`` the innermost, carrying the sensor) turns about a unit axis ``u_j⁰`` given in the
calibrated sensor frame with every servo at its reference angle ``θ_j^ref``. With
``Δ_j = θ_j - θ_j^ref`` the orientation of the sensor relative to the base is the product of
exponentials (every axis written in the reference sensor frame)

.. math:: R(θ) = \operatorname{Rot}(u_0⁰, Δ_0)\,\operatorname{Rot}(u_1⁰, Δ_1)\cdots
          \operatorname{Rot}(u_{S-1}⁰, Δ_{S-1}),

and the angular velocity in the sensor frame, ``ω = Rᵀ Σ_j (∏_{k<j} Rot_k) u_j⁰ θ̇_j``, is

.. math:: ω = \sum_j u_j(θ)\, \dot θ_j, \qquad
          u_j(θ) = \operatorname{Rot}(u_{S-1}⁰, -Δ_{S-1}) \cdots
                   \operatorname{Rot}(u_{j+1}⁰, -Δ_{j+1})\, u_j⁰ :

the innermost servo's axis is constant in the sensor frame, and each outer axis is carried by the
rotations of the servos inside it (never by its own angle or those of servos outside it). Angles
are the encoders' cumulative angles, so whole turns drop out. ``Rot(u, φ)`` is Rodrigues'
rotation by ``φ`` about ``u``, right-handed: positive angles are the servo's positive direction
when ``u`` points along its positive axis.

The ``kinematics`` mapping is the one Calibration v2 stores (DESIGN.md, "Calibration v1 and v2"):
``{"chain": [servo ids, base first], "axes": [[ux, uy, uz] per servo], "reference_angles_rad":
[one per servo]}``.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from gyrocal.calib.errors import CalibInputError

__all__ = ["axes_at", "axis_derivatives", "chain_axes", "pose_derivatives", "rotate", "sensor_rate",
           "up_at"]


def rotate(axis: np.ndarray, angle: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Rodrigues' formula: ``v`` rotated by ``angle`` about the unit ``axis``.

    ``v cos φ + (u × v) sin φ + u (u·v)(1 − cos φ)``; all arguments broadcast (vectors on the
    last axis, of length 3).
    """
    axis = np.asarray(axis, dtype=float)
    v = np.asarray(v, dtype=float)
    phi = np.asarray(angle, dtype=float)[..., None]
    c, s = np.cos(phi), np.sin(phi)
    return v * c + np.cross(axis, v) * s + axis * np.sum(axis * v, axis=-1, keepdims=True) * (1 - c)


def chain_axes(axes: np.ndarray, reference: np.ndarray, angles: np.ndarray) -> np.ndarray:
    """Each joint's axis in the sensor frame at the given encoder angles (array form).

    Parameters
    ----------
    axes : ndarray, shape (..., S, 3)
        Unit axes ``u_j⁰`` in the sensor frame at the reference angles, base first (may carry
        leading batch dimensions that broadcast against ``angles``).
    reference : ndarray, shape (S,) or (..., S)
        Reference angles, rad.
    angles : ndarray, shape (..., S)
        Encoder angles, rad.

    Returns
    -------
    ndarray, shape (..., S, 3)
        ``u_j(θ)`` (module docstring).
    """
    axes = np.asarray(axes, dtype=float)
    delta = np.asarray(angles, dtype=float) - np.asarray(reference, dtype=float)
    S = axes.shape[-2]
    shape = np.broadcast_shapes(axes.shape, delta.shape[:-1] + (S, 3))
    out = np.array(np.broadcast_to(axes, shape))
    # u_j(θ): apply the inner rotations Rot(u_k⁰, −Δ_k) from k = j+1 outwards to k = S−1 last.
    for j in range(S - 1):
        v = out[..., j, :]
        for k in range(j + 1, S):
            v = rotate(axes[..., k, :], -delta[..., k], v)
        out[..., j, :] = v
    return out


def up_at(axes: np.ndarray, reference: np.ndarray, up: tuple[int, int], home: np.ndarray,
          angles: np.ndarray) -> np.ndarray:
    """"Up" in the sensor frame at encoder angles ``angles``: the specific force of a still
    sensor, in g (gravity's reaction, +1 g up).

    Up is servo ``up[0]``'s axis (chain index, sign ``up[1]``) in the home pose ``θ_h``, where
    the jig stands with that axis vertical; in any pose ``θ`` it is carried by every servo's
    rotation from the home pose, like the axis of a joint outside the base:
    ``γ(θ) = Rot(u_{S-1}, −Δ_{S-1}) ⋯ Rot(u_0, −Δ_0) γ_h``, ``Δ = θ − θ_h``, the axes at
    ``θ_h`` (module docstring).

    Parameters
    ----------
    axes : ndarray, shape (S, 3)
        The servos' axes in the sensor frame at ``reference`` (a fit's kinematics), base first.
    reference : ndarray, shape (S,)
        Their reference angles, rad.
    up : (int, int)
        Chain index of the servo whose axis is vertical at home, and ±1.
    home : ndarray, shape (S,)
        The home pose, rad.
    angles : ndarray, shape (N, S)
        Encoder angles, rad.

    Returns
    -------
    ndarray, shape (N, 3)
    """
    home = np.asarray(home, dtype=float)
    at_home = chain_axes(axes, reference, home)
    g_home = up[1] * at_home[up[0]]
    ext = np.concatenate([g_home[None], at_home])
    th = np.asarray(angles, dtype=float)
    th = np.concatenate([np.zeros((th.shape[0], 1)), th], axis=1)
    return chain_axes(ext, np.concatenate([[0.0], home]), th)[:, 0]


def axis_derivatives(
    axes: np.ndarray, delta: np.ndarray, index: np.ndarray, tangent: np.ndarray
) -> np.ndarray:
    r"""Exact derivatives of the turning servos' axes ``u_j(θ)`` with respect to the reference
    axes ``u_s⁰``, each along a given direction.

    With ``u_j = R_{S-1} ⋯ R_{j+1} u_j⁰`` and ``R_k = Rot(u_k⁰, −Δ_k)`` (module docstring):
    along ``t_j`` the axis moves by ``R_{S-1} ⋯ R_{j+1} t_j``; along ``t_k`` for ``k > j``, by
    ``R_{S-1} ⋯ R_{k+1} ∂R_k[t_k] x`` with ``x = R_{k-1} ⋯ R_{j+1} u_j⁰`` and, from Rodrigues'
    formula, ``∂Rot(u, φ)[t] x = (t × x) sin φ + (t (u·x) + u (t·x))(1 − cos φ)``; servos
    outside ``j`` do not move it. Exact where a finite difference loses ``ε/h`` (about 1e-10 at
    ``h = 1e-6``), which dominates a fit's whitened Jacobian once the noise is that small.

    Parameters
    ----------
    axes : ndarray, shape (B, S, 3)
        Reference axes ``u_s⁰`` (unit), base first.
    delta : ndarray, shape (B, n, S)
        Angles from the reference of every servo for each of ``n`` windows, rad.
    index : ndarray of int, shape (n,)
        The turning servo ``j`` of each window.
    tangent : ndarray, shape (B, S, 3)
        One direction ``t_s`` per axis.

    Returns
    -------
    ndarray, shape (B, n, S, 3)
        ``∂u_{j_i}/∂u_s⁰ [t_s]`` for window ``i`` and axis ``s``.
    """
    B, n, S = delta.shape
    out = np.zeros((B, n, S, 3))
    for j in range(S):
        sel = np.flatnonzero(np.asarray(index) == j)
        if not sel.size:
            continue
        d = delta[:, sel]
        v = np.broadcast_to(tangent[:, None, j], (B, sel.size, 3))
        x = np.broadcast_to(axes[:, None, j], (B, sel.size, 3))
        for k in range(j + 1, S):
            v = rotate(axes[:, None, k], -d[..., k], v)
        out[:, sel, j] = v
        for k in range(j + 1, S):
            u, t, phi = axes[:, None, k], tangent[:, None, k], -d[..., k, None]
            dv = (np.cross(t, x) * np.sin(phi)
                  + (t * np.sum(u * x, axis=-1, keepdims=True)
                     + u * np.sum(t * x, axis=-1, keepdims=True)) * (1 - np.cos(phi)))
            for kk in range(k + 1, S):
                dv = rotate(axes[:, None, kk], -d[..., kk], dv)
            out[:, sel, k] = dv
            x = rotate(u, phi[..., 0], x)
    return out


def pose_derivatives(axes: np.ndarray, delta: np.ndarray, index: np.ndarray) -> np.ndarray:
    r"""Exact derivatives of the turning servos' axes with respect to every servo's angle.

    ``∂u_j/∂Δ_k = −u_k(θ) × u_j(θ)`` for ``k > j`` (the rotation ``Rot(u_k⁰, −Δ_k)`` carried
    out by the servos outside ``k``, which turn ``u_k⁰`` into ``u_k(θ)``), and 0 for ``k ≤ j``.

    Parameters
    ----------
    axes : ndarray, shape (B, S, 3)
    delta : ndarray, shape (B, n, S)
    index : ndarray of int, shape (n,)
        As in :func:`axis_derivatives`.

    Returns
    -------
    ndarray, shape (B, n, S, 3)
        ``∂u_{j_i}/∂Δ_k`` for window ``i`` and servo ``k``.
    """
    index = np.asarray(index)
    n = index.size
    every = chain_axes(axes[:, None], 0.0, delta)  # (B, n, S, 3)
    uj = every[:, np.arange(n), index]
    outer = (np.arange(axes.shape[1])[None, :] > index[:, None])[None, :, :, None]
    return np.where(outer, -np.cross(every, uj[:, :, None, :]), 0.0)


def _parse(kinematics: Mapping[str, Any], angles: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    if not isinstance(kinematics, Mapping):
        raise CalibInputError(f"kinematics must be a mapping, got {type(kinematics).__name__}")
    try:
        chain = list(kinematics["chain"])
        axes = np.asarray(kinematics["axes"], dtype=float)
        ref = np.asarray(kinematics["reference_angles_rad"], dtype=float)
    except KeyError as exc:
        raise CalibInputError(f"kinematics lacks {exc.args[0]!r}") from None
    except (TypeError, ValueError):
        raise CalibInputError(
            "kinematics 'axes' and 'reference_angles_rad' must be numeric") from None
    S = len(chain)
    if S == 0 or axes.shape != (S, 3) or ref.shape != (S,):
        raise CalibInputError(
            f"kinematics needs one axis (3 numbers) and one reference angle per servo of the "
            f"chain ({S} servos); got axes {axes.shape} and reference angles {ref.shape}"
        )
    if not (np.all(np.isfinite(axes)) and np.all(np.isfinite(ref))):
        raise CalibInputError("kinematics contains NaN or inf")
    norms = np.linalg.norm(axes, axis=1)
    if np.any(np.abs(norms - 1.0) > 1e-6):
        raise CalibInputError(f"kinematics axes must be unit vectors; their norms are {norms}")
    th = np.asarray(angles, dtype=float)
    if th.ndim != 2 or th.shape[1] != S:
        raise CalibInputError(
            f"angles must have shape (N, {S}), one column per servo; got {th.shape}")
    if not np.all(np.isfinite(th)):
        raise CalibInputError("angles contain NaN or inf")
    return axes, ref, th


def axes_at(kinematics: Mapping[str, Any], angles: np.ndarray) -> np.ndarray:
    """Each joint's axis in the sensor frame at encoder angles ``angles``.

    Parameters
    ----------
    kinematics : mapping
        ``{"chain", "axes", "reference_angles_rad"}`` (module docstring).
    angles : array_like, shape (N, S)
        Encoder angles of the servos in chain order, rad.

    Returns
    -------
    ndarray, shape (N, S, 3)

    Raises
    ------
    CalibInputError
        On a malformed mapping (missing keys, wrong shapes, axes that are not unit vectors) or
        angles of the wrong shape.
    """
    axes, ref, th = _parse(kinematics, angles)
    return chain_axes(axes, ref, th)


def sensor_rate(kinematics: Mapping[str, Any], angles: np.ndarray, rates: np.ndarray) -> np.ndarray:
    """Angular velocity in the sensor frame, ``ω = Σ_j u_j(θ) θ̇_j``.

    Parameters
    ----------
    kinematics : mapping
        ``{"chain", "axes", "reference_angles_rad"}`` (module docstring).
    angles, rates : array_like, shape (N, S)
        Encoder angles (rad) and rates (rad/s) of the servos in chain order.

    Returns
    -------
    ndarray, shape (N, 3)
        rad/s in the sensor frame.

    Raises
    ------
    CalibInputError
        As :func:`axes_at`, or ``rates`` of another shape than ``angles``.
    """
    axes, ref, th = _parse(kinematics, angles)
    w = np.asarray(rates, dtype=float)
    if w.shape != th.shape:
        raise CalibInputError(f"rates must have the shape of angles {th.shape}, got {w.shape}")
    if not np.all(np.isfinite(w)):
        raise CalibInputError("rates contain NaN or inf")
    return np.einsum("nsk,ns->nk", chain_axes(axes, ref, th), w)
