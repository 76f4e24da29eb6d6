"""The still detector's accelerometer veto (issue 30, "Tracker recovery").

The session comes from the physics, written out here and sharing nothing with the tracker: the
sensor rests, turns slowly at a constant rate about its x axis (horizontal), rests again. The
gyro reads ``m = ω − b + v`` (Calibration v1: a still sensor reads ``−b``); the accelerometer
reads the specific force ``f = g (0, sin θ, cos θ)``, ``θ = ∫ω``, plus white noise. The turn is
at 2 °/s, inside the gyro's rate gate (5 σ plus the MPU-9250's ±5 °/s zero-rate tolerance,
PS-MPU-9250A-01 Table 1) and steady (its variance is the noise's), so the gyro alone takes it
for rest; the accelerometer sees gravity turn by 2° a second.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from gyrocal.calib.errors import CalibInputError
from gyrocal.calib.tracker import BiasTracker, TrackerSettings

ODR = 100.0
G = 9.80665
GYRO_N = 0.01 * math.pi / 180.0  # rad/s/√Hz: the MPU-9250's 0.01 °/s/√Hz (Table 1)
ACCEL_SIGMA = 300e-6 * G * math.sqrt(ODR / 2)  # 300 µg/√Hz over ODR/2 (Table 2), m/s²
OMEGA = math.radians(2.0)
BIAS = np.array([0.012, -0.007, 0.004])
REST1, TURN, REST2 = 6.0, 20.0, 6.0


def session(seed: int) -> dict[str, np.ndarray]:
    """Rest, a slow turn about x, rest: times, gyro, accelerometer, the turn's mask."""
    rng = np.random.default_rng(seed)
    n = int((REST1 + TURN + REST2) * ODR)
    t = np.arange(n) / ODR
    turning = (t >= REST1) & (t < REST1 + TURN)
    omega = np.where(turning, OMEGA, 0.0)
    theta = np.cumsum(omega) / ODR
    gyro = -BIAS + rng.normal(0.0, GYRO_N * math.sqrt(ODR), (n, 3))
    gyro[:, 0] += omega
    f = G * np.column_stack([np.zeros(n), np.sin(theta), np.cos(theta)])
    accel = f + rng.normal(0.0, ACCEL_SIGMA, (n, 3))
    return {"t": t, "gyro": gyro, "accel": accel, "turning": turning}


def tracker(with_accel: bool) -> BiasTracker:
    st = TrackerSettings(odr_hz=ODR, noise_density=(GYRO_N,) * 3,
                         rate_random_walk=(1e-5,) * 3,
                         accel_noise_std=(ACCEL_SIGMA,) * 3 if with_accel else None)
    return BiasTracker(st, initial_bias=BIAS, initial_bias_std=(1e-3,) * 3)


@pytest.fixture(scope="module")
def runs() -> dict[str, object]:
    s = session(30)
    out: dict[str, object] = {"s": s}
    for name, acc in (("gyro", None), ("accel", s["accel"])):
        tr = tracker(acc is not None)
        out[name] = tr.process(s["t"], s["gyro"], accel=acc, finish=True)
        out[name + "_tracker"] = tr
    return out


def test_gyro_alone_takes_the_slow_turn_for_rest(runs):
    s, res = runs["s"], runs["gyro"]
    inner = s["turning"] & (s["t"] > REST1 + 2) & (s["t"] < REST1 + TURN - 2)
    assert res.still[inner].mean() > 0.9  # the premise: within the gyro's gates
    # ... and by the end of the turn has pulled the bias on x towards b − ω (a still sensor
    # reads −b)
    end = int((REST1 + TURN) * ODR) - 1
    assert abs(res.bias[end, 0] - (BIAS[0] - OMEGA)) < 0.25 * OMEGA


def test_accelerometer_refuses_the_slow_turn(runs):
    s, res = runs["s"], runs["accel"]
    assert res.still[s["turning"]].mean() < 0.01
    # the rests are still seen (less the settling and the look-ahead at their edges)
    rest1 = (s["t"] > 1.5) & (s["t"] < REST1 - 0.5)
    rest2 = s["t"] > REST1 + TURN + 1.5
    assert res.still[rest1].mean() > 0.95
    assert res.still[rest2[: res.still.size] & res.decided].mean() > 0.95
    # the bias stays where the rests put it, through the turn: within 5 σ of the truth
    end = int((REST1 + TURN) * ODR) - 1
    assert np.all(np.abs(res.bias[end] - BIAS) < 5 * res.bias_std[end])


def test_batches_decide_alike(runs):
    s = runs["s"]
    tr = tracker(True)
    still = []
    n = s["t"].size
    for a in range(0, n, 37):
        b = min(n, a + 37)
        r = tr.process(s["t"][a:b], s["gyro"][a:b], accel=s["accel"][a:b], finish=b == n)
        still.append(r.decision_still)
    assert np.array_equal(np.concatenate(still), runs["accel"].decision_still)


def test_accel_is_checked():
    s = session(31)
    with pytest.raises(CalibInputError, match="give accel"):
        tracker(True).process(s["t"][:50], s["gyro"][:50])
    with pytest.raises(CalibInputError, match="accel_noise_std"):
        tracker(False).process(s["t"][:50], s["gyro"][:50], accel=s["accel"][:50])
    with pytest.raises(CalibInputError, match="shape"):
        tracker(True).process(s["t"][:50], s["gyro"][:50], accel=s["accel"][:49])


def test_streams_decide_as_the_batch(runs):
    """feed() and update() carry the accelerometer to the detector as process() does."""
    s, ref = runs["s"], runs["accel"]
    fed = tracker(True)
    for i in range(s["t"].size):
        fed.feed(s["gyro"][i], s["t"][i], accel=s["accel"][i])
    fed.flush(finish=True)
    assert fed.last_decision == (s["t"].size - 1, bool(ref.decision_still[-1]))
    assert np.allclose(fed.bias, runs["accel_tracker"].bias, rtol=0, atol=1e-12)
    k = 900  # update() one sample at a time over the first rest and the turn's start
    one = tracker(True)
    still = []
    for i in range(k):
        one.update(s["gyro"][i], s["t"][i], accel=s["accel"][i])
        d = one.last_decision
        if d is not None and d[0] == len(still):
            still.append(d[1])
    assert still == ref.decision_still[: len(still)].tolist()
    assert len(still) > k - 30


def test_slope_test_matches_a_least_squares_fit():
    """accel_quiet_windows' running-sum slope against numpy's polyfit, window by window, with
    the history rows of a previous batch."""
    from gyrocal.calib.stationarity import accel_detector, accel_quiet_windows

    rng = np.random.default_rng(32)
    det = accel_detector((0.02,) * 3, ODR)
    nw = det.n_window
    x = np.cumsum(rng.normal(0, 0.01, (400, 3)), axis=0) + 9.8  # wandering: slopes of all sizes
    h = nw - 1
    got = accel_quiet_windows(x, det, h)
    k = np.arange(nw)
    want = [bool(np.all(np.abs(np.polyfit(k, x[e - nw + 1:e + 1], 1)[0]) <= det.slope_limit))
            for e in range(h, x.shape[0])]
    assert got.tolist() == want
    assert 0 < np.mean(want) < 1  # both outcomes occur
