"""`gaitbench run`'s progress display: the walks in flight are the cases still running."""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np
from rich.console import Console

from gaitbench.checkpoint import WalkCheckpoint
from gaitbench.cli.run_progress import CaseProgress, StepsInFlight
from gaitbench.run.case import Case, PluginChoice
from gaitbench.run.runner import failed_outcome
from gaitbench.walk_types import StepOutcome


def _case(n_nodes: int) -> Case:
    return Case(PluginChoice("forward"), n_nodes, PluginChoice("hermite-simpson"), PluginChoice("ipopt"),
                PluginChoice("one-phase"), steps=3, method="OP-DC")


def test_a_failed_case_leaves_the_walks_in_flight_though_its_checkpoint_stays(tmp_path: Path) -> None:
    failing, running = _case(8), _case(10)
    step = StepOutcome(1, 1, "converged", "", next_state=np.zeros(4))
    for case in (failing, running):
        WalkCheckpoint(tmp_path / "checkpoints" / case.key, {"case": case.key}).save([step], set(), 5.0, of=3)
    in_flight = StepsInFlight(tmp_path, [failing, running])
    console = Console(file=io.StringIO(), force_terminal=True, width=200)
    with CaseProgress(console, in_flight) as progress:
        progress.start(2, 0)
        assert str(in_flight.render(None)) == "in flight: 1 of 3 steps (forward N=8 OP-DC), 1 of 3 steps " \
                                              "(forward N=10 OP-DC)"
        progress.advance(failed_outcome(failing, "crashed", "worker process killed by SIGKILL"))
        assert (tmp_path / "checkpoints" / f"{failing.key}.json").exists()  # kept for --resume
        assert str(in_flight.render(None)) == "in flight: 1 of 3 steps (forward N=10 OP-DC)"
        assert in_flight.new_steps({}) == ["step 1 of 3 saved (forward N=10 OP-DC), 5 s"]
