"""The linear Kalman filter step of the bias tracker, under filterpy's attribute names.

A plain install must not pull matplotlib, and ``filterpy`` (1.4.5, unchanged since 2018) declares
it as a requirement; the tracker needs only one predict and one update per window, so they live
here (about thirty lines), and the test suite checks them against ``filterpy.kalman.KalmanFilter``
(kept in the ``test`` extra). The tracker holds its state in a :class:`KalmanFilter` and runs
the same step written out per axis (its axes are independent), checked against this one.
The equations are the textbook ones (Bar-Shalom, Li & Kirubarajan,
*Estimation with Applications to Tracking and Navigation*, §5.2.4; the covariance update in
Joseph form, §5.2.5):

    x⁻ = F x,  P⁻ = F P Fᵀ + Q,
    y = z − H x⁻,  S = H P⁻ Hᵀ + R,  K = P⁻ Hᵀ S⁻¹,
    x = x⁻ + K y,  P = (I − K H) P⁻ (I − K H)ᵀ + K R Kᵀ.

:func:`rts_smooth` is the fixed-interval Rauch-Tung-Striebel smoother over a filter's stored
states (Rauch, Tung & Striebel 1965; Bar-Shalom et al. §8.6), under filterpy's
``rts_smoother`` conventions, against which the tests check it.
"""

from __future__ import annotations

import numpy as np

from gyrocal.calib.errors import CalibInputError

__all__ = ["KalmanFilter", "rts_smooth"]


class KalmanFilter:
    """State ``x`` (n,) and covariance ``P`` of a linear Gaussian system with ``dim_z`` readings.

    Attributes (filterpy's names)
    -----------------------------
    x : ndarray (n,)
    P, F, Q : ndarray (n, n)
        Covariance, transition and process noise (identity, identity, zero at construction).
    H : ndarray (dim_z, n)
    R : ndarray (dim_z, dim_z)
    y : ndarray (dim_z,)
        The last innovation ``z − H x⁻``.
    S, SI : ndarray (dim_z, dim_z)
        The last innovation covariance and its inverse.
    K : ndarray (n, dim_z)
        The last gain.
    """

    def __init__(self, dim_x: int, dim_z: int) -> None:
        if dim_x < 1 or dim_z < 1:
            raise CalibInputError(f"dim_x and dim_z must be >= 1, got {dim_x} and {dim_z}")
        self.x = np.zeros(dim_x)
        self.P = np.eye(dim_x)
        self.F = np.eye(dim_x)
        self.Q = np.zeros((dim_x, dim_x))
        self.H = np.zeros((dim_z, dim_x))
        self.R = np.eye(dim_z)
        self.y = np.zeros(dim_z)
        self.S = np.zeros((dim_z, dim_z))
        self.SI = np.zeros((dim_z, dim_z))
        self.K = np.zeros((dim_x, dim_z))

    def predict(self) -> None:
        """Time update: ``x = F x``, ``P = F P Fᵀ + Q``."""
        self.x = self.F @ self.x
        self.P = self.F @ self.P @ self.F.T + self.Q

    def update(self, z: np.ndarray) -> None:
        """Measurement update with reading ``z`` (dim_z,), covariance in Joseph form."""
        x = np.asarray(self.x, dtype=float).reshape(-1)
        z = np.asarray(z, dtype=float).reshape(-1)
        H = np.asarray(self.H, dtype=float)
        pht = self.P @ H.T
        self.y = z - H @ x
        self.S = H @ pht + self.R
        self.SI = np.linalg.inv(self.S)
        self.K = pht @ self.SI
        self.x = x + self.K @ self.y
        ikh = np.eye(x.size) - self.K @ H
        self.P = ikh @ self.P @ ikh.T + self.K @ self.R @ self.K.T


def rts_smooth(
    xs: np.ndarray, Ps: np.ndarray, Qs: np.ndarray, Fs: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Rauch-Tung-Striebel smoother over the filtered states of one pass.

    The forward pass stored the filtered ``x_k``, ``P_k`` of each step and went from step ``k``
    to ``k + 1`` with ``F_k``, ``Q_k`` (filterpy's convention). Backwards from ``x̂_N = x_N``,
    ``P̂_N = P_N``:

        P⁻ = F_k P_k F_kᵀ + Q_k,   C_k = P_k F_kᵀ (P⁻)⁻¹,
        x̂_k = x_k + C_k (x̂_{k+1} − F_k x_k),   P̂_k = P_k + C_k (P̂_{k+1} − P⁻) C_kᵀ

    (Bar-Shalom, Li & Kirubarajan, §8.6.2).

    Parameters
    ----------
    xs : ndarray (N, n)
        Filtered states.
    Ps : ndarray (N, n, n)
        Their covariances.
    Qs : ndarray (N, n, n)
        Process noise of the prediction from each step to the next (``Qs[N−1]`` is unused).
    Fs : ndarray (N, n, n), optional
        Transitions from each step to the next (default identity).

    Returns
    -------
    x_smooth : ndarray (N, n)
    P_smooth : ndarray (N, n, n)
    C : ndarray (N, n, n)
        The smoother gains (``C[N−1]`` is zero).
    """
    xs = np.asarray(xs, dtype=float)
    Ps = np.asarray(Ps, dtype=float)
    Qs = np.asarray(Qs, dtype=float)
    N = xs.shape[0]
    if xs.ndim != 2 or Ps.shape != (N, xs.shape[1], xs.shape[1]) or Qs.shape != Ps.shape:
        raise CalibInputError("rts_smooth needs xs (N, n), Ps and Qs (N, n, n)")
    n = xs.shape[1]
    F = np.broadcast_to(np.eye(n), Ps.shape) if Fs is None else np.asarray(Fs, dtype=float)
    x = xs.copy()
    P = Ps.copy()
    C = np.zeros_like(Ps)
    for k in range(N - 2, -1, -1):
        Fk = F[k]
        Pp = Fk @ Ps[k] @ Fk.T + Qs[k]
        C[k] = np.linalg.solve(Pp.T, (Ps[k] @ Fk.T).T).T
        x[k] = xs[k] + C[k] @ (x[k + 1] - Fk @ xs[k])
        P[k] = Ps[k] + C[k] @ (P[k + 1] - Pp) @ C[k].T
    return x, P, C
