"""What the documents' tests cost, command by command (the test suite's longest units).

``python -m bench docs`` runs each chain of documents of ``tests/test_docs.py``
(:data:`tests.test_docs.CHAINS`) as the suite does, in a temporary directory per chain, and prints
every ``gyrocal`` command's and Python block's CPU seconds (process time) and wall seconds, and
each document's and chain's totals. ``--chain=NAME`` runs one chain. Under pytest-xdist each chain
is one worker's unit (``tests/conftest.py``), so the longest chain's CPU seconds are a floor on
the suite's wall time on two cores.
"""

from __future__ import annotations

import contextlib
import shlex
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from bench.table import print_table
from tests import test_docs


@contextlib.contextmanager
def _timed(rows: list[list[Any]]) -> Iterator[None]:
    """Time every command and Python block :func:`tests.test_docs.run_document` runs."""
    run_gyrocal, exec_python = test_docs._run_gyrocal, test_docs._exec_python

    def measure(label: str, fn: Any, *args: Any) -> None:
        c0, t0 = time.process_time(), time.perf_counter()
        try:
            fn(*args)
        finally:
            rows.append([label, time.process_time() - c0, time.perf_counter() - t0])

    test_docs._run_gyrocal = lambda argv, where, expect, log: measure(
        f"{where}: gyrocal {shlex.join(argv)}", run_gyrocal, argv, where, expect, log)
    test_docs._exec_python = lambda block, argv=None: measure(
        f"{block.where}: python block", exec_python, block, argv)
    try:
        yield
    finally:
        test_docs._run_gyrocal, test_docs._exec_python = run_gyrocal, exec_python


def main(argv: list[str]) -> None:
    opts = dict(a.lstrip("-").split("=", 1) for a in argv if "=" in a)
    chains = [opts["chain"]] if "chain" in opts else list(test_docs.CHAINS)
    unknown = set(chains) - set(test_docs.CHAINS)
    if unknown:
        raise SystemExit(f"unknown chain {sorted(unknown)}; the chains: "
                         f"{', '.join(test_docs.CHAINS)}")
    totals = []
    for chain in chains:
        rows: list[list[Any]] = []
        with tempfile.TemporaryDirectory() as tmp, _timed(rows):
            for name in test_docs.CHAINS[chain]:
                c0, t0 = time.process_time(), time.perf_counter()
                test_docs.run_document(test_docs.ROOT / name, Path(tmp))
                rows.append([f"{name} (whole)", time.process_time() - c0,
                             time.perf_counter() - t0])
        print_table(["command", "CPU s", "wall s"], [r for r in rows if r[1] >= 0.05],
                    title=f"chain {chain!r}: commands and blocks of at least 0.05 CPU s")
        whole = [r for r in rows if r[0].endswith("(whole)")]
        totals.append([chain, sum(r[1] for r in whole), sum(r[2] for r in whole)])
    print_table(["chain", "CPU s", "wall s"], totals, title="each chain in all")
