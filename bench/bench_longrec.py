"""Long recordings: what reading a Recording v1 and the analysis commands cost in CPU and memory.

``python -m bench longrec`` (``--quick``: 1 and 10 minutes at 200 Hz only; ``--size=MINxHZ``,
repeatable, e.g. ``--size=60x1000``: those sizes only). Each recording is
written by ``gyrocal simulate-recording`` (streamed, bounded memory; its own CPU and peak memory
are a column) with enough turns and long rests to last 1, 10 and 60 minutes at 200 Hz and 10
and 60 minutes at 1 kHz. Each measurement runs in its own process (CPU seconds user+system and
peak resident memory from ``getrusage`` of the child):

* the reader before issue 16 (``kit/recording.py`` of commit ``BEFORE``, from git history) and
  the block reader with each parser (``GYROCAL_CSV_PARSER``): numpy.loadtxt, the vectorised
  decimal parser (numpy alone, the default without pandas) and pandas' (``fast`` extra);
* ``gyrocal estimate`` before its memory fix (today's code with the modules
  :data:`ESTIMATE_BEFORE` names as they were at its commit) and now;
* ``gyrocal estimate``, ``noise --json`` (streamed), ``track --json`` and ``report`` with the
  default parser (``report`` only with matplotlib, and only up to 10 minutes: its plots of
  every sample dominate and are not issue 16's subject);
* ``track --json`` before it streamed (the modules :data:`TRACK_BEFORE` names as they were at
  its commit) and now, with the largest difference between their documents (0 when the
  two are the same text).

A last table compares wall times of ``gyrocal --help``, ``gyrocal estimate --help``, an
argument error and ``gyrocal estimate`` on the 1-minute recording with a bare ``python -c
pass``, medians of 5 runs.
"""

from __future__ import annotations

import importlib.util
import math
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from bench.table import print_table

#: The commit whose ``kit/recording.py`` is the reader before issue 16.
BEFORE = "2b3e916"
#: The commit before the estimate's memory fix (issue 16: the gyro time refit held ten
#: stream-sized temporaries) and the modules that fix changed.
ESTIMATE_BEFORE = ("bb53b79", ("calib/timebase.py",))
#: The commit before ``track`` streamed the recording (issue 16: the recording was loaded
#: whole and the JSON document built whole) and the modules that change touched.
TRACK_BEFORE = ("741f28b", ("kit/recording.py", "calib/stationarity.py", "kit/fileio.py",
                            "kit/tracking.py", "kit/commands/track.py"))
#: The block parsers measured (``GYROCAL_CSV_PARSER``) and their column names.
PARSER_COLUMNS = {"numpy": "numpy.loadtxt", "decimal": "decimal (numpy alone)",
                  "pandas": "pandas"}
SIZES_FULL = ((1, 200), (10, 200), (60, 200), (10, 1000), (60, 1000))
SIZES_QUICK = ((1, 200), (10, 200))
#: Longest recording ``report`` is run on, minutes.
REPORT_MAX_MIN = 10

PROBE = """
import resource, sys, time
sys.path.insert(0, sys.argv[2])
if sys.argv[3] == "old":
    from old_recording import load_recording
else:
    from gyrocal.kit.recording import load_recording
t0 = time.process_time()
rec = load_recording(sys.argv[1])
cpu = time.process_time() - t0
ru = resource.getrusage(resource.RUSAGE_SELF)
print(cpu, ru.ru_maxrss * 1024, rec.imu_t.size, rec.enc_t.size)
"""

#: Runs ``python -m gyrocal.kit ARGS`` with modules replaced by older files:
#: ``-c OLD_MODULES DIR PATH,PATH -- ARGS`` (PATH relative to the repository, e.g.
#: calib/timebase.py, read from DIR/PATH).
OLD_MODULES = """
import importlib.util, runpy, sys
from pathlib import Path
import gyrocal.calib, gyrocal.kit, gyrocal.drivers, gyrocal.kit.commands
top, paths, args = Path(sys.argv[1]), sys.argv[2].split(","), sys.argv[4:]
for path in paths:
    name = "gyrocal." + path[:-3].replace("/", ".")
    spec = importlib.util.spec_from_file_location(name, top / path)
    mod = importlib.util.module_from_spec(spec)
    sys.modules[name] = mod
    spec.loader.exec_module(mod)
    parent, _, leaf = name.rpartition(".")
    setattr(sys.modules[parent], leaf, mod)
sys.argv = ["gyrocal", *args]
runpy.run_module("gyrocal.kit", run_name="__main__")
"""

WRAPPER = ("import resource, subprocess, sys\n"
           "rc = subprocess.run(sys.argv[1:], stdout=subprocess.DEVNULL,\n"
           "                    stderr=subprocess.DEVNULL).returncode\n"
           "r = resource.getrusage(resource.RUSAGE_CHILDREN)\n"
           "print(r.ru_utime + r.ru_stime, r.ru_maxrss * 1024, rc)\n")


def _env(parser: str | None = None) -> dict[str, str]:
    env = dict(os.environ)
    env.pop("GYROCAL_CSV_PARSER", None)
    if parser:
        env["GYROCAL_CSV_PARSER"] = parser
    return env


def _command(argv: list[str], parser: str | None = None) -> tuple[float, float, int]:
    """CPU s, peak MiB and exit code of one child process."""
    out = subprocess.run([sys.executable, "-c", WRAPPER, *argv], capture_output=True,
                         text=True, check=True, env=_env(parser))
    cpu, rss, rc = out.stdout.split()
    return float(cpu), float(rss) / 2**20, int(rc)


def _gyrocal(*args: str) -> list[str]:
    return [sys.executable, "-m", "gyrocal.kit", *args]


def write_session(path: Path, minutes: float, odr: float) -> tuple[float, float, int]:
    """A simulated calibration session of about ``minutes``: turns of ``minutes`` revolutions
    each way about each axis at 3 rad/s, the rest of the time in seven equal rests."""
    from gyrocal.calib.simulate import profile_duration

    turns = max(1, round(minutes))
    turn_s = profile_duration(2 * 3.141592653589793 * turns, 3.0, 8.0) + 0.1
    rest = max(1.0, (minutes * 60 - 6 * turn_s) / 7)
    return _command(_gyrocal("simulate-recording", str(path), "--turns", str(turns),
                             "--rest", f"{rest:.3f}", "--odr", str(odr)))


def _reader(rec: Path, old_dir: Path, which: str, parser: str | None) -> tuple[float, float]:
    out = subprocess.run([sys.executable, "-c", PROBE, str(rec), str(old_dir), which],
                         capture_output=True, text=True, check=True, env=_env(parser))
    cpu, rss, *_ = out.stdout.split()
    return float(cpu), float(rss) / 2**20


def _same_output(a: Path, b: Path) -> str:
    """Largest absolute difference between two ``track --json`` documents ("same text" when
    they are byte for byte the same)."""
    import json

    import numpy as np

    if a.read_bytes() == b.read_bytes():
        return "same text"
    x, y = json.loads(a.read_text()), json.loads(b.read_text())
    if sorted(x) != sorted(y) or len(x["t"]) != len(y["t"]):
        return "different rows"
    # as floats: the still flags are booleans, which numpy does not subtract
    diffs = (np.abs(np.subtract(np.asarray(x[k], dtype=float), np.asarray(y[k], dtype=float)))
             for k in x)
    return f"{max(float(np.max(d, initial=0)) for d in diffs):.1e}"


def _track_pair(rec: Path, before: list[str] | None, work: Path) -> list[str]:
    """``track --json`` before streaming and now: two cells of CPU / peak, and whether the
    documents agree."""
    out = []
    for name, prefix in (("before", before), ("now", _gyrocal())):
        if prefix is None:
            out.append("(no git)")
            continue
        doc = work / f"track-{name}.json"
        out.append(_cell(*_command([*prefix, "track", str(rec), "--json", "--out", str(doc),
                                    "--force"])))
    have = [work / f"track-{n}.json" for n in ("before", "now")]
    out.append(_same_output(*have) if all(p.exists() for p in have) else "")
    for p in have:
        p.unlink(missing_ok=True)
    return out


def _wall(argv: list[str], runs: int = 5) -> float:
    times = []
    for _ in range(runs):
        t0 = time.perf_counter()
        subprocess.run(argv, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, check=False)
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def _old_modules(work: Path, before: tuple[str, tuple[str, ...]] = ESTIMATE_BEFORE
                 ) -> list[str] | None:
    """The command prefix running gyrocal with the modules of ``before`` (commit, paths) as
    they were at that commit (None without git history)."""
    commit, paths = before
    top = work / f"modules-{commit}"
    for path in paths:
        old = subprocess.run(["git", "show", f"{commit}:{path}"], capture_output=True, text=True,
                             cwd=Path(__file__).resolve().parent.parent)
        if old.returncode != 0:
            return None
        (top / path).parent.mkdir(parents=True, exist_ok=True)
        (top / path).write_text(old.stdout)
    return [sys.executable, "-c", OLD_MODULES, str(top), ",".join(paths), "--"]


def _sizes(argv: list[str]) -> tuple[tuple[int, int], ...]:
    """The recording sizes (minutes, Hz) the arguments ask for."""
    picked = [a.split("=", 1)[1] for a in argv if a.startswith("--size=")]
    if picked:
        try:
            return tuple((int(m), int(hz)) for m, hz in (p.split("x") for p in picked))
        except ValueError:
            raise SystemExit(
                f"bench longrec: --size wants MINxHZ, e.g. --size=60x1000; got {picked}") from None
    return SIZES_QUICK if "--quick" in argv else SIZES_FULL


def _cell(cpu: float, rss: float, rc: int) -> str:
    return f"{cpu:.2f} s / {rss:.0f} MiB" + ("" if rc == 0 else f" (exit {rc})")


def main(argv: list[str]) -> None:
    """Generate the recordings, measure, print the tables."""
    sizes = _sizes(argv)
    have_plot = importlib.util.find_spec("matplotlib") is not None
    have_fast = importlib.util.find_spec("pandas") is not None
    work = Path(tempfile.mkdtemp(prefix="gyrocal-longrec-"))
    try:
        old = subprocess.run(["git", "show", f"{BEFORE}:kit/recording.py"],
                             capture_output=True, text=True,
                             cwd=Path(__file__).resolve().parent.parent)
        have_old = old.returncode == 0
        if have_old:
            (work / "old_recording.py").write_text(old.stdout)
        before = _old_modules(work)
        track_before = _old_modules(work, TRACK_BEFORE)
        read_rows, cmd_rows = [], []
        wall_rec = None
        for minutes, odr in sizes:
            rec = work / f"rec-{minutes}min-{odr}hz"
            sim = write_session(rec, minutes, odr)
            mb = sum(f.stat().st_size for f in rec.iterdir()) / 2**20
            n_rows = sum(sum(1 for _ in open(rec / f)) - 1 for f in ("imu.csv", "encoder.csv"))
            label = f"{minutes} min @ {odr} Hz"
            readers = {name: _reader(rec, work, "new", name) for name in PARSER_COLUMNS
                       if name != "pandas" or have_fast}
            old_cpu = _reader(rec, work, "old", None)[0] if have_old else math.nan
            measured = [readers.get(name) for name in PARSER_COLUMNS]  # None: not installed
            read_rows.append([label, f"{mb:.0f}", n_rows,
                              f"{old_cpu:.2f} s" if have_old else "(no git)",
                              *(f"{m[0]:.2f} s / {m[1]:.0f} MiB" if m else "(absent)"
                                for m in measured),
                              *(f"{old_cpu / m[0]:.1f}x" if m and have_old else ""
                                for m in measured),
                              f"{readers['decimal'][0] / n_rows * 1e6:.2f}"])
            cells = [label, _cell(*sim)]
            cells.append(_cell(*_command([*before, "estimate", str(rec)])) if before
                         else "(no git)")
            cells.append(_cell(*_command(_gyrocal("estimate", str(rec)))))
            cells.append(_cell(*_command(_gyrocal("noise", str(rec), "--json"))))
            cells += _track_pair(rec, track_before, work)
            if have_plot and minutes <= REPORT_MAX_MIN:
                cells.append(_cell(*_command(_gyrocal("report", str(rec), "--out",
                                                      str(work / "report"), "--force"))))
            else:
                cells.append("(skipped)")
            cmd_rows.append(cells)
            print("longrec:", *read_rows[-1], "|", *cells, file=sys.stderr, flush=True)
            if minutes == 1 and wall_rec is None:
                wall_rec = rec
            else:
                shutil.rmtree(rec)
        print_table(
            ["recording", "MiB", "CSV rows", f"reader {BEFORE} CPU",
             *(f"{PARSER_COLUMNS[n]} CPU/peak" for n in PARSER_COLUMNS),
             *(f"speed-up {PARSER_COLUMNS[n]}" for n in PARSER_COLUMNS),
             "decimal CPU s / M rows"], read_rows,
            "Reading a Recording v1 (imu.csv + encoder.csv), each in a fresh process "
            "(CPU s user+system / peak RSS); the default is decimal",
        )
        print_table(
            ["recording", "simulate-recording", f"estimate {ESTIMATE_BEFORE[0]}", "estimate",
             "noise --json", f"track --json {TRACK_BEFORE[0]}", "track --json",
             "track: max |diff|", "report"], cmd_rows,
            "Commands on the same recordings, default parser (CPU s user+system / peak RSS)",
        )
        if wall_rec is not None:
            py = _wall([sys.executable, "-c", "pass"])
            rows = [["python -c pass", f"{py:.3f}"]]
            for label, argv in (("gyrocal --help", ["--help"]),
                                ("gyrocal estimate --help", ["estimate", "--help"]),
                                ("gyrocal estimate (argument error)", ["estimate"]),
                                ("gyrocal estimate (1 min @ 200 Hz)", ["estimate", str(wall_rec)])):
                wall = _wall(_gyrocal(*argv))
                rows.append([label, f"{wall:.3f}", f"{wall - py:+.3f}"])
            rows[0].append("")
            print_table(["command", "wall s (median of 5)", "beyond python -c pass"], rows,
                        "Start-up")
    finally:
        shutil.rmtree(work, ignore_errors=True)
