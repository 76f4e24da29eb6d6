"""Third-party IMU drivers, unmodified, against the emulated chips: a driver × chip table of
checks passed (issue 26).

Each driver is brought up as its own README or example does, on an emulated chip turning at a
known rate in a known magnetic field, and checked against that truth in the driver's own units
(ranges and conversions read from its source): identity and start-up, gyro, accelerometer,
temperature, magnetometer, data-ready flags, and the simulated time its start-up took (a driver
that polls a status bit that never sets spends seconds there). A driver whose own code is wrong
is listed with the file and line in the second table; its checks are made against what the
datasheet says, so a driver bug shows as a failed check there, not as an emulator fault.

The drivers are the seventeen on PyPI for these chips (issue 26): fifteen run in the first
table; enhanced-icm20948 is listed there too but cannot be pointed at an emulated bus, and the
Python 2 original of FaBo9Axis_MPU9250 cannot be imported on Python 3 (both in the second
table, with file and line). The drivers that
install from PyPI with light dependencies are in the ``test`` extra and have tests
(tests/drivers/test_third_party_clients.py); the others are run here when installed. Where one
is missing the table says so and how to install it (``--no-deps`` avoids Adafruit-Blinka, whose
modules tests/drivers/third_party.py stands in for, as it stands in MicroPython's
``machine.I2C``, ``utime`` and ``ustruct`` for the MicroPython drivers; FaBo9Axis wants the C
``smbus`` module and lsm9ds1-rjg ``spidev`` and ``RPi.GPIO``, stood in for here).

Data: gyrocal's own emulator (drivers/emulated), truth from its parameters; the drivers come
from PyPI. Usage: ``python -m bench clients``.
"""

from __future__ import annotations

import importlib.metadata
import importlib.util
import math
import sys
import types
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from bench.table import print_table
from gyrocal.drivers.clock import VirtualClock
from gyrocal.drivers.emulated.imu_chips import SensorTruth, make_emulated_imu
from gyrocal.drivers.emulated.magnetometers import MagneticField
from gyrocal.drivers.emulated.motion import ConstantRate
from gyrocal.drivers.emulated.smbus import EmulatedSMBus
from tests.drivers.third_party import (
    BusioI2C,
    MachineI2C,
    blinka_stand_ins,
    fake_time,
    micropython_stand_ins,
)

DEG = math.pi / 180
OMEGA_DPS = np.array([10.3, -20.6, 30.2])  # no reading lands half-way between two counts
BIAS_DPS = np.array([0.5, -0.25, 1.0])
FIELD_UT = np.array([20.0, 5.0, -44.0])
TEMP_C = 31.0
#: The reading the gyro's registers carry, °/s (the calibration model's m = ω − b).
READING_DPS = OMEGA_DPS - BIAS_DPS
#: The field in the AK8963's and AK09916's axes: (y, x, −z) of the accel/gyro die.
AK_DIE_UT = np.array([FIELD_UT[1], FIELD_UT[0], -FIELD_UT[2]])

#: Drivers whose own code is wrong, with where (file and line in the PyPI release named).
DRIVER_BUGS = (
    ("icm20948 1.0.0 (Pimoroni)", "icm20948/__init__.py:231-234 (and 208-211 for the "
     "accelerometer)", "set_gyro_low_pass shifts the DLPF code by 4 and masks 0b10001110; "
     "GYRO_DLPFCFG is bits 5:3 (DS-000189 GYRO_CONFIG_1), so mode 5 writes 0x50: "
     "DLPFCFG 2 plus reserved bit 6"),
    ("imusensor 1.0.1", "imusensor/MPU9250/MPU9250.py:82",
     "MagScale = (ASA − 128)/(256 + 1)·4912/32760: the datasheet's adjustment is "
     "((ASA − 128)/256 + 1) (AK8963 §8.3.11), so the scale is 0.19× too small for ASA = 176, "
     "negative for ASA < 128"),
    ("imusensor 1.0.1", "imusensor/MPU9250/MPU9250.py:76-80",
     "reads ASAX..ASAZ after switching from fuse-ROM mode to continuous mode 2 (without "
     "power-down between); the datasheet gives the ASA values in fuse-ROM access mode only, "
     "so the emulated die answers 0 and MagScale comes out negative"),
    ("imusensor 1.0.1", "imusensor/MPU9250/MPU9250.py:55",
     "`name[0] == 113 | name[0] == 115` compares against 113 | name[0] (precedence), so begin() "
     "prints \"The name is wrong\" for every chip, the MPU-9250's 0x71 included"),
    ("micropython-lsm6dsox 0.1.0", "micropython_lsm6dsox/lsm6dsox.py:143, 164",
     "_acceleration_data_rate = CBits(4, _CTRL1_XL, 2): ODR_XL is bits 7:4 (DS12814 CTRL1_XL), "
     "so RATE_104_HZ (0100) lands on bits 5:2, setting ODR_XL to 0001 (12.5 Hz)"),
    ("micropython-lsm6dsox 0.1.0", "micropython_lsm6dsox/lsm6dsox.py:250-257 (and 146)",
     "the gyro_range setter caches the scale factor but never writes _gyro_range "
     "(CTRL2_G.FS_G): any range but the reset ±250 °/s is read with the wrong scale"),
    ("micropython-lsm6dsox 0.1.0", "micropython_lsm6dsox/lsm6dsox.py:400 with "
     "i2c_helpers.py:121-127", "temperature indexes _raw_temp_data[0], but RegisterStruct "
     "returns a scalar for formats of 2 bytes or less ('<h'): TypeError on any chip"),
    ("adafruit-circuitpython-lsm9ds1 2.1.29", "adafruit_lsm9ds1.py:321, 331",
     "read_temp_raw shifts OUT_TEMP right by 4 and temperature adds 27.5 + raw/16, i.e. "
     "1/256 °C per LSB about 27.5 °C; DocID025715 gives 16 LSB/°C about 25 °C (the driver's "
     "own comment calls its starting point a guess)"),
    ("FaBo9Axis_MPU9250 1.0.0 (PyPI fabo9axis-mpu9250)", "FaBo9Axis_MPU9250/MPU9250.py:290-299",
     "Python 2 print statements: a SyntaxError at import on Python 3 (the fork "
     "fabo9axis-mpu9250-python3 above is the one that runs; both install the same module path)"),
    ("enhanced-icm20948 0.1.0", "enhanced_icm20948/asm_sensors/common.hpp:5",
     "a C++ extension over libmraa (#include <mraa/common.hpp>) that opens the I²C device "
     "itself: it does not build without libmraa and takes no Python bus, so it cannot be run "
     "against an emulated bus"),
    ("sparkfun-qwiic-lsm6dso 2.0.0", "qwiic_lsm6dso.py:266",
     "gyro_raw_to_dps starts at 0.004375 (±125 °/s) but CTRL2_G resets to ±250 °/s "
     "(8.75 mdps/LSB, DS12814 CTRL2_G): without set_gyro_range() its rates are half the true"),
)


@dataclass
class Run:
    """One driver on one chip: the checks, what went wrong, the start-up's simulated time."""

    driver: str
    chip: str
    checks: list[tuple[str, bool]] = field(default_factory=list)
    error: str = ""
    startup_s: float = float("nan")

    def check(self, name: str, ok: Any) -> None:
        self.checks.append((name, bool(ok)))


def _emulated(model: str, omega_dps: np.ndarray = OMEGA_DPS
              ) -> tuple[VirtualClock, EmulatedSMBus, int]:
    clock = VirtualClock()
    truth = SensorTruth(bias=BIAS_DPS * DEG, noise_density_rad_s_sqrt_hz=0.0,
                        temperature_c=TEMP_C)
    bus, addr = make_emulated_imu(model, clock, ConstantRate(omega_dps * DEG), truth, seed=4)
    aux = getattr(bus.device(addr), "aux", {}).get(0x0C)
    if aux is not None:
        aux.field = MagneticField(None, FIELD_UT)
    if model == "lsm9ds1":
        bus.device(0x1E).field = MagneticField(None, FIELD_UT)
    return clock, bus, addr


def _close(a: Any, b: Any, atol: float) -> bool:
    return bool(np.allclose(np.asarray(a, dtype=float), np.asarray(b, dtype=float), atol=atol))


def _counts(dps: np.ndarray, lsb_per_dps: float) -> np.ndarray:
    return np.rint(dps * lsb_per_dps) / lsb_per_dps


# -- MPU-9250 ------------------------------------------------------------------------------------


def mpu9250_jmdev(run: Run) -> None:
    mod = importlib.import_module("mpu9250_jmdev.mpu_9250")
    reg = importlib.import_module("mpu9250_jmdev.registers")
    clock, bus, addr = _emulated("mpu9250")
    mod.smbus.SMBus = bus.smbus_class()
    mod.time = fake_time(clock)
    mpu = mod.MPU9250(address_ak=reg.AK8963_ADDRESS, address_mpu_master=addr, bus=1,
                      gfs=reg.GFS_250, afs=reg.AFS_2G, mfs=reg.AK8963_BIT_16,
                      mode=reg.AK8963_MODE_C100HZ)
    mpu.configure()
    run.startup_s = clock.monotonic()
    run.check("identity", mpu.searchMPUDevice())
    # its scale: 250/32768 °/s per count at GFS_250 (mpu_9250.py configureMPU6500)
    run.check("gyro °/s", _close(mpu.readGyroscopeMaster(),
                                 np.rint(READING_DPS * 131) * 250 / 32768, 1e-9))
    run.check("accel g", _close(mpu.readAccelerometerMaster(), [0, 0, 1], 1e-3))
    run.check("temperature °C", abs(mpu.readTemperatureMaster() - TEMP_C) < 0.01)
    run.check("magnetometer µT", _close(mpu.readMagnetometerMaster(), AK_DIE_UT, 0.3))
    run.check("ASA adjustment", _close(mpu.magCalibration,
                                       bus.device(addr).aux[0x0C].adjustment(), 1e-9))


def imusensor(run: Run) -> None:
    sys.modules["smbus"] = types.SimpleNamespace(SMBus=EmulatedSMBus)  # type: ignore[assignment]
    mod = importlib.import_module("imusensor.MPU9250.MPU9250")
    clock, bus, addr = _emulated("mpu9250", np.zeros(3))  # its begin() calibrates at rest
    mod.time = fake_time(clock)
    imu = mod.MPU9250(bus.handle(), addr)
    imu.begin()
    run.startup_s = clock.monotonic()
    imu.readSensor()
    ak = bus.device(addr).aux[0x0C]
    run.check("gyro rad/s (its calibration removes the bias)", _close(
        imu.GyroVals, 0.0, 2 * 2000 / 32768 * DEG))
    run.check("accel m/s² (its y, x, −z)", _close(imu.AccelVals, [0, 0, -9.807], 0.02))
    # the datasheet's µT per count: 4912/32760 · ((ASA − 128)/256 + 1)
    run.check("magnetometer scale", _close(imu.MagScale, 4912 / 32760 * ak.adjustment(), 1e-6))
    run.check("magnetometer µT", _close(imu.MagVals, AK_DIE_UT, 0.3))


def fabo9axis(run: Run) -> None:
    clock, bus, addr = _emulated("mpu9250")
    sys.modules["smbus"] = types.SimpleNamespace(  # type: ignore[assignment]
        SMBus=lambda n: bus.handle())
    sys.modules.pop("FaBo9Axis_MPU9250.MPU9250", None)
    sys.modules.pop("FaBo9Axis_MPU9250", None)
    mod = importlib.import_module("FaBo9Axis_MPU9250.MPU9250")
    mod.time = fake_time(clock)
    mpu = mod.MPU9250(addr)
    run.startup_s = clock.monotonic()
    run.check("identity", mpu.searchDevice())
    clock.sleep(0.01)
    run.check("data ready (INT_STATUS)", mpu.checkDataReady())
    g = mpu.readGyro()
    # its scale: 250/32768 °/s per count, rounded to 3 decimals (MPU9250.py readGyro)
    run.check("gyro °/s", _close([g["x"], g["y"], g["z"]],
                                 np.round(np.rint(READING_DPS * 131) * 250 / 32768, 3), 1e-9))
    a = mpu.readAccel()
    run.check("accel g", _close([a["x"], a["y"], a["z"]], [0, 0, 1], 1e-3))
    run.check("temperature °C", abs(mpu.readTemperature() - TEMP_C) < 0.01)
    clock.sleep(0.2)
    m = mpu.readMagnet()
    run.check("magnetometer µT (ASA from fuse ROM)", _close([m["x"], m["y"], m["z"]], AK_DIE_UT,
                                                            0.3))


# -- ICM-20948 -----------------------------------------------------------------------------------


def pimoroni_icm20948(run: Run) -> None:
    mod = importlib.import_module("icm20948")
    clock, bus, addr = _emulated("icm20948")
    mod.time = fake_time(clock)
    imu = mod.ICM20948(i2c_addr=addr, i2c_bus=bus.handle())
    run.startup_s = clock.monotonic()
    run.check("finds the AK09916", True)
    run.check("magnetometer µT", _close(imu.read_magnetometer_data(), AK_DIE_UT, 0.08))
    ag = imu.read_accelerometer_gyro_data()
    run.check("accel g", _close(ag[:3], [0, 0, 1], 1e-3))
    run.check("gyro °/s", _close(ag[3:], _counts(READING_DPS, 131), 1e-6))
    raw = round((TEMP_C - 21) * 333.87)  # its formula: (raw − 21)/333.87 + 21
    run.check("temperature °C", abs(imu.read_temperature() - ((raw - 21) / 333.87 + 21)) < 1e-9)
    bus.write_byte_data(addr, 0x7F, 0x20)
    dlpfcfg = (bus.read_byte_data(addr, 0x01) >> 3) & 0x07
    bus.write_byte_data(addr, 0x7F, 0x00)
    run.check("gyro DLPF mode 5 as asked (its set_gyro_low_pass)", dlpfcfg == 5)


def _qwiic_driver(bus: EmulatedSMBus) -> Any:
    import smbus2

    smbus2.SMBus = bus.smbus_class()  # what qwiic_i2c's Linux driver opens
    return importlib.import_module("qwiic_i2c.linux_i2c").LinuxI2C(1)


def sparkfun_icm20948(run: Run) -> None:
    mod = importlib.import_module("qwiic_icm20948")
    clock, bus, addr = _emulated("icm20948")
    mod.time = fake_time(clock)
    dev = mod.QwiicIcm20948(address=addr, i2c_driver=_qwiic_driver(bus))
    run.check("begin()", dev.begin())
    run.startup_s = clock.monotonic()
    run.check("magnetometer WHO_AM_I", dev.magWhoIAm())
    clock.sleep(0.02)
    run.check("dataReady() (INT_STATUS_1)", dev.dataReady())
    dev.getAgmt()
    run.check("gyro counts", _close([dev.gxRaw, dev.gyRaw, dev.gzRaw],
                                    np.rint(READING_DPS * 131), 0.5))
    run.check("accel counts", [dev.axRaw, dev.ayRaw, dev.azRaw] == [0, 0, 16384])
    run.check("magnetometer counts", _close([dev.mxRaw, dev.myRaw, dev.mzRaw],
                                            np.rint(AK_DIE_UT / 0.15), 0.5))


def adafruit_icm20x(run: Run) -> None:
    with blinka_stand_ins():
        mod = importlib.import_module("adafruit_icm20x")
        clock, bus, addr = _emulated("icm20948")
        mod.sleep = clock.sleep
        icm = mod.ICM20948(BusioI2C(bus), addr)
        run.startup_s = clock.monotonic()
        run.check("magnetometer µT", _close(icm.magnetic, AK_DIE_UT, 0.08))
        run.check("accel m/s²", _close(icm.acceleration, [0, 0, 9.80665], 1e-6))
        run.check("gyro rad/s", _close(icm.gyro, _counts(READING_DPS, 65.5) * DEG, 1e-9))
        run.check("start-up under 2 s", run.startup_s < 2.0)


# -- LSM6DSOX ------------------------------------------------------------------------------------


def sparkfun_lsm6dso(run: Run) -> None:
    mod = importlib.import_module("qwiic_lsm6dso")
    clock, bus, addr = _emulated("lsm6dsox")
    dev = mod.QwiicLSM6DSO(address=addr, i2c_driver=_qwiic_driver(bus))
    run.check("begin()", dev.begin())
    run.startup_s = clock.monotonic()
    dev.set_gyro_data_rate(dev.ODR_104Hz)
    clock.sleep(0.02)
    run.check("STATUS_REG GDA", dev.get_status_reg() & 0x02)
    run.check("gyro °/s at the reset range (its default scale)",
              _close(dev.read_float_gyro_all(), _counts(READING_DPS, 1 / 0.00875), 1e-6))
    dev.set_gyro_range(dev.FS_G_500dps)
    dev.set_accel_range(dev.FS_XL_4g)
    dev.set_accel_data_rate(dev.ODR_104Hz)
    clock.sleep(0.02)
    run.check("STATUS_REG XLDA and GDA", dev.get_status_reg() & 0x03 == 0x03)
    run.check("gyro °/s", _close(dev.read_float_gyro_all(), _counts(READING_DPS, 1 / 0.0175),
                                 1e-6))
    run.check("accel g", _close(dev.read_float_accel_all(), [0, 0, round(1 / 0.122e-3) * 0.000122],
                                1e-6))
    run.check("temperature °C", abs(dev.read_temp_c() - TEMP_C) < 0.01)


def adafruit_lsm6ds(run: Run) -> None:
    with blinka_stand_ins():
        mod = importlib.import_module("adafruit_lsm6ds.lsm6dsox")
        base = importlib.import_module("adafruit_lsm6ds")
        clock, bus, addr = _emulated("lsm6dsox")
        base.sleep = clock.sleep
        dev = mod.LSM6DSOX(BusioI2C(bus), addr)
        run.startup_s = clock.monotonic()
        clock.sleep(0.05)
        # its __init__ sets 104 Hz, ±4 g and ±250 °/s (adafruit_lsm6ds/__init__.py)
        run.check("accel m/s²", _close(dev.acceleration, [0, 0, round(1 / 0.122e-3) * 0.122e-3
                                                          * 9.80665], 1e-3))
        run.check("gyro rad/s", _close(dev.gyro, _counts(READING_DPS, 1 / 0.00875) * DEG, 1e-6))


# -- LSM9DS1 (the clients extra) -----------------------------------------------------------------


def melopero_lsm9ds1(run: Run) -> None:
    mod = importlib.import_module("melopero_lsm9ds1.LSM9DS1")
    clock, bus, addr = _emulated("lsm9ds1")
    mod.smbus2.SMBus = bus.smbus_class()
    dev = mod.LSM9DS1()
    dev.use_i2c()
    dev.reset_settings()
    dev.set_gyro_odr(0b011)
    dev.set_acc_odr(0b011)
    dev.set_mag_odr(dev.MAG_ODR_80Hz)
    dev.set_mag_range(dev.MAGNETIC_4G_RANGE)
    run.startup_s = clock.monotonic()
    clock.sleep(0.1)
    run.check("gyro °/s", _close(dev.get_gyro(), READING_DPS, 0.00875 * 1.01))
    run.check("accel g", _close(dev.get_acc(), [0, 0, 1], 1e-3))
    run.check("magnetometer gauss", _close(np.array(dev.get_mag()) * 100,
                                           [-FIELD_UT[1], -FIELD_UT[0], FIELD_UT[2]], 0.02))


def _installed_module(package: str, filename: str, name: str) -> types.ModuleType:
    """Load ``filename`` of the installed distribution ``package`` as module ``name`` (for a
    single-file release whose module name another installed package also uses)."""
    path = importlib.metadata.distribution(package).locate_file(filename)
    spec = importlib.util.spec_from_file_location(name, path)
    if spec is None or spec.loader is None:
        raise ImportError(f"{package} has no {filename}")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def micropython_mpu9250(run: Run) -> None:
    clock, bus, addr = _emulated("mpu9250")
    with micropython_stand_ins(clock):
        mod = importlib.import_module("mpu9250")
        m6500 = importlib.import_module("mpu6500")
        # its MPU6500 defaults: ±2 g in m/s², ±250 °/s in rad/s (mpu6500.py __init__)
        imu = mod.MPU9250(MachineI2C(bus), mpu6500=m6500.MPU6500(MachineI2C(bus), address=addr,
                                                                 gyro_sf=m6500.SF_DEG_S))
        run.startup_s = clock.monotonic()
        run.check("identity", imu.whoami == 0x71)
        run.check("gyro °/s", _close(imu.gyro, _counts(READING_DPS, 131), 1e-9))
        run.check("accel m/s²", _close(imu.acceleration, [0, 0, 9.80665], 1e-9))
        raw = round((TEMP_C - 21) * 333.87)  # its formula: (raw − 21)/333.87 + 21 (mpu6500.py)
        run.check("temperature °C (its formula)",
                  abs(imu.temperature - ((raw - 21) / 333.87 + 21)) < 1e-9)
        clock.sleep(0.2)  # continuous mode 1: 8 Hz
        ak = bus.device(addr).aux[0x0C]
        run.check("ASA adjustment (fuse ROM)", _close(imu.ak8963.adjustement, ak.adjustment(),
                                                      1e-12))
        run.check("magnetometer µT", _close(imu.magnetic, AK_DIE_UT, 0.3))


def micropython_icm20948(run: Run) -> None:
    clock, bus, addr = _emulated("icm20948")
    with micropython_stand_ins(clock):
        mod = importlib.import_module("micropython_icm20948.icm20948")
        mod.sleep = clock.sleep
        imu = mod.ICM20948(MachineI2C(bus), address=addr)  # ±2 g, ±500 °/s (its __init__)
        run.startup_s = clock.monotonic()
        clock.sleep(0.02)
        run.check("gyro rad/s", _close(imu.gyro, _counts(READING_DPS, 65.5) * 0.017453293, 1e-9))
        run.check("accel m/s²", _close(imu.acceleration, [0, 0, 9.80665], 1e-9))
        # its formula: TEMP_OUT/333.87 + 21 (icm20948.py temperature), no room-temperature offset
        raw = round((TEMP_C - 21) * 333.87)
        run.check("temperature °C (its formula)", abs(imu.temperature - (raw / 333.87 + 21))
                  < 1e-9)


def micropython_lsm6dsox(run: Run) -> None:
    clock, bus, addr = _emulated("lsm6dsox")
    with micropython_stand_ins(clock):
        mod = importlib.import_module("micropython_lsm6dsox.lsm6dsox")
        mod.sleep = clock.sleep
        imu = mod.LSM6DSOX(MachineI2C(bus), address=addr)  # ±4 g, ±250 °/s (its __init__)
        run.startup_s = clock.monotonic()
        clock.sleep(0.05)
        run.check("gyro rad/s", _close(imu.gyro, _counts(READING_DPS, 1 / 0.00875) * DEG, 1e-9))
        run.check("accel m/s²", _close(imu.acceleration, [0, 0, round(1 / 0.122e-3) * 0.122
                                                          * 0.00980665], 1e-9))
        ctrl1 = bus.read_byte_data(addr, 0x10)
        run.check("accelerometer at 104 Hz as asked (CTRL1_XL.ODR_XL)", ctrl1 >> 4 == 0b0100)
        imu.gyro_range = mod.RANGE_500_DPS
        run.check("gyro rad/s at ±500 °/s as asked (CTRL2_G.FS_G)",
                  _close(imu.gyro, _counts(READING_DPS, 1 / 0.0175) * DEG, 1e-9))
        run.check("temperature °C", abs(imu.temperature - TEMP_C) < 0.01)


def adafruit_lsm6dsox_2(run: Run) -> None:
    with blinka_stand_ins():
        clock, bus, addr = _emulated("lsm6dsox")
        mod = _installed_module("adafruit-circuitpython-lsm6dsox", "adafruit_lsm6ds.py",
                                "adafruit_lsm6ds_2_0_0")
        mod.sleep = clock.sleep
        dev = mod.LSM6DSOX(BusioI2C(bus), addr)  # 104 Hz, ±4 g, ±250 °/s (its __init__)
        run.startup_s = clock.monotonic()
        clock.sleep(0.05)
        run.check("accel m/s²", _close(dev.acceleration, [0, 0, round(1 / 0.122e-3) * 0.122e-3
                                                          * 9.80665], 1e-3))
        run.check("gyro °/s", _close(dev.gyro, _counts(READING_DPS, 1 / 0.00875), 1e-6))


def adafruit_lsm9ds1(run: Run) -> None:
    with blinka_stand_ins():
        mod = importlib.import_module("adafruit_lsm9ds1")
        clock, bus, addr = _emulated("lsm9ds1")
        mod.time = fake_time(clock)
        dev = mod.LSM9DS1_I2C(BusioI2C(bus), xg_address=addr)  # ±2 g, ±4 gauss, ±245 °/s
        run.startup_s = clock.monotonic()
        clock.sleep(0.1)
        run.check("gyro rad/s", _close(list(dev.gyro), _counts(READING_DPS, 1 / 0.00875) * DEG,
                                       1e-9))
        run.check("accel m/s²", _close(list(dev.acceleration),
                                       [0, 0, round(1 / 0.061e-3) * 0.061e-3 * 9.80665], 1e-6))
        run.check("magnetometer gauss", _close(np.array(list(dev.magnetic)) * 100,
                                               [-FIELD_UT[1], -FIELD_UT[0], FIELD_UT[2]], 0.02))
        # DocID025715 Table 5: 16 LSB/°C, 0 LSB at 25 °C (the hardware reference, §2.5)
        run.check("temperature °C", abs(dev.temperature - TEMP_C) < 0.1)


def lsm9ds1_rjg(run: Run) -> None:
    # its I²C transport imports RPi.GPIO for a data-ready pin and the package its SPI
    # transport's spidev: C modules built on a Raspberry Pi, unused on I²C
    gpio = types.ModuleType("RPi.GPIO")
    rpi = types.ModuleType("RPi")
    rpi.GPIO = gpio  # type: ignore[attr-defined]
    spidev = types.ModuleType("spidev")
    spidev.SpiDev = object  # type: ignore[attr-defined]
    sys.modules.update({"RPi": rpi, "RPi.GPIO": gpio, "spidev": spidev})
    lsm = importlib.import_module("lsm9ds1_rjg")
    transport = importlib.import_module("lsm9ds1_rjg.i2c_transport")
    driver_mod = importlib.import_module("lsm9ds1_rjg.driver")
    clock, bus, addr = _emulated("lsm9ds1")
    transport.SMBus = bus.smbus_class()
    driver_mod.time = fake_time(clock)
    drv = lsm.Driver(lsm.I2CTransport(1, addr), lsm.I2CTransport(1, 0x1E))
    drv.configure()  # ±500 °/s at 238 Hz; ±2 g; magnetometer ±4 gauss continuous
    run.startup_s = clock.monotonic()
    clock.sleep(0.1)
    run.check("status GDA", drv.read_ag_status().gyroscope_data_available)
    # it flips x to make the chip's left-handed frame right-handed (driver.py read_gyroscope)
    expect = np.rint(READING_DPS / 0.0175)
    run.check("gyro counts", _close(drv.read_gyroscope(), [-expect[0], expect[1], expect[2]],
                                    0.5))
    run.check("accel counts", _close(drv.read_acceleration(), [0, 0, round(1 / 0.061e-3)], 0.5))
    run.check("temperature counts", drv.read_temperature() == round((TEMP_C - 25.0) * 16))
    run.check("magnetometer counts", _close(
        drv.read_magnetometer(), np.array([-FIELD_UT[1], -FIELD_UT[0], FIELD_UT[2]]) * 10 / 0.14,
        1))


def enhanced_icm20948(run: Run) -> None:
    """enhanced-icm20948 0.1.0: a C++ extension over Intel's libmraa (enhanced_icm20948/
    asm_sensors/common.hpp includes mraa/common.hpp) that opens the I²C device itself; there is
    no Python bus to give it, so it cannot be run against an emulated bus."""
    importlib.import_module("enhanced_icm20948")


#: (driver, PyPI package, chip, function, how to install it where it is missing).
DRIVERS: tuple[tuple[str, str, str, Callable[[Run], None], str], ...] = (
    ("mpu9250-jmdev", "mpu9250-jmdev", "mpu9250", mpu9250_jmdev, "test extra"),
    ("imusensor", "imusensor", "mpu9250", imusensor, "test extra"),
    ("FaBo9Axis_MPU9250", "FaBo9Axis-MPU9250-Python3", "mpu9250", fabo9axis,
     "pip install --no-deps fabo9axis-mpu9250-python3"),
    ("icm20948 (Pimoroni)", "icm20948", "icm20948", pimoroni_icm20948, "test extra"),
    ("qwiic_icm20948 (SparkFun)", "sparkfun_qwiic_icm20948", "icm20948", sparkfun_icm20948,
     "test extra"),
    ("adafruit_icm20x", "adafruit-circuitpython-icm20x", "icm20948", adafruit_icm20x,
     "pip install --no-deps adafruit-circuitpython-icm20x adafruit-circuitpython-busdevice "
     "adafruit-circuitpython-register"),
    ("qwiic_lsm6dso (SparkFun)", "sparkfun_qwiic_lsm6dso", "lsm6dsox", sparkfun_lsm6dso,
     "test extra"),
    ("adafruit_lsm6ds", "adafruit-circuitpython-lsm6ds", "lsm6dsox", adafruit_lsm6ds,
     "pip install --no-deps adafruit-circuitpython-lsm6ds adafruit-circuitpython-busdevice "
     "adafruit-circuitpython-register"),
    ("melopero_lsm9ds1", "melopero-lsm9ds1", "lsm9ds1", melopero_lsm9ds1, "clients extra"),
    ("lsm9ds1-rjg", "lsm9ds1-rjg", "lsm9ds1", lsm9ds1_rjg, "clients extra"),
    ("micropython-mpu9250", "micropython-mpu9250", "mpu9250", micropython_mpu9250,
     "pip install --no-deps micropython-mpu9250"),
    ("micropython-icm20948", "micropython-icm20948", "icm20948", micropython_icm20948,
     "pip install --no-deps micropython-icm20948"),
    ("micropython-lsm6dsox", "micropython-lsm6dsox", "lsm6dsox", micropython_lsm6dsox,
     "pip install --no-deps micropython-lsm6dsox"),
    ("adafruit_lsm6ds 2.0.0 (lsm6dsox)", "adafruit-circuitpython-lsm6dsox", "lsm6dsox",
     adafruit_lsm6dsox_2, "pip install --no-deps adafruit-circuitpython-lsm6dsox "
     "adafruit-circuitpython-busdevice adafruit-circuitpython-register"),
    ("adafruit_lsm9ds1", "adafruit-circuitpython-lsm9ds1", "lsm9ds1", adafruit_lsm9ds1,
     "pip install --no-deps adafruit-circuitpython-lsm9ds1 adafruit-circuitpython-busdevice"),
    ("enhanced-icm20948", "enhanced-icm20948", "icm20948", enhanced_icm20948,
     "needs libmraa's C++ headers to build"),
)


def _version(package: str) -> str | None:
    try:
        return importlib.metadata.version(package)
    except importlib.metadata.PackageNotFoundError:
        return None


def main(argv: list[str]) -> None:
    import smbus2

    rows = []
    saved, smbus_class = dict(sys.modules), smbus2.SMBus
    for name, package, chip, fn, install in DRIVERS:
        version = _version(package)
        if version is None:
            rows.append([name, "-", chip, "not installed", "", install])
            continue
        run = Run(name, chip)
        try:
            fn(run)
        except Exception as exc:  # a driver that raises fails the checks it did not reach
            run.error = f"{type(exc).__name__}: {exc}"[:70]
        finally:  # the stand-ins go: the next driver, or benchmark, sees the real modules
            smbus2.SMBus = smbus_class
            for key in set(sys.modules) - set(saved):
                if key.startswith(("smbus", "busio", "micropython", "circuitpython_typing")):
                    del sys.modules[key]
            sys.modules.update({k: v for k, v in saved.items() if k == "smbus"})
        passed = sum(ok for _, ok in run.checks)
        failed = [n for n, ok in run.checks if not ok]
        why = "; ".join(filter(None, [run.error, ", ".join(failed)]))
        rows.append([name, version, chip, f"{passed}/{len(run.checks)}"
                     + (" + raised" if run.error else ""),
                     f"{run.startup_s:.3f}" if math.isfinite(run.startup_s) else "-", why])
    print_table(["driver", "version", "chip", "checks passed", "start-up s (simulated)",
                 "failed / why"], rows,
                title="Third-party drivers, unmodified, against the emulated chips")
    print_table(["driver", "where", "what"], [list(b) for b in DRIVER_BUGS],
                title="Driver bugs (their checks above are made against the datasheet)")
