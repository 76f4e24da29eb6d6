"""Gimbal benchmarks: sync-read round trips, the position sampling rate, a 60 s protocol.

``python -m bench gimbal`` (``--quick`` for fewer repetitions). Three tables:

1. Sync-read round trips per second for three servos. In-process on the virtual clock, the
   wall rate is the emulator's own cost and the virtual time per round trip is the modelled bus
   time, i.e. the rate a real bus at that baud rate and Return Delay Time allows. In-process on
   the system clock and over a pseudo-terminal the rate is real (wall) time.
2. The loop rate of one sync read plus an IMU FIFO drain, the drain emulated by a plain wait of
   ``IMU_DRAIN_S`` (60 bytes over I²C at 400 kHz, ≈1.5 ms: a 1 kHz gyro drained at 200 Hz).
3. A 60 s calibration protocol (one turn each way about each axis at 1 rad/s with rests) on the
   in-process transport and the virtual clock: wall time of the servo traffic alone, and with the
   jig's true rate queried at 1 kHz as the emulated IMU does.
"""

from __future__ import annotations

import inspect
import time

import numpy as np
from dynamixel_sdk import COMM_SUCCESS, GroupSyncRead, PacketHandler, PortHandler

from bench.table import print_table
from gyrocal.drivers.clock import SystemClock, VirtualClock
from gyrocal.drivers.dynamixel import Gimbal
from gyrocal.drivers.dynamixel.gimbal import SAMPLE_LAYOUTS
from gyrocal.drivers.emulated.dxl import PtyServoBridge, make_emulated_gimbal, make_servo_bus

#: Time an IMU FIFO drain takes in the loop (emulated by a wait), s.
IMU_DRAIN_S = 1.5e-3


#: Attempts per sync read after a lost or corrupt status packet: the driver's own default.
RETRIES = inspect.signature(Gimbal).parameters["retries"].default


def _sync_reads(port, n: int, layout: str, fast: bool = False) -> int:
    """``n`` sync reads of the three servos; returns how many status packets were lost.

    A failed read is retried up to :data:`RETRIES` times, as the driver does (a status packet
    lost on a loaded host is not a benchmark failure); only a read that fails every attempt
    raises.
    """
    ph = PacketHandler(2.0)
    sr = GroupSyncRead(port, ph, *SAMPLE_LAYOUTS[layout])
    for i in (1, 2, 3):
        sr.addParam(i)
    lost = 0
    for _ in range(n):
        for _attempt in range(RETRIES + 1):
            result = sr.fastSyncRead() if fast else sr.txRxPacket()
            if result == COMM_SUCCESS:
                break
            lost += 1
        else:
            raise RuntimeError(f"sync read failed {RETRIES + 1} times: "
                               f"{ph.getTxRxResult(result)}")
    return lost


def _inprocess(clock, baud: int, return_delay_us: float | None):
    port, _, _ = make_emulated_gimbal(clock, seed=1, baudrate=baud,
                                      return_delay_us=return_delay_us)
    port.openPort()
    return port


def table_round_trips(n: int) -> None:
    rows = []
    for baud in (1_000_000, 57600):
        for delay in (None, 0.0):
            for layout in ("motion", "position"):
                clock = VirtualClock()
                port = _inprocess(clock, baud, delay)
                w0, v0 = time.perf_counter(), clock.monotonic()
                lost = _sync_reads(port, n, layout)
                wall = time.perf_counter() - w0
                virt = (clock.monotonic() - v0) / n
                rows.append(["in-process, virtual clock", baud,
                             "500" if delay is None else "0", layout, n, lost, n / wall,
                             virt * 1e3, 1.0 / virt])
    for layout in ("motion", "position"):
        clock = SystemClock()
        port = _inprocess(clock, 1_000_000, None)
        w0 = time.perf_counter()
        lost = _sync_reads(port, n // 4, layout)
        wall = time.perf_counter() - w0
        rows.append(["in-process, system clock", 1_000_000, "500", layout, n // 4, lost,
                     (n // 4) / wall, wall / (n // 4) * 1e3, (n // 4) / wall])
    clock = SystemClock()
    with PtyServoBridge(make_servo_bus(clock, seed=1)) as bridge:
        port = PortHandler(bridge.path)
        port.openPort()
        port.setBaudRate(1_000_000)
        for layout, fast in (("motion", False), ("position", False), ("motion", True)):
            w0 = time.perf_counter()
            lost = _sync_reads(port, n // 2, layout, fast)
            wall = time.perf_counter() - w0
            name = "pseudo-terminal" + (" (fast sync read)" if fast else "")
            rows.append([name, "(n/a)", "0 (not modelled)", layout, n // 2, lost,
                         (n // 2) / wall,
                         wall / (n // 2) * 1e3, (n // 2) / wall])
        port.closePort()
    print_table(
        ["transport", "baud", "return delay µs", "layout", "reads", "lost (retried)",
         "wall reads/s",
         "bus ms/read", "sampling Hz"],
        rows,
        "Sync read of 3 servos through dynamixel-sdk (sampling Hz = 1 / bus time per read; a "
        f"lost status packet is retried up to {RETRIES} times, as the driver does, and counted)",
    )


def table_loop_rate(n: int) -> None:
    rows = []
    for name, make, delay in (("in-process, system clock, 1 Mbps", "inproc", None),
                              ("in-process, system clock, 1 Mbps", "inproc", 0.0),
                              ("pseudo-terminal", "pty", None)):
        for layout in ("motion", "position"):
            clock = SystemClock()
            bridge = None
            if make == "inproc":
                port = _inprocess(clock, 1_000_000, None)
            else:
                bridge = PtyServoBridge(make_servo_bus(clock, seed=1))
                port = PortHandler(bridge.start())
            g = Gimbal(port, clock=clock, sample_layout=layout, handle_signals=False,
                       return_delay_us=delay)
            try:
                g.open()
                w0 = time.perf_counter()
                for _ in range(n):
                    clock.sleep(IMU_DRAIN_S)  # the IMU FIFO drain
                    g.poll()
                wall = time.perf_counter() - w0
            finally:
                g.close()
                if bridge is not None:
                    bridge.stop()
            rate = n / wall
            delay_text = "0 (not modelled)" if make == "pty" else (
                "500 (factory)" if delay is None else f"{delay:g} (set by the driver)")
            rows.append([name, delay_text, layout, n, g.retry_count, IMU_DRAIN_S * 1e3, rate,
                         "yes" if rate >= 200 else "no"])
    print_table(["transport", "return delay µs", "layout", "loops", "driver retries",
                 "IMU drain ms", "loop Hz", ">= 200 Hz"], rows,
                "Loop of one IMU drain (emulated wait) + one Gimbal.poll(), real time")


def _protocol(with_imu: bool) -> tuple[float, float, int, int]:
    clock = VirtualClock()
    port, _, jig = make_emulated_gimbal(clock, seed=1)
    g = Gimbal(port, clock=clock, handle_signals=False)
    g.open()
    period = 0.005
    state = {"t_imu": clock.monotonic(), "polls": 0, "imu": 0}

    def loop_until(done) -> None:
        while True:
            t0 = clock.monotonic()
            g.poll()
            state["polls"] += 1
            if with_imu:
                ts = np.arange(state["t_imu"], clock.monotonic(), 1e-3)
                if ts.size:
                    jig.rate(ts)
                    state["imu"] += ts.size
                    state["t_imu"] = ts[-1] + 1e-3
            if done():
                return
            clock.sleep(max(0.0, period - (clock.monotonic() - t0)))

    w0 = time.perf_counter()
    start = clock.monotonic()
    loop_until(lambda: clock.monotonic() - start > 2.0)
    for servo in (1, 2, 3):
        for direction in (1, -1):
            g.begin_turn(servo, 1, 1.0, direction)
            loop_until(lambda: not g.busy)
            t_rest = clock.monotonic()
            loop_until(lambda t_rest=t_rest: clock.monotonic() - t_rest > 3.0)
    g.close()
    return time.perf_counter() - w0, clock.monotonic() - start, state["polls"], state["imu"]


def table_protocol() -> None:
    rows = []
    for with_imu in (False, True):
        wall, jig_time, polls, imu = _protocol(with_imu)
        rows.append(["servo traffic" + (" + jig rate at 1 kHz" if with_imu else ""),
                     jig_time, polls, imu, wall, "yes" if wall < 5.0 else "no"])
    print_table(["what", "jig time s", "sync reads", "rate samples", "wall s", "< 5 s"], rows,
                "Simulated protocol (6 one-turn motions at 1 rad/s, 200 Hz loop), in-process, "
                "virtual clock")


def main(argv: list[str]) -> None:
    """Print the three tables (``--quick``: fewer repetitions)."""
    n = 400 if "--quick" in argv else 2000
    table_round_trips(n)
    table_loop_rate(n // 4)
    table_protocol()
