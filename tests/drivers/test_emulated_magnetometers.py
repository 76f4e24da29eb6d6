"""Magnetometer dies: the AK8963 behind the MPU-9250 (bypass and I²C master) and the LSM9DS1's
magnetometer, checked against the datasheets' register maps and a field that turns with the
sensor."""

import errno

import numpy as np
import pytest

from gyrocal.drivers.clock import VirtualClock
from gyrocal.drivers.emulated.imu_chips import make_emulated_imu
from gyrocal.drivers.emulated.magnetometers import MagneticField
from gyrocal.drivers.emulated.motion import ConstantRate

FIELD = np.array([20.0, 5.0, -44.0])


class Turning:
    """A sensor turning about base z at ``w`` rad/s: orientation and rate from first principles."""

    def __init__(self, w):
        self.w = w

    def orientation(self, t):
        c, s = np.cos(self.w * t), np.sin(self.w * t)
        r = np.zeros((t.size, 3, 3))
        r[:, 0, 0], r[:, 0, 1], r[:, 1, 0], r[:, 1, 1], r[:, 2, 2] = c, -s, s, c, 1
        return r

    def rate(self, t):
        return np.tile([0.0, 0.0, self.w], (np.size(t), 1))


def s16(lo, hi):
    return int.from_bytes(bytes([lo, hi]), "little", signed=True)


def mpu_with_ak(motion=None):
    clock = VirtualClock()
    bus, addr = make_emulated_imu("mpu9250", clock, motion)
    bus.device(addr).aux[0x0C].field = MagneticField(motion, FIELD)
    return clock, bus, addr


def test_ak8963_appears_only_through_bypass_with_the_master_off():
    clock, bus, addr = mpu_with_ak()
    with pytest.raises(OSError) as info:
        bus.read_byte_data(0x0C, 0x00)
    assert info.value.errno == errno.EREMOTEIO  # bypass off after reset
    bus.write_byte_data(addr, 0x37, 0x02)  # INT_PIN_CFG.BYPASS_EN
    assert bus.read_byte_data(0x0C, 0x00) == 0x48  # WIA
    bus.write_byte_data(addr, 0x6A, 0x20)  # USER_CTRL.I2C_MST_EN disconnects the bypass
    with pytest.raises(OSError):
        bus.read_byte_data(0x0C, 0x00)
    bus6500, _ = make_emulated_imu("mpu6500", VirtualClock())
    assert 0x0C not in bus6500.addresses  # an MPU-6500 has no magnetometer die


def test_ak8963_fuse_rom_modes_and_data_in_its_own_axes():
    clock, bus, addr = mpu_with_ak()
    ak = bus.device(addr).aux[0x0C]
    bus.write_byte_data(addr, 0x37, 0x02)
    assert bus.read_i2c_block_data(0x0C, 0x10, 3) == [0, 0, 0]  # ASA hidden outside fuse mode
    bus.write_byte_data(0x0C, 0x0A, 0x0F)
    asa = bus.read_i2c_block_data(0x0C, 0x10, 3)
    assert asa == list(ak.asa)
    bus.write_byte_data(0x0C, 0x0A, 0x00)
    bus.write_byte_data(0x0C, 0x0A, 0x16)  # 16-bit, continuous mode 2 (100 Hz)
    assert bus.read_byte_data(0x0C, 0x02) & 0x01 == 0
    clock.sleep(0.011)
    d = bus.read_i2c_block_data(0x0C, 0x02, 8)  # ST1, HXL..HZH, ST2
    assert d[0] & 0x01
    adj = (np.array(asa) - 128) / 256 + 1
    h = np.array([s16(d[1], d[2]), s16(d[3], d[4]), s16(d[5], d[6])]) * 0.15 * adj
    # x_mag = y, y_mag = x, z_mag = -z (MPU-9250 PS §9.1)
    np.testing.assert_allclose(h, [FIELD[1], FIELD[0], -FIELD[2]], atol=0.15 * 1.4)
    assert d[7] & 0x10  # BITM mirrors the 16-bit setting
    assert bus.read_byte_data(0x0C, 0x02) & 0x01 == 0  # ST2 read cleared DRDY
    clock.sleep(0.035)  # three measurements, none read: data overrun
    assert bus.read_byte_data(0x0C, 0x02) == 0x03


@pytest.mark.parametrize("cntl1", [0x00, 0x01, 0x02, 0x06, 0x08, 0x12, 0x16])
def test_ak8963_asa_reads_zero_in_every_mode_but_fuse_rom(cntl1):
    # AK8963 §8.3.11: ASAX..ASAZ hold the sensitivity adjustment in fuse-ROM access mode
    # (MODE 1111, either output width); in power-down, single, continuous 1/2 and self-test
    # modes (14- and 16-bit) the die does not expose them, so a driver that reads them after
    # leaving fuse-ROM mode (imusensor MPU9250.py 76-80) gets 0, not the fuse values
    clock, bus, addr = mpu_with_ak()
    ak = bus.device(addr).aux[0x0C]
    assert ak.asa != (0, 0, 0)  # so that reading 0 below is hiding, not the fuse values
    bus.write_byte_data(addr, 0x37, 0x02)  # BYPASS_EN
    for fuse in (0x0F, 0x1F):
        bus.write_byte_data(0x0C, 0x0A, 0x00)
        bus.write_byte_data(0x0C, 0x0A, fuse)
        assert bus.read_i2c_block_data(0x0C, 0x10, 3) == list(ak.asa)
    bus.write_byte_data(0x0C, 0x0A, cntl1)  # straight from fuse-ROM mode, as imusensor does
    assert bus.read_i2c_block_data(0x0C, 0x10, 3) == [0, 0, 0]


def test_ak8963_through_the_i2c_master_slave_registers_sees_the_field_turn():
    motion = Turning(0.5)
    clock, bus, addr = mpu_with_ak(motion)
    w = bus.write_byte_data
    w(addr, 0x6B, 0x01)
    w(addr, 0x1A, 0x01)  # 1 kHz internal rate, SMPLRT_DIV 0
    w(addr, 0x6A, 0x20)  # I2C_MST_EN
    # slave 4: a single write of CNTL1 = 0x16 to the AK8963
    w(addr, 0x31, 0x0C)
    w(addr, 0x32, 0x0A)
    w(addr, 0x33, 0x16)
    w(addr, 0x34, 0x80)
    clock.sleep(0.002)
    assert bus.read_byte_data(addr, 0x36) & 0x40  # SLV4_DONE
    assert bus.read_byte_data(addr, 0x34) & 0x80 == 0
    # slave 0 reads ST1..ST2 (8 bytes) at the sample rate into EXT_SENS_DATA
    w(addr, 0x25, 0x8C)
    w(addr, 0x26, 0x02)
    w(addr, 0x27, 0x88)
    for t_read in (0.5, 2.0, 3.5):
        clock.sleep(t_read - clock.monotonic())
        d = bus.read_i2c_block_data(addr, 0x49, 8)
        adj = bus.device(addr).aux[0x0C].adjustment()
        h = np.array([s16(d[1], d[2]), s16(d[3], d[4]), s16(d[5], d[6])]) * 0.15 * adj
        t_meas = np.floor(t_read / 0.01) * 0.01  # the latest 100 Hz measurement
        th = 0.5 * (t_meas - 0.002)  # measurements started at the CNTL1 write, 2 ms in
        b = motion.orientation(np.array([th / 0.5]))[0].T @ FIELD
        np.testing.assert_allclose(h, [b[1], b[0], -b[2]], atol=0.5)
    w(addr, 0x25, 0x8D)  # nobody at 0x0D: the master flags slave 0's NACK
    clock.sleep(0.002)
    assert bus.read_byte_data(addr, 0x36) & 0x01


def test_lsm9ds1_magnetometer_registers_and_field():
    clock = VirtualClock()
    motion = Turning(1.0)
    bus, addr = make_emulated_imu("lsm9ds1", clock, motion)
    assert addr == 0x6B and 0x1E in bus.addresses
    mag = bus.device(0x1E)
    mag.field = MagneticField(motion, FIELD)
    assert bus.read_byte_data(0x1E, 0x0F) == 0x3D
    assert bus.read_byte_data(0x1E, 0x20) == 0x10 and bus.read_byte_data(0x1E, 0x22) == 0x03
    bus.write_byte_data(0x1E, 0x21, 0x20)  # ±8 gauss: 0.29 mgauss/LSB
    bus.write_byte_data(0x1E, 0x20, 0x1C)  # 80 Hz
    bus.write_byte_data(0x1E, 0x22, 0x00)  # continuous
    clock.sleep(1.0)
    assert bus.read_byte_data(0x1E, 0x27) & 0x08  # ZYXDA
    d = bus.read_i2c_block_data(0x1E, 0x28, 6)
    m_ut = np.array([s16(d[0], d[1]), s16(d[2], d[3]), s16(d[4], d[5])]) * 0.29 / 10
    b = motion.orientation(np.array([1.0]))[0].T @ FIELD  # 80 samples in, at t = 1.0 s
    np.testing.assert_allclose(m_ut, [-b[1], -b[0], b[2]], atol=0.03)
    assert bus.read_byte_data(0x1E, 0x27) & 0x08 == 0
    bus.write_byte_data(0x1E, 0x21, 0x04)  # SOFT_RST
    assert bus.read_byte_data(0x1E, 0x21) == 0 and bus.read_byte_data(0x1E, 0x22) == 0x03


def test_a_field_without_orientation_stays_put():
    f = MagneticField(ConstantRate((0, 0, 1.0)), FIELD)
    np.testing.assert_allclose(f.at(3.0), FIELD)
    with pytest.raises(ValueError, match="field_ut"):
        MagneticField(None, (1.0, 2.0))


def test_ak8963_a_data_register_read_clears_drdy_and_dor():
    # AK8963 datasheet §8.3.3: DRDY and DOR return to 0 "when any one of ST2 register or
    # measurement data register (HXL~HZH) is read"
    clock, bus, addr = mpu_with_ak()
    bus.write_byte_data(addr, 0x37, 0x02)
    bus.write_byte_data(0x0C, 0x0A, 0x16)
    clock.sleep(0.035)
    assert bus.read_byte_data(0x0C, 0x02) == 0x03  # DRDY and DOR
    bus.read_byte_data(0x0C, 0x05)  # HYL alone
    assert bus.read_byte_data(0x0C, 0x02) == 0x00


# -- ICM-20948 + AK09916 (DS-000189 register map: bank 0 USER_CTRL 0x03, LP_CONFIG 0x05,
# INT_PIN_CFG 0x0F, I2C_MST_STATUS 0x17, EXT_SLV_SENS_DATA_00 0x3B; bank 3 SLV0_ADDR/REG/CTRL/DO
# 0x03-0x06, SLV4_ADDR/REG/CTRL/DO/DI 0x13-0x17; AK09916: WIA1 0x00 = 0x48, WIA2 0x01 = 0x09,
# ST1 0x10, HXL 0x11, ST2 0x18, CNTL2 0x31, CNTL3 0x32, 0.15 µT/LSB)

BANK_SEL = 0x7F


def icm_with_ak(motion=None):
    clock = VirtualClock()
    bus, addr = make_emulated_imu("icm20948", clock, motion)
    bus.device(addr).aux[0x0C].field = MagneticField(motion, FIELD)
    bus.write_byte_data(addr, 0x06, 0x01)  # PWR_MGMT_1: awake, clock auto
    return clock, bus, addr


def slv4(bus, addr, clock, ak_register, value=None, ak_address=0x0C):
    """One slave-4 transfer as SparkFun's ICM_20948_i2c_master_slv4_txn does it: ADDR, REG,
    (DO), CTRL = EN, then poll I2C_MST_STATUS for SLV4_DONE; the status and, for a read, SLV4_DI."""
    w = bus.write_byte_data
    w(addr, BANK_SEL, 0x30)
    w(addr, 0x13, ak_address | (0x80 if value is None else 0))
    w(addr, 0x14, ak_register)
    if value is not None:
        w(addr, 0x16, value)
    w(addr, 0x15, 0x80)
    w(addr, BANK_SEL, 0x00)
    for _ in range(100):
        status = bus.read_byte_data(addr, 0x17)
        if status & 0x40:
            break
        clock.sleep(0.0005)
    w(addr, BANK_SEL, 0x30)
    di = bus.read_byte_data(addr, 0x17)
    w(addr, BANK_SEL, 0x00)
    return status, di


def test_icm20948_master_reads_the_ak09916_identity_and_flags_a_nack():
    clock, bus, addr = icm_with_ak()
    bus.write_byte_data(addr, 0x03, 0x20)  # USER_CTRL.I2C_MST_EN
    status, wia1 = slv4(bus, addr, clock, 0x00)
    assert status & 0x40 and not status & 0x10 and wia1 == 0x48
    assert slv4(bus, addr, clock, 0x01)[1] == 0x09
    assert bus.read_byte_data(addr, 0x17) == 0  # I2C_MST_STATUS cleared when read
    status, _ = slv4(bus, addr, clock, 0x00, ak_address=0x0D)  # nobody there
    assert status & 0x50 == 0x50  # SLV4_DONE and SLV4_NACK


def test_icm20948_master_off_no_transfer_and_bypass_puts_the_die_on_the_host_bus():
    clock, bus, addr = icm_with_ak()
    status, _ = slv4(bus, addr, clock, 0x01)  # master off: nothing happens
    assert status == 0
    with pytest.raises(OSError):
        bus.read_byte_data(0x0C, 0x01)
    bus.write_byte_data(addr, 0x0F, 0x02)  # INT_PIN_CFG.BYPASS_EN
    assert bus.read_byte_data(0x0C, 0x01) == 0x09


@pytest.mark.parametrize("duty_cycled", [True, False])
def test_icm20948_slave0_streams_the_ak09916_field_as_the_sensor_turns(duty_cycled):
    motion = Turning(0.5)
    clock, bus, addr = icm_with_ak(motion)
    w = bus.write_byte_data
    if not duty_cycled:  # the master at the gyro's rate (1125 Hz with GYRO_SMPLRT_DIV 0)
        w(addr, 0x05, 0x00)
    w(addr, 0x03, 0x20)
    slv4(bus, addr, clock, 0x31, 0x08)  # CNTL2: continuous mode 4, 100 Hz
    t0 = clock.monotonic()
    w(addr, BANK_SEL, 0x30)
    w(addr, 0x03, 0x8C)  # SLV0: read from 0x0C
    w(addr, 0x04, 0x10)  # from ST1
    w(addr, 0x05, 0x89)  # EN, 9 bytes: ST1, HXL..HZH, TMPS, ST2
    w(addr, BANK_SEL, 0x00)
    for t_read in (0.5, 2.0, 3.5):
        clock.sleep(t_read - clock.monotonic())
        d = bus.read_i2c_block_data(addr, 0x3B, 9)
        h = np.array([s16(d[1], d[2]), s16(d[3], d[4]), s16(d[5], d[6])]) * 0.15
        # the latest 100 Hz measurement, read by a master cycle at most ~2 ms before
        t_meas = t0 + np.floor((t_read - t0) / 0.01) * 0.01
        b = motion.orientation(np.array([t_meas]))[0].T @ FIELD
        # die axes (y, x, -z) of the accel/gyro die, as the AK8963 in the MPU-9250 (⚠ PX4)
        np.testing.assert_allclose(h, [b[1], b[0], -b[2]], atol=0.3)


def test_ak09916_status_modes_reset_and_burst_wrap():
    clock, bus, addr = icm_with_ak()
    bus.write_byte_data(addr, 0x0F, 0x02)  # bypass
    rd = bus.read_byte_data
    assert bus.read_i2c_block_data(0x0C, 0x00, 2) == [0x48, 0x09]
    bus.write_byte_data(0x0C, 0x31, 0x01)  # single measurement
    assert rd(0x0C, 0x10) == 0
    clock.sleep(0.01)
    assert rd(0x0C, 0x10) == 0x01 and rd(0x0C, 0x31) == 0  # done: back to power-down
    rd(0x0C, 0x11)  # any data register read clears DRDY (HXL to TMPS, or ST2)
    assert rd(0x0C, 0x10) == 0
    bus.write_byte_data(0x0C, 0x31, 0x08)  # 100 Hz
    clock.sleep(0.035)
    assert rd(0x0C, 0x10) == 0x03  # measurements skipped: DOR
    d = bus.read_i2c_block_data(0x0C, 0x15, 6)  # HZL, HZH, TMPS, ST2, then WIA1, WIA2
    assert d[4:] == [0x48, 0x09]  # the 0x18 -> 0x00 wrap of the burst
    assert s16(d[0], d[1]) == round(-FIELD[2] / 0.15)
    bus.write_byte_data(0x0C, 0x32, 0x01)  # CNTL3.SRST
    assert rd(0x0C, 0x31) == 0 and rd(0x0C, 0x32) == 0
