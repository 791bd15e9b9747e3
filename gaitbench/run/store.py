"""The results store: one SQLite row per finished case, its trajectories in files beside it.

Layout of a store directory::

    results.sqlite          runs (one row per `gaitbench run` session) and cases (one row per case key)
    cases/<case_key>/       walk.json + walk.npz (the WalkResult), track.json + track.npz when tracked, the marker
    checkpoints/<case_key>  the solved steps of a walk in flight (gaitbench.checkpoint), until its row is in

Only the processes that run suites write: workers return their results and the runner records each one as soon
as it arrives. A case's files are written to a temporary directory and renamed into place before its row is
committed, so a row always has its files. A worker saves each step its walk solves in the case's checkpoint, so a
crash or kill loses at most the steps in flight: the next run of the case goes on after the saved ones.

Several runs may share a store: each claims a case (table ``claims``, under SQLite's write lock) right before it
starts it, so no case is solved twice, and a claim dies with its run (:mod:`gaitbench.run.liveness`: same host, the
process is gone; any host, no heartbeat for a lease). Readers open the store read-only and never change it; a file
that is not a gaitbench store, or a directory with other files and no store, is refused before anything is written
to it. The tables, their schema version, the migrations of older stores and how values are encoded for them are in
:mod:`gaitbench.run.store_schema`; what is checked of what they hold, in :mod:`gaitbench.run.store_check`; which
files the store writes and may delete, in :mod:`gaitbench.run.store_files`. Every SQLite or file-system error of a
store operation is a :class:`StoreError` naming the store, the operation and the cause (a full disk, a file-size
limit, a lock held past the lock timeout).
"""

from __future__ import annotations

import os
import socket
import sqlite3
import threading
from collections.abc import Iterator, Mapping
from contextlib import contextmanager, suppress
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

from gaitbench.run.liveness import OPEN_RUNS, run_alive
from gaitbench.run.pack_cache import unpacked
from gaitbench.run.pack_format import is_pack, refusal
from gaitbench.run.store_check import check_store, decode_json, row_problem
from gaitbench.run.store_files import (
    CASES_DIR,
    CHECKPOINTS_DIR,
    case_file,
    checkpoint_file,
    holds_anything,
    leftovers,
    place_case,
    remove,
    umask,
)
from gaitbench.run.store_schema import (
    CASE_COLUMNS,
    CLAIM_COLUMNS,
    RETRYABLE_STATUSES,
    RUN_COLUMNS,
    StoreError,
    check_file,
    check_schema,
    connect_read_only,
    encode_value,
    encoded_row,
    failure_cause,
    insert_statement,
    upgrade,
    upgrade_file,
)

DATABASE = "results.sqlite"

__all__ = ["CASES_DIR", "CHECKPOINTS_DIR", "DATABASE", "BadRow", "ResultStore", "case_file", "checkpoint_file",
           "load_results"]

LOCK_TIMEOUT_S = 60.0
"""How long a store operation waits for SQLite's write lock, which another run holds for milliseconds at a time,
before it fails (``gaitbench run --lock-timeout``)."""

HEARTBEAT_S = 20.0
"""How often a running suite refreshes its run's ``heartbeat_at``."""



@contextmanager
def _closed_on_failure(connection: sqlite3.Connection) -> Iterator[None]:
    """Close ``connection`` when what is inside raises, whatever it raises: a store that cannot be opened leaves no
    connection open."""
    try:
        yield
    except BaseException:
        connection.close()
        raise


class BadRow(ValueError):
    """A case row with a value its column cannot hold (a plugin's result of the wrong type): refused unwritten."""


class ResultStore:
    """A store directory; open with :meth:`create` (writing) or :meth:`open` (reading an existing one)."""

    def __init__(self, directory: Path, connection: sqlite3.Connection, tables: set[str],
                 lock_timeout: float = LOCK_TIMEOUT_S) -> None:
        self.directory = directory
        self._db = connection
        self._tables = tables
        self.lock_timeout = lock_timeout

    @property
    def database(self) -> Path:
        return self.directory / DATABASE

    @classmethod
    def create(cls, directory: str | Path, lock_timeout: float = LOCK_TIMEOUT_S) -> ResultStore:
        """Open the store at ``directory`` for writing, creating it (and its tables) if needed; each write waits up
        to ``lock_timeout`` seconds for the write lock.

        :class:`StoreError` (one line naming the path) if ``directory`` is a pack (read-only), cannot be written,
        holds other files but no ``results.sqlite``, or its ``results.sqlite`` is not a gaitbench store, one newer
        than this code or one whose tables were changed outside gaitbench (:mod:`gaitbench.run.store_check`);
        nothing is changed then. A store written by an older gaitbench is migrated to today's schema version.
        """
        directory = Path(directory)
        if is_pack(directory):
            raise StoreError(refusal(directory))
        database = directory / DATABASE
        if directory.is_dir() and not database.exists() and holds_anything(directory):
            raise StoreError(f"{directory}: not a gaitbench results store (a directory with other files and no "
                             f"{DATABASE}); nothing was changed; choose a new or empty directory, or a store")
        try:
            directory.mkdir(parents=True, exist_ok=True)
        except OSError as error:
            raise StoreError(f"{directory}: cannot create the results store here ({failure_cause(error)})") from None
        check_file(database)
        try:
            connection = sqlite3.connect(database, timeout=lock_timeout, isolation_level=None)
        except sqlite3.Error as error:
            raise StoreError(f"{database}: cannot open the results store for writing "
                             f"({failure_cause(error, lock_timeout)})") from None
        store = cls(directory, connection, set(), lock_timeout)
        with _closed_on_failure(connection):
            connection.row_factory = sqlite3.Row
            with store._write("check the results store"):  # again under the write lock: what the WAL holds
                check_schema(connection, database)
            # readers (`runs show` during a run) never block the writer, and several runs can share the store
            with store._failing("switch the results store to write-ahead logging"):
                connection.execute("PRAGMA journal_mode=WAL")
                connection.execute("PRAGMA synchronous=FULL")
            with store._write("create or migrate the results store's tables"):
                upgrade(connection, database)
            with store._failing("check the results store's tables"):
                store._tables = check_store(connection, database)
        return store

    @classmethod
    def open(cls, directory: str | Path) -> ResultStore:
        """Open an existing store for reading; :class:`StoreError` if there is none at ``directory``.

        The connection is read-only (``immutable`` too where the directory cannot be written, which a WAL database
        needs for its lock files), so a store in a read-only place can be read and reading never changes one. A
        store written by an older gaitbench is migrated here when it can be written (see
        :mod:`gaitbench.run.store_schema`); otherwise it is read without the columns it lacks. A pack
        (:mod:`gaitbench.run.pack_format`) is read from its unpacked copy (:mod:`gaitbench.run.pack_cache`).
        """
        directory = Path(directory)
        packed = is_pack(directory)
        if packed:
            directory = unpacked(directory)
        database = directory / DATABASE if directory.is_dir() else directory
        if not database.is_file():
            raise StoreError(f"{directory}: no results store here (expected {DATABASE}); "
                             "pass the directory given to `gaitbench run --store`, or the suite's output directory")
        if database.stat().st_size == 0:  # SQLite would take it for a new database, and migrating would fill it
            raise StoreError(f"{database}: an empty file, not a results store (a copy that failed, or a full disk?); "
                             "nothing was changed")
        check_file(database)
        writable = not packed and os.access(database.parent, os.W_OK) and os.access(database, os.W_OK)
        if writable:
            upgrade_file(database)
        try:
            connection = connect_read_only(database, immutable=not writable)
        except sqlite3.Error as error:
            raise StoreError(f"{database}: cannot open the results store ({failure_cause(error)})") from None
        with _closed_on_failure(connection):
            try:
                check_schema(connection, database)
                connection.execute("SELECT case_key FROM cases LIMIT 1")
            except sqlite3.DatabaseError as error:
                raise StoreError(f"{database}: not a gaitbench results store ({error})") from None
            store = cls(database.parent, connection, set())
            with store._failing("check the results store's tables"):
                store._tables = check_store(connection, database)
        return store

    def close(self) -> None:
        self._db.close()

    @contextmanager
    def _write(self, what: str = "write the results store") -> Iterator[None]:
        """A write transaction that takes SQLite's write lock at once (``BEGIN IMMEDIATE``): what is read inside it
        stays true until the commit, which is what makes claims and run ids race-free between processes. Errors
        as :meth:`_failing`; ``what`` names the operation in them."""
        with self._failing(what):
            self._db.execute("BEGIN IMMEDIATE")
            try:
                yield
                self._db.execute("COMMIT")
            except BaseException:  # a commit that fails (a full disk) is rolled back too
                if self._db.in_transaction:
                    with suppress(sqlite3.Error):
                        self._db.execute("ROLLBACK")
                raise

    @contextmanager
    def _failing(self, what: str) -> Iterator[None]:
        """Turn an SQLite or file-system error inside into one :class:`StoreError` line: the store, ``what`` it
        could not do, and why (:func:`failure_cause`)."""
        try:
            yield
        except (sqlite3.Error, OSError) as error:
            raise StoreError(f"{self.directory}: cannot {what} ({failure_cause(error, self.lock_timeout)})") from None

    def __enter__(self) -> ResultStore:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()

    # --- runs -----------------------------------------------------------------------------------------------

    def start_run(self, run: dict[str, Any]) -> str:
        """Record a run starting in this process and return its id: ``run["run_id"]``, or with ``-2``, ``-3``, ...
        when that is taken (runs of one suite started within a second), chosen under the write lock so that
        concurrent runs never collide."""
        run_id = self._add_run(run | {"host": socket.gethostname(), "pid": os.getpid(), "heartbeat_at": _now()})
        OPEN_RUNS.add(run_id)
        return run_id

    def add_run(self, run: Mapping[str, Any]) -> str:
        """Record a run that another store holds (:mod:`gaitbench.run.merge`), as it is there: its id, or with a
        suffix as in :meth:`start_run` when this store uses that id; the id given."""
        return self._add_run({column: run.get(column) for column in RUN_COLUMNS})

    def _add_run(self, run: dict[str, Any]) -> str:
        stem = run["run_id"]
        with self._write(f"record run {stem}"):
            taken = {row[0] for row in self._db.execute(
                "SELECT run_id FROM runs WHERE run_id = ? OR run_id LIKE ?", (stem, f"{stem}-%"))}
            run_id = next(run_id for run_id in (stem, *(f"{stem}-{n}" for n in range(2, len(taken) + 2)))
                          if run_id not in taken)
            self._db.execute(insert_statement("runs", RUN_COLUMNS, replace=False),
                             encoded_row(run | {"run_id": run_id}, RUN_COLUMNS))
        return run_id

    def finish_run(self, run_id: str, finished_at: str | None) -> None:
        """End a run: its claims go, and ``finished_at`` is set; a run that was stopped keeps it null, and its last
        heartbeat is now, when it stopped (what a sweep's wall time counts to)."""
        OPEN_RUNS.discard(run_id)
        with self._write(f"end run {run_id}"):
            self._db.execute("DELETE FROM claims WHERE run_id = ?", (run_id,))
            if finished_at is not None:
                self._db.execute("UPDATE runs SET finished_at = ? WHERE run_id = ?", (finished_at, run_id))
            else:
                self._db.execute("UPDATE runs SET heartbeat_at = ? WHERE run_id = ?", (_now(), run_id))

    def forget_run(self, run_id: str) -> None:
        """End ``run_id`` in this process without writing (the store failed): its row stays unfinished, and its
        claims are dead at once here and with this process elsewhere (:func:`run_alive`)."""
        OPEN_RUNS.discard(run_id)

    @contextmanager
    def heartbeat(self, run_id: str) -> Iterator[None]:
        """Keep ``run_id`` alive for other runs (its ``heartbeat_at``, every :data:`HEARTBEAT_S`) while inside."""
        stop = threading.Event()

        def beat() -> None:
            try:
                connection = sqlite3.connect(self.database, timeout=self.lock_timeout, isolation_level=None)
            except sqlite3.Error:  # the run's own writes will say what is wrong with the store
                return
            try:
                while not stop.wait(HEARTBEAT_S):
                    try:
                        connection.execute("UPDATE runs SET heartbeat_at = ? WHERE run_id = ?", (_now(), run_id))
                    except sqlite3.Error:  # busy or failing: the lease outlasts a few missed beats
                        pass
            finally:
                connection.close()

        thread = threading.Thread(target=beat, name=f"heartbeat {run_id}", daemon=True)
        thread.start()
        try:
            yield
        finally:
            stop.set()
            thread.join()

    def live_runs(self, exclude: str | None = None) -> list[dict[str, Any]]:
        """The runs working on this store now (unfinished, process alive, heartbeat fresh), but ``exclude``."""
        with self._failing("read the runs"):
            rows = self._db.execute("SELECT * FROM runs WHERE finished_at IS NULL").fetchall()
        return [dict(row) for row in rows if row["run_id"] != exclude and run_alive(row)]

    def live_claims(self) -> set[str]:
        """The keys of the cases that live runs are solving now (none in a store from before claims, read where it
        cannot be migrated)."""
        if "claims" not in self._tables:
            return set()
        with self._failing("read the claims"):
            rows = self._db.execute("SELECT claims.case_key AS claimed, runs.* FROM claims "
                                    "JOIN runs ON runs.run_id = claims.run_id").fetchall()
        return {row["claimed"] for row in rows if run_alive(row)}

    def claim(self, case_key: str, run_id: str, expected: str | None) -> str:
        """Claim a case for ``run_id`` before starting it: ``"claimed"``, ``"running"`` (a live run holds it) or
        ``"done"`` (its row changed since the run read it: another run finished it).

        ``expected`` is the run id of the case's row when this run planned it (``""`` for a row without one, None
        for no row). A claim whose run is dead is taken over.
        """
        with self._write(f"claim case {case_key}"):
            holder = self._db.execute(
                "SELECT runs.* FROM claims LEFT JOIN runs ON runs.run_id = claims.run_id WHERE claims.case_key = ?",
                (case_key,)).fetchone()
            if holder is not None and holder["run_id"] not in (None, run_id) and run_alive(holder):
                return "running"
            stored = self._db.execute("SELECT run_id FROM cases WHERE case_key = ?", (case_key,)).fetchone()
            if (None if stored is None else stored[0] or "") != expected:
                return "done"
            self._db.execute(insert_statement("claims", CLAIM_COLUMNS, replace=True),
                             encoded_row({"case_key": case_key, "run_id": run_id, "claimed_at": _now()}, CLAIM_COLUMNS))
        return "claimed"

    def clean_leftovers(self, run_id: str) -> list[str]:
        """Remove what a killed run can leave and the store can prove it wrote (:func:`store_files.leftovers`:
        marked staging and case directories that no row names, checkpoint files being written by a process that is
        gone) unless another run is live, whose files these might be; the paths removed, relative to the store.

        Under the write lock, so that no run can start (and begin writing files) between the check and the removal.
        """
        removed = []
        with self._write("remove what a stopped run left"):
            if self.live_runs(exclude=run_id):
                return removed
            named = {row[0] for row in self._db.execute(
                "SELECT case_key FROM cases WHERE walk_path IS NOT NULL OR tracking_path IS NOT NULL")}
            for path in leftovers(self.directory, named):
                remove(path)
                removed.append(path.relative_to(self.directory).as_posix())
        return removed

    def runs(self) -> list[dict[str, Any]]:
        """Every run, oldest first, with how many of the stored cases it computed and how many failed (every column
        of :data:`RUN_COLUMNS` present, null where a store lacks it)."""
        with self._failing("read the runs"):
            rows = self._db.execute(
                "SELECT runs.*, COUNT(cases.case_key) AS cases_done, "
                "SUM(CASE WHEN cases.status != 'solved' THEN 1 ELSE 0 END) AS cases_failed "
                "FROM runs LEFT JOIN cases ON cases.run_id = runs.run_id GROUP BY runs.run_id ORDER BY started_at"
            ).fetchall()
        return [decode_json("runs", dict.fromkeys(RUN_COLUMNS) | dict(row), self.database) for row in rows]

    # --- cases ----------------------------------------------------------------------------------------------

    def finished_keys(self, retry_failed: bool = False, retry_incomplete: bool = False,
                      retry_unverified: bool = False) -> set[str]:
        """Keys of cases that need no new run: all stored ones, less the run's failures with ``retry_failed``, the
        walks that stopped with ``retry_incomplete``, and with ``retry_unverified`` the complete walks that failed
        the whole-walk verification (``verified`` 0) or have no ACOT; rows never checked (``verified`` null) are
        not run again: `gaitbench verify --store` checks them."""
        again = (RETRYABLE_STATUSES if retry_failed else ()) + (("incomplete",) if retry_incomplete else ())
        query = f"SELECT case_key FROM cases WHERE status NOT IN ({', '.join('?' * len(again))})"
        if retry_unverified:
            query += " AND NOT (status = 'solved' AND (acot IS NULL OR COALESCE(verified, 1) = 0))"
        with self._failing("read the cases"):
            return {key for (key,) in self._db.execute(query, again)}

    def case_runs(self) -> dict[str, str]:
        """The run id of every stored case (``""`` where a row has none): what :meth:`claim` expects."""
        with self._failing("read the cases"):
            return {key: run_id or "" for key, run_id in self._db.execute("SELECT case_key, run_id FROM cases")}

    def record_case(self, row: dict[str, Any], files: dict[str, bytes] | None = None,
                    unchanged: tuple[str, str | None] | None = None) -> bool:
        """Write one finished case: its files first (renamed into place as one directory), then its row, which
        releases the case's claim. True when written.

        ``unchanged`` (the ``run_id`` and ``finished_at`` of the case's row when the caller read the store; None for
        each where it had no row) makes the write conditional, for a writer that holds no claim
        (:mod:`gaitbench.run.merge`): a case whose row changed since, or that a live run has claimed, is left alone,
        and False is returned. The check, the files and the row are one write transaction, so no run records the
        case between them.

        ``files`` maps file names to their contents; the row's path columns should name them through
        :func:`case_file`. The case directory has the permissions of the umask, as if made by ``mkdir``, and the
        store's marker (:mod:`gaitbench.run.store_files`); an earlier directory of the case is replaced only if it
        has the marker or the case's row names it.

        A row whose walk is not ``solved`` never replaces a stored ``solved`` one: a complete walk run again (``--retry-
        unverified``, ``--retry-inconsistent``, a merge) that crashed, timed out or stopped early keeps the walk it
        was run again for. Then only the claim is released, and False is returned.

        A row the store's checks would refuse when it is next opened (a word where a number belongs, JSON of the
        wrong shape: :func:`~gaitbench.run.store_check.row_problem`) raises :class:`BadRow` before anything is
        written.
        """
        key = row["case_key"]
        values = encoded_row(row, CASE_COLUMNS)
        problem = row_problem("cases", dict(zip(CASE_COLUMNS, values, strict=True)), self.database)
        if problem:
            raise BadRow(f"case {key}: {problem}")
        with self._write(f"record case {key}"):
            stored = self._db.execute("SELECT status, walk_path, tracking_path, run_id, finished_at FROM cases "
                                      "WHERE case_key = ?", (key,)).fetchone()
            if unchanged is not None and (
                    (tuple(stored[3:]) if stored is not None else (None, None)) != tuple(unchanged)
                    or key in self.live_claims()):
                return False
            release = "DELETE FROM claims WHERE case_key = ? AND run_id = ?"
            if stored is not None and stored[0] == "solved" and row.get("status") != "solved":
                self._db.execute(release, (key, row.get("run_id")))
                return False
            if files:
                named = stored is not None and any(
                    isinstance(path, str) and path.startswith(case_file(key) + "/") for path in stored[1:3])
                place_case(self.directory, key, files, 0o777 & ~umask(), replaceable=named)
            self._db.execute(insert_statement("cases", CASE_COLUMNS, replace=True), values)
            self._db.execute(release, (key, row.get("run_id")))
        return True

    def update_cases(self, updates: Mapping[str, Mapping[str, Any]],
                     unchanged: Mapping[str, tuple[str | None, str | None]] | None = None) -> list[str]:
        """Set some columns of stored cases, ``{case_key: {column: value}}``, in one transaction: what a later
        check of stored walks adds to their rows (``gaitbench verify --store``). With ``unchanged`` (each case's
        ``run_id`` and ``finished_at`` when it was read), a case recorded again since then is left alone: its
        verdict was of the walk before. Returns the keys left alone."""
        for values in updates.values():
            unknown = set(values) - set(CASE_COLUMNS)
            if unknown:
                raise ValueError(f"unknown case columns {sorted(unknown)}")
        changed = []
        with self._write("update cases"):
            for case_key, values in updates.items():
                assignments = ", ".join(f"{column} = ?" for column in values)
                values = tuple(encode_value(column, value) for column, value in values.items())
                if unchanged is None:
                    self._db.execute(f"UPDATE cases SET {assignments} WHERE case_key = ?", (*values, case_key))
                    continue
                run_id, finished_at = unchanged.get(case_key, (None, None))
                done = self._db.execute(f"UPDATE cases SET {assignments} WHERE case_key = ? AND run_id IS ? "
                                        "AND finished_at IS ?", (*values, case_key, run_id, finished_at))
                if not done.rowcount:
                    changed.append(case_key)
        return changed

    def cases(self, run_id: str | None = None) -> list[dict[str, Any]]:
        """Stored case rows (JSON columns decoded, every column of :data:`CASE_COLUMNS` present, null where a
        store predates it), optionally only those a given run computed."""
        with self._failing("read the cases"):
            if run_id is None:
                rows = self._db.execute("SELECT * FROM cases ORDER BY rowid").fetchall()
            else:
                rows = self._db.execute("SELECT * FROM cases WHERE run_id = ? ORDER BY rowid", (run_id,)).fetchall()
        return [decode_json("cases", dict.fromkeys(CASE_COLUMNS) | dict(row), self.database) for row in rows]

    def resolve_run(self, run: str) -> str:
        """A run id from a full id or a unique prefix of one; :class:`StoreError` otherwise."""
        ids = [row["run_id"] for row in self.runs()]
        matches = [run_id for run_id in ids if run_id.startswith(run)]
        if len(matches) == 1:
            return matches[0]
        known = ", ".join(ids) or "none"
        problem = "matches several runs" if matches else "is not a run"
        raise StoreError(f"{self.directory}: {run!r} {problem} of this store; runs: {known}")


def load_results(path: str | Path):
    """The cases of a store as a pandas DataFrame: one row per case, a ``case_key`` column, JSON columns decoded.

    ``path`` is the store directory (as given to ``gaitbench run --store``), its ``results.sqlite``, or a pack.
    """
    import pandas as pd

    with ResultStore.open(path) as store:
        rows = store.cases()
    return pd.DataFrame(rows, columns=list(CASE_COLUMNS))


def _now() -> str:
    return datetime.now(timezone.utc).isoformat(timespec="seconds")
