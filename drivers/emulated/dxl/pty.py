"""Pseudo-terminal transport: the emulated servos behind a device path.

:class:`PtyServoBridge` opens a pseudo-terminal (``os.openpty``), puts it in raw mode and serves
the emulated bus from a thread, so any serial client, and in particular an unmodified
``dynamixel_sdk.PortHandler(path)``, talks to the emulated servos as to a U2D2 (hardware reference
§4.7: pyserial ignores the modem-control errors a PTY gives). The baud rate moves no bytes slower
on a PTY, but the bridge reads the one the client set on its side (Linux ``TCGETS2``, else the
termios speed) and only servos configured for it hear the packet, as on a real bus; each servo
waits its Return Delay Time before answering. Linux and macOS only (POSIX pseudo-terminals).
"""

from __future__ import annotations

import fcntl
import os
import select
import struct
import sys
import termios
import threading
import tty

from gyrocal.drivers.clock import Clock, SystemClock
from gyrocal.drivers.emulated.dxl.bus import ServoBus

__all__ = ["PtyServoBridge"]

#: Linux's TCGETS2 (asm-generic, as on x86 and ARM): a ``struct termios2`` of 44 bytes whose
#: ``c_ispeed`` and ``c_ospeed`` (offsets 36, 40) hold the baud rate in bit/s, custom rates too.
_TCGETS2 = 0x802C542A
_TERMIOS_SPEEDS = {getattr(termios, f"B{n}"): n for n in (
    9600, 19200, 38400, 57600, 115200, 230400, 460800, 500000, 576000, 921600, 1000000,
    1152000, 1500000, 2000000, 2500000, 3000000, 3500000, 4000000) if hasattr(termios, f"B{n}")}


def line_baudrate(fd: int) -> int | None:
    """The baud rate set on the terminal ``fd`` in bit/s, or ``None`` if it cannot be told."""
    if sys.platform.startswith("linux"):
        buf = bytearray(44)
        try:
            fcntl.ioctl(fd, _TCGETS2, buf)
            return int(struct.unpack_from("I", buf, 40)[0])
        except OSError:
            pass
    try:
        return _TERMIOS_SPEEDS.get(termios.tcgetattr(fd)[5])
    except termios.error:
        return None


#: Nice levels the serving thread takes above its process when it may (Linux, privileged). A
#: real servo answers from its own MCU, which host load cannot starve; the emulated one answers
#: from a thread of a process on the host, and under a load of 10 on 2 cores it can miss the
#: client's status timeout (dynamixel-sdk: 2 × 16 ms latency timer + 2 ms + the packet),
#: which would be counted against the client.
SERVE_PRIORITY_BOOST = 10


def _raise_thread_priority(levels: int) -> bool:
    """Lower the calling thread's niceness by ``levels`` (Linux: a thread's own nice value,
    setpriority(2) on its thread ID); False if not permitted or not supported."""
    try:
        tid = threading.get_native_id()
        os.setpriority(os.PRIO_PROCESS, tid, os.getpriority(os.PRIO_PROCESS, tid) - levels)
    except (OSError, AttributeError):
        return False
    return True


class PtyServoBridge:
    """Serve a :class:`ServoBus` on a pseudo-terminal.

    Parameters
    ----------
    bus : ServoBus
        The emulated servos. Their clock should be a :class:`~gyrocal.drivers.clock.SystemClock`:
        the
        client on the other side measures its timeouts in real time.
    model_timing : bool
        Wait each servo's Return Delay Time before its reply (real time), as the e-Manual's
        Return Delay Time (9) says a servo does.
    match_baudrate : bool
        Deliver a packet only to servos set to the baud rate the client set on the PTY (a servo
        at another rate cannot decode it). ``False``: every servo hears every packet.

    Examples
    --------
    >>> with PtyServoBridge(bus) as bridge:             # doctest: +SKIP
    ...     port = dynamixel_sdk.PortHandler(bridge.path)
    """

    def __init__(self, bus: ServoBus, *, model_timing: bool = True, match_baudrate: bool = True,
                 clock: Clock | None = None) -> None:
        self.bus = bus
        self.model_timing = bool(model_timing)
        self.match_baudrate = bool(match_baudrate)
        self.clock = clock if clock is not None else SystemClock()
        self._master: int | None = None
        self._slave: int | None = None
        self._wake_r: int | None = None
        self._wake_w: int | None = None
        self._thread: threading.Thread | None = None
        self._stop = threading.Event()
        self.path: str | None = None
        #: The exception that stopped the serving thread, if any.
        self.error: Exception | None = None
        #: Whether the serving thread runs :data:`SERVE_PRIORITY_BOOST` nice levels above the
        #: process (needs the privilege to lower niceness; without it the servos share the
        #: host's lot and may answer a starved client late).
        self.boosted = False

    def start(self) -> str:
        """Open the pseudo-terminal, start serving, and return the device path."""
        if self._thread is not None:
            raise RuntimeError("the bridge is already running")
        self._master, self._slave = os.openpty()
        tty.setraw(self._slave)
        tty.setraw(self._master)
        self.path = os.ttyname(self._slave)
        self._wake_r, self._wake_w = os.pipe()
        self._stop.clear()
        self._thread = threading.Thread(target=self._serve, name="dxl-pty-bridge", daemon=True)
        self._thread.start()
        return self.path

    def stop(self) -> None:
        """Stop serving and close the pseudo-terminal."""
        if self._thread is None:
            return
        self._stop.set()
        if self._wake_w is not None:
            os.write(self._wake_w, b"x")
        self._thread.join(timeout=5.0)
        self._thread = None
        for fd in (self._master, self._slave, self._wake_r, self._wake_w):
            if fd is not None:
                try:
                    os.close(fd)
                except OSError:
                    pass
        self._master = self._slave = self._wake_r = self._wake_w = None

    def __enter__(self) -> PtyServoBridge:
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def _serve(self) -> None:
        self.boosted = _raise_thread_priority(SERVE_PRIORITY_BOOST)
        master, wake = self._master, self._wake_r
        try:
            while not self._stop.is_set():
                ready, _, _ = select.select([master, wake], [], [], 0.5)
                if wake in ready or master not in ready:
                    continue
                try:
                    data = os.read(master, 4096)
                except OSError:  # the client closed its side (EIO on Linux): keep serving
                    self._stop.wait(0.01)
                    continue
                if not data:
                    continue
                baud = line_baudrate(self._slave) if self.match_baudrate else None  # type: ignore[arg-type]
                for reply in self.bus.receive(data, baud):
                    if self.model_timing:
                        self.clock.sleep(reply.delay_s)
                    out = reply.produce()
                    if out:
                        os.write(master, out)
        except Exception as exc:  # kept for the owner to inspect (see ``error``)
            self.error = exc
