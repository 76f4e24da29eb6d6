"""Tracking the gyro bias through the kit: batches from a recording or the live jig, fed to
:class:`gyrocal.calib.tracker.BiasTracker`, collected per sample.

The command (:mod:`gyrocal.kit.commands.track`) parses arguments and calls this module:
:class:`Batch` is what a source hands the tracker, :func:`run_tracker` feeds batches and collects
a :class:`Tracked`, :func:`reference_segments` and :func:`rest_flags` turn a Recording v1 into
reference-rate and still flags, and :class:`LiveSource` with :func:`run_live` is the live loop on
the jig (the protocol runner's loop of :mod:`gyrocal.kit.protocol`, holding the servos still).

A recording is replayed in bounded memory (issue 16): :func:`open_replay` reads it once, the
readings into a temporary file (:class:`SpilledImu`), the encoder near the turns only
(:class:`_NearTurns`); :class:`ReplaySource` hands the tracker pieces with their reference
rates and still flags (:class:`StillPlan`, :func:`rest_intervals`), and :func:`json_pieces`
writes the document a few thousand rows at a time. What stays in memory per sample: its time
(8 bytes) and its still flag (1 byte).
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from gyrocal.kit.errors import InputError

#: Seconds of live data the tracker is built from (noise estimate, first still second).
LIVE_WARMUP_S = 2.0
#: Seconds of live data handed to the tracker at a time.
LIVE_CHUNK_S = 1.0
#: A servo that moves more than this between two polls marks its samples as not still, rad.
LIVE_MOVE_TOLERANCE_RAD = 2 * 2 * math.pi / 4096
#: A turn's sample gives a reference rate only where the encoder's mean rate over this many
#: seconds either side is within :data:`STEADY_TOLERANCE` of the turn's cruise rate.
STEADY_HALF_SPAN_S = 0.1
STEADY_TOLERANCE = 0.01



@dataclass(frozen=True)
class Batch:
    """What a source hands the tracker: a run of samples (a recording, a FIFO drain, ...)."""

    t: np.ndarray
    rate: np.ndarray
    temperature: np.ndarray | None = None
    still: np.ndarray | None = None
    reference_rate: np.ndarray | None = None
    reference_axis: np.ndarray | None = None
    #: Specific force at the sensor (n, 3), g, for the calibration's g-sensitivity (or None).
    specific_force: np.ndarray | None = None
    #: The accelerometer's readings (n, 3), m/s², for the still detector's veto (or None).
    accel: np.ndarray | None = None


@dataclass(frozen=True)
class Tracked:
    """Per-sample output of a whole run.

    ``t``, ``bias``, ``bias_std``, ``nis_ok`` and ``since_update_s`` hold the samples ``rows``
    (global indices; None: every sample), ``still`` every sample; ``since_max`` is the longest
    time without an update over every sample, s; ``bias_moved`` the tracker's
    :class:`gyrocal.calib.tracker.BiasMoved` when the first rest found the bias beyond what the
    calibration's sigma allows (None otherwise).
    """

    t: np.ndarray
    bias: np.ndarray
    bias_std: np.ndarray
    still: np.ndarray
    nis_ok: np.ndarray
    since_update_s: np.ndarray
    update_t: np.ndarray
    update_kind: np.ndarray
    alarm_t: np.ndarray
    shift_t: np.ndarray
    rows: np.ndarray | None = None
    since_max: float = math.nan
    bias_moved: Any = None


class _Kept:
    """Per-sample outputs of consecutive batches, kept at the samples ``rows`` (global indices,
    increasing; None: all) in arrays that grow by doubling (no list of parts to join at the end,
    which would hold everything twice)."""

    def __init__(self, rows: np.ndarray | None) -> None:
        self.rows = rows
        self.n = 0  # samples seen
        self.k = 0  # rows filled
        self.cols: dict[str, np.ndarray] = {}
        self.still = np.zeros(1024, dtype=bool)

    def _put(self, name: str, value: np.ndarray) -> None:
        col = self.cols.get(name)
        need = self.k + value.shape[0]
        if col is None or col.shape[0] < need:
            size = max(need, 2 * (0 if col is None else col.shape[0]), 1024)
            if self.rows is not None:
                size = self.rows.size
            grown = np.empty((size, *value.shape[1:]), dtype=value.dtype)
            if col is not None:
                grown[: self.k] = col[: self.k]
            self.cols[name] = col = grown
        col[self.k:need] = value

    def add(self, res: Any) -> None:
        n = res.t.size
        if self.rows is None:
            sel: Any = slice(None)
        else:
            a, b = np.searchsorted(self.rows, (self.n, self.n + n))
            sel = self.rows[a:b] - self.n
        for name, v in (("t", res.t), ("bias", res.bias), ("std", res.bias_std),
                        ("nis", res.nis_ok), ("since", res.since_update_s)):
            self._put(name, np.asarray(v)[sel])
        self.k += int(np.asarray(res.t)[sel].shape[0])
        self.n += n
        if self.still.size < self.n:
            grown = np.zeros(max(self.n, 2 * self.still.size), dtype=bool)
            grown[: self.still.size] = self.still
            self.still = grown
        self.still[res.decision_index] = res.decision_still

    def col(self, name: str) -> np.ndarray:
        return self.cols[name][: self.k]


def run_tracker(tracker: Any, batches: Iterable[Batch], *,
                rows: np.ndarray | None = None) -> Tracked:
    """Feed ``batches`` to a :class:`gyrocal.calib.tracker.BiasTracker` and collect per-sample
    output.

    A live source (the jig's IMU FIFO) is one more iterable of :class:`Batch`. The last batch is
    processed with ``finish=True``; still decisions that arrive after their batch (the
    detector's look-ahead) are placed by the sample index the tracker reports with them.
    ``rows`` (increasing global sample indices) keeps the estimates at those samples only, so
    a long replay holds a few bytes per sample (the still flags) besides the rows shown.
    """
    kept = _Kept(None if rows is None else np.asarray(rows, dtype=np.int64))
    upd: dict[str, list[np.ndarray]] = {k: [] for k in ("ut", "uk", "al", "sh")}
    since_max = -math.inf
    it = iter(batches)
    current = next(it, None)
    if current is None:
        raise InputError("no samples to track")
    while current is not None:
        nxt = next(it, None)
        res = tracker.process(
            current.t, current.rate, current.temperature, current.still,
            reference_rate=current.reference_rate, reference_axis=current.reference_axis,
            specific_force=current.specific_force,
            accel=current.accel if getattr(tracker, "accel_detector", None) is not None
            else None,
            finish=nxt is None,
        )
        kept.add(res)
        if res.t.size:
            since_max = max(since_max, float(np.max(res.since_update_s)))
        for key, v in (("ut", res.updates.t), ("uk", res.updates.kind),
                       ("al", res.updates.t[res.updates.alarm]),
                       ("sh", res.updates.t[res.updates.shift])):
            upd[key].append(v)
        current = nxt
    return Tracked(
        t=kept.col("t"),
        bias=kept.col("bias"),
        bias_std=kept.col("std"),
        still=kept.still[: kept.n].copy(),
        nis_ok=kept.col("nis"),
        since_update_s=kept.col("since"),
        update_t=np.concatenate(upd["ut"]),
        update_kind=np.concatenate(upd["uk"]),
        alarm_t=np.concatenate(upd["al"]),
        shift_t=np.concatenate(upd["sh"]),
        rows=kept.rows,
        since_max=since_max,
        bias_moved=tracker.bias_moved,
    )


#: Samples smoothed at a time (:meth:`gyrocal.calib.tracker.BiasTracker.smoothed`: a few
#: state-sized matrices per sample, some 3 MB of temporaries at this size).
SMOOTH_CHUNK = 4096


def smooth_tracked(tracker: Any, tr: Tracked, temperature: np.ndarray | None, *,
                   at_rows: bool = False) -> Tracked:
    """``tr`` with each sample's bias and uncertainty smoothed over the whole run
    (:meth:`gyrocal.calib.tracker.BiasTracker.smoothed`; the tracker was built with
    ``keep_states=True``): for a replayed recording, where every sample is at hand.
    ``temperature`` covers every sample (``at_rows``: only ``tr``'s rows); only ``tr``'s rows
    are smoothed."""
    from dataclasses import replace

    temp = temperature
    if temp is not None and tr.rows is not None and not at_rows:
        temp = np.asarray(temp)[tr.rows]
    bias, std = tracker.smoothed(tr.t, temp, chunk=SMOOTH_CHUNK)
    return replace(tr, bias=bias, bias_std=std)


def chunks(batch: Batch, size: int) -> Iterator[Batch]:
    """``batch`` in runs of ``size`` samples (as a live source would hand them over)."""
    n = batch.t.size
    for a in range(0, n, size):
        sl = slice(a, min(a + size, n))
        yield Batch(*(None if x is None else x[sl] for x in (
            batch.t, batch.rate, batch.temperature, batch.still, batch.reference_rate,
            batch.reference_axis, batch.specific_force, batch.accel)))


def load_calibration(path: str) -> Any:
    """Read the --cal Calibration v1 file (InputError naming the problem)."""
    from gyrocal.kit.exports import load_document

    return load_document(path, "gyrocal-calibration", "--cal")


def load_noise(path: str) -> Any:
    """Read the --noise gyrocal-noise v1 file (InputError naming the problem)."""
    from gyrocal.kit.exports import load_document

    return load_document(path, "gyrocal-noise", "--noise")


@dataclass(frozen=True)
class Reference:
    """Reference rates of a recording's rotate segments, held per segment (a few bytes per
    turning sample, instead of a rate and an axis for every sample of the recording).

    Attributes
    ----------
    runs : list of (int, ndarray (m,), ndarray (3,))
        First sample index, the encoder rate of each sample from there (NaN where the encoder
        does not cover it), and the servo's unit axis in the sensor frame during the turn.
    """

    runs: list[tuple[int, np.ndarray, np.ndarray]]

    def window(self, a: int, b: int) -> tuple[np.ndarray, np.ndarray] | None:
        """``(rate (b−a,), axis (b−a, 3))`` of samples ``a:b`` (NaN off the turns), or None
        when no turn covers them."""
        rr = ra = None
        for i0, rate, u in self.runs:
            lo, hi = max(a, i0), min(b, i0 + rate.size)
            if lo >= hi:
                continue
            if rr is None:
                rr = np.full(b - a, np.nan)
                ra = np.full((b - a, 3), np.nan)
            seg = rate[lo - i0:hi - i0]
            ok = np.isfinite(seg)
            rr[lo - a:hi - a][ok] = seg[ok]
            ra[lo - a:hi - a][ok] = u  # type: ignore[index]
        return None if rr is None else (rr, ra)  # type: ignore[return-value]


def turn_axis(rec: Any, cal: Any, motor: int, t_mid: float) -> np.ndarray | None:
    """Servo ``motor``'s unit axis in the sensor frame during a turn.

    With a Calibration v2's ``kinematics`` the axis is carried by the servos inside it in the
    chain (:func:`gyrocal.calib.kinematics.axes_at`, at their encoder angles mid-turn; a
    servo's own angle and those outside it do not move its axis, so the axis is constant
    through the turn), which a posed turn needs; otherwise the calibration's ``axes`` entry
    (:func:`gyrocal.kit.report_plots.calibration_axis`, the axis at the reference pose).
    """
    from gyrocal.kit.report_plots import calibration_axis

    kin = getattr(cal, "kinematics", None)
    chain = [int(x) for x in kin["chain"]] if kin else []
    if motor not in chain:
        return calibration_axis(cal, motor)
    from gyrocal.calib.kinematics import axes_at

    angles = np.empty((1, len(chain)))
    for j, sid in enumerate(chain):
        et, ea = rec.encoder(sid)
        if et.size == 0:
            angles[0, j] = float(kin["reference_angles_rad"][j])  # never moved
        else:
            angles[0, j] = float(np.interp(t_mid, et, ea))
    u = axes_at(kin, angles)[0, chain.index(motor)]
    return u / np.linalg.norm(u)


def reference_segments(rec: Any, cal: Any) -> tuple[Reference, list[str]]:
    """Reference rates and axes over the recording's rotate segments.

    The rate of sample ``i`` is the encoder angle's change across the sample's own interval
    ``[t_i − dt/2, t_i + dt/2]`` (linear interpolation of the encoder), so the mean over any
    run of samples is the angle change across the run divided by its length: the reference a
    window needs (DESIGN.md, "What makes the estimate right", item 2). Axes: :func:`turn_axis`.
    """
    from gyrocal.calib.timebase import median_step
    from gyrocal.kit.report_plots import encoder_rate

    n = rec.imu_t.size
    runs: list[tuple[int, np.ndarray, np.ndarray]] = []
    notes: list[str] = []
    if n < 2:
        return Reference(runs), notes
    dt = median_step(rec.imu_t)
    for seg in rec.segments:
        if seg.kind != "rotate":
            continue
        u = turn_axis(rec, cal, int(seg.motor), 0.5 * (seg.t_start + seg.t_end))
        if u is None:
            notes.append(f"no axis for servo {seg.motor} in the calibration: segment "
                         f"{seg.index} gives no reference-rate updates")
            continue
        et, ea = rec.encoder(seg.motor)
        i0 = int(np.searchsorted(rec.imu_t, seg.t_start, side="left"))
        i1 = int(np.searchsorted(rec.imu_t, seg.t_end, side="right"))
        rate = steady_only(et, ea, rec.imu_t[i0:i1], encoder_rate(et, ea, rec.imu_t[i0:i1],
                                                                     dt / 2))
        if not np.isfinite(rate).any():
            notes.append(f"no encoder readings of servo {seg.motor} across segment {seg.index}")
            continue
        runs.append((int(i0), rate, np.asarray(u, dtype=float)))
    return Reference(runs), notes


def steady_only(enc_t: np.ndarray, enc_angle: np.ndarray, t: np.ndarray, rate: np.ndarray
                ) -> np.ndarray:
    """``rate`` with NaN off the turn's cruise: where the encoder's mean rate over
    ±:data:`STEADY_HALF_SPAN_S` differs from its median over the turn by more than
    :data:`STEADY_TOLERANCE`.

    While the servo accelerates, a delay ``τ`` between the gyro and the encoder (the gyro's
    low-pass filter, the encoder's read latency) puts ``α τ`` on each sample's reference
    (10 rad/s² × 4 ms = 0.04 rad/s), which a window shorter than the whole turn does not
    cancel; at cruise it puts nothing.
    """
    from gyrocal.kit.report_plots import encoder_rate

    wide = encoder_rate(enc_t, enc_angle, t, STEADY_HALF_SPAN_S)
    if not np.isfinite(wide).any():
        return rate
    cruise = float(np.nanmedian(wide))
    with np.errstate(invalid="ignore"):
        steady = np.abs(wide - cruise) <= STEADY_TOLERANCE * abs(cruise)
    return np.where(steady, rate, np.nan)


def replay_chunks(batch: Batch, ref: Reference | None, size: int,
                  gravity: Any = None) -> Iterator[Batch]:
    """``batch`` in runs of ``size`` samples, each with the reference rates of ``ref``, the
    specific force of ``gravity`` and the batch's accelerometer readings over its samples (a
    recording replayed in bounded working memory)."""
    n = batch.t.size
    for a in range(0, n, size):
        b = min(a + size, n)
        rr_ra = ref.window(a, b) if ref is not None else None
        yield Batch(batch.t[a:b], batch.rate[a:b],
                    None if batch.temperature is None else batch.temperature[a:b],
                    None if batch.still is None else batch.still[a:b],
                    *(rr_ra if rr_ra is not None else (None, None)),
                    None if gravity is None else gravity.at(batch.t[a:b]),
                    None if batch.accel is None else batch.accel[a:b])


def live_gravity(cal: Any, ids: Iterable[int]
                 ) -> tuple[Callable[[np.ndarray], np.ndarray] | None, str]:
    """Where gravity points during a live run, for a calibration's g-sensitivity.

    The calibration's ``kinematics`` carries the home pose its "up" refers to
    (:attr:`gyrocal.calib.model.GyroCalibration.gravity_reference`), so the servo encoders give
    ``f`` in any pose (:func:`gyrocal.calib.kinematics.gravity_up`, as the fit and the replay
    carry it). Returns the function of encoder angles ``(N, servos in ids order)`` giving ``f``
    (N, 3) in g, and the note the run prints; None and the note of what is missing where the
    calibration (or the gimbal) cannot say, and the tracked bias then includes ``G f`` of the
    pose the jig holds.
    """
    from gyrocal.calib.kinematics import gravity_up

    ref = cal.gravity_reference
    ids = [int(i) for i in ids]
    missing = (None if ref is not None else
               "this calibration does not store the home pose its 'up' refers to (calibrations "
               "written before gyrocal stored kinematics.home_angles_rad: calibrate again)")
    chain = [] if cal.kinematics is None else [int(c) for c in cal.kinematics["chain"]]
    if missing is None and not set(chain) <= set(ids):
        missing = f"the calibration's servos {chain} are not all on this gimbal ({ids})"
    if missing is not None:
        return None, (f"the calibration's g-sensitivity is NOT applied live ({missing}; replay "
                      "the --record recording to apply it): the tracked bias includes G f, up to "
                      f"{cal.g_rate_error_per_g:.1e} rad/s per g")
    home, up = ref
    cols = [ids.index(c) for c in chain]

    def force(angles: np.ndarray) -> np.ndarray:
        return gravity_up(cal.kinematics, np.asarray(angles, dtype=float)[:, cols], home, up)

    return force, ("the calibration's g-sensitivity is applied live: the specific force comes "
                   "from the servo encoders and the calibration's home pose")


def chip_zero_rate(model: Any) -> tuple[float | None, str | None]:
    """The gyro's initial zero-rate tolerance of the chip ``model`` (a Recording v1 manifest's
    ``sensor.model``, a config's ``imu.model``), rad/s, from the chip data
    (:attr:`gyrocal.drivers.imu.chips.ChipFamily.gyro_errors`), with the note saying so; ``(None,
    None)`` for a model gyrocal does not know (the tracker's default then stands)."""
    from gyrocal.drivers.imu import READER_CLASSES, READERS

    if not isinstance(model, str) or model not in READER_CLASSES:
        return None, None
    ge = READERS[model].family.gyro_errors
    return ge.zero_rate_rad_s, (f"still detector's rate gate widened by the {model} gyro's "
                                f"zero-rate tolerance, +-{ge.zero_rate_dps:g} deg/s "
                                f"({ge.source})")


#: Seconds on each side of a rotate segment whose encoder readings a streamed replay keeps
#: (the reference rate of a sample interpolates the encoder half a sample period either side).
ENCODER_MARGIN_S = 1.0


class _NearTurns:
    """The encoder readings a streamed replay keeps: every reading inside one of the servo's
    windows (its rotate segments widened by :data:`ENCODER_MARGIN_S`, and the middle instant of
    every other servo's, where :func:`turn_axis` reads its angle), both readings of each pair of
    a servo's
    consecutive readings whose interval meets a window, and each servo's first and last
    reading. Linear interpolation (``numpy.interp``, which holds the end values outside the
    readings) at any time in a window then uses the same readings, so
    :func:`reference_segments` and :func:`turn_axis` give what they give on every reading
    (blocks are fed in file order)."""

    def __init__(self, windows: dict[int | None, list[tuple[float, float]]]) -> None:
        self.spans = windows  # servo (None: every servo) -> its windows
        self.windows: dict[int, tuple[np.ndarray, np.ndarray]] = {}
        self.last: dict[int, tuple[float, float, bool]] = {}  # servo: its last reading, kept?
        self.parts: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []

    def _meets(self, m: int, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """Whether ``[a, b]`` meets one of servo ``m``'s windows."""
        if m not in self.windows:
            lo_l: list[float] = []
            hi_l: list[float] = []
            for x, y in sorted(self.spans.get(m, []) + self.spans.get(None, [])):
                if lo_l and x <= hi_l[-1]:  # merged into disjoint, increasing spans
                    hi_l[-1] = max(hi_l[-1], y)
                else:
                    lo_l.append(x)
                    hi_l.append(y)
            self.windows[m] = (np.asarray(lo_l), np.asarray(hi_l))
        lo, hi = self.windows[m]
        if not lo.size:
            return np.zeros(a.shape, dtype=bool)
        k = np.searchsorted(lo, b, side="right") - 1
        return (k >= 0) & (hi[np.maximum(k, 0)] >= a)

    def add(self, et: np.ndarray, em: np.ndarray, ea: np.ndarray) -> None:
        """One block of ``encoder.csv``."""
        for m in np.unique(em).tolist():
            sel = em == m
            t, a = et[sel], ea[sel]
            prev = self.last.get(m)
            if prev is not None:
                t, a = np.concatenate([[prev[0]], t]), np.concatenate([[prev[1]], a])
            keep = self._meets(m, t, t)
            pair = self._meets(m, t[:-1], t[1:])
            keep[:-1] |= pair
            keep[1:] |= pair
            if prev is None:
                keep[0] = True  # the servo's first reading
            self.last[m] = (float(t[-1]), float(a[-1]), bool(keep[-1]))
            if prev is not None and prev[2]:
                keep[0] = False  # kept with its own block
            if keep.any():
                self.parts.append((t[keep], np.full(int(keep.sum()), m, dtype=np.int64),
                                   a[keep]))

    def columns(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(t, motor, angle)`` of the kept readings (each servo's in time order)."""
        for m, (t, a, kept) in self.last.items():
            if not kept:  # the servo's last reading
                self.parts.append((np.array([t]), np.array([m], dtype=np.int64), np.array([a])))
                self.last[m] = (t, a, True)
        if not self.parts:
            return np.empty(0), np.empty(0, dtype=np.int64), np.empty(0)
        return tuple(np.concatenate([p[i] for p in self.parts])  # type: ignore[return-value]
                     for i in range(3))


class SpilledImu:
    """A recording's gyro samples read once, block by block
    (:func:`gyrocal.kit.recording.iter_imu`, with all its checks): the times kept in memory
    (8 bytes a sample), the readings and temperatures (and the accelerometer's, where
    ``imu.csv`` has them) written to a temporary file (32 bytes a sample, 56 with the
    accelerometer; deleted on :meth:`close`) and read back a piece at a time, so a replay's working
    memory does not grow with the recording's rate columns.

    Parameters
    ----------
    root : Path
        The recording directory (manifest already checked).
    warnings : list of str
        Receives what the reader tolerated.

    Attributes
    ----------
    t : ndarray (n,)
        Sample times, s.
    temperature_complete : bool
        Whether every sample has a temperature.
    """

    def __init__(self, root: Any, warnings: list[str]) -> None:
        import tempfile
        from pathlib import Path

        from gyrocal.kit.recording import IMU_HEADER_ACCEL, imu_header, imu_rows_bound, iter_imu

        t = np.empty(imu_rows_bound(root))
        #: Whether imu.csv has the accelerometer's columns (kept as columns 4-6 of a row).
        self.has_accel = imu_header(Path(root) / "imu.csv") == IMU_HEADER_ACCEL
        self.width = 7 if self.has_accel else 4
        self._fh = tempfile.TemporaryFile(prefix="gyrocal-replay-")
        n = 0
        complete = True
        try:
            for tb, rate, temp, acc in iter_imu(root, warnings, accel=True):
                k = tb.size
                t[n:n + k] = tb
                complete = complete and bool(np.isfinite(temp).all())
                rows = np.empty((k, self.width))
                rows[:, :3] = rate
                rows[:, 3] = temp
                if acc is not None:
                    rows[:, 4:7] = acc
                self._fh.write(rows.data)
                n += k
            self._fh.flush()
        except BaseException:
            self._fh.close()
            raise
        self.t = t[:n]
        self.n = n
        self.temperature_complete = complete

    def rows(self, lo: int, hi: int) -> np.ndarray:
        """Samples ``lo:hi`` as an ``(hi − lo, 4)`` array: rate x, y, z (rad/s), temperature
        (°C or NaN); ``(hi − lo, 7)`` with the accelerometer's x, y, z (m/s²) after them when
        the recording has them (:attr:`has_accel`)."""
        lo, hi = max(0, int(lo)), min(self.n, int(hi))
        out = np.empty((max(hi - lo, 0), self.width))
        view = memoryview(out).cast("B")
        self._fh.seek(lo * self.width * 8)
        got = 0
        while got < len(view):
            k = self._fh.readinto(view[got:])
            if not k:
                raise OSError(f"the replay's temporary file ended {len(view) - got} bytes early")
            got += k
        return out

    def rate(self, lo: int, hi: int) -> np.ndarray:
        """Readings of samples ``lo:hi``, ``(hi − lo, 3)`` rad/s."""
        return np.ascontiguousarray(self.rows(lo, hi)[:, :3])

    def accel(self, lo: int, hi: int) -> np.ndarray:
        """The accelerometer's readings of samples ``lo:hi``, ``(hi − lo, 3)`` m/s² (only with
        :attr:`has_accel`)."""
        if not self.has_accel:
            raise ValueError("this recording has no accelerometer columns")
        return np.ascontiguousarray(self.rows(lo, hi)[:, 4:7])

    def close(self) -> None:
        """Delete the temporary file."""
        self._fh.close()

    def __enter__(self) -> SpilledImu:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


@dataclass(frozen=True)
class Timeline:
    """What a streamed replay holds of a recording besides its readings: the sample times, the
    segments, and the encoder readings near the rotate segments (:class:`_NearTurns`); enough
    for :func:`reference_segments` and :func:`turn_axis`."""

    path: Any
    manifest: dict[str, Any]
    imu_t: np.ndarray
    segments: tuple[Any, ...]
    enc_t: np.ndarray
    enc_motor: np.ndarray
    enc_angle: np.ndarray

    def encoder(self, motor: int) -> tuple[np.ndarray, np.ndarray]:
        """``(t, angle)`` of one servo (near the rotate segments only)."""
        sel = self.enc_motor == motor
        return self.enc_t[sel], self.enc_angle[sel]


def open_replay(path: Any, warnings: list[str], *, encoder: bool = True,
                every_encoder: bool = False) -> tuple[SpilledImu, Timeline]:
    """Read a Recording v1 for a streamed replay: the manifest, ``imu.csv`` into a
    :class:`SpilledImu`, ``encoder.csv`` (every row checked, those near the rotate segments
    kept: :class:`_NearTurns`) and ``segments.csv``, in the order and
    with the checks of :func:`gyrocal.kit.recording.load_recording`. Without ``encoder`` (no
    reference rates wanted) no encoder reading is kept, though every one is checked; with
    ``every_encoder`` every one is kept (a calibration's g-sensitivity needs the pose at every
    sample: :func:`gyrocal.kit.gravity.force_of`). The caller closes the :class:`SpilledImu`."""
    from pathlib import Path

    from gyrocal.kit.recording import iter_encoder, read_manifest, read_segments

    root = Path(path)
    manifest = read_manifest(root)
    imu = SpilledImu(root, warnings)
    try:
        # the segments say which encoder rows to keep; a fault in them is raised after the
        # encoder's own, as load_recording would
        seg_w: list[str] = []
        segments: tuple[Any, ...] = ()
        seg_error: BaseException | None = None
        try:
            segments = read_segments(root, seg_w)
        except InputError as exc:
            seg_error = exc
        windows: dict[int | None, list[tuple[float, float]]] = {}
        for s in segments if encoder else ():
            if s.kind != "rotate" or s.motor is None:
                continue
            mid = 0.5 * (s.t_start + s.t_end)
            windows.setdefault(int(s.motor), []).append(
                (s.t_start - ENCODER_MARGIN_S, s.t_end + ENCODER_MARGIN_S))
            windows.setdefault(None, []).append((mid, mid))  # every servo's angle mid-turn
        if every_encoder:
            windows = {None: [(-math.inf, math.inf)]}
        near = _NearTurns(windows)
        for block in iter_encoder(root, warnings):
            near.add(*block)
        if seg_error is not None:
            raise seg_error
        warnings += seg_w
    except BaseException:
        imu.close()
        raise
    return imu, Timeline(root, manifest, imu.t, segments, *near.columns())


@dataclass(frozen=True)
class StillPlan:
    """Still flags of a replay, made a piece at a time: 1 on the ``intervals``
    (:func:`rest_intervals`), ``outside`` elsewhere (0: not still; NaN: the detector decides),
    0 wherever a reference rate is given (the sensor turns)."""

    intervals: list[tuple[int, int]]
    outside: float

    def window(self, a: int, b: int, reference: np.ndarray | None) -> np.ndarray:
        """Flags of samples ``a:b`` (``reference``: their reference rates, NaN off turns)."""
        still = np.full(b - a, float(self.outside))
        for i0, i1 in self.intervals:
            lo, hi = max(a, i0), min(b, i1)
            if lo < hi:
                still[lo - a:hi - a] = 1.0
        if reference is not None:
            still[np.isfinite(reference)] = 0.0
        return still


def spilled_chunks(
    imu: SpilledImu, ref: Reference | None, size: int, *, still: StillPlan | None = None,
    temperature: bool = False, rows: np.ndarray | None = None,
    kept_temperature: list[np.ndarray] | None = None, accel: bool = False,
) -> Iterator[Batch]:
    """A :class:`SpilledImu` in runs of ``size`` samples, each with its reference rates
    (``ref``), still flags (``still``) and, with ``temperature``, the die temperature: a
    recording replayed in bounded working memory. ``kept_temperature`` receives the
    temperatures of the samples ``rows`` (None: all), for the smoother; with ``accel``, the
    accelerometer's readings (the still detector's veto)."""
    n = imu.n
    for a in range(0, n, size):
        b = min(a + size, n)
        block = imu.rows(a, b)
        rr_ra = ref.window(a, b) if ref is not None else None
        flags = None if still is None else still.window(a, b, None if rr_ra is None
                                                         else rr_ra[0])
        temp = block[:, 3]
        if kept_temperature is not None:
            if rows is None:
                kept_temperature.append(temp.copy())
            else:
                lo, hi = np.searchsorted(rows, (a, b))
                kept_temperature.append(temp[rows[lo:hi] - a])
        yield Batch(imu.t[a:b], np.ascontiguousarray(block[:, :3]),
                    temp if temperature else None, flags,
                    *(rr_ra if rr_ra is not None else (None, None)),
                    accel=np.ascontiguousarray(block[:, 4:7]) if accel else None)


class ReplaySource:
    """A recording ready to replay through the tracker (:func:`gyrocal.kit.commands.track`):
    its spilled readings, reference rates, still plan, whether the tracker takes the
    temperature, the specific force for a calibration's g-sensitivity (``gravity``) and
    whether the batches carry the accelerometer's readings (``accel``: the tracker's still
    detector uses them). A context manager: leaving it deletes the temporary file."""

    def __init__(self, imu: SpilledImu, ref: Reference | None, still: StillPlan | None,
                 temperature: bool, gravity: Any = None, accel: bool = False) -> None:
        self.imu = imu
        self.accel = accel
        self.ref = ref
        self.still = still
        self.temperature = temperature
        self.gravity = gravity
        self._temps: list[np.ndarray] = []

    @property
    def t(self) -> np.ndarray:
        """Sample times, s."""
        return self.imu.t

    def batches(self, size: int, rows: np.ndarray | None = None) -> Iterator[Batch]:
        """The samples in runs of ``size`` (:func:`spilled_chunks`); the temperatures of
        ``rows`` (None: all) are kept for :meth:`kept_temperature`."""
        self._temps = []
        pieces = spilled_chunks(self.imu, self.ref, size, still=self.still,
                                temperature=self.temperature, rows=rows,
                                kept_temperature=self._temps if self.temperature else None,
                                accel=self.accel)
        if self.gravity is None:
            return pieces
        gravity = self.gravity
        return (replace(b, specific_force=gravity.at(b.t)) for b in pieces)

    def kept_temperature(self) -> np.ndarray | None:
        """Temperatures of the rows of the last :meth:`batches` run (None without the
        temperature model)."""
        return np.concatenate(self._temps) if self.temperature and self._temps else None

    def close(self) -> None:
        """Delete the temporary file."""
        self.imu.close()

    def __enter__(self) -> ReplaySource:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def rest_intervals(
    t: np.ndarray,
    segments: Iterable[Any],
    read: Callable[[int, int], np.ndarray],
    trim_s: float = 0.5,
    *,
    check: Any = None,
    notes: list[str] | None = None,
) -> list[tuple[int, int]]:
    """The sample ranges ``[i0, i1)`` inside the recording's rest segments (less ``trim_s`` at
    each end) that are still.

    ``t`` are the sample times (non-decreasing), ``read(lo, hi)`` the readings of samples
    ``lo:hi`` (so a recording held in a temporary file is read a piece at a time). With
    ``check`` (a :class:`gyrocal.calib.stationarity.StillDetector`), a rest is trusted only when
    at least 95 % of its windows pass the detector's variance test (the rate test is left out:
    the bias is what is being tracked, :func:`gyrocal.calib.stationarity.quiet_fraction`); a
    rest that fails is left out, with a line in ``notes`` (a recording whose "rest" moved,
    e.g. one not made on the jig).
    """
    out: list[tuple[int, int]] = []
    loose = None
    if check is not None:
        from gyrocal.calib.stationarity import StillDetector

        loose = StillDetector(check.n_window, check.n_min, check.n_lookahead, check.var_limit,
                              np.full(3, np.inf))
    for seg in segments:
        if seg.kind != "rest" or seg.duration <= 2 * trim_s:
            continue
        # t is non-decreasing: the samples with t_start + trim <= t <= t_end - trim
        i0 = int(np.searchsorted(t, seg.t_start + trim_s, side="left"))
        i1 = int(np.searchsorted(t, seg.t_end - trim_s, side="right"))
        if loose is not None:
            from gyrocal.calib.stationarity import quiet_fraction

            frac = quiet_fraction(max(i1 - i0, 0), lambda a, b, i0=i0: read(i0 + a, i0 + b),
                                  loose)
            if frac is None or frac < 0.95:
                if notes is not None:
                    notes.append(f"rest segment {seg.index} ({seg.t_start:.1f}-{seg.t_end:.1f} "
                                 "s) shows motion in the gyro readings: left to the detector")
                continue
        if i1 > i0:
            out.append((i0, i1))
    return out


def rest_flags(
    rec: Any,
    trim_s: float = 0.5,
    outside: float = 0.0,
    *,
    check: Any = None,
    notes: list[str] | None = None,
) -> np.ndarray:
    """Still flags of a :class:`gyrocal.kit.recording.Recording` from its rest segments: 1 on
    samples inside a rest (:func:`rest_intervals`), ``outside`` elsewhere (0: not still; NaN:
    the detector decides)."""
    still = np.full(rec.imu_t.size, float(outside))
    for i0, i1 in rest_intervals(rec.imu_t, rec.segments, lambda a, b: rec.imu_rate[a:b],
                                 trim_s, check=check, notes=notes):
        still[i0:i1] = 1.0
    return still


@dataclass(frozen=True)
class TurnPlan:
    """Turns that give the tracker reference-rate updates during a live run.

    Attributes
    ----------
    turns : int
        Whole turns each way (positive, then back).
    speed : float
        rad/s.
    every_s : float
        Still time between two turn pairs, s.
    axes : dict
        Servo id -> unit axis in the sensor frame (from the calibration); the servos turn in
        this order, round robin.
    """

    turns: int
    speed: float
    every_s: float
    axes: dict[int, np.ndarray]


class LiveSource:
    """Batches from the jig: the servos hold the sensor still while the IMU FIFO is drained.

    One loop on the jig's clock, as the protocol runner's: drain the FIFO, one sync read of the
    servos (:meth:`gyrocal.drivers.dynamixel.Gimbal.poll`, with its safety checks), wait for the
    next
    period (dithered by up to half a period, seeded, so drains fall at random phases of the
    chip's sample grid). Samples drained in a period in which a servo moved by more than
    :data:`LIVE_MOVE_TOLERANCE_RAD` are flagged not still.

    With a :class:`TurnPlan`, every ``every_s`` of still time one servo turns ``turns`` whole
    turns and back; the samples of the turn pair go to the tracker as one batch with the
    encoder's reference rate per sample (the angle change across the sample's own interval, as
    a replay computes it) and the servo's axis.

    Parameters
    ----------
    jig : gyrocal.kit.jig.Jig
        Its gimbal open (inside ``with jig.gimbal``), its IMU configured.
    period_s : float
        Loop period (the config's ``gimbal.sample_hz``).
    temperature : bool
        Hand the die temperature to the tracker (``--tempco``).
    trust_jig : bool
        Flag every sample still unless a servo moved (``--still segments``); otherwise leave the
        decision to the detector.
    turns : TurnPlan, optional
    gravity : callable, optional
        Encoder angles ``(N, servos)`` → specific force ``(N, 3)``, g (:func:`live_gravity`):
        every batch then carries ``f`` at each sample, from the servo readings around it.
    """

    def __init__(self, jig: Any, period_s: float, *, temperature: bool = False,
                 trust_jig: bool = False, turns: TurnPlan | None = None,
                 gravity: Callable[[np.ndarray], np.ndarray] | None = None) -> None:
        self.jig = jig
        self.clock = jig.clock
        self.period_s = float(period_s)
        self.temperature = temperature
        self.trust_jig = trust_jig
        self.plan = turns
        self.notes: list[str] = []
        self.t0 = math.nan
        self.samples = 0
        self.lost = 0
        self.moved_samples = 0
        self.turn_pairs = 0
        self.temperatures: list[np.ndarray] = []
        self._next = 0.0
        self._angles: np.ndarray | None = None
        self._dither = np.random.default_rng(0x74726B)
        self.gravity = gravity
        self._polls: list[tuple[float, np.ndarray]] = []  # (time, angles) since the last batch
        #: A RecordingWriter that receives every sample (``--record``), or None.
        self.writer: Any = None

    def start(self) -> None:
        """Note the hold angles and start the IMU stream."""
        self._angles = np.asarray(self.jig.gimbal.poll().angles, dtype=float)
        self.t0 = self.clock.monotonic()
        self._next = self.t0
        self.jig.imu.start()

    @property
    def elapsed_s(self) -> float:
        """Time since :meth:`start` on the jig's clock, s."""
        return self.clock.monotonic() - self.t0 if math.isfinite(self.t0) else 0.0

    def _tick(self) -> tuple[Any, bool, Any]:
        b = self.jig.imu.read()
        s = self.jig.gimbal.poll()
        if self.writer is not None:
            if len(b):
                self.writer.append_imu(b.t - self.t0, b.rate, b.temperature_c)
            self.writer.append_encoder(s.t - self.t0, list(s.ids), s.angles)
        angles = np.asarray(s.angles, dtype=float)
        if self.gravity is not None:
            self._polls.append((float(s.t), angles))
        moved = bool(np.any(np.abs(angles - self._angles) > LIVE_MOVE_TOLERANCE_RAD))
        self._angles = angles
        for g in b.gaps:
            self.lost += int(g.samples)
            self.notes.append(f"lost {g.samples} gyro samples at {g.t - self.t0:.2f} s "
                              f"({g.reason})")
        self._next += self.period_s * (1.0 + self._dither.uniform(-0.5, 0.5))
        wait = self._next - self.clock.monotonic()
        if wait > 0:
            self.clock.sleep(wait)
        else:
            self._next = self.clock.monotonic()
        return b, moved, s

    def _batch(self, parts: list[tuple[Any, bool]], planned: bool = False) -> Batch:
        t = np.concatenate([b.t for b, _ in parts]) - self.t0
        rate = np.vstack([b.rate for b, _ in parts])
        temp = np.concatenate([np.asarray(b.temperature_c, dtype=float) for b, _ in parts])
        moved = np.concatenate([np.full(len(b), mv) for b, mv in parts])
        accel = np.vstack([np.asarray(b.accel, dtype=float).reshape(-1, 3) for b, _ in parts])
        self.samples += t.size
        if not planned:
            self.moved_samples += int(moved.sum())
        self.temperatures.append(temp)
        if self.trust_jig:
            still = np.where(moved, 0.0, 1.0)
        else:
            still = np.where(moved, 0.0, np.nan)
        return Batch(t, rate, temp if self.temperature else None, still,
                     specific_force=self._force(t + self.t0), accel=accel)

    def _force(self, t: np.ndarray) -> np.ndarray | None:
        """``f`` at jig times ``t`` from the servo readings (interpolated linearly, held
        outside them); keeps only the last reading for the next batch."""
        if self.gravity is None or not self._polls:
            return None
        pt = np.array([p[0] for p in self._polls])
        pa = np.array([p[1] for p in self._polls])
        self._polls = self._polls[-1:]
        angles = np.column_stack([np.interp(t, pt, pa[:, j]) for j in range(pa.shape[1])])
        return self.gravity(angles)

    def collect(self, until_s: float) -> Batch | None:
        """Drain until ``until_s`` after :meth:`start`; the samples as one batch (or None)."""
        parts: list[tuple[Any, bool]] = []
        while self.elapsed_s < until_s:
            b, moved, _ = self._tick()
            if len(b):
                parts.append((b, moved))
        return self._batch(parts) if parts else None

    def turn_time_s(self) -> float:
        """Jig time of one turn pair with its settling, s (an upper estimate)."""
        p = self.plan
        if p is None:
            return 0.0
        accel = float(self.jig.gimbal.acceleration)
        one = p.turns * 2 * math.pi / p.speed + p.speed / accel
        return 2 * (one + 0.5) + 0.5

    def turn_pair(self, motor: int) -> Batch | None:
        """Turn ``motor`` the plan's turns positive and back, draining all along; the samples
        with the encoder's reference rate and the servo's axis."""
        from gyrocal.kit.report_plots import encoder_rate

        p = self.plan
        if p is None:
            raise InputError("no turns planned")
        gimbal = self.jig.gimbal
        k = gimbal.ids.index(motor)
        parts: list[tuple[Any, bool]] = []
        enc_t: list[float] = []
        enc_a: list[float] = []
        for direction in (1, -1):
            gimbal.begin_turn(motor, p.turns, p.speed, direction)
            while gimbal.busy:
                b, moved, smp = self._tick()
                enc_t.append(smp.t - self.t0)
                enc_a.append(float(smp.angles[k]))
                if len(b):
                    parts.append((b, moved))
        settle_end = self.elapsed_s + 0.3  # encoder readings past the last gyro sample
        while self.elapsed_s < settle_end:
            b, moved, smp = self._tick()
            enc_t.append(smp.t - self.t0)
            enc_a.append(float(smp.angles[k]))
            if len(b):
                parts.append((b, True))
        self.turn_pairs += 1
        if not parts:
            return None
        batch = self._batch(parts, planned=True)
        t = batch.t
        dt = 1.0 / float(self.jig.imu.odr_hz)
        rr = encoder_rate(np.asarray(enc_t), np.asarray(enc_a), t, dt / 2)
        ra = np.full((t.size, 3), np.nan)
        ra[np.isfinite(rr)] = p.axes[motor]
        return Batch(batch.t, batch.rate, batch.temperature, np.zeros(t.size), rr, ra,
                     batch.specific_force, batch.accel)

    def batches(self, first: Batch, duration_s: float, chunk_s: float) -> Iterator[Batch]:
        """``first``, then a batch every ``chunk_s`` (and the turn pairs of the plan) until
        ``duration_s``."""
        yield first
        end = float(first.t[-1])
        order = list(self.plan.axes) if self.plan is not None else []
        next_turn = self.elapsed_s + self.plan.every_s if self.plan is not None else math.inf
        while self.elapsed_s < duration_s:
            now = self.elapsed_s
            if now >= next_turn and now + self.turn_time_s() < duration_s:
                nxt = self.turn_pair(order[self.turn_pairs % len(order)])
                next_turn = self.elapsed_s + self.plan.every_s  # type: ignore[union-attr]
            else:
                if now >= next_turn:  # no time left for another turn pair
                    next_turn = math.inf
                nxt = self.collect(min(now + chunk_s, duration_s, next_turn))
            if nxt is None:
                continue
            if nxt.t[0] <= end:
                from gyrocal.kit.errors import HardwareError

                raise HardwareError("the IMU reader returned samples out of time order; check "
                                    "the I2C bus and imu.odr_hz, and try again")
            end = float(nxt.t[-1])
            yield nxt



@dataclass(frozen=True)
class LiveTruth:
    """The emulated sensor's true bias at each tracked sample (for the summary and the plot)."""

    true_bias: np.ndarray


def run_live(
    jig: Any,
    source: LiveSource,
    duration_s: float,
    build: Callable[[Batch], Any],
    *,
    make_writer: Callable[[], Any] | None = None,
    announce: Callable[[], None] | None = None,
    where: str = "the jig",
) -> Tracked:
    """Hold the jig still, track, release.

    The servos stop and torque goes off at the end, on an error, Ctrl-C or SIGTERM (the
    gimbal's context), before anything else.

    Parameters
    ----------
    jig : gyrocal.kit.jig.Jig
        Not yet opened; closed on return, whatever happens.
    source : LiveSource
        Built on ``jig``.
    duration_s : float
        Jig time to track for, s (at least :data:`LIVE_WARMUP_S`).
    build : callable
        Makes the :class:`gyrocal.calib.tracker.BiasTracker` from the first
        :data:`LIVE_WARMUP_S` seconds of samples.
    make_writer : callable, optional
        Opens a :class:`gyrocal.kit.recording.RecordingWriter` once the gimbal is open; the
        session is written to it as one rest and finished, or left incomplete on a failure.
    announce : callable, optional
        Called once the gimbal holds the sensor (the command says what happens).
    where : str
        Names the jig in errors.

    Returns
    -------
    Tracked

    Raises
    ------
    InterruptedRun
        On Ctrl-C or SIGTERM (exit 130 or 143), after the servos are stopped.
    """
    from gyrocal.drivers.dynamixel.errors import TerminatedBySignal
    from gyrocal.kit.errors import InterruptedRun

    interrupted: BaseException | None = None
    tr: Tracked | None = None
    writer = None
    try:
        with jig.gimbal:
            if announce is not None:
                announce()
            if make_writer is not None:
                writer = make_writer()
                source.writer = writer
            source.start()
            warm = source.collect(LIVE_WARMUP_S)
            if warm is None or warm.t.size < 3:
                raise InputError(f"{where}: the IMU delivered no samples in the first "
                                 f"{LIVE_WARMUP_S:g} s; check imu.odr_hz and the I2C bus")
            tracker = build(warm)
            tr = run_tracker(tracker, source.batches(warm, duration_s, LIVE_CHUNK_S))
            if writer is not None:
                from gyrocal.calib.segments import Segment

                writer.append_segment(Segment(0, "rest", None, 0, 0.0, 0.0, source.elapsed_s))
                writer.finish()
    except (KeyboardInterrupt, TerminatedBySignal) as exc:
        interrupted = exc
    finally:
        jig.close()
        if writer is not None:
            writer.close()  # incomplete unless finished above
    if interrupted is not None:
        signum = 15 if isinstance(interrupted, TerminatedBySignal) else 2
        raise InterruptedRun(
            f"{'terminated' if signum == 15 else 'interrupted'} after "
            f"{source.elapsed_s:.1f} s of live tracking: servos stopped, torque off; nothing "
            "was printed", signum)
    assert tr is not None
    return tr


def live_truth(jig: Any, source: LiveSource, tr: Tracked) -> LiveTruth | None:
    """The emulated sensor's true bias at each tracked sample (None on a real jig)."""
    if jig.sim is None:
        return None
    st = jig.sim.truth
    temp = np.concatenate(source.temperatures)[: tr.t.size]
    coeff = np.asarray(st.bias_temp_coeff_rad_s_per_c, dtype=float)
    return LiveTruth(np.asarray(st.bias)[None, :]
                     + coeff[None, :] * (temp[:, None] - st.reference_temperature_c))



def tracker_notes(tracker: Any) -> list[str]:
    """What the tracker learnt from the data that the user should know: whether the bias moved
    since calibration (beyond its sigma), the bias random walk it estimated (when none was
    given) and whether the temperature coefficient matters."""
    out: list[str] = []
    if tracker.bias_moved is not None:
        out.append(tracker.bias_moved.message() + ": recalibrate the bias (or give "
                   "--initial-bias-std to say the calibration is older than its sigma)")
    k = tracker.rate_random_walk_estimate
    if k is not None:
        out.append("bias random walk estimated from the innovations: "
                   + ", ".join(f"{x:.2g}" for x in k) + " rad/s/sqrt(s) (x, y, z; pass "
                   "--rate-random-walk or --noise to fix it)")
    c, c_std = tracker.tempco, tracker.tempco_std
    if c is not None:
        sig = [name for name, a, b in zip("xyz", c, c_std, strict=True) if abs(a) > 3 * b]
        out.append("temperature coefficient "
                   + ", ".join(f"{a:.2g} +- {b:.1g}" for a, b in zip(c, c_std, strict=True))
                   + " rad/s/degC: "
                   + (f"it matters on {', '.join(sig)} (beyond 3 sigma)" if sig
                      else "not distinguishable from zero (--no-tempco would do)"))
    return out


#: Rows of an array turned into Python objects at a time by :func:`json_pieces`.
JSON_PIECE_ROWS = 8192


def json_pieces(columns: dict[str, Callable[[], Any]]) -> Iterator[str]:
    """The text of ``json.dumps({name: make()})`` plus a newline, in pieces.

    A column whose ``make()`` gives an array is turned into Python objects and text
    :data:`JSON_PIECE_ROWS` rows at a time, so the objects of a few thousand rows exist at
    once, not of a column; written piece by piece (:func:`gyrocal.kit.fileio.emit_text`) the
    document is never held whole. The text is ``json.dumps``'s (``allow_nan=False``); a NaN or
    infinity in an array raises ValueError before the first piece, so nothing is half-written.
    """
    values = {name: make() for name, make in columns.items()}
    for name, value in values.items():
        if (isinstance(value, np.ndarray) and value.dtype.kind == "f"
                and not np.isfinite(value).all()):
            raise ValueError(f"Out of range float values are not JSON compliant ({name})")
    yield "{"
    for c, (name, value) in enumerate(values.items()):
        yield f"{', ' if c else ''}{json.dumps(name)}: "
        if not isinstance(value, np.ndarray) or value.ndim == 0:
            yield json.dumps(value.tolist() if isinstance(value, np.ndarray) else value,
                             allow_nan=False)
            continue
        yield "["
        for a in range(0, value.shape[0], JSON_PIECE_ROWS):
            part = json.dumps(value[a:a + JSON_PIECE_ROWS].tolist(), allow_nan=False)[1:-1]
            yield (", " if a else "") + part
        yield "]"
    yield "}\n"


def json_rows(t: np.ndarray, every_s: float | None, max_rows: int | None) -> tuple[
        np.ndarray, float | None]:
    """Which samples the ``--json`` document keeps.

    Parameters
    ----------
    t : ndarray (n,)
        Sample times, s.
    every_s : float or None
        One row per ``every_s`` seconds (the last sample of each interval, and the last sample
        of all); 0 or None: every sample.
    max_rows : int or None
        Without ``every_s``, decimate to at most this many rows (None: never).

    Returns
    -------
    (rows, every)
        Indices of the rows kept, and the interval used (None when nothing was dropped).
    """
    n = t.size
    span = float(t[-1] - t[0]) if n else 0.0
    every = every_s if every_s else None
    if every is None and max_rows is not None and n > max_rows and span > 0:
        raw = span / max_rows
        unit = 10.0 ** (math.floor(math.log10(raw)) - 1)
        every = math.ceil(raw / unit * (1 + 1e-9)) * unit  # rounded up to two digits
    if every is None or n < 2:
        return np.arange(n), None
    # the last sample of each interval, a piece of JSON_PIECE_ROWS × 8 samples at a time (no
    # temporaries the length of the session)
    step = 8 * JSON_PIECE_ROWS
    parts = []
    for a in range(0, n - 1, step):
        b = min(n, a + step + 1)  # one sample more: does the piece's last sample end a cell?
        cell = np.floor((t[a:b] - t[0]) / every).astype(np.int64)
        parts.append(np.flatnonzero(cell[1:] != cell[:-1]) + a)
    last = np.concatenate([*parts, [n - 1]])
    if last.size == n:
        return np.arange(n), None
    return last, float(every)
