"""One Kalman step per closed update window, and the health tests that follow it.

Model
-----
The calibration model (paper Eq. 1) is ``g = scale ∘ (m + b)``, or with the full model of a
Calibration v2 ``g = A (m + b)`` (``A = diag(scale)`` for v1), so a reading is
``m = A⁻¹ g − b + v`` with white noise ``v`` of per-sample variance ``σ² = N²·odr``. A
Calibration v2 with ``g_sensitivity`` adds ``G f`` (``g = A (m + b + G f)``, ``f`` the specific
force at the sensor in g, sensor frame): where the caller gives ``f`` for its samples, every
reading enters the filter as ``m + G f`` (the detector, the measurements and the corrected
rate alike), so ``b`` stays the zero-g bias; without ``f`` the tracker follows ``b + G f`` of
the pose the sensor holds. The bias
``b`` (Calibration v1 convention: added to the reading) is the state; optionally a linear
temperature coefficient ``c`` joins it, ``b(T) = b_ref + c ∘ (T − T_ref)``:

    x = [b_ref (3)]                 or  x = [b_ref (3), c (3)],
    F = I,   Q = diag(K²·Δt [, K_c²·Δt]),

a random walk with the rate-random-walk coefficient ``K`` of the noise characterisation (or one
given by the user), each axis independent.

Measurements
------------
Each closed update window (:mod:`gyrocal.calib.tracker.pooling`) is one textbook Kalman step
(``x, P, F, Q, H, R``; with ``F = I`` and diagonal ``Q``, ``R`` and prior the axes are
independent, so it is written out per axis in floats, equal to
:class:`gyrocal.calib.kalman.KalmanFilter`'s matrix step to rounding):

    x⁻ = F x,  P⁻ = F P Fᵀ + Q,
    y = z̄ − H x⁻,  S = H P⁻ Hᵀ + R,  K = P⁻ Hᵀ S⁻¹,
    x = x⁻ + K y,  P = (I − K H) P⁻ (I − K H)ᵀ + K R Kᵀ   (Joseph form).

Health
------
The normalised innovation squared ``ε = yᵀ S⁻¹ y`` of a consistent filter is χ²(3); the sum over
the last ``nis_window`` updates is χ²(3·window) (Bar-Shalom, Li & Kirubarajan, *Estimation with
Applications to Tracking and Navigation*, §5.4). When the sum exceeds its ``1 − nis_alpha``
quantile the health flag fires; with ``recover`` the bias covariance is then widened by the
squared last innovation, so that the filter follows a real bias jump instead of averaging it
away. The time since the last measurement update is the other health figure.

Bias steps
----------
A step in the bias shifts the innovations' mean. The NIS test sums squared innovations over a
few updates and misses a step smaller than their spread; a two-sided CUSUM (Page 1954) on each
axis's normalised innovation ``e = y/√S`` accumulates the shift instead (``g⁺ ← max(0, g⁺ + e −
k)``, ``g⁻ ← max(0, g⁻ − e − k)``, alarm above ``h``; with ``k = 0.5, h = 10`` a consistent
filter raises a false alarm about once in 10⁵ updates per axis and side). On an alarm the axis's
bias variance is widened (``recover``), so the filter follows the new bias within a few updates.

The seed
--------
A calibration's bias is the seed; a MEMS gyro's bias moves between power cycles by more than
a calibration's σ (MPU-9250 initial zero-rate tolerance ±5 °/s). The first update windows test
the seed (:meth:`KalmanStep._seed_check`): an axis whose innovation is beyond ``moved_sigma``
of its standard deviation has its prior widened by the squared innovation before the update,
so the estimate takes the measured bias at the first rest, and the tracker reports how far
the bias moved (:class:`gyrocal.calib.tracker.results.BiasMoved`).
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from typing import Any

import numpy as np
from scipy.special import chdtri  # χ² quantiles without scipy.stats' import cost

from gyrocal.calib.tracker.pooling import KIND_REF, OpenWindow
from gyrocal.calib.tracker.results import BiasMoved

__all__ = ["KalmanStep"]


class KalmanStep:
    """Mixin of :class:`~gyrocal.calib.tracker.BiasTracker`: the Kalman step of a closed
    window, the seed check, the NIS and CUSUM tests and the process-noise bank's update."""

    def _bound(self, k: int) -> float:
        b = self._bound_cache.get(k)
        if b is None:
            b = float(chdtri(3 * k, self.settings.nis_alpha))
            self._bound_cache[k] = b
        return b

    def _apply_window(self, w: OpenWindow, log: dict[str, list[Any]], close: int,
                      defer: bool = False) -> None:
        """One Kalman step (predict to the window's end, update with its mean).

        The state is axis-decoupled (``F = I``, ``Q``, ``R`` diagonal, ``H = [−I]`` or
        ``[−I, −ΔT I]``, a diagonal prior): each axis is a one- or two-state filter with a
        scalar reading, so the textbook step (module docstring) is written out per axis in
        floats. The new state ``x`` takes effect at once; the rest (the Joseph-form covariance,
        the health tests, the process-noise bank) is :meth:`_step_rest`, run here, or with
        ``defer`` (:meth:`update`) a slice per following call: every reading of what it
        produces (:attr:`bias_std`, :attr:`health`, :attr:`kf`, ...) finishes it first, and the
        next step does, so nothing observable changes, only which call pays."""
        self._catch_up()
        n = w.count
        z = [v / n for v in w.sum_z]
        R = [v / n for v in self._sigma2_l]
        if w.kind == KIND_REF:
            assert w.axis is not None
            R = self._reference_variance(R, w.sum_omega / n, w.axis, n / self.settings.odr_hz)
        dt = max(w.t_last - self._t_state, 0.0)
        q = self._q.tolist()
        x = self._kf.x.tolist()
        P = self._kf.P.tolist()
        tm = self._temp_model
        dT = w.sum_temp / n - (self._t_ref if self._t_ref is not None else 0.0) if tm else 0.0
        wide = self._seed_check(w, z, x, P, R, q, dt, dT) if self._seed_armed else None
        pre = []  # per axis: predicted P00, P01, P11, innovation y, S, gains k0, k1
        for i in range(3):
            p00 = P[i][i] + q[i] * dt
            if wide is not None:
                p00 += wide[i]
            if tm:
                p01 = P[i][i + 3]
                p11 = P[i + 3][i + 3] + q[i + 3] * dt
                ph0, ph1 = -(p00 + dT * p01), -(p01 + dT * p11)  # P⁻ hᵀ, h = [−1, −ΔT]
                y = z[i] + x[i] + dT * x[i + 3]
                S = R[i] - ph0 - dT * ph1
                k0, k1 = ph0 / S, ph1 / S
                x[i] += k0 * y
                x[i + 3] += k1 * y
            else:
                p01 = p11 = k1 = 0.0
                y = z[i] + x[i]
                S = p00 + R[i]
                k0 = -p00 / S
                x[i] += k0 * y
            pre.append((p00, p01, p11, y, S, k0, k1))
        self._kf.x = np.array(x)
        self._t_state = max(self._t_state, w.t_last)
        self._t_update = w.t_last
        self._n_updates += 1
        rest = self._step_rest(pre, z, R, dt, dT, w, log, close, wide)
        if defer:
            self._todo.append(rest)
        else:
            for _ in rest:
                pass

    def _seed_check(self, w: OpenWindow, z: list[float], x: list[float], P: list[list[float]],
                    R: list[float], q: list[float], dt: float, dT: float) -> list[float] | None:
        """Whether the bias moved since calibration, on the first update windows: the
        innovation ``y`` of each axis against its standard deviation ``√S`` (``S`` the seed's
        variance, the random walk since and the window's noise). Beyond ``moved_sigma`` the
        axis's prior variance is to be widened by ``y²`` (returned per axis, None when no axis
        is beyond), so the update takes the measured bias, and :attr:`bias_moved` says so. The
        check stays armed until a full window (``update_interval_s``) has passed it or it
        fired."""
        tm = self._temp_model
        ys, ss = [], []
        for i in range(3):
            p00 = P[i][i] + q[i] * dt
            if tm:
                p01, p11 = P[i][i + 3], P[i + 3][i + 3] + q[i + 3] * dt
                ys.append(z[i] + x[i] + dT * x[i + 3])
                ss.append(p00 + 2 * dT * p01 + dT * dT * p11 + R[i])
            else:
                ys.append(z[i] + x[i])
                ss.append(p00 + R[i])
        thr = self.settings.moved_sigma
        beyond = [abs(y) > thr * math.sqrt(v) for y, v in zip(ys, ss, strict=True)]
        if any(beyond):
            self._seed_armed = False
            self._moved = BiasMoved(
                t=w.t_last, moved=np.array([-y for y in ys]), sigma=np.sqrt(np.array(ss)),
                axes=tuple(a for a, b in zip("xyz", beyond, strict=True) if b),
                kind="reference" if w.kind == KIND_REF else "still")
            return [y * y if b else 0.0 for y, b in zip(ys, beyond, strict=True)]
        if w.count >= self._U:
            self._seed_armed = False
        return None

    def _reference_variance(self, R: list[float], omega: float,
                            u: tuple[float, float, float], dur: float) -> list[float]:
        """``R`` plus the variance the reference ``A⁻¹ ω u`` carries, to first order in
        ``d(A⁻¹) = −A⁻¹ dA A⁻¹`` (entries of ``A`` independent): the calibration's matrix
        uncertainty, the axis uncertainty and the encoder resolution over the window ``dur``."""
        s = self.settings
        ai = self._A_inv_rows
        g = [omega * (r[0] * u[0] + r[1] * u[1] + r[2] * u[2]) for r in ai]
        g2 = [v * v for v in g]
        c_axis = (omega * s.reference_axis_std) ** 2
        c_enc = math.sqrt(2.0) * s.reference_angle_std / dur
        out = []
        for i in range(3):
            M, r = self._ai2_astd2[i], ai[i]
            e = c_enc * (r[0] * u[0] + r[1] * u[1] + r[2] * u[2])
            out.append(R[i] + (M[0] * g2[0] + M[1] * g2[1] + M[2] * g2[2])
                       + c_axis * self._ai2_rowsum[i] + e * e)
        return out

    def _step_rest(self, pre: list[tuple[float, ...]], z: list[float], R: list[float],
                   dt: float, dT: float, w: OpenWindow, log: dict[str, list[Any]], close: int,
                   wide: list[float] | None = None) -> Iterator[None]:
        """The rest of a Kalman step whose state :meth:`_apply_window` applied: the covariance
        in Joseph form, ``P = (I − k h) P⁻ (I − k h)ᵀ + k r kᵀ`` per axis, the NIS and CUSUM
        tests, then the process-noise bank (:meth:`QBank.steps`), yielding between slices."""
        s = self.settings
        kf = self._kf
        tm = self._temp_model
        Pn = kf.P.tolist()
        ys, Ss = [], []
        for i, (p00, p01, p11, y, S, k0, k1) in enumerate(pre):
            if tm:
                # I − k h = [[1 + k0, k0 ΔT], [k1, 1 + k1 ΔT]]
                a, b, c, d = 1.0 + k0, k0 * dT, k1, 1.0 + k1 * dT
                m00, m01 = a * p00 + b * p01, a * p01 + b * p11
                m10, m11 = c * p00 + d * p01, c * p01 + d * p11
                Pn[i][i] = m00 * a + m01 * b + k0 * k0 * R[i]
                Pn[i][i + 3] = Pn[i + 3][i] = m00 * c + m01 * d + k0 * k1 * R[i]
                Pn[i + 3][i + 3] = m10 * c + m11 * d + k1 * k1 * R[i]
            else:
                Pn[i][i] = (1.0 + k0) ** 2 * p00 + k0 * k0 * R[i]
            ys.append(y)
            Ss.append(S)
        yield
        kf.P = np.array(Pn)
        yield
        qdt = self._q * dt
        yield
        kf.Q = np.diag(qdt)
        yield
        nis = sum(yi * yi / si for yi, si in zip(ys, Ss, strict=True))
        yield
        bank_extra = [0.0, 0.0, 0.0]
        shift = self._cusum(ys, Ss, bank_extra)
        yield
        self._nis_hist.append(nis)
        k = len(self._nis_hist)
        total = float(sum(self._nis_hist))
        bound = self._bound(k)
        alarm = total > bound
        self._nis_last, self._nis_sum, self._nis_bound = nis, total, bound
        if alarm:
            self._n_alarms += 1
            if s.recover:
                y2 = [yi * yi for yi in ys]
                P = kf.P.copy()
                P[np.arange(3), np.arange(3)] += y2
                bank_extra = [a + b for a, b in zip(bank_extra, y2, strict=True)]
                kf.P = P
            self._nis_hist.clear()
        self._nis_ok = not alarm
        if wide is not None:  # the seed was wider than it said (_seed_check): so was the state
            self._widen_kept(wide)  # before this update, for the smoother
        self._keep_state(kf.Q, brk=bool(alarm and s.recover) or (shift and s.recover))
        yield
        log["shift"].append(shift)
        log["t"].append(w.t_last)
        log["kind"].append("reference" if w.kind == KIND_REF else "still")
        log["count"].append(w.count)
        log["nis"].append(nis)
        log["nis_sum"].append(total)
        log["nis_bound"].append(bound)
        log["alarm"].append(alarm)
        log["at"].append(close)
        if self._bank is not None:
            yield
            bank = self._bank
            if wide is not None:  # the seed's widening, before the bank's update as before ours
                bank.widen(np.array(wide))
            yield from bank.steps(z, R, dT if tm else None, dt)
            # a detected step widened every filter of the bank as the tracker's own (after the
            # bank's update, as the tracker's widening came after its own)
            if any(bank_extra):
                bank.widen(np.array(bank_extra))
            yield
            self._q[:3] = bank.q + bank.q_std

    def _cusum(self, y: list[float], s_diag: list[float], bank_extra: list[float]) -> bool:
        """Two-sided CUSUM (Page 1954) on each axis's normalised innovation ``e = y/√S``.

        ``g⁺ ← max(0, g⁺ + e − k)``, ``g⁻ ← max(0, g⁻ − e − k)``; a sum above ``h`` says the
        innovations' mean has shifted (a bias step the NIS window is too short or too coarse
        to see). With ``recover``, the axis's bias variance is then widened by four times the
        squared mean innovation since the sum last left zero (the size of the shift the filter
        has not yet followed), so the next updates move the estimate to the new bias; the same
        widening of the process-noise bank is added to ``bank_extra``.
        """
        s = self.settings
        if not math.isfinite(s.cusum_h):
            return False
        # per axis and side in Python floats (six numbers: numpy's per-call cost dominates)
        cu, cu_sum, cu_n = self._cu, self._cu_sum, self._cu_n
        k, h = s.cusum_k, s.cusum_h
        hit = [[False] * 3, [False] * 3]
        for i in range(3):
            yi = y[i]
            e = yi / math.sqrt(s_diag[i])
            for side, step in ((0, e - k), (1, -e - k)):
                c, c_sum, c_n = cu[side], cu_sum[side], cu_n[side]
                if c[i] <= 0.0:  # the sum left zero: its mean innovation starts afresh
                    c_sum[i], c_n[i] = yi, 1.0
                else:
                    c_sum[i] += yi
                    c_n[i] += 1.0
                g = c[i] + step
                c[i] = g if g > 0.0 else 0.0
                hit[side][i] = g > h
        axes = [i for i in range(3) if hit[0][i] or hit[1][i]]
        if not axes:
            return False
        self._n_shifts += 1
        if s.recover:
            P = self._kf.P.copy()
            for i in axes:
                side = 0 if hit[0][i] else 1
                mean_y = cu_sum[side][i] / cu_n[side][i]
                P[i, i] += 4.0 * mean_y**2
                bank_extra[i] += 4.0 * mean_y**2
            self._kf.P = P
        for i in axes:
            for side in (0, 1):
                cu[side][i] = cu_sum[side][i] = cu_n[side][i] = 0.0
        return True
