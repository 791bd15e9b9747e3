"""Every solver plugin on the same one-step gait problems: status, time, iterations and final COT.

Run: .venv/bin/python benchmarks/solvers.py [--time-limit S] [--solvers a,b] [--nodes 25,50,100]
(writes benchmarks/results/solvers.json and .md). The problem is the upward-slope experiment's first step, Second
Phase (4-DOF), with the thesis's cost and default options, from the transcription's standard initial guess, for
``hermite-simpson`` and ``dmoc`` at N = 25, 50, 100. Each solve has the same time limit and iteration limit; times
are wall-clock seconds of the solve call (the first solve of a structure includes each solver's own build).
"""

from __future__ import annotations

import argparse
import json
import platform
import time
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path

from gaitbench import __version__
from gaitbench.gait_problem import ProblemOptions, StepData, StepStructure
from gaitbench.plugins import load_registry

EXPERIMENT = "upward-slope"
TRANSCRIPTIONS = ("hermite-simpson", "dmoc")
NODES = (25, 50, 100)
OUT = Path(__file__).parent / "results"
PACKAGES = ("casadi", "numpy", "scipy", "qpsolvers", "osqp", "cyipopt-wheels", "pyomo", "pyomo-ripopt")


def problems(registry, nodes):
    experiment = registry.create("experiment", EXPERIMENT)
    geometry = experiment.terrain.steps[0]
    for name in TRANSCRIPTIONS:
        transcription = registry.create("transcription", name)
        for n_nodes in nodes:
            built = transcription.build(StepStructure("second", n_nodes, ProblemOptions(limits=experiment.limits)))
            data = StepData(experiment.robot, experiment.stance_leg(1), experiment.initial_state[[0, 1, 4, 5]],
                            geometry.D, geometry.theta, experiment.time_step(n_nodes))
            yield name, n_nodes, built, data


def run(solver_names, nodes, time_limit_s, max_iterations):
    registry = load_registry()
    rows = []
    for transcription, n_nodes, built, data in problems(registry, nodes):
        for solver_name in solver_names:
            solver = registry.create("solver", solver_name, time_limit_s=time_limit_s,
                                     max_iterations=max_iterations)
            started = time.perf_counter()
            result = solver.solve(built.nlp, data.parameter_vector(), built.initial_guess(data))
            rows.append({"solver": solver_name, "transcription": transcription, "N": n_nodes,
                         "variables": built.nlp.n_variables, "status": result.status.value,
                         "message": result.message, "call_s": time.perf_counter() - started,
                         "wall_time_s": result.wall_time_s, "function_time_s": result.function_time_s,
                         "iterations": result.iterations, "cot": result.objective,
                         "violation": result.constraint_violation})
            print(json.dumps(rows[-1]), flush=True)
    return rows


def machine() -> dict:
    versions = {}
    for package in PACKAGES:
        try:
            versions[package] = version(package)
        except PackageNotFoundError:
            versions[package] = None
    return {"python": platform.python_version(), "gaitbench": __version__, "machine": platform.machine(),
            "platform": platform.platform(), "cpus": __import__("os").cpu_count(), "packages": versions}


def markdown(results: dict) -> str:
    limits = results["limits"]
    lines = [f"# Solvers on one 4-DOF gait step ({EXPERIMENT}, step 1, thesis cost)", "",
             f"Machine: {results['machine']}", "",
             f"Limits per solve: {limits['time_limit_s']} s, {limits['max_iterations']} iterations. "
             "COT is the optimizer's objective at the returned point (a failed solve's COT is not an optimum); "
             "time is the wall-clock time of the solve call.", "",
             "| solver | transcription | N | status | time (s) | iterations | COT | violation |",
             "|---|---|---|---|---|---|---|---|"]
    for r in results["rows"]:
        lines.append(f"| {r['solver']} | {r['transcription']} | {r['N']} | {r['status']} | {r['call_s']:.2f} | "
                     f"{r['iterations']} | {r['cot']:.4f} | {r['violation']:.1e} |")
    return "\n".join(lines) + "\n"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--solvers", help="comma-separated solver names (default: every registered solver)")
    parser.add_argument("--nodes", default=",".join(map(str, NODES)), help="comma-separated N values")
    parser.add_argument("--time-limit", type=float, default=60.0, help="seconds per solve")
    parser.add_argument("--max-iterations", type=int, default=3000)
    parser.add_argument("--out", default="solvers", help="file stem under benchmarks/results")
    args = parser.parse_args()
    names = args.solvers.split(",") if args.solvers else load_registry().names("solver")
    nodes = [int(n) for n in args.nodes.split(",")]
    rows = run(names, nodes, args.time_limit, args.max_iterations)
    results = {"machine": machine(), "limits": {"time_limit_s": args.time_limit,
                                                "max_iterations": args.max_iterations}, "rows": rows}
    OUT.mkdir(exist_ok=True)
    (OUT / f"{args.out}.json").write_text(json.dumps(results, indent=2))
    (OUT / f"{args.out}.md").write_text(markdown(results))


if __name__ == "__main__":
    main()
