"""The tracker's streaming paths on sessions of the independent generator (bench.sessions, which
shares no code with gyrocal.calib.noise_sim): update() one sample at a time, process() on
FIFO-sized drains and feed() in blocks must give what one process() batch gives."""

import numpy as np
import pytest

from bench.bench_tracker import _reference
from bench.sessions import generate
from gyrocal.calib.tracker import BiasTracker, TrackerSettings

#: The samples of each family's session (1 kHz) run here. The jig's first 20 s: a rest, turns
#: with the encoder's reference about each axis, part of the next rest (73 updates of both
#: kinds). The bias-steps session's first steps come at 286 s and 451 s (its first 30 s are the
#: jig's turns again, with no step): 270-300 s hold the first, rests and turns around it.
WINDOWS = {"jig turns, 6-15 s rests": slice(0, 20_000), "bias steps": slice(270_000, 300_000)}


@pytest.mark.parametrize("family", list(WINDOWS))
def test_update_drains_and_feed_equal_one_batch_at_1khz(family):
    s = generate(family, 7, 1000.0)
    rr, ra = _reference(s)
    w = WINDOWS[family]
    t, m, temp, rr, ra = s.t[w], s.rate[w], s.temperature_c[w], rr[w], ra[w]
    N = t.size
    st = TrackerSettings(odr_hz=s.odr_hz, noise_density=tuple(s.noise_density),
                         temperature_model=True)
    batch_tr = BiasTracker(st, s.calibration)
    batch = batch_tr.process(t, m, temp, reference_rate=rr, reference_axis=ra)
    assert np.isfinite(rr).sum() > 1000 and batch.updates.t.size > 50
    assert set(batch.updates.kind) == {"still", "reference"}
    steps = [u for u in s.step_times if t[0] < u < t[-1]]
    assert (len(steps), int(batch.updates.alarm.sum()) > 0) == (
        (1, True) if family == "bias steps" else (0, False))
    # update(): the same estimate at every sample
    up = BiasTracker(st, s.calibration)
    bias = np.empty((N, 3))
    for i in range(N):
        ref = {} if np.isnan(rr[i]) else {"reference_rate": float(rr[i]),
                                           "reference_axis": ra[i]}
        up.update(m[i], t[i], temp[i], **ref)
        bias[i] = up.bias
    np.testing.assert_allclose(bias, batch.bias, rtol=0, atol=1e-15)
    assert up.health.updates == batch.updates.t.size
    # process() on 37-sample drains (pooled a row at a time): the same estimates and log
    dr = BiasTracker(st, s.calibration)
    parts = [dr.process(t[a:a + 37], m[a:a + 37], temp[a:a + 37],
                        reference_rate=rr[a:a + 37], reference_axis=ra[a:a + 37])
             for a in range(0, N, 37)]
    np.testing.assert_allclose(np.vstack([p.bias for p in parts]), batch.bias, rtol=0,
                               atol=1e-15)
    np.testing.assert_array_equal(np.concatenate([p.updates.applied_at for p in parts]),
                                  batch.updates.applied_at)
    # feed() in blocks: the batch's final state
    fd = BiasTracker(st, s.calibration)
    for i in range(N):
        ref = {} if np.isnan(rr[i]) else {"reference_rate": float(rr[i]),
                                           "reference_axis": ra[i]}
        fd.feed(m[i], t[i], temp[i], **ref)
    fd.flush()
    np.testing.assert_allclose(fd.bias, batch_tr.bias, rtol=0, atol=1e-15)
    assert fd.health.updates == batch_tr.health.updates
