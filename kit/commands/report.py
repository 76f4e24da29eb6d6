"""``gyrocal report``: PNG plots of a recording and its calibration (the ``plot`` extra)."""

from __future__ import annotations

import argparse
import sys

from gyrocal.kit import argtypes

HELP = "plot a recording: raw and calibrated rates per turn against the encoder, windows, residuals"
DESCRIPTION = (
    "Write PNG plots of a Recording v1 into --out DIR: an overview; for each turn the raw and "
    "the calibrated rate about the servo's axis against the encoder reference, with the window "
    "the estimator used shaded by its weight; the rest windows against -bias; and each window's "
    "residual in standard deviations. With CAL (a Calibration JSON, v2 or v1) the plots use that "
    "calibration; without it one is estimated from the recording. Also writes report.html, one "
    "self-contained page to read or send: a summary (verdict, model, largest cross-axis term, "
    "misalignment, what to do next), the fitted model with its standard deviations, the "
    "verification, the noise, the environment and the plots inline. Prints the list of files. "
    "Needs matplotlib: pip install 'gyrocal[plot]'."
)


def add_arguments(p: argparse.ArgumentParser) -> None:
    """Register the arguments."""
    from gyrocal.kit.choices import METHODS

    p.add_argument("recording", metavar="RECORDING", type=argtypes.recording_dir,
                   help="Recording v1 directory")
    p.add_argument("cal", nargs="?", metavar="CAL",
                   help="Calibration JSON, v2 or v1 (default: estimate one from the recording)")
    p.add_argument("--out", required=True, metavar="DIR", help="directory for the PNG files")
    p.add_argument("--force", action="store_true", help="replace existing plots in DIR")
    p.add_argument("--verification", metavar="FILE",
                   help="a `gyrocal verify --json` document to include in report.html")
    p.add_argument("--method", choices=METHODS, default=METHODS[0],
                   help="estimator when no CAL is given (default auto: the full model when the "
                        "recording's poses determine it and it is predicted better in general "
                        "motion, else paired-axis)")


def run(args: argparse.Namespace) -> int:
    """Load, window (and estimate without CAL), draw, print the index."""
    from gyrocal.kit.exports import load_document
    from gyrocal.kit.pipeline import judged_windows
    from gyrocal.kit.plots import require_matplotlib
    from gyrocal.kit.recording import load_recording
    from gyrocal.kit.report_html import write_run_report

    require_matplotlib()  # before any work: a missing extra is the first thing to say
    rec = load_recording(args.recording)
    for w in rec.warnings:
        print(f"gyrocal: warning: {w}", file=sys.stderr)
    if args.cal:
        cal = load_document(args.cal, "gyrocal-calibration", "calibration")
        extracted = judged_windows(rec)[0]
        what = f"calibration {args.cal}"
    else:
        from gyrocal.kit.pipeline import estimate_recording

        est = estimate_recording(rec, args.method)
        cal, extracted = est.calibration, est.extracted
        what = f"the {args.method} estimate from the recording (no CAL given)"
    for w in extracted.warnings:
        print(f"gyrocal: warning: {w}", file=sys.stderr)
    verification = None
    if args.verification:
        from gyrocal.kit.exports import read_json

        verification = read_json(args.verification, "verification")
    written = write_run_report(rec, cal, extracted, args.out, title=f"{rec.path} with {what}",
                               verification=verification, force=args.force,
                               calibration=args.cal)
    print(f"gyrocal report: {len(written) - 1} plots and a page of {rec.path} with {what}")
    width = max(len(str(p)) for p, _ in written)
    for path, desc in written:
        print(f"{str(path):<{width}}  {desc}")
    return 0
