"""Run benchmarks and print their tables.

Usage: ``python -m bench`` (all) or ``python -m bench estimators imu`` (``bench/bench_<name>.py``).
Each module defines ``main(argv: list[str]) -> None`` that prints one or more tables. Speed and
accuracy targets are measured here, never as timed pass/fail tests.
"""

from __future__ import annotations

import importlib
import pkgutil
import sys

import bench


def _names() -> list[str]:
    return sorted(
        m.name[len("bench_") :]
        for m in pkgutil.iter_modules(bench.__path__)
        if m.name.startswith("bench_")
    )


def main(argv: list[str]) -> int:
    available = _names()
    if any(a in ("-h", "--help") for a in argv):
        print(__doc__)
        print("available:", " ".join(available))
        return 0
    names = [a for a in argv if not a.startswith("-")] or available
    unknown = [n for n in names if n not in available]
    if unknown:
        print(f"unknown benchmark(s): {' '.join(unknown)}; available: {' '.join(available)}")
        return 2
    extra = [a for a in argv if a.startswith("-")]
    for name in names:
        print(f"\n=== bench {name} ===", flush=True)
        importlib.import_module(f"bench.bench_{name}").main(extra)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
