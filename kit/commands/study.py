"""``gyrocal study --preset NAME``: the paper's simulation study, reproducible by one command."""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any

from gyrocal.kit import argtypes

HELP = "reproduce the paper's simulation study (Monte Carlo, all estimators side by side)"
DESCRIPTION = (
    "Monte Carlo study of the estimators at sample level (200 Hz), as in the paper's Section "
    "III. Presets: normal (k ~ U(0.8,1.2), b ~ U(-0.1,0.1) rad/s, 30 sensors x 500 runs per "
    "noise level 0.035 and 0.2 rad/s), extreme (k ~ U(1.2,2.0), |b| in [0.1,0.2]), speed-sweep "
    "(0.3 to 3.0 rad/s), convergence (the paper's Table I) and demo (before/after on a sine-wave "
    "rotation). Prints error statistics per parameter for each estimator side by side."
)
PRESET_CHOICES = ("normal", "extreme", "speed-sweep", "convergence", "demo")

#: What the paper reports for its normal conditions (Section III-A): "the majority" of errors.
PAPER_FIGURES = {
    0.035: {"scale": 9.3e-4, "bias": 3.0e-3},
    0.2: {"scale": 5.4e-3, "bias": 1.7e-2},
}


#: The presets that draw plots with ``--plot``.
PLOTTED_PRESETS = ("normal", "extreme", "speed-sweep")


def add_arguments(p: argparse.ArgumentParser) -> None:
    """Register the arguments."""
    p.add_argument("--preset", choices=PRESET_CHOICES, default="normal")
    p.add_argument("--sensors", type=int, help="sensors drawn (default 30)")
    p.add_argument("--reps", type=int, help="runs per sensor (default 500; speed-sweep 10)")
    p.add_argument("--noise", type=float, nargs="+", metavar="SIGMA",
                   help="noise levels per sample, rad/s (default 0.035 0.2)")
    p.add_argument("--seed", type=argtypes.seed, default=2023)
    p.add_argument("--workers", type=int, default=min(2, os.cpu_count() or 1),
                   help="processes (default: up to 2)")
    p.add_argument("--no-lm", action="store_true",
                   help="skip scipy Levenberg-Marquardt (one call per run, the slowest)")
    p.add_argument("--plot", metavar="DIR", help="write PNG plots to DIR (needs the plot extra)")
    p.add_argument("--force", action="store_true", help="replace existing plots in --plot DIR")
    p.add_argument("--json", action="store_true", help="print the numbers as JSON")


@contextmanager
def _mapper(workers: int) -> Iterator[Callable[..., Any]]:
    """``map`` over ``workers`` processes (the built-in ``map`` for one)."""
    if workers <= 1:
        yield map
        return
    from concurrent.futures import ProcessPoolExecutor

    with ProcessPoolExecutor(max_workers=workers) as pool:
        yield pool.map


def _stats_table(result: Any) -> str:
    from gyrocal.calib.study import METHOD_ORDER, PARAMS

    lines = []
    stats = result.stats()
    for noise, by_method in stats.items():
        methods = [m for m in METHOD_ORDER if m in by_method]
        n = next(iter(result.errors[noise].values())).shape[0]
        lines.append(f"\nnoise {noise} rad/s per sample, {n} runs ({result.config.name})")
        lines.append(f"{'param':<6}{'statistic':<11}" + "".join(f"{m:>22}" for m in methods))
        for p in PARAMS:
            for label, get in (("median", lambda s: f"{s.median:+.2e}"),
                               ("q1..q3", lambda s: f"{s.q1:+.1e}..{s.q3:+.1e}"),
                               ("whiskers", lambda s: f"{s.whisker_lo:+.1e}..{s.whisker_hi:+.1e}"),
                               ("rms", lambda s: f"{s.rms:.3e}")):
                first = p if label == "median" else ""
                lines.append(f"{first:<6}{label:<11}"
                             + "".join(f"{get(by_method[m][p]):>22}" for m in methods))
        extra = result.extra[noise]
        fails = ", ".join(f"{m}: {int((~extra[m + ':ok']).sum())}" for m in methods)
        lines.append(f"failed runs: {fails}")
        its = ", ".join(f"{m}: {extra[m + ':iterations'].mean():.1f}" for m in methods)
        lines.append(f"mean iterations: {its}")
        cov = result.coverage(noise)
        lines.append("paired-axis 95 % intervals holding the truth: "
                     + " ".join(f"{p}={c:.1%}" for p, c in zip(PARAMS, cov, strict=True)))
        if "iterative-ls" in by_method:
            rk = max(by_method["paired-axis"][p].rms / by_method["iterative-ls"][p].rms
                     for p in PARAMS[:3])
            rb = max(by_method["paired-axis"][p].rms / by_method["iterative-ls"][p].rms
                     for p in PARAMS[3:])
            lines.append(f"paired-axis / Algorithm 1 RMS error: scale {rk:.2f}, bias {rb:.2f} "
                         "(worst axis)")
        if result.config.name == "normal" and noise in PAPER_FIGURES:
            fig = PAPER_FIGURES[noise]
            ils = by_method["iterative-ls"]
            wk = max(max(abs(ils[p].whisker_lo), ils[p].whisker_hi) for p in PARAMS[:3])
            wb = max(max(abs(ils[p].whisker_lo), ils[p].whisker_hi) for p in PARAMS[3:])
            lines.append(
                f"paper (Fig. 4, 'majority within'): scale ±{fig['scale']:.1e}, bias "
                f"±{fig['bias']:.1e}; Algorithm 1 here, whiskers: scale ±{wk:.1e}, "
                f"bias ±{wb:.1e}"
            )
    return "\n".join(lines)


def _stats_json(result: Any) -> dict[str, Any]:
    from dataclasses import asdict

    out: dict[str, Any] = {"preset": result.config.name, "seed": result.config.seed,
                           "levels": {}}
    for noise, by_method in result.stats().items():
        out["levels"][str(noise)] = {
            "runs": int(next(iter(result.errors[noise].values())).shape[0]),
            "methods": {m: {p: asdict(s) for p, s in ps.items()} for m, ps in by_method.items()},
            "paired_axis_coverage_95": result.coverage(noise).tolist(),
        }
    return out


def run(args: argparse.Namespace) -> int:
    """Run the command."""
    import numpy as np

    from gyrocal.calib import study
    from gyrocal.kit.errors import InputError
    from gyrocal.kit.fileio import make_output_dir, refuse_existing

    for name in ("sensors", "reps", "workers"):
        v = getattr(args, name)
        if v is not None and v < 1:
            raise InputError(f"--{name} must be at least 1, got {v}")
    if args.noise is not None and any(not n > 0 for n in args.noise):
        raise InputError("--noise levels must be positive")
    plot_dir = None
    if args.plot and args.preset not in PLOTTED_PRESETS:
        raise InputError(
            f"--plot: the {args.preset} preset draws no plots (only "
            f"{', '.join(PLOTTED_PRESETS)} do); drop --plot or choose one of those presets"
        )
    if args.plot:

        from gyrocal.kit.plots import require_matplotlib

        require_matplotlib()
        plot_dir = make_output_dir(args.plot, "--plot")
    t0 = time.perf_counter()
    doc: dict[str, Any]
    text: str
    if args.preset in ("normal", "extreme"):
        base = study.PRESETS[args.preset]
        cfg = study.StudyConfig(
            name=base.name, sensors=base.sensors,
            n_sensors=args.sensors or base.n_sensors, reps=args.reps or base.reps,
            noise_levels=tuple(args.noise) if args.noise else base.noise_levels,
            protocol=base.protocol, misalignment=base.misalignment, seed=args.seed,
        )
        paths = {} if plot_dir is None else {
            noise: plot_dir / f"study-{cfg.name}-noise-{noise}.png" for noise in cfg.noise_levels}
        refuse_existing(paths.values(), force=args.force)  # before minutes of Monte Carlo
        with _mapper(args.workers) as map_fn:
            result = study.run_study(cfg, map_fn=map_fn, lm=not args.no_lm)
        text = _stats_table(result)
        doc = _stats_json(result)
        if plot_dir is not None:
            from gyrocal.kit.plots import study_boxplots

            for noise, errs in result.errors.items():
                path = study_boxplots(errs, f"{cfg.name} conditions, noise {noise} rad/s",
                                      paths[noise], force=args.force)
                text += f"\nwrote {path}"
    elif args.preset == "speed-sweep":
        speeds = np.round(np.arange(0.3, 3.0001, 0.1), 1)
        base = study.StudyConfig(
            name="speed-sweep", n_sensors=args.sensors or 30, reps=args.reps or 10,
            noise_levels=tuple(args.noise) if args.noise else (0.035, 0.2), seed=args.seed,
        )
        sweep_path = None if plot_dir is None else plot_dir / "speed-sweep-mse.png"
        refuse_existing([sweep_path], force=args.force)
        with _mapper(args.workers) as map_fn:
            sweep = study.speed_sweep(speeds, base=base, map_fn=map_fn, lm=not args.no_lm)
        lines = []
        doc = {"preset": "speed-sweep", "levels": {}}
        for noise, by_speed in sweep.items():
            methods = list(next(iter(by_speed.values())))
            lines.append(f"\nnoise {noise} rad/s: mean squared error (Eq. 10), "
                         f"{base.runs} runs per speed")
            lines.append(f"{'speed':>6}" + "".join(f"{m + ' k':>24}{m + ' b':>24}"
                                                   for m in methods))
            doc["levels"][str(noise)] = {}
            for s, by_m in by_speed.items():
                lines.append(f"{s:>6.1f}" + "".join(
                    f"{np.mean(by_m[m][:3]):>24.3e}{np.mean(by_m[m][3:]):>24.3e}"
                    for m in methods))
                doc["levels"][str(noise)][str(s)] = {m: v.tolist() for m, v in by_m.items()}
        text = "\n".join(lines)
        if sweep_path is not None:
            from gyrocal.kit.plots import speed_sweep_plot

            path = speed_sweep_plot(sweep, sweep_path, force=args.force)
            text += f"\nwrote {path}"
    elif args.preset == "convergence":
        rows = study.convergence_table(noise=(args.noise or [0.035])[0], seed=args.seed)
        lines = ["Algorithm 1 iterates for the paper's Table I cases "
                 "(one run each, 1 rad/s, noise as given)"]
        doc = {"preset": "convergence", "cases": []}
        for r in rows:
            lines.append(f"\n{r['name']}")
            lines.append(f"{'':<14}" + "".join(f"{p:>9}" for p in study.PARAMS))
            lines.append(f"{'actual':<14}" + "".join(f"{v:>9.4f}" for v in r["actual"]))
            for i, it in enumerate(r["iterates"], start=1):
                tag = f"{i}-converged" if i == len(r["iterates"]) and r["converged"] else str(i)
                lines.append(f"{tag:<14}" + "".join(f"{v:>9.4f}" for v in it))
            doc["cases"].append({"name": r["name"], "actual": r["actual"].tolist(),
                                 "iterates": np.asarray(r["iterates"]).tolist(),
                                 "iterations": r["iterations"], "converged": r["converged"]})
        text = "\n".join(lines)
    else:  # demo
        d = study.demo_before_after(seed=args.seed, noise=(args.noise or [0.035])[0])
        lines = ["before/after: sine-wave rotation, 1 rad/s amplitude at 0.75 Hz about "
                 "(1,1,1)/sqrt(3), RMS error against the true rate (rad/s)",
                 f"{'':<22}{'x':>10}{'y':>10}{'z':>10}",
                 f"{'raw reading':<22}" + "".join(f"{v:>10.4f}" for v in d["rms_before"])]
        for m, v in d["rms_after"].items():
            lines.append(f"{'calibrated, ' + m:<22}"[:22] + "".join(f"{x:>10.4f}" for x in v))
        lines.append(f"{'noise floor (k·σ)':<22}" + "".join(f"{x:>10.4f}"
                                                            for x in d["noise_floor"]))
        text = "\n".join(lines)
        doc = {"preset": "demo", "rms_before": d["rms_before"].tolist(),
               "rms_after": {m: v.tolist() for m, v in d["rms_after"].items()},
               "truth": d["truth"].tolist(),
               "estimates": {m: v.tolist() for m, v in d["estimates"].items()}}
    elapsed = time.perf_counter() - t0
    if args.json:
        doc["elapsed_s"] = elapsed
        json.dump(doc, sys.stdout, indent=2)
        print()
    else:
        print(text)
        print(f"\n({elapsed:.1f} s)")
    return 0
