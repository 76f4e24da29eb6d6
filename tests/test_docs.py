"""The documents are part of the product: every command in them must work.

Every fenced block of ``README.md`` and ``hardware_docs/*.md`` is run in the order a reader meets
them: ``README.md``, then the index ``hardware_docs/README.md``, then the pages in the order of the
index's table, each page's blocks in the order they appear; the documents that build on each
other's files share a working directory (a chain, :data:`CHAINS`), in which a command reads the
files every earlier command of its chain wrote (a chain's blocks that share no file with the rest
of it but its configurations, its branches of :data:`BRANCHES`, run in directories of their own,
so that a long chain runs on both xdist workers). An emulated ``gyrocal calibrate`` that a part
of a chain runs a second time under another name (:data:`SHARED_RUNS`: the same configuration and
jig arguments, so the same recording) is recorded once: the second run's command runs in full on
a copy of the first's recording (:class:`JigRuns`); and a report plot that a worker's documents
draw a second time from the same data is a copy of the first drawing (:class:`ReportPlots`). The
blocks:

* ``sh``/``bash``/``shell``/``console`` blocks: every ``gyrocal ...`` command (in ``console``
  blocks the lines after a ``$`` prompt; ``a && gyrocal b`` chains are split) runs in-process
  through :func:`gyrocal.kit.cli.main` and must exit 0. Other shell lines (``pip``, ``sudo``,
  ``cd``,
  ``i2cdetect``, ``udevadm``, ...) are not run.
* ``python`` blocks run with ``exec`` in the document's directory; ``c`` blocks with a ``main`` are
  compiled with ``-Wall -Wextra -Werror`` and run (skipped without a C compiler); ``toml`` blocks
  must be valid gyrocal configurations, and ``json`` blocks valid JSON (a Calibration v1 document
  must pass gyrocal's reader).

An HTML comment right before a block changes what happens to it:

``<!-- doctest: sim -->``
    add ``--sim`` to the commands that would talk to the jig (``calibrate``, ``doctor``,
    ``verify`` without ``--recording``, ``track --live``): the emulated jig stands in for it.
``<!-- doctest: file NAME -->``
    also write the block's text to ``NAME`` in the document's directory (a config the next
    commands read).
``<!-- doctest: exit N -->``
    the block's commands must exit ``N`` instead of 0.
``<!-- doctest: emulated-servo -->``
    run the Python block as a script with ``PORT 2`` as arguments, ``PORT`` being a factory-new
    servo emulated by ``gyrocal emulate --pty`` in a subprocess.
``<!-- doctest: skip (needs hardware: why) -->``
    do not run the block; the reason is required.
``<!-- doctest: output -->``
    the (``text``) block is what the document's last ``gyrocal`` command before it (in the
    block's part of its chain) printed on stdout, line by line (trailing spaces aside); a line
    ``...`` stands for any lines left out. A sample that no longer matches fails with the
    command's output.

Besides, the tables the documents promise to keep in step with the code are compared with it: the
configuration keys with :data:`gyrocal.kit.config.SCHEMA`, the exit codes with
:data:`gyrocal.kit.errors.EXIT_CODES`, the quoted error messages with the source, and the Recording
v1 and
Calibration v1 field lists with the files a real ``gyrocal calibrate --sim`` run wrote. Relative
links and their anchors must resolve.
"""

from __future__ import annotations

import contextlib
import io
import json
import os
import re
import select
import shlex
import shutil
import subprocess
import sys
import time
import tomllib
from collections.abc import Iterator
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any
from unittest import mock

import pytest

from gyrocal.calib.model import GyroCalibration, ModelChoice
from gyrocal.kit.cli import main as gyrocal_main
from gyrocal.kit.config import SCHEMA, load_config
from gyrocal.kit.errors import EXIT_CODES
from gyrocal.kit.recording import ENCODER_HEADER, IMU_HEADER, IMU_HEADER_ACCEL, SEGMENTS_HEADER

ROOT = Path(__file__).resolve().parents[1]
DOC_DIR = ROOT / "hardware_docs"


def reading_order() -> list[Path]:
    """README.md, the index, then the pages in the order of the index's table."""
    index = DOC_DIR / "README.md"
    linked = re.findall(r"^\|\s*\[[^\]]+\]\(([\w\-]+\.md)\)", index.read_text("utf-8"), re.M)
    pages = [DOC_DIR / name for name in dict.fromkeys(linked)]
    rest = sorted(set(DOC_DIR.glob("*.md")) - {index, *pages})
    return [ROOT / "README.md", index, *pages, *rest]


DOCS = reading_order()

SHELL_LANGS = {"sh", "bash", "shell", "console"}
FENCE = re.compile(r"^(\s*)```(\S*)\s*$")
MARKER = re.compile(r"^<!--\s*doctest:\s*(.*?)\s*-->$")
SHELL_OPERATORS = {"|", "||", ";", "&", ">", ">>", "<", "2>", "2>&1"}
#: The only directives a marker may carry (``skip`` needs a reason in parentheses).
DIRECTIVE = re.compile(
    r"^(sim|emulated-servo|output|file\s+(?P<file>[\w.\-]+)|exit\s+(?P<exit>\d+)"
    r"|skip\s+\((?P<reason>[^)]+)\))$"
)


def _name(path: Path) -> str:
    return str(path.relative_to(ROOT))


# --------------------------------------------------------------------------------- parsing
@dataclass(frozen=True)
class Block:
    """One fenced block of a document, with the marker that preceded it (if any)."""

    doc: str
    line: int
    lang: str
    text: str
    directive: str | None

    @property
    def where(self) -> str:
        return f"{self.doc}:{self.line}"


def parse_blocks(path: Path) -> list[Block]:
    """The fenced blocks of a Markdown file, in order; a marker binds to the next block only."""
    lines = path.read_text(encoding="utf-8").splitlines()
    blocks: list[Block] = []
    pending: tuple[int, str] | None = None
    i = 0
    while i < len(lines):
        stripped = lines[i].strip()
        marker = MARKER.match(stripped)
        fence = FENCE.match(lines[i])
        if marker:
            if pending is not None:
                raise AssertionError(f"{_name(path)}:{pending[0]}: marker not followed by a block")
            if not DIRECTIVE.match(marker.group(1)):
                raise AssertionError(f"{_name(path)}:{i + 1}: unknown doctest directive "
                                     f"{marker.group(1)!r}")
            pending = (i + 1, marker.group(1))
        elif fence:
            indent, lang = len(fence.group(1)), fence.group(2)
            body = []
            i += 1
            while i < len(lines) and lines[i].strip() != "```":
                body.append(lines[i][indent:] if lines[i][:indent].strip() == "" else lines[i])
                i += 1
            if i == len(lines):
                raise AssertionError(f"{_name(path)}: unterminated code block")
            start = i - len(body)
            blocks.append(Block(_name(path), start, lang, "\n".join(body) + "\n",
                                pending[1] if pending else None))
            pending = None
        elif stripped and pending is not None:
            raise AssertionError(f"{_name(path)}:{pending[0]}: a doctest marker must come right "
                                 "before its code block")
        i += 1
    if pending is not None:
        raise AssertionError(f"{_name(path)}:{pending[0]}: marker not followed by a block")
    return blocks


def shell_commands(block: Block) -> list[list[str]]:
    """The ``gyrocal`` commands of a shell block, as argv lists without the ``gyrocal``."""
    raw = block.text.splitlines()
    if block.lang == "console":
        raw = [line[2:] for line in raw if line.startswith("$ ")]
    logical: list[str] = []
    for line in raw:
        if logical and logical[-1].endswith("\\"):
            logical[-1] = logical[-1][:-1] + " " + line
        else:
            logical.append(line)
    out = []
    for line in logical:
        tokens = shlex.split(line, comments=True)
        part: list[str] = []
        for tok in [*tokens, "&&"]:
            if tok != "&&":
                part.append(tok)
                continue
            if part and part[0] == "gyrocal":
                bad = SHELL_OPERATORS.intersection(part)
                if bad:
                    raise AssertionError(f"{block.where}: a gyrocal command with shell operators "
                                         f"{sorted(bad)} cannot be checked: {line!r}")
                out.append(part[1:])
            part = []
    return out


def needs_jig(argv: list[str]) -> bool:
    """Whether a command talks to the jig (so that ``doctest: sim`` must add ``--sim``)."""
    if not argv:
        return False
    if argv[0] in ("calibrate", "doctor"):
        return True
    if argv[0] == "verify":
        return "--recording" not in argv
    return argv[0] == "track" and "--live" in argv


def table_rows(section: str) -> list[list[str]]:
    """The body rows of the Markdown table(s) in ``section``, as lists of cells."""
    rows = []
    for line in section.splitlines():
        line = line.strip()
        if not (line.startswith("|") and line.endswith("|")):
            continue
        cells = [c.strip() for c in re.split(r"(?<!\\)\|", line[1:-1])]
        if all(re.fullmatch(r":?-+:?", c) for c in cells):
            continue
        rows.append(cells)
    return rows[1:] if rows else rows  # drop the header row


def code_spans(cell: str) -> list[str]:
    """The contents of the inline code spans in a table cell (single or double backticks)."""
    spans = re.findall(r"``\s?(.+?)\s?``|`([^`]+)`", cell)
    return [a or b for a, b in spans]


def section(path: Path, start: str, end: str) -> str:
    """The text between two HTML-comment markers of a document."""
    text = path.read_text(encoding="utf-8")
    a, b = text.find(start), text.find(end)
    assert a >= 0 and b > a, f"{_name(path)}: no section between {start!r} and {end!r}"
    return text[a + len(start):b]


# --------------------------------------------------------------------------------- running
@dataclass
class DocRun:
    """What running one document's blocks produced."""

    workdir: Path
    log: list[str] = field(default_factory=list)
    skipped: list[str] = field(default_factory=list)
    seconds: float = 0.0
    #: The last ``gyrocal`` command run (its block and command line) and what it printed on
    #: stdout, for a ``doctest: output`` block.
    last_output: tuple[str, str] | None = None
    #: The ``doctest: output`` blocks compared.
    outputs_checked: list[str] = field(default_factory=list)


@contextlib.contextmanager
def _cwd(path: Path) -> Iterator[None]:
    old = os.getcwd()
    os.chdir(path)
    try:
        yield
    finally:
        os.chdir(old)


#: The arguments of ``gyrocal calibrate`` that say only what becomes of a recording once the jig
#: has made it (where the run goes, whether it replaces one, whether it is stored in a history,
#: whether a report is written, how the result is printed, whether an implausible result is
#: written): two runs that differ in these alone make the same recording (``calibrate.run`` in
#: ``kit/commands/calibrate.py`` reads them only around or after ``run_jig``).
AFTER_THE_JIG = frozenset({"out", "force", "history", "sensor_label", "json", "no_report",
                           "allow_implausible"})


@dataclass(frozen=True)
class _JigRun:
    """What one emulated jig run wrote in its run's directory (a copy), and printed."""

    files: Path
    stdout: str
    stderr: str
    jig: Any


class JigRuns:
    """The emulated jig's ``gyrocal calibrate`` runs made so far by one worker, by what defines
    their recording (:meth:`key`), each made once.

    The documents show one emulated run under several names: the README's ``gyrocal calibrate
    --sim`` and the index's ``--out demo``; running.md's ``run1`` and history.md's ``run-h``
    (stored in a history). The emulated jig records the same bytes for the same configuration,
    arguments and code (``tests/drivers/test_emulated_golden.py`` pins a seed's recording), so
    the second of these gets a copy of what the first's jig wrote in its directory (the
    recording, ``sim-state.json``), with the recording's ``created`` stamp made now as a new run
    would (:func:`gyrocal.kit.recording.now_iso`), and what the first's jig printed; everything
    of the command after the jig (the fit, ``calibration.json``, the report, the history, the
    printed result and exit code) runs for it as for the first (but for the report's plots that
    show nothing of the run's own, copies: :class:`ReportPlots`). A run that fails is not kept.
    Runs of other commands, with an ``extend``, or into a directory other than the run's
    ``recording/`` (a plate's sensors) always run.
    """

    def __init__(self, store: Path) -> None:
        from gyrocal.kit import jig

        self.store = store
        self.runs: dict[str, _JigRun] = {}
        self.replayed: list[str] = []
        self._jig_module = jig
        self._real = jig.run_jig

    @staticmethod
    def key(cfg: Any, args: Any) -> str | None:
        """What defines an emulated ``gyrocal calibrate`` run's recording: the configuration
        (with the command line's overrides) and every argument but :data:`AFTER_THE_JIG`; None
        for a run that is not one (another command, or the real jig)."""
        if getattr(args, "command", None) != "calibrate" or not getattr(args, "sim", False):
            return None
        fields = {k: v for k, v in sorted(vars(args).items()) if k not in AFTER_THE_JIG}
        return repr((cfg, fields))

    def installed(self) -> contextlib.AbstractContextManager[Any]:
        """``gyrocal.kit.jig.run_jig`` replaced by :meth:`run_jig` for the duration."""
        return mock.patch.object(self._jig_module, "run_jig", self.run_jig)

    def run_jig(self, cfg: Any, args: Any, out: Path, rec_dir: Path, extend: Any = None) -> Any:
        """:func:`gyrocal.kit.jig.run_jig`, made once per :meth:`key`."""
        key = self.key(cfg, args) if extend is None and rec_dir == out / "recording" else None
        if key is None:
            return self._real(cfg, args, out, rec_dir, extend)
        if key in self.runs:
            return self._replay(self.runs[key], out, rec_dir)
        before = set(out.iterdir())
        stdout, stderr = io.StringIO(), io.StringIO()
        try:
            with contextlib.redirect_stdout(stdout), contextlib.redirect_stderr(stderr):
                jig = self._real(cfg, args, out, rec_dir, extend)
        finally:
            sys.stdout.write(stdout.getvalue())
            sys.stderr.write(stderr.getvalue())
        files = self.store / f"run{len(self.runs)}"
        files.mkdir()
        for path in sorted(set(out.iterdir()) - before):
            (shutil.copytree if path.is_dir() else shutil.copy2)(path, files / path.name)
        self.runs[key] = _JigRun(files, stdout.getvalue(), stderr.getvalue(), jig)
        return jig

    def _replay(self, run: _JigRun, out: Path, rec_dir: Path) -> Any:
        from gyrocal.kit.recording import now_iso

        shutil.copytree(run.files, out, dirs_exist_ok=True)
        manifest = rec_dir / "manifest.json"
        text = manifest.read_text(encoding="utf-8")
        stamp = json.dumps(json.loads(text)["created"])
        manifest.write_text(text.replace(f'"created": {stamp}', f'"created": "{now_iso()}"', 1),
                            encoding="utf-8")
        sys.stdout.write(run.stdout)
        sys.stderr.write(run.stderr)
        self.replayed.append(str(rec_dir.resolve()))
        return run.jig


class ReportPlots:
    """The report plots drawn so far by one worker, by what each shows (:meth:`key`), each
    drawn once.

    The documents draw some plots twice from the same data: running.md's ``gyrocal report
    run1/recording run1/calibration.json`` draws every plot its ``gyrocal calibrate`` drew in
    ``run1/plots``, and the runs :class:`JigRuns` makes once (``demo``, ``run-h``) draw every
    plot of the first's but the overview, whose title names the recording's directory. A plot
    is a function of the recording's data and manifest, the calibration and the windows
    extracted (:func:`gyrocal.kit.report_plots._draw`; the recording's path is shown by the
    overview only, the calibration's ``created`` and ``source`` by none), drawn by the same
    code in the same process, so the second gets the bytes of the first's file, written where
    and as the second's would have been (``atomic_write_bytes``, refusing an existing file
    without ``force`` as ``save_png`` does); everything else of the command (the fit, the other
    plots, the page) runs. ``copied`` lists the files so made.
    """

    def __init__(self) -> None:
        from gyrocal.kit import report_plots

        self._module = report_plots
        self._real = report_plots._draw
        self.drawn: dict[str, bytes] = {}
        self.copied: list[str] = []
        #: The digest of each (recording, calibration, windows) seen, kept with them (their ids
        #: are not reused while they are held here).
        self._digests: dict[tuple[int, int, int], tuple[Any, str]] = {}

    @staticmethod
    def key(p: Any, rec: Any, cal: Any, extracted: Any, data: str) -> str:
        """What defines plot ``p``'s file: the plot, ``data`` (:meth:`digest` of what it is
        drawn from), and for the overview the recording's path."""
        import hashlib
        import pickle

        shown = str(rec.path) if p.kind == "overview" else None
        return hashlib.sha256(pickle.dumps((p, shown, data))).hexdigest()

    @staticmethod
    def digest(rec: Any, cal: Any, extracted: Any) -> str:
        """A digest of what a report's plots are drawn from: the recording's arrays, segments
        and manifest (but its ``created`` stamp), the calibration (but its ``created`` and
        ``source``) and the windows."""
        import hashlib
        import pickle

        manifest = {k: v for k, v in rec.manifest.items() if k != "created"}
        doc = {k: v for k, v in cal.to_dict().items() if k not in ("created", "source")}
        arrays = (rec.imu_t, rec.imu_rate, rec.imu_temp, rec.enc_t, rec.enc_motor,
                  rec.enc_angle, rec.segments, rec.warnings, rec.imu_accel)
        return hashlib.sha256(pickle.dumps((
            json.dumps(manifest, sort_keys=True, default=repr),
            json.dumps(doc, sort_keys=True, default=repr), arrays, extracted))).hexdigest()

    def installed(self) -> contextlib.AbstractContextManager[Any]:
        """``gyrocal.kit.report_plots._draw`` replaced by :meth:`draw` for the duration."""
        return mock.patch.object(self._module, "_draw", self.draw)

    def draw(self, plt: Any, p: Any, out: Path, rec: Any, cal: Any, extracted: Any,
             turns: Any, home: Any, axes: Any, index: Any, force: bool) -> tuple[Path, str]:
        """:func:`gyrocal.kit.report_plots._draw`, each plot drawn once per :meth:`key`."""
        from gyrocal.kit.fileio import atomic_write_bytes

        ids = (id(rec), id(cal), id(extracted))
        if ids not in self._digests:
            self._digests[ids] = ((rec, cal, extracted), self.digest(rec, cal, extracted))
        key = self.key(p, rec, cal, extracted, self._digests[ids][1])
        if key in self.drawn:
            path = atomic_write_bytes(out / p.name, self.drawn[key], force=force)
            self.copied.append(str(path.resolve()))
            return path, p.description
        written = self._real(plt, p, out, rec, cal, extracted, turns, home, axes, index, force)
        self.drawn[key] = Path(written[0]).read_bytes()
        return written


@dataclass
class Shares:
    """What one worker's document runs share: the emulated jig's runs (:class:`JigRuns`) and
    the report plots (:class:`ReportPlots`)."""

    jig: JigRuns
    plots: ReportPlots

    @contextlib.contextmanager
    def installed(self) -> Iterator[None]:
        """Both in place for the duration."""
        with self.jig.installed(), self.plots.installed():
            yield


def _run_gyrocal(argv: list[str], where: str, expect: int, log: list[str],
                 shares: Shares | None = None) -> str:
    """Run ``gyrocal argv`` in-process; it must exit ``expect``. Returns what it printed on
    stdout."""
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err), \
            (shares.installed() if shares else contextlib.nullcontext()):
        code = gyrocal_main(argv)
    log.append(f"{where}: gyrocal {shlex.join(argv)} -> {code}")
    if code != expect:
        raise AssertionError(
            f"{where}: `gyrocal {shlex.join(argv)}` exited {code}, expected {expect}\n"
            f"--- stdout ---\n{out.getvalue()[-3000:]}\n--- stderr ---\n{err.getvalue()[-3000:]}"
        )
    return out.getvalue()


def sample_matches(sample: str, printed: str) -> bool:
    """Whether a document's sample output is what a command printed: line by line, trailing
    spaces aside, a sample line ``...`` standing for any number of printed lines."""
    want = [line.rstrip() for line in sample.rstrip("\n").split("\n")]
    got = [line.rstrip() for line in printed.rstrip("\n").split("\n")]
    pattern = "".join(r"(?:[^\n]*\n)*?" if line == "..." else re.escape(line + "\n")
                      for line in want)
    return re.fullmatch(pattern, "\n".join(got) + "\n", flags=re.S) is not None


def _run_shell_block(block: Block, expect: int, run: DocRun, shares: Shares | None) -> None:
    """Run the ``gyrocal`` commands of a shell block (with ``--sim`` added to the jig's under
    ``doctest: sim``); each must exit ``expect``."""
    commands = shell_commands(block)
    if block.directive == "sim":
        assert any(needs_jig(c) for c in commands), (
            f"{block.where}: 'doctest: sim' on a block with no jig command")
    for argv in commands:
        if block.directive == "sim" and needs_jig(argv) and "--sim" not in argv:
            argv = [*argv, "--sim"]
        printed = _run_gyrocal(argv, block.where, expect, run.log, shares)
        run.last_output = (f"{block.where}: gyrocal {shlex.join(argv)}", printed)


def _check_output(block: Block, run: DocRun) -> None:
    """A ``doctest: output`` block against what the document's last command printed."""
    assert block.lang in ("text", ""), f"{block.where}: 'doctest: output' on a {block.lang} block"
    assert run.last_output is not None, f"{block.where}: 'doctest: output' after no command"
    command, printed = run.last_output
    assert sample_matches(block.text, printed), (
        f"{block.where}: the sample is not what `{command}` prints now; it printed:\n{printed}")
    run.outputs_checked.append(block.where)


def _exec_python(block: Block, argv: list[str] | None = None) -> None:
    code = compile(block.text, block.where, "exec")
    old_argv = sys.argv
    if argv is not None:
        sys.argv = argv
    out = io.StringIO()
    try:
        with contextlib.redirect_stdout(out):
            exec(code, {"__name__": "__main__"})  # the documents' own examples
    except SystemExit as exc:
        if exc.code not in (None, 0):
            raise AssertionError(f"{block.where}: the script exited with {exc.code!r}\n"
                                 f"{out.getvalue()}") from None
    finally:
        sys.argv = old_argv


@contextlib.contextmanager
def _emulated_servo() -> Iterator[str]:
    """A factory-new servo (ID 1, 57 600 bps) behind a pseudo-terminal; yields its device."""
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    proc = subprocess.Popen(
        [sys.executable, "-m", "gyrocal.kit", "emulate", "--pty", "--ids", "1", "--baud", "57600",
         "--duration", "60"],
        cwd=ROOT, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )
    try:
        ready, _, _ = select.select([proc.stdout], [], [], 30)
        assert ready, "gyrocal emulate --pty printed no device path within 30 s"
        device = proc.stdout.readline().strip()  # type: ignore[union-attr]
        assert device.startswith("/dev/"), f"gyrocal emulate --pty printed {device!r}"
        yield device
    finally:
        proc.terminate()
        try:
            proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()


def _run_c(block: Block, workdir: Path, run: DocRun) -> None:
    cc = shutil.which("cc") or shutil.which("gcc") or shutil.which("clang")
    if cc is None:
        run.skipped.append(f"{block.where}: no C compiler")
        return
    src = workdir / f"example_{block.line}.c"
    src.write_text(block.text, encoding="utf-8")
    exe = workdir / f"example_{block.line}"
    done = subprocess.run([cc, "-std=c99", "-Wall", "-Wextra", "-Werror", "-o", str(exe),
                           str(src), "-lm"], cwd=workdir, capture_output=True, text=True,
                          check=False)
    assert done.returncode == 0, f"{block.where}: does not compile:\n{done.stderr}"
    ran = subprocess.run([str(exe)], cwd=workdir, capture_output=True, text=True, check=False,
                         timeout=30)
    assert ran.returncode == 0, f"{block.where}: exited {ran.returncode}:\n{ran.stderr}"
    run.log.append(f"{block.where}: C example printed {ran.stdout.strip()!r}")


def run_document(path: Path, workdir: Path, part: str | None = None,
                 shares: Shares | None = None) -> DocRun:
    """Run the blocks of ``path`` that belong to ``part`` of its chain (the branch of that name,
    or with None the rest: :func:`block_branch`) in order in ``workdir``. The ``doctest: file``
    blocks of every part write their files in every part: a later command of any part may read
    them (a configuration in the working directory is read without being named). With
    ``shares``, an emulated calibration run already made gives its recording (:class:`JigRuns`)
    and a report plot already drawn from the same data its file (:class:`ReportPlots`)."""
    run = DocRun(workdir)
    chain = chain_of(path)
    t0 = time.perf_counter()
    with _cwd(workdir):
        for block in parse_blocks(path):
            d = DIRECTIVE.match(block.directive) if block.directive else None
            mine = block_branch(chain, block) == part
            if d and d.group("reason"):
                if mine:
                    run.skipped.append(f"{block.where}: {d.group('reason')}")
                continue
            if d and d.group("file"):
                (workdir / d.group("file")).write_text(block.text, encoding="utf-8")
            if not mine:
                continue
            expect = int(d.group("exit")) if d and d.group("exit") else 0
            if block.directive == "output":
                _check_output(block, run)
            elif block.lang in SHELL_LANGS:
                _run_shell_block(block, expect, run, shares)
            elif block.lang == "python":
                if block.directive == "emulated-servo":
                    with _emulated_servo() as device:
                        _exec_python(block, ["script.py", device, "2"])
                else:
                    _exec_python(block)
                run.log.append(f"{block.where}: python block ran")
            elif block.lang == "c" and re.search(r"\bint\s+main\s*\(", block.text):
                _run_c(block, workdir, run)
            elif block.lang == "json":
                doc = json.loads(block.text)
                if isinstance(doc, dict) and doc.get("format") == "gyrocal-calibration":
                    GyroCalibration.from_dict(doc)  # raises CalibrationFormatError
            elif block.lang == "toml":
                name = d.group("file") if d and d.group("file") else f"check_{block.line}.toml"
                cfg_path = workdir / name
                if not cfg_path.exists():
                    cfg_path.write_text(block.text, encoding="utf-8")
                load_config(cfg_path)  # raises InputError naming the bad key
            else:
                assert block.directive is None or (d and d.group("file")), (
                    f"{block.where}: directive {block.directive!r} on a {block.lang or 'plain'} "
                    "block does nothing")
    run.seconds = time.perf_counter() - t0
    return run


#: The documents' chains. A chain's documents run in reading order in one directory of the
#: chain's own, each after the ones before it (a command reads what the earlier ones wrote, and a
#: second ``--out`` of the same name fails as it would for the reader); the chains share no
#: directory, so under pytest-xdist they run on different workers at once (``tests/conftest.py``
#: hands out the longest work units first, by their wall seconds in ``LONG_UNITS``: a chain added
#: here belongs there too). A document that needs a file of
#: another chain fails, as it would for a reader who skipped that page; what one directory for
#: all caught across chains (two documents writing one output) is checked by
#: ``test_no_two_documents_write_one_output``.
CHAINS: dict[str, tuple[str, ...]] = {
    # using.md and history.md read running.md's run1 and its gyrocal.toml
    "running": ("hardware_docs/running.md", "hardware_docs/using.md", "hardware_docs/history.md",
                "hardware_docs/formats.md", "hardware_docs/method.md"),
    # the single-servo jig's page runs its own emulated run
    "single-servo": ("hardware_docs/single-servo.md",),
    "intro": ("README.md", "hardware_docs/README.md", "hardware_docs/bom.md",
              "hardware_docs/wiring.md", "hardware_docs/chips.md", "hardware_docs/mechanical.md",
              "hardware_docs/setup.md"),
    # the hand jig's page writes and reads its own run (hand1)
    "hand": ("hardware_docs/hand-jig.md",),
}


#: Branches of a chain: blocks that read nothing the rest of their chain writes (beyond its
#: ``doctest: file`` blocks) and write nothing the rest reads, split off so that a long chain runs
#: on both xdist workers at once (``tests/conftest.py``). ``chain -> {branch: outputs}``: a block
#: belongs to the branch whose outputs (a directory or file of the document's directory) one of
#: its commands names, as ``--out`` or as an input (:func:`block_branch`); every other block to
#: the chain's main part. A branch runs in a directory of its own, in which the chain's
#: ``doctest: file`` blocks are written in their place in reading order and nothing else of the
#: main part runs, so a branch block that read a main part's output, or a main block that read a
#: branch's, would fail as it would for a reader who skipped it.
BRANCHES: dict[str, dict[str, tuple[str, ...]]] = {
    # running.md's two-sensor plate (plate1) and using.md's warm-up (five emulated
    # calibrations, warmup) read only gyrocal.toml and plate.toml
    "running": {"plate": ("plate1",), "thermal": ("warmup",)},
    # not the index's emulated run (demo): it is the README's run under another name, made once
    # with it in the chain's main part (JigRuns)
}


def _names(block: Block) -> list[str]:
    """The words of a block that may be paths: its commands' arguments (shell blocks) or its
    path-like words (other blocks)."""
    if block.lang in SHELL_LANGS:
        return [arg for argv in shell_commands(block) for arg in argv]
    return re.findall(r"[\w.\-/]+", block.text)


def block_branch(chain: str, block: Block) -> str | None:
    """The branch of ``chain`` (:data:`BRANCHES`) that ``block`` belongs to, or None for the
    chain's main part."""
    names = [os.path.normpath(n) for n in _names(block)]
    hits = {branch for branch, outputs in BRANCHES.get(chain, {}).items()
            if any(n == out or n.startswith(out + "/") for n in names for out in outputs)}
    assert len(hits) <= 1, f"{block.where} names the outputs of branches {sorted(hits)}"
    return hits.pop() if hits else None


def branch_ids() -> list[str]:
    """Every branch as ``chain/branch``."""
    return [f"{chain}/{branch}" for chain, branches in BRANCHES.items() for branch in branches]


def chain_of(path: Path | str) -> str:
    """The name of the chain that runs document ``path``."""
    name = path if isinstance(path, str) else _name(path)
    for chain, names in CHAINS.items():
        if name in names:
            return chain
    raise AssertionError(f"{name} is in no chain: add it to tests.test_docs.CHAINS")


def xdist_unit(nodeid: str) -> str | None:
    """The scheduling unit of a test of this module that runs a chain (the chain's name under
    this module), or None for a test that runs none (``tests/conftest.py``)."""
    module, _, test = nodeid.partition("::")
    name, _, param = test.partition("[")
    if param.rstrip("]") in branch_ids():
        return f"{module}::{param.rstrip(']')}"
    if param.rstrip("]") in {n for names in CHAINS.values() for n in names}:
        return f"{module}::{chain_of(param.rstrip(']'))}"
    chain = USES_CHAIN.get(name)
    return f"{module}::{chain}" if chain else None


#: The chain each test that is not parametrized by a document reads (:func:`uses_chain`).
USES_CHAIN: dict[str, str] = {}


def uses_chain(chain: str) -> Any:
    """Declare that a test reads the files of ``chain``'s documents, so the scheduler puts it
    with them; the ``docs`` fixture refuses any other chain to such a test."""
    def mark(fn: Any) -> Any:
        USES_CHAIN[fn.__name__] = chain
        return fn
    return mark


class DocRunner:
    """Runs each part of each chain (its main part, and each branch: :data:`BRANCHES`) once per
    worker, the chain's documents in reading order in the part's own directory (as a reader
    would), and remembers what each produced; an emulated calibration that two documents of a
    part run under different names is made once (:class:`JigRuns`), and a report plot drawn
    twice from the same data is drawn once (:class:`ReportPlots`)."""

    def __init__(self, factory: pytest.TempPathFactory) -> None:
        self.factory = factory
        self.workdirs: dict[tuple[str, str | None], Path] = {}
        self.runs: dict[tuple[str, str | None], DocRun] = {}
        self.failures: dict[tuple[str, str | None], BaseException] = {}
        self.jig_runs = JigRuns(factory.mktemp("jig-runs"))
        self.report_plots = ReportPlots()
        self.shares = Shares(self.jig_runs, self.report_plots)

    def __call__(self, path: Path, part: str | None = None) -> DocRun:
        chain = chain_of(path)
        names = CHAINS[chain]
        if (chain, part) not in self.workdirs:
            where = f"docs-{chain}" + (f"-{part}" if part else "")
            self.workdirs[chain, part] = self.factory.mktemp(where)
        for key in names[: names.index(_name(path)) + 1]:
            if (key, part) in self.failures:
                if key == _name(path):
                    raise self.failures[key, part]
                raise AssertionError(f"{key}, read before {_name(path)}, failed: "
                                     f"{self.failures[key, part]}")
            if (key, part) not in self.runs:
                try:
                    self.runs[key, part] = run_document(ROOT / key, self.workdirs[chain, part],
                                                        part, self.shares)
                except BaseException as exc:  # remember, so a second caller sees the same failure
                    self.failures[key, part] = exc
                    raise
        return self.runs[_name(path), part]


@pytest.fixture(scope="module")
def doc_runner(tmp_path_factory: pytest.TempPathFactory) -> DocRunner:
    return DocRunner(tmp_path_factory)


@pytest.fixture
def docs(doc_runner: DocRunner, request: pytest.FixtureRequest) -> Any:
    """The runner, for the chains this test may read: its document's, or the one it declares
    with :func:`uses_chain` (so the scheduler's units hold every test of a chain)."""
    param = getattr(request.node, "callspec", None)
    doc = param.params.get("path") if param else None
    allowed = chain_of(doc) if doc is not None else USES_CHAIN.get(request.node.originalname)

    def run(path: Path) -> DocRun:
        assert chain_of(path) == allowed, (
            f"{request.node.name} reads {_name(path)} of the chain {chain_of(path)!r}: declare "
            "it with @uses_chain so that it runs with that chain")
        return doc_runner(path)
    return run


# --------------------------------------------------------------------------------- tests
@pytest.mark.parametrize("path", DOCS, ids=_name)
def test_every_command_in_the_document_works(path: Path, docs: Any) -> None:
    run = docs(path)
    samples = [b.where for b in parse_blocks(path)
               if b.directive == "output" and block_branch(chain_of(path), b) is None]
    assert run.outputs_checked == samples, "a 'doctest: output' sample was not compared"
    for reason in run.skipped:
        assert "needs hardware" in reason or "no C compiler" in reason, (
            f"a skipped block must say which hardware it needs: {reason}")


@pytest.mark.parametrize("branch", branch_ids())
def test_every_command_of_a_branch_works(branch: str, doc_runner: DocRunner) -> None:
    chain, _, part = branch.partition("/")
    names = CHAINS[chain]
    doc_runner(ROOT / names[-1], part)
    runs = [doc_runner.runs[name, part] for name in names]
    assert any(": gyrocal " in line for run in runs for line in run.log), f"{branch} ran nothing"
    for reason in (r for run in runs for r in run.skipped):
        assert "needs hardware" in reason or "no C compiler" in reason, (
            f"a skipped block must say which hardware it needs: {reason}")


#: The emulated calibrations the documents show again under another name, by chain: (the first
#: run's directory, a glob; the second's), the second made from a copy of the first's recording
#: (:class:`JigRuns`).
SHARED_RUNS: dict[str, tuple[str, str]] = {
    "intro": ("gyrocal-*", "demo"),  # the README's `gyrocal calibrate --sim`, the index's
    "running": ("run1", "run-h"),  # running.md's, history.md's (stored in a history)
}


def _check_shared_run(doc_runner: DocRunner, chain: str) -> None:
    first, again = SHARED_RUNS[chain]
    doc_runner(ROOT / CHAINS[chain][-1])
    workdir = doc_runner.workdirs[chain, None]
    (a,) = (p / "recording" for p in workdir.glob(first))
    b = workdir / again / "recording"
    assert str(b.resolve()) in doc_runner.jig_runs.replayed, (
        f"{chain}: {again} no longer makes the same emulated run as {first} (JigRuns.key): "
        f"its recording was made again; list it in SHARED_RUNS only if it should be shared")
    assert sorted(p.name for p in b.iterdir()) == sorted(p.name for p in a.iterdir())
    for path in sorted(a.iterdir()):
        got, want = (b / path.name).read_text(), path.read_text()
        if path.name == "manifest.json":  # the created stamp is the run's own
            got, want = ({k: v for k, v in json.loads(t).items() if k != "created"}
                         for t in (got, want))
        assert got == want, f"{b / path.name} is not {path}"
    _check_copied_plots(doc_runner, a.parent / "plots", b.parent / "plots", {"overview.png"})


def _check_copied_plots(doc_runner: DocRunner, first: Path, again: Path,
                        drawn: set[str]) -> None:
    """``again`` holds the plots of ``first``, each a copy (:class:`ReportPlots`) but those of
    ``drawn``, which were drawn (they show something of their own)."""
    names = sorted(p.name for p in first.glob("*.png"))
    assert names and sorted(p.name for p in again.glob("*.png")) == names
    copied = set(doc_runner.report_plots.copied)
    for name in names:
        was_copied = str((again / name).resolve()) in copied
        assert was_copied == (name not in drawn), (
            f"{again / name}: {'copied' if was_copied else 'drawn again'} (ReportPlots.key)")
        if name not in drawn:
            assert (again / name).read_bytes() == (first / name).read_bytes()


@uses_chain("running")
def test_the_report_command_copies_the_plots_calibrate_drew(doc_runner: DocRunner) -> None:
    # running.md's `gyrocal report run1/recording run1/calibration.json --out run1/report`
    # draws from what `gyrocal calibrate --out run1` drew from: every plot is a copy
    doc_runner(ROOT / CHAINS["running"][0])
    run1 = doc_runner.workdirs["running", None] / "run1"
    _check_copied_plots(doc_runner, run1 / "plots", run1 / "report", set())


@uses_chain("running")
def test_a_copied_plot_is_the_plot_drawn_again(doc_runner: DocRunner, tmp_path: Path) -> None:
    # the premise of ReportPlots: the same data draw the same bytes. run1/report/overview.png
    # was copied from run1/plots; drawn again here from what the report command reads
    from gyrocal.kit.exports import load_document
    from gyrocal.kit.pipeline import judged_windows
    from gyrocal.kit.plots import require_matplotlib
    from gyrocal.kit.recording import load_recording
    from gyrocal.kit.report_plots import plan_report

    doc_runner(ROOT / CHAINS["running"][0])
    workdir = doc_runner.workdirs["running", None]
    copy = workdir / "run1" / "report" / "overview.png"
    assert str(copy.resolve()) in doc_runner.report_plots.copied
    with _cwd(workdir):
        rec = load_recording("run1/recording")
        cal = load_document("run1/calibration.json", "gyrocal-calibration", "calibration")
        extracted = judged_windows(rec)[0]  # as kit/commands/report.py reads them
        (plot,) = (p for p in plan_report(rec, extracted) if p.kind == "overview")
        plots = doc_runner.report_plots
        path, _ = plots._real(require_matplotlib(), plot, tmp_path, rec, cal, extracted,
                              None, None, None, None, False)
        assert path.read_bytes() == copy.read_bytes()
        # what the key holds: the data drawn, not when or from where the calibration was made
        data = plots.digest(rec, cal, extracted)
        assert plots.key(plot, rec, cal, extracted, data) in plots.drawn
        stamped = replace(cal, created="2000-01-01T00:00:00+00:00", source="elsewhere")
        assert plots.digest(rec, stamped, extracted) == data
        assert plots.digest(rec, replace(cal, bias=(0.0, 0.0, 0.0)), extracted) != data
        moved = replace(rec, path=Path("elsewhere"))
        turn = next(p for p in plan_report(rec, extracted) if p.kind == "turn")
        assert plots.key(plot, moved, cal, extracted, data) != plots.key(
            plot, rec, cal, extracted, data)
        assert plots.key(turn, moved, cal, extracted, data) == plots.key(
            turn, rec, cal, extracted, data)


@uses_chain("intro")
def test_the_index_demo_run_is_the_readme_run_recorded_once(doc_runner: DocRunner) -> None:
    _check_shared_run(doc_runner, "intro")


@uses_chain("running")
def test_history_md_run_is_running_md_run_recorded_once(doc_runner: DocRunner) -> None:
    _check_shared_run(doc_runner, "running")


def test_an_emulated_run_is_shared_only_by_runs_that_record_the_same(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from gyrocal.kit.cli import build_parser
    from gyrocal.kit.jig import load_cli_config

    monkeypatch.chdir(tmp_path)
    (tmp_path / "other.toml").write_text("[imu]\nodr_hz = 100\n", encoding="utf-8")

    def key(*argv: str) -> str | None:
        args = build_parser(list(argv)).parse_args(list(argv))
        return JigRuns.key(load_cli_config(args), args)

    base = key("calibrate", "--sim")
    assert base is not None
    # what becomes of the recording: the same run
    assert key("calibrate", "--sim", "--out", "demo", "--force", "--json", "--no-report",
               "--history", "sqlite:///h.sqlite", "--sensor-label", "imu-07",
               "--allow-implausible") == base
    # what the jig records or prints: another run
    for other in (["--sim-seed", "1"], ["--sim-noise-seed", "5"], ["--config", "other.toml"],
                  ["--protocol", "auto"], ["--odr", "100"], ["--sim-without", "wobble"],
                  ["--jig", "single-servo"], ["--quiet"]):
        assert key("calibrate", "--sim", *other) not in (base, None), other
    # the real jig, and other commands, always run
    assert key("calibrate") is None
    assert key("verify", "run1/calibration.json", "--sim") is None


def _outputs(blocks: list[Block]) -> set[str]:
    """What the ``gyrocal`` commands of ``blocks`` write with ``--out``."""
    return {os.path.normpath(value) for block in blocks if block.lang in SHELL_LANGS
            for argv in shell_commands(block)
            for flag, value in zip(argv, argv[1:], strict=False) if flag == "--out"}


def test_each_branch_writes_its_outputs_and_reads_none_of_the_main_part() -> None:
    # a branch's outputs are written by its commands, and its blocks name nothing a main-part
    # command writes (block_branch refuses a block naming two branches' outputs)
    for branch in branch_ids():
        chain, _, part = branch.partition("/")
        blocks = [b for name in CHAINS[chain] for b in parse_blocks(ROOT / name)]
        mine = [b for b in blocks if block_branch(chain, b) == part]
        assert set(BRANCHES[chain][part]) <= _outputs(mine), f"{branch}: an output not written"
        main = _outputs([b for b in blocks if block_branch(chain, b) is None])
        for block in mine:
            clash = {n for n in map(os.path.normpath, _names(block)) for out in main
                     if n == out or n.startswith(out + "/")}
            assert not clash, f"{block.where} ({branch}) reads {sorted(clash)} of the main part"


def test_the_chains_hold_every_document_once_in_reading_order() -> None:
    listed = [n for names in CHAINS.values() for n in names]
    assert sorted(listed) == sorted(_name(p) for p in DOCS), (
        "tests.test_docs.CHAINS must list every document once")
    order = [_name(p) for p in DOCS]
    for chain, names in CHAINS.items():
        assert list(names) == sorted(names, key=order.index), f"{chain}: not in reading order"


def _commands() -> list[tuple[Block, list[str]]]:
    """Every ``gyrocal`` command the documents' tests run, with its block."""
    out = []
    for path in DOCS:
        for block in parse_blocks(path):
            d = DIRECTIVE.match(block.directive) if block.directive else None
            if block.lang in SHELL_LANGS and not (d and d.group("reason")):
                out.extend((block, argv) for argv in shell_commands(block))
    return out


def test_the_documents_run_gyrocal_commands_and_few_blocks_are_skipped() -> None:
    # each command counted here is run, its exit code checked, by
    # test_every_command_in_the_document_works
    assert len(_commands()) >= 15
    skipped = [b.where for p in DOCS for b in parse_blocks(p)
               if b.directive and (d := DIRECTIVE.match(b.directive)) and d.group("reason")]
    if not (shutil.which("cc") or shutil.which("gcc") or shutil.which("clang")):
        skipped += [b.where for p in DOCS for b in parse_blocks(p)
                    if b.lang == "c" and re.search(r"\bint\s+main\s*\(", b.text)]
    assert len(skipped) <= 3, skipped


def test_a_sample_output_matches_only_what_was_printed() -> None:
    printed = "a\nb 1.00\nc\nd\n"
    assert sample_matches("a\nb 1.00\nc\nd\n", printed)
    assert sample_matches("a   \nb 1.00\nc\nd", printed)  # trailing spaces and newline aside
    assert sample_matches("a\n...\nd\n", printed)
    assert sample_matches("a\n...\nb 1.00\nc\nd\n", printed)  # `...` for no line
    assert not sample_matches("a\nb 1.01\nc\nd\n", printed)  # a stale figure
    assert not sample_matches("a\nb 1.00\nc\n", printed)  # a line left out without `...`
    assert not sample_matches("a\nb 1\n...\nd\n", printed)  # part of a line
    assert not sample_matches("a\nb 1.00\nc\nd\ne\n", printed)  # a line not printed
    # the documents compare samples: setup.md's doctor, running.md's calibrate
    marked = [b.where for p in DOCS for b in parse_blocks(p) if b.directive == "output"]
    assert len(marked) >= 2, marked


def test_no_two_documents_write_one_output() -> None:
    # in one directory for all, a second `--out X` failed (gyrocal refuses to overwrite); the
    # chains have a directory each, so the same name in two of them would pass unnoticed
    seen: dict[str, str] = {}
    for block, argv in _commands():
        for flag, value in zip(argv, argv[1:], strict=False):
            if flag != "--out":
                continue
            target = os.path.normpath(value)
            assert target not in seen or "--force" in argv, (
                f"{block.where} writes {value}, which {seen.get(target)} wrote already")
            seen[target] = block.where


def test_config_table_lists_exactly_the_schema() -> None:
    rows = table_rows(section(DOC_DIR / "running.md", "<!-- config-table -->",
                              "<!-- /config-table -->"))
    keys = [code_spans(r[0])[0] for r in rows]
    schema_keys = [f"{s}.{k}" for s, ks in SCHEMA.items() for k in ks]
    assert keys == schema_keys, "the config table must list SCHEMA's keys in SCHEMA's order"
    for row in rows:
        dotted = code_spans(row[0])[0]
        section_name, name = dotted.split(".")
        key = SCHEMA[section_name][name]
        (default_text,) = code_spans(row[1])
        default = tomllib.loads(f"v = {default_text}")["v"]
        assert default == key.default and type(default) is type(key.default), (
            f"{dotted}: the table says {default_text}, the schema {key.default!r}")
        if key.choices is not None:
            allowed = tuple(tomllib.loads(f"v = {c}")["v"] for c in code_spans(row[2]))
            assert allowed == key.choices, f"{dotted}: allowed {allowed} != {key.choices}"


def test_exit_code_table_matches_the_code() -> None:
    rows = table_rows(section(DOC_DIR / "running.md", "<!-- exit-codes -->",
                              "<!-- /exit-codes -->"))
    assert [int(r[0]) for r in rows] == list(EXIT_CODES)


def test_quoted_messages_exist_in_the_code() -> None:
    source = "\n".join(p.read_text(encoding="utf-8")
                       for pkg in ("kit", "drivers", "calib") for p in (ROOT / pkg).rglob("*.py"))
    checked = 0
    for doc in DOCS:
        text = doc.read_text(encoding="utf-8")
        for part in text.split("<!-- messages -->")[1:]:
            assert "<!-- /messages -->" in part, f"{_name(doc)}: unterminated messages table"
            for row in table_rows(part.split("<!-- /messages -->")[0]):
                for fragment in code_spans(row[0]):
                    assert fragment in source, (
                        f"{_name(doc)} quotes {fragment!r}, which no message in the code has")
                    checked += 1
                kind = row[1]
                assert kind in ("FAIL", "warn") or int(kind) in EXIT_CODES, (
                    f"{_name(doc)}: {kind!r} is neither an exit code nor a doctor line kind")
    assert checked >= 40


def _paths(obj: Any, prefix: str = "") -> set[str]:
    """Field paths of a JSON document: ``a.b``, ``list[].field``, numeric keys as ``<id>``."""
    out = {prefix} if prefix else set()
    if isinstance(obj, dict):
        for k, v in obj.items():
            key = "<id>" if re.fullmatch(r"\d+", str(k)) else str(k)
            out |= _paths(v, f"{prefix}.{key}" if prefix else key)
    elif isinstance(obj, list) and obj and all(isinstance(x, dict) for x in obj):
        for x in obj:
            out |= _paths(x, f"{prefix}[]") - {f"{prefix}[]"}
    return out


def _check_fields(documented: list[str], real: set[str], what: str) -> None:
    doc = set(documented)
    assert len(doc) == len(documented), f"{what}: a field is listed twice"
    leaves = {d for d in doc if not any(o.startswith((d + ".", d + "[]")) for o in doc)}
    missing = sorted(
        r for r in real
        if r not in doc and not any(r.startswith((leaf + ".", leaf + "[]")) for leaf in leaves)
    )
    assert not missing, f"{what}: fields written by gyrocal but not documented: {missing}"
    stale = sorted(doc - real)
    assert not stale, f"{what}: documented fields gyrocal does not write: {stale}"


def _field_table(name: str) -> list[str]:
    rows = table_rows(section(DOC_DIR / "formats.md", f"<!-- fields: {name} -->",
                              f"<!-- /fields: {name} -->"))
    return [code_spans(r[0])[0] for r in rows]


def _real_runs(docs: Any) -> tuple[Path, Path]:
    """A ``gyrocal calibrate --sim`` run (running.md) and a ``simulate-recording`` (formats.md)."""
    cal_runs = sorted(docs(DOC_DIR / "running.md").workdir.glob("*/calibration.json"))
    assert cal_runs, "running.md must make a calibration with gyrocal calibrate"
    sims = [m.parent for m in docs(DOC_DIR / "formats.md").workdir.glob("*/manifest.json")
            if json.loads(m.read_text())["protocol"].get("name") == "simulated"]
    assert sims, "formats.md must write a recording with gyrocal simulate-recording"
    return cal_runs[0].parent, sims[0]


@uses_chain("running")
def test_recording_v1_fields_match_real_recordings(docs: Any) -> None:
    run, simulated = _real_runs(docs)
    real: set[str] = set()
    for rec in (run / "recording", simulated):
        real |= _paths(json.loads((rec / "manifest.json").read_text()))
    _check_fields(_field_table("manifest.json"), real, "formats.md manifest.json")
    # imu.csv: calibrate writes the accelerometer's optional columns, simulate-recording not
    for name, header, headers in (
            ("imu.csv", IMU_HEADER_ACCEL, (IMU_HEADER_ACCEL, IMU_HEADER)),
            ("encoder.csv", ENCODER_HEADER, (ENCODER_HEADER, ENCODER_HEADER)),
            ("segments.csv", SEGMENTS_HEADER, (SEGMENTS_HEADER, SEGMENTS_HEADER))):
        assert _field_table(name) == header.split(","), f"formats.md {name} columns"
        for rec, want in zip((run / "recording", simulated), headers, strict=True):
            first = (rec / name).read_text().split("\n", 1)[0]
            assert first == want, f"{rec / name} header"
        for h in set(headers):
            assert f"`{h}`" in (DOC_DIR / "formats.md").read_text(), f"{name}: header line"


def _real_calibrations(docs: Any) -> dict[int, dict]:
    """The calibration documents running.md makes, by version (its ``gyrocal calibrate`` writes a
    version 2, its diagonal ``gyrocal estimate --out`` a version 1)."""
    out: dict[int, dict] = {}
    for path in sorted(docs(DOC_DIR / "running.md").workdir.glob("*/*.json")):
        doc = json.loads(path.read_text())
        if isinstance(doc, dict) and doc.get("format") == "gyrocal-calibration":
            out.setdefault(doc["version"], doc)
    return out


@uses_chain("running")
def test_calibration_v1_fields_match_a_real_calibration(docs: Any) -> None:
    _real_runs(docs)
    real = _real_calibrations(docs)
    assert set(real) == {1, 2}, "running.md must make a version 1 and a version 2 calibration"
    _check_fields(_field_table("calibration"), _paths(real[1]), "formats.md calibration")
    # the real version 2 document: what it adds to version 1 is in the version 2 table
    _check_fields([f for f in _field_table("calibration v2") if f != "covariance"],
                  _paths(real[2]) - _paths(real[1]), "formats.md calibration v2")


def test_calibration_v2_fields_match_a_v2_document() -> None:
    eye = [[float(i == j) for j in range(3)] for i in range(3)]
    cal = GyroCalibration(
        scale=(1.0, 1.0, 1.0), bias=(0.0, 0.0, 0.0), matrix=eye, matrix_std=eye,
        covariance=[[0.0] * 12] * 12, frame="gyro-x-xy",
        kinematics={"chain": [1], "axes": [[1.0, 0.0, 0.0]], "reference_angles_rad": [0.0],
                    "home_angles_rad": [0.0], "up_servo": [1, 1]},
        g_sensitivity={"matrix": [[0.0] * 3] * 3, "matrix_std": [[0.0] * 3] * 3,
                       "directions": eye},
        model_choice=ModelChoice(full=1e-4, diagonal=1.2e-2, diagonal_cross_axis=1.15e-2,
                                 cross_axis=0.02),
    )
    v1 = _paths(GyroCalibration(scale=(1.0, 1.0, 1.0), bias=(0.0, 0.0, 0.0)).to_dict())
    real = _paths(cal.to_dict()) - v1
    _check_fields([f for f in _field_table("calibration v2") if f != "covariance"], real,
                  "formats.md calibration v2")


def _slug(heading: str) -> str:
    text = re.sub(r"\[([^\]]*)\]\([^)]*\)", r"\1", heading.strip().lower())
    text = re.sub(r"[^\w\- ]", "", text)
    return text.replace(" ", "-")


def test_relative_links_and_anchors_resolve() -> None:
    anchors: dict[Path, set[str]] = {}

    def slugs(path: Path) -> set[str]:
        if path not in anchors:
            text = re.sub(r"```.*?```", "", path.read_text(encoding="utf-8"), flags=re.S)
            anchors[path] = {_slug(h) for h in re.findall(r"^#+\s+(.+)$", text, flags=re.M)}
        return anchors[path]

    for doc in DOCS:
        text = re.sub(r"```.*?```", "", doc.read_text(encoding="utf-8"), flags=re.S)
        for target in re.findall(r"\]\(([^)\s]+)\)", text):
            if re.match(r"[a-z]+:", target):
                continue
            file_part, _, anchor = target.partition("#")
            dest = (doc.parent / file_part).resolve() if file_part else doc
            assert dest.exists(), f"{_name(doc)}: broken link {target}"
            if anchor and dest.suffix == ".md":
                assert anchor in slugs(dest), (
                    f"{_name(doc)}: no heading for #{anchor} in {dest.name}")
