"""One self-contained HTML page per run: what a user reads or sends (``gyrocal report``).

The page holds the result table with uncertainties, the consistency verdict, the servo axes, the
verification figures when given, the environment (versions, chip, jig), and every plot inline as a
base64 PNG, so the one file is the whole report: no network, no neighbouring files, no scripts.
"""

from __future__ import annotations

import base64
import html
import platform
import sys
from collections.abc import Mapping, Sequence
from importlib import metadata
from pathlib import Path
from typing import Any

import numpy as np

from gyrocal.calib.model import GyroCalibration
from gyrocal.kit import __version__

__all__ = ["environment", "render_html", "write_run_report"]

_CSS = """
body{font-family:system-ui,sans-serif;max-width:1100px;margin:2em auto;padding:0 1em;color:#222}
h1{font-size:1.5em}h2{font-size:1.2em;border-bottom:1px solid #ccc;padding-bottom:.2em}
table{border-collapse:collapse;margin:.5em 0}td,th{border:1px solid #ccc;padding:.25em .6em}
td.n{text-align:right;font-variant-numeric:tabular-nums}th{background:#f3f3f3}
.ok{color:#1a7f37;font-weight:bold}.bad{color:#b42318;font-weight:bold}
figure{margin:1em 0}figure img{max-width:100%;border:1px solid #ddd}figcaption{color:#555}
"""


def _e(x: Any) -> str:
    return html.escape(str(x))


def _version(dist: str) -> str:
    try:
        return metadata.version(dist)
    except metadata.PackageNotFoundError:
        return "not installed"


def environment(manifest: Mapping[str, Any] | None = None) -> dict[str, str]:
    """Versions, platform, chip and jig of a run, as label → text."""
    env = {
        "gyrocal": __version__,
        "Python": sys.version.split()[0],
        "numpy": _version("numpy"),
        "scipy": _version("scipy"),
        "dynamixel-sdk": _version("dynamixel-sdk"),
        "platform": f"{platform.system()} {platform.release()} ({platform.machine()})",
    }
    m = manifest or {}
    sensor = m.get("sensor") or {}
    if sensor:
        env["chip"] = ", ".join(f"{k} {v}" for k, v in sensor.items())
    motors = (m.get("gimbal") or {}).get("motors") or []
    if motors:
        env["jig"] = "; ".join(
            f"servo {mo.get('id')} {mo.get('model', '')} about {mo.get('axis', '?')}"
            for mo in motors
        )
    if m.get("created"):
        env["recorded"] = str(m["created"])
    return env


def _result_table(cal: GyroCalibration, truth: Mapping[str, Any] | None) -> str:
    head = "<tr><th>axis</th><th>scale</th><th>± std</th><th>bias rad/s</th><th>± std</th>"
    if truth is not None:
        head += "<th>scale err/σ</th><th>bias err/σ</th>"
    rows = [head + "</tr>"]
    for j, ax in enumerate("xyz"):
        r = (f"<tr><td>{ax}</td><td class=n>{cal.scale[j]:.6f}</td>"
             f"<td class=n>{cal.scale_std[j]:.2e}</td><td class=n>{cal.bias[j]:.6f}</td>"
             f"<td class=n>{cal.bias_std[j]:.2e}</td>")
        if truth is not None:
            r += (f"<td class=n>{(cal.scale[j] - truth['scale'][j]) / cal.scale_std[j]:.2f}</td>"
                  f"<td class=n>{(cal.bias[j] - truth['bias'][j]) / cal.bias_std[j]:.2f}</td>")
        rows.append(r + "</tr>")
    return "<table id=result>" + "".join(rows) + "</table>"


def _verdict(cal: GyroCalibration) -> str:
    c = cal.consistency
    if c is None:
        return "<p id=verdict>consistency: not tested (no redundant observations)</p>"
    cls, word = ("ok", "consistent") if c.ok else ("bad", "NOT consistent")
    return (f"<p id=verdict>consistency: <span class={cls}>{word}</span> with the measured "
            f"noise (χ² = {c.chi2:.1f} on {c.dof} dof, p = {c.p_value:.3g})</p>")


def _axes(cal: GyroCalibration) -> str:
    if not cal.axes:
        return "<p>no servo axes in this calibration</p>"
    rows = ["<tr><th>servo</th><th>axis in the sensor frame</th><th>nearest</th>"
            "<th>misalignment</th></tr>"]
    for motor, info in sorted(cal.axes.items(), key=lambda kv: int(kv[0])):
        u = np.asarray(info["axis"], dtype=float)
        rows.append(f"<tr><td>{_e(motor)}</td><td class=n>[{u[0]:+.4f} {u[1]:+.4f} {u[2]:+.4f}]"
                    f"</td><td>{_e(info['nearest'])}</td><td class=n>"
                    f"{info['misalignment_deg']:.2f}° ± {info['std_deg']:.3f}°</td></tr>")
    return "<table id=axes>" + "".join(rows) + "</table>"


def _verification(doc: Mapping[str, Any]) -> str:
    """Every number or 3-vector of a ``gyrocal verify --json`` document, by its name."""
    rows = []
    for key, v in doc.items():
        if isinstance(v, (int, float)) and not isinstance(v, bool):
            rows.append(f"<tr><td>{_e(key)}</td><td class=n>{v:.4g}</td></tr>")
        elif isinstance(v, list) and v and all(isinstance(x, (int, float)) for x in v):
            cells = " ".join(f"{x:.4g}" for x in v)
            rows.append(f"<tr><td>{_e(key)}</td><td class=n>{cells}</td></tr>")
        elif isinstance(v, str):
            rows.append(f"<tr><td>{_e(key)}</td><td>{_e(v)}</td></tr>")
    return "<table id=verification>" + "".join(rows) + "</table>"


def render_html(
    cal: GyroCalibration,
    *,
    title: str,
    plots: Sequence[tuple[str | Path, str]] = (),
    truth: Mapping[str, Any] | None = None,
    verification: Mapping[str, Any] | None = None,
    env: Mapping[str, str] | None = None,
) -> str:
    """The report page as one HTML string.

    Parameters
    ----------
    cal : GyroCalibration
    title : str
        What the run was (e.g. the recording's path).
    plots : sequence of (PNG path, caption)
        Embedded as base64 ``data:`` images, in order.
    truth : mapping, optional
        A simulated recording's ``{"scale", "bias"}``: adds each row's error in its own σ.
    verification : mapping, optional
        A ``gyrocal verify --json`` document.
    env : mapping, optional
        Label → text (:func:`environment`).
    """
    parts = [
        "<!DOCTYPE html><html lang=en><head><meta charset=utf-8>",
        f"<title>gyrocal report: {_e(title)}</title><style>{_CSS}</style></head><body>",
        f"<h1>gyrocal calibration report</h1><p>{_e(title)}</p>",
        f"<h2>Result</h2><p>model: g = scale ∘ (m + bias), rad/s; method {_e(cal.method)}, "
        f"{cal.iterations} iterations</p>",
        _result_table(cal, truth),
        _verdict(cal),
    ]
    if cal.temperature_c is not None:
        parts.append(f"<p>mean die temperature: {cal.temperature_c:.1f} °C</p>")
    parts += ["<h2>Servo axes</h2>", _axes(cal)]
    parts.append("<h2>Verification</h2>")
    parts.append(_verification(verification) if verification else
                 "<p>no verification given (gyrocal verify --json, then gyrocal report "
                 "--verification FILE)</p>")
    if plots:
        parts.append("<h2>Plots</h2>")
        for path, caption in plots:
            data = base64.b64encode(Path(path).read_bytes()).decode("ascii")
            parts.append(f"<figure><img alt='{_e(caption)}' src='data:image/png;base64,{data}'>"
                         f"<figcaption>{_e(Path(path).name)}: {_e(caption)}</figcaption></figure>")
    if env:
        parts.append("<h2>Environment</h2><table id=environment>")
        parts += [f"<tr><th>{_e(k)}</th><td>{_e(v)}</td></tr>" for k, v in env.items()]
        parts.append("</table>")
    parts.append("</body></html>\n")
    return "\n".join(parts)


def write_run_report(
    rec: Any,
    cal: GyroCalibration,
    extracted: Any,
    out_dir: str | Path,
    *,
    title: str,
    verification: Mapping[str, Any] | None = None,
    html_path: str | Path | None = None,
    force: bool = False,
) -> list[tuple[Path, str]]:
    """Draw the plots of a run into ``out_dir`` and write ``html_path`` (default
    ``out_dir/report.html``) around them.

    Nothing is written if ``report.html`` or a plot exists and ``force`` is false; every file is
    written atomically. Needs matplotlib (the ``plot`` extra).

    Returns
    -------
    list of (Path, str)
        The plots with their descriptions, then the page.
    """
    from gyrocal.kit.fileio import atomic_write_text, refuse_existing
    from gyrocal.kit.report_plots import write_report

    html_path = Path(out_dir) / "report.html" if html_path is None else Path(html_path)
    refuse_existing([html_path], force=force)
    written = write_report(rec, cal, extracted, out_dir, force=force)
    page = render_html(cal, title=title, plots=written, truth=rec.truth,
                       verification=verification, env=environment(rec.manifest))
    atomic_write_text(html_path, page, force=force)
    return [*written, (html_path, "the whole report as one self-contained page")]


def write_optional_report(rec: Any, cal: GyroCalibration, extracted: Any, out_dir: Path, *,
                          title: str, html_path: Path, force: bool = False,
                          written_already: str = "calibration.json") -> str | None:
    """:func:`write_run_report` as an optional output of a run whose calibration is already
    written: a failure (a plot that cannot be drawn, a full disk) is returned as a warning that
    says what was written and how to draw the report again, never raised, so that the
    calibration and its history entry are kept. None when the report was written."""
    try:
        write_run_report(rec, cal, extracted, out_dir, title=title, html_path=html_path,
                         force=force)
    except Exception as exc:
        partial = " (some of its plots may be there)" if Path(out_dir).exists() else ""
        return (f"the report was not written ({str(exc)[:300] or type(exc).__name__}); "
                f"{written_already} and the recording are complete{partial}: `gyrocal report` "
                "draws the report again")
    return None
