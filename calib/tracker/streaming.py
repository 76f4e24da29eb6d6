"""Streams: :meth:`~gyrocal.calib.tracker.BiasTracker.update` a sample at a time in scalar
code, and :meth:`~gyrocal.calib.tracker.BiasTracker.feed` into blocks.

:meth:`BiasTracker.process` takes a batch ``(t, rate (n, 3), temperature (n,) or None,
still (n,) or None, reference_rate, reference_axis)`` and carries everything a later batch needs
(the detector's last window, the samples whose still decision is still open, the open update
window), so a recording processed at once and the same samples fed one at a time through
:meth:`BiasTracker.update` give the same estimates. The still decision on a sample comes
``lookahead_s`` after it (see :mod:`gyrocal.calib.stationarity`); an external ``still`` flag
overrides the detector's decision for its sample. The detector never looks at the estimate it
feeds (a detector gated on the tracker's own bias never sees a sensor whose bias moved since
calibration, so the filter would never correct it): its variance test needs no bias, and its
rate test is centred on the seed (the calibration's bias) with room for the chip's whole
zero-rate tolerance (``zero_rate_tolerance``).

:meth:`BiasTracker.update` does the arithmetic of a one-sample :meth:`process` call in scalar
code (the detector's window by running sums, :class:`gyrocal.calib.stationarity.StreamingQuiet`;
the update window's sums; the output from the current state), with the same estimates to
rounding. The Kalman step of a closing update window is written out per axis (the state is
axis-decoupled); the closing call applies the new state ``x`` (all the corrected rate needs), and
the rest of the step (the Joseph-form covariance, the NIS and CUSUM tests, the process-noise
bank) runs a slice per following call, so no call pays a whole step. Reading what that rest
produces (:attr:`BiasTracker.bias_std`, :attr:`BiasTracker.health`, :attr:`BiasTracker.kf`, the
random walk, :meth:`BiasTracker.smoothed`) or calling :meth:`process` finishes it first, and so
does the next step: every observable equals the batch path's. A :meth:`BiasTracker.process`
call of a few samples (a FIFO drain) pools them into update windows the same way, a row at a
time, where array operations would cost more than the work.
:meth:`BiasTracker.feed` instead fuses samples into blocks of ``stream_block_s``: each
sample is corrected at once with the latest estimate (the estimate only changes at update
windows, ``update_interval_s`` apart, and the still decision lags by ``lookahead_s`` anyway),
and every full block goes through :meth:`process`. The filter therefore sees exactly the samples
of a batch run and ends in the same state; a corrected sample uses an estimate at most one block
older than the batch run's.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from gyrocal.calib.errors import CalibInputError
from gyrocal.calib.stationarity import StreamingQuiet
from gyrocal.calib.tracker.pooling import KIND_NONE, KIND_REF, KIND_STILL
from gyrocal.calib.tracker.results import TrackResult

__all__ = ["Streaming"]

_DONE = object()  # a finished generator's next()


class Streaming:
    """Mixin of :class:`~gyrocal.calib.tracker.BiasTracker`: :meth:`update`, :meth:`feed`,
    :meth:`flush` and the deferred rest of a step (``_todo``)."""

    def update(
        self,
        sample: Any,
        t: float,
        temperature: float | None = None,
        still: bool | None = None,
        *,
        reference_rate: float | None = None,
        reference_axis: Any = None,
        specific_force: Any = None,
        accel: Any = None,
    ) -> np.ndarray:
        """Feed one reading; returns its corrected rate ``A (m + bias [+ G f])``, rad/s.

        Parameters
        ----------
        sample : array_like (3,)
            The reading ``m``, rad/s.
        t : float
            Its time, s (strictly increasing).
        temperature : float, optional
            Die temperature, °C (required with the temperature model).
        still : bool, optional
            External still flag; None lets the detector decide.
        reference_rate : float, optional
            Rate of the turning servo from its encoder, rad/s (jig only).
        reference_axis : array_like (3,), optional
            That servo's unit axis in the sensor frame.
        specific_force : array_like (3,), optional
            Specific force at the sensor, g, sensor frame: with the calibration's
            g-sensitivity the reading counts as ``m + G f`` (ignored without it).
        accel : array_like (3,), optional
            The accelerometer's reading, m/s² (required with ``accel_noise_std``: the
            detector's accelerometer veto; such a tracker takes the one-sample
            :meth:`process` path, the scalar path being the gyro's alone).

        Returns
        -------
        ndarray (3,)
        """
        fast = None if self.accel_detector is not None else self._update_fast(
            sample, t, temperature, still, reference_rate, reference_axis, specific_force)
        if fast is not None:
            return fast
        m = np.asarray(sample, dtype=float)
        if m.shape != (3,):
            raise CalibInputError(f"sample must be 3 numbers (rad/s), got shape {m.shape}")
        if (reference_rate is None) != (reference_axis is None):
            raise CalibInputError("give reference_rate and reference_axis together")
        res = self.process(
            np.array([t], dtype=float),
            m[None, :],
            None if temperature is None else np.array([temperature], dtype=float),
            None if still is None else np.array([1.0 if still else 0.0]),
            reference_rate=None if reference_rate is None else np.array([reference_rate], float),
            reference_axis=None
            if reference_axis is None
            else np.asarray(reference_axis, dtype=float).reshape(1, -1),
            specific_force=None if specific_force is None
            else np.asarray(specific_force, dtype=float).reshape(1, -1),
            accel=None if accel is None else np.asarray(accel, dtype=float).reshape(1, -1),
        )
        return res.corrected[0]

    def _update_fast(
        self, sample: Any, t: Any, temperature: Any, still: Any, reference_rate: Any,
        reference_axis: Any, specific_force: Any = None,
    ) -> np.ndarray | None:
        """:meth:`update` for the common sample (valid, not the first), with or without a
        reference rate: the same arithmetic as a one-sample :meth:`process` call, without its
        per-call overhead. Returns None where the general path must run (it also names bad
        input)."""
        if self._k == 0 or self._finished or self._nbuf:
            return None
        try:
            m0, m1, m2 = _three_floats(sample)
            tf = float(t)
            temp = math.nan if temperature is None else float(temperature)
        except (TypeError, ValueError):
            return None
        if specific_force is not None and self._G_rows is not None:  # m + G f
            try:
                f0, f1, f2 = _three_floats(specific_force)
            except (TypeError, ValueError):
                return None
            if not (math.isfinite(f0) and math.isfinite(f1) and math.isfinite(f2)):
                return None
            G = self._G_rows
            m0 += G[0][0] * f0 + G[0][1] * f1 + G[0][2] * f2
            m1 += G[1][0] * f0 + G[1][1] * f1 + G[1][2] * f2
            m2 += G[2][0] * f0 + G[2][1] * f1 + G[2][2] * f2
        if (not (math.isfinite(m0) and math.isfinite(m1) and math.isfinite(m2)
                 and math.isfinite(tf))
                or self._t_last is None or not tf > self._t_last
                or (self._temp_model and not math.isfinite(temp))):
            return None
        ext = math.nan if still is None else (1.0 if still else 0.0)
        rr, axis = math.nan, None
        if reference_rate is not None or reference_axis is not None:
            ref = self._fast_reference(reference_rate, reference_axis, ext)
            if ref is None:
                return None
            rr, axis = ref
        if self._pending:  # samples a process() call left awaiting their decision
            pend = self._pending
            for i in range(pend["t"].size):
                r = float(pend["rr"][i])
                self._pq.append((float(pend["t"][i]), tuple(pend["m"][i].tolist()),
                                 float(pend["temp"][i]), float(pend["ext"][i]), r,
                                 tuple(float(v) for v in pend["ra"][i]) if math.isfinite(r)
                                 else None))
            self._pending = {}
        if self._todo:  # a slice of a step an earlier call left
            self._advance()
        k = self._k
        if self._t_ref is None and math.isfinite(temp):
            self._t_ref = temp
        # detector: the window ending at this sample, and the run of quiet windows
        det = self.detector
        sq = self._sq
        if sq is None:
            sq = self._sq = StreamingQuiet(det, self._hist)
        b = self._det_bias_l
        quiet = sq.push(m0 + b[0], m1 + b[1], m2 + b[2])
        self._run = self._run + 1 if quiet else 0
        # the still decision on the sample L back, and the update window it feeds
        pq = self._pq
        pq.append((tf, (m0, m1, m2), temp, ext, rr, axis))
        L = det.n_lookahead
        while len(pq) > L:
            g = k - len(pq) + 1
            td, md, tempd, extd, rrd, axd = pq.popleft()
            if axd is not None:  # a servo turns the sample: a reference, never still
                self._last_decision = (g, False)
                self._window_step(g, L, td, md, tempd, KIND_REF, rrd, axd)
                continue
            is_still = (self._run >= det.n_min + L) if math.isnan(extd) else extd > 0.5
            self._last_decision = (g, bool(is_still))
            self._window_step(g, L, td, md, tempd, KIND_STILL if is_still else KIND_NONE)
        return self._sample_output(m0, m1, m2, tf, temp)

    def _fast_reference(self, reference_rate: Any, reference_axis: Any, ext: float
                        ) -> tuple[float, tuple[float, float, float] | None] | None:
        """The reference of one :meth:`update` call as ``(rate, axis)`` (axis None where the
        rate is NaN: no servo turns), checked as :meth:`_validate` checks a batch; None where
        the general path must run (to name what is wrong)."""
        if reference_rate is None or reference_axis is None:
            return None
        try:
            rr = float(reference_rate)
        except (TypeError, ValueError):
            return None
        if math.isnan(rr):
            return rr, None
        if (not math.isfinite(rr) or ext == 1.0 or self.calibration is None
                or not self._ref_ready):
            return None
        try:
            u0, u1, u2 = _three_floats(reference_axis)
        except (TypeError, ValueError):
            return None
        if not (math.isfinite(u0) and math.isfinite(u1) and math.isfinite(u2)
                and abs(math.sqrt(u0 * u0 + u1 * u1 + u2 * u2) - 1.0) <= 1e-6):
            return None
        return rr, (u0, u1, u2)

    def _sample_output(self, m0: float, m1: float, m2: float, t: float, temp: float
                       ) -> np.ndarray:
        """Bias and the corrected rate at one sample from the current state (the one-row case
        of :meth:`_outputs`), in scalar arithmetic (three axes written out: this runs for every
        sample); its uncertainty is computed when :attr:`bias_std` is read (:meth:`_std_at`)."""
        key = (self._n_updates, self._t_ref)
        terms = self._out_terms
        if terms is None or terms[0] != key:
            terms = (key, self._kf.x.tolist(), self._A.ravel().tolist())
            self._out_terms = terms
        _, x, A = terms
        if self._temp_model:
            dT = temp - (self._t_ref if self._t_ref is not None else 0.0)
            b0, b1, b2 = x[0] + x[3] * dT, x[1] + x[4] * dT, x[2] + x[5] * dT
        else:
            b0, b1, b2 = x[0], x[1], x[2]
        c0, c1, c2 = m0 + b0, m1 + b1, m2 + b2
        out = np.array([A[0] * c0 + A[1] * c1 + A[2] * c2,
                        A[3] * c0 + A[4] * c1 + A[5] * c2,
                        A[6] * c0 + A[7] * c1 + A[8] * c2])
        self._k += 1
        self._t_last = t
        self._temp_last = temp
        self._last = {"bias": [b0, b1, b2], "bias_std": None, "since": t - self._t_update,
                      "t": t, "temp": temp}
        return out

    def _std_at(self, t: float, temp: float) -> list[float]:
        """The bias's one-sigma uncertainty at time ``t`` and temperature ``temp`` from the
        current state (the filter's prediction ``P + q (t − t_state)``, one row of
        :meth:`_outputs`)."""
        P = self._kf.P
        pd = np.diag(P).tolist()
        q = self._q.tolist()
        dt = t - self._t_state
        if dt < 0.0:
            dt = 0.0
        if self._temp_model:
            pbc = [float(P[i, i + 3]) for i in range(3)]
            dT = temp - (self._t_ref if self._t_ref is not None else 0.0)
            d2 = dT * dT
            v = [pd[i] + 2 * dT * pbc[i] + d2 * pd[i + 3] + (q[i] + q[i + 3] * d2) * dt
                 for i in range(3)]
        else:
            v = [pd[i] + q[i] * dt for i in range(3)]
        return [math.sqrt(x) if x > 0.0 else 0.0 for x in v]

    def _catch_up(self) -> None:
        """Finish every step :meth:`update` left to its following calls."""
        while self._todo:
            for _ in self._todo.popleft():
                pass

    def _advance(self) -> None:
        """One slice of the oldest step :meth:`update` left unfinished."""
        if next(self._todo[0], _DONE) is _DONE:
            self._todo.popleft()

    def feed(
        self, sample: Any, t: float, temperature: float | None = None, still: bool | None = None,
        specific_force: Any = None, *, reference_rate: float | None = None,
        reference_axis: Any = None, accel: Any = None,
    ) -> np.ndarray:
        """Fast streaming: buffer one reading, return it corrected with the latest estimate.

        Every ``stream_block_s`` of samples the block goes through :meth:`process` (see
        "Batches and streams" in the module docstring); :meth:`flush` processes a partial block.
        Bad values are refused when their block is processed, naming the problem. That call is
        the one long one (about half a millisecond on a desktop core, mostly fixed cost); at
        200 Hz and below, where a block holds a few dozen samples, :meth:`update` costs about
        as much per sample without it.

        Parameters
        ----------
        sample : array_like (3,)
            The reading ``m``, rad/s.
        t : float
            Its time, s (strictly increasing).
        temperature : float, optional
            Die temperature, °C (required with the temperature model).
        still : bool, optional
            External still flag; None lets the detector decide.
        specific_force : array_like (3,), optional
            Specific force at the sensor, g, sensor frame (as in :meth:`update`).
        reference_rate : float, optional
            Rate of the turning servo from its encoder, rad/s (jig only; as in :meth:`update`).
        reference_axis : array_like (3,), optional
            That servo's unit axis in the sensor frame (with ``reference_rate``).
        accel : array_like (3,), optional
            The accelerometer's reading, m/s² (as in :meth:`process`).

        Returns
        -------
        ndarray (3,)
            ``A (m + bias [+ G f])`` with the bias estimate at the end of the last processed
            block (at this sample's temperature with the temperature model).

        Raises
        ------
        CalibInputError
            A reading or an axis that is not three numbers, or a reference rate without its
            axis (or the reverse), at once; other bad values when their block is processed.
        """
        if (reference_rate is None) != (reference_axis is None):
            raise CalibInputError("give reference_rate and reference_axis together")
        i = self._nbuf
        if i == 0 and self._buf_m is None:
            B = max(1, int(round(self.settings.stream_block_s * self.settings.odr_hz)))
            self._buf_t = np.empty(B)
            self._buf_m = np.empty((B, 3))
            self._buf_temp = np.full(B, np.nan)
            self._buf_still = np.full(B, np.nan)
            self._buf_rr = np.full(B, np.nan)
            self._buf_ra = np.full((B, 3), np.nan)
            self._buf_acc = np.full((B, 3), np.nan)
            self._buf_has_ref = False
            self._buf_has_acc = False
        m = self._buf_m[i]
        try:
            m[:] = sample
            if reference_rate is not None:
                self._buf_ra[i] = reference_axis
                self._buf_rr[i] = reference_rate
                self._buf_has_ref = True
            if accel is not None:
                self._buf_acc[i] = accel
                self._buf_has_acc = True
        except (TypeError, ValueError):
            raise CalibInputError(
                "sample, reference_axis and accel must be 3 numbers each, and reference_rate a "
                "number"
            ) from None
        if specific_force is not None and self._G is not None:
            m += self._G @ self._force(specific_force, 1)[0]
        self._buf_t[i] = t
        if temperature is not None:
            self._buf_temp[i] = temperature
        if still is not None:
            self._buf_still[i] = 1.0 if still else 0.0
        self._nbuf = i + 1
        x = self._fx
        if self._temp_model and temperature is not None and self._t_ref is not None:
            out = self._A @ (m + x[:3] + x[3:] * (temperature - self._t_ref))
        else:
            out = self._A @ (m + x[:3])
        if self._nbuf == self._buf_t.size:
            self.flush()
        return out

    def flush(self, *, finish: bool = False) -> TrackResult | None:
        """Process the samples :meth:`feed` has buffered (and end the stream with ``finish``).

        Returns
        -------
        TrackResult or None
            Their per-sample estimates (None when nothing was buffered and ``finish`` is off).
        """
        n = self._nbuf
        if n == 0 and not finish:
            return None
        self._nbuf = 0
        assert self._buf_m is not None or n == 0
        ref: dict[str, np.ndarray] = {}
        if n:
            cols = (self._buf_t[:n].copy(), self._buf_m[:n].copy(),
                    self._buf_temp[:n].copy() if self._temp_model else None,
                    self._buf_still[:n].copy())
            if self._buf_has_ref:
                ref = {"reference_rate": self._buf_rr[:n].copy(),
                       "reference_axis": self._buf_ra[:n].copy()}
                self._buf_rr[:n] = np.nan
                self._buf_ra[:n] = np.nan
                self._buf_has_ref = False
            if self._buf_has_acc:
                ref["accel"] = self._buf_acc[:n].copy()
                self._buf_acc[:n] = np.nan
                self._buf_has_acc = False
            self._buf_temp[:n] = np.nan
            self._buf_still[:n] = np.nan
        else:
            cols = (np.zeros(0), np.zeros((0, 3)), None, None)
        return self._process_fed(cols, finish, ref)

    def _process_fed(self, cols: tuple[Any, ...], finish: bool,
                     ref: dict[str, np.ndarray] | None = None) -> TrackResult:
        self._fed = True
        try:
            return self.process(*cols, finish=finish, **(ref or {}))
        finally:
            self._fed = False
            self._fx = self._kf.x.reshape(-1).copy()


def _three_floats(v: Any) -> tuple[float, float, float]:
    """``v`` (a reading, an axis, a specific force) as three Python floats for :meth:`update`'s
    scalar path, without a new array when it is one of three float64 already; ``ValueError`` (or
    ``TypeError``) for anything that is not exactly three numbers, which the general path then
    checks and names."""
    if not (type(v) is np.ndarray and v.dtype == np.float64):
        v = np.asarray(v, dtype=float)
    if v.shape != (3,):
        raise ValueError("not three numbers")
    a, b, c = v.tolist()
    return a, b, c
