"""An emulated I²C adapter with the methods and signatures of ``smbus2.SMBus``.

Devices attach at 7-bit addresses and see the bus at the level of I²C messages: a write message
(``[register, data...]``) and a read message (``n`` bytes from the device's register pointer),
which is how register chips behave on the wire. Every ``smbus2.SMBus`` call is carried out as
the messages the Linux kernel's SMBus emulation puts on the wire for it (``i2c_smbus_xfer_emulated``
in ``drivers/i2c/i2c-core-smbus.c``), including the PEC byte when :meth:`EmulatedSMBus.enable_pec`
is on. The bus spends the transfer time of every message on the shared clock, counted from the
start of the call, so a call lasts what the bus speed implies and no more (a byte write, 29 bit
times, is 72.5 µs at 400 kHz), and keeps a log of transactions for tests.

An :class:`EmulatedSMBus` is a handle on an adapter (``/dev/i2c-N``): :meth:`EmulatedSMBus.handle`
and the ``smbus2``-shaped class from :meth:`EmulatedSMBus.smbus_class` open further handles on the
same devices, and closing one handle closes only that handle, as with file descriptors.

Errors follow smbus2 and the Linux i2c-dev ioctls (hardware reference §3): ``ValueError`` for an
SMBus block transfer over 32 bytes (before any I/O), ``OSError(EREMOTEIO)`` when no device
acknowledges the address, ``OSError`` with the device's errno when it refuses (a NACK knob).
"""

from __future__ import annotations

import ctypes
import errno
import os
import re
from collections import deque
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import NamedTuple, Protocol, runtime_checkable

from smbus2 import I2cFunc

from gyrocal.drivers.clock import Clock, VirtualClock, waiter_until

__all__ = ["I2C_SMBUS_BLOCK_MAX", "EmulatedSMBus", "I2CDevice", "Transaction", "smbus_pec"]

#: smbus2's limit for SMBus block transfers.
I2C_SMBUS_BLOCK_MAX = 32
_I2C_M_RD = 0x0001  # i2c_msg flag of a read message


@runtime_checkable
class I2CDevice(Protocol):
    """What a device needs to sit on :class:`EmulatedSMBus`."""

    def i2c_ack(self) -> int | None:
        """``None`` to acknowledge the address now, or the errno of a refusal."""
        ...

    def i2c_write(self, data: bytes) -> None:
        """A write message: ``data[0]`` sets the register pointer, the rest are written (never
        called with no data: a Quick Command only asks :meth:`i2c_ack`)."""
        ...

    def i2c_read(self, length: int) -> bytes:
        """A read message: ``length`` bytes from the register pointer."""
        ...


class Transaction(NamedTuple):
    """One logged bus call (a named tuple: one is made for every call on the bus).

    Parameters
    ----------
    t : float
        Clock time at its start.
    op : str
        The ``smbus2.SMBus`` method (``"read_byte_data"``, ``"write_quick"``, ``"i2c_rdwr"``...).
    address : int
        Address of the first message.
    register : int or None
        The register byte of the first write message, if any.
    written : bytes
        Data bytes written after the register byte.
    read_length : int
        Bytes read.
    errno : int or None
        The errno it failed with, if it failed.
    duration_s : float
        Bus time spent.
    """

    t: float
    op: str
    address: int
    register: int | None
    written: bytes
    read_length: int
    errno: int | None
    duration_s: float


def _oserror(code: int) -> OSError:
    return OSError(code, os.strerror(code))


def smbus_pec(data: bytes, crc: int = 0) -> int:
    """SMBus Packet Error Code: CRC-8, polynomial x⁸ + x² + x + 1, over ``data`` (SMBus 3.0
    §6.4; the kernel's ``i2c_smbus_pec``), continuing from ``crc``."""
    for byte in data:
        crc ^= byte
        for _ in range(8):
            crc = ((crc << 1) ^ 0x07) & 0xFF if crc & 0x80 else (crc << 1) & 0xFF
    return crc


@dataclass
class _Msg:
    """One I²C message: a write of ``data``, or a read of ``length`` bytes (``recv_len``: the
    first byte read is a count of the bytes that follow, as in SMBus block reads)."""

    addr: int
    data: bytes | None = None
    length: int = 0
    recv_len: bool = False


_I2C_FUNC = int(I2cFunc.I2C)
#: What every adapter can do, as ``smbus2.I2cFunc`` bits (the kernel's I2C_FUNC_SMBUS_EMUL plus
#: block reads and block process calls).
_SMBUS_FUNCS = (
    I2cFunc.SMBUS_QUICK | I2cFunc.SMBUS_BYTE | I2cFunc.SMBUS_BYTE_DATA | I2cFunc.SMBUS_WORD_DATA
    | I2cFunc.SMBUS_PROC_CALL | I2cFunc.SMBUS_BLOCK_DATA | I2cFunc.SMBUS_BLOCK_PROC_CALL
    | I2cFunc.SMBUS_I2C_BLOCK
)


class _Adapter:
    """The shared side of a bus: its devices, clock, speed and log (``/dev/i2c-N``)."""

    def __init__(self, clock: Clock, bus_hz: float, log_size: int | None, funcs: int,
                 number: int) -> None:
        self.clock = clock
        self.bus_hz = bus_hz
        self.funcs = funcs
        self.number = number
        self.log: deque[Transaction] = deque(maxlen=log_size)
        self.transactions = 0
        self.devices: dict[int, I2CDevice] = {}


class EmulatedSMBus:
    """A drop-in for ``smbus2.SMBus`` in front of emulated devices.

    Parameters
    ----------
    clock : Clock, optional
        The shared clock; a fresh :class:`VirtualClock` when omitted.
    bus_hz : float
        SCL frequency used to model transfer time: each message costs a START, the address
        byte and its data bytes at 9 bits a byte (8 + ACK), and each call a STOP. ``0`` spends
        no time.
    log_size : int or None
        How many transactions :attr:`log` keeps (``None``: all).
    i2c_rdwr_supported : bool
        With ``False``, :meth:`i2c_rdwr` fails with ``EOPNOTSUPP`` like an adapter without
        I2C_FUNC_I2C.
    pec_supported : bool
        With ``False``, :meth:`enable_pec` fails like smbus2 on an adapter without
        I2C_FUNC_SMBUS_PEC.
    bus_number : int
        The adapter's number ``N`` (``/dev/i2c-N``): :meth:`open` accepts only this bus.
    """

    def __init__(
        self,
        clock: Clock | None = None,
        bus_hz: float = 400_000,
        *,
        log_size: int | None = 10_000,
        i2c_rdwr_supported: bool = True,
        pec_supported: bool = True,
        bus_number: int = 1,
    ) -> None:
        if not bus_hz >= 0:
            raise ValueError(f"bus_hz must be >= 0 (0 disables transfer time), got {bus_hz!r}")
        if not isinstance(bus_number, int) or bus_number < 0:
            raise ValueError(f"bus_number must be a non-negative integer, got {bus_number!r}")
        funcs = int(_SMBUS_FUNCS)
        if i2c_rdwr_supported:
            funcs |= int(I2cFunc.I2C)
        if pec_supported:
            funcs |= int(I2cFunc.SMBUS_PEC)
        adapter = _Adapter(clock if clock is not None else VirtualClock(), float(bus_hz),
                           log_size, funcs, bus_number)
        self._bind(adapter)
        self._open = True

    def _bind(self, adapter: _Adapter) -> None:
        self._adapter = adapter
        self._open = False
        self._pec = 0
        #: The address of the last call, as smbus2 keeps it (``None`` when closed).
        self.address: int | None = None
        self.force = False

    # -- the adapter's shared state -------------------------------------------------------------

    @property
    def clock(self) -> Clock:
        """The shared clock."""
        return self._adapter.clock

    @property
    def bus_hz(self) -> float:
        """The SCL frequency (Hz) transfer time is modelled at."""
        return self._adapter.bus_hz

    @property
    def log(self) -> deque[Transaction]:
        """Recent transactions of every handle on this adapter."""
        return self._adapter.log

    @property
    def transactions(self) -> int:
        """Calls carried out on this adapter, by every handle."""
        return self._adapter.transactions

    @property
    def funcs(self) -> I2cFunc:
        """What the adapter supports, as smbus2's ``SMBus.funcs``."""
        return I2cFunc(self._adapter.funcs)

    @property
    def i2c_rdwr_supported(self) -> bool:
        """Whether :meth:`i2c_rdwr` works (I2C_FUNC_I2C); settable, for every handle."""
        return bool(self._adapter.funcs & I2cFunc.I2C)

    @i2c_rdwr_supported.setter
    def i2c_rdwr_supported(self, value: bool) -> None:
        if value:
            self._adapter.funcs |= int(I2cFunc.I2C)
        else:
            self._adapter.funcs &= ~int(I2cFunc.I2C)

    @property
    def fd(self) -> int | None:
        """Stands in for smbus2's file descriptor: ``None`` when closed."""
        return 1000 + self._adapter.number if self._open else None

    # -- wiring -------------------------------------------------------------------------------

    def attach(self, address: int, device: I2CDevice) -> None:
        """Put ``device`` on the bus at the 7-bit ``address``."""
        if not isinstance(address, int) or not 0 <= address <= 0x7F:
            raise ValueError(f"address must be a 7-bit integer, got {address!r}")
        if address in self._adapter.devices:
            raise ValueError(f"address 0x{address:02X} is already taken")
        if not isinstance(device, I2CDevice):
            raise TypeError("device must have i2c_ack(), i2c_write(data) and i2c_read(length)")
        self._adapter.devices[address] = device

    def detach(self, address: int) -> None:
        """Remove the device at ``address`` (it then NACKs like an unplugged chip)."""
        self._adapter.devices.pop(address, None)

    def device(self, address: int) -> I2CDevice:
        """The device attached at ``address``."""
        return self._adapter.devices[address]

    @property
    def addresses(self) -> tuple[int, ...]:
        """Addresses with a device attached."""
        return tuple(sorted(self._adapter.devices))

    def handle(self) -> EmulatedSMBus:
        """A new, open handle on the same adapter (another ``SMBus(N)`` on the same bus)."""
        other = object.__new__(type(self))
        EmulatedSMBus._bind(other, self._adapter)
        other._open = True
        return other

    def smbus_class(self) -> type[EmulatedSMBus]:
        """A class with ``smbus2.SMBus``'s constructor, ``SMBus(bus=None, force=False)``, whose
        instances are handles on this adapter: patch it in where a client does
        ``smbus2.SMBus(1)``. ``bus`` must be this adapter's number (or ``/dev/i2c-N``)."""
        adapter = self._adapter

        class SMBus(EmulatedSMBus):
            def __init__(self, bus: int | str | None = None, force: bool = False) -> None:
                self._bind(adapter)
                self.force = bool(force)
                if bus is not None:
                    self.open(bus)

        SMBus.__qualname__ = SMBus.__name__ = "SMBus"
        return SMBus

    # -- smbus2 API: the handle ---------------------------------------------------------------

    def open(self, bus: int | str) -> None:
        """Open bus ``bus`` (its number or ``/dev/i2c-N``), as ``smbus2.SMBus.open``.

        Raises
        ------
        TypeError
            ``bus`` is neither an int nor a str (smbus2's error).
        FileNotFoundError
            It names another bus than this adapter's, as ``os.open`` on a missing device.
        """
        if isinstance(bus, bool) or not isinstance(bus, int | str):
            raise TypeError(f"Unexpected type(bus)={type(bus)}")
        path = f"/dev/i2c-{bus}" if isinstance(bus, int) else bus
        match = re.fullmatch(r"/dev/i2c-(\d+)", path)
        if match is None or int(match.group(1)) != self._adapter.number:
            raise FileNotFoundError(errno.ENOENT, os.strerror(errno.ENOENT), path)
        self._open = True

    def close(self) -> None:
        """Close this handle; its later calls fail with ``EBADF`` as on a closed file
        descriptor. Other handles, and :meth:`open` on this one, still reach the devices."""
        self._open = False
        self._pec = 0
        self.address = None

    def __enter__(self) -> EmulatedSMBus:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def _get_pec(self) -> int:
        return self._pec

    def enable_pec(self, enable: bool = True) -> None:
        """Turn SMBus Packet Error Checking on or off for this handle, as smbus2 does.

        With PEC on, SMBus calls other than ``write_quick`` and the I²C block transfers send a
        CRC-8 byte after a write and read one after a read, which is checked (``EBADMSG`` on a
        mismatch, as the kernel's ``i2c_smbus_check_pec``). A device that does not know PEC
        takes the extra written byte as data, as on the wire.

        Raises
        ------
        OSError
            The adapter lacks I2C_FUNC_SMBUS_PEC (smbus2's ``IOError``).
        """
        if not self._adapter.funcs & I2cFunc.SMBUS_PEC:
            raise OSError("SMBUS_PEC is not a feature")
        self._check_open()
        self._pec = int(enable)

    pec = property(_get_pec, enable_pec)

    # -- smbus2 API: SMBus transfers --------------------------------------------------------------

    def write_quick(self, i2c_addr: int, force: bool | None = None) -> None:
        """SMBus Quick Command (write): START, address, STOP."""
        self._smbus("write_quick", I2cFunc.SMBUS_QUICK, [_Msg(i2c_addr, b"")], pec=False)

    def read_byte(self, i2c_addr: int, force: bool | None = None) -> int:
        """SMBus Receive Byte: one byte from the device's current register pointer."""
        return self._smbus("read_byte", I2cFunc.SMBUS_BYTE, [_Msg(i2c_addr, None, 1)])[0]

    def write_byte(self, i2c_addr: int, value: int, force: bool | None = None) -> None:
        """SMBus Send Byte: one byte (a register chip takes it as its register pointer)."""
        self._smbus("write_byte", I2cFunc.SMBUS_BYTE, [_Msg(i2c_addr, _bytes([value]))])

    def read_byte_data(self, i2c_addr: int, register: int, force: bool | None = None) -> int:
        """SMBus Read Byte: write the register, repeated START, read one byte."""
        return self._smbus("read_byte_data", I2cFunc.SMBUS_BYTE_DATA,
                           [_Msg(i2c_addr, _bytes([register])), _Msg(i2c_addr, None, 1)])[0]

    def write_byte_data(
        self, i2c_addr: int, register: int, value: int, force: bool | None = None
    ) -> None:
        """SMBus Write Byte: write ``[register, value]``."""
        self._smbus("write_byte_data", I2cFunc.SMBUS_BYTE_DATA,
                    [_Msg(i2c_addr, _bytes([register, value]))])

    def read_word_data(self, i2c_addr: int, register: int, force: bool | None = None) -> int:
        """SMBus Read Word: two bytes from ``register``, low byte first."""
        lo, hi = self._smbus("read_word_data", I2cFunc.SMBUS_WORD_DATA,
                             [_Msg(i2c_addr, _bytes([register])), _Msg(i2c_addr, None, 2)])
        return lo | hi << 8

    def write_word_data(
        self, i2c_addr: int, register: int, value: int, force: bool | None = None
    ) -> None:
        """SMBus Write Word: ``[register, value & 0xFF, value >> 8]``."""
        self._smbus("write_word_data", I2cFunc.SMBUS_WORD_DATA,
                    [_Msg(i2c_addr, _bytes([register, *_word(value)]))])

    def process_call(self, i2c_addr: int, register: int, value: int,
                     force: bool | None = None) -> int:
        """SMBus Process Call: write a word to ``register``, read a word back."""
        lo, hi = self._smbus(
            "process_call", I2cFunc.SMBUS_PROC_CALL,
            [_Msg(i2c_addr, _bytes([register, *_word(value)])), _Msg(i2c_addr, None, 2)],
        )
        return lo | hi << 8

    def read_block_data(self, i2c_addr: int, register: int,
                        force: bool | None = None) -> list[int]:
        """SMBus Block Read: the device sends a count (1–32), then that many bytes.

        Raises
        ------
        OSError
            ``EPROTO`` when the count is 0 or over 32, as the kernel reports it.
        """
        return self._smbus("read_block_data", I2cFunc.SMBUS_BLOCK_DATA,
                           [_Msg(i2c_addr, _bytes([register])), _Msg(i2c_addr, None, 1, True)])

    def write_block_data(self, i2c_addr: int, register: int, data: Sequence[int],
                         force: bool | None = None) -> None:
        """SMBus Block Write: ``[register, len(data), *data]`` (at most 32 bytes)."""
        payload = _block(data)
        self._smbus("write_block_data", I2cFunc.SMBUS_BLOCK_DATA,
                    [_Msg(i2c_addr, _bytes([register, len(payload)]) + payload)])

    def block_process_call(self, i2c_addr: int, register: int, data: Sequence[int],
                           force: bool | None = None) -> list[int]:
        """SMBus Block Write – Block Read Process Call: send a block, receive one."""
        payload = _block(data)
        return self._smbus(
            "block_process_call", I2cFunc.SMBUS_BLOCK_PROC_CALL,
            [_Msg(i2c_addr, _bytes([register, len(payload)]) + payload),
             _Msg(i2c_addr, None, 1, True)],
        )

    def read_i2c_block_data(
        self, i2c_addr: int, register: int, length: int, force: bool | None = None
    ) -> list[int]:
        """I²C block read of ``length`` (≤ 32) bytes from ``register`` (no count, no PEC)."""
        if length > I2C_SMBUS_BLOCK_MAX:
            raise ValueError(f"Desired block length over {I2C_SMBUS_BLOCK_MAX} bytes")
        return self._smbus("read_i2c_block_data", I2cFunc.SMBUS_I2C_BLOCK,
                           [_Msg(i2c_addr, _bytes([register])), _Msg(i2c_addr, None, length)],
                           pec=False)

    def write_i2c_block_data(
        self, i2c_addr: int, register: int, data: Iterable[int], force: bool | None = None
    ) -> None:
        """I²C block write of ``data`` (≤ 32 bytes) starting at ``register`` (no PEC)."""
        payload = _block(list(data))
        self._smbus("write_i2c_block_data", I2cFunc.SMBUS_I2C_BLOCK,
                    [_Msg(i2c_addr, _bytes([register]) + payload)], pec=False)

    def i2c_rdwr(self, *i2c_msgs: object) -> None:
        """Combined transaction of ``smbus2.i2c_msg`` messages (repeated STARTs, one STOP).

        Read messages are filled in place, as smbus2 does; there is no 32-byte limit.
        """
        self._check_open()
        if not self._adapter.funcs & _I2C_FUNC:
            raise _oserror(errno.EOPNOTSUPP)
        plan: list[_Msg] = []
        reads = []
        for m in i2c_msgs:
            # ctypes fields read as ints; a slice of the buffer pointer is ``bytes(m)`` without
            # smbus2's ``string_at`` call (a fifth of its cost)
            addr, flags, length = m.addr, m.flags, m.len  # type: ignore[attr-defined]
            if flags & _I2C_M_RD:
                plan.append(_Msg(addr, None, length))
                reads.append(m)
            else:
                plan.append(_Msg(addr, m.buf[:length]))  # type: ignore[attr-defined]
        for msg, data in zip(reads, self._run("i2c_rdwr", plan), strict=True):
            ctypes.memmove(msg.buf, data, len(data))  # type: ignore[attr-defined]

    # -- machinery ----------------------------------------------------------------------------

    def _check_open(self) -> None:
        if not self._open:
            raise _oserror(errno.EBADF)

    def _smbus(self, op: str, func: int, plan: list[_Msg], *, pec: bool = True) -> list[int]:
        """An SMBus call: check the adapter supports it, add PEC, run it, check PEC."""
        self._check_open()
        if not self._adapter.funcs & int(func):  # as ints: an enum's & is slow
            raise _oserror(errno.EOPNOTSUPP)
        for m in plan:
            if not 0 <= m.addr <= 0x7F:
                raise _oserror(errno.EINVAL)  # the kernel's answer to I2C_SLAVE over 0x7F
        self.address = plan[0].addr
        pec = pec and bool(self._pec)
        last = plan[-1]
        if pec and last.data is not None:  # a write: append the PEC of the whole message
            last.data += bytes([smbus_pec(bytes([last.addr << 1]) + last.data)])
        out = self._run(op, plan, read_pec=pec and last.data is None)
        if not out:
            return []
        data = out[-1]
        if pec:
            crc = 0
            for m in plan[:-1]:
                crc = smbus_pec(bytes([m.addr << 1]) + (m.data or b""), crc)
            crc = smbus_pec(bytes([last.addr << 1 | 1]) + data[:-1], crc)
            if crc != data[-1]:
                raise _oserror(errno.EBADMSG)
            data = data[:-1]
        return list(data[1:] if last.recv_len else data)

    def _run(self, op: str, plan: list[_Msg], *, read_pec: bool = False) -> list[bytes]:
        """Carry out the messages in order; return what each read message got."""
        if not self._open:
            raise _oserror(errno.EBADF)
        ad = self._adapter
        ad.transactions += 1
        clock, bus_hz, devices = ad.clock, ad.bus_hz, ad.devices
        monotonic, wait = clock.monotonic, waiter_until(clock)
        # Each step waits until the bus has clocked its bits since t0 (no wait with bus_hz 0):
        # a (repeated) START and the address byte, the data bytes at 9 bits (8 + ACK), a STOP.
        # A host that stalled meanwhile (VirtualClock.stall_at) finds them clocked already: the
        # adapter shifts the bits out without it. (One call per wait: this runs three times per
        # FIFO drain.)
        t0 = monotonic()
        timed = bus_hz > 0
        bits = 0
        first = plan[0]
        register = first.data[0] if first.data else None
        reads: list[bytes] = []
        failure: int | None = None
        try:
            for m in plan:
                bits += 10
                if timed:
                    wait(t0 + bits / bus_hz)
                dev = devices.get(m.addr)
                refusal = errno.EREMOTEIO if dev is None else dev.i2c_ack()
                if refusal is not None:
                    failure = refusal
                    raise _oserror(failure)
                data = m.data
                if data is not None:
                    bits += 9 * len(data)
                    if timed:
                        wait(t0 + bits / bus_hz)
                    if data:  # a Quick Command is the address alone
                        dev.i2c_write(data)  # type: ignore[union-attr]
                    continue
                length = m.length
                data = bytes(dev.i2c_read(length))  # type: ignore[union-attr]
                if m.recv_len:
                    if not 1 <= data[0] <= I2C_SMBUS_BLOCK_MAX:
                        failure = errno.EPROTO
                        raise _oserror(failure)
                    length = 1 + data[0]
                    data += bytes(dev.i2c_read(data[0]))  # type: ignore[union-attr]
                if read_pec and m is plan[-1]:
                    length += 1
                    data += bytes(dev.i2c_read(1))  # type: ignore[union-attr]
                if len(data) != length:
                    raise RuntimeError(f"device returned {len(data)} bytes for {length}")
                bits += 9 * length
                if timed:
                    wait(t0 + bits / bus_hz)
                reads.append(data)
            bits += 1  # STOP
            if timed:
                wait(t0 + bits / bus_hz)
        finally:
            ad.log.append(Transaction(t0, op, first.addr, register, _written(plan),
                                      sum(map(len, reads)), failure, monotonic() - t0))
        return reads

    def __repr__(self) -> str:
        devs = ", ".join(f"0x{a:02X}: {type(d).__name__}"
                         for a, d in sorted(self._adapter.devices.items()))
        return f"EmulatedSMBus({{{devs}}}, bus_hz={self.bus_hz:g})"


def _written(plan: list[_Msg]) -> bytes:
    """The data bytes a transaction's write messages carried after its register byte."""
    first = plan[0]
    if (len(plan) == 2 and plan[1].data is None and first.data is not None
            and len(first.data) <= 1):  # a register read: the register byte alone
        return b""
    return b"".join(m.data[1:] if i == 0 else m.data for i, m in enumerate(plan) if m.data)


def _bytes(values: Iterable[int]) -> bytes:
    """Bytes from ints, with a clear error for a value that is not one byte."""
    values = list(values)
    for v in values:
        if not isinstance(v, int) or not 0 <= v <= 0xFF:
            raise ValueError(f"I²C data must be integers 0..255, got {v!r}")
    return bytes(values)


def _word(value: int) -> tuple[int, int]:
    if not isinstance(value, int) or not 0 <= value <= 0xFFFF:
        raise ValueError(f"an SMBus word must be an integer 0..65535, got {value!r}")
    return value & 0xFF, value >> 8


def _block(data: Sequence[int]) -> bytes:
    if len(data) > I2C_SMBUS_BLOCK_MAX:
        raise ValueError(f"Data length cannot exceed {I2C_SMBUS_BLOCK_MAX} bytes")
    return _bytes(data)
