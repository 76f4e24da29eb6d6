"""What ``gyrocal history`` shows and writes: lists, a record, the trend of a sensor's
calibrations (table, JSON, plot), and the import and export of Calibration files.

The trend reads the documents' own numbers (``scale``, ``bias``, and the v2 ``matrix``'s
off-diagonal, cross-axis terms of ``g = A (m + b)``, hardware_docs/formats.md) and fits a
straight line to each against temperature and against time (:func:`statistics.linear_regression`,
ordinary least squares), so a drift is seen as a number; fitting a thermal model with its
uncertainty is ``gyrocal thermal``'s job.
"""

from __future__ import annotations

import json
import os
import statistics
import unicodedata
from collections.abc import Sequence
from dataclasses import dataclass, field
from datetime import datetime
from pathlib import Path
from typing import Any

from gyrocal.kit.errors import InputError
from gyrocal.kit.history import (
    MAX_DOCUMENT_BYTES,
    HistoryDatabaseError,
    HistoryError,
    HistoryRecord,
    HistoryStore,
)

__all__ = [
    "ImportReport",
    "export_records",
    "import_dir",
    "import_text",
    "list_text",
    "show_text",
    "trend",
    "trend_plot",
    "trend_text",
]

#: The cross-axis terms of the v2 matrix, by (row, column).
CROSS_TERMS = {"xy": (0, 1), "xz": (0, 2), "yx": (1, 0), "yz": (1, 2), "zx": (2, 0),
               "zy": (2, 1)}


def _dumps(obj: Any) -> str:
    return json.dumps(obj, indent=2, allow_nan=False) + "\n"


def _fmt(x: float | None, spec: str) -> str:
    return "—" if x is None else format(x, spec)


def printable(text: str) -> str:
    """``text`` safe to print on a terminal: control and format characters (an escape sequence's
    ESC, a carriage return, a bidirectional override) shown as ``\\xNN`` / ``\\uNNNN`` escapes
    instead of acting on the terminal. A stored label, method or source is user text."""
    return "".join(ch if unicodedata.category(ch)[0] != "C" else
                   (f"\\x{ord(ch):02x}" if ord(ch) < 0x100 else f"\\u{ord(ch):04x}")
                   for ch in str(text))


def _table(headers: Sequence[str], rows: Sequence[Sequence[str]]) -> str:
    rows = [[printable(c) for c in r] for r in rows]
    widths = [max(len(h), *(len(r[i]) for r in rows)) if rows else len(h)
              for i, h in enumerate(headers)]
    lines = ["  ".join(h.ljust(w) for h, w in zip(headers, widths, strict=True)).rstrip()]
    lines.append("  ".join("-" * w for w in widths))
    lines += ["  ".join(c.ljust(w) for c, w in zip(r, widths, strict=True)).rstrip()
              for r in rows]
    return "\n".join(lines) + "\n"


# --------------------------------------------------------------------------- list, show
def list_text(store: HistoryStore, label: str | None, *, as_json: bool = False) -> str:
    """The sensors (``label`` None) or one sensor's calibrations, as a table or JSON."""
    if label is None:
        sensors = store.sensors()
        if as_json:
            return _dumps({"history": store.url, "sensors": [s.to_dict() for s in sensors]})
        if not sensors:
            return f"no calibrations in the history {store.url} yet\n"
        rows = [[s.label, s.model, str(s.count), s.first or "—", s.last or "—",
                 "—" if s.temperature_min_c is None else
                 f"{s.temperature_min_c:.1f}..{s.temperature_max_c:.1f}"] for s in sensors]
        return _table(["sensor", "model", "calibrations", "first", "last", "T °C"], rows)
    records = store.records(label)
    if as_json:
        return _dumps({"history": store.url, "sensor": label,
                       "calibrations": [r.summary() for r in records]})
    rows = [[f"#{r.id}", r.created or "—", _fmt(r.temperature_c, ".2f"), f"v{r.format_version}",
             r.method, r.verdict, r.jig or "—", r.source or "—"] for r in records]
    return _table(["id", "created (UTC)", "T °C", "ver", "method", "verdict", "jig", "source"],
                  rows)


def show_text(record: HistoryRecord, *, as_json: bool = False) -> str:
    """One record: its fields, then its Calibration document (verbatim)."""
    if as_json:
        return _dumps({**record.summary(), "document": json.loads(record.document)})
    s = record.summary()
    lines = [printable(f"{k}: {'—' if v is None else v}") for k, v in s.items()
             if k != "identity"]
    lines.insert(3, f"identity: {json.dumps(record.identity, sort_keys=True)}")
    text = record.document if record.document.endswith("\n") else record.document + "\n"
    return "\n".join(lines) + "\n\n" + text


# --------------------------------------------------------------------------- trend
def _when(text: str | None) -> datetime | None:
    try:
        return None if text is None else datetime.fromisoformat(text)
    except ValueError:
        return None


#: The least span of temperature (°C) or time (days) a slope is given over: over less, a slope
#: is the calibrations' scatter divided by a small number, not a drift.
MIN_SLOPE_SPAN = 1.0


def _slope(xs: Sequence[float | None], ys: Sequence[float]) -> float | None:
    """Least-squares slope of ``ys`` on ``xs`` (pairs with a None x left out); None if the x
    span less than :data:`MIN_SLOPE_SPAN`."""
    pairs = [(x, y) for x, y in zip(xs, ys, strict=True) if x is not None and y is not None]
    if not pairs or max(x for x, _ in pairs) - min(x for x, _ in pairs) < MIN_SLOPE_SPAN:
        return None
    return statistics.linear_regression([x for x, _ in pairs], [y for _, y in pairs]).slope


def trend(records: Sequence[HistoryRecord]) -> dict[str, Any]:
    """How a sensor's calibrations moved: per record and as slopes against temperature and time.

    Returns
    -------
    dict
        ``rows``: per record ``id``, ``created``, ``temperature_c``, ``scale`` (3),
        ``scale_change_ppm`` (3, against the first record), ``cross_axis`` (the six off-diagonal
        terms of the v2 matrix, or None for v1), ``bias`` (3, rad/s), ``bias_std`` (3),
        ``verdict``. ``per_degree`` and ``per_day``: the least-squares slope of each of
        ``scale_ppm_x``.., ``bias_x``.. (rad/s), ``cross_xy``.. against temperature (°C) and
        against time (days), None where the values span less than :data:`MIN_SLOPE_SPAN`
        (1 °C, 1 day).
    """
    rows = []
    first_scale: list[float] | None = None
    for r in records:
        doc = json.loads(r.document)
        scale = [float(v) for v in doc["scale"]]
        first_scale = first_scale or scale
        matrix = doc.get("matrix")
        cross = None if matrix is None else {k: float(matrix[i][j])
                                             for k, (i, j) in CROSS_TERMS.items()}
        rows.append({
            "id": r.id, "created": r.created, "temperature_c": r.temperature_c,
            "scale": scale,
            "scale_change_ppm": [1e6 * (k / k0 - 1) for k, k0 in zip(scale, first_scale,
                                                                      strict=True)],
            "cross_axis": cross, "bias": [float(v) for v in doc["bias"]],
            "bias_std": doc.get("bias_std"), "verdict": r.verdict})
    series: dict[str, list[float | None]] = {}
    for i, axis in enumerate("xyz"):
        series[f"scale_ppm_{axis}"] = [row["scale_change_ppm"][i] for row in rows]
    for i, axis in enumerate("xyz"):
        series[f"bias_{axis}"] = [row["bias"][i] for row in rows]
    for k in CROSS_TERMS:
        series[f"cross_{k}"] = [None if row["cross_axis"] is None else row["cross_axis"][k]
                                for row in rows]
    temps = [row["temperature_c"] for row in rows]
    times = [_when(row["created"]) for row in rows]
    t0 = next((t for t in times if t is not None), None)
    days = [None if t is None or t0 is None else (t - t0).total_seconds() / 86400 for t in times]

    def slopes(xs: list[float | None]) -> dict[str, float | None]:
        out = {}
        for name, ys in series.items():
            keep = [(x, y) for x, y in zip(xs, ys, strict=True) if y is not None]
            out[name] = _slope([x for x, _ in keep], [y for _, y in keep])
        return out

    return {"rows": rows, "per_degree": slopes(temps), "per_day": slopes(days)}


def trend_text(records: Sequence[HistoryRecord], *, as_json: bool = False) -> str:
    """:func:`trend` as JSON, or as a table (scale change in ppm against the first record,
    cross-axis terms in ‰, bias in mrad/s) with the slopes under it."""
    t = trend(records)
    if as_json:
        return _dumps(t)
    if not t["rows"]:
        return "no calibrations of this sensor yet\n"
    rows = []
    for row in t["rows"]:
        cross = row["cross_axis"]
        rows.append([
            f"#{row['id']}", (row["created"] or "—")[:19], _fmt(row["temperature_c"], ".2f"),
            " ".join(f"{v:+8.0f}" for v in row["scale_change_ppm"]),
            "—" if cross is None else " ".join(f"{1e3 * v:+6.2f}" for v in cross.values()),
            " ".join(f"{1e3 * v:+8.4f}" for v in row["bias"]), row["verdict"]])
    text = _table(["id", "created (UTC)", "T °C", "Δscale ppm x y z",
                   "cross-axis ‰ " + " ".join(CROSS_TERMS), "bias mrad/s x y z", "verdict"],
                  rows)
    lines = []
    for key, unit in (("per_degree", "°C"), ("per_day", "day")):
        s = t[key]
        if all(v is None for v in s.values()):
            lines.append(f"per {unit}: the calibrations span less than 1 {unit}, no slope")
            continue
        parts = [f"scale {' '.join(_fmt(s[f'scale_ppm_{a}'], '+.1f') for a in 'xyz')} ppm",
                 f"bias {' '.join(_fmt(_milli(s[f'bias_{a}']), '+.4f') for a in 'xyz')} mrad/s"]
        if any(s[f"cross_{k}"] is not None for k in CROSS_TERMS):
            parts.append("cross-axis " + " ".join(_fmt(_milli(s[f"cross_{k}"]), "+.3f")
                                                  for k in CROSS_TERMS) + " ‰")
        lines.append(f"per {unit} (least-squares slope): " + "; ".join(parts))
    return text + "\n" + "\n".join(lines) + "\n"


def _milli(v: float | None) -> float | None:
    return None if v is None else 1e3 * v


def trend_plot(records: Sequence[HistoryRecord], path: str | os.PathLike[str], *,
               force: bool = False) -> Path:
    """Scale change, cross-axis terms (v2) and bias against time and against temperature, as a
    PNG (needs the ``plot`` extra).

    Raises
    ------
    InputError
        Without matplotlib (saying how to install it), or if ``path`` exists without ``force``.
    """
    from gyrocal.kit.fileio import refuse_existing
    from gyrocal.kit.plots import literal, require_matplotlib, save_png

    refuse_existing([path], force=force)
    plt = require_matplotlib()
    t = trend(records)
    rows = t["rows"]
    if not rows:
        raise InputError("no calibrations to plot")
    has_cross = any(r["cross_axis"] is not None for r in rows)
    panels = [("Δscale (ppm)", lambda r: r["scale_change_ppm"], "xyz"),
              ("bias (mrad/s)", lambda r: [1e3 * v for v in r["bias"]], "xyz")]
    if has_cross:
        panels.insert(1, ("cross-axis (‰)", lambda r: None if r["cross_axis"] is None else
                          [1e3 * v for v in r["cross_axis"].values()], list(CROSS_TERMS)))
    fig, axes = plt.subplots(len(panels), 2, figsize=(11, 3 * len(panels)), squeeze=False)
    xs = {"time": [_when(r["created"]) for r in rows],
          "temperature (°C)": [r["temperature_c"] for r in rows]}
    for p, (title, get, names) in enumerate(panels):
        for c, (xname, xvals) in enumerate(xs.items()):
            ax = axes[p][c]
            for i, name in enumerate(names):
                pts = [(x, get(r)[i]) for x, r in zip(xvals, rows, strict=True)
                       if x is not None and get(r) is not None]
                if pts:
                    ax.plot([x for x, _ in pts], [y for _, y in pts], "o-", label=name, ms=4)
            ax.set_ylabel(title)
            ax.set_xlabel(xname)
            ax.grid(True, alpha=0.3)
            if c == 0:
                ax.legend(fontsize=7)
    fig.suptitle(f"calibration history of {literal(records[0].label)} ({len(rows)} "
                 "calibrations)")
    fig.autofmt_xdate()
    fig.tight_layout()
    return save_png(fig, path, force=force)


# --------------------------------------------------------------------------- export, import
def _file_name(r: HistoryRecord) -> str:
    when = _when(r.created)
    stamp = when.strftime("%Y%m%dT%H%M%SZ") if when is not None else "undated"
    return f"{stamp}-{r.id}.json"


def export_records(records: Sequence[HistoryRecord], out: str | os.PathLike[str], *,
                   force: bool = False) -> list[Path]:
    """Write each record's Calibration document, verbatim, to ``out/STAMP-ID.json``.

    Existing files are refused before anything is written (unless ``force``); each file is
    written atomically (:mod:`gyrocal.kit.fileio`).
    """
    from gyrocal.kit.fileio import atomic_write_text, make_output_dir, refuse_existing

    d = make_output_dir(out, "export DIR")
    paths = [d / _file_name(r) for r in records]
    refuse_existing(paths, force=force)
    for r, p in zip(records, paths, strict=True):
        atomic_write_text(p, r.document, force=force)
    return paths


@dataclass
class ImportReport:
    """What ``import`` did: files stored (path, id), already stored (path, id, label), refused
    (path, why)."""

    stored: list[tuple[str, int]] = field(default_factory=list)
    duplicates: list[tuple[str, int, str]] = field(default_factory=list)
    refused: list[tuple[str, str]] = field(default_factory=list)


def _candidates(root: Path) -> list[Path]:
    """``root/*.json`` and ``root/*/calibration.json``, sorted."""
    files = [p for p in root.glob("*.json") if p.is_file()]
    files += [p for p in root.glob("*/calibration.json") if p.is_file()]
    return sorted(files)


def import_dir(store: HistoryStore, directory: str | os.PathLike[str], *, label: str,
               jig: str | None = None) -> ImportReport:
    """Store every Calibration document in ``directory`` under sensor ``label``.

    Takes ``DIR/*.json`` (Calibration files) and ``DIR/*/calibration.json`` (run directories of
    ``gyrocal calibrate``). Each file is its own transaction: a bad one is reported and the
    others are stored; a document already stored (same content hash) is reported as such.

    Raises
    ------
    InputError
        If ``directory`` is not a directory or holds no candidate file.
    """
    from gyrocal.kit.history import check_label

    label = check_label(label)
    root = Path(directory)
    if not root.is_dir():
        raise InputError(f"import {root}: not a directory; give a directory of Calibration "
                         "files or of run directories")
    files = _candidates(root)
    if not files:
        raise InputError(f"import {root}: no *.json files and no */calibration.json in it")
    report = ImportReport()
    for path in files:
        try:
            if path.stat().st_size > MAX_DOCUMENT_BYTES:
                raise HistoryError(f"larger than {MAX_DOCUMENT_BYTES} bytes: not a calibration")
            text = path.read_text(encoding="utf-8")
            result = store.add(text, label=label, source=str(path.resolve()), jig=jig)
        except (OSError, UnicodeDecodeError) as exc:
            report.refused.append((str(path), f"cannot read it: {exc}"))
            continue
        except HistoryDatabaseError:
            raise  # the database itself failed: stop, say so
        except HistoryError as exc:
            report.refused.append((str(path), str(exc)))
            continue
        if result.duplicate:
            report.duplicates.append((str(path), result.id, result.duplicate_of or ""))
        else:
            report.stored.append((str(path), result.id))
    return report


def import_text(report: ImportReport, *, as_json: bool = False) -> str:
    """The import's summary (the refusals are listed too)."""
    if as_json:
        return _dumps({
            "stored": [{"path": p, "id": i} for p, i in report.stored],
            "duplicates": [{"path": p, "id": i, "sensor": s} for p, i, s in report.duplicates],
            "refused": [{"path": p, "error": e} for p, e in report.refused]})
    lines = [f"stored {p} as #{i}" for p, i in report.stored]
    lines += [f"already stored: {p} (#{i}, sensor {s!r})" for p, i, s in report.duplicates]
    lines.append(f"{len(report.stored)} stored, {len(report.duplicates)} already in the history, "
                 f"{len(report.refused)} refused")
    return "\n".join(lines) + "\n"
