"""Fuzzing the command line with random and mutated suite files and store rows (issue 63): every one ends with exit
status 0, 1 or 2 and no traceback, and nothing outside the store is deleted.

Each test runs a small budget of examples under a fixed seed in the default run, and a long one behind the
``fuzz`` marker (``pytest -m fuzz tests/test_fuzz_cli.py``). Runs hand their cases to an executor that solves
nothing (``Instant``), so a valid suite costs milliseconds; everything up to the executor, and the recording, is
the real code.
"""

from __future__ import annotations

import json
import math
import shutil
import sqlite3
from pathlib import Path

import pytest
from click.testing import CliRunner
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from test_store import Instant, fake_case, listing, suite_of

import gaitbench.cli.run_commands
from gaitbench.cli.main import main
from gaitbench.run.runner import run_suite
from gaitbench.run.store import DATABASE
from gaitbench.run.store_schema import TABLES

BUDGETS = [pytest.param(40, id="quick"), pytest.param(1000, id="long", marks=pytest.mark.fuzz)]
REPORT_BUDGETS = [pytest.param(6, id="quick"), pytest.param(150, id="long", marks=pytest.mark.fuzz)]
"""Examples per test: a report takes about a second."""


def fuzz_settings(examples: int):
    return settings(max_examples=examples, derandomize=True, deadline=None, database=None, print_blob=True,
                    suppress_health_check=list(HealthCheck))


def invoke(*args: str):
    """The command in this process, as a user would run it; its result, after checking it ended as promised."""
    result = CliRunner().invoke(main, list(args))
    assert result.exit_code in (0, 1, 2), (args, result.exit_code, result.output)
    assert result.exception is None or isinstance(result.exception, SystemExit), (args, repr(result.exception))
    assert "Traceback" not in result.output, result.output
    return result


@pytest.fixture
def sandbox(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """A working directory (the current one) beside a directory of a user's files, with the executor that solves
    nothing in place of the local pool."""
    work = tmp_path / "work"
    work.mkdir()
    (work / "notes.txt").write_text("a user's notes")
    victim = tmp_path / "victim"
    (victim / "cases" / "photos").mkdir(parents=True)
    (victim / "cases" / "photos" / "a.jpg").write_bytes(b"\xff\xd8")
    monkeypatch.chdir(work)
    monkeypatch.setattr(gaitbench.cli.run_commands, "_executor", lambda *args: Instant())
    return tmp_path


# --- suite files --------------------------------------------------------------------------------------------------

BASE_SUITE = {
    "suite": {"name": "fuzz", "steps": 1, "time_limit_s": 60},
    "sweep": {"experiments": ["forward"], "N": [6, 8], "transcriptions": ["hermite-simpson"], "solvers": ["ipopt"],
              "strategies": ["one-phase"]},
}

SCALARS = st.one_of(st.none(), st.booleans(), st.integers(-10**12, 10**12), st.floats(allow_nan=False),
                    st.text(max_size=12), st.sampled_from(["forward", "ipopt", "dmoc", "one-phase", "N", "", "-"]))
VALUES = st.recursive(SCALARS, lambda inner: st.one_of(st.lists(inner, max_size=4),
                                                       st.dictionaries(st.text(max_size=8), inner, max_size=3)),
                      max_leaves=8)
OUTPUTS = ["results/fuzz", "../x", "..", ".", "../victim", "results/../../x", "{root}/victim", "{root}/victim/cases",
           "{root}/work", "{root}/new-store", "/", ""]
"""Where a suite may point its store: inside the current directory, out of it with `..`, and absolute paths to a
user's directories, all inside the sandbox (an absolute path is used as written, so none may lead outside it)."""


def toml_value(value) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        return repr(value) if math.isfinite(value) else ("inf" if value > 0 else "-inf")
    if isinstance(value, str):
        return json.dumps(value)  # a TOML basic string is a JSON string
    if isinstance(value, list):
        return "[" + ", ".join(toml_value(item) for item in value if item is not None) + "]"
    if isinstance(value, dict):
        return "{" + ", ".join(f"{json.dumps(key)} = {toml_value(item)}" for key, item in value.items()
                               if item is not None) + "}"
    return '""'


def toml_text(suite: dict) -> str:
    lines = []
    for table, values in suite.items():
        lines.append(f"[{table}]" if isinstance(values, dict) else f"{table} = {toml_value(values)}")
        if isinstance(values, dict):
            lines += [f"{json.dumps(key)} = {toml_value(value)}" for key, value in values.items() if value is not None]
    return "\n".join(lines) + "\n"


@st.composite
def suite_texts(draw, root: Path) -> str:
    """The base suite with a few of its values replaced, keys dropped or added, its output chosen from
    :data:`OUTPUTS`, and its text then perhaps cut or spliced after the output line (which stays as chosen, so that
    no edit makes an absolute path outside the sandbox)."""
    suite = json.loads(json.dumps(BASE_SUITE))
    for _ in range(draw(st.sampled_from([0, 0, 0, 1, 2, 4]))):  # the base suite, intact, often: it runs
        table = draw(st.sampled_from(["suite", "sweep"]))
        key = draw(st.sampled_from([*suite[table], "repetitions", "N", "description", "problem_options", "bogus"]))
        action = draw(st.sampled_from(["set", "drop"]))
        if action == "drop":
            suite[table].pop(key, None)
        else:
            suite[table][key] = draw(VALUES)
    output = draw(st.sampled_from(OUTPUTS)).format(root=root)
    if draw(st.integers(0, 7)) == 7:  # not at the simplest example, which is the base suite as it is
        suite["suite"]["plugins"] = ["no-such-plugin-directory"]  # never a real directory: no code is loaded
    head = "[suite]\n" + (f"output = {json.dumps(output)}\n" if output else "")
    text = toml_text(suite).replace("[suite]\n", head, 1)
    edit = draw(st.sampled_from(["none", "none", "none", "none", "cut", "splice"]))
    if edit != "none" and len(text) > len(head):
        at = draw(st.integers(len(head), len(text) - 1))
        text = text[:at] if edit == "cut" else text[:at] + draw(st.text(max_size=6)) + text[at + 1:]
    return text


@pytest.mark.parametrize("examples", BUDGETS)
def test_random_suite_files_end_with_a_status_and_delete_nothing_of_the_user_s(sandbox: Path, examples: int) -> None:
    before = {"victim": listing(sandbox / "victim"), "notes": (sandbox / "work" / "notes.txt").read_bytes()}
    suite = sandbox / "work" / "suite.toml"

    codes = set()

    @fuzz_settings(examples)
    @given(text=suite_texts(sandbox), resume=st.booleans())
    def run_one(text: str, resume: bool) -> None:
        suite.write_text(text)
        codes.add(invoke("run", str(suite), "--no-report", *(["--resume"] if resume else [])).exit_code)
        assert listing(sandbox / "victim") == before["victim"]
        assert (sandbox / "work" / "notes.txt").read_bytes() == before["notes"]

    run_one()
    assert codes == {0, 1, 2}  # runs recorded, stores refused, suites refused: the fuzzing reached each


# --- store rows -----------------------------------------------------------------------------------------------------

CELLS = st.one_of(st.none(), st.integers(-2**63, 2**63 - 1), st.floats(), st.text(max_size=16), st.binary(max_size=8),
                  st.sampled_from(["{}", "[]", "null", '"x"', "[1, \"a\"]", "[null, 0.5]", '{"a":', "{\"packages\": 1}",
                                   "2026-12-07T03:00:00+00:00", "solved", "error", "crashed", "forward"]))


@st.composite
def store_edits(draw) -> list[tuple[str, tuple]]:
    """A few statements a hand edit of the store could be: cells set to anything, rows deleted or added with
    only a key, a column or a table dropped."""
    edits = []
    for _ in range(draw(st.integers(1, 3))):
        table = draw(st.sampled_from(sorted(TABLES)))
        column = draw(st.sampled_from(sorted(TABLES[table])))
        kind = draw(st.sampled_from(["set", "set", "set", "set-one", "delete", "insert", "drop-column", "drop"]))
        if kind == "set":
            edits.append((f"UPDATE {table} SET {column} = ?", (draw(CELLS),)))
        elif kind == "set-one":
            edits.append((f"UPDATE {table} SET {column} = ? WHERE rowid = (SELECT MIN(rowid) FROM {table})",
                          (draw(CELLS),)))
        elif kind == "delete":
            edits.append((f"DELETE FROM {table}", ()))
        elif kind == "insert":
            key = "run_id" if table == "runs" else "case_key"
            extra = ", run_id" if table == "claims" else ""
            values = "?, 'r'" if table == "claims" else "?"
            edits.append((f"INSERT OR IGNORE INTO {table} ({key}{extra}) VALUES ({values})", (draw(CELLS),)))
        elif kind == "drop-column":
            edits.append((f"ALTER TABLE {table} DROP COLUMN {column}", ()))
        else:
            edits.append((f"DROP TABLE {table}", ()))
    return edits


def edited_copy(base: Path, store: Path, edits: list[tuple[str, tuple]]) -> None:
    """``store`` anew as a copy of ``base`` with ``edits`` applied (an edit SQLite refuses, such as dropping a key
    column, is no edit)."""
    shutil.rmtree(store, ignore_errors=True)
    shutil.copytree(base, store)
    with sqlite3.connect(store / DATABASE) as db:
        for statement, values in edits:
            try:
                db.execute(statement, values)
            except sqlite3.Error:
                pass
    db.close()


@pytest.fixture
def base_store(sandbox: Path) -> Path:
    """A store of two recorded cases, with a user's file in its cases directory."""
    store = sandbox / "base"
    run_suite(suite_of([fake_case(6), fake_case(7)]), store, Instant())
    (store / "cases" / "photos").mkdir()
    (store / "cases" / "photos" / "a.jpg").write_bytes(b"\xff\xd8")
    return store


@pytest.mark.parametrize("examples", BUDGETS)
def test_hand_edited_stores_end_with_a_status_in_every_reader(sandbox: Path, base_store: Path,
                                                             examples: int) -> None:
    suite = sandbox / "work" / "suite.toml"
    suite.write_text(toml_text(BASE_SUITE))
    store = sandbox / "edited"

    @fuzz_settings(examples)
    @given(edits=store_edits())
    def read_one(edits: list[tuple[str, tuple]]) -> None:
        edited_copy(base_store, store, edits)
        for command in (["runs", "show", str(store), "--wide"], ["runs", "list", str(store)],
                        ["runs", "export", str(store), "--out", str(sandbox / "cases.csv")],
                        ["run", str(suite), "--store", str(store), "--resume", "--no-report"]):
            invoke(*command)
        assert (store / "cases" / "photos" / "a.jpg").read_bytes() == b"\xff\xd8"

    read_one()


@pytest.mark.parametrize("examples", REPORT_BUDGETS)
def test_hand_edited_stores_end_with_a_status_in_the_report(sandbox: Path, base_store: Path, examples: int) -> None:
    """As above for `gaitbench report`, which reads every column (and takes a second a report)."""
    store = sandbox / "edited"

    @fuzz_settings(examples)
    @given(edits=store_edits())
    def report_one(edits: list[tuple[str, tuple]]) -> None:
        edited_copy(base_store, store, edits)
        invoke("report", str(store), "--out", str(sandbox / "report"))

    report_one()
