"""An independent Recording v1 generator, written from the contract in DESIGN.md alone.

It shares no code with gyrocal (no RecordingWriter, no simulator): plain numpy and text files.
Each servo turns a whole number of revolutions one way and back on a trapezoidal speed profile,
with rests between; the gyro reads ``m = K⁻¹ g − b`` (the paper's model g = K (m + b) solved for
m) plus white noise; the encoders read the true angle quantised to 4096 ticks per turn.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

TICK = 2 * np.pi / 4096


def _profile(t, speed, turns, accel):
    """Angle and rate of a trapezoidal move of ``turns`` revolutions starting at t = 0."""
    total = 2 * np.pi * turns
    ramp = speed / accel
    cruise = (total - speed * ramp) / speed
    end = 2 * ramp + cruise
    tc = np.clip(t, 0, end)
    a1 = 0.5 * accel * np.minimum(tc, ramp) ** 2
    a2 = speed * np.clip(tc - ramp, 0, cruise)
    td = np.clip(tc - ramp - cruise, 0, ramp)
    a3 = speed * td - 0.5 * accel * td ** 2
    rate = np.where(tc < ramp, accel * tc,
                    np.where(tc < ramp + cruise, speed, speed - accel * td))
    rate = np.where((t < 0) | (t > end), 0.0, rate)
    return a1 + a2 + a3, rate, end


def write_recording(path, *, scale=(1.01, 0.99, 1.02), bias=(0.01, -0.02, 0.005), odr=200.0,
                    speed=np.pi, turns=2, accel=10.0, rest=1.0, noise=0.005, seed=0,
                    gyro_unit=1.0, angle_unit=1.0, thermal=None):
    """Write a Recording v1 directory; ``gyro_unit``/``angle_unit`` scale the written gyro
    readings / encoder angles (180/π writes °/s / degrees: the unit mistakes).

    ``thermal`` (optional) makes the sensor temperature-dependent: a dict with ``die`` (die
    temperature in °C as a function of time, vectorised), ``t0`` (the recording's start on that
    time axis), ``bias_coeffs`` (3 × (p+1): per axis, ascending powers of T − 25 °C; they
    replace ``bias``) and ``scale_coeff`` (3: relative scale change per °C). The temp column
    then carries the die temperature."""
    rng = np.random.default_rng(seed)
    path = Path(path)
    path.mkdir(parents=True)
    k, b = np.asarray(scale), np.asarray(bias)
    steps, t = [], 0.0
    for motor in (1, 2, 3):
        for d in (-1, 1):
            steps.append(("rest", None, 0, t, t + rest))
            t += rest
            _, _, dur = _profile(np.zeros(1), speed, turns, accel)
            steps.append(("rotate", motor, d, t, t + dur))
            t += dur
    steps.append(("rest", None, 0, t, t + rest))
    t_end = t + rest
    ts = np.arange(0, t_end, 1 / odr)
    true = np.zeros((ts.size, 3))
    angles = np.zeros((ts.size, 3))
    for kind, motor, d, t0, _ in steps:
        if kind == "rotate":
            ang, rate, _ = _profile(ts - t0, speed, turns, accel)
            ang = np.where(ts >= t0, ang, 0.0)
            true[:, motor - 1] += d * rate
            angles[:, motor - 1] += d * ang
    temp = np.full(ts.size, 25.0)
    if thermal is not None:
        temp = np.asarray(thermal["die"](thermal["t0"] + ts), dtype=float)
        d = (temp - 25.0)[:, None]
        c = np.asarray(thermal["bias_coeffs"], dtype=float)
        b = sum(c[:, i] * d**i for i in range(c.shape[1]))
        k = k * (1.0 + np.asarray(thermal["scale_coeff"], dtype=float) * d)
    m = true / k - b + noise * rng.standard_normal(true.shape)
    with open(path / "imu.csv", "w") as f:
        f.write("t,gx,gy,gz,temp\n")
        for ti, row, tc in zip(ts, m * gyro_unit, temp, strict=True):
            f.write(f"{ti:.6f},{row[0]:.7g},{row[1]:.7g},{row[2]:.7g},{tc:.4f}\n")
    with open(path / "encoder.csv", "w") as f:
        f.write("t,motor,angle\n")
        q = np.round(angles / TICK) * TICK * angle_unit
        for i in range(0, ts.size, 2):
            for j in range(3):
                f.write(f"{ts[i]:.6f},{j + 1},{q[i, j]:.9g}\n")
    with open(path / "segments.csv", "w") as f:
        f.write("index,kind,motor,direction,speed,t_start,t_end\n")
        for i, (kind, motor, d, t0, t1) in enumerate(steps):
            sp = speed if kind == "rotate" else 0.0
            f.write(f"{i},{kind},{'' if motor is None else motor},{d},{sp},{t0:.6f},{t1:.6f}\n")
    manifest = {"format": "gyrocal-recording", "version": 1, "created": "2026-01-01T00:00:00Z",
                "sensor": {"model": "mpu9250", "odr_hz": odr, "full_scale_dps": 500,
                           "sensitivity_rad_s_per_lsb": np.radians(500) / 32768},
                "gimbal": {"motors": [{"id": i, "model": "XM430-W350", "axis": a}
                                      for i, a in ((1, "x"), (2, "y"), (3, "z"))]},
                "protocol": {"name": "contract"}, "complete": True}
    (path / "manifest.json").write_text(json.dumps(manifest), encoding="utf-8")
    return path
