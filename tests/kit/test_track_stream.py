"""``gyrocal track`` on a recording streams it (issue 16): the readings go once through the
block reader into a temporary file and are read back a piece at a time. The output must be
what the whole-array replay gives (the recording loaded whole, every estimate of the noise,
the first still second and the rest checks taken on whole arrays, as before the streaming):
that replay is written out here from the library's whole-array functions, and the streamed
command is run with tiny blocks, pieces and running-sum blocks so that every piece boundary
is crossed many times.
"""

import argparse
import json
import math

import numpy as np
import pytest

from gyrocal.calib import stationarity
from gyrocal.calib.stationarity import StillDetector, quiet_windows
from gyrocal.kit import recording
from gyrocal.kit.cli import main
from gyrocal.kit.commands import track
from gyrocal.kit.recording import load_recording
from gyrocal.kit.tracking import (
    Batch,
    reference_segments,
    replay_chunks,
    run_tracker,
    smooth_tracked,
)


@pytest.fixture(scope="module")
def rec(tmp_path_factory):
    """A seeded simulated calibration run (turns and rests), and its estimated calibration."""
    d = tmp_path_factory.mktemp("stream")
    assert main(["simulate-recording", str(d / "rec"), "--seed", "5", "--turns", "1",
                 "--rest", "4", "--odr", "200"]) == 0
    assert main(["estimate", str(d / "rec"), "--out", str(d / "cal.json")]) == 0
    return d / "rec", d / "cal.json"


def whole_array_track(path, argv):
    """The replay with the recording held whole (the code path before streaming)."""
    p = argparse.ArgumentParser()
    track.add_arguments(p)
    args = p.parse_args([str(path), *argv])
    r = load_recording(path)
    odr = 1.0 / float(np.median(np.diff(r.imu_t)))
    if args.tempco is None:
        args.tempco = bool(np.all(np.isfinite(r.imu_temp)))
    tracker, cal = track._build_tracker(args, odr, r.imu_rate, [], "the recording", str(path),
                                        keep_states=not args.causal)
    still = None
    if args.still == "segments" or (args.still == "auto"
                                    and any(s.kind == "rest" for s in r.segments)):
        det = tracker.detector
        loose = StillDetector(det.n_window, det.n_min, det.n_lookahead, det.var_limit,
                              np.full(3, np.inf))
        still = np.full(r.imu_t.size, 0.0 if args.still == "segments" else math.nan)
        for seg in r.segments:
            if seg.kind != "rest" or seg.duration <= 1.0:
                continue
            sel = (r.imu_t >= seg.t_start + 0.5) & (r.imu_t <= seg.t_end - 0.5)
            if args.still == "auto":
                q = quiet_windows(r.imu_rate[sel], loose, 0)[loose.n_window - 1:]
                if q.size == 0 or q.mean() < 0.95:
                    continue
            still[sel] = 1.0
    ref = None
    if cal is not None and not args.no_reference:
        ref, _ = reference_segments(r, cal)
        ref = ref if ref.runs else None
        if ref is not None and still is not None:
            for i0, rate, _ in ref.runs:
                still[i0:i0 + rate.size][np.isfinite(rate)] = 0.0
    batch = Batch(r.imu_t, r.imu_rate, r.imu_temp if args.tempco else None, still)
    tr = run_tracker(tracker, replay_chunks(batch, ref, 65_536))
    if not args.causal:
        tr = smooth_tracked(tracker, tr, batch.temperature)
    return tr


@pytest.mark.parametrize("argv", [
    [],                                              # no --cal: the first still second
    ["--cal", "CAL"],                                # reference-rate updates, rest checks
    ["--cal", "CAL", "--still", "segments", "--no-tempco"],
    ["--cal", "CAL", "--still", "detect", "--causal"],
], ids=["no-cal", "cal", "segments", "detect-causal"])
def test_streamed_replay_equals_the_whole_array_replay(rec, argv, monkeypatch, capsys):
    path, cal = rec
    argv = [str(cal) if a == "CAL" else a for a in argv]
    want = whole_array_track(path, argv)
    # every piece boundary crossed many times: reader blocks, replay pieces, running sums
    monkeypatch.setattr(recording, "BLOCK_BYTES", 8192)
    monkeypatch.setattr(track, "REPLAY_CHUNK", 1000)
    monkeypatch.setattr(stationarity, "_BLOCK", 64)
    assert main(["track", str(path), *argv, "--json", "--every", "0"]) == 0
    doc = json.loads(capsys.readouterr().out)
    np.testing.assert_array_equal(doc["t"], want.t)
    np.testing.assert_array_equal(doc["still"], want.still)
    np.testing.assert_allclose(doc["bias"], want.bias, rtol=0, atol=1e-12)
    np.testing.assert_allclose(doc["bias_std"], want.bias_std, rtol=1e-12, atol=0)
    # the run is long enough to cross the pieces, with turns updating the filter
    assert len(doc["t"]) > 8 * 1000 and 0 < np.mean(doc["still"]) < 1


def test_a_bad_row_stops_the_streamed_replay_at_its_line(rec, tmp_path, monkeypatch, capsys):
    import shutil

    path, _ = rec
    bad = tmp_path / "bad"
    shutil.copytree(path, bad)
    lines = (bad / "imu.csv").read_text().split("\n")
    lines[7001] = lines[7001].replace(",", ",x", 1)
    (bad / "imu.csv").write_text("\n".join(lines))
    monkeypatch.setattr(recording, "BLOCK_BYTES", 8192)
    assert main(["track", str(bad), "--json"]) == 2
    out, err = capsys.readouterr()
    assert out == "" and "imu.csv:7002: field 2 is 'x" in err and "Traceback" not in err


def test_pieces_of_the_stationarity_estimates_equal_the_whole(monkeypatch):
    """quiet_noise_std, first_still_mean and quiet_fraction read piecewise give the whole
    array's answer bit for bit, on readings with still and moving stretches."""
    monkeypatch.setattr(stationarity, "_BLOCK", 50)
    rng = np.random.default_rng(12)
    n = 9000
    m = rng.normal(scale=1e-3, size=(n, 3)) + 0.02
    m[:700] += np.sin(np.arange(700) / 30.0)[:, None]  # moving first: the still start is late
    m[4000:4600] += 0.5
    read = lambda a, b: m[a:b].copy()  # noqa: E731
    np.testing.assert_array_equal(stationarity.quiet_noise_std(None, 100, n=n, read=read),
                                  stationarity.quiet_noise_std(m, 100))
    sig = np.full(3, 1e-3)
    got = stationarity.first_still_mean(None, sig, 100.0, n=n, read=read)
    np.testing.assert_array_equal(got, stationarity.first_still_mean(m, sig, 100.0))
    assert got is not None
    full = StillDetector.build(sig, 100.0)
    det = StillDetector(full.n_window, full.n_min, full.n_lookahead, full.var_limit,
                        np.full(3, np.inf))  # the variance test only, as the rest checks
    whole = quiet_windows(m, det, 0)[det.n_window - 1:]
    assert stationarity.quiet_fraction(n, read, det, blocks=3) == whole.mean()
    assert 0.5 < whole.mean() < 0.95
    assert stationarity.quiet_fraction(det.n_window - 1, read, det) is None


def test_json_rows_by_pieces_equal_the_whole_formula(monkeypatch):
    from gyrocal.kit import tracking

    monkeypatch.setattr(tracking, "JSON_PIECE_ROWS", 16)  # pieces of 128 samples
    rng = np.random.default_rng(8)
    for n in (2, 3, 127, 128, 129, 130, 1000):
        t = np.cumsum(rng.uniform(0.0005, 0.0015, n))
        for every in (0.001, 0.01, 0.37):
            cell = np.floor((t - t[0]) / every).astype(np.int64)
            want = np.flatnonzero(np.append(cell[1:] != cell[:-1], True))
            got, used = tracking.json_rows(t, every, None)
            if want.size == n:
                assert used is None
                want = np.arange(n)
            np.testing.assert_array_equal(got, want)


def test_json_pieces_are_json_dumps_text_and_refuse_nan_before_writing(monkeypatch):
    from gyrocal.kit import tracking

    monkeypatch.setattr(tracking, "JSON_PIECE_ROWS", 7)
    rng = np.random.default_rng(9)
    cols = {"t": rng.normal(size=50), "bias": rng.normal(size=(50, 3)) * 1e-3,
            "still": rng.random(50) < 0.5, "empty": np.empty((0, 3)), "every": 0.25}
    text = "".join(tracking.json_pieces({k: (lambda v=v: v) for k, v in cols.items()}))
    want = {k: v.tolist() if isinstance(v, np.ndarray) else v for k, v in cols.items()}
    assert text == json.dumps(want) + "\n"
    cols["bias"][31, 1] = np.nan
    pieces = tracking.json_pieces({k: (lambda v=v: v) for k, v in cols.items()})
    with pytest.raises(ValueError, match="bias"):
        next(pieces)


def test_encoder_rows_kept_near_turns_interpolate_as_all_rows():
    """However the file is cut into blocks and however sparse a servo's readings (gaps longer
    than the windows, a servo read once), interpolation anywhere in a window over the kept
    readings equals interpolation over all of them, and so does the reference rate."""
    from gyrocal.kit.report_plots import encoder_rate
    from gyrocal.kit.tracking import _NearTurns

    rng = np.random.default_rng(14)
    for trial in range(20):
        rows = []
        for m, n in ((1, 400), (2, 30), (3, 1)):
            t = np.sort(rng.uniform(0, 100, n))
            rows += [(ti, m, rng.normal()) for ti in t]
        rows.sort()
        et = np.array([r[0] for r in rows])
        em = np.array([r[1] for r in rows], dtype=np.int64)
        ea = np.array([r[2] for r in rows])
        lo = np.sort(rng.uniform(0, 95, 4))
        lo = lo[np.concatenate([[True], np.diff(lo) > 3])]
        hi = lo + rng.uniform(0.1, 3, lo.size)
        # servo 1 turns in the windows; every servo is read at their middles (turn_axis)
        near = _NearTurns({1: list(zip(lo, hi, strict=True)),
                           None: [((a + b) / 2, (a + b) / 2) for a, b in zip(lo, hi,
                                                                             strict=True)]})
        cuts = np.sort(rng.integers(0, et.size, 6))
        for a, b in zip(np.r_[0, cuts], np.r_[cuts, et.size], strict=True):
            near.add(et[a:b], em[a:b], ea[a:b])
        kt, km, ka = near.columns()
        assert kt.size < et.size
        # queries as a replay makes them: inside the windows by the half span at least
        q = np.concatenate([rng.uniform(a + 0.01, b - 0.01, 50) for a, b in zip(lo, hi,
                                                                             strict=True)])
        mids = (lo + hi) / 2
        for m in (1, 2, 3):
            full_t, full_a = et[em == m], ea[em == m]
            got_t, got_a = kt[km == m], ka[km == m]
            assert np.all(np.diff(got_t) >= 0), trial
            np.testing.assert_array_equal(np.interp(mids, got_t, got_a),
                                          np.interp(mids, full_t, full_a))
            if m == 1:
                np.testing.assert_array_equal(np.interp(q, got_t, got_a),
                                              np.interp(q, full_t, full_a))
                np.testing.assert_array_equal(encoder_rate(got_t, got_a, q, 0.01),
                                              encoder_rate(full_t, full_a, q, 0.01))
