"""The kit's side of the accelerometer rests: protocol.accel_rests / --no-accel-rests, the plan
the jig runs, and the manifest that records it (calib.design.plan_accel_rests is tested in
tests/calib/test_accel_rests.py)."""

import math
from dataclasses import replace
from types import SimpleNamespace

import pytest

from gyrocal.calib.design import FULL_TIME_BUDGET_S, jig_time, protocol_sequence
from gyrocal.kit.cli import build_parser
from gyrocal.kit.jig import choose_plan, load_cli_config
from gyrocal.kit.protocol import build_steps

GIMBAL = SimpleNamespace(top_speed=math.radians(275) * 0.9)
IMU = SimpleNamespace(odr_hz=200.0, full_scale_dps=500)


def plan_for(*flags):
    args = build_parser().parse_args(["calibrate", "--sim", *flags])
    cfg = load_cli_config(args)
    return cfg, choose_plan(cfg, GIMBAL, IMU)


def test_the_default_full_plan_tilts_rests_and_the_flag_turns_it_off(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)  # no ./gyrocal.toml
    cfg, on = plan_for()
    assert cfg["protocol"]["accel_rests"] is True
    _, off = plan_for("--no-accel-rests")
    assert on.accel_moves and not off.accel_moves
    # the whole run, the accelerometer's moves included, fits the full model's budget (45 s):
    # the gyro's part is planned within what the moves leave
    assert on.jig_time_s <= FULL_TIME_BUDGET_S and off.jig_time_s <= FULL_TIME_BUDGET_S
    assert on.jig_time_s - on.accel_time_s <= off.jig_time_s
    assert on.jig_time_s - on.accel_time_s == pytest.approx(jig_time(
        on.speed, on.turns, on.rest_s, on.accel, move_angles=tuple(a for *_, a in on.poses),
        gravity_angles=tuple(a for _, a in on.gravity_poses)), rel=1e-12)
    assert 0 < on.accel_time_s < 10.0
    assert on.accel_std_ratio <= 2.0
    # the turns are those of the same gyro protocol without the moves; every accelerometer
    # move is a step the runner carries out
    gyro = replace(on, accel_moves=(), accel_time_s=0.0, accel_std_ratio=None)
    turns = [(s.motor, s.direction) for s in build_steps(on, [1, 2, 3]) if s.kind == "rotate"]
    assert turns == [(s.motor, s.direction) for s in build_steps(gyro, [1, 2, 3])
                     if s.kind == "rotate"]
    steps = build_steps(on, [1, 2, 3])
    assert len(steps) == len(protocol_sequence(on))
    assert [s.kind for s in steps].count("rest") == [s.kind for s in build_steps(
        gyro, [1, 2, 3])].count("rest")
    # the paper's protocol and the diagonal one are left as they are
    _, auto = plan_for("--protocol", "auto")
    _, paper = plan_for("--protocol", "paper")
    assert not auto.accel_moves and not paper.accel_moves


def test_the_config_key_turns_it_off(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "gyrocal.toml").write_text("[protocol]\naccel_rests = false\n")
    _, plan = plan_for()
    assert not plan.accel_moves and plan.accel_time_s == 0.0
