"""Fault matrix: signals at every phase of a run, and damaged inputs, tallied by outcome.

Targets (issue 17): aborts with torque left on 0 (of >= 100); tracebacks 0; hangs 0; silent wrong
calibrations 0.

* signals: ``gyrocal calibrate --sim-imu`` against emulated servos on a PTY
  (:mod:`bench.signal_rig`); SIGINT, SIGTERM and SIGHUP land on instruction packet K (inside
  ``Gimbal.open`` for small K, in a rest or a turn later), alone or followed by a second signal
  one packet later (inside the stop); torque is read back through dynamixel-sdk.
* damaged recordings: the independent generator's recording (tests/kit/contract_recording.py)
  with one file damaged (:mod:`bench.fuzz_inputs`), then ``gyrocal estimate --json``.
* damaged configs: ``load_config`` on a damaged ``gyrocal init`` template.
* damaged calibrations: ``gyrocal export --format json|yaml`` on a damaged Calibration document.

Usage: ``python -m bench faults [--quick] [--signals] [--hogs=N]`` (``--quick``: 12 signal
cases, 40 inputs each; ``--signals``: the signal cases only; ``--hogs=N``: N CPU-bound processes
run beside the signal cases, the loaded host on which aborts once left torque on).
"""

from __future__ import annotations

import multiprocessing as mp
import os
import signal
import tempfile
import time
from collections import Counter
from pathlib import Path

import numpy as np

from bench.bench_servo_link import _burn
from bench.fuzz_inputs import copy_tree, damage, run_command
from bench.signal_rig import SIGNALS, ServoRig, write_config
from bench.table import print_table

MOMENTS = (1, 2, 3, 5, 8, 12, 16, 20, 25, 30, 40, 55, 80, 120, 200, 350, 600, 900, 1200)


def signal_matrix(quick: bool, bad: list[list[str]] | None = None) -> Counter:
    """Tally of the signal cases; the cases that did not end cleanly are appended to ``bad``.

    A servo that reads torque on after the run counts as "torque left on" (the kit's fault); a
    servo that did not answer the read-back at all counts as "servo did not answer" (the
    emulated servo, starved of CPU, not the kit: it is not evidence either way).
    """
    tally: Counter = Counter()
    bad = [] if bad is None else bad
    rig = ServoRig(ids=(1, 2, 3))
    tmp = Path(tempfile.mkdtemp(prefix="gyrocal-faults-"))
    cfg = write_config(tmp / "gyrocal.toml", rig.path, ids=rig.ids)
    cases = [(sig, k, second) for k in MOMENTS for sig in SIGNALS
             for second in (None, signal.SIGINT if sig != signal.SIGINT else signal.SIGTERM)]
    if quick:
        cases = cases[::9]
    try:
        for n, (sig, k, second) in enumerate(cases):
            plan = [(k, sig, 0.0)] + ([(k + 1, second, 0.0)] if second else [])
            o = rig.run(cfg, tmp / f"run{n}", plan)
            tally["cases"] += 1
            name = (f"{signal.Signals(sig).name}@{k}"
                    + (f"+{signal.Signals(second).name}" if second else ""))
            last = (o.stderr.strip().splitlines()[-1:] or [""])[0][:90]
            if not o.fired:  # the run ended before packet K: finished, or failed on its own
                tally[f"ended before the signal, exit {o.returncode}"] += 1
                if o.returncode != 0:  # a failure must leave torque off as well
                    tally["failed on its own, torque left on"] += o.torque_left_on
                    bad.append([name, str(o.returncode), str(o.torque), "before the signal",
                                last])
                continue
            tally["aborts"] += 1
            flags = {"torque left on": o.torque_left_on,
                     "servo did not answer": o.torque_unknown,
                     "hang": o.returncode is None,
                     "traceback": "Traceback" in o.stderr,
                     "no message": "servos stopped, torque off" not in o.stderr}
            for key, hit in flags.items():
                tally[key] += hit
            if o.returncode not in (None, 128 + sig):
                tally[f"other exit: {o.returncode}"] += 1
            if any(flags.values()) or o.returncode not in (None, 128 + sig):
                bad.append([name, str(o.returncode), str(o.torque),
                            ", ".join(f for f, hit in flags.items() if hit), last])
    finally:
        rig.close()
    return tally


def recording_matrix(n: int, tmp: Path) -> Counter:
    from tests.kit.contract_recording import write_recording
    from tests.kit.test_fuzz import FILES, judge_estimate

    good = write_recording(tmp / "good", odr=100.0, turns=1)
    rng = np.random.default_rng(2017)
    tally: Counter = Counter()
    for k in range(n):
        d = copy_tree(good, tmp / f"r{k}")
        name = FILES[k % len(FILES)]
        _, data = damage((d / name).read_bytes(), rng)
        (d / name).write_bytes(data)
        outcome, code, out, _ = run_command(["estimate", str(d), "--json"], timeout_s=30)
        tally[judge_estimate(outcome, code, out)] += 1
    return tally


def config_matrix(n: int, tmp: Path) -> Counter:
    from gyrocal.kit.config import load_config, template
    from gyrocal.kit.errors import InputError

    rng = np.random.default_rng(2018)
    tally: Counter = Counter()
    for k in range(n):
        p = tmp / f"c{k}.toml"
        p.write_bytes(damage(template().encode(), rng)[1])
        try:
            load_config(p)
            tally["ok"] += 1
        except InputError:
            tally["refused"] += 1
        except Exception:
            tally["traceback"] += 1
    return tally


def calibration_matrix(n: int, tmp: Path) -> Counter:
    from tests.kit.contract_recording import write_recording

    rec = write_recording(tmp / "calrec", odr=100.0, turns=1)
    cal = tmp / "cal.json"
    run_command(["estimate", str(rec), "--out", str(cal)])
    text = cal.read_bytes()
    rng = np.random.default_rng(2019)
    tally: Counter = Counter()
    for k in range(n):
        p = tmp / f"cal{k}.json"
        p.write_bytes(damage(text, rng)[1])
        fmt = ("json", "yaml")[k % 2]
        outcome, _, _, _ = run_command(["export", str(p), "--format", fmt])
        tally[outcome] += 1
    return tally


def main(argv: list[str]) -> None:
    quick = "--quick" in argv
    hogs = next((int(a.split("=", 1)[1]) for a in argv if a.startswith("--hogs=")), 0)
    n = 40 if quick else 200
    tmp = Path(tempfile.mkdtemp(prefix="gyrocal-fuzz-"))
    rows = []
    inputs = (("damaged recordings (estimate)", lambda: recording_matrix(n, tmp)),
              ("damaged configs (load_config)", lambda: config_matrix(2 * n, tmp)),
              ("damaged calibrations (export)", lambda: calibration_matrix(n, tmp)))
    for name, fn in inputs if "--signals" not in argv else ():
        t = time.perf_counter()
        c = fn()
        rows.append([name, sum(c.values()), c["ok"] + c["finished"], c["refused"],
                     c["silent-wrong"], c["traceback"], c["hang"],
                     f"{time.perf_counter() - t:.0f}"])
    if rows:
        print_table(["inputs", "runs", "ok", "refused", "silent wrong", "traceback", "hang",
                     "s"], rows)
    t = time.perf_counter()
    stop = mp.Event()
    procs = [mp.Process(target=_burn, args=(stop, os.getpriority(os.PRIO_PROCESS, 0)),
                        daemon=True) for _ in range(hogs)]
    for p in procs:
        p.start()
    load = os.getloadavg()[0]
    bad: list[list[str]] = []
    try:
        s = signal_matrix(quick, bad)
    finally:
        stop.set()
        for p in procs:
            p.join(timeout=5)
    print(f"\nsignals ({hogs} CPU hogs beside): host load average {load:.1f} at the start, "
          f"{os.getloadavg()[0]:.1f} at the end ({os.cpu_count()} CPUs)")
    keys = ["cases", "aborts", "torque left on", "servo did not answer", "no message",
            "traceback", "hang"]
    print_table(keys + ["s"], [[s[k] for k in keys] + [f"{time.perf_counter() - t:.0f}"]])
    other = sorted(k for k in s if k.startswith(("ended before", "other exit", "failed on")))
    print_table(["other outcomes", "count"], [[k, s[k]] for k in other])
    if bad:
        print_table(["case", "exit", "torque read back", "flags", "last line of stderr"], bad)
