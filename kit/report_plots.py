"""The plots of ``gyrocal report``: what the estimator saw, turn by turn, and how well it fits.

Numbers first (no matplotlib needed): :func:`servo_axes` decides each servo's rotation axis in the
sensor frame (the calibration's ``axes`` where present, else fitted to the servo's windows under
the calibration, else the nominal axis of the recording's manifest); :func:`window_axes` gives
each turn its own axis as measured (a servo turned in several gimbal poses turns about a
different sensor-frame axis in each: the calibration's kinematics at the window's encoder angles,
else fitted per pose); :func:`window_residuals` whitens each window's mean against the
calibration's prediction (the full model's ``A`` where it has one), and :func:`encoder_rate` /
:func:`boxcar_mean` put the gyro and the encoder on the same averaging weight. Then the figures
(need the ``plot`` extra), each written atomically:

``overview.png``
    The whole recording: raw rates, the windows used (rotation windows by servo, rest windows),
    and the servo angles.
``turn-NN-servoM-pos|neg.png``
    One rotate segment: the rate about the servo's axis (raw, calibrated, encoder reference) with
    the window's trapezoid weight shaded; calibrated minus reference on one averaging weight, the
    part of it the gyro's delay explains on the speed ramps (:func:`ramp_lag`), and the window
    mean the fit used; the raw rates of all three axes.
``rests.png``
    Each rest window's mean reading with its standard error against ``-bias``.
``residuals.png``
    Each window's mean minus its prediction in units of its standard deviation, and each still
    angle's error in its prior's: the residuals the fit's χ² sums (:func:`fit_residuals`).
"""

from __future__ import annotations

import math
import os
from collections.abc import Mapping
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from gyrocal.calib.kinematics import axes_at
from gyrocal.calib.model import GyroCalibration
from gyrocal.calib.segments import Segment
from gyrocal.calib.windows import (  # the estimator's own weight and grid: plot what the fit used
    ExtractedWindows,
    Window,
    trapezoid_weight,
    weight_grid,
)
from gyrocal.kit.errors import InputError, OutputExistsError
from gyrocal.kit.jig_kinds import DEFAULT_JIG, axis_label
from gyrocal.kit.plots import literal, save_png
from gyrocal.kit.recording import Recording

__all__ = [
    "PlannedPlot",
    "Residuals",
    "ServoAxis",
    "boxcar_mean",
    "calibrated",
    "calibration_axis",
    "encoder_rate",
    "fit_residuals",
    "nominal_axis",
    "plan_report",
    "ramp_lag",
    "report_residuals",
    "servo_axes",
    "window_axes",
    "window_forces",
    "window_residuals",
    "write_report",
]

_AXES = "xyz"
_AXIS_COLORS = ("C0", "C1", "C2")


# ============================================================================ numbers
@dataclass(frozen=True)
class ServoAxis:
    """A servo's rotation axis in the sensor frame.

    Attributes
    ----------
    motor : int
    axis : ndarray (3,)
        Unit vector: a positive turn of the servo is a positive rotation about it.
    source : str
        ``calibration`` (the fit's estimate), ``kinematics`` (the full model's chain at the
        turn's encoder angles), ``fitted`` (to the servo's windows under the calibration's
        model; per pose when the servo turned in several) or ``nominal`` (the manifest's axis
        name).
    pose_terms : ndarray (K, 3), optional
        For an axis carried by the held servos' encoder angles (``kinematics``): its change
        per standard deviation of each held angle's reading (a servo holds anywhere within its
        encoder tick, ``q/√12``), so the residuals can count that uncertainty.
    """

    motor: int
    axis: np.ndarray
    source: str
    pose_terms: np.ndarray | None = None


def nominal_axis(name: str) -> np.ndarray:
    """Unit vector of an axis name such as ``x`` or ``-y``.

    Raises
    ------
    InputError
        If ``name`` is not x, y or z with an optional sign.
    """
    s = str(name).strip().lower()
    sign = -1.0 if s.startswith("-") else 1.0
    s = s.lstrip("+-")
    if s not in ("x", "y", "z"):
        raise InputError(f"axis name {name!r} is not x, y or z with an optional sign")
    u = np.zeros(3)
    u["xyz".index(s)] = sign
    return u


def calibration_axis(cal: GyroCalibration, motor: int) -> np.ndarray | None:
    """Servo ``motor``'s unit axis in the sensor frame from the calibration's ``axes``, or None
    if the calibration has none for it.

    Raises
    ------
    InputError
        If the entry is there but is not 3 finite numbers, not all zero.
    """
    entry = (cal.axes or {}).get(str(motor))
    if not isinstance(entry, Mapping) or "axis" not in entry:
        return None
    try:
        u = np.asarray(entry["axis"], dtype=float)
    except (TypeError, ValueError):
        u = np.full(1, np.nan)
    if u.shape != (3,) or not np.all(np.isfinite(u)) or np.linalg.norm(u) == 0:
        raise InputError(
            f"the calibration's axes[{str(motor)!r}].axis must be 3 finite numbers, not all "
            f"zero; got {entry['axis']!r}"
        )
    return u / np.linalg.norm(u)


def servo_axes(
    motors: list[int], cal: GyroCalibration, manifest: Mapping[str, Any],
    windows: tuple[Window, ...] = (), forces: np.ndarray | None = None,
) -> dict[int, ServoAxis]:
    """Each servo's axis in the sensor frame, for the plots and the residuals.

    In order of preference: the calibration's ``axes`` (the paired-axis fit estimates them);
    else fitted to the servo's windows under this calibration's scale and bias (the least-squares
    direction of ``ω_i · k ∘ (m̄_i + b)``, or ``ω_i A (m̄_i + b + G f_i)`` with g-sensitivity: the
    mount's misalignment is then absorbed, as it is by an estimator that does not model axes);
    else the nominal axis the manifest names.

    Parameters
    ----------
    motors : list of int
        The servos that turned.
    cal : GyroCalibration
    manifest : mapping
        The recording's manifest (``gimbal.motors[].axis`` names the nominal axes).
    windows : tuple of Window
        The rotation windows.
    forces : ndarray, shape (len(windows), 3), optional
        Each window's mean specific force, g (:meth:`~gyrocal.calib.observations.
        ObservationSet.specific_force`), for a calibration with g-sensitivity; without it ``G``
        is left out (its ``G f`` mostly cancels between a servo's two directions).

    Raises
    ------
    InputError
        A malformed axis in the calibration, or a servo with no axis from any source.
    """
    nominal: dict[int, str] = {}
    for m in (manifest.get("gimbal") or {}).get("motors") or []:
        if isinstance(m, Mapping) and "id" in m and isinstance(m.get("axis"), str):
            nominal[int(m["id"])] = m["axis"]
    out: dict[int, ServoAxis] = {}
    for motor in motors:
        u = calibration_axis(cal, motor)
        mine = [i for i, w in enumerate(windows) if w.motor == motor]
        acc = _fitted_direction(cal, [windows[i] for i in mine],
                                None if forces is None else np.asarray(forces)[mine])
        if u is not None:
            out[motor] = ServoAxis(motor, u, "calibration")
        elif np.any(acc):
            out[motor] = ServoAxis(motor, acc / np.linalg.norm(acc), "fitted")
        elif motor in nominal:
            out[motor] = ServoAxis(motor, nominal_axis(nominal[motor]), "nominal")
        else:
            raise InputError(f"servo {motor}: no axis in the calibration, no window and no axis "
                             "in the manifest; cannot tell which axis it turns about")
    return out


def _fitted_direction(cal: GyroCalibration, windows: list[Window],
                      forces: np.ndarray | None = None) -> np.ndarray:
    """``Σ ω_i A (m̄_i + b + G f_i)`` over ``windows``: the least-squares direction of their
    calibrated means (not normalised; zero without windows)."""
    acc = np.zeros(3)
    for i, w in enumerate(windows):
        acc += w.rate * calibrated(cal, w.mean, None if forces is None else forces[i])
    return acc


def calibrated(cal: GyroCalibration, m: np.ndarray, force: np.ndarray | None) -> np.ndarray:
    """``cal.apply(m)`` with the specific force ``force`` (g, one row per reading or one for
    all) where the calibration has g-sensitivity; without a force its ``G f`` is left out
    silently (the report says where)."""
    if cal.g_sensitivity is not None and force is not None:
        return cal.apply(m, specific_force=force)
    import warnings

    from gyrocal.calib.model import GSensitivityWarning

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", GSensitivityWarning)
        return cal.apply(m)


def _kinematic_axes(extracted: ExtractedWindows, cal: GyroCalibration
                    ) -> tuple[np.ndarray, np.ndarray] | None:
    """Each rotation window's axis from the calibration's kinematics at the window's encoder
    angles (:func:`gyrocal.calib.kinematics.axes_at`) and its change per standard deviation of
    each held servo's angle (``ServoAxis.pose_terms``, by central differences); None when the
    calibration has no kinematics or the observations no poses of its chain."""
    obs = extracted.observations
    kin = cal.kinematics
    if kin is None or obs.pose is None or not obs.chain or not extracted.windows:
        return None
    chain = [int(c) for c in kin["chain"]]
    have = [int(c) for c in obs.chain]
    if not set(chain) <= set(have) or any(int(w.motor) not in chain  # type: ignore[arg-type]
                                          for w in extracted.windows):
        return None
    angles = np.asarray(obs.pose)[:, [have.index(c) for c in chain]]
    n, S = angles.shape
    rows = np.arange(n)
    idx = np.array([chain.index(int(w.motor)) for w in extracted.windows])  # type: ignore[arg-type]
    axes = axes_at(kin, angles)[rows, idx]
    terms = np.zeros((n, S, 3))
    sigma, h = float(obs.still_angle_std), 1e-6
    if sigma > 0:
        for k in range(S):
            step = np.zeros(S)
            step[k] = h
            d = (axes_at(kin, angles + step)[rows, idx] - axes_at(kin, angles - step)[rows, idx])
            terms[:, k] = np.where((idx == k)[:, None], 0.0, d / (2 * h) * sigma)
    return axes, terms


def window_axes(
    extracted: ExtractedWindows, cal: GyroCalibration, manifest: Mapping[str, Any],
) -> tuple[ServoAxis, ...]:
    """Each rotation window's turning axis in the sensor frame, as the calibration sees it.

    A servo turned with the gimbal in several poses (the full model's protocol,
    hardware_docs/method.md §9) turns about a different sensor-frame axis in each. In order of
    preference: the calibration's kinematics at the window's encoder angles (a full-model
    calibration; :mod:`gyrocal.calib.kinematics`); else, for a servo turned in one pose only,
    :func:`servo_axes`; else the least-squares direction of the calibrated window means of
    each pose (``fitted``).

    Returns
    -------
    tuple of ServoAxis
        One per ``extracted.windows``, in order.

    Raises
    ------
    InputError
        As :func:`servo_axes`.
    """
    windows = extracted.windows
    kin = _kinematic_axes(extracted, cal)
    forces = window_forces(extracted.observations, cal)
    f_win = None if forces is None else forces[0]
    if kin is not None:
        return tuple(ServoAxis(int(w.motor), kin[0][i], "kinematics",  # type: ignore[arg-type]
                               kin[1][i]) for i, w in enumerate(windows))
    groups = [int(g) for g in extracted.observations.pose_groups()]
    per_motor: dict[int, set[int]] = {}
    for w, g in zip(windows, groups, strict=True):
        per_motor.setdefault(int(w.motor), set()).add(g)  # type: ignore[arg-type]
    single = sorted(m for m, gs in per_motor.items() if len(gs) == 1)
    home = servo_axes(single, cal, manifest, windows, f_win)
    fitted: dict[int, ServoAxis] = {}
    for g in set(groups):
        idx = [i for i, h in enumerate(groups) if h == g]
        members = [windows[i] for i in idx]
        motor = int(members[0].motor)  # type: ignore[arg-type]
        if motor in home:
            fitted[g] = home[motor]
        else:
            acc = _fitted_direction(cal, members, None if f_win is None else f_win[idx])
            fitted[g] = ServoAxis(motor, acc / np.linalg.norm(acc), "fitted")
    return tuple(fitted[g] for g in groups)


def encoder_rate(
    enc_t: np.ndarray, enc_angle: np.ndarray, t: np.ndarray, half_span_s: float
) -> np.ndarray:
    """The encoder's mean rate over ``[t - h, t + h]``: ``(θ(t + h) − θ(t − h)) / 2h``, with the
    angle interpolated linearly between readings (NaN where the readings do not cover it)."""
    t = np.asarray(t, dtype=float)
    h = float(half_span_s)
    if enc_t.size < 2:
        return np.full(t.shape, np.nan)
    lo, hi = t - h, t + h
    r = (np.interp(hi, enc_t, enc_angle) - np.interp(lo, enc_t, enc_angle)) / (2 * h)
    return np.where((lo >= enc_t[0]) & (hi <= enc_t[-1]), r, np.nan)


def boxcar_mean(t: np.ndarray, x: np.ndarray, at: np.ndarray, half_span_s: float) -> np.ndarray:
    """Mean of the piecewise-linear signal ``x(t)`` over ``[at - h, at + h]`` (the same weight
    :func:`encoder_rate` puts on the encoder), NaN where ``t`` does not cover it."""
    t = np.asarray(t, dtype=float)
    x = np.asarray(x, dtype=float)
    h = float(half_span_s)
    cum = np.concatenate([[0.0], np.cumsum(np.diff(t) * (x[1:] + x[:-1]) / 2)])
    lo, hi = at - h, at + h
    r = (np.interp(hi, t, cum) - np.interp(lo, t, cum)) / (2 * h)
    return np.where((lo >= t[0]) & (hi <= t[-1]), r, np.nan)


def ramp_lag(difference: np.ndarray, slope: np.ndarray) -> float | None:
    r"""The gyro's delay against the encoder that best explains ``difference`` (calibrated minus
    reference rate) by the reference's rate of change ``slope``: a reading delayed by ``δ`` is
    ``ω(t − δ) ≈ ω(t) − δ ω̇(t)``, so ``δ = −Σ d ω̇ / Σ ω̇²`` (least squares; the fit that
    :func:`gyrocal.kit.verify.verify_recording` makes of its several-servo blocks). None where
    the rate does not change (no ramp) or nothing is finite.

    On a window from rest to rest, ``−δ ω̇`` integrates to ``−δ (ω_end − ω_start) = 0``: the
    ramps' error does not reach the window's mean, which is what the fit uses.
    """
    d, s = np.asarray(difference, dtype=float), np.asarray(slope, dtype=float)
    ok = np.isfinite(d) & np.isfinite(s)
    ss = float(np.sum(s[ok] ** 2))
    if not ok.any() or ss == 0.0:
        return None
    return -float(np.sum(d[ok] * s[ok])) / ss


@dataclass(frozen=True)
class Residuals:
    """Whitened residuals of the windows against a calibration.

    Attributes
    ----------
    labels : list of str
        One per window: ``s1-`` (servo 1, negative turn), ``rest 4`` (segment 4).
    kinds : list of str
        ``rotate`` or ``rest``.
    z : ndarray (n, 3)
        ``(mean − prediction) / σ`` per sensor axis (:func:`window_residuals`), or the fit's
        whitened residuals (:func:`fit_residuals`; a still angle's one value in the first
        column, NaN in the others).
    error : ndarray (n, 3) or None
        ``mean − prediction``, rad/s (:func:`window_residuals` only).
    sigma : ndarray (n, 3) or None
        The standard deviation each residual is divided by, rad/s (:func:`window_residuals`
        only).
    axis_sources : dict
        Servo -> where its axis came from (see :class:`ServoAxis`).
    note : str
        What the plot's title says the residuals are.
    """

    labels: list[str]
    kinds: list[str]
    z: np.ndarray
    error: np.ndarray | None
    sigma: np.ndarray | None
    axis_sources: dict[int, str]
    note: str = ""

    @property
    def chi2(self) -> float:
        """Sum of the squared whitened residuals."""
        return float(np.nansum(self.z**2))

    @property
    def count(self) -> int:
        """How many residuals there are (the NaN padding of a still angle's row not counted)."""
        return int(np.sum(np.isfinite(self.z)))


def window_forces(obs: Any, cal: GyroCalibration) -> tuple[np.ndarray, np.ndarray] | None:
    """The mean specific force of each window and rest (g), from the poses and the
    calibration's kinematics as its fit took it
    (:meth:`~gyrocal.calib.observations.ObservationSet.specific_force`), for a calibration with
    g-sensitivity; None otherwise (or when the observations do not say where gravity points)."""
    kin = cal.kinematics
    if cal.g_sensitivity is None or kin is None or not obs.has_gravity:
        return None
    if [int(c) for c in kin["chain"]] != [int(c) for c in obs.chain]:
        return None
    return obs.specific_force(np.asarray(kin["axes"]), np.asarray(kin["reference_angles_rad"]))


def _g_offsets(obs: Any, cal: GyroCalibration) -> tuple[np.ndarray, np.ndarray]:
    """``G f`` of each window and rest (:func:`window_forces`); zeros without them."""
    forces = window_forces(obs, cal)
    if forces is None:
        return np.zeros((obs.n_windows, 3)), np.zeros((obs.n_rests, 3))
    G = np.asarray(cal.g_sensitivity["matrix"])  # type: ignore[index]
    return forces[0] @ G.T, forces[1] @ G.T


def window_residuals(
    extracted: ExtractedWindows, cal: GyroCalibration,
    axes: Mapping[int, ServoAxis] | tuple[ServoAxis, ...], jig: str = DEFAULT_JIG,
) -> Residuals:
    """Each window's mean minus what the calibration predicts, in units of its deviation.

    A rotation window at reference rate ``ω`` about the axis ``u`` predicts ``A⁻¹ ω u − b`` (the
    model ``g = A (m + b)`` inverted, with ``g = ω u``; less ``G f`` with g-sensitivity;
    ``A = diag(k)`` for the paper's model,
    ``ω u ⊘ k − b``); a rest predicts ``−b``. The deviation of each component is
    ``sqrt(σ_m² + (σ_ω A⁻¹u)²)``: the window mean's standard error (the noise pooled over the
    windows where it is homogeneous, as the fits do) and the reference rate's; for an axis from
    the kinematics also ``Σ_k (ω A⁻¹ ∂u/∂θ_k σ_q)²`` for every held servo ``k`` (it holds
    anywhere within its encoder tick, ``σ_q = q/√12``; the fit estimates these hold errors as
    shared unknowns, this function does not, nor a hand turn's return to the stop: the fit's
    own residuals, whose ``Σ z²`` is its χ², are :func:`fit_residuals`). Axes fitted
    to the windows (:func:`servo_axes`, :func:`window_axes`) take two degrees of freedom per
    servo and pose from the residuals; nominal axes leave the mount's misalignment in them.

    Parameters
    ----------
    extracted : ExtractedWindows
    cal : GyroCalibration
    axes : mapping or tuple
        Per servo (from :func:`servo_axes`: one axis for all its turns) or per window (from
        :func:`window_axes`).

    Returns
    -------
    Residuals
    """
    obs = extracted.observations.with_pooled_noise()
    per_window = (tuple(axes[int(w.motor)] for w in extracted.windows)  # type: ignore[arg-type]
                  if isinstance(axes, Mapping) else tuple(axes))
    if len(per_window) != len(extracted.windows):
        raise InputError(f"{len(per_window)} axes for {len(extracted.windows)} windows")
    a_inv = np.linalg.inv(cal.full_matrix)
    b = np.asarray(cal.bias)
    f_win, f_rest = _g_offsets(obs, cal)
    labels: list[str] = []
    kinds: list[str] = []
    err, sig = [], []
    for i, w in enumerate(extracted.windows):
        v = a_inv @ per_window[i].axis
        err.append(obs.mean[i] - (obs.rate[i] * v - b - f_win[i]))
        var = obs.mean_std[i] ** 2 + (obs.rate_std[i] * v) ** 2
        if per_window[i].pose_terms is not None:
            var = var + np.sum((obs.rate[i] * per_window[i].pose_terms @ a_inv.T) ** 2, axis=0)
        sig.append(np.sqrt(var))
        labels.append(f"{axis_label(jig, int(w.motor), short=True)}"  # type: ignore[arg-type]
                      f"{'+' if w.direction > 0 else '-'}")
        kinds.append("rotate")
    for i, w in enumerate(extracted.rests):
        err.append(obs.rest_mean[i] + b + f_rest[i])  # type: ignore[index]
        sig.append(obs.rest_mean_std[i])  # type: ignore[index]
        labels.append(f"rest {w.segment}")
        kinds.append("rest")
    error = np.array(err).reshape(-1, 3)
    sigma = np.array(sig).reshape(-1, 3)
    sources: dict[int, str] = {}
    for a in per_window:
        sources[a.motor] = a.source
    return Residuals(labels, kinds, error / sigma, error, sigma, sources)


def fit_residuals(extracted: ExtractedWindows, cal: GyroCalibration, jig: str = DEFAULT_JIG
                  ) -> Residuals:
    """The residuals the fit's χ² sums, at ``cal``'s model
    (:func:`gyrocal.calib.estimators.residuals_at`): each window's and rest's, whitened by its
    covariance as the fit whitens it, and each still angle's fitted error over its prior σ
    (the encoder's hold within its tick; on the hand jig the box's return to the stop, which
    every turn from or to that rest shares). The turn axes, the still angles' errors and the
    g-sensitivity are fitted to the windows under ``cal``'s scale (or matrix) and bias, as
    the fit fits them; ``Σ z²`` is then the fit's χ² for a calibration fitted on these
    windows (:func:`gyrocal.kit.pipeline.judged_windows`), on every jig.

    Raises
    ------
    InputError
        If the fit's model cannot be fitted to these windows (a full-model calibration and a
        recording without the gimbal's poses, too few windows, ...).
    """
    from gyrocal.calib.errors import CalibInputError
    from gyrocal.calib.estimators import residuals_at

    obs = extracted.observations
    try:
        if cal.matrix is None:
            res = residuals_at(obs, np.asarray(cal.bias), scale=np.asarray(cal.scale))
        else:
            res = residuals_at(obs, np.asarray(cal.bias), matrix=np.asarray(cal.matrix))
    except CalibInputError as exc:
        raise InputError(f"the {cal.method} fit's residuals: {exc}") from None
    stills = np.full((res.stills.size, 3), np.nan)
    stills[:, 0] = res.stills
    labels = [f"{axis_label(jig, int(w.motor), short=True)}"  # type: ignore[arg-type]
              f"{'+' if w.direction > 0 else '-'}" for w in extracted.windows]
    labels += [f"rest {w.segment}" for w in extracted.rests]
    labels += [f"still {k + 1}" for k in range(res.stills.size)]
    kinds = (["rotate"] * len(extracted.windows) + ["rest"] * len(extracted.rests)
             + ["still"] * res.stills.size)
    z = np.vstack([res.windows, res.rests, stills])
    return Residuals(labels, kinds, z, None, None, {}, note=(
        f"the {res.method} fit's residuals at this calibration, the turn axes and the still "
        "angles' errors fitted as the fit fits them"))


def report_residuals(extracted: ExtractedWindows, cal: GyroCalibration,
                     axes: Mapping[int, ServoAxis] | tuple[ServoAxis, ...],
                     jig: str = DEFAULT_JIG) -> Residuals:
    """The residuals ``residuals.png`` draws: :func:`fit_residuals` (what the fit's χ²
    sums), or where the fit's model cannot be fitted to these windows the per-window
    :func:`window_residuals` about ``axes``, with the reason in its ``note``."""
    try:
        return fit_residuals(extracted, cal, jig)
    except InputError as exc:
        res = window_residuals(extracted, cal, axes, jig)
        return replace(res, note=f"each window against its own σ ({exc})")


# ============================================================================ the report
def _jig(rec: Recording) -> str:
    """The jig kind ``rec`` was made on (:func:`gyrocal.kit.pipeline.recording_jig`)."""
    from gyrocal.kit.pipeline import recording_jig

    return recording_jig(rec)


@dataclass(frozen=True)
class PlannedPlot:
    """One file of the report."""

    name: str
    description: str
    kind: str  # overview, turn, rests, residuals
    segment: Segment | None = None


def plan_report(rec: Recording, extracted: ExtractedWindows) -> list[PlannedPlot]:
    """The files :func:`write_report` writes, in index order (no matplotlib needed)."""
    by_segment = {w.segment: w for w in extracted.windows}
    jig = _jig(rec)
    plots = [PlannedPlot("overview.png", "the whole recording: raw rates, the windows used"
                         + (", servo angles" if rec.enc_t.size else ""), "overview")]
    for seg in rec.segments:
        if seg.kind != "rotate":
            continue
        sense = "pos" if seg.direction > 0 else "neg"
        w = by_segment.get(seg.index)
        if w is None:
            what = "no window (skipped by the extraction)"
        else:
            what = f"{w.kind} window over {w.revolutions:.2f} rev at {abs(w.rate):.4f} rad/s"
        plots.append(PlannedPlot(
            f"turn-{seg.index:02d}-servo{seg.motor}-{sense}.png",
            f"segment {seg.index}: {axis_label(jig, int(seg.motor))} turns "  # type: ignore[arg-type]

            f"{'positive' if seg.direction > 0 else 'negative'}, {what}", "turn", seg))
    plots.append(PlannedPlot("rests.png", f"{len(extracted.rests)} rest windows: mean reading "
                             "against -bias", "rests"))
    plots.append(PlannedPlot("residuals.png", "each window's mean minus its prediction, in "
                             "standard deviations (the fit's χ²)", "residuals"))
    return plots


def _shade_weight(ax: Any, t: np.ndarray, corners: tuple[float, float, float, float],
                  color: str = "C3", label: str | None = None) -> None:
    """The trapezoid weight as a shaded area over the panel's height (axes-fraction y)."""
    tg = weight_grid(t, corners)
    ax.fill_between(tg, 0.0, trapezoid_weight(tg, corners), transform=ax.get_xaxis_transform(),
                    color=color, alpha=0.12, lw=0, label=label)


def _gaps(t: np.ndarray) -> list[tuple[float, float]]:
    """Stretches where the gyro stream skips more than 2.5 sample periods (lost samples)."""
    if t.size < 3:
        return []
    dt = np.diff(t)
    idx = np.flatnonzero(dt > 2.5 * float(np.median(dt)))
    return [(float(t[i]), float(t[i + 1])) for i in idx]


def _mark_gaps(ax: Any, gaps: list[tuple[float, float]]) -> None:
    for k, (a, b) in enumerate(gaps):
        ax.axvspan(a, b, color="red", alpha=0.35, lw=0,
                   label="gap in the gyro stream" if k == 0 else None)


def _difference_panel(ax: Any, t: np.ndarray, gu: np.ndarray, et: np.ndarray,
                      ea: np.ndarray, h: float = 0.25) -> None:
    """Calibrated minus reference rate, both averaged over ``2h``, and what the gyro's delay
    makes of it on the speed ramps (:func:`ramp_lag`), said in the legend."""
    ref = encoder_rate(et, ea, t, h)
    diff = boxcar_mean(t, gu, t, h) - ref
    ax.plot(t, diff, color="C0", lw=1.0,
            label=f"calibrated − reference, both averaged over {2 * h:g} s")
    slope = np.gradient(ref, t)
    lag = ramp_lag(diff, slope)
    if lag is not None:
        ax.plot(t, -lag * slope, color="k", lw=1.0, ls=":",
                label=f"−delay × angular acceleration, delay {lag * 1e3:.1f} ms fitted: the "
                      "ramps' error is timing, not calibration")
    finite = diff[np.isfinite(diff)]
    if finite.size:
        span = max(float(np.percentile(np.abs(finite), 98)), 1e-4)
        ax.set_ylim(-2.5 * span, 2.5 * span)


#: The report's resolution, px per inch (the turn plots are placed at it).
_DPI = 100
#: matplotlib settings of the report's figures. Glyphs unhinted (FreeType's ``no_hinting``):
#: matplotlib 3.11 renders each glyph through FreeType on its own, running the font's hinting
#: program each time (a 25-character label: 4.9 ms hinted, 2.8 ms unhinted, on this host); the
#: report's write_report takes 5-13 % less CPU, its text a shade softer at the same sizes.
_RC = {"text.hinting": "no_hinting"}
#: The turn plot's three panels: their heights relative to each other.
_TURN_HEIGHTS = (1.3, 1.0, 1.0)


class _TurnFigure:
    """The turn plots' figure, drawn once and reused: every turn plot has the same three
    panels, and a fresh figure costs its axes, ticks and tick labels again (a third of a turn
    plot's time). :meth:`get` hands it back emptied of the last turn's artists, with the
    axes' limits, data limits and positions as a new figure has them, and each turn is placed
    by :func:`_place_column` from its own texts, so that a turn plot is drawn as on a figure
    of its own (``tests/kit/test_report.py`` compares the pixels)."""

    def __init__(self, plt: Any) -> None:
        self.plt = plt
        self.fig: Any = None
        self.axs: Any = None
        self._positions: list[Any] = []

    def get(self) -> tuple[Any, Any]:
        """The figure and its three axes, ready for a turn."""
        if self.fig is None:
            self.fig, self.axs = self.plt.subplots(3, 1, sharex=True, figsize=(10, 8.5),
                                                   dpi=_DPI)
            self._positions = [ax.get_position(original=True) for ax in self.axs]
            return self.fig, self.axs
        from matplotlib.transforms import Bbox

        for ax, pos in zip(self.axs, self._positions, strict=True):
            for artist in [*ax.lines, *ax.collections, *ax.patches, *ax.texts]:
                artist.remove()
            if ax.get_legend() is not None:
                ax.get_legend().remove()
            ax.dataLim.set_points(Bbox.null().get_points())
            ax.ignore_existing_data_limits = True
            ax.set_autoscale_on(True)
            ax.set_position(pos)
        return self.fig, self.axs

    def close(self) -> None:
        """Close the figure (after the last turn)."""
        if self.fig is not None:
            self.plt.close(self.fig)
            self.fig = None


def _tick_label_boxes(axis: Any, renderer: Any) -> list[Any]:
    """The window extents of ``axis``' shown major tick labels (visible, within the view),
    its ticks updated for the axes' present size."""
    axis.get_majorticklabels()  # sets each major tick's position and label
    lo, hi = sorted(axis.get_view_interval())
    tol = 1e-9 * (hi - lo)
    return [t.label1.get_window_extent(renderer) for t in axis.get_major_ticks()
            if t.label1.get_visible() and t.label1.get_text() and
            lo - tol <= t.get_loc() <= hi + tol]


def _offset_height(axis: Any, renderer: Any) -> float:
    """Height in px of ``axis``' offset text (``1e−2`` above a y axis), 0 when it has none."""
    text = axis.get_major_formatter().get_offset()
    if not text:
        return 0.0
    label = axis.get_offset_text()
    label.set_text(text)
    return float(label.get_window_extent(renderer).height)


def _place_column(fig: Any, axs: Any, title: Any, heights: tuple[float, ...]) -> None:
    """Place a column of panels that share their x axis (its tick labels and label on the
    bottom panel only) under the figure's title ``title``.

    Each text gets the room it measures and a pad of 3 points (constrained layout's), and the
    panels share the height left in proportion to ``heights``. The vertical room comes first
    (a y axis' ticks depend on its panel's height), then the left margin from the y axes' tick
    labels and labels; the right one holds half the bottom axis' widest tick label (the one at
    the edge is centred on it).

    Constrained layout placed these panels too, but it measures every decoration of every
    panel twice and computes every axis' ticks again for each measure (about 60 tick
    computations per turn plot, a quarter of its CPU); this measures the few texts that take
    room once. As with the layout engine, the places depend on the plot's own texts only.
    """
    renderer = fig.canvas.get_renderer()
    pt = fig.dpi / 72.0  # px per point
    width, height = fig.bbox.width, fig.bbox.height
    pad = 3 * pt
    bottom_x = axs[-1].xaxis
    x_boxes = _tick_label_boxes(bottom_x, renderer)
    x_tick = (bottom_x.get_tick_padding() + bottom_x.majorTicks[0].get_pad()) * pt
    x_room = (x_tick + max((b.height for b in x_boxes), default=0.0)
              + bottom_x.labelpad * pt + bottom_x.label.get_window_extent(renderer).height)
    y_boxes = [_tick_label_boxes(ax.yaxis, renderer) for ax in axs]
    half_label = max((b.height for boxes in y_boxes for b in boxes), default=0.0) / 2
    above = [max(half_label, _offset_height(ax.yaxis, renderer) + ax.yaxis.OFFSETTEXTPAD * pt)
             for ax in axs]
    below = [max(half_label, ax.xaxis.get_tick_padding() * pt) for ax in axs[:-1]]
    title.set_y(1.0 - pad / height)
    top = pad + title.get_window_extent(renderer).height + pad + above[0]
    gaps = [b + 2 * pad + a for b, a in zip(below, above[1:], strict=True)]
    free = height - top - (pad + x_room) - sum(gaps)
    rows, y = [], height - top
    for i, h in enumerate(heights):
        rows.append((y - free * h / sum(heights), free * h / sum(heights)))
        y = rows[-1][0] - (gaps[i] if i < len(gaps) else 0.0)
    for ax, (y0, h) in zip(axs, rows, strict=True):
        ax.set_position([ax.get_position().x0, y0 / height, ax.get_position().width,
                         h / height])
    left = pad + max(
        ax.yaxis.label.get_window_extent(renderer).width + ax.yaxis.labelpad * pt
        + max((b.width for b in _tick_label_boxes(ax.yaxis, renderer)), default=0.0)
        + (ax.yaxis.get_tick_padding() + ax.yaxis.majorTicks[0].get_pad()) * pt
        for ax in axs)
    right = pad + max((b.width for b in x_boxes), default=0.0) / 2
    for ax, (y0, h) in zip(axs, rows, strict=True):
        ax.set_position([left / width, y0 / height, (width - left - right) / width, h / height])


def _inside(legend: Any) -> None:
    """A legend drawn inside its axes: the layout need not measure it (it lies within the
    axes' box, which the layout keeps clear anyway), which spares finding its best place twice
    per layout pass."""
    legend.set_in_layout(False)


def _turn_plot(figures: _TurnFigure, rec: Recording, cal: GyroCalibration, seg: Segment,
               window: Window | None, axis: ServoAxis, extracted: ExtractedWindows,
               window_index: int | None) -> Any:
    margin = 0.3
    lo, hi = seg.t_start - margin, seg.t_end + margin
    if window is not None:
        lo, hi = min(lo, window.corners[0] - 0.1), max(hi, window.corners[3] + 0.1)
    sel = (rec.imu_t >= lo) & (rec.imu_t <= hi)
    t, m = rec.imu_t[sel], rec.imu_rate[sel]
    et, ea = rec.encoder(int(seg.motor))  # type: ignore[arg-type]
    u = axis.axis
    from gyrocal.kit.gravity import force_source, specific_force

    f = (specific_force(rec, cal, t) if cal.g_sensitivity is not None and t.size
         and force_source(rec, cal) is None else None)
    g = calibrated(cal, m, f) if m.shape[0] else np.zeros((0, 3))
    fig, axs = figures.get()
    sense = "positive" if seg.direction > 0 else "negative"
    head = (f"segment {seg.index}: {axis_label(_jig(rec), int(seg.motor))} turns "  # type: ignore[arg-type]
            f"{sense}; axis "
            f"[{u[0]:+.4f} {u[1]:+.4f} {u[2]:+.4f}] ({axis.source})")
    if window is not None:
        head += (f"\n{window.kind} window over {window.revolutions:.2f} rev, reference "
                 f"{window.rate:+.5f} rad/s (encoder), {window.count} gyro samples")
    else:
        head += "\nno window: the extraction skipped this turn (see its warnings)"
    title = fig.suptitle(head, fontsize=10)

    # 1: rate about the servo axis
    ax = axs[0]
    if t.size:
        ax.plot(t, m @ u, color="0.55", lw=0.8, label="raw  m·u")
        ax.plot(t, g @ u, color="C0", lw=1.0, label="calibrated  g·u")
        ref = encoder_rate(et, ea, t, 0.025)
        ax.plot(t, ref, color="k", lw=0.9, ls="--", label="encoder reference (50 ms)")
    if window is not None:
        _shade_weight(ax, t, window.corners, label="window weight (height = w)")
    gaps = _gaps(rec.imu_t[(rec.imu_t >= lo - 1.0) & (rec.imu_t <= hi + 1.0)])
    gaps = [(a, b) for a, b in gaps if b >= lo and a <= hi]
    _mark_gaps(ax, gaps)
    ax.set_ylabel("rate about the servo axis\nrad/s")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="best", fontsize=8, ncol=2)

    # 2: calibrated minus reference on one weight, and the window mean the fit used
    ax = axs[1]
    if t.size > 2:
        _difference_panel(ax, t, g @ u, et, ea)
    if window is not None and window_index is not None:
        obs = extracted.observations.with_pooled_noise()
        forces = window_forces(obs, cal)
        e = float(calibrated(cal, window.mean, None if forces is None
                             else forces[0][window_index]) @ u - window.rate)
        s = float(math.hypot(np.linalg.norm((cal.full_matrix.T @ u)
                                            * obs.mean_std[window_index]),
                             obs.rate_std[window_index]))
        a, b = window.corners[0], window.corners[3]
        ax.hlines(e, a, b, color="C3", lw=2.0,
                  label=f"window mean: {e:+.2e} ± {s:.1e} rad/s ({e / s:+.1f} σ)")
        _shade_weight(ax, t, window.corners)
    ax.axhline(0.0, color="0.4", lw=0.7)
    ax.set_ylabel("calibrated − reference\nrad/s")
    ax.ticklabel_format(axis="y", style="sci", scilimits=(-2, 2))
    ax.grid(True, alpha=0.3)
    ax.legend(loc="upper right", fontsize=8)

    # 3: raw rates, all axes
    ax = axs[2]
    for j in range(3):
        if t.size:
            ax.plot(t, m[:, j], color=_AXIS_COLORS[j], lw=0.8, label=f"raw {_AXES[j]}")
    if window is not None:
        _shade_weight(ax, t, window.corners)
    _mark_gaps(ax, gaps)
    ax.set_ylabel("raw gyro rates\nrad/s")
    ax.set_xlabel("t on the recording clock, s")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="best", fontsize=8, ncol=3)
    ax.set_xlim(lo, hi)
    _place_column(fig, axs, title, _TURN_HEIGHTS)
    return fig


def _overview_plot(plt: Any, rec: Recording, extracted: ExtractedWindows) -> Any:
    servos = sorted(int(x) for x in np.unique(rec.enc_motor))
    rows = 2 if servos else 1  # a hand recording has no servo angles to show
    fig, axs = plt.subplots(rows, 1, sharex=True, figsize=(12, 4.5 + 2.0 * (rows - 1)),
                            constrained_layout=True, squeeze=False,
                            gridspec_kw={"height_ratios": [1.6, 1.0][:rows]})
    axs = axs[:, 0]
    jig = _jig(rec)
    step = max(1, rec.imu_t.size // 20000)
    t = rec.imu_t[::step]
    ax = axs[0]
    for j in range(3):
        ax.plot(t, rec.imu_rate[::step, j], color=_AXIS_COLORS[j], lw=0.7, label=f"raw {_AXES[j]}")
    motors = sorted({int(w.motor) for w in extracted.windows if w.motor is not None})
    colors = {m: f"C{3 + i}" for i, m in enumerate(motors)}
    for w in extracted.windows:
        _shade_weight(ax, rec.imu_t, w.corners, color=colors[int(w.motor)])  # type: ignore[arg-type]
    for w in extracted.rests:
        ax.axvspan(w.corners[0], w.corners[3], color="0.5", alpha=0.15, lw=0)
    _mark_gaps(ax, _gaps(rec.imu_t))
    handles, labels = ax.get_legend_handles_labels()
    from matplotlib.patches import Patch

    handles += [Patch(color=colors[m], alpha=0.3) for m in motors]
    labels += [f"window, {axis_label(jig, m)}" for m in motors]
    handles.append(Patch(color="0.5", alpha=0.3))
    labels.append("rest window")
    ax.legend(handles, labels, loc="upper left", bbox_to_anchor=(1.0, 1.0), fontsize=8)
    ax.set_ylabel("raw gyro rates, rad/s")
    ax.grid(True, alpha=0.3)
    if servos:
        ax = axs[1]
        for m in servos:
            et, ea = rec.encoder(m)
            ax.plot(et, ea / (2 * np.pi), lw=1.0, label=f"servo {m}",
                    color=colors.get(m, "0.3"))
        ax.set_ylabel("servo angle, turns")
        ax.grid(True, alpha=0.3)
        ax.legend(loc="upper left", bbox_to_anchor=(1.0, 1.0), fontsize=8)
    axs[-1].set_xlabel("t on the recording clock, s")
    state = "complete" if rec.complete else "INCOMPLETE (interrupted run)"
    fig.suptitle(f"{literal(rec.path)}: {rec.imu_t.size} gyro samples over "
                 f"{rec.imu_t[-1] - rec.imu_t[0]:.1f} s, {len(extracted.windows)} rotation "
                 f"windows, {len(extracted.rests)} rest windows; recording {state}", fontsize=10)
    return fig


def _rests_plot(plt: Any, extracted: ExtractedWindows, cal: GyroCalibration,
                truth: Mapping[str, Any] | None) -> Any:
    fig, axs = plt.subplots(1, 3, figsize=(12, 4.5), constrained_layout=True)
    obs = extracted.observations.with_pooled_noise()
    x = np.array([w.segment for w in extracted.rests])
    # With g-sensitivity a still sensor reads −(b + G f): show each rest mean plus its G f, so
    # that all sit on −b (the zero-g bias).
    shift = _g_offsets(obs, cal)[1]
    gsens = cal.g_sensitivity is not None and bool(np.any(shift))
    for j, ax in enumerate(axs):
        bj, sj = cal.bias[j], cal.bias_std[j]
        ax.axhline(-bj, color="C0", lw=1.2, label="−bias (calibration)")
        if math.isfinite(sj):
            ax.axhspan(-bj - sj, -bj + sj, color="C0", alpha=0.15, lw=0, label="±1σ of the bias")
        if truth is not None and "bias" in truth:
            ax.axhline(-float(truth["bias"][j]), color="k", lw=0.8, ls=":",
                       label="−bias (simulation truth)")
        if x.size:
            ax.errorbar(x, obs.rest_mean[:, j] + shift[:, j],  # type: ignore[index]
                        yerr=obs.rest_mean_std[:, j],  # type: ignore[index]
                        fmt="o", color=_AXIS_COLORS[j], ms=4, capsize=3,
                        label="rest mean + G f ±1σ" if gsens else "rest mean ±1σ")
        ax.set_title(f"{_AXES[j]} axis")
        ax.set_xlabel("segment index")
        ax.ticklabel_format(axis="y", style="sci", scilimits=(-3, 3), useOffset=False)
        ax.grid(True, alpha=0.3)
    axs[0].set_ylabel("mean reading at rest, rad/s")
    _inside(axs[0].legend(fontsize=8))
    fig.suptitle("rest windows: a still sensor reads −bias (Calibration v1 convention)"
                 + ("; with g-sensitivity −(bias + G f), f gravity's direction in the rest"
                    if gsens else ""), fontsize=10)
    return fig


def _residuals_plot(plt: Any, res: Residuals, cal: GyroCalibration, jig: str) -> Any:
    fig, (ax, axh) = plt.subplots(1, 2, figsize=(12, 5), constrained_layout=True,
                                  gridspec_kw={"width_ratios": [3, 1]})
    n = len(res.labels)
    x = np.arange(n)
    still = np.array([k == "still" for k in res.kinds], dtype=bool)
    for j in range(3):
        ax.plot(x + (j - 1) * 0.2, np.where(still, np.nan, res.z[:, j]), "o",
                color=_AXIS_COLORS[j], ms=5, label=f"{_AXES[j]} component")
    if still.any():
        ax.plot(x[still], res.z[still, 0], "s", color="k", ms=5,
                label="still angle: its fitted error / its prior σ")
    for level, style in ((0, "-"), (2, "--"), (-2, "--"), (3, ":"), (-3, ":")):
        ax.axhline(level, color="0.5", lw=0.8, ls=style)
    ax.set_xticks(x, res.labels, rotation=60, fontsize=8)
    ax.set_ylabel("(mean − prediction) / σ")
    lim = max(4.0, float(np.nanmax(np.abs(res.z))) * 1.1) if n else 4.0
    ax.set_ylim(-lim, lim)
    ax.grid(True, axis="y", alpha=0.3)
    _inside(ax.legend(fontsize=8, loc="upper right"))
    text = f"Σz² = {res.chi2:.1f} over {res.count} residuals"
    c = cal.consistency
    if c is not None:
        text += (f"; the fit: χ² = {c.chi2:.1f} on {c.dof} dof, p = {c.p_value:.3g} "
                 f"({c.verdict})")
    if res.note:
        text += f"\n{res.note}"
    sources = set(res.axis_sources.values())
    if not sources <= {"calibration", "kinematics"}:
        text += "\nturn axes: " + ", ".join(f"{axis_label(jig, m)} {s}" for m, s in
                                             sorted(res.axis_sources.items()))
        if "fitted" in sources:
            text += " (fitted: to the windows under this calibration)"
        if "nominal" in sources:
            text += " (nominal: mounting misalignment shows as off-axis residuals)"
    ax.set_title(text, fontsize=9)
    z = res.z[np.isfinite(res.z)]
    if z.size:
        bins = np.linspace(-lim, lim, 17)
        axh.hist(z, bins=bins, color="0.6", density=True, label="all residuals")
        zz = np.linspace(-lim, lim, 200)
        axh.plot(zz, np.exp(-0.5 * zz**2) / math.sqrt(2 * math.pi), color="k", lw=1.0,
                 label="N(0, 1)")
        _inside(axh.legend(fontsize=8))
    axh.set_xlabel("z")
    fig.suptitle(f"residuals of the windows against the calibration ({cal.method})", fontsize=10)
    return fig


def write_report(
    rec: Recording,
    cal: GyroCalibration,
    extracted: ExtractedWindows,
    out_dir: str | os.PathLike[str],
    *,
    force: bool = False,
) -> list[tuple[Path, str]]:
    """Draw every plot of :func:`plan_report` into ``out_dir`` (created).

    Every file is checked before anything is drawn: without ``force`` an existing file is an
    error and nothing is written. Each PNG is written atomically.

    Returns
    -------
    list of (Path, str)
        Each file with its one-line description, in index order.

    Raises
    ------
    OutputExistsError
        If a file exists and ``force`` is false.
    InputError
        If matplotlib is missing, or ``out_dir`` cannot be created.
    """
    from gyrocal.kit.fileio import make_output_dir
    from gyrocal.kit.plots import require_matplotlib

    plt = require_matplotlib()
    out = Path(out_dir)
    plan = plan_report(rec, extracted)
    existing = [p.name for p in plan if (out / p.name).exists()]
    if existing and not force:
        raise OutputExistsError(
            f"{out} already holds {', '.join(existing[:4])}"
            + (f" and {len(existing) - 4} more" if len(existing) > 4 else "")
            + "; choose another --out or pass --force to replace them"
        )
    make_output_dir(out, "--out")
    motors = sorted({int(s.motor) for s in rec.segments if s.kind == "rotate"})  # type: ignore[arg-type]
    forces = window_forces(extracted.observations, cal)
    home = servo_axes(motors, cal, rec.manifest, extracted.windows,
                      None if forces is None else forces[0])
    axes = window_axes(extracted, cal, rec.manifest)
    index = {w.segment: (i, w) for i, w in enumerate(extracted.windows)}
    written: list[tuple[Path, str]] = []
    turns = _TurnFigure(plt)
    try:
        for p in plan:
            written.append(_draw(plt, p, out, rec, cal, extracted, turns, home, axes, index,
                                 force))
    finally:
        turns.close()
    return written


def _draw(plt: Any, p: PlannedPlot, out: Path, rec: Recording, cal: GyroCalibration,
          extracted: ExtractedWindows, turns: _TurnFigure, home: Mapping[int, ServoAxis],
          axes: list[ServoAxis], index: Mapping[int, tuple[int, Window]], force: bool
          ) -> tuple[Path, str]:
    """Draw and write one planned plot with :data:`_RC`; the turn plots on the one reused
    figure."""
    with plt.rc_context(_RC):
        if p.kind == "overview":
            fig = _overview_plot(plt, rec, extracted)
        elif p.kind == "turn":
            seg = p.segment
            i, w = index.get(seg.index, (None, None))  # type: ignore[union-attr]
            # a turn with no window (skipped by the extraction) is drawn about the servo's
            # home axis
            axis = home[int(seg.motor)] if i is None else axes[i]  # type: ignore[union-attr,arg-type]
            fig = _turn_plot(turns, rec, cal, seg, w, axis, extracted, i)  # type: ignore[arg-type]
        elif p.kind == "rests":
            fig = _rests_plot(plt, extracted, cal, rec.truth)
        else:
            jig = _jig(rec)
            fig = _residuals_plot(plt, report_residuals(extracted, cal, axes, jig), cal, jig)
        save_png(fig, out / p.name, force=force, dpi=_DPI, keep=p.kind == "turn")
    return out / p.name, p.description
