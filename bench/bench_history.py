"""The calibration history (kit/history.py) at 10,000 records: storing, listing, the trend.

``python -m bench history`` prints one table: on a new SQLite file (WAL, ``synchronous = FULL``,
one transaction per record, as ``gyrocal calibrate --history`` stores), the time to store N
Calibration documents (v1 and v2 alternately, 20 sensors), then to list the sensors, to list one
sensor's records, to read every record, to compute one sensor's trend, and the file's size.
The documents are built here from seeded numbers with :class:`GyroCalibration`, the way the
kit writes them.

Options: ``--quick`` stores 1,000 records instead of 10,000; ``--url=URL`` runs on another
database (e.g. a scratch PostgreSQL database; its gyrocal tables must not exist yet).
"""

from __future__ import annotations

import os
import tempfile
import time
from pathlib import Path

import numpy as np

from bench.table import print_table
from gyrocal.calib.model import Consistency, GyroCalibration
from gyrocal.kit.history import open_history
from gyrocal.kit.history_view import trend

SENSORS = 20


def _documents(n: int) -> list[str]:
    rng = np.random.default_rng(13)
    out = []
    for i in range(n):
        scale = 1 + 0.01 * rng.standard_normal(3)
        kw = {}
        if i % 2:
            a = np.diag(scale) + 0.005 * rng.standard_normal((3, 3)) * (1 - np.eye(3))
            kw = {"matrix": a.tolist(), "covariance": (1e-10 * np.eye(12)).tolist()}
        else:
            kw = {"covariance": (1e-10 * np.eye(6)).tolist()}
        day, sec = divmod(i, 86400)
        cal = GyroCalibration(
            scale=tuple(scale), bias=tuple(0.02 * rng.standard_normal(3)),
            consistency=Consistency(chi2=3.0, dof=4, p_value=0.5, ok=True),
            sensor={"model": "mpu9250", "odr_hz": 200.0}, temperature_c=20 + 10 * rng.random(),
            created=f"2026-{1 + day // 28:02d}-{1 + day % 28:02d}T{sec // 3600:02d}:"
                    f"{sec // 60 % 60:02d}:{sec % 60:02d}+00:00",
            method="paired-axis", **kw)
        out.append(cal.to_json() + "\n")
    return out


def main(argv: list[str]) -> None:
    n = 1000 if "--quick" in argv else 10_000
    url = next((a.split("=", 1)[1] for a in argv if a.startswith("--url=")), None)
    docs = _documents(n)
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "history.sqlite"
        url = url or f"sqlite:///{path}"
        rows = []
        with open_history(url) as store:
            t0 = time.perf_counter()
            for i, d in enumerate(docs):
                store.add(d, label=f"imu-{i % SENSORS:02d}", jig="bench")
            t_add = time.perf_counter() - t0
            rows.append([f"store {n} records, one transaction each", t_add,
                         1e3 * t_add / n])
            for what, fn in (
                ("list the sensors", store.sensors),
                (f"list one sensor ({n // SENSORS} records)", lambda: store.records("imu-03")),
                (f"read all {n} records", store.records),
                (f"trend of one sensor ({n // SENSORS} records)",
                 lambda: trend(store.records("imu-03"))),
            ):
                t0 = time.perf_counter()
                fn()
                dt = time.perf_counter() - t0
                rows.append([what, dt, ""])
            assert store.count() == n
        size = f"{os.path.getsize(path) / 1e6:.1f} MB" if path.exists() else "(server)"
    print_table(["operation", "seconds", "ms per record"], rows,
                title=f"calibration history, {url.split(':')[0]}, {n} records; file {size}")
