"""The bias tracker itself: its state, validation, batches and per-sample output.

:class:`BiasTracker` joins the pieces, each in its own module: the still detector
(:mod:`gyrocal.calib.stationarity`), the pooling of decided samples into update windows
(:mod:`.pooling`), the Kalman step and its health tests (:mod:`.step`), the process-noise
bank (:mod:`.qbank`), the smoother (:mod:`.smoother`) and the streaming paths
(:mod:`.streaming`). What is here: building the state from the settings and the calibration,
the public read-outs, checking a batch, :meth:`BiasTracker.process` (the detector's decisions
on a batch, then pooling and steps, then the per-sample output).
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Iterator
from dataclasses import replace
from typing import Any

import numpy as np
from scipy.special import chdtri  # χ² quantiles without scipy.stats' import cost

from gyrocal.calib.errors import CalibInputError
from gyrocal.calib.kalman import KalmanFilter
from gyrocal.calib.model import GyroCalibration
from gyrocal.calib.stationarity import (
    StillDetector,
    StreamingQuiet,
    accel_detector,
    accel_quiet_windows,
    quiet_windows,
    run_lengths,
)
from gyrocal.calib.tracker.pooling import (
    KIND_NONE,
    KIND_REF,
    KIND_STILL,
    OpenWindow,
    Snapshot,
    WindowPooling,
)
from gyrocal.calib.tracker.qbank import QBank
from gyrocal.calib.tracker.results import BiasMoved, Health, TrackResult
from gyrocal.calib.tracker.settings import TrackerSettings
from gyrocal.calib.tracker.smoother import Replay
from gyrocal.calib.tracker.step import KalmanStep
from gyrocal.calib.tracker.streaming import Streaming
from gyrocal.calib.validation import vec3

__all__ = ["BiasTracker"]


class BiasTracker(Streaming, WindowPooling, KalmanStep, Replay):
    """Kalman-filter tracker of a gyro's bias (the equations: :mod:`gyrocal.calib.tracker.step`).

    Parameters
    ----------
    settings : TrackerSettings
        Noise model and tuning (:meth:`TrackerSettings.from_noise` from an Allan analysis).
    calibration : GyroCalibration, optional
        Seeds the bias and its covariance (``bias``, ``bias_std``) and gives the scale used for
        the corrected rate and for reference-rate updates; its ``temperature_c`` is the default
        reference temperature.
    initial_bias, initial_bias_std : array_like (3,), optional
        The prior without a calibration (or overriding it), rad/s.
    keep_states : bool
        Keep the filtered state of every update (about 0.7 kB each) for :meth:`smoothed`.

    Attributes
    ----------
    kf : gyrocal.calib.kalman.KalmanFilter
        The filter's state ``x`` and covariance ``P`` (filterpy's names), and ``Q`` of the last
        step (the step itself is written out per axis: :meth:`_apply_window`).
    detector : StillDetector
    """

    def __init__(
        self,
        settings: TrackerSettings,
        calibration: GyroCalibration | None = None,
        *,
        initial_bias: Any = None,
        initial_bias_std: Any = None,
        keep_states: bool = False,
    ) -> None:
        if not isinstance(settings, TrackerSettings):
            raise CalibInputError("settings must be a TrackerSettings")
        if calibration is not None and not isinstance(calibration, GyroCalibration):
            raise CalibInputError("calibration must be a GyroCalibration")
        self.settings = settings
        self.calibration = calibration
        b0, b0_std = self._seed(initial_bias, initial_bias_std)
        self._init_model()
        self._init_filter(b0, b0_std)
        self._init_detector(b0)
        self._init_stream(b0, b0_std, keep_states)

    def _seed(self, initial_bias: Any, initial_bias_std: Any) -> tuple[np.ndarray, np.ndarray]:
        """The prior bias and its standard deviation: given, else the calibration's."""
        cal = self.calibration
        if initial_bias is not None:
            b0 = vec3(initial_bias, "initial_bias")
        elif cal is not None:
            b0 = np.asarray(cal.bias)
        else:
            b0 = np.zeros(3)
        if initial_bias_std is not None:
            b0_std = vec3(initial_bias_std, "initial_bias_std", positive=True)
        elif cal is not None:
            b0_std = np.asarray(cal.bias_std)
            if not np.all(np.isfinite(b0_std) & (b0_std > 0)):
                raise CalibInputError(
                    "the calibration has no usable bias_std; pass initial_bias_std (rad/s)"
                )
        else:
            raise CalibInputError("give a calibration or initial_bias_std to seed the tracker")
        return b0, b0_std

    def _init_model(self) -> None:
        """The calibration's model terms: the matrix ``A`` (``diag(scale)`` for v1), its
        inverse and entry uncertainties, the g-sensitivity ``G``, the reference's variance
        terms."""
        cal = self.calibration
        if cal is not None:
            self.scale = np.asarray(cal.scale)
            self.scale_std = np.asarray(cal.scale_std)
            self._A = cal.full_matrix
            a_std = cal.matrix_std
            self._A_std = np.diag(self.scale_std) if a_std is None else np.array(a_std)
        else:
            self.scale = np.ones(3)
            self.scale_std = np.full(3, np.nan)
            self._A = np.eye(3)
            self._A_std = np.diag(self.scale_std)
        self._A_inv = np.linalg.inv(self._A)
        self._A_inv_rows = self._A_inv.tolist()  # update()'s scalar reference arithmetic
        g_sens = None if cal is None else cal.g_sensitivity
        self._G = None if g_sens is None else np.array(g_sens["matrix"], dtype=float)
        self._G_rows = None if self._G is None else self._G.tolist()
        self._ref_ready = bool(np.all(np.isfinite(self.scale_std)))
        # the reference's variance terms (_reference_variance): (A⁻¹)∘² σ_A², its row sums
        ai2 = self._A_inv**2
        self._ai2_astd2 = (ai2 @ self._A_std**2).tolist()
        self._ai2_rowsum = ai2.sum(axis=1).tolist()
        if self.settings.t_ref_c is not None:
            self._t_ref: float | None = float(self.settings.t_ref_c)
        elif cal is not None and cal.temperature_c is not None:
            self._t_ref = float(cal.temperature_c)
        else:
            self._t_ref = None

    def _init_filter(self, b0: np.ndarray, b0_std: np.ndarray) -> None:
        """The Kalman filter (``x, P, F, Q``), the process noise and its bank, the health
        tests' state."""
        s = self.settings
        self._temp_model = bool(s.temperature_model)
        dim = 6 if self._temp_model else 3
        kf = KalmanFilter(dim_x=dim, dim_z=3)
        self._adaptive = s.rate_random_walk is None
        k_rw = np.asarray(s.rate_random_walk_prior if self._adaptive else s.rate_random_walk)
        if self._temp_model:
            kf.x = np.concatenate([b0, np.asarray(s.tempco)])
            kf.P = np.diag(np.concatenate([b0_std**2, np.asarray(s.tempco_std) ** 2]))
            self._q = np.concatenate([k_rw**2, np.asarray(s.tempco_random_walk) ** 2])
        else:
            kf.x = b0.astype(float).copy()
            kf.P = np.diag(b0_std**2)
            self._q = k_rw**2
        kf.F = np.eye(dim)
        kf.Q = np.zeros((dim, dim))
        self._kf = kf
        self._dim = dim
        self._sigma2_l = (s.noise_std**2).tolist()  # per-sample white-noise variance
        # Process-noise estimate: a bank of filters over a grid of K (see QBank)
        self._bank = (
            QBank(b0, b0_std, s, kf.x[3:] if self._temp_model else None) if self._adaptive
            else None
        )
        # CUSUM state per axis: upper and lower sums, and the innovations summed since each
        # last left zero (their mean sizes a detected shift).
        self._cu = [[0.0] * 3, [0.0] * 3]
        self._cu_sum = [[0.0] * 3, [0.0] * 3]
        self._cu_n = [[0.0] * 3, [0.0] * 3]
        self._n_shifts = 0
        self._nis_hist: deque[float] = deque(maxlen=s.nis_window)
        self._nis_ok = True
        self._nis_last = math.nan
        self._nis_sum = 0.0
        self._nis_bound = float(chdtri(3, s.nis_alpha))
        self._bound_cache: dict[int, float] = {}
        self._n_updates = 0
        self._n_alarms = 0
        # the seed check (_seed_check): armed until a full window passed it or it fired
        self._seed_armed = True
        self._moved: BiasMoved | None = None

    def _init_detector(self, b0: np.ndarray) -> None:
        """The still detector: its rate test centred on the seed, never on the estimate
        (:mod:`gyrocal.calib.tracker`), with room for the chip's zero-rate tolerance, fixed
        for the tracker's life."""
        s = self.settings
        det = StillDetector.build(s.noise_std, s.odr_hz, s.still)
        if s.still.rate_threshold is None:  # room for the bias to have moved from the seed
            det = replace(det, rate_limit=det.rate_limit + s.zero_rate_tolerance)
        self.detector = det
        # the accelerometer's veto (None: the gyro alone decides) and its last window's rows
        self.accel_detector = (None if s.accel_noise_std is None
                               else accel_detector(s.accel_noise_std, s.odr_hz, s.still))
        self._ahist = np.zeros((0, 3))
        self._det_bias = b0.astype(float).copy()
        self._det_bias_l = self._det_bias.tolist()  # update()'s scalar copy
        self._U = max(1, int(round(s.update_interval_s * s.odr_hz)))

    def _init_stream(self, b0: np.ndarray, b0_std: np.ndarray, keep_states: bool) -> None:
        """What carries across batches and samples: the detector's last window, the samples
        awaiting their decision, the open update window, feed()'s block, the kept states."""
        # steps update() left to its following calls (generators, a slice per call)
        self._todo: deque[Iterator[None]] = deque()
        # feed(): the block buffer and the estimate it corrects with
        self._nbuf = 0
        self._buf_m: np.ndarray | None = None
        self._fed = False
        self._fx = np.asarray(self._kf.x, dtype=float).reshape(-1).copy()
        self._temp_last = math.nan
        self._k = 0
        self._t_last: float | None = None
        self._t_state = 0.0
        self._t_update = 0.0
        self._hist = np.zeros((0, 3))
        self._run = 0
        self._pending: dict[str, np.ndarray] = {}
        # update()'s own queue of samples awaiting their still decision
        # (t, m, temp, ext, reference rate, reference axis or None), and the output terms of
        # the current state (rebuilt after each measurement update)
        self._pq: deque[tuple[Any, ...]] = deque()
        self._out_terms: tuple[Any, ...] | None = None
        # update()'s detector window (None while self._hist holds it, for process())
        self._sq: StreamingQuiet | None = None
        self._open: OpenWindow | None = None
        self._finished = False
        # bias, bias_std and time since the last update at the latest sample (the prior before)
        self._last: dict[str, Any] = {"bias": b0.astype(float), "bias_std": b0_std, "since": 0.0}
        self._last_decision: tuple[int, bool] | None = None
        # keep_states: time, state, covariance and the process noise into each update
        self._states: dict[str, list[Any]] | None = (
            {"t": [], "x": [], "P": [], "Q": [], "break": []} if keep_states else None
        )
        self._smooth_cache: tuple[int, tuple[np.ndarray, ...]] | None = None

    @property
    def t_ref_c(self) -> float | None:
        """Reference temperature of the temperature model, °C (None until known)."""
        return self._t_ref

    @property
    def samples(self) -> int:
        """Samples processed so far."""
        return self._k

    @property
    def bias(self) -> np.ndarray:
        """Bias estimate at the latest sample (its time and temperature), rad/s."""
        return np.array(self._last["bias"], dtype=float)

    @property
    def bias_std(self) -> np.ndarray:
        """One-sigma uncertainty of :attr:`bias`, rad/s."""
        if self._last["bias_std"] is None:  # update() leaves it to be read
            self._catch_up()
            self._last["bias_std"] = self._std_at(self._last["t"], self._last["temp"])
        return np.array(self._last["bias_std"], dtype=float)

    @property
    def kf(self) -> KalmanFilter:
        """The filter's state ``x``, covariance ``P`` and the last step's ``Q`` (filterpy's
        names), with every step that :meth:`update` left to its following calls finished."""
        self._catch_up()
        return self._kf

    @property
    def bias_covariance(self) -> np.ndarray:
        """Covariance of :attr:`bias` (3×3; axes are independent in this model), (rad/s)²."""
        return np.diag(self.bias_std**2)

    @property
    def rate_random_walk(self) -> np.ndarray:
        """The bias random walk ``K`` the filter uses now, rad/s/√s (when estimated: from the
        posterior mean of ``q = K²`` plus its posterior standard deviation)."""
        self._catch_up()
        return np.sqrt(self._q[:3])

    @property
    def rate_random_walk_estimate(self) -> np.ndarray | None:
        """The estimated ``K`` (from the posterior mean of ``q = K²``), rad/s/√s (None when
        ``rate_random_walk`` was given)."""
        self._catch_up()
        return None if self._bank is None else np.sqrt(self._bank.q)

    @property
    def applies_g_sensitivity(self) -> bool:
        """Whether the calibration has a g-sensitivity ``G`` for the ``specific_force`` that
        :meth:`process`, :meth:`update` and :meth:`feed` take (without it they ignore it)."""
        return self._G is not None

    @property
    def shifts(self) -> int:
        """Bias shifts the CUSUM test has detected so far."""
        self._catch_up()
        return self._n_shifts

    @property
    def tempco(self) -> np.ndarray | None:
        """Estimated temperature coefficient, rad/s/°C (None without the temperature model)."""
        return self._kf.x[3:].copy() if self._temp_model else None

    @property
    def tempco_std(self) -> np.ndarray | None:
        """One-sigma uncertainty of :attr:`tempco`, rad/s/°C (None without the model)."""
        self._catch_up()
        return np.sqrt(np.diag(self._kf.P)[3:]) if self._temp_model else None

    @property
    def health(self) -> Health:
        """Health flags after the latest sample."""
        self._catch_up()
        since = self._last["since"]
        return Health(
            nis=self._nis_last,
            nis_sum=self._nis_sum,
            nis_bound=self._nis_bound,
            nis_ok=self._nis_ok,
            since_update_s=float(since),
            stale=bool(since > self.settings.stale_after_s),
            updates=self._n_updates,
            alarms=self._n_alarms,
        )

    @property
    def bias_moved(self) -> BiasMoved | None:
        """Set when the first rest (or reference turn) found the bias beyond what the seed's σ
        allows (``moved_sigma``): how far it moved since calibration; None otherwise."""
        return self._moved

    @property
    def last_decision(self) -> tuple[int, bool] | None:
        """``(sample index, still)`` of the most recent still decision, or None."""
        return self._last_decision

    # ------------------------------------------------------------------ batches
    def _validate(
        self,
        t: Any,
        rate: Any,
        temperature: Any,
        still: Any,
        reference_rate: Any,
        reference_axis: Any,
    ) -> tuple[np.ndarray, ...]:
        try:
            t = np.asarray(t, dtype=float).reshape(-1)
            m = np.asarray(rate, dtype=float)
        except (TypeError, ValueError):
            raise CalibInputError("t must be (n,) seconds and rate (n, 3) rad/s") from None
        n = t.size
        if m.shape != (n, 3):
            raise CalibInputError(f"rate must have shape ({n}, 3) to match t, got {m.shape}")
        if not (np.isfinite(t).all() and np.isfinite(m).all()):
            raise CalibInputError("t and rate must be finite; drop or repair bad samples first")
        if n > 1 and not (t[1:] > t[:-1]).all():
            i = int(np.flatnonzero(~(t[1:] > t[:-1]))[0])
            raise CalibInputError(f"t must increase strictly; t[{i + 1}]={t[i + 1]} <= t[{i}]")
        if n and self._t_last is not None and t[0] <= self._t_last:
            raise CalibInputError(
                f"t[0]={t[0]} is not after the previous sample's time {self._t_last}"
            )
        if temperature is None:
            temp = np.full(n, np.nan)
        else:
            temp = np.asarray(temperature, dtype=float).reshape(-1)
            if temp.shape != (n,):
                raise CalibInputError(f"temperature must have shape ({n},), got {temp.shape}")
        if self._temp_model and not np.isfinite(temp).all():
            raise CalibInputError(
                "the temperature model needs a finite temperature for every sample; "
                "give temperature or turn temperature_model off"
            )
        if still is None:
            ext = np.full(n, np.nan)
        else:
            ext = np.asarray(still, dtype=float).reshape(-1)
            if ext.shape != (n,):
                raise CalibInputError(f"still must have shape ({n},), got {ext.shape}")
            if not (np.isnan(ext) | (ext == 0) | (ext == 1)).all():
                raise CalibInputError(
                    "still must hold True/False (or NaN: let the detector decide)"
                )
        if (reference_rate is None) != (reference_axis is None):
            raise CalibInputError("give reference_rate and reference_axis together")
        if reference_rate is None:
            rr = np.full(n, np.nan)
            ra = np.full((n, 3), np.nan)
        else:
            rr = np.asarray(reference_rate, dtype=float).reshape(-1)
            ra = np.asarray(reference_axis, dtype=float)
            if ra.shape == (3,):
                ra = np.broadcast_to(ra, (n, 3)).copy()
            if rr.shape != (n,) or ra.shape != (n, 3):
                raise CalibInputError(
                    f"reference_rate must be ({n},) and reference_axis ({n}, 3) or (3,), got "
                    f"{rr.shape} and {ra.shape}"
                )
            has = np.isfinite(rr)
            if has.any():
                if self.calibration is None:
                    raise CalibInputError(
                        "reference-rate updates need a calibration (its scale and scale_std)"
                    )
                if not np.isfinite(self.scale_std).all():
                    raise CalibInputError(
                        "the calibration has no scale_std; reference-rate updates need it"
                    )
                axes = ra[has]
                if not np.isfinite(axes).all():
                    raise CalibInputError("reference_axis must be finite where reference_rate is")
                norms = np.sqrt((axes * axes).sum(axis=1))
                if (np.abs(norms - 1.0) > 1e-6).any():
                    raise CalibInputError("reference_axis rows must be unit vectors")
                if (ext[has] == 1).any():
                    raise CalibInputError("a sample cannot be still while a servo turns it")
        return t, m, temp, ext, rr, ra

    def process(
        self,
        t: Any,
        rate: Any,
        temperature: Any = None,
        still: Any = None,
        *,
        reference_rate: Any = None,
        reference_axis: Any = None,
        specific_force: Any = None,
        accel: Any = None,
        finish: bool = False,
    ) -> TrackResult:
        """Feed a batch of readings (vectorised); returns per-sample estimates.

        Parameters
        ----------
        t : array_like (n,)
            Sample times, s, strictly increasing (also across calls).
        rate : array_like (n, 3)
            Readings ``m``, rad/s.
        temperature : array_like (n,), optional
            Die temperature, °C (NaN allowed without the temperature model).
        still : array_like (n,), optional
            External still flags: True/False, or NaN where the detector should decide.
        reference_rate : array_like (n,), optional
            Encoder rate of the turning servo, rad/s; NaN where none turns.
        reference_axis : array_like (n, 3) or (3,), optional
            Unit axis of the turning servo in the sensor frame.
        specific_force : array_like (n, 3) or (3,), optional
            Specific force at the sensor, g, sensor frame: with the calibration's
            g-sensitivity ``G`` the readings count as ``m + G f`` (module docstring); ignored
            without it.
        accel : array_like (n, 3), optional
            The accelerometer's reading of each sample (m/s², the unit of
            ``accel_noise_std``): required when the settings give ``accel_noise_std`` (the
            still detector's accelerometer veto), refused otherwise.
        finish : bool
            The stream ends with this batch: decide the samples still awaiting their look-ahead
            (as not still, unless flagged), close the open update window and apply it. Further
            calls are refused.

        Returns
        -------
        TrackResult
        """
        if self._finished:
            raise CalibInputError("this tracker has finished; start a new one")
        if self._nbuf and not self._fed:
            raise CalibInputError("samples given to feed() are waiting: call flush() before "
                                  "process() or update()")
        self._catch_up()
        cols = self._validate(t, rate, temperature, still, reference_rate, reference_axis)
        acc = self._accel(accel, cols[0].size)
        if specific_force is not None and self._G is not None:
            cols = (cols[0], cols[1] + self._force(specific_force, cols[0].size) @ self._G.T,
                    *cols[2:])
        if self._sq is not None:  # update()'s detector window, back to the rows process() keeps
            self._hist = self._sq.history()
            self._sq = None
        if self._pq:  # samples update() left awaiting their decision
            q = list(self._pq)
            self._pq.clear()
            self._pending = {
                "t": np.array([r[0] for r in q]), "m": np.array([r[1] for r in q]),
                "temp": np.array([r[2] for r in q]), "ext": np.array([r[3] for r in q]),
                "rr": np.array([r[4] for r in q]),
                "ra": np.array([(math.nan,) * 3 if r[5] is None else r[5] for r in q]),
            }
        return self._process(*cols, acc=acc, finish=finish)

    def _accel(self, accel: Any, n: int) -> np.ndarray | None:
        """``accel`` as (n, 3), checked against the settings (CalibInputError naming the
        problem)."""
        if self.accel_detector is None:
            if accel is not None:
                raise CalibInputError("accel was given but the settings have no "
                                      "accel_noise_std: give it to use the accelerometer")
            return None
        if accel is None and n == 0:
            return None
        if accel is None:
            raise CalibInputError("this tracker's still detector uses the accelerometer "
                                  "(accel_noise_std): give accel for every sample")
        try:
            a = np.asarray(accel, dtype=float)
        except (TypeError, ValueError):
            raise CalibInputError("accel must be numbers (m/s²)") from None
        if a.shape != (n, 3):
            raise CalibInputError(f"accel must have shape ({n}, 3), got {a.shape}")
        if not np.all(np.isfinite(a)):
            raise CalibInputError("accel contains NaN or inf")
        return a

    @staticmethod
    def _force(specific_force: Any, n: int) -> np.ndarray:
        """``specific_force`` as (n, 3) g, checked (CalibInputError naming the problem)."""
        try:
            f = np.asarray(specific_force, dtype=float)
        except (TypeError, ValueError):
            raise CalibInputError("specific_force must be numbers (g)") from None
        if f.shape == (3,):
            f = np.broadcast_to(f, (n, 3))
        if f.shape != (n, 3):
            raise CalibInputError(
                f"specific_force must have shape ({n}, 3) or (3,), got {f.shape}")
        if not np.all(np.isfinite(f)):
            raise CalibInputError("specific_force contains NaN or inf")
        return f

    def _process(
        self,
        t: np.ndarray,
        m: np.ndarray,
        temp: np.ndarray,
        ext: np.ndarray,
        rr: np.ndarray,
        ra: np.ndarray,
        *,
        acc: np.ndarray | None = None,
        finish: bool,
    ) -> TrackResult:
        """:meth:`process` on validated columns (``acc``: the accelerometer's, or None)."""
        n = t.size
        if n:
            if self._k == 0:
                self._t_state = float(t[0])
                self._t_update = float(t[0])
                self._keep_state(np.zeros((self._dim, self._dim)))
            if self._t_ref is None and np.isfinite(temp[0]):
                self._t_ref = float(temp[0])
        det = self.detector
        # ---- detector: quiet windows and run lengths, carrying the last window across batches
        if n:
            centred = np.concatenate([self._hist, m + self._det_bias[None, :]])
            quiet = quiet_windows(centred, det, self._hist.shape[0])
            run = run_lengths(quiet, self._run)
            # the accelerometer's veto: its window ending at the same row as the gyro's run
            a_quiet = None if acc is None else self._accel_quiet(acc)
            self._run = int(run[-1])
            keep = det.history
            self._hist = centred[-keep:] if keep else centred[:0]
        else:
            run = np.zeros(0, dtype=np.int64)
            a_quiet = None
        # ---- samples awaiting a decision: the pending ones, then this batch
        cols = {"t": t, "m": m, "temp": temp, "ext": ext, "rr": rr, "ra": ra}
        if self._pending:
            S = {k: np.concatenate([self._pending[k], v]) for k, v in cols.items()}
        else:
            S = cols
        P0 = S["t"].size - n
        g0 = self._k - P0  # global index of S[0]
        L = det.n_lookahead
        total = P0 + n
        n_dec = total if finish else max(total - L, 0)
        det_still = np.zeros(n_dec, dtype=bool)
        n_conf = min(n_dec, total - L) if total > L else 0
        if n_conf > 0:
            # decision on S[i] uses the run at S[i + L], i.e. batch row i + L - P0 (>= 0)
            at = np.arange(n_conf) + L - P0
            det_still[:n_conf] = run[at] >= det.n_min + L
            if a_quiet is not None:
                det_still[:n_conf] &= a_quiet[at]
        ext_d = S["ext"][:n_dec]
        still_d = np.where(np.isnan(ext_d), det_still, ext_d > 0.5)
        has_ref = np.isfinite(S["rr"][:n_dec])
        still_d &= ~has_ref
        kind = np.where(has_ref, KIND_REF, np.where(still_d, KIND_STILL, KIND_NONE))
        self._pending = {k: v[n_dec:] for k, v in S.items()}
        if n_dec:
            self._last_decision = (g0 + n_dec - 1, bool(still_d[-1]))

        snaps, log = self._assemble_and_apply(S, n_dec, kind, g0, finish)

        # ---- per-sample output of this batch
        g = self._k + np.arange(n)
        closes = np.array([s.close for s in snaps], dtype=np.int64)
        # the last snapshot applied at or before each sample (snapshot 0, close -1, is the state
        # before this batch)
        sidx = np.searchsorted(closes, g, side="right") - 1
        out = self._outputs(snaps, sidx, t, m, temp)
        # still decisions for this batch's rows
        still_rows = np.zeros(n, dtype=bool)
        decided_rows = np.zeros(n, dtype=bool)
        rows = np.arange(n_dec) + g0 - self._k
        sel = (rows >= 0) & (rows < n)
        still_rows[rows[sel]] = still_d[sel]
        decided_rows[rows[sel]] = True
        if n:
            self._k += n
            self._t_last = float(t[-1])
            self._temp_last = float(temp[-1])
            self._last = {
                "bias": out["bias"][-1],
                "bias_std": out["bias_std"][-1],
                "since": out["since"][-1],
            }
        if finish:
            self._finished = True
        return TrackResult(
            t=t,
            bias=out["bias"],
            bias_std=out["bias_std"],
            corrected=out["corrected"],
            still=still_rows,
            decided=decided_rows,
            since_update_s=out["since"],
            nis_ok=out["nis_ok"],
            updates=log,
            decision_index=g0 + np.arange(n_dec, dtype=np.int64),
            decision_still=still_d.copy(),
            bias_moved=self._moved,
        )

    def _accel_quiet(self, acc: np.ndarray) -> np.ndarray:
        """The accelerometer's quiet flags of the windows ending at each row of ``acc``,
        carrying its last window's rows across batches."""
        adet = self.accel_detector
        assert adet is not None
        rows = np.concatenate([self._ahist, acc])
        quiet = accel_quiet_windows(rows, adet, self._ahist.shape[0])
        self._ahist = rows[-adet.history:] if adet.history else rows[:0]
        return quiet

    def _outputs(
        self,
        snaps: list[Snapshot],
        sidx: np.ndarray,
        t: np.ndarray,
        m: np.ndarray,
        temp: np.ndarray,
    ) -> dict[str, np.ndarray]:
        W = len(snaps)
        X = np.array([s.x for s in snaps]).reshape(W, self._dim)
        Pd = np.array([np.diag(s.P) for s in snaps]).reshape(W, self._dim)
        ts = np.array([s.t_state for s in snaps])
        tu = np.array([s.t_update for s in snaps])
        ok = np.array([s.nis_ok for s in snaps], dtype=bool)
        j = sidx
        dt = np.maximum(t - ts[j], 0.0)
        q = np.array([s.q for s in snaps]).reshape(W, -1)[j]  # the process noise then
        if self._temp_model:
            Pbc = np.array([[s.P[i, i + 3] for i in range(3)] for s in snaps]).reshape(W, 3)
            dT = (temp - (self._t_ref if self._t_ref is not None else 0.0))[:, None]
            bias = X[j, :3] + X[j, 3:] * dT
            var = (
                Pd[j, :3]
                + 2 * dT * Pbc[j]
                + dT * dT * Pd[j, 3:]
                + (q[:, :3] + q[:, 3:] * dT * dT) * dt[:, None]
            )
        else:
            bias = X[j, :3]
            var = Pd[j, :3] + q[:, :3] * dt[:, None]
        return {
            "bias": bias,
            "bias_std": np.sqrt(np.maximum(var, 0.0)),
            "corrected": (m + bias) @ self._A.T,
            "since": t - tu[j],
            "nis_ok": ok[j],
        }
