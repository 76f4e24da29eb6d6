"""``gyrocal noise``: noise figures of a still gyro (overlapping Allan deviation)."""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any

from gyrocal.kit import argtypes
from gyrocal.kit.errors import InputError

if TYPE_CHECKING:
    import numpy as np

HELP = "noise figures of a still gyro: angle random walk, bias instability, rate random walk"
DESCRIPTION = (
    "Characterise the gyro's noise from a still recording by the overlapping Allan deviation "
    "(IEEE Std 952): angle random walk N (rad/s/sqrt(Hz)), bias instability B (rad/s) and rate "
    "random walk K (rad/s/sqrt(s)), each with its uncertainty. --sim draws a synthetic still "
    "sensor with known noise (gyrocal.calib.noise_sim; not the emulated jig). --json prints the "
    "gyrocal-noise v1 document that 'gyrocal export --format kalibr' and 'gyrocal track --noise' "
    "read."
)

RAD2DEG = 180.0 / math.pi


def add_arguments(p: argparse.ArgumentParser) -> None:
    """Register the flags."""
    p.add_argument("recording", nargs="?", metavar="RECORDING", type=argtypes.recording_dir,
                   help="Recording v1 directory of the sensor at rest")
    p.add_argument("--sim", action="store_true",
                   help="use a simulated still sensor with known noise instead of a recording")
    p.add_argument("--duration", type=float, default=1800.0, metavar="S",
                   help="--sim: length of the record, s (default 1800)")
    p.add_argument("--odr", type=float, default=200.0, metavar="HZ",
                   help="--sim: sample rate, Hz (default 200)")
    p.add_argument("--seed", type=argtypes.seed, default=0, help="--sim: random seed (default 0)")
    p.add_argument("--sim-noise-density", type=float, default=1.75e-4, metavar="N",
                   help="--sim: true angle random walk, rad/s/sqrt(Hz) (default 1.75e-4)")
    p.add_argument("--sim-rate-random-walk", type=float, default=2e-6, metavar="K",
                   help="--sim: true rate random walk, rad/s/sqrt(s) (default 2e-6)")
    p.add_argument("--sim-bias-instability", type=float, default=0.0, metavar="B",
                   help="--sim: true flicker coefficient, rad/s (default 0)")
    p.add_argument("--span", choices=("auto", "all", "longest-rest"), default="auto",
                   help="which samples of a recording: all, or its longest rest segment "
                        "(auto: all if the recording has no rotations)")
    p.add_argument("--min-tau", type=float, default=None, metavar="S",
                   help="shortest averaging time of the white-noise slope N is read on "
                        "(default 10 samples; N is read near 1 s where the curve allows)")
    p.add_argument("--allow-implausible", action="store_true",
                   help="accept a white-noise density no MEMS gyro in rad/s has (readings in "
                        "°/s are refused: exit 6)")
    p.add_argument("--json", action="store_true", help="print the gyrocal-noise v1 document")
    p.add_argument("--out", metavar="FILE", help="also write the document to FILE (atomically)")
    p.add_argument("--force", action="store_true", help="replace existing --out and --plot files")
    p.add_argument("--plot", metavar="FILE",
                   help="draw the Allan deviation to FILE (PNG; needs the 'plot' extra)")


def _from_sim(args: argparse.Namespace) -> tuple[np.ndarray, float, dict[str, Any], Any]:
    import numpy as np

    from gyrocal.calib.noise_sim import NoiseModel, simulate_still

    if not args.sim_noise_density > 0:
        raise InputError("--sim-noise-density must be positive")
    try:
        model = NoiseModel(noise_density=args.sim_noise_density,
                           rate_random_walk=args.sim_rate_random_walk,
                           bias_instability=args.sim_bias_instability)
        s = simulate_still(np.random.default_rng(args.seed), args.duration, odr_hz=args.odr,
                           model=model)
    except ValueError as exc:
        raise InputError(f"--sim: {exc}") from None
    meta = {"sensor": {"model": "simulated", "odr_hz": s.odr_hz}, "source": "simulation",
            "temperature_c": 25.0}
    return s.rate, s.odr_hz, meta, model


def _table(nc: Any, truth: Any) -> str:
    rows = []
    hdr = (f"{'axis':4}  {'N rad/s/sqrt(Hz)':>22}  {'(deg/sqrt(h))':>13}  "
           f"{'B rad/s':>22}  {'(deg/h)':>8}  {'K rad/s/sqrt(s)':>22}  {'tau N/B/K s':>18}")
    rows.append(hdr)
    rows.append("-" * len(hdr))
    for i, ax in enumerate("xyz"):
        n, ns = nc.noise_density.value[i], nc.noise_density.std[i]
        b, bs = nc.bias_instability.value[i], nc.bias_instability.std[i]
        k, ks = nc.rate_random_walk.value[i], nc.rate_random_walk.std[i]
        taus = (f"{nc.noise_density.tau_s[i]:.3g}/{nc.bias_instability.tau_s[i]:.3g}/"
                f"{nc.rate_random_walk.tau_s[i]:.3g}")
        rows.append(
            f"{ax:4}  {n:10.4e} +- {ns:8.2e}  {n * RAD2DEG * 60:13.4f}  "
            f"{b:10.4e} +- {bs:8.2e}  {b * RAD2DEG * 3600:8.3f}  "
            f"{k:10.4e} +- {ks:8.2e}  {taus:>18}"
        )
    if truth is not None:
        rows.append(
            f"true  N {truth.noise_density[0]:.4e}   B {truth.bias_instability[0]:.4e}   "
            f"K {truth.rate_random_walk[0]:.4e}  (simulation, every axis)"
        )
    return "\n".join(rows)


def plot_allan(nc: Any, path: str, *, force: bool = False) -> None:
    """Draw the Allan deviation with its one-sigma band and the fitted noise model to ``path``."""
    from gyrocal.kit.plots import require_matplotlib, save_png

    plt = require_matplotlib()
    import numpy as np

    from gyrocal.calib.noise_sim import FLICKER_FLOOR

    tau = nc.tau_s
    fig, ax = plt.subplots(figsize=(7, 5))
    for i, (name, col) in enumerate(zip("xyz", ("C0", "C1", "C2"), strict=True)):
        ax.loglog(tau, nc.adev[:, i], "o-", ms=3, color=col, label=f"{name}")
        ax.fill_between(tau, nc.adev_lo[:, i], nc.adev_hi[:, i], color=col, alpha=0.2)
        N, B, K = nc.fit["N"][i], nc.fit["B"][i], nc.fit["K"][i]
        model = np.sqrt(N**2 / tau + (FLICKER_FLOOR * B) ** 2 + K**2 * tau / 3.0)
        ax.loglog(tau, model, "--", color=col, lw=1)
    ax.set_xlabel("averaging time tau, s")
    ax.set_ylabel("Allan deviation, rad/s")
    ax.set_title("overlapping Allan deviation (band: 68 %; dashed: N, B, K model)")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend()
    save_png(fig, path, force=force, dpi=120)


def run(args: argparse.Namespace) -> int:
    """Analyse, print, write and plot."""
    from gyrocal.kit.fileio import atomic_write_json, refuse_existing
    from gyrocal.kit.recording import now_iso, read_manifest

    if args.sim == (args.recording is not None):
        raise InputError("give a RECORDING or --sim (one of them)")
    refuse_existing((args.out, args.plot), force=args.force)
    if not args.sim:
        read_manifest(Path(args.recording))  # a bad path is said before any heavy import
    from gyrocal.calib.allan import characterise_noise

    if args.sim:
        rate, odr, meta, truth = _from_sim(args)
        nc = characterise_noise(rate, odr, min_tau_s=args.min_tau)
    else:
        from gyrocal.kit.still import open_still

        truth = None
        with open_still(args.recording, args.span) as still:  # streamed: bounded memory
            odr, meta = still.odr_hz, still.meta
            nc = characterise_noise(still.phase, odr, min_tau_s=args.min_tau)
        from gyrocal.kit.pipeline import check_plausible_noise

        for problem in check_plausible_noise(nc.noise_density.value,
                                             allow=args.allow_implausible):
            print(f"gyrocal: warning: {problem} (accepted: --allow-implausible)",
                  file=sys.stderr)
    from gyrocal.calib.noise_sim import FLICKER_FLOOR

    nc = nc.with_meta(created=now_iso(), **meta)
    doc = nc.to_dict()
    if args.out:
        atomic_write_json(args.out, doc, force=args.force)
        print(f"wrote {args.out}", file=sys.stderr)
    if args.plot:
        plot_allan(nc, args.plot, force=args.force)
        print(f"wrote {args.plot}", file=sys.stderr)
    if args.json:
        print(json.dumps(doc, indent=2, allow_nan=False))
    else:
        print(f"gyrocal noise: {meta['source']}, {nc.duration_s:.1f} s at {odr:g} Hz "
              f"({nc.n_samples} samples per axis); overlapping Allan deviation, IEEE Std 952")
        print(_table(nc, truth))
        print("B: flicker floor 0.664 B read where best determined; curve minimum/0.664: "
              + ", ".join(f"{v / FLICKER_FLOOR:.3e}" for v in nc.adev_min["value"]) + " rad/s")
    return 0
