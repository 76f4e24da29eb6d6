"""``gyrocal apply CAL SOURCE``: calibrated rates of a recording, or of a CSV stream."""

from __future__ import annotations

import argparse
import sys

HELP = "apply a calibration: calibrated rates of a recording (CSV) or of a stream (stdin->stdout)"
DESCRIPTION = (
    "Write the calibrated rates of SOURCE as CSV rows t,gx,gy,gz,temp (rad/s, °C; the layout of a "
    "recording's imu.csv). SOURCE is a Recording v1 directory, an imu.csv-style file, or - to "
    "read rows from standard input and write each calibrated row to standard output as it "
    "arrives. A calibration with a temperature model is applied at each row's temperature."
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
    note = apply.g_sensitivity_note(cal)
    if note:
        print(note, file=sys.stderr)
    if args.source == "-":
        from gyrocal.kit.fileio import bounded_lines

        apply.stream(cal, bounded_lines(sys.stdin), sys.stdout)
        return 0
    src = Path(args.source)
    if src.is_dir():
        from gyrocal.kit.recording import load_recording

        rec = load_recording(src)
        t, rate, temp = rec.imu_t, rec.imu_rate, rec.imu_temp
        text = apply.calibrated_rows(cal, t, rate, temp)
    elif src.is_file():
        import io

        from gyrocal.kit.fileio import bounded_lines

        buf = io.StringIO()
        with open(src, encoding="ascii", errors="replace") as fh:
            apply.stream(cal, bounded_lines(fh, str(src)), buf)
        text = buf.getvalue()
    else:
        raise InputError(f"{src} is neither a recording directory nor a file; give the "
                         "directory gyrocal calibrate wrote (e.g. run1/recording) or -")
    emit_text(text, args.out, force=args.force)
    return 0
