"""Verification of a calibration against the servo encoders (the paper's Tables V and VI).

The paper compares the calibrated gyro with a second, pre-calibrated gyroscope. Here the reference
is the servo itself: during each turn the true rate in the sensor frame is the encoder's rate
along the servo's axis, ``ω(t) u_s``, and at rest it is zero. The readings are compared in blocks
(half a second by default): the encoder's angle change over a block divided by its length against
the gyro's mean over the same block, raw and calibrated, and the RMS error of each axis is
reported before and after calibration.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gyrocal.calib.model import GyroCalibration
from gyrocal.kit.errors import InputError
from gyrocal.kit.recording import Recording
from gyrocal.kit.report_plots import encoder_rate, servo_axes

__all__ = ["Verification", "verify_recording"]


@dataclass(frozen=True)
class Verification:
    """Per-axis RMS rate errors against the encoder reference.

    Attributes
    ----------
    rms_before, rms_after : ndarray (3,)
        rad/s, raw readings and calibrated readings.
    rms_after_turning, rms_after_rest : ndarray (3,)
        The calibrated error in blocks at steady speed (the encoder's rate within 5 % of the
        turn's commanded speed) and at rest. Blocks on the acceleration ramps are in the totals
        only: there the gyro's low-pass delay of a few milliseconds against the encoder makes
        errors that say nothing about the calibration.
    blocks : int
        Blocks compared.
    block_s : float
    axes_source : str
        Where the servo axes came from: ``calibration`` (its estimated axes), ``nominal
        configuration`` (the axis names in the recording's manifest) or both.
    """

    rms_before: np.ndarray
    rms_after: np.ndarray
    rms_after_turning: np.ndarray
    rms_after_rest: np.ndarray
    blocks: int
    block_s: float
    axes_source: str

    def table(self) -> str:
        """The result as text (like the paper's Tables V and VI)."""
        lines = [
            f"RMS rate error against the encoder reference ({self.blocks} blocks of "
            f"{self.block_s:g} s; servo axes from the {self.axes_source})",
            f"{'axis':<6}{'before (rad/s)':>16}{'after (rad/s)':>16}{'ratio':>9}"
            f"{'after, steady':>17}{'after, at rest':>17}",
        ]

        def num(v: float, width: int, fmt: str) -> str:
            return f"{'n/a':>{width}}" if not np.isfinite(v) else f"{v:>{width}{fmt}}"

        for j, ax in enumerate("xyz"):
            ratio = self.rms_after[j] / self.rms_before[j] if self.rms_before[j] else np.nan
            lines.append(
                f"{ax:<6}{num(self.rms_before[j], 16, '.5f')}{num(self.rms_after[j], 16, '.5f')}"
                f"{num(ratio, 9, '.3f')}{num(self.rms_after_turning[j], 17, '.5f')}"
                f"{num(self.rms_after_rest[j], 17, '.5f')}"
            )
        return "\n".join(lines)

    def to_dict(self) -> dict[str, object]:
        """JSON-ready form."""
        return {
            "rms_before": self.rms_before.tolist(), "rms_after": self.rms_after.tolist(),
            "rms_after_turning": self.rms_after_turning.tolist(),
            "rms_after_rest": self.rms_after_rest.tolist(), "blocks": self.blocks,
            "block_s": self.block_s, "axes_source": self.axes_source,
        }


def verify_recording(rec: Recording, cal: GyroCalibration, block_s: float = 0.5) -> Verification:
    """Compare raw and calibrated readings with the encoder reference, block by block.

    Parameters
    ----------
    rec : Recording
        A run on the jig (ideally not the one the calibration was fitted to).
    cal : GyroCalibration
    block_s : float
        Block length, s: long enough to average the encoder's quantisation (a tick over half a
        second is 3e-3 rad/s), short enough to follow the motion.

    Returns
    -------
    Verification
    """
    if not block_s > 0:
        raise InputError(f"block length must be positive, got {block_s}")
    motors = sorted({int(s.motor) for s in rec.segments
                     if s.kind == "rotate" and s.motor is not None})
    found = servo_axes(motors, cal, rec.manifest)  # the calibration's, else the nominal ones
    axes = {motor: a.axis for motor, a in found.items()}
    sources = {a.source for a in found.values()}
    source = "calibration" if sources == {"calibration"} else (
        "nominal configuration" if sources <= {"nominal"} else "calibration and nominal names")
    t, m = rec.imu_t, rec.imu_rate
    if t.size < 10:
        raise InputError(f"{rec.path}: too few gyro samples to verify")
    err_raw, err_cal, kind = [], [], []
    for seg in rec.segments:
        n = int((seg.t_end - seg.t_start) // block_s)
        for i in range(n):
            a = seg.t_start + i * block_s
            b = a + block_s
            sel = (t >= a) & (t < b)
            if sel.sum() < 3:
                continue
            raw = m[sel].mean(axis=0)
            ref = np.zeros(3)
            block = "rest"
            if seg.kind == "rotate":
                te, th = rec.encoder(seg.motor)
                if te.size < 2:
                    raise InputError(f"{rec.path}: no encoder readings of servo {seg.motor}")
                w = float(encoder_rate(te, th, np.array(a + block_s / 2), block_s / 2))
                if not np.isfinite(w):
                    continue  # the encoder readings do not cover this block
                ref = w * axes[seg.motor]
                block = "steady" if abs(w) >= 0.95 * seg.speed else "ramp"
            err_raw.append(raw - ref)
            err_cal.append(cal.apply(raw) - ref)
            kind.append(block)
    if not err_raw:
        raise InputError(f"{rec.path}: no segment is long enough for {block_s:g} s blocks")
    er, ec, kinds = np.array(err_raw), np.array(err_cal), np.array(kind)

    def rms(e: np.ndarray) -> np.ndarray:
        return np.sqrt(np.mean(e**2, axis=0)) if e.size else np.full(3, np.nan)

    return Verification(rms(er), rms(ec), rms(ec[kinds == "steady"]),
                        rms(ec[kinds == "rest"]), int(kinds.size), float(block_s), source)
