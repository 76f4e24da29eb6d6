"""``gyrocal verify`` with g-sensitivity: does it pass a calibration with G and catch one without?

Per seed, on the emulated jig (the default realistic ``--sim`` sensor): ``gyrocal calibrate
--sim --sim-seed S``, then ``gyrocal verify`` of that calibration ``--sim --sim-seed S`` (the same
sensor, fresh noise). The table gives verify's verdict, the worst axis's RMS error over the
blocks against its prediction (``after/pred``) and over the gravity pairs (``grav/pred``); then
the same verification of the full model fitted to the same recording WITHOUT g-sensitivity
(``calib.estimators.fit_full_matrix(g_sensitivity=False)``), which should fail on the gravity
pairs.

``--independent``: the same on recordings from the independent generator
(tests/kit/contract_fullmodel_recording.py, nothing of gyrocal's emulator, kinematics or
planner) with a random g-sensitivity of ``--g`` rad/s/g per term: calibrate on one recording
(poses at 60°), verify on another of the same sensor (poses at 45°, another speed, rests as long
as verify's gravity pairs); its schedule has one gravity rest and two posed rests that tilt
gravity, each followed by a rest at home.

Usage: ``python -m bench verify [--seeds=N] [--independent] [--g=1e-3]``.
"""

from __future__ import annotations

import contextlib
import io
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

from bench.table import print_table


def _opt(argv: list[str], name: str, default: str) -> str:
    for a in argv:
        if a.startswith(f"--{name}="):
            return a.split("=", 1)[1]
    return default


def _without_g(cal_rec: Path, cal: Any) -> Any:
    from gyrocal.calib.estimators import estimate
    from gyrocal.kit.pipeline import extract_recording
    from gyrocal.kit.recording import load_recording

    ex = extract_recording(load_recording(cal_rec))
    fit = estimate(ex.observations, "full-matrix", g_sensitivity=False)
    return fit.to_calibration(sensor=cal.sensor)


def _row(label: str, cal: Any, no_g: Any, rec: Any) -> list[str]:
    from gyrocal.kit.verify import verify_recording

    v = verify_recording(rec, cal)
    vn = verify_recording(rec, no_g)
    return [label, cal.g_sensitivity is not None and v.g_sensitivity or "none",
            "pass" if v.ok else "FAIL", f"{np.nanmax(v.ratio):.2f}",
            f"{np.nanmax(v.gravity_ratio):.2f}" if v.gravity_pairs else "n/a",
            str(v.gravity_pairs), "pass" if vn.ok else "FAIL",
            f"{np.nanmax(vn.ratio):.2f}",
            f"{np.nanmax(vn.gravity_ratio):.2f}" if vn.gravity_pairs else "n/a"]


HEAD = ["seed", "G", "verify", "after/pred", "grav/pred", "pairs", "no-G verify",
        "no-G after/pred", "no-G grav/pred"]


def _emulated(seeds: int) -> None:
    from gyrocal.calib.model import GyroCalibration
    from gyrocal.kit.cli import main as gyrocal
    from gyrocal.kit.recording import load_recording

    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for s in range(seeds):
            d = Path(tmp) / f"s{s}"
            with contextlib.redirect_stdout(io.StringIO()), \
                    contextlib.redirect_stderr(io.StringIO()):
                gyrocal(["calibrate", "--sim", "--sim-seed", str(s), "--out", str(d / "cal"),
                         "--quiet", "--no-report"])
                gyrocal(["verify", str(d / "cal" / "calibration.json"), "--sim", "--sim-seed",
                         str(s), "--out", str(d / "ver"), "--quiet", "--json"])
            cal = GyroCalibration.from_json((d / "cal" / "calibration.json").read_text())
            rows.append(_row(str(s), cal, _without_g(d / "cal" / "recording", cal),
                             load_recording(d / "ver" / "recording")))
            print(" ".join(rows[-1]), flush=True)
    print_table(HEAD, rows, f"verify on the emulated jig (default realistic sensor), {seeds} seeds")


def _independent(seeds: int, g: float) -> None:
    from gyrocal.kit.pipeline import estimate_recording
    from gyrocal.kit.recording import load_recording
    from gyrocal.kit.verify import GRAVITY_REST_S
    from tests.kit.contract_fullmodel_recording import write_recording

    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for s in range(seeds):
            G = np.random.default_rng([s, 12]).uniform(-g, g, (3, 3))
            a, b = Path(tmp) / f"a{s}", Path(tmp) / f"b{s}"
            write_recording(a, seed=s, g_sensitivity=G, pose_deg=60.0)
            # rests as long as verify's gravity pairs (the generator's default 0.8 s rests
            # leave the pairs' noise 1.7 times larger)
            write_recording(b, seed=s, g_sensitivity=G, pose_deg=45.0, speed=3.0,
                            rest=GRAVITY_REST_S)
            cal = estimate_recording(load_recording(a)).calibration
            rows.append(_row(str(s), cal, _without_g(a, cal), load_recording(b)))
    print_table(HEAD, rows,
                f"verify on the independent generator, G within ±{g:g} rad/s/g, {seeds} seeds")


def main(argv: list[str]) -> None:
    """Print the tables (``--seeds``, default 6; ``--independent`` for the generator only)."""
    seeds = int(_opt(argv, "seeds", "6"))
    if "--independent" in argv:
        _independent(seeds, float(_opt(argv, "g", "1.7e-3")))
    else:
        _emulated(seeds)
