"""From a recording to a calibration: windows, fit, Calibration v1 or v2 (shared by the commands).

With the method ``auto`` (the default) the full model ``g = A (m + b)`` is fitted when the
recording's poses determine it (hardware_docs/method.md §9), and so is the paper's diagonal model
with the paired-axis estimator; the full model is kept when its predicted general-motion error is
below the diagonal model's, which includes the cross-axis terms the datasheet allows
(:func:`gyrocal.calib.design.choose_model`). The calibration carries both figures
(``model_choice``) and a note says them; a diagonal one also says that cross-axis terms were not
calibrated and how large the error they leave can be.

When the recording's ``imu.csv`` has the accelerometer's columns, the same run's still windows
(the rests, held in the orientations the protocol's poses give) are the accelerometer's
observations: each window's mean reading must have the magnitude of the local gravity, and
:func:`gyrocal.calib.accel.fit_accelerometer` fits scale, cross-axis and bias to them, with
standard deviations and the χ² verdict, into the calibration's ``accelerometer``. Too few
distinct orientations give a note instead (the planner's gravity tour supplies them).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, replace
from typing import Any, NamedTuple

import numpy as np

from gyrocal.calib.accel import AccelCalibration
from gyrocal.calib.drift import BiasDrift
from gyrocal.calib.errors import CalibInputError
from gyrocal.calib.estimators import FitResult, add_bias_drift, add_window_wander, estimate
from gyrocal.calib.model import GyroCalibration, ModelChoice
from gyrocal.calib.systematics import add_wobble, remove_nod
from gyrocal.calib.windows import ExtractedWindows, extract_observations
from gyrocal.kit.errors import EstimationError, InputError
from gyrocal.kit.recording import Recording, now_iso

__all__ = [
    "AUTO",
    "PLAUSIBLE_NOISE_DENSITY",
    "PLAUSIBLE_SCALE",
    "Estimate",
    "plausible_bounds",
    "judged_windows",
    "recording_jig",
    "check_plausible",
    "check_plausible_noise",
    "datasheet_cross_axis",
    "diagonal_g_note",
    "diagonal_note",
    "sensor_cross_axis",
    "estimate_recording",
    "extract_recording",
    "fit_recording_accelerometer",
    "local_gravity",
]

#: Scale factors a real MEMS gyro calibration can have: datasheet sensitivity tolerances are a
#: few percent (MPU-9250 ±3 %, PS-MPU-9250A-01 table 1; LSM9DS1 a similar figure), so anything
#: outside 0.5..2 is a unit or setup mistake, not a sensor.
PLAUSIBLE_SCALE = (0.5, 2.0)
#: The paper's extreme sensors: scale factors up to 2.0 and biases up to ±0.2 rad/s (the
#: emulator's ``--sim-sensor paper-extreme``, :data:`gyrocal.kit.sim` SENSORS); a chip's
#: plausibility bounds admit them (:func:`plausible_bounds`).
PAPER_EXTREME_SCALE = 2.0
PAPER_EXTREME_BIAS_RAD_S = 0.2
#: Margin of the plausibility bounds over the larger of the datasheet tolerance and the paper's
#: extremes: a refusal is a unit or setup mistake, not a sensor at the edge of its tolerance.
PLAUSIBLE_MARGIN = 2.0
#: The power-of-two scales a full-scale setting mix-up gives (readings converted with the
#: sensitivity of a range one or two steps away: 250/500/1000/2000 °/s are factors of 2).
FULL_SCALE_MIXUPS = (0.25, 0.5, 2.0, 4.0)
#: The largest white-noise density a MEMS gyro recording in rad/s can have, rad/s/√Hz: 11×
#: the MPU-9250's typical 0.01 °/s/√Hz (PS-MPU-9250A-01 §3.1) and 5× the noisiest real gyro of
#: the corpus (imu_tk's Xsens, 4.2e-4; BROAD 0.7–1.3e-4, Fusion's 1.1–2.3e-4, imucal's 1.1e-4:
#: bench/real_corpus.py). The same readings in °/s are 57× larger: 3.8e-3 and up.
PLAUSIBLE_NOISE_DENSITY = 2e-3
#: How near (ratio) every axis's scale must be to one power of two to be named a full-scale
#: mix-up: beyond any datasheet's sensitivity tolerance (±3 % at most) and a cross-axis share.
_MIXUP_TOLERANCE = 0.05
#: The gyro's full scale assumed when the recording does not say (the largest of the chips), °/s.
_DEFAULT_FULL_SCALE_DPS = 2000.0

#: The method that chooses the full model when the poses determine it and it is predicted better
#: in general motion (:func:`gyrocal.calib.design.choose_model`), else the diagonal one.
AUTO = "auto"
#: Cross-axis sensitivity for a model the chip data does not know: the MPU-9250's ±2 %
#: (PS-MPU-9250A-01 §3.1), the typical MEMS value.
_CROSS_AXIS_DEFAULT = 0.02


def datasheet_cross_axis(sensor_model: str | None) -> float | None:
    """The gyro's cross-axis sensitivity its datasheet allows (fraction of the rate), from the
    chip data (:attr:`gyrocal.drivers.imu.chips.ChipFamily.gyro_errors`, each figure with its
    source); None for a model gyrocal does not read."""
    from gyrocal.drivers.imu import READER_CLASSES, READERS

    model = str(sensor_model or "").lower()
    return READERS[model].family.gyro_errors.cross_axis if model in READER_CLASSES else None


@dataclass(frozen=True, eq=False)
class Estimate:
    """A calibration with what it was computed from, and what the user must know about it."""

    calibration: GyroCalibration
    fit: FitResult
    extracted: ExtractedWindows
    notes: tuple[str, ...] = ()


def extract_recording(rec: Recording) -> ExtractedWindows:
    """The recording's windows (:func:`gyrocal.calib.windows.extract_observations`), with each
    window's pose when the manifest lists the gimbal's chain.

    Raises
    ------
    InputError
        If the recording cannot be windowed (truncated, a servo without encoder data, ...).
    """
    try:
        if recording_jig(rec) == "hand":
            from gyrocal.calib.hand import STOP_STD_RAD, hand_observations

            stop = (rec.manifest.get("jig") or {}).get("stop_std_deg")
            stop_rad = (math.radians(stop) if isinstance(stop, (int, float))
                        and not isinstance(stop, bool) and stop > 0 else STOP_STD_RAD)
            return hand_observations(rec.imu_t, rec.imu_rate, imu_temp=rec.imu_temp,
                                     accel=rec.imu_accel, stop_std_rad=stop_rad)[0]
        if rec.enc_t.size == 0 and not any(s.kind == "rotate" for s in rec.segments):
            raise InputError(
                f"{rec.path}: no encoder readings and no turns in segments.csv, so no gimbal "
                "turn to window; if the sensor was turned by hand (whole turns against a stop "
                "between rests), say so in manifest.json: \"jig\": {\"kind\": \"hand\"} "
                "(hardware_docs/hand-jig.md)")
        ex = extract_observations(
            rec.imu_t, rec.imu_rate, rec.enc_t, rec.enc_motor, rec.enc_angle, rec.segments,
            imu_temp=rec.imu_temp, chain=_chain(rec),
        )
        starts = seat_starts(rec.manifest)
        if starts is not None:
            return replace(ex, observations=_by_seat(ex, rec.manifest, starts))
        up = gravity_servo(rec.manifest)
        if up is not None and ex.observations.chain is not None:
            ex = replace(ex, observations=replace(ex.observations, gravity=up))
        return ex
    except CalibInputError as exc:
        raise InputError(f"{rec.path}: {exc}") from None


def seat_starts(manifest: Mapping[str, Any]) -> np.ndarray | None:
    """The start times of the cube's seats of a single-servo recording (the manifest's
    ``jig.kind`` ``"single-servo"`` and its ``protocol.seats``: each seat's ``t_start`` on
    the recording clock, in order), or None for a recording of another jig.

    Each window then turns about its seat's own axis (:meth:`gyrocal.calib.observations.
    ObservationSet.by_seat`: seat ``k`` is the ``k``-th listed, from its ``t_start`` on).

    Raises
    ------
    CalibInputError
        If a single-servo recording lists no seats or a seat without a time.
    """
    if manifest_jig(manifest) != "single-servo":
        return None
    protocol = manifest.get("protocol")
    seats = protocol.get("seats") if isinstance(protocol, Mapping) else None
    try:
        starts = np.array([float(s["t_start"]) for s in seats], dtype=float)
    except (KeyError, TypeError, ValueError):
        raise CalibInputError("a single-servo recording's manifest must list protocol.seats, "
                              "each with its t_start (s, recording clock)") from None
    if not starts.size or not np.all(np.isfinite(starts)) or np.any(np.diff(starts) <= 0):
        raise CalibInputError("protocol.seats of a single-servo recording must list at least "
                              "one seat, with increasing finite t_start")
    return starts


def _by_seat(ex: ExtractedWindows, manifest: Mapping[str, Any], starts: np.ndarray) -> Any:
    """The observations of a single-servo recording with each seat its own axis
    (:meth:`~gyrocal.calib.observations.ObservationSet.by_seat`), each window and rest in the
    seat it began in; with the gravity each seat's check read (``protocol.seats[].gravity``),
    the specific force of every window for the g-sensitivity model."""
    def seat_of(windows: Any) -> np.ndarray:
        return np.searchsorted(starts, [w.corners[0] for w in windows], side="right")

    seats = manifest["protocol"]["seats"]
    try:
        force = np.array([[float(x) for x in s["gravity"]] for s in seats])
    except (KeyError, TypeError, ValueError):
        force = None
    if force is None or force.shape != (len(seats), 3):
        return ex.observations.by_seat(seat_of(ex.windows))
    return ex.observations.by_seat(seat_of(ex.windows), seat_of(ex.rests), force)


def manifest_jig(manifest: Mapping[str, Any]) -> str:
    """The jig kind a recording was made on: its manifest's ``jig.kind``, a key of
    :data:`gyrocal.kit.jig_kinds.JIG_KINDS` (``gimbal`` when the manifest does not say).

    Raises
    ------
    CalibInputError
        If the manifest names a kind gyrocal does not know.
    """
    from gyrocal.kit.jig_kinds import DEFAULT_JIG, JIG_KINDS

    jig = manifest.get("jig")
    kind = jig.get("kind", DEFAULT_JIG) if isinstance(jig, Mapping) else DEFAULT_JIG
    if kind not in JIG_KINDS:
        raise CalibInputError(f"manifest jig.kind {kind!r} is not one of "
                              f"{', '.join(JIG_KINDS)}")
    return str(kind)


def recording_jig(rec: Recording) -> str:
    """The jig kind the recording was made on (:func:`manifest_jig`).

    Raises
    ------
    InputError
        If the manifest names a kind gyrocal does not know.
    """
    try:
        return manifest_jig(rec.manifest)
    except CalibInputError as exc:
        raise InputError(f"{rec.path}: {exc}") from None


def gravity_servo(manifest: Mapping[str, Any]) -> tuple[int, int] | None:
    """``(servo ID, sign)`` of the servo whose axis is vertical in the home pose, for the
    g-sensitivity model (:attr:`gyrocal.calib.observations.ObservationSet.gravity`).

    The jig stands with the sensor's +z up in the home pose (``hardware_docs/mechanical.md``),
    so "up" is the servo listed with axis ``z`` (sign +1) or ``-z`` (sign -1) in the manifest's
    ``gimbal.motors``; None when no servo is (then no g-sensitivity is fitted).
    """
    motors = (manifest.get("gimbal") or {}).get("motors")
    if not isinstance(motors, list):
        return None
    for m in motors:
        if isinstance(m, Mapping) and m.get("axis") in ("z", "+z", "-z"):
            try:
                return int(m["id"]), (-1 if m["axis"] == "-z" else 1)
            except (KeyError, TypeError, ValueError):
                return None
    return None


def _chain(rec: Recording) -> tuple[int, ...] | None:
    """The chain when every servo in it has encoder readings (else poses cannot be read)."""
    chain = rec.chain
    if chain is None or not set(chain) <= set(rec.enc_motor.tolist()):
        return None
    return chain


def sensor_cross_axis(sensor_model: str | None) -> float:
    """The cross-axis sensitivity a diagonal calibration of ``sensor_model`` leaves out: the
    datasheet's (:func:`datasheet_cross_axis`), or the typical ±2 % for a model gyrocal does
    not read."""
    return datasheet_cross_axis(sensor_model) or _CROSS_AXIS_DEFAULT


def diagonal_note(sensor_model: str | None, reason: str, *, jig: str = "gimbal") -> str:
    """What a user must know about a diagonal calibration: cross-axis terms are not in it, and
    how large the error they leave can be; how to calibrate them (on a gimbal: record with a
    posed protocol; on another ``jig``: a gimbal's posed protocol does)."""
    frac = sensor_cross_axis(sensor_model)
    how = ("Record with a posed protocol (gyrocal calibrate's default) to calibrate the full "
           "matrix." if jig == "gimbal" else
           "A gimbal's posed protocol (gyrocal calibrate's default) calibrates the full matrix.")
    return (
        f"cross-axis terms were NOT calibrated ({reason}); the diagonal model is exact only "
        f"about the six calibration axes: in other directions the calibrated rate can be off "
        f"by up to the sensor's cross-axis sensitivity, ±{100 * frac:g} % of the rate "
        f"(datasheet). {how}"
    )


def diagonal_g_note(fit: FitResult, jig: str = "gimbal") -> str | None:
    """What a diagonal fit did with g-sensitivity, and what the diagonal calibration leaves out.

    :func:`gyrocal.calib.estimators.fit_paired_axis` fits ``G`` along the directions of gravity
    the run determines (on the home-pose protocols, the home "up": the rests against the
    horizontal turns), so the bias is the zero-g bias; Calibration v1 has no ``G``, so the
    calibrated rate is off by ``k ∘ (G f)`` in use: the note states that size. Where the data
    did not need ``G`` (``extra["g_left_out_per_g"]``), the note says how large the ``G`` left
    in the bias is. None for a full-model fit, or a fit where gravity was not modelled. What
    calibrates the full model is said for the recording's ``jig``
    (:attr:`gyrocal.kit.jig_kinds.JigKind.full_model`).
    """
    from gyrocal.kit.jig_kinds import JIG_KINDS

    left = fit.extra.get("g_left_out_per_g") if fit.matrix is None else None
    if left is not None:
        return (f"g-sensitivity not fitted: the rests and the turns agree within their noise; "
                f"the g-sensitivity they determine, up to {left:.2g} rad/s per g, is what the "
                "noise explains and stays in the bias")
    if fit.matrix is not None or fit.g_sensitivity is None:
        return None
    kG = np.diag(fit.scale) @ np.asarray(fit.g_sensitivity)
    per_g = float(np.max(np.linalg.norm(kG, axis=1)))
    k = 0 if fit.g_directions is None else len(fit.g_directions)
    return (f"g-sensitivity fitted along {k} of 3 directions of gravity (where the rests and "
            f"turns see gravity differently), so the bias is the zero-g bias; the diagonal model "
            f"(Calibration v1) cannot carry it: in use the calibrated rate is off by up to "
            f"{per_g:.2g} rad/s per g of specific force ({math.degrees(per_g):.2g} °/s/g); the "
            f"full model carries it. {JIG_KINDS[jig].full_model}")


class _Systematics(NamedTuple):
    """What widens a fit's σ beyond the white noise: the bias's wander over the run
    (:class:`gyrocal.calib.drift.BiasDrift`) and between the windows and rests
    (``wander_change``: :meth:`~gyrocal.calib.drift.BiasDrift.window_covariance_change`), and
    the links' once-per-revolution tilt, rad (:func:`jig_wobble_rad`)."""

    drift: BiasDrift
    wobble_rad: float
    wander_change: np.ndarray

    def widen(self, fit: FitResult, obs: Any) -> FitResult:
        """``fit`` with all three in its covariance
        (:func:`gyrocal.calib.systematics.add_wobble`; the wander between the windows,
        :func:`gyrocal.calib.estimators.add_window_wander`, and the run's,
        :func:`gyrocal.calib.estimators.add_bias_drift`); a failed fit as it is."""
        if not fit.success:
            return fit
        fit = add_window_wander(fit, self.wander_change)
        return add_bias_drift(add_wobble(fit, obs, self.wobble_rad), self.drift)


def _fit(ex: ExtractedWindows, method: str, sensor_model: str | None, systematics: _Systematics,
         path: object, seats: bool = False
         ) -> tuple[FitResult, ModelChoice | None, tuple[str, ...]]:
    """Fit ``method``, or with ``auto`` both models and keep the one predicted better
    (:func:`_fit_auto`); each fit with the run's systematics in its σ (:class:`_Systematics`),
    so the figures compared are the calibration's. ``seats``: a single-servo recording
    (:func:`_without_chain`)."""
    try:
        if method != AUTO:
            fit = estimate(ex.observations, method)
            return systematics.widen(_without_chain(fit, seats), ex.observations), None, ()
        return _fit_auto(ex.observations, sensor_model, systematics, seats)
    except CalibInputError as exc:
        raise InputError(f"{path}: {exc}") from None


def _fit_auto(obs: Any, sensor_model: str | None, systematics: _Systematics,
              seats: bool = False
              ) -> tuple[FitResult, ModelChoice | None, tuple[str, ...]]:
    """The full model (where the chain is known) and the diagonal one, and the one whose
    predicted general-motion error is smaller (:func:`gyrocal.calib.design.choose_model`),
    with the notes that say why. A hand recording (each turn its own axis) has the diagonal
    model only (:data:`gyrocal.kit.jig_kinds.JIG_KINDS`' ``undetermined``)."""
    from gyrocal.calib.design import choose_model

    if obs.own_axes:
        from gyrocal.kit.jig_kinds import JIG_KINDS

        diag = systematics.widen(estimate(obs, "paired-axis"), obs)
        return diag, None, (diagonal_note(sensor_model, JIG_KINDS["hand"].undetermined,
                                          jig="hand"),)
    jig = "single-servo" if seats else "gimbal"
    full, reason = None, "the recording's manifest does not list the gimbal's servos in chain order"
    if obs.chain is not None:
        full = estimate(obs, "full-matrix")
        reason = (f"the recording's poses do not determine them: {full.message}" if not seats
                  else f"the {len(obs.chain)} seats of the cube do not determine them: seat it "
                  "on edges too, in the V-block (hardware_docs/single-servo.md)")
        full = systematics.widen(_without_chain(full, seats), obs) if full.success else None
    try:
        diag = estimate(obs, "paired-axis")
    except CalibInputError:
        if full is None:
            raise
        return full, None, ()  # a full model and no diagonal one to weigh it against
    if not diag.success:
        return (full, None, ()) if full is not None else (diag, None, ())
    diag = systematics.widen(_without_chain(diag, seats), obs)
    choice = choose_model(None if full is None else full.covariance,
                          None if full is None else full.matrix, diag.covariance, diag.scale,
                          sensor_cross_axis(sensor_model))
    if full is not None and choice.chosen == "full":
        return full, choice, (choice.sentence(),)
    if full is not None:
        reason = (f"the full model's predicted general-motion error, {choice.full:.2g} per "
                  f"rad/s, is above the diagonal model's, {choice.diagonal:.2g}")
    return diag, choice, (diagonal_note(sensor_model, reason, jig=jig), choice.sentence())


def _without_chain(fit: FitResult, seats: bool) -> FitResult:
    """A single-servo fit without the kinematics and servo axes: its "servos" are the cube's
    seats, not a gimbal's, so nothing may carry gravity or poses through them, nor read them as
    a servo's mounting misalignment."""
    return replace(fit, kinematics=None, axes=None, axes_std_rad=None) if seats else fit


def local_gravity(section: Mapping[str, Any]) -> tuple[float, str]:
    """The local gravity magnitude (m/s²) from the config's ``[accelerometer]`` keys, and where
    it came from: ``gravity_m_s2`` as given (standard gravity by default), or with
    ``gravity_m_s2 = 0`` the WGS-84 normal gravity at ``latitude_deg`` and ``height_m``
    (:func:`gyrocal.calib.accel.normal_gravity`, NIMA TR8350.2 Eqs. 4-1 and 4-3)."""
    from gyrocal.calib.accel import STANDARD_GRAVITY, normal_gravity

    g = float(section.get("gravity_m_s2", STANDARD_GRAVITY))
    if g:
        return g, ("standard gravity" if g == STANDARD_GRAVITY else "configured")
    lat, h = float(section.get("latitude_deg", 0.0)), float(section.get("height_m", 0.0))
    return normal_gravity(lat, h), f"WGS-84 normal gravity at {lat:g}°, {h:g} m"


def recording_gravity(rec: Recording) -> float:
    """The gravity magnitude the recording's manifest gives (``site.gravity_m_s2``, written by
    the runner from the config), else standard gravity."""
    from gyrocal.calib.accel import STANDARD_GRAVITY

    site = rec.manifest.get("site")
    g = site.get("gravity_m_s2") if isinstance(site, Mapping) else None
    if isinstance(g, (int, float)) and not isinstance(g, bool) and 9.7 <= g <= 9.9:
        return float(g)
    return STANDARD_GRAVITY


def fit_recording_accelerometer(
    rec: Recording, ex: ExtractedWindows, gravity_m_s2: float
) -> tuple[AccelCalibration | None, str | None]:
    """Fit the accelerometer to the recording's still windows (module docstring), and measure
    its white-noise density there (:func:`gyrocal.calib.accel.white_noise_density`).

    Returns
    -------
    (AccelCalibration, None)
        When the recording has accelerometer columns and its rests determine the fit and the
        density;
    (AccelCalibration, note)
        the fit without the density, and why (rests too short for its blocks);
    (None, note)
        with what is missing otherwise (``(None, None)`` for a recording without the columns).
    """
    from gyrocal.calib.accel import fit_accelerometer, still_means, white_noise_density

    if rec.imu_accel is None:
        return None, None
    spans = [(w.corners[0], w.corners[3]) for w in ex.rests]
    try:
        means, mean_std, _ = still_means(rec.imu_t, rec.imu_accel, spans)
        fit = fit_accelerometer(means, mean_std, gravity_m_s2)
    except CalibInputError as exc:
        return None, (f"the accelerometer was NOT calibrated: {exc} (a protocol with the "
                      "gravity tour holds the sensor in enough orientations)")
    try:
        density, std, tau, _ = white_noise_density(rec.imu_t, rec.imu_accel, spans)
    except CalibInputError as exc:
        return fit, f"the accelerometer's noise density was not measured: {exc}"
    return replace(fit, noise_density=density, noise_density_std=std, noise_tau_s=tau), None


def chip_bias_drift(model: Any, ex: ExtractedWindows) -> BiasDrift:
    """The bias instability and rate random walk of the chip ``model`` (a manifest's
    ``sensor.model``) from the chip data (:class:`gyrocal.drivers.imu.chips.GyroErrors`; the
    stated assumption there for a chip without the figures, or a model gyrocal does not know),
    over the span of the run's windows and rests (:mod:`gyrocal.calib.drift`)."""
    from gyrocal.drivers.imu import READER_CLASSES, READERS
    from gyrocal.drivers.imu.chips import GyroErrors

    if isinstance(model, str) and model in READER_CLASSES:
        ge = READERS[model].family.gyro_errors
    else:
        ge = GyroErrors(0.0, 0.0, 0.0, "", noise_density_dps_sqrt_hz=0.0,
                        g_sensitivity_dps_per_g=0.0, noise_source="")
    spans = [w.corners for w in (*ex.windows, *ex.rests)]
    span = max(c[3] for c in spans) - min(c[0] for c in spans) if spans else 0.0
    return BiasDrift(ge.bias_instability_rad_s, ge.rate_random_walk_rad_s_sqrt_s, span,
                     source=ge.drift_source)


def with_bias_wander(ex: ExtractedWindows, drift: BiasDrift) -> ExtractedWindows:
    """``ex`` with each window's and rest's standard error widened by the bias's wander about
    the run's mean over its length (:meth:`gyrocal.calib.drift.BiasDrift.window_variance`):
    the fit takes one bias for the run, so the residuals see that wander beside the white
    noise (a quiet gyro's rests disagree by it otherwise, and the χ² test blames a rest). The
    fit's weights and verdict use these σ; its covariance takes the wander as the process in
    time it is instead (:func:`gyrocal.calib.estimators.add_window_wander`)."""
    obs = ex.observations
    if obs.mean_std is None:
        return ex
    turns = drift.window_variance([w.corners[3] - w.corners[0] for w in ex.windows])
    widened = {"mean_std": np.sqrt(obs.mean_std**2 + turns)}
    if obs.rest_mean_std is not None and ex.rests:
        rests = drift.window_variance([w.corners[3] - w.corners[0] for w in ex.rests])
        widened["rest_mean_std"] = np.sqrt(obs.rest_mean_std**2 + rests)
    return replace(ex, observations=replace(obs, **widened))


def judged_windows(rec: Recording) -> tuple[ExtractedWindows, BiasDrift]:
    """The recording's windows as a fit judges them (:func:`extract_recording`, each window's
    and rest's σ widened by the bias's wander, :func:`with_bias_wander`, the links' measured
    nod taken out of their means, :func:`without_nod`), and the chip's bias
    drift figures: what :func:`estimate_recording` fits and a report's residuals are read
    against, so both give one χ².

    Raises
    ------
    InputError
        If the recording cannot be windowed.
    """
    ex = extract_recording(rec)
    drift = chip_bias_drift(rec.sensor.get("model"), ex)
    return without_nod(with_bias_wander(ex, drift)), drift


def without_nod(ex: ExtractedWindows) -> ExtractedWindows:
    """``ex`` with the links' once-per-revolution nod, as each servo's own turns measure it,
    taken out of the window means (:func:`gyrocal.calib.systematics.remove_nod`, through a
    full-matrix fit of the windows as they are); ``ex`` as it is where the gimbal's chain is
    not known or its poses do not determine the full matrix."""
    obs = ex.observations
    if obs.nod is None or obs.chain is None or obs.own_axes:
        return ex
    try:
        fit = estimate(obs, "full-matrix")
    except CalibInputError:
        return ex
    if not fit.success:
        return ex
    clean = remove_nod(obs, fit)
    if not clean.nod_removed:
        return ex
    shift = np.asarray(obs.mean) - np.asarray(clean.mean)
    windows = tuple(replace(w, mean=tuple(float(v) for v in np.asarray(w.mean) - shift[i]))
                    for i, w in enumerate(ex.windows))
    return replace(ex, observations=clean, windows=windows)


def jig_wobble_rad(manifest: Mapping[str, Any]) -> float:
    """The largest once-per-revolution link tilt of the recording's servos, rad: the servo
    table's ``wobble_deg`` (:class:`gyrocal.drivers.dynamixel.control_table.ServoModel`) of each
    ``gimbal.motors[].model``; the assumed figure for a model the table does not hold."""
    from gyrocal.drivers.dynamixel.control_table import ASSUMED_WOBBLE_DEG, MODELS

    by_name = {m.name: m.wobble_deg for m in MODELS.values()}
    motors = (manifest.get("gimbal") or {}).get("motors") or []
    figs = [by_name.get(m.get("model"), ASSUMED_WOBBLE_DEG) for m in motors
            if isinstance(m, Mapping)]
    return math.radians(max(figs, default=ASSUMED_WOBBLE_DEG))


def estimate_recording(
    rec: Recording, method: str = AUTO, *, source: str | None = None,
    gravity_m_s2: float | None = None,
) -> Estimate:
    """Window a recording and fit it with ``method`` (``auto``: module docstring); with the
    accelerometer's columns, fit the accelerometer too against ``gravity_m_s2`` (by default
    the manifest's ``site.gravity_m_s2``, else standard gravity).

    Raises
    ------
    InputError
        If the recording cannot be windowed (truncated, a servo without encoder data, ...).
    EstimationError
        If the estimator fails (the message says why).
    """
    ex, drift = judged_windows(rec)
    spans = np.array([(w.corners[0], w.corners[3]) for w in (*ex.windows, *ex.rests)])
    systematics = _Systematics(drift, jig_wobble_rad(rec.manifest),
                               drift.window_covariance_change(*spans.reshape(-1, 2).T))
    fit, choice, notes = _fit(ex, method, rec.sensor.get("model"), systematics, rec.path,
                              seats=seat_starts(rec.manifest) is not None)
    if not fit.success:
        raise EstimationError(f"{fit.method} failed on {rec.path}: {fit.message}")
    notes = (*notes, *filter(None, [diagonal_g_note(fit, recording_jig(rec))]), drift.note())
    cal = replace(fit.to_calibration(
        sensor=rec.sensor,
        temperature_c=ex.observations.temperature_c,
        created=now_iso(),
        source=source if source is not None else str(rec.path),
    ), model_choice=choice)
    g = recording_gravity(rec) if gravity_m_s2 is None else gravity_m_s2
    accel, accel_note = fit_recording_accelerometer(rec, ex, g)
    if accel is not None:
        cal = replace(cal, accelerometer=accel)
    if accel_note is not None:
        notes = (*notes, accel_note)
    from gyrocal.kit.thermal import scale_drift_note

    drift = scale_drift_note(rec.imu_t, rec.imu_temp, ex.windows, cal, rec.sensor.get("model"))
    if drift is not None:
        notes = (*notes, drift)
    return Estimate(calibration=cal, fit=fit, extracted=ex, notes=notes)


def plausible_bounds(model: Any) -> tuple[float, float, float | None, str]:
    """The scale factors and bias a calibration of a ``model`` gyro may have, and their source.

    The scale bound is the paper's extreme scale (:data:`PAPER_EXTREME_SCALE`) widened by the
    chip's sensitivity tolerance (``ChipFamily.gyro_errors.scale_tolerance``, the datasheet's
    "Sensitivity Scale Factor Tolerance") and 5 %, either way in ratio; the bias bound is
    :data:`PLAUSIBLE_MARGIN` times the larger of the chip's zero-rate offset tolerance
    (``gyro_errors.zero_rate_dps``) and the paper's extreme bias. A model gyrocal has no
    datasheet for gets :data:`PLAUSIBLE_SCALE` and no bias bound (the full scale still holds).

    Returns
    -------
    lo, hi : float
        The scale factors allowed.
    bias : float or None
        The largest |bias| allowed, rad/s.
    source : str
        Where the figures come from (said in a refusal).
    """
    from gyrocal.drivers.imu import READER_CLASSES, READERS

    key = str(model or "").strip().lower().replace("-", "")
    if key not in READER_CLASSES:
        return PLAUSIBLE_SCALE[0], PLAUSIBLE_SCALE[1], None, "any MEMS gyro"
    family = READERS[key].family
    err = family.gyro_errors
    hi = PAPER_EXTREME_SCALE * (1.0 + err.scale_tolerance) * 1.05
    bias = PLAUSIBLE_MARGIN * max(err.zero_rate_rad_s, PAPER_EXTREME_BIAS_RAD_S)
    source = (f"the {family.title} datasheet (sensitivity ±{100 * err.scale_tolerance:g} %, "
              f"zero-rate offset ±{err.zero_rate_dps:g} °/s) with room for the paper's extreme "
              f"sensors (scale up to {PAPER_EXTREME_SCALE:g}, bias "
              f"±{PAPER_EXTREME_BIAS_RAD_S:g} rad/s)")
    return 1.0 / hi, hi, bias, source


def _full_scale_mixup(k: np.ndarray, tolerance: float) -> float | None:
    """The power of two (:data:`FULL_SCALE_MIXUPS`) every axis's scale ``k`` is within
    ``tolerance`` (ratio) of, or ``None``: the sensitivity of another full-scale range."""
    for p in FULL_SCALE_MIXUPS:
        if all(math.isfinite(x) and x > 0 and abs(math.log(x / p)) <= math.log1p(tolerance)
               for x in k):
            return p
    return None


def _scale_cause(k: float) -> str:
    """The likely cause of an implausible scale factor ``k`` (reference rate / gyro rate)."""
    deg = math.pi / 180.0
    if abs(math.log(k / deg)) < math.log(1.5):
        return ("the gyro reads about 57 times the reference: its readings are probably in °/s "
                "where Recording v1 wants rad/s (imu.csv gx,gy,gz)")
    if abs(math.log(k * deg)) < math.log(1.5):
        return ("the reference is about 57 times the gyro: the encoder angles are probably in "
                "degrees where Recording v1 wants radians (encoder.csv angle)")
    if k < 1:
        return ("the gyro reads far more than the encoders turned: check the gyro's units and "
                "the sensitivity (full-scale range) the readings were converted with")
    return ("the gyro reads far less than the encoders turned: check the gyro's units and "
            "sensitivity, and that the sensor is fixed to the turning stage")


def check_plausible_noise(density: Any, *, allow: bool = False) -> list[str]:
    """Refuse a gyro white-noise density no MEMS gyro in rad/s has: readings in °/s.

    Parameters
    ----------
    density : sequence of 3 float
        The measured white-noise density per axis, rad/s/√Hz.
    allow : bool
        Return the problems instead of raising (``--allow-implausible``).

    Returns
    -------
    list of str
        The problems found (empty when plausible).

    Raises
    ------
    EstimationError
        If a problem is found and ``allow`` is false (exit 6), as :func:`check_plausible`.
    """
    n = np.asarray(density, dtype=float)
    limit = PLAUSIBLE_NOISE_DENSITY
    bad = [j for j in range(n.size) if not (math.isfinite(n[j]) and n[j] <= limit)]
    if not bad:
        return []
    values = ", ".join(f"{'xyz'[j]} = {n[j]:.3g}" for j in bad)
    problem = (f"white-noise density {values} rad/s/sqrt(Hz) above the {limit:g} "
               "a MEMS gyro has: the readings look like °/s (57x rad/s); convert them to rad/s")
    if not allow:
        raise EstimationError(f"implausible gyro readings: {problem}. If the sensor really is "
                              "like this, pass --allow-implausible.")
    return [problem]


def check_plausible(cal: GyroCalibration, sensor: Mapping[str, Any] | None = None, *,
                    allow: bool = False, recording: Recording | None = None,
                    extracted: ExtractedWindows | None = None) -> list[str]:
    """Refuse a calibration no real gyro can have: a unit or setup mistake.

    A scale factor outside the chip's :func:`plausible_bounds` (of g = K (m + b), the paper's
    model; for v2 the diagonal of the matrix: the gyro's magnitude against the encoder rate), or
    a bias beyond the gyro's full scale (the recording's ``sensor.full_scale_dps``), means the
    readings or the reference are in the wrong units; a bias beyond the chip's zero-rate offset
    bound, a sensor that moved during the first rest or another chip than ``sensor.model``; a
    scale near one power of two on every axis (:data:`FULL_SCALE_MIXUPS`), readings converted
    with another full-scale range's sensitivity. With the ``recording`` and its windows
    (``extracted``), on every protocol, also: each turn's encoder rate against the speed its
    plan commanded (:func:`_turn_rate_problems`: angles in degrees, a wrong velocity unit), and
    each servo's axis in the sensor frame against the axis the manifest names
    (:func:`_axis_problems`: swapped or negated gyro columns, a sensor mounted otherwise).

    Parameters
    ----------
    cal : GyroCalibration
    sensor : mapping, optional
        The recording's sensor section (its ``full_scale_dps``).
    allow : bool
        Return the problems instead of raising (``--allow-implausible``).
    recording : Recording, optional
        The recording ``cal`` was fitted to (its segments and manifest).
    extracted : ExtractedWindows, optional
        Its windows (:func:`extract_recording`).

    Returns
    -------
    list of str
        The problems found (empty when plausible).

    Raises
    ------
    EstimationError
        If a problem is found and ``allow`` is false (exit 6), naming the likely cause.
    """
    lo, hi, bias_limit, source = plausible_bounds((sensor or {}).get("model"))
    matrix = getattr(cal, "matrix", None)
    k = np.diag(np.asarray(matrix, dtype=float)) if matrix is not None else np.asarray(
        cal.scale, dtype=float)
    b = np.asarray(cal.bias, dtype=float)
    fs_dps = (sensor or {}).get("full_scale_dps")
    if not isinstance(fs_dps, (int, float)) or isinstance(fs_dps, bool) or not (
            math.isfinite(fs_dps) and fs_dps > 0):
        fs_dps = _DEFAULT_FULL_SCALE_DPS
    fs = math.radians(fs_dps)
    problems = []
    mixup = _full_scale_mixup(k, _MIXUP_TOLERANCE)
    bad = [j for j in range(3) if not (math.isfinite(k[j]) and lo <= k[j] <= hi)]
    if mixup is not None:
        values = ", ".join(f"{'xyz'[j]} = {k[j]:.4g}" for j in range(3))
        problems.append(
            f"scale {values}: every axis about {mixup:g}, a power of two: the readings were "
            "probably converted with the sensitivity of another full-scale range; check "
            "imu.range_dps against the range the chip was set to (and the recording's "
            "sensor.full_scale_dps and sensitivity)")
    elif bad:
        causes = dict.fromkeys(  # one line per distinct cause, in axis order
            _scale_cause(k[j]) if math.isfinite(k[j]) and k[j] > 0
            else "the fit did not find a usable scale: check the recording" for j in bad)
        values = ", ".join(f"{'xyz'[j]} = {k[j]:.4g}" for j in bad)
        problems.append(f"scale {values} outside {lo:.3g}..{hi:.3g} ({source}): "
                        + "; ".join(causes))
    bad = [j for j in range(3) if not (math.isfinite(b[j]) and abs(b[j]) <= fs)]
    beyond = [j for j in range(3) if j not in bad and bias_limit is not None
              and abs(b[j]) > bias_limit]
    if beyond:
        values = ", ".join(f"{'xyz'[j]} = {b[j]:.4g}" for j in beyond)
        problems.append(
            f"bias {values} rad/s beyond ±{bias_limit:.3g} rad/s ({source}): check that the "
            "sensor was still and warmed up at the start, that imu.model names the chip on the "
            "jig, and the gyro's units (rad/s)")
    if bad:
        values = ", ".join(f"{'xyz'[j]} = {b[j]:.4g}" for j in bad)
        problems.append(
            f"bias {values} rad/s beyond the gyro's full scale (±{fs_dps:g}°/s = "
            f"±{fs:.3g} rad/s): check the gyro's units (rad/s) and the sensitivity the "
            "readings were converted with")
    if recording is not None and extracted is not None:
        problems += _turn_rate_problems(recording, extracted)
        problems += _axis_problems(recording, extracted, cal)
    if problems and not allow:
        raise EstimationError(
            "implausible calibration, not written: " + "; ".join(problems)
            + ". If the sensor really is like this, pass --allow-implausible.")
    return problems


#: A turn's steady encoder rate must be within this factor of the speed its plan commanded
#: (a servo's velocity loop holds a few percent; 57 is degrees for radians).
_PLAN_RATE_FACTOR = 1.5
#: A rest-to-rest window (from still time before a turn to still time after it) averages the
#: ramps and the still margins too: its rate is at least this fraction of the commanded speed
#: (the paper's one-turn protocol at 60 °/s with 3 s waits gives about 0.6).
_REST_TO_REST_LOW = 0.25


def _turn_rate_problems(rec: Recording, ex: ExtractedWindows) -> list[str]:
    """Turns whose reference rate (the encoder angle change over the window) is not the speed
    the plan commanded (the segment's ``speed``, rad/s): encoder angles in degrees, or a
    velocity unit the driver converted wrongly. One line per distinct cause."""
    speeds = {s.index: float(s.speed) for s in rec.segments
              if s.kind == "rotate" and math.isfinite(s.speed) and s.speed > 0}
    ratios = [(w, abs(w.rate) / speeds[w.segment]) for w in ex.windows if w.segment in speeds]
    # a rest-to-rest window's mean includes the ramps and still margins: only slower
    bad = [(w, r) for w, r in ratios if not (_REST_TO_REST_LOW if w.kind == "rest-to-rest"
                                            else 1 / _PLAN_RATE_FACTOR) <= r <= _PLAN_RATE_FACTOR]
    if not bad:
        return []
    w, r = bad[0]
    deg = 180.0 / math.pi
    cause = ("the encoder angles are probably in degrees where Recording v1 wants radians "
             "(encoder.csv angle)" if abs(math.log(r / deg)) < math.log(1.5) else
             "check the encoder's angle unit (radians) and the speed unit of segments.csv "
             "(rad/s)")
    return [f"{len(bad)} of {len(ratios)} turns ran at a rate the plan did not command (segment "
            f"{w.segment}, servo {w.motor}: the encoders say {abs(w.rate):.4g} rad/s, the plan "
            f"{speeds[w.segment]:.4g} rad/s): {cause}"]


def _axis_problems(rec: Recording, ex: ExtractedWindows, cal: GyroCalibration) -> list[str]:
    """Servos whose axis in the sensor frame (estimated by the fit, or fitted to their windows
    under ``cal``) is nearest another signed axis than the one the manifest names
    (``gimbal.motors[].axis``): the gyro's columns swapped or negated, or the sensor mounted
    otherwise than the manifest says."""
    from gyrocal.kit.report_plots import nominal_axis, servo_axes

    if seat_starts(rec.manifest) is not None:
        # the single-servo jig: the one servo's axis is another in each seat, and each seat was
        # checked against gravity as it was taken (gyrocal.kit.seating.check_seat)
        return []
    named: dict[int, str] = {}
    for m in (rec.manifest.get("gimbal") or {}).get("motors") or []:
        if isinstance(m, Mapping) and isinstance(m.get("id"), int) \
                and isinstance(m.get("axis"), str):
            named[int(m["id"])] = m["axis"]
    motors = sorted({int(w.motor) for w in ex.windows if w.motor is not None} & set(named))
    try:
        found = servo_axes(motors, cal, rec.manifest, ex.windows)
        nominal = {m: nominal_axis(named[m]) for m in motors}
    except InputError:
        return []  # a malformed name or axis is reported where it is read
    wrong = []
    for m in motors:
        if found[m].source == "nominal":
            continue
        u = np.asarray(found[m].axis, dtype=float)
        j = int(np.argmax(np.abs(u)))
        near = np.zeros(3)
        near[j] = np.sign(u[j])
        if not np.array_equal(near, nominal[m]):
            name = ("+" if near[j] > 0 else "-") + "xyz"[j]
            wrong.append(f"servo {m} turns about {name} in the sensor frame, the manifest says "
                         f"{named[m]}")
    if not wrong:
        return []
    return ["; ".join(wrong) + ": check that imu.csv's gx,gy,gz are the sensor's x, y, z in "
            "that order and sign (a driver's axis map), and that the sensor is mounted as "
            "gimbal.motors[].axis says"]
