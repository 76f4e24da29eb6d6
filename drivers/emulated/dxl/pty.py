"""Pseudo-terminal transport: the emulated servos behind a device path.

:class:`PtyServoBridge` opens a pseudo-terminal (``os.openpty``), puts it in raw mode and serves
the emulated bus from a thread, so any serial client, and in particular an unmodified
``dynamixel_sdk.PortHandler(path)``, talks to the emulated servos as to a U2D2 (hardware reference
§4.7: pyserial ignores the modem-control errors a PTY gives; the baud rate has no effect on a
PTY but must be one the SDK accepts). Linux and macOS only (POSIX pseudo-terminals).
"""

from __future__ import annotations

import os
import select
import threading
import tty

from gyrocal.drivers.clock import Clock, SystemClock
from gyrocal.drivers.emulated.dxl.bus import ServoBus

__all__ = ["PtyServoBridge"]


class PtyServoBridge:
    """Serve a :class:`ServoBus` on a pseudo-terminal.

    Parameters
    ----------
    bus : ServoBus
        The emulated servos. Their clock should be a :class:`~gyrocal.drivers.clock.SystemClock`:
        the
        client on the other side measures its timeouts in real time.
    model_timing : bool
        Wait each servo's Return Delay Time before its reply (real time). Off by default: the
        PTY itself adds latency.

    Examples
    --------
    >>> with PtyServoBridge(bus) as bridge:             # doctest: +SKIP
    ...     port = dynamixel_sdk.PortHandler(bridge.path)
    """

    def __init__(self, bus: ServoBus, *, model_timing: bool = False,
                 clock: Clock | None = None) -> None:
        self.bus = bus
        self.model_timing = bool(model_timing)
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
                for reply in self.bus.receive(data, None):
                    if self.model_timing:
                        self.clock.sleep(reply.delay_s)
                    out = reply.produce()
                    if out:
                        os.write(master, out)
        except Exception as exc:  # kept for the owner to inspect (see ``error``)
            self.error = exc
