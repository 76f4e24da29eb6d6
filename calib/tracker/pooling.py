"""Pooling decided samples into update windows (the measurements of the Kalman step).

*Zero-rate*: while the sensor is still, ``m = −b(T) + v``. *Reference-rate*: while a servo of
the jig turns at a known rate ``ω`` (from its encoder) about a known axis ``u`` (unit, sensor
frame), ``m − A⁻¹ ω u = −b(T) + v``. Both have ``H = [−I]`` or ``[−I, −(T − T_ref) I]``.

Consecutive samples of one kind are pooled into update windows of at most
``update_interval_s``: the window mean ``z̄`` with ``H̄`` at the mean temperature and
``R = σ²/n`` (plus, for reference windows, the variance the calibration's scale uncertainty,
the axis uncertainty and the encoder resolution put on ``A⁻¹ ω u``, to first order in
``d(A⁻¹) = −A⁻¹ dA A⁻¹``). For a bias constant
over the window this is exactly the result of ``n`` sequential per-sample updates (the sum of
``n`` identical-H information terms), at a fraction of the cost; averaging readings and the
encoder rate over the same window is also what makes a reference rate right (speed ripple
cancels).

Two ways pool alike, closing the same windows at the same samples: a sample at a time
(:meth:`WindowPooling._window_step`, as :meth:`~gyrocal.calib.tracker.BiasTracker.update` and
small batches do) and with array operations over a batch
(:meth:`WindowPooling._pool_rows_vectorised`). A window closes when it holds
``update_interval_s`` of samples, or when a sample of another kind (or another servo axis)
arrives; a closed window goes to the Kalman step (:mod:`gyrocal.calib.tracker.step`).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from gyrocal.calib.tracker.results import UpdateLog

__all__ = ["KIND_NONE", "KIND_REF", "KIND_STILL", "LOG_KEYS", "NO_LOG", "OpenWindow", "Snapshot",
           "WindowPooling"]

#: What a decided sample is: not used, a zero-rate (still) sample, a reference-rate sample.
KIND_NONE, KIND_STILL, KIND_REF = 0, 1, 2
#: What each Kalman step logs (:meth:`KalmanStep._step_rest`), gathered into an UpdateLog.
LOG_KEYS = ("t", "kind", "count", "nis", "nis_sum", "nis_bound", "alarm", "at", "shift")
#: Decided rows that a batch pools one at a time, as update() does (numpy's fixed cost per
#: call outweighs the work below this).
ROWS_ONE_BY_ONE = 64


@dataclass
class OpenWindow:
    """An update window being filled: its kind, servo axis, sums and last sample."""

    kind: int
    axis: tuple[float, float, float] | None
    last: int
    count: int
    sum_z: list[float]  # three floats: the window's readings (less the reference) summed
    sum_temp: float
    sum_omega: float
    t_last: float


@dataclass
class Snapshot:
    """The filter's state after one closed window (a batch's per-sample output reads it)."""

    close: int
    x: np.ndarray
    P: np.ndarray
    t_state: float
    t_update: float
    nis_ok: bool
    q: np.ndarray



class _Discard:
    """A list that keeps nothing (the update log of :meth:`BiasTracker.update`)."""

    def append(self, value: Any) -> None:
        pass


#: A throwaway update log (:meth:`BiasTracker.update` returns no log): appending costs nothing.
NO_LOG: dict[str, Any] = {k: _Discard() for k in LOG_KEYS}


class WindowPooling:
    """Mixin of :class:`~gyrocal.calib.tracker.BiasTracker`: the open update window and the
    pooling of decided samples into it (the tracker's state: ``_open``, ``_U``, ``_A_inv``,
    ``_A_inv_rows``, ``_temp_model``; the close goes to ``_apply_window``)."""

    def _window_step(self, g: int, L: int, t: float, m: tuple[float, float, float],
                     temp: float, kind: int, rr: float = math.nan,
                     axis: tuple[float, float, float] | None = None,
                     close: Callable[[OpenWindow, int], None] | None = None) -> None:
        """Pool the decided sample ``g`` (reading ``m``, of ``kind``; with a reference its
        encoder rate ``rr`` and servo axis) into the open update window, closing the window
        where :meth:`_pool_rows_vectorised` closes it; in floats, as the window's sums are
        kept. ``close(window, at)`` applies a closed window (default: :meth:`update`'s, the
        rest of the step deferred, no log)."""
        if close is None:
            close = self._close_deferred
        op = self._open
        if op is not None and not (kind == op.kind and axis == op.axis):
            close(op, g + L)
            self._open = op = None
        if kind == KIND_NONE:
            return
        z0, z1, z2 = m
        if kind == KIND_REF:  # z = m − A⁻¹ ω u, the reading less the reference
            assert axis is not None
            ai = self._A_inv_rows
            w0, w1, w2 = rr * axis[0], rr * axis[1], rr * axis[2]
            z0 -= ai[0][0] * w0 + ai[0][1] * w1 + ai[0][2] * w2
            z1 -= ai[1][0] * w0 + ai[1][1] * w1 + ai[1][2] * w2
            z2 -= ai[2][0] * w0 + ai[2][1] * w1 + ai[2][2] * w2
            omega = rr
        else:
            omega = 0.0
        sum_temp = temp if self._temp_model else 0.0
        if op is None:
            op = OpenWindow(kind=kind, axis=axis, last=g, count=1, sum_z=[z0, z1, z2],
                             sum_temp=sum_temp, sum_omega=omega, t_last=t)
        else:
            op.count += 1
            sz = op.sum_z
            sz[0] += z0
            sz[1] += z1
            sz[2] += z2
            op.sum_temp += sum_temp
            op.sum_omega += omega
            op.last = g
            op.t_last = t
        if op.count == self._U:
            close(op, op.last + L)
            self._open = None
        else:
            self._open = op

    def _close_deferred(self, w: OpenWindow, at: int) -> None:
        """:meth:`update`'s window close: the state at once, the rest of the step deferred."""
        self._apply_window(w, NO_LOG, at, defer=True)

    def _snapshot(self, close: int) -> Snapshot:
        return Snapshot(
            close=close,
            x=self._kf.x.copy(),
            P=self._kf.P.copy(),
            t_state=self._t_state,
            t_update=self._t_update,
            nis_ok=self._nis_ok,
            q=self._q.copy(),
        )

    def _assemble_and_apply(
        self, S: dict[str, np.ndarray], n_dec: int, kind: np.ndarray, g0: int, finish: bool
    ) -> tuple[list[Snapshot], UpdateLog]:
        """Pool decided samples into update windows and apply the closed ones in order: a few
        rows one at a time (:meth:`_window_step`, as :meth:`update` pools them; numpy's
        per-call cost would dominate), more with array operations
        (:meth:`_pool_rows_vectorised`); both close the same windows at the same rows."""
        L = self.detector.n_lookahead
        snaps = [self._snapshot(-1)]
        log: dict[str, list[Any]] = {k: [] for k in LOG_KEYS}

        def apply(w: OpenWindow, close: int) -> None:
            self._apply_window(w, log, close)
            snaps.append(self._snapshot(close))

        if n_dec <= ROWS_ONE_BY_ONE:
            cols = [S[k][:n_dec].tolist() for k in ("t", "m", "temp", "rr", "ra")]
            for i, (t, m, temp, rr, ra) in enumerate(zip(*cols, strict=True)):
                k = int(kind[i])
                self._window_step(g0 + i, L, t, tuple(m), temp, k, rr,
                                  tuple(ra) if k == KIND_REF else None, apply)
        elif n_dec:
            self._pool_rows_vectorised(S, n_dec, kind, g0, apply)
        if finish and self._open is not None:
            apply(self._open, self._open.last + 1 + L)
            self._open = None
        return snaps, UpdateLog(
            t=np.array(log["t"], dtype=float),
            kind=np.array(log["kind"], dtype=object),
            count=np.array(log["count"], dtype=np.int64),
            nis=np.array(log["nis"], dtype=float),
            nis_sum=np.array(log["nis_sum"], dtype=float),
            nis_bound=np.array(log["nis_bound"], dtype=float),
            alarm=np.array(log["alarm"], dtype=bool),
            applied_at=np.array(log["at"], dtype=np.int64),
            shift=np.array(log["shift"], dtype=bool),
        )

    def _pool_rows_vectorised(self, S: dict[str, np.ndarray], n_dec: int, kind: np.ndarray,
                              g0: int, apply: Callable[[OpenWindow, int], None]) -> None:
        """:meth:`_assemble_and_apply`'s pooling with array operations: runs of one kind (and
        one servo axis), cut into windows of at most ``U`` rows, each closed window applied."""
        L = self.detector.n_lookahead
        U = self._U
        ra = S["ra"][:n_dec]
        # z_i: the reading, less the reference's A⁻¹ ω u where a servo turns
        z = S["m"][:n_dec].copy()
        is_ref = kind == KIND_REF
        if is_ref.any():
            z[is_ref] -= (S["rr"][:n_dec][is_ref, None] * ra[is_ref]) @ self._A_inv.T
        # run starts: kind changes, or a different servo axis within reference samples
        new_run = np.ones(n_dec, dtype=bool)
        if n_dec > 1:
            same_axis = np.all(ra[1:] == ra[:-1], axis=1) | ~is_ref[1:]
            new_run[1:] = (kind[1:] != kind[:-1]) | ~same_axis
        op = self._open
        continues = False
        if op is not None:
            k0 = int(kind[0])
            axis0 = tuple(float(x) for x in ra[0]) if k0 == KIND_REF else None
            continues = k0 == op.kind and axis0 == op.axis
            if not continues:
                apply(op, g0 + L)  # closed by the decision on S[0], made at g0 + L
                self._open = op = None
        new_run[0] = not continues
        idx = np.arange(n_dec)
        run_start = np.maximum.accumulate(np.where(new_run, idx, 0))
        offset = np.where(run_start == 0, op.count if continues and op else 0, 0)
        pos = idx - run_start + offset
        active = kind != KIND_NONE
        win_start = active & ((pos % U == 0) | new_run)
        if continues:
            win_start[0] = False
        starts = np.flatnonzero(win_start)
        # windows: [start, end) in decided rows; the first may be the continued open window
        bounds = list(starts)
        if continues:
            bounds = [0, *bounds]
        bounds_arr = np.array(bounds, dtype=np.int64)
        # each window runs to the earlier of the next window start or the end of its run
        ends_at = np.flatnonzero(np.append(new_run[1:], True))  # last row of each run
        # exclusive end of the run of each row
        run_id = np.cumsum(new_run) - int(new_run[0])  # the first run may continue
        run_end = ends_at[run_id] + 1
        for wi, b in enumerate(bounds_arr):
            nxt = bounds_arr[wi + 1] if wi + 1 < bounds_arr.size else n_dec
            e = int(min(nxt, run_end[b]))
            rows = slice(int(b), e)
            cnt = e - int(b)
            sum_z = z[rows].sum(axis=0).tolist()
            sum_temp = float(np.sum(S["temp"][rows])) if self._temp_model else 0.0
            sum_omega = float(np.sum(S["rr"][rows])) if kind[b] == KIND_REF else 0.0
            if wi == 0 and continues and op is not None:
                w = op
                w.count += cnt
                w.sum_z = [a + b for a, b in zip(w.sum_z, sum_z, strict=True)]
                w.sum_temp += sum_temp
                w.sum_omega += sum_omega
                w.last = g0 + e - 1
                w.t_last = float(S["t"][e - 1])
            else:
                w = OpenWindow(
                    kind=int(kind[b]),
                    axis=tuple(float(x) for x in ra[b]) if kind[b] == KIND_REF else None,
                    last=g0 + e - 1,
                    count=cnt,
                    sum_z=sum_z,
                    sum_temp=sum_temp,
                    sum_omega=sum_omega,
                    t_last=float(S["t"][e - 1]),
                )
            if w.count == U:
                apply(w, w.last + L)
                self._open = None
            elif e < n_dec:  # ended by a row of another kind (or another axis)
                apply(w, w.last + 1 + L)
                self._open = None
            else:
                self._open = w
