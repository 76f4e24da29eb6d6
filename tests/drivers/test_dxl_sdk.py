"""The real dynamixel-sdk, unmodified, against the emulated servos over both transports.

Expected values come from the datasheet (hardware reference §5) and from the emulated servos'
configured truth, never from the emulator's own answers.
"""

import math

import pytest
from dynamixel_sdk import (
    COMM_RX_TIMEOUT,
    COMM_SUCCESS,
    GroupBulkRead,
    GroupBulkWrite,
    GroupSyncRead,
    GroupSyncWrite,
    PacketHandler,
    PortHandler,
    port_handler,
)

from gyrocal.drivers.clock import SystemClock, VirtualClock
from gyrocal.drivers.dynamixel.control_table import model_by_name
from gyrocal.drivers.emulated.dxl import (
    EmulatedPortHandler,
    EmulatedServo,
    PtyServoBridge,
    ServoBus,
)

BAUD = 1_000_000
XM = model_by_name("XM430-W350").table


class Rig:
    def __init__(self, port, bus, clock):
        self.port, self.bus, self.clock = port, bus, clock
        self.ph = PacketHandler(2.0)


def _servos(clock):
    return [
        EmulatedServo(1, "XM430-W350", clock=clock, seed=1, baudrate=BAUD, initial_ticks=1000),
        EmulatedServo(2, "XM430-W350", clock=clock, seed=2, baudrate=BAUD, velocity_limit=350),
        EmulatedServo(3, "XL430-W250", clock=clock, seed=3, baudrate=BAUD),
    ]


#: LATENCY_TIMER (ms) for the pseudo-terminal runs. The SDK's packet timeout assumes an FTDI
#: latency timer of 16 ms (§4.7) and asks users to adjust it to their adapter; here the
#: "adapter" is a thread of this test run, which a loaded machine can deschedule for longer.
PTY_LATENCY_MS = 100


@pytest.fixture(params=["inprocess", "pty"])
def rig(request, monkeypatch):
    if request.param == "inprocess":
        clock = VirtualClock()
        bus = ServoBus(_servos(clock), clock)
        port = EmulatedPortHandler(bus)
        port.baudrate = BAUD
        assert port.openPort()
        yield Rig(port, bus, clock)
        port.closePort()
    else:
        monkeypatch.setattr(port_handler, "LATENCY_TIMER", PTY_LATENCY_MS)
        clock = SystemClock()
        bus = ServoBus(_servos(clock), clock)
        with PtyServoBridge(bus) as bridge:
            port = PortHandler(bridge.path)  # the SDK's own serial PortHandler
            assert port.openPort()
            assert port.setBaudRate(BAUD)
            yield Rig(port, bus, clock)
            port.closePort()


def read(r, dxl_id, name):
    item = (model_by_name("XL430-W250").table if dxl_id == 3 else XM)[name]
    data, result, error = r.ph.readTxRx(r.port, dxl_id, item.address, item.size)
    assert result == COMM_SUCCESS, r.ph.getTxRxResult(result)
    assert error == 0, r.ph.getRxPacketError(error)
    return item.from_bytes(data)


def write(r, dxl_id, name, value):
    item = XM[name]
    fn = {1: r.ph.write1ByteTxRx, 2: r.ph.write2ByteTxRx, 4: r.ph.write4ByteTxRx}[item.size]
    return fn(r.port, dxl_id, item.address, item.encode(value))


def test_ping_reports_model_numbers(rig):
    assert rig.ph.ping(rig.port, 1) == (1020, COMM_SUCCESS, 0)
    assert rig.ph.ping(rig.port, 3) == (1060, COMM_SUCCESS, 0)
    _, result, _ = rig.ph.ping(rig.port, 9)
    assert result == COMM_RX_TIMEOUT


def test_read_only_items_have_their_datasheet_values(rig):
    assert read(rig, 1, "Model Number") == 1020
    assert read(rig, 3, "Model Number") == 1060
    assert read(rig, 1, "Firmware Version") == 46
    assert read(rig, 1, "Hardware Error Status") == 0
    assert read(rig, 1, "Present Input Voltage") == 120  # 12.0 V in 0.1 V
    assert read(rig, 1, "Present Temperature") == 25
    assert read(rig, 1, "Present Velocity") == 0
    assert read(rig, 1, "Moving") == 0
    assert 0 <= read(rig, 1, "Realtime Tick") < 32768
    assert read(rig, 1, "Present Position") == 1000  # power-up: within one turn (§5.2)
    # Velocity Limit is firmware-dependent (§5): the emulated servos carry 200, 350 and 265.
    assert [read(rig, i, "Velocity Limit") for i in (1, 2, 3)] == [200, 350, 265]
    # EEPROM defaults
    assert read(rig, 1, "Temperature Limit") == 80 and read(rig, 3, "Temperature Limit") == 72
    assert read(rig, 1, "Return Delay Time") == 250
    assert read(rig, 1, "Operating Mode") == 3
    assert read(rig, 1, "Shutdown") == 52


@pytest.mark.parametrize(("name", "value"), [
    ("Return Delay Time", 0), ("Drive Mode", 0), ("Operating Mode", 4),
    ("Temperature Limit", 70), ("Min Voltage Limit", 100), ("Max Voltage Limit", 150),
    ("Velocity Limit", 210), ("Bus Watchdog", 5), ("Goal Velocity", -5),
    ("Profile Acceleration", 8), ("Profile Velocity", 42), ("Goal Position", -1000),
])
def test_write_then_read_back_every_writable_item_the_driver_uses(rig, name, value):
    if name == "Goal Position":
        assert write(rig, 1, "Operating Mode", 4) == (COMM_SUCCESS, 0)
    assert write(rig, 1, name, value) == (COMM_SUCCESS, 0)
    assert read(rig, 1, name) == value


def test_torque_enable_locks_the_eeprom(rig):
    assert write(rig, 1, "Torque Enable", 1) == (COMM_SUCCESS, 0)
    assert read(rig, 1, "Torque Enable") == 1
    assert write(rig, 1, "Operating Mode", 4) == (COMM_SUCCESS, 7)  # Access Error
    assert write(rig, 1, "Torque Enable", 0) == (COMM_SUCCESS, 0)
    assert write(rig, 1, "Operating Mode", 4) == (COMM_SUCCESS, 0)


def test_access_errors_and_the_sdk_pitfall(rig):
    assert write(rig, 1, "Model Number", 5)[1] == 7  # read-only
    # A READ past the table: Access Error with no data (§4.5). readTxRx then returns the CRC
    # bytes as data, and read4ByteTxRx raises IndexError: the driver must not trust either.
    data, result, error = rig.ph.readTxRx(rig.port, 1, 700, 4)
    assert result == COMM_SUCCESS and error == 7 and len(data) == 2
    with pytest.raises(IndexError):
        rig.ph.read4ByteTxRx(rig.port, 1, 700)


def test_goal_velocity_beyond_the_velocity_limit_is_refused(rig):
    assert write(rig, 1, "Goal Velocity", 201)[1] == 6  # Data Limit Error
    assert write(rig, 2, "Goal Velocity", 340) == (COMM_SUCCESS, 0)  # its limit is 350


def test_sync_write_then_sync_read(rig):
    sw = GroupSyncWrite(rig.port, rig.ph, 112, 4)
    for i, v in ((1, 11), (2, 22), (3, 33)):
        assert sw.addParam(i, list(v.to_bytes(4, "little")))
    assert sw.txPacket() == COMM_SUCCESS
    sr = GroupSyncRead(rig.port, rig.ph, 112, 4)
    for i in (1, 2, 3):
        sr.addParam(i)
    assert sr.txRxPacket() == COMM_SUCCESS
    assert [sr.getData(i, 112, 4) for i in (1, 2, 3)] == [11, 22, 33]


def test_fast_sync_read(rig):
    for i, v in ((1, 7), (2, 8), (3, 9)):
        assert write(rig, i, "Profile Acceleration", v) == (COMM_SUCCESS, 0)
    sr = GroupSyncRead(rig.port, rig.ph, 108, 8)
    for i in (3, 1, 2):
        sr.addParam(i)
    assert sr.fastSyncRead() == COMM_SUCCESS
    assert [sr.getData(i, 108, 4) for i in (1, 2, 3)] == [7, 8, 9]
    assert [sr.getData(i, 112, 4) for i in (1, 2, 3)] == [0, 0, 0]


@pytest.mark.parametrize("fast", [False, True])
def test_bulk_read(rig, fast):
    # dynamixel-sdk's fastBulkReadRx finds each ID with list.index() in the flat parameter list,
    # so an address or length byte equal to a later ID would be mistaken for it: the parameters
    # here avoid that (a quirk of the SDK, not of the protocol).
    br = GroupBulkRead(rig.port, rig.ph)
    assert br.addParam(1, 0, 7)      # Model Number, Model Information, Firmware Version
    assert br.addParam(2, 144, 4)    # Present Input Voltage, Present Temperature, Backup Ready
    assert br.addParam(3, 44, 4)     # Velocity Limit
    assert (br.fastBulkRead() if fast else br.txRxPacket()) == COMM_SUCCESS
    assert br.getData(1, 0, 2) == 1020
    assert br.getData(2, 144, 2) == 120
    assert br.getData(1, 6, 1) == 46
    assert br.getData(3, 44, 4) == 265


def test_byte_stuffed_replies_and_instructions(rig):
    # Present Position = -131073 encodes as FF FF FD FF: the status must be stuffed (§4.3).
    offset = -131073 - 1000  # servo 1 powers up at 1000 ticks
    assert write(rig, 1, "Homing Offset", offset) == (COMM_SUCCESS, 0)
    value, result, error = rig.ph.read4ByteTxRx(rig.port, 1, 132)
    assert (result, error) == (COMM_SUCCESS, 0)
    assert XM["Present Position"].decode(value) == -131073
    sr = GroupSyncRead(rig.port, rig.ph, 132, 4)
    sr.addParam(1)
    sr.addParam(2)
    assert sr.txRxPacket() == COMM_SUCCESS
    assert XM["Present Position"].decode(sr.getData(1, 132, 4)) == -131073
    # and an instruction carrying FF FF FD (stuffed by the SDK) is understood
    assert write(rig, 2, "Operating Mode", 4) == (COMM_SUCCESS, 0)
    assert write(rig, 2, "Goal Position", -131073) == (COMM_SUCCESS, 0)
    assert read(rig, 2, "Goal Position") == -131073


def test_broadcast_ping_lists_every_servo(rig):
    found, result = rig.ph.broadcastPing(rig.port)
    assert result == COMM_SUCCESS
    assert found == {1: [1020, 46], 2: [1020, 46], 3: [1060, 46]}


def test_reg_write_waits_for_action(rig):
    item = XM["Profile Velocity"]
    result, error = rig.ph.regWriteTxRx(rig.port, 1, item.address, 4, list(item.to_bytes(77)))
    assert (result, error) == (COMM_SUCCESS, 0)
    assert read(rig, 1, "Profile Velocity") == 0
    assert read(rig, 1, "Registered Instruction") == 1
    assert rig.ph.action(rig.port, 1) == COMM_SUCCESS
    # The servo answers ACTION but the SDK does not wait for it (§4.4); let the status arrive
    # before the next transaction's clearPort, or it would be taken for the next reply.
    rig.clock.sleep(0.02)
    assert read(rig, 1, "Profile Velocity") == 77
    assert read(rig, 1, "Registered Instruction") == 0


def test_status_return_level(rig):
    # (the write that lowers the level is itself not answered: the new level already applies)
    assert write(rig, 1, "Status Return Level", 1)[0] in (COMM_SUCCESS, COMM_RX_TIMEOUT)
    # level 1: reads answer, writes do not (the SDK then times out waiting for a status)
    assert read(rig, 1, "Status Return Level") == 1
    assert write(rig, 1, "LED", 1)[0] == COMM_RX_TIMEOUT
    assert read(rig, 1, "LED") == 1  # ...but it was executed
    assert rig.ph.ping(rig.port, 1)[1] == COMM_SUCCESS


def test_hardware_alert_reaches_every_status_until_reboot(rig):
    servo = rig.bus.servo(2)
    assert write(rig, 2, "Torque Enable", 1) == (COMM_SUCCESS, 0)
    servo.raise_alert_at(rig.clock.monotonic(), bits=1 << 5)
    data, result, error = rig.ph.readTxRx(rig.port, 2, 70, 1)
    assert result == COMM_SUCCESS and error == 0x80 and data == [0x20]
    assert "Hardware error" in rig.ph.getRxPacketError(error)
    assert read_alerting(rig, 2, 64) == 0  # torque was switched off
    result, error = rig.ph.reboot(rig.port, 2)
    assert result == COMM_SUCCESS
    rig.clock.sleep(servo.reboot_time_s)  # it hears nothing while it boots
    assert read(rig, 2, "Hardware Error Status") == 0


def read_alerting(r, dxl_id, address):
    data, result, error = r.ph.readTxRx(r.port, dxl_id, address, 1)
    assert result == COMM_SUCCESS and error & 0x80
    return data[0]


def test_clear_multi_turn_rebases_within_one_turn(rig):
    assert write(rig, 1, "Operating Mode", 4) == (COMM_SUCCESS, 0)
    offset = 3 * 4096
    assert write(rig, 1, "Homing Offset", offset) == (COMM_SUCCESS, 0)
    assert read(rig, 1, "Present Position") == 1000 + offset
    result, error = rig.ph.clearMultiTurn(rig.port, 1)
    assert (result, error) == (COMM_SUCCESS, 0)
    assert math.floor((read(rig, 1, "Present Position") - offset) / 4096) == 0


def test_group_bulk_write_sets_different_items_on_different_servos(rig):
    bw = GroupBulkWrite(rig.port, rig.ph)
    lim, rdt = XM["Velocity Limit"], XM["Return Delay Time"]
    assert bw.addParam(1, lim.address, lim.size, list(lim.to_bytes(150)))
    assert bw.addParam(2, rdt.address, rdt.size, list(rdt.to_bytes(20)))
    assert bw.txPacket() == COMM_SUCCESS
    assert read(rig, 1, "Velocity Limit") == 150
    assert read(rig, 2, "Return Delay Time") == 20


def test_factory_reset_keeping_id_and_baud_over_the_sdk(rig):
    # e-Manual, Protocol 2.0, Factory Reset (0x06), option 0x02: all but ID and Baud Rate
    assert write(rig, 1, "Velocity Limit", 150) == (COMM_SUCCESS, 0)
    assert rig.ph.factoryReset(rig.port, 1, 0x02) == (COMM_SUCCESS, 0)
    assert read(rig, 1, "Velocity Limit") == 200  # XM430-W350's factory value
