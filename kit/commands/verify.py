"""``gyrocal verify CAL``: check a calibration against the servo encoders."""

from __future__ import annotations

import argparse
import json
import sys
from datetime import datetime
from pathlib import Path

HELP = "verify a calibration: RMS rate error before/after against the encoder reference"
DESCRIPTION = (
    "Repeat the protocol's turns on the jig (or --sim) with the calibration applied, or replay a "
    "recording (--recording), and report each axis's RMS rate error before and after "
    "calibration against the servo encoders: the true rate is the servos' encoder rates along "
    "their axes (the calibration's kinematics, or the home-pose axes of a version 1 "
    "calibration), at rest it is zero (like the paper's Tables V and VI, with the servos as the "
    "reference instead of a second gyroscope), and the change of the still sensor's calibrated "
    "rate when gravity is tilted (its g-sensitivity). Exits 3 when the calibration's error "
    "exceeds 3 times what its own uncertainty predicts."
)


def add_arguments(p: argparse.ArgumentParser) -> None:
    """Register the arguments."""
    from gyrocal.kit.commands.calibrate import add_common_jig_arguments

    p.add_argument("calibration", help="a Calibration JSON file (version 1 or 2)")
    p.add_argument("--recording", metavar="DIR",
                   help="replay this recording instead of running the jig")
    p.add_argument("--block", type=float, default=0.5, metavar="S",
                   help="comparison block length, s (default 0.5)")
    p.add_argument("--out", metavar="DIR",
                   help="where the verification run is recorded (jig mode; default "
                        "./gyrocal-verify-YYYYmmdd-HHMMSS)")
    p.add_argument("--force", action="store_true", help="replace files in --out")
    p.add_argument("--json", action="store_true", help="print the numbers as JSON")
    p.add_argument("--quiet", action="store_true", help="no progress display")
    add_common_jig_arguments(p)


def run(args: argparse.Namespace) -> int:
    """Run the command."""
    from gyrocal.kit.errors import InconsistentCalibrationError, InputError
    from gyrocal.kit.exports import load_document
    from gyrocal.kit.fileio import make_output_dir
    from gyrocal.kit.jig import load_cli_config, run_jig
    from gyrocal.kit.recording import load_recording
    from gyrocal.kit.verify import verify_recording

    path = Path(args.calibration)
    cal = load_document(args.calibration, "gyrocal-calibration", "calibration file")
    if getattr(args, "sim_imu", False):
        raise InputError("verify needs a sensor that sees the motion; --sim-imu emulates one at "
                         "rest (it tests the servos only): use --sim, or the real sensor")
    if args.recording:
        if args.sim:
            raise InputError("give either --recording (replay) or --sim (run), not both")
        rec_dir = Path(args.recording)
    else:
        cfg = load_cli_config(args)
        if args.sim and args.sim_noise_seed is None:
            args.sim_noise_seed = args.sim_seed + 1  # the same sensor and jig, fresh noise
        out = Path(args.out or datetime.now().strftime("gyrocal-verify-%Y%m%d-%H%M%S"))
        make_output_dir(out, "--out")
        rec_dir = out / "recording"
        from functools import partial

        import numpy as np

        from gyrocal.kit.report_plots import nominal_axis
        from gyrocal.kit.verify import GeneralMotionRunner, general_motion_steps

        axes = np.array([nominal_axis(a) for a in cfg["gimbal"]["axes"]])
        run_jig(cfg, args, out, rec_dir,
                extend=(GeneralMotionRunner, partial(general_motion_steps, axes=axes)))
    rec = load_recording(rec_dir)
    v = verify_recording(rec, cal, args.block)
    if v.blocks["one_servo"] + v.blocks["several_servos"] == 0:
        print(f"gyrocal: note: no {args.block:g} s block lies inside a steady turn (every "
              "turning block is on an acceleration ramp), so this checks only the rests: the "
              "biases, and g-sensitivity with the gravity pairs; give --block 0.5 or shorter "
              "to check the scale factors and cross-axis terms", file=sys.stderr)
    if args.json:
        json.dump({"calibration": str(path), "recording": str(rec_dir), **v.to_dict()},
                  sys.stdout, indent=2)
        print()
    else:
        print(v.table())
        if v.ok:
            print(f"\npassed: the calibration holds for this sensor and jig; worst {v.verdict()}")
        print(f"\nrecording: {rec_dir}")
    if not v.ok:
        raise InconsistentCalibrationError(
            f"the calibration is worse than its own uncertainty predicts: {v.verdict()}. Its "
            "model does not hold for this sensor or jig (a version 1 calibration cannot correct "
            "cross-axis sensitivity: calibrate the full model), or the sensor changed since; "
            "calibrate again")
    return 0
