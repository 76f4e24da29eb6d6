"""The command line's help and argument/path errors import neither numpy nor scipy (issues 11,
16), nor the configuration, the recording reader or the drivers (issue 25: a start within three
times a bare Python's), and the help lines read from source are the modules' own."""

import importlib
import json
import subprocess
import sys

import pytest

from gyrocal.kit import cli

PROBE = (
    "import sys, io, contextlib\n"
    "from gyrocal.kit.cli import main\n"
    "out = io.StringIO()\n"
    "with contextlib.redirect_stdout(out), contextlib.redirect_stderr(out):\n"
    "    code = main(sys.argv[2:])\n"
    "heavy = sorted(m for m in sys.modules\n"
    "            if m.split('.')[0] in ('numpy', 'scipy', 'matplotlib'))\n"
    "parser_only = sorted(m for m in sys.modules if m in sys.argv[1].split(','))\n"
    "print(__import__('json').dumps({'code': code, 'heavy': heavy[:5], 'out': out.getvalue(),\n"
    "                                'beyond_parser': parser_only}))\n"
)

#: Modules that building the parser, ``--help`` and an argument error do not import: the
#: configuration (tomllib, dataclasses, the IMU drivers' table), the recording reader and the file
#: helpers (tempfile) are for running a command (issue 25: ``gyrocal calibrate --help`` took 3.3
#: times a bare Python start with them, 2.1 without; ``python -m bench start``).
NOT_FOR_THE_PARSER = (
    "gyrocal.kit.config", "gyrocal.kit.recording", "gyrocal.kit.fileio", "gyrocal.kit.history",
    "gyrocal.kit.pipeline", "gyrocal.kit.jig", "gyrocal.drivers.imu", "gyrocal.drivers.dynamixel",
    "tomllib", "dataclasses", "tempfile",
)


def probe(*argv):
    """Run ``gyrocal ARGV`` in a fresh interpreter: its exit code, output, the numpy/scipy
    modules and the :data:`NOT_FOR_THE_PARSER` modules it imported."""
    out = subprocess.run([sys.executable, "-c", PROBE, ",".join(NOT_FOR_THE_PARSER), *argv],
                         capture_output=True, text=True, timeout=120, check=True)
    return json.loads(out.stdout)


@pytest.mark.parametrize("argv, code, says", [
    (["--help"], 0, "simulate-recording"),
    (["estimate", "--help"], 0, "--method"),
    (["noise", "--help"], 0, "--span"),
    (["report", "--help"], 0, "--out"),
    (["estimate", "nope"], 2, "nope is not a directory"),
    (["noise", "nope"], 2, "nope is not a directory"),
    (["report", "nope"], 2, "nope is not a directory"),
    (["track", "nope"], 2, "nope is not a directory"),
    (["estimte", "x"], 2, "invalid choice: 'estimte'"),
    (["estimate"], 2, "the following arguments are required"),
    (["calibrate", "--bogus"], 2, "unrecognized arguments: --bogus"),
    (["calibrate", "--method", "x"], 2, "invalid choice: 'x'"),
    (["calibrate", "--sim-seed", "-1"], 2, "seeds are whole numbers >= 0"),
    (["thermal", "--runs", "x"], 2, "--runs"),
])
def test_help_and_bad_arguments_import_no_numpy_or_scipy(argv, code, says):
    got = probe(*argv)
    assert got["code"] == code and says in got["out"]
    assert got["heavy"] == []
    assert got["beyond_parser"] == []


#: What a command's parser needs beyond argparse: ``export`` lists the registered exporters and
#: their options (:data:`gyrocal.kit.exports.EXPORTERS`, dataclasses).
PARSER_NEEDS = {"export": ["dataclasses"]}


@pytest.mark.parametrize("command", [name for name, _ in cli.COMMANDS])
def test_every_commands_help_imports_no_numpy_or_scipy(command):
    got = probe(command, "--help")
    assert got["code"] == 0 and f"gyrocal {command}" in got["out"]
    assert got["heavy"] == []
    assert got["beyond_parser"] == PARSER_NEEDS.get(command, [])


def test_the_parsers_choices_are_the_configurations():
    """The choices the parser offers without importing the configuration are the ones it
    accepts (one list, :mod:`gyrocal.kit.choices`)."""
    from gyrocal.kit import choices, config

    assert config.METHODS is choices.METHODS and config.PROTOCOLS is choices.PROTOCOLS
    assert config.SCHEMA["protocol"]["method"].choices == choices.METHODS
    assert config.SCHEMA["protocol"]["name"].choices == choices.PROTOCOLS


def test_a_recording_with_a_bad_manifest_is_refused_before_heavy_imports(tmp_path):
    (tmp_path / "manifest.json").write_text('{"format": "something else"}')
    got = probe("estimate", str(tmp_path))
    assert got["code"] == 2 and "'format' must be 'gyrocal-recording'" in got["out"]
    assert got["heavy"] == []


def test_help_lines_read_from_source_are_the_modules_own():
    for _, module_name in cli.COMMANDS:
        assert cli._summary(module_name) == importlib.import_module(module_name).HELP


def test_every_command_is_still_registered_in_full():
    parser = cli.build_parser()
    sub = next(a for a in parser._actions if a.dest == "command")
    assert list(sub.choices) == [name for name, _ in cli.COMMANDS]
    for name, p in sub.choices.items():
        assert callable(p.get_default("_run")), name


STATS_PROBE = (
    "import sys, io, contextlib\n"
    "from gyrocal.kit.cli import main\n"
    "with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):\n"
    "    code = main(sys.argv[1:])\n"
    "print(code, 'scipy.stats' in sys.modules, 'scipy.optimize' in sys.modules)\n"
)


def test_analysis_commands_do_not_import_scipy_stats(tmp_path):
    """Only the chi-square tail is needed, which scipy.special has (issue 16: scipy.stats costs
    seconds to import on a Pi); estimate's default method does not import scipy.optimize."""
    rec = tmp_path / "rec"
    from gyrocal.kit.cli import main

    assert main(["simulate-recording", str(rec), "--turns", "1", "--rest", "2"]) == 0
    for argv in (["estimate", str(rec)], ["noise", str(rec), "--span", "all", "--min-tau",
                                            "0.005"], ["track", str(rec), "--every", "1"]):
        out = subprocess.run([sys.executable, "-c", STATS_PROBE, *argv], capture_output=True,
                             text=True, timeout=120, check=True)
        code, stats, optimize = out.stdout.split()
        assert stats == "False", (argv, out.stdout)
        if argv[0] == "estimate":  # the default method needs no optimiser
            assert optimize == "False", out.stdout
        assert code in ("0", "2"), (argv, out.stdout)


def test_the_emulated_jig_and_the_windows_import_no_scipy():
    """Issue 25: ``calib.windows`` (drift correction, from ``calib.thermal``) and the emulated
    jig need no scipy; ``calib.thermal`` imported ``scipy.special`` (which pulls ``numpy.f2py``,
    about 0.3 s) at import for its χ² tail only. The fit imports it where it is used."""
    code = ("import sys, gyrocal.kit.sim, gyrocal.calib.windows, gyrocal.calib.thermal\n"
            "print(sorted(m for m in sys.modules if m.split('.')[0] == 'scipy')[:3])")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=120, check=True)
    assert out.stdout.strip() == "[]"


@pytest.mark.parametrize(("given", "used"), [(None, "1"), ("2", "2")])
def test_the_command_line_gives_numpy_one_blas_thread_unless_told(given, used):
    """The kit's matrices are small: OpenBLAS's thread per core spins more than it helps (a
    full-matrix fit's batched pinv took 40-146 ms of CPU with two threads on a loaded two-core
    host, 1.5 ms with one). The CLI sets one thread before numpy loads; a caller's setting
    stands."""
    import os

    env = {k: v for k, v in os.environ.items()
           if k not in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")}
    if given is not None:
        env["OPENBLAS_NUM_THREADS"] = given
    code = ("import os, sys, gyrocal.kit.cli\n"
            "assert 'numpy' not in sys.modules\n"
            "print(os.environ['OPENBLAS_NUM_THREADS'])")
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True,
                         check=True).stdout.strip()
    assert out == used
