"""A real consumer-grade MEMS gyro's recording with rests, for the bias tracker's benchmark.

Source: BROAD, the Berlin Robust Orientation Estimation Assessment Dataset (D. Laidig,
M. Caruso, A. Cereatti, T. Seel, "BROAD - A Benchmark for Robust Inertial Orientation
Estimation", Data 6(7), 2021), Creative Commons Attribution 4.0 International. Each trial is
about three minutes of one myon aktos-t wearable IMU at 285.71 Hz (``imu_gyr`` in rad/s), with
about 30 s of rest at the start and at the end and, in the "with breaks" trials, three breaks
of 10 s between hand-held motions; an optical motion-capture system (eight OptiTrack Flex13
cameras) gives the IMU's orientation (``opt_quat``) on the same clock. See
``bench/data/README.md`` for what is kept and why the excerpt is not in the repository.

The excerpt keeps, per trial, the gyro readings (integers of 10 µrad/s: the rounding,
2.9 µrad/s RMS, is under a five-hundredth of the white noise's 1.7e-3 rad/s per sample) and
a *reference stillness* flag computed from the optical orientation alone, so it shares nothing
with the gyro or with :mod:`gyrocal.calib.stationarity`: the angle the optical orientation turns
over :data:`STILL_SPAN_S` is taken at every sample, and a sample is still when the median of that
angle over the :data:`MEDIAN_S` around it is under :data:`STILL_DEG` with no optical sample
missing there (the median: the optical orientation jumps by about 0.2 degrees for a few samples
about once a second while the gyro, integrated, turns by 0.01 degrees); each still stretch so
found is trimmed by :data:`TRIM_S` at both ends and kept when at least :data:`MIN_REST_S`
long.

Usage::

    python -m bench.real_gyro BROAD_DATA_MAT_DIR OUT.csv.xz   # write the excerpt

(an xz-compressed CSV, :data:`HEADER`: one row per sample, in time order within each trial,
sample ``k`` of a trial at ``k / FS_HZ`` s; xz rather than gzip keeps six trials near 1.6 MB)
and :func:`load` reads it back. The file is looked for at ``$GYROCAL_REAL_GYRO`` when that is
set (there only), else in ``bench/data/``, then ``shared/data/`` beside the repository or beside
one of its two parent folders (a work tree kept in a folder of work trees).
"""

from __future__ import annotations

import lzma
import math
import os
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

#: The trials kept (BROAD's names): the four "with breaks" trials that the repository's
#: snapshot holds, a stationary-magnet trial (medium-speed motion with breaks; the magnet
#: only disturbs the magnetometer) and one without breaks (rests at the start and the end
#: only: the bias carried through two minutes of motion).
TRIALS = (
    "05_undisturbed_slow_rotation_with_breaks_B",
    "09_undisturbed_fast_rotation_with_breaks_B",
    "14_undisturbed_slow_translation_with_breaks_B",
    "18_undisturbed_fast_translation_with_breaks_B",
    "30_disturbed_stationary_magnet_C",
    "02_undisturbed_slow_rotation_B",
)

#: BROAD's sampling rate, Hz (``sampling_rate`` of every trial: 2000/7).
FS_HZ = 2000.0 / 7.0
#: Reference stillness: the optical orientation turns by less than this, degrees ...
STILL_DEG = 0.1
#: ... over this span centred on the sample, s.
STILL_SPAN_S = 0.5
#: The median of that angle is taken over this span, s.
MEDIAN_S = 1.0
#: Each still stretch loses this much at each end, s (settling after a motion, and the
#: median's reach).
TRIM_S = 1.0
#: Shortest reference rest kept, s.
MIN_REST_S = 2.0

FILE_NAME = "broad-gyro-rests.csv.xz"
#: The readings' unit in the file, rad/s.
UNIT_RAD_S = 1e-5
HEADER = "trial,gx_1e-5rad_s,gy_1e-5rad_s,gz_1e-5rad_s,still_ref"


@dataclass(frozen=True, eq=False)
class Trial:
    """One trial of the excerpt: sample ``k`` is at ``t[k] = k / odr_hz`` (s)."""

    name: str
    odr_hz: float
    t: np.ndarray
    rate: np.ndarray  # (n, 3) rad/s
    still_ref: np.ndarray  # (n,) bool: the optical reference's rests

    def rests(self) -> list[tuple[int, int]]:
        """The reference rests as ``[start, stop)`` sample ranges."""
        d = np.diff(np.r_[0, self.still_ref.astype(np.int8), 0])
        return list(zip(np.flatnonzero(d == 1).tolist(), np.flatnonzero(d == -1).tolist(),
                        strict=True))


def optical_still(quat: np.ndarray, fs: float) -> np.ndarray:
    """The reference stillness of one trial from its optical orientation (module docstring).

    Parameters
    ----------
    quat : (n, 4) array
        Unit quaternions (NaN where the markers were lost).
    fs : float
        Sampling rate, Hz.
    """
    from numpy.lib.stride_tricks import sliding_window_view

    n = quat.shape[0]
    half = int(round(STILL_SPAN_S * fs / 2))
    mh = int(round(MEDIAN_S * fs / 2))
    turn = np.full(n, np.inf)
    a, b = quat[: n - 2 * half], quat[2 * half:]
    with np.errstate(invalid="ignore"):
        turn[half: n - half] = 2.0 * np.degrees(
            np.arccos(np.clip(np.abs(np.sum(a * b, axis=1)), 0.0, 1.0)))
    turn[~np.isfinite(turn)] = np.inf  # a missing optical sample at either end
    ok = np.zeros(n, dtype=bool)
    # the median of the angle around each sample; inf (missing) anywhere in reach: not still
    win = sliding_window_view(turn, 2 * mh + 1)
    ok[mh: n - mh] = (np.median(win, axis=1) < STILL_DEG) & np.isfinite(win).all(axis=1)
    return trimmed(ok, fs)


def trimmed(still: np.ndarray, fs: float) -> np.ndarray:
    """``still`` with each stretch of still samples shortened by :data:`TRIM_S` at both ends
    and dropped when then shorter than :data:`MIN_REST_S` (``fs``: sampling rate, Hz)."""
    out = np.zeros(still.size, dtype=bool)
    trim = int(round(TRIM_S * fs))
    d = np.diff(np.r_[0, still.astype(np.int8), 0])
    for lo, hi in zip(np.flatnonzero(d == 1), np.flatnonzero(d == -1), strict=True):
        lo, hi = lo + trim, hi - trim
        if hi - lo >= MIN_REST_S * fs:
            out[lo:hi] = True
    return out


def convert(src: Path, out: Path, preset: int = 9 | lzma.PRESET_EXTREME) -> None:
    """Write the excerpt of the BROAD trials in :data:`TRIALS` (``src``: BROAD's ``data_mat``
    folder) to ``out`` (xz CSV, :data:`HEADER`; ``preset``: the xz level, the strongest by
    default). Refuses to overwrite ``out``."""
    from scipy.io import loadmat
    from scipy.io.matlab import MatReadError

    from gyrocal.kit.fileio import atomic_write_bytes

    if out.exists():
        raise FileExistsError(f"{out} exists; remove it first")
    if not out.parent.is_dir():
        raise FileNotFoundError(f"{out.parent} is not a folder: create it first, or write the "
                                "excerpt elsewhere")
    missing = [f"{n}.mat" for n in TRIALS if not (src / f"{n}.mat").is_file()]
    if missing:
        raise FileNotFoundError(f"{src} lacks {', '.join(missing)}: give BROAD's data_mat "
                                "folder (bench/data/README.md)")
    lines = [HEADER]
    for name in TRIALS:
        try:
            m = loadmat(src / f"{name}.mat")
        except MatReadError as exc:
            raise ValueError(f"{src / name}.mat is not a MATLAB file ({exc}): give BROAD's "
                             "data_mat folder (bench/data/README.md)") from None
        lack = [k for k in ("sampling_rate", "imu_gyr", "opt_quat") if k not in m]
        if lack:
            raise ValueError(f"{src / name}.mat has no {', '.join(lack)}: not a BROAD trial "
                             "(bench/data/README.md)")
        fs = float(m["sampling_rate"][0, 0])
        if not math.isclose(fs, FS_HZ, rel_tol=1e-9):
            raise ValueError(f"{name}: sampling rate {fs} Hz, expected {FS_HZ}")
        gyr = np.rint(np.asarray(m["imu_gyr"], dtype=float) / UNIT_RAD_S).astype(np.int64)
        still = optical_still(np.asarray(m["opt_quat"], dtype=float), fs)
        cols = [gyr[:, 0].astype(str), gyr[:, 1].astype(str), gyr[:, 2].astype(str),
                still.astype(np.int8).astype(str)]
        lines += [f"{name},{a},{b},{c},{d}" for a, b, c, d in zip(*cols, strict=True)]
    text = "\n".join(lines) + "\n"
    atomic_write_bytes(out, lzma.compress(text.encode("ascii"), preset=preset))


def locate() -> Path | None:
    """The excerpt's path, or None when it is nowhere it is looked for (module docstring)."""
    env = os.environ.get("GYROCAL_REAL_GYRO")
    if env:  # the one place when given: a wrong path is not quietly replaced by another file
        return Path(env) if Path(env).is_file() else None
    repo = Path(__file__).resolve().parent.parent
    places = [repo / "bench" / "data" / FILE_NAME]
    places += [up / "shared" / "data" / FILE_NAME for up in repo.parents[:3]]
    return next((p for p in places if p.is_file()), None)


def load(path: Path | None = None) -> list[Trial]:
    """The trials of the excerpt, in file order.

    Raises
    ------
    FileNotFoundError
        No excerpt was given or found (the message says how to make one).
    ValueError
        The file is not the excerpt: not xz, cut short, or not its header or columns.
    """
    path = path or locate()
    if path is None:
        env = os.environ.get("GYROCAL_REAL_GYRO")
        raise FileNotFoundError(
            (f"GYROCAL_REAL_GYRO={env} is not a file; " if env else f"no {FILE_NAME}: ")
            + f"build it with `python -m bench.real_gyro BROAD/data_mat bench/data/{FILE_NAME}` "
            "from a copy of BROAD (bench/data/README.md), or point GYROCAL_REAL_GYRO at it")
    try:
        with lzma.open(path, "rt", encoding="ascii") as fh:
            head = fh.readline().strip()
            if head != HEADER:
                raise ValueError(f"header {head!r}, expected {HEADER!r}")
            rows = fh.read().split()
        if not rows:
            raise ValueError("no samples after the header")
        names = np.array([r.split(",", 1)[0] for r in rows])
        nums = np.array([r.split(",")[1:] for r in rows], dtype=np.int64).reshape(-1, 4)
    except (lzma.LZMAError, EOFError, UnicodeDecodeError, ValueError) as exc:
        raise ValueError(f"{path} is not the excerpt ({exc}): rebuild it with `python -m "
                         "bench.real_gyro` (bench/data/README.md)") from None
    trials = []
    cut = np.flatnonzero(names[1:] != names[:-1]) + 1
    for lo, hi in zip(np.r_[0, cut], np.r_[cut, names.size], strict=True):
        trials.append(Trial(str(names[lo]), FS_HZ, np.arange(hi - lo) / FS_HZ,
                            nums[lo:hi, :3] * UNIT_RAD_S, nums[lo:hi, 3] == 1))
    return trials


# ------------------------------------------------------------------ held-out reference biases
#: Length of the held-out blocks of still readings whose mean is the reference bias, s.
BLOCK_S = 2.0


def blocks(trial: Trial, block_s: float = BLOCK_S) -> np.ndarray:
    """The reference rests of ``trial`` cut into whole blocks of ``block_s`` (a remainder under
    one block is left out): ``(nb, 3)`` int array of ``[start, stop)`` sample ranges and the
    rest's number."""
    w = int(round(block_s * trial.odr_hz))
    out = [(lo + j * w, lo + (j + 1) * w, r)
           for r, (lo, hi) in enumerate(trial.rests()) for j in range((hi - lo) // w)]
    return np.array(out, dtype=np.int64).reshape(-1, 3)


def reference_bias(trial: Trial, blk: np.ndarray) -> np.ndarray:
    """The reference bias of each block: minus the mean of its readings (a still sensor reads
    ``-bias`` in the Calibration v1 convention), ``(nb, 3)`` rad/s."""
    return np.array([-trial.rate[a:b].mean(axis=0) for a, b, _ in blk]).reshape(-1, 3)


#: The white noise is measured at this averaging time, s (see :func:`reference_variance`).
WHITE_TAU_S = 0.25


def reference_variance(trials: list[Trial], blks: list[np.ndarray]) -> np.ndarray:
    """The variance of one block's reference about the bias it stands for, per axis (rad/s)²:
    ``N² / block_s``, the white noise of density ``N`` averaged over the block. ``N²`` is the
    Allan variance at :data:`WHITE_TAU_S` times that time (``σ²(τ) = N²/τ`` for white noise),
    from the differences of consecutive 0.25-s means inside each block, pooled over the blocks
    of all trials: long enough that the noise's correlation from sample to sample (the sensor's
    low-pass filter) has died out, short enough that the bias's own drift (``σ²(τ)`` grows as
    ``K² τ / 3`` for a random walk ``K``) does not count, as it would in the Allan variance at
    the block length itself."""
    d2, tau, block_s = [], 0.0, 0.0
    for tr, blk in zip(trials, blks, strict=True):
        m = int(round(WHITE_TAU_S * tr.odr_hz))
        for a, b, _ in blk:
            k = (b - a) // m
            means = tr.rate[a:a + k * m].reshape(k, m, 3).mean(axis=1)
            d2.append(np.diff(means, axis=0) ** 2)
            tau, block_s = m / tr.odr_hz, (b - a) / tr.odr_hz
    if not d2:
        raise ValueError("no blocks")
    avar = 0.5 * np.concatenate(d2).mean(axis=0)
    return avar * tau / block_s


def leave_one_out_bias(trials: list[Trial], i: int) -> tuple[np.ndarray, np.ndarray]:
    """An earlier calibration's bias and its spread for trial ``i``, from the *other* trials
    only (the same sensor, the same day): the mean over them of each one's first reference
    rest's bias, and the standard deviation of those (rad/s, per axis)."""
    firsts = []
    for j, tr in enumerate(trials):
        rests = tr.rests() if j != i else []
        if rests:
            lo, hi = rests[0]
            firsts.append(-tr.rate[lo:hi].mean(axis=0))
    if len(firsts) < 2:
        raise ValueError("need two other trials with a rest")
    f = np.array(firsts)
    return f.mean(axis=0), f.std(axis=0, ddof=1)


if __name__ == "__main__":
    if len(sys.argv) != 3:
        print("usage: python -m bench.real_gyro BROAD_DATA_MAT_DIR OUT.csv.xz", file=sys.stderr)
        sys.exit(2)
    try:
        convert(Path(sys.argv[1]), Path(sys.argv[2]))
    except (OSError, ValueError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        sys.exit(2)
