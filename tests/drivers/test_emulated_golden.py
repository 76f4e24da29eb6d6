"""The emulated jig records the same run for the same seed as the emulators did before they were
made faster (:mod:`tests.drivers.golden_run`): every realism effect on, an MPU-9250 (DLPF at the
internal 1 kHz, SMPLRT_DIV decimation) and an LSM9DS1 (its output filter), the servos' encoders
and the segments, byte for byte."""

from __future__ import annotations

import gzip
from pathlib import Path

import pytest

from tests.drivers.golden_run import FILES, RUNS, record

DATA = Path(__file__).parent / "data"


@pytest.mark.parametrize("name", sorted(RUNS))
def test_a_seed_records_the_pinned_run(name: str, tmp_path: Path) -> None:
    rec = record(tmp_path / "rec", RUNS[name])
    for f in FILES:
        want = gzip.decompress((DATA / f"golden-{name}-{f}.gz").read_bytes()).decode()
        got = (rec / f).read_text()
        assert got.count("\n") == want.count("\n"), f"{name} {f}: row count changed"
        for i, (a, b) in enumerate(zip(got.splitlines(), want.splitlines(), strict=True)):
            assert a == b, f"{name} {f} line {i + 1}: {a!r} != pinned {b!r}"
