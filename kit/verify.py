"""Verification of a calibration against the servo encoders (the paper's Tables V and VI).

The paper compares the calibrated gyro with a second, pre-calibrated gyroscope. Here the reference
is the jig itself: at any moment the true rate in the sensor frame is ``ω = Σ_j u_j(θ) θ̇_j``, the
servos' encoder rates along their axes, each outer axis carried by the rotations of the servos
inside it (:func:`gyrocal.calib.kinematics.sensor_rate`). The axes come from the calibration's
``kinematics`` (Calibration v2) or, for a version 1 calibration, from its estimated servo axes or
the manifest's nominal ones, all at the home pose. So every motion can be checked: rests (ω = 0),
one servo turning, and several servos turning at once, which sweeps the rate through directions
no single calibration turn has.

The readings are compared in blocks (half a second by default): the mean reference over a block
against the gyro's mean over it, raw, with the calibration's diagonal only, and with the full
calibration. Blocks on an acceleration ramp are left out: there the gyro's low-pass delay of a few
milliseconds against the encoder makes errors that say nothing about the calibration.

A calibration with g-sensitivity (``g = A (m + b + G f)``, hardware_docs/method.md §10) is
applied as it was fitted: ``f`` at each gyro sample is gravity's direction in the sensor frame
from the joint angles the encoders read, the calibration's kinematics and the servo the manifest
lists as vertical at home (:mod:`gyrocal.kit.gravity`), averaged over the block like the
readings. The lever arm's accelerations are neglected, as the fit neglects them: at the sweeps'
speeds (at most the protocol's, 3.6 rad/s on the emulated jig) the centripetal term of a sensor
39 mm off the axes is 0.05 g, about 9e-5 rad/s through an MPU-9250's 0.1 °/s/g, far below a
turning block's reference scatter (a few 1e-3 rad/s); the gravity pairs are at rest.

Each block also gets the error the calibration's own uncertainty predicts (gyro noise over the
block, the parameters' covariance, the g-sensitivity's standard deviations, the encoders'
quantisation); a calibration whose RMS error exceeds :data:`FLAG_RATIO` times its prediction on
any axis fails the verification.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from gyrocal.calib.kinematics import sensor_rate
from gyrocal.calib.model import GyroCalibration
from gyrocal.calib.observations import diff_noise
from gyrocal.calib.segments import Segment
from gyrocal.calib.windows import window_mean, window_rate
from gyrocal.drivers.dynamixel.control_table import POSITION_UNIT_RAD
from gyrocal.kit.errors import InputError
from gyrocal.kit.gravity import force_source, specific_force
from gyrocal.kit.protocol import Runner, Step
from gyrocal.kit.recording import Recording
from gyrocal.kit.report_plots import encoder_rate, servo_axes

__all__ = ["FLAG_RATIO", "KINDS", "GeneralMotionRunner", "Sweep", "Verification",
           "general_motion_steps", "verify_recording"]

#: A calibration fails verification when an axis's RMS error exceeds this multiple of the error
#: its own uncertainty predicts (a 3-sigma rule on the RMS).
FLAG_RATIO = 3.0
#: Block kinds in the figures, with their column headings.
KINDS = {"rest": "at rest", "one_servo": "one servo", "several_servos": "several servos"}
#: A servo whose encoder rate stays below this is holding, rad/s (a tick in 0.1 s is 0.015).
_MOVING = 0.05
#: A moving servo is at steady speed in a block when its rate varies by less than this fraction.
_STEADY = 0.05


#: Speeds of the servos in a general-motion sweep, as fractions of the protocol's speed, base
#: first: unequal, so that the rate's direction in the sensor frame keeps changing.
SWEEP_SPEEDS = (1.0, 0.62, 0.38)


@dataclass(frozen=True)
class Sweep(Step):
    """A general-motion step: every servo of ``moves`` turns at once.

    Recorded as one ``move`` segment per servo (Recording v1), all with the sweep's times.
    ``kind``, ``motor``, ``direction`` and ``speed`` describe its slowest servo, the one that
    turns throughout, so the :class:`~gyrocal.kit.protocol.Runner` treats it as a turn (repeats
    included); :class:`GeneralMotionRunner` checks every servo's speed, and the gimbal stops a
    servo that stalls (``Gimbal.begin_turns``).
    """

    moves: tuple[tuple[int, int, float, int], ...] = ()  # (servo, turns, speed, direction)

    def describe(self) -> str:
        """Human-readable, e.g. ``turn servos 1, 2, 3 at once``."""
        return f"turn servos {', '.join(str(m[0]) for m in self.moves)} at once"


#: Rest of each gravity pair (a rest with gravity tilted, then one at home), s.
GRAVITY_REST_S = 2.0


def general_motion_steps(plan: Any, ids: list[int], axes: np.ndarray | None = None
                         ) -> list[Step]:
    """Two sweeps, every servo one turn at once at :data:`SWEEP_SPEEDS` of the plan's speed,
    the negative way first and back (so every servo ends where it started and the cables never
    twist further than the protocol's turns), each after a rest; then the gravity pairs: each
    servo horizontal at home (``axes``, its nominal axes in chain order, default x, y, z; "up"
    is +z) is moved a quarter turn, rests :data:`GRAVITY_REST_S` with gravity tilted, moves
    back and rests as long at home (:func:`gyrocal.calib.design.gravity_poses`), then the same
    a quarter turn the other way: with one way only the changes of gravity ``Δf`` span two
    directions, and a g-sensitivity that acts little on them escapes. Each pair's
    difference of calibrated means is zero for a still sensor whatever its bias did, so it
    tests the calibration's g-sensitivity alone (:func:`verify_recording`)."""
    from gyrocal.calib.design import gravity_poses

    steps: list[Step] = []
    for d in (-1, 1):
        moves = tuple((int(i), 1, plan.speed * f, d) for i, f in zip(ids, SWEEP_SPEEDS,
                                                                       strict=False))
        steps.append(Step("rest", rest_s=plan.rest_s))
        steps.append(Sweep("rotate", motor=moves[-1][0], direction=d, turns=1,
                           speed=moves[-1][2], moves=moves))
    steps.append(Step("rest", rest_s=plan.rest_s))
    for moved, angle in gravity_poses((), axes):
        for a in (angle, -angle):  # both ways: the tilts' Δf then span all three directions
            if moved < len(ids):
                steps += [Step("move", motor=int(ids[moved]), angle=a, speed=plan.speed),
                          Step("rest", rest_s=GRAVITY_REST_S),
                          Step("move", motor=int(ids[moved]), angle=0.0, speed=plan.speed),
                          Step("rest", rest_s=GRAVITY_REST_S)]
    return steps


class GeneralMotionRunner(Runner):
    """The protocol runner, plus :class:`Sweep` steps (several servos turning at once)."""

    def _run_turn(self, step: Step) -> tuple[float, float, Any]:
        if not isinstance(step, Sweep):
            return super()._run_turn(step)
        start = self.now()
        motion = self.gimbal.begin_turns({m: (n, v, d) for m, n, v, d in step.moves})
        while self.gimbal.busy:
            self._tick()
        self._tick()
        return start, self.now(), motion

    def _reposition(self, step: Step) -> None:
        if not isinstance(step, Sweep):
            return super()._reposition(step)
        self.gimbal.begin_turns({m: (n, v, -d) for m, n, v, d in step.moves})
        while self.gimbal.busy:
            self._tick()

    def _check_speed(self, step: Step, motion: Any, d: Any) -> Any:
        """Every servo of a sweep held its own commanded speed over the middle half of its own
        turns (the runner's check of one servo, :meth:`Runner.servo_speed_failure`, per servo;
        a servo that stops outright is stopped by the gimbal's stall check before this)."""
        if not isinstance(step, Sweep):
            return super()._check_speed(step, motion, d)
        _, _, et, ea = d.arrays()
        speeds = getattr(motion, "speeds", {})  # as the gimbal quantized them
        for m, n, v, _ in step.moves:
            failure = self.servo_speed_failure(m, float(speeds.get(m, v)), et, ea,
                                               2 * math.pi * n / v)
            if failure is not None:
                return failure
        return None

    def _record(self, seg: Segment) -> None:
        step = self.steps[self.step_index]
        if not isinstance(step, Sweep) or seg.kind != "rotate":
            return super()._record(seg)
        for m, _, v, d in step.moves:
            super()._record(Segment(len(self._segments), "move", m, d, v, seg.t_start,
                                    seg.t_end))


@dataclass(frozen=True)
class Verification:
    """Per-axis RMS rate errors against the encoder reference.

    Attributes
    ----------
    rms_before, rms_diagonal, rms_full : ndarray (3,)
        rad/s, over every block used: raw readings; with the calibration's scale factors and
        bias only (its cross-axis terms dropped; for a version 1 calibration, the calibration
        itself); with the full matrix (NaN for a version 1 calibration).
    rms_predicted : ndarray (3,)
        What the calibration's own uncertainty predicts for its error over the same blocks.
    rms_by_kind : dict
        The calibration's error (full where it has a matrix) over the blocks of each kind of
        :data:`KINDS` (NaN where there were none).
    predicted_by_kind : dict
        What the calibration's uncertainty predicts over the blocks of each kind.
    gravity_pairs : int
        Pairs of rests, one with gravity tilted from its home direction and the next at home
        (:func:`general_motion_steps`), compared.
    rms_gravity, predicted_gravity : ndarray (3,)
        RMS over the pairs of the difference of their calibrated means (zero for a still
        sensor: a g-sensitivity the calibration does not model shows here, while the bias's
        slow wander cancels), and what the calibration predicts for it; NaN without pairs.
    blocks : dict
        Blocks used per kind, and ``ramp_excluded``.
    block_s : float
    reference : str
        Where the servo axes came from.
    full : bool
        Whether the calibration has a full matrix.
    delay_s : float
        The gyro's delay against the encoders, fitted (s); the reference is compared as delayed.
    g_sensitivity : str
        How the calibration's g-sensitivity was applied: ``"applied"`` (with the specific force
        from the kinematics), ``"none"`` (the calibration has none), or why it could not be.
    """

    rms_before: np.ndarray
    rms_diagonal: np.ndarray
    rms_full: np.ndarray
    rms_predicted: np.ndarray
    rms_by_kind: dict[str, np.ndarray]
    blocks: dict[str, int]
    block_s: float
    reference: str
    full: bool
    delay_s: float = 0.0
    g_sensitivity: str = "none"
    predicted_by_kind: dict[str, np.ndarray] | None = None
    gravity_pairs: int = 0
    rms_gravity: np.ndarray = field(default_factory=lambda: np.full(3, np.nan))
    predicted_gravity: np.ndarray = field(default_factory=lambda: np.full(3, np.nan))

    @property
    def rms_after(self) -> np.ndarray:
        """The calibration's error: full where it has a matrix, else diagonal."""
        return self.rms_full if self.full else self.rms_diagonal

    @property
    def ratio(self) -> np.ndarray:
        """``rms_after / rms_predicted`` per axis."""
        with np.errstate(divide="ignore", invalid="ignore"):
            return self.rms_after / self.rms_predicted

    @property
    def gravity_ratio(self) -> np.ndarray:
        """``rms_gravity / predicted_gravity`` per axis (NaN without gravity pairs)."""
        with np.errstate(divide="ignore", invalid="ignore"):
            return self.rms_gravity / self.predicted_gravity

    @property
    def ok(self) -> bool:
        """Whether the error stays within :data:`FLAG_RATIO` times the prediction on every axis,
        over all blocks and over the gravity pairs (where there are any)."""
        grav = self.gravity_ratio
        return bool(np.all(self.ratio <= FLAG_RATIO)
                    and (self.gravity_pairs == 0 or np.all(grav <= FLAG_RATIO)))

    def table(self) -> str:
        """The result as text (like the paper's Tables V and VI), with a legend."""
        used = sum(self.blocks[k] for k in KINDS)
        heads = ["before", "diagonal", "full", "predicted", *KINDS.values()]
        lines = [
            f"RMS rate error against the encoder reference, rad/s ({used} blocks of "
            f"{self.block_s:g} s: " + ", ".join(f"{self.blocks[k]} {KINDS[k]}" for k in KINDS)
            + f"; servo axes from the {self.reference})",
            f"{'axis':<6}" + "".join(f"{h:>16}" for h in heads),
        ]
        for j, ax in enumerate("xyz"):
            vals = [self.rms_before[j], self.rms_diagonal[j], self.rms_full[j],
                    self.rms_predicted[j], *(self.rms_by_kind[k][j] for k in KINDS)]
            lines.append(f"{ax:<6}" + "".join(
                f"{'n/a':>16}" if not np.isfinite(v) else f"{v:>16.5f}" for v in vals))
        after = "full" if self.full else "diagonal"
        lines += [
            "",
            "before: raw readings; diagonal: scale factors and bias only"
            + ("" if self.full else " (this calibration)")
            + "; full: with the cross-axis terms" + ("" if self.full else " (n/a: a version 1 "
                                                     "calibration has none)") + ".",
            f"predicted: what the calibration's own uncertainty predicts for '{after}'; the "
            f"last three columns split '{after}' by what the jig was doing.",
            f"{self.blocks['ramp_excluded']} blocks on acceleration ramps are left out: there "
            "the gyro's filter delay against the encoder is an error of the timing, not of the "
            f"calibration. That delay, fitted on the several-servo blocks, is "
            f"{self.delay_s * 1e3:.1f} ms; the reference is compared as delayed by it.",
        ]
        if self.gravity_pairs:
            lines.append(
                f"gravity: {self.gravity_pairs} pairs of rests (gravity tilted, then at home); "
                "RMS of the difference of their calibrated means, rad/s: "
                + ", ".join(f"{a} {e:.5f}" for a, e in zip("xyz", self.rms_gravity, strict=True))
                + " (predicted " + ", ".join(f"{e:.5f}" for e in self.predicted_gravity)
                + "): zero for a still sensor; an unmodelled g-sensitivity shows here.")
        if self.g_sensitivity == "applied":
            lines.append("g-sensitivity: applied with the specific force from the encoder angles "
                         "(gravity only; the lever arm's accelerations are left out).")
        elif self.g_sensitivity != "none":
            lines.append(f"g-sensitivity: NOT applied ({self.g_sensitivity}); the errors include "
                         "it.")
        return "\n".join(lines)

    def verdict(self) -> str:
        """One line: the worst axis's error against its prediction."""
        grav = self.gravity_ratio
        if self.gravity_pairs and np.nanmax(grav) > max(float(np.nanmax(self.ratio)),
                                                       FLAG_RATIO):
            j = int(np.nanargmax(grav))
            return (f"axis {'xyz'[j]}: with gravity tilted the still sensor's calibrated rate "
                    f"moves by {self.rms_gravity[j]:.2g} rad/s, {grav[j]:.1f} times what the "
                    f"calibration's uncertainty predicts ({self.predicted_gravity[j]:.2g} "
                    f"rad/s; the limit is {FLAG_RATIO:g} times): its g-sensitivity is not "
                    "modelled or wrong")
        j = int(np.nanargmax(self.ratio)) if np.any(np.isfinite(self.ratio)) else 0
        return (f"axis {'xyz'[j]}: error {self.rms_after[j]:.2g} rad/s is "
                f"{self.ratio[j]:.1f} times what the calibration's uncertainty predicts "
                f"({self.rms_predicted[j]:.2g} rad/s; the limit is {FLAG_RATIO:g} times)")

    def to_dict(self) -> dict[str, object]:
        """JSON-ready form; the field names follow the table's columns."""

        def arr(a: np.ndarray) -> list[float | None]:
            return [float(x) if np.isfinite(x) else None for x in a]

        return {
            "rms_before": arr(self.rms_before), "rms_diagonal": arr(self.rms_diagonal),
            "rms_full": arr(self.rms_full), "rms_predicted": arr(self.rms_predicted),
            **{f"rms_{k}": arr(v) for k, v in self.rms_by_kind.items()},
            **{f"rms_predicted_{k}": arr(v) for k, v in (self.predicted_by_kind or {}).items()},
            "blocks": dict(self.blocks), "block_s": self.block_s, "reference": self.reference,
            "delay_s": self.delay_s, "g_sensitivity": self.g_sensitivity,
            "gravity_pairs": self.gravity_pairs, "rms_gravity": arr(self.rms_gravity),
            "rms_predicted_gravity": arr(self.predicted_gravity), "ok": self.ok,
            "flag_ratio": FLAG_RATIO,
        }

    @classmethod
    def from_dict(cls, doc: Mapping[str, Any]) -> Verification:
        """The verification a :meth:`to_dict` document (``gyrocal verify --json``) holds.

        Raises
        ------
        InputError
            If a field is missing or malformed (the message names it).
        """
        def vec(name: str) -> np.ndarray:
            v = doc.get(name, [None] * 3)
            if not isinstance(v, list) or len(v) != 3 or not all(
                    x is None or (isinstance(x, (int, float)) and not isinstance(x, bool))
                    for x in v):
                raise InputError(f"{name} must be 3 numbers (null for n/a), got {v!r:.80}")
            return np.array([np.nan if x is None else float(x) for x in v])

        missing = [k for k in ("rms_before", "rms_diagonal", "rms_predicted", "blocks",
                               "block_s", "reference") if k not in doc]
        if missing:
            raise InputError(f"not a `gyrocal verify --json` document: no {', '.join(missing)}")
        blocks = doc["blocks"]
        if not isinstance(blocks, Mapping) or not all(
                isinstance(blocks.get(k), int) for k in (*KINDS, "ramp_excluded")):
            raise InputError(f"blocks must give a count for each of {', '.join(KINDS)} and "
                             f"ramp_excluded, got {blocks!r:.80}")
        full = vec("rms_full")
        try:
            return cls(
                rms_before=vec("rms_before"), rms_diagonal=vec("rms_diagonal"), rms_full=full,
                rms_predicted=vec("rms_predicted"),
                rms_by_kind={k: vec(f"rms_{k}") for k in KINDS},
                predicted_by_kind={k: vec(f"rms_predicted_{k}") for k in KINDS},
                blocks={k: int(blocks[k]) for k in (*KINDS, "ramp_excluded")},
                block_s=float(doc["block_s"]), reference=str(doc["reference"]),
                full=bool(np.any(np.isfinite(full))), delay_s=float(doc.get("delay_s", 0.0)),
                g_sensitivity=str(doc.get("g_sensitivity", "none")),
                gravity_pairs=int(doc.get("gravity_pairs", 0)),
                rms_gravity=vec("rms_gravity"), predicted_gravity=vec("rms_predicted_gravity"))
        except (TypeError, ValueError) as exc:
            raise InputError(f"malformed `gyrocal verify --json` document: {exc}") from None


def _kinematics(rec: Recording, cal: GyroCalibration) -> tuple[dict[str, Any], str]:
    """The chain to compute the reference with: the calibration's, else home-pose axes."""
    if cal.kinematics is not None:
        return dict(cal.kinematics), "calibration's kinematics"
    motors = [m for m in (rec.manifest.get("gimbal") or {}).get("motors") or []
              if isinstance(m, Mapping) and isinstance(m.get("id"), int)]
    chain = [int(m["id"]) for m in motors] or sorted({int(s.motor) for s in rec.segments
                                                      if s.motor is not None})
    found = servo_axes(chain, cal, rec.manifest)
    missing = [m for m in chain if m not in found]
    if missing:
        raise InputError(f"{rec.path}: no axis for servo(s) {missing}: the calibration has no "
                         "kinematics and the manifest names no axis (gimbal.motors[].axis)")
    sources = {found[m].source for m in chain}
    source = ("calibration" if sources == {"calibration"} else "nominal configuration"
              if sources <= {"nominal"} else "calibration and nominal names")
    axes = [np.asarray(found[m].axis, dtype=float) for m in chain]
    return {"chain": chain, "axes": [(a / np.linalg.norm(a)).tolist() for a in axes],
            "reference_angles_rad": [0.0] * len(chain)}, source


def _encoders(rec: Recording, chain: list[int]) -> tuple[np.ndarray, np.ndarray]:
    """Encoder times and angles (N, S) of the chain, on the first servo's reading times."""
    t0, _ = rec.encoder(chain[0])
    if t0.size < 2:
        raise InputError(f"{rec.path}: no encoder readings of servo {chain[0]}")
    cols = []
    for m in chain:
        te, th = rec.encoder(m)
        if te.size < 2:
            raise InputError(f"{rec.path}: no encoder readings of servo {m}")
        cols.append(np.interp(t0, te, th))
    return t0, np.column_stack(cols)


def _block_kind(te: np.ndarray, ang: np.ndarray, a: float, b: float) -> str | None:
    """``rest``, ``one_servo``, ``several_servos``, ``ramp``; None where encoders do not cover."""
    h = min(0.05, (b - a) / 4)
    at = np.array([a + h, 0.5 * (a + b), b - h])
    moving = 0
    for j in range(ang.shape[1]):
        w = encoder_rate(te, ang[:, j], at, h)
        if not np.all(np.isfinite(w)):
            return None
        top = float(np.max(np.abs(w)))
        if top < _MOVING:
            continue
        if np.ptp(w) > _STEADY * top:
            return "ramp"
        moving += 1
    return "rest" if moving == 0 else "one_servo" if moving == 1 else "several_servos"


def _reference_variance(te: np.ndarray, ang: np.ndarray, a: float, b: float) -> float:
    """Variance of a block's reference rate from the encoders' scatter: each moving servo's
    angle about a straight line over the block (quantisation, read-time jitter, ripple), as
    the error of a rate from the block's two ends, ``2 r² / T²``; at least the quantisation
    (a tick, uniform: ``tick² / 12`` per end)."""
    sel = (te >= a) & (te <= b)
    if sel.sum() < 4:
        return 0.0
    x = te[sel] - 0.5 * (a + b)
    var = 0.0
    for j in range(ang.shape[1]):
        y = ang[sel, j]
        if np.ptp(y) < 2 * POSITION_UNIT_RAD:
            continue  # holding
        r2 = float(np.mean((y - np.polyval(np.polyfit(x, y, 1), x)) ** 2))
        var += 2 * max(r2, POSITION_UNIT_RAD**2 / 12) / (b - a) ** 2
    return var


#: Blocks of several servos turning needed to fit the gyro's delay (else it is taken as 0).
_MIN_DELAY_BLOCKS = 3
#: Span over which the rate's slope is taken at each end of a block, s.
_EDGE_S = 0.05


def _turned(kin: Mapping[str, Any], ang: np.ndarray) -> np.ndarray:
    """The sensor's rotation accumulated since the first encoder reading, (N, 3) rad: each
    reading interval's angle changes carried along the servos' axes at the interval's middle
    (:func:`~gyrocal.calib.kinematics.sensor_rate` is linear in the rates). Its change over a
    window is the encoder's angle change the estimator takes (no derivative of jittered
    readings), in the sensor frame even while several servos turn."""
    step = sensor_rate(kin, 0.5 * (ang[1:] + ang[:-1]), np.diff(ang, axis=0))
    return np.vstack([np.zeros((1, 3)), np.cumsum(step, axis=0)])


def _mean_rate(te: np.ndarray, turned: np.ndarray, corners: tuple[float, float, float, float]
               ) -> np.ndarray:
    """The reference rate over a window: the change of ``turned`` across it
    (:func:`gyrocal.calib.windows.window_rate`, the estimator's reference); NaN where the
    encoder readings do not cover it."""
    if corners[0] < te[0] or corners[3] > te[-1]:
        return np.full(3, np.nan)
    return np.array([window_rate(te, turned[:, k], corners) for k in range(3)], dtype=float)


def _param_variance(cal: GyroCalibration, x: np.ndarray, gf: np.ndarray,
                    f: np.ndarray | None) -> np.ndarray:
    """Per axis, the variance the parameters' covariance puts on the calibrated rate of the
    block mean ``x`` (first order: ``J C Jᵀ``, ``J`` the derivative of ``A (x + b + G f)``,
    ``gf = G f``), plus, with g-sensitivity, ``Σ_jk (A_ij f_k σ(G_jk))²``: the document keeps
    ``G``'s standard deviations only, so its correlation with ``b`` is left out."""
    c = cal.covariance_matrix
    y = x + np.asarray(cal.bias) + gf
    a = cal.full_matrix
    g_var = 0.0
    if f is not None and cal.g_sensitivity is not None:
        s = np.nan_to_num(np.asarray(cal.g_sensitivity["matrix_std"], dtype=float))
        g_var = (a**2) @ ((s**2) @ (f**2))
    if cal.is_full:  # g_i = Σ_j A_ij y_j: ∂/∂A_ij = y_j (index 3i+j), ∂/∂b_j = A_ij (9+j)
        jac = np.zeros((3, 12))
        for i in range(3):
            jac[i, 3 * i:3 * i + 3] = y
        jac[:, 9:] = a
    else:  # g_i = k_i y_i: ∂/∂k_i = y_i, ∂/∂b_i = k_i
        jac = np.hstack([np.diag(y), np.diag(np.diag(a))])
    if c is None:
        std = (np.concatenate([np.ravel(cal.matrix_std), cal.bias_std])
               if cal.is_full and cal.matrix_std is not None
               else np.concatenate([cal.scale_std, cal.bias_std]))
        if not cal.is_full or cal.matrix_std is not None:
            c = np.diag(np.nan_to_num(np.asarray(std, dtype=float)) ** 2)
        else:
            c = np.zeros((12, 12))
    c = np.nan_to_num(c)
    return np.einsum("ik,kl,il->i", jac, c, jac) + g_var


def _block_rows(rec: Recording, t: np.ndarray, m: np.ndarray, te: np.ndarray, ang: np.ndarray,
                turned: np.ndarray, force: np.ndarray | None, block_s: float
                ) -> list[tuple[Any, ...]]:
    """Every segment cut into ``block_s`` blocks: per block ``(kind, gyro mean, reference mean,
    readings, count, reference slope, reference variance, mean specific force or None)``.

    Raises
    ------
    InputError
        When no segment is long enough for one block.
    """
    rows: list[tuple[Any, ...]] = []
    ramp = min(_EDGE_S, block_s / 4)
    for start, end in sorted({(s.t_start, s.t_end) for s in rec.segments}):
        for i in range(int((end - start) // block_s)):
            a = start + i * block_s
            b = a + block_s
            sel = (t >= a) & (t <= b)
            kind = _block_kind(te, ang, a, b) if sel.sum() >= 3 else None
            if kind is None:
                continue
            # gyro and reference with one trapezoid weight on one clock (DESIGN.md fact 2)
            corners = (a, a + ramp, b - ramp, b)
            ref = _mean_rate(te, turned, corners)
            slope = (_mean_rate(te, turned, (b - ramp, b - ramp, b, b))
                     - _mean_rate(te, turned, (a, a, a + ramp, a + ramp))) / (b - a - ramp)
            if not (np.all(np.isfinite(ref)) and np.all(np.isfinite(slope))):
                continue
            gyro, n_eff = window_mean(t, m, corners)
            rows.append((kind, gyro, ref, m[sel], n_eff, slope,
                         _reference_variance(te, ang, a, b),
                         None if force is None else window_mean(t, force, corners)[0]))
    if not rows:
        raise InputError(f"{rec.path}: no segment is long enough for {block_s:g} s blocks")
    return rows


def verify_recording(rec: Recording, cal: GyroCalibration, block_s: float = 0.5) -> Verification:
    """Compare raw and calibrated readings with the encoder reference, block by block.

    Parameters
    ----------
    rec : Recording
        A run on the jig (ideally not the one the calibration was fitted to).
    cal : GyroCalibration
        Version 1 or 2.
    block_s : float
        Block length, s: long enough to average the encoder's quantisation (a tick over half a
        second is 3e-3 rad/s), short enough to follow the motion.

    Returns
    -------
    Verification
    """
    if not (math.isfinite(block_s) and block_s > 0):
        raise InputError(f"block length must be a positive number of seconds, got {block_s}")
    t, m = rec.imu_t, rec.imu_rate
    if t.size < 10:
        raise InputError(f"{rec.path}: too few gyro samples to verify")
    kin, source = _kinematics(rec, cal)
    te, ang = _encoders(rec, list(kin["chain"]))
    turned = _turned(kin, ang)
    g_note = "none" if cal.g_sensitivity is None else (force_source(rec, cal) or "applied")
    force = specific_force(rec, cal, t) if g_note == "applied" else None
    diag = GyroCalibration(scale=cal.scale, bias=cal.bias)
    rows = _block_rows(rec, t, m, te, ang, turned, force, block_s)
    ramps = sum(r[0] == "ramp" for r in rows)
    used = [r for r in rows if r[0] != "ramp"]
    if not used:
        raise InputError(f"{rec.path}: every {block_s:g} s block is on an acceleration ramp; "
                         "use shorter blocks (--block)")
    kinds = np.array([r[0] for r in used])
    raw = np.array([r[1] for r in used])
    slope = np.array([r[5] for r in used])
    f = None if force is None else np.array([r[7] for r in used])
    # G f, in the readings' units (0 without g-sensitivity or its force): the model is
    # A (m + b + G f), so the diagonal column applies it too.
    gf = (np.zeros_like(raw) if f is None
          else f @ np.asarray(cal.g_sensitivity["matrix"]).T)  # type: ignore[index]
    calibrated = (cal.apply(raw, specific_force=f) if f is not None
                  else _quietly(cal.apply, raw))
    # The gyro's filter and sample timing lag the encoders by a few ms: while the rate turns
    # (several servos at once) that is an error of -delay * dω/dt. Fit the delay (a nuisance:
    # rates linear in ω change sign with the direction of the sweeps, dω/dt does not) and
    # compare with the reference as a gyro with that delay sees it.
    first = calibrated - np.array([r[2] for r in used])
    turning = kinds == "several_servos"  # where the rate's direction changes
    ss = float(np.sum(slope[turning] ** 2))
    delay = (-float(np.sum(first[turning] * slope[turning])) / ss
             if turning.sum() >= _MIN_DELAY_BLOCKS and ss > 0 else 0.0)
    ref = np.array([r[2] for r in used]) - delay * slope
    rest = [r[3] for r in used if r[0] == "rest" and r[4] >= 3]
    sigma = (np.sqrt(np.mean([diff_noise(x) ** 2 for x in rest], axis=0)) if rest
             else diff_noise(m))
    a_mat = cal.full_matrix
    noise_var = np.einsum("ij,j,ij->i", a_mat, sigma**2, a_mat)
    predicted = np.array([noise_var / r[4] + _param_variance(cal, r[1], gf[i], r[7]) + r[6]
                          for i, r in enumerate(used)])
    err_full = calibrated - ref if cal.is_full else np.full(raw.shape, np.nan)
    err_diag = diag.apply(raw + gf) - ref
    err_after = err_full if cal.is_full else err_diag

    def rms(e: np.ndarray) -> np.ndarray:
        return np.sqrt(np.mean(e**2, axis=0)) if e.size else np.full(3, np.nan)

    pairs, g_err, g_pred = _gravity_pairs(rec, cal, list(kin["chain"]), t, m, force, sigma)
    return Verification(
        gravity_pairs=pairs, rms_gravity=g_err, predicted_gravity=g_pred,
        rms_before=rms(raw - ref), rms_diagonal=rms(err_diag), rms_full=rms(err_full),
        rms_predicted=np.sqrt(np.mean(predicted, axis=0)),
        rms_by_kind={k: rms(err_after[kinds == k]) for k in KINDS},
        predicted_by_kind={k: (np.sqrt(np.mean(predicted[kinds == k], axis=0))
                               if np.any(kinds == k) else np.full(3, np.nan)) for k in KINDS},
        blocks={**{k: int(np.sum(kinds == k)) for k in KINDS}, "ramp_excluded": int(ramps)},
        block_s=float(block_s), reference=source, full=cal.is_full, delay_s=delay,
        g_sensitivity=g_note,
    )


#: Settling time left out at each end of a rest in the gravity pairs, s.
_REST_GUARD_S = 0.3
#: A rest is in the home pose when every servo is within this of its home angle (mod 2π), rad.
_HOME_TOL = 0.05


def _gravity_pairs(rec: Recording, cal: GyroCalibration, chain: list[int], t: np.ndarray,
                   m: np.ndarray, force: np.ndarray | None, sigma: np.ndarray
                   ) -> tuple[int, np.ndarray, np.ndarray]:
    """Each rest out of the home pose (gravity tilted) paired with the next rest at home:
    ``(pairs, RMS of the difference of the calibrated means, its predicted RMS)``.

    For a still sensor the difference is zero; a g-sensitivity ``G_s`` the calibration does not
    model makes it ``A G_s Δf`` (up to 2.4e-3 rad/s for an MPU-9250's 0.1 °/s/g and a quarter
    turn), while the bias's slow wander (bias instability) cancels over the seconds between the
    two. Predicted: the white noise of both means (``A diag(σ²) Aᵀ / n``) and, with
    g-sensitivity applied, ``Σ_jk (A_ij Δf_k σ(G_jk))²``; the matrix's own uncertainty acts on
    ``Δm ≈ −G Δf`` only, a negligible 1e-6 of it.
    """
    nan = np.full(3, np.nan)
    home = np.array([rec.encoder(mm)[1][0] for mm in chain])
    rests = []
    for seg in sorted((s for s in rec.segments if s.kind == "rest"), key=lambda s: s.t_start):
        a, b = seg.t_start + _REST_GUARD_S, seg.t_end - _REST_GUARD_S
        sel = (t >= a) & (t <= b)
        if sel.sum() < 10:
            continue
        mid = 0.5 * (a + b)
        ang = np.array([np.interp(mid, *rec.encoder(mm)) for mm in chain])
        off = np.abs(np.angle(np.exp(1j * (ang - home))))
        rests.append((bool(np.all(off < _HOME_TOL)), sel))
    a_mat = cal.full_matrix
    g = None if force is None else np.asarray(cal.g_sensitivity["matrix"])  # type: ignore[index]
    s = (None if force is None else
         np.nan_to_num(np.asarray(cal.g_sensitivity["matrix_std"], dtype=float)))  # type: ignore[index]
    errs, preds = [], []
    for i, (at_home, sel) in enumerate(rests):
        if at_home or i + 1 >= len(rests) or not rests[i + 1][0]:
            continue
        sel2 = rests[i + 1][1]
        means = []
        for k in (sel, sel2):
            f = None if force is None else force[k].mean(axis=0)
            mk = m[k].mean(axis=0) + (0.0 if f is None else g @ f)  # type: ignore[operator]
            means.append((a_mat @ (mk + np.asarray(cal.bias)), f, int(k.sum())))
        errs.append(means[0][0] - means[1][0])
        var = np.einsum("ij,j,ij->i", a_mat, sigma**2, a_mat) * (1 / means[0][2] + 1 / means[1][2])
        if force is not None:
            df = means[0][1] - means[1][1]  # type: ignore[operator]
            var = var + (a_mat**2) @ ((s**2) @ (df**2))  # type: ignore[operator]
        preds.append(var)
    if not errs:
        return 0, nan, nan
    return (len(errs), np.sqrt(np.mean(np.square(errs), axis=0)),
            np.sqrt(np.mean(preds, axis=0)))


def _quietly(apply: Any, raw: np.ndarray) -> np.ndarray:
    """``apply(raw)`` without the warning that g-sensitivity is not applied (the table says so)."""
    import warnings

    from gyrocal.calib.model import GSensitivityWarning

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", GSensitivityWarning)
        return apply(raw)
