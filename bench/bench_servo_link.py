"""The servo link under host load: runs completed, worst poll interval, Bus Watchdog margin.

Each run is ``gyrocal calibrate --sim-imu`` (the kit's real servo path, wall clock) against
emulated servos on a pseudo-terminal (:mod:`bench.signal_rig`); the run's manifest records the
longest gap between two gimbal polls while a servo moved (``protocol.worst_poll_interval_s``)
and the Bus Watchdog armed during motion (``protocol.bus_watchdog_s``, 100 ms). A gap longer
than the watchdog stops the servo (exit 4). Loads: idle, and two CPU-bound processes beside it.

Usage: ``python -m bench servo_link [--runs=N]`` (default 20 per load).
"""

from __future__ import annotations

import json
import multiprocessing as mp
import tempfile
import time
from pathlib import Path

from bench.signal_rig import ServoRig, write_config
from bench.table import print_table


def _burn(stop) -> None:  # a CPU-bound process
    x = 0
    while not stop.is_set():
        for _ in range(100_000):
            x += 1


def main(argv: list[str]) -> None:
    runs = 20
    for a in argv:
        if a.startswith("--runs="):
            runs = int(a.split("=", 1)[1])
    rows = []
    for hogs in (0, 2):
        stop = mp.Event()
        procs = [mp.Process(target=_burn, args=(stop,), daemon=True) for _ in range(hogs)]
        for p in procs:
            p.start()
        rig = ServoRig(ids=(1, 2))
        tmp = Path(tempfile.mkdtemp(prefix="gyrocal-link-"))
        cfg = write_config(tmp / "gyrocal.toml", rig.path, ids=rig.ids)
        done, codes, worst, watchdog = 0, {}, [], 0.0
        t = time.perf_counter()
        try:
            for k in range(runs):
                o = rig.run(cfg, tmp / f"run{k}", [], timeout_s=120)
                codes[o.returncode] = codes.get(o.returncode, 0) + 1
                done += o.returncode == 0
                m = tmp / f"run{k}" / "recording" / "manifest.json"
                if m.exists():
                    proto = json.loads(m.read_text())["protocol"]
                    if "worst_poll_interval_s" in proto:
                        worst.append(proto["worst_poll_interval_s"])
                        watchdog = proto["bus_watchdog_s"]
        finally:
            stop.set()
            for p in procs:
                p.join(timeout=5)
            rig.close()
        w = max(worst) if worst else float("nan")
        rows.append([f"{hogs} CPU hogs", f"{done}/{runs}",
                     ", ".join(f"{c}: {n}" for c, n in sorted(codes.items(), key=str)),
                     f"{w * 1e3:.0f}", f"{watchdog * 1e3:.0f}",
                     f"{(watchdog - w) * 1e3:.0f}", f"{time.perf_counter() - t:.0f}"])
    print_table(["load", "completed", "exit codes", "worst poll ms", "watchdog ms",
                 "margin ms", "s"], rows)
