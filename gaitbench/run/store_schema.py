"""What a results store's database holds: its tables, its schema version, and the migrations that bring a store
written by an older gaitbench up to today's version.

The version is SQLite's ``PRAGMA user_version``. A new store is created at :data:`SCHEMA_VERSION`; an older one
runs the :data:`MIGRATIONS` after its version, in order, in one transaction, and is stamped. Version 0 is a store
from before versions were recorded: it may hold any columns up to today's, so each migration adds only what such a
store lacks. A store of a newer version than this code knows is refused, never changed. Adding a column is one more
:class:`Migration` at the end of the list and its column in the table's dict; ``tests/test_store_schema.py`` checks
that the oldest schema migrated equals a new store.
"""

from __future__ import annotations

import errno
import json
import math
import sqlite3
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from gaitbench._version import __version__

APPLICATION_ID = int.from_bytes(b"gbch", "big")
"""``PRAGMA application_id`` of a gaitbench store: how a store is told from another SQLite file before anything is
written (stores written before it existed are recognized by their tables, and stamped when next written)."""

FINISHED_STATUSES = ("solved", "incomplete", "error", "timeout", "crashed")
"""``solved``: every step solved and verified. ``incomplete``: the method failed at a step (a result, not a
fault). ``error``: the case raised. ``timeout``: it ran past its time limit. ``crashed``: its worker died."""

RETRYABLE_STATUSES = ("error", "timeout", "crashed")
"""Failures of the run rather than of the method: ``--resume --retry-failed`` runs them again."""

STOP_CAUSES = ("complete", "geometry", "solver", "verification", "time_limit", "error", "crashed")
"""Values of the ``stop_cause`` column: why a walk ended (``complete``: it did not stop; null: not recorded, a row
written before the column existed)."""

CASE_COLUMNS: dict[str, str] = {
    "case_key": "TEXT PRIMARY KEY",
    "run_id": "TEXT",
    "suite": "TEXT",
    "method": "TEXT",
    "experiment": "TEXT",
    "experiment_options": "TEXT",
    "N": "INTEGER",
    "steps": "INTEGER",
    "transcription": "TEXT",
    "transcription_options": "TEXT",
    "solver": "TEXT",
    "solver_options": "TEXT",
    "strategy": "TEXT",
    "strategy_options": "TEXT",
    "objective": "TEXT",
    "problem_options": "TEXT",
    "repetition": "INTEGER",
    "time_limit_s": "REAL",
    "tracking_stage": "TEXT",
    "status": "TEXT",
    "message": "TEXT",
    "acot": "REAL",
    "claimed_acot": "REAL",
    "thesis_reading_acot": "REAL",
    "cot_steps": "TEXT",
    "cot_min": "REAL",
    "cot_max": "REAL",
    "steps_solved": "INTEGER",
    "stop_cause": "TEXT",
    "stop_step": "INTEGER",
    "stop_status": "TEXT",
    "retries": "INTEGER",
    "back_ups": "INTEGER",
    "wall_time_s": "REAL",
    "solve_time_s": "REAL",
    "function_time_s": "REAL",
    "iterations": "INTEGER",
    "max_defect": "REAL",
    "max_resim_error": "REAL",
    "verified": "INTEGER",
    "verification_failure": "TEXT",
    "max_join_mismatch": "REAL",
    "join_energy": "REAL",
    "strategy_details": "TEXT",
    "max_position_error": "REAL",
    "max_velocity_error": "REAL",
    "acot_tracked": "REAL",
    "acot_increase_percent": "REAL",
    "fell": "INTEGER",
    "tracking": "TEXT",
    "walk_path": "TEXT",
    "tracking_path": "TEXT",
    "provenance": "TEXT",
    "finished_at": "TEXT",
}
"""Every column of the ``cases`` table, in order (documented in docs/results.md). Columns holding lists or
dicts are JSON text; paths are relative to the store directory. A column added here needs its :class:`Migration`."""

JSON_COLUMNS = ("experiment_options", "transcription_options", "solver_options", "strategy_options",
                "problem_options", "tracking_stage", "cot_steps", "strategy_details", "tracking", "provenance")

RUN_COLUMNS: dict[str, str] = {
    "run_id": "TEXT PRIMARY KEY",
    "suite": "TEXT",
    "suite_path": "TEXT",
    "suite_text": "TEXT",
    "executor": "TEXT",
    "jobs": "INTEGER",
    "cases_total": "INTEGER",
    "cases_skipped": "INTEGER",
    "started_at": "TEXT",
    "finished_at": "TEXT",
    "provenance": "TEXT",
    "host": "TEXT",
    "pid": "INTEGER",
    "heartbeat_at": "TEXT",
}

CLAIM_COLUMNS: dict[str, str] = {
    "case_key": "TEXT PRIMARY KEY",
    "run_id": "TEXT NOT NULL",
    "claimed_at": "TEXT",
}
"""A case being solved and by which run; the row goes when the case's row is written or its run ends."""

TABLES: dict[str, dict[str, str]] = {"runs": RUN_COLUMNS, "cases": CASE_COLUMNS, "claims": CLAIM_COLUMNS}
"""Today's tables, as a new store is created."""


@dataclass(frozen=True)
class Migration:
    """What schema version ``version`` added to the one before: new tables, new columns of existing tables, and the
    ``fill`` statements that give the old rows the value the code that added a column would have written."""

    version: int
    purpose: str
    tables: dict[str, dict[str, str]] = field(default_factory=dict)
    columns: dict[str, dict[str, str]] = field(default_factory=dict)
    """Table → {column: declared type}."""
    fill: tuple[str, ...] = ()

    def applied(self, connection: sqlite3.Connection) -> bool:
        """Whether the store already has every table and column this migration adds (a version-0 store may)."""
        return all(_columns(connection, table) for table in self.tables) and all(
            set(columns) <= _columns(connection, table) for table, columns in self.columns.items())

    def apply(self, connection: sqlite3.Connection) -> None:
        """Add what is missing (``ALTER TABLE ADD COLUMN`` keeps every row), then fill the old rows."""
        for table, columns in self.tables.items():
            connection.execute(create_table(table, columns))
        for table, columns in self.columns.items():
            present = _columns(connection, table)
            for column, kind in columns.items():
                if column not in present:
                    connection.execute(f"ALTER TABLE {table} ADD COLUMN {column} {kind}")
        for statement in self.fill:
            connection.execute(statement)


MIGRATIONS: tuple[Migration, ...] = (
    # Version 1 is the first store: runs and cases, cases without the columns the migrations below add.
    Migration(2, "why a walk stopped",
              columns={"cases": {"stop_cause": "TEXT", "stop_step": "INTEGER", "stop_status": "TEXT",
                                 "retries": "INTEGER"}}),
    Migration(3, "several runs share a store: claims, and the host, pid and heartbeat of each run",
              tables={"claims": {"case_key": "TEXT PRIMARY KEY", "run_id": "TEXT NOT NULL", "claimed_at": "TEXT"}},
              columns={"runs": {"host": "TEXT", "pid": "INTEGER", "heartbeat_at": "TEXT"}}),
    Migration(4, "dead-end back-ups",
              columns={"cases": {"back_ups": "INTEGER"}},
              # counted with the retries (runner.walk_stop), and none was taken before back-ups existed
              fill=("UPDATE cases SET back_ups = 0 WHERE back_ups IS NULL AND retries IS NOT NULL",)),
    Migration(5, "objectives other than net power",
              columns={"cases": {"objective": "TEXT"}},
              fill=("UPDATE cases SET objective = 'net-power' WHERE objective IS NULL",)),  # the only one before
    # left null in older rows: `gaitbench verify --store` checks their walk files and fills them
    Migration(6, "whole-walk verification: the verified flag, its reason, the joins; the thesis's reading",
              columns={"cases": {"thesis_reading_acot": "REAL", "verified": "INTEGER", "verification_failure": "TEXT",
                                 "max_join_mismatch": "REAL", "join_energy": "REAL"}}),
)
"""Every schema change, oldest first; the last one's version is :data:`SCHEMA_VERSION`."""

SCHEMA_VERSION = MIGRATIONS[-1].version
"""The schema version this gaitbench writes and reads; a store of a higher one is refused."""


class StoreError(Exception):
    """A store that is missing, unreadable, not a gaitbench store or too new; the message says which path and why."""


def failure_cause(error: Exception, lock_timeout: float | None = None) -> str:
    """Why a store operation failed, in words: a full disk, a file-size limit, a lock held past ``lock_timeout``,
    a place that cannot be written, else SQLite's or the system's own message."""
    if isinstance(error, sqlite3.Error):
        name = getattr(error, "sqlite_errorname", "") or ""
        if name.startswith(("SQLITE_BUSY", "SQLITE_LOCKED")):
            waited = f" for {lock_timeout:g} s" if lock_timeout is not None else ""
            return (f"{error}: another process holds the store's write lock; waited{waited}, "
                    "--lock-timeout waits longer")
        if name.startswith("SQLITE_IOERR"):
            return f"{error}: the disk may be full, or a file-size limit (ulimit -f) reached"
        if name.startswith("SQLITE_READONLY"):
            return f"{error}: the store cannot be written here"
        return str(error)
    if isinstance(error, OSError):
        where = f": {error.filename}" if error.filename else ""
        words = {errno.ENOSPC: "no space left on the device: the disk is full",
                 errno.EFBIG: "file too large: a file-size limit (ulimit -f) reached",
                 errno.EDQUOT: "disk quota exceeded"}.get(error.errno, error.strerror or str(error))
        return words + (where if error.strerror else "")
    return str(error)


def stored_version(connection: sqlite3.Connection) -> int:
    """The store's schema version (``PRAGMA user_version``; 0: written before versions were recorded)."""
    return connection.execute("PRAGMA user_version").fetchone()[0]


def pending_migrations(connection: sqlite3.Connection, database: Path) -> list[Migration]:
    """The migrations an existing store still needs; :class:`StoreError` for a store newer than this code."""
    version = stored_version(connection)
    check_version(version, database)
    return [migration for migration in MIGRATIONS
            if migration.version > version and not migration.applied(connection)]


def upgrade(connection: sqlite3.Connection, database: Path) -> None:
    """Bring the store to :data:`SCHEMA_VERSION` and stamp it (its version, gaitbench's application id): today's
    tables for an empty database, else the pending migrations. Call inside a write transaction."""
    if not _tables(connection):
        for table, columns in TABLES.items():
            connection.execute(create_table(table, columns))
    else:
        for migration in pending_migrations(connection, database):
            migration.apply(connection)
    connection.execute(f"PRAGMA user_version = {SCHEMA_VERSION}")
    connection.execute(f"PRAGMA application_id = {APPLICATION_ID}")


def upgrade_file(database: Path) -> None:
    """Migrate a store that can be written if it lacks anything (for readers: a store that needs nothing is left
    untouched, even unstamped); where it cannot be written, or is busy, it is read as it is."""
    try:
        connection = connect_read_only(database, immutable=False)
        try:
            pending = pending_migrations(connection, database)
        finally:
            connection.close()
        if not pending:
            return
        connection = sqlite3.connect(database, timeout=5, isolation_level=None)
        try:
            connection.execute("BEGIN IMMEDIATE")
            try:
                upgrade(connection, database)
            except BaseException:
                connection.execute("ROLLBACK")
                raise
            connection.execute("COMMIT")
        finally:
            connection.close()
    except sqlite3.Error:  # read-only after all, locked, or not a store (which the caller reports): read as it is
        pass


def check_version(version: int, database: Path) -> None:
    """Refuse a store written by a newer gaitbench: this code cannot know what its columns mean."""
    if version > SCHEMA_VERSION:
        raise StoreError(f"{database}: results store of schema version {version}, newer than this gaitbench "
                         f"{__version__} knows (schema version {SCHEMA_VERSION}); upgrade gaitbench (pip install -U "
                         f"gaitbench, or pull and reinstall the checkout) to use it; nothing was changed")


def check_file(database: Path) -> None:
    """Refuse, before anything is written, a ``results.sqlite`` that is not a gaitbench store or is too new
    (StoreError).

    Reads the SQLite header (magic, user version, application id) and, for a file without gaitbench's application
    id, its tables, through an immutable read-only connection that touches nothing, not even lock files.
    """
    try:
        with open(database, "rb") as file:
            header = file.read(100)
    except FileNotFoundError:
        return
    except OSError as error:
        raise StoreError(f"{database}: cannot read the results store ({error.strerror or error})") from None
    if not header:
        return  # an empty file is an empty database: a new store
    if not header.startswith(b"SQLite format 3\0"):
        raise StoreError(f"{database}: not a gaitbench results store (not an SQLite database); nothing was changed")
    application_id = int.from_bytes(header[68:72], "big") if len(header) >= 72 else 0
    if application_id == APPLICATION_ID:
        check_version(int.from_bytes(header[60:64], "big"), database)
        return
    if application_id:
        raise StoreError(f"{database}: not a gaitbench results store (an SQLite file of another application, "
                         f"application_id {application_id:#x}); nothing was changed")
    try:
        connection = connect_read_only(database, immutable=True)
        try:
            check_schema(connection, database)
        finally:
            connection.close()
    except sqlite3.DatabaseError as error:
        raise StoreError(f"{database}: not a gaitbench results store ({error}); nothing was changed") from None


def check_schema(connection: sqlite3.Connection, database: Path) -> None:
    """StoreError unless the database is empty, or is a gaitbench store (its application id, or only gaitbench's
    tables with a ``cases.case_key`` column: a store from before the application id) no newer than this code."""
    if connection.execute("PRAGMA application_id").fetchone()[0] != APPLICATION_ID:
        tables = _tables(connection)
        if not tables:
            return
        if not (tables <= set(TABLES) and "case_key" in _columns(connection, "cases")):
            foreign = ", ".join(sorted(tables - set(TABLES)) or sorted(tables))
            raise StoreError(f"{database}: not a gaitbench results store (it holds tables {foreign}); "
                             "nothing was changed")
    check_version(stored_version(connection), database)


def connect_read_only(database: Path, immutable: bool) -> sqlite3.Connection:
    """A connection that cannot write (``immutable`` also skips the lock files, for a place that cannot be written)."""
    uri = database.resolve().as_uri() + "?mode=ro" + ("&immutable=1" if immutable else "")
    connection = sqlite3.connect(uri, uri=True, timeout=30, isolation_level=None)
    connection.row_factory = sqlite3.Row
    return connection


def create_table(name: str, columns: dict[str, str]) -> str:
    return f"CREATE TABLE IF NOT EXISTS {name} ({', '.join(f'{c} {t}' for c, t in columns.items())})"


def _tables(connection: sqlite3.Connection) -> set[str]:
    """The database's tables but SQLite's own (``sqlite_stat1`` after ANALYZE, ``sqlite_sequence``)."""
    return {row[0] for row in connection.execute(
        "SELECT name FROM sqlite_master WHERE type = 'table' AND name NOT LIKE 'sqlite\\_%' ESCAPE '\\'")}


def _columns(connection: sqlite3.Connection, table: str) -> set[str]:
    return {row[1] for row in connection.execute(f"PRAGMA table_info({table})")}


def insert_statement(table: str, columns: dict[str, str], replace: bool) -> str:
    """An INSERT (or INSERT OR REPLACE) of every column of ``columns`` into ``table``, with one parameter each."""
    verb = "INSERT OR REPLACE" if replace else "INSERT"
    return f"{verb} INTO {table} ({', '.join(columns)}) VALUES ({', '.join('?' * len(columns))})"


def encoded_row(values: dict[str, Any], columns: dict[str, str]) -> tuple:
    """``values`` as the parameters of :func:`insert_statement`: every column, null where missing, each encoded;
    ValueError for a key that is no column."""
    unknown = set(values) - set(columns)
    if unknown:
        raise ValueError(f"unknown store columns: {', '.join(sorted(unknown))}")
    return tuple(encode_value(column, values.get(column)) for column in columns)


def encode_value(column: str, value: Any) -> Any:
    """A value as SQLite stores it in ``column``: JSON text for the JSON columns, plain Python numbers for NumPy
    scalars, 0/1 for booleans, null for a non-finite number."""
    if column in JSON_COLUMNS:
        return None if value is None else json.dumps(value, sort_keys=True, default=_json_default)
    if hasattr(value, "item"):  # NumPy scalars (np.int64, np.bool_) that SQLite cannot bind
        value = value.item()
    if isinstance(value, bool):
        return int(value)
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def _json_default(value: Any) -> Any:
    if hasattr(value, "tolist"):
        return value.tolist()
    return str(value)
