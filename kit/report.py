"""Plain-text reports of calibrations for the terminal."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from gyrocal.calib.model import GyroCalibration
from gyrocal.kit.jig_kinds import DEFAULT_JIG, axis_label

__all__ = ["TruthError", "accelerometer_rows", "calibration_table", "error_against_truth",
           "inconsistency_causes", "model_choice_rows"]


@dataclass(frozen=True)
class TruthError:
    """A calibration's error against a simulated recording's truth, each parameter in units of
    its own standard deviation (what the terminal table and the HTML report both print).

    Attributes
    ----------
    bias : ndarray (3,)
        ``(b − b_true) / σ_b`` per axis (the bias is added to the raw reading, so it compares in
        any frame).
    matrix : ndarray (3, 3) or None
        ``(A − A_true) / σ_A`` of the full model's free entries (0 where ``A`` is fixed by its
        frame, σ = 0); ``A_true`` is the simulated sensor's in the gyro's frame
        (:func:`gyrocal.calib.estimators.matrix_in_frame`, hardware_docs/method.md §9). None
        for the diagonal model, or when the matrix is in another frame (``matrix_note``).
    scale : ndarray (3,) or None
        ``(k − k_true) / σ_k`` of the diagonal model (paper Eq. 1); None for the full model.
    matrix_note : str or None
        Why the matrix was not compared, when it was not.
    accel_matrix, accel_bias : ndarray or None
        The accelerometer's (``f = A (a + b)``, lower triangle of ``A`` and ``b``), where the
        calibration and the truth both have one.
    general_motion : float or None
        The calibrated rate's RMS error over all directions of a motion at 1 rad/s, per rad/s
        (:func:`gyrocal.calib.design.general_motion_rms`, in any output frame): what the
        calibration's ``model_choice`` predicts.
    """

    bias: np.ndarray
    matrix: np.ndarray | None = None
    scale: np.ndarray | None = None
    matrix_note: str | None = None
    accel_matrix: np.ndarray | None = None
    accel_bias: np.ndarray | None = None
    general_motion: float | None = None

    @property
    def matrix_max(self) -> float | None:
        """``max |err/σ|`` over the gyro's matrix (or its scale factors), None if not compared."""
        z = self.matrix if self.matrix is not None else self.scale
        return None if z is None else float(np.max(np.abs(z)))

    @property
    def accel_matrix_max(self) -> float | None:
        """``max |err/σ|`` over the accelerometer's matrix, None without one."""
        return None if self.accel_matrix is None else float(np.max(np.abs(self.accel_matrix)))


def error_against_truth(cal: GyroCalibration, truth: Mapping[str, Any] | None
                        ) -> TruthError | None:
    """The calibration's error against a simulated recording's ``truth`` (its manifest's
    ``scale``, ``bias``, ``misalignment``, ``accelerometer``), in units of each parameter's own
    standard deviation; None without a truth.

    A truth with a temperature model (``truth.temperature``) is taken at the calibration's mean
    die temperature (:func:`gyrocal.kit.thermal.truth_at`). The one computation behind the
    terminal's table (:func:`calibration_table`) and the HTML report
    (:mod:`gyrocal.kit.report_html`).
    """
    from gyrocal.kit.thermal import truth_at

    truth = truth_at(truth, cal.temperature_c)
    if truth is None:
        return None
    bias = (np.asarray(cal.bias) - np.asarray(truth["bias"])) / np.asarray(cal.bias_std)
    matrix = scale = note = None
    if cal.matrix is None:
        scale = (np.asarray(cal.scale) - np.asarray(truth["scale"])) / np.asarray(cal.scale_std)
    elif cal.frame == "accel-x-xy":  # --align-gyro-to-accel: A is full there
        note = "matrix not compared (it is in the accelerometer's frame)"
    else:
        A, At = np.asarray(cal.matrix), _truth_matrix(truth)
        S = (np.asarray(cal.matrix_std) if cal.matrix_std is not None
             else np.full((3, 3), np.nan))
        free = S > 0
        matrix = np.where(free, (A - At) / np.where(free, S, 1.0), 0.0)
    acc, acc_truth = cal.accelerometer, truth.get("accelerometer")
    acc_m = acc_b = None
    if acc is not None and isinstance(acc_truth, Mapping) and {"matrix", "bias_m_s2"} <= set(
            acc_truth):
        il = np.tril_indices(3)
        acc_m = (acc.matrix - np.asarray(acc_truth["matrix"]))[il] / acc.std[:6]
        acc_b = (acc.bias - np.asarray(acc_truth["bias_m_s2"])) / acc.std[6:]
    return TruthError(bias, matrix, scale, note, acc_m, acc_b, _general_motion(cal, truth))


def _general_motion(cal: GyroCalibration, truth: Mapping[str, Any]) -> float:
    """:func:`gyrocal.calib.design.general_motion_rms` of ``cal`` against the truth's sensor
    ``C = diag(1/scale) @ misalignment`` and bias."""
    from gyrocal.calib.design import general_motion_rms

    mis = np.asarray(truth.get("misalignment", np.eye(3)), dtype=float)
    sensing = np.diag(1.0 / np.asarray(truth["scale"], dtype=float)) @ mis
    return general_motion_rms(cal.full_matrix, np.asarray(cal.bias), sensing,
                              np.asarray(truth["bias"], dtype=float))


def calibration_table(cal: GyroCalibration, truth: Mapping[str, Any] | None = None, *,
                      jig: str = DEFAULT_JIG) -> str:
    """The result table: scale and bias with standard deviations, the verdict, the axes.

    With ``truth`` (a simulated recording's ``{"scale", "bias"}``) the table also shows the
    error in units of each parameter's standard deviation (:func:`error_against_truth`). The
    turn axes are named as the recording's ``jig`` names them
    (:func:`gyrocal.kit.jig_kinds.axis_label`: ``servo 2`` on a gimbal, ``box axis y`` on the
    hand jig), as the HTML report names them.
    """
    try:
        err = error_against_truth(cal, truth)
    except (TypeError, ValueError, KeyError, IndexError, AttributeError):
        if truth is None:
            raise
        # a hand-edited manifest's truth (a string for a number): the calibration, already
        # written, is shown without the comparison rather than lost to a traceback
        return (calibration_table(cal, None, jig=jig) + "\n(the recording manifest's 'truth' "
                "is not the simulator's numbers: not compared)")
    lines = [f"gyrocal calibration ({cal.method}, {cal.iterations} iterations)"]
    if cal.matrix is not None:
        lines += _matrix_rows(cal, err)
    else:
        lines += _diagonal_rows(cal, err)
    lines += model_choice_rows(cal, err)
    _verdict(cal, lines)
    lines += _axes_rows(cal, jig)
    lines += _trailer_rows(cal)
    if cal.accelerometer is not None:
        lines += accelerometer_rows(cal.accelerometer, err)
    return "\n".join(lines)


def model_choice_rows(cal: GyroCalibration, err: TruthError | None = None) -> list[str]:
    """Why the calibration has its model (:attr:`GyroCalibration.model_choice`: each model's
    predicted general-motion error), and with a simulated truth the error it actually has
    (:func:`error_against_truth`); nothing for a calibration without either."""
    import textwrap

    lines = []
    if cal.model_choice is not None:
        lines += textwrap.wrap(cal.model_choice.sentence(), 100)
    if err is not None and err.general_motion is not None:
        lines.append(f"general-motion error against the simulated truth: {err.general_motion:.2g}"
                     " per rad/s (RMS over all directions at 1 rad/s)")
    return [*lines, ""] if lines else []


def accelerometer_rows(acc: Any, err: TruthError | None = None) -> list[str]:
    """The accelerometer's part of the summary: ``f = A (a + bias)`` (calib.accel) with standard
    deviations, the gravity it was fitted against and its χ² verdict; with the error against a
    simulated truth (:func:`error_against_truth`) the largest error in σ."""
    std = acc.std
    S = np.zeros((3, 3))
    S[np.tril_indices(3)] = std[:6]
    lines = ["", f"accelerometer, calibrated from the same run: the rests between the turns held "
             f"the sensor still in {acc.rests} orientations, each a look at gravity.",
             "It is in the calibration file too: a flight stack calibrates its accelerometer with "
             "it, and applying a gyro's g-sensitivity needs the specific force it measures.",
             f"model: f = A (a + bias), m/s²; frame accel-x-xy, fitted against gravity "
             f"{acc.gravity:.5f} m/s²", ""]
    lines.append(f"{'row':<5}" + "".join(f"{'A_' + c:>13}{'± std':>10}" for c in "xyz")
                 + f"{'bias m/s²':>14}{'± std':>10}")
    for j, ax in enumerate("xyz"):
        lines.append(f"{ax:<5}" + "".join(f"{acc.matrix[j, i]:>13.6f}{S[j, i]:>10.1e}"
                                          for i in range(3))
                     + f"{acc.bias[j]:>14.5f}{std[6 + j]:>10.1e}")
    if err is not None and err.accel_bias is not None:
        lines.append(f"error against the simulated truth, in σ: matrix max |err/σ| = "
                     f"{err.accel_matrix_max:.2f}, bias "
                     + " ".join(f"{v:+.2f}" for v in err.accel_bias))
    c = acc.consistency
    lines.append(f"accelerometer consistency: {_words(c)} (chi2 = "
                 f"{c.chi2:.1f} on {c.dof} dof, p = {c.p_value:.3g})")
    if acc.fixed:
        lines.append(f"  {acc.advice}")
    return lines


def _words(c: Any) -> str:
    """The verdict as the report prints it (:attr:`Consistency.verdict`, DESIGN.md fact 7)."""
    if not c.ok:
        return "NOT consistent with the measured noise" + (f" ({c.reason})" if c.reason else "")
    return c.verdict if c.excess > 0 else "consistent with the measured noise"


def _truth_matrix(truth: Mapping[str, Any]) -> np.ndarray:
    """The simulated sensor's true ``A`` in the calibration's frame (hardware_docs/method.md §9);
    a truth without ``misalignment`` is the paper's sensor."""
    from gyrocal.calib.estimators import matrix_in_frame

    mis = np.asarray(truth.get("misalignment", np.eye(3)), dtype=float)
    return matrix_in_frame(np.diag(1.0 / np.asarray(truth["scale"], dtype=float)) @ mis)


def _matrix_rows(cal: GyroCalibration, err: TruthError | None) -> list[str]:
    A = np.asarray(cal.matrix)
    S = np.asarray(cal.matrix_std) if cal.matrix_std is not None else np.full((3, 3), np.nan)
    aligned = cal.frame == "accel-x-xy"  # --align-gyro-to-accel: A is full there
    where = ("the accelerometer's frame: x along its x axis, y in its x-y plane" if aligned else
             "A lower triangular: x along the gyro's x axis, y in its x-y plane")
    lines = [f"model: g = A (m + bias), rad/s; frame {cal.frame} ({where})", ""]
    head = f"{'row':<5}" + "".join(f"{'A_' + c:>13}{'± std':>10}" for c in "xyz")
    head += f"{'bias rad/s':>14}{'± std':>10}"
    lines.append(head)
    for j, ax in enumerate("xyz"):
        row = f"{ax:<5}" + "".join(f"{A[j, i]:>13.6f}{S[j, i]:>10.1e}" for i in range(3))
        row += f"{cal.bias[j]:>14.6f}{cal.bias_std[j]:>10.1e}"
        lines.append(row)
    if err is not None:
        text = err.matrix_note or f"matrix max |err/σ| = {err.matrix_max:.2f}"
        lines.append(f"error against the simulated truth, in σ: {text}, bias "
                     + " ".join(f"{v:+.2f}" for v in err.bias))
    lines.append("")
    return lines


def _diagonal_rows(cal: GyroCalibration, err: TruthError | None) -> list[str]:
    lines = ["model: g = scale * (m + bias), rad/s", ""]
    head = f"{'axis':<5}{'scale':>12}{'± std':>11}{'bias rad/s':>14}{'± std':>11}"
    if err is not None:
        head += f"{'scale err/σ':>13}{'bias err/σ':>12}"
    lines.append(head)
    for j, ax in enumerate("xyz"):
        row = (f"{ax:<5}{cal.scale[j]:>12.6f}{cal.scale_std[j]:>11.2e}"
               f"{cal.bias[j]:>14.6f}{cal.bias_std[j]:>11.2e}")
        if err is not None and err.scale is not None:
            row += f"{err.scale[j]:>13.2f}{err.bias[j]:>12.2f}"
        lines.append(row)
    lines.append("")
    return lines


def inconsistency_causes(cal: GyroCalibration) -> str:
    """What to do when the fit's residuals are larger than the noise explains, the likely
    causes most likely first.

    A diagonal calibration (the paper's model, protocols ``paper`` and ``auto``) leaves the
    cross-axis terms (±2 % on the datasheets) and the g-sensitivity in its residuals, hundreds of
    times the noise on a realistic sensor: the model is the likeliest cause, then a sensor that
    slipped or flexed on the mount, then saturation. The full model has no such terms left out.
    """
    slip = "the sensor slipped or flexed on the mount: tighten it and repeat the run"
    saturation = ("the gyro saturated during the turns: a larger imu.range_dps, or a slower "
                  "protocol.speed_dps")
    if cal.matrix is None:
        causes = ["the model is too simple: the diagonal model leaves the cross-axis terms and "
                  "the g-sensitivity the rests do not determine in the residuals; calibrate "
                  "the full model with "
                  "--protocol full (a note on stderr gives both models' predicted errors "
                  "when the full one was not kept)", slip, saturation]
    else:
        causes = [slip, saturation]
    return "the residuals are larger than the noise explains; likely causes, most likely " \
        "first: " + "; ".join(f"({i}) {c}" for i, c in enumerate(causes, 1))


def _drift_rows(d: Any) -> list[str]:
    """The bias's wander (:class:`gyrocal.calib.drift.BiasDrift`): what its σ includes, and
    how far the bias an hour later may be from the calibration's
    (:attr:`~gyrocal.calib.drift.BiasDrift.wander`)."""
    run = np.sqrt(d.run_variance)
    return [f"bias wander {d.horizon_s / 3600:g} h after calibration, against this bias "
            "(1 sigma): "
            + " ".join(f"{x:.1e}" for x in d.wander) + " rad/s"
            f" (bias instability {max(d.bias_instability):.2g} rad/s, rate random walk "
            f"{max(d.rate_random_walk):.2g} rad/s/√s: {d.source});",
            f"  the bias ± std above includes its wander over the {d.span_s:.0f} s run, "
            + " ".join(f"{x:.1e}" for x in run) + " rad/s"]


def _verdict(cal: GyroCalibration, lines: list[str]) -> None:
    c = cal.consistency
    if c is None:
        lines.append("consistency: not tested (no redundant observations)")
    else:
        lines.append(
            f"consistency: {_words(c)} "
            f"(chi2 = {c.chi2:.1f} on {c.dof} dof, p = {c.p_value:.3g})"
        )
        if not c.ok:
            lines.append("  " + inconsistency_causes(cal))


def _axes_rows(cal: GyroCalibration, jig: str) -> list[str]:
    """The turn axes the fit estimated, each named as ``jig`` names it (:func:`axis_label`)."""
    if not cal.axes:
        return []
    lines = ["", "turn axes in the sensor frame (mounting misalignment):"]
    for motor, info in sorted(cal.axes.items(), key=lambda kv: int(kv[0])):
        u = np.asarray(info["axis"])
        lines.append(
            f"  {axis_label(jig, int(motor))}: [{u[0]:+.4f} {u[1]:+.4f} {u[2]:+.4f}]  nearest "
            f"{info['nearest']}, off by {info['misalignment_deg']:.2f}° ± {info['std_deg']:.3f}°"
        )
    return lines


def _trailer_rows(cal: GyroCalibration) -> list[str]:
    """The bias's wander and the die temperature, where the calibration has them."""
    lines = []
    if cal.bias_drift is not None:
        lines += ["", *_drift_rows(cal.bias_drift)]
    if cal.temperature_c is not None:
        lines.append(f"\nmean die temperature: {cal.temperature_c:.1f} °C")
    return lines
