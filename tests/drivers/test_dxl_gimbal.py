"""The gimbal driver against the emulated jig, through the real dynamixel-sdk.

Truth comes from the emulator's state (servo registers read directly, the jig's true rate) and
from quantities computed here, never from the driver's own answers.
"""

import math
import os
import signal

import numpy as np
import pytest

from gyrocal.drivers.clock import VirtualClock
from gyrocal.drivers.dynamixel import (
    Gimbal,
    OverloadError,
    ServoCommunicationError,
    ServoHardwareError,
    ServoIdentityError,
    ServoStatusError,
    ShutdownError,
    StallError,
    TerminatedBySignal,
    TurnLimitError,
    WatchdogTrippedError,
)
from gyrocal.drivers.dynamixel.control_table import VELOCITY_UNIT_RAD_S
from gyrocal.drivers.emulated.dxl import MotorParams, make_emulated_gimbal
from gyrocal.drivers.errors import CommunicationError, ConfigurationError, SafetyError

TWO_PI = 2 * math.pi


def emulated(seed=0, **kw):
    clock = VirtualClock()
    port, bus, jig = make_emulated_gimbal(clock, seed=seed, **kw)
    return clock, port, bus, jig


def all_torque_off(bus):
    return all(not s.torque_enabled() for s in bus.servos)


# ---- opening ------------------------------------------------------------------------------------
def test_open_identifies_servos_reads_limits_and_holds():
    clock, port, bus, _ = emulated(velocity_limit=180)
    with Gimbal(port, clock=clock) as g:
        assert sorted(g.infos) == [1, 2, 3]
        info = g.infos[2]
        assert (info.model_number, info.model_name, info.supported) == (1020, "XM430-W350", True)
        assert info.velocity_limit == pytest.approx(180 * 0.229 * TWO_PI / 60)
        assert info.no_load_speed == pytest.approx(46 * TWO_PI / 60)
        assert g.top_speed == pytest.approx(info.velocity_limit)
        assert info.voltage_v == pytest.approx(12.0) and info.temperature_c == 25
        assert g.notices == []
        for s in bus.servos:
            assert s.register("Operating Mode") == 4 and s.torque_enabled()
            assert s.register("Goal Position") == s.register("Present Position")
        np.testing.assert_array_equal(g.last_sample.angles, [0.0, 0.0, 0.0])
    assert all_torque_off(bus)


def test_a_compatible_model_is_accepted_with_a_notice_and_others_refused():
    clock, port, bus, _ = emulated()
    bus.servo(3).set_register("Model Number", 1030)  # XM430-W210: same table
    with Gimbal(port, clock=clock) as g:
        assert g.infos[3].model_name == "XM430-W210" and not g.infos[3].supported
        assert len(g.notices) == 1 and "XM430-W210" in g.notices[0]
    with pytest.raises(ServoIdentityError, match="accept_compatible=True"):
        Gimbal(port, clock=clock, accept_compatible=False).open()
    bus.servo(3).set_register("Model Number", 350)  # an XL-320
    with pytest.raises(ServoIdentityError, match=r"model number 350.*XM430-W350 \(1020\)"):
        Gimbal(port, clock=clock).open()
    assert all_torque_off(bus)


def test_a_missing_servo_is_named_with_the_baud_rate():
    clock, port, bus, _ = emulated()
    with pytest.raises(ServoIdentityError, match=r"servo ID 7 did not answer a PING at 1000000"):
        Gimbal(port, ids=(1, 2, 7), clock=clock).open()
    assert all_torque_off(bus)


def test_an_open_that_fails_half_way_stops_and_says_if_the_stop_is_unconfirmed():
    # Servo 3 answers its PING, then goes silent while the servos are prepared (servos 1 and 2
    # already hold with torque on). No with-block runs __exit__ for a failed open(), so open()
    # itself must stop every servo and report a stop it could not confirm.
    clock, port, bus, _ = emulated()
    bus.servo(3).go_silent(at=clock.monotonic() + 0.005)
    before = signal.getsignal(signal.SIGINT)
    with pytest.raises(
        ShutdownError,
        match=r"^[^(]*servo 3.*\. The safe stop then could not confirm torque off on servo\(s\) 3:",
    ) as info:
        with Gimbal(port, clock=clock):
            pass
    assert isinstance(info.value.__cause__, ServoCommunicationError)
    assert bus.servo(1).packets_received > 5  # it did get as far as preparing servo 1
    assert all_torque_off(bus)  # servo 3 still hears: the broadcast torque-off reached it
    assert signal.getsignal(signal.SIGINT) == before


def test_a_port_that_does_not_exist_is_a_clear_communication_error():
    with pytest.raises(CommunicationError, match="cannot open the servo port"):
        Gimbal("/dev/gyrocal-no-such-port", clock=VirtualClock()).open()


def test_bad_constructor_arguments_say_what_is_wrong():
    clock, port, _, _ = emulated()
    with pytest.raises(ConfigurationError, match="distinct"):
        Gimbal(port, ids=(1, 1), clock=clock)
    with pytest.raises(ConfigurationError, match="watchdog_s"):
        Gimbal(port, clock=clock, watchdog_s=10.0)
    with pytest.raises(ConfigurationError, match="baud rate 4500000"):
        Gimbal(port, clock=clock, baudrate=4_500_000).open()


# ---- motion and the encoder reference -----------------------------------------------------------
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_two_turns_at_1_rad_s_encoder_rate_matches_the_truth(seed):
    # Servos that hold exactly on their goal tick, so the kinematics can be checked exactly (a
    # holding servo resting anywhere in its tick would tilt the downstream axes by < 0.8 mrad).
    clock, port, bus, jig = emulated(seed=seed, motor_params=MotorParams(hold_band=0.0))
    samples = []
    with Gimbal(port, clock=clock) as g:
        m = g.run_turn(2, 2, 1.0, -1, on_sample=samples.append, poll_period_s=0.004)
        assert m.finished and m.speed == pytest.approx(round(1.0 / VELOCITY_UNIT_RAD_S)
                                                       * VELOCITY_UNIT_RAD_S)
        assert g.last_sample.angle(2) == pytest.approx(-2 * TWO_PI)
        assert bus.servo(2).register("Present Position") == g.home_ticks[2] - 2 * 4096
    t = np.array([s.t for s in samples])
    ang = np.array([s.angle(2) for s in samples])
    # the steady revolutions: after the ramp (+0.2 s) and before the deceleration (-0.2 s)
    ramp = m.speed / m.acceleration
    steady = (t > m.t_begin + ramp + 0.2) & (t < m.t_end - ramp - 0.5)
    ia, ib = np.flatnonzero(steady)[[0, -1]]
    assert abs(ang[ib] - ang[ia]) > 1.5 * TWO_PI
    encoder_rate = (ang[ib] - ang[ia]) / (t[ib] - t[ia])
    # truth: the jig's true sensor rate over exactly the same window, integrated exactly
    dt = bus.servo(2).motor.dt
    edges = np.r_[t[ia], np.arange(math.floor(t[ia] / dt) + 1, math.ceil(t[ib] / dt)) * dt, t[ib]]
    w = jig.rate(0.5 * (edges[:-1] + edges[1:]))
    mean_w = (w * np.diff(edges)[:, None]).sum(axis=0) / (t[ib] - t[ia])
    axis = jig.home_axes[2]
    assert abs(mean_w @ axis) / np.linalg.norm(mean_w) > 1 - 1e-9  # about the expected axis
    assert np.linalg.norm(mean_w - (mean_w @ axis) * axis) < 1e-9
    assert encoder_rate == pytest.approx(mean_w @ axis, rel=1e-4)  # ...at the encoder's rate
    assert encoder_rate == pytest.approx(-m.speed, rel=5e-3)


def test_return_home_and_watchdog_armed_only_while_moving():
    clock, port, bus, _ = emulated(seed=4)
    with Gimbal(port, clock=clock, watchdog_s=0.1) as g:
        g.begin_turn(1, 1, 2.0, +1)
        seen = []
        while g.busy:
            g.poll()
            seen.append(bus.servo(1).register("Bus Watchdog"))
            clock.sleep(0.005)
        assert seen[0] == 5 and seen[-1] == 0
        g.run_turn(3, 2, 3.0, -1)
        assert g.last_sample.angle(1) == pytest.approx(TWO_PI)
        m = g.return_home(speed=2.5)
        assert m.kind == "return" and set(m.servo_ids) == {1, 2, 3}
        np.testing.assert_array_equal(g.last_sample.angles, [0.0, 0.0, 0.0])
        for i in (1, 2, 3):
            assert bus.servo(i).register("Present Position") == g.home_ticks[i]
            assert bus.servo(i).register("Bus Watchdog") == 0


def test_sample_is_timestamped_mid_transaction_and_unwraps_realtime_tick():
    clock, port, bus, _ = emulated()
    with Gimbal(port, clock=clock) as g:
        s0 = g.sample()
        assert s0.t_start < s0.t < s0.t_end and s0.t == pytest.approx(0.5 * (s0.t_start + s0.t_end))
        for _ in range(40):  # 40 s: Realtime Tick wraps at 32.768 s
            clock.sleep(1.0)
            g.sample()
        s1 = g.sample()
        elapsed_ms = (s1.servo_time_ms - s0.servo_time_ms)
        np.testing.assert_allclose(elapsed_ms, (s1.t - s0.t) * 1000, atol=2.0)
        # 70 s without a read: the tick wraps twice, which only the host clock can tell
        clock.sleep(70.0)
        s2 = g.sample()
        np.testing.assert_allclose(s2.servo_time_ms - s1.servo_time_ms, (s2.t - s1.t) * 1000,
                                   atol=2.0)


@pytest.mark.parametrize(("layout", "fast"), [("position", False), ("position", True),
                                              ("motion", True)])
def test_other_sample_layouts_and_fast_sync_read(layout, fast):
    clock, port, bus, _ = emulated(seed=3)
    with Gimbal(port, clock=clock, sample_layout=layout, fast_sync_read=fast) as g:
        m = g.run_turn(1, 1, 2.0, -1)
        assert m.finished
        assert bus.servo(1).register("Present Position") == g.home_ticks[1] - 4096
        assert g.last_sample.angle(1) == pytest.approx(-TWO_PI)
        assert (g.last_sample.velocities is None) == (layout == "position")


def test_motion_arguments_are_checked():
    clock, port, bus, _ = emulated()
    with Gimbal(port, clock=clock) as g:
        with pytest.raises(ConfigurationError, match="top speed"):
            g.begin_turn(1, 1, 50.0)
        with pytest.raises(ConfigurationError, match="whole number"):
            g.begin_turn(1, 1.5, 1.0)
        with pytest.raises(ConfigurationError, match="direction"):
            g.begin_turn(1, 1, 1.0, 0)
        with pytest.raises(ConfigurationError, match="not on this gimbal"):
            g.begin_turn(9, 1, 1.0)
        g.begin_turn(1, 1, 1.0)
        with pytest.raises(SafetyError, match="still running"):
            g.begin_turn(2, 1, 1.0)


def test_the_turn_limit_refuses_a_turn_and_stops_a_servo_found_beyond_it():
    clock, port, bus, _ = emulated(seed=5)
    with pytest.raises(TurnLimitError, match="cable-wrap limit of 2 turns"):
        with Gimbal(port, clock=clock, max_turns=2.0) as g:
            g.run_turn(1, 2, 4.0, +1)
            goal_before = bus.servo(1).register("Goal Position")
            try:
                g.begin_turn(1, 1, 4.0, +1)
            finally:
                assert bus.servo(1).register("Goal Position") == goal_before
    assert all_torque_off(bus)
    clock, port, bus, _ = emulated(seed=5)
    with Gimbal(port, clock=clock, max_turns=2.0) as g:
        s = bus.servo(3)  # something turns servo 3 behind the driver's back
        item = s.table["Goal Position"]
        s.write(item.address, item.to_bytes(g.home_ticks[3] + int(2.2 * 4096)))
        clock.sleep(4.0)
        with pytest.raises(TurnLimitError, match=r"servo 3 is 2\.\d+ turns from home"):
            g.poll()
        assert all_torque_off(bus)


# ---- faults -------------------------------------------------------------------------------------
def test_dropped_and_corrupted_statuses_are_retried():
    clock, port, bus, _ = emulated()
    with Gimbal(port, clock=clock, retries=3) as g:
        before = g.retry_count
        bus.servo(2).drop_replies(2)
        bus.servo(3).corrupt_replies(1)
        s = g.sample()
        assert g.retry_count - before >= 2
        assert bus.servo(2).replies_dropped == 2 and bus.servo(3).replies_corrupted == 1
        assert [int(x) for x in s.ticks] == [bus.servo(i).register("Present Position")
                                            for i in (1, 2, 3)]
        bus.servo(1).drop_probability = 0.2
        m = g.run_turn(1, 1, 3.0, +1)
        assert m.finished and bus.servo(1).replies_dropped > 0


@pytest.mark.parametrize(("knob", "text"), [
    ("drop_replies", "There is no status packet"),
    ("corrupt_replies", "Incorrect status packet"),
])
def test_persistent_failures_name_servo_instruction_and_sdk_text(knob, text):
    clock, port, bus, _ = emulated()
    with pytest.raises(ServoCommunicationError) as info:
        with Gimbal(port, clock=clock, retries=2) as g:
            getattr(bus.servo(3), knob)(3)
            g.sample()
    err = info.value
    assert err.servo_id == 3 and err.attempts == 3 and "SYNC_READ" in err.instruction
    assert text in str(err) and "servo 3" in str(err)
    assert all_torque_off(bus)


def test_a_servo_that_stops_answering_mid_turn():
    clock, port, bus, _ = emulated(seed=6)
    with pytest.raises(
        ShutdownError,
        match=r"^SYNC_READ.*servo 2.*safe stop then could not confirm torque off on servo\(s\) 2:",
    ) as info:
        with Gimbal(port, clock=clock) as g:
            g.begin_turn(2, 2, 1.0)
            bus.servo(2).go_silent(at=clock.monotonic() + 1.0)
            while True:
                g.poll()
                clock.sleep(0.005)
    cause = info.value.__cause__
    assert isinstance(cause, ServoCommunicationError)
    # the stop poll() tried at once failed too, and the error says so
    assert any("safe stop after this error failed" in n for n in getattr(cause, "__notes__", []))
    # the broadcast torque-off reached the silent servo too: every servo is off
    assert all_torque_off(bus)


def test_the_stop_retries_until_a_lost_torque_off_is_confirmed():
    """A servo that misses the stop's first write and read-back (a starved host, a noise
    burst: more lost replies than one transaction's retries) is asked again, and the stop
    confirms torque off by reading it back instead of giving up."""
    clock, port, bus, _ = emulated(seed=8)
    with Gimbal(port, clock=clock, retries=1) as g:
        g.begin_turn(2, 2, 1.0)
        for _ in range(20):
            g.poll()
            clock.sleep(0.005)
        bus.servo(2).drop_replies(5)  # 2 attempts per transaction: the first round fails
        g.stop()  # no ShutdownError: the next round confirms
        assert bus.servo(2).replies_dropped == 5
        assert all_torque_off(bus)
        assert all(s.register("Bus Watchdog") == 0 for s in bus.servos)


def test_a_stop_that_cannot_confirm_gives_up_within_its_bound_and_says_what_to_do():
    from gyrocal.drivers.dynamixel.gimbal import STOP_CONFIRM_S

    clock, port, bus, _ = emulated(seed=9)
    g = Gimbal(port, clock=clock, retries=1)
    g.open()
    bus.servo(3).go_silent(deaf=True)  # a cut cable: it neither hears nor answers
    t0 = clock.monotonic()
    with pytest.raises(ShutdownError) as info:
        g.close()
    spent = clock.monotonic() - t0
    assert STOP_CONFIRM_S <= spent < STOP_CONFIRM_S + 1.0  # bounded, and not given up at once
    text = str(info.value)
    assert "could not confirm torque off on servo(s) 3:" in text
    assert "Switch the servo power off" in text and "time(s) within" in text
    assert bus.servo(3).torque_enabled()  # the truth: it is on, and the error says so
    assert not bus.servo(1).torque_enabled() and not bus.servo(2).torque_enabled()


@pytest.mark.parametrize(("cause", "name"), [(KeyboardInterrupt(), "SIGINT"),
                                             (TerminatedBySignal(signal.SIGTERM), "SIGTERM")])
def test_a_signal_whose_stop_cannot_confirm_says_so_instead_of_claiming_torque_off(cause, name):
    clock, port, bus, _ = emulated(seed=10)
    with pytest.raises(ShutdownError) as info:
        with Gimbal(port, clock=clock, retries=1):
            bus.servo(2).go_silent(deaf=True)
            raise cause
    assert str(info.value).startswith(
        f"Stopping on {name}. The safe stop then could not confirm torque off on servo(s) 2:")
    assert isinstance(info.value.__cause__, type(cause))
    assert bus.servo(2).torque_enabled() and not bus.servo(1).torque_enabled()


def test_a_hardware_alert_is_raised_by_name_and_everything_stops():
    clock, port, bus, _ = emulated(seed=7)
    with pytest.raises(OverloadError) as info:
        with Gimbal(port, clock=clock) as g:
            g.begin_turn(1, 2, 1.0)
            bus.servo(1).raise_alert_at(clock.monotonic() + 2.0, bits=1 << 5)
            while True:
                g.poll()
                clock.sleep(0.005)
    err = info.value
    assert isinstance(err, ServoHardwareError) and err.servo_id == 1 and err.status == 0x20
    assert "overload" in str(err) and "reboot" in str(err).lower()
    assert all_torque_off(bus)


@pytest.mark.parametrize(("bits", "name"), [(1 << 0, "input voltage"), (1 << 2, "overheating"),
                                            (1 << 3, "motor encoder"),
                                            (1 << 4, "electrical shock")])
def test_each_hardware_error_bit_has_its_named_error(bits, name):
    clock, port, bus, _ = emulated()
    g = Gimbal(port, clock=clock)
    g.open()
    bus.servo(3).raise_alert_at(clock.monotonic(), bits=bits)
    with pytest.raises(ServoHardwareError, match=name) as info:
        g.poll()
    assert info.value.bit == int(math.log2(bits))
    assert all_torque_off(bus)
    # a servo with a latched error is refused at open until it is rebooted
    g.close()
    with pytest.raises(ServoHardwareError):
        Gimbal(port, clock=clock).open()
    bus.servo(3).reboot()
    clock.sleep(bus.servo(3).reboot_time_s)  # it hears nothing while it boots
    with Gimbal(port, clock=clock) as g2:
        assert g2.infos[3].model_number == 1020


def test_reboot_clears_an_error_and_rehomes():
    clock, port, bus, _ = emulated()
    with Gimbal(port, clock=clock) as g:
        bus.servo(2).raise_alert_at(clock.monotonic(), bits=1 << 5)
        with pytest.raises(OverloadError):
            g.poll()
        g.reboot(2)
        assert bus.servo(2).register("Hardware Error Status") == 0
        assert bus.servo(2).torque_enabled()
        assert g.run_turn(2, 1, 2.0).finished


def test_a_stall_is_detected_and_the_servos_stopped():
    clock, port, bus, _ = emulated(seed=8)
    with pytest.raises(StallError, match=r"servo 3 turns at 0\.\d+ rad/s but was commanded 1\.0"):
        with Gimbal(port, clock=clock) as g:
            g.begin_turn(3, 2, 1.0)
            bus.servo(3).stall_at(clock.monotonic() + 2.0, speed_fraction=0.4)
            while True:
                g.poll()
                clock.sleep(0.005)
    assert all_torque_off(bus)


@pytest.mark.parametrize("fraction", [0.0, 0.5])
def test_a_stall_of_one_servo_among_several_turning_at_once_is_detected(fraction):
    # verify's general motion: three servos at three speeds; the middle one (its own speed
    # 0.62 rad/s, below the others' top speed of 1.0) stalls to `fraction` of it. The check must
    # use each servo's own speed: at 0.5 of 0.62 rad/s it still turns faster than 0.8 × 0.38.
    clock, port, bus, _ = emulated(seed=8)
    with pytest.raises(StallError, match=r"servo 2 turns at 0\.\d+ rad/s but was commanded "
                                         r"0\.6\d+ rad/s"):
        with Gimbal(port, clock=clock) as g:
            g.begin_turns({1: (1, 1.0, 1), 2: (1, 0.62, -1), 3: (1, 0.38, 1)})
            assert g.motion.speeds[2] == pytest.approx(0.62, abs=0.025)
            bus.servo(2).stall_at(clock.monotonic() + 2.0, speed_fraction=fraction)
            for _ in range(6000):  # 30 s of polls: the turns take 17 s unstalled
                g.poll()
                clock.sleep(0.005)
    assert all_torque_off(bus)


def test_several_servos_turning_at_their_own_speeds_are_not_taken_for_a_stall():
    clock, port, bus, _ = emulated(seed=8)
    with Gimbal(port, clock=clock) as g:
        m = g.begin_turns({1: (1, 1.0, 1), 2: (1, 0.62, -1), 3: (1, 0.38, 1)})
        while not m.finished:
            g.poll()
            clock.sleep(0.005)
        assert m.t_end - m.t_begin > 2 * math.pi / 0.38


def test_a_late_host_trips_the_bus_watchdog():
    clock, port, bus, _ = emulated(seed=9)
    with pytest.raises(WatchdogTrippedError, match="Bus Watchdog expired"):
        with Gimbal(port, clock=clock, watchdog_s=0.1) as g:
            g.begin_turn(1, 2, 1.0)
            g.poll()
            clock.sleep(1.0)  # the host hangs for a second
            g.poll()
    s = bus.servo(1)
    assert all_torque_off(bus)
    # the servo stopped where the watchdog tripped, far from its goal
    assert abs(s.register("Present Position") - s.register("Goal Position")) > 4096


def test_access_error_without_data_is_an_error_not_an_index_error_or_a_zero():
    clock, port, bus, _ = emulated()
    with Gimbal(port, clock=clock) as g:
        with pytest.raises(ServoStatusError, match="servo 1 refused READ.*not available"):
            g._read_raw(1, 700, 4, "READ past the table")


def test_status_report_for_doctor():
    clock, port, bus, _ = emulated()
    with Gimbal(port, clock=clock) as g:
        g.begin_turn(1, 2, 1.5)
        for _ in range(300):
            g.poll()
            clock.sleep(0.005)
        st = g.read_status()
        assert st[1].moving and st[1].velocity == pytest.approx(1.5, rel=0.15)
        assert not st[2].moving and st[2].velocity == 0
        assert st[1].voltage_v == pytest.approx(12.0, abs=0.5)
        assert st[3].temperature_c == 25 and st[3].hardware_error == 0
        assert all(st[i].torque_enabled and not st[i].bus_watchdog_tripped for i in (1, 2, 3))
        assert st[2].angle == 0.0 and 1.0 < st[1].angle < 4 * math.pi


# ---- signals ------------------------------------------------------------------------------------
@pytest.mark.parametrize(("sig", "exc"), [(signal.SIGINT, KeyboardInterrupt),
                                          (signal.SIGTERM, TerminatedBySignal)])
def test_signals_end_with_every_servo_stopped(sig, exc):
    clock, port, bus, _ = emulated()
    for s in bus.servos:  # a goal velocity left over from another program: the stop zeroes it
        s.set_register("Goal Velocity", 50)
    before = signal.getsignal(sig)
    with pytest.raises(exc) as info:
        with Gimbal(port, clock=clock) as g:
            g.begin_turn(2, 2, 1.0)
            for k in range(1000):
                g.poll()
                clock.sleep(0.005)
                if k == 100:
                    os.kill(os.getpid(), sig)
    assert all_torque_off(bus)
    assert all(s.register("Goal Velocity") == 0 for s in bus.servos)
    assert signal.getsignal(sig) == before
    if sig == signal.SIGTERM:
        assert info.value.code == 143
