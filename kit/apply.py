"""Calibrated rates out of raw ones: a recording to a CSV file, or a CSV stream line by line.

The rows are those of Recording v1's ``imu.csv`` in either documented layout
(hardware_docs/formats.md, "imu.csv"), in and out: ``t,gx,gy,gz,temp`` (rad/s and °C; ``temp``
may be empty, or the column left out) or, with the accelerometer's columns,
``t,gx,gy,gz,temp,ax,ay,az`` (m/s²). ``gx,gy,gz`` become the calibrated rate
``GyroCalibration.apply`` gives (paper Eq. 1, or the full matrix model of Calibration v2);
``t`` and ``temp`` pass through. The temperature column travels with every reading so that a
calibration with a temperature model is applied at each sample's own temperature
(:func:`calibrated`).

With the accelerometer's columns the rows carry the specific force, so a calibration's
g-sensitivity is applied, ``g = A (m + b + G f)`` (:func:`specific_force` gives ``f`` in g),
and ``ax,ay,az`` come out calibrated by the calibration's accelerometer, ``A_acc (a + b_acc)``,
when it has one (unchanged when not). :func:`layout_note` says on stderr what was applied.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Iterator
from typing import Any, TextIO

import numpy as np

from gyrocal.kit.errors import InputError
from gyrocal.kit.recording import IMU_HEADER, IMU_HEADER_ACCEL

__all__ = ["calibrated", "calibrated_rows", "format_rows", "layout_note", "specific_force",
           "stream"]


def specific_force(cal: Any, accel: np.ndarray) -> np.ndarray:
    """The specific force ``f`` in g that a calibration's g-sensitivity takes, from readings
    ``accel`` (N, 3) m/s² of the accelerometer beside the gyro.

    With the calibration's accelerometer (``cal.accelerometer``), ``f = A_acc (a + b_acc) / g``
    with ``g`` the gravity that fit used, so a still sensor gives ``|f| = 1``, the unit "up"
    the g-sensitivity was fitted against; without one, the reading over standard gravity
    (9.80665 m/s², the factor imu.csv's ``ax,ay,az`` were converted with).
    """
    from gyrocal.calib.accel import STANDARD_GRAVITY

    acc = getattr(cal, "accelerometer", None)
    a = np.asarray(accel, dtype=float)
    if acc is None:
        return a / STANDARD_GRAVITY
    return acc.apply(a) / float(acc.gravity)


def calibrated(cal: Any, rate: np.ndarray, temp_c: np.ndarray,
               accel: np.ndarray | None = None) -> np.ndarray:
    """Calibrated rates of raw ``rate`` (N, 3) rad/s read at die temperatures ``temp_c`` (N,),
    with the accelerometer's readings ``accel`` (N, 3) m/s² when the rows carry them.

    A calibration that carries a temperature model (``cal.temperature_model`` not None) is
    applied at ``temp_c``; one with g-sensitivity gets ``specific_force`` from ``accel``
    (:func:`specific_force`) when given. The model itself is the calibration's
    (``cal.apply``); nothing of it is reimplemented here.
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
    if accel is not None and getattr(cal, "g_sensitivity", None) is not None:
        kw["specific_force"] = specific_force(cal, accel)
    with warnings.catch_warnings():  # said once per run by layout_note instead
        warnings.simplefilter("ignore", GSensitivityWarning)
        return np.asarray(cal.apply(rate, **kw), dtype=float)


def layout_note(cal: Any, has_accel: bool) -> str | None:
    """What a user must know about the rows' layout against the calibration (stderr), or None:
    whether the g-sensitivity is applied (with the accelerometer's columns) or not (without,
    with the error that leaves), and what becomes of ``ax,ay,az``."""
    g = getattr(cal, "g_sensitivity", None)
    acc = getattr(cal, "accelerometer", None)
    if not has_accel:
        if g is None:
            return None
        return (f"note: the calibration's g-sensitivity is NOT applied: the rows carry no "
                f"accelerometer columns (ax,ay,az), so the rates are off by up to "
                f"{cal.g_rate_error_per_g:.1e} rad/s per g of specific force (its bias is the "
                "zero-g bias); give rows with the accelerometer's columns "
                "(t,gx,gy,gz,temp,ax,ay,az), or apply it in code with "
                "GyroCalibration.apply(m, specific_force=f)")
    force = ("the calibration's accelerometer (A_acc (a + b_acc) / its gravity)" if acc
             is not None else "ax,ay,az / 9.80665 (the calibration has no accelerometer)")
    parts = [f"the g-sensitivity is applied with the specific force from {force}"
             if g is not None else None,
             "ax,ay,az are calibrated by the calibration's accelerometer" if acc is not None
             else "ax,ay,az pass through unchanged (the calibration has no accelerometer)"]
    return "note: " + "; ".join(p for p in parts if p)


def format_rows(t: np.ndarray, rate: np.ndarray, temp_c: np.ndarray,
                accel: np.ndarray | None = None) -> Iterator[str]:
    """``imu.csv`` lines (no newline), numbers to 9 significant digits (temp: 6; empty if NaN);
    with ``accel``, the three columns ``ax,ay,az`` after ``temp``."""
    extra = (("",) * len(t) if accel is None else
             (f",{ax:.9g},{ay:.9g},{az:.9g}" for ax, ay, az in accel))
    for ti, (gx, gy, gz), tc, tail in zip(t, rate, temp_c, extra, strict=True):
        temp = "" if math.isnan(tc) else f"{tc:.6g}"
        yield f"{ti:.9g},{gx:.9g},{gy:.9g},{gz:.9g},{temp}{tail}"


def _calibrated_accel(cal: Any, accel: np.ndarray | None) -> np.ndarray | None:
    acc = getattr(cal, "accelerometer", None)
    if accel is None or acc is None:
        return accel
    return acc.apply(accel)


def calibrated_rows(cal: Any, t: np.ndarray, rate: np.ndarray, temp_c: np.ndarray,
                    accel: np.ndarray | None = None) -> str:
    """The whole calibrated ``imu.csv`` text, header first (the accelerometer's layout when
    ``accel`` is given)."""
    out = calibrated(cal, rate, temp_c, accel)
    header = IMU_HEADER if accel is None else IMU_HEADER_ACCEL
    return "\n".join([header, *format_rows(t, out, temp_c, _calibrated_accel(cal, accel))]) + "\n"


#: Fields per row of each layout: without the accelerometer (``temp`` may be left out), with it.
_PLAIN_FIELDS, _ACCEL_FIELDS = (4, 5), (8,)


def _parse(line: str, number: int, fields: tuple[int, ...]
           ) -> tuple[float, np.ndarray, float, np.ndarray | None]:
    cells = line.strip().split(",")
    if len(cells) not in fields:
        want = (f"{IMU_HEADER_ACCEL!r} (8 comma-separated fields)" if fields == _ACCEL_FIELDS
                else f"{IMU_HEADER!r} (4 or 5 comma-separated fields)")
        raise InputError(f"line {number}: expected {want}, got {line.strip()!r}")
    try:
        t, gx, gy, gz = (float(c) for c in cells[:4])
        temp = float(cells[4]) if len(cells) >= 5 and cells[4].strip() else math.nan
        accel = np.array([float(c) for c in cells[5:8]]) if len(cells) == 8 else None
    except ValueError:
        raise InputError(f"line {number}: not numbers: {line.strip()!r}") from None
    rate = np.array([gx, gy, gz])
    if not np.all(np.isfinite(rate)) or not math.isfinite(t):
        raise InputError(f"line {number}: t and the rates must be finite numbers")
    if accel is not None and not np.all(np.isfinite(accel)):
        raise InputError(f"line {number}: ax,ay,az must be finite numbers")
    return t, rate, temp, accel


def _layout(line: str, number: int) -> tuple[int, ...] | None:
    """The fields a row may have after ``line``: a header fixes the layout, a data row's field
    count does (8: the accelerometer's layout); None for a blank line."""
    text = line.strip()
    if not text:
        return None
    if text in (IMU_HEADER, IMU_HEADER_ACCEL, "t,gx,gy,gz"):
        return _ACCEL_FIELDS if text == IMU_HEADER_ACCEL else _PLAIN_FIELDS
    if text.startswith("t,"):
        raise InputError(f"line {number}: unknown header {_short(text)!r}; imu.csv's are "
                         f"{IMU_HEADER!r} and {IMU_HEADER_ACCEL!r}")
    return _ACCEL_FIELDS if len(text.split(",")) in _ACCEL_FIELDS else _PLAIN_FIELDS


def _short(text: str) -> str:
    return text if len(text) <= 80 else text[:77] + "..."


def stream(cal: Any, lines: Iterable[str], out: TextIO, err: TextIO | None = None) -> int:
    """Calibrate ``imu.csv`` rows read from ``lines`` and write each to ``out`` as it comes.

    The layout (with or without ``ax,ay,az``) is fixed by the header line when there is one,
    else by the first row; the output has the same layout and starts with its header, and
    :func:`layout_note` goes to ``err`` then. Blank lines are passed over. Each row is flushed
    at once, so a reader at the other end of a pipe sees it without delay.

    Returns
    -------
    int
        Rows written.

    Raises
    ------
    InputError
        A malformed row (its line number and text), a row of the other layout, or a time
        before the previous row's.
    """
    fields: tuple[int, ...] | None = None
    n, before = 0, -math.inf
    for number, line in enumerate(lines, 1):
        layout = _layout(line, number)
        if layout is None:
            continue
        if fields is None:
            fields = layout
            _start(cal, fields == _ACCEL_FIELDS, out, err)
        if line.lstrip().startswith("t,"):
            if layout != fields:
                raise InputError(f"line {number}: a header of the other layout after the "
                                 "first; give one layout per stream")
            continue
        t, rate, temp, accel = _parse(line, number, fields)
        if t < before:  # the Recording v1 reader's rule (kit.recording: non-decreasing time)
            raise InputError(f"line {number}: time goes backwards ({t} < {before}); give the "
                             "rows in the order they were read")
        before = t
        acc_rows = None if accel is None else accel[None, :]
        (row,) = format_rows(np.array([t]), calibrated(cal, rate[None, :], np.array([temp]),
                                                       acc_rows),
                             np.array([temp]), _calibrated_accel(cal, acc_rows))
        out.write(row + "\n")
        out.flush()
        n += 1
    if fields is None:
        _start(cal, False, out, err)
    return n


def _start(cal: Any, has_accel: bool, out: TextIO, err: TextIO | None) -> None:
    """The output's header, and the layout's note on ``err``."""
    note = layout_note(cal, has_accel)
    if note and err is not None:
        print(note, file=err)
    out.write((IMU_HEADER_ACCEL if has_accel else IMU_HEADER) + "\n")
    out.flush()
