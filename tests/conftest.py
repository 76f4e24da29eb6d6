"""Shared test configuration.

Under pytest-xdist (``pytest -n 2``, the README's command) the scheduler below is xdist's
``LoadScopeScheduling`` with these work units, each run whole by one worker:

* each chain of documents of ``tests/test_docs.py`` (:data:`tests.test_docs.CHAINS`: documents
  that read each other's files run in reading order in one directory) with the tests that read
  that chain's files. Split over workers, as xdist's default ``load`` scheduling does, a chain ran
  on every worker that had one of its tests. The chains are the longest units (several emulated
  calibrations each), so they are handed out first, one to each worker, longest first;
* each module of :data:`MODULE_UNITS`, whose tests share a module-scoped fixture costing emulated
  calibrations: split, every worker that ran one of its tests built the fixture again;
* every other test, a unit of its own, so the rest is balanced as ``load`` balances it.

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

from tests.test_docs import CHAINS, xdist_unit  # noqa: E402

#: Modules whose module-scoped fixtures run emulated calibrations (tens of CPU seconds): one
#: work unit each, so one worker builds the fixture once.
MODULE_UNITS = frozenset({
    "tests/kit/test_calibrate.py",
    "tests/kit/test_plate.py",
    "tests/kit/test_report.py",
})

try:
    from xdist.scheduler import LoadScopeScheduling
except ImportError:  # plain pytest: nothing to schedule
    LoadScopeScheduling = None


def work_unit(nodeid: str) -> str:
    """The work unit of a test (see the module's docstring)."""
    unit = xdist_unit(nodeid) if nodeid.startswith("tests/test_docs.py::") else None
    if unit is not None:
        return unit
    module = nodeid.split("::", 1)[0]
    return module if module in MODULE_UNITS else nodeid


#: The documents' chains' units, in the order they are handed out.
CHAIN_UNITS = tuple(f"tests/test_docs.py::{chain}" for chain in CHAINS)


if LoadScopeScheduling is not None:

    class DocumentsTogether(LoadScopeScheduling):  # type: ignore[misc, valid-type]
        """``load`` scheduling, except for the units of :func:`work_unit`, the documents'
        chains first."""

        _chains_first = False

        def _split_scope(self, nodeid: str) -> str:
            return work_unit(nodeid)

        def _assign_work_unit(self, node: Any) -> None:
            if not self._chains_first:  # the queue is complete at the first assignment
                self._chains_first = True
                for unit in reversed(CHAIN_UNITS):
                    if unit in self.workqueue:
                        self.workqueue.move_to_end(unit, last=False)
            super()._assign_work_unit(node)

    @pytest.hookimpl(optionalhook=True)
    def pytest_xdist_make_scheduler(config: pytest.Config, log: Any) -> Any:
        """:class:`DocumentsTogether` in place of xdist's ``load`` scheduling."""
        if config.getvalue("dist") == "load":
            return DocumentsTogether(config, log)
        return None
