"""Build time, solve time and iterations of one 4-DOF step per transcription and N, and of full 11-step walks.

Run: .venv/bin/python benchmarks/step_solve.py  (writes benchmarks/results/step_solve.json and .md)
Times are whole-call wall-clock seconds on the machine named in the output; IPOPT through CasADi, exact Hessian.
"""

from __future__ import annotations

import json
import platform
import time
from pathlib import Path

import casadi
import numpy as np

from gaitbench import __version__
from gaitbench.contracts import WalkProblem
from gaitbench.plugins import load_registry
from gaitbench.problem.gait_problem import ProblemOptions, StepData, StepStructure

TRANSCRIPTIONS = ("hermite-simpson", "trapezoidal", "dmoc")
NODES = (25, 50, 100, 200)
WALK_NODES = 50
OUT = Path(__file__).parent / "results"


def step_rows(registry, experiment):
    rows = []
    state = np.asarray(experiment.initial_state)[[0, 1, 4, 5]]
    first = experiment.terrain.steps[0]
    for name in TRANSCRIPTIONS:
        transcription = registry.create("transcription", name)
        for n_nodes in NODES:
            started = time.perf_counter()
            built = transcription.build(StepStructure("second", n_nodes, ProblemOptions(limits=experiment.limits)))
            build_s = time.perf_counter() - started
            solver = registry.create("solver", "ipopt")
            data = StepData(experiment.robot, 1, state, first.D, first.theta, experiment.time_step(n_nodes))
            cold = solver.solve(built.nlp, data.parameter_vector(), built.initial_guess(data))  # builds nlpsol
            # Re-solve the same structure with new parameters (step 3's geometry): no rebuild.
            third = experiment.terrain.steps[2]
            data3 = StepData(experiment.robot, 1, state, third.D, third.theta, experiment.time_step(n_nodes))
            started = time.perf_counter()
            warm = solver.solve(built.nlp, data3.parameter_vector(), built.initial_guess(data3))
            resolve_call_s = time.perf_counter() - started
            rows.append({
                "transcription": name, "N": n_nodes, "variables": built.nlp.n_variables,
                "constraints": built.nlp.n_constraints, "build_s": build_s,
                "first_solve_status": cold.status.value, "first_solve_s": cold.wall_time_s,
                "first_iterations": cold.iterations, "first_function_s": cold.function_time_s,
                "resolve_status": warm.status.value, "resolve_s": warm.wall_time_s, "resolve_call_s": resolve_call_s,
                "resolve_iterations": warm.iterations, "solver_instances_cached": len(built.nlp.solver_cache),
            })
            print(rows[-1], flush=True)
    return rows


def walk_rows(registry, experiment):
    rows = []
    for name in TRANSCRIPTIONS:
        problem = WalkProblem(experiment, registry.create("transcription", name), registry.create("solver", "ipopt"),
                              WALK_NODES)
        walk = registry.create("strategy", "one-phase").solve(problem)
        rows.append({"transcription": name, "N": WALK_NODES, "complete": walk.complete, "acot": walk.acot,
                     "failure": walk.failure, "wall_time_s": walk.wall_time_s,
                     "solve_time_s": sum(s.solver_result.wall_time_s for s in walk.steps if s.solver_result),
                     "iterations": [s.solver_result.iterations if s.solver_result else None for s in walk.steps]})
        print(rows[-1], flush=True)
    return rows


def main() -> None:
    registry = load_registry()
    experiment = registry.create("experiment", "forward")
    machine = {"python": platform.python_version(), "casadi": casadi.__version__, "gaitbench": __version__,
               "machine": platform.machine(), "processor": platform.processor() or platform.platform(),
               "cpus": __import__("os").cpu_count()}
    results = {"machine": machine, "steps": step_rows(registry, experiment), "walks": walk_rows(registry, experiment)}
    OUT.mkdir(exist_ok=True)
    (OUT / "step_solve.json").write_text(json.dumps(results, indent=2))
    lines = ["# One 4-DOF step and full walks (forward experiment, IPOPT, exact Hessian)", "",
             f"Machine: {machine}", "",
             "| transcription | N | vars | build (s) | 1st solve (s) | iters | re-solve (s) | iters | cached solvers |",
             "|---|---|---|---|---|---|---|---|---|"]
    for r in results["steps"]:
        lines.append(f"| {r['transcription']} | {r['N']} | {r['variables']} | {r['build_s']:.3f} | "
                     f"{r['first_solve_s']:.2f} ({r['first_solve_status']}) | {r['first_iterations']} | "
                     f"{r['resolve_s']:.2f} ({r['resolve_status']}) | {r['resolve_iterations']} | "
                     f"{r['solver_instances_cached']} |")
    lines += ["", f"Full 11-step forward walk, one phase, N = {WALK_NODES}:", "",
              "| transcription | complete | ACOT | wall time (s) | IPOPT time (s) |", "|---|---|---|---|---|"]
    for r in results["walks"]:
        acot = "—" if r["acot"] is None else f"{r['acot']:.4f}"
        lines.append(f"| {r['transcription']} | {r['complete']} | {acot} | {r['wall_time_s']:.1f} | "
                     f"{r['solve_time_s']:.1f} |")
    (OUT / "step_solve.md").write_text("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
