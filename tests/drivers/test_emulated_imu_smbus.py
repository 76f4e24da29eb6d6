"""EmulatedSMBus: the smbus2 surface, its errors, transfer time and the transaction log."""

import errno

import pytest
from smbus2 import i2c_msg

from gyrocal.drivers.clock import VirtualClock
from gyrocal.drivers.emulated.smbus import EmulatedSMBus, I2CDevice


class RegisterFile:
    """A minimal I²C register device: a pointer that auto-increments over 256 bytes."""

    def __init__(self):
        self.regs = bytearray(range(256))
        self.ptr = 0
        self.refuse = None

    def i2c_ack(self):
        return self.refuse

    def i2c_write(self, data):
        self.ptr = data[0]
        for b in data[1:]:
            self.regs[self.ptr] = b
            self.ptr = (self.ptr + 1) & 0xFF

    def i2c_read(self, length):
        out = bytes(self.regs[(self.ptr + i) & 0xFF] for i in range(length))
        self.ptr = (self.ptr + length) & 0xFF
        return out


@pytest.fixture
def bus():
    b = EmulatedSMBus(VirtualClock(), bus_hz=400_000)
    b.attach(0x50, RegisterFile())
    return b


def test_register_access_matches_smbus2_signatures(bus):
    assert isinstance(bus.device(0x50), I2CDevice)
    assert bus.read_byte_data(0x50, 0x10) == 0x10
    bus.write_byte_data(0x50, 0x10, 0xAB)
    assert bus.read_byte_data(0x50, 0x10) == 0xAB
    bus.write_i2c_block_data(0x50, 0x20, [1, 2, 3])
    assert bus.read_i2c_block_data(0x50, 0x1F, 5) == [0x1F, 1, 2, 3, 0x23]


def test_block_transfers_over_32_bytes_raise_value_error_before_any_io(bus):
    t0 = bus.clock.monotonic()
    with pytest.raises(ValueError, match="32"):
        bus.read_i2c_block_data(0x50, 0, 33)
    with pytest.raises(ValueError, match="32"):
        bus.write_i2c_block_data(0x50, 0, list(range(33)))
    assert bus.clock.monotonic() == t0
    assert len(bus.log) == 0
    assert len(bus.read_i2c_block_data(0x50, 0, 32)) == 32


def test_absent_address_is_eremoteio(bus):
    with pytest.raises(OSError) as info:
        bus.read_byte_data(0x51, 0)
    assert info.value.errno == errno.EREMOTEIO
    assert bus.log[-1].errno == errno.EREMOTEIO


def test_device_refusal_carries_its_errno(bus):
    bus.device(0x50).refuse = errno.ETIMEDOUT
    with pytest.raises(OSError) as info:
        bus.write_byte_data(0x50, 0, 1)
    assert info.value.errno == errno.ETIMEDOUT


def test_i2c_rdwr_fills_read_messages_and_has_no_32_byte_limit(bus):
    w = i2c_msg.write(0x50, [0x00])
    r = i2c_msg.read(0x50, 200)
    bus.i2c_rdwr(w, r)
    assert list(r) == list(range(200))
    assert bytes(r) == bytes(range(200))
    entry = bus.log[-1]
    assert (entry.op, entry.register, entry.read_length) == ("i2c_rdwr", 0x00, 200)


def test_i2c_rdwr_can_be_unsupported_like_a_plain_smbus_adapter():
    b = EmulatedSMBus(VirtualClock(), i2c_rdwr_supported=False)
    b.attach(0x50, RegisterFile())
    with pytest.raises(OSError) as info:
        b.i2c_rdwr(i2c_msg.write(0x50, [0]), i2c_msg.read(0x50, 4))
    assert info.value.errno == errno.EOPNOTSUPP


def test_transfer_time_is_spent_on_the_clock(bus):
    # read_byte_data: START + address(9) + register(9), repeated START + address(9) + data(9),
    # STOP: 1 + 9 + 9 + 1 + 9 + 9 + 1 = 39 bit times at 400 kHz.
    t0 = bus.clock.monotonic()
    bus.read_byte_data(0x50, 0)
    assert bus.clock.monotonic() - t0 == pytest.approx(39 / 400_000)
    assert bus.log[-1].duration_s == pytest.approx(39 / 400_000)
    # a 512-byte burst: 1 + 9 + 9 + 1 + 9 + 512 * 9 + 1
    t0 = bus.clock.monotonic()
    bus.i2c_rdwr(i2c_msg.write(0x50, [0]), i2c_msg.read(0x50, 512))
    assert bus.clock.monotonic() - t0 == pytest.approx((30 + 512 * 9) / 400_000)


def test_zero_bus_hz_spends_no_time():
    b = EmulatedSMBus(VirtualClock(), bus_hz=0)
    b.attach(0x50, RegisterFile())
    b.read_i2c_block_data(0x50, 0, 32)
    assert b.clock.monotonic() == 0.0


def test_log_is_bounded_and_counts_everything():
    b = EmulatedSMBus(VirtualClock(), log_size=3)
    b.attach(0x50, RegisterFile())
    for _ in range(5):
        b.read_byte_data(0x50, 0)
    assert len(b.log) == 3
    assert b.transactions == 5


def test_close_and_context_manager():
    with EmulatedSMBus(VirtualClock()) as b:
        b.attach(0x50, RegisterFile())
        b.read_byte_data(0x50, 0)
    with pytest.raises(OSError) as info:
        b.read_byte_data(0x50, 0)
    assert info.value.errno == errno.EBADF


def test_attach_checks_its_arguments(bus):
    with pytest.raises(ValueError, match="already"):
        bus.attach(0x50, RegisterFile())
    with pytest.raises(ValueError, match="7-bit"):
        bus.attach(0x80, RegisterFile())
    with pytest.raises(TypeError):
        bus.attach(0x51, object())
    with pytest.raises(ValueError, match="bus_hz"):
        EmulatedSMBus(VirtualClock(), bus_hz=-1)
    bus.detach(0x50)
    with pytest.raises(OSError):
        bus.read_byte_data(0x50, 0)
