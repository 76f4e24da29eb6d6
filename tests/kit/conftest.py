"""Session-wide emulated runs shared by the kit tests (each costs tens of seconds of CPU).

``full_run`` is one ``gyrocal calibrate --sim`` at the defaults (the full model's protocol, an
emulated sensor within the datasheet's tolerances, its ±2 % cross-axis terms included, and every
realism effect), its HTML report included;
``verify_run`` is one ``gyrocal verify --sim`` of that calibration on the same emulated sensor
and jig (every realism effect too: verify applies the calibration's g-sensitivity), with a short
diagonal protocol (18 s) before its general-motion sweeps. Under pytest-xdist the workers share
them: the first to arrive runs the command under a file lock, the others read its output.
"""

from __future__ import annotations

import contextlib
import fcntl
import io
import json
import os
from collections.abc import Callable
from pathlib import Path

import pytest

from gyrocal.kit.cli import main

#: The emulated sensor and jig of the shared runs (seed of ``--sim-seed``).
SHARED_SEED = 5
#: ``full_run`` and ``verify_run`` are the default ``--sim`` sensor: scale, bias and cross-axis
#: terms within the datasheet's tolerances and every realism effect (coloured noise,
#: g-sensitivity, DLPF, ...), which the full model with g-sensitivity must handle;
#: ``paper_full_run`` the paper's exaggerated sensor (``--sim-sensor paper``: scale ±20 %, bias
#: ±0.1 rad/s) without realism effects (what each realism effect costs is measured by
#: ``python -m bench realism``).
PAPER_REALISM = ("--sim-sensor", "paper", "--sim-realism", "off")
#: The paper's sensor and model: no cross-axis terms, the planner's diagonal protocol.
PAPER_DIAGONAL = (*PAPER_REALISM, "--protocol", "auto", "--sim-cross-axis", "0")
#: A config of the jig's loop (each sensor's FIFO drain and the servos' sync read) at 50 Hz
#: instead of 200: a quarter of the emulated bus traffic, which is most of an emulated run's
#: CPU, for the same samples (each chip's FIFO holds them between drains). For the runs whose
#: checks do not depend on the loop rate; the default rate is ``full_run``'s (and the docs').
LOOP_50_HZ = "[gimbal]\nsample_hz = 50\n"


def loop_50_hz_config(run: Path) -> str:
    """A config file of :data:`LOOP_50_HZ` beside the run directory ``run`` (for ``--config``)."""
    cfg = run.with_name(run.name + ".toml")
    cfg.write_text(LOOP_50_HZ)
    return str(cfg)


def loop_50_hz_args(run: Path) -> list[str]:
    """``--config`` of :func:`loop_50_hz_config` (the file beside ``run``), for a command's
    arguments."""
    return ["--config", loop_50_hz_config(run)]


def _once(tmp_path_factory: pytest.TempPathFactory, name: str,
          make: Callable[[Path], int]) -> tuple[Path, int]:
    """Run ``make(directory)`` once per test session (across xdist workers, whose base
    temporary directories share a parent); its exit code is kept beside the directory."""
    root = tmp_path_factory.getbasetemp()
    if os.environ.get("PYTEST_XDIST_WORKER"):
        root = root.parent
    d = root / f"shared-{name}"
    with open(root / f"shared-{name}.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        try:
            done = root / f"shared-{name}.json"
            if not done.exists():
                code = make(d)
                done.write_text(json.dumps({"exit": code}))
            return d, json.loads(done.read_text())["exit"]
        finally:
            fcntl.flock(lock, fcntl.LOCK_UN)


def _stdout_file(directory: Path) -> Path:
    """Where a shared run's standard output is kept: beside its directory, not in it."""
    return directory.with_name(directory.name + ".stdout")


@pytest.fixture(scope="session")
def full_run(tmp_path_factory):
    """``(directory, exit code)`` of ``gyrocal calibrate --sim`` at the defaults, its report
    included when the plot extra is installed (what it printed: :func:`full_run_stdout`)."""
    def make(d: Path) -> int:
        out = io.StringIO()
        with contextlib.redirect_stdout(out):
            code = main(["calibrate", "--sim", "--sim-seed", str(SHARED_SEED), "--out", str(d),
                         "--quiet"])
        _stdout_file(d).write_text(out.getvalue())
        return code
    return _once(tmp_path_factory, "calibrate", make)


@pytest.fixture(scope="session")
def full_run_stdout(full_run):
    """What ``full_run``'s ``gyrocal calibrate`` printed on its standard output."""
    return _stdout_file(full_run[0]).read_text()


@pytest.fixture(scope="session")
def paper_full_run(tmp_path_factory):
    """``(directory, exit code)`` of ``gyrocal calibrate --sim`` with the full protocol on the
    paper's exaggerated sensor (``--sim-sensor paper``, the datasheet's cross-axis terms, no
    realism effects): for what compares with a truth that has no g-sensitivity or coloured noise
    in it (the tracker's bias). Its loop at 50 Hz (:data:`LOOP_50_HZ`)."""
    return _once(tmp_path_factory, "calibrate-paper", lambda d: main(
        ["calibrate", "--sim", "--sim-seed", str(SHARED_SEED), *PAPER_REALISM, "--config",
         loop_50_hz_config(d), "--out", str(d), "--quiet", "--no-report"]))


@pytest.fixture(scope="session")
def paper_diagonal_run(tmp_path_factory):
    """``(directory, exit code)`` of ``gyrocal calibrate --sim`` of the paper's sensor and model
    (:data:`PAPER_DIAGONAL`, seed 1): one axis per servo, a version 1 calibration. Seed 1 of
    tests/kit/test_calibrate.py's runs, and tests/kit/test_report.py's run."""
    return _once(tmp_path_factory, "calibrate-paper-diagonal", lambda d: main(
        ["calibrate", "--sim", "--sim-seed", "1", *PAPER_DIAGONAL, "--out", str(d), "--quiet",
         "--no-report"]))


@pytest.fixture(scope="session")
def verify_run(tmp_path_factory, full_run):
    """``(directory, exit code)`` of ``gyrocal verify`` of ``full_run``'s calibration on the same
    emulated sensor (fresh noise), its protocol the planner's diagonal one in 18 s, its loop at
    50 Hz (:data:`LOOP_50_HZ`: verify's blocks are cut from the recorded samples and segments,
    which the loop rate does not change; at 200 Hz and at 50 the same 40 rest, 17 one-servo, 4
    several-servo and 29 ramp-excluded blocks; the truth's full calibration at 0.43, 0.35, 0.25
    times its predicted error at 200 Hz, 0.44, 0.38, 0.27 at 50 (flagged above 3), its diagonal
    part at 18.5 and 19.2 times at worst)."""
    def make(d: Path) -> int:
        d.mkdir()
        (d / "gyrocal.toml").write_text('[protocol]\nname = "auto"\ntime_budget_s = 18.0\n'
                                        + LOOP_50_HZ)
        return main(["verify", str(full_run[0] / "calibration.json"), "--sim", "--sim-seed",
                     str(SHARED_SEED), "--config", str(d / "gyrocal.toml"), "--out",
                     str(d / "run"), "--quiet", "--json"])
    return _once(tmp_path_factory, "verify", make)


def verification_document(ok: bool) -> dict:
    """A `gyrocal verify --json` document as the command writes it (Verification.to_dict), with
    errors within (ok) or beyond 3 times the prediction on y."""
    import numpy as np

    from gyrocal.kit.verify import KINDS, Verification

    full = np.array([0.003, 0.004 if ok else 0.02, 0.0025])
    v = Verification(
        rms_before=np.array([0.1, 0.2, 0.3]), rms_diagonal=full, rms_full=np.full(3, np.nan),
        rms_predicted=np.array([0.004, 0.005, 0.004]),
        rms_by_kind={k: full for k in KINDS}, predicted_by_kind={k: full for k in KINDS},
        blocks={"rest": 20, "one_servo": 18, "several_servos": 0, "ramp_excluded": 22},
        block_s=0.5, reference="home-pose axes", full=False)
    return {"calibration": "cal.json", "recording": "rec", **v.to_dict()}


@pytest.fixture(scope="session")
def paper_diagonal_report(tmp_path_factory, paper_diagonal_run):
    """``(plots directory, what it printed)`` of ``gyrocal report`` of ``paper_diagonal_run``'s
    recording and calibration (a version 1, diagonal one) with a failing verification document
    (:func:`verification_document`): one drawing read by tests/kit/test_report.py (the plots
    and their listing) and tests/kit/test_report_html.py (the page). Needs the plot extra."""
    pytest.importorskip("matplotlib")
    run, code = paper_diagonal_run
    assert code == 0

    def make(d: Path) -> int:
        d.mkdir()
        verification = d / "verification.json"
        verification.write_text(json.dumps(verification_document(ok=False)))
        out = io.StringIO()
        with contextlib.redirect_stdout(out):
            code = main(["report", str(run / "recording"), str(run / "calibration.json"),
                         "--out", str(d / "plots"), "--verification", str(verification)])
        _stdout_file(d).write_text(out.getvalue())
        return code

    d, code = _once(tmp_path_factory, "report-paper-diagonal", make)
    assert code == 0
    return d / "plots", _stdout_file(d).read_text()
