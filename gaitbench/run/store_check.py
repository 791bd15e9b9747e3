"""Checking what a store's tables hold before it is read: a store changed outside gaitbench (a table dropped, a word
where a number belongs, JSON that does not parse) is one line naming the store, the table, the row and the column,
never a traceback deep inside a reader.

:func:`check_store` runs when a store is opened, for reading or writing, so every command refuses such a store before
it does anything with it.
"""

from __future__ import annotations

import json
import sqlite3
from pathlib import Path
from typing import Any

from gaitbench.run.store_schema import JSON_COLUMNS, MIGRATIONS, TABLES, StoreError, stored_version

KEYS = {"cases": "case_key", "runs": "run_id", "claims": "case_key"}
"""The column that names a row of each table in messages."""

REQUIRED_COLUMNS = {"cases": ("case_key", "run_id", "status"), "runs": ("run_id", "started_at", "finished_at"),
                    "claims": ("case_key", "run_id")}
"""The columns every store has had since its table existed, which the store's own queries need."""

NOT_NULL = {"cases": ("case_key", "experiment"), "runs": ("run_id",), "claims": ("case_key", "run_id")}
"""The cells that every row gaitbench writes has and the readers cannot do without (a case's experiment names its
table and figures in the report)."""

CLAIMS_VERSION = next(migration.version for migration in MIGRATIONS if "claims" in migration.tables)
"""The schema version that added ``claims``: an older store, read where it cannot be migrated, has none."""

JSON_SHAPES: dict[str, type] = {"cot_steps": list}
"""The JSON value of each JSON column that does not hold an object (every other one of :data:`JSON_COLUMNS`
does); ``cot_steps`` is an array of numbers or nulls."""

_STORAGE = {"INTEGER": ("integer",), "REAL": ("integer", "real"), "TEXT": ("text",)}
_WHAT = {"INTEGER": "an integer", "REAL": "a number", "TEXT": "text"}


def check_store(connection: sqlite3.Connection, database: Path) -> set[str]:
    """The store's tables, once :func:`check_tables`, :func:`check_types` and :func:`check_json` found nothing
    wrong (:class:`StoreError` for the first thing they found)."""
    tables = check_tables(connection, database)
    check_types(connection, database, tables)
    check_json(connection, database, tables)
    return tables


def check_tables(connection: sqlite3.Connection, database: Path) -> set[str]:
    """The store's tables; :class:`StoreError` if one it needs is missing (``claims`` from :data:`CLAIMS_VERSION`
    on) or lacks a column of :data:`REQUIRED_COLUMNS`."""
    tables = {row[0] for row in connection.execute("SELECT name FROM sqlite_master WHERE type = 'table'")}
    needed = ["cases", "runs"] + (["claims"] if stored_version(connection) >= CLAIMS_VERSION else [])
    for table in needed:
        if table not in tables:
            raise StoreError(f"{database}: table {table} is missing (the store was changed outside gaitbench); "
                             "restore it from a copy, or run into a new store")
        present = columns_of(connection, table)
        for column in REQUIRED_COLUMNS[table]:
            if column not in present:
                raise StoreError(f"{database}: table {table} has no column {column} (the store was changed "
                                 "outside gaitbench); restore it from a copy, or run into a new store")
    return tables


def check_types(connection: sqlite3.Connection, database: Path, tables: set[str]) -> None:
    """:class:`StoreError` naming the first cell whose SQLite type is not its column's (a word in ``acot``, a
    fraction in ``N``), or that is null where :data:`NOT_NULL` needs a value, in every table gaitbench reads."""
    for table, columns in TABLES.items():
        if table not in tables:
            continue
        key = KEYS[table]
        present = columns_of(connection, table)
        for column, declared in columns.items():
            if column not in present:
                continue
            kind = declared.split()[0]
            required = column in NOT_NULL[table]
            allowed = _STORAGE[kind] + (() if required else ("null",))
            found = connection.execute(
                f"SELECT {key}, {column}, typeof({column}) FROM {table} "
                f"WHERE typeof({column}) NOT IN ({', '.join('?' * len(allowed))}) LIMIT 1", allowed).fetchone()
            if found is not None:
                name, value, stored = found[0], found[1], found[2]
                expected = _WHAT[kind] + ("" if required else " or null")
                raise StoreError(f"{database}: table {table}, row {key} = {name!r}, column {column}: expected "
                                 f"{expected}, found {stored}{'' if value is None else ' ' + _shown(value)} (the "
                                 "store was changed outside gaitbench)")


def row_problem(table: str, values: dict[str, Any], database: Path) -> str | None:
    """Why a row about to be written (``values``, encoded for SQLite) would make :func:`check_types` or
    :func:`check_json` refuse the store the next time it is opened, or None: a plugin's bad value is refused before
    it is written, so that it costs its own case, not the whole store."""
    for column, declared in TABLES[table].items():
        value, kind = values.get(column), declared.split()[0]
        if value is None:
            if column in NOT_NULL[table]:
                return f"column {column}: expected {_WHAT[kind]}, found null"
            continue
        fits = {"INTEGER": isinstance(value, int) or (isinstance(value, float) and value.is_integer()),
                "REAL": isinstance(value, (int, float)), "TEXT": isinstance(value, str)}[kind]
        if not fits:
            return f"column {column}: expected {_WHAT[kind]}, found {_shown(value)}"
        if column in JSON_COLUMNS:
            try:
                _json_value(value, database, table, values.get(KEYS[table]), column)
            except StoreError as error:
                return f"column {column}: {str(error).rpartition(f'column {column}: ')[2]}"
    return None


def check_json(connection: sqlite3.Connection, database: Path, tables: set[str]) -> None:
    """:class:`StoreError` naming the first JSON cell that does not parse or is not its column's value, in every
    table gaitbench reads (so a damaged store is refused before a run starts on it, not when it is read)."""
    for table in ("cases", "runs"):
        if table not in tables:
            continue
        present = columns_of(connection, table)
        for column in (column for column in JSON_COLUMNS if column in present):
            for name, text in connection.execute(
                    f"SELECT {KEYS[table]}, {column} FROM {table} WHERE {column} IS NOT NULL"):
                _json_value(text, database, table, name, column)


def decode_json(table: str, row: dict[str, Any], database: Path) -> dict[str, Any]:
    """``row`` with its JSON columns decoded (checked as :func:`check_json` does)."""
    for column in JSON_COLUMNS:
        if isinstance(row.get(column), str):
            row[column] = _json_value(row[column], database, table, row.get(KEYS[table]), column)
    return row


def _json_value(text: Any, database: Path, table: str, name: Any, column: str) -> Any:
    where = f"{database}: table {table}, row {KEYS[table]} = {name!r}, column {column}: "
    try:
        value = json.loads(text)
    except (TypeError, ValueError) as error:
        raise StoreError(where + f"not JSON ({error})") from None
    shape = JSON_SHAPES.get(column, dict)
    if value is not None and not isinstance(value, shape):
        raise StoreError(where + f"expected a JSON {_JSON_NAMES[shape]}, found {_shown(text)}")
    if column == "cot_steps" and value and not all(_number_or_null(item) for item in value):
        raise StoreError(where + f"expected an array of numbers or nulls, found {_shown(text)}")
    return value


_JSON_NAMES = {dict: "object", list: "array"}


def _number_or_null(value: Any) -> bool:
    return value is None or (isinstance(value, (int, float)) and not isinstance(value, bool))


def _shown(value: Any) -> str:
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


def columns_of(connection: sqlite3.Connection, table: str) -> set[str]:
    return {row[1] for row in connection.execute(f"PRAGMA table_info({table})")}
