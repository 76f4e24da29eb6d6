"""Secondary (Shadow) ID, control table address 12, through the unmodified dynamixel-sdk.

Expected behaviour transcribed from the e-Manual (X series control table, "Secondary(Shadow)
ID(12)"): servos sharing a Secondary ID form a group; ID(7) has priority over it; "The EEPROM
area of the Control Table cannot be modified with Secondary ID(12). Only the RAM area can be
modified"; "If Instruction Packet ID is the same as Secondary ID(12), the Status Packet will not
be returned"; 253-255 deactivate it; and its worked example with five servos of IDs 1-5.
"""

from dynamixel_sdk import COMM_RX_TIMEOUT, COMM_SUCCESS, PacketHandler

from gyrocal.drivers.clock import VirtualClock
from gyrocal.drivers.emulated.dxl import EmulatedPortHandler, EmulatedServo, ServoBus

BAUD = 1_000_000
SECONDARY_ID, RETURN_DELAY, LED = 12, 9, 65  # e-Manual X series control table addresses


def five_servos():
    clock = VirtualClock()
    bus = ServoBus([EmulatedServo(i, "XM430-W350", clock=clock, seed=i, baudrate=BAUD)
                    for i in range(1, 6)], clock)
    port = EmulatedPortHandler(bus)
    port.baudrate = BAUD
    assert port.openPort()
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
