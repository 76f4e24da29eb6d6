"""stream_raw_run (bounded memory, issue 16) gives simulate_raw_run's values bit for bit, for the
same generator state, and leaves the generator where simulate_raw_run does."""

from types import SimpleNamespace as RawRunTuple

import numpy as np
import pytest

from gyrocal.calib.segments import Segment
from gyrocal.calib.simulate import (
    TWO_PI,
    SimProtocol,
    _speed_profile,
    draw_mount_axes,
    draw_sensors,
    profile_duration,
    simulate_raw_run,
    stream_raw_run,
)


def whole_run_oracle(rng, scale, bias, axes, protocol, noise_std, *, accel=8.0,
                     imu_clock_error=0.0, enc_rate_hz=100.0, enc_jitter_s=0.0, imu_jitter_s=0.0,
                     encoder_ticks=4096, motor_ids=(1, 2, 3), settle_s=0.1, grid_hz=10_000.0,
                     temperature_c=25.0):
    """simulate_raw_run as it was before issue 16 (the whole 10 kHz grid at once), kept as the
    oracle the streamed run must equal bit for bit."""
    scale = np.asarray(scale, dtype=float).reshape(3)
    bias = np.asarray(bias, dtype=float).reshape(3)
    axes = np.asarray(axes, dtype=float).reshape(3, 3)
    total = TWO_PI * protocol.turns
    t_turn = profile_duration(total, protocol.speed, accel)
    segs: list[Segment] = []
    starts = []
    t = 0.0
    idx = 0
    for s, motor in enumerate(motor_ids):
        for d in (1, -1):
            segs.append(Segment(idx, "rest", None, 0, 0.0, t, t + protocol.rest_s))
            t += protocol.rest_s
            idx += 1
            segs.append(Segment(idx, "rotate", motor, d, protocol.speed, t,
                                t + t_turn + settle_s))
            starts.append((s, d, t))
            t += t_turn + settle_s
            idx += 1
    segs.append(Segment(idx, "rest", None, 0, 0.0, t, t + protocol.rest_s))
    t_total = t + protocol.rest_s

    g = np.arange(0.0, t_total + 1.0 / grid_hz, 1.0 / grid_hz)
    rate = np.zeros((3, g.size))
    for s, d, t0 in starts:
        p = _speed_profile(g - t0, total, protocol.speed, accel)
        f_rev = protocol.speed / TWO_PI
        freqs = [f_rev, 2 * f_rev, 3 * f_rev, rng.uniform(3.0, 6.0)]
        amp = protocol.ripple * np.sqrt(2.0 / len(freqs))
        rip = sum(amp * np.sin(TWO_PI * f * (g - t0) + rng.uniform(0, TWO_PI))
                  for f in freqs)
        rate[s] += d * p * (1.0 + rip)
    # Exact integral of the piecewise-linear rate on the grid.
    angle = np.concatenate(
        [np.zeros((3, 1)), np.cumsum((rate[:, 1:] + rate[:, :-1]) / 2 / grid_hz, axis=1)], axis=1
    )

    # Gyro: true sampling instants of a chip whose clock runs (1 + err) fast.
    period = 1.0 / (protocol.odr_hz * (1.0 + imu_clock_error))
    imu_t = np.arange(0.0, t_total, period) + rng.uniform(0, period)
    imu_t = imu_t[imu_t <= g[-1]]
    w_true = np.stack([np.interp(imu_t, g, rate[s]) for s in range(3)], axis=1)  # shaft rates
    g_sensor = w_true @ axes  # Σ_s ω_s u_s, sensor frame
    m = g_sensor / scale - bias + rng.standard_normal(g_sensor.shape) * noise_std
    # Encoder: every servo read together at enc_rate_hz (a sync read), jittered timestamps.
    te = np.arange(0.0, t_total, 1.0 / enc_rate_hz)
    q = TWO_PI / encoder_ticks
    enc_t, enc_m, enc_a = [], [], []
    stamp = np.sort(te + rng.normal(0.0, enc_jitter_s, te.size)) if enc_jitter_s else te
    for s, motor in enumerate(motor_ids):
        th = np.interp(te, g, angle[s])
        enc_t.append(stamp)
        enc_m.append(np.full(te.size, motor))
        enc_a.append(np.round(th / q) * q)
    order = np.argsort(np.concatenate(enc_t), kind="stable")
    if imu_jitter_s:
        lim = period / 3
        imu_t = imu_t + np.clip(rng.normal(0.0, imu_jitter_s, imu_t.size), -lim, lim)
    return RawRunTuple(
        imu_t=imu_t,
        imu_rate=m,
        imu_temp=np.full(imu_t.size, float(temperature_c)),
        enc_t=np.concatenate(enc_t)[order],
        enc_motor=np.concatenate(enc_m)[order],
        enc_angle=np.concatenate(enc_a)[order],
        segments=tuple(segs),
        scale=scale,
        bias=bias,
        axes=axes,
        motor_ids=tuple(motor_ids),
        grid_t=g,
        grid_rate=rate,
        grid_angle=angle,
    )


@pytest.mark.parametrize("opts", [
    {},
    {"imu_clock_error": 0.002, "enc_rate_hz": 200.0, "enc_jitter_s": 0.001},
    {"imu_jitter_s": 0.0004, "enc_jitter_s": 0.004, "enc_rate_hz": 333.0},
])
@pytest.mark.parametrize("chunk", [997, 1 << 16])
def test_stream_equals_the_whole_run(opts, chunk):
    rng = np.random.default_rng(5)
    k, b = draw_sensors(rng, 1)
    axes = draw_mount_axes(rng, 1)[0]
    proto = SimProtocol(speed=3.0, turns=1, odr_hz=190.0, rest_s=0.5)
    state = rng.bit_generator.state
    whole = whole_run_oracle(rng, k[0], b[0], axes, proto, 0.03, **opts)
    after = rng.bit_generator.state
    rng.bit_generator.state = state
    stream = stream_raw_run(rng, k[0], b[0], axes, proto, 0.03, grid_chunk=chunk, **opts)
    assert rng.bit_generator.state == after
    imu = list(stream.imu_chunks())
    if chunk < 1000:
        assert len(imu) > 20
    t, rate, temp = (np.concatenate(x) for x in zip(*imu, strict=True))
    assert stream.n_imu == whole.imu_t.size
    np.testing.assert_array_equal(t, whole.imu_t)
    np.testing.assert_array_equal(rate, whole.imu_rate)
    np.testing.assert_array_equal(temp, whole.imu_temp)
    et, em, ea = (np.concatenate(x) for x in zip(*stream.encoder_chunks(), strict=True))
    np.testing.assert_array_equal(et, whole.enc_t)
    np.testing.assert_array_equal(em, whole.enc_motor)
    np.testing.assert_array_equal(ea, whole.enc_angle)
    assert stream.segments == whole.segments


def test_simulate_recording_writes_the_files_the_whole_run_gives(tmp_path):
    """The command streams; its CSV files are byte for byte those of the whole-array run
    written at once (what simulate-recording wrote before issue 16)."""
    from gyrocal.kit.cli import main
    from gyrocal.kit.recording import RecordingWriter

    assert main(["simulate-recording", str(tmp_path / "new"), "--seed", "4", "--turns", "1",
                 "--odr", "500"]) == 0
    rng = np.random.default_rng(4)
    k, b = draw_sensors(rng, 1)
    axes = draw_mount_axes(rng, 1)[0]
    proto = SimProtocol(speed=3.0, turns=1, odr_hz=500.0, rest_s=1.0)
    run = whole_run_oracle(rng, k[0], b[0], axes, proto, 0.035, imu_clock_error=0.002,
                           enc_rate_hz=200.0, enc_jitter_s=0.001)
    with RecordingWriter(tmp_path / "old", sensor={}, gimbal={}, protocol={}) as w:
        w.append_imu(run.imu_t, run.imu_rate, run.imu_temp)
        w.append_encoder(run.enc_t, run.enc_motor, run.enc_angle)
        for seg in run.segments:
            w.append_segment(seg)
    for name in ("imu.csv", "encoder.csv", "segments.csv"):
        assert (tmp_path / "new" / name).read_bytes() == (tmp_path / "old" / name).read_bytes()


def test_simulate_raw_run_gathers_the_stream_with_its_grid():
    rng = np.random.default_rng(9)
    proto = SimProtocol(speed=4.0, turns=1, odr_hz=100.0, rest_s=0.3)
    state = rng.bit_generator.state
    run = simulate_raw_run(rng, np.ones(3), np.zeros(3), np.eye(3), proto, 0.01,
                           enc_jitter_s=0.002)
    rng.bit_generator.state = state
    ref = whole_run_oracle(rng, np.ones(3), np.zeros(3), np.eye(3), proto, 0.01,
                           enc_jitter_s=0.002)
    for name in ("imu_t", "imu_rate", "enc_t", "enc_angle", "grid_t", "grid_rate",
                 "grid_angle"):
        np.testing.assert_array_equal(getattr(run, name), getattr(ref, name), err_msg=name)
