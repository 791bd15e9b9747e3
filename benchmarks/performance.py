"""Where the time goes: NLP build, cold step solves against N, per-iteration split, sectional solves, D&C against
one-phase, and whole-suite wall time.

Run:    OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/performance.py [steps] [sections] [scaling] [walks]
        [contact] [suite] [suite-all] [suite-all-large] [suite-all-large-scaled] [suite-forward-full]
        [suite-forward-full-scaled] [suite-all-rest] [executors]

Each part appends its rows to ``benchmarks/results/performance.json`` (replacing that part's earlier rows) and
rewrites ``performance.md`` from them (``performance_summary.py``). Run it on a quiet machine: every figure is a
wall-clock time of this process.

- ``steps``: the second-phase step 1 of the forward experiment per transcription and N, from the standard guess:
  transcription and IPOPT build time, resident memory of the built solver, solve time, iterations, and each
  iteration split into derivative evaluation (IPOPT's callbacks: f, g, their derivatives, the Hessian) and the
  rest (linear algebra and IPOPT's own work); log–log slopes against N.
- ``sections``: the sectional solves of decrease-and-conquer for one step, from the First Phase tail (the thesis's
  guess, the default) and from the complete Second Phase tail.
- ``scaling``: cold steps and sections solved by IPOPT as configured by default and with each scaling of
  ``SCALINGS`` (the objective, the variables and constraints, both): time, iterations and the objective each
  reaches. What the scaling does to the results
  of whole walks is measured by ``acot_regression.py --solver-option``.
- ``walks``: decrease-and-conquer against one-phase, whole walks, with 1 and 2 sectional workers.
- ``contact``: the cold step with the ground-reaction rows (unilateral contact and a friction cone, off in the
  thesis suites) against the same step without them: what those rows cost, compiled per node
  (``NLPBuilder.constrain_columns``).
- ``suite``: a sample of ``thesis-forward`` (every method at a few N) run with ``gaitbench run`` at 1 and 2 jobs;
  the whole-suite time is extrapolated per experiment and method with a power law in N fitted to the sample, and
  labelled so. ``suite-all``: the same for ``thesis-all`` (all four experiments). ``suite-all-large``: ``thesis-all``
  without its reference column at N = 50, 100, 150, 200 with 2 jobs and the suite's own case limit, where the
  sweep costs most. ``suite-all-large-scaled``: the same with IPOPT's objective scaling (``OBJECTIVE_SCALING``),
  which changes the results: what the sweep would take if the reproduction adopted it.
- ``suite-forward-full``: the whole of ``thesis-forward`` without its reference column, 2 jobs;
  ``suite-forward-full-scaled``: the same with the objective scaled. ``suite-all-rest``: the rest of
  ``thesis-all`` the same way (its other three experiments), which with ``suite-forward-full`` measures the whole
  of ``thesis-all``'s IPOPT part; its row also holds that sum and the computed 2-worker schedule of all 320 cases.
- ``executors``: one sample of ``thesis-forward``'s IPOPT methods with 2 jobs on the local pool and on Dask.
"""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
from performance_summary import summary_markdown  # its siblings in benchmarks/
from scaling import makespan

from gaitbench.contracts import WalkProblem
from gaitbench.plugins import load_registry
from gaitbench.problem.gait_problem import StepData, sectional_structure
from gaitbench.run.case import Case
from gaitbench.run.provenance import provenance
from gaitbench.run.runner import largest_first
from gaitbench.run.store import load_results
from gaitbench.run.suite import load_suite
from gaitbench.solve.solver import prepare
from gaitbench.solve.walk import solve_and_verify

HERE = Path(__file__).parent
RESULTS = HERE / "results" / "performance.json"
SUMMARY = HERE / "results" / "performance.md"
TRANSCRIPTIONS = ("hermite-simpson", "dmoc")
STEP_NODES = (25, 50, 100, 200)
SECTION_NODES = (25, 50)
WALK_NODES = (20, 40)
WALK_STEPS = 3
SCALING_STEP_NODES = (50, 100)
SCALING_SECTION_NODES = 50
CONTACT_STEP_NODES = (50, 100)
FRICTION_COEFFICIENT = 0.8
"""μ of the friction cone in the ``contact`` part (docs/model.md §2 leaves it a parameter)."""
OBJECTIVE_SCALING = {"nlp_scaling_obj_target_gradient": 1.0}
"""IPOPT scales the objective so that its gradient at the starting point has max-norm 1. The step costs are COTs
of 1e-8 … 0.5, their gradients as small, so unscaled the barrier and the constraints steer IPOPT's path."""
SCALINGS = {"default": {}, "objective": OBJECTIVE_SCALING, "nominal": {"scaling": "nominal"},
            "nominal + objective": {"scaling": "nominal"} | OBJECTIVE_SCALING}
"""IPOPT's defaults and the scalings compared with them. ``nominal`` scales the variables and the constraint rows
(:mod:`gaitbench.problem.scaling`)."""
SUITE_SAMPLE_NODES = (10, 20, 30)
SUITE_SAMPLE_TIME_LIMIT_S = 600
"""The sample's case time limit (the thesis suites' own is 7200 s since 2026-12-03, 3600 s before): ripopt, the
reference method's solver until 2026-12, could spend the whole limit in one step's solve (stairs, N = 20: over 13
minutes), which would make the sample take hours. A case that reaches it makes the extrapolation a lower bound, and
the summary says how many did."""
LARGE_SAMPLE_NODES = (50, 100, 150, 200)
FULL_NODES = tuple(range(10, 201, 10))
EXECUTOR_SAMPLE_NODES = (20, 40)
ALL_EXPERIMENTS = ("forward", "downward-slope", "upward-slope", "stairs")
"""``thesis-all``'s experiments, in its order."""
IPOPT_METHODS = ("OP-DC", "OP-DM", "D&C-DC", "D&C-DM")
"""``thesis-all``'s methods solved by IPOPT through gaitbench's core: all but the reference column."""


def resident_mb() -> float:
    return int(Path("/proc/self/statm").read_text().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 2**20


def forward_step(registry, n_nodes: int, transcription: str = "hermite-simpson", **solver_options):
    experiment = registry.create("experiment", "forward")
    problem = WalkProblem(experiment, registry.create("transcription", transcription),
                          registry.create("solver", "ipopt", **solver_options), n_nodes)
    state = np.asarray(experiment.initial_state)[[0, 1, 4, 5]]
    return problem, problem.step_data(1, state)


def steps_part(registry) -> list[dict]:
    rows, kept = [], []  # built solvers stay alive, so freed memory is not reused and growth is attributable
    for name in TRANSCRIPTIONS:
        for n_nodes in STEP_NODES:
            problem, data = forward_step(registry, n_nodes)
            transcription, solver = registry.create("transcription", name), registry.create("solver", "ipopt")
            started = time.perf_counter()
            built = transcription.build(problem.structure("second"))
            transcribe_s = time.perf_counter() - started
            memory = resident_mb()
            started = time.perf_counter()
            prepare(solver, built.nlp)  # what the first solve of a structure pays once
            nlpsol_s = time.perf_counter() - started
            solver_mb = resident_mb() - memory
            kept.append(built)
            result = solver.solve(built.nlp, data.parameter_vector(), built.initial_guess(data))
            derivative_s = result.function_time_s  # IPOPT's callbacks: f, g, their derivatives, the Hessian
            iterations = max(result.iterations, 1)
            rows.append({
                "transcription": name, "N": n_nodes, "variables": built.nlp.n_variables,
                "constraints": built.nlp.n_constraints, "transcribe_s": transcribe_s, "nlpsol_build_s": nlpsol_s,
                "solver_memory_mb": solver_mb, "status": result.status.value, "solve_s": result.wall_time_s,
                "iterations": result.iterations, "derivative_s": derivative_s,
                "per_iteration_ms": 1e3 * result.wall_time_s / iterations,
                "derivative_per_iteration_ms": 1e3 * derivative_s / iterations,
                "rest_per_iteration_ms": 1e3 * (result.wall_time_s - derivative_s) / iterations,
            })
            print(rows[-1], flush=True)
    return rows


def contact_part(registry) -> list[dict]:
    """Forward step 1 from the standard guess with and without the ground-reaction rows, per transcription and N."""
    rows = []
    for name in TRANSCRIPTIONS:
        for n_nodes in CONTACT_STEP_NODES:
            for contact in (False, True):
                experiment, transcription = registry.create("experiment", "forward"), registry.create(
                    "transcription", name)
                solver = registry.create("solver", "ipopt")
                options = replace(WalkProblem(experiment, transcription, solver, n_nodes).options,
                                  unilateral_contact=contact, friction_coefficient=FRICTION_COEFFICIENT if contact
                                  else None)
                problem = WalkProblem(experiment, transcription, solver, n_nodes, options=options)
                data = problem.step_data(1, np.asarray(experiment.initial_state)[[0, 1, 4, 5]])
                built = transcription.build(problem.structure("second"))
                prepare(solver, built.nlp)
                result = solver.solve(built.nlp, data.parameter_vector(), built.initial_guess(data))
                rows.append({"transcription": name, "N": n_nodes, "contact_rows": contact,
                             "constraints": built.nlp.n_constraints, "status": result.status.value,
                             "solve_s": result.wall_time_s, "iterations": result.iterations,
                             "derivative_s": result.function_time_s})
                print(rows[-1], flush=True)
    return rows


def sections_part(registry) -> list[dict]:
    rows = []
    for name in TRANSCRIPTIONS:
        for n_nodes in SECTION_NODES:
            problem, data = forward_step(registry, n_nodes, name)
            first, complete = first_and_complete(problem, data)
            for guess, source in (("first-phase", first), ("complete", complete)):
                results = sectional_solves(problem, data, first, source)
                rows.append({"transcription": name, "N": n_nodes, "guess": guess, **section_summary(results)})
                print(rows[-1], flush=True)
    return rows


def first_phase(problem: WalkProblem, data: StepData):
    """Step 1's First Phase solution: the sectional problems' initial states."""
    return solve_and_verify(problem, 1, problem.transcription.build(problem.structure("first")), data, phase="first")


def first_and_complete(problem: WalkProblem, data: StepData):
    """Step 1's First Phase and complete Second Phase solutions: what the sectional problems start from."""
    first = first_phase(problem, data)
    complete = solve_and_verify(problem, 1, problem.transcription.build(problem.structure("second")), data,
                                seed=first.trajectory.seed())
    return first, complete


def section_summary(results: list) -> dict:
    times = [result.wall_time_s for result in results]
    return {"sections": len(times), "converged": sum(result.converged for result in results),
            "mean_s": float(np.mean(times)), "median_s": float(np.median(times)), "max_s": float(np.max(times)),
            "mean_iterations": float(np.mean([result.iterations for result in results]))}


def sectional_solves(problem: WalkProblem, data: StepData, first, source) -> list:
    """The solver results of sections k0 = 2 … N−2, each from the First Phase state at k0 and ``source``'s tail."""
    h, results = data.time_step, []
    for k0 in range(2, problem.n_nodes - 1):
        built = problem.transcription.build(sectional_structure(problem.structure("second"), k0))
        section = StepData(data.robot, data.stance, np.r_[first.trajectory.q[k0 - 1], first.trajectory.dq[k0 - 1]],
                           data.chord, data.slope, h)
        x0 = built.initial_guess(section, source.trajectory.seed((k0 - 1) * h))
        prepare(problem.solver, built.nlp)  # timed below: the solve, not the build
        results.append(problem.solver.solve(built.nlp, section.parameter_vector(), x0))
    return results


def scaling_part(registry) -> list[dict]:
    """IPOPT with its defaults and with each of :data:`SCALINGS` on the same cold steps and sections.

    Both solve the same problems from the same guesses; the sections start from the default solver's First Phase.
    """
    rows = []
    for name in TRANSCRIPTIONS:
        for n_nodes in SCALING_STEP_NODES:
            for label, options in SCALINGS.items():
                problem, data = forward_step(registry, n_nodes, name, **options)
                built = problem.transcription.build(problem.structure("second"))
                prepare(problem.solver, built.nlp)
                result = problem.solver.solve(built.nlp, data.parameter_vector(), built.initial_guess(data))
                rows.append({"transcription": name, "N": n_nodes, "problem": "cold step", "ipopt": label,
                             "converged": int(result.converged), "mean_s": result.wall_time_s,
                             "mean_iterations": result.iterations, "objectives": [result.objective]})
                print(rows[-1], flush=True)
        problem, data = forward_step(registry, SCALING_SECTION_NODES, name)
        first = first_phase(problem, data)
        for label, options in SCALINGS.items():
            solving, _ = forward_step(registry, SCALING_SECTION_NODES, name, **options)
            results = sectional_solves(solving, data, first, first)
            rows.append({"transcription": name, "N": SCALING_SECTION_NODES, "problem": "sections", "ipopt": label,
                         **section_summary(results), "objectives": [result.objective for result in results]})
            print({key: value for key, value in rows[-1].items() if key != "objectives"}, flush=True)
    return rows


def walks_part(registry) -> list[dict]:
    rows = []
    experiment = registry.create("experiment", "forward")
    for name in TRANSCRIPTIONS:
        for n_nodes in WALK_NODES:
            runs = [("one-phase", {}), ("decrease-and-conquer", {"workers": 1}),
                    ("decrease-and-conquer", {"workers": 2})]
            for strategy, options in runs:
                # a new problem: each walk builds its sections, as the first D&C case of a worker does
                problem = WalkProblem(experiment, registry.create("transcription", name),
                                      registry.create("solver", "ipopt"), n_nodes, steps=WALK_STEPS)
                started = time.perf_counter()
                walk = registry.create("strategy", strategy, **options).solve(problem)
                wall = time.perf_counter() - started
                rows.append({"transcription": name, "N": n_nodes, "steps": WALK_STEPS, "strategy": strategy,
                             "workers": options.get("workers", 1), "complete": walk.complete,
                             "acot": walk.strategy_details.get("verified_acot", walk.acot), "wall_s": wall})
                print(rows[-1], flush=True)
    return rows


def sampled_suite(suite: str, sample_nodes, time_limit_s: int, ipopt_options: dict | None = None,
                  experiments: tuple[str, ...] = ()) -> str:
    """The text of ``suites/<suite>.toml`` at ``sample_nodes`` with ``time_limit_s`` for every case (a method's own
    limit dropped), its IPOPT methods solving with ``ipopt_options`` if given, and only ``experiments`` if given."""
    sample = (HERE.parent / "suites" / f"{suite}.toml").read_text()
    head, methods = sample.split("[[method]]", 1)
    sample = head + "[[method]]" + re.sub(r"(?m)^time_limit_s = .*\n", "", methods)
    replacements = [("N = { start = 10, stop = 200, step = 10 }", f"N = {list(sample_nodes)}"),
                    ("time_limit_s = 7200", f"time_limit_s = {time_limit_s}")]
    if experiments:
        replacements.append((f"experiments = {json.dumps(list(ALL_EXPERIMENTS))}",
                             f"experiments = {json.dumps(list(experiments))}"))
    if ipopt_options:
        inline = ", ".join(f"{key} = {json.dumps(value)}" for key, value in ipopt_options.items())
        replacements.append(('solver = "ipopt"', f'solver = {{ name = "ipopt", options = {{ {inline} }} }}'))
    for full, sampled in replacements:
        if full not in sample:
            raise SystemExit(f"suites/{suite}.toml no longer has the line `{full}` this benchmark replaces")
        sample = sample.replace(full, sampled)
    return sample


def suite_part(registry, suite: str = "thesis-forward", sample_nodes=SUITE_SAMPLE_NODES, jobs_runs=(1, 2),
               methods: tuple[str, ...] = (), time_limit_s: int = SUITE_SAMPLE_TIME_LIMIT_S,
               ipopt_options: dict | None = None, experiments: tuple[str, ...] = ()) -> list[dict]:
    """``suite`` at ``sample_nodes`` only, run with ``gaitbench run`` once per entry of ``jobs_runs``; with
    ``methods``, only those methods' cases (``--method``); with ``ipopt_options``, its IPOPT methods solve with them;
    with ``experiments``, only those experiments."""
    sample = sampled_suite(suite, sample_nodes, time_limit_s, ipopt_options, experiments)
    selected = [argument for method in methods for argument in ("--method", method)]
    rows = []
    with tempfile.TemporaryDirectory() as scratch:
        suite_file = Path(scratch) / f"{suite}-sample.toml"
        suite_file.write_text(sample)
        for jobs in jobs_runs:
            wall, per_case = run_sample(suite_file, Path(scratch) / f"store-{jobs}", "--jobs", str(jobs), *selected)
            rows.append({"suite": suite, "sample_N": list(sample_nodes), "jobs": jobs, "methods": list(methods),
                         "ipopt_options": ipopt_options or {}, "experiments": list(experiments),
                         "git_commit": provenance()["git_commit"],
                         "time_limit_s": time_limit_s, "cases": len(per_case),
                         "at_time_limit": sum(row["wall_s"] >= time_limit_s for row in per_case),
                         "wall_s": wall, "per_case": per_case,
                         "extrapolated": extrapolate(per_case, range(10, 201, 10), jobs)})
            print({key: value for key, value in rows[-1].items() if key != "per_case"}, flush=True)
    return rows


def run_sample(suite_file: Path, store: Path, *arguments: str) -> tuple[float, list[dict]]:
    """``gaitbench run suite_file`` into ``store``: its wall time and each case's outcome and time."""
    started = time.perf_counter()
    subprocess.run([str(Path(sys.executable).parent / "gaitbench"), "run", str(suite_file), "--store", str(store),
                    "--no-report", *arguments], check=False, stdout=subprocess.DEVNULL)
    wall = time.perf_counter() - started
    per_case = [{"experiment": row["experiment"], "method": row["method"], "N": int(row["N"]),
                 "status": row["status"], "steps_solved": int(row["steps_solved"] or 0),
                 "wall_s": float(row["wall_time_s"])}
                for row in load_results(store).to_dict("records")]
    return wall, per_case


def executors_part(registry) -> list[dict]:
    """The same sample of ``thesis-forward``'s IPOPT methods with 2 jobs on each executor: the local pool of
    worker processes, and Dask (a local cluster of 2 workers, each case in its own child process)."""
    sample = sampled_suite("thesis-forward", EXECUTOR_SAMPLE_NODES, 3600)
    selected = [argument for method in IPOPT_METHODS for argument in ("--method", method)]
    rows = []
    with tempfile.TemporaryDirectory() as scratch:
        suite_file = Path(scratch) / "thesis-forward-sample.toml"
        suite_file.write_text(sample)
        for executor in ("local", "dask"):
            wall, per_case = run_sample(suite_file, Path(scratch) / executor, "--jobs", "2", "--executor", executor,
                                        *selected)
            rows.append({"executor": executor, "jobs": 2, "sample_N": list(EXECUTOR_SAMPLE_NODES),
                         "cases": len(per_case), "wall_s": wall, "per_case": per_case})
            print({key: value for key, value in rows[-1].items() if key != "per_case"}, flush=True)
    return rows


def suite_all_part(registry) -> list[dict]:
    return suite_part(registry, "thesis-all")


def suite_all_large_part(registry) -> list[dict]:
    """``thesis-all`` without its reference column at N = 50 … 200, 2 jobs, the suite's own case limit: the
    part of the sweep that is gaitbench's own, measured where it costs most rather than extrapolated from N ≤ 30."""
    return suite_part(registry, "thesis-all", LARGE_SAMPLE_NODES, (2,), IPOPT_METHODS, 3600)


def suite_all_large_scaled_part(registry) -> list[dict]:
    """``suite-all-large`` with IPOPT's objective scaling: other results, and the sweep's time if adopted."""
    return suite_part(registry, "thesis-all", LARGE_SAMPLE_NODES, (2,), IPOPT_METHODS, 3600, OBJECTIVE_SCALING)


def suite_forward_full_part(registry, ipopt_options: dict | None = None) -> list[dict]:
    """The whole of ``thesis-forward`` (N = 10 … 200) without its reference column, 2 jobs: measured, not
    extrapolated. Its per-case times also give the wall time of the same cases handed out in suite order."""
    rows = suite_part(registry, "thesis-forward", FULL_NODES, (2,), IPOPT_METHODS, 3600, ipopt_options)
    cases = suite_cases("thesis-forward", FULL_NODES, IPOPT_METHODS, ipopt_options)
    for row in rows:
        row["list_schedule_s"] = {"suite order": list_schedule(row["per_case"], row["jobs"], cases),
                                  "largest N first": list_schedule(row["per_case"], row["jobs"], largest_first(cases))}
    return rows


def suite_forward_full_scaled_part(registry) -> list[dict]:
    """``suite-forward-full`` with IPOPT's objective scaling: other results, and the suite's time if adopted."""
    return suite_forward_full_part(registry, OBJECTIVE_SCALING)


def suite_all_rest_part(registry) -> list[dict]:
    """``thesis-all``'s experiments other than forward, whole, without the reference column, 2 jobs. Forward's cases
    are the same as ``thesis-forward``'s, so with ``suite-forward-full``'s rows this measures all of
    ``thesis-all``'s IPOPT part, in two runs; the row records that sum and, from the measured case times, when 2
    workers would finish all of it in the runner's order."""
    rest = tuple(experiment for experiment in ALL_EXPERIMENTS if experiment != "forward")
    rows = suite_part(registry, "thesis-all", FULL_NODES, (2,), IPOPT_METHODS, 3600, experiments=rest)
    forward = json.loads(RESULTS.read_text()).get("suite-forward-full", []) if RESULTS.exists() else []
    if forward:
        row, forward_row = rows[0], forward[0]
        per_case = forward_row["per_case"] + row["per_case"]
        cases = suite_cases("thesis-all", FULL_NODES, IPOPT_METHODS, None)
        row["with_forward"] = {"forward_git_commit": forward_row.get("git_commit"), "cases": len(per_case),
                               "case_time_s": sum(case["wall_s"] for case in per_case),
                               "wall_s_measured_sum": forward_row["wall_s"] + row["wall_s"],
                               "list_schedule_s": list_schedule(per_case, row["jobs"], largest_first(cases))}
    return rows


def suite_cases(suite: str, nodes, methods: tuple[str, ...], ipopt_options: dict | None) -> list[Case]:
    """The cases of ``sampled_suite(suite, nodes, ...)`` with only ``methods``, in suite order."""
    with tempfile.TemporaryDirectory() as scratch:
        suite_file = Path(scratch) / f"{suite}.toml"
        suite_file.write_text(sampled_suite(suite, nodes, 3600, ipopt_options))
        return load_suite(suite_file).with_methods(methods).cases


def list_schedule(per_case: list[dict], jobs: int, order: list[Case]) -> float:
    """When ``jobs`` workers would finish the measured cases, each taking the next case of ``order`` as it frees
    up: a computed schedule, not a run."""
    times = {(row["experiment"], row["N"], row["method"]): row["wall_s"] for row in per_case}
    return makespan([times[case.experiment.name, case.n_nodes, case.method] for case in order], jobs)


def extrapolate(per_case: list[dict], nodes, jobs: int) -> dict:
    """Case time ≈ a·N^b per experiment and method, fitted to the sample; the suite's total over ``nodes``,
    divided by ``jobs`` (perfect packing: a lower bound for the wall time with that many jobs)."""
    fits, total = {}, 0.0
    for experiment, method in sorted({(row["experiment"], row["method"]) for row in per_case}):
        points = [(row["N"], row["wall_s"]) for row in per_case
                  if (row["experiment"], row["method"]) == (experiment, method) and row["wall_s"] > 0]
        if len(points) < 2:
            continue
        slope, intercept = np.polyfit(np.log([n for n, _ in points]), np.log([t for _, t in points]), 1)
        predicted = float(sum(np.exp(intercept) * n**slope for n in nodes))
        fits[f"{experiment} {method}"] = {"exponent": float(slope), "suite_case_time_s": predicted}
        total += predicted
    return {"methods": fits, "case_time_s": total, "wall_s_lower_bound": total / jobs}




PARTS = {"steps": steps_part, "sections": sections_part, "scaling": scaling_part, "walks": walks_part,
         "contact": contact_part, "suite": suite_part, "suite-all": suite_all_part,
         "suite-all-large": suite_all_large_part,
         "suite-all-large-scaled": suite_all_large_scaled_part, "suite-forward-full": suite_forward_full_part,
         "suite-forward-full-scaled": suite_forward_full_scaled_part, "suite-all-rest": suite_all_rest_part,
         "executors": executors_part}


def main(argv: list[str]) -> None:
    chosen = argv or list(PARTS)
    unknown = [part for part in chosen if part not in PARTS]
    if unknown:
        raise SystemExit(f"unknown part(s) {unknown}; choose from {list(PARTS)}")
    registry = load_registry()
    results = json.loads(RESULTS.read_text()) if RESULTS.exists() else {}
    for part in chosen:
        results[part] = PARTS[part](registry)
        results["provenance"] = provenance()
        RESULTS.write_text(json.dumps(results, indent=1, default=float) + "\n")
        SUMMARY.write_text(summary_markdown(results))


if __name__ == "__main__":
    main(sys.argv[1:])
