"""The Dask executor when a worker dies: its case runs again on another worker, and the worker the nanny starts in
its place can run cases (it is not daemonic)."""

from __future__ import annotations

import os
import signal
import threading
import time
from pathlib import Path
from types import SimpleNamespace

import psutil
import pytest

import gaitbench
from gaitbench.run.case import Case, PluginChoice
from gaitbench.run.executors import DaskExecutor, InProcessExecutor
from gaitbench.run.runner import run_suite

SLOW_PLUGIN = '''
import time
from gaitbench import Registration, hookimpl


class Slow:
    """IPOPT after a pause: a case long enough for its worker to be killed while it runs."""
    name = "slow-ipopt"

    def __init__(self, pause_s=3.0, log=None, pids=None, **options):
        from gaitbench_plugins.solvers.ipopt import Ipopt
        self.pause_s, self.log, self.pids, self.ipopt = pause_s, log, pids, Ipopt(**options)

    def solve(self, nlp, parameters, initial_guess):
        import os
        if self.log:  # the Dask worker whose case process this is
            with open(self.log, "a") as file:
                file.write(f"{os.getppid()} ")
        if self.pids:  # the process that solves, and its parent
            with open(self.pids, "a") as file:
                file.write(f"{os.getppid()}:{os.getpid()} ")
        time.sleep(self.pause_s)
        return self.ipopt.solve(nlp, parameters, initial_guess)


class KillsItsWorker:
    """Kills the Dask worker that runs its case's process, as a worker lost to the out-of-memory killer."""
    name = "kills-its-worker"

    def __init__(self, **options):
        pass

    def solve(self, nlp, parameters, initial_guess):
        import os, signal
        os.kill(os.getppid(), signal.SIGKILL)
        time.sleep(60)


@hookimpl
def register_solvers():
    return [Registration("slow-ipopt", "IPOPT after a pause", Slow),
            Registration("kills-its-worker", "kills its Dask worker", KillsItsWorker)]
'''


def slow_case(n_nodes: int, plugin_dir: Path, solver: str = "slow-ipopt", **options) -> Case:
    return Case(PluginChoice("forward"), n_nodes, PluginChoice("hermite-simpson"), PluginChoice(solver, options),
                PluginChoice("one-phase"), steps=1, method="OP-DC slow", time_limit_s=120,
                plugin_dirs=(str(plugin_dir),))


def dc_case(plugin_dir: Path, **options) -> Case:
    return Case(PluginChoice("forward"), 8, PluginChoice("hermite-simpson"), PluginChoice("slow-ipopt", options),
                PluginChoice("decrease-and-conquer", {"polish": False}), steps=1, method="DC", time_limit_s=120,
                plugin_dirs=(str(plugin_dir),))


def _suite(tmp_path: Path, cases: list[Case]) -> SimpleNamespace:
    return SimpleNamespace(name="dask-kill", path=Path("dask-kill.toml"), text="# test", cases=cases)


def _plugin_dir(tmp_path: Path) -> Path:
    (tmp_path / "plugins").mkdir()
    (tmp_path / "plugins" / "slow.py").write_text(SLOW_PLUGIN)
    return tmp_path / "plugins"


def _dask_workers() -> list[psutil.Process]:
    """The worker processes of this process's local cluster: its children started by spawn (the nannies run here)."""
    workers = []
    for child in psutil.Process().children():
        try:
            if "spawn_main" in " ".join(child.cmdline()):
                workers.append(child)
        except psutil.NoSuchProcess:
            continue
    return workers


def test_a_killed_local_worker_s_case_is_solved_on_another_and_its_replacement_runs_cases(tmp_path: Path) -> None:
    """kill -9 of a worker of the local cluster mid-case: every case is solved, none recorded as an error (the
    replacement the nanny starts is not daemonic, and runs cases), and the dead worker's case process is gone."""
    plugins, log = _plugin_dir(tmp_path), tmp_path / "workers.log"
    cases = [slow_case(n, plugins, log=str(log)) for n in (8, 9, 10, 11)]
    suite = _suite(tmp_path, cases)
    killed: list[int] = []
    first: set[int] = set()
    orphans: list[int] = []

    def kill_one_worker() -> None:
        deadline = time.monotonic() + 90
        while time.monotonic() < deadline:
            started = log.read_text().split() if log.exists() else []
            if started:  # a case is in its pause, in a process of this worker
                worker = psutil.Process(int(started[0]))
                first.update(process.pid for process in _dask_workers())
                orphans.extend(child.pid for child in worker.children(recursive=True))
                os.kill(worker.pid, signal.SIGKILL)
                killed.append(worker.pid)
                return
            time.sleep(0.1)

    killer = threading.Thread(target=kill_one_worker, daemon=True)
    killer.start()
    summary = run_suite(suite, tmp_path / "store", DaskExecutor(jobs=2))
    killer.join()

    assert killed, "no worker was found running a case"
    rows = gaitbench.load_results(tmp_path / "store").to_dict("records")
    assert {row["status"]: row["message"] for row in rows if row["status"] != "solved"} == {}
    assert summary.solved == len(cases) == len(rows) and summary.failed == 0
    ran_on = [int(pid) for pid in log.read_text().split()]
    assert len(ran_on) == len(cases) + 1  # the killed case's solve started twice
    assert set(ran_on) - first, "the replacement worker ran no case"
    assert not [pid for pid in orphans if psutil.pid_exists(pid)
                and psutil.Process(pid).status() != psutil.STATUS_ZOMBIE]


@pytest.mark.slow
def test_a_case_whose_workers_keep_dying_is_crashed_with_the_cause_worker_died(tmp_path: Path) -> None:
    """A case that kills every worker it runs on is tried on allowed-failures + 1 workers, then recorded as
    ``crashed``, "worker died"; the other case of the run is solved."""
    import dask

    plugins = _plugin_dir(tmp_path)
    deadly, fine = slow_case(8, plugins, "kills-its-worker"), slow_case(10, plugins)
    with dask.config.set({"distributed.scheduler.allowed-failures": 1}):  # read by the local scheduler
        summary = run_suite(_suite(tmp_path, [deadly, fine]), tmp_path / "store", DaskExecutor(jobs=2))

    rows = {row["case_key"]: row for row in gaitbench.load_results(tmp_path / "store").to_dict("records")}
    assert rows[fine.key]["status"] == "solved" and summary.solved == 1 and summary.failed == 1
    assert rows[deadly.key]["status"] == "crashed" and rows[deadly.key]["stop_cause"] == "crashed"
    assert rows[deadly.key]["message"].startswith("worker died: the 2 Dask workers that ran this case each died")


@pytest.mark.slow
def test_a_case_s_sections_fan_out_over_the_cluster_s_workers_with_the_walk_solved_here(tmp_path: Path) -> None:
    """On Dask, decrease and conquer's sectional solves are tasks on every worker of the cluster, not solves in its
    case's process, and the walk is the one solved in this process (same choices, candidate COTs, ACOTs)."""
    plugins, pids = _plugin_dir(tmp_path), tmp_path / "solves.pids"
    here = run_suite(_suite(tmp_path, [dc_case(plugins, pause_s=0.0)]), tmp_path / "here", InProcessExecutor())
    fanned = run_suite(_suite(tmp_path, [dc_case(plugins, pause_s=0.0, pids=str(pids))]), tmp_path / "dask",
                       DaskExecutor(jobs=2))
    assert here.solved == fanned.solved == 1

    local, = gaitbench.load_results(tmp_path / "here").to_dict("records")
    dask, = gaitbench.load_results(tmp_path / "dask").to_dict("records")
    for column in ("status", "acot", "claimed_acot", "cot_steps", "iterations", "strategy_details"):
        assert dask[column] == local[column], column
    solves = [tuple(int(pid) for pid in entry.split(":")) for entry in pids.read_text().split()]
    (dask_worker, case_process), *_ = solves  # the First Phase is solved in the case's process
    sections = [solve for solve in solves if solve[1] != case_process]
    assert len(solves) == 2 + len(sections) and len(sections) == 8 - 3  # First Phase, complete here; N − 3 there
    parents = {parent for parent, _ in sections}
    assert len(parents) == 2 and dask_worker in parents  # both workers' section processes, not the case's
