"""The hand jig's run: on hardware (``gyrocal calibrate --jig hand``) the user turns the box when
prompted; on the emulator (``--sim --jig hand``) the emulated hand does. Both read the IMU
through the real reader into a Recording v1 that says ``jig.kind = "hand"``.

On hardware (:func:`record_hand_live`) there is no servo bus at all: only the IMU. The user
follows the steps of :func:`gyrocal.drivers.emulated.hand.hand_steps` (the emulated hand's own
table), each asked by a prompt through :class:`gyrocal.kit.seating.Seater` (the single-servo
jig's: Enter is polled while the reader drains the FIFO). After each Enter the box rests for
:data:`HAND_REST_S`, and :func:`check_hand_step` looks in the data so far for what the step
asked (:func:`gyrocal.calib.hand.find_hand_turns`: the rest long enough, one whole turn about
the asked box axis in the asked sense, the asked face up from gravity); what is wrong is said
and the step asked again, up to :data:`HAND_TRIES` times.

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

import numpy as np

__all__ = ["FACE_UPS", "HAND_REST_S", "HAND_TRIES", "POLL_S", "check_hand_step", "hand_prompt",
           "record_hand", "record_hand_live", "record_hand_sim"]

#: How often the reader drains the FIFO, s (the gimbal runner's poll period at its default
#: sample_hz of 50).
POLL_S = 0.02
#: Still time recorded after the schedule's last rest, s.
_TAIL_S = 0.5
#: Rest recorded after each Enter on hardware, s: twice the rest detector's shortest rest
#: (:class:`gyrocal.calib.hand.HandSettings` ``min_rest_s``), so edges trimmed by the detector
#: leave a rest it takes.
HAND_REST_S = 2.5
#: How many times a step is asked before the run stops (the single-servo jig's seat tries).
HAND_TRIES = 3
#: The box faces' "up" in the sensor frame (the sensor's axes are the box's, within its mount).
FACE_UPS: dict[str, tuple[float, float, float]] = {
    f"{sign}{axis}": tuple(float(v) for v in (1 if sign == "+" else -1) * np.eye(3)[k])
    for k, axis in enumerate("xyz") for sign in "+-"}  # type: ignore[misc]
_SENSE = {1: "counter-clockwise", -1: "clockwise"}
_NOT_STILL = "the box was not still"


def hand_prompt(step: tuple[str, str, int], number: int, total: int,
                problem: str | None = None) -> str:
    """What the user reads for ``step`` (of :func:`~gyrocal.drivers.emulated.hand.hand_steps`)
    and, on a repeat, what was wrong."""
    kind, face, sense = step
    head = f"{problem}; " if problem else ""
    if kind == "face":
        what = f"lay the box with face {face} up against the stop"
    else:
        what = (f"with face {face} up, turn the box one whole turn {_SENSE[sense]} (seen from "
                "above) back against the stop")
    return f"{head}step {number}/{total}: {what}, hands off, then press Enter"


def check_hand_step(t: np.ndarray, rate: np.ndarray, accel: np.ndarray,
                    step: tuple[str, str, int], entered: int) -> str | None:
    """Whether the samples say ``step`` was done: None if they do, else what is wrong.

    Parameters
    ----------
    t, rate, accel : ndarray
        The samples from the last rest taken (its first sample) to the end of the rest after
        the user's Enter; s, rad/s, any unit.
    step : (kind, face, sense)
        The step asked (:func:`~gyrocal.drivers.emulated.hand.hand_steps`).
    entered : int
        Index of the first sample after Enter (the rest checked).
    """
    from gyrocal.calib.errors import CalibInputError
    from gyrocal.calib.hand import HandSettings, find_hand_turns
    from gyrocal.kit.seating import check_seat

    kind, face, sense = step
    still = f"{_NOT_STILL} after Enter: leave it {HAND_REST_S:g} s, hands off"
    try:
        found = find_hand_turns(t, rate)
    except CalibInputError:
        return still
    last = found.rests[-1] if found.rests else (0.0, -1.0)
    # the rest after Enter: still to the end, at least the shortest rest the detector takes
    if last[1] < found.t[-1] - 0.25 * HAND_REST_S or last[1] - last[0] < HandSettings().min_rest_s:
        return still
    wrong_face = check_seat(accel[entered:], face, ups=FACE_UPS, thing="box")
    if wrong_face is not None:
        return wrong_face
    if kind == "turn":
        return _check_turn(found.turns, face, sense,
                           sum(m[2] for m in found.moves))
    return None


def _check_turn(turns: Any, face: str, sense: int, moved_rad: float) -> str | None:
    """What is wrong with the turns found after a turn step, or None."""
    axis = "xyz".index(face[1])
    if not turns:
        return (f"no whole turn found since the last rest (the box turned "
                f"{np.degrees(moved_rad):.0f}° in all): turn it one whole turn, from the stop "
                "back to the stop")
    if len(turns) > 1 or turns[0].revolutions != 1:
        n = sum(tr.revolutions for tr in turns)
        return f"{n} whole turns found since the last rest: turn the box one whole turn only"
    tr = turns[0]
    if tr.axis != axis:
        return (f"the turn was about the box's {'xyz'[tr.axis]} axis, not its {face[1]} axis: "
                f"keep face {face} up while turning")
    if tr.direction != sense:
        return f"the turn was {_SENSE[tr.direction]}: turn {_SENSE[sense]} (seen from above)"
    return None


class _Samples:
    """The samples read so far (time, rate, accelerometer), for the checks."""

    def __init__(self) -> None:
        self.t: list[np.ndarray] = []
        self.rate: list[np.ndarray] = []
        self.accel: list[np.ndarray] = []
        self.n = 0

    def add(self, batch: Any) -> None:
        self.t.append(np.asarray(batch.t, dtype=float))
        self.rate.append(np.asarray(batch.rate, dtype=float))
        acc = batch.accel if batch.accel is not None else np.full((len(batch), 3), np.nan)
        self.accel.append(np.asarray(acc, dtype=float))
        self.n += len(batch)

    def since(self, k: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        if not self.t:
            return np.zeros(0), np.zeros((0, 3)), np.zeros((0, 3))
        return (np.concatenate(self.t)[k:], np.concatenate(self.rate)[k:],
                np.concatenate(self.accel)[k:])


def record_hand(imu: Any, clock: Any, user: Any, writer: Any, *,
                rest_s: float = HAND_REST_S, tries: int = HAND_TRIES,
                poll_s: float = POLL_S) -> list[dict[str, Any]]:
    """Prompt ``user`` through the hand jig's steps while ``imu`` (started) is drained into
    ``writer``; each step checked by :func:`check_hand_step` and asked again with what was
    wrong.

    Parameters
    ----------
    imu : ImuReader
        Streaming.
    clock : Clock
        The reader's clock (``monotonic``, ``sleep``).
    user : gyrocal.kit.seating.Seater
        Who turns the box: prompted with the step's face and text, polled for Enter.
    writer : RecordingWriter
        Open; its manifest's ``protocol`` gains the steps taken and the ones refused.
    rest_s : float
        Rest recorded after each Enter, s.
    tries : int
    poll_s : float
        How often the FIFO is drained and Enter polled, s (within the FIFO's capacity at the
        chip's rate).

    Returns
    -------
    list of dict
        The steps taken (``kind``, ``face``, ``sense``, ``t_start`` of the rest checked).

    Raises
    ------
    ProtocolCheckError
        A step still not done after ``tries`` prompts.
    """
    from gyrocal.drivers.emulated.hand import hand_steps
    from gyrocal.kit.errors import ProtocolCheckError

    samples = _Samples()

    def drain_until(done: Any) -> None:
        while not done():
            clock.sleep(poll_s)
            batch = imu.read()
            if len(batch):
                writer.append_imu(batch.t, batch.rate, batch.temperature_c, accel=batch.accel)
                samples.add(batch)

    steps = hand_steps()
    taken: list[dict[str, Any]] = []
    refused: list[dict[str, Any]] = []
    start = 0  # first sample of the last rest taken
    for number, step in enumerate(steps, 1):
        problem = None
        for _ in range(tries):
            user.prompt(step[1], hand_prompt(step, number, len(steps), problem))
            drain_until(user.ready)
            entered, t_enter = samples.n, clock.monotonic()
            drain_until(lambda t_end=t_enter + rest_s: clock.monotonic() >= t_end)
            t, rate, accel = samples.since(start)
            problem = check_hand_step(t, rate, accel, step, entered - start)
            said = {"kind": step[0], "face": step[1], "sense": step[2], "t_start": t_enter}
            if problem is None:
                taken.append(said)
                writer.update_manifest(protocol={**writer.manifest["protocol"], "steps": taken})
                start = entered
                break
            refused.append({**said, "check": problem})
            writer.update_manifest(protocol={**writer.manifest["protocol"],
                                             "discarded": refused})
            if not problem.startswith(_NOT_STILL):
                start = entered  # the box rests: the next try starts from this rest
        else:
            raise ProtocolCheckError(f"{problem} (asked {tries} times): do as the prompt says "
                                     "(hardware_docs/hand-jig.md)")
    return taken


def _hand_writer(cfg: Any, args: argparse.Namespace, imu: Any, rec_dir: Path,
                 protocol: dict[str, Any], truth: dict[str, Any] | None = None) -> Any:
    """The hand jig's Recording v1 writer (``jig.kind = "hand"``, no servo, the site's
    gravity); ``truth`` for the emulated jig (which also says its stop's repeatability)."""
    from gyrocal.kit.pipeline import local_gravity
    from gyrocal.kit.recording import RecordingWriter

    gravity, source = local_gravity(cfg["accelerometer"])
    jig: dict[str, Any] = {"kind": "hand"}
    if truth is not None:
        from gyrocal.kit.sim import HAND_STOP_DEG

        jig["stop_std_deg"] = HAND_STOP_DEG
    return RecordingWriter(rec_dir, sensor=imu.info.manifest(), gimbal={"motors": []},
                           protocol=protocol, truth=truth, force=getattr(args, "force", False),
                           accel=True, extra={"jig": jig, "site": {
                               "gravity_m_s2": gravity, "gravity_from": source}})


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
    from gyrocal.kit.sim import SIM_SENSOR, build_hand_sim

    if not args.sim:
        raise InputError("record_hand_sim runs the emulated hand jig (--sim); on hardware "
                         "use record_hand_live")
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
    motion = sim.jig
    truth = {**sim.truth.manifest(), "box_axes": motion.box_axes().tolist(),
             "turn_angles_rad": list(motion.turn_angles)}
    schedule = [{"kind": p.kind, "t_start": p.t_start, "t_end": p.t_end, "axis": p.axis,
                 "angle_rad": p.angle} for p in motion.schedule]
    try:
        with _hand_writer(cfg, args, imu, rec_dir, {"name": "hand", "schedule": schedule},
                          truth=truth) as writer:
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


def record_hand_live(cfg: Any, args: argparse.Namespace, rec_dir: Path) -> None:
    """Record the hand jig on hardware into ``rec_dir``: the configured IMU only (no servo bus
    is opened), the user prompted at the terminal (:class:`~gyrocal.kit.seating.TerminalSeater`)
    through :func:`record_hand`.

    Raises
    ------
    InputError
        With several sensors or an emulation flag.
    InterruptedRun
        On Ctrl-C, SIGTERM or SIGHUP: the recording, if begun, is kept, marked incomplete.
    """
    from gyrocal.drivers import signals
    from gyrocal.drivers.clock import SystemClock
    from gyrocal.drivers.imu import open_imu
    from gyrocal.kit.errors import InputError, InterruptedRun
    from gyrocal.kit.jig import note_rounded_odr, resolve_sensor
    from gyrocal.kit.seating import TerminalSeater

    if len(cfg.imus()) > 1 or args.sim_fault or getattr(args, "sim_imu", False):
        raise InputError("--jig hand records one sensor on a box: no [[imu]] plate, "
                         "--sim-fault or --sim-imu")
    imu_cfg, clock = cfg["imu"], SystemClock()
    chip = resolve_sensor(imu_cfg, imu_cfg["bus"])
    imu = open_imu(imu_cfg["model"], imu_cfg["bus"], chip["address"], clock=clock,
                   range_dps=imu_cfg["range_dps"], odr_hz=chip["odr_hz"])
    note_rounded_odr(imu_cfg["odr_hz"], imu.info)
    old = signals.install()
    try:
        with _hand_writer(cfg, args, imu, rec_dir, {"name": "hand"}) as writer:
            imu.start()
            record_hand(imu, clock, TerminalSeater(), writer)
            imu.stop()
            writer.finish()
    except (KeyboardInterrupt, signals.TerminatedBySignal) as exc:
        signum = getattr(exc, "signum", 2)
        what = {2: "interrupted", 15: "terminated", 1: "hung up"}.get(signum, "stopped")
        kept = (f"the recording in {rec_dir} is kept, marked incomplete"
                if (rec_dir / "manifest.json").exists() else "no recording was begun")
        raise InterruptedRun(f"{what}: {kept}", signum) from None
    finally:
        with signals.shielded():
            imu.close()
        signals.restore(old)
