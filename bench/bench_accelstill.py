"""The still detector's accelerometer veto on real recordings (issue 30, "Tracker recovery").

For each real session with a gyro and an accelerometer (``bench/real_corpus.py``: Fusion's
sample recording, imu_tk's Xsens session, imucal's Ferraris session), the tracker's still
fraction with the gyro alone and with the accelerometer's veto
(:func:`gyrocal.calib.stationarity.accel_detector`), beside the fraction that the corpus's own
rest rule (:func:`bench.real_corpus.still_spans`, gyro and accelerometer spread under three
times their 5th percentile, shared with nothing under test) calls still, and how much of that
the tracker keeps. The noise figures are read from the data as ``gyrocal track`` reads them
(:func:`gyrocal.calib.stationarity.quiet_noise_std`); the seed is the first still second's mean
(as ``track`` without ``--cal``). Not held out: the test's form (the slope, not the variance,
of the accelerometer) was chosen after a variance test at the white-noise limit kept only 49-73 %
of these sessions' rests; no threshold was fitted to them (the limit is the noise's, at
``variance_alpha``).

Usage: ``python -m bench accelstill``.
"""

from __future__ import annotations

import math

import numpy as np

from bench import real_corpus
from bench.table import print_table
from gyrocal.calib.stationarity import first_still_mean, quiet_noise_std
from gyrocal.calib.tracker import BiasTracker, TrackerSettings


def still_fraction(s: real_corpus.Session, accel: bool) -> np.ndarray:
    """The tracker's still flags over the session (gyro alone, or with the accelerometer)."""
    odr = s.odr_hz
    block = max(8, int(round(odr)))
    sigma = quiet_noise_std(s.gyro, block)
    a_sigma = quiet_noise_std(s.accel, block) if accel else None
    st = TrackerSettings(odr_hz=odr, noise_density=tuple(sigma / math.sqrt(odr)),
                         accel_noise_std=None if a_sigma is None else tuple(a_sigma))
    guess = first_still_mean(s.gyro, st.noise_std, odr, st.still)
    b0 = np.zeros(3) if guess is None else -guess
    tr = BiasTracker(st, initial_bias=b0, initial_bias_std=(1e-3,) * 3)
    return tr.process(s.t, s.gyro, accel=s.accel if accel else None, finish=True).still


def main(argv: list[str]) -> None:
    rows = []
    for name in ("fusion", "imutk", "imucal"):
        path = real_corpus.locate(name)
        if path is None:
            rows.append([name, real_corpus.missing_reason(name), "", "", "", "", ""])
            continue
        s = real_corpus.load(name, path)
        ref = np.zeros(s.t.size, dtype=bool)
        for lo, hi in real_corpus.still_spans(s.gyro, s.accel, s.odr_hz):
            ref[lo:hi] = True
        g = still_fraction(s, False)
        a = still_fraction(s, True)
        rows.append([name, f"{s.t[-1] - s.t[0]:.0f}", f"{ref.mean():.3f}", f"{g.mean():.3f}",
                     f"{a.mean():.3f}", f"{a[ref].mean():.3f}" if ref.any() else "-",
                     f"{(g & ~a).mean():.3f}"])
    print_table(["session", "s", "still (corpus rule)", "still (gyro)", "still (gyro+accel)",
                 "corpus rests kept (gyro+accel)", "vetoed by accel"], rows,
                title="Still fraction on real recordings with and without the accelerometer")
