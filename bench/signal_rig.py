"""A rig that ends ``gyrocal calibrate`` with signals at chosen moments and reads the servos back.

The servos are the kit's emulated X-series servos behind a pseudo-terminal (what ``gyrocal
emulate --pty`` serves), in this process; the kit runs its real servo path against them in a
subprocess (``gyrocal calibrate --sim-imu --port PTY``). A moment is "the K-th instruction packet
the servos receive": the signal is sent from the serving thread before that packet is answered,
so it lands inside a transaction, anywhere in ``Gimbal.open``, a turn, or the stop. Afterwards
the servos' state is read through an unmodified ``dynamixel_sdk.PortHandler`` on the PTY.

Used by ``tests/kit/test_signals.py`` and ``python -m bench faults``.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from dynamixel_sdk import COMM_SUCCESS, PacketHandler, PortHandler

from gyrocal.drivers.clock import SystemClock
from gyrocal.drivers.emulated.dxl import PtyServoBridge, make_servo_bus

__all__ = ["Outcome", "ServoRig", "write_config"]

#: Control-table addresses read back (hardware reference §5): Torque Enable, Bus Watchdog,
#: Moving, Present Velocity.
TORQUE_ENABLE, BUS_WATCHDOG, MOVING, PRESENT_VELOCITY = 64, 98, 122, 128
BAUD = 1_000_000
#: How long a read-back keeps asking a servo that does not answer, s.
READ_WITHIN_S = 10.0


@dataclass
class Outcome:
    """What one signalled run ended with."""

    returncode: int | None  # None: it hung (killed after the timeout)
    stderr: str
    packets: int  # instruction packets the servos received in all
    torque: dict[int, int | None] = field(default_factory=dict)  # read back; None: no answer
    fired: bool = False  # the signal was sent (the run reached the moment)
    #: The longest time between two instruction packets arriving while a servo's Bus Watchdog
    #: was armed, s, as the servos saw it (what their watchdog measures).
    armed_gap_s: float = 0.0
    #: The servos' Bus Watchdog and Present Velocity, from the emulator itself, at the moment
    #: the signal was sent (empty if it was not): what a kill -9 test needs to know it killed a
    #: moving, watched servo.
    at_fire: dict[str, dict[int, int]] = field(default_factory=dict)

    @property
    def torque_left_on(self) -> bool:
        """A servo answered the read-back with torque on: the kit left it on."""
        return any(v is not None and v != 0 for v in self.torque.values())

    @property
    def torque_unknown(self) -> bool:
        """A servo did not answer the read-back (the emulator, not the kit): torque unknown."""
        return any(v is None for v in self.torque.values())


def write_config(path: Path, port: str, ids: tuple[int, ...] = (1, 2, 3), *,
                 retries: int | None = None, watchdog_s: float | None = None) -> Path:
    """A ``gyrocal.toml`` for a short protocol on the PTY servos.

    ``retries`` and ``watchdog_s`` (``gimbal.*``; default: the kit's defaults) let a test on a
    loaded host absorb the emulated servos' lateness, which a real servo's own MCU does not
    have, without changing what the test checks of the kit.
    """
    axes = ["x", "y", "z"][: len(ids)]
    knobs = "".join(f"{k} = {v}\n" for k, v in (("retries", retries),
                                                  ("watchdog_s", watchdog_s)) if v is not None)
    path.write_text(
        "[gimbal]\n"
        f'port = "{port}"\nbaud = {BAUD}\nids = {list(ids)}\n'
        f"axes = {axes!r}\n".replace("'", '"')
        + knobs + "sample_hz = 100.0\n"
        '[protocol]\nname = "auto"\nspeed_dps = 180\nturns = 1\nrest_s = 0.3\n',  # no poses
        encoding="utf-8")
    return path


class ServoRig:
    """Emulated servos on a PTY that can signal a process at its K-th instruction packet."""

    def __init__(self, ids: tuple[int, ...] = (1, 2, 3), seed: int = 0,
                 kit_niceness: int = 0) -> None:
        #: Run the kit this much nicer than the servos' process (``bench servo_link``: the
        #: servos' own CPU must not starve with the host; real servos have their own MCU).
        self.kit_niceness = int(kit_niceness)
        self.ids = tuple(ids)
        self.bus = make_servo_bus(SystemClock(), self.ids, "XM430-W350", seed, baudrate=BAUD)
        self._handle = self.bus.handle
        self.bus.handle = self._count  # type: ignore[method-assign]
        self.bridge = PtyServoBridge(self.bus)
        self.path = self.bridge.start()
        self.packets = 0
        self.armed_gap_s = 0.0
        self._armed_since: float | None = None
        self._plan: list[tuple[int, int, float]] = []  # (packet, signal, delay after it)
        self._pid: int | None = None
        self.fired = threading.Event()
        self.at_fire: dict[str, dict[int, int]] = {}
        self._from_armed = False
        self._armed_packets = 0  # packets since a servo first turned with its watchdog armed
        self._watched_motion = False

    def close(self) -> None:
        """Stop serving."""
        self.bridge.stop()

    def _count(self, instr, baudrate=None):  # the bus's handle, counting
        self.packets += 1
        now = time.monotonic()
        if self._armed_since is not None:
            self.armed_gap_s = max(self.armed_gap_s, now - self._armed_since)
        if self._armed_packets or self._watched_motion:
            self._armed_packets += 1
        try:
            return self._serve(instr, baudrate)
        finally:
            armed = any(s.register("Bus Watchdog") > 0 for s in self.bus.servos)
            self._armed_since = now if armed else None
            self._watched_motion = any(s.register("Bus Watchdog") > 0
                                       and s.register("Present Velocity") != 0
                                       for s in self.bus.servos)

    def _serve(self, instr, baudrate):
        count = self._armed_packets if self._from_armed else self.packets
        ready = self._watched_motion or not self._from_armed
        while ready and self._plan and count >= self._plan[0][0] and self._pid is not None:
            _, sig, delay = self._plan.pop(0)
            if delay > 0:
                time.sleep(delay)
            self.at_fire = {name: {i: self.bus.servo(i).register(name) for i in self.ids}
                            for name in ("Bus Watchdog", "Present Velocity")}
            try:
                os.kill(self._pid, sig)
                self.fired.set()
            except ProcessLookupError:
                pass
        return self._handle(instr, baudrate)

    def read(self, address: int, size: int, within_s: float = READ_WITHIN_S
             ) -> dict[int, int | None]:
        """One control-table item of every servo, signed, through dynamixel-sdk on the PTY.

        Each servo is asked again until it answers or ``within_s`` has passed (a loaded host
        can starve the emulated servos past the SDK's ~34 ms status timeout); None: it never
        answered.
        """
        port = PortHandler(self.path)
        port.openPort()
        port.setBaudRate(BAUD)
        ph = PacketHandler(2.0)
        fn = {1: ph.read1ByteTxRx, 2: ph.read2ByteTxRx, 4: ph.read4ByteTxRx}[size]
        out: dict[int, int | None] = {}
        try:
            for i in self.ids:
                out[i] = None
                deadline = time.monotonic() + within_s
                while True:
                    value, result, error = fn(port, i, address)
                    if result == COMM_SUCCESS:
                        bits = 8 * size  # the SDK returns unsigned values (§6, point 5)
                        out[i] = int(value) - (1 << bits) * (int(value) >> (bits - 1))
                        break
                    if time.monotonic() >= deadline:
                        break
                    time.sleep(0.02)
                    port.clearPort()  # a late answer to the previous try must not be read
        finally:
            port.closePort()
        return out

    def wait_for(self, name: str, done: Callable[[dict[int, int]], bool],
                 within_s: float = 20.0) -> dict[int, int]:
        """Watch one item of every servo in the emulator itself until ``done(values)`` or
        ``within_s`` has passed; the last values (a test waits on the event, not a fixed sleep).

        No packet is sent: a read through the bus would restart the Bus Watchdog it waits on.
        The emulator applies a timed event (the watchdog's expiry) at its own deadline,
        whenever it is looked at.
        """
        deadline = time.monotonic() + within_s
        while True:
            got = {i: self.bus.servo(i).register(name) for i in self.ids}
            if done(got) or time.monotonic() >= deadline:
                return got
            time.sleep(0.05)

    def read_torque(self) -> dict[int, int | None]:
        """Torque Enable (64) of every servo."""
        return self.read(TORQUE_ENABLE, 1)

    def run(self, config: Path, out: Path, plan: list[tuple[int, int, float]], *,
            timeout_s: float = 120.0, extra: tuple[str, ...] = (),
            from_motion: bool = False) -> Outcome:
        """Run ``gyrocal calibrate --sim-imu`` and send ``plan``'s signals.

        Parameters
        ----------
        plan : list of (packet, signal, delay)
            Send ``signal`` when the servos receive instruction packet number ``packet`` of this
            run (counted from 1), after waiting ``delay`` s.
        from_motion : bool
            Count ``packet`` from the first packet a servo receives while it turns with its
            Bus Watchdog armed, not from the start, and send it only while one does: a SIGKILL
            then lands mid-motion, after the kit armed the watchdog, however slowly the host
            got there.
        """
        self.packets = 0
        self.armed_gap_s = 0.0
        self._armed_since = None
        self._armed_packets = 0
        self._watched_motion = False
        self._from_armed = from_motion
        self.at_fire = {}
        self.fired.clear()
        self._plan = sorted(plan)
        cmd = [sys.executable, "-m", "gyrocal.kit", "calibrate", "--sim-imu", "--config",
               str(config), "--out", str(out), "--quiet", *extra]
        nice = os.getpriority(os.PRIO_PROCESS, 0) + self.kit_niceness
        proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                                text=True, preexec_fn=lambda: os.setpriority(
                                    os.PRIO_PROCESS, 0, nice) if self.kit_niceness else None)
        self._pid = proc.pid
        try:
            _, err = proc.communicate(timeout=timeout_s)
            code: int | None = proc.returncode
        except subprocess.TimeoutExpired:
            proc.kill()
            _, err = proc.communicate()
            code = None
        finally:
            self._pid = None
            self._plan = []
        gap = self.armed_gap_s
        if code == -signal.SIGKILL:  # nothing of the kit's ran: leave the servos to their
            torque: dict[int, int | None] = {}  # watchdog (a read-back would restart it)
        else:
            torque = self.read_torque()
        return Outcome(code, err, self.packets, torque, self.fired.is_set(), gap,
                       dict(self.at_fire))


def expected_code(sig: int) -> int:
    """The exit code of a run ended by ``sig``."""
    return 128 + int(sig)


SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)
