"""CPU time of one emulated calibration per second of jig time, where it goes, and against the
code before the emulators were made fast (issue 25).

``python -m bench sim`` runs ``gyrocal calibrate --sim --sim-seed 3 --quiet --no-report`` (the
full protocol, every realism effect on) in a fresh interpreter, for this checkout and for the
code before the change (``git archive`` of :data:`BEFORE` from this repository, unpacked in a
temporary directory), one after the other in the same invocation, and prints:

* each run's CPU seconds (process time of the whole command, imports included: a loaded host
  changes it little), the jig time it recorded (the last IMU sample's time) and CPU per jig
  second (the target is 0.2 or less). This is a run of the plain command: timing the parts
  wraps functions called a quarter of a million times (the clock's ``sleep`` most), and the
  wrappers' own cost (two thread-time reads each) added 15–20 % to the whole;
* from a second run of the same command with the parts timed, the CPU of each part (the CPU
  time of the thread it runs in, so the writer's thread is not counted in the loop's parts)
  and its share of that run's CPU (the wrappers' cost falls mostly in the parts they wrap):
  the IMU chip's sample generation (``_sync``; within it
  the true rates at the chip's internal rate, and the DLPF), the IMU reader with the emulated
  I²C bus around it, the servo packets (the real dynamixel-sdk encoding and decoding every
  packet, and the emulated servos), the emulated clock, the recording writer (its own thread,
  thread time), the queue between the loop and the writer, the rest of the protocol loop, the
  plan, the imports, and the rest (fitting, outputs);
* the ratio of the two runs' CPU, and whether the two recordings are byte-identical
  (``imu.csv``, ``encoder.csv``, ``segments.csv``, and ``manifest.json`` less its ``created``
  wall-clock stamp), with each file's SHA-256;
* the CPU of the report's plots (``gyrocal report RECORDING CALIBRATION`` of each run, drawn by
  its own checkout: ``write_report``'s process time, the target is under 5 s) and their ratio.

Options: ``--seed=S``; ``--ref=DIR`` compares with another checkout instead of :data:`BEFORE`;
``--ref-commit=REV`` archives another commit; ``--repeat=N`` runs each N times, alternating,
and keeps each one's least CPU (the host is shared); ``--args="..."`` adds arguments to the
command (e.g. ``--args="--config plate.toml"``); ``--no-plots`` leaves the plots out.
"""

from __future__ import annotations

import hashlib
import json
import os
import shlex
import subprocess
import sys
import tarfile
import tempfile
from io import BytesIO
from pathlib import Path

from bench.table import print_table

ROOT = Path(__file__).resolve().parents[1]
#: The commit before the emulated jig was made fast (issue 25).
BEFORE = "ffa5743"

#: Runs in the child: time the parts with the CPU time of the thread they run in (the loop's, the
#: writer's), the whole with process time; run the command, print JSON. A part's time excludes
#: the parts timed inside it.
_CHILD = r"""
import collections, functools, json, os, sys, threading, time
T0 = time.process_time()
PARTS = os.environ.get("GYROCAL_BENCH_PARTS") == "1"
cpu = collections.Counter()
stack = threading.local()

def timed(obj, name, label, clock=time.thread_time):
    f = getattr(obj, name, None)
    if f is None or not PARTS:
        return
    @functools.wraps(f)
    def g(*a, **k):
        st = getattr(stack, "s", None)
        if st is None:
            st = stack.s = []
        if st and st[-1][0] == label:  # re-entered: counted once
            return f(*a, **k)
        t = clock()
        st.append([label, 0.0])
        try:
            return f(*a, **k)
        finally:
            _, inner = st.pop()
            spent = clock() - t
            cpu[label] += spent - inner
            if st:
                st[-1][1] += spent
    setattr(obj, name, g)

import gyrocal.kit.cli as cli
import gyrocal.kit.sim  # the emulators: imported before the parts are timed
import gyrocal.kit.jig as kj
import gyrocal.kit.protocol as kp
import gyrocal.kit.backlog as kb
import gyrocal.kit.pipeline  # the fit
import gyrocal.drivers.clock as clk
import gyrocal.drivers.emulated.imu_chips as ic
import gyrocal.drivers.dynamixel.gimbal as gim
import gyrocal.drivers.imu.base as ib
cpu["imports"] = time.process_time() - T0
timed(kj, "choose_plan", "plan")
timed(kp.Runner, "run", "loop, other")
timed(ib.ImuReader, "read", "IMU reader and I2C bus")
timed(ic._EmulatedImu, "_sync", "chip samples, other")
timed(ic._EmulatedImu, "_internal_rates", "chip true rates (internal rate)")
timed(ic._EmulatedImu, "_filtered", "chip DLPF")
timed(ic._EmulatedImu, "_lowpass", "chip DLPF")
timed(gim.Gimbal, "sample", "servo packets (dynamixel-sdk + emulated servos)")
timed(clk.VirtualClock, "sleep", "clock")
timed(clk.VirtualClock, "sleep_until", "clock")
timed(kb.Backlog, "_put", "queue to the writer")
timed(kb.Backlog, "_handle", "recording writer (thread)")
timed(kb.Backlog, "_write_samples", "recording writer (thread)")
t = time.process_time()
code = cli.main(sys.argv[1:])
end = time.process_time()
cpu["total"] = end - T0
cpu["rest (fit, outputs)"] = cpu["total"] - sum(v for k, v in cpu.items() if k != "total")
print(json.dumps({"code": code, **cpu}))
"""

#: Runs in the child: ``gyrocal report RECORDING CALIBRATION --out DIR`` (the report a default
#: ``calibrate --sim`` run writes), timing ``write_report`` (every plot, drawn and written) with
#: the process time; prints JSON.
_PLOT_CHILD = r"""
import json, sys, time
T0 = time.process_time()
import gyrocal.kit.cli as cli
import gyrocal.kit.report_plots as rp
cpu = {"plots": 0.0}
draw = rp.write_report
def timed(*a, **k):
    t = time.process_time()
    try:
        return draw(*a, **k)
    finally:
        cpu["plots"] += time.process_time() - t
rp.write_report = timed
code = cli.main(sys.argv[1:])
cpu["report"] = time.process_time() - T0
print(json.dumps({"code": code, **cpu}))
"""

#: The rows of the parts table, in order.
PARTS = ("chip samples, other", "chip true rates (internal rate)", "chip DLPF",
         "IMU reader and I2C bus", "servo packets (dynamixel-sdk + emulated servos)", "clock",
         "recording writer (thread)", "queue to the writer", "loop, other", "plan", "imports",
         "rest (fit, outputs)")
FILES = ("imu.csv", "encoder.csv", "segments.csv", "manifest.json")


def _archive(rev: str, dest: Path) -> Path:
    """Unpack ``git archive REV`` of this repository into ``dest``."""
    data = subprocess.run(["git", "-C", str(ROOT), "archive", rev], capture_output=True,
                          check=True).stdout
    with tarfile.open(fileobj=BytesIO(data)) as tar:
        tar.extractall(dest, filter="data")
    return dest


def _run(checkout: Path, out: Path, seed: int, extra: list[str]) -> dict:
    """Run the calibration with ``gyrocal`` imported from ``checkout``: once plain (its CPU is
    the run's total, its recording in ``out``), once with the parts timed (in ``out/parts``;
    its CPU is ``"parts total"``)."""
    shim = out.parent / f"shim-{out.name}" / "gyrocal"
    shim.mkdir(parents=True)
    (shim / "__init__.py").write_text(f"__path__ = [{str(checkout)!r}]\n")
    plain = _child(shim.parent, out, seed, extra, parts=False)
    r = _child(shim.parent, out / "parts", seed, extra, parts=True)
    r["parts total"] = r["total"]
    r["total"] = plain["total"]
    r["jig_s"] = _jig_seconds(out)
    return r


def _child(shim: Path, out: Path, seed: int, extra: list[str], *, parts: bool) -> dict:
    env = {**os.environ, "PYTHONPATH": str(shim), "GYROCAL_BENCH_PARTS": "1" if parts else "0"}
    done = subprocess.run(
        [sys.executable, "-c", _CHILD, "calibrate", "--sim", "--sim-seed", str(seed), "--out",
         str(out), "--quiet", "--no-report", *extra],
        env=env, capture_output=True, text=True, check=False, cwd=shim.parent)
    lines = [x for x in done.stdout.splitlines() if x.startswith("{")]
    if not lines:
        raise RuntimeError(f"{shim}: the run printed no result\n{done.stderr[-2000:]}")
    return json.loads(lines[-1])


def _plots(out: Path, k: int) -> dict:
    """Time the report's plots of the run in ``out`` with the checkout its shim imports, into
    ``out/plots-k``."""
    env = {**os.environ, "PYTHONPATH": str(out.parent / f"shim-{out.name}")}
    done = subprocess.run(
        [sys.executable, "-c", _PLOT_CHILD, "report", str(out / "recording"),
         str(out / "calibration.json"), "--out", str(out / f"plots-{k}")],
        env=env, capture_output=True, text=True, check=False, cwd=out.parent)
    lines = [x for x in done.stdout.splitlines() if x.startswith("{")]
    if not lines:
        raise RuntimeError(f"{out}: the report printed no result\n{done.stderr[-2000:]}")
    return json.loads(lines[-1])


def _recordings(out: Path) -> list[Path]:
    """The plain run's recordings in ``out`` (not the parts-timed run's, in ``out/parts``)."""
    return sorted(p.parent for p in out.rglob("manifest.json")
                  if (p.parent / "imu.csv").exists() and "parts" not in p.relative_to(out).parts)


def _jig_seconds(out: Path) -> float:
    """The recorded jig time: the latest IMU sample's time over the run's recordings."""
    last = 0.0
    for rec in _recordings(out):
        with open(rec / "imu.csv", "rb") as fh:
            fh.seek(max(0, fh.seek(0, 2) - 400))
            row = fh.read().splitlines()[-1].decode()
        last = max(last, float(row.split(",")[0]))
    return last


def _digest(path: Path) -> str:
    """SHA-256 of a recording file; a manifest's without its wall-clock ``created`` stamp."""
    if path.name == "manifest.json":
        m = json.loads(path.read_text())
        m.pop("created", None)
        return hashlib.sha256(json.dumps(m, sort_keys=True).encode()).hexdigest()
    return hashlib.sha256(path.read_bytes()).hexdigest()


def main(argv: list[str]) -> None:
    opts = dict(a.lstrip("-").split("=", 1) for a in argv if "=" in a)
    seed = int(opts.get("seed", 3))
    repeat = max(1, int(opts.get("repeat", 1)))
    extra = shlex.split(opts.get("args", ""))
    with tempfile.TemporaryDirectory() as tmp:
        if "ref" in opts:
            ref, ref_name = Path(opts["ref"]).resolve(), f"--ref {opts['ref']}"
        else:
            rev = opts.get("ref-commit", BEFORE)
            ref, ref_name = _archive(rev, Path(tmp) / "before"), f"before ({rev})"
        checkouts = [("this checkout", ROOT), (ref_name, ref)]
        best: dict[str, dict] = {}
        outs: dict[str, Path] = {}
        for i in range(repeat):
            for j, (name, path) in enumerate(checkouts):
                out = Path(tmp) / f"run-{j}-{i}"
                print(f"running {name} ({i + 1}/{repeat}) ...", file=sys.stderr, flush=True)
                r = _run(path, out, seed, extra)
                if name not in best or r["total"] < best[name]["total"]:
                    best[name], outs[name] = r, out
        names = [n for n, _ in checkouts]
        now, before = best[names[0]], best[names[1]]
        cmd = " ".join(["gyrocal calibrate --sim --sim-seed", str(seed), *extra,
                        "--quiet --no-report"])
        print_table(
            ["code", "exit", "CPU s", "jig s", "CPU per jig s"],
            [[n, best[n]["code"], best[n]["total"], best[n]["jig_s"],
              best[n]["total"] / max(best[n]["jig_s"], 1e-9)] for n in names],
            title=f"{cmd}: CPU seconds (process time, the least of {repeat} run(s) each)")
        print_table(
            ["part", *[f"{n} CPU s" for n in names], *[f"{n} share" for n in names]],
            [[p, *[best[n].get(p, 0.0) for n in names],
              *[f"{100 * best[n].get(p, 0.0) / best[n]['parts total']:.1f} %" for n in names]]
             for p in (*PARTS, "parts total")],
            title="where the CPU goes, in a second run with the parts timed (a part excludes "
                  "the parts inside it; the timing's own cost is in its total)")
        print(f"CPU ratio, {names[1]} / {names[0]}: {before['total'] / now['total']:.2f}")
        rows = []
        recs = [_recordings(outs[n]) for n in names]
        for a, b in zip(*recs, strict=False):
            for f in FILES:
                da, db = _digest(a / f), _digest(b / f)
                rel = a.relative_to(outs[names[0]]) / f
                rows.append([str(rel), da[:16], db[:16], "yes" if da == db else "NO"])
        if len(recs[0]) != len(recs[1]):
            rows.append(["(number of recordings)", len(recs[0]), len(recs[1]), "NO"])
        print()
        print_table(["file", f"{names[0]} sha256", f"{names[1]} sha256", "identical"], rows,
                    title="the recordings, byte for byte (manifest less its `created` stamp)")
        if "no-plots" not in {a.lstrip("-") for a in argv}:
            _plot_table(names, outs, repeat)


def _plot_table(names: list[str], outs: dict[str, Path], repeat: int) -> None:
    """The report's plots of each checkout's run, drawn by that checkout, alternating."""
    best: dict[str, dict] = {}
    for i in range(repeat):
        for name in names:
            print(f"drawing the report of {name} ({i + 1}/{repeat}) ...", file=sys.stderr,
                  flush=True)
            r = _plots(outs[name], i)
            if name not in best or r["plots"] < best[name]["plots"]:
                best[name] = r
    print()
    print_table(
        ["code", "exit", "plots CPU s", "whole command CPU s"],
        [[n, best[n]["code"], best[n]["plots"], best[n]["report"]] for n in names],
        title="gyrocal report RECORDING CALIBRATION of that run: the plots (write_report, "
              f"process time; target < 5 s), the least of {repeat} run(s) each")
    print(f"plot CPU ratio, {names[1]} / {names[0]}: "
          f"{best[names[1]]['plots'] / best[names[0]]['plots']:.2f}")
