"""Every solver plugin on the same one-step gait problems: status, time, iterations and final COT.

Run: .venv/bin/python benchmarks/solvers.py [--time-limit S] [--solvers a,b] [--nodes 25,50,100]
(writes benchmarks/results/solvers.json and .md). The problem is the upward-slope experiment's first step, Second
Phase (4-DOF), with the thesis's cost and default options, from the transcription's standard initial guess, for
``hermite-simpson`` and ``dmoc`` at N = 25, 50, 100. Each solve has the same time limit and iteration limit; times
are wall-clock seconds of the solve call (including each solver's own build). Each solve runs in a child process
that is stopped at 1.5 × the time limit + 60 s, for solvers that cannot be interrupted (``killed`` rows). Rows
are appended to ``solvers.jsonl`` as they finish, and a rerun skips what is there.
"""

from __future__ import annotations

import argparse
import json
import multiprocessing
import time
from concurrent.futures import TimeoutError as FutureTimeout
from pathlib import Path

from pebble import ProcessPool

from gaitbench.plugins import load_registry
from gaitbench.problem.gait_problem import ProblemOptions, StepData, StepStructure
from gaitbench.run.provenance import provenance

EXPERIMENT = "upward-slope"
TRANSCRIPTIONS = ("hermite-simpson", "dmoc")
NODES = (25, 50, 100)
OUT = Path(__file__).parent / "results"


def solve_one(solver_name: str, transcription_name: str, n_nodes: int, time_limit_s: float,
              max_iterations: int) -> dict:
    """Build the step's NLP and solve it once; runs in a child process so a solver that ignores its limit can
    be stopped."""
    registry = load_registry()
    experiment = registry.create("experiment", EXPERIMENT)
    geometry = experiment.terrain.steps[0]
    transcription = registry.create("transcription", transcription_name)
    built = transcription.build(StepStructure("second", n_nodes, ProblemOptions(limits=experiment.limits)))
    data = StepData(experiment.robot, experiment.stance_leg(1), experiment.initial_state[[0, 1, 4, 5]],
                    geometry.D, geometry.theta, experiment.time_step(n_nodes))
    solver = registry.create("solver", solver_name, time_limit_s=time_limit_s, max_iterations=max_iterations)
    started = time.perf_counter()
    result = solver.solve(built.nlp, data.parameter_vector(), built.initial_guess(data))
    return {"solver": solver_name, "transcription": transcription_name, "N": n_nodes,
            "variables": built.nlp.n_variables, "status": result.status.value, "message": result.message,
            "call_s": time.perf_counter() - started, "wall_time_s": result.wall_time_s,
            "function_time_s": result.function_time_s, "iterations": result.iterations, "cot": result.objective,
            "violation": result.constraint_violation}


def run(solver_names, nodes, time_limit_s, max_iterations, log: Path) -> list[dict]:
    """Every (transcription, N, solver) not yet in ``log`` (JSON lines, appended as each finishes), then all."""
    done = [json.loads(line) for line in log.read_text().splitlines()] if log.exists() else []
    seen = {(row["solver"], row["transcription"], row["N"]) for row in done}
    hard_limit = 1.5 * time_limit_s + 60  # the solve's own limit, plus the build and a margin
    for transcription in TRANSCRIPTIONS:
        for n_nodes in nodes:
            for solver_name in solver_names:
                if (solver_name, transcription, n_nodes) in seen:
                    continue
                with ProcessPool(max_workers=1, context=multiprocessing.get_context("spawn")) as pool:
                    future = pool.schedule(solve_one, (solver_name, transcription, n_nodes, time_limit_s,
                                                       max_iterations), timeout=hard_limit)
                    try:
                        row = future.result()
                    except FutureTimeout:
                        row = {"solver": solver_name, "transcription": transcription, "N": n_nodes,
                               "variables": None, "status": "killed",
                               "message": f"ignored its {time_limit_s:g} s time limit; stopped after {hard_limit:g} s",
                               "call_s": hard_limit, "wall_time_s": None, "function_time_s": None,
                               "iterations": None, "cot": None, "violation": None}
                with log.open("a") as stream:
                    stream.write(json.dumps(row) + "\n")
                print(json.dumps(row), flush=True)
                done.append(row)
    return done


def markdown(results: dict) -> str:
    limits = results["limits"]
    limits, machine = results["limits"], results["machine"]
    packages = ", ".join(f"{name} {ver}" for name, ver in machine["packages"].items() if ver)
    lines = [f"# Solvers on one 4-DOF gait step ({EXPERIMENT}, step 1, thesis cost)", "",
             f"Machine: {machine['cpus']} CPUs, {machine['platform']}, Python {machine['python']}; gaitbench "
             f"{machine['gaitbench']} at {machine['git_commit']}; {packages}.", "",
             *([results["note"], ""] if results.get("note") else []),
             f"Limits per solve: {limits['time_limit_s']} s, {limits['max_iterations']} iterations. "
             "COT is the optimizer's objective at the returned point (a failed solve's COT is not an optimum); "
             "time is the wall-clock time of the solve call; `killed`: the solver ignored its time limit and its "
             "process was stopped.", "",
             "| solver | transcription | N | status | time (s) | iterations | COT | violation |",
             "|---|---|---|---|---|---|---|---|"]
    for r in results["rows"]:
        cot = "—" if r["cot"] is None else f"{r['cot']:.4g}"
        violation = "—" if r["violation"] is None else f"{r['violation']:.1e}"
        lines.append(f"| {r['solver']} | {r['transcription']} | {r['N']} | {r['status']} | {r['call_s']:.2f} | "
                     f"{r['iterations']} | {cot} | {violation} |")
    return "\n".join(lines) + "\n"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--solvers", help="comma-separated solver names (default: every registered solver)")
    parser.add_argument("--nodes", default=",".join(map(str, NODES)), help="comma-separated N values")
    parser.add_argument("--time-limit", type=float, default=60.0, help="seconds per solve")
    parser.add_argument("--max-iterations", type=int, default=3000)
    parser.add_argument("--out", default="solvers", help="file stem under benchmarks/results")
    parser.add_argument("--note", help="a line for the summary, e.g. what else ran on the machine")
    args = parser.parse_args()
    names = args.solvers.split(",") if args.solvers else load_registry().names("solver")
    nodes = [int(n) for n in args.nodes.split(",")]
    OUT.mkdir(exist_ok=True)
    rows = run(names, nodes, args.time_limit, args.max_iterations, OUT / f"{args.out}.jsonl")
    results = {"machine": provenance(), "limits": {"time_limit_s": args.time_limit,
                                                "max_iterations": args.max_iterations},
               "note": args.note, "rows": rows}
    (OUT / f"{args.out}.json").write_text(json.dumps(results, indent=2))
    (OUT / f"{args.out}.md").write_text(markdown(results))


if __name__ == "__main__":
    main()
