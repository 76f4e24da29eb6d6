"""The pseudo-terminal transport: the driver by device path, and ``gyrocal emulate --pty``."""

import json
import math
import signal
import subprocess
import sys

import pytest
from dynamixel_sdk import COMM_SUCCESS, GroupSyncRead, PacketHandler, PortHandler, port_handler

from gyrocal.drivers.clock import SystemClock
from gyrocal.drivers.dynamixel import Gimbal
from gyrocal.drivers.emulated.dxl import EmulatedServo, PtyServoBridge, ServoBus

pytestmark = pytest.mark.skipif(sys.platform == "win32", reason="POSIX pseudo-terminals")


@pytest.fixture(autouse=True)
def patient_sdk(monkeypatch):
    """Room for a loaded machine: the servos answer from a thread or a process of this run, not
    from a U2D2 with a 16 ms latency timer (the SDK asks users to set LATENCY_TIMER to their
    adapter's; see test_dxl_sdk.PTY_LATENCY_MS)."""
    monkeypatch.setattr(port_handler, "LATENCY_TIMER", 100)


def test_the_driver_opens_a_device_path_and_turns_a_servo_in_real_time():
    clock = SystemClock()
    servos = [EmulatedServo(i, clock=clock, seed=i, baudrate=1_000_000) for i in (1, 2, 3)]
    bus = ServoBus(servos, clock)
    with PtyServoBridge(bus) as bridge:
        # (a Bus Watchdog of 1 s: a loaded machine may pause this loop for more than 100 ms)
        with Gimbal(bridge.path, clock=clock, acceleration=30.0, watchdog_s=1.0) as g:
            assert [g.infos[i].model_number for i in (1, 2, 3)] == [1020] * 3
            m = g.run_turn(3, 1, 4.5, -1)
            assert m.finished
            assert g.last_sample.angle(3) == pytest.approx(-2 * math.pi)
            assert servos[2].register("Present Position") == g.home_ticks[3] - 4096
        assert not any(s.torque_enabled() for s in servos)
    assert bridge.error is None


def test_gyrocal_emulate_pty_serves_the_sdk():
    proc = subprocess.Popen(
        [sys.executable, "-m", "gyrocal.kit", "emulate", "--pty", "--json", "--ids", "4,5",
         "--model", "XL430-W250", "--duration", "60"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        info = json.loads(proc.stdout.readline())
        assert info["ids"] == [4, 5] and info["model"] == "XL430-W250"
        port = PortHandler(info["device"])
        assert port.openPort() and port.setBaudRate(1_000_000)
        ph = PacketHandler(2.0)
        assert ph.ping(port, 4) == (1060, COMM_SUCCESS, 0)
        sr = GroupSyncRead(port, ph, 144, 3)
        sr.addParam(4)
        sr.addParam(5)
        assert sr.txRxPacket() == COMM_SUCCESS
        assert [sr.getData(i, 144, 2) for i in (4, 5)] == [120, 120]
        port.closePort()
    finally:
        proc.send_signal(signal.SIGTERM)
        out, err = proc.communicate(timeout=20)
    assert proc.returncode == 0, err


def test_gyrocal_emulate_without_pty_is_a_usage_error():
    proc = subprocess.run([sys.executable, "-m", "gyrocal.kit", "emulate"], capture_output=True,
                          text=True, timeout=60)
    assert proc.returncode == 2 and "--pty" in proc.stderr


def test_only_servos_at_the_clients_baud_rate_answer_over_the_pty():
    # e-Manual, X-series, Baud Rate (8): host and servo must share the rate to communicate
    clock = SystemClock()
    bus = ServoBus([EmulatedServo(1, clock=clock, seed=1, baudrate=1_000_000),
                    EmulatedServo(2, clock=clock, seed=2, baudrate=57600)], clock)
    with PtyServoBridge(bus) as bridge:
        port = PortHandler(bridge.path)
        ph = PacketHandler(2.0)
        assert port.openPort() and port.setBaudRate(57600)
        assert ph.ping(port, 1)[1] != COMM_SUCCESS
        assert ph.ping(port, 2)[:2] == (1020, COMM_SUCCESS)
        assert port.setBaudRate(1_000_000)
        assert ph.ping(port, 1)[:2] == (1020, COMM_SUCCESS)
        assert ph.ping(port, 2)[1] != COMM_SUCCESS
        port.closePort()
    assert bridge.error is None


class RecordingClock(SystemClock):
    def __init__(self):
        self.sleeps = []

    def sleep(self, seconds):
        self.sleeps.append(seconds)
        super().sleep(seconds)


def test_the_pty_bridge_waits_each_servos_return_delay_time():
    # e-Manual, X-series, Return Delay Time (9): the servo waits this long (2 µs units) after
    # an instruction packet before it sends its status packet
    clock = SystemClock()
    bus = ServoBus([EmulatedServo(1, clock=clock, seed=1, baudrate=1_000_000,
                                  return_delay_us=300)], clock)
    with PtyServoBridge(bus, clock=RecordingClock()) as bridge:
        port = PortHandler(bridge.path)
        assert port.openPort() and port.setBaudRate(1_000_000)
        assert PacketHandler(2.0).ping(port, 1)[1] == COMM_SUCCESS
        port.closePort()
    assert bridge.clock.sleeps == [pytest.approx(300e-6)]
