"""Run benchmarks and print their tables.

Usage: ``python -m bench`` (all) or ``python -m bench estimators imu`` (``bench/bench_<name>.py``).
Each module defines ``main(argv: list[str]) -> None`` that prints one or more tables. Speed and
accuracy targets are measured here, never as timed pass/fail tests. A benchmark that fails is
reported with its traceback and marked FAILED; the others still run, and the exit status is 1
when any failed.
"""

from __future__ import annotations

import importlib
import pkgutil
import sys
import time
import traceback

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
    failed = []
    for name in names:
        print(f"\n=== bench {name} ===", flush=True)
        t0 = time.perf_counter()
        try:
            importlib.import_module(f"bench.bench_{name}").main(extra)
        except KeyboardInterrupt:
            raise
        except SystemExit as e:  # its own argument check: argparse has said what is wrong
            if e.code in (0, None):
                continue
            print(f"=== bench {name}: FAILED (bad arguments, exit {e.code}) ===", flush=True)
            failed.append(name)
        except BaseException:  # any other failure is reported with its traceback
            traceback.print_exc(file=sys.stdout)
            print(f"=== bench {name}: FAILED after {time.perf_counter() - t0:.1f} s ===",
                  flush=True)
            failed.append(name)
    if failed:
        print(f"\n{len(failed)} of {len(names)} benchmark(s) FAILED: {' '.join(failed)}")
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
