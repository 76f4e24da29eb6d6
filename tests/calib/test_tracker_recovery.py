"""A calibration whose bias went stale (the ordinary case after a power cycle: MPU-9250 initial
zero-rate tolerance ±5 °/s, PS-MPU-9250A-01 §3.1) is corrected at the first rest, and said.

Sessions come from bench.sessions, the independent generator (written from the model alone,
sharing no code with the tracker or gyrocal.calib.noise_sim); the truth is its true bias.
"""

import math

import numpy as np
import pytest

from bench.sessions import generate
from gyrocal.calib.model import GyroCalibration
from gyrocal.calib.tracker import BiasTracker, TrackerSettings

#: Seed offsets on every axis (+, -, +), rad/s: 0.6, 1.1 and 5 deg/s.
STALE = (10e-3, 20e-3, 87e-3)


@pytest.fixture(scope="module")
def session():
    # 100 Hz: per-sample noise 1.1-1.8e-3 rad/s, so the old detector's gate (5 sigma about the
    # tracker's own bias, 6-9 mrad/s) never opened for a seed 10 mrad/s off
    s = generate("temperature cycle", 7, odr_hz=100.0)
    n = int(40.0 * s.odr_hz)  # the first rest (0-8.3 s), a turn, the second rest
    return s, n


def _seeded(s, offset, bias_std=2e-4):
    """A calibration of the session's sensor whose bias is the true one at the start plus
    ``offset``, claiming ``bias_std``."""
    return GyroCalibration(scale=tuple(s.calibration.scale), bias=tuple(s.true_bias[0] + offset),
                           scale_std=(2e-4,) * 3, bias_std=(bias_std,) * 3, method="stale",
                           temperature_c=float(s.temperature_c[0]))


def _track(s, n, cal):
    st = TrackerSettings(odr_hz=s.odr_hz, noise_density=tuple(s.noise_density))
    tr = BiasTracker(st, cal)
    return tr, tr.process(s.t[:n], s.rate[:n])  # the detector alone decides what is still


@pytest.mark.parametrize("d", STALE)
def test_a_stale_seed_converges_at_the_first_rest_and_is_reported(session, d):
    s, n = session
    offset = d * np.array([1.0, -1.0, 1.0])
    tr, r = _track(s, n, _seeded(s, offset))
    end = int((s.rests[0][1] - 0.3) * s.odr_hz)  # before the first turn
    err = r.bias[end] - s.true_bias[end]
    # within the band it states, and far inside the offset it started from
    assert np.all(np.abs(err) <= 3 * r.bias_std[end]), (err, r.bias_std[end])
    assert np.all(np.abs(err) < 5e-4)
    moved = tr.bias_moved
    assert moved is not None and moved.axes == ("x", "y", "z")
    assert r.bias_moved is moved  # on the result too
    assert moved.t < s.rests[0][1]
    # what moved: the true bias less the seed, i.e. -offset (to the first window's noise)
    np.testing.assert_allclose(moved.moved, -offset, atol=1e-3)
    assert "the bias moved by" in moved.message()
    assert moved.as_dict()["axes"] == ["x", "y", "z"]


def test_the_report_fires_beyond_the_calibrations_sigma_and_not_within(session):
    s, n = session
    sd = 1e-3  # well above a window's noise (about 3e-4), so the bound is the seed's sigma
    sign = np.array([1.0, -1.0, 1.0])
    within, _ = _track(s, n, _seeded(s, 3 * sd * sign, bias_std=sd))
    assert within.bias_moved is None
    beyond, r = _track(s, n, _seeded(s, np.array([8 * sd, 0.0, 0.0]), bias_std=sd))
    assert beyond.bias_moved is not None and beyond.bias_moved.axes == ("x",)
    assert beyond.bias_moved.sigma[0] == pytest.approx(sd, rel=0.2)
    end = int((s.rests[0][1] - 0.3) * s.odr_hz)
    assert abs(r.bias[end, 0] - s.true_bias[end, 0]) < 5e-4


def test_the_detector_does_not_follow_the_estimate(session):
    """The rate test is centred on the seed and never moves: the detector built for a tracker
    has the same thresholds before and after it tracked, with room for the zero-rate
    tolerance."""
    s, n = session
    tr, _ = _track(s, n, _seeded(s, np.zeros(3)))
    st = tr.settings
    np.testing.assert_allclose(tr.detector.rate_limit,
                               st.still.rate_sigma * st.noise_std + math.radians(5.0))
    before = tr._det_bias_l
    np.testing.assert_allclose(before, s.true_bias[0])


def test_a_stale_seed_in_a_smoothed_replay_is_carried_back_to_the_start(session):
    """Before the first rest's update the filter still holds the stale seed; the replay's
    smoother carries the first rest's bias back over those samples."""
    s, n = session
    offset = 20e-3 * np.array([1.0, -1.0, 1.0])
    st = TrackerSettings(odr_hz=s.odr_hz, noise_density=tuple(s.noise_density))
    tr = BiasTracker(st, _seeded(s, offset), keep_states=True)
    r = tr.process(s.t[:n], s.rate[:n], finish=True)
    b, sd = tr.smoothed(s.t[:n])
    early = slice(0, int(0.5 * s.odr_hz))  # before any update
    assert np.all(np.abs(r.bias[early] - s.true_bias[early]) > 9e-3)  # causal: the seed
    assert np.all(np.abs(b[early] - s.true_bias[early]) <= 3 * sd[early])
    assert np.all(np.abs(b[early] - s.true_bias[early]) < 1.5e-3)
