"""A plain-text table printer shared by the benchmarks."""

from __future__ import annotations

import os
import sys
from collections.abc import Callable, Sequence
from concurrent.futures import ProcessPoolExecutor

#: Processes :func:`pooled` runs at once (the benches' host has two cores to share).
WORKERS = min(2, os.cpu_count() or 1)


def print_table(headers: Sequence[str], rows: Sequence[Sequence[object]], title: str = "") -> None:
    """Print ``rows`` under ``headers`` as an aligned text table (floats to 4 digits)."""

    def fmt(v: object) -> str:
        if isinstance(v, float):
            return f"{v:.4g}"
        return str(v)

    cells = [[fmt(v) for v in row] for row in rows]
    widths = [max(len(h), *(len(r[i]) for r in cells)) if cells else len(h)
              for i, h in enumerate(headers)]
    if title:
        print(title)
    print("  ".join(h.ljust(w) for h, w in zip(headers, widths, strict=True)))
    print("  ".join("-" * w for w in widths))
    for r in cells:
        print("  ".join(c.ljust(w) for c, w in zip(r, widths, strict=True)))
    print(flush=True)


def pooled(fn: Callable, jobs: Sequence, describe: Callable[[dict], str]) -> list[dict]:
    """``fn`` over ``jobs`` on :data:`WORKERS` processes, in order, each result described on
    stderr as it arrives; Ctrl-C stops the pool and returns the results that finished (the
    benches then print their tables from those)."""
    results: list[dict] = []
    pool = ProcessPoolExecutor(WORKERS)
    try:
        for r in pool.map(fn, jobs):
            results.append(r)
            print(f"# {describe(r)}", file=sys.stderr, flush=True)
    except KeyboardInterrupt:
        print(f"# stopped after {len(results)} of {len(jobs)}; the tables hold those",
              file=sys.stderr, flush=True)
        pool.shutdown(wait=False, cancel_futures=True)
    else:
        pool.shutdown()
    return results
