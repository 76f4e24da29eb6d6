"""CPU time of one emulated calibration, and where it goes (the emulators' share).

``python -m bench sim`` runs ``gyrocal calibrate --sim --sim-seed 3 --quiet --no-report`` (the full
protocol, every realism effect) in a fresh interpreter and prints its CPU seconds (process time,
so a loaded machine changes it little), with the CPU spent inside the emulated IMU chip's sample
generation (``_sync``: the jig's true rate at the sub-sample times, its specific force, the
coloured noise, the DLPF) and inside the gimbal driver's sync reads of the emulated servos.

``--ref=DIR`` also runs the same command on another checkout of the repository (for example
``git worktree add /tmp/before <commit>``), in the same session, and says whether the two
recordings are byte-identical (the emulators must record the same run for the same seed however
fast they are). ``--seed=S`` changes the seed.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

from bench.table import print_table

ROOT = Path(__file__).resolve().parents[1]

#: Runs in the child: time the parts with process time, run the command, print JSON.
_CHILD = r"""
import collections, functools, json, sys, time
import gyrocal.drivers.emulated.imu_chips as ic
import gyrocal.drivers.emulated.noise as noise
import gyrocal.drivers.dynamixel.gimbal as gim
from gyrocal.kit.cli import main

cpu = collections.Counter()

def timed(cls, name, label):
    f = getattr(cls, name)
    depth = [0]
    @functools.wraps(f)
    def g(*a, **k):
        if depth[0]:
            return f(*a, **k)
        depth[0] += 1
        t = time.process_time()
        try:
            return f(*a, **k)
        finally:
            cpu[label] += time.process_time() - t
            depth[0] -= 1
    setattr(cls, name, g)

timed(ic._EmulatedImu, "_sync", "chip")
timed(ic._EmulatedImu, "_internal_rates", "rates")
timed(ic._EmulatedImu, "_specific_force", "force")
timed(noise.ColouredNoise, "draw", "coloured")
timed(gim.Gimbal, "sample", "servos")
t0 = time.process_time()
code = main(sys.argv[1:])
cpu["total"] = time.process_time() - t0
print(json.dumps({"code": code, **cpu}))
"""


def _run(checkout: Path, out: Path, seed: int) -> dict:
    """Run the calibration with ``gyrocal`` imported from ``checkout``."""
    shim = out.parent / f"shim-{out.name}" / "gyrocal"
    shim.mkdir(parents=True)
    (shim / "__init__.py").write_text(f"__path__ = [{str(checkout)!r}]\n")
    env = {**os.environ, "PYTHONPATH": str(shim.parent)}
    done = subprocess.run(
        [sys.executable, "-c", _CHILD, "calibrate", "--sim", "--sim-seed", str(seed), "--out",
         str(out), "--quiet", "--no-report"],
        env=env, capture_output=True, text=True, check=False)
    lines = [x for x in done.stdout.splitlines() if x.startswith("{")]
    if not lines:
        raise RuntimeError(f"{checkout}: the run printed no result\n{done.stderr[-2000:]}")
    return json.loads(lines[-1])


def main(argv: list[str]) -> None:
    opts = dict(a.lstrip("-").split("=", 1) for a in argv if "=" in a)
    seed = int(opts.get("seed", 3))
    checkouts = [("this checkout", ROOT)]
    if "ref" in opts:
        checkouts.append((f"--ref {opts['ref']}", Path(opts["ref"]).resolve()))
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        runs = []
        for name, path in checkouts:
            out = Path(tmp) / f"run{len(runs)}"
            r = _run(path, out, seed)
            runs.append(out)
            same = "—" if len(runs) == 1 else (
                "yes" if all((runs[0] / "recording" / f).read_bytes()
                             == (out / "recording" / f).read_bytes()
                             for f in ("imu.csv", "encoder.csv", "segments.csv")) else "NO")
            rows.append([name, r["code"], r["total"], r.get("chip", 0.0), r.get("rates", 0.0),
                         r.get("force", 0.0), r.get("coloured", 0.0), r.get("servos", 0.0), same])
    print_table(["code", "exit", "CPU s", "IMU chip", "  true rates", "  specific force",
                 "  coloured noise", "servo reads", "same recording"], rows,
                title=f"gyrocal calibrate --sim --sim-seed {seed} --quiet --no-report: CPU "
                      "seconds (process time) in all and in the emulators' parts")
