"""The ``gyrocal`` command line: one console script with subcommands.

Each subcommand lives in a module of :mod:`gyrocal.kit.commands` that defines ``HELP`` (one line),
``add_arguments(parser)`` and ``run(args) -> int``; :data:`COMMANDS` lists them in the order
``gyrocal --help`` shows them. Only the command being run is imported; the others are listed
with their ``HELP`` line read from the source, so ``gyrocal --help``, ``gyrocal CMD --help`` and
argument errors import neither numpy nor scipy whatever a command module imports.
"""

from __future__ import annotations

import argparse
import ast
import contextlib
import importlib
import importlib.util
import os
import signal
import sys
import warnings
from collections.abc import Iterator, Sequence
from typing import Any

# One BLAS thread, set before numpy loads OpenBLAS (a caller's own setting stands). Every matrix
# the kit factors is small (a fit's 30–50 parameters, a plan's 3×3 designs), where OpenBLAS's
# threads spin more than they help: on a two-core host with other work running, one batched
# pseudo-inverse of the full-matrix fit took 40–146 ms of CPU with two threads and 1.5 ms with
# one, and `calibrate --sim`'s fit and outputs 1.9 CPU s against 1.1 (issue 25). The test suite
# sets the same (tests/conftest.py).
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

from gyrocal.drivers import signals  # noqa: E402
from gyrocal.kit import __version__  # noqa: E402
from gyrocal.kit.errors import EXIT_CODES, exit_code_for  # noqa: E402

__all__ = ["COMMANDS", "build_parser", "main"]

#: (subcommand, module) in the order of ``gyrocal --help``.
COMMANDS: tuple[tuple[str, str], ...] = (
    ("init", "gyrocal.kit.commands.init"),
    ("doctor", "gyrocal.kit.commands.doctor"),
    ("calibrate", "gyrocal.kit.commands.calibrate"),
    ("verify", "gyrocal.kit.commands.verify"),
    ("estimate", "gyrocal.kit.commands.estimate"),
    ("export", "gyrocal.kit.commands.export"),
    ("apply", "gyrocal.kit.commands.apply"),
    ("report", "gyrocal.kit.commands.report"),
    ("track", "gyrocal.kit.commands.track"),
    ("history", "gyrocal.kit.commands.history"),
    ("thermal", "gyrocal.kit.commands.thermal"),
    ("noise", "gyrocal.kit.commands.noise"),
    ("study", "gyrocal.kit.commands.study"),
    ("simulate-recording", "gyrocal.kit.commands.simulate_recording"),
    ("emulate", "gyrocal.kit.commands.emulate"),
)


def _epilog() -> str:
    lines = ["exit codes:"]
    lines += [f"  {code:>3}  {meaning}" for code, meaning in EXIT_CODES.items()]
    return "\n".join(lines)


def _summary(module_name: str) -> str:
    """The ``HELP`` line of a command module, read from its source without importing it."""
    spec = importlib.util.find_spec(module_name)
    if spec is not None and spec.origin:
        try:
            with open(spec.origin, encoding="utf-8") as fh:
                lines = fh.read().splitlines()
        except OSError:
            lines = []
        for i, line in enumerate(lines):
            if line.startswith("HELP = "):
                for j in range(i + 1, min(i + 10, len(lines)) + 1):
                    try:
                        value = ast.literal_eval("\n".join(lines[i:j])[len("HELP = "):].strip())
                    except (SyntaxError, ValueError):
                        continue
                    if isinstance(value, str):
                        return value
                break
    return str(importlib.import_module(module_name).HELP)


def _command_in(argv: Sequence[str]) -> str | None:
    """The subcommand ``argv`` names (its first word that is not an option), if a known one."""
    names = {name for name, _ in COMMANDS}
    for word in argv:
        if word == "--":
            return None
        if not word.startswith("-"):
            return word if word in names else None
    return None


def build_parser(argv: Sequence[str] | None = None) -> argparse.ArgumentParser:
    """The argument parser: every subcommand of :data:`COMMANDS`, the one ``argv`` names in full.

    Without ``argv`` every subcommand is registered in full (all modules imported).
    """
    selected = None if argv is None else _command_in(argv)
    parser = argparse.ArgumentParser(
        prog="gyrocal",
        description=(
            "Calibrate a MEMS gyroscope on a Dynamixel gimbal: spin it about each axis (and with "
            "an inner servo posed), time the turns with the servo encoders, and fit the full "
            "model g = A (m + b), a 3x3 matrix A (scale factors and cross-axis terms) and biases "
            "b, with uncertainties (Calibration v2; the accelerometer and the gyro's "
            "g-sensitivity too when the IMU's accelerometer is read). --protocol auto or paper "
            "give the paper's diagonal model (Calibration v1)."
        ),
        epilog=_epilog(),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--version", action="version", version=f"gyrocal {__version__}")
    parser.add_argument(
        "--traceback", action="store_true", help="show the full traceback of any error"
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True
    for name, module_name in COMMANDS:
        if argv is not None and name != selected:
            sub.add_parser(name, help=_summary(module_name))
            continue
        module = importlib.import_module(module_name)
        p = sub.add_parser(
            name,
            help=module.HELP,
            description=getattr(module, "DESCRIPTION", module.HELP),
            epilog=_epilog(),
            formatter_class=argparse.RawDescriptionHelpFormatter,
        )
        module.add_arguments(p)
        p.set_defaults(_run=module.run)
    return parser


@contextlib.contextmanager
def _chip_notices_as_notes() -> Iterator[None]:
    """Say a chip accepted with a caveat (the drivers' ``ChipNotice``: an MPU-6500, an LSM6DSO)
    as a ``gyrocal: note:`` line rather than as a Python warning with a source location."""
    original = warnings.showwarning

    def show(message: Any, category: type[Warning], *args: Any, **kwargs: Any) -> None:
        if category.__name__ == "ChipNotice":
            print(f"gyrocal: note: {message}", file=sys.stderr)
        else:
            original(message, category, *args, **kwargs)

    warnings.showwarning = show
    try:
        yield
    finally:
        warnings.showwarning = original


def main(argv: Sequence[str] | None = None) -> int:
    """Run ``gyrocal`` with ``argv`` (default ``sys.argv[1:]``) and return the exit code."""
    # SIGINT, SIGTERM and SIGHUP end any command with a message and exit 130/143/129, at any
    # phase: before the ports open, during the run (the gimbal installs the same handlers and
    # stops the servos) and during the fit and the output.
    old = signals.install()
    if argv is None:
        argv = sys.argv[1:]
    old_show = warnings.showwarning
    warnings.showwarning = _show_warning  # a library warning is a line for the user
    try:
        show_traceback = False
        try:
            parser = build_parser(argv)
            try:
                args = parser.parse_args(argv)
            except SystemExit as exc:  # argparse: --help (0) or bad usage (2)
                return int(exc.code or 0)
            show_traceback = args.traceback
            with _chip_notices_as_notes():
                code = int(args._run(args) or 0)
            sys.stdout.flush()  # here, so that a reader gone (head) is seen as such
            return code
        except BaseException as exc:
            if _stdout_closed(exc):
                return _quiet_stdout()
            with signals.shielded():  # a second signal cannot cut the report short
                return _report(exc, show_traceback)
    finally:
        signals.restore(old)
        warnings.showwarning = old_show


def _stdout_closed(exc: BaseException) -> bool:
    """Whether ``exc`` is (or was caused by) standard output's reader having gone: a
    ``BrokenPipeError`` while standard output can no longer be flushed."""
    chain: BaseException | None = exc
    while chain is not None and not isinstance(chain, BrokenPipeError):
        chain = chain.__cause__ or chain.__context__
    if chain is None:
        return False
    try:
        sys.stdout.flush()
    except BrokenPipeError:
        return True
    except (OSError, ValueError):
        return False
    try:  # nothing was left to flush: ask the pipe itself (POLLERR once its reader closed it)
        import select

        poller = select.poll()
        poller.register(sys.stdout.fileno(), select.POLLOUT)
        return any(ev & select.POLLERR for _, ev in poller.poll(0))
    except (OSError, ValueError, AttributeError):
        return False


def _quiet_stdout() -> int:
    """End quietly after standard output's reader went away (``gyrocal verify ... | head``): the
    rest of the output goes to ``os.devnull`` so that Python's flush at exit cannot fail again
    (Python docs, signal module, "Note on SIGPIPE"), and the exit code is a shell's for a
    command ended by SIGPIPE, 128 + 13."""
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        os.close(devnull)
    except (OSError, ValueError):  # no file descriptor (a replaced sys.stdout): nothing to do
        pass
    return 128 + signal.SIGPIPE


def _show_warning(message: Warning | str, category: type[Warning], filename: str, lineno: int,
                  file: object = None, line: str | None = None) -> None:
    """Print a warning as ``gyrocal: warning: ...`` on stderr (no source line)."""
    print(f"gyrocal: warning: {message}", file=sys.stderr)


def _report(exc: BaseException, show_traceback: bool) -> int:
    """Print the message of the exception that ended a command; return its exit code."""
    if isinstance(exc, KeyboardInterrupt):
        print("gyrocal: interrupted (SIGINT)", file=sys.stderr)
        return 130
    if isinstance(exc, signals.TerminatedBySignal):
        name = {15: "terminated (SIGTERM)", 1: "hung up (SIGHUP)"}.get(exc.signum, "stopped")
        print(f"gyrocal: {name}", file=sys.stderr)
        return int(exc.code)
    if isinstance(exc, SystemExit):  # a command's own exit
        code = exc.code if isinstance(exc.code, int) else 1
        print(f"gyrocal: stopped (exit {code})", file=sys.stderr)
        return code
    if not isinstance(exc, Exception):
        raise exc
    code = exit_code_for(exc)  # every error becomes a message and a documented exit code
    if code == 1 or show_traceback:
        import traceback  # only here: its import costs a tenth of a bare Python start

        traceback.print_exception(exc)
    print(f"gyrocal: error: {exc}", file=sys.stderr)
    return code
