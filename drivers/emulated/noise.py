"""Coloured gyro noise for the emulated chips: bias instability and rate random walk.

The white noise of a chip (angle random walk) is drawn by the chip itself from its density
(:class:`~gyrocal.drivers.emulated.imu_chips.SensorTruth`); this module adds the two slower terms
of the IEEE Std 952 noise model that an Allan deviation plot shows:

* **bias instability** ``B`` (rad/s): a flat Allan floor ``σ_A = B·sqrt(2 ln 2 / π) ≈ 0.664 B``.
  Flicker noise has no finite-state generator, so it is stood in for by a sum of independent
  first-order Gauss–Markov processes with correlation times spaced a decade apart
  (:data:`FLICKER_TIME_CONSTANTS_S`), of equal variance, scaled so that the Allan deviation of the
  sum has its geometric mean over ``τ`` in ``[T_min, T_max]`` equal to ``0.664 B``. The
  Allan deviation of a Gauss–Markov process of variance ``q²`` and correlation time ``T`` is

      σ_A²(τ) = (2 q² T / τ) · [1 − (T / 2τ)(3 − 4 e^(−τ/T) + e^(−2τ/T))]

  and independent processes add their Allan variances, so :func:`allan_deviation` is exact for
  the generator; its ripple about the floor is −15 %/+4 % over ``[T_min, T_max]`` and
  −7 %/+4 % over 1–1000 s.
* **rate random walk** ``K`` (rad/s/√s): a bias that random-walks, ``σ_A(τ) = K·sqrt(τ/3)``.

Each process is generated exactly in discrete time (``x_k+1 = φ x_k + sqrt(1 − φ²) q w_k`` with
``φ = e^(−Δt/T)``), so the statistics do not depend on the sample rate, and the state carries
across calls. :meth:`ColouredNoise.ahead` computes what a run of one-step calls would give
without drawing (an emulated chip computing its samples ahead), and :meth:`ColouredNoise.resume`
takes up one of its states, as if those calls had been made.
"""

from __future__ import annotations

import math

import numpy as np

from gyrocal.drivers.emulated.iir import lfilter

__all__ = ["FLICKER_TIME_CONSTANTS_S", "ColouredNoise", "Normals", "allan_deviation",
           "flicker_component_sigma"]

#: Correlation times of the Gauss–Markov processes that stand in for flicker noise, s: a decade
#: apart, so the Allan floor is flat from about 1 s to 1000 s (a calibration run's time scales).
FLICKER_TIME_CONSTANTS_S = (0.5, 5.0, 50.0, 500.0)
#: ``σ_A / B`` of flicker noise (IEEE Std 952-1997, Annex C): sqrt(2 ln 2 / π).
FLICKER_FLOOR = math.sqrt(2.0 * math.log(2.0) / math.pi)


def _gm_avar(tau: np.ndarray, q2: float, T: float) -> np.ndarray:
    x = tau / T
    return (2.0 * q2 * T / tau) * (1.0 - (3.0 - 4.0 * np.exp(-x) + np.exp(-2.0 * x)) / (2.0 * x))


def _unit_flicker_avar(tau: np.ndarray) -> np.ndarray:
    """Allan variance of the flicker stand-in with unit variance per component."""
    return sum(_gm_avar(tau, 1.0, T) for T in FLICKER_TIME_CONSTANTS_S)


def flicker_component_sigma(bias_instability: float) -> float:
    """Standard deviation of each Gauss–Markov component for bias instability ``B``: the scale
    that puts the geometric mean of the Allan deviation over ``[T_min, T_max]`` at ``0.664 B``."""
    T = FLICKER_TIME_CONSTANTS_S
    tau = np.geomspace(T[0], T[-1], 61)
    gmean = float(np.exp(np.mean(0.5 * np.log(_unit_flicker_avar(tau)))))
    return FLICKER_FLOOR * float(bias_instability) / gmean


def allan_deviation(tau: np.ndarray, white_density: float, bias_instability: float,
                    rate_random_walk: float) -> np.ndarray:
    """The exact Allan deviation of the generator at averaging times ``tau`` (s): white noise of
    density ``N`` (rad/s/√Hz; ``σ_A² = N²/τ``), the flicker stand-in and the rate random walk
    (``σ_A² = K² τ / 3``)."""
    tau = np.asarray(tau, dtype=float)
    q = flicker_component_sigma(bias_instability)
    return np.sqrt(white_density**2 / tau + q**2 * _unit_flicker_avar(tau)
                   + rate_random_walk**2 * tau / 3.0)


class Normals:
    """A generator's standard normals handed out in order: :meth:`standard_normal` gives what
    ``rng.standard_normal(shape)`` would (numpy's :class:`~numpy.random.Generator` draws the
    same stream whatever the sizes of its calls), drawn ahead in chunks so that :meth:`peek`
    can show the next values without using them up.

    Parameters
    ----------
    rng : numpy.random.Generator
        Seeded by the caller; drawn from by this object only from then on.
    """

    _CHUNK = 3 * 1024

    def __init__(self, rng: np.random.Generator) -> None:
        self.rng = rng
        self._buf = np.zeros(0)
        self._pos = 0

    def peek(self, n: int) -> np.ndarray:
        """The next ``n`` values, left in the stream."""
        if self._pos + n > self._buf.size:
            self._buf = np.concatenate((self._buf[self._pos:],
                                        self.rng.standard_normal(max(n, self._CHUNK))))
            self._pos = 0
        return self._buf[self._pos: self._pos + n]

    def skip(self, n: int) -> None:
        """Use up the next ``n`` values (drawn first where the buffer runs short, as
        :meth:`peek` draws them)."""
        if self._pos + n > self._buf.size:
            self.peek(n)
        self._pos += n

    def standard_normal(self, shape: int | tuple[int, ...]) -> np.ndarray:
        """The next values, as an array of ``shape``."""
        n = math.prod(shape) if isinstance(shape, tuple) else int(shape)
        out = self.peek(n).reshape(shape)
        self._pos += n
        return out


class ColouredNoise:
    """Bias instability and rate random walk on three axes, generated sample by sample.

    Parameters
    ----------
    bias_instability : float
        ``B`` in rad/s (0 = none).
    rate_random_walk : float
        ``K`` in rad/s/√s (0 = none).
    rng : numpy.random.Generator or Normals
        Seeded by the caller (a :class:`Normals` for :meth:`ahead`).
    """

    def __init__(self, bias_instability: float, rate_random_walk: float,
                 rng: np.random.Generator) -> None:
        if not (bias_instability >= 0 and rate_random_walk >= 0):
            raise ValueError("bias_instability and rate_random_walk must be >= 0, got "
                             f"{bias_instability!r}, {rate_random_walk!r}")
        self.q = flicker_component_sigma(bias_instability)
        self.k = float(rate_random_walk)
        self._rng = rng
        n = len(FLICKER_TIME_CONSTANTS_S)
        # stationary start: each component drawn from its steady-state distribution
        self._gm = rng.standard_normal((n, 3)) * self.q
        self._walk = np.zeros(3)

    @property
    def active(self) -> bool:
        """Whether there is anything to add."""
        return self.q > 0 or self.k > 0

    def draw(self, dt: np.ndarray) -> np.ndarray:
        """The noise (N, 3) at the ends of the ``N`` steps ``dt`` (s, each > 0), continuing from
        the previous call."""
        dt = np.asarray(dt, dtype=float).reshape(-1)
        n = dt.size
        out = np.zeros((n, 3))
        if n == 0 or not self.active:
            return out
        n_gm = _TAU.size if self.q > 0 else 0
        # one draw for every process, in the order they use it: each Gauss–Markov component's
        # (n, 3) steps, then the random walk's
        z = self._rng.standard_normal((n_gm + (self.k > 0), n, 3))
        if n_gm:
            phi = np.exp(-dt[None, :] / _TAU[:, None])  # (component, step)
            w = z[:n_gm] * (self.q * np.sqrt(1.0 - phi**2))[:, :, None]
            # a fixed step (to numpy.allclose's tolerance) filters with the first step's φ
            fixed = np.all(np.abs(phi - phi[:, :1]) <= 1e-8 + 1e-5 * np.abs(phi[:, :1]), axis=1)
            coef = np.where(fixed[:, None], phi[:, :1], phi)
            y = _first_order(coef, w, self._gm)
            self._gm = y[:, -1].copy()
            for j in range(n_gm):
                out += y[j]
        if self.k > 0:
            steps = z[-1] * (self.k * np.sqrt(dt))[:, None]
            walk = self._walk + np.cumsum(steps, axis=0)
            self._walk = walk[-1].copy()
            out += walk
        return out

    @property
    def draws_per_step(self) -> int:
        """Normals a one-step :meth:`draw` takes from the generator."""
        return 3 * ((_TAU.size if self.q > 0 else 0) + (self.k > 0))

    def state(self) -> tuple[np.ndarray, np.ndarray]:
        """The present state (the Gauss–Markov components', the walk's), for :meth:`resume`."""
        return self._gm, self._walk

    def ahead(self, dt: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """What :meth:`draw` would return called once for each step of ``dt`` (N,) in turn,
        to the last bit, without drawing: ``(noise (N, 3), states (N, J, 3), walks (N, 3))``,
        ``states[i]`` and ``walks[i]`` the state after step ``i`` (:meth:`resume`). The
        generator must be a :class:`Normals`."""
        dt = np.asarray(dt, dtype=float).reshape(-1)
        n = dt.size
        n_gm = _TAU.size if self.q > 0 else 0
        out = np.zeros((n, 3))
        gms = np.empty((n, n_gm, 3))
        walks = np.empty((n, 3))
        if n == 0 or not self.active:
            return out, gms, walks
        per = n_gm + (self.k > 0)
        # each one-step draw's normals, (components, 1, 3) in the generator's order
        z = self._rng.peek(3 * per * n).reshape(n, per, 3)  # type: ignore[union-attr]
        if n_gm:
            phi = np.exp(-dt[None, :] / _TAU[:, None])  # (component, step)
            w = z[:, :n_gm] * (self.q * np.sqrt(1.0 - phi**2)).T[:, :, None]
            x = self._gm
            for i in range(n):  # a one-step draw filters with its own step's φ
                x = phi[:, i, None] * x + w[i]
                gms[i] = x
            for j in range(n_gm):
                out += gms[:, j]
        if self.k > 0:
            steps = z[:, -1] * (self.k * np.sqrt(dt))[:, None]
            walks = np.cumsum(np.vstack((self._walk[None, :], steps)), axis=0)[1:]
            out += walks
        return out, gms, walks

    def resume(self, gm: np.ndarray, walk: np.ndarray, steps: int) -> None:
        """Take up a state :meth:`ahead` gave, after ``steps`` one-step draws: as if they had
        been made."""
        if self.q > 0:
            self._gm = gm
        if self.k > 0:
            self._walk = walk
        self._rng.skip(self.draws_per_step * steps)  # type: ignore[union-attr]


#: :data:`FLICKER_TIME_CONSTANTS_S` as an array.
_TAU = np.asarray(FLICKER_TIME_CONSTANTS_S)
#: Up to this many steps :func:`_first_order` runs its loop in numpy over the components; longer
#: runs go through one first-order filter per component
#: (:func:`~gyrocal.drivers.emulated.iir.lfilter`).
_LOOP_STEPS = 24


def _first_order(coef: np.ndarray, w: np.ndarray, x0: np.ndarray) -> np.ndarray:
    """``x_k = coef_k x_k−1 + w_k`` from ``x0`` for each component: ``coef`` (J, n), ``w`` (J,
    n, 3), ``x0`` (J, 3); returns every ``x_k``, (J, n, 3). A component whose ``coef`` is
    constant goes through :func:`~gyrocal.drivers.emulated.iir.lfilter` on long runs, which
    computes the same products and sums in the same order."""
    J, n = coef.shape
    y = np.empty_like(w)
    if n <= _LOOP_STEPS:
        x = x0
        for i in range(n):
            x = coef[:, i, None] * x + w[:, i]
            y[:, i] = x
        return y
    for j in range(J):
        c = coef[j]
        if np.all(c == c[0]):
            y[j], _ = lfilter([1.0], [1.0, -c[0]], w[j], zi=(c[0] * x0[j])[None, :])
        else:
            x = x0[j]
            for i in range(n):
                x = c[i] * x + w[j, i]
                y[j, i] = x
    return y
