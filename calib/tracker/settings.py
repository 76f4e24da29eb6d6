"""The tracker's noise model and tuning (:class:`TrackerSettings`).

Every figure the filter, the still detector and the health tests use, checked when made;
:meth:`TrackerSettings.from_noise` takes ``R`` and ``Q`` from an Allan analysis.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from gyrocal.calib.errors import CalibInputError
from gyrocal.calib.stationarity import StillSettings
from gyrocal.calib.validation import scalar, vec3

if TYPE_CHECKING:
    from gyrocal.calib.allan import NoiseCharacterisation

__all__ = ["ENCODER_TICK_RAD", "TrackerSettings"]

#: Resolution of the X-series servo encoder, rad per tick (4096 ticks per turn).
ENCODER_TICK_RAD = 2.0 * math.pi / 4096.0


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
        initial zero-rate tolerance (PS-MPU-9250A-01 §3.1 Table 1), so a bias that moved
        anywhere within the chip's tolerance since calibration is still seen at rest; ``gyrocal
        track`` gives the chip's own datasheet figure (``ChipFamily.gyro_errors`` in the chip
        data, joined by the kit: this module knows no chip). A steady turn slower than this
        gate passes the gyro's tests: ``accel_noise_std`` lets the accelerometer veto it.
    moved_sigma : float
        The first update window whose innovation on an axis exceeds this many of its standard
        deviations (the seed's σ, the window's noise and the random walk since) says the bias
        moved since calibration (:attr:`BiasTracker.bias_moved`): the seed's variance on that
        axis is widened by the squared innovation before the update, so the estimate jumps to
        the measured bias at the first rest.
    stream_block_s : float
        Samples fused per :meth:`BiasTracker.feed` block, s.
    accel_noise_std : tuple of 3 float or None
        Per-sample white-noise standard deviation of the accelerometer beside the gyro, in the
        unit of the ``accel`` readings given to :meth:`BiasTracker.process` (m/s²). Given, the
        still detector also runs the accelerometer's variance test
        (:func:`gyrocal.calib.stationarity.accel_detector`), which vetoes the gyro's still flag
        where the accelerometer moves, and every batch must carry ``accel``; None (the
        default): the gyro alone decides.
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
    accel_noise_std: tuple[float, float, float] | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "odr_hz", scalar(self.odr_hz, "odr_hz", positive=True))
        for name, kw in (
            ("noise_density", {"positive": True}),
            ("rate_random_walk", {"nonneg": True}),
            ("rate_random_walk_prior", {"positive": True}),
            ("tempco", {}),
            ("tempco_std", {"positive": True}),
            ("tempco_random_walk", {"nonneg": True}),
            ("accel_noise_std", {"positive": True}),
        ):
            if getattr(self, name) is None and name in ("rate_random_walk", "accel_noise_std"):
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
