"""Writing output files safely: never half-written, never silently overwritten."""

from __future__ import annotations

import errno
import json
import os
import stat
import sys
import tempfile
from collections.abc import Iterable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from gyrocal.kit.errors import InputError, OutputExistsError

__all__ = [
    "atomic_write_bytes",
    "built_beside",
    "atomic_write_json",
    "atomic_write_text",
    "bounded_lines",
    "check_replaceable_run",
    "emit_text",
    "make_output_dir",
    "read_input_bytes",
    "refuse_existing",
    "replace_dir",
    "staging_dir",
]


def _file_in_the_way(path: Path) -> Path | None:
    """The nearest ancestor of ``path`` (or ``path`` itself) that exists and is not a directory."""
    for p in (path, *path.parents):
        if p.exists() or p.is_symlink():
            return None if p.is_dir() else p
    return None


def _no_directory_message(dest: Path, what: str) -> str:
    blocker = _file_in_the_way(dest)
    if blocker is None:
        return f"cannot write {what}: directory {dest} does not exist"
    if blocker == dest:
        return f"cannot write {what}: {dest} is a file, not a directory"
    return f"cannot write {what}: {blocker} is a file, so there is no directory {dest} under it"


def make_output_dir(path: str | os.PathLike[str], flag: str) -> Path:
    """Create the output directory ``path`` (and its parents) named by the option ``flag``.

    Raises
    ------
    InputError
        If ``path`` or one of its parents is an existing file, or the directory cannot be made;
        the message names ``flag`` as the user typed it and what to do.
    """
    out = Path(path)
    blocker = _file_in_the_way(out)
    if blocker is not None:
        where = "is a file" if blocker == out else f"is under {blocker}, which is a file"
        raise InputError(f"{flag} {path} {where}; give a new or existing directory")
    new = [d for d in (out, *out.parents) if not d.exists()]
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InputError(f"{flag} {path}: cannot create the directory ({exc.strerror})") from None
    _MADE.update(d.absolute() for d in new)
    return out


#: The directories :func:`make_output_dir` created in this process: a run that fails before it
#: writes anything removes them again (:func:`built_beside`), and only them.
_MADE: set[Path] = set()


def _remove_if_made_and_empty(path: Path) -> None:
    """Remove ``path``, and the parents made with it, where :func:`make_output_dir` created
    them and they are still empty; a directory the user made, or one holding anything, stays."""
    for d in (path.absolute(), *path.absolute().parents):
        if d not in _MADE:
            return
        try:
            d.rmdir()  # only an empty directory goes
        except OSError:
            return
        _MADE.discard(d)


def atomic_write_bytes(
    path: str | os.PathLike[str], data: bytes | Iterable[bytes], *, force: bool = False
) -> Path:
    """Write ``data`` to ``path`` atomically.

    The data go to a temporary file in the same directory, which is flushed, fsynced and then
    renamed over ``path``, so a reader sees either the old file or the whole new one.

    Parameters
    ----------
    path : path-like
        Destination file.
    data : bytes or iterable of bytes
        Contents (pieces are written as they come: a long document need not be held whole).
    force : bool
        Replace an existing file. Without it an existing file is an error.

    Returns
    -------
    Path
        The destination.

    Raises
    ------
    OutputExistsError
        If ``path`` exists and ``force`` is false.
    InputError
        If the directory does not exist.
    """
    dest = Path(path)
    if dest.is_dir():
        raise InputError(f"cannot write {dest}: it is a directory; give a file name "
                         f"(e.g. {dest / 'out'})")
    if dest.exists() and not force:
        raise OutputExistsError(f"{dest} already exists; pass --force to replace it")
    if dest.exists() and not dest.is_file():
        raise InputError(f"cannot write {dest}: it is not a regular file (a device, FIFO or "
                         "socket); give the path of a file")
    if not dest.parent.is_dir():
        raise InputError(_no_directory_message(dest.parent, str(dest)))
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{dest.name}.", suffix=".tmp", dir=dest.parent)
    except OSError as exc:
        raise InputError(f"cannot write {dest}: {exc.strerror or exc}; {_advice(exc)}") from None
    try:
        os.chmod(tmp, 0o666 & ~_umask())  # mkstemp makes 0600; give the usual file mode
        with os.fdopen(fd, "wb") as fh:
            for part in (data,) if isinstance(data, bytes) else data:
                fh.write(part)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, dest)
    except BaseException as exc:
        try:
            os.unlink(tmp)
        except FileNotFoundError:
            pass
        if isinstance(exc, OSError):
            raise InputError(f"cannot write {dest}: {exc.strerror or exc}"
                             + (f"; {_advice(exc)}" if exc.errno in _FULL else "")) from None
        raise
    return dest


#: errno values of a full disk or quota (no space, no inode, over quota).
_FULL = frozenset({errno.ENOSPC, errno.EDQUOT})


def _advice(exc: OSError) -> str:
    """What to do about a file that cannot be written: free space on a full disk, else another
    directory."""
    if exc.errno in _FULL:
        return "free space on that disk or choose another directory"
    return "choose a directory you may write to"


def _umask() -> int:
    current = os.umask(0)
    os.umask(current)
    return current


def atomic_write_text(path: str | os.PathLike[str], text: str, *, force: bool = False) -> Path:
    """:func:`atomic_write_bytes` for UTF-8 text."""
    return atomic_write_bytes(path, text.encode("utf-8"), force=force)


def emit_text(text: str | Iterable[str], out: str | os.PathLike[str] | None, *,
              force: bool = False) -> None:
    """A command's output: written atomically to ``out`` (``--out``, said on stderr), or to stdout.

    ``text`` may come in pieces (an iterable of str), written as they come.

    Raises
    ------
    OutputExistsError, InputError
        As :func:`atomic_write_bytes`.
    """
    if isinstance(text, str):
        text = (text,)
    if out:
        atomic_write_bytes(out, (p.encode("utf-8") for p in text), force=force)
        print(f"wrote {out}", file=sys.stderr)
    else:
        for part in text:
            sys.stdout.write(part)


def atomic_write_json(path: str | os.PathLike[str], doc: Any, *, force: bool = False) -> Path:
    """:func:`atomic_write_text` of ``doc`` as indented JSON with a final newline."""
    return atomic_write_text(path, json.dumps(doc, indent=2) + "\n", force=force)


def refuse_existing(
    paths: Iterable[str | os.PathLike[str] | None], *, force: bool = False
) -> None:
    """Refuse existing output files before any work is done (``None`` entries are skipped).

    The refusal :func:`atomic_write_bytes` makes when it writes, made up front, so that a
    command does not run for minutes (or drive the jig) only to find it may not write.

    Raises
    ------
    OutputExistsError
        If a path exists and ``force`` is false.
    """
    for p in paths:
        if p is not None and Path(p).exists() and not force:
            raise OutputExistsError(f"{p} already exists; pass --force to replace it")


def staging_dir(dest: str | os.PathLike[str]) -> Path:
    """A new, empty directory beside ``dest`` in which to build its replacement.

    Named ``.NAME.new-XXXXXXXX`` in ``dest``'s parent (same file system, so :func:`replace_dir`
    can rename it into place).

    Raises
    ------
    InputError
        If the parent directory cannot be written.
    """
    d = Path(dest)
    try:
        d.parent.mkdir(parents=True, exist_ok=True)
        return Path(tempfile.mkdtemp(prefix=f".{d.name}.new-", dir=d.parent))
    except OSError as exc:
        raise InputError(f"cannot create the output beside {d}: {exc.strerror or exc}") from None


def replace_dir(staging: str | os.PathLike[str], dest: str | os.PathLike[str]) -> Path:
    """Put the finished directory ``staging`` in the place of ``dest`` as a whole.

    The old ``dest`` (if any) is renamed aside, ``staging`` renamed into place, and the old one
    removed: a reader finds the old run or the new one, never a mix of both. Only a crash
    between the two renames leaves ``dest`` missing, with the old run kept as ``.NAME.old-*``.

    Raises
    ------
    InputError
        If ``dest`` exists and is not a directory.
    """
    import shutil

    src, d = Path(staging), Path(dest)
    old = None
    if d.exists() or d.is_symlink():
        if not d.is_dir() or d.is_symlink():
            raise InputError(f"cannot replace {d}: it is not a directory; give another --out")
        os.chmod(src, stat.S_IMODE(d.stat().st_mode))  # the user's permissions, not mkdtemp's
        old = Path(tempfile.mkdtemp(prefix=f".{d.name}.old-", dir=d.parent))
        os.rename(d, old / d.name)
    try:
        os.rename(src, d)
    except BaseException:
        if old is not None:
            os.rename(old / d.name, d)
            old.rmdir()
        raise
    if old is not None:
        shutil.rmtree(old, ignore_errors=True)
    return d


@contextmanager
def built_beside(work: Path, out: Path) -> Iterator[Path]:
    """Build a run's output in ``work`` and, when the body ends without an exception, put it in
    the place of ``out`` as a whole (:func:`replace_dir`, shielded from signals); ``work`` may
    be ``out`` itself (nothing to replace). On failure ``out`` is untouched and stderr says
    where this run's output is (``--force`` replaces a run only when the new one is whole); a
    directory this run created and left empty (a usage error found after it was made) is
    removed."""
    from gyrocal.drivers.signals import shielded

    try:
        yield work
    except BaseException:
        _remove_if_made_and_empty(work)
        if work != out:
            print(f"gyrocal: the previous run in {out} is untouched; this run's output is in "
                  f"{work}", file=sys.stderr)
        raise
    if work != out:
        with shielded():
            replace_dir(work, out)


#: What a gyrocal run directory holds at its top level (``gyrocal calibrate``, a plate run's
#: ``summary.json``, the emulated jig's ``sim-state.json``, the report); a sensor's or a thermal
#: run's own directory inside it is a gyrocal run too (:func:`_is_run`).
RUN_ENTRIES = frozenset({"calibration.json", "recording", "report.html", "plots", "summary.json",
                         "sim-state.json"})


def _is_run(d: Path) -> bool:
    """Whether ``d`` holds a gyrocal run: a recording manifest (``recording/manifest.json`` of
    format ``gyrocal-recording``) or a ``calibration.json`` of format ``gyrocal-calibration``."""
    for f, kind in ((d / "recording" / "manifest.json", "gyrocal-recording"),
                    (d / "calibration.json", "gyrocal-calibration")):
        try:
            if f.is_file() and not f.is_symlink() and f.stat().st_size < _MAX_DOCUMENT_BYTES:
                doc = json.loads(f.read_text(encoding="utf-8"))
                if isinstance(doc, dict) and doc.get("format") == kind:
                    return True
        except (OSError, ValueError, RecursionError):
            continue
    return False


def check_replaceable_run(out: str | os.PathLike[str], flag: str = "--out") -> None:
    """Refuse, before any work, an output directory that ``--force`` may not replace.

    ``--force`` replaces a directory only when it holds a gyrocal run (:func:`_is_run`) and
    nothing else: every entry at its top level is one gyrocal writes (:data:`RUN_ENTRIES`), a
    run directory of its own (a plate's sensor, a thermal run), or an atomic write's leftover
    (``.NAME.*.tmp``); anything else (a ``.git``, notes) is the user's and stops it. The
    current directory, one of its ancestors, the root, and a symbolic link are refused by name,
    so a run never starts only to fail at its end.

    Raises
    ------
    InputError
        Naming ``flag``, the directory and (up to three of) the entries gyrocal did not write.
    """
    d = Path(out)
    if d.is_symlink():
        raise InputError(f"{flag} {out} is a symbolic link; --force replaces a run directory "
                         f"itself: give the directory it points to ({os.path.realpath(d)}) or a "
                         "new name")
    if not d.is_dir():
        return
    real, cwd = d.resolve(), Path.cwd().resolve()
    if real == cwd or real in cwd.parents or real == Path(real.anchor):
        raise InputError(f"{flag} {out} is the current directory or one above it; --force "
                         "replaces a run directory as a whole: give the run's own directory "
                         f"(e.g. {flag} run1)")
    if not _is_run(d) and not any(_is_run(e) for e in _entries(d) if e.is_dir()):
        raise InputError(f"{flag} {out} does not hold a gyrocal run (no recording/manifest.json "
                         "or calibration.json); --force replaces only a gyrocal run: give a new "
                         "directory")
    foreign = [e.name for e in _entries(d)
               if e.name not in RUN_ENTRIES
               and not (e.name.startswith(".") and e.name.endswith(".tmp"))
               and not (e.is_dir() and not e.is_symlink() and _is_run(e))]
    if foreign:
        names = ", ".join(sorted(foreign)[:3]) + (" ..." if len(foreign) > 3 else "")
        raise InputError(f"{flag} {out} holds {names}, which gyrocal did not write; --force "
                         "replaces only a gyrocal run: move them away or give another "
                         f"{flag}")


def _entries(d: Path) -> list[Path]:
    try:
        return sorted(d.iterdir())
    except OSError as exc:
        raise InputError(f"cannot list {d}: {exc.strerror or exc}") from None


#: Largest document (calibration, noise, verification JSON) gyrocal reads, bytes: a calibration
#: is a few kB, a thermal one with its runs a few hundred.
_MAX_DOCUMENT_BYTES = 16 << 20
#: Longest line of a CSV stream on standard input (``gyrocal apply -``), characters: a row of
#: five numbers is under 200.
MAX_LINE_CHARS = 4096


def read_input_bytes(path: str, what: str, limit: int = _MAX_DOCUMENT_BYTES) -> tuple[bytes, str]:
    """The bytes of the input file ``path`` (``-``: standard input), checked as every command's
    inputs are: a regular file (not a FIFO, device or directory), readable, at most ``limit``
    bytes (standard input: read up to the limit, no further). Returns ``(data, where)``,
    ``where`` naming the input for messages.

    Raises
    ------
    InputError
        Naming ``what`` and ``path`` and what to do; never echoing the contents.
    """
    if path == "-":
        where = f"{what} on standard input"
        data = _read_stdin(limit + 1)
    else:
        p = Path(path)
        where = f"{what} {p}"
        try:
            st = p.stat()
        except FileNotFoundError:
            raise InputError(f"{where} does not exist; give a gyrocal JSON document") from None
        except OSError as exc:  # a symbolic link loop, no permission on a directory above
            raise InputError(f"cannot read {where}: {exc.strerror or exc}") from None
        if stat.S_ISDIR(st.st_mode):
            raise InputError(f"{where} is a directory; give the file itself")
        if not stat.S_ISREG(st.st_mode):
            raise InputError(f"{where} is not a regular file (a FIFO, device or socket); give "
                             "the path of a file")
        if st.st_size > limit:
            raise InputError(f"{where} is {st.st_size} bytes, more than the {limit} a gyrocal "
                             "document can be")
        try:
            with open(p, "rb") as fh:
                data = fh.read(limit + 1)
        except OSError as exc:
            raise InputError(f"cannot read {where}: {exc.strerror or exc}") from None
    if len(data) > limit:
        raise InputError(f"{where} is more than {limit} bytes, more than a gyrocal document can "
                         "be")
    return data, where


def _read_stdin(n: int) -> bytes:
    stream = getattr(sys.stdin, "buffer", None)
    if stream is not None:
        return stream.read(n)
    return sys.stdin.read(n).encode("utf-8")


def bounded_lines(stream: Any, what: str = "standard input",
                  max_line: int = MAX_LINE_CHARS) -> Iterator[str]:
    """The lines of the text ``stream`` as they arrive, each at most ``max_line`` characters.

    One line is held at a time, so an endless stream (a live sensor through ``gyrocal apply -``)
    runs in constant memory; a line longer than ``max_line`` (``/dev/zero``, a binary file) is
    refused instead of being read whole.

    Raises
    ------
    InputError
        At the first line longer than ``max_line``, by its number (not its text).
    """
    number = 0
    while True:
        try:
            line = stream.readline(max_line + 1)
        except UnicodeDecodeError as exc:
            raise InputError(f"{what}, line {number + 1}: not text ({exc.reason}); give CSV "
                             "rows") from None
        if not line:
            return
        number += 1
        if len(line) > max_line and not line.endswith("\n"):
            raise InputError(f"{what}, line {number}: longer than {max_line} characters; give "
                             "CSV rows (t,gx,gy,gz,temp)")
        yield line
