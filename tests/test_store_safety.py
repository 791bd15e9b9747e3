"""What a store may delete and how it fails (issue 63): a directory that is not a store is refused and kept, a
suite cannot point a run out of the current directory, the first store error stops a run with one line and keeps
the finished walks, and a store changed by hand is one line in every command that reads it."""

from __future__ import annotations

import errno
import json
import os
import shutil
import sqlite3
from pathlib import Path

import pytest
from test_store import Instant, assert_one_line_error, fake_case, listing, run_cli, suite_of, tiny_suite

import gaitbench
from gaitbench.checkpoint import CheckpointError, WalkCheckpoint
from gaitbench.run.executors import LocalPoolExecutor
from gaitbench.run.runner import run_suite
from gaitbench.run.store import DATABASE, ResultStore
from gaitbench.run.store_files import CASE_MARKER
from gaitbench.run.store_schema import StoreError
from gaitbench.run.suite import SuiteError, load_suite

INPROCESS = ("--executor", "inprocess", "--no-report")


@pytest.fixture
def suite_file(tmp_path: Path) -> Path:
    return tiny_suite(tmp_path / "tiny.toml", "tiny", [6], ["hermite-simpson"])


@pytest.fixture
def two_case_suite(tmp_path: Path) -> Path:
    return tiny_suite(tmp_path / "two.toml", "two", [6, 7], ["hermite-simpson"])


# --- a directory that is not a store ----------------------------------------------------------------------------

def _victim(tmp_path: Path) -> Path:
    victim = tmp_path / "victim"
    (victim / "cases" / "photos").mkdir(parents=True)
    (victim / "cases" / "photos" / "a.jpg").write_bytes(b"\xff\xd8 a photo")
    (victim / "cases" / "my-thesis-data").mkdir()
    (victim / "cases" / "my-thesis-data" / "chapter1.tex").write_text("\\chapter{One}")
    return victim


def test_a_directory_with_other_files_is_refused_and_left_as_it_was(tmp_path: Path, suite_file: Path) -> None:
    victim = _victim(tmp_path)
    before = listing(victim)
    result = run_cli("run", str(suite_file), "--store", str(victim), *INPROCESS)
    assert_one_line_error(result, str(victim), "not a gaitbench results store", "no results.sqlite")
    assert listing(victim) == before
    absolute = tmp_path / "absolute.toml"  # the same through a suite's absolute `output`
    absolute.write_text(suite_file.read_text().replace('name = "tiny"', f'name = "tiny"\noutput = "{victim}"'))
    assert_one_line_error(run_cli("run", str(absolute), *INPROCESS), str(victim), "not a gaitbench results store")
    source = tmp_path / "source"
    run_suite(suite_of([fake_case(6)]), source, Instant())
    assert_one_line_error(run_cli("runs", "merge", str(source), "--into", str(victim)), str(victim),
                          "not a gaitbench results store")
    assert listing(victim) == before


def test_a_store_keeps_what_a_user_put_in_its_cases_directory(tmp_path: Path, suite_file: Path) -> None:
    """A real run into a store whose cases/ holds a user's directories, and --resume of it: only the run's own case
    directory (with its marker) is added."""
    store = tmp_path / "store"
    ResultStore.create(store).close()
    victim = _victim(tmp_path)
    (victim / "cases").rename(store / "cases")
    users = listing(store / "cases")
    result = run_cli("run", str(suite_file), "--store", str(store), *INPROCESS)
    assert result.code == 0, result.output
    after = listing(store / "cases")
    assert {name: after[name] for name in users} == users
    (key,) = gaitbench.load_results(store).case_key
    assert json.loads(after[f"{key}/{CASE_MARKER}"]) == {"gaitbench": "case", "case_key": key}
    result = run_cli("run", str(suite_file), "--store", str(store), "--resume", *INPROCESS)
    assert result.code == 0, result.output
    assert listing(store / "cases") == after


@pytest.mark.parametrize("output", ["../x", "results/../../x", ".."])
def test_a_relative_output_that_leads_out_of_the_current_directory_is_refused(tmp_path: Path, suite_file: Path,
                                                                            output: str) -> None:
    escaping = tmp_path / "escaping.toml"
    escaping.write_text(suite_file.read_text().replace('name = "tiny"', f'name = "tiny"\noutput = "{output}"'))
    with pytest.raises(SuiteError, match=r"\[suite\]\.output: .* leads out of the current directory"):
        load_suite(escaping)
    result = run_cli("run", str(escaping), *INPROCESS)
    assert result.code == 2 and "Traceback" not in result.output
    assert f"{escaping}: [suite].output" in result.output


@pytest.mark.parametrize("output", ["results/../inside", "/absolute/place"])
def test_an_output_inside_or_written_absolute_is_taken_as_written(tmp_path: Path, suite_file: Path,
                                                                  output: str) -> None:
    path = tmp_path / "ok.toml"
    path.write_text(suite_file.read_text().replace('name = "tiny"', f'name = "tiny"\noutput = "{output}"'))
    assert load_suite(path).output == Path(output)


def test_a_case_directory_is_replaced_only_with_the_marker_or_a_row_naming_it(tmp_path: Path) -> None:
    """A case recorded again replaces its directory when the store can prove it wrote it: its marker, or (a store
    from before markers) its row naming it. A directory in the way without either is refused and kept."""
    legacy, foreign = fake_case(6), fake_case(7)
    run_suite(suite_of([legacy]), tmp_path, Instant())
    (tmp_path / "cases" / legacy.key / CASE_MARKER).unlink()  # as written before markers
    blocking = tmp_path / "cases" / foreign.key
    blocking.mkdir()
    (blocking / "mine.txt").write_text("not gaitbench's")
    with ResultStore.create(tmp_path) as store:
        store.record_case({"case_key": legacy.key, "run_id": None, "status": "solved", "experiment": "forward"},
                          {"walk.json": b"[]"})
        assert (tmp_path / "cases" / legacy.key / "walk.json").read_bytes() == b"[]"
        with pytest.raises(StoreError, match=f"cannot record case {foreign.key} .*was not written by this store"):
            store.record_case({"case_key": foreign.key, "run_id": None, "status": "solved", "experiment": "forward"},
                              {"walk.json": b"{}"})
    assert (blocking / "mine.txt").read_text() == "not gaitbench's"


# --- store errors while running: one line, finished work kept ---------------------------------------------------

def _lock(database: Path) -> sqlite3.Connection:
    """Another program holding the store's write lock (an open write transaction)."""
    holder = sqlite3.connect(database, isolation_level=None)
    holder.execute("BEGIN IMMEDIATE")
    return holder


def test_a_lock_held_at_claim_time_stops_the_run_with_one_line_and_keeps_what_was_recorded(
        tmp_path: Path, two_case_suite: Path, monkeypatch) -> None:
    store = tmp_path / "store"
    holders = []
    record = ResultStore.record_case

    def record_then_lock(self, row, files=None):
        record(self, row, files)
        if not holders:
            holders.append(_lock(self.database))

    monkeypatch.setattr(ResultStore, "record_case", record_then_lock)
    result = run_cli("run", str(two_case_suite), "--store", str(store), "--lock-timeout", "0.5", *INPROCESS)
    assert_one_line_error(result, str(store), "cannot claim case", "database is locked",
                          "waited for 0.5 s", "--lock-timeout")
    holders[0].rollback()
    holders[0].close()
    first = gaitbench.load_results(store)
    assert list(first.status) == ["solved"]
    monkeypatch.setattr(ResultStore, "record_case", record)
    result = run_cli("run", str(two_case_suite), "--store", str(store), "--resume", *INPROCESS)
    assert result.code == 0, result.output
    rows = gaitbench.load_results(store)
    assert sorted(rows.N) == [6, 7] and set(rows.status) == {"solved"}
    assert rows.set_index("case_key").loc[first.case_key[0], "acot"] == first.acot[0]  # kept as it was


def test_a_walk_finished_while_the_lock_is_held_keeps_its_checkpoint_and_resumes_from_it(
        tmp_path: Path, monkeypatch) -> None:
    """A local pool's worker finishes a walk while another program holds the lock: the next claim and then its
    recording fail, the run stops once, and the walk's checkpoint holds every step, which --resume records."""
    suite = load_suite(tiny_suite(tmp_path / "two.toml", "two", [6, 7], ["hermite-simpson"]))
    store = tmp_path / "store"
    holders = []
    claim = ResultStore.claim

    def claim_then_lock(self, case_key, run_id, expected):
        verdict = claim(self, case_key, run_id, expected)
        if not holders:
            holders.append(_lock(self.database))
        return verdict

    monkeypatch.setattr(ResultStore, "claim", claim_then_lock)
    with pytest.raises(StoreError, match=r"store: cannot (claim|record) case .*database is locked"):
        run_suite(suite, store, LocalPoolExecutor(1), lock_timeout=0.5)
    holders[0].rollback()
    holders[0].close()
    monkeypatch.setattr(ResultStore, "claim", claim)
    assert len(gaitbench.load_results(store)) == 0
    first = max(suite.cases, key=lambda case: case.n_nodes)  # largest first
    assert (store / "checkpoints" / f"{first.key}.json").exists()
    assert json.loads((store / "checkpoints" / f"{first.key}.json").read_text())["saved"] == 1
    summary = run_suite(suite, store, LocalPoolExecutor(1), resume=True)
    assert (summary.solved, summary.failed) == (2, 0)
    walk = json.loads((store / "cases" / first.key / "walk.json").read_text())
    assert walk["resumed"]["steps"] == 1  # taken from the checkpoint, not solved again


def test_a_store_that_cannot_take_checkpoints_mid_run_stops_the_run_once(tmp_path: Path, two_case_suite: Path,
                                                                        monkeypatch) -> None:
    """The store's checkpoints directory replaced by a file after the first case (a store that became unwritable;
    root ignores permissions): the next walk cannot save its first step, and the run stops with that line instead of
    recording the case, and every case after it, as an error."""
    store = tmp_path / "store"
    claim = ResultStore.claim
    claims = []

    def break_then_claim(self, case_key, run_id, expected):
        claims.append(case_key)
        if len(claims) == 2:
            shutil.rmtree(self.directory / "checkpoints")
            (self.directory / "checkpoints").write_text("in the way")
        return claim(self, case_key, run_id, expected)

    monkeypatch.setattr(ResultStore, "claim", break_then_claim)
    result = run_cli("run", str(two_case_suite), "--store", str(store), *INPROCESS)
    assert_one_line_error(result, str(store), "the run stopped", "cannot save the walk's checkpoint")
    assert list(gaitbench.load_results(store).status) == ["solved"]  # the second case is not an error row


def test_a_checkpoint_that_cannot_be_written_leaves_no_part_written_file(tmp_path: Path, monkeypatch) -> None:
    checkpoint = WalkCheckpoint(tmp_path / "checkpoints" / "0123456789abcdef", {"case": "x"})

    def full(*args):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(os, "replace", full)
    with pytest.raises(CheckpointError, match="cannot save the walk's checkpoint .No space left on device"):
        checkpoint.save([], set(), 1.0)
    assert list((tmp_path / "checkpoints").iterdir()) == []


# --- a store changed by hand: one line in every reader ----------------------------------------------------------

EDITS = {
    "a word in acot": ("UPDATE cases SET acot = 'fast'", "table cases, row case_key = '{key}', column acot: "
                                                         "expected a number or null, found text 'fast'"),
    "a fraction in N": ("UPDATE cases SET N = 6.5", "column N: expected an integer or null, found real 6.5"),
    "no experiment": ("UPDATE cases SET experiment = NULL", "column experiment: expected text, found null (the"),
    "bad JSON": ("UPDATE cases SET cot_steps = '[0.1,'", "table cases, row case_key = '{key}', column cot_steps: "
                                                         "not JSON"),
    "JSON of the wrong shape": ("UPDATE cases SET provenance = '[1]'", "column provenance: expected a JSON object"),
    "runs dropped": ("DROP TABLE runs", "table runs is missing"),
    "claims dropped": ("DROP TABLE claims", "table claims is missing"),
    "a run's pid as text": ("UPDATE runs SET pid = 'me'", "table runs, row run_id = "),
}


@pytest.mark.parametrize("edit", EDITS, ids=list(EDITS))
def test_a_store_changed_by_hand_is_one_line_in_every_reader(tmp_path: Path, suite_file: Path, edit: str) -> None:
    store = tmp_path / "store"
    case = load_suite(suite_file).cases[0]
    run_suite(suite_of([case]), store, Instant())
    statement, message = EDITS[edit]
    with sqlite3.connect(store / DATABASE) as db:
        db.execute(statement)
    db.close()
    expected = message.format(key=case.key)
    for command in (["runs", "show", str(store)], ["runs", "list", str(store)],
                    ["runs", "export", str(store), "--out", str(tmp_path / "cases.csv")],
                    ["report", str(store), "--out", str(tmp_path / "report")],
                    ["run", str(suite_file), "--store", str(store), "--resume", *INPROCESS]):
        assert_one_line_error(run_cli(*command), str(store / DATABASE), expected)


def test_a_report_that_cannot_be_written_is_one_line(tmp_path: Path) -> None:
    """`report --out` where nothing can be written (under a regular file: root is not stopped by permissions; a
    full disk gives the same OSError from the reporter's writes)."""
    run_suite(suite_of([fake_case(6)]), tmp_path / "store", Instant())
    (tmp_path / "file").write_text("a regular file, so nothing can be written under it")
    out = tmp_path / "file" / "report"
    assert_one_line_error(run_cli("report", str(tmp_path / "store"), "--out", str(out)), str(out),
                          "cannot write the report")
