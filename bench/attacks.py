"""The outside audit's attacks (issue 27), each run as ``gyrocal`` in a subprocess and judged.

One case per cause the audit reproduced, by area: ``--force`` over user files and odd ``--out``
values, ``verify`` of correct calibrations and of hostile calibration paths, unit and axis
mistakes, strings that reach a formatter (matplotlib mathtext, a terminal, a C comment), input
bombs (a TOML key of 50,000 parts, endless standard input, a huge integer, deep nesting, a key
given twice), a damaged history, a servo adapter pulled mid-turn, the servo emulator frozen
(SIGSTOP) mid-turn with and without its port's buffer full (a hung port), and a disk that fills
during the recording or the plots.

Every case says what a right outcome is (``expect``: ``ok`` = the command does its work, exit 0
or 3; ``refuse`` = a clean refusal, exit 2, 4 or 6 with one ``gyrocal: error:`` line) and how its
data is checked afterwards. The subprocess runs under a 1.5 GB address-space limit and a time
limit, so an attack that once took gigabytes or hung is counted, not suffered. The command line
is ``python -m gyrocal.kit``: whatever ``gyrocal`` package the environment imports is judged
(``PYTHONPATH`` can point it at another checkout for a before/after table).

Outcome classes: ``ok`` (did its work, checks pass), ``refused`` (clean refusal, before any jig
motion when the case says so), ``late refusal`` (refused only after the jig ran: a staged run
``.NAME.new-*`` is left), ``silent
wrong`` (exit 0/3 where a refusal was due, a wrong verdict, or output that a check finds
wrong), ``exit 1 / traceback``, ``hang``, ``data lost`` (a file the user had is gone or
changed), ``bad message`` (a refusal that echoes kilobytes of its input).
"""

from __future__ import annotations

import errno
import json
import os
import resource
import shutil
import signal
import sqlite3
import stat
import subprocess
import sys
import tempfile
import threading
import time
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["CASES", "Case", "attack_matrix"]

#: Address space each attacked command may use, bytes (the 20,000-part TOML key needed 2.4 GB).
MEMORY_LIMIT = 1536 << 20
#: A short emulated run: the planner's diagonal protocol in 18 s of jig time, no realism (what
#: is attacked is the output directory, not the estimate).
SHORT = '[protocol]\nname = "auto"\ntime_budget_s = 18.0\n'
DEG = 180 / np.pi


@dataclass
class Case:
    """One attack.

    ``setup(d)`` prepares the scratch directory ``d`` and returns the argv (after ``gyrocal``),
    optionally with standard input bytes and a working directory; ``check(d, code, out, err)``
    returns an outcome class overriding the exit-code judgement (``data lost``, ``silent
    wrong``), or None.
    """

    area: str
    name: str
    expect: str  # "ok" or "refuse"
    setup: Callable[[Path], dict]
    check: Callable[[Path, int | None, str, str], str | None] | None = None
    timeout_s: float = 60.0
    before_jig: bool = False  # a refusal must come before the jig moves (no staged run)


@dataclass
class Result:
    case: Case
    outcome: str
    code: int | None
    seconds: float
    last: str = ""
    extra: dict = field(default_factory=dict)


def _limit() -> None:
    resource.setrlimit(resource.RLIMIT_AS, (MEMORY_LIMIT, MEMORY_LIMIT))


def _run(argv: list[str], *, stdin: bytes | None, cwd: Path, timeout_s: float,
         full_disk: tuple[int | None, int | None, str | None] | None = None
         ) -> tuple[int | None, str, str, float]:
    t0 = time.perf_counter()
    head = ["-m", "gyrocal.kit"]
    if full_disk is not None:  # the command on a disk that fills (FullDisk)
        head = ["-c", _FULL_DISK_MAIN.format(root=str(Path(__file__).resolve().parents[1])),
                *("-" if v is None else str(v) for v in full_disk)]
    proc = subprocess.Popen([sys.executable, *head, *argv], cwd=cwd,
                            stdin=subprocess.PIPE if stdin is not None else subprocess.DEVNULL,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, preexec_fn=_limit)
    try:
        out, err = proc.communicate(stdin, timeout=timeout_s)
        code: int | None = proc.returncode
    except subprocess.TimeoutExpired:
        proc.kill()
        out, err = proc.communicate()
        code = None
    except BrokenPipeError:  # it refused before reading all of standard input
        out, err = proc.communicate()
        code = proc.returncode
    return (code, out.decode("utf-8", "replace"), err.decode("utf-8", "replace"),
            time.perf_counter() - t0)


def _judge(case: Case, code: int | None, out: str, err: str, seconds: float) -> str:
    if code is None:
        return "hang"
    if code == 1 or "Traceback" in err or code < 0:
        return "exit 1 / traceback"
    if case.expect == "ok":
        return "ok" if code in (0, 3) else f"refused a right input (exit {code})"
    if code in (0, 3):
        return "silent wrong"
    if len(err) > 4000:
        return "bad message"
    return "refused"


def _staged(d: Path) -> bool:
    """Whether a run was staged under ``d`` (``.NAME.new-*``, ``.NAME.old-*``): the jig ran."""
    return any(".new-" in p.name or ".old-" in p.name for p in d.rglob(".*"))


def run_case(case: Case, root: Path) -> Result:
    d = root / f"{case.area}-{case.name}".replace(" ", "_").replace("/", "_")
    d.mkdir(parents=True)
    spec = case.setup(d)
    code, out, err, seconds = _run(spec["argv"], stdin=spec.get("stdin"),
                                   cwd=spec.get("cwd", d), timeout_s=case.timeout_s,
                                   full_disk=spec.get("full_disk"))
    while _EMULATORS:
        _EMULATORS.pop().close()
    outcome = _judge(case, code, out, err, seconds)
    if case.before_jig and outcome == "refused" and _staged(d):
        outcome = "late refusal"
    if case.check is not None and outcome not in ("hang", "exit 1 / traceback"):
        outcome = case.check(d, code, out, err) or outcome
    last = (err.strip().splitlines()[-1:] or [""])[0][:110]
    return Result(case, outcome, code, seconds, last)


# --------------------------------------------------------------------------- helpers
def _fake_run(d: Path) -> Path:
    """A directory holding a gyrocal run's marks (what --force may replace)."""
    (d / "recording").mkdir(parents=True)
    (d / "recording" / "manifest.json").write_text(json.dumps(
        {"format": "gyrocal-recording", "version": 1, "complete": True}))
    (d / "calibration.json").write_text(json.dumps({"format": "gyrocal-calibration"}))
    return d


def _short(d: Path) -> str:
    (d / "short.toml").write_text(SHORT)
    return str(d / "short.toml")


def _calibrate(d: Path, out: str, *extra: str) -> list[str]:
    return ["calibrate", "--sim", "--sim-realism", "off", "--config", _short(d), "--no-report",
            "--quiet", "--out", out, *extra]


def _kept(path_name: str, text: str) -> Callable:
    def check(d: Path, code: int | None, out: str, err: str) -> str | None:
        p = d / path_name
        return None if p.exists() and p.read_text() == text else "data lost"
    return check


def _contract(d: Path, name: str = "rec", **kw) -> Path:
    from tests.kit.contract_recording import write_recording

    return write_recording(d / name, odr=100.0, **kw)


def _rewrite_imu(path: Path, row: Callable[[list[str]], list[str]]) -> Path:
    lines = (path / "imu.csv").read_text().splitlines()
    (path / "imu.csv").write_text("\n".join(
        [lines[0]] + [",".join(row(x.split(","))) for x in lines[1:]]) + "\n")
    return path


def _cal_doc(**kw) -> str:
    from gyrocal.calib.model import GyroCalibration

    base = dict(scale=(1.0, 1.0, 1.0), bias=(0.0, 0.0, 0.0), scale_std=(1e-4,) * 3,
                bias_std=(1e-4,) * 3, sensor={"model": "mpu9250"},
                created="2026-01-01T00:00:00Z")
    base.update(kw)
    return GyroCalibration(**base).to_json()


def _history(d: Path, *, created: str = "2026-01-0{i}T00:00:00Z", method: str = "paired-axis",
             n: int = 3) -> str:
    """A SQLite history with ``n`` calibrations of sensor ``imu`` stored by the CLI."""
    docs = d / "docs"
    docs.mkdir()
    for i in range(1, n + 1):
        (docs / f"c{i}.json").write_text(_cal_doc(bias=(0.001 * i, 0.0, 0.0), method=method,
                                                  created=created.format(i=i)))
    url = f"sqlite:///{d / 'h.sqlite'}"
    subprocess.run([sys.executable, "-m", "gyrocal.kit", "history", "import", str(docs),
                    "--history", url, "--sensor-label", "imu"], capture_output=True, check=False)
    return url


def _damage_history(d: Path, statement: str) -> None:
    con = sqlite3.connect(d / "h.sqlite")
    con.execute(statement)
    con.commit()
    con.close()


def _all_of(argvs: list[list[str]]) -> Callable:
    """A check that runs more history commands; any that is not exit 0 fails the case."""
    def check(d: Path, code: int | None, out: str, err: str) -> str | None:
        for argv in argvs:
            c, _, e, _ = _run(argv, stdin=None, cwd=d, timeout_s=60)
            if c != 0:
                return "exit 1 / traceback" if c == 1 or "Traceback" in e else \
                    f"refused a right input (exit {c})"
        return None
    return check


# --------------------------------------------------------------------------- the cases
def _force_user_files(d: Path) -> dict:
    (d / "out").mkdir()
    (d / "out" / "thesis.tex").write_text("work")
    return {"argv": _calibrate(d, "out", "--force")}


def _force_beside_run(d: Path) -> dict:
    _fake_run(d / "out")
    (d / "out" / "notes.txt").write_text("mine")
    return {"argv": _calibrate(d, "out", "--force")}


def _force_dot(d: Path) -> dict:
    _fake_run(d / "run")
    return {"argv": _calibrate(d, ".", "--force"), "cwd": d / "run"}


def _dot_check(d: Path, code: int | None, out: str, err: str) -> str | None:
    leftovers = [p.name for p in d.iterdir() if p.name.startswith("..")]
    if leftovers or not (d / "run" / "calibration.json").exists():
        return "data lost"
    return None


def _force_symlink(d: Path) -> dict:
    _fake_run(d / "real")
    (d / "link").symlink_to(d / "real")
    return {"argv": _calibrate(d, "link", "--force")}


def _symlink_check(d: Path, code: int | None, out: str, err: str) -> str | None:
    hidden = [p.name for p in d.iterdir() if p.name.startswith(".link.new-")]
    return "data lost" if hidden else None


def _force_mode(d: Path) -> dict:
    _fake_run(d / "out")
    os.chmod(d / "out", 0o750)
    return {"argv": _calibrate(d, "out", "--force")}


def _mode_check(d: Path, code: int | None, out: str, err: str) -> str | None:
    mode = stat.S_IMODE((d / "out").stat().st_mode)
    return None if mode == 0o750 else "silent wrong"


def _passed(d: Path, code: int | None, out: str, err: str) -> str | None:
    """verify of a correct calibration must pass: exit 3 condemns it (a wrong verdict)."""
    return None if code == 0 else "silent wrong"


def _verify_synthetic(d: Path) -> dict:
    subprocess.run([sys.executable, "-m", "gyrocal.kit", "simulate-recording", str(d / "rec")],
                   capture_output=True, check=True)
    subprocess.run([sys.executable, "-m", "gyrocal.kit", "estimate", str(d / "rec"), "--out",
                    str(d / "cal.json")], capture_output=True, check=False)
    return {"argv": ["verify", str(d / "cal.json"), "--recording", str(d / "rec")]}


def jitter_encoder_times(rec: Path, seed: int = 27, half_width_s: float = 0.003) -> None:
    """Move each of ``rec``'s encoder time stamps by a uniform ±``half_width_s`` (seeded; the
    readings of one sync read keep one stamp), as a host's read times scatter."""
    rng = np.random.default_rng(seed)
    lines = (rec / "encoder.csv").read_text().splitlines()
    rows = [x.split(",") for x in lines[1:]]
    jitter = {t: rng.uniform(-half_width_s, half_width_s) for t in {r[0] for r in rows}}
    (rec / "encoder.csv").write_text("\n".join(
        [lines[0]] + [f"{float(r[0]) + jitter[r[0]]:.6f},{r[1]},{r[2]}" for r in rows]) + "\n")


def _verify_truth_jittered(d: Path) -> dict:
    rec = _contract(d)
    jitter_encoder_times(rec)
    (d / "truth.json").write_text(_cal_doc(scale=(1.01, 0.99, 1.02),
                                           bias=(0.01, -0.02, 0.005)))
    return {"argv": ["verify", str(d / "truth.json"), "--recording", str(rec)]}


def _verify_path(kind: str) -> Callable[[Path], dict]:
    def setup(d: Path) -> dict:
        p = d / "cal.json"
        if kind == "fifo":
            os.mkfifo(p)
        elif kind == "zero":
            p = Path("/dev/zero")
        elif kind == "loop":
            (d / "a").symlink_to(d / "b")
            (d / "b").symlink_to(d / "a")
            p = d / "a"
        else:
            p.mkdir()
        return {"argv": ["verify", str(p), "--recording", str(d)]}
    return setup


def _estimate_of(mistake: str) -> Callable[[Path], dict]:
    def setup(d: Path) -> dict:
        if mistake == "degrees":
            rec = _contract(d, gyro_unit=DEG, angle_unit=DEG)
        elif mistake == "swapped":
            rec = _rewrite_imu(_contract(d), lambda r: [r[0], r[2], r[1], r[3], r[4]])
        elif mistake == "negated":
            rec = _rewrite_imu(_contract(d),
                               lambda r: [r[0], repr(-float(r[1])), r[2], r[3], r[4]])
        elif mistake == "underscore":  # "1_0.5": Python's float() reads 10.5
            rec = _rewrite_imu(_contract(d), lambda r: [r[0], r[1].replace(".", "_0.", 1)
                                                        if r[1][0].isdigit() else r[1],
                                                        *r[2:]])
        elif mistake == "truth":  # a hand-edited truth: a string for the scale
            rec = _contract(d)
            m = json.loads((rec / "manifest.json").read_text())
            m["truth"] = {"scale": "abc", "bias": [0, 0, 0]}
            (rec / "manifest.json").write_text(json.dumps(m))
        elif mistake == "duplicate id":
            rec = _contract(d)
            m = json.loads((rec / "manifest.json").read_text())
            m["gimbal"]["motors"][1]["id"] = 1
            (rec / "manifest.json").write_text(json.dumps(m))
        else:
            rec = _contract(d)
        return {"argv": ["estimate", str(rec), "--out", str(d / "cal.json")]}
    return setup


def _no_cal_written(d: Path, code: int | None, out: str, err: str) -> str | None:
    return "silent wrong" if (d / "cal.json").exists() and code not in (0, 3) else None


def _report_dollar(d: Path) -> dict:
    rec = _contract(d, name="rec$\\foo{$")
    return {"argv": ["report", str(rec), "--out", str(d / "plots$x^2$")]}


def _plots_written(d: Path, code: int | None, out: str, err: str) -> str | None:
    return None if list((d / "plots$x^2$").glob("*.png")) else "silent wrong"


def _trend_dollar(d: Path) -> dict:
    docs = d / "docs"
    docs.mkdir()
    for i in (1, 2, 3):
        (docs / f"c{i}.json").write_text(_cal_doc(bias=(0.001 * i, 0, 0), temperature_c=20.0 + i,
                                                  created=f"2026-01-0{i}T00:00:00Z"))
    url = f"sqlite:///{d / 'h.sqlite'}"
    subprocess.run([sys.executable, "-m", "gyrocal.kit", "history", "import", str(docs),
                    "--history", url, "--sensor-label", "imu$\\foo{$"], capture_output=True,
                   check=False)
    return {"argv": ["history", "trend", "imu$\\foo{$", "--history", url, "--plot",
                     str(d / "t.png")]}


def _history_escape(d: Path) -> dict:
    url = _history(d, method="x\x1b]0;owned\x07\x1b[2J", n=1)
    return {"argv": ["history", "list", "imu", "--history", url]}


def _no_escape(d: Path, code: int | None, out: str, err: str) -> str | None:
    return "silent wrong" if "\x1b" in out or "\x07" in out else None


def _c_header(d: Path) -> dict:
    (d / "cal.json").write_text(_cal_doc(source="run /* first */ and /* second"))
    return {"argv": ["export", str(d / "cal.json"), "--format", "c-header", "--out",
                     str(d / "cal.h")]}


def _compiles(d: Path, code: int | None, out: str, err: str) -> str | None:
    if shutil.which("gcc") is None or not (d / "cal.h").exists():
        return None
    (d / "main.c").write_text('#include "cal.h"\nint main(void) { return 0; }\n')
    cc = subprocess.run(["gcc", "-std=c99", "-Wall", "-Werror", "-c", "main.c", "-o", "m.o"],
                        cwd=d, capture_output=True)
    return None if cc.returncode == 0 else "silent wrong"


def _toml_depth(d: Path) -> dict:
    (d / "deep.toml").write_text("a" + ".a" * 49_999 + " = 1\n")
    return {"argv": ["calibrate", "--sim", "--config", str(d / "deep.toml"), "--out",
                     str(d / "o")]}


def _stdin_export(d: Path) -> dict:
    return {"argv": ["export", "-", "--format", "json"], "stdin": b"\0" * (64 << 20)}


def _stdin_apply(d: Path) -> dict:
    (d / "cal.json").write_text(_cal_doc())
    return {"argv": ["apply", str(d / "cal.json"), "-"], "stdin": b"1" * (100 << 20)}


def _apply_backwards(d: Path) -> dict:
    (d / "cal.json").write_text(_cal_doc())
    rows = "t,gx,gy,gz,temp\n1.0,0,0,0,25\n0.5,0,0,0,25\n"
    return {"argv": ["apply", str(d / "cal.json"), "-"], "stdin": rows.encode()}


def _cal_text(text: str) -> Callable[[Path], dict]:
    def setup(d: Path) -> dict:
        (d / "cal.json").write_text(text)
        return {"argv": ["export", str(d / "cal.json"), "--format", "json"]}
    return setup


def _damaged_history(statement: str) -> Callable[[Path], dict]:
    def setup(d: Path) -> dict:
        url = _history(d)
        _damage_history(d, statement)
        return {"argv": ["history", "list", "--history", url]}
    return setup


def _history_reads(d: Path, code: int | None, out: str, err: str) -> str | None:
    url = f"sqlite:///{d / 'h.sqlite'}"
    return _all_of([["history", a, "imu", "--history", url] for a in ("list", "trend")]
                   + [["history", "export", "imu", str(d / "exp"), "--history", url]])(
        d, code, out, err)


def _created(when: str) -> Callable[[Path], dict]:
    def setup(d: Path) -> dict:
        (d / "docs").mkdir()
        (d / "docs" / "c.json").write_text(_cal_doc(created=when))
        return {"argv": ["history", "import", str(d / "docs"), "--history",
                         f"sqlite:///{d / 'h.sqlite'}", "--sensor-label", "imu"]}
    return setup


def _pulled_adapter(d: Path) -> dict:
    from bench.signal_rig import ServoRig, write_config

    rig = ServoRig(ids=(1, 2))
    cfg = write_config(d / "gyrocal.toml", rig.path, ids=rig.ids, retries=30, watchdog_s=2.5)

    def pull() -> None:
        rig.wait_for("Present Velocity", lambda v: any(v.values()), within_s=60.0)
        rig.close()  # the adapter is gone, mid-turn

    threading.Thread(target=pull, daemon=True).start()
    return {"argv": ["calibrate", "--sim-imu", "--config", str(cfg), "--out", str(d / "run"),
                     "--quiet"]}


def fill_tty(path: str) -> int:
    """Write NULs into the terminal ``path`` until its buffers take no more (the bytes written):
    whole pages, then the last bytes one by one; again after a pause until a round takes nothing
    (the kernel moves data on to the reader's side in the background)."""
    fd = os.open(path, os.O_WRONLY | os.O_NONBLOCK | os.O_NOCTTY)
    written = 0
    try:
        while True:
            before = written
            for size in (4096, 1):
                while True:
                    try:
                        written += os.write(fd, b"\0" * size)
                    except BlockingIOError:
                        break
            if written == before:
                break
            time.sleep(0.05)
    finally:
        os.close(fd)
    return written


class FrozenEmulator:
    """``gyrocal emulate --pty`` in a process of its own, which can be frozen with SIGSTOP.

    Frozen, the servos answer nothing and the PTY keeps what the kit writes until its buffer is
    full; :meth:`freeze` with ``fill=True`` fills it first, so the kit's next write blocks (a hung
    port: an adapter or driver that stopped taking data). :meth:`close` thaws and ends it.
    """

    def __init__(self, ids: tuple[int, ...] = (1, 2)) -> None:
        self.ids = tuple(ids)
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "gyrocal.kit", "emulate", "--pty",
             "--ids", ",".join(map(str, self.ids))],
            stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
        self.path = self.proc.stdout.readline().strip()
        self.frozen_at: float | None = None

    def freeze(self, *, fill: bool = False) -> int:
        """SIGSTOP the emulator; with ``fill``, write into its PTY until it takes no more.
        Returns the bytes written."""
        os.kill(self.proc.pid, signal.SIGSTOP)
        self.frozen_at = time.monotonic()
        return fill_tty(self.path) if fill else 0

    def close(self) -> None:
        """Thaw and stop the emulator."""
        if self.proc.poll() is None:
            os.kill(self.proc.pid, signal.SIGCONT)
            self.proc.terminate()
            self.proc.wait(timeout=30)
        self.proc.stdout.close()


def turning(recording: Path, rad: float = 0.2) -> bool:
    """Whether ``recording/encoder.csv`` (flushed row by row) has a servo ``rad`` from home."""
    try:
        rows = (recording / "encoder.csv").read_text().splitlines()[1:]
    except OSError:
        return False
    return any(abs(float(r.split(",")[2])) > rad for r in rows if r.count(",") == 2)


def freeze_when_turning(emulator: FrozenEmulator, recording: Path, *, fill: bool,
                        within_s: float = 120.0) -> threading.Thread:
    """Freeze ``emulator`` (see :meth:`FrozenEmulator.freeze`) once the run recording into
    ``recording`` has a servo turning, from a thread; the thread is returned started."""
    def watch() -> None:
        deadline = time.monotonic() + within_s
        while not turning(recording) and time.monotonic() < deadline:
            time.sleep(0.05)
        emulator.freeze(fill=fill)

    thread = threading.Thread(target=watch, daemon=True)
    thread.start()
    return thread


def _frozen_link(fill: bool) -> Callable[[Path], dict]:
    def setup(d: Path) -> dict:
        from bench.signal_rig import write_config

        emulator = FrozenEmulator()
        _EMULATORS.append(emulator)
        cfg = write_config(d / "gyrocal.toml", emulator.path, ids=emulator.ids, retries=30,
                           watchdog_s=2.5)
        freeze_when_turning(emulator, d / "run" / "recording", fill=fill)
        return {"argv": ["calibrate", "--sim-imu", "--config", str(cfg), "--out",
                         str(d / "run"), "--quiet"]}
    return setup


class FullDisk:
    """A disk that fills: the recording writer's files (:mod:`gyrocal.kit.recording`) and every
    atomic write (:mod:`gyrocal.kit.fileio`: ``manifest.json``, ``sim-state.json``, each plot)
    share ``left`` bytes (None: no limit) and ``files_left`` new atomic files (None: no limit;
    with ``files_in``, only those in a directory of that name count: ``"plots"``); past either,
    a write, a flush or a new file fails with ``OSError(ENOSPC)`` as on a full filesystem.
    Portable (no root, no small filesystem): ``patch`` is ``setattr`` in a subprocess, or
    pytest's ``monkeypatch.setattr``.
    """

    def __init__(self, patch: Callable[..., None], left: int | None,
                 files_left: int | None = None, files_in: str | None = None) -> None:
        import builtins
        import types

        from gyrocal.kit import fileio, recording

        self.left = left
        self.files_left = files_left
        disk = self

        class File:
            def __init__(self, fh: Any) -> None:
                self._fh = fh

            def write(self, text: str) -> int:
                disk.take(len(text))
                return self._fh.write(text)

            def flush(self) -> None:
                disk.take(0)
                self._fh.flush()

            def __getattr__(self, name: str) -> Any:
                return getattr(self._fh, name)

        def open_(path: Any, *args: Any, **kwargs: Any) -> File:
            return File(builtins.open(path, *args, **kwargs))

        def mkstemp(*args: Any, **kwargs: Any) -> tuple[int, str]:
            counts = files_in is None or Path(kwargs.get("dir", "")).name == files_in
            if disk.files_left is not None and counts:
                disk.files_left -= 1
            disk.take(0)
            return tempfile.mkstemp(*args, **kwargs)

        if patch is setattr:  # the module has no ``open`` of its own (builtins'), pytest needs
            recording.open = open_
        else:  # raising=False to add it
            patch(recording, "open", open_, raising=False)
        patch(fileio, "tempfile", types.SimpleNamespace(mkstemp=mkstemp))

    def take(self, n: int) -> None:
        """Use ``n`` bytes; ENOSPC once the space or the files are gone."""
        if self.left is not None:
            self.left -= n
        if (self.left is not None and self.left < 0) or \
                (self.files_left is not None and self.files_left < 0):
            raise OSError(errno.ENOSPC, "No space left on device")


#: The code a disk-full case runs instead of ``-m gyrocal.kit``: a :class:`FullDisk` with the
#: bytes, files and directory of ``sys.argv[1:4]`` ("-": none), then ``gyrocal`` with the rest.
_FULL_DISK_MAIN = (
    "import sys; sys.path.insert(0, {root!r}); from bench.attacks import FullDisk; "
    "lim = [None if a == '-' else int(a) for a in sys.argv[1:3]]; "
    "FullDisk(setattr, *lim, None if sys.argv[3] == '-' else sys.argv[3]); "
    "from gyrocal.kit.cli import main; sys.exit(main(sys.argv[4:]))")


def _disk_full(left: int | None, files_left: int | None, files_in: str | None
               ) -> Callable[[Path], dict]:
    def setup(d: Path) -> dict:
        argv = _calibrate(d, str(d / "out"))
        if files_in == "plots":
            argv.remove("--no-report")
        return {"argv": argv, "full_disk": (left, files_left, files_in)}
    return setup


def _disk_full_named(what: str) -> Callable:
    def check(d: Path, code: int | None, out: str, err: str) -> str | None:
        last = (err.strip().splitlines() or [""])[-1]
        if what == "recording":
            m = d / "out" / "recording" / "manifest.json"
            ok = (code == 2 and "the recording's imu.csv" in last and m.exists()
                  and json.loads(m.read_text()).get("complete") is False)
        else:  # the plots: the calibration kept, and the warning says so
            ok = (code in (0, 3) and (d / "out" / "calibration.json").exists()
                  and "calibration.json and the recording are complete" in err)
        return None if ok else "silent wrong"
    return check


#: Emulator processes the frozen-link cases started (ended after the case: :func:`run_case`).
_EMULATORS: list[FrozenEmulator] = []


def _link_message(d: Path, code: int | None, out: str, err: str) -> str | None:
    m = d / "run" / "recording" / "manifest.json"
    if code != 4 or "torque off" not in err or not m.exists() \
            or json.loads(m.read_text()).get("complete") is not False:
        return "silent wrong"
    return None


CASES: list[Case] = [
    Case("--force", "over user files", "refuse", _force_user_files, _kept("out/thesis.tex", "work"),
         timeout_s=180, before_jig=True),
    Case("--force", "user file beside a run", "refuse", _force_beside_run,
         _kept("out/notes.txt", "mine"), timeout_s=180, before_jig=True),
    Case("--force", "--out .", "refuse", _force_dot, _dot_check, timeout_s=180, before_jig=True),
    Case("--force", "--out SYMLINK", "refuse", _force_symlink, _symlink_check, timeout_s=180,
         before_jig=True),
    Case("--force", "keeps the user's mode", "ok", _force_mode, _mode_check, timeout_s=180),
    Case("verify", "own synthetic calibration", "ok", _verify_synthetic, _passed),
    Case("verify", "true calibration, jittered stamps", "ok", _verify_truth_jittered, _passed),
    Case("verify", "FIFO", "refuse", _verify_path("fifo"), timeout_s=20),
    Case("verify", "/dev/zero", "refuse", _verify_path("zero"), timeout_s=20),
    Case("verify", "symlink loop", "refuse", _verify_path("loop"), timeout_s=20),
    Case("verify", "a directory", "refuse", _verify_path("dir"), timeout_s=20),
    Case("units", "degrees throughout", "refuse", _estimate_of("degrees"), _no_cal_written),
    Case("units", "gx/gy swapped", "refuse", _estimate_of("swapped"), _no_cal_written),
    Case("units", "gx negated", "refuse", _estimate_of("negated"), _no_cal_written),
    Case("units", "right recording", "ok", _estimate_of("ok")),
    Case("units", "1_0.5 in imu.csv", "refuse", _estimate_of("underscore"), _no_cal_written),
    Case("units", "two motors, one id", "refuse", _estimate_of("duplicate id"), _no_cal_written),
    Case("units", "a truth with a string", "ok", _estimate_of("truth")),
    Case("formatters", "$..$ in paths (report)", "ok", _report_dollar, _plots_written),
    Case("formatters", "$..$ in a label (trend --plot)", "ok", _trend_dollar),
    Case("formatters", "escapes in history list", "ok", _history_escape, _no_escape),
    Case("formatters", "/* in the C header", "ok", _c_header, _compiles),
    Case("bounds", "TOML key of 50,000 parts", "refuse", _toml_depth),
    Case("bounds", "export - of 64 MB of NULs", "refuse", _stdin_export),
    Case("bounds", "apply - with a 100 MB line", "refuse", _stdin_apply),
    Case("bounds", "apply - times going backwards", "refuse", _apply_backwards),
    Case("bounds", "5000-digit integer", "refuse", _cal_text(
        '{"format": "gyrocal-calibration", "version": ' + "9" * 5000 + "}")),
    Case("bounds", "200,000-deep nesting", "refuse", _cal_text("[" * 200_000 + "]" * 200_000)),
    Case("bounds", "bias given twice", "refuse", _cal_text(
        _cal_doc()[:-2] + ', "bias": [1, 1, 1]}')),
    Case("history", "a document not JSON", "ok",
         _damaged_history("UPDATE calibrations SET document = 'x' WHERE id = 2"),
         _history_reads),
    Case("history", "an identity not JSON", "ok",
         _damaged_history("UPDATE sensors SET identity = '{x'"), _history_reads),
    Case("history", "created 9999-12-31 -01:00", "refuse", _created("9999-12-31T23:59:59-01:00")),
    Case("history", "created 0001-01-01 +01:00", "refuse", _created("0001-01-01T00:00:00+01:00")),
    Case("servo link", "adapter pulled mid-turn", "refuse", _pulled_adapter, _link_message,
         timeout_s=180),
    Case("servo link", "emulator frozen mid-turn", "refuse", _frozen_link(False),
         _link_message, timeout_s=120),
    Case("servo link", "port hung mid-turn (frozen, full)", "refuse", _frozen_link(True),
         _link_message, timeout_s=120),
    Case("disk full", "during the recording", "refuse", _disk_full(20_000, None, None),
         _disk_full_named("recording"), timeout_s=180),
    Case("disk full", "while plotting", "ok", _disk_full(None, 1, "plots"),
         _disk_full_named("plots"), timeout_s=300),
]

OUTCOMES = ["ok", "refused", "late refusal", "silent wrong", "exit 1 / traceback", "hang",
            "data lost", "bad message"]


def attack_matrix(cases: list[Case] | None = None) -> tuple[list[list[object]], list[Result]]:
    """Run the cases; rows of the audit table per area (and all), and every result."""
    root = Path(tempfile.mkdtemp(prefix="gyrocal-attacks-"))
    results = [run_case(c, root) for c in (CASES if cases is None else cases)]
    rows = []
    for area in [*dict.fromkeys(r.case.area for r in results), "all"]:
        mine = [r for r in results if area in ("all", r.case.area)]
        tally = Counter(r.outcome for r in mine)
        other = sum(v for k, v in tally.items() if k not in OUTCOMES)
        rows.append([area, len(mine), *[tally[k] for k in OUTCOMES], other])
    return rows, results
