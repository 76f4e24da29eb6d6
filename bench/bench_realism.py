"""How close the emulated hardware is to the chips (issue: emulated hardware third-party clients
cannot tell from the chips).

1. Bus time on the wall clock: an SMBus byte write (29 bit times) on :class:`EmulatedSMBus` with
   the system clock, against the time the bus speed implies (72.5 µs at 400 kHz).
2. The LSM9DS1 gyro bandwidth through the driver: the gain of the emulated chip at each
   cutoff of ST Table 47 (−3 dB = 0.7071 expected), for the LPF2 path the driver selects.
3. Third-party clients run unmodified against the emulators: which pass, which fail and why
   (the test suite's ``tests/drivers/test_third_party_clients.py``, run here with ``-rA``).

Not measured yet: the calibration error each realism effect causes (coloured noise,
g-sensitivity, gravity and lever arm, wobble, chip clock, encoder latency), which needs those
effects in the emulated sensor first.

Usage: ``python -m bench realism [--quick]``.
"""

from __future__ import annotations

import math
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from bench.table import print_table


class _RegisterFile:
    """A minimal register device: a pointer and 256 bytes."""

    def __init__(self) -> None:
        self.regs = bytearray(256)
        self.ptr = 0

    def i2c_ack(self) -> int | None:
        return None

    def i2c_write(self, data: bytes) -> None:
        self.ptr = data[0]
        for b in data[1:]:
            self.regs[self.ptr] = b
            self.ptr = (self.ptr + 1) & 0xFF

    def i2c_read(self, length: int) -> bytes:
        out = bytes(self.regs[(self.ptr + i) & 0xFF] for i in range(length))
        self.ptr = (self.ptr + length) & 0xFF
        return out


def bus_timing(calls: int) -> None:
    from gyrocal.drivers.clock import SystemClock
    from gyrocal.drivers.emulated.smbus import EmulatedSMBus

    rows = []
    for hz in (100_000, 400_000, 1_000_000):
        bus = EmulatedSMBus(SystemClock(), bus_hz=hz)
        bus.attach(0x50, _RegisterFile())
        d = np.empty(calls)
        for i in range(calls):
            t0 = time.perf_counter()
            bus.write_byte_data(0x50, 1, 2)
            d[i] = time.perf_counter() - t0
        d *= 1e6
        rows.append([f"{hz / 1000:g} kHz", 29 / hz * 1e6, float(np.median(d)),
                     float(np.percentile(d, 90)), float(d.mean())])
    print_table(["bus", "nominal µs", "median µs", "p90 µs", "mean µs"], rows,
                title=f"SMBus byte write on the wall clock ({calls} calls each; the mean "
                      "includes the host's scheduling)")


def lsm_bandwidth() -> None:
    from gyrocal.drivers.clock import VirtualClock
    from gyrocal.drivers.emulated.imu_chips import SensorTruth, make_emulated_imu
    from gyrocal.drivers.emulated.motion import FunctionMotion
    from gyrocal.drivers.imu import open_imu
    from gyrocal.drivers.imu.chips import LSM9DS1_BW_G_CUTOFF_HZ

    amp = 200 * math.pi / 180
    rows = []
    for odr, cutoffs in LSM9DS1_BW_G_CUTOFF_HZ.items():
        for fc in sorted(set(cutoffs)):
            if fc > odr / 2:
                continue
            clock = VirtualClock()
            motion = FunctionMotion(lambda t, f=fc: np.column_stack(
                [amp * np.sin(2 * np.pi * f * t), 0 * t, 0 * t]))
            bus, addr = make_emulated_imu("lsm9ds1", clock, motion,
                                          SensorTruth(),  # typical noise: a live gyro
                                          subsamples=1)
            reader = open_imu("lsm9ds1", bus, addr, clock=clock, range_dps=500, odr_hz=odr,
                              lowpass_hz=fc)
            reader.start()
            t, g = [], []
            while clock.monotonic() < 1.5:
                clock.sleep(0.01)
                b = reader.read()
                t.append(b.t)
                g.append(b.rate[:, 0])
            tt, gg = np.concatenate(t), np.concatenate(g)
            keep = tt > tt[0] + 0.7
            basis = np.column_stack([np.sin(2 * np.pi * fc * tt[keep]),
                                     np.cos(2 * np.pi * fc * tt[keep])])
            coef, *_ = np.linalg.lstsq(basis, gg[keep], rcond=None)
            rows.append([odr, fc, reader.info.lowpass_hz, float(np.hypot(*coef)) / amp])
    print_table(["ODR Hz", "Table 47 cutoff Hz", "driver reports Hz", "gain at cutoff"], rows,
                title="LSM9DS1 gyro bandwidth through the driver (0.7071 = −3 dB)")


def clients() -> None:
    test = Path(__file__).resolve().parent.parent / "tests/drivers/test_third_party_clients.py"
    run = subprocess.run([sys.executable, "-m", "pytest", "-q", "-rA", "-p", "no:cacheprovider",
                          str(test)], capture_output=True, text=True, check=False)
    rows = []
    for line in run.stdout.splitlines():
        for status in ("PASSED", "FAILED", "SKIPPED", "ERROR"):
            if line.startswith(status + " "):
                rest = line[len(status) + 1:]
                name, _, why = rest.partition(" - ")
                rows.append([name.split("::")[-1], status, why.strip()[:70]])
    print_table(["client test", "result", "why"], rows,
                title="Third-party clients, unmodified, against the emulators")


def main(argv: list[str]) -> None:
    quick = "--quick" in argv
    bus_timing(300 if quick else 3000)
    lsm_bandwidth()
    clients()
