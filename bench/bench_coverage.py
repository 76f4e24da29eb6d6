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
   with a bias random walk of ``--walk`` rad/s/√s (default 2e-6, the figure the kit assumes),
   fitted by ``gyrocal estimate``; the truth is the bias at the recording's start.

``--python=PATH`` runs the calibrations with another installation's interpreter (e.g. the
code before a change: ``--python=/work/venv-main/bin/python``); the comparison with the truth
is this installation's.

Usage: ``python -m bench coverage [--seeds=N] [--first=S] [--python=PATH] [--independent]
[--walk=K]``.
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
    zm = (np.asarray(cal["matrix"]) - C) / np.asarray(cal["matrix_std"])
    diag = np.eye(3, dtype=bool)
    free = np.asarray(cal["matrix_std"]) > 0  # the frame convention fixes some terms (σ 0)
    return {"bias, white-noise σ": zw, "bias": zb, "matrix diagonal": zm[diag & free],
            "matrix off-diagonal": zm[~diag & free]}


def _sim_run(job: tuple[str, int]) -> dict[str, np.ndarray] | None:
    python, seed = job
    with tempfile.TemporaryDirectory() as tmp:
        d = Path(tmp) / "run"
        run = subprocess.run([python, "-m", "gyrocal.kit", "calibrate", "--sim", "--sim-seed",
                              str(seed), "--out", str(d), "--quiet", "--no-report"],
                             capture_output=True, text=True, check=False)
        if run.returncode not in (0, 3):  # 3: not consistent, still a calibration
            print(f"# seed {seed}: exit {run.returncode}: {run.stderr[-300:]}", file=sys.stderr)
            return None
        cal = json.loads((d / "calibration.json").read_text(encoding="utf-8"))
        truth = json.loads((d / "recording" / "manifest.json").read_text(encoding="utf-8"))
        return _z(cal, truth["truth"])


def _independent_run(job: tuple[str, int, float]) -> dict[str, np.ndarray] | None:
    python, seed, walk = job
    root = Path(__file__).resolve().parent.parent
    sys.path.insert(0, str(root))
    from tests.kit.contract_fullmodel_recording import write_recording

    with tempfile.TemporaryDirectory() as tmp:
        rec = Path(tmp) / "rec"
        t = write_recording(rec, seed=seed, bias_walk=walk)
        run = subprocess.run([python, "-m", "gyrocal.kit", "estimate", str(rec), "--json"],
                             capture_output=True, text=True, check=False)
        if run.returncode not in (0, 3):
            print(f"# seed {seed}: exit {run.returncode}: {run.stderr[-300:]}", file=sys.stderr)
            return None
        cal = json.loads(run.stdout)
        truth = {"scale": t["scale"], "bias": t["bias"], "misalignment": t["misalignment"]}
        return _z(cal, truth)


def _describe(r: dict[str, np.ndarray] | None) -> str:
    if r is None:
        return "failed (above)"
    return ("bias z " + " ".join(f"{z:+.2f}" for z in r["bias"]) + " (white-noise σ: "
            + " ".join(f"{z:+.2f}" for z in r["bias, white-noise σ"]) + ")")


def _table(results: list[dict[str, np.ndarray] | None], title: str) -> None:
    ok = [r for r in results if r is not None]
    rows = []
    for g in _GROUPS:
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

    seeds, first = int(opt("seeds", "40")), int(opt("first", "0"))
    python = opt("python", sys.executable)
    seed_list = range(first, first + seeds)
    if "--independent" in argv:
        walk = float(opt("walk", "2e-6"))
        res = pooled(_independent_run, [(python, s, walk) for s in seed_list], _describe)
        _table(res, f"Independent generator, bias random walk {walk:g} rad/s/√s, seeds "
                    f"{first}..{first + seeds - 1}, {python}")
        return
    res = pooled(_sim_run, [(python, s) for s in seed_list], _describe)
    _table(res, f"Default `gyrocal calibrate --sim`, seeds {first}..{first + seeds - 1}, {python}")
