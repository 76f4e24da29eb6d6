"""The emulated jig records the same run for the same seed as the emulators did before they were
made faster (:mod:`tests.drivers.golden_run`): every realism effect on, an MPU-9250 (DLPF at the
internal 1 kHz, SMPLRT_DIV decimation) and an LSM9DS1 (its output filter), the servos' encoders
and the segments, byte for byte.

The pinned streams were regenerated when each chip got its own noise density and the white
noise moved ahead of the filter (issue 26), and the MPU-9250's again when its accelerometer got
its DLPF (issue 26): the accelerometer filter's run-in rows draw gyro noise too, so the gyro's
white-noise realisation changed, nothing else (the same 1134 sample times, encoder and
segments files unchanged; new − old per sample has σ ≈ √2 × the white noise per sample, 3.8e-3
rad/s, and means within 6e-5 rad/s; the rests' RMS over the datasheet figure went from 0.965 to
1.021). The LSM9DS1's was re-pinned when its accelerometer got its anti-aliasing filter (105 Hz
at 238 Hz, BW_SCAL_ODR = 0): again only the gyro's white-noise realisation changed (the same
1347 sample times, encoder and segments unchanged; new − old σ 3.0e-3 rad/s, means within
1.1e-5; the rests' RMS over the datasheet figure 0.913 before, 0.930 after).
:func:`test_the_pinned_rests_have_the_datasheet_noise` checks that they are what the
datasheet says, not only that they are unchanged."""

from __future__ import annotations

import gzip
import io
import math
from pathlib import Path

import numpy as np
import pytest

from gyrocal.drivers.imu import READERS
from tests.drivers.golden_run import FILES, FILTERS, RUNS, record

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


def _pinned(name: str, f: str) -> np.ndarray:
    text = gzip.decompress((DATA / f"golden-{name}-{f}.gz").read_bytes()).decode()
    return np.genfromtxt(io.StringIO(text), delimiter=",", names=True, dtype=None,
                         encoding=None)


@pytest.mark.parametrize("name", sorted(RUNS))
def test_the_pinned_rests_have_the_datasheet_noise(name: str) -> None:
    # The gyro about each rest's mean (0.05 s off each end) against the chip table's density
    # N drawn at the filter's rate through the first-order filter at the datasheet bandwidth:
    # σ = N √(rate · k / (1 + k)), k = tan(π fc / rate). About 550-650 samples (3 axes, three
    # rests), nearly independent at these bandwidths: the RMS has a relative standard error
    # of about 1/√(2n) ≈ 3 %, so ±12 % is 4 standard errors (the coloured noise, constant at
    # rest over 0.6 s, adds under 1 %). The streams pinned before issue 26 (noise added after
    # the filter, σ = N √odr) give 0.87 (MPU-9250) and 1.21 (LSM9DS1) and fail.
    imu, segments = _pinned(name, "imu.csv"), _pinned(name, "segments.csv")
    rows = []
    for seg in segments[segments["kind"] == "rest"]:
        keep = (imu["t"] > seg["t_start"] + 0.05) & (imu["t"] < seg["t_end"] - 0.05)
        g = np.column_stack([imu[a][keep] for a in ("gx", "gy", "gz")])
        rows.append(g - g.mean(axis=0))
    residual = np.vstack(rows)
    fc, rate = FILTERS[name]
    k = math.tan(math.pi * fc / rate)
    density = READERS[name].family.gyro_errors.noise_density_rad_s_sqrt_hz
    want = density * math.sqrt(rate * k / (1 + k))
    assert residual.size > 500
    assert math.sqrt(float(np.mean(residual**2))) / want == pytest.approx(1.0, abs=0.12)
