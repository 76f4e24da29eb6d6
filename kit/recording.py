"""Recording v1: the raw record of a calibration run, as a directory (DESIGN.md, "Contracts").

``manifest.json``
    ``{"format": "gyrocal-recording", "version": 1, "created", "sensor", "gimbal", "protocol",
    "complete", "truth"?}``
``imu.csv``
    ``t,gx,gy,gz,temp``: seconds on the recording clock; rad/s with the datasheet sensitivity only;
    °C or empty.
``encoder.csv``
    ``t,motor,angle``: the cumulative, unwrapped shaft angle of servo ``motor`` in rad.
``segments.csv``
    ``index,kind,motor,direction,speed,t_start,t_end``.

:class:`RecordingWriter` appends and flushes rows as they come, so an interrupted run leaves a
readable recording whose manifest says ``"complete": false``. :func:`load_recording` reads one
back (also one written by another tool that follows the layout) into arrays.
"""

from __future__ import annotations

import io
import json
import math
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import Any, TextIO

import numpy as np

from gyrocal.calib.segments import Segment
from gyrocal.kit.errors import InputError, OutputExistsError
from gyrocal.kit.fileio import atomic_write_json

__all__ = [
    "FORMAT",
    "VERSION",
    "Recording",
    "RecordingError",
    "RecordingWriter",
    "load_recording",
]

FORMAT = "gyrocal-recording"
VERSION = 1
IMU_HEADER = "t,gx,gy,gz,temp"
ENCODER_HEADER = "t,motor,angle"
SEGMENTS_HEADER = "index,kind,motor,direction,speed,t_start,t_end"
FILES = ("manifest.json", "imu.csv", "encoder.csv", "segments.csv")


class RecordingError(InputError):
    """A recording directory is missing, incomplete in a way that matters, or malformed."""


def now_iso() -> str:
    """The current UTC time as ISO-8601 (wall time, only for the ``created`` stamp)."""
    return datetime.now(UTC).isoformat(timespec="seconds")


class RecordingWriter:
    """Write a Recording v1 directory as the run goes.

    Parameters
    ----------
    path : path-like
        The directory; created. An existing non-empty directory is an error unless ``force``.
    sensor, gimbal, protocol : dict
        Manifest sections (see the module docstring).
    truth : dict, optional
        ``{"scale": [3], "bias": [3]}`` for simulated recordings.
    force : bool
        Replace the recording files in an existing directory.
    extra : dict, optional
        More manifest fields (kept by readers, ignored by gyrocal).

    Notes
    -----
    Use as a context manager: leaving the block by an exception closes the files with
    ``complete`` still false; :meth:`finish` marks a clean finish.
    """

    def __init__(
        self,
        path: str | os.PathLike[str],
        *,
        sensor: Mapping[str, Any],
        gimbal: Mapping[str, Any],
        protocol: Mapping[str, Any],
        truth: Mapping[str, Any] | None = None,
        force: bool = False,
        extra: Mapping[str, Any] | None = None,
        created: str | None = None,
    ) -> None:
        self.path = Path(path)
        if self.path.exists():
            if not self.path.is_dir():
                raise OutputExistsError(f"{self.path} exists and is not a directory")
            if any(self.path.iterdir()) and not force:
                raise OutputExistsError(
                    f"{self.path} already holds files; choose another --out or pass --force"
                )
        else:
            try:
                self.path.mkdir(parents=True)
            except OSError as exc:
                raise InputError(f"cannot create {self.path}: {exc.strerror}") from None
        self.manifest: dict[str, Any] = {
            "format": FORMAT,
            "version": VERSION,
            "created": created or now_iso(),
            "sensor": dict(sensor),
            "gimbal": dict(gimbal),
            "protocol": dict(protocol),
            "complete": False,
        }
        if truth is not None:
            self.manifest["truth"] = dict(truth)
        if extra:
            self.manifest.update(dict(extra))
        self._write_manifest()
        self._imu = self._open("imu.csv", IMU_HEADER)
        self._enc = self._open("encoder.csv", ENCODER_HEADER)
        self._seg = self._open("segments.csv", SEGMENTS_HEADER)
        self._closed = False
        self.n_imu = 0
        self.n_encoder = 0
        self.n_segments = 0

    def _open(self, name: str, header: str) -> TextIO:
        fh = open(self.path / name, "w", encoding="ascii", newline="\n")
        fh.write(header + "\n")
        fh.flush()
        return fh

    def _write_manifest(self) -> None:
        atomic_write_json(self.path / "manifest.json", self.manifest, force=True)

    def update_manifest(self, **fields: Any) -> None:
        """Merge ``fields`` into the manifest and rewrite it atomically."""
        self.manifest.update(fields)
        self._write_manifest()

    def append_imu(
        self, t: np.ndarray, rate: np.ndarray, temperature_c: np.ndarray | None = None
    ) -> None:
        """Append gyro samples: ``t`` (N,), ``rate`` (N, 3) rad/s, ``temperature_c`` (N,)."""
        t = np.asarray(t, dtype=float).reshape(-1)
        rate = np.asarray(rate, dtype=float).reshape(-1, 3)
        if rate.shape[0] != t.size:
            raise ValueError(f"append_imu: {t.size} times but {rate.shape[0]} rate rows")
        if t.size == 0:
            return
        buf = io.StringIO()
        if temperature_c is None:
            np.savetxt(buf, np.column_stack([t, rate]), fmt="%.9f,%.10g,%.10g,%.10g,")
        else:
            temp = np.asarray(temperature_c, dtype=float).reshape(-1)
            np.savetxt(buf, np.column_stack([t, rate, temp]), fmt="%.9f,%.10g,%.10g,%.10g,%.4f")
        self._imu.write(buf.getvalue().replace(",nan\n", ",\n"))
        self._imu.flush()
        self.n_imu += t.size

    def append_encoder(self, t: float | np.ndarray, motor: Sequence[int] | np.ndarray,
                       angle: Sequence[float] | np.ndarray) -> None:
        """Append encoder readings: one time for several motors, or arrays of equal length."""
        motor = np.asarray(motor, dtype=np.int64).reshape(-1)
        angle = np.asarray(angle, dtype=float).reshape(-1)
        t = np.broadcast_to(np.asarray(t, dtype=float), motor.shape)
        if angle.shape != motor.shape:
            raise ValueError("append_encoder: motor and angle differ in length")
        rows = "".join(
            f"{ti:.9f},{int(mi)},{ai:.12g}\n" for ti, mi, ai in zip(t, motor, angle, strict=True)
        )
        self._enc.write(rows)
        self._enc.flush()
        self.n_encoder += motor.size

    def append_segment(self, seg: Segment) -> None:
        """Append one finished protocol segment."""
        motor = "" if seg.motor is None else str(int(seg.motor))
        self._seg.write(
            f"{seg.index},{seg.kind},{motor},{seg.direction},{seg.speed:.9g},"
            f"{seg.t_start:.9f},{seg.t_end:.9f}\n"
        )
        self._seg.flush()
        self.n_segments += 1

    def close(self, complete: bool = False) -> None:
        """Flush and close the files; with ``complete`` mark the manifest complete."""
        if self._closed:
            return
        for fh in (self._imu, self._enc, self._seg):
            fh.flush()
            os.fsync(fh.fileno())
            fh.close()
        self._closed = True
        if complete:
            self.manifest["complete"] = True
        self._write_manifest()

    def finish(self) -> None:
        """Close and mark the recording complete (a clean finish)."""
        self.close(complete=True)

    def __enter__(self) -> RecordingWriter:
        return self

    def __exit__(self, exc_type: object, exc: object, tb: object) -> None:
        self.close(complete=False)


@dataclass(frozen=True, eq=False)
class Recording:
    """A Recording v1 read into arrays.

    Attributes
    ----------
    path : Path
    manifest : dict
    imu_t : ndarray (N,)
    imu_rate : ndarray (N, 3)
        rad/s.
    imu_temp : ndarray (N,)
        °C, NaN where absent.
    enc_t, enc_motor, enc_angle : ndarray (M,)
    segments : tuple of Segment
    warnings : tuple of str
        What the reader tolerated (a partial last row of an interrupted run).
    """

    path: Path
    manifest: dict[str, Any]
    imu_t: np.ndarray
    imu_rate: np.ndarray
    imu_temp: np.ndarray
    enc_t: np.ndarray
    enc_motor: np.ndarray
    enc_angle: np.ndarray
    segments: tuple[Segment, ...]
    warnings: tuple[str, ...] = ()

    @property
    def complete(self) -> bool:
        """Whether the run finished cleanly."""
        return bool(self.manifest.get("complete", False))

    @property
    def sensor(self) -> dict[str, Any]:
        """The manifest's sensor section."""
        return dict(self.manifest.get("sensor") or {})

    @property
    def chain(self) -> tuple[int, ...] | None:
        """The gimbal's servo IDs in chain order, base first (``gimbal.motors``), or None if the
        manifest does not list them."""
        motors = (self.manifest.get("gimbal") or {}).get("motors")
        if not isinstance(motors, list) or not motors:
            return None
        try:
            return tuple(int(m["id"]) for m in motors)
        except (TypeError, KeyError, ValueError):
            return None

    @property
    def truth(self) -> dict[str, Any] | None:
        """The true parameters of a simulated recording, else None."""
        return self.manifest.get("truth")

    def encoder(self, motor: int) -> tuple[np.ndarray, np.ndarray]:
        """``(t, angle)`` of one servo."""
        sel = self.enc_motor == motor
        return self.enc_t[sel], self.enc_angle[sel]

    @property
    def temperature_c(self) -> float | None:
        """Mean die temperature, or None if no temperature was recorded."""
        ok = np.isfinite(self.imu_temp)
        return float(np.mean(self.imu_temp[ok])) if ok.any() else None


def _read_csv(path: Path, header: str, ncols: int, warnings: list[str]) -> list[list[str]]:
    if not path.exists():
        raise RecordingError(
            f"{path.name} is missing from {path.parent}: not a complete Recording v1 directory"
        )
    text = path.read_text(encoding="ascii", errors="replace")
    if not text:
        raise RecordingError(f"{path} is empty: expected the header {header!r}")
    lines = text.split("\n")
    if lines[0].strip() != header:
        raise RecordingError(f"{path}: header is {lines[0].strip()!r}, expected {header!r}")
    body = lines[1:]
    if body and body[-1] == "":
        body.pop()
    elif body:
        warnings.append(f"{path.name}: dropped a partial last row {body[-1]!r} (interrupted run)")
        body.pop()
    rows = []
    for i, line in enumerate(body, start=2):
        fields = line.split(",")
        if len(fields) != ncols:
            raise RecordingError(
                f"{path}:{i}: expected {ncols} comma-separated fields, got {len(fields)}: "
                f"{line[:80]!r}"
            )
        rows.append(fields)
    return rows


def _floats(
    rows: list[list[str]], cols: Sequence[int], path: Path, empty_ok: bool = False
) -> np.ndarray:
    """Parse columns ``cols`` of ``rows`` as finite floats (empty -> NaN if ``empty_ok``)."""
    try:  # fast path: numpy parses the strings; any problem falls through to the exact report
        strs = [[row[c].strip() or ("nan" if empty_ok else "") for c in cols] for row in rows]
        out = np.array(strs, dtype=float).reshape(len(rows), len(cols))
        if not np.any(np.isinf(out) if empty_ok else ~np.isfinite(out)):
            return out
    except ValueError:
        pass
    out = np.empty((len(rows), len(cols)))
    for r, row in enumerate(rows):
        for c, col in enumerate(cols):
            s = row[col].strip()
            if s == "" and empty_ok:
                out[r, c] = math.nan
                continue
            try:
                v = float(s)
            except ValueError:
                raise RecordingError(
                    f"{path}:{r + 2}: field {col + 1} is {s!r}, not a number"
                ) from None
            if not math.isfinite(v):
                raise RecordingError(f"{path}:{r + 2}: field {col + 1} is {s!r}")
            out[r, c] = v
    return out


def load_recording(path: str | os.PathLike[str]) -> Recording:
    """Read a Recording v1 directory.

    Parameters
    ----------
    path : path-like
        The recording directory.

    Returns
    -------
    Recording

    Raises
    ------
    RecordingError
        If the directory or a file is missing, a manifest is not Recording v1, a header or row is
        malformed (the message names the file and line), or times go backwards.
    """
    root = Path(path)
    if not root.is_dir():
        raise RecordingError(f"{root} is not a directory: give the recording directory")
    mpath = root / "manifest.json"
    if not mpath.exists():
        raise RecordingError(f"manifest.json is missing from {root}: not a Recording v1 directory")
    try:
        manifest = json.loads(mpath.read_text(encoding="utf-8"))
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise RecordingError(f"{mpath} is not valid JSON: {exc}") from None
    if not isinstance(manifest, dict) or manifest.get("format") != FORMAT:
        raise RecordingError(f"{mpath}: 'format' must be {FORMAT!r}")
    if manifest.get("version") != VERSION:
        raise RecordingError(
            f"{mpath}: recording version {manifest.get('version')!r} is not supported "
            f"(this gyrocal reads version {VERSION})"
        )
    for key in ("sensor", "gimbal", "protocol"):
        if not isinstance(manifest.get(key, {}), dict):
            raise RecordingError(f"{mpath}: {key!r} must be an object")
    warnings: list[str] = []
    imu_rows = _read_csv(root / "imu.csv", IMU_HEADER, 5, warnings)
    imu = _floats(imu_rows, (0, 1, 2, 3), root / "imu.csv")
    temp = _floats(imu_rows, (4,), root / "imu.csv", empty_ok=True)[:, 0]
    enc_rows = _read_csv(root / "encoder.csv", ENCODER_HEADER, 3, warnings)
    enc = _floats(enc_rows, (0, 1, 2), root / "encoder.csv")
    seg_rows = _read_csv(root / "segments.csv", SEGMENTS_HEADER, 7, warnings)
    segments = []
    for i, row in enumerate(seg_rows, start=2):
        try:
            motor = None if row[2].strip() == "" else int(row[2])
            seg = Segment(
                index=int(row[0]),
                kind=row[1].strip(),
                motor=motor,
                direction=int(row[3]),
                speed=float(row[4]),
                t_start=float(row[5]),
                t_end=float(row[6]),
            )
        except ValueError as exc:
            raise RecordingError(f"{root / 'segments.csv'}:{i}: {exc}") from None
        segments.append(seg)
    for name, t in (("imu.csv", imu[:, 0]), ("encoder.csv", enc[:, 0])):
        if t.size > 1 and np.any(np.diff(t) < 0):
            i = int(np.flatnonzero(np.diff(t) < 0)[0])
            raise RecordingError(
                f"{root / name}:{i + 3}: time goes backwards ({t[i + 1]} < {t[i]})"
            )
    return Recording(
        path=root,
        manifest=manifest,
        imu_t=imu[:, 0],
        imu_rate=imu[:, 1:4],
        imu_temp=temp,
        enc_t=enc[:, 0],
        enc_motor=enc[:, 1].astype(np.int64),
        enc_angle=enc[:, 2],
        segments=tuple(segments),
        warnings=tuple(warnings),
    )
