"""kit.tracking's replay pieces: estimates kept at chosen rows only, and reference rates made
per chunk, give what the whole-array run gives (issue 16: track in bounded memory)."""

import numpy as np

from gyrocal.calib.noise_sim import NoiseModel, sim_calibration, simulate_session
from gyrocal.calib.tracker import BiasTracker, TrackerSettings
from gyrocal.kit.tracking import Batch, Reference, chunks, replay_chunks, run_tracker

MODEL = NoiseModel(rate_random_walk=1e-5)


def _session():
    s = simulate_session(np.random.default_rng(31), 60.0, model=MODEL, motion="jig",
                         still_s=(1.0, 3.0), motion_s=(3.0, 5.0))
    cal = sim_calibration(np.random.default_rng(32), s)
    st = TrackerSettings(odr_hz=200.0, noise_density=MODEL.noise_density,
                         rate_random_walk=MODEL.rate_random_walk, temperature_model=True,
                         reference_axis_std=1e-4)
    return s, cal, st


def test_kept_rows_and_chunked_references_equal_the_whole_run():
    s, cal, st = _session()
    whole = Batch(s.t, s.rate, s.temperature_c, None, s.reference_rate, s.reference_axis)
    full = run_tracker(BiasTracker(st, cal, keep_states=True), chunks(whole, 997))
    # the references as rotate runs: contiguous stretches of finite rate about one axis
    has = np.isfinite(s.reference_rate)
    edges = np.flatnonzero(np.diff(np.concatenate([[0], has.astype(int), [0]])))
    runs = [(int(a), s.reference_rate[a:b].copy(), s.reference_axis[a].copy())
            for a, b in zip(edges[::2], edges[1::2], strict=True)]
    assert len(runs) >= 4
    ref = Reference(runs)
    rows = np.unique(np.random.default_rng(33).integers(0, s.n, 500))
    bare = Batch(s.t, s.rate, s.temperature_c)
    tr = BiasTracker(st, cal, keep_states=True)
    kept = run_tracker(tr, replay_chunks(bare, ref, 997), rows=rows)
    assert kept.t.size == rows.size and kept.still.size == s.n
    np.testing.assert_array_equal(kept.t, s.t[rows])
    np.testing.assert_allclose(kept.bias, full.bias[rows], rtol=0, atol=1e-15)
    np.testing.assert_allclose(kept.bias_std, full.bias_std[rows], rtol=1e-13)
    np.testing.assert_array_equal(kept.still, full.still)
    np.testing.assert_array_equal(kept.nis_ok, full.nis_ok[rows])
    assert kept.since_max == full.since_update_s.max()
    np.testing.assert_array_equal(kept.update_kind, full.update_kind)
    assert "reference" in set(kept.update_kind)
    # a chunk off every turn gets no reference arrays at all; one across a turn gets NaN off it
    a, b = runs[0][0] - 10, runs[0][0] + 10
    rr, ra = ref.window(a, b)
    assert np.all(np.isnan(rr[:10])) and np.all(np.isfinite(rr[10:]))
    np.testing.assert_array_equal(ra[10:], np.broadcast_to(runs[0][2], (10, 3)))
    assert ref.window(0, 1) is None or runs[0][0] == 0
