"""The servo link under host load: runs completed, worst poll interval, Bus Watchdog margin.

Each run is ``gyrocal calibrate --sim-imu`` (the kit's real servo path, wall clock) against
emulated servos on a pseudo-terminal (:mod:`bench.signal_rig`). Two worst gaps are reported:

* ``kit poll``: the run's manifest, ``protocol.worst_poll_interval_s``, the longest time the
  kit measured between two polls while a servo moved (written at a clean finish only);
* ``servo gap``: what the servos saw, the longest time between two instruction packets
  arriving while a Bus Watchdog was armed (every run, also failed ones). This is what the
  watchdog measures: a gap longer than it stops the servo (exit 4).

Loads: none of ours (the host's own load average is printed), and two CPU-bound processes
beside it. The emulated servos serve from this process at 10 nice levels above the kit and the
hogs (when allowed): a real servo answers from its own MCU, so only the kit's lateness may fail a
run (without the head start, a starved emulator missed the SDK's reply timeout: exit 4, "There is
no status packet!"). Repeats of disturbed turns are counted from the manifests'
``protocol.discarded``.

Usage: ``python -m bench servo_link [--runs=N] [--watchdog=S]`` (default 20 per load, the
configured default watchdog).
"""

from __future__ import annotations

import json
import multiprocessing as mp
import os
import tempfile
import time
from pathlib import Path

import numpy as np

from bench.signal_rig import ServoRig, write_config
from bench.table import print_table


def _burn(stop, niceness: int) -> None:  # a CPU-bound process, at the kit's niceness
    os.setpriority(os.PRIO_PROCESS, 0, niceness)
    x = 0
    while not stop.is_set():
        for _ in range(100_000):
            x += 1


def main(argv: list[str]) -> None:
    runs, watchdog_s = 20, None
    for a in argv:
        if a.startswith("--runs="):
            runs = int(a.split("=", 1)[1])
        elif a.startswith("--watchdog="):
            watchdog_s = float(a.split("=", 1)[1])
    base = os.getpriority(os.PRIO_PROCESS, 0)
    try:  # needs the privilege to lower niceness; without it the servos share the host's lot
        os.setpriority(os.PRIO_PROCESS, 0, base - 10)
        head_start = 10
    except PermissionError:
        head_start = 0
        print("note: cannot raise the emulated servos' priority; their lateness under load "
              "counts against the kit")
    rows: list[list[str]] = []
    failures: list[list[str]] = []
    for hogs in (0, 2):
        stop = mp.Event()
        procs = [mp.Process(target=_burn, args=(stop, base), daemon=True) for _ in range(hogs)]
        for p in procs:
            p.start()
        # The emulated servos serve from this process; a real servo has its own MCU, which
        # host load cannot starve. Give the servos' process a head start of 10 nice levels
        # over the kit and the hogs (which share the default), so that a run fails only for
        # the kit's own lateness, not because the emulated servo answered late.
        rig = ServoRig(ids=(1, 2), kit_niceness=head_start)
        tmp = Path(tempfile.mkdtemp(prefix="gyrocal-link-"))
        cfg = write_config(tmp / "gyrocal.toml", rig.path, ids=rig.ids)
        if watchdog_s is not None:
            cfg.write_text(cfg.read_text().replace(
                "[protocol]", f"watchdog_s = {watchdog_s}\n[protocol]"), encoding="utf-8")
        done, codes, worst, servo_gaps, watchdog, repeats = 0, {}, [], [], 0.0, 0
        load = os.getloadavg()[0]
        t = time.perf_counter()
        try:
            for k in range(runs):
                o = rig.run(cfg, tmp / f"run{k}", [], timeout_s=120)
                codes[o.returncode] = codes.get(o.returncode, 0) + 1
                done += o.returncode == 0
                if o.returncode != 0:  # what stopped it, for the table below
                    why = [ln for ln in o.stderr.splitlines() if "error" in ln][-1:]
                    failures.append([f"{hogs} CPU hogs", str(o.returncode),
                                     (why[0] if why else o.stderr[-200:])[:160]])
                servo_gaps.append(o.armed_gap_s)
                m = tmp / f"run{k}" / "recording" / "manifest.json"
                if m.exists():
                    proto = json.loads(m.read_text())["protocol"]
                    repeats += sum(d.get("disturbed", False) for d in proto.get("discarded", []))
                    if "worst_poll_interval_s" in proto:
                        worst.append(proto["worst_poll_interval_s"])
                        watchdog = proto["bus_watchdog_s"]
        finally:
            stop.set()
            for p in procs:
                p.join(timeout=5)
            rig.close()
        w = max(worst) if worst else float("nan")
        g = max(servo_gaps) if servo_gaps else float("nan")
        rows.append([f"{hogs} CPU hogs", f"{load:.1f}", f"{done}/{runs}",
                     ", ".join(f"{c}: {n}" for c, n in sorted(codes.items(), key=str)),
                     str(repeats), f"{w * 1e3:.0f}", f"{g * 1e3:.0f}",
                     f"{np.median(servo_gaps) * 1e3:.0f}" if servo_gaps else "nan",
                     f"{watchdog * 1e3:.0f}", f"{(watchdog - g) * 1e3:.0f}",
                     f"{time.perf_counter() - t:.0f}"])
    print_table(["load", "loadavg", "completed", "exit codes", "repeats", "kit poll ms",
                 "servo gap ms", "median run's ms", "watchdog ms", "margin ms", "s"], rows)
    if failures:
        print()
        print_table(["load", "exit", "message"], failures)
