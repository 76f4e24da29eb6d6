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

* the outside audit's attacks (issue 27, :mod:`bench.attacks`): ``--force`` over user files,
  ``verify``'s reference and readers, units and axes, mathtext, terminal escapes and C comments,
  stdin bombs, a TOML key's depth, huge integers and deep nesting, a damaged history, a servo
  adapter pulled mid-turn; one case per cause, tallied as the audit's table.

Usage: ``python -m bench faults [--quick] [--signals] [--attacks] [--hogs=N] [--kill9=N]``
(``--quick``: 12 signal cases, 40 inputs each, 3 kills; ``--signals``: the signal cases only;
``--attacks``: the audit's attacks only; ``--hogs=N``: N
CPU-bound processes run beside the signal cases, the loaded host on which aborts once left
torque on; ``--kill9=N``: N SIGKILLs mid-motion, default 20).
"""

from __future__ import annotations

import json
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


def kill9_matrix(runs: int) -> tuple[Counter, list[float]]:
    """SIGKILL mid-motion, ``runs`` times at moments spread over the run: nothing of the kit
    runs, so only the servos themselves can stop: at the end of the commanded turn (a turn is
    an extended-position move, gimbal module docstring) or when their Bus Watchdog (armed
    before the first motion) trips, whichever comes first.

    Each kill lands on the K-th packet after a servo started turning with its watchdog armed
    (K = 1, 8, 15, ...), while one turns. A case passes when every servo that was turning
    reaches Present Velocity 0 and its watchdog has tripped within 1 s of its period; the
    seconds from the kill to the last servo's stop are returned for the passing cases (watched
    in the emulator every 50 ms, so the figure is good to about that).
    """
    tally: Counter = Counter()
    stops: list[float] = []
    rig = ServoRig(ids=(1, 2, 3))
    tmp = Path(tempfile.mkdtemp(prefix="gyrocal-kill9-"))
    # the loaded-host knobs of tests/kit/test_signals.py (more resends, the longest watchdog):
    # a starved emulator must not end the run with exit 4 before the kill; the stop measured
    # is then the 2.5 s watchdog's, an upper bound of the default 0.3 s one's
    cfg = write_config(tmp / "gyrocal.toml", rig.path, ids=rig.ids, retries=30, watchdog_s=2.5)
    try:
        for n in range(runs):
            o = rig.run(cfg, tmp / f"run{n}", [(1 + 7 * n, signal.SIGKILL, 0.0)],
                        from_motion=True)
            tally["runs"] += 1
            if not o.fired:
                tally[f"ended before the kill, exit {o.returncode}"] += 1
                continue
            t0 = time.monotonic()
            turning = [i for i, v in o.at_fire["Present Velocity"].items() if v != 0]
            if not turning:  # a turn ended between the last packet and the kill
                tally["killed just after a turn"] += 1
                continue
            tally["killed mid-motion"] += 1
            tally["turning servo unwatched"] += not all(o.at_fire["Bus Watchdog"][i] > 0
                                                        for i in turning)
            ids = tuple(turning)
            got = rig.wait_for("Present Velocity",
                               lambda v, ids=ids: all(v[i] == 0 for i in ids), within_s=20.0)
            stopped = all(got[i] == 0 for i in turning)
            tripped = rig.wait_for("Bus Watchdog",
                                   lambda v, ids=ids: all(v[i] == -1 for i in ids),
                                   within_s=max(0.0, 2.5 + 1.0 - (time.monotonic() - t0)))
            tally["kept turning"] += not stopped
            tally["watchdog tripped"] += stopped and all(tripped[i] == -1 for i in turning)
            if stopped:
                stops.append(time.monotonic() - t0)
    finally:
        rig.close()
    return tally, stops


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


#: What :func:`fullmodel_matrix` tallies beside each run's verdict: a finished fit that fell
#: back to less than asked and said so on stderr (counted, not a run of its own).
DECLARED = ("diagonal fallback", "accelerometer left out")


def fullmodel_matrix(n: int, tmp: Path) -> Counter:
    """Damaged copies of a full-model recording with the accelerometer's columns and tour.

    The recording is the independent generator's (tests/kit/contract_fullmodel_recording.py:
    scipy rotations, a skewed gimbal, 60° poses, an accelerometer read through a known lower-
    triangular A and bias). A finished ``estimate --json`` is judged against that truth: a
    calibration that says it is consistent while its gyro matrix, bias, or accelerometer is
    more than 6 of its own σ from the truth is a silent wrong calibration. A diagonal fallback
    (cross-axis NOT calibrated, said on stderr) or an accelerometer left out are declared
    outcomes, not silent ones.
    """
    from tests.calib.fullmodel_truth import truth_in_frame
    from tests.kit.contract_fullmodel_recording import draw_accel, write_recording
    from tests.kit.test_fuzz import FILES

    acc_truth = draw_accel(3)
    truth = write_recording(tmp / "fm-good", seed=3, accel_truth=acc_truth, turns=1)
    sensing = np.diag(1 / truth["scale"]) @ truth["misalignment"]
    A_true = truth_in_frame(sensing)
    low = np.tril_indices(3)
    def judge(d: Path) -> str:
        outcome, code, out, _ = run_command(["estimate", str(d), "--json"], timeout_s=60)
        if outcome != "finished":
            return outcome
        cal = json.loads(out)
        if code == 3 or not cal["consistency"]["ok"]:
            return "ok"  # an inconsistent fit, said so
        bias_z = (np.array(cal["bias"]) - truth["bias"]) / np.array(cal["bias_std"])
        if cal.get("method") != "full-matrix":  # the diagonal model: only the bias compares
            tally["diagonal fallback"] += 1
            z = [bias_z]
        else:
            z = [((np.array(cal["matrix"]) - A_true)[low]
                  / np.array(cal["matrix_std"], dtype=float)[low]), bias_z]
        acc = cal.get("accelerometer")
        if acc is None:
            tally["accelerometer left out"] += 1
        elif acc["consistency"]["ok"]:
            z += [(np.array(acc["matrix"]) - acc_truth["matrix"])[low]
                  / np.array(acc["matrix_std"], dtype=float)[low],
                  (np.array(acc["bias"]) - acc_truth["bias"]) / np.array(acc["bias_std"])]
        return "ok" if np.all(np.abs(np.concatenate(z)) < 6) else "silent-wrong"

    tally: Counter = Counter()
    if judge(tmp / "fm-good") != "ok" or tally:  # the judge itself, on the undamaged recording
        raise RuntimeError(f"the undamaged full-model recording judged wrong: {dict(tally)}")
    rng = np.random.default_rng(2020)
    for k in range(n):
        d = copy_tree(tmp / "fm-good", tmp / f"fm{k}")
        name = FILES[k % len(FILES)]
        (d / name).write_bytes(damage((d / name).read_bytes(), rng)[1])
        tally[judge(d)] += 1
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


def print_attacks() -> None:
    """The audit's attacks (:mod:`bench.attacks`): the table per area, then every case."""
    from bench.attacks import OUTCOMES, attack_matrix

    t = time.perf_counter()
    rows, results = attack_matrix()
    print("\nthe audit's attacks (issue 27), one case per cause; each gyrocal run in a "
          f"subprocess ({time.perf_counter() - t:.0f} s):")
    print_table(["area", "cases", *OUTCOMES, "other"], rows)
    print_table(["area", "case", "expect", "outcome", "exit", "s", "last line of stderr"],
                [[r.case.area, r.case.name, r.case.expect, r.outcome, str(r.code),
                  f"{r.seconds:.1f}", r.last] for r in results])


def main(argv: list[str]) -> None:
    if "--attacks" in argv:
        print_attacks()
        return
    quick = "--quick" in argv
    hogs = next((int(a.split("=", 1)[1]) for a in argv if a.startswith("--hogs=")), 0)
    n = 40 if quick else 200
    tmp = Path(tempfile.mkdtemp(prefix="gyrocal-fuzz-"))
    rows = []
    inputs = (("damaged recordings (estimate)", lambda: recording_matrix(n, tmp)),
              ("damaged full-model recordings with accelerometer (estimate)",
               lambda: fullmodel_matrix(n // 2, tmp)),
              ("damaged configs (load_config)", lambda: config_matrix(2 * n, tmp)),
              ("damaged calibrations (export)", lambda: calibration_matrix(n, tmp)))
    if "--signals" not in argv:
        print_attacks()
    for name, fn in inputs if "--signals" not in argv else ():
        t = time.perf_counter()
        c = fn()
        runs = sum(v for k, v in c.items() if k not in DECLARED)
        declared = ", ".join(f"{k} {c[k]}" for k in DECLARED if c[k]) or "-"
        rows.append([name, runs, c["ok"] + c["finished"], c["refused"],
                     c["silent-wrong"], c["traceback"], c["hang"], declared,
                     f"{time.perf_counter() - t:.0f}"])
    if rows:
        print_table(["inputs", "runs", "ok", "refused", "silent wrong", "traceback", "hang",
                     "declared fallbacks", "s"], rows)
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
    kills = next((int(a.split("=", 1)[1]) for a in argv if a.startswith("--kill9=")),
                 3 if quick else 20)
    t = time.perf_counter()
    k9, stops = kill9_matrix(kills)
    print("\nkill -9 mid-motion (no handler runs; the servos' Bus Watchdog must stop them):")
    keys = ["runs", "killed mid-motion", "turning servo unwatched", "watchdog tripped",
            "kept turning"]
    print_table(keys + ["stop s median", "stop s max", "s"],
                [[k9[k] for k in keys]
                 + [float(np.median(stops)) if stops else float("nan"),
                    max(stops) if stops else float("nan"), f"{time.perf_counter() - t:.0f}"]])
    other = sorted(k for k in k9 if k.startswith(("ended before", "killed just")))
    if other:
        print_table(["other outcomes", "count"], [[k, k9[k]] for k in other])
    if bad:
        print_table(["case", "exit", "torque read back", "flags", "last line of stderr"], bad)
