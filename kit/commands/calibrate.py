"""``gyrocal calibrate``: run the protocol on the jig (or the emulated jig), record, estimate."""

from __future__ import annotations

import argparse
import json
import math
import sys
from datetime import datetime
from pathlib import Path
from typing import Any

HELP = "calibrate: spin the sensor on the jig, record, fit, write calibration.json"
DESCRIPTION = (
    "Run the calibration protocol on the gimbal (or with --sim on the emulated jig): for each "
    "servo whole turns one way and back with rests, the IMU drained and the servos sampled in "
    "one loop, every sample recorded. Then window the recording, fit the six parameters, write "
    "DIR/recording/ (Recording v1) and DIR/calibration.json (Calibration v1), and print the "
    "result. Exits 3 if the calibration is not consistent with the measured noise. On an error, "
    "Ctrl-C or SIGTERM the servos stop and torque goes off first; the recording is kept, "
    "marked incomplete."
)


def _floats3(name: str) -> Any:
    def parse(text: str) -> float:
        try:
            return float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{name}: {text!r} is not a number") from None

    return parse


def add_common_jig_arguments(p: argparse.ArgumentParser, *, sim_flag: bool = True) -> None:
    """Flags shared by the commands that run the jig (calibrate, verify, doctor, track --live).

    With ``sim_flag=False`` the ``--sim`` flag is left to the caller, which must still set
    ``args.sim`` (``gyrocal track`` has its own ``--sim``).
    """
    p.add_argument("--config", metavar="FILE",
                   help="gyrocal.toml (default: ./gyrocal.toml if it exists, else defaults)")
    if sim_flag:
        p.add_argument("--sim", action="store_true",
                       help="use the emulated jig instead of hardware")
    p.add_argument("--sim-seed", type=int, default=0, metavar="S",
                   help="seed of the emulated sensor's true errors and the jig's geometry "
                        "(default 0)")
    p.add_argument("--sim-noise-seed", type=int, metavar="S",
                   help="seed of the emulated run's noise and ripple (default: --sim-seed; "
                        "verify uses a fresh one)")
    p.add_argument("--sim-scale", type=_floats3("--sim-scale"), nargs=3, metavar="K",
                   help="true scale factors of the emulated sensor (default: drawn by seed)")
    p.add_argument("--sim-bias", type=_floats3("--sim-bias"), nargs=3, metavar="B",
                   help="true biases of the emulated sensor, rad/s (default: drawn by seed)")
    p.add_argument("--sim-cross-axis", type=float, default=0.02, metavar="FRACTION",
                   help="largest cross-axis term of the emulated sensor, drawn by seed (default "
                        "0.02, the MPU-9250 datasheet's ±2 %%; 0 = the paper's sensor)")
    p.add_argument("--realtime", action="store_true",
                   help="run the emulated jig on the wall clock (a demonstration)")
    p.add_argument("--sim-fault", action="append", default=[], metavar="KIND:ARGS",
                   help="arm a fault of the emulated jig (repeatable): "
                        "stall:SERVO:AT[:FRACTION[:S]], silent:SERVO:AT, alert:SERVO:AT[:BITS], "
                        "slip:AT:DEG, fifo:CAPACITY, nack:PROBABILITY, imu-dead:AT "
                        "(AT: seconds into the recording)")
    p.add_argument("--port", help="servo serial port (gimbal.port)")
    p.add_argument("--baud", type=int, help="servo bus speed (gimbal.baud)")
    p.add_argument("--imu-model", help="imu.model")
    p.add_argument("--imu-bus", type=int, help="imu.bus: /dev/i2c-N")
    p.add_argument("--imu-address", type=lambda s: int(s, 0), help="imu.address, e.g. 0x68")
    p.add_argument("--range-dps", type=int, help="imu.range_dps")
    p.add_argument("--odr", type=float, help="imu.odr_hz")


def add_arguments(p: argparse.ArgumentParser) -> None:
    """Register the arguments."""
    from gyrocal.kit.config import METHODS, PROTOCOLS

    add_common_jig_arguments(p)
    p.add_argument("--out", metavar="DIR",
                   help="output directory (default: ./gyrocal-YYYYmmdd-HHMMSS)")
    p.add_argument("--force", action="store_true", help="replace files in DIR")
    p.add_argument("--protocol", choices=PROTOCOLS,
                   help="auto: planned for this jig (default); paper: 60°/s, one turn, 3 s waits")
    p.add_argument("--method", choices=METHODS)
    p.add_argument("--json", action="store_true", help="print the Calibration v1 document")
    p.add_argument("--quiet", action="store_true", help="no progress display")


def load_cli_config(args: argparse.Namespace) -> Any:
    """The config file (or defaults) with the command-line overrides applied."""
    from gyrocal.kit.config import apply_overrides, load_config

    path = args.config
    if path is None and Path("gyrocal.toml").exists():
        path = "gyrocal.toml"
    cfg = load_config(path)
    return apply_overrides(cfg, {
        "gimbal.port": args.port, "gimbal.baud": args.baud, "imu.model": args.imu_model,
        "imu.bus": args.imu_bus, "imu.address": args.imu_address,
        "imu.range_dps": args.range_dps, "imu.odr_hz": args.odr,
        "protocol.name": getattr(args, "protocol", None),
        "protocol.method": getattr(args, "method", None),
    })


def jig_endpoints(cfg: Any, args: argparse.Namespace) -> tuple[Any, Any, Any, int, Any]:
    """Where the devices are: ``(sim, clock, servo port, baud, I2C bus)`` of the emulated jig
    with ``--sim`` (``sim`` is its :class:`~gyrocal.kit.sim.SimJig`), else of the configured
    hardware
    (``sim`` is None)."""
    if args.sim_fault and not args.sim:
        from gyrocal.kit.errors import InputError

        raise InputError("--sim-fault needs --sim")
    if args.sim:
        from gyrocal.kit.sim import SIM_BAUD, build_sim

        sim = build_sim(cfg, seed=args.sim_seed, scale=args.sim_scale, bias=args.sim_bias,
                        realtime=args.realtime, noise_seed=args.sim_noise_seed,
                        cross_axis=args.sim_cross_axis)
        return sim, sim.clock, sim.port, SIM_BAUD, sim.imu_bus
    from gyrocal.drivers.clock import SystemClock

    g = cfg["gimbal"]
    return None, SystemClock(), g["port"], g["baud"], cfg["imu"]["bus"]


class Jig:
    """The devices of one run: a gimbal driver and an IMU reader on one clock (real or sim)."""

    def __init__(self, cfg: Any, args: argparse.Namespace) -> None:
        from gyrocal.drivers.dynamixel import Gimbal
        from gyrocal.drivers.imu import open_imu

        self.cfg = cfg
        self.faults: list[str] = []
        self.sim, self.clock, port, baud, bus = jig_endpoints(cfg, args)
        self._fault_specs: list[str] = list(args.sim_fault)
        if self._fault_specs:
            from gyrocal.kit.sim import apply_fault, build_sim

            scratch = build_sim(cfg, seed=args.sim_seed)
            for spec in self._fault_specs:  # validate now; armed when the protocol starts
                apply_fault(scratch, spec)
        g, imu = cfg["gimbal"], cfg["imu"]
        self.imu = open_imu(imu["model"], bus, imu["address"], clock=self.clock,
                            range_dps=imu["range_dps"], odr_hz=imu["odr_hz"])
        self.gimbal = Gimbal(port, g["ids"], baudrate=baud, clock=self.clock,
                             max_turns=g["max_turns"], acceleration=g["acceleration"])

    def arm_faults(self) -> list[str]:
        """Arm the ``--sim-fault`` knobs with their times counted from now (the recording's
        start); returns their descriptions."""
        from gyrocal.kit.sim import apply_fault

        if self.sim is None:
            return []
        t0 = self.clock.monotonic()
        self.faults = [apply_fault(self.sim, spec, t0) for spec in self._fault_specs]
        return self.faults

    def close(self) -> None:
        """Close the IMU (the gimbal closes through its context manager)."""
        from contextlib import suppress

        from gyrocal.drivers.errors import DriverError

        with suppress(DriverError):
            self.imu.close()


def measure_still_noise(imu: Any, clock: Any, seconds: float = 0.5) -> float | None:
    """The gyro's white noise per sample at rest (rad/s), from a short stream before the
    protocol (first differences; the median over the axes), for the planner; None if the stream
    gave too few samples."""
    import numpy as np

    from gyrocal.calib.observations import diff_noise

    imu.start()
    try:
        end = clock.monotonic() + seconds
        rates = []
        while clock.monotonic() < end:
            clock.sleep(0.02)
            rates.append(imu.read().rate)
    finally:
        imu.stop()
    x = np.concatenate(rates) if rates else np.zeros((0, 3))
    if x.shape[0] < 20:
        return None
    return float(np.median(diff_noise(x)))


def choose_plan(cfg: Any, gimbal: Any, imu: Any, noise_std: float | None = None) -> Any:
    """The protocol: planned for this servo and gyro (and its measured noise), or the paper's;
    fixed values override."""
    from dataclasses import replace

    from gyrocal.calib.design import jig_time, paper_plan, plan_protocol
    from gyrocal.kit.errors import InputError

    p = cfg["protocol"]
    accel = float(cfg["gimbal"]["acceleration"])
    noise = {} if noise_std is None else {"noise_std": noise_std}
    if p["name"] == "paper":
        plan = paper_plan(accel=accel, odr_hz=imu.odr_hz, **noise)
    else:
        plan = plan_protocol(servo_max_speed=gimbal.top_speed,
                             full_scale=math.radians(imu.full_scale_dps),
                             time_budget_s=p["time_budget_s"], odr_hz=imu.odr_hz, accel=accel,
                             **noise)
    fixed = {}
    if p["speed_dps"] > 0:
        fixed["speed"] = math.radians(p["speed_dps"])
    if p["turns"] > 0:
        fixed["turns"] = int(p["turns"])
    if p["rest_s"] > 0:
        fixed["rest_s"] = float(p["rest_s"])
    if fixed:
        plan = replace(plan, **fixed)
        plan = replace(plan, jig_time_s=jig_time(plan.speed, plan.turns, plan.rest_s, accel))
    if plan.speed > gimbal.top_speed:
        raise InputError(
            f"protocol speed {math.degrees(plan.speed):.0f}°/s exceeds the servos' top speed "
            f"{math.degrees(gimbal.top_speed):.0f}°/s; lower protocol.speed_dps"
        )
    if plan.turns > cfg["gimbal"]["max_turns"]:
        raise InputError(
            f"protocol turns {plan.turns} exceed gimbal.max_turns {cfg['gimbal']['max_turns']}"
            " (the cable-wrap limit); lower protocol.turns or raise the limit if the cables allow"
        )
    return plan


def run_jig(cfg: Any, args: argparse.Namespace, out: Path, rec_dir: Path,
            extend: Any = None) -> Any:
    """Run the protocol on the jig (or the emulated jig) into a Recording v1 at ``rec_dir``.

    Servos stop and torque goes off before the recording is closed, on success, error, Ctrl-C
    or SIGTERM; an interrupted run raises :class:`~gyrocal.kit.errors.InterruptedRun` (exit 130/143)
    with the recording kept, marked incomplete. With ``--sim`` the emulated servos' final state
    is written to ``out/sim-state.json`` (what the emulator holds, not what the driver believes).

    ``extend``, if given, is ``(runner_class, extra_steps)``: a :class:`Runner` subclass and
    ``extra_steps(plan, ids) -> steps`` run after the protocol (``gyrocal verify``'s general
    motion).

    Returns
    -------
    Jig
        The (closed) jig, for its sim truth.
    """
    from gyrocal.drivers.dynamixel.errors import TerminatedBySignal
    from gyrocal.kit.errors import InterruptedRun
    from gyrocal.kit.fileio import atomic_write_json
    from gyrocal.kit.progress import Progress
    from gyrocal.kit.protocol import Runner, build_steps
    from gyrocal.kit.recording import RecordingWriter

    jig = Jig(cfg, args)
    interrupted: BaseException | None = None
    quiet = getattr(args, "quiet", False)
    try:
        with jig.gimbal:
            noise_std = measure_still_noise(jig.imu, jig.clock)
            plan = choose_plan(cfg, jig.gimbal, jig.imu, noise_std)
            steps = build_steps(plan, cfg["gimbal"]["ids"])
            runner_class = Runner
            if extend is not None:
                runner_class, extra = extend
                steps += extra(plan, cfg["gimbal"]["ids"])
            sensor = jig.imu.info.manifest()
            gimbal_info = {"motors": [
                {"id": sid, "model": jig.gimbal.infos[sid].model_name,
                 "axis": cfg.axis_of()[sid]} for sid in cfg["gimbal"]["ids"]]}
            protocol = {"name": cfg["protocol"]["name"], "speed": plan.speed,
                        "turns": plan.turns, "rest_s": plan.rest_s, "acceleration": plan.accel,
                        "planned_jig_time_s": plan.jig_time_s,
                        "planning_noise_std": noise_std,
                        "sample_hz": cfg["gimbal"]["sample_hz"]}
            truth = None
            if jig.sim is not None:
                truth = {**jig.sim.truth.manifest(),
                         "axes": {str(k): v.tolist() for k, v in jig.sim.jig.home_axes.items()}}
            progress = Progress(sys.stderr, plan.jig_time_s,
                                interactive=False if quiet else None)
            if not quiet:
                progress.event(
                    f"protocol {cfg['protocol']['name']}: {plan.turns} turn(s) each way at "
                    f"{plan.speed_dps:.0f}°/s, {plan.rest_s:.1f} s rests, about "
                    f"{plan.jig_time_s:.0f} s of jig time"
                    + (" (emulated jig)" if jig.sim is not None else ""))
            with RecordingWriter(rec_dir, sensor=sensor, gimbal=gimbal_info, protocol=protocol,
                                 truth=truth, force=args.force) as writer:
                runner = runner_class(
                    jig.gimbal, jig.imu, writer, jig.clock, steps,
                    sample_hz=cfg["gimbal"]["sample_hz"],
                    on_progress=None if quiet else progress.update,
                    on_event=(lambda line: None) if quiet else progress.event,
                )
                for f in jig.arm_faults():
                    if not quiet:
                        progress.event(f"fault armed: {f} (time in the recording)")
                try:
                    runner.run()
                finally:
                    progress.close()
                if jig.sim is not None:
                    # The true axis of each servo during its turns (the holding servos rest
                    # somewhere within their ticks, which tilts the axes slightly off the
                    # ideal home pose).
                    writer.update_manifest(truth={**truth, "axes": jig.sim.turn_axes(
                        cfg["gimbal"]["ids"], runner.turn_times(), runner.t0)})
                writer.finish()
    except (KeyboardInterrupt, TerminatedBySignal) as exc:
        interrupted = exc
    finally:
        jig.close()
        if jig.sim is not None:
            atomic_write_json(out / "sim-state.json",
                              {"servos": jig.sim.servo_state()}, force=True)
    if interrupted is not None:
        signum = 15 if isinstance(interrupted, TerminatedBySignal) else 2
        raise InterruptedRun(
            f"{'terminated' if signum == 15 else 'interrupted'}: servos stopped, torque off; the "
            f"recording in {rec_dir} is kept, marked incomplete", signum)
    return jig


def run(args: argparse.Namespace) -> int:
    """Run the command."""
    from gyrocal.kit.errors import OutputExistsError
    from gyrocal.kit.fileio import atomic_write_text
    from gyrocal.kit.pipeline import estimate_recording
    from gyrocal.kit.recording import load_recording
    from gyrocal.kit.report import calibration_table

    cfg = load_cli_config(args)
    out = Path(args.out or datetime.now().strftime("gyrocal-%Y%m%d-%H%M%S"))
    cal_path = out / "calibration.json"
    if cal_path.exists() and not args.force:
        raise OutputExistsError(f"{cal_path} already exists; pass --force to replace it")
    out.mkdir(parents=True, exist_ok=True)
    rec_dir = out / "recording"
    run_jig(cfg, args, out, rec_dir)
    rec = load_recording(rec_dir)
    est = estimate_recording(rec, cfg["protocol"]["method"], source=str(rec_dir))
    cal = est.calibration
    atomic_write_text(cal_path, cal.to_json() + "\n", force=args.force)
    for w in est.extracted.warnings:
        print(f"gyrocal: warning: {w}", file=sys.stderr)
    for note in est.notes:
        print(f"gyrocal: note: {note}", file=sys.stderr)
    if args.json:
        json.dump(cal.to_dict(), sys.stdout, indent=2)
        print()
    else:
        print(calibration_table(cal, rec.truth))
        print(f"\nwrote {cal_path} and {rec_dir}/")
    return 3 if cal.consistency is not None and not cal.consistency.ok else 0
