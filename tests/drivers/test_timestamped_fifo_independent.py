"""The ICM-42688-P reader's sample numbering on FIFO data from an independent generator.

:class:`PacketChip` shares no code with gyrocal's emulator: it is the host's view of an
ICM-42688-P reduced to the datasheet's contract (DS-000347: WHO_AM_I 0x47 at 0x75, FIFO_COUNT
big-endian in bytes at 0x2E, FIFO_DATA at 0x30, INT_STATUS bit 1 FIFO_FULL cleared when read,
SIGNAL_PATH_RESET bit 1 flushes, FIFO_CONFIG bits 7:6 start and stop collection, and 16-byte
packets ``header 0x68, accel XYZ, gyro XYZ (int16 big-endian), temperature int8, timestamp
uint16 big-endian`` in 16 µs units) packed here with :mod:`struct`. Each packet's gyro X/Y
counts encode its sample number, so the test knows exactly which samples arrived.
"""

import math
import struct

import numpy as np

from gyrocal.drivers.clock import VirtualClock
from gyrocal.drivers.imu import open_imu

FIFO_BYTES = 2048


class PacketChip:
    """A bus with one ICM-42688-P at 0x68 sampling at ``odr_hz`` from host time 0."""

    def __init__(self, clock, odr_hz=1000.0, drop=(), start_us=40_000.0):
        self.clock, self.period = clock, 1.0 / odr_hz
        self.regs = {0x75: 0x47}
        self.drop = set(drop)
        self.start_us = start_us  # the chip's timestamp counter at sample 0
        self.next_k = 1
        self.fifo = bytearray()
        self.full = False
        self.enabled_at = None  # host time FIFO collection started
        self.first_k = None  # sample number of the first packet collected

    def _generate(self):
        now = self.clock.monotonic()
        while self.next_k * self.period <= now:
            k = self.next_k
            self.next_k += 1
            if self.enabled_at is None or k * self.period <= self.enabled_at or k in self.drop:
                continue
            if len(self.fifo) + 16 > FIFO_BYTES:
                self.full = True
                continue
            if self.first_k is None:
                self.first_k = k
            stamp = math.floor((self.start_us + k * self.period * 1e6) / 16) & 0xFFFF
            self.fifo += struct.pack(">B3h3hbH", 0x68, 0, 0, 2048, k & 0x3FFF, k >> 14, 0, 0,
                                     stamp)

    def write_byte_data(self, addr, reg, value):
        self._generate()
        self.regs[reg] = value
        if reg == 0x4B and value & 0x02:  # FIFO_FLUSH
            self.fifo.clear()
        if reg == 0x16:  # FIFO_CONFIG: collection on unless bypass
            on = bool(value >> 6)
            if on and self.enabled_at is None:
                self.enabled_at = self.clock.monotonic()
            elif not on:
                self.enabled_at = None

    def read_byte_data(self, addr, reg):
        self._generate()
        if reg == 0x2D:  # INT_STATUS, cleared when read
            value, self.full = (0x02 if self.full else 0), False
            return value
        return self.regs.get(reg, 0)

    def read_i2c_block_data(self, addr, reg, length):
        self._generate()
        if reg == 0x2E:
            return list(struct.pack(">H", len(self.fifo)))[:length]
        if reg == 0x30:
            out = bytes(self.fifo[:length])
            del self.fifo[:length]
            return list(out)
        return [self.regs.get(reg + i, 0) for i in range(length)]


def stream(chip, clock, seconds, pause_at=None, pause_s=0.0, seed=3):
    reader = open_imu("icm42688p", chip, 0x68, clock=clock, range_dps=2000, odr_hz=1000,
                      stuck_after_s=None)  # gyro Y and Z hold still by design
    reader.start()
    rng = np.random.default_rng(seed)
    batches = []
    while clock.monotonic() < seconds:
        clock.sleep(rng.uniform(0.002, 0.02))
        if pause_at is not None and clock.monotonic() >= pause_at:
            clock.sleep(pause_s)
            pause_at = None
        batches.append(reader.read())
    return reader, batches


def sample_numbers(batches):
    raw = np.concatenate([b.raw_counts for b in batches]).astype(np.int64)
    return (raw[:, 0] & 0x3FFF) | (raw[:, 1] << 14)


def test_samples_lost_inside_the_chip_are_gaps_of_their_exact_size():
    clock = VirtualClock()
    drop = {500, 501, 502, 1700, 2999}
    chip = PacketChip(clock, drop=drop)
    _, batches = stream(chip, clock, 4.0)
    ks = sample_numbers(batches)
    index = np.concatenate([b.index for b in batches])
    np.testing.assert_array_equal(index, ks - chip.first_k)  # every sample on its own number
    gaps = [(g.first_index + chip.first_k, g.samples) for b in batches for g in b.gaps]
    assert gaps == [(500, 3), (1700, 1), (2999, 1)]
    t = np.concatenate([b.t for b in batches])
    assert np.max(np.abs(t - ks * chip.period)) < 0.5e-3


def test_a_stall_longer_than_the_timestamp_wrap_is_counted_exactly():
    # 1.5 s without a drain: the 128-packet FIFO fills and stops, the reader restarts it, and
    # the first sample after the restart is more than one 16-bit wrap (1.05 s) of timestamps
    # after the last one delivered
    clock = VirtualClock()
    chip = PacketChip(clock)
    reader, batches = stream(chip, clock, 4.0, pause_at=1.0, pause_s=1.5)
    ks = sample_numbers(batches)
    index = np.concatenate([b.index for b in batches])
    np.testing.assert_array_equal(index, ks - chip.first_k)
    missing = set(range(int(ks[0]), int(ks[-1]) + 1)) - set(ks.tolist())
    assert len(missing) > 1100
    reported = sum(g.samples for b in batches for g in b.gaps)
    assert reported == len(missing) == reader.samples_lost
    t = np.concatenate([b.t for b in batches])
    assert np.max(np.abs(t - ks * chip.period)) < 1e-3
