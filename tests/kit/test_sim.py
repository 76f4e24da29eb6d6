import pytest

from gyrocal.drivers.errors import DriverError
from gyrocal.drivers.imu import open_imu
from gyrocal.kit.config import apply_overrides, default_config
from gyrocal.kit.sim import build_sim


def _sim(**overrides):
    return build_sim(apply_overrides(default_config(), overrides), seed=1)


def test_the_emulated_chip_sits_at_the_configured_address_when_its_model_allows_it():
    sim = _sim(**{"imu.address": 0x69})  # the MPU-9250's AD0-high address
    assert sim.imu_address == 0x69
    assert sim.imu_bus.device(0x69) is sim.chip
    reader = open_imu("mpu9250", sim.imu_bus, 0x69, clock=sim.clock, range_dps=500, odr_hz=200)
    reader.close()
    lsm = _sim(**{"imu.model": "lsm9ds1", "imu.address": 0x6A})
    assert lsm.imu_address == 0x6A


def test_an_address_the_model_cannot_have_fails_as_on_hardware():
    sim = _sim(**{"imu.address": 0x6A})  # an LSM9DS1 address in an MPU-9250 config
    assert sim.imu_address == 0x68
    with pytest.raises(DriverError, match="0x68"):
        open_imu("mpu9250", sim.imu_bus, 0x6A, clock=sim.clock, range_dps=500, odr_hz=200)
