"""``gyrocal apply CAL SOURCE``: calibrated rates of a recording, or of a CSV stream."""

from __future__ import annotations

import argparse
import sys

HELP = ("apply a calibration (g = A (m + b), with g-sensitivity from the accelerometer's "
        "columns): calibrated rates of a recording or of a stream (stdin->stdout)")
DESCRIPTION = (
    "Write the calibrated rates of SOURCE as CSV rows in the layout of a recording's imu.csv: "
    "t,gx,gy,gz,temp (rad/s, °C), or t,gx,gy,gz,temp,ax,ay,az (m/s²) when SOURCE has the "
    "accelerometer's columns. SOURCE is a Recording v1 directory, an imu.csv file (either "
    "layout, header optional), or - to read such rows from standard input and write each "
    "calibrated row to standard output as it arrives. The full model of the calibration is "
    "applied: g = A (m + b) (Calibration v2; v1 is its diagonal), at each row's temperature "
    "when it has a temperature model, and with its g-sensitivity (g = A (m + b + G f), f from "
    "ax,ay,az) when it has one and the rows carry the accelerometer; stderr says when it "
    "cannot. With the calibration's accelerometer, ax,ay,az come out calibrated too."
)


def add_arguments(p: argparse.ArgumentParser) -> None:
    """Register the arguments."""
    p.add_argument("calibration", help="a Calibration document (calibration.json)")
    p.add_argument("source", help="a Recording v1 directory, an imu.csv-style file, or - (stdin)")
    p.add_argument("--out", metavar="FILE",
                   help="write the CSV here (atomically) instead of standard output")
    p.add_argument("--force", action="store_true", help="replace an existing --out file")


def run(args: argparse.Namespace) -> int:
    """Run the command."""
    from pathlib import Path

    from gyrocal.kit import apply
    from gyrocal.kit.errors import InputError
    from gyrocal.kit.exports import load_document
    from gyrocal.kit.fileio import emit_text, refuse_existing

    if args.source == "-" and args.out:
        raise InputError("a stream (-) goes to standard output; --out goes with a recording")
    refuse_existing([args.out], force=args.force)
    cal = load_document(args.calibration, "gyrocal-calibration", "calibration")
    if args.source == "-":
        from gyrocal.kit.fileio import bounded_lines

        apply.stream(cal, bounded_lines(sys.stdin), sys.stdout, sys.stderr)
        return 0
    src = Path(args.source)
    if src.is_dir():
        from gyrocal.kit.recording import load_recording

        rec = load_recording(src)
        note = apply.layout_note(cal, rec.imu_accel is not None)
        if note:
            print(note, file=sys.stderr)
        text = apply.calibrated_rows(cal, rec.imu_t, rec.imu_rate, rec.imu_temp, rec.imu_accel)
    elif src.is_file():
        import io

        from gyrocal.kit.fileio import bounded_lines

        buf = io.StringIO()
        with open(src, encoding="ascii", errors="replace") as fh:
            apply.stream(cal, bounded_lines(fh, str(src)), buf, sys.stderr)
        text = buf.getvalue()
    else:
        raise InputError(f"{src} is neither a recording directory nor a file; give the "
                         "directory gyrocal calibrate wrote (e.g. run1/recording) or -")
    emit_text(text, args.out, force=args.force)
    return 0
