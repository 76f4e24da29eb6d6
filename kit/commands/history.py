"""``gyrocal history``: each sensor's stored calibrations (list, show, trend, import, export)."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

HELP = "each sensor's calibration history: list, show, trend (table, plot), import, export"
DESCRIPTION = (
    "The calibration history (kit/history.py): every calibration stored by 'gyrocal calibrate "
    "--history' or 'gyrocal estimate --history', or imported from files, keyed by the sensor's "
    "label. 'list' shows the sensors, or one sensor's calibrations; 'show ID' one record and its "
    "document; 'trend SENSOR' how scale, cross-axis terms and bias moved with time and "
    "temperature (--plot FILE with the plot extra); 'import DIR' stores a directory of "
    "Calibration files or run directories (duplicates are found by content); 'export SENSOR "
    "DIR' writes the sensor's Calibration documents, which 'gyrocal thermal' takes. The "
    "database is --history URL, else history.url in gyrocal.toml, else the local default "
    "(sqlite:///~/.local/share/gyrocal/history.sqlite)."
)


def add_history_arguments(p: argparse.ArgumentParser) -> None:
    """``--history [URL]`` and ``--sensor-label`` for the commands that make a calibration."""
    p.add_argument("--history", nargs="?", const="", default=None, metavar="URL",
                   help="store the calibration in the history: sqlite:///PATH or "
                        "postgresql://USER@HOST/DB (without URL: history.url, else "
                        "~/.local/share/gyrocal/history.sqlite)")
    p.add_argument("--sensor-label", metavar="LABEL",
                   help="the sensor's label in the history (history.sensor_label), e.g. imu-07")


def add_arguments(p: argparse.ArgumentParser) -> None:
    """Register the arguments."""
    common = argparse.ArgumentParser(add_help=False)
    common.add_argument("--history", metavar="URL",
                        help="the database (default: history.url, else the local file)")
    common.add_argument("--config", metavar="FILE",
                        help="gyrocal.toml for history.url (default: ./gyrocal.toml if it exists)")
    common.add_argument("--json", action="store_true", help="print JSON")
    sub = p.add_subparsers(dest="action", metavar="ACTION")
    sub.required = True
    s = sub.add_parser("list", parents=[common], help="the sensors, or one sensor's calibrations")
    s.add_argument("sensor", nargs="?", help="a sensor label")
    s = sub.add_parser("show", parents=[common], help="one record and its document")
    s.add_argument("id", type=int, help="the record number (from list)")
    s = sub.add_parser("trend", parents=[common],
                       help="how scale, cross-axis terms and bias moved with time and temperature")
    s.add_argument("sensor", help="a sensor label")
    s.add_argument("--plot", metavar="FILE", help="also draw the trend as a PNG (plot extra)")
    s.add_argument("--force", action="store_true", help="replace --plot FILE if it exists")
    s = sub.add_parser("import", parents=[common],
                       help="store a directory of Calibration files or run directories")
    s.add_argument("dir", help="holds *.json Calibration files and/or RUN/calibration.json")
    s.add_argument("--sensor-label", required=True, metavar="LABEL",
                   help="the sensor these calibrations are of")
    s.add_argument("--jig", metavar="NAME", help="the jig that made them (default: unknown)")
    s = sub.add_parser("export", parents=[common],
                       help="write a sensor's Calibration documents into a directory")
    s.add_argument("sensor", help="a sensor label")
    s.add_argument("dir", help="output directory (made if missing)")
    s.add_argument("--force", action="store_true", help="replace files of the same names")


def _url(args: argparse.Namespace) -> str:
    from gyrocal.kit.config import load_config
    from gyrocal.kit.history import check_url, default_url

    if args.history:
        return check_url(args.history)
    path = args.config or ("gyrocal.toml" if Path("gyrocal.toml").is_file() else None)
    configured = load_config(path)["history"]["url"] if path else ""
    return check_url(configured, "history.url") if configured else default_url()


def run(args: argparse.Namespace) -> int:
    """Run the command."""
    from gyrocal.kit import history_view as view
    from gyrocal.kit.history import check_label, open_history

    url = _url(args)
    with open_history(url, create=args.action == "import") as store:
        if args.action == "list":
            out = view.list_text(store, args.sensor, as_json=args.json)
        elif args.action == "show":
            out = view.show_text(store.get(args.id), as_json=args.json)
        elif args.action == "trend":
            records = store.records(args.sensor)
            out = view.trend_text(records, as_json=args.json)
            if args.plot:
                view.trend_plot(records, args.plot, force=args.force)
                print(f"wrote {args.plot}", file=sys.stderr)
        elif args.action == "export":
            written = view.export_records(store.records(args.sensor), args.dir,
                                          force=args.force)
            out = (json.dumps({"written": [str(p) for p in written]}, indent=2) + "\n"
                   if args.json else f"wrote {len(written)} calibration(s) of {args.sensor} "
                   f"into {args.dir}/\n")
        else:
            jig = None if args.jig is None else check_label(args.jig, "--jig")
            report = view.import_dir(store, args.dir, label=args.sensor_label, jig=jig)
            out = view.import_text(report, as_json=args.json)
            for path, why in report.refused:
                print(f"gyrocal: error: {path}: {why}", file=sys.stderr)
            sys.stdout.write(out)
            return 2 if report.refused else 0
        for line in store.damaged:
            print(f"gyrocal: warning: {view.printable(line)}", file=sys.stderr)
    sys.stdout.write(out)
    return 0


def history_target_from(args: argparse.Namespace, settings: dict[str, Any]) -> Any:
    """The :class:`~gyrocal.kit.history.HistoryTarget` of ``--history``/``--sensor-label`` and
    the config's ``[history]`` (None if nothing is to be stored); the database is opened once
    (created if new) so that an unusable one stops the command before any work."""
    from gyrocal.kit.history import check_target, history_target

    target = history_target(args.history, args.sensor_label, settings)
    if target is not None:
        check_target(target)
    return target


def store_and_say(target: Any, document: str, source: str | None) -> None:
    """Store ``document`` at ``target`` and say where on stderr (stdout may be JSON)."""
    from gyrocal.kit.history import store_calibration

    if target is None:
        return
    result = store_calibration(target, document, source)
    if result.duplicate:
        print(f"gyrocal: note: this calibration is already in the history as #{result.id} "
              f"(sensor {result.duplicate_of!r})", file=sys.stderr)
    else:
        print(f"gyrocal: stored in the history {target.url} as #{result.id} "
              f"(sensor {target.label!r})", file=sys.stderr)
