"""Long recordings: what reading a Recording v1 and ``gyrocal noise`` cost in CPU and memory.

``python -m bench longrec`` (``--quick``: 1 and 10 minutes at 200 Hz only). Each recording is a
still sensor (white noise about a bias, temperature, three servos' encoders at 200 Hz each) of
1, 10 and 60 minutes at 200 Hz and 10 and 60 minutes at 1 kHz, written block by block in
bounded memory. Each measurement runs in its own process (CPU seconds user+system and peak
resident memory from ``/usr/bin/time`` or ``getrusage``):

* the Recording v1 reader before issue 16 (taken from git history, commit ``BEFORE``) and now;
* ``gyrocal noise RECORDING --json`` (the whole record at once).

``estimate``, ``report`` and ``track --json`` need turns, which a still recording lacks; their
cost on long sessions is not measured here yet.
"""

from __future__ import annotations

import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

from bench.table import print_table
from gyrocal.kit.recording import RecordingWriter

#: The commit whose ``kit/recording.py`` is the reader before issue 16.
BEFORE = "2b3e916"
SIZES_FULL = ((1, 200), (10, 200), (60, 200), (10, 1000), (60, 1000))
SIZES_QUICK = ((1, 200), (10, 200))

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


def write_still(path: Path, minutes: float, odr: float, seed: int = 0) -> None:
    """A still recording, written in blocks of 10 s."""
    rng = np.random.default_rng(seed)
    bias = np.array([0.01, -0.02, 0.005])
    n = int(minutes * 60 * odr)
    block = int(10 * odr)
    enc_every = max(1, int(round(odr / 200)))
    with RecordingWriter(path, sensor={"model": "simulated", "odr_hz": odr},
                         gimbal={"motors": []}, protocol={"name": "still"}) as w:
        for a in range(0, n, block):
            i = np.arange(a, min(n, a + block))
            t = i / odr
            w.append_imu(t, bias + rng.normal(scale=0.002, size=(i.size, 3)),
                         25.0 + 0.01 * rng.normal(size=i.size))
            te = t[::enc_every]
            w.append_encoder(np.repeat(te, 3), np.tile([1, 2, 3], te.size),
                             np.zeros(3 * te.size))
        from gyrocal.calib.segments import Segment

        w.append_segment(Segment(0, "rest", None, 0, 0.0, 0.0, (n - 1) / odr))
        w.finish()


def _reader(rec: Path, old_dir: Path, which: str) -> tuple[float, float]:
    out = subprocess.run([sys.executable, "-c", PROBE, str(rec), str(old_dir), which],
                         capture_output=True, text=True, check=True)
    cpu, rss, *_ = out.stdout.split()
    return float(cpu), float(rss) / 2**20


def _command(argv: list[str]) -> tuple[float, float, int]:
    """CPU s and peak MiB of one child process (getrusage of the children, via a wrapper)."""
    wrapper = ("import resource, subprocess, sys\n"
               "rc = subprocess.run(sys.argv[1:], stdout=subprocess.DEVNULL).returncode\n"
               "r = resource.getrusage(resource.RUSAGE_CHILDREN)\n"
               "print(r.ru_utime + r.ru_stime, r.ru_maxrss * 1024, rc)\n")
    out = subprocess.run([sys.executable, "-c", wrapper, *argv], capture_output=True,
                         text=True, check=True)
    cpu, rss, rc = out.stdout.split()
    return float(cpu), float(rss) / 2**20, int(rc)


def main(argv: list[str]) -> None:
    """Generate the recordings, measure, print the table."""
    sizes = SIZES_QUICK if "--quick" in argv else SIZES_FULL
    work = Path(tempfile.mkdtemp(prefix="gyrocal-longrec-"))
    try:
        old = subprocess.run(["git", "show", f"{BEFORE}:kit/recording.py"],
                             capture_output=True, text=True,
                             cwd=Path(__file__).resolve().parent.parent)
        have_old = old.returncode == 0
        if have_old:
            (work / "old_recording.py").write_text(old.stdout)
        base_cpu, base_rss = _command([sys.executable, "-c", "import numpy"])[:2]
        rows = []
        for minutes, odr in sizes:
            rec = work / f"rec-{minutes}min-{odr}hz"
            write_still(rec, minutes, odr)
            mb = sum(f.stat().st_size for f in rec.iterdir()) / 2**20
            n_rows = sum(sum(1 for _ in open(rec / f)) - 1 for f in ("imu.csv", "encoder.csv"))
            new_cpu, new_rss = _reader(rec, work, "new")
            if have_old:
                old_cpu, old_rss = _reader(rec, work, "old")
                old_cols = [old_cpu, old_rss, f"{old_cpu / new_cpu:.1f}x"]
            else:
                old_cols = ["(no git)", "", ""]
            n_cpu, n_rss, rc = _command([sys.executable, "-m", "gyrocal.kit", "noise", str(rec),
                                         "--json"])
            rows.append([f"{minutes} min @ {odr} Hz", f"{mb:.0f}", n_rows, *old_cols, new_cpu,
                         new_rss, new_cpu / n_rows * 1e6, n_cpu, n_rss,
                         "ok" if rc == 0 else f"exit {rc}"])
            shutil.rmtree(rec)
        print_table(
            ["recording", "MiB", "CSV rows", "old read CPU s", "old peak MiB", "speed-up",
             "new read CPU s", "new peak MiB", "new CPU s / M rows", "noise CPU s",
             "noise peak MiB", "noise"], rows,
            f"Reading a still Recording v1 (imu.csv + encoder.csv), each in a fresh process; "
            f"bare 'import numpy' costs {base_cpu:.2f} CPU s and {base_rss:.0f} MiB",
        )
    finally:
        shutil.rmtree(work, ignore_errors=True)
