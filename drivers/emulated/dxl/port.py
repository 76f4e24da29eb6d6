"""In-process transport: a ``dynamixel_sdk.PortHandler`` that talks to a :class:`ServoBus`.

The unmodified ``PacketHandler``, ``GroupSyncRead`` and ``GroupSyncWrite`` of dynamixel-sdk use it
exactly as they use a serial port (hardware reference §4.7). It models the bus's timing on the
shared clock: sending ``n`` bytes takes ``n × 10 / baud`` s, each servo waits its Return Delay Time
before answering, and its status packet then takes its own transfer time. A reply is produced when
its first byte would be sent, so the servo samples its state at that instant.

PortHandler measures its packet timeout with the host's ``time.time()``; here
:meth:`EmulatedPortHandler.getCurrentTime` reads the shared clock instead, and a read that finds
nothing left to arrive waits (on the clock) until the timeout has passed. A dropped status
packet therefore times out after the SDK's usual timeout in virtual time, at once in wall time,
instead of spinning for ever or waiting for real.
"""

from __future__ import annotations

from collections import deque

from dynamixel_sdk import PortHandler

from gyrocal.drivers.clock import Clock
from gyrocal.drivers.emulated.dxl.bus import PendingReply, ServoBus

__all__ = ["EmulatedPortHandler"]


class EmulatedPortHandler(PortHandler):
    """A PortHandler whose wire is an emulated servo bus.

    Parameters
    ----------
    bus : ServoBus
        The emulated servos.
    clock : Clock or None
        The clock the timing is spent on; default the bus's clock.
    port_name : str
        A name for messages (there is no device file).
    model_timing : bool
        Spend serial transfer time and Return Delay Time on the clock (default). Without it only
        timeouts take clock time.
    """

    def __init__(self, bus: ServoBus, clock: Clock | None = None, port_name: str = "emulated",
                 *, model_timing: bool = True) -> None:
        super().__init__(port_name)
        self.bus = bus
        self.clock = clock if clock is not None else bus.clock
        self.model_timing = bool(model_timing)
        self._rx = bytearray()
        self._pending: deque[PendingReply] = deque()
        #: Bytes sent and received, for benchmarks.
        self.bytes_sent = 0
        self.bytes_received = 0

    # ---- PortHandler overrides -----------------------------------------------------------
    def setupPort(self, cflag_baud: int) -> bool:
        """Open the emulated port at ``self.baudrate`` (no device is touched)."""
        self.is_open = True
        self._rx.clear()
        self._pending.clear()
        self.tx_time_per_byte = (1000.0 / self.baudrate) * 10.0
        return True

    def closePort(self) -> None:
        """Close the port; bytes in flight are lost."""
        self.is_open = False
        self._rx.clear()
        self._pending.clear()

    def clearPort(self) -> None:
        """Discard received bytes and replies still to come (``reset_input_buffer``)."""
        self._rx.clear()
        self._pending.clear()

    def getBytesAvailable(self) -> int:
        """Bytes received and not yet read."""
        return len(self._rx)

    def getCurrentTime(self) -> float:
        """The shared clock in ms (PortHandler's unit for packet timeouts)."""
        return self.clock.monotonic() * 1000.0

    def writePort(self, packet) -> int:
        """Send ``packet`` to the bus; returns the number of bytes written (0 if closed)."""
        if not self.is_open:
            return 0
        data = bytes(packet)
        n = len(data)
        if self.model_timing:
            self.clock.sleep(n * (10.0 / self.baudrate))
        self.bytes_sent += n
        self._pending.extend(self.bus.receive(data, self.baudrate))
        return n

    def readPort(self, length: int) -> bytes:
        """Up to ``length`` received bytes; replies are sent (and time spent) as needed."""
        if not self.is_open:
            return b""
        rx, pending = self._rx, self._pending
        if 0 < length <= len(rx):  # the rest of a status already received (the usual 2nd read)
            out = bytes(rx[:length])
            del rx[:length]
            return out
        timed = self.model_timing
        sleep = self.clock.sleep
        while len(rx) < length and pending:
            reply = pending.popleft()
            if timed and reply.delay_s > 0:
                sleep(reply.delay_s)
            data = reply.produce()
            if data:
                if timed:
                    sleep(len(data) * (10.0 / self.baudrate))
                rx += data
                self.bytes_received += len(data)
        if not rx and not pending:
            # Nothing more will arrive: wait out the SDK's packet timeout on the clock.
            remaining_ms = self.packet_start_time + self.packet_timeout - self.getCurrentTime()
            self.clock.sleep(max(remaining_ms, 0.0) / 1000.0 + 1e-6)
            return b""
        out = bytes(rx[:length])
        del rx[:length]
        return out
