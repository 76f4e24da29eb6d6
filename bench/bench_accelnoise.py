"""The accelerometer's white-noise density from the rests (issue 15;
:func:`gyrocal.calib.accel.white_noise_density`, Kalibr's continuous-time
``accelerometer_noise_density``).

Table 1. Coverage over Monte Carlo runs: twelve 0.6 s rests at 200 Hz (the default protocol's
accelerometer rests), white noise of a known density per axis, each rest around its own gravity
reading; how often the truth lies within 1σ and 2σ of the estimate, the mean and spread of
``(estimate − truth)/σ``, and the relative σ.

Table 2. The chip's low-pass: 1 kHz samples through a second-order Butterworth low-pass (unit
DC gain) at the cutoff given, long rests (100 × 3 s); the estimate's bias against the truth, and
what the naive per-sample scatter ``σ_d / sqrt(ODR)`` would give instead.

Data: the independent generator of tests/calib/test_accel_noise.py (numpy and scipy.signal, no
gyrocal code). Usage: ``python -m bench accelnoise [--quick] [--runs=N]``.
"""

from __future__ import annotations

import math

import numpy as np

from bench.table import print_table
from gyrocal.calib.accel import white_noise_density
from tests.calib.test_accel_noise import _rests


def main(argv: list[str]) -> None:
    n = next((a.split("=", 1)[1] for a in argv if a.startswith("--runs=")), None)
    if n is not None and not (n.isdigit() and int(n) > 0):
        raise SystemExit(f"--runs needs a positive whole number, got {n!r}")
    runs = int(n) if n is not None else 100 if "--quick" in argv else 400
    rng = np.random.default_rng(2026)
    truth = np.array([2e-3, 3e-3, 0.7e-3])
    z, rel = [], []
    for _ in range(runs):
        t, x, spans = _rests(rng, truth, 200.0, 12, 0.6)
        d, s, _, _ = white_noise_density(t, x, spans)
        z.append((d - truth) / s)
        rel.append(s / d)
    z = np.array(z)
    print_table(["runs × axes", "within 1σ", "within 2σ", "mean z", "std z", "relative σ"],
                [[f"{runs} × 3", f"{100 * np.mean(np.abs(z) < 1):.1f} %",
                  f"{100 * np.mean(np.abs(z) < 2):.1f} %", f"{z.mean():+.3f}",
                  f"{z.std():.3f}", f"{100 * np.mean(rel):.1f} %"]],
                "Table 1: 12 rests of 0.6 s at 200 Hz, white noise (expected 68.3 % / 95.4 %)")
    rows, taus = [], set()
    density = np.full(3, 1e-3)
    for cutoff in (20.0, 50.0, 100.0, 200.0, None):
        t, x, spans = _rests(rng, density, 1000.0, 100, 3.0, lowpass_hz=cutoff)
        d, s, tau, _ = white_noise_density(t, x, spans)
        taus.add(f"{tau:.3g}")
        first = (t >= spans[0, 0]) & (t <= spans[0, 1])  # the first rest, whole
        naive = x[first].std(axis=0) / math.sqrt(1000.0)
        rows.append(["none" if cutoff is None else f"{cutoff:g}",
                     f"{100 * (d.mean() / 1e-3 - 1):+.1f} %", f"{100 * s.mean() / 1e-3:.1f} %",
                     f"{100 * (naive.mean() / 1e-3 - 1):+.0f} %"])
    print_table(["low-pass Hz", "estimate − truth", "its σ", "naive σ_d/√ODR − truth"], rows,
                "Table 2: 1 kHz, 100 rests of 3 s, density 1e-3 m/s²/√Hz, the estimate's "
                f"τ = {' / '.join(sorted(taus))} s; naive: the first rest's samples")
