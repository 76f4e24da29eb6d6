"""``gyrocal export``: write a calibration or noise document in another tool's format."""

from __future__ import annotations

import argparse
import sys

HELP = "write a calibration or noise document in another tool's format (json, kalibr, ...)"
DESCRIPTION = (
    "Render a gyrocal JSON document (a Calibration from 'gyrocal calibrate/estimate': v2, the full "
    "model g = A (m + b) with a 3x3 matrix A, by default, or v1, the paper's diagonal model; or a "
    "noise document from 'gyrocal noise') in the format another tool reads, written in that "
    "tool's terms (notes on stderr say what it cannot carry). DOC is the JSON file, or - for "
    "standard input."
)


def add_arguments(p: argparse.ArgumentParser) -> None:
    """Register the flags (format options come from every registered exporter)."""
    from gyrocal.kit.exports import EXPORTERS

    p.add_argument("doc", metavar="DOC", help="gyrocal JSON document, or - for stdin")
    lines = [f"{name}: {e.description} (takes {', '.join(e.accepts)})"
             for name, e in EXPORTERS.items()]
    p.add_argument("--format", required=True, choices=list(EXPORTERS), metavar="FORMAT",
                   help="one of: " + "; ".join(lines))
    p.add_argument("--out", metavar="FILE", help="write here (atomically) instead of stdout")
    p.add_argument("--force", action="store_true", help="replace an existing --out file")
    seen: set[str] = set()
    for e in EXPORTERS.values():
        for opt in e.options:
            if opt.name in seen:
                continue
            seen.add(opt.name)
            p.add_argument("--" + opt.name.replace("_", "-"), dest="opt_" + opt.name,
                           metavar=opt.name.upper(), type=opt.type, default=None,
                           help=opt.help)


def run(args: argparse.Namespace) -> int:
    """Load, check the document kind against the format, render, write."""
    from gyrocal.kit.exports import export, read_json
    from gyrocal.kit.fileio import emit_text

    doc = read_json(args.doc)
    options = {k[4:]: v for k, v in vars(args).items() if k.startswith("opt_") and v is not None}
    text, notes = export(doc, args.format, options)
    for note in notes:
        print(f"gyrocal: note: {note}", file=sys.stderr)
    emit_text(text, args.out, force=args.force)
    return 0
