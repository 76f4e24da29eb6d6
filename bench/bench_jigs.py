"""The jigs side by side (issue 29): general-motion error, bias error and jig time per jig kind.

One row per jig kind of :data:`gyrocal.kit.jig_kinds.JIG_KINDS` and per source of data:

``emulator``
    ``gyrocal calibrate --sim [--jig KIND] --sim-seed S`` at its defaults (the realistic
    emulated MPU-9250: ±2 % cross-axis, g-sensitivity, coloured noise, ...); the gimbal runs its
    default protocol (the full model), the hand jig the emulated hand
    (:mod:`gyrocal.drivers.emulated.hand`).
``independent``
    Recordings made by generators that share nothing with the code under test: the gimbal's
    ``tests/kit/contract_fullmodel_recording.py`` (scipy rotations, a skewed gimbal, 60° poses,
    ±2 % cross-axis), the hand's ``tests/calib/hand_truth.py`` (scipy rotations, a hand's speed
    family and wobble of its own, ±2 % cross-axis, the MPU-9250's noise and up to its 0.1 °/s/g
    g-sensitivity), each estimated by ``estimate_recording``.

Columns: the model written (Calibration v2 full, v1 diagonal), the RMS error of the calibrated
rate over all directions per rad/s (:func:`gyrocal.calib.design.general_motion_rms`: what no
output frame removes) and the RMS its covariance predicts (which, for a diagonal model, cannot
hold the cross-axis terms it leaves out), the bias error (RMS over the axes, the zero-g bias)
beside its σ, for a diagonal model its scales' error in their σ against the scales it converges
to on that sensor and those turn axes (:func:`diagonal_truth`), the jig time (the recording's
span) and the verdicts that passed. imucal's real Ferraris session (when its excerpt is
present) follows: gyrocal's result beside imucal's own.

Usage: ``python -m bench jigs [--seeds=N]`` (N sensors per row, default 2; the emulator rows cost
about 40 CPU s per gimbal run and 10 per hand run).
"""

from __future__ import annotations

import io
import tempfile
from contextlib import redirect_stderr, redirect_stdout
from pathlib import Path

import numpy as np

from bench.table import print_table


def diagonal_truth(C: np.ndarray, axes: np.ndarray) -> np.ndarray:
    """The scales a diagonal model fitted to turns about ``axes`` (rows, unit, sensor frame)
    converges to on the sensor ``m = C ω − b``: each turn's free axis ``k ∘ (C u)`` is a unit
    vector, ``Σ_j k_j² (C u)_j² = 1`` (the paper's squared-norm equation, Eq. 3), linear in
    ``k²``."""
    v = (np.asarray(axes, float) @ np.asarray(C, float).T) ** 2  # row a: (C u_a)_j²
    return np.sqrt(np.linalg.solve(v, np.ones(3)))


def _scores(fit, C: np.ndarray, b: np.ndarray, jig_s: float,
            axes: np.ndarray | None = None) -> dict:
    from gyrocal.calib.design import general_motion_rms, predicted_general_motion_rms

    M = fit.matrix if fit.matrix is not None else np.diag(fit.scale)
    sd = np.sqrt(np.diag(fit.covariance))
    sd_b = sd[-3:]
    z = float("nan")
    if fit.matrix is None and axes is not None:
        z = float(np.sqrt(np.mean(((fit.scale - diagonal_truth(C, axes)) / sd[:3]) ** 2)))
    return {"z_scale": z, "model": "v2 full" if fit.matrix is not None else "v1 diagonal",
            "gm": general_motion_rms(M, fit.bias, C, b),
            "gm_pred": predicted_general_motion_rms(fit.covariance),
            "bias": float(np.sqrt(np.mean((fit.bias - b) ** 2))),
            "bias_sd": float(np.sqrt(np.mean(sd_b**2))), "jig_s": jig_s,
            "ok": bool(fit.consistency is None or fit.consistency.ok)}


def _emulator(kind: str, seed: int) -> dict:
    from gyrocal.kit.cli import main
    from gyrocal.kit.pipeline import estimate_recording
    from gyrocal.kit.recording import load_recording

    with tempfile.TemporaryDirectory() as tmp:
        d = Path(tmp) / "run"
        with redirect_stdout(io.StringIO()), redirect_stderr(io.StringIO()):
            main(["calibrate", "--sim", "--jig", kind, "--sim-seed", str(seed), "--out", str(d),
                  "--quiet", "--no-report"])
        rec = load_recording(d / "recording")
        fit = estimate_recording(rec).fit
    t = rec.truth
    C = np.diag(1 / np.asarray(t["scale"])) @ np.asarray(t["misalignment"])
    return _scores(fit, C, np.asarray(t["bias"]), float(rec.imu_t[-1] - rec.imu_t[0]),
                   t.get("box_axes"))


def _gimbal_recording(path: Path, seed: int) -> tuple[np.ndarray, np.ndarray, None]:
    """The gimbal's independent recording at ``path``; its ``(C, b, None)``."""
    from tests.kit.contract_fullmodel_recording import write_recording

    truth = write_recording(path, seed=seed)
    return np.diag(1 / truth["scale"]) @ truth["misalignment"], truth["bias"], None


def _hand_recording(path: Path, seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The hand jig's independent recording at ``path`` (±2 % cross-axis, the MPU-9250's noise
    and up to its 0.1 °/s/g g-sensitivity); its ``(C, b, turn axes)``."""
    from gyrocal.kit.recording import RecordingWriter
    from tests.calib import hand_truth as ht

    rng = np.random.default_rng([seed, 29])
    C, b, mount = ht.draw_sensor(rng, cross=0.02)
    G = rng.uniform(-1, 1, (3, 3)) * np.radians(0.1)  # MPU-9250: 0.1 °/s/g
    t, m, acc, _ = ht.hand_session(rng, C, b, mount, noise=1.75e-3, g_sensitivity=G)
    with RecordingWriter(path, sensor={"model": "mpu9250", "odr_hz": 100.0},
                         gimbal={"motors": []}, protocol={"name": "hand"},
                         extra={"jig": {"kind": "hand"}}, accel=True) as w:
        w.append_imu(t, m, np.full(t.size, np.nan), accel=acc)
        w.finish()
    return C, b, mount.T  # the box axes in the sensor frame, rows


#: Each jig kind's independent generator (a kind without one gets a row that says so).
INDEPENDENT = {"gimbal": _gimbal_recording, "hand": _hand_recording}


def _independent(kind: str, seed: int) -> dict:
    from gyrocal.kit.pipeline import estimate_recording
    from gyrocal.kit.recording import load_recording

    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "rec"
        C, b, axes = INDEPENDENT[kind](path, seed)
        rec = load_recording(path)
        fit = estimate_recording(rec).fit
    return _scores(fit, C, b, float(rec.imu_t[-1] - rec.imu_t[0]), axes)


def _real_imucal() -> None:
    from bench import real_corpus as rc
    from gyrocal.kit.pipeline import estimate_recording
    from gyrocal.kit.recording import load_recording

    if rc.locate("imucal") is None:
        print(f"(imucal: {rc.missing_reason('imucal')})")
        return
    s = rc.load("imucal")
    own = rc.imucal_ferraris_gyro(s)
    with tempfile.TemporaryDirectory() as tmp:
        rc.write_recording(s, Path(tmp) / "rec")
        est = estimate_recording(load_recording(Path(tmp) / "rec"))
    fit = est.fit
    sd = np.sqrt(np.diag(fit.covariance))
    rows = [[f"scale {a}", f"{fit.scale[j]:.6f}", f"{sd[j]:.1e}", f"{own.scale[j]:.6f}",
             f"{fit.scale[j] - own.scale[j]:+.1e}"] for j, a in enumerate("xyz")]
    rows += [[f"bias {a} rad/s", f"{fit.bias[j]:.6f}", f"{sd[3 + j]:.1e}",
              f"{-np.radians(own.b[j]):.6f}", f"{fit.bias[j] + np.radians(own.b[j]):+.1e}"]
             for j, a in enumerate("xyz")]
    print("imucal's real Ferraris session (hand jig: 3 turns, 13 rests), gyrocal beside "
          "imucal 2.6.0's FerrarisCalibration (its equations, bench.real_corpus."
          "imucal_ferraris_gyro):")
    print_table(["parameter", "gyrocal", "σ", "imucal", "difference"], rows)
    c = fit.consistency
    angles = []
    for j, m in enumerate(sorted(fit.axes)):
        r = own.R[:, j] / np.linalg.norm(own.R[:, j])
        angles.append(np.degrees(np.arccos(min(1.0, abs(float(fit.axes[m] @ r))))))
    print(f"gyrocal's verdict: {c.verdict} (χ² {c.chi2:.1f} on {c.dof} dof); each turn's axis "
          "against the direction imucal's R_g column gives it: "
          + ", ".join(f"{a:.2f}°" for a in angles) + "\n")


def _single_servo_rows(seeds: int) -> list[list]:
    """The single-servo jig's rows (:func:`bench.bench_single_servo.single_servo_rows`, the V-block
    edges and the faces alone) in this table's columns; what it does not measure is blank."""
    from bench.bench_single_servo import single_servo_rows

    return [["single-servo", f"{r['source']} ({r['protocol']})", r["sensors"], r["method"],
             f"{r['gm']:.1e}", "", f"{r['bias']:.1e}", "", "-",
             f"{r['jig_s'] if r['jig_s'] is not None else r['plan_s']:.0f}",
             f"{r['consistent']}/{r['sensors']}"] for r in single_servo_rows(list(range(seeds)))]


def main(argv: list[str]) -> None:
    from gyrocal.kit.jig_kinds import JIG_KINDS

    seeds = next((int(a.split("=", 1)[1]) for a in argv if a.startswith("--seeds=")), 2)
    rows = []
    for kind in JIG_KINDS:
        if kind == "single-servo":  # its own runs: the seats' emulator and generator
            rows += _single_servo_rows(seeds)
            continue
        for source, fn in (("emulator", _emulator), ("independent", _independent)):
            if source == "independent" and kind not in INDEPENDENT:
                rows.append([kind, source, 0, "no independent generator yet (INDEPENDENT)",
                             "", "", "", "", "", "", ""])
                continue
            rs = [fn(kind, s) for s in range(seeds)]
            rows.append([kind, source, len(rs), rs[0]["model"],
                         f"{np.sqrt(np.mean([r['gm'] ** 2 for r in rs])):.1e}",
                         f"{np.sqrt(np.mean([r['gm_pred'] ** 2 for r in rs])):.1e}",
                         f"{np.sqrt(np.mean([r['bias'] ** 2 for r in rs])):.1e}",
                         f"{np.sqrt(np.mean([r['bias_sd'] ** 2 for r in rs])):.1e}",
                         f"{np.sqrt(np.nanmean([r['z_scale'] ** 2 for r in rs])):.2f}"
                         if rs[0]["model"].startswith("v1") else "-",
                         f"{np.mean([r['jig_s'] for r in rs]):.0f}",
                         f"{sum(r['ok'] for r in rs)}/{len(rs)}"])
    print_table(["jig", "data", "runs", "model", "general-motion RMS err per rad/s",
                 "predicted (own σ)", "bias err RMS rad/s", "bias σ", "v1 scale err/σ RMS",
                 "jig time s", "verdict ok"], rows)
    print("(general-motion error: over all directions at 1 rad/s, what no output frame "
          "removes; a diagonal model's includes the ±2 % cross-axis terms it cannot determine, "
          "which its own σ does not predict. v1 scale err/σ: against the scales a diagonal "
          "model converges to on that sensor and those turn axes, diagonal_truth)\n")
    _real_imucal()
