"""stream_raw_run (bounded memory, issue 16) gives simulate_raw_run's values bit for bit, for the
same generator state, and leaves the generator where simulate_raw_run does."""

import numpy as np
import pytest

from gyrocal.calib.simulate import (
    SimProtocol,
    draw_mount_axes,
    draw_sensors,
    simulate_raw_run,
    stream_raw_run,
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
    whole = simulate_raw_run(rng, k[0], b[0], axes, proto, 0.03, **opts)
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
    run = simulate_raw_run(rng, k[0], b[0], axes, proto, 0.035, imu_clock_error=0.002,
                           enc_rate_hz=200.0, enc_jitter_s=0.001)
    with RecordingWriter(tmp_path / "old", sensor={}, gimbal={}, protocol={}) as w:
        w.append_imu(run.imu_t, run.imu_rate, run.imu_temp)
        w.append_encoder(run.enc_t, run.enc_motor, run.enc_angle)
        for seg in run.segments:
            w.append_segment(seg)
    for name in ("imu.csv", "encoder.csv", "segments.csv"):
        assert (tmp_path / "new" / name).read_bytes() == (tmp_path / "old" / name).read_bytes()
