"""IMU readers (MPU-9250 family, LSM9DS1, ICM-20948, ICM-42688-P, LSM6DSOX) over any bus like
smbus2's.

The kit names the sensor model as a string; :func:`open_imu` turns it into a configured reader::

    reader = open_imu("mpu9250", bus, clock=clock, range_dps=500, odr_hz=1000)
    reader.start()
    batch = reader.read()     # ImuBatch: t, rate (rad/s), temperature_c, saturated, gaps
"""

from __future__ import annotations

import contextlib
import importlib
from typing import TYPE_CHECKING, Any

from gyrocal.drivers.clock import Clock
from gyrocal.drivers.errors import ConfigurationError, DriverError
from gyrocal.drivers.imu.errors import (
    BusOpenError,
    ChipIdentityError,
    ImuStateError,
    SensorFaultError,
)

if TYPE_CHECKING:
    from gyrocal.drivers.imu.base import (
        ChipNotice,
        FifoGap,
        ImuBatch,
        ImuReader,
        SensorInfo,
        open_bus,
    )
    from gyrocal.drivers.imu.icm20948 import ICM20948Reader
    from gyrocal.drivers.imu.icm42688p import ICM42688PReader
    from gyrocal.drivers.imu.lsm6dsox import LSM6DSOXReader
    from gyrocal.drivers.imu.lsm9ds1 import LSM9DS1Reader
    from gyrocal.drivers.imu.mpu9250 import MPU9250Reader

__all__ = [
    "MODELS",
    "READERS",
    "READER_CLASSES",
    "BusOpenError",
    "ChipIdentityError",
    "ChipNotice",
    "FifoGap",
    "ICM20948Reader",
    "ICM42688PReader",
    "ImuBatch",
    "ImuReader",
    "ImuStateError",
    "LSM6DSOXReader",
    "LSM9DS1Reader",
    "MPU9250Reader",
    "SensorFaultError",
    "SensorInfo",
    "open_bus",
    "open_imu",
]

#: The module and class of the reader for each model name a config may give. The readers
#: (and numpy) are imported when first used, so that a list of names (the config's check, the
#: command line's help) costs no import.
READER_CLASSES: dict[str, tuple[str, str]] = {
    "mpu9250": ("gyrocal.drivers.imu.mpu9250", "MPU9250Reader"),
    "mpu9255": ("gyrocal.drivers.imu.mpu9250", "MPU9250Reader"),
    "mpu6500": ("gyrocal.drivers.imu.mpu9250", "MPU9250Reader"),
    "lsm9ds1": ("gyrocal.drivers.imu.lsm9ds1", "LSM9DS1Reader"),
    "icm42688p": ("gyrocal.drivers.imu.icm42688p", "ICM42688PReader"),
    "lsm6dsox": ("gyrocal.drivers.imu.lsm6dsox", "LSM6DSOXReader"),
    "icm20948": ("gyrocal.drivers.imu.icm20948", "ICM20948Reader"),
}
#: The model names :func:`open_imu` accepts.
MODELS: tuple[str, ...] = tuple(READER_CLASSES)

_LAZY = {
    **{name: "gyrocal.drivers.imu.base"
       for name in ("ChipNotice", "FifoGap", "ImuBatch", "ImuReader", "SensorInfo", "open_bus")},
    "LSM9DS1Reader": "gyrocal.drivers.imu.lsm9ds1",
    "ICM42688PReader": "gyrocal.drivers.imu.icm42688p",
    "ICM20948Reader": "gyrocal.drivers.imu.icm20948",
    "LSM6DSOXReader": "gyrocal.drivers.imu.lsm6dsox",
    "MPU9250Reader": "gyrocal.drivers.imu.mpu9250",
}


def _reader_class(key: str) -> type[ImuReader]:
    module, cls = READER_CLASSES[key]
    return getattr(importlib.import_module(module), cls)


def __getattr__(name: str) -> Any:
    """The readers and batch types, imported on first use (PEP 562).

    ``READERS`` maps each of :data:`MODELS` to its reader class.
    """
    if name == "READERS":
        return {key: _reader_class(key) for key in READER_CLASSES}
    if name in _LAZY:
        return getattr(importlib.import_module(_LAZY[name]), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def open_imu(
    model: str,
    bus: Any,
    address: int | None = None,
    *,
    clock: Clock | None = None,
    range_dps: float,
    odr_hz: float,
    lowpass_hz: float | None = None,
    **options: Any,
) -> ImuReader:
    """Open and configure the reader for ``model`` (not yet streaming: call ``start()``).

    Parameters
    ----------
    model : str
        One of :data:`MODELS`. The MPU names share one reader, which accepts any of the three
        chips and reports the one it found as ``reader.model``.
    bus : smbus2.SMBus-like, int or str
        A bus object, or an adapter number / device path to open.
    address : int, optional
        7-bit address; the chip's default when omitted.
    clock : Clock, optional
        The clock of the caller's loop.
    range_dps, odr_hz, lowpass_hz : float
        Passed to :meth:`ImuReader.configure`.
    **options
        Reader options (``retries``, ``stuck_after_s``, ``burst_wrap``...).

    Returns
    -------
    ImuReader
        The configured reader.

    Raises
    ------
    ConfigurationError
        For an unknown model or settings the chip cannot do.
    """
    key = str(model).strip().lower().replace("-", "")
    if key not in READER_CLASSES:
        raise ConfigurationError(
            f"unknown IMU model {model!r}; choose one of {', '.join(MODELS)}"
        )
    reader = _reader_class(key)(bus, address, clock=clock, **options)
    try:
        reader.configure(range_dps=range_dps, odr_hz=odr_hz, lowpass_hz=lowpass_hz)
    except BaseException:
        with contextlib.suppress(DriverError):  # the configure error is the one to report
            reader.close()
        raise
    return reader
