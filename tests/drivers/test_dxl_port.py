"""The in-process transport: bus timing and SDK timeouts on the virtual clock, transport faults."""

import time

import pytest
from dynamixel_sdk import (
    COMM_RX_CORRUPT,
    COMM_RX_TIMEOUT,
    COMM_SUCCESS,
    GroupSyncRead,
    PacketHandler,
)

from gyrocal.drivers.clock import VirtualClock
from gyrocal.drivers.emulated.dxl import make_emulated_gimbal

PH = PacketHandler(2.0)


@pytest.fixture
def emu():
    clock = VirtualClock()
    port, bus, jig = make_emulated_gimbal(clock, seed=5, baudrate=1_000_000)
    assert port.openPort()
    return clock, port, bus


def test_a_ping_takes_its_modelled_bus_time(emu):
    clock, port, _ = emu
    t0 = clock.monotonic()
    assert PH.ping(port, 1)[1] == COMM_SUCCESS
    byte_s = 10 / 1_000_000
    # 10-byte instruction, 500 µs Return Delay Time, 14-byte status (hardware reference §4.7, §5)
    assert clock.monotonic() - t0 == pytest.approx(10 * byte_s + 500e-6 + 14 * byte_s, rel=1e-9)


def test_sync_read_replies_come_one_after_another(emu):
    clock, port, bus = emu
    sr = GroupSyncRead(port, PH, 132, 4)
    for i in (1, 2, 3):
        sr.addParam(i)
    t0 = clock.monotonic()
    assert sr.txRxPacket() == COMM_SUCCESS
    byte_s = 10 / 1_000_000
    expected = (14 + 3) * byte_s + 3 * (500e-6 + 15 * byte_s)
    assert clock.monotonic() - t0 == pytest.approx(expected, rel=1e-9)


def test_a_dropped_status_times_out_in_virtual_time_not_wall_time(emu):
    clock, port, bus = emu
    bus.servo(2).drop_replies(1)
    t0, w0 = clock.monotonic(), time.monotonic()
    _, result, _ = PH.ping(port, 2)
    assert result == COMM_RX_TIMEOUT
    # the SDK's timeout: 11 bytes × tx time + 2 × 16 ms latency timer + 2 ms (§4.7)
    sdk_timeout = (11 * 10 / 1_000_000 + 0.034)
    elapsed = clock.monotonic() - t0
    assert sdk_timeout < elapsed < sdk_timeout + 10 * 10 / 1_000_000 + 1e-3
    assert time.monotonic() - w0 < 0.5
    assert PH.ping(port, 2)[1] == COMM_SUCCESS  # the next one gets through


def test_a_corrupted_status_is_reported_corrupt(emu):
    _, port, bus = emu
    bus.servo(1).corrupt_replies(1)
    _, result, _ = PH.read4ByteTxRx(port, 1, 132)
    assert result == COMM_RX_CORRUPT
    assert PH.read4ByteTxRx(port, 1, 132)[1] == COMM_SUCCESS


def test_a_servo_at_another_baud_rate_does_not_hear(emu):
    clock, port, bus = emu
    assert port.setBaudRate(57600)
    assert PH.ping(port, 1)[1] == COMM_RX_TIMEOUT
    assert port.setBaudRate(1_000_000)
    assert PH.ping(port, 1)[1] == COMM_SUCCESS


def test_a_silent_servo_breaks_the_sync_read_at_its_turn(emu):
    clock, port, bus = emu
    bus.servo(2).go_silent()
    sr = GroupSyncRead(port, PH, 132, 4)
    for i in (1, 2, 3):
        sr.addParam(i)
    assert sr.txRxPacket() == COMM_RX_TIMEOUT
    # a silent servo (dead TX line) still executes what it hears
    assert PH.write1ByteTxRx(port, 2, 65, 1)[0] == COMM_RX_TIMEOUT
    assert bus.servo(2).register("LED") == 1


def test_an_instruction_with_a_bad_crc_gets_a_crc_error_status(emu):
    clock, port, bus = emu
    from gyrocal.drivers.emulated.dxl.protocol import instruction_packet

    packet = bytearray(instruction_packet(1, 0x02, bytes([132, 0, 4, 0])))
    packet[-1] ^= 0x01
    port.writePort(packet)
    data = port.readPort(64)
    assert data[7:9] == bytes([0x55, 0x03])  # STATUS, CRC error (§4.5)
