"""The store's reliability: runs sharing a store, clear errors on files that are not stores, reading a store in a
read-only place, and what a killed run leaves behind."""

from __future__ import annotations

import json
import os
import re
import shutil
import socket
import sqlite3
import subprocess
import sys
import textwrap
import threading
from pathlib import Path
from types import SimpleNamespace

import pytest
from click.testing import CliRunner

import gaitbench
from gaitbench.cli.main import main
from gaitbench.run.case import Case, PluginChoice
from gaitbench.run.runner import CaseOutcome, case_row, failed_outcome, run_suite
from gaitbench.run.store import DATABASE, ResultStore
from gaitbench.run.store_files import CASE_MARKER
from gaitbench.run.store_schema import StoreError

GAITBENCH = str(Path(sys.executable).with_name("gaitbench"))
ENV = {**os.environ, "OPENBLAS_NUM_THREADS": "1", "COLUMNS": "200"}


def fake_case(n_nodes: int, tag: str = "") -> Case:
    return Case(PluginChoice("forward"), n_nodes, PluginChoice("hermite-simpson"), PluginChoice("ipopt", {"tag": tag}),
                PluginChoice("one-phase"), steps=1, method="OP-DC")


def suite_of(cases: list[Case], name: str = "test") -> SimpleNamespace:
    return SimpleNamespace(name=name, path=Path(f"{name}.toml"), text="# test suite", cases=cases)


class Instant:
    """An executor that solves nothing: each case it takes comes back at once as solved, with a walk file."""

    name, jobs = "instant", 1

    def __init__(self, during=None) -> None:
        self.taken: list[str] = []
        self.during = during  # called as the executor takes its third case

    def run(self, cases):
        for case in cases:
            self.taken.append(case.key)
            if len(self.taken) == 3 and self.during is not None:
                self.during()
            yield CaseOutcome(case, "solved", "", 0.0, files={"walk.json": b"{}"})


def tiny_suite(path: Path, name: str, n_values: list[int], transcriptions: list[str],
               experiment: str = "forward") -> Path:
    path.write_text(textwrap.dedent(f"""
        [suite]
        name = "{name}"
        steps = 1
        time_limit_s = 60
        [sweep]
        experiments = ["{experiment}"]
        N = {n_values}
        transcriptions = {transcriptions}
        solvers = ["ipopt"]
        strategies = ["one-phase"]
    """))
    return path


def dead_pid() -> int:
    process = subprocess.Popen(["true"])
    process.wait()
    return process.pid


def other_run(store: Path, run_id: str, claims: tuple[str, ...] = (), **values) -> None:
    """A run of another process (by default on this host, pid 1, heartbeat now), holding claims on ``claims``."""
    from gaitbench.run.store import _now

    ResultStore.create(store).close()
    row = {"run_id": run_id, "suite": "test", "started_at": _now(), "heartbeat_at": _now(),
           "host": socket.gethostname(), "pid": 1} | values
    with sqlite3.connect(store / DATABASE) as db:
        db.execute(f"INSERT INTO runs ({', '.join(row)}) VALUES ({', '.join('?' * len(row))})", tuple(row.values()))
        db.executemany("INSERT INTO claims (case_key, run_id) VALUES (?, ?)", [(key, run_id) for key in claims])
    db.close()


def listing(directory: Path) -> dict[str, bytes]:
    return {path.relative_to(directory).as_posix(): path.read_bytes() if path.is_file() else b""
            for path in sorted(directory.rglob("*"))}


# --- 1. one store, several runs ---------------------------------------------------------------------------------

def test_two_processes_on_one_store_solve_each_case_once(tmp_path: Path) -> None:
    """Two `gaitbench run` processes on one store of 10 real cases (one without --resume and a local pool, one with
    --resume in-process) solve 10 cases between them: each process counts the outcomes it recorded."""
    suite = tiny_suite(tmp_path / "shared.toml", "shared", [6, 7, 8, 9, 10], ["hermite-simpson", "trapezoidal"])
    store = tmp_path / "store"
    command = [GAITBENCH, "run", str(suite), "--store", str(store), "--no-report"]
    first = subprocess.Popen([*command, "--executor", "local", "--jobs", "1"], env=ENV, text=True,
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    second = subprocess.Popen([*command, "--executor", "inprocess", "--resume"], env=ENV, text=True,
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    outputs = [process.communicate(timeout=600) for process in (first, second)]
    summaries = {}
    for process, (_, stderr) in zip((first, second), outputs, strict=True):
        assert process.returncode == 0, stderr
        assert "Traceback" not in stderr
        found = re.search(r"run (\S+): (\d+) solved, (\d+) failed", stderr)
        assert found, stderr
        summaries[found[1]] = int(found[2]) + int(found[3])
    assert len(summaries) == 2  # distinct run ids
    assert sum(summaries.values()) == 10, summaries  # every case solved once: none twice, none lost
    rows = gaitbench.load_results(store)
    assert len(rows) == 10 and set(rows.status) == {"solved"}
    assert rows.run_id.value_counts().to_dict() == {run: count for run, count in summaries.items() if count}
    with ResultStore.open(store) as opened:
        assert all(run["finished_at"] for run in opened.runs())


def test_a_run_started_during_another_shares_its_cases(tmp_path: Path) -> None:
    """A run started (without --resume) while another runs on the store, after that one has recorded two cases,
    takes the cases nobody holds; the first leaves it those and keeps the one it had claimed."""
    cases = [fake_case(6 + n) for n in range(10)]
    inner = Instant()
    later = []
    outer = Instant(during=lambda: later.append(run_suite(suite_of(cases), tmp_path, inner)))
    first = run_suite(suite_of(cases), tmp_path, outer)
    second = later[0]
    assert len(outer.taken) == 3 and len(inner.taken) == 7
    assert not set(outer.taken) & set(inner.taken)
    assert (first.solved, first.elsewhere, second.solved, second.elsewhere, second.skipped) == (3, 7, 7, 1, 2)
    rows = gaitbench.load_results(tmp_path)
    assert sorted(rows.run_id.value_counts()) == [3, 7] and len(rows) == 10
    with sqlite3.connect(tmp_path / DATABASE) as db:
        assert db.execute("SELECT COUNT(*) FROM claims").fetchone()[0] == 0  # every claim released


def test_run_ids_are_unique_when_runs_start_at_once(tmp_path: Path) -> None:
    ResultStore.create(tmp_path).close()
    start = threading.Barrier(6)
    ids, errors = [], []

    def begin() -> None:
        try:
            with ResultStore.create(tmp_path) as store:
                start.wait()
                ids.append(store.start_run({"run_id": "20261201-210000-test", "suite": "test"}))
                store.finish_run(ids[-1], None)
        except Exception as error:  # noqa: BLE001 - any failure of a starting run is what this test looks for
            errors.append(error)

    threads = [threading.Thread(target=begin) for _ in range(6)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    assert not errors
    assert sorted(ids) == ["20261201-210000-test", *(f"20261201-210000-test-{n}" for n in range(2, 7))]


def test_claims_of_dead_runs_expire_and_live_ones_are_left(tmp_path: Path) -> None:
    """--resume takes back the cases claimed by a run whose process is gone (this host) or whose heartbeat is stale
    (another host), and leaves a case claimed by a live run on another host."""
    dead, stale, live, free = (fake_case(n) for n in (6, 7, 8, 9))
    other_run(tmp_path, "dead", (dead.key,), pid=dead_pid())
    other_run(tmp_path, "stale", (stale.key,), host="elsewhere.example", heartbeat_at="2026-01-01T00:00:00+00:00")
    other_run(tmp_path, "live", (live.key,), host="elsewhere.example")
    executor = Instant()
    summary = run_suite(suite_of([dead, stale, live, free]), tmp_path, executor, resume=True)
    assert set(executor.taken) == {dead.key, stale.key, free.key}
    assert summary.elsewhere == 1
    with sqlite3.connect(tmp_path / DATABASE) as db:
        assert db.execute("SELECT case_key, run_id FROM claims").fetchall() == [(live.key, "live")]


def test_a_second_run_after_a_finished_one_is_still_refused_without_resume(tmp_path: Path) -> None:
    from gaitbench.run.runner import RunRefused

    cases = [fake_case(6), fake_case(7)]
    run_suite(suite_of(cases), tmp_path, Instant())
    with pytest.raises(RunRefused, match="pass --resume"):
        run_suite(suite_of(cases), tmp_path, Instant())


def test_a_run_records_its_suite_s_absolute_path_so_runs_list_finds_it_from_anywhere(tmp_path: Path,
                                                                                     monkeypatch) -> None:
    monkeypatch.chdir(tmp_path)
    run_suite(suite_of([fake_case(6)]), tmp_path / "store", Instant())  # the suite named as `test.toml`
    with ResultStore.open(tmp_path / "store") as store:
        assert [run["suite_path"] for run in store.runs()] == [str(tmp_path.resolve() / "test.toml")]


def test_run_alive_ends_with_the_process_or_the_heartbeat() -> None:
    from gaitbench.run.liveness import run_alive

    here = socket.gethostname()
    now = "2999-01-01T00:00:00+00:00"  # a heartbeat from the future is fresh
    row = {"run_id": "not-a-run-of-this-process", "finished_at": None, "started_at": now, "heartbeat_at": now,
           "host": here}
    assert run_alive(row | {"pid": os.getppid()})
    assert not run_alive(row | {"pid": dead_pid()})
    assert not run_alive(row | {"pid": os.getppid(), "finished_at": now})
    assert not run_alive(row | {"pid": os.getppid(), "heartbeat_at": "2000-01-01T00:00:00+00:00"})
    assert run_alive(row | {"pid": 1, "host": "elsewhere.example"})
    assert not run_alive(row | {"pid": os.getpid()})  # this process, but not one of its runs


def test_runs_list_shows_the_walks_in_flight_with_their_saved_steps(tmp_path: Path, monkeypatch) -> None:
    """A case whose checkpoint holds steps is named by its suite's label, with the steps saved, the hours spent, when
    the last was saved and whether a live run holds it; one whose suite can no longer be read keeps its key."""
    from gaitbench.cli.runs_commands import walks_in_flight
    from gaitbench.run.suite import load_suite

    suite = tiny_suite(tmp_path / "tiny.toml", "tiny", [6, 7], ["hermite-simpson"])
    solving, resumable = load_suite(suite).cases
    store_dir = tmp_path / "store"
    with ResultStore.create(store_dir) as store:
        store.start_run({"run_id": "r1", "suite": "tiny", "suite_path": str(suite), "started_at": "now"})
        store.start_run({"run_id": "r0", "suite": "gone", "suite_path": str(tmp_path / "gone.toml"),
                         "started_at": "then"})
        rows = store.runs()
    checkpoints = store_dir / "checkpoints"
    checkpoints.mkdir()
    (checkpoints / f"{solving.key}.json").write_text('{"saved": 3, "of": 11, "elapsed_s": 5400.0}')
    (checkpoints / f"{resumable.key}.json").write_text('{"saved": 1, "of": 11, "elapsed_s": 36.0}')
    (checkpoints / "0123456789abcdef.json").write_text('{"saved": 7, "of": 11, "elapsed_s": 720.0}')
    (checkpoints / "fedcba9876543210.json").write_text('{"saved": 2, "of": 11, "elapsed_s": 72.0, "code": "older"}')
    saved_at = 4_102_444_800  # 2100-01-01 00:00 UTC
    for path in checkpoints.iterdir():
        os.utime(path, (saved_at, saved_at))
    at = "2100-01-01 00:00"
    expected = {solving.key: (solving.label, "3 of 11", "1.50", at, "solving"),
                resumable.key: (resumable.label, "1 of 11", "0.01", at, "resumable"),
                "0123456789abcdef": ("0123456789abcdef", "7 of 11", "0.20", at, "resumable"),
                "fedcba9876543210": ("fedcba9876543210", "2 of 11", "0.02", at, "saved by other code: from step 1")}
    assert walks_in_flight(store_dir, rows, {solving.key}) == [expected[key] for key in sorted(expected)]
    monkeypatch.setenv("COLUMNS", "200")
    listed = run_cli("runs", "list", str(store_dir))
    assert listed.code == 0, listed.output
    assert "walks in flight" in listed.output and "3 of 11" in listed.output and "resumable" in listed.output
    assert walks_in_flight(tmp_path / "no-store", rows, set()) == []


def test_walks_in_flight_are_named_from_the_suite_text_a_run_recorded_when_its_file_is_gone(tmp_path: Path) -> None:
    """Runs recorded before suite paths were made absolute hold `suites/thesis-all.toml`, unreadable from another
    directory; the suite's text, recorded with the run, still names their walks."""
    from gaitbench.cli.runs_commands import walks_in_flight
    from gaitbench.run.suite import load_suite

    suite = tiny_suite(tmp_path / "tiny.toml", "tiny", [6], ["hermite-simpson"])
    case, = load_suite(suite).cases
    text = suite.read_text()
    suite.unlink()
    store_dir = tmp_path / "store"
    with ResultStore.create(store_dir) as store:
        store.start_run({"run_id": "r1", "suite": "tiny", "suite_path": "suites/tiny.toml", "suite_text": text,
                         "started_at": "now"})
        rows = store.runs()
    (store_dir / "checkpoints").mkdir()
    (store_dir / "checkpoints" / f"{case.key}.json").write_text('{"saved": 2, "of": 11, "elapsed_s": 36.0}')
    (named,) = walks_in_flight(store_dir, rows, set())
    assert named[:2] == (case.label, "2 of 11")


def test_a_run_whose_output_is_no_terminal_logs_each_case_and_each_saved_step_with_the_time(tmp_path: Path) -> None:
    """A batch job's log (`nohup gaitbench run ... > log`) gets no progress bar; hour-long walks show there as a
    timestamped line per case finished and per step saved."""
    import re

    from gaitbench.cli.run_progress import StepsInFlight
    from gaitbench.run.suite import load_suite

    suite = tiny_suite(tmp_path / "tiny.toml", "tiny", [6], ["hermite-simpson"])
    result = run_cli("run", str(suite), "--store", str(tmp_path / "store"), "--executor", "inprocess",
                     "--no-report")
    assert result.code == 0, result.output
    stamp = r"\d{4}-\d\d-\d\d \d\d:\d\d:\d\d "
    assert re.search(stamp + r"1 case to run", result.output)
    assert re.search(stamp + r"\[1/1\] solved: forward N=6 .*: ACOT \d\.\d{4}, \d+ s", result.output)

    case, = load_suite(suite).cases
    watcher = StepsInFlight(tmp_path / "flight", [case])
    (tmp_path / "flight" / "checkpoints").mkdir(parents=True)
    progress = tmp_path / "flight" / "checkpoints" / f"{case.key}.json"
    (tmp_path / "flight" / "checkpoints" / "0123456789abcdef.json").write_text('{"saved": 4, "of": 11}')
    seen: dict[str, int] = {}
    progress.write_text('{"saved": 2, "of": 11, "elapsed_s": 5400.0}')
    assert watcher.new_steps(seen) == [f"step 2 of 11 saved ({case.label.split(':')[0]}), 1.50 h"]
    assert watcher.new_steps(seen) == []  # nothing new; another suite's walk is never named
    progress.write_text('{"saved": 3, "of": 11, "elapsed_s": 750.0}')
    assert watcher.new_steps(seen) == [f"step 3 of 11 saved ({case.label.split(':')[0]}), 12.5 min"]
    progress.write_text('{"saved": 1, "of": 11, "elapsed_s": 4.0}')  # started again from step 1 (other code)
    assert watcher.new_steps(seen) == [f"step 1 of 11 saved ({case.label.split(':')[0]}), 4 s"]


# --- 2. store errors: one line, the path, nothing changed -------------------------------------------------------

@pytest.fixture
def suite_file(tmp_path: Path) -> Path:
    return tiny_suite(tmp_path / "tiny.toml", "tiny", [6], ["hermite-simpson"])


def run_cli(*args: str) -> SimpleNamespace:
    result = CliRunner().invoke(main, list(args))
    lines = [line for line in result.output.splitlines() if line.strip() and "━" not in line]
    return SimpleNamespace(code=result.exit_code, lines=lines, exception=result.exception, output=result.output)


def assert_one_line_error(result: SimpleNamespace, *fragments: str) -> None:
    assert result.code == 1, result.output
    assert isinstance(result.exception, SystemExit), repr(result.exception)  # a ClickException, not a crash
    errors = [line for line in result.lines if line.startswith("Error:")]
    assert len(errors) == 1, result.output
    for fragment in fragments:
        assert fragment in errors[0], errors[0]


def test_a_store_that_cannot_be_created_is_one_line(tmp_path: Path, suite_file: Path) -> None:
    blocker = tmp_path / "file"
    blocker.write_text("a regular file, so nothing can be made under it, even by root")
    store = blocker / "store"
    result = run_cli("run", str(suite_file), "--store", str(store), "--executor", "inprocess", "--no-report")
    assert_one_line_error(result, str(store), "cannot create the results store")
    database = tmp_path / "dir-db"
    (database / DATABASE).mkdir(parents=True)  # results.sqlite that SQLite cannot open
    result = run_cli("run", str(suite_file), "--store", str(database), "--executor", "inprocess", "--no-report")
    assert_one_line_error(result, str(database / DATABASE))
    result = run_cli("run", str(suite_file), "--store", str(blocker), "--executor", "inprocess", "--no-report")
    assert result.code == 2 and f"--store: {blocker} is a file, not a results store's directory" in result.output


def test_a_file_that_is_not_sqlite_is_one_line_and_unchanged(tmp_path: Path, suite_file: Path) -> None:
    (tmp_path / "store").mkdir()
    database = tmp_path / "store" / DATABASE
    database.write_bytes(b"these are my notes, not a database\n" * 20)
    before = listing(tmp_path / "store")
    result = run_cli("run", str(suite_file), "--store", str(tmp_path / "store"), "--executor", "inprocess",
                     "--no-report")
    assert_one_line_error(result, str(database), "not an SQLite database")
    assert_one_line_error(run_cli("runs", "show", str(tmp_path / "store")), str(database))
    assert listing(tmp_path / "store") == before


def test_a_foreign_sqlite_file_is_refused_and_never_modified(tmp_path: Path, suite_file: Path) -> None:
    store = tmp_path / "store"
    store.mkdir()
    with sqlite3.connect(store / DATABASE) as db:
        db.execute("CREATE TABLE people (name TEXT)")
        db.execute("INSERT INTO people VALUES ('Ada')")
    db.close()
    before = listing(store)
    result = run_cli("run", str(suite_file), "--store", str(store), "--executor", "inprocess", "--no-report")
    assert_one_line_error(result, str(store / DATABASE), "not a gaitbench results store", "people")
    assert_one_line_error(run_cli("runs", "show", str(store)), str(store / DATABASE), "not a gaitbench")
    assert_one_line_error(run_cli("report", str(store), "--out", str(tmp_path / "report")), "not a gaitbench")
    with pytest.raises(StoreError, match="not a gaitbench results store"):
        gaitbench.load_results(store)
    assert listing(store) == before  # same bytes (no `runs` table, still a rollback journal), no -wal or -shm
    with sqlite3.connect(f"file:{store / DATABASE}?mode=ro", uri=True) as db:
        assert db.execute("PRAGMA journal_mode").fetchone()[0] == "delete"


def test_another_application_s_file_is_told_by_its_application_id(tmp_path: Path) -> None:
    with sqlite3.connect(tmp_path / DATABASE) as db:
        db.execute("PRAGMA application_id = 1234")
        db.execute("CREATE TABLE cases (case_key TEXT)")  # even with a table of the same name
    db.close()
    with pytest.raises(StoreError, match="another application"):
        ResultStore.create(tmp_path)


def test_an_empty_or_older_store_is_accepted_and_stamped(tmp_path: Path) -> None:
    empty, older = tmp_path / "empty", tmp_path / "older"
    empty.mkdir()
    (empty / DATABASE).touch()
    older.mkdir()
    with sqlite3.connect(older / DATABASE) as db:  # before the application id, and analyzed (sqlite_stat1)
        db.execute("CREATE TABLE runs (run_id TEXT PRIMARY KEY, suite TEXT, started_at TEXT, finished_at TEXT)")
        db.execute("CREATE TABLE cases (case_key TEXT PRIMARY KEY, run_id TEXT, status TEXT)")
        db.execute("INSERT INTO cases VALUES ('old', 'r0', 'solved')")
        db.execute("ANALYZE")
    db.close()
    for store in (empty, older):
        ResultStore.create(store).close()
        with sqlite3.connect(store / DATABASE) as db:
            assert db.execute("PRAGMA application_id").fetchone()[0] == int.from_bytes(b"gbch", "big")
        db.close()
    assert list(gaitbench.load_results(older).case_key) == ["old"]


# --- 3. a store in a read-only place ----------------------------------------------------------------------------

def test_a_store_in_a_read_only_place_is_read_without_a_write(tmp_path: Path, monkeypatch) -> None:
    """runs show, report and load_results on a store copied into a read-only directory.

    The tests run as root, whom permissions do not stop, so the directory is made read-only (0555, files 0444) and
    os.access is made to say so: what this checks is that reading takes the read-only path (mode=ro, immutable)
    and writes nothing at all, no byte of the database and no -wal/-shm lock file, which is what a really
    read-only place needs. A store missing a newer column is read without it.
    """
    cases = [fake_case(6), fake_case(7)]
    source = tmp_path / "source"
    run_suite(suite_of(cases), source, Instant())
    place = tmp_path / "readonly" / "store"
    shutil.copytree(source, place, ignore=shutil.ignore_patterns("*-wal", "*-shm"))
    with sqlite3.connect(place / DATABASE) as db:
        db.execute("ALTER TABLE cases DROP COLUMN retries")  # as a store written before the column existed
    db.close()
    for path in place.rglob("*"):
        path.chmod(0o555 if path.is_dir() else 0o444)
    place.chmod(0o555)
    real_access = os.access

    def access(path, mode, *args, **kwargs) -> bool:
        if mode & os.W_OK and isinstance(path, (str, Path)) and Path(path).resolve().is_relative_to(place.resolve()):
            return False
        return real_access(path, mode, *args, **kwargs)

    monkeypatch.setattr(os, "access", access)
    monkeypatch.setenv("COLUMNS", "200")
    before = listing(place)
    try:
        frame = gaitbench.load_results(place)
        assert len(frame) == 2 and frame.retries.isna().all()
        shown = run_cli("runs", "show", str(place))
        assert shown.code == 0, shown.output
        assert "solved" in shown.output
        listed = run_cli("runs", "list", str(place))
        assert listed.code == 0 and "test" in listed.output, listed.output
        exported = run_cli("runs", "export", str(place), "--out", str(tmp_path / "cases.csv"))
        assert exported.code == 0 and (tmp_path / "cases.csv").exists(), exported.output
        report = run_cli("report", str(place), "--out", str(tmp_path / "report"))
        assert report.code == 0, report.output
        assert (tmp_path / "report" / "index.html").exists()
        assert listing(place) == before
    finally:
        for path in [place, *place.rglob("*")]:
            path.chmod(0o755 if path.is_dir() else 0o644)


def test_an_export_that_cannot_be_written_is_one_line(tmp_path: Path) -> None:
    run_suite(suite_of([fake_case(6)]), tmp_path / "store", Instant())
    out = tmp_path / "file" / "cases.csv"
    (tmp_path / "file").write_text("a regular file, so nothing can be written under it")
    assert_one_line_error(run_cli("runs", "export", str(tmp_path / "store"), "--out", str(out)), str(out))


# --- 7. kill-safety at the edges --------------------------------------------------------------------------------

def test_resume_removes_what_a_killed_run_left_and_only_that(tmp_path: Path) -> None:
    """What the store wrote (its marker proves it) and no row needs goes; everything else stays: a directory a user
    put in cases/, a case directory from before markers, a staging directory without the marker, a checkpoint
    file being written by a live process."""
    kept, rowless = fake_case(6), fake_case(8)
    run_suite(suite_of([kept, rowless]), tmp_path, Instant())
    with sqlite3.connect(tmp_path / DATABASE) as db:  # a kill between the rename of its files and its row
        db.execute("DELETE FROM cases WHERE case_key = ?", (rowless.key,))
    db.close()
    staged = tmp_path / f".{fake_case(7).key}-k1lled00"  # a kill before the rename
    shutil.copytree(tmp_path / "cases" / kept.key, staged)
    (staged / CASE_MARKER).write_text(json.dumps({"gaitbench": "case", "case_key": fake_case(7).key}))
    empty_staging = tmp_path / f".{fake_case(9).key}-abcd1234"  # a kill before the marker
    empty_staging.mkdir()
    unmarked_staging = tmp_path / f".{fake_case(10).key}-abcd1234"
    unmarked_staging.mkdir()
    (unmarked_staging / "notes.txt").write_text("mine")
    legacy = tmp_path / "cases" / fake_case(11).key  # written before markers: never deleted
    legacy.mkdir()
    (legacy / "walk.json").write_text("{}")
    photos = tmp_path / "cases" / "photos"
    photos.mkdir()
    (photos / "a.jpg").write_bytes(b"\xff\xd8")
    checkpoints = tmp_path / "checkpoints"
    checkpoints.mkdir(exist_ok=True)
    dead, live = dead_pid(), os.getpid()
    written = [checkpoints / f".{fake_case(12).key}.{dead}", checkpoints / f".{fake_case(12).key}.json.{dead}"]
    writing = checkpoints / f".{fake_case(13).key}.{live}"
    notes = checkpoints / f".notes.{dead}"
    for path in (*written, writing, notes):
        path.write_bytes(b"part")
    other = tmp_path / ".not-gaitbench"
    other.mkdir()

    run_suite(suite_of([kept, fake_case(14)]), tmp_path, Instant(), resume=True)
    gone = (tmp_path / "cases" / rowless.key, staged, empty_staging, *written)
    assert not any(path.exists() for path in gone)
    assert all(path.exists() for path in (unmarked_staging, legacy, photos / "a.jpg", writing, notes, other))
    assert (tmp_path / "cases" / kept.key / "walk.json").exists()


def test_leftovers_are_kept_while_another_run_is_live(tmp_path: Path) -> None:
    other_run(tmp_path, "other", pid=os.getppid())  # a live process on this host, heartbeat fresh
    staging = tmp_path / f".{fake_case(7).key}-inflight"
    staging.mkdir()
    run_suite(suite_of([fake_case(6)]), tmp_path, Instant(), resume=True)
    assert staging.exists()  # it may be the other run's case being written


def test_a_stopped_run_ends_its_span_when_it_stops_not_at_its_last_beat(tmp_path: Path) -> None:
    """A sweep's wall time counts each stopped run to its last heartbeat: SIGTERM between two beats lost up to one."""
    with ResultStore.create(tmp_path) as store:
        store.start_run({"run_id": "r", "suite": "test", "started_at": "2026-01-01T00:00:00+00:00"})
        with sqlite3.connect(tmp_path / "results.sqlite") as db:  # its last beat, long before it is stopped
            db.execute("UPDATE runs SET heartbeat_at = '2026-01-01T00:00:30+00:00'")
        store.finish_run("r", None)
        (run,) = store.runs()
    assert run["finished_at"] is None and run["heartbeat_at"] > "2026-01-02"


@pytest.mark.parametrize("umask", [0o022, 0o002])
def test_case_directories_follow_the_umask(tmp_path: Path, umask: int) -> None:
    old = os.umask(umask)
    try:
        with ResultStore.create(tmp_path) as store:
            store.start_run({"run_id": "r", "suite": "test"})
            outcome = CaseOutcome(fake_case(6), "solved", "", 0.0)
            store.record_case(case_row(outcome, "test", "r"), {"walk.json": b"{}"})
            store.finish_run("r", None)
    finally:
        os.umask(old)
    directory = tmp_path / "cases" / fake_case(6).key
    assert directory.stat().st_mode & 0o777 == 0o777 & ~umask
    assert (directory / "walk.json").stat().st_mode & 0o777 == 0o666 & ~umask


SLOW_EXIT_PLUGIN = '''
"""Makes the race of a pool's shutdown certain: a semaphore registered with the resource tracker, as pyomo makes on
import, and a worker exit that takes a while, so that Pebble's SIGTERM lands in the middle of it."""
import inspect
import multiprocessing
import multiprocessing.util
import time

from gaitbench import Registration, hookimpl

LOCK = multiprocessing.get_context("spawn").Lock()


def slow_exit():
    killed = any(frame.function == "process_exit" for frame in inspect.stack())
    time.sleep(0.3 if killed else 1.5)  # both well within Pebble's 3 s before SIGKILL


multiprocessing.util.Finalize(None, slow_exit, exitpriority=10)  # runs before the lock's own finalizer (0)


def slow_forward():
    from gaitbench_plugins.experiments.thesis_experiments import forward

    time.sleep(1.0)  # each of the two workers takes one case
    return forward()


@hookimpl
def register_experiments():
    return [Registration("slow-forward", "forward, slowly", slow_forward)]
'''


def test_a_local_pool_run_leaks_no_semaphore(tmp_path: Path) -> None:
    plugins = tmp_path / "plugins"
    plugins.mkdir()
    (plugins / "slow_exit.py").write_text(SLOW_EXIT_PLUGIN)
    suite = tiny_suite(tmp_path / "pool.toml", "pool", [6, 7], ["hermite-simpson"], experiment="slow-forward")
    result = subprocess.run([GAITBENCH, "--plugins-dir", str(plugins), "run", str(suite), "--store",
                             str(tmp_path / "store"), "--jobs", "2", "--no-report"],
                            capture_output=True, text=True, env=ENV, timeout=600)
    assert result.returncode == 0, result.stderr
    assert "2 solved" in result.stderr
    assert "leaked semaphore" not in result.stderr, result.stderr



# --- 4. merging stores: a sweep run a part at a time --------------------------------------------------------------

class Tagged:
    """An executor like :class:`Instant` whose walks say which store they were run for, and take ``seconds``."""

    name, jobs = "tagged", 1

    def __init__(self, tag: str, seconds: float = 1.0) -> None:
        self.tag, self.seconds = tag, seconds

    def run(self, cases):
        for case in cases:
            yield CaseOutcome(case, "solved", "", self.seconds,
                              files={"walk.json": f'{{"store": "{self.tag}", "N": {case.n_nodes}}}'.encode()})


def stored(store: Path) -> dict[str, dict]:
    return {row["case_key"]: row for row in ResultStore.open(store).cases()}


def test_merging_stores_gathers_cases_with_their_files_and_runs(tmp_path: Path) -> None:
    """Two stores holding parts of one sweep, merged: every case once, with its own files, row and run; the case
    both hold is the destination's unless --replace; merging again changes nothing."""
    cases = [fake_case(n) for n in (6, 7, 8)]
    run_suite(suite_of(cases[:2]), tmp_path / "a", Tagged("a"))
    run_suite(suite_of(cases[1:], name="b"), tmp_path / "b", Tagged("b", seconds=2.0))
    before = stored(tmp_path / "a")
    source = stored(tmp_path / "b")

    result = run_cli("runs", "merge", str(tmp_path / "b"), "--into", str(tmp_path / "a"))
    assert result.code == 0, result.output
    assert "1 cases copied" in result.output and "1 cases differ" in result.output and cases[1].key in result.output
    merged = stored(tmp_path / "a")
    assert set(merged) == {case.key for case in cases}
    assert merged[cases[1].key] == before[cases[1].key]  # kept: the destination's own
    assert merged[cases[2].key] == source[cases[2].key]  # copied whole, run id and provenance included
    walk = tmp_path / "a" / merged[cases[2].key]["walk_path"]
    assert b'"store": "b"' in walk.read_bytes()
    with ResultStore.open(tmp_path / "a") as store:
        runs = {run["run_id"]: run for run in store.runs()}
    assert source[cases[2].key]["run_id"] in runs and runs[source[cases[2].key]["run_id"]]["cases_done"] == 1

    again = run_cli("runs", "merge", str(tmp_path / "b"), "--into", str(tmp_path / "a"))
    assert again.code == 0 and "0 cases copied" in again.output and "1 already there" in again.output
    assert stored(tmp_path / "a") == merged

    replaced = run_cli("runs", "merge", str(tmp_path / "b"), "--into", str(tmp_path / "a"), "--replace")
    assert replaced.code == 0 and "1 replaced" in replaced.output
    assert stored(tmp_path / "a")[cases[1].key] == source[cases[1].key]
    assert b'"store": "b"' in (tmp_path / "a" / source[cases[1].key]["walk_path"]).read_bytes()


def test_replace_never_puts_a_failed_walk_over_a_complete_one(tmp_path: Path) -> None:
    from gaitbench.run.merge import merge_store

    case = fake_case(6)
    run_suite(suite_of([case]), tmp_path / "a", Tagged("a"))
    crashing = SimpleNamespace(name="crashing", jobs=1,
                               run=lambda cases: (failed_outcome(case, "crashed", "worker died") for case in cases))
    run_suite(suite_of([case], name="b"), tmp_path / "b", crashing)
    with ResultStore.create(tmp_path / "a") as into, ResultStore.open(tmp_path / "b") as source:
        summary = merge_store(into, source, replace=True)
    assert summary.kept == [case.key] and not summary.replaced
    assert stored(tmp_path / "a")[case.key]["status"] == "solved"


def test_a_case_a_run_records_while_the_merge_goes_on_keeps_the_runs_result(tmp_path: Path, monkeypatch) -> None:
    """The merge reads the destination once, then copies case by case: a case a run records in the destination
    meanwhile is not overwritten by the source's (even with ``replace``), and the summary says it was left."""
    import gaitbench.run.merge as merge

    case = fake_case(6)
    crashing = SimpleNamespace(name="crashing", jobs=1,
                               run=lambda cases: (failed_outcome(case, "crashed", "worker died") for case in cases))
    run_suite(suite_of([case]), tmp_path / "a", crashing)
    run_suite(suite_of([case], name="b"), tmp_path / "b", Tagged("b"))
    read_files = merge.case_files

    def files_while_a_run_records(directory, key):
        run_suite(suite_of([case]), tmp_path / "a", Tagged("a"), resume=True, retry_failed=True)
        return read_files(directory, key)

    monkeypatch.setattr(merge, "case_files", files_while_a_run_records)
    with ResultStore.create(tmp_path / "a") as into, ResultStore.open(tmp_path / "b") as source:
        summary = merge.merge_store(into, source, replace=True)
    assert summary.in_flight == [case.key] and not summary.replaced
    row = stored(tmp_path / "a")[case.key]
    assert row["status"] == "solved" and b'"store": "a"' in (tmp_path / "a" / row["walk_path"]).read_bytes()


def test_a_run_id_taken_by_another_run_is_renamed_when_merged(tmp_path: Path) -> None:
    from gaitbench.run.merge import merge_store

    run_suite(suite_of([fake_case(6)]), tmp_path / "a", Tagged("a"))
    run_suite(suite_of([fake_case(7)], name="b"), tmp_path / "b", Tagged("b"))
    taken = next(iter(stored(tmp_path / "b").values()))["run_id"]
    other_run(tmp_path / "a", taken, finished_at="2026-01-01T00:00:00+00:00")  # another run under the same id
    with ResultStore.create(tmp_path / "a") as into, ResultStore.open(tmp_path / "b") as source:
        summary = merge_store(into, source)
    assert summary.runs == [f"{taken}-2"]
    assert stored(tmp_path / "a")[fake_case(7).key]["run_id"] == f"{taken}-2"


def test_a_case_being_solved_on_the_destination_is_left_to_its_run(tmp_path: Path) -> None:
    from gaitbench.run.merge import merge_store

    run_suite(suite_of([fake_case(6)]), tmp_path / "b", Tagged("b"))
    other_run(tmp_path / "a", "live", claims=(fake_case(6).key,), pid=os.getpid())
    from gaitbench.run import liveness

    liveness.OPEN_RUNS.add("live")  # this process's run, so alive
    try:
        with ResultStore.create(tmp_path / "a") as into, ResultStore.open(tmp_path / "b") as source:
            summary = merge_store(into, source)
    finally:
        liveness.OPEN_RUNS.discard("live")
    assert summary.in_flight == [fake_case(6).key] and not summary.copied
    assert stored(tmp_path / "a") == {}


def test_a_source_missing_a_file_merges_nothing_and_says_which(tmp_path: Path) -> None:
    run_suite(suite_of([fake_case(6), fake_case(7)]), tmp_path / "b", Tagged("b"))
    lost = stored(tmp_path / "b")[fake_case(7).key]["walk_path"]
    (tmp_path / "b" / lost).unlink()
    result = run_cli("runs", "merge", str(tmp_path / "b"), "--into", str(tmp_path / "a"))
    assert_one_line_error(result, lost, "nothing was merged")
    assert stored(tmp_path / "a") == {}
    missing = run_cli("runs", "merge", str(tmp_path / "nowhere"), "--into", str(tmp_path / "c"))
    assert_one_line_error(missing, "nowhere", "no results store here")
    assert not (tmp_path / "c").exists()  # the sources are opened before the destination is made
    itself = run_cli("runs", "merge", str(tmp_path / "b"), "--into", str(tmp_path / "b"))
    assert_one_line_error(itself, "cannot be merged into itself")


def test_runs_show_narrows_the_table_by_experiment_method_and_status(tmp_path: Path) -> None:
    one_phase, other = fake_case(6), fake_case(7)
    other = Case(other.experiment, 7, other.transcription, other.solver, PluginChoice("decrease-and-conquer"),
                 steps=1, method="D&C-DC")
    run_suite(suite_of([one_phase, other]), tmp_path / "store", Tagged("a"))

    def shown(*options: str) -> list[str]:
        result = run_cli("runs", "show", str(tmp_path / "store"), *options)
        assert result.code == 0, result.output
        return [line for line in result.lines if line.lstrip().startswith("forward")]

    assert len(shown()) == 2
    assert [line.split()[1:3] for line in shown("--method", "D&C-DC")] == [["7", "D&C-DC"]]
    assert len(shown("--method", "D&C-DC", "--method", "OP-DC", "--experiment", "forward")) == 2
    assert shown("--status", "incomplete") == []  # a status none has: an empty table (an unknown name is refused)


def test_a_verdict_is_not_written_onto_a_walk_recorded_again_since_it_was_read(tmp_path: Path) -> None:
    """``gaitbench verify --store`` reads the rows, verifies for a long while, then writes: a case a run recorded
    again meanwhile keeps its new row."""
    cases = [fake_case(6), fake_case(7)]
    run_suite(suite_of(cases), tmp_path, Tagged("first"))
    read = {key: (row["run_id"], row["finished_at"]) for key, row in stored(tmp_path).items()}
    with ResultStore.create(tmp_path) as store:
        store.update_cases({cases[1].key: {"finished_at": "2099-01-01T00:00:00+00:00"}})  # recorded again
        changed = store.update_cases({case.key: {"verified": True} for case in cases}, read)
    assert changed == [cases[1].key]
    rows = stored(tmp_path)
    assert rows[cases[0].key]["verified"] == 1 and rows[cases[1].key]["verified"] is None


def test_a_merge_holds_the_write_lock_from_its_check_to_its_row(tmp_path: Path, monkeypatch) -> None:
    """Between the merge's check that a case is unchanged and its row, no other writer gets in: one placing the
    case's files finds the store locked (before, it could record the case there and have it overwritten)."""
    import gaitbench.run.merge as merge
    import gaitbench.run.store as store_module

    case = fake_case(6)
    run_suite(suite_of([case], name="b"), tmp_path / "b", Tagged("b"))
    other = ResultStore.create(tmp_path / "a", lock_timeout=0.2)
    place = store_module.place_case
    attempts = []

    def place_while_another_writer_tries(*args, **kwargs):
        with pytest.raises(StoreError, match="lock"):
            other.update_cases({case.key: {"message": "written meanwhile"}})
        attempts.append("refused")
        return place(*args, **kwargs)

    monkeypatch.setattr(store_module, "place_case", place_while_another_writer_tries)
    with other, ResultStore.create(tmp_path / "a") as into, ResultStore.open(tmp_path / "b") as source:
        summary = merge.merge_store(into, source)
    assert attempts == ["refused"] and summary.copied == [case.key]


@pytest.mark.parametrize("where", ["file", "database"])
def test_an_empty_file_is_no_store_and_reading_it_leaves_it_empty(tmp_path: Path, where: str) -> None:
    """`runs show` on an empty file (or a store whose results.sqlite a failed copy left empty) turned it into a new,
    empty store and showed "0 cases"."""
    if where == "file":
        path = empty = tmp_path / "empty"
    else:
        path, empty = tmp_path / "store", tmp_path / "store" / DATABASE
        path.mkdir()
    empty.write_bytes(b"")
    result = CliRunner().invoke(main, ["runs", "show", str(path)])
    assert result.exit_code == 1 and "an empty file, not a results store" in result.output
    assert empty.stat().st_size == 0

