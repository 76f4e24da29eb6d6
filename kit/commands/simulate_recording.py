"""``gyrocal simulate-recording OUT``: write a synthetic Recording v1 with its truth."""

from __future__ import annotations

import argparse

from gyrocal.kit import argtypes

HELP = "write a synthetic recording (with its true parameters) for testing"
DESCRIPTION = (
    "Simulate a calibration run at sample level — a sensor with scale, bias and a misaligned "
    "mount drawn from the paper's normal conditions, servo turns with acceleration ramps and "
    "speed ripple, a quantised and jittered encoder — and write it as a Recording v1 directory "
    "whose manifest holds the truth. This is the numerical simulator (gyrocal.calib.simulate), "
    "not the "
    "emulated jig."
)


def _positive(kind: type) -> object:
    def parse(text: str) -> object:
        try:
            v = kind(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
        if not v > 0:
            raise argparse.ArgumentTypeError(f"must be positive, got {text}")
        return v

    return parse


def add_arguments(p: argparse.ArgumentParser) -> None:
    """Register the arguments."""
    p.add_argument("out", help="the recording directory to create")
    p.add_argument("--seed", type=argtypes.seed, default=0, help="random seed (default 0)")
    p.add_argument("--speed", type=_positive(float), default=3.0, help="rad/s (default 3.0)")
    p.add_argument("--turns", type=_positive(int), default=3,
                   help="whole revolutions per direction (default 3)")
    p.add_argument("--rest", type=_positive(float), default=1.0, help="rest per turn, s")
    p.add_argument("--odr", type=_positive(float), default=200.0, help="gyro rate, Hz")
    p.add_argument("--noise", type=_positive(float), default=0.035,
                   help="gyro white noise per sample, rad/s (default 0.035)")
    p.add_argument("--force", action="store_true", help="replace files in OUT")


def run(args: argparse.Namespace) -> int:
    """Run the command."""
    import numpy as np

    from gyrocal.calib.simulate import (
        SimProtocol,
        draw_mount_axes,
        draw_sensors,
        stream_raw_run,
    )
    from gyrocal.kit.recording import RecordingWriter

    rng = np.random.default_rng(args.seed)
    k, b = draw_sensors(rng, 1)
    axes = draw_mount_axes(rng, 1)[0]
    proto = SimProtocol(speed=args.speed, turns=args.turns, odr_hz=args.odr, rest_s=args.rest)
    runsim = stream_raw_run(rng, k[0], b[0], axes, proto, args.noise,
                              imu_clock_error=0.002, enc_rate_hz=200.0, enc_jitter_s=0.001)
    sensor = {"model": "simulated", "odr_hz": args.odr, "full_scale_dps": None,
              "sensitivity_rad_s_per_lsb": None}
    gimbal = {"motors": [{"id": m, "model": "simulated", "axis": ax}
                         for m, ax in zip(runsim.motor_ids, "xyz", strict=True)]}
    protocol = {"name": "simulated", "speed": args.speed, "turns": args.turns,
                "rest_s": args.rest, "seed": args.seed, "noise_std": args.noise}
    truth = {"scale": k[0].tolist(), "bias": b[0].tolist(),
             "axes": {str(m): u.tolist() for m, u in zip(runsim.motor_ids, axes, strict=True)}}
    with RecordingWriter(args.out, sensor=sensor, gimbal=gimbal, protocol=protocol,
                         truth=truth, force=args.force) as w:
        for chunk in runsim.imu_chunks():  # written as generated: bounded memory
            w.append_imu(*chunk)
        for chunk in runsim.encoder_chunks():
            w.append_encoder(*chunk)
        for seg in runsim.segments:
            w.append_segment(seg)
        w.finish()
    print(f"wrote {args.out}: {runsim.n_imu} gyro samples, {len(runsim.segments)} segments")
    return 0
