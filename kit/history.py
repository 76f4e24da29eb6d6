"""Each sensor's calibration history: a store of Calibration documents keyed by sensor identity.

A record holds one Calibration document (v1 or v2) as the JSON text it was given, verbatim, with
what the history is searched and sorted by: the sensor (the user's label and what the chip tells
of itself), when the calibration was made and stored, the mean temperature, the method, the
consistency verdict, the jig that made it and the path it came from. Documents are deduplicated
by the SHA-256 of their canonical JSON (sorted keys, no whitespace), so importing the same file
twice, or a re-indented copy of it, stores it once.

Backends, chosen by a URL (:func:`open_history`):

``sqlite:///PATH`` (the default, :func:`default_url`)
    One file, no server, stdlib :mod:`sqlite3`. ``PATH`` follows SQLAlchemy's convention:
    ``sqlite:///history.sqlite`` is relative, ``sqlite:////home/pi/h.sqlite`` absolute; ``~`` is
    expanded. The file runs in WAL mode with ``synchronous=FULL`` and a busy timeout; every write
    is one ``BEGIN IMMEDIATE`` transaction, so two processes writing at once queue rather than
    fail, and a process killed mid-write leaves its record absent, never half-written (SQLite's
    atomic commit, https://www.sqlite.org/atomiccommit.html).
``postgresql://USER@HOST/DB`` (optional, ``pip install 'gyrocal[postgres]'``: psycopg 3)
    One server for a lab's jigs. PostgreSQL because it is the well-kept open server whose SQL is
    closest to the standard SQLite also follows (``ON CONFLICT DO NOTHING``, transactional DDL),
    so the same statements run on both; MVCC lets jigs write while others read.

Every statement is written once with ``?`` placeholders in SQL both backends accept; a thin
:class:`Dialect` converts the placeholders (``%s`` for psycopg), supplies the one DDL type that
differs (the auto-numbered key), the table-exists query, the write lock and the returned row id.

The schema is versioned in the table ``gyrocal_schema``; :data:`MIGRATIONS` lists the statements
that bring a database from each version to the next, run in one transaction on open. A database
written by a newer gyrocal is refused, never modified.

Nothing here imports numpy; a document is validated (:class:`gyrocal.calib.model.GyroCalibration`)
only when it is added.
"""

from __future__ import annotations

import abc
import contextlib
import hashlib
import json
import os
import socket
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from gyrocal.kit.errors import InputError

__all__ = [
    "DEFAULT_TIMEOUT_S",
    "MIGRATIONS",
    "SCHEMA_VERSION",
    "AddResult",
    "Dialect",
    "HistoryDatabaseError",
    "HistoryError",
    "HistoryRecord",
    "HistoryStore",
    "HistoryTarget",
    "SensorSummary",
    "check_label",
    "check_target",
    "check_url",
    "content_hash",
    "default_url",
    "history_target",
    "open_history",
    "sensor_identity",
    "store_calibration",
]

#: The schema version this gyrocal writes (the last key of :data:`MIGRATIONS`).
SCHEMA_VERSION = 1
#: How long a writer waits for another one before giving up, s.
DEFAULT_TIMEOUT_S = 30.0
#: Longest sensor label.
MAX_LABEL = 64
#: Largest document stored (a Calibration v2 is a few kB).
MAX_DOCUMENT_BYTES = 1 << 20
#: Keys of a Calibration's ``sensor`` object that identify the chip (copied into the identity
#: when present): the model (the drivers derive it from WHO_AM_I), and the identity byte and a
#: serial or unique ID should a reader's manifest ever carry them (none of today's does: the
#: MPU-9250 and LSM9DS1 have no unique-ID register).
IDENTITY_KEYS = ("model", "who_am_i", "serial", "unique_id")

#: ``{version: statements}`` bringing a database from ``version - 1`` to ``version``. ``{id}`` is
#: the dialect's auto-numbered primary key. Append a new version; never edit an old one. Text a
#: document brings (method, model, source) is TEXT: PostgreSQL enforces a VARCHAR's length,
#: SQLite does not, so a bounded column would store on one backend what the other refuses.
MIGRATIONS: dict[int, tuple[str, ...]] = {
    1: (
        "CREATE TABLE gyrocal_schema (version INTEGER NOT NULL)",
        "CREATE TABLE sensors ("
        " id {id},"
        " label VARCHAR(64) NOT NULL UNIQUE,"
        " model TEXT NOT NULL,"
        " identity TEXT NOT NULL,"
        " first_stored VARCHAR(40) NOT NULL)",
        "CREATE TABLE calibrations ("
        " id {id},"
        " sensor_id INTEGER NOT NULL REFERENCES sensors (id),"
        " content_hash CHAR(64) NOT NULL UNIQUE,"
        " created VARCHAR(40),"
        " stored_at VARCHAR(40) NOT NULL,"
        " temperature_c DOUBLE PRECISION,"
        " method TEXT NOT NULL,"
        " verdict VARCHAR(16) NOT NULL,"
        " format_version INTEGER NOT NULL,"
        " jig TEXT,"
        " source TEXT,"
        " document TEXT NOT NULL)",
        "CREATE INDEX calibrations_by_sensor ON calibrations (sensor_id, created)",
        "INSERT INTO gyrocal_schema (version) VALUES (0)",
    ),
}

_RECORD_COLUMNS = ("c.id, s.label, s.model, s.identity, c.created, c.stored_at, c.temperature_c, "
                   "c.method, c.verdict, c.format_version, c.jig, c.source, c.content_hash, "
                   "c.document")
#: Oldest first, undated last, on both backends (their NULLs sort differently by default).
_BY_TIME = "CASE WHEN c.created IS NULL THEN 1 ELSE 0 END, c.created, c.id"
#: Every query the store runs, in the SQL both backends accept, ``?`` placeholders.
QUERIES: dict[str, str] = {
    "version": "SELECT version FROM gyrocal_schema",
    "set_version": "UPDATE gyrocal_schema SET version = ?",
    "add_sensor": "INSERT INTO sensors (label, model, identity, first_stored) VALUES (?, ?, ?, ?) "
                  "ON CONFLICT (label) DO NOTHING",
    "sensor_by_label": "SELECT id, model, identity FROM sensors WHERE label = ?",
    "by_hash": "SELECT c.id, s.label FROM calibrations c JOIN sensors s ON s.id = c.sensor_id "
               "WHERE c.content_hash = ?",
    "add_calibration": "INSERT INTO calibrations (sensor_id, content_hash, created, stored_at, "
                       "temperature_c, method, verdict, format_version, jig, source, document) "
                       "VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?) "
                       "ON CONFLICT (content_hash) DO NOTHING",
    "records_of": f"SELECT {_RECORD_COLUMNS} FROM calibrations c "
                  "JOIN sensors s ON s.id = c.sensor_id WHERE s.label = ? "
                  f"ORDER BY {_BY_TIME}",
    "all_records": f"SELECT {_RECORD_COLUMNS} FROM calibrations c "
                   f"JOIN sensors s ON s.id = c.sensor_id ORDER BY s.label, {_BY_TIME}",
    "record": f"SELECT {_RECORD_COLUMNS} FROM calibrations c "
              "JOIN sensors s ON s.id = c.sensor_id WHERE c.id = ?",
    "sensors": "SELECT s.label, s.model, s.identity, COUNT(c.id), MIN(c.created), "
               "MAX(c.created), MIN(c.temperature_c), MAX(c.temperature_c) "
               "FROM sensors s LEFT JOIN calibrations c ON c.sensor_id = s.id "
               "GROUP BY s.id, s.label, s.model, s.identity ORDER BY s.label",
    "count": "SELECT COUNT(*) FROM calibrations",
}


class HistoryError(InputError):
    """The history refuses a record or a request: a bad document, label, URL or record number
    (exit 2)."""


class HistoryDatabaseError(HistoryError):
    """The database itself: missing, not a database or damaged, locked, of a newer schema,
    unreachable (exit 2)."""


# --------------------------------------------------------------------------- identity, checks
def check_label(label: Any, flag: str = "--sensor-label") -> str:
    """The sensor label, checked: 1..64 printable characters, not only spaces.

    Raises
    ------
    HistoryError
        Naming ``flag`` and what is allowed.
    """
    if not isinstance(label, str) or not label.strip():
        raise HistoryError(f"{flag} must name the sensor (the label on it, e.g. 'imu-07'): "
                           "one label per physical sensor keeps its history apart")
    if len(label) > MAX_LABEL or not label.isprintable():
        raise HistoryError(f"{flag} {label[:MAX_LABEL]!r}: use at most {MAX_LABEL} printable "
                           "characters")
    return label.strip()


def check_url(url: Any, flag: str = "--history") -> str:
    """A history URL, checked: ``sqlite:///PATH`` or ``postgresql://...``.

    Raises
    ------
    HistoryError
        If ``url`` is neither (the message names ``flag`` and both forms).
    """
    text = str(url)
    if text.startswith("sqlite:///") and len(text) > len("sqlite:///"):
        return text
    if text.startswith(("postgresql://", "postgres://")):
        return text
    raise HistoryError(
        f"{flag} {text!r} is not a history database URL: give sqlite:///PATH (a file; "
        "sqlite:////abs/path for an absolute path) or postgresql://USER@HOST/DB (a lab server). "
        "With estimate, put --history after the recording directory, or give the URL")


def default_url() -> str:
    """The single-machine default: ``$XDG_DATA_HOME/gyrocal/history.sqlite`` (else
    ``~/.local/share/gyrocal/history.sqlite``)."""
    base = os.environ.get("XDG_DATA_HOME") or str(Path.home() / ".local" / "share")
    return "sqlite:///" + str(Path(base) / "gyrocal" / "history.sqlite")


def sensor_identity(sensor: Mapping[str, Any]) -> dict[str, Any]:
    """What a Calibration's ``sensor`` object says of the chip (:data:`IDENTITY_KEYS`)."""
    ident = {k: sensor[k] for k in IDENTITY_KEYS if sensor.get(k) is not None}
    ident["model"] = str(ident.get("model", "unknown"))[:MAX_LABEL]
    return {k: (v if isinstance(v, (str, int, float)) else str(v)) for k, v in ident.items()}


def content_hash(doc: Mapping[str, Any]) -> str:
    """SHA-256 (hex) of ``doc`` as canonical JSON: sorted keys, no whitespace, UTF-8."""
    canon = json.dumps(doc, sort_keys=True, separators=(",", ":"), ensure_ascii=False,
                       allow_nan=False)
    return hashlib.sha256(canon.encode("utf-8")).hexdigest()


def _utc_text(when: Any) -> str | None:
    """An ISO-8601 time as UTC text (sortable); naive times are taken as UTC; None if not one."""
    if not isinstance(when, str):
        return None
    try:
        t = datetime.fromisoformat(when)
    except ValueError:
        return None
    if t.tzinfo is None:
        t = t.replace(tzinfo=UTC)
    try:
        return t.astimezone(UTC).isoformat(timespec="seconds")
    except OverflowError:  # an offset that carries it past year 1 or 9999
        return None


#: The ``created`` times a stored calibration may have, UTC ISO-8601 (inclusive, exclusive):
#: no MEMS gyro was calibrated before 1970, and a time past 2100 is a wrong clock or a typing
#: slip; both would stretch the trend's time axis (and, at ``datetime``'s own edges, break it).
CREATED_RANGE = ("1970-01-01T00:00:00+00:00", "2100-01-01T00:00:00+00:00")


def _created_problem(created: Any) -> str | None:
    """Why a document's ``created`` cannot be stored, or None (absent is allowed)."""
    if created is None:
        return None
    text = _utc_text(created)
    if text is None:
        return (f"its 'created' {str(created)[:60]!r} is not an ISO-8601 time in the range of "
                "dates (e.g. 2026-03-01T12:00:00Z)")
    if not CREATED_RANGE[0] <= text < CREATED_RANGE[1]:
        return (f"its 'created' {text} is outside {CREATED_RANGE[0][:4]}..."
                f"{int(CREATED_RANGE[1][:4]) - 1}: a wrong clock or a typing slip; the trend "
                "cannot place it in time")
    return None


def _now() -> str:
    return datetime.now(UTC).isoformat(timespec="seconds")


# --------------------------------------------------------------------------- records
@dataclass(frozen=True)
class HistoryRecord:
    """One stored calibration.

    Attributes
    ----------
    id : int
        The record's number in this database.
    label : str
        The sensor's label.
    model : str
        The sensor's model (from the document's ``sensor.model``).
    identity : dict
        What the chip told of itself (:func:`sensor_identity`) when the sensor was first stored.
    created : str or None
        The calibration's ``created`` time, UTC ISO-8601 (None if the document has none).
    stored_at : str
        When the record was stored, UTC ISO-8601.
    temperature_c : float or None
        The calibration's mean die temperature.
    method : str
        The estimator.
    verdict : str
        ``consistent``, ``inconsistent`` or ``untested`` (the document's consistency test).
    format_version : int
        Calibration version, 1 (diagonal) or 2 (full matrix).
    jig : str or None
        The jig (or host) that stored it.
    source : str or None
        The file or run directory it came from.
    content_hash : str
        :func:`content_hash` of the document.
    document : str
        The Calibration document, the JSON text as given.
    """

    id: int
    label: str
    model: str
    identity: dict[str, Any]
    created: str | None
    stored_at: str
    temperature_c: float | None
    method: str
    verdict: str
    format_version: int
    jig: str | None
    source: str | None
    content_hash: str
    document: str

    @classmethod
    def _from_row(cls, row: Sequence[Any]) -> HistoryRecord:
        (rid, label, model, identity, created, stored_at, temp, method, verdict, version, jig,
         source, digest, document) = row
        return cls(int(rid), label, model, json.loads(identity), created, stored_at,
                   None if temp is None else float(temp), method, verdict, int(version), jig,
                   source, digest, document)

    def summary(self) -> dict[str, Any]:
        """Everything but the document, JSON-ready."""
        return {"id": self.id, "sensor": self.label, "model": self.model,
                "identity": self.identity, "created": self.created,
                "stored_at": self.stored_at, "temperature_c": self.temperature_c,
                "method": self.method, "verdict": self.verdict, "version": self.format_version,
                "jig": self.jig, "source": self.source, "content_hash": self.content_hash}


@dataclass(frozen=True)
class SensorSummary:
    """A sensor in the history: its label, identity and the span of its calibrations."""

    label: str
    model: str
    identity: dict[str, Any]
    count: int
    first: str | None
    last: str | None
    temperature_min_c: float | None
    temperature_max_c: float | None

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready."""
        return {"sensor": self.label, "model": self.model, "identity": self.identity,
                "calibrations": self.count, "first": self.first, "last": self.last,
                "temperature_min_c": self.temperature_min_c,
                "temperature_max_c": self.temperature_max_c}


@dataclass(frozen=True)
class AddResult:
    """What :meth:`HistoryStore.add` did: the record's id, and whether it was already stored
    (``duplicate_of``: the label it is stored under)."""

    id: int
    duplicate_of: str | None = None

    @property
    def duplicate(self) -> bool:
        """Whether the document was already in the history."""
        return self.duplicate_of is not None


# --------------------------------------------------------------------------- dialects
class Dialect(abc.ABC):
    """What differs between the backends; the statements themselves do not.

    Subclasses set :attr:`name`, :attr:`paramstyle_marker` and :attr:`id_column` and implement
    :meth:`connect`, :meth:`table_exists`, :meth:`begin_write` and :meth:`insert`: SQLite and
    PostgreSQL today; another server (MariaDB: ``INSERT IGNORE`` instead of ``ON CONFLICT``)
    would need its own statements, not only a dialect.
    """

    name = "abstract"
    #: What a ``?`` placeholder becomes.
    paramstyle_marker = "?"
    #: The auto-numbered primary key column type.
    id_column = "INTEGER PRIMARY KEY"

    def sql(self, statement: str) -> str:
        """``statement`` with the dialect's placeholders (no literal ``?`` or ``%`` allowed)."""
        if "%" in statement:
            raise ValueError("a history statement may not contain '%' (psycopg's marker)")
        return statement.replace("?", self.paramstyle_marker)

    def ddl(self, statement: str) -> str:
        """A migration statement with the dialect's key type."""
        return statement.replace("{id}", self.id_column)

    @abc.abstractmethod
    def connect(self, url: str, *, create: bool, timeout_s: float) -> Any:
        """A DB-API connection in autocommit mode (transactions are explicit)."""

    @abc.abstractmethod
    def table_exists(self, cur: Any, name: str) -> bool:
        """Whether the table ``name`` exists."""

    @abc.abstractmethod
    def begin_write(self, cur: Any) -> None:
        """Begin a write transaction that serialises with other writers."""

    @abc.abstractmethod
    def insert(self, cur: Any, statement: str, params: Sequence[Any]) -> int | None:
        """Run an ``INSERT ... ON CONFLICT DO NOTHING``; the new row's id, None if it conflicted."""

    def describe(self, exc: BaseException) -> str | None:
        """A user's message for a backend error, or None if not one of the backend's."""
        return None


class SQLiteDialect(Dialect):
    """SQLite through :mod:`sqlite3` (SQLite 3.24 or newer for ``ON CONFLICT DO NOTHING``)."""

    name = "sqlite"
    id_column = "INTEGER PRIMARY KEY AUTOINCREMENT"

    def __init__(self) -> None:
        import sqlite3

        self.module = sqlite3
        self.path: Path | None = None

    def connect(self, url: str, *, create: bool, timeout_s: float) -> Any:
        path = Path(os.path.expanduser(url[len("sqlite:///"):]))
        self.path = path
        if path.is_dir():
            raise HistoryDatabaseError(f"history database {path} is a directory; give a file "
                               f"(e.g. sqlite:///{path / 'history.sqlite'})")
        if not path.exists():
            if not create:
                raise HistoryDatabaseError(
                    f"there is no history database at {path}; store a calibration with "
                    "--history, or run 'gyrocal history import DIR --sensor-label LABEL'")
            try:
                path.parent.mkdir(parents=True, exist_ok=True)
            except OSError as exc:
                raise HistoryDatabaseError(f"cannot create the directory of the history database "
                                   f"{path}: {exc.strerror or exc}") from None
        try:
            conn = self.module.connect(str(path), timeout=timeout_s, isolation_level=None)
            conn.execute(f"PRAGMA busy_timeout = {int(timeout_s * 1000)}")
            conn.execute("PRAGMA journal_mode = WAL")
            conn.execute("PRAGMA synchronous = FULL")
            conn.execute("PRAGMA foreign_keys = ON")
        except self.module.Error as exc:
            raise HistoryDatabaseError(self.describe(exc) or str(exc)) from None
        return conn

    def table_exists(self, cur: Any, name: str) -> bool:
        cur.execute("SELECT 1 FROM sqlite_master WHERE type = 'table' AND name = ?", (name,))
        return cur.fetchone() is not None

    def begin_write(self, cur: Any) -> None:
        cur.execute("BEGIN IMMEDIATE")  # take the write lock now: no upgrade deadlock later

    def insert(self, cur: Any, statement: str, params: Sequence[Any]) -> int | None:
        cur.execute(self.sql(statement), tuple(params))
        return int(cur.lastrowid) if cur.rowcount == 1 else None

    def describe(self, exc: BaseException) -> str | None:
        if not isinstance(exc, self.module.Error):
            return None
        where = f"history database {self.path}"
        text = str(exc)
        if "locked" in text or "busy" in text:
            return (f"{where} is locked by another process (waited its busy timeout); try "
                    "again when the other gyrocal has finished")
        if "not a database" in text or "malformed" in text or "corrupt" in text:
            return (f"{where} is not a SQLite database or is damaged ({text}); move it aside "
                    "and import the calibration files again ('gyrocal history import')")
        if "readonly" in text or "unable to open" in text:
            return (f"cannot write {where} ({text}); check the permissions of the file and its "
                    "directory")
        return f"{where}: {text}"


class PostgresDialect(Dialect):
    """PostgreSQL through psycopg 3 (the ``postgres`` extra)."""

    name = "postgresql"
    paramstyle_marker = "%s"
    id_column = "INTEGER GENERATED BY DEFAULT AS IDENTITY PRIMARY KEY"
    #: pg_advisory_xact_lock key serialising the store's writers (and its migrations).
    LOCK_KEY = 0x67797263  # "gyrc"

    def __init__(self) -> None:
        try:
            import psycopg
        except ImportError:
            raise HistoryDatabaseError("a postgresql:// history needs psycopg: pip install "
                               "'gyrocal[postgres]'") from None
        self.module = psycopg
        self.url = ""

    def connect(self, url: str, *, create: bool, timeout_s: float) -> Any:
        self.url = "postgresql://" + url.split("://", 1)[1].split("@")[-1]  # no password shown
        try:
            conn = self.module.connect(url, autocommit=True, connect_timeout=int(timeout_s))
            conn.execute(f"SET lock_timeout = {int(timeout_s * 1000)}")
        except self.module.Error as exc:
            raise HistoryDatabaseError(self.describe(exc) or str(exc)) from None
        return conn

    def table_exists(self, cur: Any, name: str) -> bool:
        cur.execute(self.sql("SELECT 1 FROM information_schema.tables WHERE table_name = ? "
                             "AND table_schema = current_schema()"), (name,))
        return cur.fetchone() is not None

    def begin_write(self, cur: Any) -> None:
        cur.execute("BEGIN")
        cur.execute(self.sql("SELECT pg_advisory_xact_lock(?)"), (self.LOCK_KEY,))

    def insert(self, cur: Any, statement: str, params: Sequence[Any]) -> int | None:
        cur.execute(self.sql(statement + " RETURNING id"), tuple(params))
        row = cur.fetchone()
        return None if row is None else int(row[0])

    def describe(self, exc: BaseException) -> str | None:
        if not isinstance(exc, self.module.Error):
            return None
        text = (str(exc).strip().splitlines() or [type(exc).__name__])[0]
        if isinstance(exc, self.module.OperationalError):  # the server or the link went away
            return (f"history server {self.url} is gone or unreachable ({text}); a write "
                    "it cut short stored nothing (its transaction is rolled back): check that "
                    "the server runs and this host reaches it, then run again")
        return f"history server {self.url}: {text}"


def dialect_for(url: str) -> Dialect:
    """The :class:`Dialect` of a checked URL."""
    return SQLiteDialect() if url.startswith("sqlite:") else PostgresDialect()


# --------------------------------------------------------------------------- the store
class HistoryStore:
    """A calibration history (open it with :func:`open_history`; use it as a context manager).

    Parameters
    ----------
    conn : DB-API connection
        In autocommit mode; the store begins and ends its own transactions.
    dialect : Dialect
        The backend's differences.
    url : str
        Shown in messages (a server URL's password is not kept).
    """

    def __init__(self, conn: Any, dialect: Dialect, url: str) -> None:
        self._conn = conn
        self.dialect = dialect
        self.url = url if dialect.name == "sqlite" else getattr(dialect, "url", "postgresql")
        #: One line per damaged row met while reading (skipped, or listed without the damaged
        #: field), for the command to print: a bad row never hides the others.
        self.damaged: list[str] = []

    def __enter__(self) -> HistoryStore:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        """Close the connection."""
        self._conn.close()

    # ------------------------------------------------------------------ transactions
    @contextlib.contextmanager
    def _errors(self) -> Iterator[None]:
        """Backend errors become :class:`HistoryError` with a message that says what to do."""
        try:
            yield
        except HistoryError:
            raise
        except Exception as exc:
            text = self.dialect.describe(exc)
            if text is None:
                raise
            raise HistoryDatabaseError(text) from None

    @contextlib.contextmanager
    def _write(self) -> Iterator[Any]:
        """One write transaction: committed whole at the end, rolled back on any exception."""
        with self._errors():
            cur = self._conn.cursor()
            self.dialect.begin_write(cur)
            try:
                yield cur
            except BaseException:
                with contextlib.suppress(Exception):
                    cur.execute("ROLLBACK")
                raise
            cur.execute("COMMIT")

    def _read(self, name: str, params: Sequence[Any] = ()) -> list[Any]:
        with self._errors():
            cur = self._conn.cursor()
            cur.execute(self.dialect.sql(QUERIES[name]), tuple(params))
            return list(cur.fetchall())

    def _version(self, cur: Any) -> int:
        """The schema version (0: no gyrocal tables yet)."""
        if not self.dialect.table_exists(cur, "gyrocal_schema"):
            if self.dialect.table_exists(cur, "calibrations"):
                raise HistoryDatabaseError(f"{self.url} holds a 'calibrations' table that "
                                           "is not gyrocal's; give another database")
            return 0
        cur.execute(self.dialect.sql(QUERIES["version"]))
        version = int(cur.fetchone()[0])
        if version > SCHEMA_VERSION:
            raise HistoryDatabaseError(
                f"history database {self.url} has schema version {version}, newer than this "
                f"gyrocal's {SCHEMA_VERSION}: upgrade gyrocal (the database is left as it is)")
        return version

    def migrate(self) -> int:
        """Bring the schema to :data:`SCHEMA_VERSION`; the version it had.

        An up-to-date schema is only read (no write lock); otherwise the version is read again
        under the write lock and every missing migration runs in that one transaction, so two
        processes opening a new database at once migrate it once.

        Raises
        ------
        HistoryDatabaseError
            If the database is of a newer gyrocal, or holds a ``calibrations`` table not ours.
        """
        with self._errors():
            before = self._version(self._conn.cursor())
        if before == SCHEMA_VERSION:
            return before
        with self._write() as cur:
            before = self._version(cur)
            for version in range(before + 1, SCHEMA_VERSION + 1):
                for statement in MIGRATIONS[version]:
                    cur.execute(self.dialect.ddl(statement))
            if before < SCHEMA_VERSION:
                cur.execute(self.dialect.sql(QUERIES["set_version"]), (SCHEMA_VERSION,))
        return before

    # ------------------------------------------------------------------ writing
    def add(self, document: str, *, label: str, source: str | None = None,
            jig: str | None = None) -> AddResult:
        """Store one Calibration document (JSON text, kept verbatim) under the sensor ``label``.

        The document is validated first (:meth:`GyroCalibration.from_dict`: v1 or v2). The
        sensor is created on its first calibration with the document's identity
        (:func:`sensor_identity`); a later document whose model differs is refused. A document
        already stored (same :func:`content_hash`) is not stored again.

        Parameters
        ----------
        document : str
            The Calibration JSON text.
        label : str
            The sensor's label (:func:`check_label`).
        source : str, optional
            The file or run directory it came from.
        jig : str, optional
            The jig (or host) that made it; None or empty if unknown (an imported file).

        Returns
        -------
        AddResult

        Raises
        ------
        HistoryError
            Not a valid Calibration document, a model that contradicts the label's sensor, or a
            database error (locked, damaged, unreachable).
        """
        from gyrocal.calib.errors import CalibrationFormatError
        from gyrocal.calib.model import GyroCalibration

        label = check_label(label)
        if len(document.encode("utf-8")) > MAX_DOCUMENT_BYTES:
            raise HistoryError(f"the document is larger than {MAX_DOCUMENT_BYTES} bytes: not a "
                               "calibration")
        try:
            doc = json.loads(document)
            cal = GyroCalibration.from_dict(doc)
        except (ValueError, RecursionError) as exc:  # JSONDecodeError, huge integers
            raise HistoryError(f"not valid JSON: {str(exc)[:120]}") from None
        except CalibrationFormatError as exc:
            raise HistoryError(str(exc)) from None
        problem = _created_problem(cal.created)
        if problem is not None:
            raise HistoryError(problem)
        identity = sensor_identity(cal.sensor)
        c = cal.consistency
        verdict = "untested" if c is None else "consistent" if c.ok else "inconsistent"
        digest = content_hash(doc)
        with self._write() as cur:
            cur.execute(self.dialect.sql(QUERIES["by_hash"]), (digest,))
            row = cur.fetchone()
            if row is not None:
                return AddResult(int(row[0]), duplicate_of=row[1])
            sensor_id = self._sensor(cur, label, identity)
            new = self.dialect.insert(cur, QUERIES["add_calibration"], (
                sensor_id, digest, _utc_text(cal.created), _now(), cal.temperature_c,
                cal.method, verdict, 2 if cal.is_full else 1, jig or None, source, document))
            if new is None:  # cannot happen under the write lock; kept for a shared server
                raise HistoryError("another writer stored the same document at the same "
                                   "moment; run again to see it")
        return AddResult(new)

    def _sensor(self, cur: Any, label: str, identity: dict[str, Any]) -> int:
        """The id of sensor ``label``, created with ``identity`` if new; refuses another model."""
        self.dialect.insert(cur, QUERIES["add_sensor"], (
            label, identity["model"], json.dumps(identity, sort_keys=True), _now()))
        cur.execute(self.dialect.sql(QUERIES["sensor_by_label"]), (label,))
        sid, model, _ = cur.fetchone()
        if model != identity["model"]:
            raise HistoryError(
                f"sensor {label!r} is an {model} in the history, but this calibration is of an "
                f"{identity['model']}: give this sensor its own --sensor-label")
        return int(sid)

    # ------------------------------------------------------------------ reading
    def count(self) -> int:
        """How many calibrations are stored."""
        return int(self._read("count")[0][0])

    def sensors(self) -> list[SensorSummary]:
        """Every sensor with the count and span of its calibrations, by label (a sensor whose
        stored identity is damaged is listed without it, and named in :attr:`damaged`)."""
        out = []
        for label, model, ident, n, first, last, tmin, tmax in self._read("sensors"):
            identity = _json_object(ident)
            if identity is None:
                self.damaged.append(f"sensor {label!r}: its stored identity is not a JSON "
                                    "object; listed without it")
                identity = {}
            out.append(SensorSummary(label, model, identity, int(n), first, last,
                                     None if tmin is None else float(tmin),
                                     None if tmax is None else float(tmax)))
        return out

    def _records(self, rows: Sequence[Sequence[Any]]) -> list[HistoryRecord]:
        """The readable records of ``rows``; each damaged one skipped and named in
        :attr:`damaged`."""
        out = []
        for row in rows:
            problem = _damage(row)
            if problem is None:
                out.append(HistoryRecord._from_row(row))
            else:
                self.damaged.append(f"calibration #{row[0]} of sensor {row[1]!r} is damaged "
                                    f"({problem}); skipped")
        return out

    def records(self, label: str | None = None) -> list[HistoryRecord]:
        """The calibrations of sensor ``label`` (all sensors if None), oldest first.

        Raises
        ------
        HistoryError
            If ``label`` is given and no such sensor is stored (the message lists the labels).
        """
        if label is None:
            return self._records(self._read("all_records"))
        rows = self._read("records_of", (label,))
        if not rows and not self._read("sensor_by_label", (label,)):
            known = ", ".join(repr(s.label) for s in self.sensors()) or "none yet"
            raise HistoryError(f"no sensor {label!r} in the history {self.url} (sensors: "
                               f"{known})")
        return self._records(rows)

    def get(self, record_id: int) -> HistoryRecord:
        """The record numbered ``record_id``.

        Raises
        ------
        HistoryError
            If there is none.
        """
        rows = self._read("record", (int(record_id),))
        if not rows:
            raise HistoryError(f"no calibration #{record_id} in the history {self.url}; "
                               "'gyrocal history list SENSOR' shows the numbers")
        problem = _damage(rows[0])
        if problem is not None:
            raise HistoryError(f"calibration #{record_id} in the history {self.url} is damaged "
                               f"({problem}); the other records are readable")
        return HistoryRecord._from_row(rows[0])


def _json_object(text: Any) -> dict[str, Any] | None:
    """``text`` parsed as a JSON object, or None if it is not one."""
    try:
        value = json.loads(text)
    except (TypeError, ValueError, RecursionError):
        return None
    return value if isinstance(value, dict) else None


def _damage(row: Sequence[Any]) -> str | None:
    """What is wrong with a stored calibration row, or None: its identity and document must be
    JSON objects (a row written by another program, or a damaged file, may not be)."""
    if len(row) != 14:
        return f"{len(row)} columns, not 14"
    if _json_object(row[3]) is None:
        return "its sensor identity is not a JSON object"
    doc = _json_object(row[13])
    if doc is None:
        return "its document is not a JSON object"
    m = doc.get("matrix")
    if m is not None and not (isinstance(m, list) and len(m) == 3 and all(
            isinstance(r, list) and len(r) == 3
            and all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in r)
            for r in m)):
        return "its document's 'matrix' is not 3 × 3 numbers"
    for key in ("scale", "bias"):
        v = doc.get(key)
        if not (isinstance(v, list) and len(v) == 3
                and all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in v)):
            return f"its document's {key!r} is not 3 numbers"
    try:
        int(row[0]), int(row[9])
        None if row[6] is None else float(row[6])
    except (TypeError, ValueError):
        return "a number column holds something else"
    return None


def open_history(url: str, *, create: bool = True,
                 timeout_s: float = DEFAULT_TIMEOUT_S) -> HistoryStore:
    """Open (and, with ``create``, create or migrate) the history at ``url``.

    Parameters
    ----------
    url : str
        ``sqlite:///PATH`` or ``postgresql://...`` (:func:`check_url`).
    create : bool
        Create a missing SQLite file and bring the schema up to date. Without it a missing file
        is an error (the reading commands do not leave empty databases behind).
    timeout_s : float
        How long to wait for another writer.

    Raises
    ------
    HistoryError
        Bad URL, missing file (without ``create``), not a database, locked, newer schema, server
        unreachable, psycopg missing.
    """
    url = check_url(url)
    dialect = dialect_for(url)
    conn = dialect.connect(url, create=create, timeout_s=timeout_s)
    store = HistoryStore(conn, dialect, url)
    try:
        store.migrate()
    except BaseException:
        store.close()
        raise
    return store


# --------------------------------------------------------------------------- storing a run's result
@dataclass(frozen=True)
class HistoryTarget:
    """Where ``gyrocal calibrate``/``estimate`` store their calibration: the database, the
    sensor's label and the jig's name."""

    url: str
    label: str
    jig: str


def history_target(flag_url: str | None, flag_label: str | None,
                   settings: Mapping[str, Any]) -> HistoryTarget | None:
    """Resolve ``--history [URL]``, ``--sensor-label`` and the config's ``[history]``.

    Parameters
    ----------
    flag_url : str or None
        ``--history``'s value: None when the flag is absent, ``""`` when given without a URL
        (then ``history.url``, else :func:`default_url`).
    flag_label : str or None
        ``--sensor-label`` (else ``history.sensor_label``).
    settings : mapping
        The config's ``[history]`` section (``url``, ``sensor_label``, ``jig``); a set
        ``history.url`` stores every calibration without the flag.

    Returns
    -------
    HistoryTarget or None
        None when nothing is to be stored.

    Raises
    ------
    HistoryError
        A bad URL, or a label missing or malformed, or ``--sensor-label`` without a history.
    """
    url = flag_url or settings.get("url") or (default_url() if flag_url == "" else None)
    if not url:
        if flag_label is not None:
            raise HistoryError("--sensor-label names the sensor in the calibration history; "
                               "add --history [URL] (or set history.url in gyrocal.toml)")
        return None
    url = check_url(url, "--history" if flag_url else "history.url")
    label = flag_label if flag_label is not None else settings.get("sensor_label") or None
    if label is None:
        raise HistoryError("storing the calibration in the history needs the sensor's label: "
                           "give --sensor-label LABEL (the name on the sensor, e.g. 'imu-07') "
                           "or set history.sensor_label in gyrocal.toml")
    label = check_label(label, "--sensor-label" if flag_label is not None
                        else "history.sensor_label")
    return HistoryTarget(url, label, settings.get("jig") or socket.gethostname())


def check_target(target: HistoryTarget) -> None:
    """Open (creating it if needed) and close the target's database: before a run, so that an
    unusable history stops the command before the jig moves.

    Raises
    ------
    HistoryError
        As :func:`open_history`.
    """
    open_history(target.url).close()


def store_calibration(target: HistoryTarget, document: str, source: str | None) -> AddResult:
    """Store one Calibration document (JSON text) at ``target`` (see :meth:`HistoryStore.add`).

    Raises
    ------
    HistoryError
        As :meth:`HistoryStore.add`; the message adds that the calibration file is kept and
        how to store it later.
    """
    try:
        with open_history(target.url) as store:
            return store.add(document, label=target.label, source=source, jig=target.jig)
    except HistoryError as exc:
        where = f" ({source})" if source else ""
        raise type(exc)(f"{exc}. The calibration{where} was written but not stored in the "
                           "history; store it later with 'gyrocal history import DIR "
                           "--sensor-label LABEL'") from None
