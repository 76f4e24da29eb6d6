"""Secondary (Shadow) ID, control table address 12, through the unmodified dynamixel-sdk.

Expected behaviour transcribed from the e-Manual (X series control table, "Secondary(Shadow)
ID(12)"): servos sharing a Secondary ID form a group; ID(7) has priority over it; "The EEPROM
area of the Control Table cannot be modified with Secondary ID(12). Only the RAM area can be
modified"; "If Instruction Packet ID is the same as Secondary ID(12), the Status Packet will not
be returned"; 253-255 deactivate it; and its worked example with five servos of IDs 1-5.
The e-Manual names no instruction besides WRITE: REBOOT and CLEAR, which change nothing in the
EEPROM, act on the group without a status; FACTORY_RESET, which rewrites the EEPROM, does not.
"""

from dynamixel_sdk import COMM_RX_TIMEOUT, COMM_SUCCESS, PacketHandler

from gyrocal.drivers.clock import VirtualClock
from gyrocal.drivers.dynamixel.control_table import model_by_name
from gyrocal.drivers.emulated.dxl import EmulatedPortHandler, EmulatedServo, ServoBus

BAUD = 1_000_000
SECONDARY_ID, RETURN_DELAY, LED = 12, 9, 65  # e-Manual X series control table addresses
HW_ERROR, TORQUE, OPERATING_MODE, GOAL, PRESENT = 70, 64, 11, 116, 132
XM = model_by_name("XM430-W350").table


def five_servos():
    clock = VirtualClock()
    bus = ServoBus([EmulatedServo(i, "XM430-W350", clock=clock, seed=i, baudrate=BAUD)
                    for i in range(1, 6)], clock)
    port = EmulatedPortHandler(bus)
    port.baudrate = BAUD
    assert port.openPort()
    five_servos.bus = bus
    return port, PacketHandler(2.0)


def leds(port, ph):
    out = []
    for i in range(1, 6):
        value, result, _ = ph.read1ByteTxRx(port, i, LED)
        assert result == COMM_SUCCESS
        out.append(value)
    return out


def test_the_e_manual_example_five_servos_with_secondary_id_5():
    port, ph = five_servos()
    for i in range(1, 6):
        assert ph.write1ByteTxRx(port, i, SECONDARY_ID, 5)[0] == COMM_SUCCESS
    # "Send Write Instruction Packet(ID = 1, LED(65) = 1)": only ID 1, which replies
    assert ph.write1ByteTxRx(port, 1, LED, 1)[0] == COMM_SUCCESS
    assert leds(port, ph) == [1, 0, 0, 0, 0]
    # "(ID = 5, LED(65) = 1)": all five LEDs; the status is ID 5's (its primary ID)
    result, error = ph.write1ByteTxRx(port, 5, LED, 1)
    assert (result, error) == (COMM_SUCCESS, 0)
    assert leds(port, ph) == [1, 1, 1, 1, 1]


def test_a_group_id_nobody_has_as_id_acts_silently_and_only_on_ram():
    port, ph = five_servos()
    for i in (2, 3, 4):
        assert ph.write1ByteTxRx(port, i, SECONDARY_ID, 100)[0] == COMM_SUCCESS
    assert ph.write1ByteTxRx(port, 100, LED, 1)[0] == COMM_RX_TIMEOUT  # no status packet
    assert leds(port, ph) == [0, 1, 1, 1, 0]
    # an EEPROM item cannot be modified with the Secondary ID
    before = [ph.read1ByteTxRx(port, i, RETURN_DELAY)[0] for i in (2, 3, 4)]
    assert ph.write1ByteTxRx(port, 100, RETURN_DELAY, 10)[0] == COMM_RX_TIMEOUT
    assert [ph.read1ByteTxRx(port, i, RETURN_DELAY)[0] for i in (2, 3, 4)] == before
    # a READ to the group answers nothing
    assert ph.read1ByteTxRx(port, 100, LED)[1] == COMM_RX_TIMEOUT


def test_secondary_id_253_and_above_is_off():
    port, ph = five_servos()
    assert ph.write1ByteTxRx(port, 2, SECONDARY_ID, 100)[0] == COMM_SUCCESS
    ph.write1ByteTxOnly(port, 100, LED, 1)
    assert leds(port, ph) == [0, 1, 0, 0, 0]
    assert ph.write1ByteTxRx(port, 2, LED, 0)[0] == COMM_SUCCESS
    for off in (253, 255):
        assert ph.write1ByteTxRx(port, 2, SECONDARY_ID, off)[0] == COMM_SUCCESS
        ph.write1ByteTxOnly(port, 100, LED, 1)
        assert leds(port, ph) == [0, 0, 0, 0, 0]


def _group_100(port, ph, members=(2, 3, 4)):
    for i in members:
        assert ph.write1ByteTxRx(port, i, SECONDARY_ID, 100)[0] == COMM_SUCCESS


def _rebooted(port, ph):
    """Wait out the boot (the servos hear nothing meanwhile), then read each one's LED."""
    bus = five_servos.bus
    bus.clock.sleep(bus.servo(1).reboot_time_s)
    return leds(port, ph)


def test_reboot_to_a_group_id_reboots_the_group_silently():
    port, ph = five_servos()
    _group_100(port, ph)
    for i in range(1, 6):
        assert ph.write1ByteTxRx(port, i, LED, 1)[0] == COMM_SUCCESS
    bus = five_servos.bus
    bus.servo(3).raise_alert_at(bus.clock.monotonic())  # an overload latched in servo 3
    assert ph.read1ByteTxRx(port, 3, HW_ERROR)[0] == 0x20
    assert ph.reboot(port, 100)[0] == COMM_RX_TIMEOUT  # no status packet
    # the group's RAM is back to its power-up values (LED 0), servo 3's error is cleared;
    # servos 1 and 5 were not rebooted
    assert _rebooted(port, ph) == [1, 0, 0, 0, 1]
    data, result, error = ph.readTxRx(port, 3, HW_ERROR, 1)
    assert (data, result, error) == ([0], COMM_SUCCESS, 0)
    # the Secondary ID is in the EEPROM: the group is still there
    assert [ph.read1ByteTxRx(port, i, SECONDARY_ID)[0] for i in (2, 3, 4)] == [100] * 3


def test_reboot_to_an_id_that_is_also_a_group_id_reboots_both_one_answers():
    port, ph = five_servos()
    for i in range(1, 6):
        assert ph.write1ByteTxRx(port, i, SECONDARY_ID, 5)[0] == COMM_SUCCESS
        assert ph.write1ByteTxRx(port, i, LED, 1)[0] == COMM_SUCCESS
    assert ph.reboot(port, 5) == (COMM_SUCCESS, 0)  # ID 5's own status
    assert _rebooted(port, ph) == [0, 0, 0, 0, 0]


def _turn_twice(port, ph, ids):
    """Extended Position mode, two turns and a bit forward, until still; their positions."""
    for i in ids:
        assert ph.write1ByteTxRx(port, i, OPERATING_MODE, 4)[0] == COMM_SUCCESS
        assert ph.write1ByteTxRx(port, i, TORQUE, 1)[0] == COMM_SUCCESS
        start = XM["Present Position"].from_bytes(bytes(ph.readTxRx(port, i, PRESENT, 4)[0]))
        goal = list(XM["Goal Position"].to_bytes(start + 2 * 4096 + 300))
        assert ph.writeTxRx(port, i, GOAL, 4, goal)[0] == COMM_SUCCESS
    five_servos.bus.clock.sleep(6.0)
    return [XM["Present Position"].from_bytes(bytes(ph.readTxRx(port, i, PRESENT, 4)[0]))
            for i in ids]


def test_clear_to_a_group_id_rebases_the_group_within_one_turn_silently():
    port, ph = five_servos()
    _group_100(port, ph, (2, 3))
    before = _turn_twice(port, ph, (1, 2, 3))
    assert all(p >= 2 * 4096 for p in before)
    assert ph.clearMultiTurn(port, 100)[0] == COMM_RX_TIMEOUT  # no status packet
    after = [XM["Present Position"].from_bytes(bytes(ph.readTxRx(port, i, PRESENT, 4)[0]))
             for i in (1, 2, 3)]
    # e-Manual, Protocol 2.0, Clear: "Reset a current Present Position value to an absolute
    # value within one full rotation (0-4096)"; servo 1 is not in the group
    assert after[0] == before[0]
    assert [0 <= p < 4096 and p % 4096 == b % 4096 for p, b in zip(after[1:], before[1:],
                                                                       strict=True)] == [True] * 2


def test_factory_reset_to_a_group_id_changes_no_eeprom():
    port, ph = five_servos()
    _group_100(port, ph)
    limit = XM["Velocity Limit"]
    assert ph.write4ByteTxRx(port, 2, limit.address, 150)[0] == COMM_SUCCESS
    assert ph.factoryReset(port, 100, 0x02)[0] == COMM_RX_TIMEOUT
    assert ph.read4ByteTxRx(port, 2, limit.address)[0] == 150
    assert [ph.read1ByteTxRx(port, i, SECONDARY_ID)[0] for i in (2, 3, 4)] == [100] * 3
