"""Recording v1: the raw record of a calibration run, as a directory (DESIGN.md, "Contracts").

``manifest.json``
    ``{"format": "gyrocal-recording", "version": 1, "created", "sensor", "gimbal", "protocol",
    "complete", "truth"?}``
``imu.csv``
    ``t,gx,gy,gz,temp``: seconds on the recording clock; rad/s with the datasheet sensitivity only;
    °C or empty. Optionally three trailing columns ``ax,ay,az`` (header
    ``t,gx,gy,gz,temp,ax,ay,az``): the accelerometer's specific force of the same sample in m/s²,
    sensor frame, datasheet sensitivity times standard gravity and nothing else. A recording
    without them is as valid; readers accept both.
``encoder.csv``
    ``t,motor,angle``: the cumulative, unwrapped shaft angle of servo ``motor`` in rad.
``segments.csv``
    ``index,kind,motor,direction,speed,t_start,t_end``.

:class:`RecordingWriter` appends and flushes rows as they come, so an interrupted run leaves a
readable recording whose manifest says ``"complete": false``. :func:`load_recording` reads one
back (also one written by another tool that follows the layout) into arrays.
"""

from __future__ import annotations

import contextlib
import io
import json
import math
import os
import stat
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import TYPE_CHECKING, Any, BinaryIO, TextIO

from gyrocal.kit.errors import InputError, OutputExistsError
from gyrocal.kit.fileio import atomic_write_json

if TYPE_CHECKING:
    import numpy as np

    from gyrocal.calib.segments import Segment

__all__ = [
    "FORMAT",
    "VERSION",
    "Recording",
    "RecordingError",
    "RecordingWriter",
    "imu_rows_bound",
    "iter_encoder",
    "iter_imu",
    "load_recording",
    "open_regular",
    "read_manifest",
    "read_segments",
]

FORMAT = "gyrocal-recording"
VERSION = 1
IMU_HEADER = "t,gx,gy,gz,temp"
#: The header of an ``imu.csv`` with the accelerometer's optional columns.
IMU_HEADER_ACCEL = IMU_HEADER + ",ax,ay,az"
#: Column of the temperature, the one field of an imu.csv row that may be empty.
_TEMP_COL = 4
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
        accel: bool = False,
    ) -> None:
        self.path = Path(path)
        #: Whether imu.csv has the accelerometer's columns ``ax,ay,az``.
        self.accel = bool(accel)
        if self.path.exists():
            if not self.path.is_dir():
                raise OutputExistsError(f"{self.path} exists and is not a directory")
            if any(self.path.iterdir()) and not force:
                raise OutputExistsError(
                    f"{self.path} already holds files; choose another directory or pass --force "
                    "to replace them"
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
        self._imu = self._open("imu.csv", IMU_HEADER_ACCEL if self.accel else IMU_HEADER)
        self._enc = self._open("encoder.csv", ENCODER_HEADER)
        self._seg = self._open("segments.csv", SEGMENTS_HEADER)
        self._closed = False
        self.n_imu = 0
        self.n_encoder = 0
        self.n_segments = 0

    def _open(self, name: str, header: str) -> TextIO:
        with self._writing(name):
            fh = open(self.path / name, "w", encoding="ascii", newline="\n")
            fh.write(header + "\n")
            fh.flush()
        return fh

    @contextlib.contextmanager
    def _writing(self, name: str) -> Iterator[None]:
        """A write to the recording's file ``name``: an OSError (a full disk, a failing card)
        becomes an :class:`InputError` naming the recording's file, so that it, not a later
        write elsewhere, is what the run reports."""
        try:
            yield
        except OSError as exc:
            raise InputError(
                f"cannot write the recording's {name} ({self.path / name}): "
                f"{exc.strerror or exc}; free space on that disk (or write the recording "
                "elsewhere) and run again") from None

    def _write_manifest(self) -> None:
        atomic_write_json(self.path / "manifest.json", self.manifest, force=True)

    def update_manifest(self, **fields: Any) -> None:
        """Merge ``fields`` into the manifest and rewrite it atomically."""
        self.manifest.update(fields)
        self._write_manifest()

    def append_imu(
        self, t: np.ndarray, rate: np.ndarray, temperature_c: np.ndarray | None = None,
        accel: np.ndarray | None = None,
    ) -> None:
        """Append samples: ``t`` (N,), ``rate`` (N, 3) rad/s, ``temperature_c`` (N,) and, in a
        recording with the accelerometer's columns (``accel=True`` at creation), ``accel``
        (N, 3) m/s², which such a recording requires; one without them ignores ``accel``."""
        import numpy as np

        t = np.asarray(t, dtype=float).reshape(-1)
        rate = np.asarray(rate, dtype=float).reshape(-1, 3)
        if rate.shape[0] != t.size:
            raise ValueError(f"append_imu: {t.size} times but {rate.shape[0]} rate rows")
        if t.size == 0:
            return
        temp = (np.full(t.size, np.nan) if temperature_c is None
                else np.asarray(temperature_c, dtype=float).reshape(-1))
        cols, fmt = [t, rate, temp], "%.9f,%.10g,%.10g,%.10g,%.4f"
        if self.accel:
            if accel is None:
                raise ValueError("append_imu: this recording has accelerometer columns; give "
                                 "accel")
            acc = np.asarray(accel, dtype=float).reshape(-1, 3)
            if acc.shape[0] != t.size:
                raise ValueError(f"append_imu: {t.size} times but {acc.shape[0]} accel rows")
            cols.append(acc)
            fmt += ",%.10g,%.10g,%.10g"
        # the rows as numpy.savetxt writes them (``fmt % row`` each), without its per-call
        # set-up, which cost the loop's one-sample batches more than the formatting
        line = fmt + "\n"
        text = "".join([line % tuple(row) for row in np.column_stack(cols).tolist()])
        # an absent temperature is an empty field
        text = text.replace(",nan,", ",,") if self.accel else text.replace(",nan\n", ",\n")
        with self._writing("imu.csv"):
            self._imu.write(text)
            self._imu.flush()
        self.n_imu += t.size

    def append_encoder(self, t: float | np.ndarray, motor: Sequence[int] | np.ndarray,
                       angle: Sequence[float] | np.ndarray) -> None:
        """Append encoder readings: one time for several motors, or arrays of equal length."""
        import numpy as np

        motor = np.asarray(motor, dtype=np.int64).reshape(-1)
        angle = np.asarray(angle, dtype=float).reshape(-1)
        t = np.broadcast_to(np.asarray(t, dtype=float), motor.shape)
        if angle.shape != motor.shape:
            raise ValueError("append_encoder: motor and angle differ in length")
        rows = "".join([f"{ti:.9f},{mi},{ai:.12g}\n" for ti, mi, ai
                        in zip(t.tolist(), motor.tolist(), angle.tolist(), strict=True)])
        with self._writing("encoder.csv"):
            self._enc.write(rows)
            self._enc.flush()
        self.n_encoder += motor.size

    def append_segment(self, seg: Segment) -> None:
        """Append one finished protocol segment."""
        motor = "" if seg.motor is None else str(int(seg.motor))
        with self._writing("segments.csv"):
            self._seg.write(
                f"{seg.index},{seg.kind},{motor},{seg.direction},{seg.speed:.9g},"
                f"{seg.t_start:.9f},{seg.t_end:.9f}\n"
            )
            self._seg.flush()
        self.n_segments += 1

    def close(self, complete: bool = False) -> None:
        """Flush and close the files; with ``complete`` mark the manifest complete.

        Every file is closed even if one cannot be flushed (a full disk); the first such
        failure is then raised, naming its file, and the manifest is not marked complete.
        """
        if self._closed:
            return
        self._closed = True
        failed: InputError | None = None
        for name, fh in (("imu.csv", self._imu), ("encoder.csv", self._enc),
                         ("segments.csv", self._seg)):
            try:
                with self._writing(name):
                    fh.flush()
                    os.fsync(fh.fileno())
            except InputError as exc:
                failed = failed or exc
            finally:
                with contextlib.suppress(OSError):  # closed even if its last flush failed
                    fh.close()
        if complete and failed is None:
            self.manifest["complete"] = True
        try:
            self._write_manifest()
        except InputError:
            if failed is None:
                raise
        if failed is not None:  # the data's own file first: the manifest only follows it
            raise failed

    def finish(self) -> None:
        """Close and mark the recording complete (a clean finish)."""
        self.close(complete=True)

    def __enter__(self) -> RecordingWriter:
        return self

    def __exit__(self, exc_type: object, exc: object, tb: object) -> None:
        try:
            self.close(complete=False)
        except InputError:
            if exc is None:
                raise
            # the error that ended the run stays the error (a full disk: it named the file)


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
    imu_accel : ndarray (N, 3) or None
        The accelerometer's specific force, m/s², or None when imu.csv has no ``ax,ay,az``.
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
    imu_accel: np.ndarray | None = None

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
        import numpy as np

        ok = np.isfinite(self.imu_temp)
        return float(np.mean(self.imu_temp[ok])) if ok.any() else None


# ---------------------------------------------------------------------------------------------
# Reading. Input bounds (issue 17): only regular files are opened (a FIFO, a directory or a
# device is refused before a byte is read, so nothing can block), every file has a size cap, a
# line may not run longer than MAX_LINE_BYTES, a NUL byte is refused where it is met, and a
# message quotes at most EXCERPT_CHARS of a row. Parsing (issue 16): blocks of about
# BLOCK_BYTES go through a fast parser, the vectorised decimal one (kit.decimal_csv, numpy
# alone) unless GYROCAL_CSV_PARSER names numpy.loadtxt or pandas, see PARSERS; a block it
# rejects is parsed again line by line by the exact checker, which names the file, line and
# field of the fault.

#: Largest manifest.json read, bytes.
MAX_MANIFEST_BYTES = 1 << 20
#: Largest imu.csv or encoder.csv read, bytes (about 16 hours at 1 kHz).
MAX_CSV_BYTES = 4 << 30
#: Largest segments.csv read, bytes (some 100 000 segments).
MAX_SEGMENTS_BYTES = 16 << 20
#: Longest line accepted in a CSV file, bytes (a Recording v1 row is under 100).
MAX_LINE_BYTES = 4096
#: Most characters of a row quoted in a message.
EXCERPT_CHARS = 60
#: Bytes parsed at a time by the block reader.
#
# numpy (and calib.segments, which imports it) are imported inside the functions that use
# them, so that checking a recording's path and manifest costs no import.
BLOCK_BYTES = 1 << 22


def _excerpt(text: str | bytes, quote: bool = True) -> str:
    """``text`` (quoted), cut to :data:`EXCERPT_CHARS` characters with an ellipsis."""
    if isinstance(text, bytes):
        text = text.decode("ascii", errors="replace")
    if len(text) <= EXCERPT_CHARS:
        return repr(text) if quote else text
    cut = text[:EXCERPT_CHARS]
    return f"{cut!r}... ({len(text)} characters)" if quote else f"{cut}... ({len(text)} characters)"


def _file_kind(mode: int) -> str:
    for test, kind in ((stat.S_ISDIR, "a directory"), (stat.S_ISFIFO, "a named pipe (FIFO)"),
                       (stat.S_ISCHR, "a character device"), (stat.S_ISBLK, "a block device"),
                       (stat.S_ISSOCK, "a socket")):
        if test(mode):
            return kind
    return "not a regular file"


def open_regular(path: Path, max_bytes: int, what: str = "a Recording v1 directory") -> BinaryIO:
    """Open ``path`` for reading if it is a regular file of at most ``max_bytes``.

    The file is opened without blocking and checked with ``fstat`` before any read, so a FIFO,
    a directory, a device such as ``/dev/zero`` (or a symlink to any of them) is refused at once
    rather than read for ever.

    Parameters
    ----------
    path : Path
        The file.
    max_bytes : int
        Size cap.
    what : str
        What the file belongs to, for the message when it is missing.

    Returns
    -------
    BinaryIO
        An unbuffered binary file; the caller closes it.

    Raises
    ------
    RecordingError
        Missing, unreadable, not a regular file, or larger than ``max_bytes``.
    """
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | os.O_CLOEXEC)
    except FileNotFoundError:
        raise RecordingError(
            f"{path.name} is missing from {path.parent}: not {what}"
        ) from None
    except OSError as exc:
        raise RecordingError(f"cannot read {path}: {exc.strerror}") from None
    try:
        st = os.fstat(fd)
        if not stat.S_ISREG(st.st_mode):
            raise RecordingError(
                f"{path} is {_file_kind(st.st_mode)}: a recording's files must be regular files; "
                "copy the data into a file"
            )
        if st.st_size > max_bytes:
            raise RecordingError(
                f"{path} is {st.st_size} bytes, more than the {max_bytes} gyrocal reads from "
                "such a file; split the session into shorter recordings"
            )
        os.set_blocking(fd, True)
        return os.fdopen(fd, "rb", buffering=0)
    except BaseException:
        os.close(fd)
        raise


def read_manifest(root: Path) -> dict[str, Any]:
    """Read and check the ``manifest.json`` of the recording directory ``root``.

    Raises
    ------
    RecordingError
        Not a directory, manifest missing, too large, not JSON, or not Recording v1.
    """
    if not root.is_dir():
        raise RecordingError(f"{root} is not a directory: give the recording directory")
    mpath = root / "manifest.json"
    with open_regular(mpath, MAX_MANIFEST_BYTES) as fh:
        data = fh.read(MAX_MANIFEST_BYTES + 1)
    if len(data) > MAX_MANIFEST_BYTES:
        raise RecordingError(f"{mpath} is larger than {MAX_MANIFEST_BYTES} bytes")
    try:
        manifest = json.loads(data.decode("utf-8"))
    except (ValueError, RecursionError) as exc:  # JSONDecodeError, UnicodeDecodeError, nesting
        why = _excerpt(str(exc), quote=False)
        raise RecordingError(f"{mpath} is not valid JSON: {why}") from None
    if not isinstance(manifest, dict) or manifest.get("format") != FORMAT:
        raise RecordingError(f"{mpath}: 'format' must be {FORMAT!r}")
    if manifest.get("version") != VERSION:
        raise RecordingError(
            f"{mpath}: recording version {_excerpt(repr(manifest.get('version')), quote=False)} "
            f"is not supported (this gyrocal reads version {VERSION})"
        )
    for key in ("sensor", "gimbal", "protocol"):
        if not isinstance(manifest.get(key, {}), dict):
            raise RecordingError(f"{mpath}: {key!r} must be an object")
    motors = (manifest.get("gimbal") or {}).get("motors")
    ids = [m.get("id") for m in (motors if isinstance(motors, list) else [])
           if isinstance(m, dict)]
    twice = sorted({i for i in ids if isinstance(i, int) and ids.count(i) > 1})
    if twice:
        raise RecordingError(f"{mpath}: gimbal.motors lists servo id {twice[0]} more than once; "
                             "each servo of the chain has its own id")
    return manifest


def _long_line(path: Path, buf: bytes, lo: int, hi: int, line_no: int) -> None:
    """Refuse a line longer than :data:`MAX_LINE_BYTES` in ``buf[lo:hi]`` (line ``line_no`` at
    ``lo``).

    Such a line holds a newline-free window of half that length starting at a multiple of it,
    so one ``find`` per half-line-length finds every candidate.
    """
    step = MAX_LINE_BYTES // 2
    for w in range(lo, hi - step + 1, step):
        if buf.find(b"\n", w, w + step) >= 0:
            continue
        start = buf.rfind(b"\n", lo, w) + 1 or lo
        stop = buf.find(b"\n", w)
        stop = len(buf) if stop < 0 else stop
        if stop - start > MAX_LINE_BYTES:
            bad = line_no + buf.count(b"\n", lo, start)
            raise RecordingError(
                f"{path}:{bad}: line longer than {MAX_LINE_BYTES} bytes "
                f"({_excerpt(buf[start:start + EXCERPT_CHARS + 1])}); this is not a Recording "
                "v1 row"
            )


def _lines(
    path: Path, header: str, max_bytes: int, warnings: list[str],
) -> Iterator[tuple[int, bytes, int]]:
    """Blocks of whole lines of a CSV file after its header.

    Yields ``(number of the block's first line, the block, how many lines it holds)``.
    Each block ends with a newline. A last line without one (an interrupted run) is dropped with
    a warning; a NUL byte or a line longer than :data:`MAX_LINE_BYTES` is an error.
    """
    with open_regular(path, max_bytes) as fh:
        carry = b""
        line_no = 1  # of the first line in carry
        total = 0
        header_done = False
        while True:
            chunk = fh.read(BLOCK_BYTES)
            total += len(chunk)
            if total > max_bytes:
                raise RecordingError(f"{path} grew past {max_bytes} bytes while being read")
            buf = carry + chunk if carry else chunk
            nul = buf.find(b"\0")
            if nul >= 0:
                bad = line_no + buf.count(b"\n", 0, nul)
                raise RecordingError(
                    f"{path}:{bad}: NUL bytes (a power loss can leave zeros at the end of a "
                    f"file); cut the file before line {bad} and read it again"
                )
            if not header_done:
                end = buf.find(b"\n")
                if end < 0 and chunk and len(buf) <= MAX_LINE_BYTES:
                    carry = buf
                    continue
                first = buf[: end if end >= 0 else MAX_LINE_BYTES].decode("ascii", "replace")
                if not buf:
                    raise RecordingError(f"{path} is empty: expected the header {header!r}")
                if first.strip() != header:
                    raise RecordingError(
                        f"{path}: header is {_excerpt(first.strip())}, expected {header!r}"
                    )
                header_done = True
                buf = buf[end + 1:] if end >= 0 else b""
                line_no = 2
            end = buf.rfind(b"\n") + 1
            if not chunk:  # end of file
                _long_line(path, buf, 0, end, line_no)
                if end:
                    yield line_no, buf[:end], buf.count(b"\n", 0, end)
                if buf[end:]:
                    warnings.append(
                        f"{path.name}: dropped a partial last row {_excerpt(buf[end:])} "
                        "(interrupted run)"
                    )
                return
            if len(buf) - end > MAX_LINE_BYTES:
                _long_line(path, buf, 0, len(buf), line_no)
            _long_line(path, buf, 0, end, line_no)
            if end:
                k = buf.count(b"\n", 0, end)
                yield line_no, buf[:end], k
                line_no += k
            carry = buf[end:]


def _split_rows(text: str, first: int, path: Path, ncols: int) -> list[list[str]]:
    """The comma-separated fields of each line of ``text`` (lines numbered from ``first``)."""
    rows = []
    for i, line in enumerate(text.split("\n")[:-1], start=first):
        fields = line.split(",")
        if len(fields) != ncols:
            raise RecordingError(
                f"{path}:{i}: expected {ncols} comma-separated fields, got {len(fields)}: "
                f"{_excerpt(line)}"
            )
        rows.append(fields)
    return rows


def _parse_exact(block: bytes, first: int, path: Path, ncols: int, empty_col: int | None
                 ) -> np.ndarray:
    """Parse ``block`` line by line; the first fault raises with its file, line and field."""
    import numpy as np

    rows = _split_rows(block.decode("ascii", errors="replace"), first, path, ncols)
    out = np.empty((len(rows), ncols))
    for r, row in enumerate(rows):
        for c, field in enumerate(row):
            s = field.strip()
            last = c == empty_col
            if s == "" and last:
                out[r, c] = math.nan
                continue
            try:
                if "_" in s:  # float() reads "1_0.5" as 10.5; a CSV number has no underscore
                    raise ValueError(s)
                v = float(s)
            except ValueError:
                raise RecordingError(
                    f"{path}:{first + r}: field {c + 1} is {_excerpt(s)}, not a number"
                ) from None
            if math.isinf(v) or (math.isnan(v) and not last):
                raise RecordingError(f"{path}:{first + r}: field {c + 1} is {_excerpt(s)}")
            out[r, c] = v
    return out


def _numpy_parse(block: bytes, empty_col: int | None, ncols: int) -> np.ndarray | None:
    """A block through ``numpy.loadtxt`` (its C reader); None if it rejects the block.

    Empty fields are read as NaN (only column ``empty_col`` may hold one: :func:`_parse_block`
    checks)."""
    import numpy as np

    if empty_col is not None:
        block = block.replace(b",\n", b",nan\n").replace(b",,", b",nan,")
    try:
        return np.loadtxt(io.BytesIO(block), delimiter=",", dtype=float, comments=None, ndmin=2)
    except ValueError:
        return None


def _pandas_parse(block: bytes, empty_col: int | None, ncols: int) -> np.ndarray | None:
    """A block through pandas' C parser; None if it rejects the block.

    Only an empty field is read as missing (NaN), quotes are ordinary characters and no column
    becomes an index, so the parser accepts no row the exact checker refuses (the shape and
    comma count checks of :func:`_parse_block` catch short rows and blank lines).
    """
    import csv

    import numpy as np
    import pandas as pd

    try:
        df = pd.read_csv(io.BytesIO(block), header=None, index_col=False, dtype=np.float64,
                         engine="c", keep_default_na=False, na_values=[""],
                         quoting=csv.QUOTE_NONE, skip_blank_lines=False)
    except (ValueError, TypeError, IndexError, pd.errors.ParserError, pd.errors.EmptyDataError):
        return None
    return df.to_numpy(dtype=np.float64)


def _decimal_parse(block: bytes, empty_col: int | None, ncols: int) -> np.ndarray | None:
    """A block through the vectorised decimal parser (:mod:`gyrocal.kit.decimal_csv`, numpy
    alone, exact: every value equals ``float`` of its text); a block of anything else
    (spaces, ``inf``, many exponents) goes to :func:`_numpy_parse`."""
    from gyrocal.kit.decimal_csv import parse_plain_decimal

    out = parse_plain_decimal(block, ncols, empty_col)
    return _numpy_parse(block, empty_col, ncols) if out is None else out


#: The block parsers by name (``GYROCAL_CSV_PARSER``); ``auto`` is the vectorised decimal
#: parser (``decimal``, numpy alone): on an hour at 1 kHz it reads as fast as pandas' C parser
#: with its import, without pandas' 35 MiB of resident memory (issue 16, ``python -m bench
#: longrec``); ``numpy`` is ``numpy.loadtxt`` alone, ``pandas`` pandas' parser (the ``fast``
#: extra).
PARSERS = {"decimal": _decimal_parse, "numpy": _numpy_parse, "pandas": _pandas_parse}


def _choose_parser() -> Callable[[bytes, int | None, int], np.ndarray | None]:
    """The block parser (see :data:`PARSERS`)."""
    import importlib.util

    name = os.environ.get("GYROCAL_CSV_PARSER", "auto")
    if name == "auto":
        name = "decimal"
    if name not in PARSERS:
        raise InputError(
            f"GYROCAL_CSV_PARSER is {_excerpt(name)}; use auto, decimal, numpy or pandas"
        )
    if name == "pandas" and importlib.util.find_spec("pandas") is None:
        raise InputError(
            "GYROCAL_CSV_PARSER=pandas but pandas is not installed; install gyrocal[fast] or "
            "unset it"
        )
    return PARSERS[name]


def _parse_block(
    block: bytes, nlines: int, first: int, path: Path, ncols: int, empty_col: int | None,
    parse: Callable[[bytes, int | None, int], np.ndarray | None] = _decimal_parse,
) -> np.ndarray:
    """Parse a block of whole lines into an ``(n, ncols)`` array.

    A fast parser (``parse``: the vectorised decimal one, numpy's or pandas') takes the block
    first; anything it rejects, a
    row count or comma count other than ``ncols`` fields per line, or a value out of domain
    sends the block to :func:`_parse_exact` for the located message.
    """
    import numpy as np

    fast = block
    if b"\r" in fast:
        fast = fast.replace(b"\r\n", b"\n")
    out = parse(fast, empty_col, ncols)
    if (out is not None and out.shape == (nlines, ncols)
            and fast.count(b",") == nlines * (ncols - 1)):
        head = out if empty_col is None else np.delete(out, empty_col, axis=1)
        if np.isfinite(head).all() and not (
                empty_col is not None and np.isinf(out[:, empty_col]).any()):
            return out
    return _parse_exact(block, first, path, ncols, empty_col)


def _csv_blocks(
    path: Path, header: str, ncols: int, warnings: list[str], *, empty_col: int | None = None,
    max_bytes: int = MAX_CSV_BYTES,
) -> Iterator[np.ndarray]:
    """``(n, ncols)`` float blocks of a numeric CSV file, its first column a non-decreasing time.

    Raises
    ------
    RecordingError
        Naming file and line: a malformed row, or a time smaller than the one before it.
    """
    import numpy as np

    last_t = -math.inf
    parse = _choose_parser()
    for first, block, nlines in _lines(path, header, max_bytes, warnings):
        arr = _parse_block(block, nlines, first, path, ncols, empty_col, parse)
        if arr.shape[0] == 0:
            continue
        t = arr[:, 0]
        back = t[0] < last_t
        if not back and t.size > 1:
            steps = np.diff(t) < 0
            back = bool(steps.any())
        if back:
            i = 0 if t[0] < last_t else int(np.flatnonzero(steps)[0]) + 1
            before = last_t if i == 0 else t[i - 1]
            raise RecordingError(
                f"{path}:{first + i}: time goes backwards ({t[i]} < {before})"
            )
        last_t = float(t[-1])
        yield arr


def _count_lines(path: Path, max_bytes: int) -> int:
    """Newlines in ``path`` (an upper bound on its rows, so arrays can be sized once).

    Stops at a NUL byte: the file is damaged there and the parsing pass says so.
    """
    n = 0
    with open_regular(path, max_bytes) as fh:
        while chunk := fh.read(BLOCK_BYTES):
            n += chunk.count(b"\n")
            if b"\0" in chunk:
                break
    return n


def _read_columns(
    path: Path, header: str, widths: Sequence[int], warnings: list[str], *,
    empty_col: int | None = None,
) -> list[np.ndarray]:
    """A numeric CSV file as contiguous float64 arrays, one per group of ``widths`` columns.

    The rows are counted first so that each array is allocated once at its final size.
    """
    import numpy as np

    cap = _count_lines(path, MAX_CSV_BYTES)
    out = [np.empty((cap, w)) if w > 1 else np.empty(cap) for w in widths]
    edges = np.cumsum([0, *widths]).tolist()
    n = 0
    for arr in _csv_blocks(path, header, edges[-1], warnings, empty_col=empty_col):
        k = arr.shape[0]
        for a, lo, hi in zip(out, edges[:-1], edges[1:], strict=True):
            a[n:n + k] = arr[:, lo:hi] if hi - lo > 1 else arr[:, lo]
        n += k
    return [a[:n] for a in out]


def iter_imu(
    path: str | os.PathLike[str], warnings: list[str] | None = None, *, accel: bool = False
) -> Iterator[tuple[np.ndarray, ...]]:
    """Stream ``imu.csv`` of a recording in blocks of some 60 000 rows.

    For commands that need one pass over the samples (``noise``, ``track``): memory stays
    bounded whatever the recording's length. Every check of :func:`load_recording` applies
    (file and line of a bad row, a partial last row dropped with a warning, time going
    backwards refused). The accelerometer's optional columns (``ax,ay,az``) are checked and
    left out unless ``accel`` asks for them.

    Parameters
    ----------
    path : path-like
        The recording directory (its manifest is checked first).
    warnings : list of str, optional
        Receives what the reader tolerated (a partial last row).

    Yields
    ------
    t : ndarray (n,)
    rate : ndarray (n, 3)
        rad/s.
    temp : ndarray (n,)
        °C, NaN where absent.
    """
    root = Path(path)
    read_manifest(root)
    sink: list[str] = [] if warnings is None else warnings
    header = imu_header(root / "imu.csv")
    for arr in _csv_blocks(root / "imu.csv", header, header.count(",") + 1, sink,
                           empty_col=_TEMP_COL):
        if not accel:
            yield arr[:, 0], arr[:, 1:4], arr[:, 4]
        else:
            yield (arr[:, 0], arr[:, 1:4], arr[:, 4],
                   arr[:, 5:8] if header == IMU_HEADER_ACCEL else None)


def imu_header(path: Path) -> str:
    """The header of the ``imu.csv`` at ``path``: :data:`IMU_HEADER_ACCEL` when its first line
    is that (the accelerometer's optional columns), else :data:`IMU_HEADER` (which the parser
    then checks, naming the file if the header is neither)."""
    with open_regular(path, MAX_CSV_BYTES) as fh:
        first = fh.read(len(IMU_HEADER_ACCEL) + 2)
    line = first.split(b"\n", 1)[0].strip().decode("ascii", "replace")
    return IMU_HEADER_ACCEL if line == IMU_HEADER_ACCEL else IMU_HEADER


def iter_encoder(
    path: str | os.PathLike[str], warnings: list[str] | None = None
) -> Iterator[tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """Stream ``encoder.csv`` of the recording directory ``path`` in blocks (the manifest is not
    read again), with every check of :func:`load_recording`.

    Yields
    ------
    t : ndarray (n,)
    motor : ndarray (n,) of int64
    angle : ndarray (n,)
        rad.
    """
    sink: list[str] = [] if warnings is None else warnings
    for arr in _csv_blocks(Path(path) / "encoder.csv", ENCODER_HEADER, 3, sink):
        yield arr[:, 0], arr[:, 1].astype("int64"), arr[:, 2]


def imu_rows_bound(path: str | os.PathLike[str]) -> int:
    """An upper bound on the rows of ``imu.csv`` in the recording directory ``path`` (its
    newlines), so a column can be allocated once at its final size."""
    return _count_lines(Path(path) / "imu.csv", MAX_CSV_BYTES)


def read_segments(root: Path, warnings: list[str]) -> tuple[Segment, ...]:
    """The protocol segments listed in ``segments.csv`` of the recording ``root``."""
    from gyrocal.calib.segments import Segment

    spath = root / "segments.csv"
    segments = []
    for first, block, _ in _lines(spath, SEGMENTS_HEADER, MAX_SEGMENTS_BYTES, warnings):
        rows = _split_rows(block.decode("ascii", errors="replace"), first, spath, 7)
        for i, row in enumerate(rows, start=first):
            try:
                if any("_" in f for f in row):  # int() and float() read "1_0" as 10
                    raise ValueError(f"a number with an underscore: {','.join(row)[:60]}")
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
                raise RecordingError(f"{spath}:{i}: {_excerpt(str(exc), quote=False)}") from None
            segments.append(seg)
    return tuple(segments)


def load_recording(path: str | os.PathLike[str]) -> Recording:
    """Read a Recording v1 directory.

    The numeric files are parsed in blocks by the vectorised decimal parser
    (:mod:`gyrocal.kit.decimal_csv`, numpy alone; ``GYROCAL_CSV_PARSER=numpy|pandas`` forces
    numpy.loadtxt or pandas' C parser) straight into one float64 array per column (no
    per-row Python objects), so the memory beyond the returned arrays is one block;
    :func:`iter_imu` streams the samples instead for one-pass analyses.

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
        If the directory or a file is missing or not a regular file, a file is over its size
        cap, a manifest is not Recording v1, a header or row is malformed (the message names
        the file and line), or times go backwards.
    """
    root = Path(path)
    manifest = read_manifest(root)
    warnings: list[str] = []
    header = imu_header(root / "imu.csv")
    accel = None
    if header == IMU_HEADER_ACCEL:
        t, rate, temp, accel = _read_columns(root / "imu.csv", header, (1, 3, 1, 3), warnings,
                                             empty_col=_TEMP_COL)
    else:
        t, rate, temp = _read_columns(root / "imu.csv", header, (1, 3, 1), warnings,
                                      empty_col=_TEMP_COL)
    enc_t, enc_motor, enc_angle = _read_columns(root / "encoder.csv", ENCODER_HEADER, (1, 1, 1),
                                                warnings)
    segments = read_segments(root, warnings)
    return Recording(
        path=root,
        manifest=manifest,
        imu_t=t,
        imu_rate=rate,
        imu_temp=temp,
        enc_t=enc_t,
        enc_motor=enc_motor.astype("int64"),
        enc_angle=enc_angle,
        segments=segments,
        warnings=tuple(warnings),
        imu_accel=accel,
    )
