"""Thermal calibration: calibrations at several die temperatures to one thermal model (issue 13).

Two ways in:

* existing Calibration JSON files, or directories of them (what ``gyrocal history export``
  writes, or a set of ``gyrocal calibrate`` runs): :func:`collect_calibrations`;
* the jig itself: :func:`run_warmup` runs the calibration protocol back to back while the die
  temperature moves (a warm-up after power-on, a cold-soaked sensor warming, an ambient the
  user changes), each run a Recording v1 and a Calibration of its own.

Either way :func:`fit_calibrations` fits :func:`gyrocal.calib.thermal.fit_thermal` and
:func:`thermal_calibration` makes the Calibration document that carries it: the model at its
reference temperature as the calibration proper, and ``temperature_model``.

:func:`static_warmup` is the flight stacks' approach for comparison (PX4's thermal calibration,
ArduPilot's temperature calibration): the sensor still while it warms, bias only, the scale (or
matrix) of one spin calibration kept at every temperature.
"""

from __future__ import annotations

import argparse
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from gyrocal.calib.errors import CalibInputError
from gyrocal.calib.model import FORMAT, GyroCalibration
from gyrocal.calib.observations import diff_noise
from gyrocal.calib.thermal import ThermalModel, fit_thermal
from gyrocal.kit.errors import InputError

__all__ = [
    "STATIC_BIN_S",
    "WarmupRun",
    "collect_calibrations",
    "fit_calibrations",
    "run_warmup",
    "scale_drift_note",
    "static_warmup",
    "thermal_calibration",
    "truth_at",
]

#: Length of one block of a static warm-up, s: one bias point per block (PX4 and ArduPilot
#: fit to samples accumulated over the warm-up in the same way).
STATIC_BIN_S = 10.0


def truth_at(truth: Mapping[str, Any] | None, temperature_c: float | None
             ) -> Mapping[str, Any] | None:
    """A simulated recording's ``truth`` at one die temperature: ``scale`` and ``bias`` moved
    by ``truth.temperature`` (the emulator's coefficients, :class:`~gyrocal.drivers.emulated.
    imu_chips.SensorTruth`); unchanged without a temperature model or a temperature."""
    if truth is None or temperature_c is None or "temperature" not in truth:
        return truth
    tm = truth["temperature"]
    d = float(temperature_c) - float(tm["reference_c"])
    coeffs = np.asarray(tm["bias_coeffs"], dtype=float)
    bias = coeffs @ d ** np.arange(coeffs.shape[1])
    scale = np.asarray(truth["scale"], dtype=float) * (
        1.0 + np.asarray(tm["scale_coeff_per_c"], dtype=float) * d)
    return {**truth, "scale": scale.tolist(), "bias": bias.tolist()}


def turn_temperature_offsets(imu_t: np.ndarray, imu_temp: np.ndarray, windows: Sequence[Any],
                             mean_c: float) -> dict[int, float]:
    """Per servo, the mean die temperature of its turn windows minus the run's mean ``mean_c``
    (°C): where, on the run's warm-up, each axis's scale was measured."""
    from gyrocal.calib.windows import window_temperatures

    temps = window_temperatures(np.asarray(imu_t, float), np.asarray(imu_temp, float), windows)
    out: dict[int, float] = {}
    for motor in sorted({int(w.motor) for w in windows if w.motor is not None}):
        sel = np.array([w.motor == motor for w in windows]) & np.isfinite(temps)
        if sel.any():
            out[motor] = float(temps[sel].mean()) - float(mean_c)
    return out


def scale_drift_note(imu_t: np.ndarray, imu_temp: np.ndarray, windows: Sequence[Any],
                     cal: GyroCalibration, sensor_model: str | None) -> str | None:
    """Flag the scale's temperature drift within one run (issue 13, "within one calibration
    run"), or None when it is below the scale's standard deviation.

    The paper's fit (Eq. 1) takes each axis's scale from that axis's turns, so when the die
    warms during the run each scale is the one at the temperature of its own turns,
    ``T̄ + δ_servo``, not at the run's mean ``T̄`` that the calibration reports (the bias is
    referred to ``T̄`` by :func:`gyrocal.calib.thermal.correct_drift`; the scale's coefficient
    cannot be measured within one run). With the chip's datasheet sensitivity change ``k``
    (:data:`gyrocal.drivers.emulated.thermal.THERMAL_DATASHEET`: ±change over half the rated
    range, per °C) the scale may be off by up to ``k · max |δ|`` (relative); that is reported
    when it exceeds the scale's relative standard deviation, which does not include it.
    """
    from gyrocal.drivers.emulated.thermal import THERMAL_DATASHEET

    if cal.temperature_c is None or imu_temp is None or not np.any(np.isfinite(imu_temp)):
        return None
    spec = THERMAL_DATASHEET.get(str(sensor_model or "").lower().replace("-", ""))
    offsets = turn_temperature_offsets(imu_t, imu_temp, windows, cal.temperature_c)
    if spec is None or not offsets:
        return None
    k = spec.sensitivity_change / (spec.span_c / 2.0)
    worst = k * max(abs(d) for d in offsets.values())
    std = np.diag(cal.matrix_std) if cal.is_full and cal.matrix_std is not None \
        else np.asarray(cal.scale_std, dtype=float)
    rel = std / np.abs(np.asarray(cal.scale, dtype=float))
    rel = rel[np.isfinite(rel)]
    if rel.size == 0 or worst <= float(rel.min()):
        return None
    where = ", ".join(f"servo {m} {d:+.2f}" for m, d in offsets.items())
    return (f"the scale drifts with the die temperature within the run: the servos' turns were "
            f"at {where} °C from the run's mean {cal.temperature_c:.2f} °C, so with the "
            f"{sensor_model}'s datasheet sensitivity change (up to {k * 100:.3f} %/°C, "
            f"{spec.source}) a scale may be off by up to {worst:.1e} (relative), "
            f"{worst / float(rel.min()):.1f}× its standard deviation, which does not include "
            "it; let the sensor warm up first, or calibrate over the warm-up with gyrocal "
            "thermal")


def collect_calibrations(paths: Sequence[str]) -> list[tuple[str, GyroCalibration]]:
    """The calibrations in ``paths``: Calibration JSON files, or directories searched
    recursively for them (JSON files of another kind inside a directory, and thermal models,
    are passed over).

    Raises
    ------
    InputError
        A path that does not exist, a file given by name that is not a valid Calibration or is
        a thermal model, a directory without any, or a calibration without its mean die
        temperature.
    """
    from gyrocal.kit.exports import load_document, read_json

    found: list[tuple[str, GyroCalibration]] = []
    for p in map(Path, paths):
        if p.is_dir():
            inside = []
            for f in sorted(p.rglob("*.json")):
                try:
                    doc = read_json(str(f), "calibration")
                except InputError:
                    continue
                if (isinstance(doc, dict) and doc.get("format") == FORMAT
                        and doc.get("temperature_model") is None):  # a fit is not a point
                    inside.append((str(f), load_document(str(f), FORMAT, "calibration")))
            if not inside:
                raise InputError(f"{p} holds no gyrocal calibration (*.json with format "
                                 f"{FORMAT!r}); give calibration files or their directory")
            found += inside
        elif p.exists():
            cal = load_document(str(p), FORMAT, "calibration")
            if cal.temperature_model is not None:
                raise InputError(f"{p} is a thermal model (it has a temperature_model), not a "
                                 "calibration at one temperature; give the calibrations it was "
                                 "fitted on")
            found.append((str(p), cal))
        else:
            raise InputError(f"{p} does not exist; give Calibration JSON files or directories "
                             "of them")
    for path, cal in found:
        if cal.temperature_c is None:
            raise InputError(f"calibration {path} has no temperature_c (mean die temperature); "
                             "a thermal model needs it: recalibrate with the temperature recorded")
    return found


def fit_calibrations(cals: Sequence[GyroCalibration]) -> ThermalModel:
    """Fit the thermal model of a set of calibrations (:func:`gyrocal.calib.thermal.
    fit_thermal`): the full matrix when every one is a full-model calibration with its
    ``matrix_std``, the paper's diagonal scale otherwise. The bias's wander over each run
    (a calibration's ``bias_drift``, part of its ``bias_std``) is shared by calibrations made
    minutes apart, so it is passed as their common variance rather than as independent scatter
    that the fit would average away.

    Raises
    ------
    InputError
        If the set cannot be fitted (the message says why: too few, one temperature, a
        calibration without standard deviations).
    """
    full = all(c.is_full and c.matrix_std is not None for c in cals)
    temps = [c.temperature_c for c in cals]
    if any(t is None for t in temps):
        raise InputError("every calibration needs its mean die temperature (temperature_c)")
    gain = [c.full_matrix if full else c.scale for c in cals]
    gain_std = [c.matrix_std if full else c.scale_std for c in cals]
    try:
        return fit_thermal(np.array(temps, dtype=float), np.array([c.bias for c in cals]),
                           np.array([c.bias_std for c in cals]), np.array(gain),
                           np.array(gain_std, dtype=float),
                           bias_common_var=np.array([np.zeros(3) if c.bias_drift is None
                                                     else c.bias_drift.run_variance
                                                     for c in cals]))
    except CalibInputError as exc:
        raise InputError(f"cannot fit a thermal model: {exc}") from None


def thermal_calibration(cals: Sequence[GyroCalibration], model: ThermalModel,
                        source: str, created: str | None = None) -> GyroCalibration:
    """The Calibration document of a thermal fit: the calibration nearest the model's reference
    temperature, its scale/matrix and bias replaced by the model's at the reference (their
    standard deviations the model's), and the model as ``temperature_model``.

    Its covariance is dropped (the model's uncertainties replace it); the kinematics, frame and
    sensor are those of the nearest calibration. ``model`` may be bias-only (a static warm-up):
    then the nearest calibration's scale/matrix is kept.
    """
    ref = model.reference_c
    base = min(cals, key=lambda c: abs(float(c.temperature_c) - ref))  # type: ignore[arg-type]
    st = model.at(ref)
    kw: dict[str, Any] = {"bias": tuple(st.bias), "bias_std": tuple(st.bias_std)}
    if st.gain is not None:
        if not model.diagonal:
            kw.update(matrix=st.gain, matrix_std=st.gain_std,
                      scale=tuple(np.diag(st.gain)), scale_std=(math.nan,) * 3)
        else:  # the paper's diagonal model (a set that was not all full-model): version 1
            kw.update(scale=tuple(np.diag(st.gain)), scale_std=tuple(np.diag(st.gain_std)),
                      matrix=None, matrix_std=None, frame=None, kinematics=None)
    return replace(base, **kw, covariance=None, temperature_c=ref, consistency=model.consistency,
                   method=f"thermal ({model.kind}; {base.method})", iterations=0, source=source,
                   created=created, temperature_model=model)


@dataclass(frozen=True)
class WarmupRun:
    """One calibration of a warm-up: where it was written and what it gave."""

    directory: Path
    calibration: GyroCalibration
    jig_time_s: float
    notes: tuple[str, ...]


def run_warmup(jig: Any, cfg: Any, args: argparse.Namespace, work: Path, runs: int,
               wait_s: float = 0.0, on_run: Any = None) -> list[WarmupRun]:
    """Run the calibration protocol ``runs`` times back to back on ``jig``
    (:class:`~gyrocal.kit.jig.Jig`, the emulated one with ``--sim``), waiting
    ``wait_s`` between runs, into ``work/run-NN/recording`` and ``work/run-NN/calibration.json``.

    The servos stop with torque off after every run and after any failure (each run opens and
    closes the gimbal as ``gyrocal calibrate`` does); the caller closes the jig. Every run
    runs the protocol planned for the first (:func:`~gyrocal.kit.jig.choose_plan`, its still
    noise): the calibrations the thermal model compares come from one protocol, and the plan's
    search (a few CPU seconds) is made once.

    Returns
    -------
    list of WarmupRun

    Raises
    ------
    InputError, EstimationError, DriverError
        As ``gyrocal calibrate``; a run that cannot be fitted stops the warm-up.
    """
    from gyrocal.kit.fileio import atomic_write_text
    from gyrocal.kit.jig import record_protocol
    from gyrocal.kit.pipeline import check_plausible, estimate_recording
    from gyrocal.kit.recording import load_recording

    out: list[WarmupRun] = []
    plan = None
    for i in range(runs):
        run_dir = work / f"run-{i + 1:02d}"
        t0 = jig.clock.monotonic()
        plan = record_protocol(cfg, args, jig, run_dir / "recording", plan=plan)
        rec = load_recording(run_dir / "recording")
        est = estimate_recording(rec, cfg["protocol"]["method"],
                                 source=str(run_dir / "recording"))
        check_plausible(est.calibration, rec.sensor,
                        allow=getattr(args, "allow_implausible", False), recording=rec,
                        extracted=est.extracted)
        atomic_write_text(run_dir / "calibration.json", est.calibration.to_json() + "\n")
        run = WarmupRun(run_dir, est.calibration, jig.clock.monotonic() - t0,
                        (*est.extracted.warnings, *est.notes))
        out.append(run)
        if on_run is not None:
            on_run(i, run)
        if wait_s > 0 and i + 1 < runs:
            jig.clock.sleep(wait_s)
    return out


def static_warmup(jig: Any, seconds: float, bin_s: float = STATIC_BIN_S
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Read the still sensor for ``seconds`` on ``jig`` (servos off) and return per block of
    ``bin_s`` its mean die temperature (n,), bias ``−mean reading`` (n, 3) and the bias's
    standard deviation (n, 3) from the block's white noise (first differences).

    Raises
    ------
    InputError
        If the stream gave no temperature, or fewer than two blocks.
    """
    clock, imu = jig.clock, jig.imu
    t_parts, r_parts, c_parts = [], [], []
    imu.start()
    try:
        end = clock.monotonic() + float(seconds)
        while clock.monotonic() < end:
            clock.sleep(0.1)
            b = imu.read()
            t_parts.append(b.t)
            r_parts.append(b.rate)
            c_parts.append(b.temperature_c)
    finally:
        imu.stop()
    t, rate, temp = (np.concatenate(x) for x in (t_parts, r_parts, c_parts))
    if temp.size == 0 or not np.any(np.isfinite(temp)):
        raise InputError("the still warm-up gave no die temperature; the IMU must report it")
    edges = np.arange(t[0], t[-1] + bin_s, bin_s)
    idx = np.digitize(t, edges) - 1
    T, bias, std = [], [], []
    for k in np.unique(idx):
        sel = idx == k
        if sel.sum() < 20:
            continue
        T.append(float(np.nanmean(temp[sel])))
        bias.append(-rate[sel].mean(axis=0))
        std.append(np.maximum(diff_noise(rate[sel]), 1e-12) / math.sqrt(sel.sum()))
    if len(T) < 2:
        raise InputError(f"the still warm-up of {seconds:g} s gave fewer than two "
                         f"{bin_s:g}-s blocks; record longer")
    return np.array(T), np.array(bias), np.array(std)


def write_model_json(path: Path, cal: GyroCalibration) -> None:
    """Write the thermal Calibration document to ``path`` (atomically)."""
    from gyrocal.kit.fileio import atomic_write_text

    atomic_write_text(path, cal.to_json() + "\n")


def thermal_on_jig(cfg: Any, args: argparse.Namespace, out: Path, work: Path, *,
                   quiet: bool = False) -> tuple[GyroCalibration, list[tuple[str, Any]], Any]:
    """``gyrocal thermal`` on the jig: :func:`run_warmup` (``args.runs`` runs, ``args.wait``
    apart), or with ``args.static`` one run then :func:`static_warmup`; the thermal Calibration
    written to ``out/calibration.json`` (built in ``work``, swapped in at the end as
    ``gyrocal calibrate`` does).

    Returns
    -------
    (GyroCalibration, list of (name, GyroCalibration), dict or None)
        The thermal calibration, the calibrations it was fitted on, and the simulated truth
        (``--sim``) for the report.
    """
    import sys

    from gyrocal.drivers.signals import shielded
    from gyrocal.kit.fileio import built_beside
    from gyrocal.kit.recording import now_iso

    static = getattr(args, "static", None)
    runs_wanted = 1 if static is not None else args.runs

    def progress(i: int, run: WarmupRun) -> None:
        if not quiet:
            print(f"gyrocal: run {i + 1}/{runs_wanted}: {run.calibration.temperature_c:.2f} °C, "
                  f"{run.jig_time_s:.0f} s", file=sys.stderr)

    if not quiet:  # the protocol's own progress display is off: one line per run instead
        print(f"gyrocal: thermal: {runs_wanted} calibration run(s)"
              + (f", then {static:g} s still" if static is not None else ""), file=sys.stderr)
    from gyrocal.kit.jig import Jig

    quiet_args = argparse.Namespace(**{**vars(args), "quiet": True})
    with built_beside(work, out):
        jig = Jig(cfg, args)
        try:
            runs = run_warmup(jig, cfg, quiet_args, work, runs_wanted, args.wait, progress)
            if static is not None:
                T, bias, std = static_warmup(jig, static)
        finally:
            with shielded():
                jig.close()
        cals = [r.calibration for r in runs]
        names = [str(r.directory.name) for r in runs]
        if static is not None:
            try:
                model = fit_thermal(T, bias, std, kind="static")
            except CalibInputError as exc:
                raise InputError(f"cannot fit the still warm-up: {exc}") from None
        else:
            model = fit_calibrations(cals)
        cal = thermal_calibration(cals, model, source=str(out), created=now_iso())
        write_model_json(work / "calibration.json", cal)
    truth = None if jig.sim is None else jig.sim.truth.manifest()
    return cal, list(zip(names, cals, strict=True)), truth


def tracker_tempco(cal: GyroCalibration) -> tuple[tuple[float, ...], tuple[float, ...]] | None:
    """The bias tracker's temperature-coefficient prior from ``cal``'s thermal model: the
    slope ``db/dT`` at the calibration's temperature (the tracker's reference) and its standard
    deviation, widened by the curvature over half the covered range (the tracker's coefficient
    is linear); None without a model or a bias slope."""
    tm = cal.temperature_model
    if tm is None or tm.bias_order < 1:
        return None
    d = (cal.temperature_c if cal.temperature_c is not None else tm.reference_c) - tm.reference_c
    k = np.arange(1, tm.bias_order + 1)
    v = np.zeros(tm.bias_order + 1)
    v[1:] = k * d ** (k - 1)  # d/dT of the powers at d
    slope = tm.bias_coeffs @ v
    std = np.sqrt(np.einsum("i,aij,j->a", v, tm.bias_coeffs_covariance, v))
    half = 0.5 * (tm.range_c[1] - tm.range_c[0])
    curve = np.abs(tm.bias_coeffs[:, 2]) * 2 * half if tm.bias_order >= 2 else np.zeros(3)
    std = np.maximum(np.hypot(std, curve), 1e-9)
    return tuple(float(x) for x in slope), tuple(float(x) for x in std)
