"""Seeded damage to input files, and the outcome of a command on them.

Used by ``tests/kit/test_fuzz.py`` (a few seconds) and ``python -m bench faults`` (larger). An
outcome is one of:

* ``refused``: exit 2 (bad input) or 6 (estimation refused) with a one-line message;
* ``ok``: exit 0 or 3 and, where the truth is known, a calibration within tolerance of it;
* ``silent-wrong``: exit 0 or 3 with a calibration off the truth (target 0);
* ``traceback``: exit 1, an escaped exception, or a traceback printed (target 0);
* ``hang``: no answer within the time limit (target 0).
"""

from __future__ import annotations

import contextlib
import io
import signal
from collections.abc import Callable
from pathlib import Path

import numpy as np

__all__ = ["MUTATIONS", "damage", "run_command"]


def _truncate(b: bytes, rng: np.random.Generator) -> bytes:
    return b[: int(rng.integers(0, max(1, len(b))))]


def _flip(b: bytes, rng: np.random.Generator) -> bytes:
    a = bytearray(b)
    for _ in range(int(rng.integers(1, 8))):
        if a:
            a[int(rng.integers(len(a)))] = int(rng.integers(256))
    return bytes(a)


def _number(b: bytes, rng: np.random.Generator) -> bytes:
    """Replace one number with an extreme or non-finite one."""
    import re

    nums = list(re.finditer(rb"-?\d+(\.\d+)?(e-?\d+)?", b))
    if not nums:
        return b
    m = nums[int(rng.integers(len(nums)))]
    new = [b"nan", b"inf", b"-inf", b"1e308", b"-1e308", b"9" * 401, b"0", b"-0.0",
           b"1e-300", b"\"7\""][int(rng.integers(10))]
    return b[: m.start()] + new + b[m.end():]


def _lines(b: bytes, rng: np.random.Generator) -> bytes:
    """Drop, duplicate or swap lines."""
    lines = b.split(b"\n")
    if len(lines) < 3:
        return b
    i = int(rng.integers(1, len(lines) - 1))
    op = int(rng.integers(3))
    if op == 0:
        del lines[i]
    elif op == 1:
        lines.insert(i, lines[i])
    else:
        j = int(rng.integers(1, len(lines) - 1))
        lines[i], lines[j] = lines[j], lines[i]
    return b"\n".join(lines)


def _junk(b: bytes, rng: np.random.Generator) -> bytes:
    """Insert NUL bytes, invalid UTF-8 or a long line."""
    pos = int(rng.integers(0, len(b) + 1))
    junk = [b"\0" * 64, b"\xff\xfe\xc3", b"x" * 5000, b"\r", b",,,,", b"[[[[[[[["][
        int(rng.integers(6))]
    return b[:pos] + junk + b[pos:]


#: Mutations: name -> function(bytes, rng) -> bytes.
MUTATIONS: dict[str, Callable[[bytes, np.random.Generator], bytes]] = {
    "truncate": _truncate, "flip": _flip, "number": _number, "lines": _lines, "junk": _junk}


def damage(data: bytes, rng: np.random.Generator) -> tuple[str, bytes]:
    """One random mutation of ``data``: ``(its name, the damaged bytes)``."""
    name = list(MUTATIONS)[int(rng.integers(len(MUTATIONS)))]
    return name, MUTATIONS[name](data, rng)


class _Hang(Exception):
    pass


def run_command(argv: list[str], timeout_s: float = 20.0) -> tuple[str, int | None, str, str]:
    """Run ``gyrocal argv`` in this process: ``(outcome class, exit code, stdout, stderr)``.

    The outcome class here is ``traceback``, ``hang``, ``refused`` or ``finished`` (exit 0/3;
    the caller judges it against the truth). Uses SIGALRM for the time limit (main thread).
    """
    from gyrocal.kit.cli import main

    def on_alarm(signum: int, frame: object) -> None:
        raise _Hang

    out, err = io.StringIO(), io.StringIO()
    old = signal.signal(signal.SIGALRM, on_alarm)
    signal.setitimer(signal.ITIMER_REAL, timeout_s)
    try:
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            code: int | None = main(argv)
    except _Hang:
        return "hang", None, out.getvalue(), err.getvalue()
    except BaseException as exc:  # an exception that escaped main is a traceback
        return "traceback", None, out.getvalue(), f"{err.getvalue()}{exc!r}"
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, old)
    e = err.getvalue()
    if code == 1 or "Traceback" in e:
        return "traceback", code, out.getvalue(), e
    if code in (0, 3):
        return "finished", code, out.getvalue(), e
    return "refused", code, out.getvalue(), e


def copy_tree(src: Path, dst: Path) -> Path:
    """Copy a recording directory (plain files)."""
    dst.mkdir(parents=True)
    for p in src.iterdir():
        (dst / p.name).write_bytes(p.read_bytes())
    return dst
