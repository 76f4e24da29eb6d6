"""A corpus of real IMU recordings beside BROAD (bench/real_gyro.py): converters and readers.

Three public data sets of real sensors, each cut down by a converter here to one xz-compressed
CSV whose bytes the converter reproduces exactly from the source files (``bench/data/README.md``
gives each source's repository, commit, licence and sha256, input and output):

``imutk``
    imu_tk's Xsens test session (``bin/test_data/xsens_acc.mat``, ``xsens_gyro.mat`` of
    imu_tk, BSD licence): 512 s at 100 Hz of an Xsens IMU's raw 16-bit accelerometer and gyro
    readings (the files' names; the repository does not name the model), a 50 s rest then 38
    hand-placed static poses, the example of imu_tk's multi-position calibration (Tedaldi,
    Pretto, Menegatti, ICRA 2014).
``imucal``
    imucal's Ferraris session (``example_data/example_ferraris_session.csv`` and
    ``example_ferraris_session_list.json`` of mad-lab-fau/imucal, MIT licence): 101 s at
    102.4 Hz of a wearable IMU laid on its six faces and turned about each axis, with the
    sections imucal's example labels.
``fusion``
    x-io Technologies' Fusion sample (``Examples/Python/sensor_data.csv`` of
    xioTechnologies/Fusion, MIT licence): 135 s at 100 Hz of a real IMU (the repository does
    not name it), gyro in °/s and accelerometer in g, still for 12 s at the start and 17 s at
    the end; the magnetometer is left out.

Usage::

    python -m bench.real_corpus NAME SOURCE... OUT.csv.xz     # write one excerpt
    python -m bench.real_corpus recording imucal OUT_DIR      # imucal's session as a recording

The second writes imucal's Ferraris session (from its excerpt) as a Recording v1 directory of
the hand jig (:func:`write_recording`: manifest ``jig.kind`` ``hand``, no encoder, no
segments), which ``gyrocal estimate OUT_DIR`` reads: the rests and the three turns are found in
the data (:mod:`gyrocal.calib.hand`). :func:`imucal_ferraris_gyro` is imucal's own gyro
calibration of the session, its equations modelled from its source, to set beside gyrocal's.

and :func:`load` reads one back as a :class:`Session` in SI units. A file is looked for at
``$GYROCAL_REAL_DATA/<file>`` when that variable is set (there only), else in ``bench/data/``,
then ``shared/data/`` beside the repository or beside one of its two parent folders, as
``bench/real_gyro.py`` looks for BROAD's excerpt.
"""

from __future__ import annotations

import json
import lzma
import os
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

#: imu_tk's gravity magnitude for this session, m/s² (``apps/test_imu_calib.cpp``:
#: ``mp_calib.setGravityMagnitude(9.81744)``).
IMUTK_GRAVITY = 9.81744
#: imu_tk's initial guesses for the raw counts (same file): accelerometer and gyro bias 32768
#: counts, gyro scale 1/6258 rad/s per count.
IMUTK_OFFSET = 32768.0
IMUTK_GYRO_SCALE = 1.0 / 6258.0
#: imu_tk's static-interval detector (``src/filters.cpp`` ``staticIntervalsDetector``: window
#: of 101 samples, threshold a multiple of the variance norm of the initial rest;
#: ``src/calibration.cpp`` ``calibrateAcc``: initial rest 50 s in ``test_imu_calib.cpp``,
#: intervals of at least 100 samples kept, multipliers 2..10 tried).
IMUTK_WINDOW = 101
IMUTK_INIT_S = 50.0
IMUTK_MIN_SAMPLES = 100

#: imucal's Ferraris session: sampling rate, Hz (``examples/basic_ferraris.py``:
#: ``sampling_rate_hz=102.4``), and the readings' steps: every accelerometer value is a whole
#: multiple of 9.81/2048 m/s² and every gyro value of 2000/32768 °/s (checked by the converter).
IMUCAL_FS_HZ = 102.4
IMUCAL_ACC_LSB = 9.81 / 2048.0
IMUCAL_GYR_LSB = 2000.0 / 32768.0

#: Standard gravity, m/s², for the Fusion sample's accelerometer in g (its header:
#: ``Accelerometer X (g)``).
G_N = 9.80665

FILES = {"imutk": "imutk-xsens.csv.xz", "imucal": "imucal-ferraris.csv.xz",
         "fusion": "fusion-sample.csv.xz"}
HEADERS = {
    "imutk": "t_us,ax,ay,az,gx,gy,gz",
    "imucal": "sample,section,ax_lsb,ay_lsb,az_lsb,gx_lsb,gy_lsb,gz_lsb",
    "fusion": "t_s,gx_dps,gy_dps,gz_dps,ax_g,ay_g,az_g",
}
#: The source files each converter takes, in order.
SOURCES = {
    "imutk": ("xsens_acc.mat", "xsens_gyro.mat"),
    "imucal": ("example_ferraris_session.csv", "example_ferraris_session_list.json"),
    "fusion": ("sensor_data.csv",),
}


@dataclass(frozen=True, eq=False)
class Session:
    """One real recording in SI units.

    Attributes
    ----------
    name : str
        ``imutk``, ``imucal`` or ``fusion``.
    t : (n,) ndarray
        Sample times, s.
    gyro : (n, 3) ndarray
        rad/s (imu_tk: its initial scale guess, 1/6258 rad/s per count, bias not removed).
    accel : (n, 3) ndarray
        m/s² (imu_tk: counts less 32768 times :attr:`accel_scale`, a nominal scale).
    accel_scale : float
        m/s² per count the accelerometer was given (1 where the source is in SI units).
    gravity : float
        The local gravity the source's own calibration used, m/s².
    sections : tuple of (str, int, int)
        Labelled sample ranges ``[start, stop)`` (imucal's), empty elsewhere.
    """

    name: str
    t: np.ndarray
    gyro: np.ndarray
    accel: np.ndarray
    accel_scale: float
    gravity: float
    sections: tuple[tuple[str, int, int], ...] = ()

    @property
    def odr_hz(self) -> float:
        """The median sampling rate, Hz."""
        return float(1.0 / np.median(np.diff(self.t)))


# ------------------------------------------------------------------------------ converters
def _whole(values: np.ndarray, step: float, what: str) -> np.ndarray:
    """``values / step`` as integers, refusing values that are not whole multiples."""
    k = np.rint(values / step)
    if not np.all(np.abs(values - k * step) <= 1e-9 * np.maximum(1.0, np.abs(values))):
        raise ValueError(f"{what} holds values that are not whole multiples of {step!r}")
    return k.astype(np.int64)


def _imutk_text(src: list[Path]) -> str:
    acc, gyr = (np.loadtxt(p, ndmin=2) for p in src)
    if acc.shape[1] != 4 or gyr.shape != acc.shape or not np.array_equal(acc[:, 0], gyr[:, 0]):
        raise ValueError("xsens_acc.mat and xsens_gyro.mat must be imu_tk's two 4-column "
                         "files (time, x, y, z) on the same time stamps")
    t_us = _whole(acc[:, 0], 1e-6, "the time column")
    counts = _whole(np.hstack([acc[:, 1:], gyr[:, 1:]]), 1.0, "the readings")
    rows = np.column_stack([t_us, counts]).astype(str)
    return "\n".join([HEADERS["imutk"]] + [",".join(r) for r in rows]) + "\n"


def _imucal_text(src: list[Path]) -> str:
    data = np.genfromtxt(src[0], delimiter=",", names=True)
    want = ("n_samples", "gyr_x", "gyr_y", "gyr_z", "acc_x", "acc_y", "acc_z")
    if data.dtype.names != want:
        raise ValueError(f"{src[0]} must have the columns {want}, got {data.dtype.names}")
    sections = json.loads(src[1].read_text())
    label = np.full(data.size, "", dtype=object)
    for name, span in sections.items():
        label[int(span["start"]):int(span["end"])] = name
    acc = _whole(np.column_stack([data[c] for c in want[4:]]), IMUCAL_ACC_LSB, "acc")
    gyr = _whole(np.column_stack([data[c] for c in want[1:4]]), IMUCAL_GYR_LSB, "gyr")
    lines = [HEADERS["imucal"]]
    for k in range(data.size):
        lines.append(f"{int(data['n_samples'][k])},{label[k]},"
                     + ",".join(map(str, acc[k])) + "," + ",".join(map(str, gyr[k])))
    return "\n".join(lines) + "\n"


def _fusion_text(src: list[Path]) -> str:
    lines = src[0].read_text().splitlines()
    if not lines or not lines[0].startswith("Time (s),Gyroscope X (deg/s)"):
        raise ValueError(f"{src[0]} is not Fusion's sensor_data.csv (its header differs)")
    return "\n".join([HEADERS["fusion"]] + [",".join(r.split(",")[:7]) for r in lines[1:]]) + "\n"


_TEXT = {"imutk": _imutk_text, "imucal": _imucal_text, "fusion": _fusion_text}


def convert(name: str, src: list[Path], out: Path, preset: int = 9 | lzma.PRESET_EXTREME) -> None:
    """Write the excerpt ``name`` from its :data:`SOURCES` files ``src`` to ``out`` (xz CSV of
    :data:`HEADERS`); refuses to overwrite ``out``."""
    from gyrocal.kit.fileio import atomic_write_bytes

    if name not in _TEXT:
        raise ValueError(f"unknown data set {name!r}; one of {', '.join(_TEXT)}")
    if len(src) != len(SOURCES[name]) or not all(p.is_file() for p in src):
        raise FileNotFoundError(f"{name} needs the files {', '.join(SOURCES[name])} of its "
                                "source (bench/data/README.md)")
    if out.exists():
        raise FileExistsError(f"{out} exists; remove it first")
    text = _TEXT[name](src)
    atomic_write_bytes(out, lzma.compress(text.encode("ascii"), preset=preset))


# ------------------------------------------------------------------------------ readers
def locate(name: str) -> Path | None:
    """The excerpt's path, or None when it is nowhere it is looked for (module docstring)."""
    env = os.environ.get("GYROCAL_REAL_DATA")
    if env:  # the one place when given
        p = Path(env) / FILES[name]
        return p if p.is_file() else None
    repo = Path(__file__).resolve().parent.parent
    places = [repo / "bench" / "data" / FILES[name]]
    places += [up / "shared" / "data" / FILES[name] for up in repo.parents[:3]]
    return next((p for p in places if p.is_file()), None)


def missing_reason(name: str) -> str:
    """What to do when :func:`locate` finds nothing (the tests' skip reason)."""
    return (f"no {FILES[name]}: build it with `python -m bench.real_corpus {name} "
            f"{' '.join(SOURCES[name])} {FILES[name]}` from its source (bench/data/README.md) "
            "and put it in shared/data/ beside the repository, or set GYROCAL_REAL_DATA")


def _rows(path: Path, name: str) -> list[list[str]]:
    try:
        with lzma.open(path, "rt", encoding="ascii") as fh:
            head = fh.readline().strip()
            if head != HEADERS[name]:
                raise ValueError(f"header {head!r}, expected {HEADERS[name]!r}")
            rows = [r.split(",") for r in fh.read().split()]
    except (lzma.LZMAError, EOFError, UnicodeDecodeError, ValueError) as exc:
        raise ValueError(f"{path} is not the {name} excerpt ({exc}): rebuild it with "
                         "`python -m bench.real_corpus` (bench/data/README.md)") from None
    if not rows or any(len(r) != 7 and len(r) != 8 for r in rows):
        raise ValueError(f"{path} is not the {name} excerpt (rows of the wrong length)")
    return rows


def load(name: str, path: Path | None = None) -> Session:
    """The excerpt ``name`` as a :class:`Session`.

    Raises
    ------
    FileNotFoundError
        Not given and not found (the message says how to make it).
    ValueError
        The file is not that excerpt.
    """
    if name not in FILES:
        raise ValueError(f"unknown data set {name!r}; one of {', '.join(FILES)}")
    path = path or locate(name)
    if path is None:
        raise FileNotFoundError(missing_reason(name))
    rows = _rows(path, name)
    if name == "imucal":
        nums = np.array([[r[0]] + r[2:] for r in rows], dtype=float)
        labels = np.array([r[1] for r in rows])
        cut = np.flatnonzero(labels[1:] != labels[:-1]) + 1
        sections = tuple((str(labels[lo]), int(lo), int(hi))
                         for lo, hi in zip(np.r_[0, cut], np.r_[cut, labels.size], strict=True)
                         if labels[lo])
        return Session(name, nums[:, 0] / IMUCAL_FS_HZ,
                       np.radians(nums[:, 4:7] * IMUCAL_GYR_LSB), nums[:, 1:4] * IMUCAL_ACC_LSB,
                       1.0, 9.81, sections)
    nums = np.array(rows, dtype=float)
    if name == "fusion":
        return Session(name, nums[:, 0], np.radians(nums[:, 1:4]), nums[:, 4:7] * G_N, 1.0, G_N)
    t = nums[:, 0] * 1e-6
    acc = nums[:, 1:4] - IMUTK_OFFSET
    init = t < t[0] + IMUTK_INIT_S
    scale = IMUTK_GRAVITY / float(np.linalg.norm(acc[init].mean(axis=0)))
    return Session(name, t, (nums[:, 4:7] - IMUTK_OFFSET) * IMUTK_GYRO_SCALE, acc * scale,
                   scale, IMUTK_GRAVITY)


def imutk_static_intervals(accel: np.ndarray, t: np.ndarray, multiplier: int = 6
                           ) -> list[tuple[int, int]]:
    """imu_tk's static intervals ``[start, stop)`` of an accelerometer recording.

    A port of imu_tk's ``staticIntervalsDetector`` (``src/filters.cpp``): a sample is static
    when the norm of the per-axis sample variance over the :data:`IMUTK_WINDOW` samples centred
    on it is under ``multiplier`` times that norm over the first :data:`IMUTK_INIT_S` s; then,
    as ``extractIntervalsSamples`` (``include/imu_tk/base.h``), intervals shorter than
    :data:`IMUTK_MIN_SAMPLES` samples are dropped. imu_tk tries multipliers 2..10 and keeps the
    lowest-cost fit; 6 is in the middle of the range that gives 38 poses on its Xsens session.
    """
    from numpy.lib.stride_tricks import sliding_window_view

    a = np.asarray(accel, dtype=float)
    h = IMUTK_WINDOW // 2
    init = t < t[0] + IMUTK_INIT_S
    threshold = multiplier * float(np.linalg.norm(a[init].var(axis=0, ddof=1)))
    var = sliding_window_view(a, IMUTK_WINDOW, axis=0).var(axis=2, ddof=1)
    quiet = np.linalg.norm(var, axis=1) < threshold
    d = np.diff(np.r_[0, quiet.astype(np.int8), 0])
    spans = zip(np.flatnonzero(d == 1) + h, np.flatnonzero(d == -1) + h, strict=True)
    return [(int(lo), int(hi)) for lo, hi in spans if hi - lo >= IMUTK_MIN_SAMPLES]


def still_spans(gyro: np.ndarray, accel: np.ndarray, fs: float, *, window_s: float = 0.5,
                min_s: float = 2.0, trim_s: float = 0.25) -> list[tuple[int, int]]:
    """Rests ``[start, stop)`` of a recording by a rule shared with nothing under test: the
    gyro's and the accelerometer's standard deviation over ``window_s`` both under three times
    their 5th percentile over the recording (the quietest stretches set the noise floor), each
    stretch trimmed by ``trim_s`` at both ends and kept when at least ``min_s`` long."""
    from numpy.lib.stride_tricks import sliding_window_view

    w = max(3, int(round(window_s * fs)))
    quiet = np.ones(gyro.shape[0] - w + 1, dtype=bool)
    for x in (gyro, accel):
        s = np.linalg.norm(sliding_window_view(np.asarray(x, float), w, axis=0).std(axis=2),
                           axis=1)
        quiet &= s < 3.0 * np.percentile(s, 5)
    d = np.diff(np.r_[0, quiet.astype(np.int8), 0])
    trim = int(round(trim_s * fs))
    out = []
    for lo, hi in zip(np.flatnonzero(d == 1), np.flatnonzero(d == -1) + w - 1, strict=True):
        lo, hi = lo + trim, hi - trim
        if hi - lo >= min_s * fs:
            out.append((int(lo), int(hi)))
    return out


#: imucal's Ferraris sections (``imucal/ferraris_calibration.py`` L160-170, FERRARIS_SECTIONS)
#: and its default turn angle, degrees (L175, ``expected_angle=-360``: clockwise, the gyro reads
#: negative) and gravity (L174, ``grav=9.81``).
IMUCAL_FACES = ("x_p", "x_a", "y_p", "y_a", "z_p", "z_a")
IMUCAL_TURNS = ("x_rot", "y_rot", "z_rot")
IMUCAL_ANGLE_DEG = -360.0
IMUCAL_GRAV = 9.81


@dataclass(frozen=True)
class ImucalGyro:
    """imucal's gyro calibration (its units: readings in °/s): ``ω = R⁻¹ K⁻¹ (m − b − K_ga a)``.

    Attributes
    ----------
    K : (3, 3) ndarray
        Diagonal scaling (``K_g``); ``1 / diag(K)`` is comparable with gyrocal's scale.
    R : (3, 3) ndarray
        Rows of unit norm (``R_g``: the sensing axes in the box frame).
    b : (3,) ndarray
        Offset, °/s (``b_g``; gyrocal's bias in rad/s is ``-radians(b)``).
    K_ga : (3, 3) ndarray
        g-sensitivity, (°/s) per (m/s²).
    """

    K: np.ndarray
    R: np.ndarray
    b: np.ndarray
    K_ga: np.ndarray

    @property
    def scale(self) -> np.ndarray:
        """``1 / diag(K)``: gyrocal's diagonal scale of the same sensor (to first order in the
        axes' misalignment)."""
        return 1.0 / np.diag(self.K)


def _section(s: Session, name: str) -> slice:
    lo, hi = next((a, b) for n, a, b in s.sections if n == name)
    return slice(lo, hi)


def imucal_ferraris_gyro(s: Session) -> ImucalGyro:
    """imucal 2.6.0's ``FerrarisCalibration.compute`` on its labelled session, gyro part, with
    ``sampling_rate_hz`` :data:`IMUCAL_FS_HZ` (``examples/basic_ferraris.py``), modelled from
    ``imucal/ferraris_calibration.py`` of mad-lab-fau/imucal at commit 8716e4c:

    * L210-249: the accelerometer's ``b_a`` (Eq. 20, half the sum of the ±face means),
      ``K_a`` (Eq. 23, row norms of the difference over ``2 g``) and ``R_a`` (Eq. 22);
    * L259-271: ``b_g``, the mean gyro reading over the six faces;
    * L278-295: ``K_ga = (U_g_p − U_g_a) / (2 g)`` (Eq. 9), from the ±face gyro means;
    * L300-305 with ``ferraris_calibration_info.py`` L109-110 and L131-134: each turn's
      readings less ``b_g + K_ga a_cal``, ``a_cal = R_a⁻¹ K_a⁻¹ (a − b_a)``;
    * L309-323: ``W_s`` the sum of each turn over the sampling rate (Eq. 13/14), ``M = W_s /
      expected_angle`` (Eq. 15), ``K_g`` the row norms of ``M`` (Eq. 12), ``R_g = K_g⁻¹ M``.

    ``tests/bench/test_real_corpus.py`` checks it against imucal 2.6.0 itself (the ``test``
    extra): every matrix agrees to rounding.

    Parameters
    ----------
    s : Session
        :func:`load` ``("imucal")`` (gyro in rad/s: converted back to imucal's °/s here).
    """
    gyr, acc = np.degrees(s.gyro), s.accel
    mean = {n: (acc[_section(s, n)].mean(axis=0), gyr[_section(s, n)].mean(axis=0))
            for n in IMUCAL_FACES}
    U_a_p = np.column_stack([mean[f"{a}_p"][0] for a in "xyz"])
    U_a_n = np.column_stack([mean[f"{a}_a"][0] for a in "xyz"])
    b_a = np.diag((U_a_p + U_a_n) / 2)
    U_a_d = U_a_p - U_a_n
    K_a = np.diag(np.sqrt(np.diag(U_a_d @ U_a_d.T) / (4 * IMUCAL_GRAV**2)))
    R_a = np.linalg.inv(K_a) @ U_a_d / (2 * IMUCAL_GRAV)
    b_g = np.mean(np.vstack([gyr[_section(s, n)] for n in IMUCAL_FACES]), axis=0)
    U_g_p = np.column_stack([mean[f"{a}_p"][1] for a in "xyz"])
    U_g_a = np.column_stack([mean[f"{a}_a"][1] for a in "xyz"])
    K_ga = (U_g_p - U_g_a) / (2 * IMUCAL_GRAV)
    acc_mat = np.linalg.inv(R_a) @ np.linalg.inv(K_a)
    W_s = np.zeros((3, 3))
    for j, name in enumerate(IMUCAL_TURNS):
        sl = _section(s, name)
        a_cal = (acc_mat @ (acc[sl] - b_a).T).T
        W_s[:, j] = np.sum(gyr[sl] - (K_ga @ a_cal.T).T - b_g, axis=0) / IMUCAL_FS_HZ
    M = W_s @ np.linalg.inv(IMUCAL_ANGLE_DEG * np.eye(3))
    K_g = np.diag(np.sqrt(np.diag(M @ M.T)))
    return ImucalGyro(K_g, np.linalg.inv(K_g) @ M, b_g, K_ga)


def write_recording(s: Session, out: Path) -> None:
    """Write a session as a Recording v1 of the hand jig (module docstring): ``imu.csv`` with
    the gyro (rad/s) and the accelerometer (m/s²) at the session's sample times, empty
    ``encoder.csv`` and ``segments.csv`` (the rests and turns are found in the data), the
    manifest's ``jig`` ``{"kind": "hand"}`` and ``source``. Refuses to overwrite ``out``."""
    from gyrocal.kit.recording import RecordingWriter

    if out.exists():
        raise FileExistsError(f"{out} exists; remove it first")
    lsb = {"imucal": IMUCAL_GYR_LSB}.get(s.name)
    sensor = {"model": f"{s.name}-session", "odr_hz": s.odr_hz}
    if lsb is not None:
        sensor.update(full_scale_dps=2000.0, sensitivity_rad_s_per_lsb=float(np.radians(lsb)))
    extra = {"jig": {"kind": "hand"}, "site": {"gravity_m_s2": s.gravity,
                                                "gravity_from": "the source's own"},
             "source": f"bench.real_corpus {s.name} (bench/data/README.md)"}
    with RecordingWriter(out, sensor=sensor, gimbal={"motors": []},
                         protocol={"name": "hand", "source": s.name}, extra=extra,
                         accel=True) as w:
        w.append_imu(s.t, s.gyro, np.full(s.t.size, np.nan), accel=s.accel)
        w.finish()


def main(argv: list[str]) -> int:
    if len(argv) == 3 and argv[0] == "recording":
        try:
            write_recording(load(argv[1]), Path(argv[2]))
        except (OSError, ValueError) as exc:
            print(f"error: {exc}", file=sys.stderr)
            return 2
        return 0
    if len(argv) < 3 or argv[0] not in SOURCES or len(argv) != len(SOURCES[argv[0]]) + 2:
        print("usage: python -m bench.real_corpus NAME SOURCE... OUT.csv.xz\n"
              "       python -m bench.real_corpus recording imucal OUT_DIR\n"
              + "\n".join(f"  {n}: {' '.join(s)}" for n, s in SOURCES.items()), file=sys.stderr)
        return 2
    try:
        convert(argv[0], [Path(p) for p in argv[1:-1]], Path(argv[-1]))
    except (OSError, ValueError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))

__all__ = ["FILES", "ImucalGyro", "Session", "convert", "imucal_ferraris_gyro",
           "imutk_static_intervals", "load", "locate", "missing_reason", "still_spans",
           "write_recording"]
