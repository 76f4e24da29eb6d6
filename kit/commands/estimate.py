"""``gyrocal estimate RECORDING``: fit a calibration to a Recording v1 directory."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

from gyrocal.kit import argtypes

HELP = "estimate a calibration from a recording directory"
DESCRIPTION = (
    "Window a Recording v1 directory (whole revolutions at steady speed, encoder reference over "
    "the same windows, rests as bias windows) and fit the full model g = A (m + b) when the "
    "recording's poses determine it and its predicted error in general motion is below the "
    "paper's six parameters' (a note says both), else those (and say that cross-axis terms "
    "were not calibrated). Prints the result table, or the Calibration document with "
    "--json. Exits 3 if the fit is not consistent with the measured noise."
)


def add_arguments(p: argparse.ArgumentParser) -> None:
    """Register the arguments."""
    from gyrocal.kit.choices import METHODS

    p.add_argument("recording", type=argtypes.recording_dir, help="a Recording v1 directory")
    p.add_argument("--method", choices=METHODS, default=METHODS[0],
                   help="estimator (default: auto = full-matrix when the poses determine it "
                   "and it is predicted better in general motion, else paired-axis)")
    g = p.add_mutually_exclusive_group()
    g.add_argument("--gravity", type=float, metavar="M_S2",
                   help="local gravity magnitude for the accelerometer fit, m/s² (9.7..9.9; "
                   "default: the recording's site.gravity_m_s2, else standard gravity 9.80665)")
    g.add_argument("--latitude", type=float, metavar="DEG",
                   help="geodetic latitude of the jig: the accelerometer is fitted against the "
                   "WGS-84 normal gravity there (with --height)")
    p.add_argument("--height", type=float, metavar="M", default=0.0,
                   help="height above the WGS-84 ellipsoid, m, with --latitude (default 0)")
    p.add_argument("--json", action="store_true",
                   help="print the Calibration document (v2 for the full matrix, v1 for the "
                   "diagonal model)")
    p.add_argument("--out", metavar="FILE",
                   help="also write the Calibration document (v2 or v1) here")
    p.add_argument("--force", action="store_true", help="replace --out if it exists")
    p.add_argument("--allow-implausible", action="store_true",
                   help="accept a scale outside 0.5..2 or a bias beyond the gyro's range "
                        "(normally refused, exit 6: a unit mix-up such as °/s for rad/s)")
    p.add_argument("--align-gyro-to-accel", action="store_true",
                   help="express the gyro calibration in the calibrated accelerometer's frame "
                        "(accel-x-xy), as imu_tk does: the rotation between the frames is "
                        "estimated from the rests and applied with its uncertainty (needs the "
                        "recording's accelerometer columns and the full model)")
    from gyrocal.kit.commands.history import add_history_arguments

    add_history_arguments(p)


def run(args: argparse.Namespace) -> int:
    """Run the command."""
    from gyrocal.kit.fileio import refuse_existing
    from gyrocal.kit.recording import load_recording

    if args.out:
        refuse_existing([args.out], force=args.force)
    gravity = _gravity(args)
    history = _history(args)
    rec = load_recording(args.recording)  # path and contents checked before scipy is imported
    from gyrocal.kit.commands.history import store_and_say
    from gyrocal.kit.fileio import atomic_write_text
    from gyrocal.kit.pipeline import check_plausible, estimate_recording, recording_jig
    from gyrocal.kit.report import calibration_table

    for w in rec.warnings:
        print(f"gyrocal: warning: {w}", file=sys.stderr)
    if not rec.complete:
        print("gyrocal: warning: the recording is not marked complete (an interrupted run, or "
              "a tool that does not mark it)",
              file=sys.stderr)
    est = estimate_recording(rec, args.method, gravity_m_s2=gravity)
    for w in est.extracted.warnings:
        print(f"gyrocal: warning: {w}", file=sys.stderr)
    for note in est.notes:
        print(f"gyrocal: note: {note}", file=sys.stderr)
    cal = est.calibration
    if args.align_gyro_to_accel:
        from gyrocal.kit.alignment import align_to_accelerometer

        cal, note = align_to_accelerometer(
            cal, rec, est.extracted, getattr(est.fit, "axes_std_rad", None))
        print(f"gyrocal: note: {note}", file=sys.stderr)
    for problem in check_plausible(cal, rec.sensor, allow=args.allow_implausible,
                                   recording=rec, extracted=est.extracted):
        print(f"gyrocal: warning: {problem} (accepted: --allow-implausible)", file=sys.stderr)
    if args.out:
        atomic_write_text(args.out, cal.to_json() + "\n", force=args.force)
    store_and_say(history, cal.to_json() + "\n",
                  str(Path(args.out or args.recording).resolve()))
    if args.json:
        json.dump(cal.to_dict(), sys.stdout, indent=2)
        print()
    else:
        print(calibration_table(cal, rec.truth, jig=recording_jig(rec)))
    return 3 if cal.consistency is not None and not cal.consistency.ok else 0


def _gravity(args: argparse.Namespace) -> float | None:
    """The gravity of ``--gravity`` or ``--latitude``/``--height`` (checked as the config's
    ``[accelerometer]`` keys are), or None for the recording's own."""
    if args.gravity is None and args.latitude is None:
        return None  # before the imports: an argument error must not import numpy or scipy
    from gyrocal.kit.config import SCHEMA
    from gyrocal.kit.errors import InputError
    from gyrocal.kit.pipeline import local_gravity

    keys = SCHEMA["accelerometer"]
    given = ({"gravity_m_s2": args.gravity} if args.gravity is not None else
             {"gravity_m_s2": 0.0, "latitude_deg": args.latitude, "height_m": args.height})
    for name, value in given.items():
        problem = keys[name].check(value) if keys[name].check else None
        if name == "gravity_m_s2" and args.gravity is not None and (
                problem or value == 0):
            problem = "must be in 9.7..9.9 m/s²"
        if problem:
            flag = {"gravity_m_s2": "--gravity", "latitude_deg": "--latitude",
                    "height_m": "--height"}[name]
            raise InputError(f"{flag} {value!r} {problem}")
    return local_gravity(given)[0]


def _history(args: argparse.Namespace) -> Any:
    """Where to store the calibration (``--history``; the config's ``[history]`` is read, from
    ./gyrocal.toml, only then), or None."""
    if args.history is None and args.sensor_label is None:
        return None  # before the imports, as in _gravity
    from gyrocal.kit.commands.history import history_target_from
    from gyrocal.kit.config import default_config, load_config

    path = "gyrocal.toml" if Path("gyrocal.toml").is_file() else None
    cfg = load_config(path) if args.history is not None else default_config()
    return history_target_from(args, cfg["history"])
