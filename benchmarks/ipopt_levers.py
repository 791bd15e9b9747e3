"""IPOPT option levers, paired: the same problems solved with IPOPT's defaults (A, sections too) and with a variant
(B), A and B interleaved, so that a shared machine's load falls on both alike.

Run:    OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/ipopt_levers.py steps VARIANT [--nodes 20 60 120]
        OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/ipopt_levers.py sections VARIANT [--nodes 20 60]
        OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/ipopt_levers.py walks VARIANT [--nodes 20 60]
                                                    [--suite benchmarks/suites/regression.toml]
        OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/ipopt_levers.py fatrop --nodes 100 --repeats 3

- ``steps``: step 1 of every experiment (the standard guess), per transcription and N: status, iterations,
  objective and wall time (min of ``--repeats`` paired solves).
- ``sections``: decrease and conquer's sectional NLPs of step 1 of every experiment, from the First Phase's tail
  (as the strategy starts them; the First Phase solved with the walk's retries): converged count, iterations,
  wall time and how many end with a lower objective.
- ``walks``: whole cases through the suite runner's ``run_case`` (one-phase and decrease and conquer, 2 steps, one
  sectional worker): status, verified ACOT, whether the walk verifies, iterations of every solve (sections
  included) and wall time.
- ``fatrop``: forward step 1, IPOPT (A) against FATROP on the stage-wise form (B, :mod:`gaitbench.problem.stagewise`).

Each row has wall and CPU time (``cpu_s``, this process's: steadier on a shared machine). ``VARIANT`` names an
entry of :data:`VARIANTS`: the solver options of B (A has none). Rows are appended to
``benchmarks/results/ipopt_levers.jsonl`` with the commit.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import time
from pathlib import Path

import numpy as np

from gaitbench.plugins import load_registry
from gaitbench.problem.build_cache import BuildCache
from gaitbench.problem.gait_problem import StepData, sectional_structure
from gaitbench.run.case import Case, PluginChoice
from gaitbench.run.provenance import provenance
from gaitbench.run.runner import run_case
from gaitbench.run.suite import load_suite
from gaitbench.solve.solver import prepare, section_solver
from gaitbench.solve.walk import solve_with_retries
from gaitbench.walk_types import WalkProblem

RESULTS = Path(__file__).parent / "results" / "ipopt_levers.jsonl"
EXPERIMENTS = ("forward", "downward-slope", "upward-slope", "stairs")
TRANSCRIPTIONS = ("hermite-simpson", "dmoc")
ADAPTIVE = {"mu_strategy": "adaptive"}
VARIANTS: dict[str, dict] = {
    "adaptive-qf": ADAPTIVE | {"mu_oracle": "quality-function"},
    "adaptive-probing": ADAPTIVE | {"mu_oracle": "probing"},
    "steps-adaptive-qf": ADAPTIVE | {"mu_oracle": "quality-function", "section_options": {"mu_strategy": "monotone"}},
    "sections-adaptive-qf": {"section_options": ADAPTIVE | {"mu_oracle": "quality-function"}},
    "sections-adaptive-probing": {"section_options": ADAPTIVE | {"mu_oracle": "probing"}},
    "sections-objective": {"section_options": {"nlp_scaling_obj_target_gradient": 1.0}},
    "mumps-amd": {"mumps_pivot_order": 0},
    "mumps-metis": {"mumps_pivot_order": 5},
    "mumps-pord": {"mumps_pivot_order": 4},
    "mumps-noscaling": {"mumps_permuting_scaling": 0, "mumps_scaling": 0},
    "spral": {"linear_solver": "spral"},
}
"""Solver options of the B side, by name."""

IPOPT_DEFAULTS = {"section_options": {}}
"""The A side: IPOPT at its own defaults, sections too (the ``ipopt`` plugin's own default for sections is a lever
measured here)."""


_RECORD: dict = {}
"""What every row of this run carries: the variant, its options and the commit (set by :func:`main`)."""


def emit(row: dict) -> None:
    """Print ``row`` and append it to :data:`RESULTS` at once, so that a run stopped early keeps what it measured."""
    print(json.dumps(row), flush=True)
    with RESULTS.open("a") as out:
        out.write(json.dumps({**_RECORD, **row}) + "\n")


def timed(spent: list[float], call, *arguments):
    """``call(*arguments)``, appending the CPU time this process spent in it to ``spent``: on a shared machine a
    steadier measure than wall time (every solve here runs in this process)."""
    started = time.process_time()
    result = call(*arguments)
    spent.append(time.process_time() - started)
    return result


def step_problem(registry, experiment: str, transcription: str, n_nodes: int, options: dict):
    """Step 1 of ``experiment`` from its initial state, solved by IPOPT with ``options``."""
    made = registry.create("experiment", experiment)
    problem = WalkProblem(made, registry.create("transcription", transcription),
                          registry.create("solver", "ipopt", **options), n_nodes)
    return problem, problem.step_data(1, np.asarray(made.initial_state)[[0, 1, 4, 5]])


def steps_part(registry, options: dict, experiments, nodes, repeats: int) -> list[dict]:
    rows = []
    for experiment in experiments:
        for transcription in TRANSCRIPTIONS:
            for n_nodes in nodes:
                sides = {side: step_problem(registry, experiment, transcription, n_nodes, opts)
                         for side, opts in (("A", IPOPT_DEFAULTS), ("B", IPOPT_DEFAULTS | options))}
                built = sides["A"][0].transcription.build(sides["A"][0].structure("second"))
                data = sides["A"][1]
                for problem, _ in sides.values():
                    prepare(problem.solver, built.nlp)
                results, cpu = {"A": [], "B": []}, {"A": [], "B": []}
                for _ in range(repeats):
                    for side, (problem, _) in sides.items():
                        results[side].append(timed(cpu[side], problem.solver.solve, built.nlp,
                                                   data.parameter_vector(), built.initial_guess(data)))
                row = {"part": "steps", "experiment": experiment, "transcription": transcription, "N": n_nodes}
                for side, solved in results.items():
                    last = solved[-1]
                    row[side] = {"status": last.status.value, "iterations": last.iterations,
                                 "objective": last.objective, "wall_s": min(r.wall_time_s for r in solved),
                                 "cpu_s": min(cpu[side])}
                rows.append(row)
                emit(row)
    return rows


def sections_part(registry, options: dict, experiments, nodes) -> list[dict]:
    rows = []
    for experiment in experiments:
        for transcription in TRANSCRIPTIONS:
            for n_nodes in nodes:
                problem, data = step_problem(registry, experiment, transcription, n_nodes, IPOPT_DEFAULTS)
                first = solve_with_retries(problem, 1, problem.transcription.build(problem.structure("first")),
                                           data, phase="first")
                if not first.solved:
                    continue
                solvers = {"A": section_solver(problem.solver),
                           "B": section_solver(registry.create("solver", "ipopt", **IPOPT_DEFAULTS | options))}
                results, cpu = {"A": [], "B": []}, {"A": [], "B": []}
                for k0 in range(2, n_nodes - 1):
                    built = problem.transcription.build(sectional_structure(problem.structure("second"), k0))
                    section = StepData(data.robot, data.stance, np.r_[first.trajectory.q[k0 - 1],
                                                                      first.trajectory.dq[k0 - 1]],
                                       data.chord, data.slope, data.time_step)
                    x0 = built.initial_guess(section, first.trajectory.seed((k0 - 1) * data.time_step))
                    for side, solver in solvers.items():
                        prepare(solver, built.nlp)
                        results[side].append(timed(cpu[side], solver.solve, built.nlp, section.parameter_vector(), x0))
                row = {"part": "sections", "experiment": experiment, "transcription": transcription, "N": n_nodes}
                for side, solved in results.items():
                    converged = [r for r in solved if r.converged]
                    row[side] = {"sections": len(solved), "converged": len(converged),
                                 "iterations": int(sum(r.iterations for r in solved)),
                                 "converged_iterations": int(sum(r.iterations for r in converged)),
                                 "wall_s": float(sum(r.wall_time_s for r in solved)), "cpu_s": sum(cpu[side])}
                pairs = [(a, b) for a, b in zip(results["A"], results["B"], strict=True) if a.converged and b.converged]
                row["B_lower_objective"] = sum(b.objective < a.objective * (1 - 1e-9) for a, b in pairs)
                row["B_higher_objective"] = sum(b.objective > a.objective * (1 + 1e-9) for a, b in pairs)
                rows.append(row)
                emit(row)
    return rows


def fatrop_part(registry, nodes, repeats: int) -> list[dict]:
    """Forward step 1 from the standard guess, IPOPT (A) against FATROP on the stage-wise form (B), interleaved."""
    rows = []
    for transcription in TRANSCRIPTIONS:
        for n_nodes in nodes:
            problem, data = step_problem(registry, "forward", transcription, n_nodes, IPOPT_DEFAULTS)
            built = problem.transcription.build(problem.structure("second"))
            solvers = {"A": problem.solver, "B": registry.create("solver", "fatrop", stagewise=True)}
            started = time.perf_counter()
            for solver in solvers.values():
                prepare(solver, built.nlp)
            build_s = time.perf_counter() - started
            results, cpu = {"A": [], "B": []}, {"A": [], "B": []}
            for _ in range(repeats):
                for side, solver in solvers.items():
                    results[side].append(timed(cpu[side], solver.solve, built.nlp, data.parameter_vector(),
                                               built.initial_guess(data)))
            row = {"part": "fatrop", "experiment": "forward", "transcription": transcription, "N": n_nodes,
                   "build_both_s": build_s}
            for side, solved in results.items():
                last = solved[-1]
                row[side] = {"status": last.status.value, "message": last.message, "iterations": last.iterations,
                             "objective": last.objective, "violation": last.constraint_violation,
                             "wall_s": sorted(r.wall_time_s for r in solved), "cpu_s": sorted(cpu[side])}
            rows.append(row)
            emit(row)
    return rows


class SolveCounter:
    """Every IPOPT solve's iterations and time in this process, sectional and other (the walks' effort)."""

    def __init__(self) -> None:
        from gaitbench_plugins.solvers.ipopt import Ipopt

        self.totals = {"iterations": 0, "wall_s": 0.0}
        original = Ipopt.solve

        def solve(solver, nlp, parameters, initial_guess):
            result = original(solver, nlp, parameters, initial_guess)
            self.totals["iterations"] += result.iterations
            self.totals["wall_s"] += result.wall_time_s
            return result

        Ipopt.solve = solve

    def take(self) -> dict:
        totals, self.totals = self.totals, {"iterations": 0, "wall_s": 0.0}
        return totals


def walk_cases(experiments, nodes, steps: int, strategies) -> list[Case]:
    cases = []
    for experiment in experiments:
        for transcription in TRANSCRIPTIONS:
            for n_nodes in nodes:
                for strategy in strategies:
                    options = {"workers": 1} if strategy == "decrease-and-conquer" else {}
                    cases.append(Case(experiment=PluginChoice(experiment), transcription=PluginChoice(transcription),
                                      solver=PluginChoice("ipopt"), strategy=PluginChoice(strategy, options),
                                      n_nodes=n_nodes, steps=steps, time_limit_s=600))
    return cases


def suite_cases(path: Path, strategies) -> list[Case]:
    """A suite's cases (the regression set, say) of ``strategies``, decrease and conquer with one sectional worker."""
    cases = []
    for case in load_suite(path).cases:
        if case.strategy.name not in strategies:
            continue
        if case.strategy.name == "decrease-and-conquer":
            case = dataclasses.replace(case, strategy=PluginChoice(case.strategy.name,
                                                                   {**case.strategy.options, "workers": 1}))
        cases.append(case)
    return cases


def walks_part(options: dict, cases: list[Case]) -> list[dict]:
    rows, counter = [], SolveCounter()
    builds = {"A": BuildCache(), "B": BuildCache()}
    for case in cases:
        row = {"part": "walks", "case": case.label}
        for side, opts in (("A", IPOPT_DEFAULTS), ("B", IPOPT_DEFAULTS | options)):
            solved = dataclasses.replace(case, solver=PluginChoice("ipopt", {**case.solver.options, **opts}))
            spent: list[float] = []
            outcome = timed(spent, run_case, solved, builds[side])
            metrics = outcome.metrics
            row[side] = {"status": outcome.status, "acot": metrics.get("acot"), "verified": metrics.get("verified"),
                         "wall_s": outcome.wall_time_s, "cpu_s": spent[0], **counter.take(),
                         "failed_sections": (metrics.get("strategy_details") or {}).get("failed_sections")}
        rows.append(row)
        emit(row)
    return rows


def main(argv: list[str]) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("part", choices=("steps", "sections", "walks", "fatrop"))
    parser.add_argument("variant", choices=sorted(VARIANTS), nargs="?", default=None,
                        help="the B side's options (not for fatrop, whose B side is FATROP)")
    parser.add_argument("--nodes", type=int, nargs="+", default=[20, 60])
    parser.add_argument("--repeats", type=int, default=2, help="paired solves per step (steps)")
    parser.add_argument("--steps", type=int, default=2, help="steps per walk (walks)")
    parser.add_argument("--strategies", nargs="+", default=["one-phase", "decrease-and-conquer"],
                        choices=["one-phase", "decrease-and-conquer"], help="walks: the strategies walked")
    parser.add_argument("--suite", type=Path, default=None, help="walks: this suite's cases instead of the grid")
    parser.add_argument("--experiments", nargs="+", default=list(EXPERIMENTS), choices=EXPERIMENTS)
    arguments = parser.parse_args(argv)
    if arguments.part != "fatrop" and arguments.variant is None:
        parser.error(f"{arguments.part} needs a VARIANT")
    options = VARIANTS.get(arguments.variant, {})
    _RECORD.update(variant=arguments.variant or "fatrop", options=options, commit=provenance().get("git_commit"))
    registry = load_registry()
    started = time.perf_counter()
    if arguments.part == "steps":
        rows = steps_part(registry, options, arguments.experiments, arguments.nodes, arguments.repeats)
    elif arguments.part == "sections":
        rows = sections_part(registry, options, arguments.experiments, arguments.nodes)
    elif arguments.part == "fatrop":
        rows = fatrop_part(registry, arguments.nodes, arguments.repeats)
    else:
        cases = (suite_cases(arguments.suite, arguments.strategies) if arguments.suite is not None
                 else walk_cases(arguments.experiments, arguments.nodes, arguments.steps, arguments.strategies))
        rows = walks_part(options, cases)
    print(f"{arguments.part} {arguments.variant}: {len(rows)} rows in {time.perf_counter() - started:.0f} s")


if __name__ == "__main__":
    main(sys.argv[1:])
