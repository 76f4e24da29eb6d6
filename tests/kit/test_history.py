"""The calibration history (kit/history.py): round trip, duplicates, identity, crash and
concurrency safety, schema versions, the SQL's portability, and ``gyrocal history``'s import,
export, trend and errors.

The documents are built here from seeded numbers (``GyroCalibration`` v1 and v2), so every
figure the history shows is checked against what was put in.
"""

from __future__ import annotations

import json
import math
import os
import re
import signal
import sqlite3
import subprocess
import sys
import textwrap
from pathlib import Path
from urllib.parse import urlsplit, urlunsplit

import numpy as np
import pytest

from gyrocal.calib.model import Consistency, GyroCalibration
from gyrocal.kit import history as H
from gyrocal.kit.cli import main
from gyrocal.kit.history_view import import_dir, trend


def make_doc(seed: int, *, full: bool = False, temperature: float | None = 25.0,
             created: str = "2026-01-05T10:00:00+00:00", model: str = "mpu9250",
             ok: bool | None = True) -> str:
    """A Calibration document (JSON text, as gyrocal writes it) with seeded numbers."""
    rng = np.random.default_rng(seed)
    scale = 1 + 0.01 * rng.standard_normal(3)
    bias = 0.02 * rng.standard_normal(3)
    kw = {}
    if full:
        a = np.diag(scale) + 0.005 * (rng.standard_normal((3, 3)) * (1 - np.eye(3)))
        kw = {"matrix": a.tolist(), "frame": "gyro-x-xy"}
    cons = None if ok is None else Consistency(chi2=3.0, dof=4, p_value=0.5 if ok else 1e-6,
                                               ok=ok)
    cal = GyroCalibration(scale=tuple(scale), bias=tuple(bias), method="paired-axis",
                          consistency=cons, sensor={"model": model, "odr_hz": 200.0},
                          temperature_c=temperature, created=created, source="test", **kw)
    return cal.to_json() + "\n"


def contract_doc(seed: int, *, full: bool) -> str:
    """A Calibration v1 or v2 document written from the contract in hardware_docs/formats.md
    with plain dicts: no gyrocal code makes it (an independent generator)."""
    rng = np.random.default_rng(seed)
    k = [float(1 + 0.01 * x) for x in rng.standard_normal(3)]
    doc = {"format": "gyrocal-calibration", "version": 2 if full else 1,
           "model": "g = matrix @ (m + bias)" if full else "g = scale * (m + bias)",
           "scale": k, "bias": [float(0.01 * x) for x in rng.standard_normal(3)],
           "scale_std": [4e-5] * 3, "bias_std": [4e-5] * 3, "covariance": None,
           "method": "other-tool", "iterations": 5,
           "consistency": {"chi2": 2.0, "dof": 3, "p_value": 0.57, "ok": True},
           "sensor": {"model": "mpu9250"}, "temperature_c": 22.5,
           "created": "2025-12-01T08:00:00Z", "source": "another tool"}
    if full:
        doc["matrix"] = [[k[i] if i == j else 0.001 * (i - j) for j in range(3)]
                         for i in range(3)]
    return json.dumps(doc, indent=1)


PG_URL = os.environ.get("GYROCAL_TEST_POSTGRES_URL")
needs_pg = pytest.mark.skipif(not PG_URL, reason="set GYROCAL_TEST_POSTGRES_URL to a scratch "
                              "PostgreSQL server (.ci/with-postgres starts one; a database "
                              "gyrocal_test_<worker> is made on it and its tables dropped)")


def _scratch_pg():
    """A PostgreSQL database of this test's own (one per pytest-xdist worker, its gyrocal tables
    dropped), on the server GYROCAL_TEST_POSTGRES_URL names."""
    psycopg = pytest.importorskip("psycopg")
    name = f"gyrocal_test_{os.environ.get('PYTEST_XDIST_WORKER', 'main')}"
    with psycopg.connect(PG_URL, autocommit=True) as con:
        if con.execute("SELECT 1 FROM pg_database WHERE datname = %s", (name,)).fetchone() \
                is None:
            con.execute(f'CREATE DATABASE "{name}"')
    parts = urlsplit(PG_URL)
    url = urlunsplit(parts._replace(path="/" + name))
    with psycopg.connect(url, autocommit=True) as con:
        for table in ("calibrations", "sensors", "gyrocal_schema"):
            con.execute(f"DROP TABLE IF EXISTS {table}")
    return url


@pytest.fixture
def sqlite_url(tmp_path):
    """A SQLite history (for what only SQLite has: its file, its lock, PRAGMA)."""
    return f"sqlite:///{tmp_path / 'h.sqlite'}"


@pytest.fixture(params=["sqlite", pytest.param("postgresql", marks=needs_pg)])
def url(request, tmp_path):
    """The history on each backend: a SQLite file, and a scratch database on the PostgreSQL
    server of GYROCAL_TEST_POSTGRES_URL (skipped without one)."""
    return f"sqlite:///{tmp_path / 'h.sqlite'}" if request.param == "sqlite" else _scratch_pg()


@pytest.fixture(autouse=True)
def _no_home_database(tmp_path, monkeypatch):
    """Nothing in these tests may touch the user's own history."""
    monkeypatch.setenv("XDG_DATA_HOME", str(tmp_path / "xdg"))
    monkeypatch.chdir(tmp_path)


# --------------------------------------------------------------------------- the store
def test_round_trip_keeps_the_document_verbatim_and_its_facts(url):
    docs = [make_doc(1), make_doc(2, full=True, temperature=31.5,
                                  created="2026-01-06T09:00:00+01:00", ok=False),
            make_doc(3, temperature=None, ok=None, created="2026-01-07T00:00:00")]
    with H.open_history(url) as store:
        ids = [store.add(d, label="imu-07", source=f"/runs/{i}", jig="jig-a").id
               for i, d in enumerate(docs)]
        assert store.count() == 3
        recs = store.records("imu-07")
    assert [r.document for r in recs] == docs  # verbatim, oldest first
    r0, r1, r2 = recs
    assert [r.id for r in recs] == ids
    assert (r0.temperature_c, r1.temperature_c, r2.temperature_c) == (25.0, 31.5, None)
    assert (r0.verdict, r1.verdict, r2.verdict) == ("consistent", "inconsistent", "untested")
    assert (r0.format_version, r1.format_version) == (1, 2)
    assert r1.created == "2026-01-06T08:00:00+00:00"  # normalised to UTC
    assert r0.identity == {"model": "mpu9250"} and r0.jig == "jig-a" and r1.source == "/runs/1"
    assert r0.content_hash == H.content_hash(json.loads(docs[0]))
    with H.open_history(url, create=False) as store:  # reopened: the same
        assert store.get(ids[1]).document == docs[1]
        (s,) = store.sensors()
    assert (s.label, s.model, s.count) == ("imu-07", "mpu9250", 3)
    assert (s.temperature_min_c, s.temperature_max_c) == (25.0, 31.5)


def test_records_are_oldest_first_and_undated_last(url):
    undated = json.loads(make_doc(14))
    undated["created"] = None
    with H.open_history(url) as store:
        store.add(json.dumps(undated), label="u")
        store.add(make_doc(15, created="2026-05-01T00:00:00Z"), label="u")
        store.add(make_doc(16, created="2026-04-01T00:00:00Z"), label="u")
        assert [r.created for r in store.records("u")] == [
            "2026-04-01T00:00:00+00:00", "2026-05-01T00:00:00+00:00", None]


def test_a_document_is_stored_once_whatever_its_layout_or_label(url):
    doc = make_doc(4)
    with H.open_history(url) as store:
        first = store.add(doc, label="a")
        again = store.add(json.dumps(json.loads(doc)), label="b")  # re-indented, other label
        assert again.duplicate and again.id == first.id and again.duplicate_of == "a"
        assert store.count() == 1


def test_a_label_keeps_its_chip_model(url):
    with H.open_history(url) as store:
        store.add(make_doc(5), label="imu-07")
        with pytest.raises(H.HistoryError, match="is an mpu9250 in the history.*lsm9ds1"):
            store.add(make_doc(6, model="lsm9ds1"), label="imu-07")
        assert store.count() == 1


@pytest.mark.parametrize("text, says", [
    ("{", "not valid JSON"),
    ('{"format": "gyrocal-calibration", "version": 7}', "version 7 is not supported"),
    (json.dumps({**json.loads(make_doc(7)), "scale": [1, 1]}), "scale"),
])
def test_invalid_documents_are_refused_and_nothing_is_stored(url, text, says):
    with H.open_history(url) as store:
        with pytest.raises(H.HistoryError, match=says):
            store.add(text, label="x")
        assert store.count() == 0


# --------------------------------------------------------------------------- crash, concurrency
CHILD = textwrap.dedent("""
    import os, sys, time
    from gyrocal.kit import history as H
    sys.path.insert(0, sys.argv[3])
    from test_history import make_doc
    url, mode = sys.argv[1], sys.argv[2]
    store = H.open_history(url)
    if mode == "hang":  # stop inside the write transaction, after the INSERT
        real = store.dialect.insert
        def insert(cur, statement, params):
            rid = real(cur, statement, params)
            if statement.startswith("INSERT INTO calibrations"):
                print("inside", flush=True)
                time.sleep(60)
            return rid
        store.dialect.insert = insert
        store.add(make_doc(100), label="k")
    else:  # mode "writer:N:SEED": N documents, say each once committed
        _, n, seed = mode.split(":")
        for i in range(int(n)):
            store.add(make_doc(int(seed) * 1000 + i), label="w" + seed, jig=seed)
            print(i, flush=True)
""")


def _child(tmp_path, url, mode):
    script = tmp_path / "child.py"
    if not script.exists():  # rewriting it while an earlier child reads it gives that child
        script.write_text(CHILD)  # an empty script: exit 0 with nothing printed
    return subprocess.Popen([sys.executable, str(script), url, mode, str(Path(__file__).parent)],
                            stdout=subprocess.PIPE, text=True)


def _all_whole(url):
    with H.open_history(url, create=False) as store:
        recs = store.records()
    for r in recs:
        assert H.content_hash(json.loads(r.document)) == r.content_hash
        GyroCalibration.from_json(r.document)
    if url.startswith("sqlite:"):
        path = url[len("sqlite:///"):]
        assert sqlite3.connect(path).execute("PRAGMA integrity_check").fetchone() == ("ok",)
    return recs




def test_a_process_killed_inside_the_write_leaves_no_record(tmp_path, url):
    with H.open_history(url) as store:
        store.add(make_doc(99), label="k")
    child = _child(tmp_path, url, "hang")
    try:
        assert child.stdout.readline().strip() == "inside"  # the row is written, not committed
        child.send_signal(signal.SIGKILL)
    finally:
        child.wait(timeout=30)
    assert child.returncode == -signal.SIGKILL
    recs = _all_whole(url)
    assert [json.loads(r.document)["bias"] for r in recs] == [json.loads(make_doc(99))["bias"]]
    with H.open_history(url) as store:  # the database takes writes again, the lock is gone
        assert not store.add(make_doc(100), label="k").duplicate
        assert store.count() == 2


def test_a_writer_killed_at_a_random_moment_leaves_only_whole_records(tmp_path, url):
    H.open_history(url).close()
    child = _child(tmp_path, url, "writer:400:1")
    committed = -1
    try:
        rng = np.random.default_rng(3)
        for _ in range(int(rng.integers(5, 25))):
            committed = int(child.stdout.readline())
        child.send_signal(signal.SIGKILL)
    finally:
        child.wait(timeout=30)
    # the lines it wrote before the kill that were not read yet report commits too (on a loaded
    # host the reading lags the writing by several commits: 23 records after 20 read lines)
    for line in child.stdout:
        committed = int(line)
    recs = _all_whole(url)
    # every commit the child reported is there; at most one more committed before it could say
    assert committed + 1 <= len(recs) <= committed + 2


def test_several_writers_at_once_lose_nothing(tmp_path, url):
    H.open_history(url).close()
    seeds = (1, 2, 3, 4)
    children = [_child(tmp_path, url, f"writer:20:{seed}") for seed in seeds]
    for c in children:
        out, _ = c.communicate(timeout=120)
        assert c.returncode == 0 and out.split() == [str(i) for i in range(20)]
    recs = _all_whole(url)
    assert len(recs) == 80 and len({r.id for r in recs}) == 80
    for seed in seeds:
        mine = [r for r in recs if r.label == f"w{seed}"]
        assert sorted(r.document for r in mine) == sorted(
            make_doc(seed * 1000 + i) for i in range(20))


@needs_pg
def test_a_server_that_goes_away_mid_write_loses_that_write_only():
    """The server ends the writer's connection between its INSERT and its COMMIT (as a server
    that stops, restarts or fails over): the write is a clear error saying nothing of it was
    stored, the records before it are whole, and the next write goes through."""
    psycopg = pytest.importorskip("psycopg")
    pg_url = _scratch_pg()
    with H.open_history(pg_url) as store:
        store.add(make_doc(70), label="s")
        pid = store._conn.info.backend_pid
        real = store.dialect.insert

        def insert(cur, statement, params):
            rid = real(cur, statement, params)
            if statement.startswith("INSERT INTO calibrations"):
                with psycopg.connect(pg_url, autocommit=True) as admin:
                    admin.execute("SELECT pg_terminate_backend(%s)", (pid,))
            return rid

        store.dialect.insert = insert
        with pytest.raises(H.HistoryDatabaseError, match="a write it cut short stored nothing"):
            store.add(make_doc(71), label="s")
    recs = _all_whole(pg_url)
    assert [r.document for r in recs] == [make_doc(70)]
    with H.open_history(pg_url) as store:
        assert not store.add(make_doc(71), label="s").duplicate
        assert store.count() == 2


def test_a_locked_database_is_a_clear_error(sqlite_url):
    H.open_history(sqlite_url).close()
    blocker = sqlite3.connect(sqlite_url[len("sqlite:///"):], isolation_level=None)
    blocker.execute("BEGIN IMMEDIATE")
    try:
        with H.open_history(sqlite_url, timeout_s=0.2) as store, \
                pytest.raises(H.HistoryDatabaseError, match="locked by another process"):
            store.add(make_doc(8), label="x")
    finally:
        blocker.execute("ROLLBACK")
    with H.open_history(sqlite_url) as store:
        assert store.count() == 0


# --------------------------------------------------------------------------- schema, portability
def test_the_schema_is_versioned_and_a_newer_one_is_left_alone(tmp_path, sqlite_url):
    H.open_history(sqlite_url).close()
    path = sqlite_url[len("sqlite:///"):]
    con = sqlite3.connect(path)
    assert con.execute("SELECT version FROM gyrocal_schema").fetchall() == [(H.SCHEMA_VERSION,)]
    con.execute("UPDATE gyrocal_schema SET version = 99")
    con.commit()
    con.close()
    with pytest.raises(H.HistoryDatabaseError, match="schema version 99, newer"):
        H.open_history(sqlite_url)
    con = sqlite3.connect(path)
    assert con.execute("SELECT version FROM gyrocal_schema").fetchall() == [(99,)]


def test_an_older_schema_is_migrated_keeping_its_records(sqlite_url, monkeypatch):
    with H.open_history(sqlite_url) as store:
        store.add(make_doc(9), label="old")
    monkeypatch.setattr(H, "MIGRATIONS", {
        **H.MIGRATIONS, 2: ("ALTER TABLE calibrations ADD COLUMN note TEXT",)})
    monkeypatch.setattr(H, "SCHEMA_VERSION", 2)
    with H.open_history(sqlite_url) as store:
        assert store.migrate() == 2  # done on open: already up to date
        assert store.records("old")[0].document == make_doc(9)
    con = sqlite3.connect(sqlite_url[len("sqlite:///"):])
    assert con.execute("SELECT version FROM gyrocal_schema").fetchall() == [(2,)]
    assert con.execute("SELECT note FROM calibrations").fetchall() == [(None,)]


def test_a_server_url_without_psycopg_says_what_to_install(monkeypatch):
    monkeypatch.setitem(sys.modules, "psycopg", None)  # import psycopg raises ImportError
    with pytest.raises(H.HistoryDatabaseError, match=r"pip install 'gyrocal\[postgres\]'"):
        H.open_history("postgresql://lab@db.example/gyrocal")


def test_every_statement_is_portable_sql():
    """No SQLite-only syntax in the statements; PostgreSQL's placeholders replace every ``?``.

    The statements are run on SQLite by every other test here; on PostgreSQL only by
    :func:`test_round_trip_on_a_postgresql_server` (needs a server).
    """
    sqlite_only = re.compile(r"PRAGMA|AUTOINCREMENT|INSERT OR|REPLACE INTO|GLOB|sqlite_|"
                             r"\bIFNULL\b|\bLIMIT\s+\?\s*,|`", re.I)
    pg = H.PostgresDialect.__new__(H.PostgresDialect)
    statements = list(H.QUERIES.values()) + [s for v in H.MIGRATIONS.values() for s in v]
    for s in statements:
        assert not sqlite_only.search(s), s
        assert pg.sql(s).count("%s") == s.count("?") and "?" not in pg.sql(s)
    assert "AUTOINCREMENT" not in pg.ddl(H.MIGRATIONS[1][1])
    assert "IDENTITY" in pg.ddl(H.MIGRATIONS[1][1])
    assert sorted(H.MIGRATIONS) == list(range(1, H.SCHEMA_VERSION + 1))


@needs_pg
def test_round_trip_on_a_postgresql_server():
    pg_url = _scratch_pg()
    docs = [make_doc(11), make_doc(12, full=True, temperature=30.0)]
    with H.open_history(pg_url) as store:
        ids = [store.add(d, label="imu-pg", jig="j").id for d in docs]
        assert store.add(docs[0], label="other").duplicate
        with pytest.raises(H.HistoryError, match="is an mpu9250"):
            store.add(make_doc(13, model="lsm9ds1"), label="imu-pg")
        recs = store.records("imu-pg")
        assert [r.document for r in recs] == docs and [r.id for r in recs] == ids
        assert store.sensors()[0].count == 2 and store.get(ids[1]).format_version == 2
    with H.open_history(pg_url) as store:  # migrate() on an up-to-date schema is a no-op
        assert store.count() == 2


# --------------------------------------------------------------------------- import, export, trend
def test_import_a_directory_of_v1_v2_and_a_bad_file(tmp_path, url, capsys):
    d = tmp_path / "cals"
    d.mkdir()
    (d / "a.json").write_text(make_doc(21))
    (d / "b.json").write_text(make_doc(22, full=True))
    (d / "bad.json").write_text('{"format": "gyrocal-calibration", "version": 1}')
    (d / "run1").mkdir()
    (d / "run1" / "calibration.json").write_text(make_doc(23, temperature=28.0))
    (d / "copy.json").write_text(json.dumps(json.loads(make_doc(21)), indent=4))
    (d / "other-v1.json").write_text(contract_doc(24, full=False))
    (d / "other-v2.json").write_text(contract_doc(25, full=True))
    code = main(["history", "import", str(d), "--sensor-label", "imu-9", "--history", url])
    out, err = capsys.readouterr()
    assert code == 2, "a refused file makes the import exit 2"
    assert "bad.json" in err and "lacks the field 'scale'" in err and "Traceback" not in err
    assert "5 stored, 1 already in the history, 1 refused" in out
    with H.open_history(url) as store:
        recs = store.records("imu-9")
    assert sorted(r.format_version for r in recs) == [1, 1, 1, 2, 2]
    assert {Path(r.source).name for r in recs} == {"a.json", "b.json", "calibration.json",
                                                    "other-v1.json", "other-v2.json"}
    other = {Path(r.source).name: r for r in recs}["other-v2.json"]
    assert other.document == contract_doc(25, full=True) and other.temperature_c == 22.5
    assert other.created == "2025-12-01T08:00:00+00:00" and other.method == "other-tool"
    assert all(r.jig is None for r in recs)  # an imported file's jig is not known


def test_export_then_import_gives_the_same_documents(tmp_path, url, capsys):
    docs = [make_doc(30 + i, full=i % 2 == 1, created=f"2026-02-0{i + 1}T08:00:00+00:00")
            for i in range(4)]
    with H.open_history(url) as store:
        for d in docs:
            store.add(d, label="imu-e")
    assert main(["history", "export", "imu-e", str(tmp_path / "out"), "--history", url]) == 0
    files = sorted((tmp_path / "out").glob("*.json"))
    assert [f.read_text() for f in files] == docs  # named by date: in time order, verbatim
    assert main(["history", "export", "imu-e", str(tmp_path / "out"), "--history", url]) == 2
    assert "already exists" in capsys.readouterr().err
    other = f"sqlite:///{tmp_path / 'other.sqlite'}"
    with H.open_history(other) as store:
        report = import_dir(store, tmp_path / "out", label="imu-e")
        assert len(report.stored) == 4 and not report.refused
        assert {r.content_hash for r in store.records("imu-e")} == {
            H.content_hash(json.loads(d)) for d in docs}


def test_trend_shows_the_drift_that_was_put_in(url, capsys):
    # bias moves 2e-4 rad/s per °C and scale 30 ppm per day, on x; a v2 matrix's cross-axis
    # term in the last two
    base = json.loads(make_doc(40))
    docs = []
    for i in range(5):
        d = dict(base, temperature_c=20.0 + 2.5 * i, created=f"2026-03-{1 + 3 * i:02d}T12:00:00Z")
        d["bias"] = [base["bias"][0] + 2e-4 * 2.5 * i, *base["bias"][1:]]
        d["scale"] = [base["scale"][0] * (1 + 30e-6 * 3 * i), *base["scale"][1:]]
        docs.append(json.dumps(d))
    with H.open_history(url) as store:
        for d in docs:
            store.add(d, label="imu-t")
        t = trend(store.records("imu-t"))
    assert t["rows"][4]["scale_change_ppm"][0] == pytest.approx(360.0)
    assert t["per_degree"]["bias_x"] == pytest.approx(2e-4)
    assert t["per_degree"]["bias_y"] == pytest.approx(0.0, abs=1e-15)
    assert t["per_day"]["scale_ppm_x"] == pytest.approx(30.0)
    assert t["per_degree"]["cross_xy"] is None  # v1 documents: no cross-axis terms
    assert main(["history", "trend", "imu-t", "--history", url]) == 0
    out = capsys.readouterr().out
    assert "+360" in out and "per °C (least-squares slope)" in out and "+0.2000" in out
    assert main(["history", "trend", "imu-t", "--history", url, "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["per_degree"]["bias_x"] == pytest.approx(2e-4)


def test_trend_plot(tmp_path, url, capsys):
    pytest.importorskip("matplotlib")
    with H.open_history(url) as store:
        store.add(make_doc(50), label="p")
        store.add(make_doc(51, full=True, temperature=27.0,
                           created="2026-01-09T10:00:00+00:00"), label="p")
    png = tmp_path / "trend.png"
    assert main(["history", "trend", "p", "--history", url, "--plot", str(png)]) == 0
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert main(["history", "trend", "p", "--history", url, "--plot", str(png)]) == 2
    assert "already exists" in capsys.readouterr().err


def test_trend_plot_without_matplotlib_says_what_to_install(url, monkeypatch, capsys):
    with H.open_history(url) as store:
        store.add(make_doc(52), label="p")
    monkeypatch.setitem(sys.modules, "matplotlib", None)
    assert main(["history", "trend", "p", "--history", url, "--plot", "t.png"]) == 2
    assert "pip install 'gyrocal[plot]'" in capsys.readouterr().err
    assert not Path("t.png").exists()


def test_where_a_calibration_is_stored(monkeypatch):
    monkeypatch.setattr(H.socket, "gethostname", lambda: "pi-jig")
    cfg = {"url": "sqlite:///cfg.sqlite", "sensor_label": "imu-1", "jig": ""}
    assert H.history_target(None, None, {"url": "", "sensor_label": "", "jig": ""}) is None
    assert H.history_target(None, None, cfg) == H.HistoryTarget(
        "sqlite:///cfg.sqlite", "imu-1", "pi-jig")  # history.url alone stores
    assert H.history_target("sqlite:///flag.sqlite", "imu-2", cfg) == H.HistoryTarget(
        "sqlite:///flag.sqlite", "imu-2", "pi-jig")  # flags win
    assert H.history_target("", None, {**cfg, "url": "", "jig": "j1"}) == H.HistoryTarget(
        H.default_url(), "imu-1", "j1")  # --history without URL and no history.url
    with pytest.raises(H.HistoryError, match="history.sensor_label"):
        H.history_target("", None, {"url": "", "sensor_label": "", "jig": ""})


# --------------------------------------------------------------------------- CLI errors
def test_history_command_errors_are_clear(tmp_path, sqlite_url, capsys):
    def run(*argv):
        code = main(["history", *argv])
        err = capsys.readouterr().err
        assert "Traceback" not in err
        return code, err

    code, err = run("list", "--history", sqlite_url)
    assert code == 2 and "there is no history database" in err
    assert not Path(sqlite_url[len("sqlite:///"):]).exists(), \
        "reading must not create a database"
    code, err = run("list")  # the local default, under XDG_DATA_HOME
    assert code == 2 and str(tmp_path / "xdg" / "gyrocal" / "history.sqlite") in err
    junk = tmp_path / "junk.sqlite"
    junk.write_bytes(b"this is not a database" * 100)
    code, err = run("list", "--history", f"sqlite:///{junk}")
    assert code == 2 and "not a SQLite database or is damaged" in err
    code, err = run("list", "--history", "mysql://x")
    assert code == 2 and "is not a history database URL" in err
    with H.open_history(sqlite_url) as store:
        store.add(make_doc(60), label="s1")
    code, err = run("show", "7", "--history", sqlite_url)
    assert code == 2 and "no calibration #7" in err
    code, err = run("list", "nobody", "--history", sqlite_url)
    assert code == 2 and "no sensor 'nobody'" in err and "'s1'" in err
    code, err = run("import", str(tmp_path / "nope"), "--sensor-label", "s1", "--history",
                    sqlite_url)
    assert code == 2 and "not a directory" in err
    assert main(["history", "show", "1", "--history", sqlite_url, "--json"]) == 0
    shown = json.loads(capsys.readouterr().out)
    assert shown["document"] == json.loads(make_doc(60)) and shown["sensor"] == "s1"


def test_the_config_names_the_database(tmp_path, sqlite_url, capsys):
    with H.open_history(sqlite_url) as store:
        store.add(make_doc(61), label="cfg")
    (tmp_path / "gyrocal.toml").write_text(f'[history]\nurl = "{sqlite_url}"\n')
    assert main(["history", "list"]) == 0
    assert "cfg" in capsys.readouterr().out
    (tmp_path / "gyrocal.toml").write_text('[history]\nurl = "somewhere"\n')
    assert main(["history", "list"]) == 2
    assert "config key history.url" in capsys.readouterr().err


# --------------------------------------------------------------------------- storing from estimate
@pytest.fixture(scope="module")
def recording(tmp_path_factory):
    out = tmp_path_factory.mktemp("rec") / "run"
    assert main(["simulate-recording", str(out), "--seed", "11"]) == 0
    return out


def test_estimate_stores_its_calibration(recording, tmp_path, url, capsys):
    out = tmp_path / "cal.json"
    assert main(["estimate", str(recording), "--out", str(out), "--history", url,
                 "--sensor-label", "sim-1"]) == 0
    assert "stored in the history" in capsys.readouterr().err
    with H.open_history(url) as store:
        (rec,) = store.records("sim-1")
    assert rec.document == out.read_text() and rec.source == str(out.resolve())
    assert rec.model == "simulated" and not math.isnan(rec.temperature_c)
    # the same file imported is found by its content
    assert main(["history", "import", str(tmp_path), "--sensor-label", "sim-1",
                 "--history", url]) == 0
    assert "0 stored, 1 already in the history" in capsys.readouterr().out


def test_nothing_is_stored_when_the_estimate_fails(recording, tmp_path, url, monkeypatch,
                                                  capsys):
    import gyrocal.kit.pipeline as pipeline
    from gyrocal.kit.errors import EstimationError

    def fail(*a, **k):
        raise EstimationError("no convergence")

    monkeypatch.setattr(pipeline, "estimate_recording", fail)
    assert main(["estimate", str(recording), "--history", url, "--sensor-label", "s"]) == 6
    assert "stored" not in capsys.readouterr().err
    with H.open_history(url) as store:
        assert store.count() == 0


@pytest.mark.parametrize("argv, says", [
    (["--history", "{url}"], "needs the sensor's label"),
    (["--sensor-label", "x"], "add --history"),
    (["--history", "not-a-url", "--sensor-label", "x"], "not a history database URL"),
    (["--history", "{url}", "--sensor-label", " "], "must name the sensor"),
])
def test_estimate_refuses_a_bad_history_before_the_fit(recording, tmp_path, url, capsys, argv,
                                                        says):
    out = tmp_path / "cal.json"
    argv = [a.replace("{url}", url) for a in argv]
    assert main(["estimate", str(recording), "--out", str(out), *argv]) == 2
    assert says in capsys.readouterr().err
    assert not out.exists()


def test_calibrate_refuses_a_history_without_a_label_before_the_jig_moves(tmp_path, url,
                                                                         capsys):
    assert main(["calibrate", "--sim", "--out", str(tmp_path / "run"), "--history", url]) == 2
    assert "needs the sensor's label" in capsys.readouterr().err
    assert not (tmp_path / "run").exists()
