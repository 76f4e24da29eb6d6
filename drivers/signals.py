"""Termination signals as exceptions, and a shield that defers them during a safe stop.

A process that drives servos must stop them, with torque off, whatever ends it. The handlers here
turn SIGINT into :class:`KeyboardInterrupt` and SIGTERM and SIGHUP into
:class:`TerminatedBySignal` (exit ``128 + signum``: 130, 143, 129), so that every ``finally`` and
context manager on the way out runs. Once one signal has been raised, and while a safe stop runs
inside :func:`shielded`, a further signal is only recorded: it cannot cut the way out or the stop
short (hardware reference §6, point 4: Goal Velocity 0, then Torque Enable 0 on every ID, read
back). The first signal decides the exit code.

The handlers are process-wide (Python runs them in the main thread); installs and shields nest
(counters), and the record of a raised signal ends when the outermost install is restored.
"""

from __future__ import annotations

import signal
import threading
from types import TracebackType

__all__ = [
    "SIGNALS",
    "TerminatedBySignal",
    "exception_for",
    "install",
    "restore",
    "shielded",
]

#: The signals that end a run: interrupt (Ctrl-C), terminate, hang-up (terminal closed).
SIGNALS: tuple[signal.Signals, ...] = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)


class TerminatedBySignal(SystemExit):
    """Raised by the SIGTERM and SIGHUP handlers so that the safe stop runs on the way out.

    Its exit code is ``128 + signum`` (143 for SIGTERM, 129 for SIGHUP), as ``gyrocal``
    documents. A :class:`SystemExit`, so ``except Exception`` blocks do not swallow it.
    """

    def __init__(self, signum: int) -> None:
        super().__init__(128 + int(signum))
        self.signum = int(signum)


class _State:
    depth = 0  # open shields
    installs = 0  # installs not yet restored
    fired = False  # a signal has been raised as an exception: the process is on its way out
    pending: int | None = None


_state = _State()


def exception_for(signum: int) -> BaseException:
    """The exception a signal becomes: KeyboardInterrupt for SIGINT, else TerminatedBySignal."""
    if signum == signal.SIGINT:
        return KeyboardInterrupt()
    return TerminatedBySignal(signum)


def _handler(signum: int, frame: object) -> None:
    if _state.fired:
        return  # the first signal's exception is already on its way out
    if _state.depth > 0:
        if _state.pending is None:
            _state.pending = int(signum)
        return
    _state.fired = True
    raise exception_for(signum)


def install() -> dict[int, object]:
    """Install the handlers for :data:`SIGNALS`; returns the previous ones for :func:`restore`.

    Outside the main thread (where Python cannot set handlers) nothing is installed and the
    result is empty.
    """
    if threading.current_thread() is not threading.main_thread():
        return {}
    old: dict[int, object] = {}
    for sig in SIGNALS:
        old[int(sig)] = signal.signal(sig, _handler)
    _state.installs += 1
    return old


def restore(old: dict[int, object]) -> None:
    """Put back the handlers that :func:`install` returned (and empty ``old``)."""
    if not old:
        return
    for sig, handler in list(old.items()):
        try:
            signal.signal(sig, handler)  # type: ignore[arg-type]
        except (ValueError, TypeError):
            pass
    old.clear()
    _state.installs = max(0, _state.installs - 1)
    if _state.installs == 0:
        _state.fired = False
        _state.pending = None


class shielded:
    """Context manager: signals that arrive inside are deferred, not raised.

    When the outermost shield ends normally and a signal arrived meanwhile, its exception is
    raised then (the stop has finished). When the block ends with an exception (the first
    signal's, or an error), that exception goes on and the deferred signal is dropped.
    """

    def __enter__(self) -> shielded:
        _state.depth += 1
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        _state.depth -= 1
        if _state.depth > 0:
            return
        pending, _state.pending = _state.pending, None
        if exc_type is None and pending is not None and not _state.fired:
            _state.fired = True
            raise exception_for(pending)
