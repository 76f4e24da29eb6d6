"""The ``gyrocal`` command line: one console script with subcommands.

Each subcommand lives in a module of :mod:`gyrocal.kit.commands` that defines ``HELP`` (one line),
``add_arguments(parser)`` and ``run(args) -> int``; :data:`COMMANDS` lists them in the order
``gyrocal --help`` shows them. Modules keep their top-level imports light so that ``--help`` is
fast.
"""

from __future__ import annotations

import argparse
import importlib
import sys
import traceback
from collections.abc import Sequence

from gyrocal.kit import __version__
from gyrocal.kit.errors import EXIT_CODES, exit_code_for

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
    ("noise", "gyrocal.kit.commands.noise"),
    ("study", "gyrocal.kit.commands.study"),
    ("simulate-recording", "gyrocal.kit.commands.simulate_recording"),
    ("emulate", "gyrocal.kit.commands.emulate"),
)


def _epilog() -> str:
    lines = ["exit codes:"]
    lines += [f"  {code:>3}  {meaning}" for code, meaning in EXIT_CODES.items()]
    return "\n".join(lines)


def build_parser() -> argparse.ArgumentParser:
    """The argument parser with every subcommand of :data:`COMMANDS` registered."""
    parser = argparse.ArgumentParser(
        prog="gyrocal",
        description=(
            "Calibrate a MEMS gyroscope on a Dynamixel gimbal: spin it about each axis, time the "
            "turns with the servo encoders, and fit scale factors and biases with uncertainties."
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


def main(argv: Sequence[str] | None = None) -> int:
    """Run ``gyrocal`` with ``argv`` (default ``sys.argv[1:]``) and return the exit code."""
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:  # argparse: --help (0) or bad usage (2)
        return int(exc.code or 0)
    try:
        return int(args._run(args) or 0)
    except KeyboardInterrupt:
        print("gyrocal: interrupted", file=sys.stderr)
        return 130
    except SystemExit as exc:  # a signal handler's exit (e.g. SIGTERM -> 143) after a safe stop
        code = exc.code if isinstance(exc.code, int) else 1
        print(f"gyrocal: stopped (exit {code})", file=sys.stderr)
        return code
    except Exception as exc:  # every error becomes a message and a documented exit code
        code = exit_code_for(exc)
        if code == 1 or args.traceback:
            traceback.print_exc()
        print(f"gyrocal: error: {exc}", file=sys.stderr)
        return code
