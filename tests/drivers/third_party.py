"""What a third-party driver needs to run unmodified on the emulated bus: the wall clock's
functions on the virtual clock, and the I²C interfaces the drivers are written against
(``smbus2.SMBus`` is the emulated bus's own class; CircuitPython's ``busio.I2C`` and the
modules Adafruit's drivers import from Blinka are stood in for here).

Nothing here changes a driver's code: the stand-ins replace what the driver imports, as a Linux
board's Blinka or a Raspberry Pi's kernel would provide it.
"""

from __future__ import annotations

import sys
import types
from contextlib import contextmanager
from typing import Any

from smbus2 import i2c_msg

from gyrocal.drivers.emulated.smbus import EmulatedSMBus

__all__ = ["BusioI2C", "blinka_stand_ins", "fake_time"]


def fake_time(clock: Any) -> types.SimpleNamespace:
    """A stand-in for the ``time`` module on the virtual clock."""
    return types.SimpleNamespace(sleep=clock.sleep, time=clock.monotonic,
                                 monotonic=clock.monotonic, perf_counter=clock.monotonic,
                                 monotonic_ns=lambda: int(clock.monotonic() * 1e9))


class BusioI2C:
    """CircuitPython's ``busio.I2C`` (the methods ``adafruit_bus_device.I2CDevice`` calls) on
    the emulated bus, through combined ``i2c_rdwr`` transfers as Blinka's Linux I²C does.

    Parameters
    ----------
    bus : EmulatedSMBus
        The emulated bus.
    """

    def __init__(self, bus: EmulatedSMBus) -> None:
        self._bus = bus.handle()

    def try_lock(self) -> bool:
        return True

    def unlock(self) -> None:
        pass

    def writeto(self, address: int, buffer: bytes, *, start: int = 0,
                end: int | None = None) -> None:
        self._bus.i2c_rdwr(i2c_msg.write(address, bytes(buffer[start:end])))

    def readfrom_into(self, address: int, buffer: bytearray, *, start: int = 0,
                      end: int | None = None) -> None:
        end = len(buffer) if end is None else end
        msg = i2c_msg.read(address, end - start)
        self._bus.i2c_rdwr(msg)
        buffer[start:end] = bytes(msg)

    def writeto_then_readfrom(self, address: int, out_buffer: bytes, in_buffer: bytearray, *,
                              out_start: int = 0, out_end: int | None = None,
                              in_start: int = 0, in_end: int | None = None) -> None:
        in_end = len(in_buffer) if in_end is None else in_end
        w = i2c_msg.write(address, bytes(out_buffer[out_start:out_end]))
        r = i2c_msg.read(address, in_end - in_start)
        self._bus.i2c_rdwr(w, r)
        in_buffer[in_start:in_end] = bytes(r)


@contextmanager
def blinka_stand_ins():
    """``busio``, ``micropython`` and ``circuitpython_typing`` as Adafruit's CircuitPython
    drivers import them (Blinka provides them on a Linux board): installed in
    ``sys.modules`` for the duration, and the modules imported meanwhile forgotten after."""
    busio = types.ModuleType("busio")
    busio.I2C = BusioI2C  # type: ignore[attr-defined]
    micropython = types.ModuleType("micropython")
    micropython.const = lambda x: x  # type: ignore[attr-defined]
    typing_ = types.ModuleType("circuitpython_typing")
    typing_.ReadableBuffer = typing_.WriteableBuffer = bytes  # type: ignore[attr-defined]
    drivers = types.ModuleType("circuitpython_typing.device_drivers")
    drivers.I2CDeviceDriver = object  # type: ignore[attr-defined]
    typing_.device_drivers = drivers  # type: ignore[attr-defined]
    stand_ins = {"busio": busio, "micropython": micropython, "circuitpython_typing": typing_,
                 "circuitpython_typing.device_drivers": drivers}
    before = set(sys.modules)
    saved = {k: sys.modules[k] for k in stand_ins if k in sys.modules}
    sys.modules.update(stand_ins)
    try:
        yield
    finally:
        for name in set(sys.modules) - before:
            del sys.modules[name]
        sys.modules.update(saved)
