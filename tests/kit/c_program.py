"""Compiling the exported C header with a small program, as a firmware build would: the one
place the export tests hold gcc's strict flags."""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import pytest

#: The warnings a careful firmware build turns into errors.
FLAGS = ["-std=c99", "-Wall", "-Wextra", "-pedantic", "-Werror", "-Wdouble-promotion",
         "-Wconversion", "-Wshadow"]

needs_gcc = pytest.mark.skipif(shutil.which("gcc") is None, reason="gcc is not installed: cannot "
                               "compile the exported C header (install gcc to run this test)")


def compile_program(tmp_path: Path, header: str, program: str) -> Path:
    """Write ``header`` as ``cal.h`` and ``program`` as ``main.c`` in ``tmp_path``, compile them
    with :data:`FLAGS`, and return the executable (``tmp_path / "apply"``)."""
    (tmp_path / "cal.h").write_text(header)
    (tmp_path / "main.c").write_text(program)
    cc = subprocess.run(["gcc", *FLAGS, "-o", "apply", "main.c"], capture_output=True,
                        text=True, cwd=tmp_path)
    assert cc.returncode == 0, cc.stderr
    return tmp_path / "apply"
