"""Every supported chip's reader under FIFO stress on the emulated bus (issue 15).

For each chip, a smooth motion is streamed for a simulated time with a FIFO of a few tens of
milliseconds (the ``fifo_capacity`` fault knob), so that it overflows at most drains and the
reader restarts it hundreds of times. The table gives, per chip and seed: the gaps reported,
lost samples reported minus those really missing (0 is exact), and the error of the delivered
samples' times against the emulator's true sample instants (median, 99th percentile, max).
The chips whose FIFO packets carry timestamps (ICM-42688-P, LSM6DSOX) number their samples from
them; the others estimate the loss of each restart from the host clock.

Data: gyrocal's own emulator only (register-level chips of ``drivers/emulated``); the exact
numbering is also checked on an independent packet generator in
``tests/drivers/test_timestamped_fifo_independent.py``.

Usage: ``python -m bench chips [--quick]`` (``--quick``: one seed, 5 s instead of three, 10 s).
"""

from __future__ import annotations

import math
import warnings

import numpy as np

from bench.table import print_table
from gyrocal.drivers.clock import VirtualClock
from gyrocal.drivers.emulated.imu_chips import ChipFaults, SensorTruth, make_emulated_imu
from gyrocal.drivers.emulated.motion import FunctionMotion
from gyrocal.drivers.imu import open_imu

# model -> (address, odr_hz, FIFO knob in the chip's unit: about 16 samples)
CHIPS = {  # FIFO capacities in samples: 16, 12, 18, 16, 12 (14-byte frames, 3 words a sample)
    "mpu9250": (0x68, 1000.0, 16 * 14),
    "lsm9ds1": (0x6B, 952.0, 12),
    "icm20948": (0x68, 1125.0, 18 * 14),
    "icm42688p": (0x68, 1000.0, 256),
    "lsm6dsox": (0x6A, 1 / (48 * 25e-6), 12 * 3),
}


def _motion() -> FunctionMotion:
    a = 250 * math.pi / 180
    return FunctionMotion(lambda t: a * np.column_stack(
        [np.sin(2 * np.pi * 0.7 * t), np.cos(2 * np.pi * 1.3 * t), np.sin(2 * np.pi * 0.3 * t)]))


def _run(model: str, seed: int, seconds: float) -> list[object]:
    address, odr, cap = CHIPS[model]
    clock = VirtualClock()
    truth = SensorTruth(noise_density_rad_s_sqrt_hz=0.0)
    bus, addr = make_emulated_imu(model, clock, _motion(), truth, address=address, seed=seed,
                                  faults=ChipFaults(fifo_capacity=cap), subsamples=1,
                                  output_filter=False)
    chip = bus.device(addr)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        reader = open_imu(model, bus, addr, clock=clock, range_dps=500, odr_hz=odr)
    reader.start()
    rng = np.random.default_rng(seed + 1)
    batches = []
    while clock.monotonic() < seconds:
        clock.sleep(rng.uniform(0.003, 0.02))
        batches.append(reader.read())
    # which chip sample each delivered one is: match by value around the reader's number
    lsb = reader.info.sensitivity_rad_s_per_lsb
    rate = np.concatenate([b.rate for b in batches])
    naive = chip.fifo_enables[0] + 1 + np.concatenate([b.index for b in batches])
    ks = naive.copy()
    for seg in np.split(np.arange(len(ks)), np.flatnonzero(np.diff(naive) != 1) + 1):
        for d in sorted(range(-50, 51), key=abs):
            t = chip.sample_time(naive[seg] + d)
            m = truth.reading(_motion().rate(t), truth.temperature_at(t))
            if np.allclose(rate[seg], np.clip(np.rint(m / lsb), -32768, 32767) * lsb, atol=1e-12):
                ks[seg] += d
                break
    err = np.abs(np.concatenate([b.t for b in batches]) - chip.sample_time(ks))
    last = ks[-1] - chip.fifo_enables[0] - 1
    reported = sum(g.samples for b in batches for g in b.gaps if g.first_index <= last)
    missing = int(last) - len(ks)
    gaps = sum(len(b.gaps) for b in batches)
    return [model, seed, gaps, reported - missing, float(np.median(err) * 1e6),
            float(np.percentile(err, 99) * 1e6), float(err.max() * 1e6)]


def main(argv: list[str]) -> None:
    """Print the table (see the module docstring)."""
    quick = "--quick" in argv
    seeds, seconds = ((0,), 5.0) if quick else ((0, 1, 2), 10.0)
    rows = [_run(model, seed, seconds) for model in CHIPS for seed in seeds]
    print_table(["chip", "seed", "gaps", "lost reported - missing", "median us", "p99 us",
                 "max us"], rows,
                title=f"FIFO stress ({seconds:g} s, ~16-sample FIFO, drains every 3-20 ms), "
                      "emulated bus")
