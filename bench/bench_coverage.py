"""Do the calibration's 95 % intervals hold the truth 95 % of the time (issue 30, "Honest σ")?

1. ``--sim``: ``--seeds=N`` (default 40) default emulated calibrations (``gyrocal calibrate
   --sim --sim-seed S``, every realism effect on, seeds ``--first`` .. ``--first + N − 1``; the
   default first seed is 0, the reported set: tune on ``--first=1000`` and up, never on the
   seeds reported). Each calibration's bias and matrix are compared with the manifest's truth
   (the matrix in the calibration's frame, :func:`gyrocal.calib.estimators.matrix_in_frame`):
   ``z = (estimate − truth) / σ``; the table gives, per parameter group, the fraction of
   ``|z| ≤ 1.96`` (95 % coverage) and the RMS of ``z`` (1 when σ is honest). The bias also
   in the white-noise σ alone (the bias σ before the bias's wander over the run was added to
   it, :mod:`gyrocal.calib.drift`: ``sqrt(bias_std² − bias_drift.run_std²)``), which is the
   ``bias_std`` the code before it wrote for the same estimate.
2. ``--independent``: the same on the independent generator's recordings
   (``tests/kit/contract_fullmodel_recording.py``, which shares no code with the emulator)
   with a bias random walk of each ``--walk`` rad/s/√s (default ``2e-6,1e-4``: the figure the
   kit assumes, and one where the walk outweighs everything else), fitted by ``gyrocal
   estimate``; the truth is the bias at the recording's middle. Besides the kit's σ (which
   assumes the chip's B and K), the bias's z with the white-noise σ plus ``K² T / 12`` of the
   generator's own K: the formula on data it did not make. ``--flicker=B`` (rad/s) adds the
   generator's flicker noise (made in the frequency domain, not the emulator's Gauss–Markov
   sum), and the truth the bias's mean over the hour from the recording's start
   (:mod:`gyrocal.calib.drift`). ``--wobble=DEG`` makes every link of the generator's gimbal
   nod by that much once per revolution (its own model, :mod:`gyrocal.calib.systematics`).
   ``--hold-band=F`` (default 1): every servo of the generator comes to rest anywhere within
   ``F`` encoder ticks about its goal's tick, a new draw at each rest, as an X-series
   position loop leaves it (``settled`` in the generator); 0 puts every servo exactly on its
   commanded angle at every rest (home on a tick's centre: no hold error at all).
   ``--ripple=F`` (default 0.05): every turn and move of the generator carries speed ripple of
   that RMS fraction of its speed, 1–20 Hz (``speed_ripple`` in the generator; the paper's
   simulation adds 5 % of the speed as rotation noise), which the gyro and the encoder both
   see; 0 turns at exactly the trapezoid's speed.

``--python=PATH`` runs the calibrations with another installation's interpreter (e.g. the
code before a change: ``--python=/work/venv-main/bin/python``); the comparison with the truth
is this installation's.

Usage: ``python -m bench coverage [--quick (3 seeds)] [--seeds=N] [--first=S] [--python=PATH]
[--independent] [--walk=K,K] [--flicker=B] [--wobble=DEG] [--hold-band=F] [--ripple=F]
[--keep=DIR]``.
``--keep=DIR`` keeps each emulated run in ``DIR/seed-S`` and, where one is there already,
re-fits its recording with ``gyrocal estimate`` instead of emulating it again (a change to the
fit's σ measured on the same runs in minutes).
"""

from __future__ import annotations

import json
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

from bench.table import pooled, print_table

_GROUPS = ("bias, white-noise σ", "bias", "matrix diagonal", "matrix off-diagonal")


def _z(cal: dict, truth: dict) -> dict[str, np.ndarray]:
    """The calibration's errors in its own σ, per parameter group."""
    from gyrocal.calib.estimators import matrix_in_frame

    sensing = np.diag(1 / np.asarray(truth["scale"])) @ np.asarray(truth["misalignment"])
    C = matrix_in_frame(sensing)
    err = np.asarray(cal["bias"]) - np.asarray(truth["bias"])
    std = np.asarray(cal["bias_std"])
    zb = err / std
    # the σ of the white noise alone (the code before the bias's wander was added to it)
    run = np.asarray((cal.get("bias_drift") or {}).get("run_std", np.zeros(3)))
    zw = err / np.sqrt(std**2 - run**2)
    with np.errstate(invalid="ignore", divide="ignore"):  # σ 0: fixed by the frame, dropped
        zm = (np.asarray(cal["matrix"]) - C) / np.asarray(cal["matrix_std"])
    diag = np.eye(3, dtype=bool)
    free = np.asarray(cal["matrix_std"]) > 0  # the frame convention fixes some terms (σ 0)
    return {"bias, white-noise σ": zw, "bias": zb, "matrix diagonal": zm[diag & free],
            "matrix off-diagonal": zm[~diag & free]}


def _refit(rec: Path) -> dict[str, np.ndarray]:
    """z of a kept recording re-fitted in this process (``gyrocal estimate``'s own path)."""
    from gyrocal.kit.pipeline import estimate_recording
    from gyrocal.kit.recording import load_recording

    recording = load_recording(rec)
    cal = estimate_recording(recording).calibration.to_dict()
    return _z(cal, recording.manifest["truth"])


def _sim_run(job: tuple[str, int, str]) -> dict[str, np.ndarray] | None:
    """One default emulated calibration of seed ``job[1]``: emulated and fitted by ``gyrocal
    calibrate --sim``, or, when ``--keep=DIR`` (``job[2]``) already holds that seed's recording,
    that recording re-fitted by ``gyrocal estimate`` (the same recording, this code's σ)."""
    python, seed, keep = job
    with tempfile.TemporaryDirectory() as tmp:
        d = Path(keep) / f"seed-{seed}" if keep else Path(tmp) / "run"
        rec = d / "recording"
        finished = (d / "calibration.json").is_file()
        if finished and python == sys.executable:  # re-fitted here: no interpreter to start
            return _refit(rec)
        if finished:  # a finished run: its recording re-fitted by the other installation
            cmd = [python, "-m", "gyrocal.kit", "estimate", str(rec), "--json"]
        else:
            cmd = [python, "-m", "gyrocal.kit", "calibrate", "--sim", "--sim-seed", str(seed),
                   "--out", str(d), "--quiet", "--no-report", "--force"]
        run = subprocess.run(cmd, capture_output=True, text=True, check=False)
        if run.returncode not in (0, 3):  # 3: not consistent, still a calibration
            print(f"# seed {seed}: exit {run.returncode}: {run.stderr[-300:]}", file=sys.stderr)
            return None
        cal = json.loads(run.stdout if cmd[3] == "estimate"
                         else (d / "calibration.json").read_text(encoding="utf-8"))
        truth = json.loads((rec / "manifest.json").read_text(encoding="utf-8"))
        return _z(cal, truth["truth"])


def _independent_run(job: tuple[str, int, float, float, float, float, float]
                     ) -> dict[str, np.ndarray] | None:
    """One recording of the independent generator with a bias random walk of ``K`` = job[2],
    fitted by ``gyrocal estimate``: z of the bias against its value at the recording's middle
    (where ``K² T / 12`` is centred) with the kit's σ, with the white-noise σ alone, and with
    the white-noise σ plus :class:`~gyrocal.calib.drift.BiasDrift` of the generator's own
    figures (B = 0, K) over the calibration's span: the formula on data it did not make."""
    from gyrocal.calib.drift import BiasDrift

    python, seed, walk, flicker, wobble, band, ripple = job
    root = Path(__file__).resolve().parent.parent
    sys.path.insert(0, str(root))
    from tests.kit.contract_fullmodel_recording import write_recording

    with tempfile.TemporaryDirectory() as tmp:
        rec = Path(tmp) / "rec"
        t = write_recording(rec, seed=seed, bias_walk=walk, bias_flicker=flicker,
                            wobble_rad=np.radians(wobble), hold_band=band, ripple=ripple)
        run = subprocess.run([python, "-m", "gyrocal.kit", "estimate", str(rec), "--json"],
                             capture_output=True, text=True, check=False)
        if run.returncode not in (0, 3):
            print(f"# seed {seed}: exit {run.returncode}: {run.stderr[-300:]}", file=sys.stderr)
            return None
        cal = json.loads(run.stdout)
        walked = np.asarray(t.get("bias_walk", np.zeros((1, 3))))
        bias = (np.asarray(t["bias"]) + walked[walked.shape[0] // 2]
                + np.asarray(t.get("bias_flicker_hour", np.zeros(3))))
        out = _z(cal, {"scale": t["scale"], "bias": bias, "misalignment": t["misalignment"]})
        drift = cal.get("bias_drift") or {}
        std = np.asarray(cal["bias_std"])
        white2 = std**2 - np.asarray(drift.get("run_std", np.zeros(3)))**2
        own = np.sqrt(white2 + BiasDrift(flicker, walk,
                                         float(drift.get("span_s", 0.0))).run_variance)
        out["bias, white σ + generator's B, K"] = out["bias"] * std / own
        return out


def _describe(r: dict[str, np.ndarray] | None) -> str:
    if r is None:
        return "failed (above)"
    return ("bias z " + " ".join(f"{z:+.2f}" for z in r["bias"]) + " (white-noise σ: "
            + " ".join(f"{z:+.2f}" for z in r["bias, white-noise σ"]) + ")")


def _table(results: list[dict[str, np.ndarray] | None], title: str) -> None:
    ok = [r for r in results if r is not None]
    rows = []
    for g in list(ok[0]) if ok else _GROUPS:
        z = np.concatenate([r[g] for r in ok]) if ok else np.zeros(0)
        inside = int(np.sum(np.abs(z) <= 1.96))
        rows.append([g, z.size, f"{100 * inside / max(z.size, 1):.1f} %",
                     float(np.sqrt(np.mean(z**2))) if z.size else float("nan"),
                     float(np.max(np.abs(z))) if z.size else float("nan")])
    print_table(["parameter", "n", "95 % coverage", "z RMS", "max |z|"], rows,
                title=f"{title} ({len(ok)} of {len(results)} runs)")


def main(argv: list[str]) -> None:
    def opt(name: str, default: str) -> str:
        return next((a.split("=", 1)[1] for a in argv if a.startswith(f"--{name}=")), default)

    try:
        seeds = int(opt("seeds", "3" if "--quick" in argv else "40"))
        first = int(opt("first", "0"))
    except ValueError:
        print("bench coverage: --seeds and --first take whole numbers", file=sys.stderr)
        raise SystemExit(2) from None
    if seeds < 1:
        print("bench coverage: --seeds must be at least 1", file=sys.stderr)
        raise SystemExit(2)
    python = opt("python", sys.executable)
    seed_list = range(first, first + seeds)
    if "--independent" in argv:
        flicker, wobble = float(opt("flicker", "0")), float(opt("wobble", "0"))
        band = float(opt("hold-band", "1"))
        ripple = float(opt("ripple", "0.05"))
        for walk in (float(w) for w in opt("walk", "2e-6,1e-4").split(",")):
            res = pooled(_independent_run,
                         [(python, s, walk, flicker, wobble, band, ripple) for s in seed_list],
                         _describe)
            _table(res, f"Independent generator, bias random walk {walk:g} rad/s/√s, flicker "
                        f"B {flicker:g} rad/s, link nod {wobble:g}°, holds within {band:g} "
                        f"tick, speed ripple {100 * ripple:g} %, seeds "
                        f"{first}..{first + seeds - 1}, {python}")
        return
    keep = opt("keep", "")
    res = pooled(_sim_run, [(python, s, keep) for s in seed_list], _describe)
    _table(res, f"Default `gyrocal calibrate --sim`, seeds {first}..{first + seeds - 1}, {python}")
