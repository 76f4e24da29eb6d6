"""``gyrocal calibrate``: run the protocol on the jig (or the emulated jig), record, estimate."""

from __future__ import annotations

import argparse
import contextlib
import importlib.util
import json
import math
import sys
from datetime import datetime
from pathlib import Path
from typing import Any

from gyrocal.kit import argtypes

HELP = "calibrate: spin the sensor on the jig, record, fit, write calibration.json"
DESCRIPTION = (
    "Run the calibration protocol on the gimbal (or with --sim on the emulated jig): for each "
    "servo whole turns one way and back with rests, and (protocol full, the default) the same "
    "turns with an inner servo moved to a pose, the IMU drained and the servos sampled in one "
    "loop, every sample recorded. Then window the recording, fit the full model g = A (m + b) "
    "(or the six parameters of the diagonal one), write DIR/recording/ (Recording v1) and "
    "DIR/calibration.json (Calibration v2, or v1 for the diagonal model), and print the "
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
    p.add_argument("--sim-seed", type=argtypes.seed, default=0, metavar="S",
                   help="seed of the emulated sensor's true errors and the jig's geometry "
                        "(default 0)")
    p.add_argument("--sim-noise-seed", type=argtypes.seed, metavar="S",
                   help="seed of the emulated run's noise and ripple (default: --sim-seed; "
                        "verify uses a fresh one)")
    p.add_argument("--sim-scale", type=_floats3("--sim-scale"), nargs=3, metavar="K",
                   help="true scale factors of the emulated sensor (default: drawn by seed)")
    p.add_argument("--sim-bias", type=_floats3("--sim-bias"), nargs=3, metavar="B",
                   help="true biases of the emulated sensor, rad/s (default: drawn by seed)")
    p.add_argument("--sim-cross-axis", type=float, metavar="FRACTION",
                   help="largest cross-axis term of the emulated sensor, drawn by seed (default "
                        "0.02, the MPU-9250 datasheet's ±2 %%; 0 = the paper's sensor)")
    p.add_argument("--sim-realism", choices=("on", "off"), default="on",
                   help="the emulated sensor's imperfections beyond its calibration errors "
                        "(coloured noise, DLPF delay, g-sensitivity, gravity and lever arm, "
                        "wobble, chip clock, encoder latency): on (default) or off")
    p.add_argument("--sim-without", action="append", default=[], metavar="EFFECT",
                   help="turn one realism effect off (repeatable): coloured-noise, dlpf, "
                        "g-sensitivity, gravity, wobble, clock, encoder-latency")
    p.add_argument("--sim-temperature", metavar="PROFILE",
                   help="ambient temperature of the emulated sensor, °C: T, ramp:T0:T1:SECONDS "
                        "or soak:T0:T1:TAU (from power-on). Turns on the die's self-heating "
                        "warm-up and temperature coefficients drawn by seed within the "
                        "datasheet (default: a constant 25 °C, no temperature terms)")
    p.add_argument("--sim-self-heating", metavar="DT[:TAU]",
                   help="self-heating of the emulated die above ambient, °C, and its time "
                        "constant, s (default 4:180; turns the thermal sensor on too)")
    p.add_argument("--realtime", action="store_true",
                   help="run the emulated jig on the wall clock (a demonstration)")
    p.add_argument("--sim-fault", action="append", default=[], metavar="KIND:ARGS",
                   help="arm a fault of the emulated jig (repeatable): "
                        "stall:SERVO:AT[:FRACTION[:S]], silent:SERVO:AT, alert:SERVO:AT[:BITS], "
                        "slip:AT:DEG, fifo:CAPACITY, nack:PROBABILITY, imu-dead:AT "
                        "(AT: seconds into the recording)")
    p.add_argument("--sim-imu", action="store_true",
                   help="drive the real servos on --port (or gimbal.port) with an emulated IMU "
                        "that sits still: tests a jig's servos before the sensor arrives, or "
                        "the kit's whole servo path against 'gyrocal emulate --pty'. The run "
                        "records but does not fit (the emulated IMU does not see the motion)")
    p.add_argument("--port", help="servo serial port (gimbal.port; not with --sim)")
    p.add_argument("--baud", type=int, help="servo bus speed (gimbal.baud)")
    p.add_argument("--imu-model", help="imu.model")
    p.add_argument("--imu-bus", type=int, help="imu.bus: /dev/i2c-N")
    p.add_argument("--imu-address", type=argtypes.i2c_address, help="imu.address, e.g. 0x68")
    p.add_argument("--range-dps", type=int, help="imu.range_dps")
    p.add_argument("--odr", type=float, help="imu.odr_hz")


def add_arguments(p: argparse.ArgumentParser) -> None:
    """Register the arguments."""
    from gyrocal.kit.config import METHODS, PROTOCOLS

    add_common_jig_arguments(p)
    p.add_argument("--out", metavar="DIR",
                   help="output directory (default: ./gyrocal-YYYYmmdd-HHMMSS)")
    p.add_argument("--force", action="store_true",
                   help="replace the run in DIR as a whole (the new run is built beside it and "
                        "swapped in only when it has finished)")
    p.add_argument("--allow-implausible", action="store_true",
                   help="write a calibration whose scale is outside 0.5..2 or whose bias is "
                        "beyond the gyro's range (normally refused, exit 6: a unit mix-up)")
    p.add_argument("--protocol", choices=PROTOCOLS,
                   help="full: planned with gimbal poses for the full matrix, three servos "
                        "(default); auto: planned for this jig, diagonal model; paper: 60°/s, "
                        "one turn, 3 s waits")
    p.add_argument("--method", choices=METHODS)
    p.add_argument("--json", action="store_true", help="print the calibration document")
    p.add_argument("--quiet", action="store_true", help="no progress display")
    p.add_argument("--no-report", action="store_true",
                   help="do not write DIR/report.html and DIR/plots/ (written by default when "
                        "the plot extra is installed)")
    from gyrocal.kit.commands.history import add_history_arguments

    add_history_arguments(p)


def note_rounded_odr(asked_hz: float, info: Any) -> None:
    """Say on stderr when the chip runs at a rate other than the one configured (``--odr 201``
    runs an MPU-9250 at 1000/(1 + 4) = 200 Hz)."""
    if info.odr_hz != asked_hz:
        print(f"gyrocal: note: imu.odr_hz {asked_hz:g} is not a rate the {info.model} can do; "
              f"it runs at the nearest, {info.odr_hz:.6g} Hz (the recording says so)",
              file=sys.stderr)


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


def sim_effects(args: argparse.Namespace) -> list[str]:
    """The realism effects ``--sim-realism`` and ``--sim-without`` leave on."""
    from gyrocal.kit.sim import REALISM_EFFECTS

    without = list(getattr(args, "sim_without", []))
    if getattr(args, "sim_realism", "on") == "off":
        return []
    return [e for e in REALISM_EFFECTS if e not in without]


def jig_endpoints(cfg: Any, args: argparse.Namespace) -> tuple[Any, Any, Any, int, Any]:
    """Where the devices are: ``(sim, clock, servo port, baud, I2C bus)``.

    With ``--sim`` everything is the emulated jig (``sim`` is its
    :class:`~gyrocal.kit.sim.SimJig`); with ``--sim-imu`` the servos are the configured port (real
    servos, or ``gyrocal emulate --pty``) on the system clock and only the IMU is emulated, at
    rest; otherwise everything is the configured hardware (``sim`` is None).
    """
    from gyrocal.kit.errors import InputError

    sim_imu = getattr(args, "sim_imu", False)
    if args.sim_fault and not args.sim:
        raise InputError("--sim-fault needs --sim")
    if getattr(args, "sim_without", []):
        from gyrocal.kit.sim import REALISM_EFFECTS

        bad = [e for e in args.sim_without if e not in REALISM_EFFECTS]
        if bad:
            raise InputError(f"--sim-without {bad[0]!r}: not a realism effect; choose from "
                             + ", ".join(REALISM_EFFECTS))
    if args.sim and sim_imu:
        raise InputError("--sim emulates the whole jig; --sim-imu emulates only the IMU and "
                         "drives the servos on --port: give one of them")
    if args.sim and args.port is not None:
        raise InputError("--sim emulates the servos, so --port would be ignored; to drive "
                         "servos on a port (or 'gyrocal emulate --pty') with an emulated IMU "
                         "use --sim-imu --port PORT")
    if args.sim or sim_imu:
        from gyrocal.kit.sim import SIM_BAUD, SIM_CROSS_AXIS, build_sim

        cross_axis = getattr(args, "sim_cross_axis", None)
        sim = build_sim(cfg, seed=args.sim_seed, scale=args.sim_scale, bias=args.sim_bias,
                        realtime=args.realtime or sim_imu, noise_seed=args.sim_noise_seed,
                        cross_axis=SIM_CROSS_AXIS if cross_axis is None else cross_axis,
                        realism=sim_effects(args),
                        temperature=getattr(args, "sim_temperature", None),
                        self_heating=getattr(args, "sim_self_heating", None))
        if sim_imu:
            g = cfg["gimbal"]
            return sim, sim.clock, g["port"], g["baud"], sim.imu_bus
        from gyrocal.kit.config import default_config

        g, default = cfg["gimbal"], default_config()["gimbal"]
        if (g["baud"], g["port"]) != (default["baud"], default["port"]):  # the user set them
            print(f"gyrocal: note: --sim runs the emulated servos on their own bus at {SIM_BAUD} "
                  f"baud; gimbal.port ({g['port']}) and gimbal.baud ({g['baud']}) are not used",
                  file=sys.stderr)
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
        sim, self.clock, port, baud, bus = jig_endpoints(cfg, args)
        # --sim-imu: only the IMU is emulated (``imu_sim``); the servos are real or on a PTY.
        self.imu_sim = sim if getattr(args, "sim_imu", False) else None
        self.sim = None if self.imu_sim is not None else sim
        self._fault_specs: list[str] = list(args.sim_fault)
        if self._fault_specs:
            from gyrocal.kit.sim import apply_fault, build_sim

            scratch = build_sim(cfg, seed=args.sim_seed)
            for spec in self._fault_specs:  # validate now; armed when the protocol starts
                apply_fault(scratch, spec)
        g, imu = cfg["gimbal"], cfg["imu"]
        self.imu = open_imu(imu["model"], bus, imu["address"], clock=self.clock,
                            range_dps=imu["range_dps"], odr_hz=imu["odr_hz"])
        note_rounded_odr(imu["odr_hz"], self.imu.info)
        self.gimbal = Gimbal(port, g["ids"], baudrate=baud, clock=self.clock,
                             max_turns=g["max_turns"], acceleration=g["acceleration"],
                             watchdog_s=g["watchdog_s"], retries=g["retries"])

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


def _nominal_axes(names: list[str]) -> Any:
    """Unit vectors of the configured signed sensor axes (``"x"``, ``"-z"``, ...)."""
    import numpy as np

    out = np.zeros((len(names), 3))
    for i, name in enumerate(names):
        out[i, "xyz".index(name[-1])] = -1.0 if name.startswith("-") else 1.0
    return out


def choose_plan(cfg: Any, gimbal: Any, imu: Any, noise_std: float | None = None) -> Any:
    """The protocol: planned for this servo and gyro (and its measured noise), or the paper's;
    fixed values override."""
    from dataclasses import replace

    from gyrocal.calib.design import FULL_TIME_BUDGET_S, jig_time, paper_plan, plan_protocol
    from gyrocal.kit.errors import InputError

    p = cfg["protocol"]
    accel = float(cfg["gimbal"]["acceleration"])
    noise = {} if noise_std is None else {"noise_std": noise_std}
    if p["name"] == "paper":
        plan = paper_plan(accel=accel, odr_hz=imu.odr_hz, **noise)
    else:
        # protocol "full": plan the full model's posed turns (hardware_docs/method.md §9) within
        # at least FULL_TIME_BUDGET_S, with the configured axes as the nominal gimbal for
        # planning only.
        full = p["name"] == "full"
        if full and len(cfg["gimbal"]["ids"]) != 3:
            raise InputError(
                f"protocol 'full' (the default) needs a three-servo gimbal; gimbal.ids lists "
                f"{len(cfg['gimbal']['ids'])}: set protocol.name = \"auto\" (or --protocol auto) "
                "to calibrate the diagonal model with fewer servos")
        budget = max(p["time_budget_s"], FULL_TIME_BUDGET_S) if full else p["time_budget_s"]
        plan = plan_protocol(servo_max_speed=gimbal.top_speed,
                             full_scale=math.radians(imu.full_scale_dps),
                             time_budget_s=budget, odr_hz=imu.odr_hz, accel=accel,
                             model="full" if full else "diagonal",
                             axes=_nominal_axes(cfg["gimbal"]["axes"]) if full else None,
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
        plan = replace(plan, jig_time_s=jig_time(
            plan.speed, plan.turns, plan.rest_s, accel,
            move_angles=tuple(abs(a) for _, _, a in plan.poses)))
    # the planned protocols stay within their budget (the full one's is at least
    # FULL_TIME_BUDGET_S) also when fixed values override the plan
    limit = max(p["time_budget_s"], FULL_TIME_BUDGET_S) if p["name"] == "full" else (
        p["time_budget_s"])
    if p["name"] != "paper" and plan.jig_time_s > limit * (1 + 1e-9):
        raise InputError(
            f"the protocol needs about {plan.jig_time_s:.0f} s of jig time, more than "
            f"protocol.time_budget_s = {limit:g} s: raise the budget, or lower "
            "protocol.turns or protocol.rest_s, or set protocol.speed_dps higher (0 lets the "
            "planner choose within the budget)")
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


def _manifest_parts(cfg: Any, jig: Jig, plan: Any, noise_std: float | None
                    ) -> tuple[dict, dict, dict, dict | None]:
    """The manifest's ``sensor``, ``gimbal``, ``protocol`` and ``truth`` (sim only) of a run."""
    sensor = jig.imu.info.manifest()
    gimbal_info = {"motors": [
        {"id": sid, "model": jig.gimbal.infos[sid].model_name,
         "axis": cfg.axis_of()[sid]} for sid in cfg["gimbal"]["ids"]]}
    ids = cfg["gimbal"]["ids"]
    protocol = {"name": cfg["protocol"]["name"], "model": plan.model, "speed": plan.speed,
                "turns": plan.turns, "rest_s": plan.rest_s,
                "poses": [{"turn": ids[t], "moved": ids[m], "angle_rad": a}
                          for t, m, a in plan.poses],
                "acceleration": plan.accel,
                "planned_jig_time_s": plan.jig_time_s,
                "planning_noise_std": noise_std,
                "sample_hz": cfg["gimbal"]["sample_hz"],
                "discarded": []}  # attempts repeated after a failed check (the runner's)
    truth = None
    if jig.sim is not None:
        truth = {**jig.sim.truth_manifest(),
                 "axes": {str(k): v.tolist() for k, v in jig.sim.jig.home_axes.items()}}
    return sensor, gimbal_info, protocol, truth


def _record(cfg: Any, args: argparse.Namespace, jig: Jig, rec_dir: Path,
            extend: Any = None) -> None:
    """Open the gimbal, plan, and run the protocol into a Recording v1 at ``rec_dir``
    (``extend``: see :func:`run_jig`)."""
    from gyrocal.kit.progress import Progress
    from gyrocal.kit.protocol import Runner, build_steps
    from gyrocal.kit.recording import RecordingWriter

    quiet = getattr(args, "quiet", False)
    with jig.gimbal:
        noise_std = measure_still_noise(jig.imu, jig.clock)
        plan = choose_plan(cfg, jig.gimbal, jig.imu, noise_std)
        steps = build_steps(plan, cfg["gimbal"]["ids"])
        runner_class = Runner
        if extend is not None:
            runner_class, extra = extend
            steps += extra(plan, cfg["gimbal"]["ids"])
        sensor, gimbal_info, protocol, truth = _manifest_parts(cfg, jig, plan, noise_std)
        progress = Progress(sys.stderr, plan.jig_time_s, interactive=False if quiet else None)
        if not quiet:
            progress.event(
                f"protocol {cfg['protocol']['name']}: {plan.turns} turn(s) each way at "
                f"{plan.speed_dps:.0f}°/s, {plan.rest_s:.1f} s rests, "
                + (f"{len(plan.poses)} posed pairs for the full matrix, " if plan.poses else "")
                + f"about {plan.jig_time_s:.0f} s of jig time"
                + (" (emulated jig)" if jig.sim is not None else "")
                + (" (emulated IMU at rest)" if jig.imu_sim is not None else ""))
        with RecordingWriter(rec_dir, sensor=sensor, gimbal=gimbal_info, protocol=protocol,
                             truth=truth, force=args.force) as writer:
            runner = runner_class(
                jig.gimbal, jig.imu, writer, jig.clock, steps,
                sample_hz=cfg["gimbal"]["sample_hz"],
                on_progress=None if quiet else progress.update,
                on_event=None if quiet else progress.event,
            )
            for f in jig.arm_faults():
                if not quiet:
                    progress.event(f"fault armed: {f} (time in the recording)")
            try:
                runner.run()
                if not quiet:
                    progress.event(f"servo link: worst poll interval during motion "
                                   f"{jig.gimbal.worst_poll_interval_s * 1e3:.0f} ms (Bus "
                                   f"Watchdog {jig.gimbal.watchdog_s * 1e3:.0f} ms)")
            finally:
                progress.close()
                # The servo link's timing, on a failed run too: the longest gap between polls
                # while a servo moved, against the Bus Watchdog that would have stopped it
                # (hardware reference §5). A failed write must not hide the run's own error.
                with contextlib.suppress(OSError):
                    writer.update_manifest(protocol={
                        **writer.manifest["protocol"],
                        "worst_poll_interval_s": jig.gimbal.worst_poll_interval_s,
                        "bus_watchdog_s": jig.gimbal.watchdog_s})
            if jig.sim is not None:
                # The true axis of each servo during its turns (the holding servos rest
                # somewhere within their ticks, which tilts the axes slightly off the
                # ideal home pose).
                writer.update_manifest(truth={**truth, "axes": jig.sim.turn_axes(
                    cfg["gimbal"]["ids"], runner.turn_times(), runner.t0)})
            writer.finish()


def run_jig(cfg: Any, args: argparse.Namespace, out: Path, rec_dir: Path,
            extend: Any = None) -> Any:
    """Run the protocol on the jig (or the emulated jig) into a Recording v1 at ``rec_dir``.

    Servos stop and torque goes off before the recording is closed, on success, error, or
    SIGINT, SIGTERM or SIGHUP at any moment (:mod:`gyrocal.drivers.signals`: the gimbal's
    handlers are in place from its first packet to its last, and a second signal cannot cut the
    stop short). An interrupted run raises :class:`~gyrocal.kit.errors.InterruptedRun`
    (exit 130/143/129) whose message says whether a recording was begun (then it is kept,
    marked incomplete). With ``--sim`` the emulated servos' final state is written to
    ``out/sim-state.json`` (what the emulator holds, not what the driver believes).

    ``extend``, if given, is ``(runner_class, extra_steps)``: a :class:`Runner` subclass and
    ``extra_steps(plan, ids) -> steps`` run after the protocol (``gyrocal verify``'s general
    motion).

    Returns
    -------
    Jig
        The (closed) jig, for its sim truth.
    """
    from gyrocal.drivers.signals import TerminatedBySignal, shielded
    from gyrocal.kit.errors import InterruptedRun
    from gyrocal.kit.fileio import atomic_write_json

    jig = Jig(cfg, args)
    interrupted: BaseException | None = None
    try:
        _record(cfg, args, jig, rec_dir, extend)
    except (KeyboardInterrupt, TerminatedBySignal) as exc:
        interrupted = exc
    finally:
        with shielded():
            jig.close()
            if jig.sim is not None:
                atomic_write_json(out / "sim-state.json",
                                  {"servos": jig.sim.servo_state()}, force=True)
    if interrupted is not None:
        signum = getattr(interrupted, "signum", 2)
        what = {2: "interrupted", 15: "terminated", 1: "hung up"}.get(signum, "stopped")
        kept = (f"the recording in {rec_dir} is kept, marked incomplete"
                if (rec_dir / "manifest.json").exists() else "no recording was begun")
        raise InterruptedRun(f"{what}: servos stopped, torque off; {kept}", signum)
    return jig


def _output_dir(args: argparse.Namespace) -> tuple[Path, Path]:
    """``(out, work)``: the run's directory, and where this run writes.

    A new directory is written in place. With ``--force`` over an existing run, the new run is
    built in a staging directory beside it and swapped in only when it has finished
    (:func:`~gyrocal.kit.fileio.replace_dir`), so the old calibration never sits next to a new
    recording.
    """
    from gyrocal.kit.errors import OutputExistsError
    from gyrocal.kit.fileio import make_output_dir, staging_dir

    out = Path(args.out or datetime.now().strftime("gyrocal-%Y%m%d-%H%M%S"))
    if out.is_dir() and any(out.iterdir()):
        if not args.force:
            raise OutputExistsError(f"{out} already exists; pass --force to replace the run "
                                    "in it as a whole")
        return out, staging_dir(out)
    make_output_dir(out, "--out")
    return out, out


def run(args: argparse.Namespace) -> int:
    """Run the command."""
    from gyrocal.drivers.signals import shielded
    from gyrocal.kit.commands.history import history_target_from, store_and_say
    from gyrocal.kit.fileio import atomic_write_text, refuse_existing, replace_dir
    from gyrocal.kit.pipeline import check_plausible, estimate_recording
    from gyrocal.kit.recording import load_recording
    from gyrocal.kit.report import calibration_table

    cfg = load_cli_config(args)
    history = history_target_from(args, cfg["history"])
    out, work = _output_dir(args)
    report = not args.no_report and importlib.util.find_spec("matplotlib") is not None
    if report and work == out:
        refuse_existing([out / "report.html", out / "plots"], force=args.force)
    try:
        run_jig(cfg, args, work, work / "recording")
        if getattr(args, "sim_imu", False):
            cal = None
        else:
            rec = load_recording(work / "recording")
            est = estimate_recording(rec, cfg["protocol"]["method"],
                                     source=str(out / "recording"))
            cal = est.calibration
            check_plausible(cal, rec.sensor, allow=args.allow_implausible)
            atomic_write_text(work / "calibration.json", cal.to_json() + "\n")
            if report:
                from gyrocal.kit.report_html import write_run_report

                write_run_report(rec, cal, est.extracted, work / "plots",
                                 title=f"{out} (gyrocal calibrate)",
                                 html_path=work / "report.html", force=args.force)
    except BaseException:
        if work != out:
            print(f"gyrocal: the previous run in {out} is untouched; this run's output is in "
                  f"{work}", file=sys.stderr)
        raise
    if work != out:
        with shielded():
            replace_dir(work, out)
    rec_dir, cal_path = out / "recording", out / "calibration.json"
    if cal is None:
        print(f"wrote {rec_dir}/ (emulated IMU at rest: the servos were tested, nothing to fit)")
        return 0
    for w in est.extracted.warnings:
        print(f"gyrocal: warning: {w}", file=sys.stderr)
    for note in est.notes:
        print(f"gyrocal: note: {note}", file=sys.stderr)
    store_and_say(history, cal_path.read_text(encoding="utf-8"), str(out.resolve()))
    if args.json:
        json.dump(cal.to_dict(), sys.stdout, indent=2)
        print()
    else:
        print(calibration_table(cal, rec.truth))
        print(f"\nwrote {cal_path} and {rec_dir}/"
              + (f", and the report {out / 'report.html'}" if report else ""))
    return 3 if cal.consistency is not None and not cal.consistency.ok else 0
