"""Calibrated rates out of raw ones: a recording to a CSV file, or a CSV stream line by line.

The rows are those of Recording v1's ``imu.csv`` (``t,gx,gy,gz,temp``, rad/s and °C), in and out:
``gx,gy,gz`` become the calibrated rate ``GyroCalibration.apply`` gives (paper Eq. 1, or the
full matrix model of Calibration v2), ``t`` and ``temp`` pass through. The temperature column
travels with every reading so that a calibration with a temperature model is applied at each
sample's own temperature (:func:`calibrated`); a calibration without one ignores it.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Iterator
from typing import Any, TextIO

import numpy as np

from gyrocal.kit.errors import InputError
from gyrocal.kit.recording import IMU_HEADER

__all__ = ["calibrated", "calibrated_rows", "format_rows", "g_sensitivity_note", "stream"]


def calibrated(cal: Any, rate: np.ndarray, temp_c: np.ndarray) -> np.ndarray:
    """Calibrated rates of raw ``rate`` (N, 3) rad/s read at die temperatures ``temp_c`` (N,).

    A calibration that carries a temperature model (``cal.temperature_model`` not None) is
    applied as ``cal.apply(rate, temperature_c=temp_c)``; otherwise as ``cal.apply(rate)``. The
    model itself is the calibration's; nothing of it is reimplemented here.
    """
    import warnings

    from gyrocal.calib.model import GSensitivityWarning

    kw = {}
    if getattr(cal, "temperature_model", None) is not None:
        if np.any(~np.isfinite(temp_c)):
            raise InputError(
                "the calibration has a temperature model, but some readings have no temperature; "
                "give the temp column for every row"
            )
        kw["temperature_c"] = temp_c
    with warnings.catch_warnings():  # said once per run by g_sensitivity_note instead
        warnings.simplefilter("ignore", GSensitivityWarning)
        return np.asarray(cal.apply(rate, **kw), dtype=float)


def g_sensitivity_note(cal: Any) -> str | None:
    """What a user must know when a calibration's g-sensitivity is not applied: apply reads
    only the gyro columns, so ``G f`` is left out (None without g-sensitivity)."""
    if getattr(cal, "g_sensitivity", None) is None:
        return None
    return (f"note: the calibration's g-sensitivity is NOT applied (apply reads only the gyro "
            f"columns of imu.csv): its bias is the zero-g bias, so the rates are off by up "
            f"to {cal.g_rate_error_per_g:.1e} rad/s per g of specific force; apply it in code "
            "with GyroCalibration.apply(m, specific_force=f)")


def format_rows(t: np.ndarray, rate: np.ndarray, temp_c: np.ndarray) -> Iterator[str]:
    """``imu.csv`` lines (no newline), numbers to 9 significant digits (temp: 6; empty if NaN)."""
    for ti, (gx, gy, gz), tc in zip(t, rate, temp_c, strict=True):
        temp = "" if math.isnan(tc) else f"{tc:.6g}"
        yield f"{ti:.9g},{gx:.9g},{gy:.9g},{gz:.9g},{temp}"


def calibrated_rows(cal: Any, t: np.ndarray, rate: np.ndarray, temp_c: np.ndarray) -> str:
    """The whole calibrated ``imu.csv`` text, header first."""
    out = calibrated(cal, rate, temp_c)
    return "\n".join([IMU_HEADER, *format_rows(t, out, temp_c)]) + "\n"


def _parse(line: str, number: int) -> tuple[float, np.ndarray, float]:
    cells = line.strip().split(",")
    if len(cells) not in (4, 5):
        raise InputError(
            f"line {number}: expected {IMU_HEADER!r} (4 or 5 comma-separated fields), got "
            f"{line.strip()!r}"
        )
    try:
        t, gx, gy, gz = (float(c) for c in cells[:4])
        temp = float(cells[4]) if len(cells) == 5 and cells[4].strip() else math.nan
    except ValueError:
        raise InputError(f"line {number}: not numbers: {line.strip()!r}") from None
    rate = np.array([gx, gy, gz])
    if not np.all(np.isfinite(rate)) or not math.isfinite(t):
        raise InputError(f"line {number}: t and the rates must be finite numbers")
    return t, rate, temp


def stream(cal: Any, lines: Iterable[str], out: TextIO) -> int:
    """Calibrate ``imu.csv`` rows read from ``lines`` and write each to ``out`` as it comes.

    A header line (``t,gx,...``) and blank lines are passed over; the output starts with the
    header. Each row is flushed at once, so a reader at the other end of a pipe sees it
    without delay.

    Returns
    -------
    int
        Rows written.

    Raises
    ------
    InputError
        A malformed row (its line number and text).
    """
    out.write(IMU_HEADER + "\n")
    out.flush()
    n = 0
    for number, line in enumerate(lines, 1):
        if not line.strip() or line.lstrip().startswith("t,"):
            continue
        t, rate, temp = _parse(line, number)
        (row,) = format_rows(np.array([t]), calibrated(cal, rate[None, :], np.array([temp])),
                             np.array([temp]))
        out.write(row + "\n")
        out.flush()
        n += 1
    return n
