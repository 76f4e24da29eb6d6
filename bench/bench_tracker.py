"""Bias tracker vs xioTechnologies Fusion's gyroscope bias estimator, and tracker speed.

Usage: ``python -m bench tracker [--sessions=N] [--duration=S]`` (with ``=``: the bench runner
takes every bare word for a benchmark name; needs the ``bench`` extra, ``pip install '.[bench]'``,
for ``imufusion``).

Accuracy: the same simulated sessions (``gyrocal.calib.noise_sim.simulate_session``: 30 minutes, a
10 °C warm-up, bias random walk, still periods of 2-5 s between smooth random motions; seeded)
go through

* our tracker (``gyrocal.calib.tracker.BiasTracker``) seeded from a simulated offline calibration,
  with
  the true noise model, with and without the temperature state;
* Fusion's ``imufusion.Bias`` (the FusionBias algorithm: after the rate stays under a threshold
  on every axis for a stationary period, the offset follows the reading through a first-order
  low-pass filter), seeded with the same calibration's bias, at its default settings
  (threshold 3 °/s, period 3 s) and at settings tuned to these sessions (0.5 °/s, 1 s).

Both corrected rates use the calibration's scale, ``scale ∘ (m + bias)``; Fusion's offset is
``−bias`` in °/s. Reported: RMS bias error and RMS corrected-rate error against the truth (all
samples, all axes), their ratios ours/Fusion, and our 3-sigma band coverage.

Speed: batch throughput (a whole 30-minute session in one ``process`` call, best of 3) and
streaming latency (``update`` per sample: median and 99th percentile), with Fusion's per-sample
update for scale.
"""

from __future__ import annotations

import argparse
import math
import time

import numpy as np

from bench.table import print_table
from gyrocal.calib.noise_sim import NoiseModel, sim_calibration, simulate_session
from gyrocal.calib.tracker import BiasTracker, TrackerSettings

DEG = 180.0 / math.pi
MODEL = NoiseModel(rate_random_walk=1e-5)
ODR = 200.0


def _settings(temperature_model: bool) -> TrackerSettings:
    return TrackerSettings(
        odr_hz=ODR,
        noise_density=MODEL.noise_density,
        rate_random_walk=MODEL.rate_random_walk,
        temperature_model=temperature_model,
    )


def _fusion(imufusion, s, cal, threshold_dps: float, period_s: float) -> np.ndarray:
    """Fusion's bias estimate per sample, converted to our convention (rad/s)."""
    b = imufusion.Bias()
    b.set_settings(imufusion.BiasSettings(ODR, threshold_dps, period_s))
    b.set_offset(-np.asarray(cal.bias) * DEG)
    out = np.empty((s.n, 3))
    rate_dps = s.rate * DEG
    for i in range(s.n):
        b.update(rate_dps[i])
        out[i] = b.get_offset()
    return -out / DEG


def _errors(s, cal, bias: np.ndarray) -> tuple[float, float]:
    scale = np.asarray(cal.scale)
    bias_rms = float(np.sqrt(np.mean((bias - s.true_bias) ** 2)))
    corrected = scale * (s.rate + bias)
    rate_rms = float(np.sqrt(np.mean((corrected - s.true_rate) ** 2)))
    return bias_rms, rate_rms


def main(argv: list[str]) -> None:
    """Print the accuracy and speed tables."""
    ap = argparse.ArgumentParser(prog="python -m bench tracker")
    ap.add_argument("--sessions", type=int, default=3)
    ap.add_argument("--duration", type=float, default=1800.0)
    args = ap.parse_args(argv)
    if args.sessions < 1:
        ap.error("--sessions must be at least 1")
    try:
        import imufusion
    except ImportError:
        print("bench tracker needs imufusion: pip install '.[bench]'")
        return

    methods = ["ours (bias RW + tempco)", "ours (bias RW only)", "Fusion default (3 dps, 3 s)",
               "Fusion tuned (0.5 dps, 1 s)"]
    acc: dict[str, list[tuple[float, float]]] = {m: [] for m in methods}
    coverage: dict[str, list[float]] = {m: [] for m in methods[:2]}
    sessions = []
    for k in range(args.sessions):
        s = simulate_session(np.random.default_rng(k), args.duration, model=MODEL)
        cal = sim_calibration(np.random.default_rng(1000 + k), s)
        sessions.append((s, cal))
        for name, tm in ((methods[0], True), (methods[1], False)):
            r = BiasTracker(_settings(tm), cal).process(s.t, s.rate, s.temperature_c,
                                                        finish=True)
            acc[name].append(_errors(s, cal, r.bias))
            coverage[name].append(float(np.mean(np.abs(r.bias - s.true_bias) <= 3 * r.bias_std)))
        acc[methods[2]].append(_errors(s, cal, _fusion(imufusion, s, cal, 3.0, 3.0)))
        acc[methods[3]].append(_errors(s, cal, _fusion(imufusion, s, cal, 0.5, 1.0)))

    def pooled(name: str, j: int) -> float:
        return float(np.sqrt(np.mean([a[j] ** 2 for a in acc[name]])))

    rows = []
    for name in methods:
        rows.append([
            name,
            pooled(name, 0),
            pooled(name, 1),
            f"{100 * np.mean(coverage[name]):.2f} %" if name in coverage else "-",
        ])
    print_table(
        ["method", "RMS bias error rad/s", "RMS corrected-rate error rad/s", "inside 3 sigma"],
        rows,
        title=f"accuracy: {args.sessions} simulated sessions of {args.duration:g} s at {ODR:g} Hz "
        f"(white noise {MODEL.white_std(ODR)[0]:.2e} rad/s per sample; same sessions for all)",
    )
    ratio_rows = []
    for ours in methods[:2]:
        for fus in methods[2:]:
            ratio_rows.append([
                f"{ours} / {fus}",
                pooled(ours, 0) / pooled(fus, 0),
                pooled(ours, 1) / pooled(fus, 1),
            ])
    print_table(["ratio", "bias error", "corrected-rate error"], ratio_rows,
                title="ratios (target: bias error <= 0.5, corrected-rate error < 1)")

    # ---- speed
    s, cal = sessions[0]
    best = math.inf
    for _ in range(3):
        tr = BiasTracker(_settings(True), cal)
        t0 = time.perf_counter()
        tr.process(s.t, s.rate, s.temperature_c, finish=True)
        best = min(best, time.perf_counter() - t0)
    n_stream = min(s.n, 20_000)
    lat = np.empty(n_stream)
    tr = BiasTracker(_settings(True), cal)
    for i in range(n_stream):
        t0 = time.perf_counter()
        tr.update(s.rate[i], s.t[i], s.temperature_c[i])
        lat[i] = time.perf_counter() - t0
    fb = imufusion.Bias()
    fb.set_settings(imufusion.BiasSettings(ODR, 3.0, 3.0))
    rate_dps = s.rate[:n_stream] * DEG
    t0 = time.perf_counter()
    for i in range(n_stream):
        fb.update(rate_dps[i])
    fusion_us = (time.perf_counter() - t0) / n_stream * 1e6
    print_table(
        ["mode", "samples", "figure"],
        [
            ["batch (process, whole session)", s.n, f"{s.n / best:,.0f} samples/s"],
            ["streaming (update) median", n_stream, f"{np.median(lat) * 1e6:.0f} us/sample"],
            ["streaming (update) p99", n_stream, f"{np.percentile(lat, 99) * 1e6:.0f} us/sample"],
            ["streaming (update) throughput", n_stream, f"{n_stream / lat.sum():,.0f} samples/s"],
            ["Fusion Bias.update (C)", n_stream, f"{fusion_us:.2f} us/sample"],
        ],
        title="speed (temperature model on; this machine)",
    )
