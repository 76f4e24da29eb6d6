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
    "chip_addresses",
    "find_address",
    "nearest_offered_rate",
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


def _model_key(model: str) -> str:
    key = str(model).strip().lower().replace("-", "")
    if key not in READER_CLASSES:
        raise ConfigurationError(
            f"unknown IMU model {model!r}; choose one of {', '.join(MODELS)}"
        )
    return key


def chip_addresses(model: str) -> tuple[int, ...]:
    """The 7-bit I²C addresses a chip of ``model`` can have, its default (strap low) first
    (:attr:`gyrocal.drivers.imu.chips.ChipFamily.addresses`).

    Raises
    ------
    ConfigurationError
        For an unknown model.
    """
    return tuple(_reader_class(_model_key(model)).family.addresses)


def nearest_offered_rate(model: str, odr_hz: float) -> float:
    """The output data rate of ``model``'s reader nearest ``odr_hz`` (ties to the faster), one
    the chip does exactly (:meth:`ImuReader.offered_rates_hz`: 200 Hz asked of an ICM-20948
    gives 1125/6 = 187.5 Hz, of an LSM9DS1 238 Hz, of an LSM6DSOX 6667/32 = 208.3 Hz).

    Raises
    ------
    ConfigurationError
        For an unknown model or a rate that is not a positive finite number.
    """
    odr = float(odr_hz)
    if not (odr > 0 and odr < float("inf")):
        raise ConfigurationError(f"odr_hz={odr_hz!r} must be a positive number of Hz")
    rates = _reader_class(_model_key(model)).offered_rates_hz()
    return min(rates, key=lambda r: (abs(r - odr), -r))


def find_address(model: str, bus: Any) -> int:
    """Where a chip of ``model`` answers on ``bus``: its identity register read at each of
    :func:`chip_addresses` (:func:`gyrocal.drivers.imu.detect.scan_bus`, reads only). When none
    answers as that chip, its first address, where the reader's own identity check then says
    what is there, or that nothing answers (:meth:`ImuReader.configure`).

    Raises
    ------
    ConfigurationError
        For an unknown model, or when a chip of the model answers at several of its addresses
        (the message says to give the address).
    """
    from gyrocal.drivers.imu.detect import scan_bus

    cls = _reader_class(_model_key(model))
    addresses = tuple(cls.family.addresses)
    mine = [c.address for c in scan_bus(bus, addresses)
            if c.model is not None and _reader_class(_model_key(c.model)) is cls]
    if len(mine) > 1:
        raise ConfigurationError(
            f"a {cls.family.title} answers at each of " + ", ".join(f"0x{a:02X}" for a in mine)
            + "; give the one to calibrate (imu.address, or --imu-address)")
    return mine[0] if mine else addresses[0]


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
    key = _model_key(model)
    reader = _reader_class(key)(bus, address, clock=clock, **options)
    try:
        reader.configure(range_dps=range_dps, odr_hz=odr_hz, lowpass_hz=lowpass_hz)
    except BaseException:
        with contextlib.suppress(DriverError):  # the configure error is the one to report
            reader.close()
        raise
    return reader
