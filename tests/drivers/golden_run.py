"""A short emulated run, pinned: what the emulated jig records for a seed must not change when
the emulators are made faster.

:func:`record` runs the protocol runner on the ``--sim`` jig (every realism effect on: coloured
noise, the DLPF at the chip's internal rate, g-sensitivity, gravity and lever arm, wobble, chip
clock, encoder latency) for a rest, a move of an inner servo to a pose, and one turn each way of
two servos (about 5 s of jig time), and writes a Recording v1. ``tests/drivers/data/`` keeps the
``imu.csv``, ``encoder.csv`` and ``segments.csv`` the emulators wrote before they were sped up
(gzipped); ``tests/drivers/test_emulated_golden.py`` compares a fresh run with them.

Regenerate (only when the emulation is meant to change, and say why in the commit)::

    python -m tests.drivers.golden_run tests/drivers/data
"""

from __future__ import annotations

import gzip
import sys
from pathlib import Path

#: The pinned runs: name -> extra ``calibrate`` arguments.
RUNS = {
    "mpu9250": ["--imu-address", "0x68"],  # given: the probe of imu.address 0 reads the bus
    "lsm9ds1": ["--imu-model", "lsm9ds1", "--imu-address", "0x6B", "--odr", "238"],
}
#: The gyro filter each run's chip has (the readers' default at the rate: the widest bandwidth
#: not above half of it) and the rate it runs at, Hz: the MPU-9250's 92 Hz DLPF at its internal
#: 1 kHz (register map CONFIG table), the LSM9DS1's 78 Hz LPF2 at 238 Hz (ST Table 47). With
#: the chip-table density it gives the white noise per sample the pinned rests must show.
FILTERS = {"mpu9250": (92.0, 1000.0), "lsm9ds1": (78.0, 238.0)}
#: The files a run pins.
FILES = ("imu.csv", "encoder.csv", "segments.csv")
SEED = 7


def record(out: Path, extra: list[str]) -> Path:
    """Run the short protocol on the emulated jig into the recording directory ``out``."""
    from gyrocal.kit.cli import build_parser
    from gyrocal.kit.jig import Jig, load_cli_config
    from gyrocal.kit.protocol import Runner, Step
    from gyrocal.kit.recording import RecordingWriter

    # the sensor the runs were pinned with: the paper's (the --sim default before issue 31)
    args = build_parser(["calibrate"]).parse_args(
        ["calibrate", "--sim", "--sim-seed", str(SEED), "--sim-sensor", "paper", *extra])
    jig = Jig(load_cli_config(args), args)
    steps = [Step("rest", rest_s=0.6),
             Step("move", motor=2, angle=0.5, speed=3.0),
             Step("rotate", motor=1, direction=1, turns=1, speed=4.0),
             Step("rest", rest_s=0.3),
             Step("rotate", motor=3, direction=-1, turns=1, speed=4.0),
             Step("rest", rest_s=0.3)]
    try:
        with jig.gimbal, RecordingWriter(out, sensor=jig.imu.info.manifest(), gimbal={},
                                         protocol={}) as w:
            Runner(jig.gimbal, jig.imu, w, jig.clock, steps).run()
            w.finish()
    finally:
        jig.close()
    return out


def write_golden(dest: Path, scratch: Path) -> None:
    """Record every run of :data:`RUNS` and store its pinned files, gzipped, in ``dest``."""
    dest.mkdir(parents=True, exist_ok=True)
    for name, extra in RUNS.items():
        rec = record(scratch / name, extra)
        for f in FILES:
            with open(dest / f"golden-{name}-{f}.gz", "wb") as raw, \
                    gzip.GzipFile(fileobj=raw, mode="wb", mtime=0) as dst:
                dst.write((rec / f).read_bytes())


if __name__ == "__main__":
    import tempfile

    with tempfile.TemporaryDirectory() as tmp:
        write_golden(Path(sys.argv[1]), Path(tmp))
