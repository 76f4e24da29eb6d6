"""Third-party drivers from PyPI, unmodified, against the emulated chips.

Each client expects ``smbus2.SMBus(bus)`` (``smbus.SMBus`` for imusensor) and the wall clock; the
tests hand it the emulated bus and the virtual clock by patching those imports in the client's
module, never its code. Truth comes from the emulator's parameters and the datasheets.
"""

import sys
import types

import numpy as np
import pytest

from gyrocal.drivers.clock import VirtualClock
from gyrocal.drivers.emulated.imu_chips import SensorTruth, make_emulated_imu
from gyrocal.drivers.emulated.magnetometers import MagneticField
from gyrocal.drivers.emulated.motion import ConstantRate
from gyrocal.drivers.emulated.smbus import EmulatedSMBus
from tests.drivers.third_party import (
    MachineI2C,
    blinka_stand_ins,
    fake_time,
    micropython_stand_ins,
)

DEG = np.pi / 180
FIELD = np.array([20.0, 5.0, -44.0])
OMEGA = np.array([10.0, -20.0, 30.0]) * DEG
BIAS = np.array([0.5, -0.25, 1.0]) * DEG


def emulated(model, *, noise=0.0, omega=OMEGA):
    clock = VirtualClock()
    truth = SensorTruth(bias=BIAS, noise_density_rad_s_sqrt_hz=noise, temperature_c=31.0)
    bus, addr = make_emulated_imu(model, clock, ConstantRate(omega), truth, seed=4)
    return clock, truth, bus, addr


def expected_reading_dps(truth, omega=OMEGA):
    return truth.reading(omega[None, :], np.array([31.0]))[0] / DEG


# -- mpu9250-jmdev --------------------------------------------------------------------------------


@pytest.fixture
def jmdev(monkeypatch):
    mod = pytest.importorskip("mpu9250_jmdev.mpu_9250")
    clock, truth, bus, addr = emulated("mpu9250")
    bus.device(addr).aux[0x0C].field = MagneticField(None, FIELD)
    monkeypatch.setattr(mod.smbus, "SMBus", bus.smbus_class())
    monkeypatch.setattr(mod, "time", fake_time(clock))
    reg = pytest.importorskip("mpu9250_jmdev.registers")
    mpu = mod.MPU9250(address_ak=reg.AK8963_ADDRESS, address_mpu_master=reg.MPU9050_ADDRESS_68,
                      bus=1, gfs=reg.GFS_250, afs=reg.AFS_2G, mfs=reg.AK8963_BIT_16,
                      mode=reg.AK8963_MODE_C100HZ)
    return mpu, truth, bus, addr


def test_mpu9250_jmdev_configures_and_reads_every_sensor(jmdev):
    mpu, truth, bus, addr = jmdev
    mpu.configure()
    assert mpu.searchMPUDevice()
    counts = np.rint(expected_reading_dps(truth) * 131)  # 131 LSB/(°/s) at ±250 °/s
    np.testing.assert_allclose(mpu.readGyroscopeMaster(), counts * mpu.gres, atol=1e-9)
    np.testing.assert_allclose(mpu.readAccelerometerMaster(), [0, 0, 1], atol=1e-3)
    assert mpu.readTemperatureMaster() == pytest.approx(31.0, abs=0.01)
    mag = mpu.readMagnetometerMaster()  # µT in the AK8963's axes: (y, x, -z) of the sensor
    np.testing.assert_allclose(mag, [FIELD[1], FIELD[0], -FIELD[2]], atol=0.3)
    ak = bus.device(addr).aux[0x0C]
    np.testing.assert_allclose(mpu.magCalibration, ak.adjustment())


class TumbleThenRest:
    """Turning at ``w`` about the fixed unit axis ``u`` until ``t_stop``, then at rest:
    ``R(t) = exp(w·min(t, t_stop)·[u]×)`` (Rodrigues), rate ``w·u`` in the sensor frame."""

    def __init__(self, u, w, t_stop):
        self.u, self.w, self.t_stop = np.asarray(u) / np.linalg.norm(u), w, t_stop

    def orientation(self, t):
        th = self.w * np.minimum(np.asarray(t, dtype=float), self.t_stop)
        k = np.array([[0, -self.u[2], self.u[1]], [self.u[2], 0, -self.u[0]],
                      [-self.u[1], self.u[0], 0]])
        return (np.eye(3) + np.sin(th)[:, None, None] * k
                + (1 - np.cos(th))[:, None, None] * (k @ k))

    def rate(self, t):
        t = np.asarray(t, dtype=float)
        return np.where((t < self.t_stop)[:, None], self.w * self.u, 0.0)


def test_mpu9250_jmdev_calibrate_sweeps_the_field_and_averages_the_fifo(monkeypatch, capsys):
    mod = pytest.importorskip("mpu9250_jmdev.mpu_9250")
    reg = pytest.importorskip("mpu9250_jmdev.registers")
    clock = VirtualClock()
    motion = TumbleThenRest((1.0, 2.0, 3.0), 0.6, t_stop=17.0)
    truth = SensorTruth(bias=BIAS, noise_density_rad_s_sqrt_hz=0.0)
    bus, addr = make_emulated_imu("mpu9250", clock, motion, truth, seed=4)
    bus.device(addr).aux[0x0C].field = MagneticField(motion, FIELD)
    monkeypatch.setattr(mod.smbus, "SMBus", bus.smbus_class())
    monkeypatch.setattr(mod, "time", fake_time(clock))
    mpu = mod.MPU9250(bus=1, gfs=reg.GFS_250, afs=reg.AFS_2G, mfs=reg.AK8963_BIT_16,
                      mode=reg.AK8963_MODE_C100HZ)
    mpu.configure()
    mpu.calibrate()  # a 15 s min/max sweep of the AK8963 while it turns, then a FIFO average
    assert clock.monotonic() > motion.t_stop  # the FIFO part ran at rest
    assert not bus.device(addr)._int_status & 0x10  # 40 ms at 1 kHz fits the 512-byte FIFO
    # at rest the client's gyro "bias" is the chip's reading of zero rate, -bias
    np.testing.assert_allclose(np.array(mpu.gbias) * DEG, -np.array(truth.bias),
                               atol=1.5 * DEG / 131)
    np.testing.assert_allclose(mpu.abias, [0, 0, 0], atol=1e-3)
    # its hard-iron estimate is the mid-range of the field it swept, in the AK8963's axes
    t = np.arange(0.0, motion.t_stop, 1e-3)
    b = np.einsum("nji,j->ni", motion.orientation(t), FIELD)
    die = np.stack([b[:, 1], b[:, 0], -b[:, 2]], axis=1)
    np.testing.assert_allclose(mpu.mbias, (die.max(0) + die.min(0)) / 2, atol=0.5)


# -- imusensor ------------------------------------------------------------------------------------


def test_imusensor_reads_gyro_accel_and_the_magnetometer_through_the_i2c_master(monkeypatch,
                                                                                capsys):
    monkeypatch.setitem(sys.modules, "smbus", types.SimpleNamespace(SMBus=EmulatedSMBus))
    mod = pytest.importorskip("imusensor.MPU9250.MPU9250")
    clock, truth, bus, addr = emulated("mpu9250", omega=np.zeros(3))
    bus.device(addr).aux[0x0C].field = MagneticField(None, FIELD)
    monkeypatch.setattr(mod, "time", fake_time(clock))
    imu = mod.MPU9250(bus.handle(), addr)
    imu.begin()  # includes its gyro calibration at rest
    assert "did not write" not in capsys.readouterr().out
    imu.readSensor()
    np.testing.assert_allclose(imu.GyroVals, 0.0, atol=2 * 2000 / 32768 * DEG)
    # imusensor turns accel (x, y, z) into (y, x, -z) and reports m/s²
    np.testing.assert_allclose(imu.AccelVals, [0, 0, -9.807], atol=0.02)
    ak = bus.device(addr).aux[0x0C]
    # begin() reads ASAX..Z after leaving fuse-ROM mode, where the die hides them (⚠ AK8963
    # datasheet §8.3.11): its MagScale (own formula, (ASA − 128)/257 · 4912/32760) sees ASA = 0
    np.testing.assert_allclose(imu.MagScale, (0 - 128) / 257 * (4912 / 32760))
    counts = np.rint(np.array([FIELD[1], FIELD[0], -FIELD[2]]) / (0.15 * ak.adjustment()))
    np.testing.assert_allclose(imu.MagVals, counts * imu.MagScale, rtol=1e-12)


# -- LSM9DS1 clients ------------------------------------------------------------------------------


def test_melopero_lsm9ds1_reads_gyro_accel_and_magnetometer(monkeypatch, capsys):
    mod = pytest.importorskip("melopero_lsm9ds1.LSM9DS1")
    clock, truth, bus, addr = emulated("lsm9ds1")
    bus.device(0x1E).field = MagneticField(None, FIELD)
    monkeypatch.setattr(mod.smbus2, "SMBus", bus.smbus_class())
    dev = mod.LSM9DS1()
    dev.use_i2c()
    dev.reset_settings()
    dev.set_gyro_odr(dev.ODR_119Hz if hasattr(dev, "ODR_119Hz") else 0b011)
    dev.set_acc_odr(0b011)
    dev.set_mag_odr(dev.MAG_ODR_80Hz)
    dev.set_mag_range(dev.MAGNETIC_4G_RANGE)
    clock.sleep(0.1)
    np.testing.assert_allclose(dev.get_gyro(), expected_reading_dps(truth), atol=0.00875 * 1.01)
    np.testing.assert_allclose(dev.get_acc(), [0, 0, 1], atol=1e-3)
    gauss = np.array(dev.get_mag())
    np.testing.assert_allclose(gauss * 100, [-FIELD[1], -FIELD[0], FIELD[2]], atol=0.02)
    dev.close()


def test_lsm9ds1_rjg_opens_a_bus_per_call_and_reads_everything(monkeypatch):
    # its I²C transport imports RPi.GPIO for an optional data-ready pin: stand it in
    gpio = types.ModuleType("RPi.GPIO")
    rpi = types.ModuleType("RPi")
    rpi.GPIO = gpio
    monkeypatch.setitem(sys.modules, "RPi", rpi)
    monkeypatch.setitem(sys.modules, "RPi.GPIO", gpio)
    # its package imports the SPI transport's spidev too (a C module built on a Pi), unused here
    try:
        import spidev  # noqa: F401
    except ImportError:
        monkeypatch.setitem(sys.modules, "spidev", types.ModuleType("spidev"))
    lsm = pytest.importorskip("lsm9ds1_rjg")
    transport = pytest.importorskip("lsm9ds1_rjg.i2c_transport")
    driver_mod = pytest.importorskip("lsm9ds1_rjg.driver")
    clock, truth, bus, addr = emulated("lsm9ds1")
    bus.device(0x1E).field = MagneticField(None, FIELD)
    monkeypatch.setattr(transport, "SMBus", bus.smbus_class())
    monkeypatch.setattr(driver_mod, "time", fake_time(clock))
    drv = lsm.Driver(lsm.I2CTransport(1, 0x6B), lsm.I2CTransport(1, 0x1E))
    drv.configure()  # 500 °/s at 238 Hz; magnetometer ±4 gauss continuous
    clock.sleep(0.1)
    assert drv.read_ag_status().gyroscope_data_available
    # the driver flips x to turn the chip's left-handed frame into a right-handed one
    expect = np.rint(expected_reading_dps(truth) / 0.0175)  # 17.5 m°/s per LSB at ±500 °/s
    np.testing.assert_array_equal(drv.read_gyroscope(), [-expect[0], expect[1], expect[2]])
    np.testing.assert_array_equal(drv.read_acceleration(), [0, 0, round(1 / 0.061e-3)])
    assert drv.read_temperature() == round((31.0 - 25.0) * 16)  # 16 LSB/°C, 0 at 25 °C
    assert drv.read_magnetometer_status().data_available
    mag = np.array(drv.read_magnetometer())
    field_die = np.array([-FIELD[1], -FIELD[0], FIELD[2]]) * 10 / 0.14
    np.testing.assert_allclose(mag, field_die, atol=1)  # read_magnetometer does not flip
    assert bus.transactions > 10  # every call opened and closed its own SMBus handle


# -- ICM-20948 clients ----------------------------------------------------------------------------
# The AK09916 sits behind the ICM-20948's I²C master; its axes are (y, x, -z) of the accel/gyro
# die (as the AK8963's in the MPU-9250) and it reads 0.15 µT/LSB, no sensitivity adjustment.

MAG_DIE_UT = np.array([FIELD[1], FIELD[0], -FIELD[2]])
MAG_DIE_COUNTS = np.rint(MAG_DIE_UT / 0.15)


def icm20948_with_field():
    clock, truth, bus, addr = emulated("icm20948")
    bus.device(addr).aux[0x0C].field = MagneticField(None, FIELD)
    return clock, truth, bus, addr


def test_pimoroni_icm20948_finds_the_ak09916_and_reads_every_sensor(monkeypatch):
    mod = pytest.importorskip("icm20948")
    clock, truth, bus, addr = icm20948_with_field()
    monkeypatch.setattr(mod, "time", fake_time(clock))
    imu = mod.ICM20948(i2c_addr=addr, i2c_bus=bus.handle())  # raised "Unable to find AK09916"
    # read_magnetometer_data: a single measurement through slave 0, counts * 0.15 µT
    np.testing.assert_allclose(imu.read_magnetometer_data(), MAG_DIE_COUNTS * 0.15, atol=1e-9)
    ax, ay, az, gx, gy, gz = imu.read_accelerometer_gyro_data()  # its ±16 g, ±250 °/s
    np.testing.assert_allclose([ax, ay, az], [0, 0, 1], atol=1 / 2048)
    np.testing.assert_allclose([gx, gy, gz], np.rint(expected_reading_dps(truth) * 131) / 131,
                               atol=1e-9)
    # its own conversion (icm20948/__init__.py read_temperature): (raw - 21) / 333.87 + 21
    raw = round((31.0 - 21.0) * 333.87)
    assert imu.read_temperature() == pytest.approx((raw - 21) / 333.87 + 21, abs=1e-9)


def test_sparkfun_qwiic_icm20948_starts_the_magnetometer_and_sees_data_ready(monkeypatch):
    mod = pytest.importorskip("qwiic_icm20948")
    linux_i2c = pytest.importorskip("qwiic_i2c.linux_i2c")
    import smbus2

    clock, truth, bus, addr = icm20948_with_field()
    monkeypatch.setattr(smbus2, "SMBus", bus.smbus_class())
    monkeypatch.setattr(mod, "time", fake_time(clock))
    dev = mod.QwiicIcm20948(address=addr, i2c_driver=linux_i2c.LinuxI2C(1))
    assert dev.begin()
    assert clock.monotonic() < 0.5  # SLV4_DONE answered: no polling to its 1000-read limit
    assert dev.magWhoIAm()
    clock.sleep(0.02)
    assert dev.dataReady()  # INT_STATUS_1.RAW_DATA_0_RDY_INT (read 0 before issue 26)
    dev.getAgmt()  # ±2 g, ±250 °/s after begin(); slave 0 reads ST1..ST2 of the AK09916
    np.testing.assert_array_equal([dev.gxRaw, dev.gyRaw, dev.gzRaw],
                                  np.rint(expected_reading_dps(truth) * 131))
    assert [dev.axRaw, dev.ayRaw, dev.azRaw] == [0, 0, 16384]
    np.testing.assert_array_equal([dev.mxRaw, dev.myRaw, dev.mzRaw], MAG_DIE_COUNTS)
    assert not dev.magStat2 & 0x08  # ST2.HOFL


def test_adafruit_icm20x_reads_the_magnetometer_through_slave_4_and_slave_0():
    with blinka_stand_ins():
        mod = pytest.importorskip("adafruit_icm20x")
        from tests.drivers.third_party import BusioI2C

        clock, truth, bus, addr = icm20948_with_field()
        mod.sleep = clock.sleep  # its ``from time import sleep``
        icm = mod.ICM20948(BusioI2C(bus), addr)
        assert clock.monotonic() < 2.0  # no 100 × 10 ms polls of SLV4_DONE per access
        np.testing.assert_allclose(icm.magnetic, MAG_DIE_COUNTS * 0.15, atol=1e-9)
        # its init sets ±8 g and ±500 °/s (adafruit_icm20x.py ICM20X.initialize)
        np.testing.assert_allclose(icm.acceleration, [0, 0, 9.80665], atol=1e-9)
        np.testing.assert_allclose(icm.gyro, np.rint(expected_reading_dps(truth) * 65.5)
                                   / 65.5 * DEG, atol=1e-12)


# -- LSM6DSOX clients -----------------------------------------------------------------------------


def test_sparkfun_qwiic_lsm6dso_sees_status_reg_data_ready_and_reads_in_its_units(monkeypatch):
    mod = pytest.importorskip("qwiic_lsm6dso")
    linux_i2c = pytest.importorskip("qwiic_i2c.linux_i2c")
    import smbus2

    clock, truth, bus, addr = emulated("lsm6dsox")
    monkeypatch.setattr(smbus2, "SMBus", bus.smbus_class())
    dev = mod.QwiicLSM6DSO(address=addr, i2c_driver=linux_i2c.LinuxI2C(1))
    assert dev.begin()
    assert dev.set_gyro_range(dev.FS_G_500dps) and dev.set_accel_range(dev.FS_XL_4g)
    dev.set_gyro_data_rate(dev.ODR_104Hz)
    dev.set_accel_data_rate(dev.ODR_104Hz)
    clock.sleep(0.02)
    assert dev.get_status_reg() & 0x03 == 0x03  # XLDA and GDA: its examples wait for them
    np.testing.assert_allclose(dev.read_float_gyro_all(),
                               np.rint(expected_reading_dps(truth) / 0.0175) * 0.0175, atol=1e-9)
    np.testing.assert_allclose(dev.read_float_accel_all(), [0, 0, round(1 / 0.122e-3) * 0.000122],
                               atol=1e-9)
    assert dev.get_status_reg() & 0x03 == 0  # both outputs read


# -- MicroPython drivers (machine.I2C, utime and ustruct stood in for) ---------------------------


def test_micropython_mpu9250_reads_every_sensor_and_the_ak8963_through_the_bypass():
    clock, truth, bus, addr = emulated("mpu9250")
    ak = bus.device(addr).aux[0x0C]
    ak.field = MagneticField(None, FIELD)
    with micropython_stand_ins(clock):
        mod = pytest.importorskip("mpu9250")
        m6500 = pytest.importorskip("mpu6500")
        # mpu6500.py __init__ writes PWR_MGMT_1 = 0x80 through ustruct "<b" (MicroPython wraps
        # it to -128) and keeps the reset ranges, ±2 g and ±250 °/s (131 LSB per °/s)
        imu = mod.MPU9250(MachineI2C(bus), mpu6500=m6500.MPU6500(
            MachineI2C(bus), address=addr, gyro_sf=m6500.SF_DEG_S))
        np.testing.assert_allclose(imu.gyro, np.rint(expected_reading_dps(truth) * 131) / 131,
                                   atol=1e-9)
        np.testing.assert_allclose(imu.acceleration, [0, 0, 9.80665], atol=1e-9)
        # ak8963.py __init__ reads ASAX..Z in fuse-ROM mode, then powers down before mode 1
        np.testing.assert_allclose(imu.ak8963.adjustement, ak.adjustment(), atol=1e-12)
        clock.sleep(0.2)  # continuous mode 1 measures at 8 Hz
        np.testing.assert_allclose(imu.magnetic, MAG_DIE_UT, atol=0.15 * 1.4)


def test_micropython_icm20948_resets_banks_and_reads_in_its_units():
    clock, truth, bus, addr = emulated("icm20948")
    with micropython_stand_ins(clock):
        mod = pytest.importorskip("micropython_icm20948.icm20948")
        mod.sleep = clock.sleep  # its ``from time import sleep``
        imu = mod.ICM20948(MachineI2C(bus), address=addr)  # ±2 g, ±500 °/s (its __init__)
        clock.sleep(0.02)
        np.testing.assert_allclose(
            imu.gyro, np.rint(expected_reading_dps(truth) * 65.5) / 65.5 * 0.017453293,
            atol=1e-12)
        np.testing.assert_allclose(imu.acceleration, [0, 0, 9.80665], atol=1e-12)


def test_micropython_lsm6dsox_reads_gyro_and_accel_at_its_ranges():
    clock, truth, bus, addr = emulated("lsm6dsox")
    with micropython_stand_ins(clock):
        mod = pytest.importorskip("micropython_lsm6dsox.lsm6dsox")
        mod.sleep = clock.sleep
        imu = mod.LSM6DSOX(MachineI2C(bus), address=addr)  # SW_RESET, ±4 g, ±250 °/s
        clock.sleep(0.1)  # its CTRL1_XL write leaves the accelerometer at 12.5 Hz (a driver bug)
        np.testing.assert_allclose(
            imu.gyro, np.rint(expected_reading_dps(truth) / 8.75e-3) * 8.75e-3 * DEG, atol=1e-12)
        # 0.122 mg per LSB at ±4 g, times its 0.00980665 (m/s²)/mg
        np.testing.assert_allclose(imu.acceleration, [0, 0, round(1 / 0.122e-3) * 0.122
                                                      * 0.00980665], atol=1e-12)
