"""Plain-text reports of calibrations for the terminal."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from gyrocal.calib.model import GyroCalibration

__all__ = ["accelerometer_rows", "calibration_table"]


def calibration_table(cal: GyroCalibration, truth: Mapping[str, Any] | None = None) -> str:
    """The result table: scale and bias with standard deviations, the verdict, the axes.

    With ``truth`` (a simulated recording's ``{"scale", "bias"}``) each row also shows the error
    in units of its own standard deviation; a truth with a temperature model (``truth.
    temperature``) is taken at the calibration's mean die temperature.
    """
    from gyrocal.kit.thermal import truth_at

    truth = truth_at(truth, cal.temperature_c)
    lines = [f"gyrocal calibration ({cal.method}, {cal.iterations} iterations)"]
    if cal.matrix is not None:
        lines += _matrix_rows(cal, truth)
    else:
        lines += _diagonal_rows(cal, truth)
    _verdict(cal, lines)
    if cal.accelerometer is not None:
        lines += accelerometer_rows(cal.accelerometer, (truth or {}).get("accelerometer"))
    return "\n".join(lines)


def accelerometer_rows(acc: Any, truth: Mapping[str, Any] | None = None) -> list[str]:
    """The accelerometer's part of the summary: ``f = A (a + bias)`` (calib.accel) with standard
    deviations, the gravity it was fitted against and its χ² verdict; with a simulated truth
    (``truth.accelerometer``: ``matrix``, ``bias_m_s2``) the largest error in σ."""
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
    if truth is not None and "matrix" in truth and "bias_m_s2" in truth:
        il = np.tril_indices(3)
        em = (acc.matrix - np.asarray(truth["matrix"]))[il] / std[:6]
        eb = (acc.bias - np.asarray(truth["bias_m_s2"])) / std[6:]
        lines.append(f"error against the simulated truth, in σ: matrix max |err/σ| = "
                     f"{np.max(np.abs(em)):.2f}, bias " + " ".join(f"{v:+.2f}" for v in eb))
    c = acc.consistency
    verdict = "consistent" if c.ok else "NOT consistent"
    lines.append(f"accelerometer consistency: {verdict} with the measured noise (chi2 = "
                 f"{c.chi2:.1f} on {c.dof} dof, p = {c.p_value:.3g})")
    return lines


def _truth_matrix(truth: Mapping[str, Any]) -> np.ndarray:
    """The simulated sensor's true ``A`` in the calibration's frame (hardware_docs/method.md §9);
    a truth without ``misalignment`` is the paper's sensor."""
    from gyrocal.calib.estimators import matrix_in_frame

    mis = np.asarray(truth.get("misalignment", np.eye(3)), dtype=float)
    return matrix_in_frame(np.diag(1.0 / np.asarray(truth["scale"], dtype=float)) @ mis)


def _matrix_rows(cal: GyroCalibration, truth: Mapping[str, Any] | None) -> list[str]:
    A = np.asarray(cal.matrix)
    S = np.asarray(cal.matrix_std) if cal.matrix_std is not None else np.full((3, 3), np.nan)
    aligned = cal.frame == "accel-x-xy"  # --align-gyro-to-accel: A is full there
    where = ("the accelerometer's frame: x along its x axis, y in its x-y plane" if aligned else
             "A lower triangular: x along the gyro's x axis, y in its x-y plane")
    lines = [f"model: g = A (m + bias), rad/s; frame {cal.frame} ({where})", ""]
    head = f"{'row':<5}" + "".join(f"{'A_' + c:>13}{'± std':>10}" for c in "xyz")
    head += f"{'bias rad/s':>14}{'± std':>10}"
    lines.append(head)
    At = _truth_matrix(truth) if truth is not None else None
    for j, ax in enumerate("xyz"):
        row = f"{ax:<5}" + "".join(f"{A[j, i]:>13.6f}{S[j, i]:>10.1e}" for i in range(3))
        row += f"{cal.bias[j]:>14.6f}{cal.bias_std[j]:>10.1e}"
        lines.append(row)
    if At is not None and truth is not None:
        # the bias is added to the raw reading, so it compares in any frame; the true matrix is
        # known here in the gyro's frame only
        zb = (np.asarray(cal.bias) - np.asarray(truth["bias"])) / np.asarray(cal.bias_std)
        if aligned:
            text = "matrix not compared (it is in the accelerometer's frame)"
        else:
            free = S > 0
            z = np.where(free, (A - At) / np.where(free, S, 1.0), 0.0)
            text = f"matrix max |err/σ| = {np.max(np.abs(z)):.2f}"
        lines.append(f"error against the simulated truth, in σ: {text}, bias "
                     + " ".join(f"{v:+.2f}" for v in zb))
    lines.append("")
    return lines


def _diagonal_rows(cal: GyroCalibration, truth: Mapping[str, Any] | None) -> list[str]:
    lines = ["model: g = scale * (m + bias), rad/s", ""]
    head = f"{'axis':<5}{'scale':>12}{'± std':>11}{'bias rad/s':>14}{'± std':>11}"
    if truth is not None:
        head += f"{'scale err/σ':>13}{'bias err/σ':>12}"
    lines.append(head)
    for j, ax in enumerate("xyz"):
        row = (f"{ax:<5}{cal.scale[j]:>12.6f}{cal.scale_std[j]:>11.2e}"
               f"{cal.bias[j]:>14.6f}{cal.bias_std[j]:>11.2e}")
        if truth is not None:
            ks = (cal.scale[j] - truth["scale"][j]) / cal.scale_std[j]
            bs = (cal.bias[j] - truth["bias"][j]) / cal.bias_std[j]
            row += f"{ks:>13.2f}{bs:>12.2f}"
        lines.append(row)
    lines.append("")
    return lines


def _verdict(cal: GyroCalibration, lines: list[str]) -> None:
    c = cal.consistency
    if c is None:
        lines.append("consistency: not tested (no redundant observations)")
    else:
        verdict = "consistent" if c.ok else "NOT consistent"
        lines.append(
            f"consistency: {verdict} with the measured noise "
            f"(chi2 = {c.chi2:.1f} on {c.dof} dof, p = {c.p_value:.3g})"
        )
        if not c.ok:
            lines.append(
                "  the residuals are larger than the noise explains: check the mount (did the "
                "sensor slip or flex?), the gyro range (saturation), and repeat the run"
            )
    if cal.axes:
        lines.append("")
        lines.append("servo axes in the sensor frame (mounting misalignment):")
        for motor, info in sorted(cal.axes.items(), key=lambda kv: int(kv[0])):
            u = np.asarray(info["axis"])
            lines.append(
                f"  servo {motor}: [{u[0]:+.4f} {u[1]:+.4f} {u[2]:+.4f}]  nearest {info['nearest']}"
                f", off by {info['misalignment_deg']:.2f}° ± {info['std_deg']:.3f}°"
            )
    if cal.temperature_c is not None:
        lines.append(f"\nmean die temperature: {cal.temperature_c:.1f} °C")
