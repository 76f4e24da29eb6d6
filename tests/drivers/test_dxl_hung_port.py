"""A servo port that takes no more data: a write ends, named, within the write timeout.

dynamixel-sdk opens pyserial without a ``write_timeout`` (``port_handler.py``, ``setupPort``), so
a write to a port whose output buffer is full blocked for ever. A pseudo-terminal whose other
side nobody reads is such a port once its buffer is full.
"""

from __future__ import annotations

import os
import sys
import time
import tty

import pytest

from bench.attacks import fill_tty
from gyrocal.drivers.dynamixel.errors import ServoPortHungError
from gyrocal.drivers.dynamixel.gimbal import WRITE_TIMEOUT_S, _CheckedPort

pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux"),
                                reason="POSIX pseudo-terminals")


@pytest.fixture
def unread_pty():
    master, slave = os.openpty()
    tty.setraw(master)
    tty.setraw(slave)
    path = os.ttyname(slave)
    yield path
    os.close(master)
    os.close(slave)




def test_a_write_to_a_full_port_fails_named_within_the_timeout(unread_pty):
    port = _CheckedPort(unread_pty)
    assert port.openPort()
    try:
        assert fill_tty(unread_pty) > 0
        t0 = time.monotonic()
        with pytest.raises(ServoPortHungError, match="took no data for 0.5 s"):
            port.writePort([0xFF, 0xFF, 0xFD, 0x00, 0x01, 0x03, 0x00, 0x01, 0x19, 0x4E])
        waited = time.monotonic() - t0
        assert WRITE_TIMEOUT_S * 0.9 <= waited < WRITE_TIMEOUT_S + 2.0
        # what the stop does first: the port's unsent output dropped, a packet goes out again
        port.drop_output()
        assert port.writePort([0xFF, 0xFF, 0xFD, 0x00]) == 4
    finally:
        t0 = time.monotonic()
        port.closePort()
        assert time.monotonic() - t0 < 1.0
