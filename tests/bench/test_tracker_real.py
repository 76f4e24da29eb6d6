"""The tracker on a real sensor (BROAD's myon aktos-t, bench/real_gyro.py): a stale calibration
is corrected at the first rest and said. Without the excerpt (third-party data in shared/data,
not in the repository) the tests skip and say why.

Only a tuning trial of bench/bench_tracker.py's split (TUNING_TRIALS) is used here: the held-out
trials are for the figures the benchmark reports.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from bench import real_gyro as rg
from bench.bench_tracker import HELD_OUT_TRIALS, TUNING_TRIALS
from gyrocal.calib.model import GyroCalibration
from gyrocal.calib.stationarity import quiet_noise_std
from gyrocal.calib.tracker import BiasTracker, TrackerSettings

TRIAL = "05_undisturbed_slow_rotation_with_breaks_B"


@pytest.fixture(scope="module")
def trials():
    try:
        return rg.load()
    except (OSError, ValueError) as exc:
        pytest.skip(f"the BROAD excerpt is not here ({exc})")


def test_the_split_names_every_trial_once():
    assert TRIAL in TUNING_TRIALS
    assert not set(HELD_OUT_TRIALS) & set(TUNING_TRIALS)
    assert set(HELD_OUT_TRIALS) | set(TUNING_TRIALS) == set(rg.TRIALS)


@pytest.mark.parametrize("d", [20e-3, 87e-3])
def test_a_stale_calibration_is_corrected_at_the_first_real_rest(trials, d):
    """Seeded 20 or 87 mrad/s off on every axis (the other trials' mean bias moved; 87 mrad/s
    is the MPU-9250's zero-rate tolerance, 5 deg/s) with a jig calibration's sigma, the causal
    estimate at the end of the first reference rest agrees with that rest's mean reading (the
    optical reference says it is still) within a few of the rest's own noise, and the tracker
    says the bias moved. The detector decides alone."""
    i = next(k for k, tr in enumerate(trials) if tr.name == TRIAL)
    tr = trials[i]
    b0, _ = rg.leave_one_out_bias(trials, i)
    cal = GyroCalibration(scale=(1.0, 1.0, 1.0),
                          bias=tuple(float(x) for x in b0 + d * np.array([1.0, -1.0, 1.0])),
                          scale_std=(math.nan,) * 3, bias_std=(5e-5,) * 3, method="stale")
    sigma = quiet_noise_std(tr.rate, max(8, int(round(tr.odr_hz))))
    st = TrackerSettings(odr_hz=tr.odr_hz, noise_density=tuple(sigma / math.sqrt(tr.odr_hz)))
    tracker = BiasTracker(st, cal)
    lo, hi = tr.rests()[0]
    r = tracker.process(tr.t[:hi], tr.rate[:hi])
    ref = -tr.rate[lo:hi].mean(axis=0)
    ref_std = sigma / math.sqrt(hi - lo)
    err = r.bias[-1] - ref
    assert np.all(np.abs(err) < 5e-4), err  # was d off: never corrected before issue 30
    assert np.all(np.abs(err) <= 3 * np.hypot(r.bias_std[-1], ref_std) + 1e-4)
    moved = tracker.bias_moved
    assert moved is not None and moved.axes == ("x", "y", "z")
    np.testing.assert_allclose(moved.moved, ref - np.asarray(cal.bias), atol=1e-3)
