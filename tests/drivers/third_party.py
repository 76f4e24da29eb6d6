"""What a third-party driver needs to run unmodified on the emulated bus: the wall clock's
functions on the virtual clock, and the I²C interfaces the drivers are written against
(``smbus2.SMBus`` is the emulated bus's own class; CircuitPython's ``busio.I2C`` and the
modules Adafruit's drivers import from Blinka, and MicroPython's ``machine.I2C``, ``utime`` and
``ustruct``, are stood in for here).

Nothing here changes a driver's code: the stand-ins replace what the driver imports, as a Linux
board's Blinka or a Raspberry Pi's kernel would provide it.
"""

from __future__ import annotations

import re
import struct
import sys
import types
from contextlib import contextmanager
from typing import Any

from smbus2 import i2c_msg

from gyrocal.drivers.emulated.smbus import EmulatedSMBus

__all__ = ["BusioI2C", "MachineI2C", "blinka_stand_ins", "fake_time",
           "micropython_stand_ins"]


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
    """``busio``, ``digitalio``, ``micropython`` and ``circuitpython_typing`` as Adafruit's
    CircuitPython drivers import them (Blinka provides them on a Linux board): installed in
    ``sys.modules`` for the duration, and the modules imported meanwhile forgotten after."""
    busio = types.ModuleType("busio")
    busio.I2C = BusioI2C  # type: ignore[attr-defined]
    busio.SPI = object  # type: ignore[attr-defined]  # named in annotations, never opened
    micropython = types.ModuleType("micropython")
    micropython.const = lambda x: x  # type: ignore[attr-defined]
    typing_ = types.ModuleType("circuitpython_typing")
    typing_.ReadableBuffer = typing_.WriteableBuffer = bytes  # type: ignore[attr-defined]
    drivers = types.ModuleType("circuitpython_typing.device_drivers")
    drivers.I2CDeviceDriver = object  # type: ignore[attr-defined]
    typing_.device_drivers = drivers  # type: ignore[attr-defined]
    digitalio = types.ModuleType("digitalio")
    digitalio.DigitalInOut = object  # type: ignore[attr-defined]  # an SPI chip select
    stand_ins = {"busio": busio, "micropython": micropython, "circuitpython_typing": typing_,
                 "circuitpython_typing.device_drivers": drivers, "digitalio": digitalio}
    before = set(sys.modules)
    saved = {k: sys.modules[k] for k in stand_ins if k in sys.modules}
    sys.modules.update(stand_ins)
    try:
        yield
    finally:
        for name in set(sys.modules) - before:
            del sys.modules[name]
        sys.modules.update(saved)


class MachineI2C:
    """MicroPython's ``machine.I2C`` memory-access methods on the emulated bus (MicroPython
    docs, class I2C, "Memory operations": ``readfrom_mem`` writes the register address then
    reads with a repeated start; ``writeto_mem`` writes the address and the bytes in one
    transfer).

    Parameters
    ----------
    bus : EmulatedSMBus
        The emulated bus.
    """

    def __init__(self, bus: EmulatedSMBus) -> None:
        self._bus = bus.handle()

    def scan(self) -> list[int]:
        return sorted(self._bus.addresses)

    def readfrom_mem(self, addr: int, memaddr: int, nbytes: int, *, addrsize: int = 8) -> bytes:
        w, r = i2c_msg.write(addr, [memaddr]), i2c_msg.read(addr, nbytes)
        self._bus.i2c_rdwr(w, r)
        return bytes(r)

    def readfrom_mem_into(self, addr: int, memaddr: int, buf: bytearray, *,
                          addrsize: int = 8) -> None:
        buf[:] = self.readfrom_mem(addr, memaddr, len(buf))

    def writeto_mem(self, addr: int, memaddr: int, buf: bytes, *, addrsize: int = 8) -> None:
        self._bus.i2c_rdwr(i2c_msg.write(addr, bytes([memaddr]) + bytes(buf)))


def _wrap(fmt: str, values: tuple[Any, ...]) -> tuple[Any, ...]:
    """``values`` reduced to the width of their ``fmt`` fields, two's complement for signed
    ones: MicroPython's ``ustruct`` stores the low bytes of an out-of-range integer where
    CPython's ``struct`` raises (MicroPython docs, "Differences to CPython", struct)."""
    codes = [code for count, code in re.findall(r"(\d*)([a-zA-Z?])", fmt)
             for _ in range(1 if code in "sp" else int(count or 1))]
    out = []
    for code, value in zip(codes, values, strict=True):
        if code in "bBhHiIlLqQ" and isinstance(value, int):
            bits = 8 * struct.calcsize("<" + code)
            value &= (1 << bits) - 1
            if code.islower() and value >= 1 << (bits - 1):
                value -= 1 << bits
        out.append(value)
    return tuple(out)


def _micropython_struct() -> types.ModuleType:
    ustruct = types.ModuleType("ustruct")
    ustruct.calcsize = struct.calcsize  # type: ignore[attr-defined]
    ustruct.unpack = struct.unpack  # type: ignore[attr-defined]
    ustruct.unpack_from = struct.unpack_from  # type: ignore[attr-defined]
    ustruct.pack = lambda fmt, *v: struct.pack(fmt, *_wrap(fmt, v))  # type: ignore[attr-defined]
    ustruct.pack_into = (  # type: ignore[attr-defined]
        lambda fmt, buf, off, *v: struct.pack_into(fmt, buf, off, *_wrap(fmt, v)))
    return ustruct


@contextmanager
def micropython_stand_ins(clock: Any):
    """``machine``, ``micropython``, ``utime`` and ``ustruct`` as MicroPython drivers import
    them, ``utime`` on the virtual ``clock``: installed in ``sys.modules`` for the duration,
    and the modules imported meanwhile forgotten after."""
    machine = types.ModuleType("machine")
    machine.I2C = MachineI2C  # type: ignore[attr-defined]
    machine.Pin = object  # type: ignore[attr-defined]
    micropython = types.ModuleType("micropython")
    micropython.const = lambda x: x  # type: ignore[attr-defined]
    utime = types.ModuleType("utime")
    utime.sleep = clock.sleep  # type: ignore[attr-defined]
    utime.sleep_ms = lambda ms: clock.sleep(ms / 1e3)  # type: ignore[attr-defined]
    utime.sleep_us = lambda us: clock.sleep(us / 1e6)  # type: ignore[attr-defined]
    utime.ticks_ms = lambda: int(clock.monotonic() * 1e3)  # type: ignore[attr-defined]
    utime.ticks_us = lambda: int(clock.monotonic() * 1e6)  # type: ignore[attr-defined]
    utime.ticks_diff = lambda a, b: a - b  # type: ignore[attr-defined]
    stand_ins = {"machine": machine, "micropython": micropython, "utime": utime,
                 "ustruct": _micropython_struct()}
    before = set(sys.modules)
    saved = {k: sys.modules[k] for k in stand_ins if k in sys.modules}
    sys.modules.update(stand_ins)
    try:
        yield
    finally:
        for name in set(sys.modules) - before:
            del sys.modules[name]
        for name in stand_ins:
            sys.modules.pop(name, None)
        sys.modules.update(saved)
