"""The suite's processes run OpenBLAS with the thread count ``tests/conftest.py`` sets (one,
unless ``OPENBLAS_NUM_THREADS`` was given): two xdist workers on two cores with OpenBLAS's
default of a thread per core each spin against each other (``python -m bench blas``).

The count is asked of the OpenBLAS libraries numpy and scipy load (their wheels bundle them);
a build on another BLAS skips.
"""

from __future__ import annotations

import ctypes
import os
from pathlib import Path

import pytest


def openblas_threads(package: str) -> list[int]:
    """The thread count of each OpenBLAS library bundled with ``package`` (its ``.libs``
    folder), as the library reports it."""
    mod = pytest.importorskip(package)
    libs = sorted((Path(mod.__file__).parent.parent / f"{package}.libs").glob("*openblas*"))
    counts = []
    for path in libs:
        lib = ctypes.CDLL(str(path))
        for name in ("scipy_openblas_get_num_threads64_", "scipy_openblas_get_num_threads",
                     "openblas_get_num_threads64_", "openblas_get_num_threads"):
            fn = getattr(lib, name, None)
            if fn is not None:
                counts.append(int(fn()))
                break
    return counts


@pytest.mark.parametrize("package", ["numpy", "scipy"])
def test_openblas_runs_the_thread_count_the_suite_sets(package: str) -> None:
    import scipy.linalg  # noqa: F401  (loads scipy's own OpenBLAS)

    counts = openblas_threads(package)
    if not counts:
        pytest.skip(f"{package} does not bundle OpenBLAS here")
    want = int(os.environ["OPENBLAS_NUM_THREADS"])
    assert counts == [want] * len(counts), (
        f"{package}'s OpenBLAS runs {counts} threads, not the {want} tests/conftest.py sets: "
        "something imported numpy before it")
