"""The emulated servo's behaviour against datasheet facts and physics computed in the tests."""

import math

import numpy as np
import pytest

from gyrocal.drivers.clock import VirtualClock
from gyrocal.drivers.dynamixel.control_table import (
    ACCELERATION_UNIT_RAD_S2,
    POSITION_UNIT_RAD,
    VELOCITY_UNIT_RAD_S,
)
from gyrocal.drivers.emulated.dxl import EmulatedServo, MotorParams
from gyrocal.drivers.emulated.dxl.motor import plan_position

TWO_PI = 2 * math.pi


def servo(**kw):
    clock = VirtualClock()
    s = EmulatedServo(1, kw.pop("model", "XM430-W350"), clock=clock, seed=kw.pop("seed", 7), **kw)
    return clock, s


def w(s, name, value):
    item = s.table[name]
    err = s.write(item.address, item.to_bytes(value))
    return err


def test_a_position_move_rests_somewhere_within_its_goal_tick():
    # The position loop stops once Present Position reads the goal: the shaft ends within that
    # tick, not on its centre (MotorParams.hold_band), and the encoder reads the goal exactly.
    offsets = []
    for seed in range(12):
        clock, s = servo(seed=seed)
        assert w(s, "Operating Mode", 4) == 0  # extended position
        w(s, "Profile Velocity", 100)
        w(s, "Profile Acceleration", 50)
        w(s, "Torque Enable", 1)
        goal = s.register("Present Position") + 4096
        w(s, "Goal Position", goal)
        run(clock, s, 6.0)
        assert s.register("Present Position") == goal
        angle, rate = s.true_motion(np.array([clock.monotonic()]))
        true_ticks = s._abs0 + angle[0] / POSITION_UNIT_RAD  # the shaft, in encoder ticks
        offsets.append(true_ticks - round(true_ticks))
        assert abs(rate[0]) < 1e-9
    offsets = np.array(offsets)
    assert np.all(np.abs(offsets) <= 0.5) and offsets.std() > 0.1


def test_at_power_up_the_shaft_rests_anywhere_within_the_tick_it_reads():
    # A real shaft is not parked on a tick's centre when the servo powers up: the first still
    # angle of a run errs by up to half a tick, like every later one.
    offsets = []
    for seed in range(12):
        clock, s = servo(seed=seed)
        angle, _ = s.true_motion(np.array([clock.monotonic()]))
        true_ticks = s._abs0 + angle[0] / POSITION_UNIT_RAD
        assert s.register("Present Position") % 4096 == round(true_ticks) % 4096
        offsets.append(true_ticks - round(true_ticks))
    offsets = np.array(offsets)
    assert np.all(np.abs(offsets) <= 0.5) and offsets.std() > 0.1
    clock, s = servo(initial_ticks=1000)  # a given reading puts the shaft on its centre
    assert s.register("Present Position") == 1000 and s._abs0 == 1000.0


def run(clock, s, seconds, step=0.01):
    """Advance the clock, reading the servo now and then as a host would."""
    end = clock.monotonic() + seconds
    while clock.monotonic() < end:
        clock.sleep(step)
        s.register("Present Position")


def test_a_shaft_already_on_its_goal_tick_does_not_move_when_torque_comes_on():
    # Torque on with Goal Position = Present Position (what a host does before every motion,
    # hardware reference §6.1), or a write that leaves the goal where it is, must not move the
    # shaft within its tick: a real position loop has nothing to correct.
    clock, s = servo(seed=3)
    assert w(s, "Operating Mode", 4) == 0
    w(s, "Profile Velocity", 100)
    w(s, "Profile Acceleration", 50)
    w(s, "Goal Position", s.register("Present Position"))
    for step in ("power-up", "after a move"):
        if step == "after a move":
            w(s, "Goal Position", s.register("Present Position") + 4096)
            run(clock, s, 6.0)
            w(s, "Torque Enable", 0)
        t0 = clock.monotonic()
        rest = s.true_motion(np.array([t0]))[0][0]
        w(s, "Torque Enable", 1)
        w(s, "Goal Velocity", 0)  # ignored in position modes
        run(clock, s, 0.5)
        angle, rate = s.true_motion(np.linspace(t0, clock.monotonic(), 500))
        np.testing.assert_allclose(angle, rest, rtol=0, atol=1e-12, err_msg=step)
        assert np.all(np.abs(rate) < 1e-9), step


def test_trapezoidal_profile_ends_exactly_on_goal_with_the_datasheet_timing():
    clock, s = servo(motor_params=MotorParams(hold_band=0.0))
    assert w(s, "Operating Mode", 4) == 0
    assert w(s, "Torque Enable", 1) == 0
    v_units, a_units = 42, 10
    v, a = v_units * VELOCITY_UNIT_RAD_S, a_units * ACCELERATION_UNIT_RAD_S2
    start = s.register("Present Position")
    t0 = clock.monotonic()
    assert w(s, "Profile Acceleration", a_units) == 0
    assert w(s, "Profile Velocity", v_units) == 0
    assert w(s, "Goal Position", start + 2 * 4096) == 0
    plan = s.motor.plan
    assert plan.kind == "trapezoidal"
    distance = 2 * TWO_PI
    assert plan.end_time - t0 == pytest.approx(distance / v + v / a, abs=2e-3)
    run(clock, s, distance / v + v / a + 0.5)
    assert s.register("Present Position") == start + 2 * 4096
    assert s.register("Moving") == 0
    assert s.register("Moving Status") & 0x01  # in position


def test_the_angle_is_the_exact_integral_of_the_rate():
    clock, s = servo()
    w(s, "Operating Mode", 1)
    w(s, "Torque Enable", 1)
    w(s, "Profile Acceleration", 20)
    w(s, "Goal Velocity", 60)
    run(clock, s, 3.0)
    rng = np.random.default_rng(3)
    dt = s.motor.dt
    for _ in range(20):
        a, b = np.sort(rng.uniform(0.1, 2.9, 2))
        # the rate is constant on each grid cell: integrate it piece by piece
        edges = np.r_[a, np.arange(math.floor(a / dt) + 1, math.ceil(b / dt)) * dt, b]
        mids = 0.5 * (edges[:-1] + edges[1:])
        _, rate = s.true_motion(mids)
        integral = float(np.sum(rate * np.diff(edges)))
        angles, _ = s.true_motion(np.array([a, b]))
        assert integral == pytest.approx(angles[1] - angles[0], rel=1e-10, abs=1e-12)


def test_speed_ripple_is_about_five_percent_with_a_gear_mesh_component():
    clock, s = servo()
    w(s, "Operating Mode", 1)
    w(s, "Torque Enable", 1)
    units = 42  # ≈ 1.007 rad/s
    w(s, "Goal Velocity", units)
    run(clock, s, 12.0, step=0.05)
    t = np.arange(2.0, 12.0, 1e-3)
    angle, rate = s.true_motion(t)
    v = units * VELOCITY_UNIT_RAD_S
    rel = rate / v - 1
    assert 0.015 < np.std(rel) < 0.05
    assert np.max(np.abs(rel)) < 0.15
    # mean speed over whole revolutions is the commanded one (the position loop keeps it)
    assert (angle[-1] - angle[0]) / (t[-1] - t[0]) == pytest.approx(v, rel=2e-3)
    # a periodic component at the output gear mesh (29 per turn), ~2 % of the speed
    phase = 29 * angle
    amp = 2 * np.hypot(np.mean(rel * np.sin(phase)), np.mean(rel * np.cos(phase)))
    assert 0.01 < amp < 0.03


def test_present_velocity_is_in_0229_rpm_units():
    clock, s = servo(motor_params=MotorParams(ripple=(), noise_fraction=0.0))
    w(s, "Operating Mode", 1)
    w(s, "Torque Enable", 1)
    w(s, "Goal Velocity", -120)
    run(clock, s, 1.0)
    assert s.register("Present Velocity") == -120
    _, rate = s.true_motion(np.array([clock.monotonic()]))
    assert rate[0] == pytest.approx(-120 * 0.229 * TWO_PI / 60, rel=1e-6)


def test_realtime_tick_counts_ms_and_wraps_at_32768():
    clock, s = servo()
    clock.sleep(32.767)
    assert s.register("Realtime Tick") == 32767
    clock.sleep(0.0015)
    assert s.register("Realtime Tick") == 0
    clock.sleep(1.0)
    assert s.register("Realtime Tick") == 1000


def test_temperature_rises_slowly_under_load_only():
    clock, s = servo()
    clock2, idle = servo(seed=8)
    w(s, "Operating Mode", 1)
    w(s, "Torque Enable", 1)
    w(s, "Goal Velocity", 200)
    for _ in range(60):
        run(clock, s, 10.0, step=1.0)
        clock2.sleep(10.0)
        idle.register("Present Temperature")
    assert s.register("Present Temperature") > 30
    assert idle.register("Present Temperature") == 25


def test_bus_watchdog_stops_a_servo_whose_host_went_quiet():
    clock, s = servo()
    w(s, "Operating Mode", 1)
    w(s, "Bus Watchdog", 5)  # 100 ms
    w(s, "Torque Enable", 1)
    w(s, "Goal Velocity", 50)
    for _ in range(10):  # the host talks every 50 ms: fine
        clock.sleep(0.05)
        s.note_instruction(clock.monotonic())
    assert s.register("Bus Watchdog") == 5
    clock.sleep(0.5)  # host silent
    assert s.register("Bus Watchdog") == -1
    assert s.register("Present Velocity") == 0
    from gyrocal.drivers.emulated.dxl.protocol import ERR_DATA_RANGE
    assert w(s, "Goal Velocity", 10) == ERR_DATA_RANGE
    assert w(s, "Bus Watchdog", -1) == ERR_DATA_RANGE  # it reads -1; a host may write 0..127
    assert w(s, "Bus Watchdog", 0) == 0
    assert w(s, "Goal Velocity", 10) == 0


def test_mode_switch_resets_profile_and_position_mode_rebases_the_turn_count():
    clock, s = servo(initial_ticks=100)
    w(s, "Operating Mode", 4)
    w(s, "Profile Velocity", 100)
    w(s, "Torque Enable", 1)
    w(s, "Goal Position", 100 + 3 * 4096 + 50)
    run(clock, s, 10.0)
    assert s.register("Present Position") == 100 + 3 * 4096 + 50
    w(s, "Torque Enable", 0)
    w(s, "Operating Mode", 1)  # velocity mode keeps the multi-turn count (§5.2)
    assert s.register("Profile Velocity") == 0
    assert s.register("Present Position") == 100 + 3 * 4096 + 50
    w(s, "Operating Mode", 3)  # to position mode: re-based into one turn
    assert s.register("Present Position") == 150


def test_eeprom_writes_need_torque_off():
    clock, s = servo()
    w(s, "Torque Enable", 1)
    from gyrocal.drivers.emulated.dxl.protocol import ERR_ACCESS
    assert w(s, "Velocity Limit", 100) == ERR_ACCESS
    assert w(s, "Torque Enable", 0) == 0
    assert w(s, "Velocity Limit", 100) == 0


def test_a_stall_slows_the_motor_and_can_end_in_an_overload_alert():
    clock, s = servo()
    w(s, "Operating Mode", 1)
    w(s, "Torque Enable", 1)
    w(s, "Goal Velocity", 100)
    run(clock, s, 1.0)
    s.stall_at(clock.monotonic(), speed_fraction=0.5, overload_after_s=2.0)
    run(clock, s, 1.0)
    assert s.register("Present Velocity") == pytest.approx(50, abs=8)
    run(clock, s, 1.5)
    assert s.register("Hardware Error Status") == 0x20
    assert not s.torque_enabled()
    assert s.error_byte() & 0x80


def test_profile_planner_handles_a_goal_change_in_motion():
    # moving at 2 rad/s toward +10, the goal is changed to -1: stop, then come back
    plan = plan_position(0.0, 0.0, 2.0, -1.0, 1.5, 4.0)
    t = np.linspace(0, plan.end_time, 20001)
    p, v = plan.evaluate(t)
    assert p[-1] == pytest.approx(-1.0)
    assert v[-1] == pytest.approx(0.0, abs=1e-9)
    assert np.max(np.abs(v)) <= 2.0 + 1e-9
    assert np.max(np.abs(np.diff(v))) < 4.0 * (t[1] - t[0]) * 1.01  # |a| <= 4 rad/s²
    # and a short move never reaches the cruise speed: triangular
    short = plan_position(0.0, 0.0, 0.0, 0.1, 2.0, 4.0)
    assert short.kind == "triangular"
    assert short.end_time == pytest.approx(2 * math.sqrt(0.1 / 4.0))
