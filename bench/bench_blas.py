"""What OpenBLAS's threads cost the test suite (``tests/conftest.py`` sets one per process).

``python -m bench blas`` runs test files the way ``pytest -n 2`` loads the machine: two pytest
processes at once (as the two xdist workers), first with OpenBLAS's default of one thread per
core (``OPENBLAS_NUM_THREADS`` = the CPU count), then with one; and prints the CPU seconds of
both processes together (their rusage) and the wall seconds. ``--files=a.py,b.py`` picks the
files (default: the window and Allan-deviation tests, whose fits call LAPACK at moderate sizes);
``--threads=4,1`` the counts compared.
"""

from __future__ import annotations

import os
import resource
import subprocess
import sys
import time
from pathlib import Path

from bench.table import print_table

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_FILES = ("tests/calib/test_windows.py", "tests/calib/test_allan.py")


def _children_cpu() -> float:
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def run_pair(files: list[str], threads: int) -> tuple[float, float, list[int]]:
    """Run ``pytest -q files`` twice at once with ``threads`` OpenBLAS threads; return the CPU
    seconds of both, the wall seconds and their exit codes."""
    env = {**os.environ, **{v: str(threads) for v in
                            ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")}}
    cmd = [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", *files]
    c0, t0 = _children_cpu(), time.perf_counter()
    procs = [subprocess.Popen(cmd, cwd=ROOT, env=env, stdout=subprocess.DEVNULL,
                              stderr=subprocess.DEVNULL) for _ in range(2)]
    codes = [p.wait() for p in procs]
    return _children_cpu() - c0, time.perf_counter() - t0, codes


def main(argv: list[str]) -> None:
    opts = dict(a.lstrip("-").split("=", 1) for a in argv if "=" in a)
    files = opts["files"].split(",") if "files" in opts else list(DEFAULT_FILES)
    counts = ([int(x) for x in opts["threads"].split(",")] if "threads" in opts
              else [os.cpu_count() or 1, 1])
    rows = []
    for n in counts:
        cpu, wall, codes = run_pair(files, n)
        rows.append([n, cpu, wall, " ".join(map(str, codes))])
    print_table(["OpenBLAS threads", "CPU s (both)", "wall s", "exit codes"], rows,
                title=f"two pytest processes at once on {os.cpu_count()} CPUs: "
                      f"{' '.join(files)}")
