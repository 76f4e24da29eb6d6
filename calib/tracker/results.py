"""What the tracker hands back: per-sample results, the update log, health, the seed check.

Frozen dataclasses only (no arithmetic of the filter here): :class:`TrackResult` per
:meth:`~gyrocal.calib.tracker.BiasTracker.process` call, :class:`UpdateLog` of its measurement
updates, :class:`Health` after the latest sample, :class:`BiasMoved` when the first rest found
the bias beyond what the calibration's σ allows.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

__all__ = ["BiasMoved", "Health", "TrackResult", "UpdateLog"]


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
    bias_moved : BiasMoved or None
        The tracker's seed check by the end of the call (:attr:`BiasTracker.bias_moved`): set
        once the first rest found the bias beyond what the calibration's σ allows.
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
    bias_moved: BiasMoved | None = None
