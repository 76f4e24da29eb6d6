"""The Recording v1 reader on imu.csv files written by an independent writer (issue 16).

``python -m bench csvstyles`` writes 300 000 IMU rows with Python's own formatting (no gyrocal
code: the contract's columns, fixed ``%.6f`` as many logging tools write, and ``repr``'s 17
significant digits) and reads each with every parser (``GYROCAL_CSV_PARSER``), each in a fresh
process, numpy imported before the clock starts: CPU s per million rows in one run. The decimal
parser takes the fixed-point file itself and hands the ``repr`` one (fields longer than 16
characters) to ``numpy.loadtxt``; the table shows what that fallback costs.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

from bench.table import print_table

ROWS = 300_000
PARSERS = ("numpy", "decimal")
PROBE = ("import sys, time, numpy\nfrom gyrocal.kit.recording import load_recording\n"
         "t0 = time.process_time()\nload_recording(sys.argv[1])\n"
         "print(time.process_time() - t0)\n")


def _write(root: Path, fmt: str, n: int) -> None:
    import numpy as np

    rng = np.random.default_rng(5)
    t = np.cumsum(rng.uniform(0.0009, 0.0011, n))
    rate = rng.normal(scale=[1e-3, 0.05, 2.0], size=(n, 3))
    temp = rng.uniform(20, 40, n)
    root.mkdir()
    (root / "manifest.json").write_text(json.dumps({
        "format": "gyrocal-recording", "version": 1, "created": "2026-01-01T00:00:00+00:00",
        "sensor": {}, "gimbal": {}, "protocol": {}, "complete": True}))
    field = (lambda v: f"{v:.6f}") if fmt == "fixed" else (lambda v: repr(float(v)))
    with open(root / "imu.csv", "w") as fh:
        fh.write("t,gx,gy,gz,temp\n")
        for i in range(n):
            fh.write(",".join(field(v) for v in (t[i], *rate[i], temp[i])) + "\n")
    (root / "encoder.csv").write_text("t,motor,angle\n0.0,1,0.0\n")
    (root / "segments.csv").write_text("index,kind,motor,direction,speed,t_start,t_end\n")


def main(argv: list[str]) -> None:
    """Write the files, read them with each parser, print the table."""
    work = Path(tempfile.mkdtemp(prefix="gyrocal-csvstyles-"))
    try:
        rows = []
        for fmt, label in (("fixed", "fixed %.6f"), ("repr", "repr (17 digits)")):
            root = work / fmt
            _write(root, fmt, ROWS)
            cells = [label]
            for parser in PARSERS:
                out = subprocess.run([sys.executable, "-c", PROBE, str(root)], check=True,
                                     capture_output=True, text=True,
                                     env={**os.environ, "GYROCAL_CSV_PARSER": parser})
                cells.append(f"{float(out.stdout) / ROWS * 1e6:.2f}")
            rows.append(cells)
        print_table(["imu.csv written as", *(f"{p} CPU s / M rows" for p in PARSERS)], rows,
                    f"Reading {ROWS:,} rows written by an independent writer")
    finally:
        shutil.rmtree(work, ignore_errors=True)
