"""Online tracking of a gyro's bias with a Kalman filter, seeded from an offline calibration.

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
cancels). Each window is one textbook Kalman step (``x, P, F, Q, H, R``; with ``F = I`` and
diagonal ``Q``, ``R`` and prior the axes are independent, so it is written out per axis in floats,
equal to :class:`gyrocal.calib.kalman.KalmanFilter`'s matrix step to rounding):

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

Batches and streams
-------------------
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

Process noise from the data
---------------------------
Without a given ``rate_random_walk`` the tracker estimates ``q = K²`` per axis as it goes, by
multiple-model adaptive estimation (Magill 1965; Bar-Shalom, Li & Kirubarajan §11.6): a bank of
filters of the same model on a log grid of ``K`` (:class:`_QBank`, 10⁻⁷ to 3·10⁻³ rad/s/√s) sees
every update window; each filter's innovation likelihood, forgotten over ``adapt_memory_s``,
weighs its ``K`` (flat prior on ``log K``), and the tracker uses the posterior mean of ``q``
plus its posterior standard deviation (the band must hold where few rests leave ``q`` loose).
Every model's likelihood is computed with its own covariance, so the estimate is not biased by
the ``q`` the tracker happens to run with (matching one filter's innovation covariance is: its
``P`` is wrong exactly when its ``q`` is). An unmodelled drift (a temperature coefficient left
out) shows up as a larger ``q``, so the band stays honest; with the temperature model the
coefficient is a state, and :attr:`BiasTracker.tempco` with :attr:`BiasTracker.tempco_std`
says whether it matters.

Replay
------
With ``keep_states=True`` the tracker keeps every update's state, and :meth:`BiasTracker.smoothed`
runs the Rauch-Tung-Striebel smoother back over them, so a replayed recording's estimate at each
sample uses the whole session (live tracking cannot). No smoothing crosses an update where the
health tests found a break (a bias step).

Bias steps
----------
A step in the bias shifts the innovations' mean. The NIS test sums squared innovations over a
few updates and misses a step smaller than their spread; a two-sided CUSUM (Page 1954) on each
axis's normalised innovation ``e = y/√S`` accumulates the shift instead (``g⁺ ← max(0, g⁺ + e −
k)``, ``g⁻ ← max(0, g⁻ − e − k)``, alarm above ``h``; with ``k = 0.5, h = 10`` a consistent
filter raises a false alarm about once in 10⁵ updates per axis and side). On an alarm the axis's
bias variance is widened (``recover``), so the filter follows the new bias within a few updates.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Any

import numpy as np
from scipy.special import chdtri  # χ² quantiles without scipy.stats' import cost

from gyrocal.calib.errors import CalibInputError
from gyrocal.calib.kalman import KalmanFilter
from gyrocal.calib.model import GyroCalibration
from gyrocal.calib.stationarity import (
    StillDetector,
    StillSettings,
    StreamingQuiet,
    quiet_windows,
    run_lengths,
)
from gyrocal.calib.validation import scalar, vec3

if TYPE_CHECKING:
    from gyrocal.calib.allan import NoiseCharacterisation

__all__ = [
    "BiasMoved",
    "BiasTracker",
    "Health",
    "TrackResult",
    "TrackerSettings",
    "UpdateLog",
]

#: Resolution of the X-series servo encoder, rad per tick (4096 ticks per turn).
ENCODER_TICK_RAD = 2.0 * math.pi / 4096.0

_KIND_NONE, _KIND_STILL, _KIND_REF = 0, 1, 2
#: What each Kalman step logs (:meth:`BiasTracker._step_rest`), gathered into an UpdateLog.
_LOG_KEYS = ("t", "kind", "count", "nis", "nis_sum", "nis_bound", "alarm", "at", "shift")
_DONE = object()  # a finished generator's next()
#: Decided rows that a batch pools one at a time, as update() does (numpy's fixed cost per
#: call outweighs the work below this).
_ROWS_ONE_BY_ONE = 64


@dataclass(frozen=True)
class TrackerSettings:
    """Noise model and tuning of the bias tracker.

    Attributes
    ----------
    odr_hz : float
        Gyro sample rate, Hz.
    noise_density : tuple of 3 float
        White-noise density ``N``, rad/s/√Hz (per-sample variance ``N²·odr``: ``R``).
    rate_random_walk : tuple of 3 float or None
        ``K``, rad/s/√s: the bias random walk (``Q = K² Δt``). None (the default): estimated
        from the data as the tracker goes (see "Process noise from the data" in the module
        docstring), starting from ``rate_random_walk_prior``; a figure given here is used as is.
    temperature_model : bool
        Also estimate a linear temperature coefficient per axis (needs temperatures).
    tempco : tuple of 3 float
        Prior mean of the coefficient, rad/s/°C.
    tempco_std : tuple of 3 float
        Prior standard deviation of the coefficient, rad/s/°C.
    tempco_random_walk : tuple of 3 float
        Random walk of the coefficient, rad/s/°C/√s (0: a constant).
    t_ref_c : float or None
        Reference temperature of ``b_ref``; default the calibration's ``temperature_c``, else
        the first sample's temperature.
    update_interval_s : float
        Longest update window.
    nis_window : int
        Updates summed in the NIS test.
    nis_alpha : float
        False-alarm probability of one NIS test.
    recover : bool
        Widen the bias covariance when the NIS test fails.
    stale_after_s : float
        ``Health.stale`` when no update came for this long.
    reference_angle_std : float
        Error of one encoder angle, rad (default one tick of a 4096-tick encoder).
    reference_axis_std : float
        Angular uncertainty of a servo axis, rad.
    still : StillSettings
        The still detector's tuning.
    rate_random_walk_prior : tuple of 3 float
        The ``K`` used until the first update gives an estimate, rad/s/√s.
    adapt_memory_s : float
        Time constant of the exponential forgetting of the ``K`` estimate, s.
    cusum_k, cusum_h : float
        Reference value and decision threshold of the per-axis two-sided CUSUM test on the
        normalised innovations (in units of their standard deviation); ``cusum_h = inf`` turns
        the test off.
    zero_rate_tolerance : float
        How far the bias may lie from the seed, rad/s: the still detector's rate test accepts a
        window whose mean, less the seed's bias, is within this plus ``still.rate_sigma`` σ
        (unless ``still.rate_threshold`` sets the limit). Default ±5 °/s, the MPU-9250's
        initial zero-rate tolerance (PS-MPU-9250A-01 §3.1), so a bias that moved anywhere
        within the chip's tolerance since calibration is still seen at rest.
    moved_sigma : float
        The first update window whose innovation on an axis exceeds this many of its standard
        deviations (the seed's σ, the window's noise and the random walk since) says the bias
        moved since calibration (:attr:`BiasTracker.bias_moved`): the seed's variance on that
        axis is widened by the squared innovation before the update, so the estimate jumps to
        the measured bias at the first rest.
    stream_block_s : float
        Samples fused per :meth:`BiasTracker.feed` block, s.
    """

    odr_hz: float
    noise_density: tuple[float, float, float]
    rate_random_walk: tuple[float, float, float] | None = None
    temperature_model: bool = False
    tempco: tuple[float, float, float] = (0.0, 0.0, 0.0)
    tempco_std: tuple[float, float, float] = (1e-3, 1e-3, 1e-3)
    tempco_random_walk: tuple[float, float, float] = (0.0, 0.0, 0.0)
    t_ref_c: float | None = None
    update_interval_s: float = 0.25
    nis_window: int = 8
    nis_alpha: float = 1e-4
    recover: bool = True
    stale_after_s: float = 30.0
    reference_angle_std: float = ENCODER_TICK_RAD
    reference_axis_std: float = 2e-3
    still: StillSettings = field(default_factory=StillSettings)
    rate_random_walk_prior: tuple[float, float, float] = (1e-4, 1e-4, 1e-4)
    adapt_memory_s: float = 600.0
    cusum_k: float = 0.5
    cusum_h: float = 10.0
    zero_rate_tolerance: float = math.radians(5.0)
    moved_sigma: float = 5.0
    stream_block_s: float = 0.25

    def __post_init__(self) -> None:
        object.__setattr__(self, "odr_hz", scalar(self.odr_hz, "odr_hz", positive=True))
        for name, kw in (
            ("noise_density", {"positive": True}),
            ("rate_random_walk", {"nonneg": True}),
            ("rate_random_walk_prior", {"positive": True}),
            ("tempco", {}),
            ("tempco_std", {"positive": True}),
            ("tempco_random_walk", {"nonneg": True}),
        ):
            if getattr(self, name) is None and name == "rate_random_walk":
                continue
            a = vec3(getattr(self, name), name, **kw)
            object.__setattr__(self, name, tuple(float(x) for x in a))
        if self.t_ref_c is not None:
            scalar(self.t_ref_c, "t_ref_c")
        scalar(self.update_interval_s, "update_interval_s", positive=True)
        if isinstance(self.nis_window, bool) or not isinstance(self.nis_window, int):
            raise CalibInputError(f"nis_window must be a positive integer, got {self.nis_window!r}")
        if self.nis_window < 1:
            raise CalibInputError(f"nis_window must be a positive integer, got {self.nis_window!r}")
        if not (0 < scalar(self.nis_alpha, "nis_alpha") < 1):
            raise CalibInputError(f"nis_alpha must be in (0, 1), got {self.nis_alpha!r}")
        scalar(self.stale_after_s, "stale_after_s", positive=True)
        scalar(self.reference_angle_std, "reference_angle_std", nonneg=True)
        scalar(self.reference_axis_std, "reference_axis_std", nonneg=True)
        scalar(self.adapt_memory_s, "adapt_memory_s", positive=True)
        scalar(self.cusum_k, "cusum_k", nonneg=True)
        if not (isinstance(self.cusum_h, (int, float)) and self.cusum_h > 0):
            raise CalibInputError(f"cusum_h must be a positive number (inf: off), got "
                                  f"{self.cusum_h!r}")
        scalar(self.zero_rate_tolerance, "zero_rate_tolerance", nonneg=True)
        scalar(self.moved_sigma, "moved_sigma", positive=True)
        scalar(self.stream_block_s, "stream_block_s", positive=True)
        if not isinstance(self.still, StillSettings):
            raise CalibInputError("still must be a StillSettings")

    @classmethod
    def from_noise(cls, noise: NoiseCharacterisation, **overrides: Any) -> TrackerSettings:
        """Settings whose ``R`` and ``Q`` come from a noise characterisation (Allan deviation).

        ``rate_random_walk`` is the characterisation's ``K``, or where that is unresolved
        (near zero) its 95 % upper bound (:attr:`NoiseCharacterisation.rate_random_walk_or_hi95`),
        so the filter never believes the bias is frozen.
        """
        kw: dict[str, Any] = {
            "odr_hz": noise.odr_hz,
            "noise_density": tuple(noise.noise_density.value),
            "rate_random_walk": noise.rate_random_walk_or_hi95,
        }
        kw.update(overrides)
        return cls(**kw)

    @property
    def noise_std(self) -> np.ndarray:
        """Per-sample white-noise standard deviation ``N·√odr``, rad/s."""
        return np.asarray(self.noise_density) * math.sqrt(self.odr_hz)


@dataclass(frozen=True)
class Health:
    """The tracker's health after the latest sample.

    Attributes
    ----------
    nis : float
        Normalised innovation squared of the last update (χ²(3) when consistent); NaN before.
    nis_sum : float
        Sum over the last ``nis_window`` updates since the last alarm.
    nis_bound : float
        Its ``1 − nis_alpha`` chi-square quantile.
    nis_ok : bool
        False from an update whose NIS test failed until the next one that passes.
    since_update_s : float
        Time since the last measurement update (since the first sample before any).
    stale : bool
        ``since_update_s`` above ``stale_after_s``.
    updates, alarms : int
        Counts so far.
    """

    nis: float
    nis_sum: float
    nis_bound: float
    nis_ok: bool
    since_update_s: float
    stale: bool
    updates: int
    alarms: int

    @property
    def ok(self) -> bool:
        """Neither flag raised."""
        return self.nis_ok and not self.stale


@dataclass(frozen=True, eq=False)
class BiasMoved:
    """The bias moved since calibration: the first update window's measured bias lies beyond
    what the seed's σ allows (:attr:`TrackerSettings.moved_sigma`).

    Attributes
    ----------
    t : float
        Time of that window's last sample, s.
    moved : ndarray (3,)
        Measured bias less the seed (at the window's temperature), rad/s.
    sigma : ndarray (3,)
        The standard deviation the seed allowed for that difference (the seed's σ, the random
        walk since, the window's noise), rad/s.
    axes : tuple of str
        The axes beyond ``moved_sigma`` σ (their prior was widened to take the measurement).
    kind : str
        ``"still"`` or ``"reference"``: the window that showed it.
    """

    t: float
    moved: np.ndarray
    sigma: np.ndarray
    axes: tuple[str, ...]
    kind: str

    @property
    def magnitude(self) -> float:
        """Length of :attr:`moved`, rad/s."""
        return float(np.linalg.norm(self.moved))

    def message(self) -> str:
        """One line for a user: how far, on which axes, against what σ."""
        return ("the bias moved by " + ", ".join(f"{v:+.3g}" for v in self.moved)
                + " rad/s (x, y, z; |.| " + f"{self.magnitude:.3g}) since calibration, beyond "
                + "the calibration's sigma (" + ", ".join(f"{v:.2g}" for v in self.sigma)
                + f") on {', '.join(self.axes)}: found at t = {self.t:.1f} s and followed "
                "from there")

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready."""
        return {"t": self.t, "moved": [float(v) for v in self.moved],
                "sigma": [float(v) for v in self.sigma], "axes": list(self.axes),
                "kind": self.kind, "magnitude": self.magnitude}


@dataclass(frozen=True, eq=False)
class UpdateLog:
    """The measurement updates applied during one :meth:`BiasTracker.process` call.

    Attributes
    ----------
    t : ndarray (W,)
        Time of each window's last sample, s.
    kind : ndarray (W,) of str
        ``"still"`` or ``"reference"``.
    count : ndarray (W,) of int
        Samples pooled.
    nis, nis_sum, nis_bound : ndarray (W,)
    alarm : ndarray (W,) of bool
        Whether the NIS test failed at this update.
    applied_at : ndarray (W,) of int
        Index (from the tracker's first sample) of the sample at which it took effect.
    shift : ndarray (W,) of bool
        Whether the CUSUM test on the mean innovation detected a shift at this update.
    """

    t: np.ndarray
    kind: np.ndarray
    count: np.ndarray
    nis: np.ndarray
    nis_sum: np.ndarray
    nis_bound: np.ndarray
    alarm: np.ndarray
    applied_at: np.ndarray
    shift: np.ndarray


@dataclass(frozen=True, eq=False)
class TrackResult:
    """Per-sample output of :meth:`BiasTracker.process` (all rad/s unless named).

    Attributes
    ----------
    t : ndarray (n,)
    bias : ndarray (n, 3)
        Bias estimate at each sample (Calibration v1 convention: added to the reading).
    bias_std : ndarray (n, 3)
        Its one-sigma uncertainty.
    corrected : ndarray (n, 3)
        ``A (m + bias)`` (``scale ∘ (m + bias)`` for a v1 calibration).
    still : ndarray (n,) of bool
        Still decision on each sample (False where not yet decided).
    decided : ndarray (n,) of bool
        Whether the still decision on the sample was made by the end of the call.
    since_update_s : ndarray (n,)
    nis_ok : ndarray (n,) of bool
        The NIS health flag at each sample.
    updates : UpdateLog
    decision_index : ndarray (d,) of int
        Every sample (counted from the tracker's first) whose still decision this call made,
        including samples of earlier calls that were awaiting their look-ahead.
    decision_still : ndarray (d,) of bool
        Those decisions.
    """

    t: np.ndarray
    bias: np.ndarray
    bias_std: np.ndarray
    corrected: np.ndarray
    still: np.ndarray
    decided: np.ndarray
    since_update_s: np.ndarray
    nis_ok: np.ndarray
    updates: UpdateLog
    decision_index: np.ndarray
    decision_still: np.ndarray


@dataclass
class _OpenWindow:
    kind: int
    axis: tuple[float, float, float] | None
    last: int
    count: int
    sum_z: list[float]  # three floats: the window's readings (less the reference) summed
    sum_temp: float
    sum_omega: float
    t_last: float


@dataclass
class _Snapshot:
    close: int
    x: np.ndarray
    P: np.ndarray
    t_state: float
    t_update: float
    nis_ok: bool
    q: np.ndarray


class _QBank:
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


class BiasTracker:
    """Kalman-filter tracker of a gyro's bias (see the module docstring for the equations).

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
        if initial_bias is not None:
            b0 = vec3(initial_bias, "initial_bias")
        elif calibration is not None:
            b0 = np.asarray(calibration.bias)
        else:
            b0 = np.zeros(3)
        if initial_bias_std is not None:
            b0_std = vec3(initial_bias_std, "initial_bias_std", positive=True)
        elif calibration is not None:
            b0_std = np.asarray(calibration.bias_std)
            if not np.all(np.isfinite(b0_std) & (b0_std > 0)):
                raise CalibInputError(
                    "the calibration has no usable bias_std; pass initial_bias_std (rad/s)"
                )
        else:
            raise CalibInputError("give a calibration or initial_bias_std to seed the tracker")
        if calibration is not None:
            self.scale = np.asarray(calibration.scale)
            self.scale_std = np.asarray(calibration.scale_std)
            # the model's matrix A (diag(scale) for v1), its inverse and entry uncertainties
            self._A = calibration.full_matrix
            a_std = calibration.matrix_std
            self._A_std = np.diag(self.scale_std) if a_std is None else np.array(a_std)
        else:
            self.scale = np.ones(3)
            self.scale_std = np.full(3, np.nan)
            self._A = np.eye(3)
            self._A_std = np.diag(self.scale_std)
        self._A_inv = np.linalg.inv(self._A)
        self._A_inv_rows = self._A_inv.tolist()  # update()'s scalar reference arithmetic
        g_sens = None if calibration is None else calibration.g_sensitivity
        self._G = None if g_sens is None else np.array(g_sens["matrix"], dtype=float)
        self._G_rows = None if self._G is None else self._G.tolist()
        self._ref_ready = bool(np.all(np.isfinite(self.scale_std)))

        s = settings
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
        # Process-noise estimate: a bank of filters over a grid of K (see _QBank)
        self._bank = (
            _QBank(b0, b0_std, s, kf.x[3:] if self._temp_model else None) if self._adaptive
            else None
        )
        # CUSUM state per axis: upper and lower sums, and the innovations summed since each
        # last left zero (their mean sizes a detected shift).
        self._cu = [[0.0] * 3, [0.0] * 3]
        self._cu_sum = [[0.0] * 3, [0.0] * 3]
        self._cu_n = [[0.0] * 3, [0.0] * 3]
        self._n_shifts = 0
        kf.F = np.eye(dim)
        kf.Q = np.zeros((dim, dim))
        self._kf = kf
        self._dim = dim
        self._sigma2_l = (s.noise_std**2).tolist()  # per-sample white-noise variance
        # the reference's variance terms (_reference_variance): (A⁻¹)∘² σ_A², its row sums
        ai2 = self._A_inv**2
        self._ai2_astd2 = (ai2 @ self._A_std**2).tolist()
        self._ai2_rowsum = ai2.sum(axis=1).tolist()
        # steps update() left to its following calls (generators, a slice per call)
        self._todo: deque[Iterator[None]] = deque()
        det = StillDetector.build(s.noise_std, s.odr_hz, s.still)
        if s.still.rate_threshold is None:  # room for the bias to have moved from the seed
            det = replace(det, rate_limit=det.rate_limit + s.zero_rate_tolerance)
        self.detector = det
        # the detector's rate test is centred on the seed, never on the estimate (module
        # docstring): fixed for the tracker's life
        self._det_bias = b0.astype(float).copy()
        self._det_bias_l = self._det_bias.tolist()  # update()'s scalar copy
        self._U = max(1, int(round(s.update_interval_s * s.odr_hz)))
        # feed(): the block buffer and the estimate it corrects with
        self._nbuf = 0
        self._buf_m: np.ndarray | None = None
        self._fed = False
        self._fx = np.asarray(kf.x, dtype=float).reshape(-1).copy()
        self._temp_last = math.nan
        if s.t_ref_c is not None:
            self._t_ref: float | None = float(s.t_ref_c)
        elif calibration is not None and calibration.temperature_c is not None:
            self._t_ref = float(calibration.temperature_c)
        else:
            self._t_ref = None
        # Streaming state.
        self._k = 0
        self._t_last: float | None = None
        self._t_state = 0.0
        self._t_update = 0.0
        self._hist = np.zeros((0, 3))
        self._run = 0
        self._pending: dict[str, np.ndarray] = {}
        # update()'s own queue of samples awaiting their still decision (t, m, temp, ext), and
        # the output terms of the current state (rebuilt after each measurement update)
        # (t, m, temp, ext, reference rate, reference axis or None)
        self._pq: deque[tuple[Any, ...]] = deque()
        self._out_terms: tuple[Any, ...] | None = None
        # update()'s detector window (None while self._hist holds it, for process())
        self._sq: StreamingQuiet | None = None
        self._open: _OpenWindow | None = None
        self._nis_hist: deque[float] = deque(maxlen=s.nis_window)
        self._nis_ok = True
        self._nis_last = math.nan
        self._nis_sum = 0.0
        self._nis_bound = float(chdtri(3, s.nis_alpha))
        self._bound_cache: dict[int, float] = {}
        self._n_updates = 0
        self._n_alarms = 0
        self._finished = False
        # the seed check (_seed_check): armed until a full window passed it or it fired
        self._seed_armed = True
        self._moved: BiasMoved | None = None
        # bias, bias_std and time since the last update at the latest sample (the prior before)
        self._last: dict[str, Any] = {"bias": b0.astype(float), "bias_std": b0_std, "since": 0.0}
        self._last_decision: tuple[int, bool] | None = None
        # keep_states: time, state, covariance and the process noise into each update
        self._states: dict[str, list[Any]] | None = (
            {"t": [], "x": [], "P": [], "Q": [], "break": []} if keep_states else None
        )
        self._smooth_cache: tuple[int, tuple[np.ndarray, ...]] | None = None

    # ------------------------------------------------------------------ public state
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

    # ------------------------------------------------------------------ streaming
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

        Returns
        -------
        ndarray (3,)
        """
        fast = self._update_fast(sample, t, temperature, still, reference_rate, reference_axis,
                                 specific_force)
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
                self._window_step(g, L, td, md, tempd, _KIND_REF, rrd, axd)
                continue
            is_still = (self._run >= det.n_min + L) if math.isnan(extd) else extd > 0.5
            self._last_decision = (g, bool(is_still))
            self._window_step(g, L, td, md, tempd, _KIND_STILL if is_still else _KIND_NONE)
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

    def _window_step(self, g: int, L: int, t: float, m: tuple[float, float, float],
                     temp: float, kind: int, rr: float = math.nan,
                     axis: tuple[float, float, float] | None = None,
                     close: Callable[[_OpenWindow, int], None] | None = None) -> None:
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
        if kind == _KIND_NONE:
            return
        z0, z1, z2 = m
        if kind == _KIND_REF:  # z = m − A⁻¹ ω u, the reading less the reference
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
            op = _OpenWindow(kind=kind, axis=axis, last=g, count=1, sum_z=[z0, z1, z2],
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

    def _close_deferred(self, w: _OpenWindow, at: int) -> None:
        """:meth:`update`'s window close: the state at once, the rest of the step deferred."""
        self._apply_window(w, _NO_LOG, at, defer=True)

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
        reference_axis: Any = None,
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
            self._buf_has_ref = False
        m = self._buf_m[i]
        try:
            m[:] = sample
            if reference_rate is not None:
                self._buf_ra[i] = reference_axis
                self._buf_rr[i] = reference_rate
                self._buf_has_ref = True
        except (TypeError, ValueError):
            raise CalibInputError(
                "sample and reference_axis must be 3 numbers each, and reference_rate a number"
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
        return self._process(*cols, finish=finish)

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
        finish: bool,
    ) -> TrackResult:
        """:meth:`process` on validated columns."""
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
            self._run = int(run[-1])
            keep = det.history
            self._hist = centred[-keep:] if keep else centred[:0]
        else:
            run = np.zeros(0, dtype=np.int64)
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
            det_still[:n_conf] = run[np.arange(n_conf) + L - P0] >= det.n_min + L
        ext_d = S["ext"][:n_dec]
        still_d = np.where(np.isnan(ext_d), det_still, ext_d > 0.5)
        has_ref = np.isfinite(S["rr"][:n_dec])
        still_d &= ~has_ref
        kind = np.where(has_ref, _KIND_REF, np.where(still_d, _KIND_STILL, _KIND_NONE))
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
        )

    # ------------------------------------------------------------------ internals
    def _snapshot(self, close: int) -> _Snapshot:
        return _Snapshot(
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
    ) -> tuple[list[_Snapshot], UpdateLog]:
        """Pool decided samples into update windows and apply the closed ones in order: a few
        rows one at a time (:meth:`_window_step`, as :meth:`update` pools them; numpy's
        per-call cost would dominate), more with array operations
        (:meth:`_pool_rows_vectorised`); both close the same windows at the same rows."""
        L = self.detector.n_lookahead
        snaps = [self._snapshot(-1)]
        log: dict[str, list[Any]] = {k: [] for k in _LOG_KEYS}

        def apply(w: _OpenWindow, close: int) -> None:
            self._apply_window(w, log, close)
            snaps.append(self._snapshot(close))

        if n_dec <= _ROWS_ONE_BY_ONE:
            cols = [S[k][:n_dec].tolist() for k in ("t", "m", "temp", "rr", "ra")]
            for i, (t, m, temp, rr, ra) in enumerate(zip(*cols, strict=True)):
                k = int(kind[i])
                self._window_step(g0 + i, L, t, tuple(m), temp, k, rr,
                                  tuple(ra) if k == _KIND_REF else None, apply)
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
                              g0: int, apply: Callable[[_OpenWindow, int], None]) -> None:
        """:meth:`_assemble_and_apply`'s pooling with array operations: runs of one kind (and
        one servo axis), cut into windows of at most ``U`` rows, each closed window applied."""
        L = self.detector.n_lookahead
        U = self._U
        ra = S["ra"][:n_dec]
        # z_i: the reading, less the reference's A⁻¹ ω u where a servo turns
        z = S["m"][:n_dec].copy()
        is_ref = kind == _KIND_REF
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
            axis0 = tuple(float(x) for x in ra[0]) if k0 == _KIND_REF else None
            continues = k0 == op.kind and axis0 == op.axis
            if not continues:
                apply(op, g0 + L)  # closed by the decision on S[0], made at g0 + L
                self._open = op = None
        new_run[0] = not continues
        idx = np.arange(n_dec)
        run_start = np.maximum.accumulate(np.where(new_run, idx, 0))
        offset = np.where(run_start == 0, op.count if continues and op else 0, 0)
        pos = idx - run_start + offset
        active = kind != _KIND_NONE
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
            sum_omega = float(np.sum(S["rr"][rows])) if kind[b] == _KIND_REF else 0.0
            if wi == 0 and continues and op is not None:
                w = op
                w.count += cnt
                w.sum_z = [a + b for a, b in zip(w.sum_z, sum_z, strict=True)]
                w.sum_temp += sum_temp
                w.sum_omega += sum_omega
                w.last = g0 + e - 1
                w.t_last = float(S["t"][e - 1])
            else:
                w = _OpenWindow(
                    kind=int(kind[b]),
                    axis=tuple(float(x) for x in ra[b]) if kind[b] == _KIND_REF else None,
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

    def _bound(self, k: int) -> float:
        b = self._bound_cache.get(k)
        if b is None:
            b = float(chdtri(3 * k, self.settings.nis_alpha))
            self._bound_cache[k] = b
        return b

    def _apply_window(self, w: _OpenWindow, log: dict[str, list[Any]], close: int,
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
        if w.kind == _KIND_REF:
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

    def _seed_check(self, w: _OpenWindow, z: list[float], x: list[float], P: list[list[float]],
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
                kind="reference" if w.kind == _KIND_REF else "still")
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
                   dt: float, dT: float, w: _OpenWindow, log: dict[str, list[Any]], close: int,
                   wide: list[float] | None = None) -> Iterator[None]:
        """The rest of a Kalman step whose state :meth:`_apply_window` applied: the covariance
        in Joseph form, ``P = (I − k h) P⁻ (I − k h)ᵀ + k r kᵀ`` per axis, the NIS and CUSUM
        tests, then the process-noise bank (:meth:`_QBank.steps`), yielding between slices."""
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
        log["kind"].append("reference" if w.kind == _KIND_REF else "still")
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

    def _outputs(
        self,
        snaps: list[_Snapshot],
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


class _Discard:
    """A list that keeps nothing (the update log of :meth:`BiasTracker.update`)."""

    def append(self, value: Any) -> None:
        pass


#: A throwaway update log (:meth:`BiasTracker.update` returns no log): appending costs nothing.
_NO_LOG: dict[str, Any] = {k: _Discard() for k in _LOG_KEYS}


def _concat(parts: list[TrackResult], g_first: int) -> TrackResult:
    """One :class:`TrackResult` from consecutive ones (whose first sample has global index
    ``g_first``): a still decision made by a later part lands on its row in an earlier one."""
    def cat(get: Any) -> np.ndarray:
        return np.concatenate([get(p) for p in parts])

    u = [p.updates for p in parts]
    log = UpdateLog(**{f: np.concatenate([getattr(x, f) for x in u])
                       for f in UpdateLog.__dataclass_fields__})
    t = cat(lambda p: p.t)
    di, ds = cat(lambda p: p.decision_index), cat(lambda p: p.decision_still)
    rows = di - g_first
    sel = (rows >= 0) & (rows < t.size)
    still = np.zeros(t.size, dtype=bool)
    decided = np.zeros(t.size, dtype=bool)
    still[rows[sel]] = ds[sel]
    decided[rows[sel]] = True
    return TrackResult(
        t=t,
        bias=np.vstack([p.bias for p in parts]),
        bias_std=np.vstack([p.bias_std for p in parts]),
        corrected=np.vstack([p.corrected for p in parts]),
        still=still,
        decided=decided,
        since_update_s=cat(lambda p: p.since_update_s),
        nis_ok=cat(lambda p: p.nis_ok),
        updates=log,
        decision_index=di,
        decision_still=ds,
    )
