"""Where gravity points in the sensor frame during a recording, for a calibration's g-sensitivity.

A Calibration v2 with ``g_sensitivity`` holds ``g = A (m + b + G f)``, ``f`` the specific force at
the sensor in g (hardware_docs/method.md §10). The fit took ``f`` from the gimbal, not from an
accelerometer: the servo the manifest lists with axis ``z`` (or ``-z``) stands vertical in the
recording's first pose (:func:`gyrocal.kit.pipeline.gravity_servo`), and "up" is carried to
every later pose by the calibration's kinematics (:func:`gyrocal.calib.kinematics.gravity_up`).
A calibration that stores that home pose (``kinematics.home_angles_rad`` and ``up_servo``:
:attr:`gyrocal.calib.model.GyroCalibration.gravity_reference`) is applied from it instead, so a
recording that starts off the home pose, or whose manifest names no vertical servo, gets the
right "up".
:func:`specific_force` does the same at any time of a recording, so the calibration is applied
as it was fitted.

What this leaves out, as the fit does: the lever arm's accelerations. A sensor ``r`` from the
meeting point of the axes feels ``ω² r⊥ / g₀`` more while turning, and ``α r`` on the ramps. At
the emulated jig's planned 3.6 rad/s (``gyrocal verify``'s sweeps turn no faster) and its 39 mm
lever arm that is 0.05 g, about 9e-5 rad/s through an MPU-9250's 0.1 °/s/g: far below a
half-second turning block's reference scatter (a few 1e-3 rad/s); the gravity pairs are at
rest, where there is none.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from gyrocal.calib.errors import CalibInputError
from gyrocal.calib.kinematics import gravity_up
from gyrocal.calib.model import GyroCalibration
from gyrocal.kit.errors import InputError
from gyrocal.kit.pipeline import gravity_servo
from gyrocal.kit.recording import Recording

__all__ = ["ForceSource", "force_of", "force_source", "specific_force"]


def force_source(rec: Recording, cal: GyroCalibration) -> str | None:
    """Why :func:`specific_force` cannot give ``f`` for this calibration and recording, or None
    when it can (the calibration has ``g_sensitivity`` and ``kinematics``, the manifest names
    the vertical servo, and every servo of the chain has encoder readings)."""
    if cal.g_sensitivity is None:
        return "the calibration has no g-sensitivity"
    if cal.kinematics is None:
        return "the calibration has no kinematics to carry gravity's direction"
    ref = cal.gravity_reference
    up = gravity_servo(rec.manifest) if ref is None else ref[1]
    if up is None:
        return ("the recording's manifest lists no servo with axis z or -z (the one vertical "
                "at home)")
    chain = [int(c) for c in cal.kinematics["chain"]]
    if up[0] not in chain:
        return f"the vertical servo {up[0]} is not in the calibration's chain {chain}"
    missing = [m for m in chain if rec.encoder(m)[0].size < 2]
    if missing:
        return f"no encoder readings of servo(s) {missing}"
    return None


@dataclass(frozen=True)
class ForceSource:
    """The specific force of a recording's sensor at any time (g, sensor frame): the chain's
    encoder angles, interpolated linearly (held at the first and last readings outside them),
    carried into "up" by the calibration's kinematics (:func:`gyrocal.calib.kinematics.gravity_up`).

    Attributes
    ----------
    kinematics : mapping
        The Calibration v2 ``kinematics``.
    up : (int, int)
        ``(servo ID, sign)`` of the servo vertical at home.
    home : ndarray (S,)
        The home pose's encoder angles, chain order: the calibration's stored one, else the
        recording's first (as the fit takes it).
    encoders : list of (ndarray, ndarray)
        Each chain servo's encoder times and angles.
    """

    kinematics: Mapping[str, Any]
    up: tuple[int, int]
    home: np.ndarray
    encoders: list[tuple[np.ndarray, np.ndarray]]

    def at(self, t: np.ndarray) -> np.ndarray:
        """Unit vectors (N, 3), +1 g up when still, at times ``t`` (N,) on the recording clock."""
        t = np.asarray(t, dtype=float).reshape(-1)
        angles = np.column_stack([np.interp(t, et, ea) for et, ea in self.encoders])
        return gravity_up(self.kinematics, angles.reshape(t.size, -1), self.home, self.up)


def force_of(rec: Any, cal: GyroCalibration) -> tuple[ForceSource | None, str | None]:
    """The :class:`ForceSource` of a recording (a :class:`Recording`, or anything with its
    ``manifest`` and ``encoder(motor)``, such as a streamed replay's timeline) for ``cal``'s
    g-sensitivity, or None and :func:`force_source`'s reason (None, None without G)."""
    if cal.g_sensitivity is None:
        return None, None
    why = force_source(rec, cal)
    if why is not None:
        return None, why
    kin: Mapping[str, Any] = cal.kinematics  # type: ignore[assignment]
    encoders = [rec.encoder(int(m)) for m in kin["chain"]]
    ref = cal.gravity_reference
    if ref is not None:  # the home pose the calibration's "up" refers to
        return ForceSource(kin, ref[1], ref[0], encoders), None
    home = np.array([float(ea[0]) for _, ea in encoders])  # the first pose, as the fit takes it
    return ForceSource(kin, gravity_servo(rec.manifest), home, encoders), None  # type: ignore[arg-type]


def specific_force(rec: Recording, cal: GyroCalibration, t: np.ndarray) -> np.ndarray:
    """The specific force of a still sensor at times ``t`` of the recording, g, sensor frame.

    Parameters
    ----------
    rec : Recording
    cal : GyroCalibration
        With ``g_sensitivity`` and ``kinematics`` (:func:`force_source` says whether).
    t : ndarray, shape (N,)
        Times on the recording clock, s (encoder angles are interpolated linearly, and held at
        the first and last readings outside them).

    Returns
    -------
    ndarray, shape (N, 3)
        Unit vectors ("up", +1 g when still).

    Raises
    ------
    InputError
        When :func:`force_source` gives a reason.
    """
    src, why = force_of(rec, cal)
    if src is None:
        raise InputError(f"{rec.path}: cannot tell where gravity points: "
                         f"{why or 'the calibration has no g-sensitivity'}")
    try:
        return src.at(t)
    except CalibInputError as exc:
        raise InputError(f"{rec.path}: {exc}") from None
