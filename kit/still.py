"""A still record of a Recording v1, streamed for ``gyrocal noise`` in bounded memory (issue 16).

:func:`open_still` reads ``imu.csv`` block by block (:func:`gyrocal.kit.recording.iter_imu`),
keeps the samples of the chosen span, checks that they are uniformly sampled, and writes their
phase (the integrated rate, :func:`gyrocal.calib.allan.phase_blocks`) to an anonymous temporary
file as raw float64 rows. The Allan deviation then reads that file three blocks at a time
(:func:`gyrocal.calib.allan.overlapping_avar_blocks`), so the memory used is a few blocks
whatever the recording's length; the disk used is 24 bytes per sample (86 MB for an hour at
1 kHz), in the directory ``TMPDIR`` names (the system's temporary directory by default; on a Pi
whose ``/tmp`` is a RAM disk, point ``TMPDIR`` at the SD card).
"""

from __future__ import annotations

import itertools
import os
import sys
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from gyrocal.kit.errors import InputError
from gyrocal.kit.recording import iter_imu, read_manifest, read_segments

if TYPE_CHECKING:
    import numpy as np

    from gyrocal.calib.allan import PhaseRecord

__all__ = ["PERIOD_SAMPLES", "StillRecord", "open_still"]

#: The sample period is the median interval of the first this-many samples of the span (for a
#: shorter span, of all of them: then the figure is the one a whole-array median gives).
PERIOD_SAMPLES = 1 << 16
#: Fewest samples to analyse (the Allan deviation refuses fewer).
MIN_SAMPLES = 64


@dataclass(frozen=True)
class StillRecord:
    """The span of a recording that ``noise`` analyses.

    Attributes
    ----------
    phase : PhaseRecord
        Random access to the phase of the three axes, held in a temporary file.
    odr_hz : float
        Sample rate from the median sample interval (see :data:`PERIOD_SAMPLES`).
    meta : dict
        ``sensor``, ``source`` and, if the recording has temperatures, their mean
        ``temperature_c``.
    """

    phase: PhaseRecord
    odr_hz: float
    meta: dict[str, Any]


def _hand_rest(root: Path) -> tuple[float, float]:
    """The longest rest of a hand-jig recording (no segments: the rests are found in the data,
    :func:`gyrocal.calib.hand.find_hand_turns`), with a note."""
    import numpy as np

    from gyrocal.calib.errors import CalibInputError
    from gyrocal.calib.hand import find_hand_turns

    blocks = list(iter_imu(root, []))
    t = np.concatenate([b[0] for b in blocks])
    rate = np.concatenate([b[1] for b in blocks])
    try:
        rests = find_hand_turns(t, rate).rests
    except CalibInputError as exc:
        raise InputError(f"{root}: {exc}") from None
    lo, hi = max(rests, key=lambda r: r[1] - r[0])
    print(f"gyrocal: note: using the longest rest the hand jig's data show ({lo:.1f}-{hi:.1f} "
          f"s, {hi - lo:.1f} s)", file=sys.stderr)
    return lo, hi


def _span(root: Path, span: str, segments: tuple[Any, ...],
          hand: bool = False) -> tuple[float, float]:
    """The time window of ``span`` (``auto``, ``all`` or ``longest-rest``), with a note; on a
    ``hand``-jig recording the rests come from the data (:func:`_hand_rest`)."""
    import math

    if span == "auto":
        span = ("longest-rest" if hand or any(s.kind == "rotate" for s in segments)
                else "all")
    if span == "all":
        return -math.inf, math.inf
    if hand and not segments:
        return _hand_rest(root)
    rests = [s for s in segments if s.kind == "rest"]
    if not rests:
        raise InputError(f"{root} has no rest segment; record the sensor still, or pass --span all")
    seg = max(rests, key=lambda s: s.duration)
    print(f"gyrocal: note: using rest segment {seg.index} ({seg.duration:.1f} s)",
          file=sys.stderr)
    return seg.t_start, seg.t_end


def _selected(root: Path, lo: float, hi: float,
              warnings: list[str]) -> Iterator[tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """The samples of ``imu.csv`` with ``lo <= t <= hi``, block by block."""
    for t, rate, temp in iter_imu(root, warnings):
        if t[0] >= lo and t[-1] <= hi:
            yield t, rate, temp
            continue
        sel = (t >= lo) & (t <= hi)
        if sel.any():
            yield t[sel], rate[sel], temp[sel]


def _checked(root: Path, blocks: Iterator[tuple[np.ndarray, np.ndarray, np.ndarray]],
             sink: dict[str, Any]) -> Iterator[np.ndarray]:
    """The rate blocks, after the sample period is known and each block is found gap-free.

    ``sink`` receives ``odr_hz``, the sample count ``n`` and the temperature sum and count.
    """
    import numpy as np

    head: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []
    held = 0
    period = None
    last_t = None
    sink.update(n=0, temp_sum=0.0, temp_n=0)

    def check(t: np.ndarray) -> None:
        nonlocal last_t
        dt = np.diff(t) if last_t is None else np.diff(t, prepend=last_t)
        gaps = np.flatnonzero(dt > 1.5 * period)
        if gaps.size:
            i = int(gaps[0])
            before = t[i] if last_t is None else (last_t if i == 0 else t[i - 1])
            raise InputError(
                f"{root}: a gap in the samples, {dt[i]:.4f} s long at t={before:.3f} s (a FIFO "
                "overflow?); the Allan deviation needs uniform sampling: record again, or cut "
                "the recording at the gap"
            )
        last_t = float(t[-1])

    def emit(t: np.ndarray, rate: np.ndarray, temp: np.ndarray) -> np.ndarray:
        check(t)
        ok = np.isfinite(temp)
        sink["n"] += t.size
        sink["temp_sum"] += float(temp[ok].sum())
        sink["temp_n"] += int(ok.sum())
        return rate

    blocks = iter(blocks)
    for block in blocks:
        head.append(block)
        held += block[0].size
        if held > PERIOD_SAMPLES:
            break
    if held < MIN_SAMPLES:
        raise InputError(
            f"{root}: only {held} samples to analyse; an Allan deviation needs a still "
            "record of many minutes"
        )
    t_head = np.concatenate([b[0] for b in head])[: PERIOD_SAMPLES + 1]
    period = float(np.median(np.diff(t_head)))
    if not period > 0:
        raise InputError(f"{root}: sample times do not advance")
    sink["odr_hz"] = 1.0 / period
    for block in head:
        yield emit(*block)
    head.clear()
    for block in blocks:
        yield emit(*block)


@contextmanager
def open_still(path: str | os.PathLike[str], span: str = "auto") -> Iterator[StillRecord]:
    """Stream the still span of a recording into a temporary phase file.

    Parameters
    ----------
    path : path-like
        A Recording v1 directory.
    span : {"auto", "all", "longest-rest"}
        All samples, or the longest rest segment (``auto``: all if the recording has no
        rotations); on a hand-jig recording (manifest ``jig.kind`` ``hand``) the longest rest
        the data show.

    Yields
    ------
    StillRecord
        Valid inside the ``with`` block; the temporary file is removed on leaving it.

    Raises
    ------
    InputError
        The recording is unreadable (:class:`gyrocal.kit.recording.RecordingError`), has no
        rest segment for ``longest-rest``, too few samples, times that do not advance, or a
        gap (the first one is named).
    """
    import numpy as np

    from gyrocal.calib.allan import PhaseRecord, phase_blocks

    root = Path(path)
    manifest = read_manifest(root)
    warnings: list[str] = []
    segments = read_segments(root, warnings)
    jig = manifest.get("jig")
    lo, hi = _span(root, span, segments,
                   hand=isinstance(jig, dict) and jig.get("kind") == "hand")
    sink: dict[str, Any] = {}
    with tempfile.TemporaryFile(prefix="gyrocal-phase-") as fh:
        fh.write(np.zeros((1, 3)).tobytes())
        rates = _checked(root, _selected(root, lo, hi, warnings), sink)
        first = next(rates)  # the sample period is known from here on
        for x in phase_blocks(itertools.chain([first], rates), sink["odr_hz"]):
            fh.write(np.ascontiguousarray(x).tobytes())
        fh.flush()
        for w in warnings:
            print(f"gyrocal: note: {w}", file=sys.stderr)
        fd = fh.fileno()

        def read(start: int, stop: int) -> np.ndarray:
            data = os.pread(fd, (stop - start) * 24, start * 24)
            return np.frombuffer(data, dtype=np.float64).reshape(-1, 3)

        sensor = dict(manifest.get("sensor") or {})
        meta: dict[str, Any] = {"sensor": sensor, "source": str(root)}
        if sink["temp_n"]:
            meta["temperature_c"] = sink["temp_sum"] / sink["temp_n"]
        odr = sink["odr_hz"]
        manifest_odr = sensor.get("odr_hz")
        if isinstance(manifest_odr, (int, float)) and abs(manifest_odr - odr) > 0.01 * odr:
            print(f"gyrocal: note: the samples arrive at {odr:.3f} Hz, the manifest says "
                  f"{manifest_odr} Hz; using the measured rate", file=sys.stderr)
        yield StillRecord(PhaseRecord(sink["n"], read), odr, meta)
