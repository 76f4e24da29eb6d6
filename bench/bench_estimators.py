"""Estimator benchmarks (issue: foundation and estimation core).

1. Algorithm 1 against scipy's Levenberg-Marquardt per calibration, same observations, same run.
2. The full 15,000-run normal-conditions study at sample level: wall time on this machine.
3. Accuracy on the paper's normal conditions: paired-axis against Algorithm 1 (RMS error ratios).
4. Honest uncertainties: coverage of paired-axis 95 % intervals.

Usage: ``python -m bench estimators [--quick]``.
"""

from __future__ import annotations

import os
import time
from concurrent.futures import ProcessPoolExecutor

import numpy as np
from scipy import optimize

from bench.table import print_table
from gyrocal.calib import estimators as E
from gyrocal.calib.simulate import SimProtocol, draw_mount_axes, draw_sensors, simulate_runs
from gyrocal.calib.study import PARAMS, StudyConfig, run_study


def _per_call(fn, items, repeat: int) -> float:
    """Best-of-``repeat`` mean seconds per call of ``fn`` over ``items``."""
    best = np.inf
    for _ in range(repeat):
        t = time.perf_counter()
        for x in items:
            fn(x)
        best = min(best, (time.perf_counter() - t) / len(items))
    return best


def speed_table(n_runs: int) -> None:
    rng = np.random.default_rng(42)
    k, b = draw_sensors(rng, n_runs)
    runs = simulate_runs(rng, k, b, draw_mount_axes(rng, n_runs), SimProtocol(), 0.035)
    obs = [runs.observation_set(i) for i in range(n_runs)]
    arrays = [(o.mean, o.rate) for o in obs]
    x0 = np.array([1.0, 1.0, 1.0, 0.0, 0.0, 0.0])

    def ils_core(a):
        return E._ils_solve(E._design(a[0]), a[1] ** 2, 1e-6, 100)

    def lm_core(a):
        return E.lm_solve(a[0], a[1])

    def lm_fd(a):
        return optimize.least_squares(E._sq_residuals, x0, method="lm", args=a)

    t_ils = _per_call(ils_core, arrays, 5)
    t_lm = _per_call(lm_core, arrays, 3)
    t_lm_fd = _per_call(lm_fd, arrays, 3)
    t_ils_api = _per_call(lambda o: E.fit_iterative_ls(o, covariance=False), obs, 3)
    t_lm_api = _per_call(lambda o: E.fit_levenberg_marquardt(o, covariance=False), obs, 3)
    t_ils_cov = _per_call(E.fit_iterative_ls, obs, 3)
    t_pa = _per_call(E.fit_paired_axis, obs[: max(20, n_runs // 10)], 2)
    diff_k = diff_b = 0.0
    for o in obs:
        a, b_ = E.fit_iterative_ls(o), E.fit_levenberg_marquardt(o)
        diff_k = max(diff_k, float(np.max(np.abs(a.scale - b_.scale))))
        diff_b = max(diff_b, float(np.max(np.abs(a.bias - b_.bias))))
    us = 1e6
    print_table(
        ["what (per calibration, 6 windows)", "µs", "LM / Algorithm 1"],
        [
            ["Algorithm 1, bare (tol 1e-6)", t_ils * us, 1.0],
            ["scipy LM, bare, analytic Jacobian", t_lm * us, t_lm / t_ils],
            ["scipy LM, bare, finite-difference Jacobian", t_lm_fd * us, t_lm_fd / t_ils],
            ["fit_iterative_ls (validation, no covariance)", t_ils_api * us, 1.0],
            ["fit_levenberg_marquardt (validation, no cov.)", t_lm_api * us, t_lm_api / t_ils_api],
            ["fit_iterative_ls with covariance + chi2", t_ils_cov * us, ""],
            ["fit_paired_axis (single run, full result)", t_pa * us, ""],
        ],
        title=f"Algorithm 1 vs scipy LM, {n_runs} simulated calibrations (same observations)",
    )
    print(f"same answer: max |Δk| = {diff_k:.1e}, max |Δb| = {diff_b:.1e} rad/s "
          "(Algorithm 1 at the paper's tolerance 1e-6 vs LM at 1e-14)\n")


def study_table(reps: int, workers: int) -> None:
    cfg = StudyConfig(n_sensors=30, reps=reps, noise_levels=(0.035, 0.2))
    rows = []
    results = {}
    for lm in (True, False):
        t = time.perf_counter()
        with ProcessPoolExecutor(workers) as pool:
            res = run_study(
                StudyConfig(n_sensors=30, reps=reps, noise_levels=(0.035,)),
                map_fn=pool.map, lm=lm,
            )
        rows.append([f"normal, σ = 0.035, {res.config.runs} runs",
                     "all three" if lm else "Algorithm 1 + paired-axis", workers,
                     time.perf_counter() - t])
        results[lm] = res
    with ProcessPoolExecutor(workers) as pool:
        t = time.perf_counter()
        both = run_study(cfg, map_fn=pool.map, lm=True)
        rows.append([f"normal, σ = 0.035 and 0.2, {2 * cfg.runs} runs", "all three", workers,
                     time.perf_counter() - t])
    print_table(["study", "estimators", "processes", "wall s"], rows,
                title="Monte Carlo study at sample level (200 Hz, 1 rad/s, 3 s rests)")
    acc = []
    for noise, by in both.stats().items():
        for m in ("iterative-ls", "levenberg-marquardt", "paired-axis"):
            s = by[m]
            acc.append([noise, m, np.sqrt(np.mean([s[p].rms ** 2 for p in PARAMS[:3]])),
                        np.sqrt(np.mean([s[p].rms ** 2 for p in PARAMS[3:]]))])
        ils, pa = by["iterative-ls"], by["paired-axis"]
        acc.append([noise, "paired-axis / Algorithm 1 (worst axis)",
                    max(pa[p].rms / ils[p].rms for p in PARAMS[:3]),
                    max(pa[p].rms / ils[p].rms for p in PARAMS[3:])])
    print_table(["noise rad/s", "estimator", "scale RMS error", "bias RMS error (rad/s)"], acc,
                title="Accuracy on the paper's normal conditions (same data for every estimator)")
    cov = [[noise, *[f"{c:.1%}" for c in both.coverage(noise)]] for noise in both.errors]
    print_table(["noise rad/s", *PARAMS], cov,
                title=f"paired-axis: share of {cfg.runs} runs whose 95 % interval holds the truth")


def main(argv: list[str]) -> None:
    quick = "--quick" in argv
    workers = min(2, os.cpu_count() or 1)
    speed_table(100 if quick else 400)
    study_table(50 if quick else 500, workers)
