"""Shared test configuration.

Under pytest-xdist (``pytest -n 2``, the README's command) the scheduler below is xdist's
``LoadScopeScheduling`` with these work units, each run whole by one worker:

* each chain of documents of ``tests/test_docs.py`` (:data:`tests.test_docs.CHAINS`: documents
  that read each other's files run in reading order in one directory) with the tests that read
  that chain's files. Split over workers, as xdist's default ``load`` scheduling does, a chain ran
  on every worker that had one of its tests. A chain's branches (:data:`tests.test_docs.BRANCHES`:
  its blocks that share no file with the rest beyond the configurations) are units of their own,
  so that the longest chain runs on both workers;
* every other test module, whole (as ``--dist loadfile``): a module-scoped fixture (an emulated
  calibration, a simulated recording, a rendered report) is built by one worker only. With every
  test a unit of its own, the two workers took a module's tests in turn and each built its
  fixtures.

The units are handed out longest first (:data:`LONG_UNITS`, measured; the rest by their number
of tests, xdist's ``--loadscope-reorder``), so that the short ones fill the end of the run on both
workers and no long unit starts last.

The tests that read a long end-to-end emulated run (:data:`E2E_FIXTURES`: the documents' chains
and the shared ``gyrocal calibrate --sim`` runs) are marked ``long``: ``pytest -n 2 -m "not
long"`` leaves them out for a quick loop while working. The README's command and ``.ci/run`` run
them all.

``--dist`` other than ``load`` is left as asked.
"""

from __future__ import annotations

import os

# One BLAS thread per process, set before numpy loads OpenBLAS (here, in the main process, which
# xdist's workers and the tests' subprocesses inherit it from). The suite runs one worker per core;
# OpenBLAS's default of one thread per core puts two threads on each core, which spin waiting for
# each other: `python -m bench blas` measured the calib tests at 1.17 times their CPU and the
# window and Allan tests at 1.7 times on a quiet host (1.8 with other work on the machine).
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

from typing import Any  # noqa: E402

import pytest  # noqa: E402

from tests.test_docs import xdist_unit  # noqa: E402

#: Wall seconds of the longest work units (:func:`work_unit`), from a `pytest -n 2` run of a
#: clean clone with a plugin summing each test's wall time, fixtures included (a shared run of
#: tests/kit/conftest.py counts on the first unit that asks for it on its worker): the scheduler
#: hands them out first, longest first. A unit missing here keeps xdist's order after them; a
#: figure out of date only moves a unit in that order. Wall, not CPU: the frozen-link cases of
#: test_signals wait out the servos' timeouts.
LONG_UNITS: dict[str, float] = {
    "tests/drivers/test_imu_streaming.py": 42.3,
    "tests/kit/test_signals.py": 35.5,
    "tests/test_docs.py::running/thermal": 34.0,
    "tests/test_docs.py::running": 33.9,
    "tests/kit/test_report.py": 24.5,
    "tests/kit/test_calibrate.py": 23.9,
    "tests/test_docs.py::running/plate": 23.1,
    "tests/kit/test_verify_general.py": 17.9,
    "tests/calib/test_tracker.py": 15.0,
    "tests/test_docs.py::intro": 12.3,
    "tests/kit/test_history.py": 12.2,
    "tests/kit/test_plate.py": 12.0,
    "tests/test_docs.py::single-servo": 11.7,
    "tests/kit/test_track.py": 9.9,
    "tests/kit/test_model_choice.py": 9.0,
    "tests/kit/test_track_live.py": 8.9,
    "tests/kit/test_recording_reader.py": 8.6,
    "tests/test_docs.py::hand": 6.8,
    "tests/kit/test_servo_link.py": 6.8,
    "tests/kit/test_cli_imports.py": 6.7,
    "tests/kit/test_thermal.py": 6.5,
    "tests/drivers/test_chip_noise.py": 6.3,
    "tests/kit/test_reliability.py": 6.2,
    "tests/drivers/test_dxl_gimbal.py": 6.0,
    "tests/kit/test_fullmodel_contract.py": 5.5,
    "tests/kit/test_align_e2e.py": 5.2,
    "tests/calib/test_allan.py": 5.1,
    "tests/calib/test_windows.py": 5.0,
}

#: Fixtures that run a long end-to-end emulated run (tens of CPU seconds each): a test that
#: requests one, itself or through another fixture, is marked ``long``.
E2E_FIXTURES: frozenset[str] = frozenset({
    "doc_runner",  # tests/test_docs.py: the documents' commands, calibrations on the emulated jig
    "full_run", "paper_full_run", "paper_diagonal_run", "verify_run",  # tests/kit/conftest.py
    "aligned_run",  # tests/kit/test_align_e2e.py
    "run_logs",  # tests/kit/test_calibrate.py
    "three",  # tests/kit/test_plate.py
})


def pytest_configure(config: pytest.Config) -> None:
    config.addinivalue_line(
        "markers", "long: reads a long end-to-end emulated run (tests/conftest.py E2E_FIXTURES); "
        "-m 'not long' leaves these out, the README's command runs them")


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """Mark ``long`` every test that requests one of :data:`E2E_FIXTURES`."""
    for item in items:
        if E2E_FIXTURES.intersection(getattr(item, "fixturenames", ())):
            item.add_marker(pytest.mark.long)


try:
    from xdist.scheduler import LoadScopeScheduling
except ImportError:  # plain pytest: nothing to schedule
    LoadScopeScheduling = None


def work_unit(nodeid: str) -> str:
    """The work unit of a test (see the module's docstring)."""
    unit = xdist_unit(nodeid) if nodeid.startswith("tests/test_docs.py::") else None
    return unit if unit is not None else nodeid.split("::", 1)[0]


def longest_first(units: list[str]) -> list[str]:
    """``units`` in the order they are handed out: those of :data:`LONG_UNITS`, longest first,
    then the others in their given order."""
    return sorted(units, key=lambda unit: -LONG_UNITS.get(unit, 0.0))


if LoadScopeScheduling is not None:

    class LongestFirst(LoadScopeScheduling):  # type: ignore[misc, valid-type]
        """``load`` scheduling of the units of :func:`work_unit`, longest first."""

        _ordered = False

        def _split_scope(self, nodeid: str) -> str:
            return work_unit(nodeid)

        def _assign_work_unit(self, node: Any) -> None:
            if not self._ordered:  # the queue is complete at the first assignment
                self._ordered = True
                for unit in reversed(longest_first(list(self.workqueue))):
                    self.workqueue.move_to_end(unit, last=False)
            super()._assign_work_unit(node)

    @pytest.hookimpl(optionalhook=True)
    def pytest_xdist_make_scheduler(config: pytest.Config, log: Any) -> Any:
        """:class:`LongestFirst` in place of xdist's ``load`` scheduling."""
        if config.getvalue("dist") == "load":
            return LongestFirst(config, log)
        return None
