"""Motion sources: the true angular rate of the sensor, in the sensor frame, as a function of time.

An emulated IMU asks its motion source for the true rate at the instants it samples (on the shared
clock) and turns that rate into readings through the sensor's true errors. The emulated jig
(gimbal kinematics driven by the emulated servos) is one motion source; :class:`ConstantRate` and
:class:`FunctionMotion` serve tests and users who want a plain function of time.

Contract of :meth:`MotionSource.rate`: ``t`` is a 1-D array of times in seconds on the shared clock,
non-decreasing within a call and across calls, none later than the clock's present time; the
result is an ``(len(t), 3)`` float array in rad/s. An implementation may rely on that order
(for example to integrate servo dynamics forward) and must keep enough history to answer for times
earlier than its latest command.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Protocol, runtime_checkable

import numpy as np

__all__ = ["ConstantRate", "FunctionMotion", "MotionSource"]


@runtime_checkable
class MotionSource(Protocol):
    """The true angular rate of the sensor in its own frame."""

    def rate(self, t: np.ndarray) -> np.ndarray:
        """True angular rate in rad/s, shape ``(len(t), 3)``, at the times ``t`` (seconds)."""
        ...


class ConstantRate:
    """A constant true rate.

    Parameters
    ----------
    omega : array_like, shape (3,)
        The rate in rad/s in the sensor frame.
    """

    def __init__(self, omega: np.ndarray | tuple[float, float, float] = (0.0, 0.0, 0.0)) -> None:
        w = np.asarray(omega, dtype=float)
        if w.shape != (3,) or not np.all(np.isfinite(w)):
            raise ValueError(f"omega must be 3 finite numbers in rad/s, got {omega!r}")
        self.omega = w

    def rate(self, t: np.ndarray) -> np.ndarray:
        """``omega`` repeated for every time in ``t``."""
        n = np.asarray(t, dtype=float).reshape(-1).size
        return np.broadcast_to(self.omega, (n, 3)).copy()


class FunctionMotion:
    """A true rate given by a vectorised function of time.

    Parameters
    ----------
    fn : callable
        ``fn(t)`` with ``t`` a 1-D float array returns an ``(len(t), 3)`` array in rad/s.
    """

    def __init__(self, fn: Callable[[np.ndarray], np.ndarray]) -> None:
        self._fn = fn

    def rate(self, t: np.ndarray) -> np.ndarray:
        """``fn(t)``, checked for shape and finiteness."""
        t = np.asarray(t, dtype=float).reshape(-1)
        w = np.asarray(self._fn(t), dtype=float)
        if w.shape != (t.size, 3):
            raise ValueError(f"motion function returned shape {w.shape}, expected ({t.size}, 3)")
        if not np.all(np.isfinite(w)):
            raise ValueError("motion function returned a non-finite rate")
        return w
