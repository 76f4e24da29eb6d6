"""One self-contained HTML page per run: what a user reads or sends (``gyrocal report``).

The page reads from the top: a summary (the verdict, the model, its largest cross-axis term, the
mount's misalignment, what to do next); the full model that was fitted with its standard
deviations (the gyro's matrix and bias, its g-sensitivity, the accelerometer); for a simulated
recording the error against its truth (:func:`gyrocal.kit.report.error_against_truth`, the
terminal's own numbers); the verification's verdict in words and its errors in rad/s; the noise
figures measured on the rests; the turn axes; the plots, with the ten or so per-turn plots
folded behind a ``<details>`` element; the environment. Every plot is inline as a base64 PNG, so
the one file is the whole report: no network, no neighbouring files, no scripts. Every text
that comes from a file or a user is HTML-escaped.
"""

from __future__ import annotations

import base64
import html
import math
import platform
import sys
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from importlib import metadata
from pathlib import Path
from typing import Any

import numpy as np

from gyrocal.calib.model import GyroCalibration
from gyrocal.kit import __version__
from gyrocal.kit.jig_kinds import DEFAULT_JIG, JIG_KINDS, axis_label
from gyrocal.kit.report import TruthError, error_against_truth, inconsistency_causes

__all__ = ["NoiseFigures", "environment", "gyro_noise", "render_html", "write_run_report"]

_CSS = """
body{font-family:system-ui,sans-serif;max-width:1100px;margin:1.5em auto;padding:0 1em;color:#222}
h1{font-size:1.5em;margin-bottom:.2em}h2{font-size:1.2em;border-bottom:1px solid #ccc;
padding-bottom:.2em;margin-top:1.4em}h3{font-size:1em;margin:1em 0 .3em}
table{border-collapse:collapse;margin:.4em 0}td,th{border:1px solid #ccc;padding:.2em .55em}
td.n{text-align:right;font-variant-numeric:tabular-nums}th{background:#f3f3f3;text-align:left}
td.fixed{color:#999}.ok{color:#1a7f37;font-weight:bold}.bad{color:#b42318;font-weight:bold}
.note{color:#555;font-size:.92em;margin:.3em 0}#summary{background:#f6f8fa;border:1px solid #d0d7de;
padding:.6em 1em;border-radius:6px}#summary th{background:none;border:0;vertical-align:top;
width:11em;padding:.25em .5em .25em 0}#summary td{border:0;padding:.25em 0}#summary table{margin:0}
#summary ol{margin:0;padding-left:1.3em}code{background:#eef;padding:0 .2em}
figure{margin:1em 0}figure img{max-width:100%;border:1px solid #ddd}figcaption{color:#555}
details{margin:1em 0}summary{cursor:pointer;font-weight:bold}
"""

RAD2DEG = 180.0 / math.pi


def _e(x: Any) -> str:
    return html.escape(str(x))


def _version(dist: str) -> str:
    try:
        return metadata.version(dist)
    except metadata.PackageNotFoundError:
        return "not installed"


# ------------------------------------------------------------------ environment
#: How the recording manifest's ``sensor`` fields read on the page (formats.md, the manifest's
#: ``sensor`` object): key, label, text of the value; other keys are shown as they are named.
_SENSOR_FIELDS: tuple[tuple[str, str, Callable[[Any], str]], ...] = (
    ("model", "chip", str),
    ("odr_hz", "sample rate", lambda v: f"{float(v):g} Hz"),
    ("full_scale_dps", "gyro range", lambda v: f"±{float(v):g} °/s"),
    ("sensitivity_rad_s_per_lsb", "gyro resolution",
     lambda v: f"{float(v):.4g} rad/s ({float(v) * RAD2DEG:.4g} °/s) per count"),
    ("accel_full_scale_g", "accelerometer range", lambda v: f"±{float(v):g} g"),
    ("accel_sensitivity_m_s2_per_lsb", "accelerometer resolution",
     lambda v: f"{float(v):.4g} m/s² per count"),
    ("i2c_bus", "I²C bus", lambda v: f"/dev/i2c-{v}"),
    ("i2c_address", "I²C address", lambda v: f"0x{int(v):02x}"),
)


def _plain(v: Any) -> str:
    """A manifest value as text: mappings as ``key value; ...``, lists comma-separated."""
    if isinstance(v, Mapping):
        return "; ".join(f"{str(k).replace('_', ' ')} {_plain(x)}" for k, x in v.items())
    if isinstance(v, (list, tuple)):
        return ", ".join(_plain(x) for x in v)
    if isinstance(v, float):
        return f"{v:.6g}"
    return str(v)


def _sensor_rows(sensor: Mapping[str, Any]) -> list[tuple[str, str]]:
    known = {k for k, _, _ in _SENSOR_FIELDS}
    rows = []
    for key, label, text in _SENSOR_FIELDS:
        if key in sensor and sensor[key] is not None:
            try:
                rows.append((label, text(sensor[key])))
            except (TypeError, ValueError):
                rows.append((label, _plain(sensor[key])))
    rows += [(str(k).replace("_", " "), _plain(v)) for k, v in sensor.items()
             if k not in known and v is not None]
    return rows


def _protocol_text(p: Mapping[str, Any]) -> str:
    parts = [str(p.get("name", "?"))]
    if isinstance(p.get("turns"), (int, float)) and isinstance(p.get("speed"), (int, float)):
        parts.append(f"{p['turns']:g} turn(s) each way at {p['speed'] * RAD2DEG:.0f} °/s")
    if p.get("poses"):
        parts.append(f"{len(p['poses'])} gimbal poses for the cross-axis terms")
    if isinstance(p.get("planned_jig_time_s"), (int, float)):
        parts.append(f"about {p['planned_jig_time_s']:.0f} s of jig time")
    return ", ".join(parts)


def environment(manifest: Mapping[str, Any] | None = None) -> dict[str, str]:
    """Versions, platform, chip, jig and protocol of a run, as label → text (one fact a row)."""
    env = {
        "gyrocal": __version__,
        "Python": sys.version.split()[0],
        "numpy": _version("numpy"),
        "scipy": _version("scipy"),
        "dynamixel-sdk": _version("dynamixel-sdk"),
        "platform": f"{platform.system()} {platform.release()} ({platform.machine()})",
    }
    m = manifest or {}
    sensor = m.get("sensor")
    if isinstance(sensor, Mapping):
        env.update(_sensor_rows(sensor))
    for mo in (m.get("gimbal") or {}).get("motors") or []:
        if isinstance(mo, Mapping):
            env[f"servo {mo.get('id')}"] = (f"{mo.get('model', 'model unknown')}, turns about "
                                            f"the sensor's {mo.get('axis', '?')} axis")
    if isinstance(m.get("protocol"), Mapping):
        env["protocol"] = _protocol_text(m["protocol"])
    site = m.get("site")
    if isinstance(site, Mapping) and isinstance(site.get("gravity_m_s2"), (int, float)):
        env["local gravity"] = (f"{site['gravity_m_s2']:.5f} m/s² "
                                f"({site.get('gravity_from', 'source not given')})")
    if m.get("created"):
        env["recorded"] = str(m["created"])
    if "complete" in m and not m["complete"]:
        env["recording"] = "INCOMPLETE (the run was interrupted)"
    return env


# ------------------------------------------------------------------ noise
@dataclass(frozen=True)
class NoiseFigures:
    """White-noise densities measured on a recording's rests (continuous time, per axis).

    Attributes
    ----------
    gyro, gyro_std : ndarray (3,)
        rad/s/√Hz (the angle random walk ``N``) and its standard deviation.
    tau_s : float
        The averaging time it was read at, s.
    """

    gyro: np.ndarray
    gyro_std: np.ndarray
    tau_s: float


def gyro_noise(rec: Any, extracted: Any) -> NoiseFigures | None:
    """The gyro's white-noise density on the recording's rest windows, by the estimator the
    accelerometer's density uses (:func:`gyrocal.calib.accel.white_noise_density`: the Allan
    variance at ``τ`` of consecutive block means, ``σ²(τ) = N²/τ``, IEEE Std 952-1997 Annex C);
    None when the rests are too short for it."""
    from gyrocal.calib.accel import white_noise_density
    from gyrocal.calib.errors import CalibInputError

    spans = [(w.corners[0], w.corners[3]) for w in extracted.rests]
    if not spans:
        return None
    try:
        density, std, tau, _ = white_noise_density(rec.imu_t, rec.imu_rate, spans)
    except CalibInputError:
        return None
    return NoiseFigures(density, std, tau)


# ------------------------------------------------------------------ pieces of the page
def _pm(x: float, s: float, fmt: str = ".6f", sfmt: str = ".1e") -> str:
    if not math.isfinite(s):
        return f"{x:{fmt}}"
    return f"{x:{fmt}} ± {s:{sfmt}}"


def _largest_cross_axis(cal: GyroCalibration) -> tuple[int, int] | None:
    """``(row, column)`` of the largest off-diagonal entry of ``A`` in size, None for the
    diagonal model."""
    if cal.matrix is None:
        return None
    off = np.abs(np.asarray(cal.matrix)) * (1 - np.eye(3))
    j, i = np.unravel_index(int(np.argmax(off)), off.shape)
    return int(j), int(i)


def _cross_axis_text(cal: GyroCalibration, jig: str) -> str:
    where = _largest_cross_axis(cal)
    if where is None:
        from gyrocal.kit.pipeline import datasheet_cross_axis

        allowed = datasheet_cross_axis(cal.sensor.get("model"))
        size = (f"its datasheet allows up to ±{allowed * 100:g} %" if allowed else
                "MEMS datasheets allow a few %")
        return (f"<span class=bad>not calibrated</span>: this diagonal model has no cross-axis "
                f"terms ({_e(size)}). {_e(JIG_KINDS[jig].full_model)}")
    j, i = where
    a = float(np.asarray(cal.matrix)[j, i])
    s = float(np.asarray(cal.matrix_std)[j, i]) if cal.matrix_std is not None else math.nan
    return (f"A<sub>{'xyz'[j]}{'xyz'[i]}</sub> = {_pm(a, s, '+.4f', '.1e')}: the calibrated "
            f"{'xyz'[j]} rate takes {a * 100:+.2f} % of the {'xyz'[i]} reading")


def _axis_name(jig: str, motor: Any) -> str:
    """A calibration's ``axes`` key (a motor ID) as the jig names it (:func:`axis_label`)."""
    try:
        return axis_label(jig, int(motor))
    except (TypeError, ValueError):
        return f"motor {motor}"


def _misalignment_text(cal: GyroCalibration, jig: str) -> str:
    if not cal.axes:
        return "not estimated (this calibration has no turn axes)"
    worst = max(cal.axes.items(), key=lambda kv: float(kv[1]["misalignment_deg"]))
    low = min(float(v["misalignment_deg"]) for v in cal.axes.values())
    m, info = worst
    return (f"the turn axes are {low:.2f}°–{float(info['misalignment_deg']):.2f}° off the "
            f"sensor's axes (largest: {_e(_axis_name(jig, m))} about {_e(info['nearest'])}, "
            f"{float(info['misalignment_deg']):.2f}° ± {float(info['std_deg']):.3f}°); the fit "
            "estimates the mount, so this needs no correction unless it is large")


def _consistency_text(c: Any, what: str = "") -> str:
    if c is None:
        return f"{what}consistency not tested (no redundant observations)"
    cls = "ok" if c.ok else "bad"
    # the rule of gyrocal.calib.dispersion: consistent, consistent with scatter (σ widened), or
    # not consistent with its reason
    word = c.verdict if hasattr(c, "verdict") else ("consistent" if c.ok else "not consistent")
    return (f"{what}<span class={cls}>{_e(word)}</span>: residuals against the measured noise "
            f"(χ² = {c.chi2:.1f} on {c.dof} dof, p = {c.p_value:.3g})")


def _model_name(cal: GyroCalibration) -> str:
    if cal.matrix is None:
        return ("diagonal model g = k ∘ (m + b) (Calibration v1): three scale factors and "
                "three biases")
    g = " + G f" if cal.g_sensitivity is not None else ""
    return (f"full model g = A (m + b{g}) (Calibration v2): a 3×3 matrix with the cross-axis "
            f"terms, three biases" + (", g-sensitivity G" if g else ""))


def _next_steps(cal: GyroCalibration, verification: Any, calibration: str | None,
                simulated: bool, jig: str) -> list[str]:
    c = cal.consistency
    path = _e(calibration) if calibration else "CAL"
    steps = []
    if c is not None and not c.ok:
        steps.append(_e(inconsistency_causes(cal)))
    if verification is not None and not verification.ok:
        steps.append("the verification failed: the model does not hold for this sensor or jig "
                     "(a diagonal calibration cannot correct cross-axis terms: calibrate the full "
                     "model), or the sensor changed since; calibrate again")
    if calibration is None:
        steps.append("this page's calibration was estimated from the recording and not saved: "
                     "<code>gyrocal estimate RECORDING --out calibration.json</code> writes one")
    if verification is None and jig != "gimbal":
        steps.append(f"gyrocal verify turns the gimbal's three servos against their encoders, "
                     f"which the {_e(jig)} jig does not have: check this calibration on a second "
                     f"{_e(jig)} session (calibrate again, compare the two within their σ) or on "
                     "a gimbal")
    elif verification is None:
        sim = " --sim --sim-seed S" if simulated else ""
        steps.append(f"verify it on fresh turns: <code>gyrocal verify {path}{sim} --json &gt; "
                     "verification.json</code>" + (" (S: this run's seed)" if simulated else "")
                     + f", then <code>gyrocal report RECORDING {path} --out DIR --verification "
                     "verification.json</code> puts its verdict on this page")
    steps.append(f"load it where it is used: <code>gyrocal export {path} --format FORMAT</code> "
                 "(<code>gyrocal export --help</code> lists the flight stacks and tools)")
    return steps


def _summary(cal: GyroCalibration, err: TruthError | None, verification: Any,
             calibration: str | None, jig: str) -> str:
    rows = [("verdict", _consistency_text(cal.consistency, "the fit is "))]
    if verification is not None:
        word = ("<span class=ok>passed</span>" if verification.ok
                else "<span class=bad>FAILED</span>")
        rows.append(("verification", f"{word}: {_e(verification.verdict())}"))
    rows.append(("model", f"{_e(_model_name(cal))}; fitted by {_e(cal.method)} in "
                          f"{cal.iterations} iterations"))
    if cal.model_choice is not None:
        rows.append(("model choice", _e(cal.model_choice.sentence())))
    rows.append(("largest cross-axis term", _cross_axis_text(cal, jig)))
    rows.append(("misalignment", _misalignment_text(cal, jig)))
    if cal.g_sensitivity is not None:
        e = cal.g_rate_error_per_g
        rows.append(("g-sensitivity", f"fitted: up to {e:.2g} rad/s ({e * RAD2DEG:.2g} °/s) per g "
                                      "of specific force on a calibrated rate"))
    acc = cal.accelerometer
    rows.append(("accelerometer", "not calibrated in this run" if acc is None else
                 f"calibrated on {acc.rests} still windows, "
                 + _consistency_text(acc.consistency)))
    if err is not None:
        worst = _worst_truth_error(err)
        rows.append(("against the simulated truth",
                     f"largest error {worst[1]:.2f} σ ({_e(worst[0])}); "
                     "within about 3 σ is what the noise explains"))
    steps = "".join(f"<li>{s}</li>" for s in _next_steps(
        cal, verification, calibration, err is not None, jig))
    rows.append(("what to do next", f"<ol>{steps}</ol>"))
    body = "".join(f"<tr><th>{_e(k)}</th><td>{v}</td></tr>" for k, v in rows)
    return f"<section id=summary><table>{body}</table></section>"


def _worst_truth_error(err: TruthError) -> tuple[str, float]:
    cands = [(f"bias {'xyz'[j]}", abs(float(v))) for j, v in enumerate(err.bias)]
    if err.matrix is not None:
        j, i = np.unravel_index(int(np.argmax(np.abs(err.matrix))), (3, 3))
        cands.append((f"A_{'xyz'[j]}{'xyz'[i]}", abs(float(err.matrix[j, i]))))
    if err.scale is not None:
        cands += [(f"scale {'xyz'[j]}", abs(float(v))) for j, v in enumerate(err.scale)]
    return max(cands, key=lambda c: c[1])


def _matrix_table(tid: str, A: np.ndarray, S: np.ndarray, bias: np.ndarray | None,
                  bias_std: np.ndarray | None, unit: str, head: str = "A") -> str:
    """Rows x, y, z of a 3×3 matrix ± std (σ = 0: fixed by the frame), then a bias ± std."""
    cols = "".join(f"<th>{head}<sub>j{c}</sub></th>" for c in "xyz")
    rows = [f"<tr><th>row j</th>{cols}" + (f"<th>bias, {_e(unit)}</th>" if bias is not None
                                         else "") + "</tr>"]
    for j, ax in enumerate("xyz"):
        cells = []
        for i in range(3):
            if S[j, i] == 0:
                cells.append(f"<td class='n fixed'>{A[j, i]:.6f} (fixed)</td>")
            else:
                cells.append(f"<td class=n>{_pm(float(A[j, i]), float(S[j, i]))}</td>")
        b = "" if bias is None else f"<td class=n>{_pm(float(bias[j]), float(bias_std[j]))}</td>"  # type: ignore[index]
        rows.append(f"<tr><th>{ax}</th>{''.join(cells)}{b}</tr>")
    return f"<table id={tid}>" + "".join(rows) + "</table>"


def _gyro_model(cal: GyroCalibration) -> str:
    parts = ["<h3>Gyro</h3>"]
    if cal.matrix is not None:
        S = (np.asarray(cal.matrix_std) if cal.matrix_std is not None
             else np.full((3, 3), np.nan))
        aligned = cal.frame == "accel-x-xy"
        where = ("the accelerometer's frame (x along its x axis, y in its x-y plane)" if aligned
                 else "the gyro's own frame: x along its x axis, y in its x-y plane, so the "
                      "entries above the diagonal are 0 by definition (fixed)")
        parts.append(f"<p>g = A (m + b{' + G f' if cal.g_sensitivity is not None else ''}), "
                     f"rad/s; frame {_e(cal.frame)}: {where}. Row j of A gives the calibrated "
                     "rate about j from the three readings.</p>")
        parts.append(_matrix_table("result", np.asarray(cal.matrix), S, np.asarray(cal.bias),
                                   np.asarray(cal.bias_std), "rad/s"))
    else:
        parts.append("<p>g = k ∘ (m + b), rad/s (paper Eq. 1): each axis scaled on its own.</p>")
        rows = ["<tr><th>axis</th><th>scale k</th><th>bias b, rad/s</th></tr>"]
        rows += [f"<tr><th>{ax}</th><td class=n>{_pm(cal.scale[j], cal.scale_std[j])}</td>"
                 f"<td class=n>{_pm(cal.bias[j], cal.bias_std[j])}</td></tr>"
                 for j, ax in enumerate("xyz")]
        parts.append("<table id=result>" + "".join(rows) + "</table>")
    parts.append(f"<p id=verdict>{_consistency_text(cal.consistency)}</p>")
    if cal.temperature_c is not None:
        parts.append(f"<p class=note>mean die temperature {cal.temperature_c:.1f} °C"
                     + ("; a temperature model is attached" if cal.temperature_model is not None
                        else "") + "</p>")
    if cal.g_sensitivity is not None:
        G = np.asarray(cal.g_sensitivity["matrix"], dtype=float)
        GS = cal.g_sensitivity.get("matrix_std")
        GS = np.full((3, 3), np.nan) if GS is None else np.asarray(GS, dtype=float)
        parts.append("<h3>g-sensitivity</h3><p>G, rad/s per g of specific force f (the unit "
                     "vector along gravity, as the encoders place it): a still sensor reads "
                     "−(b + G f).</p>")
        parts.append(_matrix_table("g-sensitivity", G, GS, None, None, "", "G"))
    return "".join(parts)


def _accel_model(acc: Any) -> str:
    std = acc.std
    S = np.zeros((3, 3))
    S[np.tril_indices(3)] = std[:6]
    return ("<h3>Accelerometer</h3><p>f = A (a + b), m/s²; frame accel-x-xy (x along its x "
            f"axis, y in its x-y plane); fitted on {acc.rests} still windows against gravity "
            f"{acc.gravity:.5f} m/s².</p>"
            + _matrix_table("accelerometer", np.asarray(acc.matrix), S, np.asarray(acc.bias),
                            std[6:], "m/s²")
            + f"<p>{_consistency_text(acc.consistency)}</p>")


def _truth_section(err: TruthError) -> str:
    def zs(v: np.ndarray) -> str:
        return " ".join(f"{x:+.2f}" for x in v)

    rows = []
    if err.matrix is not None:
        rows.append(("gyro matrix A, largest |err/σ|", f"{err.matrix_max:.2f}"))
    elif err.scale is not None:
        rows.append(("gyro scale x y z, err/σ", zs(err.scale)))
    else:
        rows.append(("gyro matrix A", _e(err.matrix_note)))
    rows.append(("gyro bias x y z, err/σ", zs(err.bias)))
    if err.general_motion is not None:
        rows.append(("gyro general-motion error, RMS per rad/s", f"{err.general_motion:.2g}"))
    if err.accel_bias is not None:
        rows.append(("accelerometer matrix, largest |err/σ|", f"{err.accel_matrix_max:.2f}"))
        rows.append(("accelerometer bias x y z, err/σ", zs(err.accel_bias)))
    body = "".join(f"<tr><th>{k}</th><td class=n>{v}</td></tr>" for k, v in rows)
    return ("<h2>Error against the simulated truth</h2><p>Each estimate minus the emulated "
            "sensor's true value, in units of its own standard deviation (the numbers the "
            "terminal prints); within about ±3 is what the noise explains.</p>"
            f"<table id=truth>{body}</table>")


def _verification(v: Any) -> str:
    word = "<span class=ok>passed</span>" if v.ok else "<span class=bad>FAILED</span>"
    from gyrocal.kit.verify import FLAG_RATIO, KINDS

    head = ["before", "diagonal", "full", "predicted", *KINDS.values()]
    rows = ["<tr><th>axis</th>" + "".join(f"<th>{_e(h)}</th>" for h in head) + "</tr>"]
    for j, ax in enumerate("xyz"):
        vals = [v.rms_before[j], v.rms_diagonal[j], v.rms_full[j], v.rms_predicted[j],
                *(v.rms_by_kind[k][j] for k in KINDS)]
        rows.append(f"<tr><th>{ax}</th>" + "".join(
            f"<td class=n>{x:.5f}</td>" if np.isfinite(x) else "<td class=n>n/a</td>"
            for x in vals) + "</tr>")
    used = sum(v.blocks[k] for k in KINDS)
    after = "full" if v.full else "diagonal"
    return (f"<p id=verification-verdict>The verification {word}: every axis's RMS error must "
            f"stay within {FLAG_RATIO:g} times what the calibration's own uncertainty predicts. "
            f"{_e(v.verdict())}.</p>"
            f"<p>RMS rate error against the encoder reference, rad/s, over {used} blocks of "
            f"{v.block_s:g} s (" + ", ".join(f"{v.blocks[k]} {_e(KINDS[k])}" for k in KINDS)
            + f"; servo axes from the {_e(v.reference)}):</p>"
            "<table id=verification>" + "".join(rows) + "</table>"
            "<p class=note>before: raw readings; diagonal: scale factors and bias only; full: "
            f"with the cross-axis terms; predicted: what the uncertainty predicts for "
            f"'{after}'; the last three columns split '{after}' by what the jig was doing. "
            f"{v.blocks['ramp_excluded']} blocks on acceleration ramps are left out (there the "
            "gyro's filter delay against the encoder is an error of timing, not of the "
            "calibration).</p>")


def _noise(noise: NoiseFigures | None, acc: Any) -> str:
    have_acc = acc is not None and acc.noise_density is not None
    if noise is None and not have_acc:
        return ("<h2>Noise</h2><p>not measured: the rests are too short (<code>gyrocal noise"
                "</code> on a still recording gives the full Allan deviation)</p>")
    head = "<tr><th>axis</th>"
    if noise is not None:
        head += "<th>gyro, rad/s/√Hz</th><th>gyro, °/s/√Hz</th>"
    if have_acc:
        head += "<th>accelerometer, m/s²/√Hz</th><th>accelerometer, µg/√Hz</th>"
    rows = [head + "</tr>"]
    for j, ax in enumerate("xyz"):
        r = f"<tr><th>{ax}</th>"
        if noise is not None:
            r += (f"<td class=n>{_pm(noise.gyro[j], noise.gyro_std[j], '.3e')}</td>"
                  f"<td class=n>{noise.gyro[j] * RAD2DEG:.4f}</td>")
        if have_acc:
            n = float(acc.noise_density[j])
            r += (f"<td class=n>{_pm(n, float(acc.noise_density_std[j]), '.3e')}</td>"
                  f"<td class=n>{n / 9.80665 * 1e6:.0f}</td>")
        rows.append(r + "</tr>")
    tau = noise.tau_s if noise is not None else acc.noise_tau_s
    return ("<h2>Noise</h2><p>White-noise density (the angle random walk N for the gyro), "
            "continuous time, measured on this run's rests from the Allan variance at "
            f"τ = {tau:.2g} s (σ²(τ) = N²/τ). Bias instability and rate random walk need a long "
            "still recording: <code>gyrocal noise</code>.</p>"
            "<table id=noise>" + "".join(rows) + "</table>")


def _axes(cal: GyroCalibration, jig: str) -> str:
    if not cal.axes:
        return "<p>no turn axes in this calibration</p>"
    rows = ["<tr><th>turns about</th><th>axis in the sensor frame</th><th>nearest</th>"
            "<th>misalignment</th></tr>"]
    for motor, info in sorted(cal.axes.items(), key=lambda kv: int(kv[0])):
        u = np.asarray(info["axis"], dtype=float)
        rows.append(f"<tr><td>{_e(_axis_name(jig, motor))}</td>"
                    f"<td class=n>[{u[0]:+.4f} {u[1]:+.4f} {u[2]:+.4f}]"
                    f"</td><td>{_e(info['nearest'])}</td><td class=n>"
                    f"{info['misalignment_deg']:.2f}° ± {info['std_deg']:.3f}°</td></tr>")
    return "<table id=axes>" + "".join(rows) + "</table>"


def _figure(path: str | Path, caption: str) -> str:
    data = base64.b64encode(Path(path).read_bytes()).decode("ascii")
    return (f"<figure><img alt='{_e(caption)}' src='data:image/png;base64,{data}'>"
            f"<figcaption>{_e(Path(path).name)}: {_e(caption)}</figcaption></figure>")


#: What the per-turn plots' middle panel shows at the speed ramps, said beside them.
RAMP_NOTE = (
    "In each turn's middle panel (calibrated − reference) the swings at the start and the end of "
    "the turn are the speed ramps: the gyro's low-pass filter delays its reading against the "
    "encoder by a few milliseconds, which while the servo accelerates is an error of "
    "−delay × angular acceleration (the dotted curve, with the delay fitted to the turn). It is "
    "timing, not calibration: over a window from rest to rest it integrates to zero, and the "
    "window's mean (red), the number the fit uses, is the error that counts.")


def _plots(plots: Sequence[tuple[str | Path, str]]) -> list[str]:
    turns = [(p, c) for p, c in plots if Path(p).name.startswith("turn-")]
    others = [(p, c) for p, c in plots if not Path(p).name.startswith("turn-")]
    parts = ["<h2>Plots</h2>"] + [_figure(p, c) for p, c in others]
    if turns:
        parts.append(f"<details id=turns><summary>The {len(turns)} turns, one plot each "
                     f"(the residuals above sum them up)</summary><p class=note>{_e(RAMP_NOTE)}"
                     "</p>")
        parts += [_figure(p, c) for p, c in turns]
        parts.append("</details>")
    return parts


def render_html(
    cal: GyroCalibration,
    *,
    title: str,
    plots: Sequence[tuple[str | Path, str]] = (),
    truth: Mapping[str, Any] | None = None,
    verification: Mapping[str, Any] | None = None,
    env: Mapping[str, str] | None = None,
    noise: NoiseFigures | None = None,
    calibration: str | None = None,
    jig: str = DEFAULT_JIG,
) -> str:
    """The report page as one HTML string (module docstring).

    Parameters
    ----------
    cal : GyroCalibration
    title : str
        What the run was (e.g. the recording's path).
    plots : sequence of (PNG path, caption)
        Embedded as base64 ``data:`` images, in order; the per-turn plots (``turn-*.png``)
        folded behind a ``<details>`` element.
    truth : mapping, optional
        A simulated recording's truth: adds the error against it
        (:func:`gyrocal.kit.report.error_against_truth`).
    verification : mapping, optional
        A ``gyrocal verify --json`` document.
    env : mapping, optional
        Label → text (:func:`environment`).
    noise : NoiseFigures, optional
        The gyro's noise (:func:`gyro_noise`).
    calibration : str, optional
        Where the calibration file is, for the next steps' commands (else ``CAL``, and the page
        says it was estimated and not saved).
    jig : str
        The jig the recording was made on (:data:`gyrocal.kit.jig_kinds.JIG_KINDS`): how the
        turn axes are named, what calibrates the full model, how to check the calibration.

    Raises
    ------
    InputError
        If ``verification`` is not a ``gyrocal verify --json`` document.
    """
    from gyrocal.kit.verify import Verification

    ver = None if verification is None else Verification.from_dict(verification)
    err = error_against_truth(cal, truth)
    parts = [
        "<!DOCTYPE html><html lang=en><head><meta charset=utf-8>",
        f"<title>gyrocal report: {_e(title)}</title><style>{_CSS}</style></head><body>",
        f"<h1>gyrocal calibration report</h1><p class=note>{_e(title)}</p>",
        _summary(cal, err, ver, calibration, jig),
        "<h2>The model that was fitted</h2>",
        _gyro_model(cal),
    ]
    if cal.accelerometer is not None:
        parts.append(_accel_model(cal.accelerometer))
    if err is not None:
        parts.append(_truth_section(err))
    parts.append("<h2>Verification</h2>")
    parts.append(_verification(ver) if ver is not None else
                 "<p>no verification given (<code>gyrocal verify CAL --json &gt; FILE</code>, "
                 "then <code>gyrocal report ... --verification FILE</code>)</p>")
    parts.append(_noise(noise, cal.accelerometer))
    parts += ["<h2>Turn axes</h2>", _axes(cal, jig)]
    if plots:
        parts += _plots(plots)
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
    calibration: str | None = None,
) -> list[tuple[Path, str]]:
    """Draw the plots of a run into ``out_dir`` and write ``html_path`` (default
    ``out_dir/report.html``) around them.

    Nothing is written if ``report.html`` or a plot exists and ``force`` is false, or if
    ``verification`` is not a ``gyrocal verify --json`` document; every file is written
    atomically. Needs matplotlib (the ``plot`` extra). ``calibration`` is where the calibration
    file is (:func:`render_html`).

    Returns
    -------
    list of (Path, str)
        The plots with their descriptions, then the page.
    """
    from gyrocal.kit.fileio import atomic_write_text, refuse_existing
    from gyrocal.kit.pipeline import recording_jig
    from gyrocal.kit.report_plots import write_report

    html_path = Path(out_dir) / "report.html" if html_path is None else Path(html_path)
    refuse_existing([html_path], force=force)
    if verification is not None:
        from gyrocal.kit.verify import Verification

        Verification.from_dict(verification)  # a malformed document: before anything is drawn
    written = write_report(rec, cal, extracted, out_dir, force=force)
    page = render_html(cal, title=title, plots=written, truth=rec.truth,
                       verification=verification, env=environment(rec.manifest),
                       noise=gyro_noise(rec, extracted), calibration=calibration,
                       jig=recording_jig(rec))
    atomic_write_text(html_path, page, force=force)
    return [*written, (html_path, "the whole report as one self-contained page")]


def write_optional_report(rec: Any, cal: GyroCalibration, extracted: Any, out_dir: Path, *,
                          title: str, html_path: Path, force: bool = False,
                          written_already: str = "calibration.json",
                          calibration: str | None = None) -> str | None:
    """:func:`write_run_report` as an optional output of a run whose calibration is already
    written: a failure (a plot that cannot be drawn, a full disk) is returned as a warning that
    says what was written and how to draw the report again, never raised, so that the
    calibration and its history entry are kept. None when the report was written."""
    try:
        write_run_report(rec, cal, extracted, out_dir, title=title, html_path=html_path,
                         force=force, calibration=calibration)
    except Exception as exc:
        partial = " (some of its plots may be there)" if Path(out_dir).exists() else ""
        return (f"the report was not written ({str(exc)[:300] or type(exc).__name__}); "
                f"{written_already} and the recording are complete{partial}: `gyrocal report` "
                "draws the report again")
    return None
