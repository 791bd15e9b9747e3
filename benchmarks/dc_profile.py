"""Where a decrease-and-conquer walk's time goes: every sectional solve timed, with its status and iterations.

Run:    OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/dc_profile.py EXPERIMENT TRANSCRIPTION N STEPS
        .venv/bin/python benchmarks/dc_profile.py --summarize benchmarks/results/dc_profile/*.json
Writes benchmarks/results/dc_profile/<experiment>-<transcription>-<N>-<steps>.json: one record per sectional solve
(k0, status, iterations, wall seconds), the wall time of every First Phase, complete and polish solve (``parts``),
and the walk's time when each step ended. ``--summarize`` prints the table of docs/performance.md ("Where D&C's
time goes at large N"). The sections are timed by wrapping ``SectionalSolves.solve_one``, so the walk is the one the
strategy solves on its own, with IPOPT at its defaults.
"""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path

import numpy as np

from gaitbench.contracts import WalkProblem
from gaitbench.plugins import load_registry
from gaitbench.problem.gait_problem import ProblemOptions

OUT = Path(__file__).parent / "results" / "dc_profile"


def ipopt_walk(experiment_name: str, transcription: str, n_nodes: int, steps: int) -> WalkProblem:
    """The walk a thesis suite's IPOPT method solves: the experiment's limits, the default problem options and the
    net-power objective (shared by the D&C benchmarks beside this one)."""
    registry = load_registry()
    experiment = registry.create("experiment", experiment_name)
    return WalkProblem(experiment, registry.create("transcription", transcription), registry.create("solver", "ipopt"),
                       n_nodes, steps=steps, options=ProblemOptions(limits=experiment.limits),
                       objective=registry.create("objective", "net-power"))


def profile(experiment_name: str, transcription: str, n_nodes: int, steps: int) -> dict:
    import gaitbench_plugins.strategies.decrease_and_conquer as dc

    registry = load_registry()
    problem = ipopt_walk(experiment_name, transcription, n_nodes, steps)
    record: dict = {"experiment": experiment_name, "transcription": transcription, "N": n_nodes, "steps": steps,
                    "sections": [], "parts": [], "steps_done_s": []}
    solve_one, solve_with_retries = dc.SectionalSolves.solve_one, dc.solve_with_retries

    def timed_section(sections, task):
        started = time.perf_counter()
        result = solve_one(sections, task)
        record["sections"].append({"k0": task[0], "status": result.status.value, "iterations": result.iterations,
                                   "wall_s": time.perf_counter() - started})
        return result

    def timed_solve(*args, **kwargs):
        started = time.perf_counter()
        outcome = solve_with_retries(*args, **kwargs)
        record["parts"].append({"phase": kwargs.get("phase", "second"), "wall_s": time.perf_counter() - started})
        return outcome

    dc.SectionalSolves.solve_one, dc.solve_with_retries = timed_section, timed_solve
    started = time.perf_counter()
    try:
        walk = registry.create("strategy", "decrease-and-conquer").solve(
            problem, on_step=lambda step: record["steps_done_s"].append(time.perf_counter() - started))
    finally:
        dc.SectionalSolves.solve_one, dc.solve_with_retries = solve_one, solve_with_retries
    record |= {"wall_s": time.perf_counter() - started, "complete": walk.complete,
               "verified_acot": (walk.strategy_details or {}).get("verified_acot")}
    return record


def summary_row(record: dict) -> str:
    sections = record["sections"]
    converged = [s["iterations"] for s in sections if s["status"] == "converged"]
    failed = [s["iterations"] for s in sections if s["status"] != "converged"]
    section_s = sum(s["wall_s"] for s in sections)
    failed_text = f"{len(failed)}, {np.mean(failed):.0f}" if failed else "0"
    return (f"| {record['experiment']} {record['transcription']}, N = {record['N']}, steps 1–{record['steps']} | "
            f"{record['wall_s']:,.0f} s | {section_s:,.0f} s ({section_s / record['wall_s']:.0%}) | "
            f"{len(converged)}, {np.mean(converged):.0f} ({np.median(converged):.0f}) | {failed_text} |")


def main(argv: list[str]) -> None:
    if argv[:1] == ["--summarize"]:
        print("| walk | wall | sectional solves | converged sections: count, mean (median) iterations "
              "| failed sections: count, mean iterations |\n|---|---|---|---|---|")
        for path in argv[1:]:
            print(summary_row(json.loads(Path(path).read_text())))
        return
    experiment, transcription, n_nodes, steps = argv[0], argv[1], int(argv[2]), int(argv[3])
    record = profile(experiment, transcription, n_nodes, steps)
    OUT.mkdir(parents=True, exist_ok=True)
    path = OUT / f"{experiment}-{transcription}-{n_nodes}-{steps}.json"
    path.write_text(json.dumps(record, indent=1))
    print(summary_row(record))
    print(f"wrote {path}")


if __name__ == "__main__":
    main(sys.argv[1:])
