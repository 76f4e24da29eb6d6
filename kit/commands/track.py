"""``gyrocal track``: follow the gyro's bias over a recording (or a simulated session)."""

from __future__ import annotations

import argparse
import math
import sys
from collections.abc import Iterable
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    import numpy as np

    from gyrocal.kit.tracking import Batch, Tracked, TurnPlan

from gyrocal.kit import argtypes
from gyrocal.kit.errors import InputError, OutputExistsError

#: Rows of the --json document beyond which it is decimated unless --every is given
#: (153 B per row: about 30 MB).
JSON_MAX_ROWS = 200_000

#: Samples handed to the tracker at a time on a replay (bounds its working memory).
REPLAY_CHUNK = 16_384

#: The prior bias std without --cal when --initial-bias-std is not given, rad/s.
DEFAULT_INITIAL_BIAS_STD = 0.1

#: The --live bias random walk when none is given, rad/s/√s: conservative for consumer MEMS gyros.
DEFAULT_RATE_RANDOM_WALK = 1e-4

HELP = "track the gyro bias with a Kalman filter: over a recording, or live on the jig (--live)"
DESCRIPTION = (
    "Replay a Recording v1 through the bias tracker (gyrocal.calib.tracker: a Kalman filter on the "
    "three biases, optionally a temperature coefficient, with zero-rate updates when the sensor is "
    "still and reference-rate updates while a servo turns about an axis the calibration knows) "
    "and print or plot the bias over time with its uncertainty. --json prints "
    '{"t": [N], "bias": [N][3], "bias_std": [N][3], "still": [N]} in rad/s, one row per gyro '
    "sample (or per --every seconds, with \"decimated_every_s\"; sessions longer than "
    f"{JSON_MAX_ROWS:,} samples are decimated by default), the bias in the Calibration's "
    "convention (g = A (m + bias), so a still sensor reads -bias). Nothing needs tuning: "
    "the white noise comes from the still seconds, the bias random walk from the filter's "
    "innovations, the temperature state is on when every sample has a temperature; figures "
    "given as flags win. A recording is replayed whole, so each sample's estimate is smoothed "
    "(Rauch-Tung-Striebel: every update of the session informs it, before and after); --causal "
    "gives the filter's own estimate instead, what a live tracker would have said at that "
    "sample. --sim tracks a synthetic 30-minute session (gyrocal.calib.noise_sim: a "
    "synthetic sensor, not the emulated jig) and compares with its truth. --live tracks on the "
    "jig itself: the servos hold the sensor still (torque on) while the IMU FIFO is drained for "
    "--duration seconds; --live --sim does it on the emulated jig and compares with the emulated "
    "sensor's true bias. Ctrl-C or an error stops the servos (torque off) and exits 130 or with "
    "the error's code."
)



def add_arguments(p: argparse.ArgumentParser) -> None:
    """Register the flags."""
    p.add_argument("recording", nargs="?", metavar="RECORDING", type=argtypes.recording_dir,
                   help="Recording v1 directory")
    src = p.add_argument_group("simulation (--sim)")
    src.add_argument("--sim", action="store_true",
                     help="track a synthetic session instead of a recording; with --live, run "
                          "on the emulated jig")
    src.add_argument("--duration", type=float, default=None, metavar="S",
                     help="--sim or --live: session length, s (default 1800 for a synthetic "
                          "session, 60 live)")
    src.add_argument("--seed", type=argtypes.seed, default=None,
                     help="--sim: random seed of the synthetic session (default 0; the emulated "
                          "jig of --live --sim takes --sim-seed)")
    src.add_argument("--motion", choices=("random", "jig"), default=None,
                     help="--sim: random hand-held-like motions (default), or servo turns of "
                          "the jig")
    src.add_argument("--step-at", type=float, default=None, metavar="S",
                     help="--sim: inject a bias step at this time")
    src.add_argument("--step", type=float, default=2e-3, metavar="RAD_S",
                     help="--sim: size of the step on the x axis, rad/s (default 2e-3)")
    m = p.add_argument_group("model")
    m.add_argument("--cal", metavar="CAL",
                   help="Calibration JSON (v1, or v2: its full matrix is applied): initial bias "
                        "and bias_std, scale, servo axes")
    m.add_argument("--noise", metavar="NOISE",
                   help="gyrocal-noise v1 JSON (from 'gyrocal noise'): sets R and Q")
    m.add_argument("--noise-density", type=float, default=None, metavar="N",
                   help="white noise density, rad/s/sqrt(Hz) (default: --noise, else estimated "
                        "from the recording)")
    m.add_argument("--rate-random-walk", type=float, default=None, metavar="K",
                   help="bias random walk, rad/s/sqrt(s) (default: --noise, else estimated "
                        "from the data as the tracker goes, starting from "
                        f"{DEFAULT_RATE_RANDOM_WALK:g})")
    m.add_argument("--tempco", action=argparse.BooleanOptionalAction, default=None,
                   help="also estimate a linear temperature coefficient per axis (default: on "
                        "when every sample of a recording has a temperature; off live)")
    m.add_argument("--tempco-std", type=float, default=1e-3, metavar="RAD_S_PER_C",
                   help="prior std of the temperature coefficient (default 1e-3)")
    m.add_argument("--initial-bias-std", type=float, default=None, metavar="RAD_S",
                   help="prior bias std (default: the calibration's bias_std with --cal, "
                   f"else {DEFAULT_INITIAL_BIAS_STD})")
    d = p.add_argument_group("still detection and updates")
    d.add_argument("--still", choices=("auto", "detect", "segments"), default="auto",
                   help="auto: the recording's rest segments are still, the detector decides "
                        "elsewhere; detect: the detector everywhere; segments: only the rest "
                        "segments (--live: every sample while no servo moves) (default auto; "
                        "live, auto = detect)")
    d.add_argument("--no-reference", action="store_true",
                   help="no reference-rate updates during servo turns")
    d.add_argument("--still-window", type=float, default=0.2, metavar="S")
    d.add_argument("--min-still", type=float, default=0.5, metavar="S")
    d.add_argument("--lookahead", type=float, default=0.2, metavar="S")
    d.add_argument("--still-rate-threshold", type=float, default=None, metavar="RAD_S",
                   help="rate gate of the detector about the calibration's bias (default "
                        "the chip's datasheet zero-rate tolerance, 5 deg/s when the chip is not "
                        "known, plus 5 sigma of the white noise: a bias that moved since "
                        "calibration is still seen)")
    d.add_argument("--update-interval", type=float, default=0.25, metavar="S")
    d.add_argument("--causal", action="store_true",
                   help="a recording: the filter's causal estimate at each sample (as live) "
                        "instead of the smoothed one over the whole recording")
    o = p.add_argument_group("output")
    o.add_argument("--json", action="store_true", help="print the per-sample JSON document")
    o.add_argument("--out", metavar="FILE", help="write the JSON document to FILE instead")
    o.add_argument("--every", type=float, default=None, metavar="S",
                   help="one JSON row every S seconds (the estimate at that sample) instead of "
                        f"one per sample; by default a session longer than {JSON_MAX_ROWS:,} "
                        "samples is decimated to at most that many rows, and says so; 0 keeps "
                        "every sample")
    o.add_argument("--force", action="store_true",
                   help="replace existing --out and --plot files (and a --record directory)")
    o.add_argument("--plot", metavar="FILE",
                   help="draw the bias and its 3-sigma band to FILE (PNG; 'plot' extra)")
    o.add_argument("--rows", type=int, default=12, help="rows of the text summary (default 12)")
    live = p.add_argument_group(
        "live on the jig (--live; with --sim the emulated jig)",
        "The servos hold the sensor still with torque on; the IMU FIFO is drained on the\n"
        "jig's clock for --duration seconds and fed to the tracker. A servo that moves between\n"
        "two polls marks its samples as not still. Ctrl-C or an error stops the servos first.")
    live.add_argument("--live", action="store_true",
                      help="track live on the jig (gyrocal.toml: gimbal, imu) instead of a "
                           "recording")
    _add_live_only_arguments(live)


def _add_live_only_arguments(live: Any) -> None:
    """The flags that apply to --live only (an argument group, or a parser)."""
    from gyrocal.kit.commands.calibrate import add_common_jig_arguments

    live.add_argument("--turns", type=int, default=0, metavar="N",
                      help="--live: every --turn-every seconds turn one servo N whole turns and "
                           "back, for reference-rate updates (needs --cal with the servo axes; "
                           "default 0: the jig stays still)")
    live.add_argument("--turn-speed-dps", type=float, default=90.0, metavar="DPS",
                      help="--live --turns: servo speed, degrees/s (default 90)")
    live.add_argument("--turn-every", type=float, default=10.0, metavar="S",
                      help="--live --turns: still time between turn pairs, s (default 10)")
    live.add_argument("--record", metavar="DIR",
                      help="--live (still sessions): also write the session as a Recording v1 "
                           "(one rest), e.g. for `gyrocal noise DIR`")
    add_common_jig_arguments(live, sim_flag=False)


def _live_only_defaults() -> dict[str, Any]:
    """Destination -> default of every flag that applies to --live only (read off the flags
    themselves, so a new jig flag is refused without --live without anyone listing it)."""
    p = argparse.ArgumentParser(add_help=False)
    _add_live_only_arguments(p)
    return vars(p.parse_args([]))



def _settings(args: argparse.Namespace, odr: float, n_density: Any, k: Any,
              axis_std: float | None) -> Any:
    from gyrocal.calib.stationarity import StillSettings
    from gyrocal.calib.tracker import TrackerSettings

    try:
        still = StillSettings(window_s=args.still_window, min_still_s=args.min_still,
                              lookahead_s=args.lookahead,
                              rate_threshold=args.still_rate_threshold)
        kw: dict[str, Any] = dict(
            odr_hz=odr, noise_density=n_density, rate_random_walk=k,
            temperature_model=bool(args.tempco), tempco_std=args.tempco_std,
            update_interval_s=args.update_interval, still=still,
        )
        if axis_std is not None:
            kw["reference_axis_std"] = axis_std
        return TrackerSettings(**kw)
    except ValueError as exc:
        raise InputError(str(exc)) from None


def _chip_and_accel(st: Any, odr: float, chip: str | None, accel: Any, notes: list[str],
                    where: str, accel_lsb: Any = None) -> Any:
    """``st`` with the chip's zero-rate tolerance (:func:`gyrocal.kit.tracking.chip_zero_rate`)
    and the accelerometer's noise (from its quietest seconds,
    :func:`gyrocal.calib.stationarity.quiet_noise_std`, at least the rounding noise
    ``lsb/√12`` of its converter step ``accel_lsb``, m/s²) where they are known."""
    from dataclasses import replace

    import numpy as np

    from gyrocal.calib.stationarity import quiet_noise_std
    from gyrocal.kit.tracking import chip_zero_rate

    tol, note = chip_zero_rate(chip)
    if tol is not None:
        st = replace(st, zero_rate_tolerance=tol)
        if st.still.rate_threshold is None:
            notes.append(str(note))
    if accel is None:
        return st
    whole, piecewise = (accel, {}) if not isinstance(accel, tuple) else (
        None, {"n": accel[0], "read": accel[1]})
    step = (float(accel_lsb) if isinstance(accel_lsb, (int, float)) and accel_lsb > 0
            else 0.0) / math.sqrt(12.0)
    try:
        sigma = np.maximum(quiet_noise_std(whole, max(8, int(round(odr))), **piecewise), step)
    except ValueError:
        if not step:
            notes.append("the accelerometer's readings do not change from sample to sample "
                         "(quantised to silence?): the gyro alone decides when it is still")
            return st
        sigma = np.full(3, step)
    notes.append("the accelerometer vetoes the still detector where it moves (per-sample noise "
                 "from its quietest seconds: " + ", ".join(f"{x:.3g}" for x in sigma)
                 + " m/s^2)")
    return replace(st, accel_noise_std=tuple(float(x) for x in sigma))


def _documents(args: argparse.Namespace) -> tuple[Any, Any]:
    """The ``--cal`` calibration and the ``--noise`` document, read and checked (None where the
    flag is not given)."""
    from gyrocal.kit.tracking import load_calibration, load_noise

    return (load_calibration(args.cal) if args.cal else None,
            load_noise(args.noise) if args.noise else None)


def _build_tracker(
    args: argparse.Namespace, odr: float, rate: Any, notes: list[str], what: str,
    where: str, *, keep_states: bool = False, documents: tuple[Any, Any] | None = None,
    chip: str | None = None, accel: Any = None, accel_lsb: Any = None,
) -> tuple[Any, Any]:
    """The tracker from the flags: calibration, noise model (``rate``, an ``(n, 3)`` array or a
    :class:`gyrocal.kit.tracking.SpilledImu` read a piece at a time, gives the estimates the
    flags leave open: the white noise, and without --cal the first still second's bias).
    ``what`` names the data in notes, ``where`` in errors; ``documents`` are
    :func:`_documents`, when the caller read them already; ``chip`` is the sensor's model
    (its datasheet's zero-rate tolerance widens the detector's rate gate); ``accel`` the
    accelerometer's readings (an ``(n, 3)`` array, m/s², or ``(n, read)``), whose noise sets
    the detector's accelerometer veto (None: the gyro alone decides), ``accel_lsb`` its
    converter step, m/s² (the noise's floor).

    Returns
    -------
    (BiasTracker, GyroCalibration or None)
    """
    from gyrocal.calib.stationarity import first_still_mean, quiet_noise_std
    from gyrocal.calib.tracker import BiasTracker
    from gyrocal.kit.tracking import SpilledImu

    # the readings whole, or n and a reader of rows lo:hi (the same arithmetic)
    spilled = isinstance(rate, SpilledImu)
    whole = None if spilled else rate
    piecewise: dict[str, Any] = {"n": rate.n, "read": rate.rate} if spilled else {}
    cal, noise = _documents(args) if documents is None else documents
    if args.noise_density is not None:
        n_density: Any = args.noise_density
    elif noise is not None:
        n_density = tuple(noise.noise_density.value)
    else:
        try:
            sigma = quiet_noise_std(whole, max(8, int(round(odr))), **piecewise)
        except ValueError as exc:
            raise InputError(f"{where}: {exc}") from None
        n_density = tuple(float(x) for x in sigma / math.sqrt(odr))
        from gyrocal.kit.pipeline import check_plausible_noise

        notes += [f"WARNING: {p}" for p in check_plausible_noise(n_density, allow=True)]
        notes.append("noise density estimated from the sample-to-sample scatter of the "
                     f"quietest seconds of {what}: "
                     + ", ".join(f"{x:.3g}" for x in n_density) + " rad/s/sqrt(Hz) "
                     "(measure it with 'gyrocal noise' and pass --noise)")
    if args.rate_random_walk is not None:
        k: Any = args.rate_random_walk
    elif noise is not None:
        k = noise.rate_random_walk_or_hi95
    else:
        k = None  # estimated from the innovations (see tracker_notes for the result)
    axis_std = None
    if cal is not None and cal.axes:
        stds = [v.get("std_deg") for v in cal.axes.values() if isinstance(v, dict)]
        stds = [s for s in stds if isinstance(s, (int, float)) and math.isfinite(s)]
        if stds:
            axis_std = math.radians(max(stds))
    st = _settings(args, odr, n_density, k, axis_std)
    st = _chip_and_accel(st, odr, chip, accel, notes, where, accel_lsb)
    if cal is not None:
        from dataclasses import replace

        from gyrocal.kit.thermal import tracker_tempco

        prior = tracker_tempco(cal) if st.temperature_model else None
        if prior is not None:  # issue 13: the thermal model seeds the coefficient
            st = replace(st, tempco=prior[0], tempco_std=prior[1])
            notes.append("temperature coefficient seeded from the calibration's thermal model")
        try:
            return BiasTracker(st, cal, initial_bias_std=args.initial_bias_std,
                               keep_states=keep_states), cal
        except ValueError as exc:  # the library names its parameter; say the flag that sets it
            msg = str(exc).replace("pass initial_bias_std", "give --initial-bias-std")
            raise InputError(f"--cal {args.cal}: {msg}") from None
    guess = first_still_mean(whole, st.noise_std, odr, st.still, **piecewise)
    if guess is None:
        raise InputError(f"{where}: no still second found to start from; give --cal")
    b0_std = DEFAULT_INITIAL_BIAS_STD if args.initial_bias_std is None else args.initial_bias_std
    notes.append("no --cal: starting from the first still second's bias "
                 f"({', '.join(f'{-x:.4g}' for x in guess)} rad/s) +- {b0_std:g}")
    try:
        tracker = BiasTracker(st, initial_bias=-guess, initial_bias_std=b0_std,
                              keep_states=keep_states)
    except ValueError as exc:
        raise InputError(str(exc)) from None
    return tracker, None


def _replay(args: argparse.Namespace, notes: list[str]) -> tuple[Any, Any, str]:
    """The tracker and the streamed source of a recording (issue 16: the readings are read
    once into a temporary file and replayed a piece at a time; only the times stay in
    memory). Returns ``(tracker, ReplaySource, name)``; the caller closes the source."""
    import numpy as np

    from gyrocal.calib.timebase import median_step
    from gyrocal.kit.tracking import (
        ReplaySource,
        StillPlan,
        load_calibration,
        open_replay,
        reference_segments,
    )
    from gyrocal.kit.tracking import rest_intervals as rests

    # the encoder gives reference rates, which need a calibration's axes, and the specific
    # force for a calibration's g-sensitivity, which needs the pose at every sample (every
    # encoder reading kept, not only those near the turns)
    g_sens = args.cal is not None and load_calibration(args.cal).g_sensitivity is not None
    imu, rec = open_replay(args.recording, notes,
                           encoder=(args.cal is not None and not args.no_reference) or g_sens,
                           every_encoder=g_sens)
    try:
        n = imu.n
        if n < 2:
            raise InputError(f"{rec.path}: only {n} gyro samples")
        odr = 1.0 / median_step(rec.imu_t)  # a block of steps at a time
        if args.tempco is None:
            args.tempco = imu.temperature_complete
        if args.tempco and not imu.temperature_complete:
            raise InputError(f"{rec.path}: --tempco needs a temperature on every sample "
                             "(imu.csv temp column); this recording lacks some")
        tracker, cal = _build_tracker(
            args, odr, imu, notes, "the recording", str(rec.path), keep_states=not args.causal,
            chip=(rec.manifest.get("sensor") or {}).get("model"),
            accel=(imu.n, imu.accel) if imu.has_accel else None,
            accel_lsb=(rec.manifest.get("sensor") or {}).get("accel_sensitivity_m_s2_per_lsb"))
        still = None
        if args.still == "segments":
            still = StillPlan(rests(rec.imu_t, rec.segments, imu.rate), 0.0)
        elif args.still == "auto" and any(seg.kind == "rest" for seg in rec.segments):
            still = StillPlan(rests(rec.imu_t, rec.segments, imu.rate, check=tracker.detector,
                                    notes=notes), math.nan)
        ref = None
        if not args.no_reference and cal is not None and any(
            s.kind == "rotate" for s in rec.segments
        ):
            ref, more = reference_segments(rec, cal)
            notes += more
            if not ref.runs:
                ref = None
            elif not np.all(np.isfinite(cal.scale_std)):
                notes.append("the calibration has no scale_std: no reference-rate updates")
                ref = None
        gravity = None  # the specific force for the calibration's G (v2 only)
        if cal is not None and cal.g_sensitivity is not None:
            from gyrocal.kit.gravity import force_of

            gravity, why = force_of(rec, cal)
            if why is not None:
                notes.append(f"the calibration's g-sensitivity is NOT applied ({why}, so the "
                             "specific force is unknown): the tracked bias is the zero-g bias "
                             f"plus G f, off by up to {cal.g_rate_error_per_g:.1e} rad/s per g")
    except BaseException:
        imu.close()
        raise
    return tracker, ReplaySource(imu, ref, still, bool(args.tempco), gravity,
                                 accel=tracker.accel_detector is not None), str(rec.path)


def _simulate(args: argparse.Namespace, notes: list[str]) -> tuple[Any, Batch, Any, str]:
    import numpy as np

    from gyrocal.calib.noise_sim import NoiseModel, sim_calibration, simulate_session
    from gyrocal.calib.tracker import BiasTracker
    from gyrocal.kit.tracking import Batch

    model = NoiseModel(rate_random_walk=1e-5)
    if args.tempco is None:
        args.tempco = True
    step = None
    if args.step_at is not None:
        step = (args.step_at, (args.step, 0.0, 0.0))
    try:
        s = simulate_session(np.random.default_rng(args.seed), args.duration, model=model,
                             motion=args.motion, bias_step=step)
        cal = sim_calibration(np.random.default_rng(args.seed + 1), s)
    except ValueError as exc:
        raise InputError(f"--sim: {exc}") from None
    if args.cal:
        notes.append("--cal is ignored with --sim (the simulation makes its own calibration)")
    n_density = args.noise_density if args.noise_density is not None else model.noise_density
    k = args.rate_random_walk if args.rate_random_walk is not None else model.rate_random_walk
    st = _settings(args, s.odr_hz, n_density, k, 1e-5 if args.motion == "jig" else None)
    tracker = BiasTracker(st, cal)
    rr = ra = None
    if args.motion == "jig" and not args.no_reference:
        rr, ra = s.reference_rate, s.reference_axis
    batch = Batch(s.t, s.rate, s.temperature_c if args.tempco else None, None, rr, ra)
    notes.append("synthetic sensor (gyrocal.calib.noise_sim), not the emulated jig: "
                 f"{args.duration:g} s, {args.motion} motions, 10 degC ramp")
    if not args.tempco:
        notes.append("the simulated die warms by 10 degC and its bias follows: without --tempco "
                     "that drift is unmodelled (the NIS alarms may say so)")
    return tracker, batch, s, "simulation"



def _turn_plan(args: argparse.Namespace, cfg: Any) -> TurnPlan | None:
    """The --turns plan, checked against the calibration and the config (None without turns)."""
    import numpy as np

    from gyrocal.kit.tracking import TurnPlan, load_calibration

    if args.turns == 0:
        return None
    if args.turns < 0:
        raise InputError(f"--turns must be a whole number >= 0, got {args.turns}")
    if args.no_reference:
        raise InputError("--turns is for reference-rate updates; drop --no-reference")
    if args.turns > cfg["gimbal"]["max_turns"]:
        raise InputError(f"--turns {args.turns} exceeds gimbal.max_turns "
                         f"{cfg['gimbal']['max_turns']} (the cable-wrap limit)")
    speed_dps, every = args.turn_speed_dps, args.turn_every
    if not (math.isfinite(speed_dps) and speed_dps > 0):
        raise InputError(f"--turn-speed-dps must be a positive number, got {speed_dps!r}")
    if not (math.isfinite(every) and every > 0):
        raise InputError(f"--turn-every must be a positive number of seconds, got {every!r}")
    if not args.cal:
        raise InputError("--turns needs --cal: the reference-rate updates use the calibration's "
                         "scale and servo axes (a paired-axis calibration from 'gyrocal "
                         "calibrate')")
    from gyrocal.kit.report_plots import calibration_axis

    cal = load_calibration(args.cal)
    if not np.all(np.isfinite(cal.scale_std)):
        raise InputError(f"--turns: the calibration {args.cal} has no scale_std")
    axes: dict[int, np.ndarray] = {}
    for sid in cfg["gimbal"]["ids"]:
        u = calibration_axis(cal, int(sid))
        if u is None:
            raise InputError(f"--turns: the calibration {args.cal} has no axis for servo {sid} "
                             "(calibrate with the paired-axis method)")
        axes[int(sid)] = u
    return TurnPlan(int(args.turns), math.radians(speed_dps), float(every), axes)



def _run_live(args: argparse.Namespace, notes: list[str]) -> tuple[Tracked, Any, str]:
    """Hold the jig still, track, release: the servos stop and torque goes off at the end, on
    an error, Ctrl-C or SIGTERM (the gimbal's context), before anything else."""
    from gyrocal.kit.jig import Jig, load_cli_config
    from gyrocal.kit.tracking import (
        LIVE_WARMUP_S,
        LiveSource,
        live_gravity,
        live_truth,
        run_live,
        tracker_notes,
    )

    duration = 60.0 if args.duration is None else float(args.duration)
    if not (math.isfinite(duration) and duration >= LIVE_WARMUP_S):
        raise InputError(f"--duration must be at least {LIVE_WARMUP_S:g} s for --live, "
                         f"got {args.duration!r}")
    cfg = load_cli_config(args)
    period = 1.0 / float(cfg["gimbal"]["sample_hz"])
    plan = _turn_plan(args, cfg)
    if args.record and plan is not None:
        raise InputError("--record writes still sessions: drop --turns (or --record)")
    if args.record:
        rec_path = Path(args.record)
        if rec_path.exists() and not rec_path.is_dir():
            raise OutputExistsError(f"{rec_path} exists and is not a directory; choose another "
                                    "--record")
        if rec_path.is_dir() and any(rec_path.iterdir()) and not args.force:
            raise OutputExistsError(f"{rec_path} already holds files; choose another --record or "
                                    "pass --force")
    documents = _documents(args)  # before the jig opens: a bad file is exit 2, nothing moves
    gravity, g_note = None, ""
    if documents[0] is not None and documents[0].g_sensitivity is not None:
        gravity, g_note = live_gravity(documents[0], cfg["gimbal"]["ids"])
    jig = Jig(cfg, args)
    where = "the emulated jig" if jig.sim is not None else f"the jig on {cfg['gimbal']['port']}"
    if plan is not None and math.degrees(plan.speed) > 0.8 * float(jig.imu.full_scale_dps):
        jig.close()
        raise InputError(f"--turn-speed-dps {args.turn_speed_dps:g} is too close to the gyro's "
                         f"range of {jig.imu.full_scale_dps:g} dps; lower it or raise "
                         "imu.range_dps")
    source = LiveSource(jig, period, temperature=bool(args.tempco),
                        trust_jig=args.still == "segments",
                        turns=plan, gravity=gravity)

    def make_writer() -> Any:
        from gyrocal.kit.recording import RecordingWriter

        truth = None if jig.sim is None else jig.sim.truth_manifest()
        return RecordingWriter(
            args.record, sensor=jig.imu.info.manifest(),
            gimbal={"motors": [{"id": sid, "model": jig.gimbal.infos[sid].model_name,
                                "axis": cfg.axis_of()[sid]}
                               for sid in cfg["gimbal"]["ids"]]},
            protocol={"name": "still", "duration_s": duration}, truth=truth, force=args.force)

    def announce() -> None:
        print(f"gyrocal: tracking live on {where} for {duration:g} s of jig time: the servos "
              "hold the sensor still (torque on); Ctrl-C stops them", file=sys.stderr)

    def build(warm: Batch) -> Any:
        tracker, _ = _build_tracker(args, float(jig.imu.odr_hz), warm.rate, notes,
                                    f"the first {LIVE_WARMUP_S:g} s", where,
                                    documents=documents, chip=jig.imu.info.model,
                                    accel=warm.accel,
                                    accel_lsb=jig.imu.info.accel_sensitivity_m_s2_per_lsb)
        if tracker.applies_g_sensitivity:
            notes.append(g_note)
        built.append(tracker)
        return tracker

    built: list[Any] = []

    tr = run_live(jig, source, duration, build, make_writer=make_writer if args.record else None,
                  announce=announce, where=where)
    notes += source.notes
    if built:
        notes += tracker_notes(built[0])
    if plan is not None:
        notes.append(f"{source.turn_pairs} turn pair(s) of {plan.turns} turn(s) at "
                     f"{args.turn_speed_dps:g} deg/s gave reference-rate updates")
    if source.moved_samples:
        notes.append(f"a servo moved under {source.moved_samples} samples: they were not "
                     "taken as still")
    if source.lost:
        notes.append(f"{source.lost} gyro samples were lost (FIFO overflow): raise "
                     "gimbal.sample_hz or lower imu.odr_hz")
    truth = live_truth(jig, source, tr)
    return tr, truth, f"live on {where}"


def plot_track(tr: Tracked, path: str, truth: Any = None, *, force: bool = False) -> None:
    """Draw the bias estimate of each axis with its 3-sigma band (and the truth of a --sim)."""
    from gyrocal.kit.plots import require_matplotlib, save_png

    plt = require_matplotlib()
    fig, axs = plt.subplots(3, 1, sharex=True, figsize=(9, 7))
    step = max(1, tr.t.size // 20000)
    t = tr.t[::step]
    for i, (ax, name) in enumerate(zip(axs, "xyz", strict=True)):
        b = tr.bias[::step, i]
        sd = tr.bias_std[::step, i]
        ax.fill_between(t, b - 3 * sd, b + 3 * sd, color="C0", alpha=0.25, label="3 sigma")
        ax.plot(t, b, color="C0", lw=1, label="estimate")
        if truth is not None:
            ax.plot(t, truth.true_bias[::step, i], color="k", lw=0.8, label="truth")
        for ta in tr.alarm_t:
            ax.axvline(ta, color="C3", lw=0.8)
        ax.set_ylabel(f"b{name}, rad/s")
        ax.grid(True, alpha=0.3)
    axs[0].legend(loc="upper right", fontsize=8)
    axs[-1].set_xlabel("t, s")
    fig.suptitle("gyro bias (Calibration v1 convention); red lines: NIS alarms")
    save_png(fig, path, force=force)


def _summary_rows(n: int, rows: int) -> np.ndarray:
    """Samples the summary table shows: ``rows`` spread evenly over ``n``."""
    import numpy as np

    return np.unique(np.linspace(0, n - 1, max(2, rows)).round().astype(int))


def _summary(tr: Tracked, rows: int, source: str, truth: Any) -> str:
    import numpy as np

    n = tr.still.size
    want = _summary_rows(n, rows)
    idx = want if tr.rows is None else np.searchsorted(tr.rows, want)
    since_max = tr.since_max if math.isfinite(tr.since_max) else float(tr.since_update_s.max())
    out = [f"gyrocal track: {source}, {n} samples over {tr.t[idx[-1]] - tr.t[idx[0]]:.1f} s; "
           f"{tr.update_t.size} updates "
           f"({np.count_nonzero(tr.update_kind == 'still')} zero-rate, "
           f"{np.count_nonzero(tr.update_kind == 'reference')} reference-rate), "
           f"still {100 * tr.still.mean():.1f} % of samples",
           f"health: {tr.alarm_t.size} NIS alarm(s)"
           + (f" at t = {', '.join(f'{x:.1f}' for x in tr.alarm_t[:5])} s" if tr.alarm_t.size
              else "")
           + f"; {tr.shift_t.size} bias shift(s) found by the CUSUM test"
           + (f" at t = {', '.join(f'{x:.1f}' for x in tr.shift_t[:5])} s" if tr.shift_t.size
              else "")
           + f"; longest time without an update {since_max:.1f} s",
           f"{'t s':>9}  {'bias x':>11} {'bias y':>11} {'bias z':>11}   "
           f"{'std x':>9} {'std y':>9} {'std z':>9}  (rad/s, Calibration v1 sign)"]
    for i in idx:
        b, s = tr.bias[i], tr.bias_std[i]
        out.append(f"{tr.t[i]:9.2f}  {b[0]:11.4e} {b[1]:11.4e} {b[2]:11.4e}   "
                   f"{s[0]:9.2e} {s[1]:9.2e} {s[2]:9.2e}")
    if truth is not None:
        err = tr.bias - truth.true_bias
        rms = np.sqrt(np.mean(err**2, axis=0))
        inside = np.mean(np.abs(err) <= 3 * tr.bias_std, axis=0)
        out.append("vs truth: RMS error " + ", ".join(f"{x:.2e}" for x in rms)
                   + " rad/s; inside 3 sigma " + ", ".join(f"{100 * x:.2f} %" for x in inside))
    return "\n".join(out)


def _check_modes(args: argparse.Namespace) -> None:
    """One source (RECORDING, --sim or --live) and only the flags that apply to it; fills in
    the defaults that depend on the mode."""
    if args.causal and args.recording is None:
        raise InputError("--causal applies to a recording (live and --sim are causal already)")
    if args.live:
        if args.recording is not None:
            raise InputError("give a RECORDING or --live, not both")
        for flag, value in (("--seed", args.seed), ("--motion", args.motion),
                            ("--step-at", args.step_at)):
            if value is not None:
                raise InputError(f"{flag} applies to the synthetic session (--sim without "
                                 "--live); the emulated jig takes --sim-seed, --sim-scale, "
                                 "--sim-bias")
        return
    if args.sim == (args.recording is not None):
        raise InputError("give a RECORDING or --sim (a synthetic session), or --live to track "
                         "on the jig (--live --sim: the emulated jig)")
    given = [name for name, default in _live_only_defaults().items()
             if getattr(args, name) != default]
    if given:
        flags = ", ".join("--" + g.replace("_", "-") for g in given)
        raise InputError(f"{flags} applies to --live only")
    if args.sim:
        args.duration = 1800.0 if args.duration is None else args.duration
        args.seed = 0 if args.seed is None else args.seed
        args.motion = "random" if args.motion is None else args.motion
    else:
        for flag, value in (("--duration", args.duration), ("--seed", args.seed),
                            ("--motion", args.motion), ("--step-at", args.step_at)):
            if value is not None:
                raise InputError(f"{flag} applies to --sim or --live, not to a recording")


def _kept_rows(args: argparse.Namespace, t: np.ndarray) -> tuple[Any, Any]:
    """The samples a replay must keep estimates for: those the JSON document and the summary
    show (every sample for --plot). Returns (rows or None, json_rows' answer or None)."""
    import numpy as np

    from gyrocal.kit.tracking import json_rows

    if args.plot:
        return None, None
    parts = []
    sel = None
    if args.json or args.out:
        sel = json_rows(t, args.every, JSON_MAX_ROWS if args.every is None else None)
        parts.append(sel[0])
    if not args.json:
        parts.append(_summary_rows(t.size, args.rows))
    return np.unique(np.concatenate(parts)), sel


def run(args: argparse.Namespace) -> int:
    """Build the tracker and its source, run, report."""
    import numpy as np

    from gyrocal.kit.fileio import emit_text, refuse_existing
    from gyrocal.kit.tracking import (
        chunks,
        json_pieces,
        json_rows,
        run_tracker,
        smooth_tracked,
        tracker_notes,
    )

    _check_modes(args)
    if args.rows < 2:
        raise InputError("--rows must be at least 2")
    if args.every is not None and not (math.isfinite(args.every) and args.every >= 0):
        raise InputError(f"--every must be a number of seconds >= 0, got {args.every!r}")
    refuse_existing((args.out, args.plot), force=args.force)  # before a long (or live) run
    notes: list[str] = []
    json_sel = None
    if args.live:
        tr, truth, source = _run_live(args, notes)
    elif args.sim:
        tracker, batch, truth, source = _simulate(args, notes)
        # fed one second at a time, as a live source would
        batches: Iterable[Batch] = chunks(batch, max(1, int(round(tracker.settings.odr_hz))))
        tr = run_tracker(tracker, batches)
        notes += tracker_notes(tracker)
    else:
        tracker, replay, source = _replay(args, notes)
        truth = None
        with replay:
            keep, json_sel = _kept_rows(args, replay.t)
            # in pieces: the tracker's working arrays stay a piece long (the estimates are the
            # same however the samples are cut, to rounding), the readings read back from the
            # temporary file, the reference rates and still flags made per piece
            tr = run_tracker(tracker, replay.batches(REPLAY_CHUNK, keep), rows=keep)
            kept_temperature = replay.kept_temperature()
        # the replay's times (8 bytes a sample) and encoder readings go before the smoother's
        # working arrays come: the rows kept are all that is shown
        del replay
        if not args.causal:
            tr = smooth_tracked(tracker, tr, kept_temperature, at_rows=True)
        del kept_temperature
        notes += tracker_notes(tracker)
    for note in notes:
        print(f"gyrocal: note: {note}", file=sys.stderr)
    if args.plot:
        plot_track(tr, args.plot, truth, force=args.force)
        print(f"wrote {args.plot}", file=sys.stderr)
    if args.json or args.out:
        if json_sel is None:
            json_sel = json_rows(tr.t, args.every, JSON_MAX_ROWS if args.every is None else None)
        rows, every = json_sel
        at = rows if tr.rows is None else np.searchsorted(tr.rows, rows)
        if every is not None:
            print(f"gyrocal: note: the JSON document is decimated to one row every {every:g} s "
                  f"({rows.size} of {tr.still.size} samples; each row the estimate at that sample, "
                  "still true if any sample since the previous row was); --every sets the "
                  "interval, --every 0 keeps every sample", file=sys.stderr)
        still = np.logical_or.reduceat(tr.still, np.concatenate([[0], rows[:-1] + 1])) \
            if every is not None else tr.still
        doc: dict[str, Any] = {
            "t": lambda: tr.t[at],
            "bias": lambda: tr.bias[at],
            "bias_std": lambda: tr.bias_std[at],
            "still": lambda: still,
        }
        if every is not None:
            doc["decimated_every_s"] = lambda: every
        if tr.bias_moved is not None:  # the first rest found the calibration's bias stale
            doc["bias_moved"] = tr.bias_moved.as_dict
        # written in pieces: the Python objects of a few thousand rows at a time
        emit_text(json_pieces(doc), args.out, force=args.force)
    if not args.json:
        print(_summary(tr, args.rows, source, truth))
    return 0

