"""Replay: the filtered states kept, and the Rauch-Tung-Striebel smoother back over them.

With ``keep_states=True`` the tracker keeps every update's state, and :meth:`BiasTracker.smoothed`
runs the Rauch-Tung-Striebel smoother back over them, so a replayed recording's estimate at each
sample uses the whole session (live tracking cannot). No smoothing crosses an update where the
health tests found a break (a bias step).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from gyrocal.calib.errors import CalibInputError

__all__ = ["Replay"]


class Replay:
    """Mixin of :class:`~gyrocal.calib.tracker.BiasTracker`: the kept states
    (``keep_states=True``) and :meth:`smoothed`."""

    def _widen_kept(self, extra: list[float]) -> None:
        """Widen the last kept state's bias variance by ``extra`` (per axis): the prior the
        seed check found too narrow, so the smoother carries the first rest's bias back."""
        if self._states is None or not self._states["P"]:
            return
        P = self._states["P"][-1]
        for i in range(3):
            P[i, i] += extra[i]

    def _keep_state(self, Q: np.ndarray, brk: bool = False) -> None:
        """Store the state after an update (and the process noise its prediction added); ``brk``:
        the health tests found a break of the model (a bias step) at this update."""
        if self._states is None:
            return
        st = self._states
        st["t"].append(self._t_state)
        st["x"].append(np.asarray(self._kf.x, dtype=float).reshape(-1).copy())
        st["P"].append(np.asarray(self._kf.P, dtype=float).copy())
        st["Q"].append(np.asarray(Q, dtype=float).copy())
        st["break"].append(brk)

    def _smoother_states(self) -> tuple[np.ndarray, ...]:
        """Per kept update: time, filtered state and covariance, smoothed state and covariance,
        the inverse of the next prediction's covariance, and the process-noise rate from each
        update to the next (cached until a new update arrives)."""
        from gyrocal.calib.kalman import rts_smooth

        assert self._states is not None
        self._catch_up()
        st = self._states
        N = len(st["t"])
        if self._smooth_cache is not None and self._smooth_cache[0] == N:
            return self._smooth_cache[1]
        T = np.array(st["t"], dtype=float)
        X = np.array(st["x"]).reshape(N, self._dim)
        P = np.array(st["P"]).reshape(N, self._dim, self._dim)
        Q_into = np.array(st["Q"]).reshape(N, self._dim, self._dim)
        Q_next = np.concatenate([Q_into[1:], np.zeros((1, self._dim, self._dim))])
        # no smoothing across a break the health tests found (a bias step): the model did not
        # hold there, so the updates after it must not pull the estimates before it
        brk = np.flatnonzero(np.array(st["break"], dtype=bool))
        bounds = [0, *[int(b) for b in brk if b > 0], N]
        Xs, Ps = X.copy(), P.copy()
        for a, b in zip(bounds[:-1], bounds[1:], strict=True):
            if b > a:
                Xs[a:b], Ps[a:b], _ = rts_smooth(X[a:b], P[a:b], Q_next[a:b])
        Pp = P + Q_next
        Pp_inv = np.zeros_like(P)
        Pp_inv[:-1] = np.linalg.inv(Pp[:-1])
        Pp_inv[np.array([b - 1 for b in bounds[1:-1]], dtype=np.int64)] = 0.0
        dtk = np.diff(T)
        rate = np.empty((N, self._dim))
        rate[-1] = self._q
        with np.errstate(divide="ignore", invalid="ignore"):
            rate[:-1] = np.where(dtk[:, None] > 0,
                                 np.diagonal(Q_next[:-1], axis1=1, axis2=2) / dtk[:, None], 0.0)
        dx = np.zeros_like(X)
        dx[:-1] = Xs[1:] - X[:-1]
        dP = np.zeros_like(P)
        dP[:-1] = Ps[1:] - Pp[:-1]
        cut = np.array([b - 1 for b in bounds[1:-1]], dtype=np.int64)
        dx[cut] = 0.0
        dP[cut] = 0.0
        out = (T, X, P, Pp_inv, rate, dx, dP)
        self._smooth_cache = (N, out)
        return out

    def smoothed(
        self, t: Any, temperature: Any = None, *, chunk: int = 16384
    ) -> tuple[np.ndarray, np.ndarray]:
        """Fixed-interval smoothed bias and its one-sigma uncertainty at times ``t``.

        The Rauch-Tung-Striebel smoother (:func:`gyrocal.calib.kalman.rts_smooth`) runs back
        over the kept updates (``keep_states=True``); between two updates ``k`` and ``k + 1`` the
        bias walks with no measurement, so a time ``τ`` after update ``k`` the filtered state is
        ``x_k`` with ``P_k + q τ`` and one more smoother step towards update ``k + 1`` gives

            C = (P_k + q τ)(P_k + Q_k)⁻¹,  x̂ = x_k + C (x̂_{k+1} − x_k),
            P̂ = P_k + q τ + C (P̂_{k+1} − P_k − Q_k) Cᵀ

        (after the last update, the filter's prediction). Every measurement of the session
        informs every estimate: what a replay of a whole recording can use and a live stream
        cannot. ``t`` may be given in pieces (``chunk`` samples are worked at a time).

        Parameters
        ----------
        t : array_like (n,)
            Times, s (those of the samples processed, or any others).
        temperature : array_like (n,), optional
            Die temperature at ``t``, °C (required with the temperature model).
        chunk : int
            Samples per vectorised step (bounds the working memory).

        Returns
        -------
        bias, bias_std : ndarray (n, 3)
        """
        if self._states is None:
            raise CalibInputError("smoothed() needs a tracker built with keep_states=True")
        self._catch_up()
        if not self._states["t"]:
            raise CalibInputError("smoothed() needs processed samples")
        t = np.asarray(t, dtype=float).reshape(-1)
        if self._temp_model:
            if temperature is None:
                raise CalibInputError("the temperature model needs the temperature at t")
            temp = np.asarray(temperature, dtype=float).reshape(-1)
            if temp.shape != t.shape or not np.all(np.isfinite(temp)):
                raise CalibInputError("temperature must be finite and match t")
        T, X, P, Pp_inv, rate, dx, dP = self._smoother_states()
        n = t.size
        bias = np.empty((n, 3))
        std = np.empty((n, 3))
        t_ref = self._t_ref if self._t_ref is not None else 0.0
        for a in range(0, n, max(1, int(chunk))):
            sl = slice(a, min(a + chunk, n))
            k = np.clip(np.searchsorted(T, t[sl], side="right") - 1, 0, T.size - 1)
            tau = np.maximum(t[sl] - T[k], 0.0)
            Pf = P[k].copy()
            idx = np.arange(self._dim)
            Pf[:, idx, idx] += rate[k] * tau[:, None]
            C = Pf @ Pp_inv[k]
            xs = X[k] + np.einsum("mij,mj->mi", C, dx[k])
            Ps = Pf + C @ dP[k] @ np.swapaxes(C, 1, 2)
            if self._temp_model:
                dT = (temp[sl] - t_ref)[:, None]
                i3 = np.arange(3)
                bias[sl] = xs[:, :3] + xs[:, 3:] * dT
                var = (Ps[:, i3, i3] + 2 * dT * Ps[:, i3, i3 + 3]
                       + dT * dT * Ps[:, i3 + 3, i3 + 3])
            else:
                bias[sl] = xs
                var = np.diagonal(Ps, axis1=1, axis2=2)
            std[sl] = np.sqrt(np.maximum(var, 0.0))
        return bias, std
