"""An emulated I²C adapter with the methods and signatures of ``smbus2.SMBus``.

Devices attach at 7-bit addresses and see the bus at the level of I²C messages: a write message
(``[register, data...]``) and a read message (``n`` bytes from the device's register pointer),
which is how register chips behave on the wire. The bus spends the transfer time of every
message on the shared clock, so timestamps taken around a transfer are as far apart as on a real
400 kHz bus, and keeps a log of transactions for tests.

Errors follow smbus2 and the Linux i2c-dev ioctls (hardware reference §3): ``ValueError`` for an
SMBus block transfer over 32 bytes (before any I/O), ``OSError(EREMOTEIO)`` when no device
acknowledges the address, ``OSError`` with the device's errno when it refuses (a NACK knob).
"""

from __future__ import annotations

import ctypes
import errno
import os
from collections import deque
from collections.abc import Iterable
from dataclasses import dataclass
from typing import Protocol, runtime_checkable

from gyrocal.drivers.clock import Clock, VirtualClock

__all__ = ["I2C_SMBUS_BLOCK_MAX", "EmulatedSMBus", "I2CDevice", "Transaction"]

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
        """A write message: ``data[0]`` sets the register pointer, the rest are written."""
        ...

    def i2c_read(self, length: int) -> bytes:
        """A read message: ``length`` bytes from the register pointer."""
        ...


@dataclass(frozen=True)
class Transaction:
    """One logged bus call.

    Parameters
    ----------
    t : float
        Clock time at its start.
    op : str
        The method: ``"read_byte_data"``, ``"write_byte_data"``, ``"read_i2c_block_data"``,
        ``"write_i2c_block_data"`` or ``"i2c_rdwr"``.
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
    """

    def __init__(
        self,
        clock: Clock | None = None,
        bus_hz: float = 400_000,
        *,
        log_size: int | None = 10_000,
        i2c_rdwr_supported: bool = True,
    ) -> None:
        if not bus_hz >= 0:
            raise ValueError(f"bus_hz must be >= 0 (0 disables transfer time), got {bus_hz!r}")
        self.clock: Clock = clock if clock is not None else VirtualClock()
        self.bus_hz = float(bus_hz)
        self.i2c_rdwr_supported = bool(i2c_rdwr_supported)
        self.log: deque[Transaction] = deque(maxlen=log_size)
        self.transactions = 0
        self._devices: dict[int, I2CDevice] = {}
        self._closed = False

    # -- wiring -------------------------------------------------------------------------------

    def attach(self, address: int, device: I2CDevice) -> None:
        """Put ``device`` on the bus at the 7-bit ``address``."""
        if not isinstance(address, int) or not 0 <= address <= 0x7F:
            raise ValueError(f"address must be a 7-bit integer, got {address!r}")
        if address in self._devices:
            raise ValueError(f"address 0x{address:02X} is already taken")
        if not isinstance(device, I2CDevice):
            raise TypeError("device must have i2c_ack(), i2c_write(data) and i2c_read(length)")
        self._devices[address] = device

    def detach(self, address: int) -> None:
        """Remove the device at ``address`` (it then NACKs like an unplugged chip)."""
        self._devices.pop(address, None)

    def device(self, address: int) -> I2CDevice:
        """The device attached at ``address``."""
        return self._devices[address]

    @property
    def addresses(self) -> tuple[int, ...]:
        """Addresses with a device attached."""
        return tuple(sorted(self._devices))

    # -- smbus2 API ---------------------------------------------------------------------------

    def read_byte_data(self, i2c_addr: int, register: int, force: bool | None = None) -> int:
        """SMBus read byte data: write the register, repeated START, read one byte."""
        return self._run("read_byte_data", [(i2c_addr, bytes([register]), 0), (i2c_addr, None, 1)])[
            0
        ][0]

    def write_byte_data(
        self, i2c_addr: int, register: int, value: int, force: bool | None = None
    ) -> None:
        """SMBus write byte data: write ``[register, value]``."""
        self._run("write_byte_data", [(i2c_addr, bytes([register, value]), 0)])

    def read_i2c_block_data(
        self, i2c_addr: int, register: int, length: int, force: bool | None = None
    ) -> list[int]:
        """I²C block read of ``length`` (≤ 32) bytes from ``register``."""
        if length > I2C_SMBUS_BLOCK_MAX:
            raise ValueError(f"Desired block length over {I2C_SMBUS_BLOCK_MAX} bytes")
        out = self._run(
            "read_i2c_block_data", [(i2c_addr, bytes([register]), 0), (i2c_addr, None, length)]
        )
        return list(out[0])

    def write_i2c_block_data(
        self, i2c_addr: int, register: int, data: Iterable[int], force: bool | None = None
    ) -> None:
        """I²C block write of ``data`` (≤ 32 bytes) starting at ``register``."""
        payload = bytes(data)
        if len(payload) > I2C_SMBUS_BLOCK_MAX:
            raise ValueError(f"Data length cannot exceed {I2C_SMBUS_BLOCK_MAX} bytes")
        self._run("write_i2c_block_data", [(i2c_addr, bytes([register]) + payload, 0)])

    def i2c_rdwr(self, *i2c_msgs: object) -> None:
        """Combined transaction of ``smbus2.i2c_msg`` messages (repeated STARTs, one STOP).

        Read messages are filled in place, as smbus2 does; there is no 32-byte limit.
        """
        if not self.i2c_rdwr_supported:
            raise _oserror(errno.EOPNOTSUPP)
        plan: list[tuple[int, bytes | None, int]] = []
        reads = []
        for m in i2c_msgs:
            addr, flags, length = int(m.addr), int(m.flags), int(m.len)  # type: ignore[attr-defined]
            if flags & _I2C_M_RD:
                plan.append((addr, None, length))
                reads.append(m)
            else:
                plan.append((addr, bytes(m), 0))  # type: ignore[call-overload]
        for msg, data in zip(reads, self._run("i2c_rdwr", plan), strict=True):
            ctypes.memmove(msg.buf, data, len(data))  # type: ignore[attr-defined]

    def close(self) -> None:
        """Close the bus; later calls fail with ``EBADF`` as on a closed file descriptor."""
        self._closed = True

    def __enter__(self) -> EmulatedSMBus:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- machinery ----------------------------------------------------------------------------

    def _spend(self, bits: int) -> None:
        if self.bus_hz > 0 and bits:
            self.clock.sleep(bits / self.bus_hz)

    def _run(self, op: str, plan: list[tuple[int, bytes | None, int]]) -> list[bytes]:
        """Carry out messages ``(address, write bytes or None, read length)`` in order."""
        if self._closed:
            raise _oserror(errno.EBADF)
        self.transactions += 1
        t0 = self.clock.monotonic()
        first = plan[0]
        register = first[1][0] if first[1] else None
        written = b"".join(w[1:] if i == 0 else w for i, (_, w, _) in enumerate(plan) if w)
        read_length = sum(n for _, _, n in plan)
        reads: list[bytes] = []
        failure: int | None = None
        try:
            for addr, wdata, rlen in plan:
                self._spend(1 + 9)  # (repeated) START + address byte
                dev = self._devices.get(addr)
                if dev is None:
                    failure = errno.EREMOTEIO
                    raise _oserror(failure)
                refusal = dev.i2c_ack()
                if refusal is not None:
                    failure = refusal
                    raise _oserror(failure)
                if wdata is not None:
                    self._spend(9 * len(wdata))
                    dev.i2c_write(wdata)
                else:
                    data = bytes(dev.i2c_read(rlen))
                    if len(data) != rlen:
                        raise RuntimeError(f"device returned {len(data)} bytes for {rlen}")
                    self._spend(9 * rlen)
                    reads.append(data)
            self._spend(1)  # STOP
        finally:
            self.log.append(
                Transaction(
                    t=t0,
                    op=op,
                    address=first[0],
                    register=register,
                    written=written,
                    read_length=read_length,
                    errno=failure,
                    duration_s=self.clock.monotonic() - t0,
                )
            )
        return reads

    def __repr__(self) -> str:
        devs = ", ".join(f"0x{a:02X}: {type(d).__name__}" for a, d in sorted(self._devices.items()))
        return f"EmulatedSMBus({{{devs}}}, bus_hz={self.bus_hz:g})"
