"""The suite runner: store round trips, resume after a kill, crashed and hung workers, Dask against local."""

from __future__ import annotations

import json
import os
import platform
import signal
import sqlite3
import subprocess
import sys
import textwrap
import time
from dataclasses import replace
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from click.testing import CliRunner

import gaitbench
from gaitbench.cli.main import main
from gaitbench.run import executors
from gaitbench.run.case import Case, PluginChoice
from gaitbench.run.executors import DaskExecutor, ExecutorError, InProcessExecutor, LocalPoolExecutor
from gaitbench.run.provenance import VECTOR_EXTENSIONS
from gaitbench.run.runner import CaseOutcome, RunRefused, case_row, failed_outcome, run_case, run_suite
from gaitbench.run.store import DATABASE, ResultStore
from gaitbench.run.store_schema import CASE_COLUMNS, StoreError

GAITBENCH = str(Path(sys.executable).with_name("gaitbench"))
COMPARED = ("case_key", "method", "N", "status", "acot", "cot_steps", "iterations", "steps_solved", "max_defect")
"""Columns that must agree between executors (times and provenance differ by nature)."""

FAULTY_PLUGIN = '''
import os, signal, time
from gaitbench import Registration, hookimpl
from gaitbench.solve.solver import SolverResult, SolverStatus


class Crash:
    """Kills its own process mid-solve, as a segfaulting solver library would."""
    name = "crash"

    def __init__(self, **options):
        pass

    def solve(self, nlp, parameters, initial_guess):
        os.kill(os.getpid(), signal.SIGKILL)


class Hang:
    """Never returns and ignores its time limit, as a solver stuck in compiled code would."""
    name = "hang"

    def __init__(self, **options):
        pass

    def solve(self, nlp, parameters, initial_guess):
        time.sleep(3600)


class SpendsItsLimit:
    """Runs until its own time limit, as IPOPT did when MUMPS's factorizations grew to seconds each; IPOPT is its
    remedy."""
    name = "spends-its-limit"

    def __init__(self, time_limit_s=None, **options):
        self.time_limit_s = time_limit_s

    def solve(self, nlp, parameters, initial_guess):
        time.sleep(self.time_limit_s)
        return SolverResult(SolverStatus.TIME_LIMIT, "time limit (scripted)", initial_guess, float("nan"),
                            float("nan"), 1, self.time_limit_s, 0.0)

    def remedies(self):
        from gaitbench_plugins.solvers.ipopt import Ipopt
        return [("ipopt", Ipopt(time_limit_s=self.time_limit_s))]


@hookimpl
def register_solvers():
    return [Registration("crash", "kills its process", Crash), Registration("hang", "never returns", Hang),
            Registration("spends-its-limit", "runs to its time limit", SpendsItsLimit)]
'''


def walk_case(n_nodes: int, solver: str = "ipopt", plugin_dirs: tuple[str, ...] = (), **options) -> Case:
    return Case(PluginChoice("forward"), n_nodes, PluginChoice("hermite-simpson"), PluginChoice(solver, options),
                PluginChoice("one-phase"), steps=1, method=f"OP-DC {solver}", time_limit_s=60,
                plugin_dirs=plugin_dirs)


def suite_of(cases: list[Case], name: str = "test") -> SimpleNamespace:
    return SimpleNamespace(name=name, path=Path(f"{name}.toml"), text="# test suite", cases=cases)


def rows_by_key(store: Path) -> dict[str, dict]:
    frame = gaitbench.load_results(store)
    return {row["case_key"]: row for row in frame.to_dict("records")}


@pytest.fixture(scope="module")
def faulty_plugins(tmp_path_factory) -> Path:
    directory = tmp_path_factory.mktemp("faulty-plugins")
    (directory / "faulty.py").write_text(FAULTY_PLUGIN)
    return directory


@pytest.fixture(scope="module")
def local_store(tmp_path_factory) -> Path:
    """Two real one-step walks run by the local process pool: the reference rows for the other executors."""
    store = tmp_path_factory.mktemp("local") / "store"
    run_suite(suite_of([walk_case(8), walk_case(10)]), store, LocalPoolExecutor(2))
    return store


def test_case_key_is_canonical() -> None:
    one = walk_case(8, tol=1e-8, max_iterations=100)
    other = walk_case(8, max_iterations=100, tol=1e-8)
    relabelled = Case(one.experiment, 8, one.transcription, one.solver, one.strategy, steps=1, method="renamed",
                      time_limit_s=5, plugin_dirs=("/elsewhere",))
    assert one.key == other.key == relabelled.key
    assert walk_case(10).key != walk_case(8).key
    assert walk_case(8, tol=1e-6).key != walk_case(8, tol=1e-8).key


def test_a_stopped_walk_is_run_again_only_when_asked(tmp_path: Path) -> None:
    case = walk_case(8)
    with ResultStore.create(tmp_path) as store:
        store.start_run({"run_id": "r1", "suite": "s", "started_at": "now"})
        store.record_case(case_row(CaseOutcome(case, "incomplete", "step 3: infeasible", 1.0), "s", "r1"),
                          {"walk.json": b"{}"})
        assert store.finished_keys(retry_failed=True) == {case.key}  # the method's result, not the run's failure
        assert store.finished_keys(retry_incomplete=True) == set()


def test_a_complete_walk_that_is_not_verified_is_run_again_only_when_asked(tmp_path: Path) -> None:
    no_acot, failed, verified, unchecked = walk_case(8), walk_case(10), walk_case(12), walk_case(14)
    with ResultStore.create(tmp_path) as store:
        store.start_run({"run_id": "r1", "suite": "s", "started_at": "now"})
        for case, metrics in ((no_acot, {"acot": None}), (failed, {"acot": 0.3, "verified": False}),
                              (verified, {"acot": 0.3, "verified": True}), (unchecked, {"acot": 0.3})):
            store.record_case(case_row(CaseOutcome(case, "solved", "", 1.0, metrics), "s", "r1"),
                              {"walk.json": b"{}"})
        everything = {no_acot.key, failed.key, verified.key, unchecked.key}
        assert store.finished_keys(retry_incomplete=True) == everything
        assert store.finished_keys(retry_unverified=True) == {verified.key, unchecked.key}


def test_store_round_trip_and_messages(tmp_path: Path) -> None:
    case = walk_case(8)
    outcome = CaseOutcome(case, "timeout", "stopped", 12.5, provenance={"hostname": "here"})
    with ResultStore.create(tmp_path) as store:
        store.start_run({"run_id": "r1", "suite": "s", "started_at": "now"})
        row = case_row(outcome, "s", "r1") | {"iterations": np.int64(7), "fell": np.bool_(False)}  # NumPy scalars
        store.record_case(row, {"walk.json": b"{}"})
        assert store.finished_keys() == {case.key}
        assert store.finished_keys(retry_failed=True) == set()  # a timeout is the run's failure: retried
        assert store.finished_keys(retry_incomplete=True) == {case.key}  # not a stopped walk
        assert store.resolve_run("r") == "r1"
        with pytest.raises(StoreError, match="'x' is not a run of this store; runs: r1"):
            store.resolve_run("x")
    frame = gaitbench.load_results(tmp_path)
    assert list(frame.columns) == list(CASE_COLUMNS)
    row = frame.iloc[0]
    assert (row.case_key, row.status, row.N, row.provenance) == (case.key, "timeout", 8, {"hostname": "here"})
    assert (row.iterations, row.fell) == (7, 0)
    assert (tmp_path / "cases" / case.key / "walk.json").read_bytes() == b"{}"
    with pytest.raises(StoreError, match="no results store here"):
        gaitbench.load_results(tmp_path / "missing")


def _checkout_commit() -> str:
    root = Path(__file__).resolve().parents[1]
    return subprocess.run(["git", "-C", str(root), "rev-parse", "HEAD"], capture_output=True, text=True,
                          check=True).stdout.strip()


def test_local_pool_records_real_walks(local_store: Path) -> None:
    rows = rows_by_key(local_store)
    assert len(rows) == 2
    for row in rows.values():
        assert row["status"] == "solved", row["message"]
        assert row["acot"] == pytest.approx(row["cot_steps"][0]) and row["acot"] > 0
        assert row["max_defect"] < 1e-6
        assert row["provenance"]["packages"]["casadi"]
        assert row["provenance"]["git_commit"].split("+")[0] == _checkout_commit()  # which code computed it
        # which CPU: its kernels can change a long walk's path (docs/results.md, "Reproducing a result")
        assert row["provenance"]["cpu"] and row["provenance"]["cpu"] != "unknown"
        assert set(row["provenance"]["vector_extensions"]) <= set(VECTOR_EXTENSIONS)
        if platform.machine() == "x86_64":
            assert "SSE42" in row["provenance"]["vector_extensions"]
        walk = (local_store / row["walk_path"]).read_text()
        assert '"complete": true' in walk and (local_store / row["walk_path"]).with_suffix(".npz").exists()


def test_crashed_and_hung_workers_fail_only_their_case(tmp_path, faulty_plugins, monkeypatch) -> None:
    monkeypatch.setattr("gaitbench.run.executors.hard_limit", lambda case: 20.0)
    dirs = (str(faulty_plugins),)
    cases = [walk_case(8, "crash", dirs), walk_case(8, "hang", dirs), walk_case(8, plugin_dirs=dirs)]
    summary = run_suite(suite_of(cases), tmp_path, LocalPoolExecutor(2))
    rows = rows_by_key(tmp_path)
    assert (summary.solved, summary.failed) == (1, 2)
    assert rows[cases[0].key]["status"] == "crashed" and "SIGKILL" in rows[cases[0].key]["message"]
    assert rows[cases[1].key]["status"] == "timeout" and "worker was stopped" in rows[cases[1].key]["message"]
    assert rows[cases[2].key]["status"] == "solved"


def test_one_solve_gets_a_quarter_of_the_case_s_time_and_the_next_rung_the_rest(faulty_plugins) -> None:
    """Downward slope, OP-DM, N = 180 spent its whole hour in one rung of step 1's retries; the next rung then solved
    the step in 2.5 s, too late for the walk."""
    case = replace(walk_case(10, "spends-its-limit", (str(faulty_plugins),)), time_limit_s=4.0)
    assert (case.solve_time_limit_s, case.hard_limit_s) == (1.0, 35.0)
    outcome = run_case(case)
    assert outcome.status == "solved", outcome.message
    step, = json.loads(outcome.files["walk.json"])["steps"]
    assert step["details"]["first_attempt"]["status"] == "time_limit"
    assert step["details"]["first_attempt"]["solve_time_s"] == 1.0
    assert [retry["remedy"] for retry in step["details"]["retries"]] == ["ipopt"]


def test_a_local_worker_runs_decrease_and_conquer_s_sectional_pool(tmp_path: Path, monkeypatch) -> None:
    """``--jobs`` and the strategy's ``workers`` together: a case worker starts its own pool of sectional workers
    (two, or as many as the idle cores with "auto"), and the walk is the one solved sequentially in this process."""
    from gaitbench.cores import CORES_DIR_ENV

    monkeypatch.setenv(CORES_DIR_ENV, str(tmp_path / "cores"))  # the case worker's ledger: no other walk in it

    def case(workers: int | str) -> Case:
        return Case(PluginChoice("forward"), 8, PluginChoice("hermite-simpson"), PluginChoice("ipopt"),
                    PluginChoice("decrease-and-conquer", {"polish": False, "workers": workers}), steps=1,
                    method=f"DC workers={workers}", time_limit_s=60)

    run_suite(suite_of([case(2)]), tmp_path / "pool", LocalPoolExecutor(1))
    run_suite(suite_of([case("auto")]), tmp_path / "auto", LocalPoolExecutor(1))
    run_suite(suite_of([case(1)]), tmp_path / "here", InProcessExecutor())
    here, = rows_by_key(tmp_path / "here").values()
    for store in ("pool", "auto"):
        pooled, = rows_by_key(tmp_path / store).values()
        assert pooled["status"] == "solved", pooled["message"]
        assert pooled["claimed_acot"] == here["claimed_acot"]
        assert pooled["strategy_details"] == here["strategy_details"]


def test_bad_options_are_an_error_row_not_a_crash(tmp_path) -> None:
    good = walk_case(8)
    case = Case(good.experiment, 8, good.transcription, good.solver, PluginChoice("one-phase", {"bogus_option": 1}))
    run_suite(suite_of([case]), tmp_path, InProcessExecutor())
    row = rows_by_key(tmp_path)[case.key]
    assert row["status"] == "error" and "bogus_option" in row["message"]


def test_cases_reach_the_executor_largest_n_first_or_smallest_when_asked(tmp_path: Path) -> None:
    """The pool gets its longest cases first and fills the end of the run with the short ones; with
    ``smallest_first`` the reverse. Either way cases of equal N keep their suite order."""
    handed = []

    class Recording:
        name, jobs = "recording", 2

        def run(self, cases):
            for case in cases:
                handed.append(case.key)
                yield failed_outcome(case, "error", "not run")

    cases = [walk_case(8), walk_case(12), walk_case(8, tolerance=1e-6), walk_case(10)]
    run_suite(suite_of(cases), tmp_path, Recording())
    assert handed == [cases[1].key, cases[3].key, cases[0].key, cases[2].key]  # equal N: suite order
    assert len(rows_by_key(tmp_path)) == 4

    handed.clear()  # a sweep over several sessions fills its tables N by N instead
    run_suite(suite_of(cases), tmp_path / "smallest", Recording(), smallest_first=True)
    assert handed == [cases[0].key, cases[2].key, cases[3].key, cases[1].key]


def test_a_complete_walk_run_again_keeps_its_row_and_files_when_the_new_run_fails(tmp_path: Path) -> None:
    """--retry-unverified and --retry-inconsistent run complete walks again: one that then crashes must not replace
    the walk, and the next run's clean-up must not take its files for leftovers. A new complete walk replaces it."""
    case = walk_case(8)

    class Finishing:
        name, jobs = "finishing", 1

        def __init__(self, outcome):
            self.outcome = outcome

        def run(self, cases):
            for case in cases:
                yield self.outcome(case)

    solved = lambda case: CaseOutcome(case, "solved", "", 1.0, {"acot": 0.3, "verified": True},  # noqa: E731
                                      {"walk.json": b'{"first": 1}'})
    run_suite(suite_of([case]), tmp_path, Finishing(solved))
    shown = []
    crashed = Finishing(lambda case: failed_outcome(case, "crashed", "worker died (SIGKILL)"))
    run_suite(suite_of([case]), tmp_path, crashed, resume=True, rerun={case.key}, on_outcome=shown.append)
    assert shown[0].message.endswith("the complete walk stored before is kept")
    run_suite(suite_of([case]), tmp_path, crashed, resume=True)  # its start cleans leftovers
    row = rows_by_key(tmp_path)[case.key]
    assert (row["status"], row["acot"]) == ("solved", 0.3)
    assert (tmp_path / row["walk_path"]).read_bytes() == b'{"first": 1}'
    again = lambda case: CaseOutcome(case, "solved", "", 1.0, {"acot": 0.25, "verified": True},  # noqa: E731
                                     {"walk.json": b'{"second": 2}'})
    run_suite(suite_of([case]), tmp_path, Finishing(again), resume=True, rerun={case.key})
    row = rows_by_key(tmp_path)[case.key]
    assert row["acot"] == 0.25 and (tmp_path / row["walk_path"]).read_bytes() == b'{"second": 2}'


def test_runs_started_within_one_second_get_distinct_ids(tmp_path: Path, monkeypatch) -> None:
    import gaitbench.run.runner as runner

    class Frozen(runner.datetime):
        @classmethod
        def now(cls, tz=None):
            return runner.datetime(2026, 12, 1, 21, 0, 0, tzinfo=tz)

    monkeypatch.setattr(runner, "datetime", Frozen)
    ids = [run_suite(suite_of([]), tmp_path, InProcessExecutor(), resume=True).run_id for _ in range(3)]
    assert ids == ["20261201-210000-test", "20261201-210000-test-2", "20261201-210000-test-3"]


def test_refuses_to_mix_without_resume(local_store: Path) -> None:
    with pytest.raises(RunRefused, match="pass --resume"):
        run_suite(suite_of([walk_case(8)]), local_store, InProcessExecutor())


def test_resume_after_kill_loses_and_duplicates_nothing(tmp_path: Path) -> None:
    suite_file = tmp_path / "resume.toml"
    suite_file.write_text(textwrap.dedent("""
        [suite]
        name = "resume"
        steps = 1
        [sweep]
        experiments = ["forward"]
        N = [8, 9, 10, 11]
        transcriptions = ["hermite-simpson"]
        solvers = ["ipopt"]
        strategies = ["one-phase"]
    """))
    store = tmp_path / "store"
    command = [GAITBENCH, "run", str(suite_file), "--store", str(store), "--executor", "inprocess"]
    first = subprocess.Popen([*command, "--no-report"], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + 120
    while _stored(store) < 1 and time.monotonic() < deadline and first.poll() is None:
        time.sleep(0.2)
    first.send_signal(signal.SIGKILL)
    first.wait()
    before = rows_by_key(store)
    assert 1 <= len(before) < 4, "the kill should land mid-run"

    refused = subprocess.run([*command, "--no-report"], capture_output=True, text=True)
    assert refused.returncode == 1 and "--resume" in refused.stderr

    resumed = subprocess.run([*command, "--resume"], capture_output=True, text=True, cwd=tmp_path)
    assert resumed.returncode == 0, resumed.stderr
    assert (tmp_path / "reports" / "store" / "index.html").exists()  # the run ends with its report
    after = rows_by_key(store)
    assert len(after) == 4
    for key, row in before.items():  # completed cases were skipped, not redone
        assert (after[key]["run_id"], after[key]["finished_at"]) == (row["run_id"], row["finished_at"])
    with ResultStore.open(store) as opened:
        runs = opened.runs()
    assert [run["cases_skipped"] for run in runs] == [0, len(before)]  # the killed run, the resumed one


def test_a_suite_runs_one_method_at_a_time_and_resume_does_the_rest(tmp_path: Path) -> None:
    suite_file = tmp_path / "parts.toml"
    suite_file.write_text(textwrap.dedent("""
        [suite]
        name = "parts"
        steps = 1
        [sweep]
        experiments = ["forward"]
        N = [8, 9]
        [[method]]
        label = "OP-DC"
        transcription = "hermite-simpson"
        solver = "ipopt"
        strategy = "one-phase"
        [[method]]
        label = "OP-DM"
        transcription = "dmoc"
        solver = "ipopt"
        strategy = "one-phase"
    """))
    store = tmp_path / "store"
    command = ["run", str(suite_file), "--store", str(store), "--executor", "inprocess", "--no-report"]
    unknown = CliRunner().invoke(main, [*command, "--method", "OP-XX"])
    assert unknown.exit_code == 2 and "no method 'OP-XX'" in unknown.output and "OP-DC, OP-DM" in unknown.output
    part = CliRunner().invoke(main, [*command, "--method", "OP-DM"])
    assert part.exit_code == 0, part.output
    assert {row["method"] for row in rows_by_key(store).values()} == {"OP-DM"}
    rest = CliRunner().invoke(main, [*command, "--resume"])
    assert rest.exit_code == 0, rest.output
    assert sorted(row["method"] for row in rows_by_key(store).values()) == ["OP-DC", "OP-DC", "OP-DM", "OP-DM"]
    with ResultStore.open(store) as opened:
        assert [run["cases_skipped"] for run in opened.runs()] == [0, 2]


def _stored(store: Path) -> int:
    if not (store / DATABASE).exists():
        return 0
    try:
        with sqlite3.connect(store / DATABASE) as connection:
            return connection.execute("SELECT COUNT(*) FROM cases").fetchone()[0]
    except sqlite3.OperationalError:  # the table is not created yet
        return 0


def _written_json(path: Path) -> bool:
    try:
        json.loads(path.read_text())
        return True
    except (OSError, ValueError):
        return False


def test_dask_cluster_on_loopback_gives_the_local_rows(tmp_path: Path, local_store: Path) -> None:
    scheduler_file = tmp_path / "scheduler.json"
    dask = str(Path(sys.executable).with_name("dask"))
    env = {**os.environ, "OPENBLAS_NUM_THREADS": "1"}
    scheduler = subprocess.Popen([dask, "scheduler", "--host", "127.0.0.1", "--port", "0", "--no-dashboard",
                                  "--scheduler-file", str(scheduler_file)], env=env,
                                 stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    worker = None
    try:
        deadline = time.monotonic() + 60
        while not _written_json(scheduler_file) and time.monotonic() < deadline:  # it appears before it is whole
            time.sleep(0.2)
        address = json.loads(scheduler_file.read_text())["address"]
        assert address.startswith("tcp://127.0.0.1:")
        worker = subprocess.Popen([dask, "worker", address, "--nworkers", "1", "--nthreads", "1", "--no-dashboard"],
                                  env=env | {"DASK_DISTRIBUTED__WORKER__DAEMON": "False"},
                                  stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        store = tmp_path / "dask-store"
        summary = run_suite(suite_of([walk_case(8), walk_case(10)]), store, DaskExecutor(address))
        assert summary.solved == 2
    finally:
        for process in (worker, scheduler):
            if process is not None:
                process.terminate()
                process.wait(timeout=30)
    local, distributed = rows_by_key(local_store), rows_by_key(store)
    assert local.keys() == distributed.keys()
    for key in local:
        for column in COMPARED:
            assert distributed[key][column] == local[key][column], column


def test_a_cluster_of_daemonic_workers_is_refused_with_the_fix(tmp_path: Path) -> None:
    """Dask's default workers may not start the process a case runs in: say so before any case is claimed."""
    from distributed import LocalCluster

    with LocalCluster(n_workers=1, threads_per_worker=1, processes=True, dashboard_address=None) as cluster:
        with pytest.raises(ExecutorError, match="DASK_DISTRIBUTED__WORKER__DAEMON=False"):
            run_suite(suite_of([walk_case(8)]), tmp_path / "store", DaskExecutor(cluster.scheduler_address))
    assert _stored(tmp_path / "store") == 0


def test_a_lost_dask_scheduler_is_one_line_saying_how_to_go_on(tmp_path: Path, monkeypatch) -> None:
    """distributed raises OSError subclasses when it cannot reach its scheduler or loses it (CommClosedError, connect
    timeouts): the user gets the scheduler, the cause and --resume, not a traceback."""
    import distributed

    class Unreachable:
        def __init__(self, *args, **kwargs):
            raise OSError("Timed out trying to connect to tcp://10.0.0.9:8786 after 30 s")

    monkeypatch.setattr(distributed, "Client", Unreachable)
    with pytest.raises(ExecutorError, match=r"lost the Dask scheduler at tcp://10.0.0.9:8786 \(OSError: Timed out.*"
                                            r"run again with --resume"):
        run_suite(suite_of([walk_case(8)]), tmp_path / "store", DaskExecutor("tcp://10.0.0.9:8786"))


@pytest.fixture
def dask_task_pool():
    """The Dask tasks' case pools, closed after the test (a Dask worker keeps them for its life)."""
    yield
    while executors._IDLE_CASE_POOLS:
        executors._IDLE_CASE_POOLS.pop().close()


def _environment(item: object, state: object) -> dict[str, str]:
    return dict(os.environ)


def test_a_dask_task_s_process_lacks_the_nanny_s_malloc_trimming(dask_task_pool, monkeypatch) -> None:
    """Dask's nanny sets MALLOC_TRIM_THRESHOLD_ for its workers; the process running their cases must not inherit
    it (it slowed the walks by up to 30 %), must keep the thread limits, and must serve the next case too."""
    monkeypatch.setenv("MALLOC_TRIM_THRESHOLD_", "65536")
    monkeypatch.setenv("OPENBLAS_NUM_THREADS", "1")
    assert executors.run_case_pooled(walk_case(8)).status == "solved"
    pool, = executors._IDLE_CASE_POOLS
    environment = pool.schedule(_environment, None).result()
    assert "MALLOC_TRIM_THRESHOLD_" not in environment and environment["OPENBLAS_NUM_THREADS"] == "1"
    assert executors.run_case_pooled(walk_case(10)).status == "solved"


def test_a_dask_task_s_process_is_replaced_after_a_crash_or_a_hang(dask_task_pool, faulty_plugins,
                                                                    monkeypatch) -> None:
    monkeypatch.setattr("gaitbench.run.executors.hard_limit", lambda case: 15.0)
    dirs = (str(faulty_plugins),)
    crashed = executors.run_case_pooled(walk_case(8, "crash", dirs))
    assert crashed.status == "crashed" and "SIGKILL" in crashed.message
    hung = executors.run_case_pooled(walk_case(8, "hang", dirs))
    assert hung.status == "timeout" and "worker was stopped" in hung.message
    assert executors.run_case_pooled(walk_case(8, plugin_dirs=dirs)).status == "solved"


def test_runs_commands_list_show_and_export(local_store: Path, tmp_path: Path) -> None:
    listed = subprocess.run([GAITBENCH, "runs", "list", str(local_store)], capture_output=True, text=True)
    assert listed.returncode == 0 and "test" in listed.stdout
    shown = subprocess.run([GAITBENCH, "runs", "show", str(local_store)], capture_output=True, text=True,
                           env={**os.environ, "COLUMNS": "200"})
    assert shown.returncode == 0 and "solved" in shown.stdout and "forward" in shown.stdout
    for fmt in ("csv", "parquet"):
        out = tmp_path / f"cases.{fmt}"
        exported = subprocess.run([GAITBENCH, "runs", "export", str(local_store), "--format", fmt, "--out", str(out)],
                                  capture_output=True, text=True)
        assert exported.returncode == 0, exported.stderr
        import pandas as pd

        frame = pd.read_csv(out) if fmt == "csv" else pd.read_parquet(out)
        assert len(frame) == 2 and set(frame.case_key) == set(rows_by_key(local_store))
    missing = subprocess.run([GAITBENCH, "runs", "show", str(tmp_path / "nowhere")], capture_output=True, text=True)
    assert missing.returncode == 1 and "no results store here" in missing.stderr


def test_every_store_column_is_documented() -> None:
    documented = (Path(__file__).parent.parent / "docs" / "results.md").read_text()
    missing = [column for column in CASE_COLUMNS if f"`{column}`" not in documented]
    assert not missing, f"docs/results.md does not describe: {', '.join(missing)}"


def test_tracking_stage_fills_the_tracking_columns(tmp_path: Path) -> None:
    from gaitbench.run.case import TrackingStage

    tracked = Case(PluginChoice("forward"), 10, PluginChoice("hermite-simpson"), PluginChoice("ipopt"),
                   PluginChoice("one-phase"), steps=2, tracking=TrackingStage("thesis", "thesis", "friction"))
    summary = run_suite(suite_of([tracked]), tmp_path, InProcessExecutor())
    row = rows_by_key(tmp_path)[tracked.key]
    assert summary.solved == 1, row["message"]
    assert 0 < row["max_position_error"] < 1e-2 and row["fell"] == 0
    assert row["acot_increase_percent"] > 5  # friction costs energy on top of the reference (measured: +65 %)
    assert (tmp_path / row["tracking_path"]).exists() and (tmp_path / row["tracking_path"]).with_suffix(".npz").exists()


# --- why a walk stopped ------------------------------------------------------------------------------------------

def test_stop_columns_record_geometry_solver_and_complete_walks(tmp_path: Path) -> None:
    """Real walks: one stopped by its geometry before any solve, one by the solver's iteration limit, one complete;
    and a timeout the run recorded without a walk."""
    geometry = Case(PluginChoice("downward-slope"), 8, PluginChoice("hermite-simpson"), PluginChoice("ipopt"),
                    PluginChoice("one-phase"), steps=2, method="geometry",
                    problem_options={"angle_bounds": "thesis"})  # the printed bounds refuse step 1
    solver = walk_case(8, max_iterations=5)
    complete = walk_case(8)
    lost = walk_case(10)

    class WithTimeout(InProcessExecutor):
        def run(self, cases):
            for case in cases:
                yield failed_outcome(case, "timeout", "stopped") if case.key == lost.key else run_case(case)

    run_suite(suite_of([geometry, solver, complete, lost]), tmp_path, WithTimeout())
    rows = rows_by_key(tmp_path)
    columns = ("status", "stop_cause", "stop_step", "stop_status", "retries")
    assert tuple(rows[geometry.key][c] for c in columns) == ("incomplete", "geometry", 1, "infeasible_geometry", 0)
    # The ladder's three rungs (adaptive μ, First-Phase seed, both) fail within 5 iterations too, and so does the
    # coarse-grid rescue's one grid (6 nodes; 4 is below its least).
    assert tuple(rows[solver.key][c] for c in columns) == ("incomplete", "solver", 1, "iteration_limit", 4)
    got = rows[complete.key]
    assert (got["status"], got["stop_cause"], got["retries"]) == ("solved", "complete", 0)
    assert got["stop_step"] is None or np.isnan(got["stop_step"])
    assert (rows[lost.key]["status"], rows[lost.key]["stop_cause"]) == ("timeout", "time_limit")


def _step(index: int, status: str, solved: bool, retries: list | None = None):
    from gaitbench.acceptance import StepVerification
    from gaitbench.walk_types import StepOutcome

    check = StepVerification(1e-12, 1e-6, 1e-6, 1.0, 0.1, 0.02) if solved else None
    return StepOutcome(index, 1, status, status, verification=check,
                       next_state=np.zeros(4) if solved else None,
                       details={"retries": retries} if retries is not None else {})


@pytest.mark.parametrize(("status", "cause"), [("infeasible", "solver"), ("iteration_limit", "solver"),
                                               ("error", "solver"), ("time_limit", "time_limit"),
                                               ("converged", "verification"), ("infeasible_geometry", "geometry")])
def test_stop_cause_of_the_failing_step_and_retries_summed_over_the_walk(status: str, cause: str) -> None:
    from gaitbench.run.runner import walk_metrics
    from gaitbench.walk_types import WalkResult

    retry = {"remedy": "adaptive-mu", "status": "infeasible"}
    walk = WalkResult("forward", "hermite-simpson", "ipopt", "one-phase", 8, "second", requested_steps=3,
                      steps=[_step(1, "converged", True, [retry]), _step(2, status, False, [retry, retry])])
    metrics = walk_metrics(walk)
    assert (metrics["stop_cause"], metrics["stop_step"], metrics["stop_status"]) == (cause, 2, status)
    assert metrics["retries"] == 3
    whole = WalkResult("forward", "hermite-simpson", "ipopt", "one-phase", 8, "second", requested_steps=1,
                       steps=[_step(1, "converged", True)])
    assert {k: walk_metrics(whole)[k] for k in ("stop_cause", "stop_step", "stop_status", "retries")} == {
        "stop_cause": "complete", "stop_step": None, "stop_status": None, "retries": 0}


def test_a_store_written_before_the_stop_columns_opens_and_gains_them(tmp_path: Path) -> None:
    new = ("stop_cause", "stop_step", "stop_status", "retries")
    old_columns = {c: t for c, t in CASE_COLUMNS.items() if c not in new}
    with sqlite3.connect(tmp_path / DATABASE) as db:
        db.execute(f"CREATE TABLE cases ({', '.join(f'{c} {t}' for c, t in old_columns.items())})")
        db.execute("CREATE TABLE runs (run_id TEXT PRIMARY KEY, suite TEXT, suite_path TEXT, suite_text TEXT, "
                   "executor TEXT, jobs INTEGER, cases_total INTEGER, cases_skipped INTEGER, started_at TEXT, "
                   "finished_at TEXT, provenance TEXT)")  # as the first stores had it (schema version 1)
        db.execute("INSERT INTO cases (case_key, experiment, status, acot) VALUES ('old', 'forward', 'solved', 0.03)")
    frame = gaitbench.load_results(tmp_path)  # reading opens it
    assert list(frame.columns) == list(CASE_COLUMNS)
    assert frame.iloc[0]["acot"] == 0.03 and frame.iloc[0]["stop_cause"] is None
    with sqlite3.connect(tmp_path / DATABASE) as db:
        present = {row[1] for row in db.execute("PRAGMA table_info(cases)")}
        runs = {row[1] for row in db.execute("PRAGMA table_info(runs)")}
    assert set(new) <= present and {"provenance", "heartbeat_at"} <= runs
    with ResultStore.create(tmp_path) as store:  # and a resumed run writes the new columns into it
        store.record_case(case_row(CaseOutcome(walk_case(8), "crashed", "SIGKILL", 1.0), "s", "r"))
        rows = {row["case_key"]: row for row in store.cases()}
    assert rows[walk_case(8).key]["stop_cause"] == "crashed" and rows["old"]["stop_cause"] is None


TINY_SUITE = """
[suite]
name = "tiny"
steps = 1
plugins = ["plugins"]

[sweep]
experiments = ["{experiment}"]
N = [6]
transcriptions = ["dmoc"]
solvers = ["ipopt"]
strategies = ["one-phase"]
"""


def test_run_reports_plugins_that_failed_to_load_and_records_them(tmp_path: Path) -> None:
    """`gaitbench run` says which plugin failed and why, as `gaitbench plugins` does, and the run records it."""
    plugins = tmp_path / "plugins"
    plugins.mkdir()
    broken = plugins / "gentle_slope.py"
    broken.write_text("raise ImportError('half-finished plugin')\n")
    suite = tmp_path / "tiny.toml"
    store = tmp_path / "store"
    arguments = ["run", str(suite), "--executor", "inprocess", "--no-report", "--store", str(store)]

    suite.write_text(TINY_SUITE.format(experiment="gentle-slope"))
    missing = CliRunner().invoke(main, arguments)
    assert missing.exit_code == 2
    error = " ".join(missing.stderr.split())
    assert "unknown experiment 'gentle-slope'" in error
    assert f"1 plugin failed to load and may have registered it: {broken.resolve()}: import failed: ImportError: " \
           "half-finished plugin" in error

    suite.write_text(TINY_SUITE.format(experiment="forward"))
    result = CliRunner().invoke(main, arguments)
    assert result.exit_code == 0, result.output
    assert result.stderr.startswith(f"warning: {broken.resolve()}: import failed: ImportError: half-finished plugin")
    with ResultStore.open(store) as opened:
        (run,) = opened.runs()
    assert run["provenance"]["plugin_problems"] == [
        {"source": str(broken.resolve()), "message": "import failed: ImportError: half-finished plugin"}]


def test_a_plugin_value_the_store_cannot_hold_costs_its_case_not_the_store(tmp_path: Path) -> None:
    """A strategy's figure of the wrong type (a word for the ACOT, a list for its details) would make every later
    opening of the store refuse it; it is refused before it is written and the case is an error row that says why."""
    bad, good = walk_case(8), walk_case(10)

    class Odd:
        name, jobs = "odd", 1

        def run(self, cases):
            for case in cases:
                metrics = {"acot": "n/a"} if case.key == bad.key else {"acot": 0.3}
                yield CaseOutcome(case, "solved", "", 1.0, metrics, {"walk.json": b"{}"})

    run_suite(suite_of([bad, good]), tmp_path, Odd())
    rows = rows_by_key(tmp_path)  # the store opens
    assert rows[good.key]["status"] == "solved"
    assert rows[bad.key]["status"] == "error"
    assert "its result cannot be stored" in rows[bad.key]["message"] and "column acot" in rows[bad.key]["message"]
    assert not isinstance(rows[bad.key]["walk_path"], str)  # no file of a walk whose row was refused


def test_a_method_renamed_in_the_suite_renames_its_stored_cases_on_resume(tmp_path: Path) -> None:
    """The label is not part of a case's key, so a resumed run skips the case; its row takes the new label, or the
    reports would show the method's N under two names."""
    case = walk_case(8)

    class Solving:
        name, jobs = "solving", 1

        def run(self, cases):
            for case in cases:
                yield CaseOutcome(case, "solved", "", 1.0, {"acot": 0.3}, {"walk.json": b"{}"})

    run_suite(suite_of([case]), tmp_path, Solving())
    renamed = replace(case, method="OP-DC renamed")
    assert renamed.key == case.key
    run_suite(suite_of([renamed]), tmp_path, Solving(), resume=True)
    assert rows_by_key(tmp_path)[case.key]["method"] == "OP-DC renamed"
