"""Signals at any moment of a run end with every servo's torque off, the message and 128+signum.

The kit runs its real servo path (``calibrate --sim-imu``) in a subprocess against emulated
servos on a pseudo-terminal; the signal lands while the servos receive a chosen instruction packet
(inside ``Gimbal.open``, inside a turn, inside the stop); torque is read back through an
unmodified ``dynamixel_sdk.PortHandler``. The larger matrix is ``python -m bench faults``.
"""

from __future__ import annotations

import fcntl
import json
import os
import signal
import subprocess
import sys
import time

import pytest
from dynamixel_sdk import PortHandler

from bench.attacks import FrozenEmulator, freeze_when_turning, turning
from bench.signal_rig import BUS_WATCHDOG, PRESENT_VELOCITY, ServoRig, write_config

pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux"),
                                reason="POSIX pseudo-terminals and /proc/locks")


@pytest.fixture(scope="module")
def rig():
    r = ServoRig(ids=(1, 2))
    yield r
    r.close()


#: On a host loaded far beyond its cores the emulated servos (a thread of this process) can
#: answer later than dynamixel-sdk's ~34 ms status timeout, and the kit's polls can be later than
#: the default 0.3 s Bus Watchdog: either ended a run with exit 4 before its signal. Real servos
#: answer from their own MCU. More resends and the longest watchdog take the emulator's
#: lateness out of the verdict; what is checked of the kit (exit code, torque read back,
#: message, recording) is unchanged, and kill -9 still needs the watchdog to trip.
LOADED_HOST = {"retries": 30, "watchdog_s": 2.5}


@pytest.fixture
def config(rig, tmp_path):
    return write_config(tmp_path / "gyrocal.toml", rig.path, ids=rig.ids, **LOADED_HOST)


# (first signal, packet it lands on, second signal one packet later or None)
# Packet 2: the first servo's PING answered, nothing torqued yet; 12 and 25: inside
# Gimbal.open, between one servo's torque-on and the next's; 200: inside a turn.
CASES = [
    (signal.SIGTERM, 2, None),
    (signal.SIGHUP, 12, signal.SIGINT),
    (signal.SIGINT, 25, signal.SIGTERM),
    (signal.SIGTERM, 200, signal.SIGTERM),
]


@pytest.mark.parametrize(("sig", "packet", "second"), CASES)
def test_a_signal_at_any_moment_ends_with_torque_off(rig, config, tmp_path, sig, packet,
                                                     second):
    plan = [(packet, sig, 0.0)] + ([(packet + 1, second, 0.0)] if second else [])
    out = rig.run(config, tmp_path / "run", plan)
    assert out.fired
    assert out.returncode == 128 + sig, out.stderr  # the first signal decides
    assert out.torque == {i: 0 for i in rig.ids}
    assert "servos stopped, torque off" in out.stderr
    assert "Traceback" not in out.stderr
    rec = tmp_path / "run" / "recording" / "manifest.json"
    if packet < 100:  # still in open: nothing recorded, and the message does not claim it
        assert not rec.exists()
        assert "no recording was begun" in out.stderr
    else:
        assert json.loads(rec.read_text())["complete"] is False
        assert "is kept, marked incomplete" in out.stderr


def test_kill_9_mid_turn_the_bus_watchdog_stops_the_servo(rig, tmp_path):
    """No handler runs on SIGKILL: the servo's own Bus Watchdog (armed before the turn) stops
    it (hardware reference §5, address 98, 20 ms units). The kill is counted from the first
    packet after a servo started turning with its watchdog armed, so it lands mid-motion
    however loaded the host is. The watchdog is 1 s here, not :data:`LOADED_HOST`'s 2.5 s:
    the test waits for it to run out after the kill, and the kill lands about 20 polls into
    the first turn, so a late poll has little time to trip it first; 1 s is still over three
    times the kit's default (0.3 s)."""
    config = write_config(tmp_path / "gyrocal.toml", rig.path, ids=rig.ids,
                          **{**LOADED_HOST, "watchdog_s": 1.0})
    out = rig.run(config, tmp_path / "run", [(20, signal.SIGKILL, 0.0)], from_motion=True)
    assert out.returncode == -signal.SIGKILL
    # at the kill a servo was turning, watched by its armed watchdog
    at = out.at_fire
    assert any(v != 0 and at["Bus Watchdog"][i] > 0
               for i, v in at["Present Velocity"].items()), at
    # wait, bounded, for the event without sending a packet (one would restart the watchdog):
    # the armed watchdog expires (-1: it tripped, the host went silent)
    rig.wait_for("Bus Watchdog", lambda v: -1 in v.values(), within_s=20.0)
    assert -1 in rig.read(BUS_WATCHDOG, 1).values()  # read back through dynamixel-sdk
    zero = {i: 0 for i in rig.ids}  # and the servo decelerates to a stop
    rig.wait_for("Present Velocity", lambda v: v == zero, within_s=20.0)
    assert rig.read(PRESENT_VELOCITY, 4) == zero


def test_a_second_process_on_the_bus_is_refused_naming_the_first(rig, tmp_path):
    """flock on the device: the second run is refused and names the first one's PID."""
    config = write_config(tmp_path / "gyrocal.toml", rig.path, ids=rig.ids)
    holder = PortHandler(rig.path)
    holder.openPort()
    fcntl.flock(holder.ser.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
    try:
        r = subprocess.run([sys.executable, "-m", "gyrocal.kit", "calibrate", "--sim-imu",
                            "--config", str(config), "--out", str(tmp_path / "b"), "--quiet"],
                           capture_output=True, text=True, timeout=60)
    finally:
        holder.closePort()
    assert r.returncode == 4
    assert f"in use by process {os.getpid()}" in r.stderr
    assert "Traceback" not in r.stderr


def test_a_pulled_servo_adapter_exits_4_saying_torque_was_not_confirmed(tmp_path):
    """The PTY ends mid-turn, as a USB-serial adapter pulled out: every read, write and
    ``tcflush`` then fails with EIO (pyserial's SerialException, ``termios.error``). It was exit 1
    and a traceback from ``clearPort()`` in ``Gimbal.close()``."""
    rig = ServoRig(ids=(1, 2))
    try:
        config = write_config(tmp_path / "gyrocal.toml", rig.path, ids=rig.ids, **LOADED_HOST)
        proc = subprocess.Popen(
            [sys.executable, "-m", "gyrocal.kit", "calibrate", "--sim-imu", "--config",
             str(config), "--out", str(tmp_path / "run"), "--quiet"],
            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
        moving = rig.wait_for("Present Velocity", lambda v: any(v.values()), within_s=60.0)
        assert any(moving.values())
        rig.close()  # the adapter is gone, mid-turn
        _, err = proc.communicate(timeout=120)
    finally:
        rig.close()
    assert proc.returncode == 4, err
    assert "Traceback" not in err
    assert "could NOT confirm torque off on servo(s) 1, 2: the servo link is gone" in err
    assert "the USB adapter was unplugged" in err
    assert "is kept, marked incomplete" in err
    manifest = json.loads((tmp_path / "run" / "recording" / "manifest.json").read_text())
    assert manifest["complete"] is False


@pytest.mark.parametrize("hung", [False, True], ids=["frozen", "hung-port"])
def test_a_frozen_servo_link_mid_turn_exits_4_in_bounded_time(tmp_path, hung):
    """``gyrocal emulate --pty`` stopped with SIGSTOP mid-turn: the servos answer nothing
    (``frozen``), and with the PTY's buffer full as well the kit's next write blocks
    (``hung-port``: an adapter or driver that takes no more data). The hung port blocked the
    kit for ever before writes had a timeout, Ctrl-C included (the stop waited in the write)."""
    emulator = FrozenEmulator(ids=(1, 2))
    try:
        config = write_config(tmp_path / "gyrocal.toml", emulator.path, ids=emulator.ids,
                              **LOADED_HOST)
        run = tmp_path / "run"
        proc = subprocess.Popen(
            [sys.executable, "-m", "gyrocal.kit", "calibrate", "--sim-imu", "--config",
             str(config), "--out", str(run), "--quiet"],
            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
        freeze_when_turning(emulator, run / "recording", fill=hung).join(timeout=120)
        assert emulator.frozen_at is not None and turning(run / "recording")
        _, err = proc.communicate(timeout=120)
        after_freeze_s = time.monotonic() - emulator.frozen_at
    finally:
        if proc.poll() is None:
            proc.kill()
        emulator.close()
    assert proc.returncode == 4, err
    assert "Traceback" not in err
    # each transaction's retries (31 here) and the two stops (2 s each) bound it
    assert after_freeze_s < 60.0
    assert "could not confirm torque off on servo(s) 1, 2" in err
    assert "torque off confirmed" not in err
    if hung:
        assert f"the servo port {emulator.path!r} took no data for 0.5 s" in err
    assert "is kept, marked incomplete" in err
    assert json.loads((run / "recording" / "manifest.json").read_text())["complete"] is False
