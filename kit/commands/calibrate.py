"""``gyrocal calibrate``: run the protocol on the jig (or the emulated jig), record, estimate."""

from __future__ import annotations

import argparse
import importlib.util
import sys
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
    p.add_argument("--sim-sensor", choices=("datasheet", "paper", "paper-extreme"),
                   default="datasheet",
                   help="the emulated sensor's true scale factors and biases, drawn by seed: "
                        "datasheet (default): within the chip's datasheet tolerances (MPU-9250: "
                        "scale ±3 %%, bias ±5 °/s); paper: the paper's exaggerated sensor of its "
                        "simulations (scale 0.8..1.2, bias ±0.1 rad/s); paper-extreme: its "
                        "extreme one (scale 1.2..2.0, |bias| 0.1..0.2 rad/s). The paper's "
                        "sensor is --sim-sensor paper --sim-cross-axis 0 --sim-realism off")
    p.add_argument("--sim-cross-axis", type=float, metavar="FRACTION",
                   help="largest cross-axis term of the emulated sensor, drawn by seed (default: "
                        "the chip's datasheet figure, 0.02 for the MPU-9250's ±2 %%; 0 = none, "
                        "as in the paper's model)")
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
                        "slip:AT:DEG, fifo:CAPACITY, nack:PROBABILITY, imu-dead:AT, seat:N "
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
    from gyrocal.kit.choices import METHODS, PROTOCOLS
    from gyrocal.kit.jig_kinds import DEFAULT_JIG, JIG_KINDS

    add_common_jig_arguments(p)
    p.add_argument("--jig", choices=tuple(JIG_KINDS), default=DEFAULT_JIG,
                   help="the kind of jig: " + "; ".join(
                       f"{k.name}: {k.description} (hardware_docs/{k.hardware_docs})"
                       for k in JIG_KINDS.values()) + f" (default {DEFAULT_JIG}; on hardware, hand "
                   "opens only the IMU and prompts at the terminal for each rest and turn)")
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
    p.add_argument("--align-gyro-to-accel", action="store_true", default=None,
                   help="express the gyro calibration in the calibrated accelerometer's frame "
                        "(accel-x-xy), as imu_tk does: the rotation between the frames is "
                        "estimated from the rests and applied with its uncertainty "
                        "(protocol.align_gyro_to_accel; needs the accelerometer's calibration)")
    p.add_argument("--accel-rests", action=argparse.BooleanOptionalAction, default=None,
                   help="tilt the rests between turns so the accelerometer is calibrated too "
                        "(protocol.accel_rests, on by default for protocol full: a few servo "
                        "moves, about 8 s on the default run); --no-accel-rests keeps the "
                        "rests in the gyro's poses")
    p.add_argument("--json", action="store_true", help="print the calibration document")
    p.add_argument("--quiet", action="store_true", help="no progress display")
    p.add_argument("--no-report", action="store_true",
                   help="do not write DIR/report.html and DIR/plots/ (written by default when "
                        "the plot extra is installed)")
    from gyrocal.kit.commands.history import add_history_arguments

    add_history_arguments(p)


def run(args: argparse.Namespace) -> int:
    """Run the command."""
    from gyrocal.kit.commands.history import history_target_from, store_and_say
    from gyrocal.kit.fileio import atomic_write_text, built_beside, refuse_existing
    from gyrocal.kit.jig import load_cli_config, output_dir, run_jig
    from gyrocal.kit.pipeline import check_plausible, estimate_recording, recording_jig
    from gyrocal.kit.recording import load_recording
    from gyrocal.kit.report import calibration_table

    cfg = load_cli_config(args)
    history = history_target_from(args, cfg["history"])
    out, work = output_dir(args)
    report = not args.no_report and importlib.util.find_spec("matplotlib") is not None
    if report and work == out:
        refuse_existing([out / "report.html", out / "plots"], force=args.force)
    if len(cfg.imus()) > 1:
        return _run_plate(cfg, args, out, work, report, history)
    report_failed = None
    with built_beside(work, out):
        if getattr(args, "jig", "gimbal") == "hand":
            from gyrocal.kit.hand import record_hand_live, record_hand_sim

            (record_hand_sim if args.sim else record_hand_live)(cfg, args, work / "recording")
        else:
            run_jig(cfg, args, work, work / "recording")
        if getattr(args, "sim_imu", False):
            cal = None
        else:
            rec = load_recording(work / "recording")
            est = estimate_recording(rec, cfg["protocol"]["method"],
                                     source=str(out / "recording"))
            cal = est.calibration
            if cfg["protocol"]["align_gyro_to_accel"]:
                from dataclasses import replace

                from gyrocal.kit.alignment import align_to_accelerometer

                cal, aligned_note = align_to_accelerometer(
                    cal, rec, est.extracted, getattr(est.fit, "axes_std_rad", None))
                est = replace(est, notes=(*est.notes, aligned_note))
            check_plausible(cal, rec.sensor, allow=args.allow_implausible, recording=rec,
                            extracted=est.extracted)
            atomic_write_text(work / "calibration.json", cal.to_json() + "\n")
            if report:
                from gyrocal.kit.report_html import write_optional_report

                report_failed = write_optional_report(
                    rec, cal, est.extracted, work / "plots", title=f"{out} (gyrocal calibrate)",
                    html_path=work / "report.html", force=args.force,
                    calibration=str(out / "calibration.json"))
                report = report_failed is None
    rec_dir, cal_path = out / "recording", out / "calibration.json"
    if cal is None:
        print(f"wrote {rec_dir}/ (emulated IMU at rest: the servos were tested, nothing to fit)")
        return 0
    for w in (*est.extracted.warnings, *filter(None, [report_failed])):
        print(f"gyrocal: warning: {w}", file=sys.stderr)
    for note in est.notes:
        print(f"gyrocal: note: {note}", file=sys.stderr)
    store_and_say(history, cal_path.read_text(encoding="utf-8"), str(out.resolve()))
    if args.json:
        import json

        json.dump(cal.to_dict(), sys.stdout, indent=2)
        print()
    else:
        print(calibration_table(cal, rec.truth, jig=recording_jig(rec)))
        print()
        print(_what_next(args, out, cal, report))
    return 3 if cal.consistency is not None and not cal.consistency.ok else 0


#: The flags that say which jig (or emulated jig) a run used, by their ``args`` names: the
#: next commands need them to reach the same sensor.
_JIG_FLAGS = ("config", "sim_seed", "sim_sensor", "sim_scale", "sim_bias", "sim_cross_axis",
              "sim_realism", "sim_without", "sim_temperature", "sim_self_heating", "port",
              "baud", "imu_model", "imu_bus", "imu_address", "range_dps", "odr")
#: Their values when not given (the flags left out of the next commands).
_JIG_DEFAULTS: dict[str, Any] = {"sim_seed": 0, "sim_sensor": "datasheet", "sim_realism": "on",
                                 "sim_without": []}


def _jig_flags(args: argparse.Namespace) -> str:
    """The run's jig-defining flags as a command line (``--sim`` first when it was given)."""
    import shlex

    parts = ["--sim"] if args.sim else []
    for name in _JIG_FLAGS:
        value = getattr(args, name, None)
        if value is None or value == _JIG_DEFAULTS.get(name):
            continue
        flag = "--" + name.replace("_", "-")
        if name == "sim_without":
            parts += [f"{flag} {shlex.quote(v)}" for v in value]
        elif isinstance(value, list):
            parts.append(flag + "".join(f" {v:g}" for v in value))
        elif name == "imu_address":
            parts.append(f"{flag} 0x{value:02X}")
        else:
            parts.append(f"{flag} {shlex.quote(str(value))}")
    return "".join(" " + p for p in parts)


def _what_next(args: argparse.Namespace, out: Path, cal: Any, report: bool) -> str:
    """What the run wrote and the commands a user runs next: verify it on a new run, export it
    for their flight stack or tool, read the report (or how to get it: the ``plot`` extra)."""
    import shlex

    from gyrocal.kit.exports import EXPORTERS

    cal_path, rec_dir = out / "calibration.json", out / "recording"
    q = shlex.quote
    jig = getattr(args, "jig", "gimbal")
    kind = ("the full model" if cal.matrix is not None else
            "the paper's diagonal model" if jig == "gimbal" else "the diagonal model")
    wrote = (f"wrote {cal_path} (Calibration v{2 if cal.matrix is not None else 1}: {kind}), "
             f"{rec_dir}/ (what the jig recorded)")
    has_matplotlib = importlib.util.find_spec("matplotlib") is not None
    if report:
        wrote += f", and the report {out / 'report.html'} (plots in {out / 'plots'}/)"
    formats = ", ".join(n for n, e in EXPORTERS.items() if "gyrocal-calibration" in e.accepts)
    verify = (("check it on a new run, in motion the calibration never saw:",
               f"gyrocal verify {q(str(cal_path))}{_jig_flags(args)}") if jig == "gimbal" else
              (f"gyrocal verify turns the gimbal's three servos against their encoders, which "
               f"the {jig} jig does not have: check this calibration on a second {jig} session "
               "(calibrate again, compare the two within their σ) or on a gimbal", ""))
    steps = [
        verify,
        (f"write it for your flight stack or tool (FORMAT: {formats}; gyrocal export --help):",
         f"gyrocal export {q(str(cal_path))} --format FORMAT"),
    ]
    if report:
        steps.append(("read the result, its verdict and plots on one page:",
                      str(out / "report.html")))
    else:
        why = ("no report was written: it needs the plot extra (pip install 'gyrocal[plot]'), "
               "then" if not has_matplotlib else "the plots and report.html (not written: "
               "--no-report)")
        steps.append((f"{why}:", f"gyrocal report {q(str(rec_dir))} {q(str(cal_path))} --out "
                                 f"{q(str(out / 'plots'))}"))
    if cal.consistency is not None and not cal.consistency.ok:
        steps = [("the calibration is NOT consistent with the measured noise: do not use it. "
                  "hardware_docs/running.md (the consistency verdict) lists the causes; fix "
                  "them and calibrate again. To see which turn or rest is off:", ""), *steps[2:]]
    lines = [wrote + ".", "", "next:"]
    for why, command in steps:
        lines.append(f"  {why}")
        if command:
            lines.append(f"    {command}")
    return "\n".join(lines)


def _run_plate(cfg: Any, args: argparse.Namespace, out: Path, work: Path, report: bool,
               history: Any) -> int:
    """Several sensors on the plate (:func:`gyrocal.kit.plate.run_plate`): exit 0 only if every
    sensor passed; with a history, one record per calibrated sensor under its own label."""
    from gyrocal.kit.commands.history import store_and_say
    from gyrocal.kit.plate import (
        describe_plate,
        history_targets,
        plate_exit_code,
        run_plate,
        summary_document,
    )

    sensors = cfg.imus()
    targets = history_targets(history, [s["name"] for s in sensors])  # refused before the run
    outcomes = run_plate(cfg, args, out, work, report=report)
    for o, target in zip(outcomes, targets, strict=True):
        if o.calibration is not None:
            store_and_say(target, (out / o.name / "calibration.json").read_text(encoding="utf-8"),
                          str((out / o.name).resolve()))
    if args.json:
        import json

        json.dump(summary_document(outcomes), sys.stdout, indent=2)
        print()
    else:
        print(describe_plate(outcomes, sensors, out))
    return plate_exit_code(outcomes)
