"""Several sensors on one plate (issue 15): the loss-free rate, the CPU per sample, the throughput.

Table 1. N = 1, 2, 4 sensors on **one** emulated 400 kHz I²C bus (an MPU-9250 at 0x68, an
ICM-42688-P at 0x69, LSM6DSOX at 0x6A and 0x6B: every address a plate of these models can use on
one bus), drained by gyrocal's own protocol loop (:class:`gyrocal.kit.protocol.Runner`, at the
default 200 Hz, with the servo sync read every iteration and every row written by a
:class:`gyrocal.kit.plate.RecordingGroup`) through a rest of ``--seconds`` of emulated time, at
rising output data rates. The emulated bus charges each transfer its time on the shared clock
(9 bits per byte at 400 kHz), so the bus, not the host, is the limit. "loss-free" means no FIFO
gap reported and every sensor's recording holding its ODR × duration samples (±1 %). CPU per
sample is the process time (both threads) over the samples recorded: it includes the emulated
chips' and servos' own work, so it bounds the reader's from above; "CPU s per s" is the
process time per second of run (the 200 Hz loop's fixed cost, the servo polls, dominates at
low rates).

Table 1b. The same four sensors on **two** emulated 400 kHz buses (two per bus), at the same
rates: what a second bus buys. The emulated buses charge their transfers to the one shared
clock, as one host thread reading them in turn does (a Linux I²C ``ioctl`` blocks for the
transfer), so the loads of the buses add up in the loop's time: measured, the loss-free rate
is the same as on one bus (1833 samples/s; at 1 kHz the two buses' 82 % + 87 % overflow as one
bus's 169 % does). Only reading the buses from threads of their own would change that. Every
row shows the planned load of :mod:`gyrocal.kit.busload`, which ``gyrocal calibrate`` checks
before a run.

Table 2. Sensors per hour on one jig, N on the plate against one at a time, from the default
(full) protocol's planned jig time, the still-noise measurement (0.5 s per sensor), a fit time
measured here on one emulated recording, and a mounting time per sensor that is an
**assumption** (``--mount-s``, default 15 and 60 s: a board in a quick-release socket, or
unscrew, place, screw and plug one board). The fits
are counted in series after the run (a line could overlap them with the next mounting).

Data: gyrocal's own emulator only (throughput is not an accuracy figure; each sensor's
recording is an ordinary Recording v1, fitted by the same estimator as a one-sensor run).

Usage: ``python -m bench multi [--quick] [--seconds=S] [--mount-s=S[,S...]]``.
"""

from __future__ import annotations

import contextlib
import io
import tempfile
import time
import warnings
from pathlib import Path
from typing import Any

from bench.table import print_table
from gyrocal.drivers.dynamixel import Gimbal
from gyrocal.drivers.imu import open_imu
from gyrocal.kit.busload import REFUSE_LOAD, WARN_LOAD, bus_loads
from gyrocal.kit.config import load_config
from gyrocal.kit.errors import GyrocalError
from gyrocal.kit.plate import RecordingGroup
from gyrocal.kit.protocol import Runner, Step
from gyrocal.kit.recording import RecordingWriter, load_recording
from gyrocal.kit.sim import SIM_BAUD, build_sim_plate

#: The plate's sensors in the order they are added: (name, model, address).
PLATE = (("mpu", "mpu9250", 0x68), ("icm", "icm42688p", 0x69), ("st1", "lsm6dsox", 0x6A),
         ("st2", "lsm6dsox", 0x6B))
#: Output data rates by level, Hz: the rates each model can stream near 200, 500 and 1000 Hz
#: (MPU-9250: 1000/(1 + SMPLRT_DIV); ICM-42688-P: its ODR table; LSM6DSOX over I²C: up to
#: 833 Hz).
LEVELS = {"mpu9250": (200.0, 500.0, 1000.0), "icm42688p": (200.0, 500.0, 1000.0),
          "lsm6dsox": (208.0, 416.0, 833.0)}
RATES_HZ = (200.0, 500.0, 1000.0)  # the level's nominal rate


def _config(n: int, odr_hz: float, tmp: Path, buses: int = 1) -> object:
    level = RATES_HZ.index(odr_hz)
    # with two buses, sensor k goes on bus 1 + k % 2: an InvenSense part and an LSM6DSOX on each
    text = "".join(f'[[imu]]\nname = "{name}"\nmodel = "{model}"\naddress = {addr}\n'
                   f"odr_hz = {LEVELS[model][level]}\nrange_dps = 500\nbus = {1 + k % buses}\n"
                   for k, (name, model, addr) in enumerate(PLATE[:n]))
    if n == 1:  # a single sensor is the plain [imu] run
        text = text.replace("[[imu]]", "[imu]").replace(f'name = "{PLATE[0][0]}"\n', "")
    p = tmp / f"plate-{n}-{odr_hz:g}-{buses}.toml"
    p.write_text(text)
    return load_config(p)


def planned_load(cfg: Any) -> str:
    """Every bus's planned load (:func:`gyrocal.kit.busload.bus_loads`), "NN %" each, joined
    by " / " in bus order."""
    loads = bus_loads(cfg.imus(), cfg["gimbal"]["sample_hz"])
    return " / ".join(f"{100 * b.load:.0f} %" for b in loads)


def drain(n: int, odr_hz: float, seconds: float, tmp: Path, buses: int = 1
          ) -> dict[str, object]:
    """One rest of ``seconds`` with ``n`` sensors at ``odr_hz`` on ``buses`` buses through the
    protocol loop."""
    cfg = _config(n, odr_hz, tmp, buses)
    sims = build_sim_plate(cfg, seed=1, realism=())
    clock = sims[0].clock
    names = [s["name"] for s in cfg.imus()]
    imus = [open_imu(s["model"], sims[k].imu_bus, s["address"], clock=clock,
                     range_dps=s["range_dps"], odr_hz=s["odr_hz"])
            for k, s in enumerate(cfg.imus())]
    g = cfg["gimbal"]
    parts = {"gimbal": {"motors": []}, "protocol": {"discarded": []}}
    root = tmp / f"rec-{n}-{odr_hz:g}-{buses}"
    writers = [RecordingWriter(root / name, sensor=imu.info.manifest(), **parts)
               for name, imu in zip(names, imus, strict=True)]
    group = RecordingGroup(writers) if n > 1 else writers[0]
    failed: dict[int, str] = {}
    cpu0 = time.process_time()
    error = ""
    with Gimbal(sims[0].port, g["ids"], baudrate=SIM_BAUD, clock=clock) as gimbal, group:
        runner = Runner(gimbal, imus if n > 1 else imus[0], group, clock,
                        [Step("rest", rest_s=seconds)], sample_hz=g["sample_hz"],
                        sensor_names=names, max_repeats=0)
        try:
            runner.run()
            group.finish()
        except GyrocalError as exc:
            error = str(exc).split(":")[0]
        failed = dict(runner.failed)
    cpu = time.process_time() - cpu0
    # rows counted in the files themselves (not through gyrocal's reader), minus the header
    counts = [len((root / name / "imu.csv").read_bytes().splitlines()) - 1 for name in names]
    actual = [imu.info.odr_hz for imu in imus]
    expected = [r * seconds for r in actual]
    lossless = (not error and not failed and not runner.discarded
                and all(abs(c - e) <= 0.01 * e for c, e in zip(counts, expected, strict=True)))
    lost = ", ".join(names[k] for k in sorted(failed))
    return {"n": n, "asked": odr_hz, "actual": "/".join(f"{r:.0f}" for r in actual),
            "load": planned_load(cfg),
            "samples_s": sum(actual), "lossless": lossless,
            "lost": (f"{lost}: FIFO overflow" if failed else "") + (f" ({error})" if error else ""),
            "cpu_us": 1e6 * cpu / max(1, sum(counts)), "cpu_per_s": cpu / seconds}


def fit_seconds(tmp: Path) -> tuple[float, float]:
    """(planned jig time of the default protocol, CPU s of one sensor's fit), from one emulated
    one-sensor calibration."""
    from gyrocal.kit.cli import main
    from gyrocal.kit.pipeline import estimate_recording

    out = tmp / "one"
    with contextlib.redirect_stdout(io.StringIO()):
        main(["calibrate", "--sim", "--sim-realism", "off", "--out", str(out), "--quiet",
              "--no-report"])
    rec = load_recording(out / "recording")
    t0 = time.process_time()
    estimate_recording(rec)
    return float(rec.manifest["protocol"]["planned_jig_time_s"]), time.process_time() - t0


def main(argv: list[str]) -> None:
    quick = "--quick" in argv
    opts = dict(a.lstrip("-").split("=", 1) for a in argv if "=" in a)
    seconds = float(opts.get("seconds", 1.0 if quick else 3.0))
    mounts = [float(x) for x in opts.get("mount-s", "15,60").split(",")]
    rates = RATES_HZ[:2] if quick else RATES_HZ
    rows = []
    best: dict[int, float] = {}
    with tempfile.TemporaryDirectory() as d, warnings.catch_warnings():
        warnings.simplefilter("ignore")
        tmp = Path(d)
        for n in (1, 2, 4):
            for r in rates:
                res = drain(n, r, seconds, tmp)
                rows.append([n, f"{r:g}", res["actual"], f"{res['samples_s']:.0f}",
                             res["load"], "yes" if res["lossless"] else "NO", res["lost"],
                             f"{res['cpu_us']:.0f}" if res["lossless"] else "-",
                             f"{res['cpu_per_s']:.2f}"])
                if res["lossless"]:
                    best[n] = max(best.get(n, 0.0), float(res["samples_s"]))
        print_table(["sensors", "asked ODR Hz", "actual ODR Hz", "samples/s",
                     "planned bus load", "loss-free", "what failed", "CPU µs/sample",
                     "CPU s per s"], rows,
                    f"Table 1: one 400 kHz emulated bus, loop 200 Hz, {seconds:g} s rest each "
                    f"(planned load: gyrocal.kit.busload, which calibrate refuses above "
                    f"{100 * REFUSE_LOAD:.0f} % and warns about above {100 * WARN_LOAD:.0f} %)")
        two_rows, best_two = [], 0.0
        for r in rates:
            res = drain(4, r, seconds, tmp, buses=2)
            two_rows.append([f"{r:g}", res["actual"], f"{res['samples_s']:.0f}", res["load"],
                             "yes" if res["lossless"] else "NO", res["lost"]])
            if res["lossless"]:
                best_two = max(best_two, float(res["samples_s"]))
        print_table(["asked ODR Hz", "actual ODR Hz", "samples/s", "planned load bus 1 / 2",
                     "loss-free", "what failed"], two_rows,
                    "Table 1b: the 4 sensors on two emulated 400 kHz buses (MPU-9250 + LSM6DSOX "
                    "0x6A on bus 1, ICM-42688-P + LSM6DSOX 0x6B on bus 2), same loop")
        print_table(["sensors", "highest loss-free samples/s (all sensors)"],
                    [[n, f"{best.get(n, 0):.0f}"] for n in (1, 2, 4)]
                    + [["4 on two buses", f"{best_two:.0f}"]])
        jig_s, fit_s = fit_seconds(tmp)
    rows = []
    for mount_s in mounts:
        one = mount_s + 0.5 + jig_s + fit_s
        for n in (1, 2, 4):
            cycle = n * mount_s + n * 0.5 + jig_s + n * fit_s
            rows.append([f"{mount_s:g}", n, f"{cycle:.0f}", f"{3600 * n / cycle:.1f}",
                         f"{(3600 * n / cycle) / (3600 / one):.2f}"])
    print_table(["mounting s/sensor (ASSUMED)", "sensors on the plate", "cycle s",
                 "sensors/hour", "× one at a time"], rows,
                f"Table 2: jig time {jig_s:.1f} s (default full protocol, planned), still noise "
                f"0.5 s and fit {fit_s:.1f} s CPU per sensor (measured here); mounting time "
                "assumed (--mount-s=S[,S...]: 15 s a quick-release socket, 60 s screws)")
