"""The store's schema version and migrations: a store written by an older gaitbench opens, gains today's columns and
keeps its rows; a store of a newer version is refused unchanged."""

from __future__ import annotations

import json
import sqlite3
import tarfile
from pathlib import Path

import pytest

import gaitbench
from gaitbench.run.store import DATABASE, ResultStore
from gaitbench.run.store_schema import APPLICATION_ID, CASE_COLUMNS, SCHEMA_VERSION, TABLES, StoreError

COMMITTED_PACK = Path(__file__).parent.parent / "benchmarks" / "results" / "thesis-all.tar.xz"
"""The thesis sweep's store, packed (docs/results.md, "Packed stores")."""

# The first store's tables (schema version 1), as gaitbench wrote them before the version was recorded.
VERSION_1_RUNS = """CREATE TABLE IF NOT EXISTS runs (run_id TEXT PRIMARY KEY, suite TEXT, suite_path TEXT,
    suite_text TEXT, executor TEXT, jobs INTEGER, cases_total INTEGER, cases_skipped INTEGER, started_at TEXT,
    finished_at TEXT, provenance TEXT)"""
VERSION_1_CASES = """CREATE TABLE IF NOT EXISTS cases (case_key TEXT PRIMARY KEY, run_id TEXT, suite TEXT,
    method TEXT, experiment TEXT, experiment_options TEXT, N INTEGER, steps INTEGER, transcription TEXT,
    transcription_options TEXT, solver TEXT, solver_options TEXT, strategy TEXT, strategy_options TEXT,
    problem_options TEXT, repetition INTEGER, time_limit_s REAL, tracking_stage TEXT, status TEXT, message TEXT,
    acot REAL, claimed_acot REAL, cot_steps TEXT, cot_min REAL, cot_max REAL, steps_solved INTEGER,
    wall_time_s REAL, solve_time_s REAL, function_time_s REAL, iterations INTEGER, max_defect REAL,
    max_resim_error REAL, strategy_details TEXT, max_position_error REAL, max_velocity_error REAL, acot_tracked REAL,
    acot_increase_percent REAL, fell INTEGER, tracking TEXT, walk_path TEXT, tracking_path TEXT, provenance TEXT,
    finished_at TEXT)"""

OLD_CASES = [
    {"case_key": "forward-N8-op", "run_id": "thesis-20240101T000000", "suite": "thesis", "method": "OP-DC",
     "experiment": "forward", "experiment_options": "{}", "N": 8, "steps": 6, "transcription": "hermite-simpson",
     "transcription_options": "{}", "solver": "ipopt", "solver_options": '{"max_iterations": 3000}',
     "strategy": "one-phase", "strategy_options": "{}", "problem_options": "{}", "repetition": 0,
     "time_limit_s": 3600.0, "status": "solved", "message": "", "acot": 0.0312, "cot_steps": "[0.031, 0.0314]",
     "cot_min": 0.031, "cot_max": 0.0314, "steps_solved": 6, "wall_time_s": 12.5, "iterations": 240,
     "max_defect": 1e-9, "strategy_details": "{}", "walk_path": "cases/forward-N8-op/walk.json",
     "provenance": '{"gaitbench": "0.1.0"}', "finished_at": "2024-01-01T00:10:00+00:00"},
    {"case_key": "stairs-N6-dc", "run_id": "thesis-20240101T000000", "suite": "thesis", "method": "D&C-DM",
     "experiment": "stairs", "N": 6, "transcription": "dmoc", "solver": "ipopt", "strategy": "decrease-and-conquer",
     "status": "incomplete", "message": "step 3: infeasible", "steps_solved": 2, "cot_steps": "[0.05, 0.06, null]",
     "strategy_details": '{"claimed_acot": 0.04, "backtracks": 2}', "claimed_acot": 0.04, "wall_time_s": 80.0},
    {"case_key": "upslope-N10-op", "run_id": "thesis-20240101T000000", "suite": "thesis", "experiment": "upslope",
     "N": 10, "status": "crashed", "message": "worker died (SIGKILL)", "wall_time_s": 5.0},
]
OLD_RUN = {"run_id": "thesis-20240101T000000", "suite": "thesis", "suite_path": "suites/thesis.toml",
           "suite_text": "# thesis", "executor": "local", "jobs": 2, "cases_total": 3, "cases_skipped": 0,
           "started_at": "2024-01-01T00:00:00+00:00", "finished_at": "2024-01-01T00:20:00+00:00",
           "provenance": '{"gaitbench": "0.1.0"}'}


def insert(db: sqlite3.Connection, table: str, row: dict) -> None:
    db.execute(f"INSERT INTO {table} ({', '.join(row)}) VALUES ({', '.join('?' * len(row))})", tuple(row.values()))


def raw(path: Path, query: str) -> list[tuple]:
    db = sqlite3.connect(path / DATABASE)
    try:
        return db.execute(query).fetchall()
    finally:
        db.close()


def columns(path: Path) -> dict[str, dict[str, str]]:
    """Each table's columns and their declared types (with NOT NULL and PRIMARY KEY)."""
    db = sqlite3.connect(path / DATABASE)
    try:
        return {table: {row[1]: f"{row[2]}{' NOT NULL' if row[3] else ''}{' PRIMARY KEY' if row[5] else ''}"
                        for row in db.execute(f"PRAGMA table_info({table})")} for table in TABLES}
    finally:
        db.close()


@pytest.fixture
def version_1_store(tmp_path: Path) -> Path:
    """A store as the first gaitbench wrote it: its two tables, three cases, one run, no version, no application id."""
    store = tmp_path / "old"
    store.mkdir()
    db = sqlite3.connect(store / DATABASE)
    with db:
        db.execute(VERSION_1_RUNS)
        db.execute(VERSION_1_CASES)
        insert(db, "runs", OLD_RUN)
        for row in OLD_CASES:
            insert(db, "cases", row)
    db.close()
    return store


def test_a_version_1_store_opens_gains_every_column_and_keeps_its_rows(version_1_store: Path) -> None:
    old_columns = list(columns(version_1_store)["cases"])
    before = raw(version_1_store, f"SELECT {', '.join(old_columns)} FROM cases ORDER BY rowid")

    frame = gaitbench.load_results(version_1_store)  # reading a store that can be written migrates it

    assert raw(version_1_store, "PRAGMA user_version") == [(SCHEMA_VERSION,)]
    assert raw(version_1_store, "PRAGMA application_id") == [(APPLICATION_ID,)]
    assert columns(version_1_store) == columns(new_store(version_1_store.parent / "new"))
    assert raw(version_1_store, f"SELECT {', '.join(old_columns)} FROM cases ORDER BY rowid") == before
    assert raw(version_1_store, "SELECT * FROM runs") == [(*OLD_RUN.values(), None, None, None)]

    assert list(frame.columns) == list(CASE_COLUMNS)
    assert list(frame.case_key) == [row["case_key"] for row in OLD_CASES]
    for (_, got), written in zip(frame.iterrows(), OLD_CASES, strict=True):
        for column, value in written.items():
            expected = json.loads(value) if column in ("cot_steps", "strategy_details", "experiment_options",
                                                       "transcription_options", "solver_options", "strategy_options",
                                                       "problem_options", "provenance") else value
            assert got[column] == expected, column
        assert got["objective"] == "net-power"  # the only objective before the column existed
        assert got["back_ups"] is None and got["retries"] is None and got["stop_cause"] is None

    with ResultStore.create(version_1_store) as store:  # and a resumed run writes today's rows into it
        assert store.runs()[0]["run_id"] == OLD_RUN["run_id"]
        store.record_case({"case_key": "new", "run_id": "r2", "status": "solved", "experiment": "forward",
                           "objective": "actuator-work",
                           "retries": 1, "back_ups": 1, "stop_cause": "complete"})
        rows = {row["case_key"]: row for row in store.cases()}
    assert len(rows) == len(OLD_CASES) + 1
    assert (rows["new"]["objective"], rows["new"]["back_ups"]) == ("actuator-work", 1)


def new_store(path: Path) -> Path:
    ResultStore.create(path).close()
    return path


def test_an_unversioned_store_gains_only_what_it_lacks(version_1_store: Path) -> None:
    """A store from before versions may stand anywhere in the history: here, with the stop columns and retries."""
    db = sqlite3.connect(version_1_store / DATABASE)
    with db:
        for column, kind in (("stop_cause", "TEXT"), ("stop_step", "INTEGER"), ("stop_status", "TEXT"),
                             ("retries", "INTEGER")):
            db.execute(f"ALTER TABLE cases ADD COLUMN {column} {kind}")
        db.execute("UPDATE cases SET retries = 2, stop_cause = 'complete' WHERE status = 'solved'")
    db.close()

    ResultStore.create(version_1_store).close()

    assert columns(version_1_store) == columns(new_store(version_1_store.parent / "new"))
    assert raw(version_1_store, "SELECT status, retries, back_ups, objective FROM cases ORDER BY rowid") == [
        ("solved", 2, 0, "net-power"),  # walks counted their retries: none took a back-up before back-ups existed
        ("incomplete", None, None, "net-power"), ("crashed", None, None, "net-power")]


def test_a_new_store_is_created_at_the_current_version(tmp_path: Path) -> None:
    store = new_store(tmp_path / "new")
    assert raw(store, "PRAGMA user_version") == [(SCHEMA_VERSION,)]
    assert columns(store) == {table: dict(table_columns) for table, table_columns in TABLES.items()}


def test_a_store_newer_than_this_gaitbench_is_refused_and_unchanged(tmp_path: Path) -> None:
    store = new_store(tmp_path / "store")
    db = sqlite3.connect(store / DATABASE)
    db.execute(f"PRAGMA user_version = {SCHEMA_VERSION + 1}")
    db.close()
    before = (store / DATABASE).read_bytes()
    for action in (ResultStore.open, ResultStore.create, gaitbench.load_results):
        with pytest.raises(StoreError) as raised:
            action(store)
        message = str(raised.value)
        assert str(store / DATABASE) in message and "upgrade gaitbench" in message, message
        assert f"schema version {SCHEMA_VERSION + 1}" in message and f"schema version {SCHEMA_VERSION})" in message
        assert (store / DATABASE).read_bytes() == before


def test_the_committed_thesis_store_opens(tmp_path: Path) -> None:
    """Read from a copy of the database in the committed pack: reading it changes nothing, and a run opening it
    finds today's schema version."""
    copy = tmp_path / "thesis-all"
    copy.mkdir()
    with tarfile.open(COMMITTED_PACK) as pack:
        (copy / DATABASE).write_bytes(pack.extractfile(f"thesis-all/{DATABASE}").read())
    before = (copy / DATABASE).read_bytes()
    count = raw(copy, "SELECT COUNT(*) FROM cases")[0][0]

    frame = gaitbench.load_results(copy)

    assert len(frame) == count > 0 and frame.status.notna().all()
    assert (copy / DATABASE).read_bytes() == before
    ResultStore.create(copy).close()
    assert raw(copy, "PRAGMA user_version") == [(SCHEMA_VERSION,)]
    assert len(gaitbench.load_results(copy)) == count


def test_the_schema_versions_are_documented() -> None:
    documented = (Path(__file__).parent.parent / "docs" / "results.md").read_text()
    assert f"(today {SCHEMA_VERSION};" in documented
    assert all(f"\n| {version} | " in documented for version in range(1, SCHEMA_VERSION + 1))
