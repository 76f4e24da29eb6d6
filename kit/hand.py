"""The hand jig's run (``gyrocal calibrate --sim --jig hand``): the emulated box turned by hand,
read through the real IMU reader into a Recording v1 that says ``jig.kind = "hand"``.

There is no protocol to drive: the hand's schedule (:func:`gyrocal.drivers.emulated.hand
.hand_schedule`) plays on the virtual clock while the reader drains the chip's FIFO, exactly as
the gimbal's runner does between servo polls. The recording has no encoder readings and no
segments: :func:`gyrocal.kit.pipeline.extract_recording` finds the rests and turns in the data
(:mod:`gyrocal.calib.hand`), as it does for a hand recording made by another tool.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

__all__ = ["POLL_S", "record_hand_sim"]

#: How often the reader drains the FIFO, s (the gimbal runner's poll period at its default
#: sample_hz of 50).
POLL_S = 0.02
#: Still time recorded after the schedule's last rest, s.
_TAIL_S = 0.5


def record_hand_sim(cfg: Any, args: argparse.Namespace, rec_dir: Path) -> Any:
    """Record the emulated hand jig into ``rec_dir`` (a Recording v1 of the hand jig).

    Returns
    -------
    SimJig
        The emulated jig (its truth).

    Raises
    ------
    InputError
        Without ``--sim`` (only the emulated hand jig records here), with several sensors, or
        with the gimbal's fault knobs.
    """
    from gyrocal.drivers.imu import open_imu
    from gyrocal.kit.errors import InputError
    from gyrocal.kit.jig import resolve_sensor, sim_effects
    from gyrocal.kit.pipeline import local_gravity
    from gyrocal.kit.recording import RecordingWriter
    from gyrocal.kit.sim import HAND_STOP_DEG, SIM_SENSOR, build_hand_sim

    if not args.sim:
        raise InputError("--jig hand records only on the emulated jig (--sim); record a real "
                         "hand session with your own reader as a Recording v1 whose manifest "
                         "says \"jig\": {\"kind\": \"hand\"} and run gyrocal estimate on it "
                         "(hardware_docs/hand-jig.md)")
    if len(cfg.imus()) > 1 or args.sim_fault or getattr(args, "sim_imu", False):
        raise InputError("--jig hand emulates one sensor on a box: no [[imu]] plate, "
                         "--sim-fault or --sim-imu")
    sim = build_hand_sim(
        cfg, seed=args.sim_seed, noise_seed=args.sim_noise_seed, scale=args.sim_scale,
        bias=args.sim_bias, cross_axis=getattr(args, "sim_cross_axis", None),
        sensor=getattr(args, "sim_sensor", None) or SIM_SENSOR, realism=sim_effects(args),
        temperature=getattr(args, "sim_temperature", None),
        self_heating=getattr(args, "sim_self_heating", None))
    imu_cfg = cfg["imu"]
    chip = resolve_sensor(imu_cfg, sim.imu_bus)
    imu = open_imu(imu_cfg["model"], sim.imu_bus, chip["address"], clock=sim.clock,
                   range_dps=imu_cfg["range_dps"], odr_hz=chip["odr_hz"])
    gravity, source = local_gravity(cfg["accelerometer"])
    motion = sim.jig
    truth = {**sim.truth.manifest(), "box_axes": motion.box_axes().tolist(),
             "turn_angles_rad": list(motion.turn_angles)}
    schedule = [{"kind": p.kind, "t_start": p.t_start, "t_end": p.t_end, "axis": p.axis,
                 "angle_rad": p.angle} for p in motion.schedule]
    try:
        with RecordingWriter(
                rec_dir, sensor=imu.info.manifest(), gimbal={"motors": []},
                protocol={"name": "hand", "schedule": schedule}, truth=truth,
                force=getattr(args, "force", False), accel=True,
                extra={"jig": {"kind": "hand", "stop_std_deg": HAND_STOP_DEG},
                       "site": {"gravity_m_s2": gravity, "gravity_from": source}}) as writer:
            imu.start()
            t_end = motion.t0 + motion.duration + _TAIL_S
            while sim.clock.monotonic() < t_end:
                sim.clock.sleep(POLL_S)
                batch = imu.read()
                if len(batch):
                    writer.append_imu(batch.t, batch.rate, batch.temperature_c,
                                      accel=batch.accel)
            imu.stop()
            writer.finish()
    finally:
        imu.close()
    return sim
