"""A reader that closes ``gyrocal``'s standard output early (``gyrocal verify ... | head``).

Python ignores SIGPIPE and raises ``BrokenPipeError`` instead; every command ended with exit 1 and
``gyrocal: error: [Errno 32] Broken pipe`` (or a traceback). Now the command stops quietly with a
shell's exit code for SIGPIPE, 128 + 13 (the Python docs' "Note on SIGPIPE", signal module). The
reader is gone before the command starts (a pipe whose read end is closed), so the first write
fails whatever the pipe's capacity.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys

import pytest

from gyrocal.kit.cli import main


@pytest.fixture(scope="module")
def estimated(tmp_path_factory):
    d = tmp_path_factory.mktemp("pipe")
    assert main(["simulate-recording", str(d / "rec"), "--seed", "3"]) == 0
    assert main(["estimate", str(d / "rec"), "--out", str(d / "calibration.json")]) in (0, 3)
    return d


def _closed_stdout(argv: list[str]) -> subprocess.CompletedProcess:
    read_end, write_end = os.pipe()
    os.close(read_end)
    try:
        return subprocess.run([sys.executable, "-m", "gyrocal.kit", *argv], stdout=write_end,
                              stderr=subprocess.PIPE, text=True, timeout=120)
    finally:
        os.close(write_end)


@pytest.mark.parametrize("command", ["verify", "apply"])
def test_a_closed_stdout_ends_quietly_with_the_sigpipe_code(estimated, command):
    cal, rec = str(estimated / "calibration.json"), str(estimated / "rec")
    argv = {"verify": ["verify", cal, "--recording", rec], "apply": ["apply", cal, rec]}[command]
    r = _closed_stdout(argv)
    assert r.returncode == 128 + signal.SIGPIPE, r.stderr
    assert "Broken pipe" not in r.stderr
    assert "Traceback" not in r.stderr and "Exception ignored" not in r.stderr


def test_a_broken_pipe_elsewhere_is_still_an_error(monkeypatch, capsys):
    """Only standard output's own reader going away is quiet: a BrokenPipeError from another
    pipe, with standard output writable, is reported as before."""
    import gyrocal.kit.commands.init as init

    def broken(args):
        raise BrokenPipeError(32, "Broken pipe")

    monkeypatch.setattr(init, "run", broken)
    assert main(["init", "--help"]) == 0  # parsed: the command module is the one patched
    assert main(["init"]) == 1
    assert "Broken pipe" in capsys.readouterr().err
