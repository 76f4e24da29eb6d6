"""IMU readers on the emulated bus: sustained streaming and the host cost of decoding.

``python -m bench imu`` prints two tables:

1. Sustained streaming: an MPU-9250 at 1 kHz and an LSM9DS1 at 952 Hz stream for five simulated
   minutes through the real readers and the register-level emulated chips on a 400 kHz emulated
   bus, drained at irregular intervals, at most 20 ms apart (with a burst's own bus time, the
   LSM9DS1's 32 slots, 33.6 ms, are then never full at a drain; a full one is dropped as if it
   had overrun). Every sample the chip put into its FIFO is accounted for: delivered, reported
   lost in a gap, or still in the FIFO at the end. Timestamps are compared with the instants
   the chip really sampled.
2. Decode cost: host CPU time per sample of ``reader.read()`` (latch the FIFO level, build the
   burst, unpack, scale to rad/s, temperature, saturation and stuck-axis checks, timestamps)
   with the bus replaced by a replay of FIFO bytes, so only the reader's own work is timed.

Options: ``--quick`` runs 30 simulated seconds instead of 300.
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np

from bench.table import print_table
from gyrocal.drivers.clock import VirtualClock
from gyrocal.drivers.emulated.imu_chips import SensorTruth, make_emulated_imu
from gyrocal.drivers.emulated.motion import FunctionMotion
from gyrocal.drivers.imu import open_imu

DEG = np.pi / 180
PI4_SLOWDOWN = (3.0, 5.0)  # a Raspberry Pi 4 core against this machine's, roughly


def _motion(range_dps: float) -> FunctionMotion:
    a = 0.5 * range_dps * DEG
    return FunctionMotion(lambda t: a * np.column_stack(
        [np.sin(2 * np.pi * 0.7 * t), np.cos(2 * np.pi * 1.3 * t), np.sin(2 * np.pi * 0.3 * t)]
    ))


def sustained(model: str, odr: float, seconds: float, *, ppm: float = 0.0,
              step: tuple[float, float] = (0.005, 0.02), **reader_kw: Any) -> list[object]:
    """Stream ``seconds`` of simulated time; return one table row."""
    clock = VirtualClock()
    truth = SensorTruth(clock_ppm=ppm)
    bus, addr = make_emulated_imu(model, clock, _motion(500), truth, seed=1)
    bus.log = type(bus.log)(maxlen=0)  # the log is not needed; keep memory flat
    chip = bus.device(addr)
    reader = open_imu(model, bus, addr, clock=clock, range_dps=500, odr_hz=odr, **reader_kw)
    rng = np.random.default_rng(2)
    reader.start()
    t_start = clock.monotonic()
    bus_time = 0.0
    delivered, lost, gaps, worst_err = 0, 0, 0, 0.0
    last_index = -1
    wall0, cpu0 = time.perf_counter(), time.process_time()
    end = t_start + seconds
    while clock.monotonic() < end:
        clock.sleep(rng.uniform(*step))
        before = clock.monotonic()
        n_tx = bus.transactions
        batch = reader.read()
        bus_time += clock.monotonic() - before if bus.transactions > n_tx else 0.0
        delivered += len(batch)
        gaps += len(batch.gaps)
        lost += sum(g.samples for g in batch.gaps)
        if len(batch):
            if batch.index[0] <= last_index or np.any(np.diff(batch.index) <= 0):
                raise AssertionError("a sample index repeated or went backwards")
            last_index = int(batch.index[-1])
            true_t = chip.sample_time(chip.fifo_enables[0] + 1 + batch.index)
            if not gaps:
                worst_err = max(worst_err, float(np.max(np.abs(batch.t - true_t))))
    wall, cpu = time.perf_counter() - wall0, time.process_time() - cpu0
    elapsed = clock.monotonic() - t_start
    frame = reader.frame_bytes if model.startswith("mpu") else 1
    in_fifo = chip.fifo_level // frame
    entered = chip.samples_taken - chip.fifo_enables[0]  # samples the chip took since start
    unaccounted = entered - 1 - delivered - lost - in_fifo  # 1: the first, dropped by design
    how = "i2c_rdwr" if reader.uses_i2c_rdwr else "32-byte blocks"
    if model == "lsm9ds1" and not reader_kw.get("burst_wrap", True):
        how = "2 × 6 bytes/slot"
    return [
        model, f"{odr:g}", f"{ppm:+g}", how, f"{elapsed:.0f}", entered, delivered, lost,
        unaccounted, f"{worst_err * 1e3:.3f}", f"{100 * bus_time / elapsed:.0f}",
        f"{wall:.1f}", f"{cpu / elapsed * 1e3:.1f}",
    ]


class _ReplayBus:
    """Delegates bring-up to an emulated bus, then serves one fixed FIFO content forever."""

    def __init__(self, bus: Any, level_register: int, level: list[int], fifo_register: int,
                 data: bytes) -> None:
        self._bus = bus
        self.replay = False
        self._level = (level_register, level)
        self._fifo = (fifo_register, data)
        self._pointer = 0

    def read_byte_data(self, addr: int, reg: int, force: Any = None) -> int:
        if self.replay:
            return self._level[1][0] if reg == self._level[0] else 0
        return self._bus.read_byte_data(addr, reg)

    def write_byte_data(self, addr: int, reg: int, value: int, force: Any = None) -> None:
        if not self.replay:
            self._bus.write_byte_data(addr, reg, value)

    def read_i2c_block_data(self, addr: int, reg: int, length: int, force: Any = None) -> list:
        if self.replay:
            if reg == self._level[0]:
                return self._level[1][:length]
            return list(self._fifo[1][:length])
        return self._bus.read_i2c_block_data(addr, reg, length)

    def i2c_rdwr(self, *msgs: Any) -> None:
        import ctypes

        data = self._fifo[1]
        ctypes.memmove(msgs[1].buf, data, msgs[1].len)


def decode_cost(model: str, samples_per_read: int, reads: int = 3000) -> list[object]:
    """Host CPU µs per sample of ``reader.read()`` with the bus replaced by a FIFO replay."""
    clock = VirtualClock()
    bus, addr = make_emulated_imu(model, clock, _motion(500), SensorTruth(), seed=3)
    rng = np.random.default_rng(4)
    counts = rng.integers(-3000, 3000, size=(samples_per_read, 6)).astype(np.int16)
    if model.startswith("mpu"):
        counts[:, 0] = 1500  # TEMP_OUT
        data = counts[:, :4].astype(">i2").tobytes()
        count = len(data)
        replay = _ReplayBus(bus, 0x72, [count >> 8, count & 0xFF], 0x74, data)
    else:
        data = counts.astype("<i2").tobytes()
        replay = _ReplayBus(bus, 0x2F, [samples_per_read], 0x18, data)
    reader = open_imu(model, replay, addr, clock=clock, range_dps=500,
                      odr_hz=1000 if model.startswith("mpu") else 952)
    reader.start()
    replay.replay = True
    period = 1.0 / reader.odr_hz
    for _ in range(50):  # warm up
        clock.sleep(samples_per_read * period)
        reader.read()
    cpu0 = time.process_time_ns()
    for _ in range(reads):
        clock.sleep(samples_per_read * period)
        reader.read()
    per_sample_us = (time.process_time_ns() - cpu0) / 1e3 / (reads * samples_per_read)
    lo, hi = (per_sample_us * f for f in PI4_SLOWDOWN)
    core = [100 * v * reader.odr_hz * 1e-6 for v in (lo, hi)]  # % of one core at the ODR
    return [
        model, samples_per_read, f"{per_sample_us * samples_per_read:.0f}",
        f"{per_sample_us:.2f}", f"{lo:.1f}–{hi:.1f}", f"{core[0]:.1f}–{core[1]:.1f}",
    ]


def main(argv: list[str]) -> None:
    """Print the streaming and decode-cost tables."""
    seconds = 30.0 if "--quick" in argv else 300.0
    rows = [
        sustained("mpu9250", 1000, seconds),
        sustained("lsm9ds1", 952, seconds),
        sustained("mpu9250", 1000, seconds, ppm=10_000),
        sustained("lsm9ds1", 952, seconds, ppm=-10_000),
        sustained("lsm9ds1", 952, seconds, burst_wrap=False, step=(0.005, 0.015)),
    ]
    print_table(
        ["model", "ODR Hz", "clock ppm", "FIFO burst", "sim s", "chip samples", "delivered",
         "lost (gaps)", "unaccounted", "max |t err| ms", "bus busy %", "wall s",
         "CPU ms per sim s"],
        rows,
        title=f"Sustained streaming on the emulated 400 kHz bus, drains every 5-20 ms "
        f"({seconds:g} simulated s). chip samples = samples the chip took since start; one is "
        "dropped by design after the start; the rest are delivered, reported lost, or still "
        "in the FIFO; unaccounted must be 0.",
    )
    sizes = {"mpu9250": (8, 32, 64), "lsm9ds1": (8, 32)}  # up to a full FIFO
    rows = [decode_cost(m, n) for m, ns in sizes.items() for n in ns]
    print_table(
        ["model", "samples/read", "µs per read", "µs per sample", "Pi 4 µs/sample (est.)",
         "Pi 4 core % at the ODR (est.)"],
        rows,
        title="Host CPU time of reader.read() per sample, bus replaced by a FIFO replay "
        "(includes building the smbus2 messages, numpy decoding, temperature, saturation, "
        "timestamps). Pi 4 column: this machine's figure × 3–5, a rough per-core ratio, not a "
        "measurement.",
    )
