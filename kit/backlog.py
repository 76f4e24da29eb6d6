"""The slow part of a run in its own thread, fed through a bounded queue.

The protocol loop (:class:`gyrocal.kit.protocol.Runner`) must poll the servos and drain the IMU
FIFO on time: a servo whose Bus Watchdog sees no packet for its period stops by itself (exit 4),
and a FIFO drained too late overflows. Writing the recording (formatting and flushing CSV rows,
which an SD card can hold up for hundreds of milliseconds) and drawing progress (a terminal or a
pipe that is not read can block) are slow and need not be on time. They run here, in one
consumer thread, in the order the loop produced them.

The queue is bounded: when the consumer falls :attr:`Backlog.capacity` items behind, the loop
raises :class:`BacklogError` instead of buffering without limit, and the run stops safely as
after any other error. On an emulated clock (``--sim`` without ``--realtime``) nothing is due in
wall time, so the loop waits for room instead (``realtime=False``): the recording is the same
whatever the two threads' timing.

Signals still arrive in the main thread, which runs the loop; the consumer never touches the
servos.
"""

from __future__ import annotations

import queue
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from gyrocal.kit.errors import HardwareError

__all__ = ["Backlog", "BacklogError", "RunStatus"]


class BacklogError(HardwareError):
    """The recording or progress output fell too far behind the protocol loop (exit 4)."""


@dataclass(frozen=True)
class RunStatus:
    """What the progress line shows, as the loop saw it (a snapshot, safe to read from the
    consumer thread).

    Attributes
    ----------
    t : float
        Time on the recording clock, s.
    step_index, n_steps : int
        The step under way (from 0) and the number of steps.
    step_desc : str
        Its description.
    rate : ndarray (3,)
        The last gyro reading, rad/s.
    speed : float
        The fastest servo's speed at the last poll, rad/s.
    """

    t: float
    step_index: int
    n_steps: int
    step_desc: str
    rate: np.ndarray
    speed: float


_STOP = object()


class Backlog:
    """Hand recording rows, segments, events and progress to a consumer thread.

    Parameters
    ----------
    writer : RecordingWriter
        Receives ``append_imu``, ``append_encoder``, ``append_segment`` and
        ``update_manifest`` in order.
    capacity : int
        Items the queue holds (>= 1); one item is one loop iteration's samples, a segment or an
        event.
    realtime : bool
        True: a full queue raises :class:`BacklogError` in the producer. False (an emulated
        clock): the producer waits for room.
    on_event : callable, optional
        ``on_event(line, t)`` with the jig time ``t`` at which the loop reported it.
    on_status : callable, optional
        ``on_status(status)`` with the latest :class:`RunStatus`; called after the queue has
        been drained of what was there, so a slow display only skips frames.

    Notes
    -----
    Use :meth:`close` (or the context manager) to drain and join. The first error the consumer
    meets (a full disk, say) is kept; :meth:`check`, :meth:`put_*` and :meth:`close` raise it in
    the producer, and the consumer writes nothing after it.
    """

    def __init__(self, writer: Any, *, capacity: int, realtime: bool = True,
                 on_event: Callable[[str, float], None] | None = None,
                 on_status: Callable[[RunStatus], None] | None = None) -> None:
        if int(capacity) < 1:
            raise ValueError(f"capacity must be at least 1, got {capacity!r}")
        self.writer = writer
        self.capacity = int(capacity)
        self.realtime = bool(realtime)
        self.on_event = on_event
        self.on_status = on_status
        self._queue: queue.Queue[Any] = queue.Queue(maxsize=self.capacity)
        self._status: RunStatus | None = None
        self._shown: RunStatus | None = None
        self._error: BaseException | None = None
        self._thread: threading.Thread | None = None
        #: The most items that waited in the queue at once (a measure of the consumer's lag).
        self.high_water = 0
        #: The most loop iterations the consumer writes (and flushes) as one append.
        self.batch_items = 512
        #: On an emulated clock (``realtime=False``), the wall time the consumer waits after
        #: taking samples before it takes those queued behind them: nothing is due in wall time
        #: there, and the loop, which would otherwise hand over the interpreter for every
        #: iteration or two, queues tens of iterations meanwhile, written as one append.
        self.gather_s = 0.05
        #: Set by :meth:`close`: the loop has stopped, so nothing more will queue up behind the
        #: samples left and the consumer writes them without waiting.
        self._closing = threading.Event()

    # ---------------------------------------------------------------- producer side
    def start(self) -> Backlog:
        """Start the consumer thread."""
        if self._thread is None:
            self._closing.clear()
            self._thread = threading.Thread(target=self._consume, name="gyrocal-backlog",
                                            daemon=True)
            self._thread.start()
        return self

    def check(self) -> None:
        """Raise the consumer's error, if it met one."""
        if self._error is not None:
            raise self._error

    def _put(self, item: tuple[Any, ...]) -> None:
        self.check()
        if self._thread is None:
            raise RuntimeError("Backlog.start() was not called")
        if self.realtime:
            try:
                self._queue.put_nowait(item)
            except queue.Full:
                raise BacklogError(
                    f"the recording fell {self.capacity} items behind the protocol loop (the "
                    "disk or the terminal cannot keep up): write the run to a faster disk "
                    "(--out), run with --quiet, or lower the host's load; the servos have been "
                    "stopped and the recording so far is kept") from None
        else:
            while True:
                try:
                    self._queue.put(item, timeout=0.5)
                    break
                except queue.Full:
                    self.check()
        self.high_water = max(self.high_water, self._queue.qsize())

    def put_samples(self, imu: Any, encoder: tuple[float, Any, np.ndarray]) -> None:
        """One loop iteration: ``imu`` ``(t, rate, temperature_c, accel)`` or None (one
        sensor), or a list of them, one per sensor (the writer's ``append_imus``); and ``encoder``
        ``(t, ids, angles)``."""
        self._put(("samples", imu, encoder))

    def put_call(self, fn: Callable[..., Any], *args: Any) -> None:
        """Call ``fn(*args)`` in the consumer, after the items before it (for instance a
        sensor's failure, after its last rows)."""
        self._put(("call", fn, args))

    def put_segment(self, seg: Any) -> None:
        """A finished segment, after the samples before it."""
        self._put(("segment", seg))

    def put_event(self, line: str, t: float) -> None:
        """A line of text for the user, at jig time ``t``."""
        self._put(("event", line, float(t)))

    def put_manifest(self, **fields: Any) -> None:
        """Fields to merge into the recording's manifest (``writer.update_manifest``), one level
        deep: ``protocol={"discarded": [...]}`` adds to the manifest's ``protocol``."""
        self._put(("manifest", fields))

    def set_status(self, status: RunStatus) -> None:
        """The newest progress snapshot (replaces the previous one; never queued)."""
        self._status = status

    def close(self, timeout_s: float | None = None) -> bool:
        """Write what is queued and stop the consumer.

        Parameters
        ----------
        timeout_s : float or None
            Wait at most this long (None: until done).

        Returns
        -------
        bool
            True if everything queued was written; False if the wait timed out (the consumer
            then stops after its current item and the rest is dropped).

        Raises
        ------
        Exception
            The consumer's error, if it met one.
        """
        if self._thread is None:
            self.check()
            return True
        done = True
        self._closing.set()
        try:
            self._queue.put(_STOP, timeout=timeout_s)
        except queue.Full:
            done = False
        self._thread.join(timeout_s)
        if self._thread.is_alive():
            done = False
            self._error = self._error or _Abandoned()
        self._thread = None
        if isinstance(self._error, _Abandoned):
            return False
        self.check()
        return done

    # ---------------------------------------------------------------- consumer side
    def _consume(self) -> None:
        pending = None  # an item taken while gathering samples, handled next
        unwaited = 0  # items queued when the last wait ended, not yet taken: no new wait
        while True:
            item, pending = (self._queue.get() if pending is None else pending), None
            if item is _STOP or self._error is not None:
                if item is _STOP:
                    self._show()
                    return
                continue
            try:
                if item[0] == "samples":
                    if unwaited <= 0 and self._worth_gathering():
                        time.sleep(self.gather_s)  # let the loop run ahead: fewer, longer writes
                        unwaited = self._queue.qsize() + 1
                    items, pending = self._gather(item)
                    self._write_samples(items)
                    unwaited -= len(items)
                else:
                    self._handle(item)
                    unwaited -= 1
                if pending is None and self._queue.empty():
                    self._show()
            except BaseException as exc:  # kept for the producer; nothing more is written
                self._error = exc

    def _worth_gathering(self) -> bool:
        """Whether to wait :attr:`gather_s` for more samples before writing: on an emulated
        clock only, while the loop still runs (not after :meth:`close`) and fewer than a batch
        are queued. :meth:`_consume` waits once for what was queued when its last wait ended:
        events between the samples split them into many short batches, each of which waited
        before (a FIFO-fault run on a two-sensor plate held the loop 4 s on a full queue)."""
        return (not self.realtime and not self._closing.is_set()
                and self._queue.qsize() < self.batch_items)

    def _gather(self, first: tuple[Any, ...]) -> tuple[list[tuple[Any, ...]], Any]:
        """``first`` and the samples items queued right behind it (at most
        :attr:`batch_items`), and the next item of another kind taken on the way, if any."""
        items = [first]
        while len(items) < self.batch_items:
            try:
                item = self._queue.get_nowait()
            except queue.Empty:
                return items, None
            if item is _STOP or item[0] != "samples":
                return items, item
            items.append(item)
        return items, None

    def _write_samples(self, items: list[tuple[Any, ...]]) -> None:
        """Write consecutive loop iterations' samples as one append (one write and one flush)
        per file: the rows, and so the files' bytes, are those of one append per iteration,
        and every row taken from the queue is flushed to the operating system before the next
        item is taken (a process that dies keeps what the files hold)."""
        imus = [it[1] for it in items]
        if any(isinstance(imu, list) for imu in imus):
            sensors = max(len(imu) for imu in imus if isinstance(imu, list))
            per_sensor = [_join_rows([imu[k] for imu in imus
                                      if isinstance(imu, list) and imu[k] is not None])
                          for k in range(sensors)]
            self.writer.append_imus(per_sensor)
        else:
            rows = _join_rows([imu for imu in imus if imu is not None])
            if rows is not None:
                self.writer.append_imu(*rows)
        self.writer.append_encoder(*_join_encoder([it[2] for it in items]))

    def _handle(self, item: tuple[Any, ...]) -> None:
        kind = item[0]
        if kind == "samples":
            self._write_samples([item])
        elif kind == "segment":
            self.writer.append_segment(item[1])
        elif kind == "call":
            item[1](*item[2])
        elif kind == "manifest":
            old = self.writer.manifest
            self.writer.update_manifest(**{
                k: {**old[k], **v} if isinstance(v, dict) and isinstance(old.get(k), dict) else v
                for k, v in item[1].items()})
        elif self.on_event is not None:
            self.on_event(item[1], item[2])

    def _show(self) -> None:
        status = self._status
        if self.on_status is not None and status is not None and status is not self._shown:
            self._shown = status
            self.on_status(status)

    def __enter__(self) -> Backlog:
        return self.start()

    def __exit__(self, exc_type: object, exc: object, tb: object) -> None:
        if exc_type is None:
            self.close()
        else:  # on the way out with an error: keep what can be written, never hide the error
            try:
                self.close(timeout_s=5.0)
            except Exception:
                pass


def _join_rows(rows: list[tuple[Any, ...]]) -> tuple[Any, ...] | None:
    """Consecutive IMU rows ``(t, rate, temperature_c, accel)`` (the arguments of
    :meth:`~gyrocal.kit.recording.RecordingWriter.append_imu`) joined into one, or None for no
    rows. An absent temperature is NaN (which the writer writes as absent); an absent
    accelerometer in any row leaves it absent."""
    if len(rows) <= 1:
        return rows[0] if rows else None
    t = [np.asarray(r[0], dtype=float).reshape(-1) for r in rows]
    rate = np.concatenate([np.asarray(r[1], dtype=float).reshape(-1, 3) for r in rows])
    temp = np.concatenate([np.full(ti.size, np.nan) if r[2] is None
                           else np.asarray(r[2], dtype=float).reshape(-1)
                           for r, ti in zip(rows, t, strict=True)])
    accel = None
    if all(len(r) > 3 and r[3] is not None for r in rows):
        accel = np.concatenate([np.asarray(r[3], dtype=float).reshape(-1, 3) for r in rows])
    return np.concatenate(t), rate, temp, accel


def _join_encoder(rows: list[tuple[float, Any, Any]]) -> tuple[Any, Any, Any]:
    """Consecutive encoder readings ``(t, motor ids, angles)`` (the arguments of
    :meth:`~gyrocal.kit.recording.RecordingWriter.append_encoder`) joined into one: the time
    repeated for each motor, the ids and angles concatenated."""
    if len(rows) == 1:
        return rows[0]
    ids = [np.asarray(m, dtype=np.int64).reshape(-1) for _, m, _ in rows]
    angles = [np.asarray(a, dtype=float).reshape(-1) for _, _, a in rows]
    if any(m.size != a.size for m, a in zip(ids, angles, strict=True)):
        raise ValueError("append_encoder: motor and angle differ in length")
    times = [np.full(m.size, t, dtype=float) for (t, _, _), m in zip(rows, ids, strict=True)]
    return np.concatenate(times), np.concatenate(ids), np.concatenate(angles)


class _Abandoned(Exception):
    """The consumer did not finish within the time it was given."""
