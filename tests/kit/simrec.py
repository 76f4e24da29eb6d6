"""Write a simulated session (gyrocal.calib.noise_sim) as a Recording v1, with encoders and
segments."""

from __future__ import annotations

import numpy as np

from gyrocal.calib.segments import Segment
from gyrocal.kit.recording import RecordingWriter

TICK = 2 * np.pi / 4096


def write_session(path, s, *, encoder_every=4, temperature=True):
    """``s`` a SimSession; the encoder of each servo is the integral of its reference rate,
    sampled every ``encoder_every`` gyro samples and quantised to 4096 ticks per turn."""
    dt = 1.0 / s.odr_hz
    sensor = {"model": "simulated", "odr_hz": s.odr_hz, "full_scale_dps": 500,
              "sensitivity_rad_s_per_lsb": 0.0002664624812}
    gimbal = {"motors": [{"id": m, "model": "XM430-W350", "axis": "xyz"[m - 1]} for m in (1, 2, 3)]}
    truth = {"scale": s.scale.tolist(), "bias": s.true_bias[0].tolist()}
    with RecordingWriter(path, sensor=sensor, gimbal=gimbal, protocol={"name": "sim"},
                         truth=truth) as w:
        w.append_imu(s.t, s.rate, s.temperature_c if temperature else None)
        idx = np.arange(0, s.n, encoder_every)
        angles = []
        for m in (1, 2, 3):
            w_m = np.where(s.reference_motor == m, np.nan_to_num(s.reference_rate), 0.0)
            # angle at the end of each sample's interval: cumulative sum of rate * dt, and the
            # encoder reads it at the sample's centre (half a sample less)
            angle = np.cumsum(w_m) * dt - 0.5 * w_m * dt
            angles.append(np.round(angle[idx] / TICK) * TICK)
        # one sync read of the three servos per encoder time, in time order
        t_rows = np.repeat(s.t[idx], 3)
        m_rows = np.tile([1, 2, 3], idx.size)
        a_rows = np.column_stack(angles).reshape(-1)
        w.append_encoder(t_rows, m_rows, a_rows)
        # segments from the runs of the turning motor
        motor = s.reference_motor
        edges = np.flatnonzero(np.diff(motor) != 0) + 1
        starts = np.concatenate([[0], edges])
        ends = np.concatenate([edges, [s.n]])
        for i, (a, b) in enumerate(zip(starts, ends, strict=True)):
            t0, t1 = s.t[a], s.t[b - 1]
            if motor[a] == 0:
                w.append_segment(Segment(i, "rest", None, 0, 0.0, t0, t1))
            else:
                mean = float(np.mean(s.reference_rate[a:b]))
                w.append_segment(Segment(i, "rotate", int(motor[a]), 1 if mean > 0 else -1,
                                         abs(mean), t0, t1))
        w.finish()
    return path
