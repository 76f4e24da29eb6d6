"""The protocol runner: one loop on one clock drives the jig and records everything.

Each iteration drains the IMU FIFO, does one sync read of the servos, appends both to the
recording and steps the plan: for each servo a rest, whole turns one way, a rest, the same turns
back (ending where it started), and a final rest; for the full model, then each posed pair (a
servo moved to a pose, recorded as a ``move`` segment, the turns of another servo, the move
back). After each turn or rest the runner checks what it recorded:

* a turn held its commanded speed (the encoder's median speed over its middle half);
* the gyro did not saturate;
* no FIFO gap fell inside the step;
* the sensor did not move during a rest (gyro and encoders).

A failed check repeats the step once (a failed turn is first reversed, so the cables never wind
past the plan's excursion); a second failure stops the run with a :class:`ProtocolCheckError`
saying what to change.
"""

from __future__ import annotations

import contextlib
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from gyrocal.calib.design import Plan
from gyrocal.calib.observations import diff_noise
from gyrocal.calib.segments import Segment
from gyrocal.drivers.clock import Clock
from gyrocal.drivers.errors import DriverError
from gyrocal.kit.errors import ProtocolCheckError
from gyrocal.kit.recording import RecordingWriter

__all__ = ["CheckFailure", "Runner", "Step", "build_steps"]


@dataclass(frozen=True)
class Step:
    """One step of the protocol."""

    kind: str  # "rest", "rotate" or "move"
    motor: int | None = None
    direction: int = 0
    turns: int = 0
    speed: float = 0.0
    rest_s: float = 0.0
    angle: float = 0.0  # a move's goal, rad from home

    def describe(self) -> str:
        """Human-readable, e.g. ``turn servo 2, 2 turns at 200°/s, negative``."""
        if self.kind == "rest":
            return f"rest {self.rest_s:.1f} s"
        if self.kind == "move":
            return f"move servo {self.motor} to {math.degrees(self.angle):+.0f}°"
        sign = "positive" if self.direction > 0 else "negative"
        return (f"turn servo {self.motor}, {self.turns} turn{'s' * (self.turns != 1)} at "
                f"{math.degrees(self.speed):.0f}°/s, {sign}")


def build_steps(plan: Plan, ids: Sequence[int]) -> list[Step]:
    """The plan as steps: per servo rest, turn −, rest, turn +; then a final rest; then, for
    each posed pair of the full model (:attr:`~gyrocal.calib.design.Plan.poses`), move a servo
    to its pose, rest, turn the other −, rest, +, rest, and move the first back home
    (:func:`gyrocal.calib.design.full_schedule` is the same order).

    Turning the negative way first and back again ends every servo where it started; every
    move is undone, so the run ends in the home pose.

    Raises
    ------
    ValueError
        If a pose names a chain position beyond ``ids``.
    """
    def turns(motor: int) -> list[Step]:
        out = []
        for d in (-1, 1):
            out.append(Step("rest", rest_s=plan.rest_s))
            out.append(Step("rotate", motor=int(motor), direction=d, turns=plan.turns,
                            speed=plan.speed))
        return out

    steps: list[Step] = []
    for motor in ids:
        steps += turns(motor)
    steps.append(Step("rest", rest_s=plan.rest_s))
    for turn, moved, angle in plan.poses:
        if max(turn, moved) >= len(ids):
            raise ValueError(f"pose ({turn}, {moved}) names a servo beyond the chain {ids}")
        steps.append(Step("move", motor=int(ids[moved]), angle=angle, speed=plan.speed))
        steps += turns(ids[turn])[1:]
        steps.append(Step("rest", rest_s=plan.rest_s))
        steps.append(Step("move", motor=int(ids[moved]), angle=0.0, speed=plan.speed))
    return steps


@dataclass(frozen=True)
class CheckFailure:
    """A runtime check that failed, with what to change."""

    check: str
    step: int
    message: str


class _StepData:
    """Samples seen during one step (times on the recording clock)."""

    def __init__(self) -> None:
        self.imu_t: list[np.ndarray] = []
        self.imu_rate: list[np.ndarray] = []
        self.saturated = 0
        self.gaps: list[Any] = []
        self.enc_t: list[float] = []
        self.enc_angles: list[np.ndarray] = []

    def arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        it = np.concatenate(self.imu_t) if self.imu_t else np.zeros(0)
        ir = np.concatenate(self.imu_rate) if self.imu_rate else np.zeros((0, 3))
        et = np.asarray(self.enc_t)
        ea = np.vstack(self.enc_angles) if self.enc_angles else np.zeros((0, 0))
        return it, ir, et, ea


class Runner:
    """Run a protocol on a gimbal and an IMU, recording as it goes.

    Parameters
    ----------
    gimbal : gyrocal.drivers.dynamixel.Gimbal
        Opened; its ``ids`` are the servos.
    imu : gyrocal.drivers.imu.ImuReader
        Configured, not yet streaming.
    writer : RecordingWriter
        Receives every sample and each finished segment.
    clock : Clock
        The clock of both devices.
    steps : sequence of Step
        From :func:`build_steps`.
    sample_hz : float
        Loop rate.
    on_progress : callable, optional
        Called as ``on_progress(runner, batch_rate, sample)`` after every iteration.
    on_event : callable, optional
        Called with a line of text at each step boundary and repeat.
    speed_fraction : float
        A turn must reach this fraction of its commanded speed.
    rest_guard_s : float
        Settling time at each end of a rest that the movement check skips.
    """

    def __init__(
        self,
        gimbal: Any,
        imu: Any,
        writer: RecordingWriter,
        clock: Clock,
        steps: Sequence[Step],
        *,
        sample_hz: float = 200.0,
        on_progress: Callable[..., None] | None = None,
        on_event: Callable[[str], None] | None = None,
        speed_fraction: float = 0.95,
        rest_guard_s: float = 0.2,
    ) -> None:
        self.gimbal = gimbal
        self.imu = imu
        self.writer = writer
        self.clock = clock
        self.steps = list(steps)
        self.period = 1.0 / float(sample_hz)
        self.on_progress = on_progress
        self.on_event = on_event or (lambda line: None)
        self.speed_fraction = speed_fraction
        self.rest_guard_s = rest_guard_s
        self.ids = tuple(gimbal.ids)
        self.t0 = 0.0
        self.step_index = 0
        self.step_desc = ""
        self._data: _StepData | None = None
        self._next = 0.0
        # Loop dither (see _tick); seeded so that runs repeat exactly.
        self._dither = np.random.default_rng(0x6779726F)
        self._rest_s = max((s.rest_s for s in self.steps if s.kind == "rest"), default=0.5)
        self._segments: list[Segment] = []
        self._pose: dict[int, float] = {}  # servo -> angle of its last move (0 = home)
        self._posed: set[int] = set()  # indices of the segments turned in a pose
        self.last_rate = np.zeros(3)
        self.last_speed = 0.0

    # ------------------------------------------------------------------ loop
    def now(self) -> float:
        """Time on the recording clock, s."""
        return self.clock.monotonic() - self.t0

    def _tick(self) -> None:
        batch = self.imu.read()
        d = self._data
        if len(batch):
            t = batch.t - self.t0
            self.writer.append_imu(t, batch.rate, batch.temperature_c)
            self.last_rate = batch.rate[-1]
            if d is not None:
                d.imu_t.append(t)
                d.imu_rate.append(batch.rate)
                d.saturated += int(np.any(batch.saturated, axis=-1).sum())
        if batch.gaps:
            if d is not None:
                d.gaps.extend(batch.gaps)
            for g in batch.gaps:
                self.on_event(f"lost {g.samples} gyro samples at {g.t - self.t0:.2f} s "
                              f"({g.reason})")
        s = self.gimbal.poll()
        ts = s.t - self.t0
        self.writer.append_encoder(ts, list(s.ids), s.angles)
        if d is not None:
            d.enc_t.append(ts)
            d.enc_angles.append(np.asarray(s.angles, dtype=float))
        if s.velocities is not None:
            self.last_speed = float(np.max(np.abs(s.velocities)))
        if self.on_progress is not None:
            self.on_progress(self, batch, s)
        # Dither each period by up to ±half a period: drains then fall at random phases of the
        # chip's sample grid, as the reader's clock fit assumes. A loop locked to the output data
        # rate would creep through the phase over many seconds and bias the fitted sample period
        # (a stretched IMU time axis is a scale error; DESIGN.md fact 2).
        self._next += self.period * (1.0 + self._dither.uniform(-0.5, 0.5))
        wait = self._next - self.clock.monotonic()
        if wait > 0:
            self.clock.sleep(wait)
        else:
            self._next = self.clock.monotonic()  # late: do not try to catch up in a burst

    # ------------------------------------------------------------------ steps
    def _run_rest(self, step: Step) -> tuple[float, float]:
        start = self.now()
        while self.now() < start + step.rest_s:
            self._tick()
        return start, self.now()

    def _run_turn(self, step: Step) -> tuple[float, float, Any]:
        """A turn, or a move to a pose: start it, loop until the driver finds it finished."""
        start = self.now()
        if step.kind == "move":
            motion = self.gimbal.begin_move(step.motor, step.angle, step.speed)
        else:
            motion = self.gimbal.begin_turn(step.motor, step.turns, step.speed, step.direction)
        while self.gimbal.busy:
            self._tick()
        self._tick()  # one reading at rest after the stop
        return start, self.now(), motion

    def _record(self, seg: Segment) -> None:
        self.writer.append_segment(seg)
        self._segments.append(seg)

    def _settle(self, turn: Step) -> None:
        """A rest before a repeated turn, recorded as a rest segment if it passes its check, so
        that the repeat has still time before it as every other turn does."""
        rest = Step("rest", rest_s=max(self._rest_s, 0.3))
        self._data = _StepData()
        t_start, t_end = self._run_rest(rest)
        if self._check_rest(rest, self._data) is None:
            self._record(Segment(len(self._segments), "rest", None, 0, 0.0, t_start, t_end))

    def _reposition(self, step: Step) -> None:
        """Undo a failed turn (turn back the same way it came), without recording a segment."""
        self.gimbal.begin_turn(step.motor, step.turns, step.speed, -step.direction)
        while self.gimbal.busy:
            self._tick()

    # ------------------------------------------------------------------ checks
    def _check_turn(self, step: Step, motion: Any, d: _StepData) -> CheckFailure | None:
        it, ir, et, ea = d.arrays()
        if d.saturated:
            return CheckFailure(
                "saturation", self.step_index,
                f"the gyro saturated during '{step.describe()}' ({d.saturated} samples at full "
                "scale): raise imu.range_dps or lower the speed (protocol.speed_dps)",
            )
        if d.gaps:
            lost = sum(g.samples for g in d.gaps)
            return CheckFailure(
                "fifo-gap", self.step_index,
                f"{lost} gyro samples were lost during '{step.describe()}' (FIFO overflow): raise "
                "gimbal.sample_hz, lower imu.odr_hz, or use a faster I2C bus (400 kHz)",
            )
        j = self.ids.index(step.motor)
        reached = 0.0
        if et.size >= 5:
            # The speed held over the middle half of the turn (its median), so that a servo which
            # reaches the speed but then drags is caught too.
            ang = ea[:, j]
            span = max(1, int(round(0.1 / max(np.median(np.diff(et)), 1e-6))))
            v = np.abs(ang[span:] - ang[:-span]) / np.maximum(et[span:] - et[:-span], 1e-9)
            tv = 0.5 * (et[span:] + et[:-span])
            quarter = (et[-1] - et[0]) / 4
            mid = (tv >= et[0] + quarter) & (tv <= et[-1] - quarter)
            if mid.any():
                reached = float(np.median(v[mid]))
        commanded = float(getattr(motion, "speed", step.speed))
        if reached < self.speed_fraction * commanded:
            return CheckFailure(
                "speed", self.step_index,
                f"servo {step.motor} held only {reached:.2f} of {commanded:.2f} rad/s: lower "
                "the speed (protocol.speed_dps), check the supply voltage, or free the joint",
            )
        return None

    def _check_rest(self, step: Step, d: _StepData) -> CheckFailure | None:
        it, ir, et, ea = d.arrays()
        if d.gaps:
            return CheckFailure(
                "fifo-gap", self.step_index,
                "gyro samples were lost during a rest (FIFO overflow): raise gimbal.sample_hz or "
                "lower imu.odr_hz",
            )
        if et.size and ea.size and np.any(np.ptp(ea, axis=0) > 6 * 2 * np.pi / 4096):
            return CheckFailure(
                "moved", self.step_index,
                "a servo moved during a rest: check that nothing pushes the gimbal and that the "
                "servos hold (torque on, not overloaded)",
            )
        if it.size < 20:
            return None
        keep = (it >= it[0] + self.rest_guard_s) & (it <= it[-1] - self.rest_guard_s)
        x = ir[keep]
        if x.shape[0] < 20:
            return None
        dt = float(np.median(np.diff(it)))
        n = max(2, int(round(0.05 / dt)))
        sigma = diff_noise(x)
        kernel = np.ones(n) / n
        avg = np.column_stack([np.convolve(x[:, j], kernel, mode="valid") for j in range(3)])
        dev = np.abs(avg - np.median(x, axis=0))
        limit = np.maximum(8 * sigma / np.sqrt(n), 0.03)
        if np.any(dev > limit):
            return CheckFailure(
                "moved", self.step_index,
                "the sensor moved during a rest (the gyro saw a rotation while every servo held):"
                " tighten the sensor's mount and keep the jig free of vibration",
            )
        return None

    def turn_times(self) -> dict[int, list[float]]:
        """Mid-times (recording clock) of each servo's recorded turns in the home pose."""
        out: dict[int, list[float]] = {}
        for seg in self._segments:
            if seg.kind == "rotate" and seg.motor is not None and seg.index not in self._posed:
                out.setdefault(seg.motor, []).append(0.5 * (seg.t_start + seg.t_end))
        return out

    # ------------------------------------------------------------------ run
    def run(self) -> None:
        """Carry out every step; the recording gets every sample and segment.

        Raises
        ------
        ProtocolCheckError
            When a step fails its check twice.
        """
        self.t0 = self.clock.monotonic()
        self._next = self.t0
        self.imu.start()
        try:
            for i, step in enumerate(self.steps):
                self.step_index = i
                self.step_desc = step.describe()
                for attempt in (1, 2):
                    self._data = _StepData()
                    self.on_event(f"step {i + 1}/{len(self.steps)}: {self.step_desc}"
                                  + (" (repeat)" if attempt == 2 else ""))
                    motion = None
                    if step.kind == "rest":
                        t_start, t_end = self._run_rest(step)
                        failure = self._check_rest(step, self._data)
                    elif step.kind == "move":
                        t_start, t_end, motion = self._run_turn(step)
                        failure = None  # the driver finished it on its goal, still
                        self._pose[step.motor] = step.angle
                    else:
                        t_start, t_end, motion = self._run_turn(step)
                        failure = self._check_turn(step, motion, self._data)
                    if failure is None:
                        speed = float(motion.speed) if motion is not None else 0.0
                        direction = step.direction
                        if step.kind == "move":
                            direction = motion.direction or 1  # type: ignore[union-attr]
                        elif step.kind == "rotate" and any(self._pose.values()):
                            self._posed.add(len(self._segments))
                        self._record(Segment(len(self._segments), step.kind, step.motor,
                                             direction, speed, t_start, t_end))
                        break
                    if attempt == 2:
                        raise ProtocolCheckError(f"{failure.message} (failed twice)")
                    self.on_event(f"check failed, repeating once: {failure.message}")
                    if step.kind == "rotate":
                        self._reposition(step)
                        self._settle(step)
            self._data = None
        except BaseException:
            # Stopping a failed IMU may fail too: that must not hide the error that stopped us.
            with contextlib.suppress(DriverError):
                self.imu.stop()
            raise
        else:
            self.imu.stop()
