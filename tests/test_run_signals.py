"""`gaitbench run` stopped by SIGTERM (a batch system's stop, `kill`): it unwinds as Ctrl-C does."""

from __future__ import annotations

import os
import signal
import sqlite3
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import psutil

from gaitbench.run.store import DATABASE

GAITBENCH = str(Path(sys.executable).with_name("gaitbench"))

SLEEPY_PLUGIN = '''
import time
from gaitbench import Registration, hookimpl


class Sleepy:
    """A solve that takes a minute: the run is stopped while its cases are running."""
    name = "sleepy"

    def __init__(self, **options):
        pass

    def solve(self, nlp, parameters, initial_guess):
        time.sleep(60)


@hookimpl
def register_solvers():
    return [Registration("sleepy", "sleeps through its solve", Sleepy)]
'''


def test_sigterm_stops_a_local_pool_run_with_one_line_and_no_leaked_semaphore(tmp_path: Path) -> None:
    (tmp_path / "plugins").mkdir()
    (tmp_path / "plugins" / "sleepy.py").write_text(SLEEPY_PLUGIN)
    suite = tmp_path / "sleepy.toml"
    suite.write_text(textwrap.dedent("""
        [suite]
        name = "sleepy"
        steps = 1
        time_limit_s = 300
        plugins = ["plugins"]
        [sweep]
        experiments = ["forward"]
        N = [6, 7, 8]
        transcriptions = ["hermite-simpson"]
        solvers = ["sleepy"]
        strategies = ["one-phase"]
        """))
    command = [GAITBENCH, "run", str(suite), "--store", str(tmp_path / "store"), "--jobs", "2", "--no-report"]
    process = subprocess.Popen(command, stderr=subprocess.PIPE, stdout=subprocess.DEVNULL, text=True,
                               env={**os.environ, "OPENBLAS_NUM_THREADS": "1", "COLUMNS": "200"})
    lines = []
    for line in process.stderr:
        lines.append(line)
        if "cases to run" in line:
            break
    deadline = time.monotonic() + 60
    workers: list[psutil.Process] = []
    while len(workers) < 2 and time.monotonic() < deadline:  # both workers started on their cases
        workers = [child for child in psutil.Process(process.pid).children() if "spawn_main" in " ".join(
            child.cmdline())]
        time.sleep(0.5)
    time.sleep(3)
    process.send_signal(signal.SIGTERM)
    stderr = "".join(lines) + process.stderr.read()
    assert process.wait(timeout=60) == 128 + signal.SIGTERM, stderr
    assert "leaked semaphore" not in stderr and "Traceback" not in stderr, stderr
    assert "stopped by SIGTERM; the finished cases are in" in stderr
    assert len(workers) == 2 and not [worker for worker in workers if worker.is_running()
                                      and worker.status() != psutil.STATUS_ZOMBIE]
    with sqlite3.connect(tmp_path / "store" / DATABASE) as connection:  # the run closed: its claims released
        assert connection.execute("SELECT COUNT(*) FROM claims").fetchone() == (0,)
        assert connection.execute("SELECT finished_at FROM runs").fetchall() == [(None,)]  # stopped, not finished
