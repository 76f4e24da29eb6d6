"""One process per servo bus: an exclusive lock on the serial device, the Linux way.

Two programs writing to one Dynamixel bus garble each other's packets and can each believe the
servos are in a state the other changed. :func:`lock_device` takes ``flock(LOCK_EX | LOCK_NB)`` on
the open device (what pyserial's ``exclusive=True`` does, and what ``flock(1)`` and ModemManager
honour): the kernel drops it when the process ends, however it ends, so no stale lock file can
block the next run. A second process is refused with a :class:`BusInUseError` that names the
holder, found in ``/proc/locks`` by the device's inode.
"""

from __future__ import annotations

import fcntl
import os
from pathlib import Path

from gyrocal.drivers.errors import CommunicationError

__all__ = ["BusInUseError", "holder_of", "lock_device"]


class BusInUseError(CommunicationError):
    """Another process holds the servo bus."""


def _describe(pid: int) -> str:
    try:
        raw = Path(f"/proc/{pid}/cmdline").read_bytes()[:200]
    except OSError:
        return f"process {pid}"
    cmd = " ".join(a.decode("utf-8", "replace") for a in raw.split(b"\0") if a)
    return f"process {pid} ({cmd})" if cmd else f"process {pid}"


def holder_of(fd: int) -> int | None:
    """The PID that holds an flock on the file open as ``fd`` (Linux ``/proc/locks``), or None."""
    st = os.fstat(fd)
    dev = f"{os.major(st.st_dev):02x}:{os.minor(st.st_dev):02x}:{st.st_ino}"
    try:
        lines = Path("/proc/locks").read_text(encoding="ascii", errors="replace").splitlines()
    except OSError:
        return None
    for line in lines:
        parts = line.split()
        # "1: FLOCK  ADVISORY  WRITE 1234 00:05:87 0 EOF"; blocked waiters are marked "->"
        if len(parts) >= 6 and parts[1] == "FLOCK" and parts[5] == dev:
            try:
                return int(parts[4])
            except ValueError:
                continue
    return None


def lock_device(fd: int, name: str) -> None:
    """Take the exclusive lock on an open serial device, or refuse naming its holder.

    Parameters
    ----------
    fd : int
        The open device's file descriptor.
    name : str
        The device's name, for the message.

    Raises
    ------
    BusInUseError
        If another process holds it.
    """
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        pid = holder_of(fd)
        who = _describe(pid) if pid is not None else "another process"
        raise BusInUseError(
            f"the servo bus {name!r} is in use by {who}: two programs cannot drive one bus. "
            "Wait for it to finish or stop it (Ctrl-C), then run again.") from None
    except OSError:
        pass  # a device without flock support: nothing to lock with
