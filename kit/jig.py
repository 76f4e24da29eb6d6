"""The jig of one run: its devices, its protocol run into a recording, its output directory.

What ``gyrocal calibrate``, ``verify``, ``thermal``, ``track`` and ``doctor`` share: the
configuration with the command-line overrides (:func:`load_cli_config`), the devices
(:class:`Jig`: the real ones, or the emulated jig with ``--sim``), the protocol planned
(:func:`choose_plan`, the paper's spins or the full model's posed turns) and run into a Recording
v1 with the servos stopped and torque off however it ends (:func:`record_protocol`,
:func:`run_jig`), and the run's output directory (:func:`output_dir`). The command modules
parse their arguments and call these.
"""

from __future__ import annotations

import argparse
import contextlib
import math
import sys
from collections.abc import Mapping
from datetime import datetime
from pathlib import Path
from typing import Any

__all__ = ["Jig", "choose_plan", "jig_endpoints", "load_cli_config",
           "measure_still_noise", "note_rounded_odr", "output_dir", "record_protocol",
           "resolve_sensor", "run_jig", "sim_effects", "time_budget"]


def note_rounded_odr(asked_hz: float, info: Any) -> None:
    """Say on stderr when the chip runs at a rate other than the one configured (``--odr 201``
    runs an MPU-9250 at 1000/(1 + 4) = 200 Hz)."""
    if info.odr_hz != asked_hz:
        print(f"gyrocal: note: imu.odr_hz {asked_hz:g} is not a rate the {info.model} can do; "
              f"it runs at the nearest, {info.odr_hz:.6g} Hz (the recording says so)",
              file=sys.stderr)


def resolve_sensor(sensor: Mapping[str, Any], bus: Any) -> dict[str, Any]:
    """The sensor's ``[imu]`` keys with what its chip will use: the output data rate nearest
    ``odr_hz`` that the chip has (:func:`gyrocal.drivers.imu.nearest_offered_rate`; the reader
    says so after it configures, :func:`note_rounded_odr`), and for ``address = 0`` the one of
    the chip's addresses where it answers (:func:`gyrocal.drivers.imu.find_address`; a note
    when it is not the chip's first).

    Parameters
    ----------
    sensor : mapping
        One of :meth:`gyrocal.kit.config.Config.imus`.
    bus : smbus2.SMBus-like, int or str
        The sensor's bus (the emulated one with ``--sim``), or an adapter number to open.

    Raises
    ------
    ConfigurationError
        If the chip answers at none of its addresses, or at several.
    """
    from gyrocal.drivers.imu import chip_addresses, find_address, nearest_offered_rate, open_bus

    out = dict(sensor)
    out["odr_hz"] = nearest_offered_rate(sensor["model"], sensor["odr_hz"])
    if not sensor["address"]:
        handle = open_bus(bus) if isinstance(bus, (int, str)) else bus
        try:
            out["address"] = find_address(sensor["model"], handle)
        finally:
            if handle is not bus:
                handle.close()
        if out["address"] != chip_addresses(sensor["model"])[0]:
            print(f"gyrocal: note: the {sensor['model']} answers at its other address, "
                  f"0x{out['address']:02X} (imu.address 0: the chip's own)", file=sys.stderr)
    return out


def load_cli_config(args: argparse.Namespace) -> Any:
    """The config file (or defaults) with the command-line overrides applied."""
    from gyrocal.kit.config import apply_overrides, load_config

    path = args.config
    if path is None and Path("gyrocal.toml").exists():
        path = "gyrocal.toml"
    cfg = load_config(path)
    cfg = apply_overrides(cfg, {
        "gimbal.port": args.port, "gimbal.baud": args.baud, "imu.model": args.imu_model,
        "imu.bus": args.imu_bus, "imu.address": args.imu_address,
        "imu.range_dps": args.range_dps, "imu.odr_hz": args.odr,
        "protocol.name": getattr(args, "protocol", None),
        "protocol.method": getattr(args, "method", None),
        "protocol.accel_rests": getattr(args, "accel_rests", None),
        "protocol.align_gyro_to_accel": getattr(args, "align_gyro_to_accel", None),
    })
    return single_servo_config(cfg) if jig_kind(args) == "single-servo" else cfg


def jig_kind(args: argparse.Namespace) -> str:
    """The run's kind of jig (``--jig``, :data:`gyrocal.kit.jig_kinds.JIG_KINDS`)."""
    from gyrocal.kit.jig_kinds import DEFAULT_JIG

    return getattr(args, "jig", None) or DEFAULT_JIG


def single_servo_config(cfg: Any) -> Any:
    """``cfg`` for the single-servo jig: its one servo. A config that leaves ``gimbal.ids`` and
    ``gimbal.axes`` at their defaults drives servo 1 (the gimbal's base); the servo's axis is
    the cube's "up", ``z`` of the first seat (the seats say the others).

    Raises
    ------
    InputError
        If the config lists several servos of its own.
    """
    from gyrocal.kit.config import apply_overrides, default_config
    from gyrocal.kit.errors import InputError

    g, default = cfg["gimbal"], default_config()["gimbal"]
    ids = g["ids"]
    if (ids, g["axes"]) == (default["ids"], default["axes"]):
        ids = ids[:1]
    elif len(ids) != 1:
        raise InputError(f"the single-servo jig drives one servo; gimbal.ids lists {len(ids)}: "
                         f"set gimbal.ids = [{ids[0]}] (hardware_docs/single-servo.md)")
    return apply_overrides(cfg, {"gimbal.ids": list(ids), "gimbal.axes": ["z"]})


def sim_effects(args: argparse.Namespace) -> list[str]:
    """The realism effects ``--sim-realism`` and ``--sim-without`` leave on."""
    from gyrocal.kit.sim import REALISM_EFFECTS

    without = list(getattr(args, "sim_without", []))
    if getattr(args, "sim_realism", "on") == "off":
        return []
    return [e for e in REALISM_EFFECTS if e not in without]


def jig_endpoints(cfg: Any, args: argparse.Namespace) -> tuple[Any, Any, Any, int, Any]:
    """Where the devices are: ``(sim, clock, servo port, baud, I2C bus)``.

    With ``--sim`` everything is the emulated jig (``sim`` is its
    :class:`~gyrocal.kit.sim.SimJig`); with ``--sim-imu`` the servos are the configured port (real
    servos, or ``gyrocal emulate --pty``) on the system clock and only the IMU is emulated, at
    rest; otherwise everything is the configured hardware (``sim`` is None).
    """
    from gyrocal.kit.errors import InputError

    sim_imu = getattr(args, "sim_imu", False)
    if args.sim_fault and not args.sim:
        raise InputError("--sim-fault needs --sim")
    if getattr(args, "sim_without", []):
        from gyrocal.kit.sim import REALISM_EFFECTS

        bad = [e for e in args.sim_without if e not in REALISM_EFFECTS]
        if bad:
            raise InputError(f"--sim-without {bad[0]!r}: not a realism effect; choose from "
                             + ", ".join(REALISM_EFFECTS))
    if args.sim and sim_imu:
        raise InputError("--sim emulates the whole jig; --sim-imu emulates only the IMU and "
                         "drives the servos on --port: give one of them")
    if args.sim and args.port is not None:
        raise InputError("--sim emulates the servos, so --port would be ignored; to drive "
                         "servos on a port (or 'gyrocal emulate --pty') with an emulated IMU "
                         "use --sim-imu --port PORT")
    if args.sim or sim_imu:
        from gyrocal.kit.sim import SIM_BAUD, SIM_SENSOR, build_sim_plate

        if sim_imu and len(cfg.imus()) > 1:
            raise InputError("--sim-imu emulates one IMU at rest; the config lists "
                             f"{len(cfg.imus())} sensors ([[imu]] tables): use --sim, or a "
                             "config with one [imu]")
        # with several [[imu]] sensors the first is returned and holds the others (sim.plate)
        sim = build_sim_plate(
            cfg, seed=args.sim_seed, scale=args.sim_scale, bias=args.sim_bias,
            realtime=args.realtime or sim_imu, noise_seed=args.sim_noise_seed,
            cross_axis=getattr(args, "sim_cross_axis", None),
            sensor=getattr(args, "sim_sensor", None) or SIM_SENSOR,
            realism=sim_effects(args), temperature=getattr(args, "sim_temperature", None),
            self_heating=getattr(args, "sim_self_heating", None))[0]
        if sim_imu:
            g = cfg["gimbal"]
            return sim, sim.clock, g["port"], g["baud"], sim.imu_bus
        from gyrocal.kit.config import default_config

        g, default = cfg["gimbal"], default_config()["gimbal"]
        if (g["baud"], g["port"]) != (default["baud"], default["port"]):  # the user set them
            print(f"gyrocal: note: --sim runs the emulated servos on their own bus at {SIM_BAUD} "
                  f"baud; gimbal.port ({g['port']}) and gimbal.baud ({g['baud']}) are not used",
                  file=sys.stderr)
        return sim, sim.clock, sim.port, SIM_BAUD, sim.imu_bus
    from gyrocal.drivers.clock import SystemClock

    g = cfg["gimbal"]
    return None, SystemClock(), g["port"], g["baud"], cfg["imu"]["bus"]


class Jig:
    """The devices of one run: a gimbal driver and the IMU readers on one clock (real or sim).

    ``imus`` has one reader per sensor of the config (:meth:`~gyrocal.kit.config.Config.imus`),
    ``imu`` is the first; ``names`` are the sensors' names. A config with several sensors is
    refused unless ``several`` (only ``gyrocal calibrate`` runs a plate of them).
    """

    def __init__(self, cfg: Any, args: argparse.Namespace, *, several: bool = False) -> None:
        from gyrocal.drivers.dynamixel import Gimbal
        from gyrocal.drivers.imu import open_imu
        from gyrocal.kit.errors import InputError

        sensors = cfg.imus()
        if len(sensors) > 1 and not several:
            raise InputError(
                f"this command drives one sensor, and the config lists {len(sensors)} ([[imu]] "
                "tables): give a config with a single [imu] (gyrocal calibrate runs several)")
        self.cfg = cfg
        self.faults: list[str] = []
        self.names = [s["name"] for s in sensors]
        sim, self.clock, port, baud, bus = jig_endpoints(cfg, args)
        # --sim-imu: only the IMU is emulated (``imu_sim``); the servos are real or on a PTY.
        self.imu_sim = sim if getattr(args, "sim_imu", False) else None
        self.sim = None if self.imu_sim is not None else sim
        #: Each sensor's emulated view (its truth and chip), with --sim.
        self.sims = (self.sim.plate or [self.sim]) if self.sim is not None else []
        self._fault_specs: list[str] = list(args.sim_fault)
        if self._fault_specs:
            from gyrocal.kit.sim import apply_fault, build_sim

            scratch = build_sim(cfg, seed=args.sim_seed)
            for spec in self._fault_specs:  # validate now; armed when the protocol starts
                apply_fault(scratch, self._fault_target(spec)[0])
        g = cfg["gimbal"]
        self.imus: list[Any] = []
        try:
            for k, s in enumerate(sensors):
                where = self.sims[k].imu_bus if self.sims else (bus if k == 0 else s["bus"])
                chip = resolve_sensor(s, where)
                self.imus.append(open_imu(s["model"], where, chip["address"], clock=self.clock,
                                          range_dps=s["range_dps"], odr_hz=chip["odr_hz"]))
                note_rounded_odr(s["odr_hz"], self.imus[-1].info)
        except BaseException:
            self.close()
            raise
        self.imu = self.imus[0]
        self.gimbal = Gimbal(port, g["ids"], baudrate=baud, clock=self.clock,
                             max_turns=g["max_turns"], acceleration=g["acceleration"],
                             watchdog_s=g["watchdog_s"], retries=g["retries"])

    def _fault_target(self, spec: str) -> tuple[str, int]:
        """``KIND:ARGS[@SENSOR]`` as ``(KIND:ARGS, sensor index)`` (the first sensor without
        ``@``)."""
        from gyrocal.kit.errors import InputError

        base, at, name = spec.rpartition("@")
        if not at:
            return spec, 0
        if name not in self.names:
            raise InputError(f"--sim-fault {spec!r}: no sensor named {name!r}; the sensors are "
                             + ", ".join(self.names))
        return base, self.names.index(name)

    def arm_faults(self) -> list[str]:
        """Arm the ``--sim-fault`` knobs with their times counted from now (the recording's
        start); returns their descriptions."""
        from gyrocal.kit.sim import apply_fault

        if self.sim is None:
            return []
        t0 = self.clock.monotonic()
        self.faults = []
        for spec in self._fault_specs:
            base, k = self._fault_target(spec)
            said = apply_fault(self.sims[k], base, t0)
            self.faults.append(f"{self.names[k]}: {said}" if len(self.sims) > 1 else said)
        return self.faults

    def close(self) -> None:
        """Close the IMUs (the gimbal closes through its context manager)."""
        from contextlib import suppress

        from gyrocal.drivers.errors import DriverError

        for imu in self.imus:
            with suppress(DriverError):
                imu.close()


def measure_still_noise(imu: Any, clock: Any, seconds: float = 1.0) -> float | None:
    """The gyro's noise per sample at rest that sets how well a window's mean is known (rad/s),
    from a short stream before the protocol, for the planner; None if the stream gave too few
    samples.

    The planner predicts a window mean's σ as this figure over the root of the window's
    samples, so the figure is the root of the long-run variance (the variance of a long mean
    times its samples): first differences (:func:`~gyrocal.calib.observations.diff_noise`)
    times the root of :func:`~gyrocal.calib.windows.correlation_factor`, which a chip's
    low-pass filter makes above 1 (the emulated LSM6DSOX's first differences alone read 0.63
    of it, and planned 0.6 s rests instead of 1.0). The median over the axes. One second
    gives the factor's estimate about 200 batch means at 200 Hz.
    """
    import numpy as np

    from gyrocal.calib.observations import diff_noise
    from gyrocal.calib.windows import correlation_factor

    imu.start()
    try:
        end = clock.monotonic() + seconds
        rates = []
        while clock.monotonic() < end:
            clock.sleep(0.02)
            rates.append(imu.read().rate)
    finally:
        imu.stop()
    x = np.concatenate(rates) if rates else np.zeros((0, 3))
    if x.shape[0] < 20:
        return None
    return float(np.median(diff_noise(x) * np.sqrt(correlation_factor([x]))))


def _nominal_axes(names: list[str]) -> Any:
    """Unit vectors of the configured signed sensor axes (``"x"``, ``"-z"``, ...)."""
    import numpy as np

    out = np.zeros((len(names), 3))
    for i, name in enumerate(names):
        out[i, "xyz".index(name[-1])] = -1.0 if name.startswith("-") else 1.0
    return out


def time_budget(protocol: Mapping[str, Any]) -> float:
    """The jig time the planner may use for the config's ``[protocol]``: ``time_budget_s``, or
    the protocol's own when it is 0 (the default): at least
    :data:`~gyrocal.calib.design.FULL_TIME_BUDGET_S` for ``full``,
    :data:`~gyrocal.calib.design.AUTO_TIME_BUDGET_S` for ``auto`` (``paper`` is not planned)."""
    from gyrocal.calib.design import AUTO_TIME_BUDGET_S, FULL_TIME_BUDGET_S

    given = float(protocol["time_budget_s"])
    if protocol["name"] == "full":
        return max(given, FULL_TIME_BUDGET_S)
    return given or AUTO_TIME_BUDGET_S


def choose_plan(cfg: Any, gimbal: Any, imu: Any, noise_std: float | None = None,
                jig: str = "gimbal") -> Any:
    """The protocol: planned for this servo and gyro (and its measured noise), or the paper's;
    fixed values override. On the single-servo jig (``jig``), the cube's seats
    (:func:`seat_plan`)."""
    from dataclasses import replace

    from gyrocal.calib.design import (
        MIN_REST_S,
        jig_time,
        paper_plan,
        plan_accel_rests,
        plan_protocol,
    )
    from gyrocal.kit.errors import InputError

    p = cfg["protocol"]
    accel = float(cfg["gimbal"]["acceleration"])
    accel_rests = p["name"] == "full" and bool(p["accel_rests"])
    max_turns = float(cfg["gimbal"]["max_turns"])
    # the planned protocols stay within their budget (the full one's is at least
    # FULL_TIME_BUDGET_S; with the accelerometer's rests the whole run, their moves included),
    # also when fixed values override the plan (checked below)
    limit = time_budget(p)
    noise = {} if noise_std is None else {"noise_std": noise_std}
    if jig == "single-servo":
        return seat_plan(cfg, gimbal, imu, noise)
    if p["name"] == "paper":
        plan = paper_plan(accel=accel, odr_hz=imu.odr_hz, **noise)
    else:
        # protocol "full": plan the full model's posed turns (hardware_docs/method.md §9) within
        # at least FULL_TIME_BUDGET_S, with the configured axes as the nominal gimbal for
        # planning only.
        full = p["name"] == "full"
        if full and len(cfg["gimbal"]["ids"]) != 3:
            raise InputError(
                f"protocol 'full' (the default) needs a three-servo gimbal; gimbal.ids lists "
                f"{len(cfg['gimbal']['ids'])}: set protocol.name = \"auto\" (or --protocol auto) "
                "to calibrate the diagonal model with fewer servos")
        plan = plan_protocol(servo_max_speed=gimbal.top_speed,
                             full_scale=math.radians(imu.full_scale_dps),
                             time_budget_s=limit, odr_hz=imu.odr_hz, accel=accel,
                             model="full" if full else "diagonal",
                             axes=_nominal_axes(cfg["gimbal"]["axes"]) if full else None,
                             accel_rests=accel_rests, max_turns=max_turns, **noise)
    fixed = {}
    if p["speed_dps"] > 0:
        fixed["speed"] = math.radians(p["speed_dps"])
    if p["turns"] > 0:
        fixed["turns"] = int(p["turns"])
    if p["rest_s"] > 0:
        fixed["rest_s"] = float(p["rest_s"])
    if fixed:
        plan = replace(plan, **fixed, accel_moves=(), accel_extra_rests=0, accel_time_s=0.0,
                       accel_std_ratio=None)
        plan = replace(plan, jig_time_s=jig_time(
            plan.speed, plan.turns, plan.rest_s, accel,
            move_angles=tuple(abs(a) for _, _, a in plan.poses),
            gravity_angles=tuple(abs(a) for _, a in plan.gravity_poses)))
        if accel_rests and plan.rest_s >= MIN_REST_S:
            # tilt the fixed protocol's rests for the accelerometer (calib.design.
            # plan_accel_rests): the turns the gyro sees are unchanged; the moves add
            # plan.accel_time_s. Not with rests shorter than the planner's own minimum: the
            # accelerometer gets no still window from them, and the moves cost the full matrix
            # its observability (a user's rest_s = 0.4 with 240 °/s, one turn: ±1.1e-3 against
            # the 1e-3 limit)
            plan = plan_accel_rests(plan, axes=_nominal_axes(cfg["gimbal"]["axes"]),
                                    max_turns=max_turns)
    if p["name"] != "paper" and plan.jig_time_s - plan.accel_time_s > limit * (1 + 1e-9):
        raise InputError(
            f"the protocol needs about {plan.jig_time_s:.0f} s of jig time, more than "
            f"protocol.time_budget_s = {limit:g} s: raise the budget, or lower "
            "protocol.turns or protocol.rest_s, or set protocol.speed_dps higher (0 lets the "
            "planner choose within the budget)")
    if plan.speed > gimbal.top_speed:
        raise InputError(
            f"protocol speed {math.degrees(plan.speed):.0f}°/s exceeds the servos' top speed "
            f"{math.degrees(gimbal.top_speed):.0f}°/s; lower protocol.speed_dps"
        )
    if plan.turns > cfg["gimbal"]["max_turns"]:
        raise InputError(
            f"protocol turns {plan.turns} exceed gimbal.max_turns {cfg['gimbal']['max_turns']}"
            " (the cable-wrap limit); lower protocol.turns or raise the limit if the cables allow"
        )
    return plan


def seat_plan(cfg: Any, gimbal: Any, imu: Any, noise: Mapping[str, float]) -> Any:
    """The single-servo jig's plan (:func:`gyrocal.calib.design.plan_seats`): protocol
    ``full`` (the default) plans the seats that determine the full matrix (faces and V-block
    edges); ``auto`` and ``paper`` the three faces (the diagonal model, the flat adapter
    alone); fixed speed, turns and rests override the planned ones."""
    from dataclasses import replace

    from gyrocal.calib.design import SEAT_TIME_BUDGET_S, plan_seats, seat_jig_time
    from gyrocal.calib.errors import CalibInputError
    from gyrocal.kit.errors import InputError

    p = cfg["protocol"]
    try:
        plan = plan_seats(servo_max_speed=gimbal.top_speed,
                          full_scale=math.radians(imu.full_scale_dps), odr_hz=imu.odr_hz,
                          accel=float(cfg["gimbal"]["acceleration"]),
                          model="full" if p["name"] == "full" else "diagonal",
                          time_budget_s=float(p["time_budget_s"]) or SEAT_TIME_BUDGET_S,
                          **noise)
    except CalibInputError as exc:
        raise InputError(f"{exc} (protocol.time_budget_s)") from None
    fixed = {k: v for k, v in (("speed", math.radians(p["speed_dps"])), ("turns", p["turns"]),
                               ("rest_s", float(p["rest_s"]))) if v}
    if fixed:
        plan = replace(plan, **fixed)
        plan = replace(plan, jig_time_s=seat_jig_time(plan.speed, plan.turns, plan.rest_s,
                                                      plan.accel, len(plan.seats)))
    if plan.speed > gimbal.top_speed:
        raise InputError(f"protocol speed {plan.speed_dps:.0f}°/s exceeds the servo's top speed "
                         f"{math.degrees(gimbal.top_speed):.0f}°/s; lower protocol.speed_dps")
    if plan.turns > cfg["gimbal"]["max_turns"]:
        raise InputError(f"protocol turns {plan.turns} exceed gimbal.max_turns "
                         f"{cfg['gimbal']['max_turns']} (the cable-wrap limit)")
    return plan


def _manifest_parts(cfg: Any, jig: Jig, plan: Any, noise_std: float | None, k: int = 0
                    ) -> tuple[dict, dict, dict, dict | None]:
    """The manifest's ``sensor``, ``gimbal``, ``protocol`` and ``truth`` (sim only) of sensor
    ``k``'s recording."""
    # where the chip sits, for the flight stacks' device IDs (kit.px4_ids)
    sensor = {**jig.imus[k].info.manifest(), "i2c_bus": int(cfg.imus()[k]["bus"]),
              "i2c_address": int(jig.imus[k].info.address)}
    gimbal_info = {"motors": [
        {"id": sid, "model": jig.gimbal.infos[sid].model_name,
         "axis": cfg.axis_of()[sid]} for sid in cfg["gimbal"]["ids"]]}
    ids = cfg["gimbal"]["ids"]
    protocol = {"name": cfg["protocol"]["name"], "model": plan.model, "speed": plan.speed,
                "turns": plan.turns, "rest_s": plan.rest_s,
                "poses": [{"turn": ids[t], "moved": ids[m], "angle_rad": a}
                          for t, m, a in plan.poses],
                "gravity_poses": [{"moved": ids[m], "angle_rad": a}
                                  for m, a in plan.gravity_poses],
                "accel_moves": [{"rest": r, "moved": ids[m], "angle_rad": a}
                                for r, m, a in plan.accel_moves],
                "accel_extra_rests": plan.accel_extra_rests,
                "accel_time_s": plan.accel_time_s,
                "acceleration": plan.accel,
                "planned_jig_time_s": plan.jig_time_s,
                "planning_noise_std": noise_std,
                "sample_hz": cfg["gimbal"]["sample_hz"],
                "discarded": []}  # attempts repeated after a failed check (the runner's)
    if plan.seats:  # the single-servo jig: the seats planned; the runner lists those taken
        protocol.update(planned_seats=list(plan.seats), seats=[])
    truth = None
    if jig.sims:
        sim = jig.sims[k]
        truth = {**sim.truth_manifest(),
                 "axes": {str(i): v.tolist() for i, v in sim.jig.home_axes.items()}}
    return sensor, gimbal_info, protocol, truth


def recording_dirs(jig: Jig, rec_dir: Path) -> list[Path]:
    """Where each sensor records: ``rec_dir`` for one sensor; with several (a plate),
    ``rec_dir.parent / NAME / "recording"`` for each (:mod:`gyrocal.kit.plate`)."""
    if len(jig.imus) == 1:
        return [rec_dir]
    return [rec_dir.parent / name / "recording" for name in jig.names]


def _planning_sensor(jig: Jig) -> Any:
    """What the planner needs of the sensors: the lowest range and output data rate among
    them (the protocol must suit every sensor on the plate)."""
    from types import SimpleNamespace

    return SimpleNamespace(full_scale_dps=min(i.full_scale_dps for i in jig.imus),
                           odr_hz=min(i.odr_hz for i in jig.imus))


def _still_noise(jig: Jig) -> float | None:
    """The largest still noise among the sensors (:func:`measure_still_noise`, each in turn)."""
    noises = [measure_still_noise(imu, jig.clock) for imu in jig.imus]
    known = [n for n in noises if n is not None]
    return max(known) if known else None


def _writers(cfg: Any, args: argparse.Namespace, jig: Jig, plan: Any, noise_std: float | None,
             rec_dir: Path) -> Any:
    """A RecordingWriter, or with several sensors a RecordingGroup of one per sensor."""
    from gyrocal.kit.pipeline import local_gravity
    from gyrocal.kit.plate import RecordingGroup
    from gyrocal.kit.recording import RecordingWriter

    dirs = recording_dirs(jig, rec_dir)
    # the local gravity the accelerometer is fitted against, from [accelerometer]
    gravity, source = local_gravity(cfg["accelerometer"])
    site = {"site": {"gravity_m_s2": gravity, "gravity_from": source}}
    writers = []
    try:
        for k, d in enumerate(dirs):
            sensor, gimbal_info, protocol, truth = _manifest_parts(cfg, jig, plan, noise_std, k)
            extra = site if len(dirs) == 1 else {**site, "plate": {
                "sensor": jig.names[k], "sensors": list(jig.names),
                "address": int(jig.imus[k].info.address), "bus": cfg.imus()[k]["bus"]}}
            if plan.seats:  # the jig kind, as every recording not made on the gimbal says it
                extra = {**extra, "jig": {"kind": "single-servo"}}
            writers.append(RecordingWriter(d, sensor=sensor, gimbal=gimbal_info,
                                           protocol=protocol, truth=truth, force=args.force,
                                           extra=extra, accel=True))
    except BaseException:
        for w in writers:
            w.close()
        raise
    return writers[0] if len(writers) == 1 else RecordingGroup(writers)


def record_protocol(cfg: Any, args: argparse.Namespace, jig: Jig, rec_dir: Path,
                    extend: Any = None, plan: Any = None) -> Any:
    """Open the gimbal, plan, and run the protocol into a Recording v1 at ``rec_dir``, or one
    per sensor (:func:`recording_dirs`) (``extend``: see :func:`run_jig`). A ``plan`` given
    (a :class:`~gyrocal.calib.design.Plan` of an earlier run on this jig) is run as it is;
    the still noise is measured either way. Returns the plan run.

    Raises
    ------
    InputError, DriverError
        As the protocol's runner and the recording writer; the gimbal's context stops the
        servos with torque off on the way out.
    """
    from gyrocal.kit.progress import Progress
    from gyrocal.kit.protocol import Runner, build_steps

    quiet = getattr(args, "quiet", False)
    with jig.gimbal:
        noise_std = _still_noise(jig)
        if plan is None:
            plan = choose_plan(cfg, jig.gimbal, _planning_sensor(jig), noise_std,
                               jig=jig_kind(args))
        steps = build_steps(plan, cfg["gimbal"]["ids"])
        runner_class = Runner
        if extend is not None:
            runner_class, extra = extend
            steps += extra(plan, cfg["gimbal"]["ids"])
        progress = Progress(sys.stderr, plan.jig_time_s, interactive=False if quiet else None)
        if not quiet:
            progress.event(
                f"protocol {cfg['protocol']['name']}: {plan.turns} turn(s) each way at "
                f"{plan.speed_dps:.0f}°/s, {plan.rest_s:.1f} s rests, "
                + (f"{len(plan.poses)} posed pairs for the full matrix, " if plan.poses else "")
                + (f"{len(plan.seats)} seats of the cube ({', '.join(plan.seats)}), "
                   if plan.seats else "")
                + f"about {plan.jig_time_s:.0f} s of jig time"
                + (f", {len(jig.imus)} sensors" if len(jig.imus) > 1 else "")
                + (" (emulated jig)" if jig.sim is not None else "")
                + (" (emulated IMU at rest)" if jig.imu_sim is not None else ""))
        with _writers(cfg, args, jig, plan, noise_std, rec_dir) as writer:
            runner = runner_class(
                jig.gimbal, jig.imus if len(jig.imus) > 1 else jig.imu, writer, jig.clock,
                steps, sample_hz=cfg["gimbal"]["sample_hz"],
                on_progress=None if quiet else progress.update,
                on_event=None if quiet else progress.event, sensor_names=jig.names,
                seater=_seater(jig, args) if plan.seats else None,
            )
            for f in jig.arm_faults():
                if not quiet:
                    progress.event(f"fault armed: {f} (time in the recording)")
            try:
                runner.run()
                if not quiet:
                    progress.event(f"servo link: worst poll interval during motion "
                                   f"{jig.gimbal.worst_poll_interval_s * 1e3:.0f} ms (Bus "
                                   f"Watchdog {jig.gimbal.watchdog_s * 1e3:.0f} ms)")
            finally:
                progress.close()
                # The servo link's timing, on a failed run too: the longest gap between polls
                # while a servo moved, against the Bus Watchdog that would have stopped it
                # (hardware reference §5). A failed write (atomic_write_json's InputError on a full
                # disk) must not hide the run's own error.
                from gyrocal.kit.errors import InputError

                with contextlib.suppress(OSError, InputError):
                    writer.update_manifest(protocol={
                        **writer.manifest["protocol"],
                        "worst_poll_interval_s": jig.gimbal.worst_poll_interval_s,
                        "bus_watchdog_s": jig.gimbal.watchdog_s})
            for k, w in enumerate(getattr(writer, "writers", [writer])):
                if jig.sims and plan.seats:
                    w.update_manifest(truth={**w.manifest["truth"], "axes": _seat_axes_truth(
                        jig, runner)})
                elif jig.sims and k not in runner.failed:
                    # The true axis of each servo during its turns (the holding servos rest
                    # somewhere within their ticks, which tilts the axes slightly off the
                    # ideal home pose).
                    w.update_manifest(truth={**w.manifest["truth"], "axes": jig.sims[k].turn_axes(
                        cfg["gimbal"]["ids"], runner.turn_times(), runner.t0)})
            writer.finish()
    return plan


def _seater(jig: Jig, args: argparse.Namespace) -> Any:
    """Who re-seats the cube: the emulated hand with ``--sim`` (seeded by ``--sim-seed``), else
    the user at the terminal."""
    from gyrocal.kit.errors import InputError
    from gyrocal.kit.seating import EmulatedSeater, TerminalSeater

    if jig.sim is not None:
        from gyrocal.drivers.emulated.seater import CubeSeater

        return EmulatedSeater(CubeSeater(jig.sim.jig, jig.clock, seed=args.sim_seed,
                                         wrong=jig.sim.wrong_seats))
    if jig.imu_sim is not None:
        raise InputError("--sim-imu emulates an IMU at rest: nobody re-seats it; run the "
                         "single-servo jig with --sim, or on the hardware")
    return TerminalSeater()


def _seat_axes_truth(jig: Jig, runner: Any) -> dict[str, list[float]]:
    """The servo's true axis in the sensor frame in each seat taken (the manifest's
    ``truth.axes`` by seat number, 1-based, as the fit numbers them), at the middle of the
    seat's first turn."""
    import numpy as np

    starts = [s["t_start"] for s in runner.seats]
    out: dict[str, list[float]] = {}
    for times in runner.turn_times().values():
        for t in times:
            k = int(np.searchsorted(starts, t, side="right"))
            if k and str(k) not in out:
                out[str(k)] = jig.sim.jig.joint_axes_sensor(
                    np.array([t + runner.t0]))[0, 0].tolist()
    return out


def run_jig(cfg: Any, args: argparse.Namespace, out: Path, rec_dir: Path,
            extend: Any = None) -> Any:
    """Run the protocol on the jig (or the emulated jig) into a Recording v1 at ``rec_dir``.

    Servos stop and torque goes off before the recording is closed, on success, error, or
    SIGINT, SIGTERM or SIGHUP at any moment (:mod:`gyrocal.drivers.signals`: the gimbal's
    handlers are in place from its first packet to its last, and a second signal cannot cut the
    stop short). An interrupted run raises :class:`~gyrocal.kit.errors.InterruptedRun`
    (exit 130/143/129) whose message says whether a recording was begun (then it is kept,
    marked incomplete). With ``--sim`` the emulated servos' final state is written to
    ``out/sim-state.json`` (what the emulator holds, not what the driver believes).

    ``extend``, if given, is ``(runner_class, extra_steps)``: a :class:`Runner` subclass and
    ``extra_steps(plan, ids) -> steps`` run after the protocol (``gyrocal verify``'s general
    motion).

    Returns
    -------
    Jig
        The (closed) jig, for its sim truth.
    """
    from gyrocal.drivers.signals import TerminatedBySignal, shielded
    from gyrocal.kit.busload import check_bus_loads
    from gyrocal.kit.errors import InterruptedRun

    # before anything is opened: a bus that cannot carry the plan's samples is refused
    for warning in check_bus_loads(cfg.imus(), cfg["gimbal"]["sample_hz"]):
        print(f"gyrocal: warning: {warning}", file=sys.stderr)
    jig = Jig(cfg, args, several=True)
    interrupted: BaseException | None = None
    failed: BaseException | None = None
    try:
        record_protocol(cfg, args, jig, rec_dir, extend)
    except (KeyboardInterrupt, TerminatedBySignal) as exc:
        interrupted = exc
    except Exception as exc:
        failed = exc
        raise
    finally:
        with shielded():
            jig.close()
            if jig.sim is not None:
                _write_sim_state(jig, out, quietly=failed is not None or interrupted is not None)
            if failed is not None:  # said before the error itself (the last line)
                stopped = ("servos stopped, torque off confirmed on every servo; "
                           if getattr(jig.gimbal, "torque_off_confirmed", None) else "")
                print(f"gyrocal: note: {stopped}{_kept(jig, rec_dir)}", file=sys.stderr)
    if interrupted is not None:
        signum = getattr(interrupted, "signum", 2)
        what = {2: "interrupted", 15: "terminated", 1: "hung up"}.get(signum, "stopped")
        raise InterruptedRun(f"{what}: servos stopped, torque off; {_kept(jig, rec_dir)}",
                             signum)
    return jig


def _kept(jig: Any, rec_dir: Path) -> str:
    """What became of a stopped run's recording(s), for its message."""
    begun = [d for d in recording_dirs(jig, rec_dir) if (d / "manifest.json").exists()]
    return (f"the recording in {', '.join(map(str, begun))} is kept, marked incomplete"
            if begun else "no recording was begun")


def _write_sim_state(jig: Any, out: Path, *, quietly: bool) -> None:
    """``out/sim-state.json``; with ``quietly`` (the run already failed) a failure to write it
    is a warning, so the run's own failure (a full disk under the recording) stays the error."""
    from gyrocal.kit.errors import InputError
    from gyrocal.kit.fileio import atomic_write_json

    try:
        atomic_write_json(out / "sim-state.json", {"servos": jig.sim.servo_state()}, force=True)
    except InputError as exc:
        if not quietly:
            raise
        print(f"gyrocal: warning: {exc}", file=sys.stderr)


def output_dir(args: argparse.Namespace) -> tuple[Path, Path]:
    """``(out, work)``: the run's directory, and where this run writes.

    A new directory is written in place. With ``--force`` over an existing run (and only over a
    gyrocal run: :func:`~gyrocal.kit.fileio.check_replaceable_run`), the new run is
    built in a staging directory beside it and swapped in only when it has finished
    (:func:`~gyrocal.kit.fileio.replace_dir`), so the old calibration never sits next to a new
    recording.
    """
    from gyrocal.kit.errors import OutputExistsError
    from gyrocal.kit.fileio import check_replaceable_run, make_output_dir, staging_dir

    out = Path(args.out or datetime.now().strftime("gyrocal-%Y%m%d-%H%M%S"))
    if args.force:
        check_replaceable_run(out)  # before the jig moves, not after the run
    if out.is_dir() and any(out.iterdir()):
        if not args.force:
            raise OutputExistsError(f"{out} already exists; pass --force to replace the run "
                                    "in it as a whole")
        return out, staging_dir(out)
    make_output_dir(out, "--out")
    return out, out
