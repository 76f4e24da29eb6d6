"""Finding the supported IMUs on a bus by their WHO_AM_I, read-only (drivers.imu.detect)."""

from gyrocal.drivers.clock import VirtualClock
from gyrocal.drivers.emulated.imu_chips import ChipFaults, make_emulated_imu
from gyrocal.drivers.emulated.smbus import EmulatedSMBus
from gyrocal.drivers.imu.detect import scan_bus


def test_every_supported_chip_on_one_bus_is_named_at_its_address():
    clock = VirtualClock()
    bus = EmulatedSMBus(clock)
    # MPU-9250 at 0x69 (AD0 high), ICM-42688-P at 0x68, LSM9DS1 at 0x6B (datasheet addresses)
    make_emulated_imu("mpu9250", clock, bus=bus, address=0x69)
    make_emulated_imu("icm42688p", clock, bus=bus, address=0x68)
    make_emulated_imu("lsm9ds1", clock, bus=bus, address=0x6B)
    bus.log.clear()
    found = scan_bus(bus)
    assert [(c.address, c.model, c.who_am_i) for c in found] == [
        (0x68, "icm42688p", 0x47), (0x69, "mpu9250", 0x71), (0x6B, "lsm9ds1", 0x68)]
    assert all(e.op == "read_byte_data" for e in bus.log)  # a scan only reads


def test_a_sibling_is_named_and_not_given_a_model():
    clock = VirtualClock()
    bus, _ = make_emulated_imu("icm42688p", clock, faults=ChipFaults(who_am_i=0x42))
    (chip,) = scan_bus(bus)
    assert chip.model is None and "ICM-42605" in chip.title and chip.who_am_i == 0x42


def test_an_empty_bus_finds_nothing():
    assert scan_bus(EmulatedSMBus(VirtualClock())) == []


def test_the_banked_and_tagged_chips_are_named_too():
    clock = VirtualClock()
    bus = EmulatedSMBus(clock)
    make_emulated_imu("icm20948", clock, bus=bus, address=0x69)  # WHO_AM_I at 0x00, bank 0
    make_emulated_imu("lsm6dsox", clock, bus=bus, address=0x6A)
    make_emulated_imu("icm42688p", clock, bus=bus, address=0x68)
    assert [(c.address, c.model) for c in scan_bus(bus)] == [
        (0x68, "icm42688p"), (0x69, "icm20948"), (0x6A, "lsm6dsox")]
