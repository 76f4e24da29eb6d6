"""The protocol runner: one loop on one clock drives the jig and records everything.

Each iteration drains the IMU FIFO, does one sync read of the servos, appends both to the
recording and steps the plan: for each servo a rest, whole turns one way, a rest, the same turns
back (ending where it started), and a final rest; for the full model, then each posed pair (a
servo moved to a pose, recorded as a ``move`` segment, the turns of another servo, the move
back). After each turn or rest the runner checks what it recorded:

* a turn held its commanded speed (the encoder's median speed over its middle half);
* the gyro did not saturate;
* the sensor did not move during a rest (gyro and encoders);
* the host kept the loop on time: no FIFO gap fell inside the step, and no gap between two
  servo polls during a turn exceeded ``gap_limit_s`` (half the servos' Bus Watchdog by default).

A step that fails the last check was *disturbed* by host load, not by the jig: it is repeated
up to ``max_repeats`` times before the run stops. A step that fails one of the others is repeated
once; a second failure stops the run with a :class:`ProtocolCheckError` saying what to change.
A failed turn is first reversed, so the cables never wind past the plan's excursion. A failed
attempt is never a segment of the recording (so it is never fitted); it is listed in the
manifest's ``protocol.discarded`` with its times and the check that failed.

Several sensors on one plate (``imu`` a list of readers, ``writer`` a
:class:`~gyrocal.kit.plate.RecordingGroup`) are drained one after the other in every iteration,
each into its own recording. A check that one sensor's data fail (saturation, a movement on its
mount, lost FIFO samples) fails that sensor alone once it has used up its repeats, as does a
sensor that stops answering; the run goes on with the others, and stops only when none is left.
The encoder checks (speed, a servo that moved) concern every sensor.

The loop itself only drains the FIFOs, polls the servos and steps the plan. Writing the recording
and drawing progress run in a consumer thread behind a bounded queue (:mod:`gyrocal.kit.backlog`),
so a slow disk or terminal cannot delay a servo poll.
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
from gyrocal.drivers.clock import Clock, VirtualClock
from gyrocal.drivers.errors import DriverError
from gyrocal.kit.backlog import Backlog, RunStatus
from gyrocal.kit.errors import HardwareError, ProtocolCheckError
from gyrocal.kit.recording import RecordingWriter

__all__ = ["CheckFailure", "Runner", "Step", "build_steps"]


@dataclass(frozen=True)
class Step:
    """One step of the protocol."""

    kind: str  # "rest", "rotate", "move", "still" (still time only: no segment, no check) or
    # "seat" (the single-servo jig: the user re-seats the cube; no segment)
    motor: int | None = None
    direction: int = 0
    turns: int = 0
    speed: float = 0.0
    rest_s: float = 0.0
    angle: float = 0.0  # a move's goal, rad from home
    seat: str = ""  # a "seat" step's seat (gyrocal.calib.design.SEATS)

    def describe(self) -> str:
        """Human-readable, e.g. ``turn servo 2, 2 turns at 200°/s, negative``."""
        if self.kind == "rest":
            return f"rest {self.rest_s:.1f} s"
        if self.kind == "still":
            return f"hold still {self.rest_s:.1f} s"
        if self.kind == "seat":
            return f"re-seat the cube with {self.seat} up"
        if self.kind == "move":
            return f"move servo {self.motor} to {math.degrees(self.angle):+.0f}°"
        sign = "positive" if self.direction > 0 else "negative"
        return (f"turn servo {self.motor}, {self.turns} turn{'s' * (self.turns != 1)} at "
                f"{math.degrees(self.speed):.0f}°/s, {sign}")


def build_steps(plan: Plan, ids: Sequence[int]) -> list[Step]:
    """The plan as steps, in :func:`gyrocal.calib.design.protocol_sequence`'s order: per servo
    rest, turn −, rest, turn +; then a final rest; then, for each posed pair of the full model
    (:attr:`~gyrocal.calib.design.Plan.poses`), move a servo to its pose, hold still
    (:data:`~gyrocal.calib.design.POSE_SETTLE_S`), turn the other −, rest, +, rest, and move
    the first back home (:func:`gyrocal.calib.design.full_schedule` is
    the same order); then, for each gravity pose (:attr:`~gyrocal.calib.design.Plan.gravity_poses`),
    move the servo there, rest, and back. The accelerometer's moves
    (:attr:`~gyrocal.calib.design.Plan.accel_moves`) tilt some rests (a move between a servo's
    two turns goes to the angle less the turns it has made, the same orientation); the run ends
    with every servo moved home.

    Turning the negative way first and back again ends every servo where it started; every
    move is undone, so the run ends in the home pose.

    Raises
    ------
    ValueError
        If a pose names a chain position beyond ``ids``.
    """
    from gyrocal.calib.design import protocol_sequence
    from gyrocal.calib.errors import CalibInputError

    if plan.seats:
        return _seat_steps(plan, ids)
    try:
        seq = protocol_sequence(plan, len(ids))
    except CalibInputError as exc:
        raise ValueError(f"{exc} (servos {list(ids)})") from None
    steps: list[Step] = []
    for st in seq:
        if st[0] == "rest":
            steps.append(Step("rest", rest_s=plan.rest_s))
        elif st[0] == "still":
            steps.append(Step("still", rest_s=float(st[1])))
        elif st[0] == "rotate":
            steps.append(Step("rotate", motor=int(ids[st[1]]), direction=st[2], turns=plan.turns,
                              speed=plan.speed))
        else:
            steps.append(Step("move", motor=int(ids[st[1]]), angle=st[2], speed=plan.speed))
    return steps


def _seat_steps(plan: Plan, ids: Sequence[int]) -> list[Step]:
    """A single-servo plan (:attr:`~gyrocal.calib.design.Plan.seats`) as steps: per seat, the
    re-seat, then rest, turn −, rest, turn +, rest."""
    if len(ids) != 1:
        raise ValueError(f"a single-servo plan drives one servo, got servos {list(ids)}")
    steps: list[Step] = []
    for seat in plan.seats:
        steps.append(Step("seat", seat=seat))
        for d in (-1, 1):
            steps += [Step("rest", rest_s=plan.rest_s),
                      Step("rotate", motor=int(ids[0]), direction=d, turns=plan.turns,
                           speed=plan.speed)]
        steps.append(Step("rest", rest_s=plan.rest_s))
    return steps


@dataclass(frozen=True)
class CheckFailure:
    """A runtime check that failed, with what to change; ``disturbed`` when the cause was the
    host (a FIFO gap, a late servo poll), not the jig; ``sensor`` the index of the one sensor
    whose data failed it (None: the jig's, every sensor's)."""

    check: str
    step: int
    message: str
    disturbed: bool = False
    sensor: int | None = None


class _StepData:
    """Samples seen during one step (times on the recording clock)."""

    def __init__(self) -> None:
        self.imu_t: list[np.ndarray] = []
        self.imu_rate: list[np.ndarray] = []
        self.imu_accel: list[np.ndarray] = []
        self.saturated = 0
        self.gaps: list[Any] = []
        self.max_poll_gap = 0.0  # longest gap the servos went without a packet in motion, s
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
    imu : gyrocal.drivers.imu.ImuReader or list of them
        Configured, not yet streaming; a list for several sensors on the plate.
    writer : RecordingWriter or RecordingGroup
        Receives every sample and each finished segment; with several sensors a
        :class:`~gyrocal.kit.plate.RecordingGroup` of one writer per sensor.
    clock : Clock
        The clock of both devices.
    steps : sequence of Step
        From :func:`build_steps`.
    sample_hz : float
        Loop rate.
    on_progress : callable, optional
        Called as ``on_progress(status)`` with a :class:`~gyrocal.kit.backlog.RunStatus`, from
        the consumer thread, at most once per queue drain.
    on_event : callable, optional
        Called as ``on_event(line, t)`` (``t`` the jig time) at each step boundary and repeat,
        from the consumer thread.
    speed_fraction : float
        A turn must reach this fraction of its commanded speed.
    rest_guard_s : float
        Settling time at each end of a rest that the movement check skips.
    max_repeats : int
        How many times a step disturbed by host load is repeated before the run stops.
    gap_limit_s : float or None
        A gap between two servo polls during a turn longer than this marks the turn disturbed;
        default half the gimbal's Bus Watchdog (``gimbal.watchdog_s``), which stops the servo
        at the full period.
    backlog_s : float
        Loop iterations the recording and progress may fall behind, in seconds of loop time,
        before the run stops with :class:`~gyrocal.kit.backlog.BacklogError`.
    sensor_names : sequence of str, optional
        Each sensor's name, for messages (several sensors).
    seater : gyrocal.kit.seating.Seater, optional
        Who re-seats the cube at a ``seat`` step (the single-servo jig); each seat taken is
        listed in the manifest's ``protocol.seats`` with its start time and the gravity the
        check read.
    max_seat_tries : int
        Prompts per seat before a cube still seated wrong stops the run.
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
        max_repeats: int = 3,
        gap_limit_s: float | None = None,
        backlog_s: float = 5.0,
        sensor_names: Sequence[str] | None = None,
        seater: Any = None,
        max_seat_tries: int = 3,
    ) -> None:
        self.gimbal = gimbal
        self.imus = list(imu) if isinstance(imu, (list, tuple)) else [imu]
        self.imu = self.imus[0]
        self.names = (list(sensor_names) if sensor_names is not None
                      else [f"sensor {k + 1}" for k in range(len(self.imus))])
        if len(self.names) != len(self.imus):
            raise ValueError(f"{len(self.imus)} sensors but {len(self.names)} sensor_names")
        #: Sensors that failed, by index: what failed them.
        self.failed: dict[int, str] = {}
        self.writer = writer
        self.clock = clock
        self.steps = list(steps)
        self.period = 1.0 / float(sample_hz)
        self.on_progress = on_progress
        self.on_event = on_event
        self.speed_fraction = speed_fraction
        self.rest_guard_s = rest_guard_s
        if int(max_repeats) < 0:
            raise ValueError(f"max_repeats must be >= 0, got {max_repeats!r}")
        self.max_repeats = int(max_repeats)
        if gap_limit_s is None:
            gap_limit_s = 0.5 * float(getattr(gimbal, "watchdog_s", 0.1))
        if not (math.isfinite(gap_limit_s) and gap_limit_s > 0):
            raise ValueError(f"gap_limit_s must be a positive number of s, got {gap_limit_s!r}")
        self.gap_limit_s = float(gap_limit_s)
        # The slow part (recording, progress) runs behind a bounded queue; on an emulated clock
        # the loop waits for room rather than fail, as nothing there is due in wall time.
        self.backlog = Backlog(
            writer, capacity=math.ceil(backlog_s / self.period) + 256,
            realtime=not isinstance(clock, VirtualClock), on_event=on_event,
            on_status=on_progress)
        #: Failed attempts of steps (never segments): one manifest entry each.
        self.discarded: list[dict[str, Any]] = []
        self.ids = tuple(gimbal.ids)
        self.t0 = 0.0
        self.step_index = 0
        self.step_desc = ""
        self._data: list[_StepData] | None = None  # one per sensor during a step
        self._next = 0.0
        # Loop dither (see _tick); seeded so that runs repeat exactly.
        self._dither = np.random.default_rng(0x6779726F)
        self._dithers: list[float] = []  # drawn ahead from _dither, next one last
        self._rest_s = max((s.rest_s for s in self.steps if s.kind == "rest"), default=0.5)
        self._segments: list[Segment] = []
        self._pose: dict[int, float] = {}  # servo -> angle of its last move (0 = home)
        self._posed: set[int] = set()  # indices of the segments turned in a pose
        self.last_rate = np.zeros(3)
        self.last_speed = 0.0
        self.seater = seater
        self.max_seat_tries = int(max_seat_tries)
        #: The seats taken (single-servo jig), as the manifest's ``protocol.seats`` lists them.
        self.seats: list[dict[str, Any]] = []

    # ------------------------------------------------------------------ loop
    def now(self) -> float:
        """Time on the recording clock, s."""
        return self.clock.monotonic() - self.t0

    def _event(self, line: str) -> None:
        """A line for the user, through the consumer thread (in order with the samples)."""
        self.backlog.put_event(line, self.now())

    @property
    def several(self) -> bool:
        """True with more than one sensor on the plate."""
        return len(self.imus) > 1

    def _drain(self, k: int, datas: list[_StepData] | None) -> Any:
        """Read sensor ``k``'s FIFO into the step's data; its rows for the recording, or None.
        With several sensors, one that stops answering is failed alone."""
        try:
            batch = self.imus[k].read()
        except DriverError as exc:
            if not self.several:
                raise
            self.fail_sensor(k, f"stopped answering ({exc})", HardwareError.exit_code)
            return None
        d = datas[k] if datas is not None else None
        rows = None
        if len(batch):
            t = batch.t - self.t0
            rows = (t, batch.rate, batch.temperature_c, batch.accel)
            if k == (min(set(range(len(self.imus))) - set(self.failed)) if self.failed else 0):
                self.last_rate = batch.rate[-1]
            if d is not None:
                d.imu_t.append(t)
                d.imu_rate.append(batch.rate)
                if batch.accel is not None:
                    d.imu_accel.append(batch.accel)
                if batch.saturated.any():
                    d.saturated += int(np.any(batch.saturated, axis=-1).sum())
        if batch.gaps and d is not None:
            d.gaps.extend(batch.gaps)
        who = f"{self.names[k]}: " if self.several else ""
        for g in batch.gaps:
            self._event(f"{who}lost {g.samples} gyro samples at {g.t - self.t0:.2f} s "
                        f"({g.reason})")
        return rows

    def fail_sensor(self, k: int, message: str, exit_code: int = ProtocolCheckError.exit_code
                    ) -> None:
        """Fail sensor ``k`` alone (several sensors): its reader stops, its recording is closed
        incomplete with ``message`` and ``exit_code`` (what the run would exit with for it
        alone: 4 hardware, 5 a check) in order with the rows before it; the run goes on.

        Raises
        ------
        HardwareError
            When no sensor is left.
        """
        self.failed[k] = message
        with contextlib.suppress(DriverError):
            self.imus[k].stop()
        self.backlog.put_call(self.writer.fail, k, message, exit_code)
        if len(self.failed) == len(self.imus):
            raise HardwareError("every sensor on the plate failed: " + "; ".join(
                f"{self.names[j]} {m}" for j, m in sorted(self.failed.items())))
        self._event(f"{self.names[k]} failed: {message}; the run goes on with the others")

    def _tick(self) -> None:
        datas = self._data
        rows = [None if k in self.failed else self._drain(k, datas)
                for k in range(len(self.imus))]
        d = datas[0] if datas is not None else None
        imu_rows = rows if self.several else rows[0]
        s = self.gimbal.poll()
        for dk in datas or ():
            dk.max_poll_gap = max(dk.max_poll_gap, self.gimbal.last_poll_gap_s)
        ts = s.t - self.t0
        self.backlog.put_samples(imu_rows, (ts, list(s.ids), s.angles))
        if d is not None:  # the sensors' step data share the encoder lists
            d.enc_t.append(ts)
            d.enc_angles.append(np.asarray(s.angles, dtype=float))
        if s.velocities is not None:
            self.last_speed = max(map(abs, s.velocities.tolist()))
        if self.on_progress is not None:
            self.backlog.set_status(RunStatus(ts, self.step_index, len(self.steps),
                                              self.step_desc, self.last_rate, self.last_speed))
        # Dither each period by up to ±half a period: drains then fall at random phases of the
        # chip's sample grid, as the reader's clock fit assumes. A loop locked to the output data
        # rate would creep through the phase over many seconds and bias the fitted sample period
        # (a stretched IMU time axis is a scale error; DESIGN.md fact 2).
        self._next += self.period * (1.0 + self._next_dither())
        wait = self._next - self.clock.monotonic()
        if wait > 0:
            self.clock.sleep(wait)
        else:
            self._next = self.clock.monotonic()  # late: do not try to catch up in a burst

    def _next_dither(self) -> float:
        """The next of ``_dither.uniform(-0.5, 0.5)``'s values, drawn 256 at a time (the
        generator gives the same values in the same order either way)."""
        if not self._dithers:
            self._dithers = self._dither.uniform(-0.5, 0.5, size=256).tolist()[::-1]
        return self._dithers.pop()

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
        self.backlog.put_segment(seg)
        self._segments.append(seg)

    def _settle(self, turn: Step) -> None:
        """A rest before a repeated turn, recorded as a rest segment if it passes its check, so
        that the repeat has still time before it as every other turn does."""
        rest = Step("rest", rest_s=max(self._rest_s, 0.3))
        self._data = self._new_data()
        t_start, t_end = self._run_rest(rest)
        if self._check(rest, None) is None:
            self._record(Segment(len(self._segments), "rest", None, 0, 0.0, t_start, t_end))

    def _reposition(self, step: Step) -> None:
        """Undo a failed turn (turn back the same way it came), without recording a segment."""
        self.gimbal.begin_turn(step.motor, step.turns, step.speed, -step.direction)
        while self.gimbal.busy:
            self._tick()

    # ------------------------------------------------------------------ checks
    def _new_data(self) -> list[_StepData]:
        """Empty step data, one per sensor, sharing the encoder lists."""
        first = _StepData()
        out = [first]
        for _ in self.imus[1:]:
            d = _StepData()
            d.enc_t, d.enc_angles = first.enc_t, first.enc_angles
            out.append(d)
        return out

    def _check(self, step: Step, motion: Any) -> CheckFailure | None:
        """The step's checks over every sensor still in the run: the host's first (it makes
        the others moot), then the sensor's data and the encoders'. The first failure, naming
        its sensor when there are several."""
        if self._data is None:
            return None
        alive = [k for k in range(len(self.imus)) if k not in self.failed]
        checks: list[Callable[[Step, _StepData], CheckFailure | None]] = [self._check_disturbed]
        if step.kind == "rest":
            checks += [self._check_rest, self._check_mount]
        elif step.kind == "rotate":
            checks.append(self._check_saturation)
        for check in checks:
            for k in alive:
                failure = check(step, self._data[k])
                if failure is not None:
                    if failure.check == "fifo-gap" or check in (self._check_saturation,
                                                                self._check_mount):
                        failure = self._blame(failure, k)
                    return failure
        if step.kind == "rotate" and alive:
            return self._check_speed(step, motion, self._data[alive[0]])
        return None

    def _blame(self, failure: CheckFailure, k: int) -> CheckFailure:
        """``failure`` as sensor ``k``'s (named in the message when there are several)."""
        if not self.several:
            return failure
        return CheckFailure(failure.check, failure.step, f"{self.names[k]}: {failure.message}",
                            failure.disturbed, sensor=k)

    def _check_disturbed(self, step: Step, d: _StepData) -> CheckFailure | None:
        """The host's part: gyro samples lost from the FIFO, or (in a turn or move) a gap
        between two servo polls beyond :attr:`gap_limit_s`. Either leaves the step's data with
        a hole the windows cannot be trusted across, though the jig did nothing wrong."""
        if d.gaps:
            lost = sum(g.samples for g in d.gaps)
            return CheckFailure(
                "fifo-gap", self.step_index,
                f"{lost} gyro samples were lost during '{step.describe()}' (FIFO overflow): raise "
                "gimbal.sample_hz, lower imu.odr_hz, use a faster I2C bus (400 kHz), or lower "
                "the host's load", disturbed=True,
            )
        if step.kind != "rest" and d.max_poll_gap > self.gap_limit_s:
            return CheckFailure(
                "poll-gap", self.step_index,
                f"the servos went {d.max_poll_gap * 1e3:.0f} ms without a poll during "
                f"'{step.describe()}' (limit {self.gap_limit_s * 1e3:.0f} ms, half the Bus "
                "Watchdog): the host is overloaded; stop other programs or lower "
                "gimbal.sample_hz", disturbed=True,
            )
        return None

    def _check_saturation(self, step: Step, d: _StepData) -> CheckFailure | None:
        """The gyro stayed within its range during a turn."""
        if d.saturated:
            return CheckFailure(
                "saturation", self.step_index,
                f"the gyro saturated during '{step.describe()}' ({d.saturated} samples at full "
                "scale): raise imu.range_dps or lower the speed (protocol.speed_dps)",
            )
        return None

    def _check_speed(self, step: Step, motion: Any, d: _StepData) -> CheckFailure | None:
        """The turning servo held its commanded speed (encoder only) over the middle half of
        the turn."""
        _, _, et, ea = d.arrays()
        duration = float(et[-1] - et[0]) if et.size else 0.0
        return self.servo_speed_failure(step.motor, float(getattr(motion, "speed", step.speed)),
                                        et, ea, duration)

    def servo_speed_failure(self, motor: int, commanded: float, et: np.ndarray, ea: np.ndarray,
                            duration: float) -> CheckFailure | None:
        """Whether servo ``motor`` held :attr:`speed_fraction` of ``commanded`` rad/s over the
        middle half of its motion, the first ``duration`` s of the step's encoder readings
        (``et``, ``ea`` with a column per servo): the median of its speed over 0.1 s spans
        there, so that a servo which reaches the speed but then drags is caught too."""
        reached = 0.0
        if et.size >= 5:
            ang = ea[:, self.ids.index(motor)]
            span = max(1, int(round(0.1 / max(np.median(np.diff(et)), 1e-6))))
            v = np.abs(ang[span:] - ang[:-span]) / np.maximum(et[span:] - et[:-span], 1e-9)
            tv = 0.5 * (et[span:] + et[:-span])
            mid = (tv >= et[0] + duration / 4) & (tv <= et[0] + 3 * duration / 4)
            if mid.any():
                reached = float(np.median(v[mid]))
        if reached < self.speed_fraction * commanded:
            return CheckFailure(
                "speed", self.step_index,
                f"servo {motor} held only {reached:.2f} of {commanded:.2f} rad/s: lower "
                "the speed (protocol.speed_dps), check the supply voltage, or free the joint",
            )
        return None

    def _check_rest(self, step: Step, d: _StepData) -> CheckFailure | None:
        it, ir, et, ea = d.arrays()
        if et.size and ea.size and np.any(np.ptp(ea, axis=0) > 6 * 2 * np.pi / 4096):
            return CheckFailure(
                "moved", self.step_index,
                "a servo moved during a rest: check that nothing pushes the gimbal and that the "
                "servos hold (torque on, not overloaded)",
            )
        return None

    def _check_mount(self, step: Step, d: _StepData) -> CheckFailure | None:
        """The gyro saw no rotation during a rest while every servo held."""
        it, ir, et, ea = d.arrays()
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
    def _discard(self, step: Step, t_start: float, t_end: float,
                 failure: CheckFailure) -> None:
        """List a failed attempt in the manifest's ``protocol.discarded`` (it is no segment)."""
        self.discarded.append({
            "step": failure.step, "kind": step.kind, "motor": step.motor,
            "direction": step.direction, "t_start": t_start, "t_end": t_end,
            "check": failure.check, "disturbed": failure.disturbed})
        self.backlog.put_manifest(protocol={"discarded": list(self.discarded)})

    def _run_step(self, step: Step) -> tuple[float, float, Any, CheckFailure | None]:
        """One attempt at a step: ``(t_start, t_end, motion or None, failure or None)``."""
        self._data = self._new_data()
        if step.kind == "rest":
            t_start, t_end = self._run_rest(step)
            return t_start, t_end, None, self._check(step, None)
        t_start, t_end, motion = self._run_turn(step)
        if step.kind == "move":
            self._pose[step.motor] = step.angle  # the driver finished it on its goal, still
        return t_start, t_end, motion, self._check(step, motion)

    def _segment(self, step: Step, t_start: float, t_end: float, motion: Any) -> Segment:
        speed = float(motion.speed) if motion is not None else 0.0
        direction = step.direction
        if step.kind == "move":
            direction = motion.direction or 1
        elif step.kind == "rotate" and step.motor in self.ids and any(
                self._pose.get(sid, 0.0) for sid in self.ids[self.ids.index(step.motor) + 1:]):
            # posed: a servo outside the turning one is away from home (the servos inside it,
            # tilted for the accelerometer's rests, leave the turn's axis in the sensor frame)
            self._posed.add(len(self._segments))
        return Segment(len(self._segments), step.kind, step.motor, direction, speed, t_start,
                       t_end)

    def _do_step(self, i: int, step: Step) -> None:
        """Run a step until it passes its checks: a disturbed attempt is repeated up to
        :attr:`max_repeats` times, a failed one once."""
        tries: dict[tuple[int | None, bool], int] = {}  # (sensor, disturbed) -> failures
        while True:
            self._event(f"step {i + 1}/{len(self.steps)}: {self.step_desc}"
                        + (" (repeat)" if tries else ""))
            t_start, t_end, motion, failure = self._run_step(step)
            if failure is None:
                self._record(self._segment(step, t_start, t_end, motion))
                return
            self._discard(step, t_start, t_end, failure)
            key = (failure.sensor, failure.disturbed)
            n = tries[key] = tries.get(key, 0) + 1
            if n > (self.max_repeats if failure.disturbed else 1):
                if failure.sensor is not None:
                    # one sensor's data failed on every repeat: it fails alone, and the others
                    # repeat the step
                    self.fail_sensor(failure.sensor, failure.message.split(": ", 1)[1]
                                     + f" (on {n} attempts)")
                elif failure.disturbed:
                    raise ProtocolCheckError(f"{failure.message} (disturbed {n} times in a row)")
                else:
                    raise ProtocolCheckError(f"{failure.message} (failed twice)")
            elif failure.disturbed:
                self._event(f"disturbed by the host, repeating ({n}/{self.max_repeats}): "
                            f"{failure.message}")
            else:
                self._event(f"check failed, repeating once: {failure.message}")
            if step.kind == "rotate":
                self._reposition(step)
                self._settle(step)

    def run(self) -> None:
        """Carry out every step; the recording gets every sample and segment.

        Raises
        ------
        ProtocolCheckError
            When a step fails its check twice, or is disturbed more than
            :attr:`max_repeats` times.
        BacklogError
            When the recording falls too far behind.
        """
        self.t0 = self.clock.monotonic()
        self._next = self.t0
        self.backlog.start()
        try:
            for k, imu in enumerate(self.imus):
                try:
                    imu.start()
                except DriverError as exc:
                    if not self.several:
                        raise
                    self.fail_sensor(k, f"did not start ({exc})", HardwareError.exit_code)
            for i, step in enumerate(self.steps):
                self.step_index = i
                self.step_desc = step.describe()
                if step.kind == "seat":
                    self._run_seat(i, step)
                    continue
                if step.kind == "still":  # still time after a turn, before a move: no segment
                    # announced as every step is, so the numbers the user reads have no gaps
                    self._event(f"step {i + 1}/{len(self.steps)}: {self.step_desc}")
                    self._data = None
                    self._run_rest(step)
                    continue
                self._do_step(i, step)
            self._data = None
        except BaseException as exc:
            self._abort(exc)
            raise
        for k, imu in enumerate(self.imus):
            if k not in self.failed:
                imu.stop()
        self.backlog.close()

    def _run_seat(self, i: int, step: Step) -> None:
        """A re-seat of the cube (single-servo jig): prompt, keep the loop going until the
        user is done, then check the seat from gravity over
        :data:`~gyrocal.kit.seating.SEAT_CHECK_S` of still time; a wrong seat is prompted
        again with what is wrong (:func:`~gyrocal.kit.seating.check_seat`), up to
        :attr:`max_seat_tries` times. No segment: the windows never reach into a re-seat.

        Raises
        ------
        ProtocolCheckError
            When the cube is still seated wrong after the last prompt.
        """
        from gyrocal.kit.seating import SEAT_CHECK_S, check_seat, seat_prompt

        if self.seater is None:
            raise ValueError("a seat step needs a seater (the single-servo jig's user)")
        total = sum(s.kind == "seat" for s in self.steps)
        number = len(self.seats) + 1
        problem = None
        for _ in range(self.max_seat_tries):
            self._event(f"step {i + 1}/{len(self.steps)}: {self.step_desc}")
            self.seater.prompt(step.seat, seat_prompt(step.seat, number, total, problem))
            self._data = None
            while not self.seater.ready():
                self._tick()
            t_seated = self.now()
            self._data = self._new_data()
            self._run_rest(Step("rest", rest_s=SEAT_CHECK_S))
            accel = (np.concatenate(self._data[0].imu_accel) if self._data[0].imu_accel
                     else np.zeros((0, 3)))
            self._data = None
            problem = check_seat(accel, step.seat)
            if problem is None:
                up = accel.mean(axis=0)
                self.seats.append({"seat": step.seat, "t_start": t_seated,
                                   "gravity": (up / np.linalg.norm(up)).tolist()})
                self.backlog.put_manifest(protocol={"seats": list(self.seats)})
                return
            self._event(f"check failed: {problem}")
            self.discarded.append({"step": i, "kind": "seat", "seat": step.seat,
                                   "t_start": t_seated, "t_end": self.now(), "check": "seat",
                                   "disturbed": False})
            self.backlog.put_manifest(protocol={"discarded": list(self.discarded)})
        raise ProtocolCheckError(f"{problem} (asked {self.max_seat_tries} times): seat the cube "
                                 "as the prompt says (hardware_docs/single-servo.md)")

    def _abort(self, exc: BaseException) -> None:
        """On the way out with ``exc``: stop the servos first (the queue may take a while),
        then stop the IMU and write what the queue holds, within a bound."""
        from gyrocal.drivers.signals import shielded

        with shielded():
            if getattr(self.gimbal, "is_open", False):
                try:
                    self.gimbal.stop()
                except Exception as stop_exc:  # the gimbal's close tries again and reports it
                    exc.add_note(f"The safe stop after this error failed too: {stop_exc}")
            # Stopping a failed IMU may fail too: that must not hide the error that stopped us.
            for imu in self.imus:
                with contextlib.suppress(DriverError):
                    imu.stop()
            try:
                if not self.backlog.close(timeout_s=5.0):
                    exc.add_note("The recording's last rows could not be written within 5 s.")
            except Exception as write_exc:
                if write_exc is not exc:
                    exc.add_note(f"Writing the recording failed too: {write_exc}")
