"""The bias random walk from the data: a bank of filters over a grid of ``K``.

Without a given ``rate_random_walk`` the tracker estimates ``q = K²`` per axis as it goes, by
multiple-model adaptive estimation (Magill 1965; Bar-Shalom, Li & Kirubarajan §11.6): a bank of
filters of the same model on a log grid of ``K`` (:class:`QBank`, 10⁻⁷ to 3·10⁻³ rad/s/√s) sees
every update window; each filter's innovation likelihood, forgotten over ``adapt_memory_s``,
weighs its ``K`` (flat prior on ``log K``), and the tracker uses the posterior mean of ``q``
plus its posterior standard deviation (the band must hold where few rests leave ``q`` loose).
Every model's likelihood is computed with its own covariance, so the estimate is not biased by
the ``q`` the tracker happens to run with (matching one filter's innovation covariance is: its
``P`` is wrong exactly when its ``q`` is). An unmodelled drift (a temperature coefficient left
out) shows up as a larger ``q``, so the band stays honest; with the temperature model the
coefficient is a state, and :attr:`BiasTracker.tempco` with :attr:`BiasTracker.tempco_std`
says whether it matters.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from gyrocal.calib.tracker.settings import TrackerSettings

__all__ = ["QBank"]


class QBank:
    """The bias random walk from the data: a bank of filters over a grid of ``K`` (multiple-model
    adaptive estimation, Magill 1965; Bar-Shalom et al. §11.6).

    Each axis is its own model (the bias, and with the temperature model its coefficient), so
    the bank is ``G`` grid values × 3 axes of one- or two-state scalar-measurement Kalman
    filters fed the same update windows as the tracker. Each filter's innovation likelihood
    ``ℓ = −½ (log S + y²/S)`` accumulates, forgotten exponentially over ``adapt_memory_s``;
    with a flat prior on ``log K`` the posterior weight of grid value ``g`` is
    ``∝ exp(Σ ℓ_g)``. The tracker uses the posterior mean of ``q = K²`` plus its posterior
    standard deviation, so that its band also holds where the data pin ``q`` down poorly (rare
    rests), while a well-observed ``q`` gets a narrow posterior and no margin to speak of.
    Unlike matching the innovations' covariance of a single filter, the likelihood of each
    model is computed with that model's own ``P``, so a wrong ``q`` in the tracker biases
    nothing; a young bank spreads its weight over the grid, which errs towards a large ``q``
    (a wide band) by itself.
    """

    #: Grid of K, rad/s/√s: consumer MEMS gyros lie within it with a decade to spare.
    GRID = np.logspace(-7.0, -2.5, 28)

    def __init__(self, b0: np.ndarray, b0_std: np.ndarray, s: TrackerSettings,
                 c0: np.ndarray | None) -> None:
        G = self.GRID.size
        self.qg = self.GRID**2
        self._qg = self.qg[:, None]
        # each filter's state and covariance entries, (G, 3) each (x1, P01, P11: the
        # temperature coefficient's, None without it): elementwise arithmetic only
        self.x0 = np.broadcast_to(np.asarray(b0, dtype=float), (G, 3)).copy()
        self.P00 = np.broadcast_to(np.asarray(b0_std, dtype=float) ** 2, (G, 3)).copy()
        self.x1 = self.P01 = self.P11 = None
        if c0 is not None:
            self.x1 = np.broadcast_to(np.asarray(c0, dtype=float), (G, 3)).copy()
            self.P01 = np.zeros((G, 3))
            self.P11 = np.broadcast_to(np.asarray(s.tempco_std) ** 2, (G, 3)).copy()
            self.qc = np.asarray(s.tempco_random_walk) ** 2
        self.memory = s.adapt_memory_s
        self.loglik = np.zeros((G, 3))
        self.q = np.asarray(s.rate_random_walk_prior, dtype=float) ** 2
        self.q_std = np.zeros(3)

    def steps(self, z: list[float], R: list[float], dT: float | None, dt: float
              ) -> Iterator[None]:
        """Predict by ``dt`` and update every filter with window mean ``z`` (variance ``R``),
        in slices (yielding between them); the last sets ``q`` and ``q_std``, the posterior mean
        of ``q = K²`` per axis and its posterior standard deviation (the tracker uses their sum).

        Each filter has ``h = [−1]`` or ``[−1, −ΔT]``: ``Ph = P h``, ``S = hᵀ P h + R``,
        ``K = Ph / S``, ``x += K y``, ``P −= K Phᵀ``, written out per entry. A slice is one
        array operation (about a microsecond or two), so that spread over the calls that
        follow a step each pays little."""
        z_a, R_a = np.array(z), np.array(R)
        yield
        pred = self._qg * dt
        yield
        self.P00 += pred
        yield
        if dT is None:
            y = z_a + self.x0
            yield
            S = self.P00 + R_a
            yield
            k0 = -self.P00 / S
            yield
            self.x0 += k0 * y
            yield
            self.P00 += k0 * self.P00  # P − K Phᵀ with Ph = −P
        else:
            self.P11 += self.qc * dt
            yield
            y = z_a + self.x0
            yield
            y += dT * self.x1
            yield
            ph0 = self.P00 + dT * self.P01
            yield
            ph0 = -ph0
            ph1 = -(self.P01 + dT * self.P11)
            yield
            S = R_a - ph0 - dT * ph1
            yield
            k0 = ph0 / S
            k1 = ph1 / S
            yield
            self.x0 += k0 * y
            yield
            self.x1 += k1 * y
            yield
            self.P00 -= k0 * ph0
            yield
            self.P01 -= k0 * ph1
            yield
            self.P11 -= k1 * ph1
        yield
        lam = math.exp(-dt / self.memory) if dt > 0 else 1.0
        ll = np.log(S)
        yield
        ll += y * y / S
        yield
        ll *= -0.5
        self.loglik *= lam
        yield
        self.loglik += ll
        yield
        w = self.loglik.max(axis=0)
        yield
        w = self.loglik - w
        yield
        w = np.exp(w)
        yield
        w /= w.sum(axis=0)
        yield
        q = w * self._qg
        yield
        q = q.sum(axis=0)
        yield
        d = self._qg - q
        d *= d
        yield
        d *= w
        yield
        d = d.sum(axis=0)
        yield
        self.q, self.q_std = q, np.sqrt(d)

    def widen(self, extra: np.ndarray) -> None:
        """Widen every filter's bias variance as the tracker widened its own (a detected step)."""
        self.P00 += extra[None, :]
