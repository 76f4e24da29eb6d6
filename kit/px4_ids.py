"""PX4's parameter files (QGroundControl ``.params``), and the device ID of the sensor a
calibration belongs to (``CAL_ACC<n>_ID``, ``CAL_GYRO<n>_ID``, ``TC_G<n>_ID``) from the chip, bus
and address a gyrocal run records.

PX4 (PX4-Autopilot ``src/lib/drivers/device/Device.hpp``, ``union DeviceId``) packs a device's
identity in 24 bits, least significant first: ``bus_type`` (3 bits; ``DeviceBusType_I2C = 1``),
``bus`` (5 bits, the bus instance), ``address`` (8 bits, the I²C address) and ``devtype`` (8
bits, one per driver: ``src/drivers/drv_sensor.h``)::

    id = bus_type | bus << 3 | address << 8 | devtype << 16

(PX4's own boards check it so: the Pixhawk 6C's internal MS5611 on I²C bus 4 at 0x77 is
``device_id: 4028193`` in ``boards/px4/fmu-v6c/src/i2c.cpp``.) The bus is the one gyrocal read the
chip on (Linux ``/dev/i2c-N``): PX4 on that Linux board numbers it the same; a flight controller
numbers its own buses, so a sensor moved there has the ID its vehicle reports.
"""

from __future__ import annotations

import argparse
from collections.abc import Iterable, Mapping
from typing import Any

__all__ = ["MAV_INT32", "MAV_REAL32", "PX4_DEVTYPE", "PX4_I2C", "device_id_arg",
           "px4_device_id", "qgc_params"]

#: ``DeviceBusType_I2C`` (Device.hpp).
PX4_I2C = 1

#: Largest device ID: the 24 bits of ``union DeviceId`` (bus_type, bus, address, devtype).
MAX_DEVICE_ID = (1 << 24) - 1

#: MAV_PARAM_TYPE of an integer and of a float parameter (MAVLink common.xml)
MAV_INT32, MAV_REAL32 = 6, 9


def qgc_params(what: str, rows: Iterable[tuple[str, float, int]]) -> str:
    """A QGroundControl ``.params`` file (what PX4's parameter load reads): a header naming
    ``what`` was written, then one tab-separated row per ``(name, value, MAV_PARAM_TYPE)``,
    integers as integers and floats to 9 significant digits."""
    lines = ["# Onboard parameters for Vehicle 1", f"# {what}", "#",
             "# Vehicle-Id Component-Id Name Value Type"]
    for name, value, kind in rows:
        text = str(int(value)) if kind == MAV_INT32 else f"{value + 0.0:.9g}"
        lines.append(f"1\t1\t{name}\t{text}\t{kind}")
    return "\n".join(lines) + "\n"


#: PX4 devtype per gyrocal sensor model (PX4-Autopilot ``src/drivers/drv_sensor.h``): the
#: accelerometer and the gyro of these combined drivers share the ID. PX4 has no driver, hence
#: no devtype, for the MPU-9255. Its LSM6DSO driver (src/drivers/imu/st/lsm6dso, which takes the
#: LSM6DSOX's WHO_AM_I 0x6C) names DRV_IMU_DEVTYPE_ST_LSM6DSO, whose value the drv_sensor.h read
#: here (PX4-Autopilot 023ba6e) does not yet define: no row until it can be checked.
PX4_DEVTYPE: Mapping[str, int] = {
    "mpu9250": 0x24,  # DRV_IMU_DEVTYPE_MPU9250
    "mpu6500": 0x36,  # DRV_IMU_DEVTYPE_MPU6500
    "icm20948": 0x28,  # DRV_IMU_DEVTYPE_ICM20948
    "icm42688p": 0x26,  # DRV_IMU_DEVTYPE_ICM42688P
    "lsm9ds1": 0x44,  # DRV_IMU_DEVTYPE_ST_LSM9DS1_AG
}


def px4_device_id(sensor: Mapping[str, Any] | None) -> tuple[int | None, str]:
    """PX4's device ID of the calibration's ``sensor`` (its model, ``i2c_bus`` and
    ``i2c_address``) and a sentence saying how it was made, or ``(None, why not)``.

    Returns
    -------
    (int, str) or (None, str)
    """
    s = sensor or {}
    model = str(s.get("model") or "")
    bus, addr = s.get("i2c_bus"), s.get("i2c_address")
    if model not in PX4_DEVTYPE:
        return None, (f"PX4 has no device type for the sensor model {model or 'not recorded'!r} "
                      f"(PX4 devtypes: {', '.join(PX4_DEVTYPE)})")
    if not all(isinstance(v, int) and not isinstance(v, bool) for v in (bus, addr)):
        return None, ("the calibration does not say which I2C bus and address the chip was "
                      "read on (sensor.i2c_bus, sensor.i2c_address; a recording from another "
                      "tool, or from gyrocal before they were recorded)")
    assert isinstance(bus, int) and isinstance(addr, int)
    if not (0 <= bus < 32 and 0 <= addr < 128):
        return None, (f"I2C bus {bus} / address {addr} do not fit PX4's device ID (bus 0-31, "
                      "7-bit address)")
    dev_id = PX4_I2C | bus << 3 | addr << 8 | PX4_DEVTYPE[model] << 16
    return dev_id, (f"device ID {dev_id} = I2C bus {bus}, address {addr:#04x}, devtype "
                    f"{PX4_DEVTYPE[model]:#04x} ({model}); the bus as gyrocal read it "
                    "(/dev/i2c-N): on a flight controller with its own bus numbering, check it "
                    "against the vehicle's")


def device_id_arg(text: str) -> int:
    """``--device-id``: a PX4 device ID as the vehicle shows it (``CAL_GYRO<n>_ID``), decimal
    or hex (``0x246809``), within the 24 bits of ``union DeviceId`` and not 0 (no device)."""
    try:
        value = int(text.strip(), 0)
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"{text!r} is not a device ID; give the number the vehicle shows as CAL_GYROn_ID "
            "(e.g. 2385929)") from None
    if not 1 <= value <= MAX_DEVICE_ID:
        raise argparse.ArgumentTypeError(
            f"{text} is not a PX4 device ID (1..{MAX_DEVICE_ID}, the 24 bits of bus type, bus, "
            "address and devtype); give the number the vehicle shows as CAL_GYROn_ID")
    return value
