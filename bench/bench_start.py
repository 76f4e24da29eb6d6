"""CPU time of ``gyrocal --help`` and of argument errors against a bare Python start (issue 25:
at most 3 times ``python -c pass``).

``python -m bench start`` runs each command below in a fresh interpreter through the installed
``gyrocal`` console script (as a user runs it), for this checkout and for the code before the
change (``git archive`` of :data:`BEFORE` from this repository, unpacked in a temporary
directory), and ``python -c pass`` beside them, all with the same ``PYTHONPATH`` shim that
makes ``gyrocal`` this or that checkout. Each run's CPU time is the user + system time of the
child process (``resource.getrusage(RUSAGE_CHILDREN)`` before and after); the runs go round
robin over the commands ``--repeat=N`` times (default 10) so a load change on the shared host
touches them all, and the table gives each command's median CPU and its ratio to the median of
``python -c pass``. Two tables: with the bytecode cached (``PYTHONPYCACHEPREFIX`` in the
temporary directory, a first run of each command untimed), as in an installed gyrocal; and with
the sources compiled at every start (``PYTHONDONTWRITEBYTECODE=1``, as in an environment that
sets it), where every module imported costs its compilation too.

Options: ``--repeat=N``; ``--ref-commit=REV`` archives another commit.
"""

from __future__ import annotations

import os
import resource
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

from bench.bench_sim import _archive
from bench.table import print_table

ROOT = Path(__file__).resolve().parents[1]
#: The commit before ``gyrocal --help`` stopped importing the configuration (issue 25).
BEFORE = "a485b38"

#: (label, arguments of ``gyrocal``): the help pages and argument errors of issue 25.
COMMANDS: tuple[tuple[str, tuple[str, ...]], ...] = (
    ("gyrocal --help", ("--help",)),
    ("gyrocal calibrate --help", ("calibrate", "--help")),
    ("gyrocal estimate --help", ("estimate", "--help")),
    ("gyrocal thermal --help", ("thermal", "--help")),
    ("gyrocal track --help", ("track", "--help")),
    ("gyrocal estimate /nonexistent", ("estimate", "/nonexistent")),
    ("gyrocal noise /nonexistent", ("noise", "/nonexistent")),
    ("gyrocal calibrate --bogus", ("calibrate", "--bogus")),
    ("gyrocal estimte x", ("estimte", "x")),
)


def _script() -> list[str]:
    """The command that runs ``gyrocal``: its console script beside this interpreter, else
    ``python -m gyrocal.kit``."""
    script = Path(sys.executable).parent / "gyrocal"
    return [sys.executable, str(script)] if script.is_file() else [sys.executable, "-m",
                                                                   "gyrocal.kit"]


def _shim(checkout: Path, where: Path, bytecode: bool) -> dict[str, str]:
    """An environment in which ``import gyrocal`` is ``checkout``; with ``bytecode`` the
    compiled modules are cached under ``where`` (as an installed package has them; nothing is
    written into the checkout), else every start compiles the sources."""
    pkg = where / "gyrocal"
    pkg.mkdir(parents=True)
    (pkg / "__init__.py").write_text(f"__path__ = [{str(checkout)!r}]\n")
    env = {k: v for k, v in os.environ.items()
           if k not in ("PYTHONDONTWRITEBYTECODE", "PYTHONPYCACHEPREFIX")}
    env["PYTHONPATH"] = str(where)
    if bytecode:
        env["PYTHONPYCACHEPREFIX"] = str(where / "pycache")
    else:
        env["PYTHONDONTWRITEBYTECODE"] = "1"
    return env


def _cpu(argv: list[str], env: dict[str, str]) -> float:
    """CPU seconds (user + system) of running ``argv`` to its end."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    subprocess.run(argv, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                   check=False)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def _measure(before: Path, where: Path, bytecode: bool, repeat: int
             ) -> dict[tuple[str, str], float]:
    """Median CPU seconds of each (command, checkout) and of ``("python -c pass", "now")``."""
    envs = {"before": _shim(before, where / "shim-before", bytecode),
            "now": _shim(ROOT, where / "shim-now", bytecode)}
    gyrocal = _script()
    jobs = [("python -c pass", "now", [sys.executable, "-c", "pass"])]
    jobs += [(label, which, [*gyrocal, *args]) for label, args in COMMANDS for which in envs]
    cpu: dict[tuple[str, str], list[float]] = {(label, which): [] for label, which, _ in jobs}
    for _, which, cmd in jobs:  # any bytecode is written by a first, untimed run
        _cpu(cmd, envs[which])
    for _ in range(repeat):
        for label, which, cmd in jobs:
            cpu[label, which].append(_cpu(cmd, envs[which]))
    return {key: statistics.median(v) for key, v in cpu.items()}


def main(argv: list[str]) -> None:
    opts = dict(a.lstrip("-").split("=", 1) for a in argv if "=" in a)
    repeat = int(opts.get("repeat", 10))
    rev = opts.get("ref-commit", BEFORE)
    with tempfile.TemporaryDirectory() as tmp:
        before = _archive(rev, Path(tmp) / "before")
        for bytecode, how in ((True, "bytecode cached, as installed"),
                              (False, "sources compiled at every start, "
                                      "PYTHONDONTWRITEBYTECODE=1")):
            cpu = _measure(before, Path(tmp) / how[:8], bytecode, repeat)
            bare = cpu["python -c pass", "now"]
            rows: list[list[object]] = [["python -c pass", f"{bare * 1e3:.1f}", "1.00", "", ""]]
            for label, _ in COMMANDS:
                old, new = cpu[label, "before"], cpu[label, "now"]
                rows.append([label, f"{new * 1e3:.1f}", f"{new / bare:.2f}", f"{old * 1e3:.1f}",
                             f"{old / bare:.2f}"])
            print_table(["command", "CPU ms", "x python -c pass", f"CPU ms {rev}",
                         f"x ({rev})"], rows,
                        f"Start-up CPU, {how} (median of {repeat}, user + system of the child "
                        "process; the target is at most 3x python -c pass)")
