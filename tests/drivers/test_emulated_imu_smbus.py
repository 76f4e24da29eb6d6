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


# -- the whole smbus2 surface ---------------------------------------------------------------------


def test_every_public_smbus2_method_exists_with_smbus2s_parameters():
    import inspect

    import smbus2

    names = [n for n, f in vars(smbus2.SMBus).items() if callable(f) and not n.startswith("_")]
    assert {"read_word_data", "block_process_call", "write_quick", "enable_pec"} <= set(names)
    for name in names:
        theirs = list(inspect.signature(getattr(smbus2.SMBus, name)).parameters)
        ours = list(inspect.signature(getattr(EmulatedSMBus, name)).parameters)
        assert ours == theirs, name
    assert isinstance(vars(EmulatedSMBus)["pec"], property)


def test_byte_and_word_calls_put_smbus_messages_on_the_wire(bus):
    dev = bus.device(0x50)
    bus.write_byte(0x50, 0x30)  # Send Byte: a register chip takes it as its pointer
    assert bus.read_byte(0x50) == 0x30
    assert bus.read_byte(0x50) == 0x31  # Receive Byte continues from the pointer
    dev.regs[0x40:0x42] = bytes([0x34, 0x12])
    assert bus.read_word_data(0x50, 0x40) == 0x1234  # low byte first
    bus.write_word_data(0x50, 0x44, 0xBEEF)
    assert dev.regs[0x44:0x46] == bytes([0xEF, 0xBE])
    dev.regs[0x4A:0x4C] = bytes([0x78, 0x56])
    assert bus.process_call(0x50, 0x48, 0x0102) == 0x5678  # write 2 bytes at 0x48, read on
    assert dev.regs[0x48:0x4A] == bytes([0x02, 0x01])
    assert bus.log[-1].op == "process_call"
    bus.write_quick(0x50)
    with pytest.raises(OSError) as info:
        bus.write_quick(0x51)
    assert info.value.errno == errno.EREMOTEIO


def test_smbus_block_calls_carry_a_count(bus):
    dev = bus.device(0x50)
    dev.regs[0x60:0x64] = bytes([3, 9, 8, 7])
    assert bus.read_block_data(0x50, 0x60) == [9, 8, 7]
    bus.write_block_data(0x50, 0x70, [5, 6])
    assert dev.regs[0x70:0x73] == bytes([2, 5, 6])
    dev.regs[0x84:0x87] = bytes([2, 0xAA, 0xBB])
    assert bus.block_process_call(0x50, 0x80, [1, 2, 3]) == [0xAA, 0xBB]
    dev.regs[0x90] = 0
    with pytest.raises(OSError) as info:
        bus.read_block_data(0x50, 0x90)
    assert info.value.errno == errno.EPROTO
    dev.regs[0x90] = 33
    with pytest.raises(OSError) as info:
        bus.read_block_data(0x50, 0x90)
    assert info.value.errno == errno.EPROTO
    with pytest.raises(ValueError, match="32"):
        bus.write_block_data(0x50, 0, list(range(33)))
    with pytest.raises(ValueError, match="32"):
        bus.block_process_call(0x50, 0, list(range(33)))


def test_pec_is_the_smbus_crc8_and_is_sent_and_checked(bus):
    from gyrocal.drivers.emulated.smbus import smbus_pec

    assert smbus_pec(b"123456789") == 0xF4  # CRC-8/SMBUS check value
    dev = bus.device(0x50)
    bus.enable_pec()
    assert bus.pec == 1
    bus.write_byte_data(0x50, 0x20, 0x5A)  # the device takes the PEC byte as the next data
    assert dev.regs[0x21] == smbus_pec(bytes([0xA0, 0x20, 0x5A]))
    dev.regs[0x30] = 0x42
    dev.regs[0x31] = smbus_pec(bytes([0xA0, 0x30, 0xA1, 0x42]))
    assert bus.read_byte_data(0x50, 0x30) == 0x42
    dev.regs[0x31] ^= 1
    with pytest.raises(OSError) as info:
        bus.read_byte_data(0x50, 0x30)
    assert info.value.errno == errno.EBADMSG
    assert bus.read_i2c_block_data(0x50, 0x30, 2) == [0x42, dev.regs[0x31]]  # no PEC there
    bus.close()
    assert bus.pec == 0  # smbus2 clears it on close
    no_pec = EmulatedSMBus(VirtualClock(), pec_supported=False)
    with pytest.raises(OSError, match="PEC"):
        no_pec.enable_pec()


def test_a_byte_write_takes_the_bit_times_of_the_bus():
    # START + address(9) + register(9) + data(9) + STOP = 29 bit times: 72.5 µs at 400 kHz.
    b = EmulatedSMBus(VirtualClock(), bus_hz=400_000)
    b.attach(0x50, RegisterFile())
    b.write_byte_data(0x50, 0, 1)
    assert b.log[-1].duration_s == pytest.approx(29 / 400_000)
    assert b.clock.monotonic() == pytest.approx(72.5e-6)


def test_a_host_stall_inside_a_transfer_delays_it_and_does_not_break_it(bus):
    # A host stall (VirtualClock.stall_at, the --sim-fault pause) that starts after the first
    # message's address byte: the transfer goes on after it, its later bits already clocked,
    # and the device answers as before (a ValueError from a negative sleep before).
    clock = bus.clock
    t0 = clock.monotonic()
    clock.stall_at(t0 + 5e-6, 0.001)
    assert bus.read_byte_data(0x50, 0x10) == 0x10
    assert clock.monotonic() == pytest.approx(t0 + 10 / 400_000 + 0.001)
    assert bus.log[-1].errno is None
    t1 = clock.monotonic()
    bus.read_byte_data(0x50, 0x11)  # the next transfer takes its bit times again
    assert clock.monotonic() - t1 == pytest.approx(39 / 400_000)


def test_handles_share_the_adapter_and_close_only_themselves(bus):
    other = bus.handle()
    SMBus = bus.smbus_class()
    third = SMBus(1)
    with SMBus("/dev/i2c-1") as fourth:
        fourth.write_byte_data(0x50, 0x05, 0x99)
    assert fourth.fd is None
    assert other.read_byte_data(0x50, 0x05) == 0x99
    assert third.read_byte_data(0x50, 0x05) == 0x99
    with pytest.raises(OSError) as info:
        fourth.read_byte_data(0x50, 0x05)
    assert info.value.errno == errno.EBADF
    fourth.open(1)
    assert fourth.read_byte_data(0x50, 0x05) == 0x99
    bus.close()
    assert other.read_byte_data(0x50, 0x05) == 0x99
    assert bus.transactions == 5  # one adapter, one count
    unopened = SMBus()
    with pytest.raises(OSError):
        unopened.read_byte(0x50)
    with pytest.raises(FileNotFoundError, match="i2c-2"):
        SMBus(2)
    with pytest.raises(TypeError, match="type"):
        SMBus(1.0)


def test_bad_values_are_refused_before_any_io(bus):
    for call in (lambda: bus.write_byte_data(0x50, 0, 256), lambda: bus.write_byte(0x50, -1),
                 lambda: bus.write_word_data(0x50, 0, 0x10000)):
        with pytest.raises(ValueError, match="0\\.\\.255|0\\.\\.65535"):
            call()
    assert len(bus.log) == 0
    with pytest.raises(OSError) as info:
        bus.read_byte(0x80)
    assert info.value.errno == errno.EINVAL
