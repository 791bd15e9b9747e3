"""Every solver plugin on the same 4-DOF gait steps: status, time, iterations and verified COT.

Run: .venv/bin/python benchmarks/solvers.py [--time-limit S] [--solvers a,b] [--nodes 25,50,100]
(writes benchmarks/results/solvers.json and .md). The steps are forward steps 1 and 2 and upward-slope step 1,
Second Phase, with the thesis's cost and the walks' default problem options, each from the transcription's
standard initial guess, for ``hermite-simpson`` and ``dmoc`` at N = 25, 50, 100. Step 2 starts from the heel-strike
state of step 1 as IPOPT solves it, the same for every solver: the late steps are where solvers that converge on a
first step fail. Each solver runs with its defaults, and :data:`VARIANTS` adds the named presets measured in
docs/solvers.md. Every solve has the same time limit and iteration limit; times are wall-clock seconds of the solve
call (including each solver's own build). A converged point is verified as a walk's step is (dynamics residual,
re-simulation, COT recomputed from the trajectory). Each solve runs in a child process that is stopped at 1.5 × the
time limit + 60 s, for solvers that cannot be interrupted (``killed`` rows). Rows are appended to ``solvers.jsonl``
as they finish, and a rerun skips what is there.
"""

from __future__ import annotations

import argparse
import json
import multiprocessing
import statistics
import time
from collections import Counter
from concurrent.futures import TimeoutError as FutureTimeout
from pathlib import Path

from pebble import ProcessPool

from gaitbench.plugins import load_registry
from gaitbench.run.provenance import provenance

STEPS = (("forward", 1), ("forward", 2), ("upward-slope", 1))
TRANSCRIPTIONS = ("hermite-simpson", "dmoc")
NODES = (25, 50, 100)
VARIANTS = {"uno filtersqp": ("uno", {"preset": "filtersqp"}), "fatrop dense": ("fatrop", {"stagewise": False})}
"""Labelled solver settings measured beside each solver's defaults: Uno's SQP preset (the open SQP that DECISIONS
§10 names for the reference column) and FATROP on the NLP as one dense stage (its default until 2026-12-03, when
the stage-wise form became it: the run of that day labels them "fatrop" and "fatrop stagewise")."""
OUT = Path(__file__).parent / "results"
COMPARED_STEPS = (("forward", 2), ("upward-slope", 1))
"""The steps whose optima the summary compares with IPOPT's: forward step 1 starts at rest, where the thesis cost's
optimum is a continuum near zero and converged solvers end anywhere on it."""
SAME_COT = 5e-4
"""Relative difference of verified COTs counted as the same optimum in the summary."""


def solve_one(label: str, solver_name: str, options: dict, experiment_name: str, step: int,
              transcription_name: str, n_nodes: int, time_limit_s: float, max_iterations: int) -> dict:
    """Build the step's NLP and solve it once, then verify the result; runs in a child process so a solver that
    ignores its limit can be stopped."""
    from gaitbench.contracts import WalkProblem
    from gaitbench.solve.walk import solve_and_verify

    registry = load_registry()
    ipopt = registry.create("solver", "ipopt")
    problem = WalkProblem(registry.create("experiment", experiment_name),
                          registry.create("transcription", transcription_name), ipopt, n_nodes, steps=step)
    built = problem.transcription.build(problem.structure("second"))
    state = problem.start_state()
    for index in range(1, step):  # the start of a later step: IPOPT's walk up to it, the same for every solver
        state = solve_and_verify(problem, index, built, problem.step_data(index, state)).next_state
    data = problem.step_data(step, state)
    solver = registry.create("solver", solver_name, time_limit_s=time_limit_s, max_iterations=max_iterations,
                             **options)
    started = time.perf_counter()
    outcome = solve_and_verify(problem, step, built, data, solver=solver)
    result, verification = outcome.solver_result, outcome.verification
    return {"solver": label, "experiment": experiment_name, "step": step, "transcription": transcription_name,
            "N": n_nodes, "variables": built.nlp.n_variables, "status": result.status.value,
            "message": result.message, "call_s": time.perf_counter() - started, "wall_time_s": result.wall_time_s,
            "function_time_s": result.function_time_s, "iterations": result.iterations, "cot": result.objective,
            "violation": result.constraint_violation,
            "verified_cot": verification.cot if verification else None,
            "max_defect": verification.max_defect if verification else None}


def run(solvers: dict[str, tuple[str, dict]], nodes, time_limit_s, max_iterations, log: Path) -> list[dict]:
    """Every (step, transcription, N, solver) not yet in ``log`` (JSON lines, appended as each finishes), then all."""
    done = [json.loads(line) for line in log.read_text().splitlines()] if log.exists() else []
    seen = {_key(row) for row in done}
    hard_limit = 1.5 * time_limit_s + 60  # the solve's own limit, plus the build and a margin
    for experiment, step in STEPS:
        for transcription in TRANSCRIPTIONS:
            for n_nodes in nodes:
                for label, (solver_name, options) in solvers.items():
                    where = {"solver": label, "experiment": experiment, "step": step, "transcription": transcription,
                             "N": n_nodes}
                    if _key(where) in seen:
                        continue
                    with ProcessPool(max_workers=1, context=multiprocessing.get_context("spawn")) as pool:
                        future = pool.schedule(solve_one, (label, solver_name, options, experiment, step,
                                                           transcription, n_nodes, time_limit_s, max_iterations),
                                               timeout=hard_limit)
                        try:
                            row = future.result()
                        except FutureTimeout:
                            row = where | {
                                "variables": None, "status": "killed",
                                "message": f"ignored its {time_limit_s:g} s time limit; stopped after {hard_limit:g} s",
                                "call_s": hard_limit, "wall_time_s": None, "function_time_s": None,
                                "iterations": None, "cot": None, "violation": None, "verified_cot": None,
                                "max_defect": None}
                    with log.open("a") as stream:
                        stream.write(json.dumps(row) + "\n")
                    print(json.dumps(row), flush=True)
                    done.append(row)
    return done


def _key(row: dict) -> tuple:
    return row["solver"], row["experiment"], row["step"], row["transcription"], row["N"]


def markdown(results: dict) -> str:
    limits, machine = results["limits"], results["machine"]
    packages = ", ".join(f"{name} {ver}" for name, ver in machine["packages"].items() if ver)
    lines = ["# Solvers on 4-DOF gait steps (forward steps 1–2, upward-slope step 1; thesis cost)", "",
             f"Machine: {machine['cpus']} CPUs, {machine['platform']}, Python {machine['python']}; gaitbench "
             f"{machine['gaitbench']} at {machine['git_commit']}; {packages}.", "",
             *([results["note"], ""] if results.get("note") else []),
             f"Limits per solve: {limits['time_limit_s']} s, {limits['max_iterations']} iterations. "
             "`COT` is the optimizer's objective at the returned point, `verified COT` the COT recomputed from the "
             "decoded trajectory of a converged solve, with its largest dynamics residual; time is the wall-clock "
             "time of the solve call; `killed`: the solver ignored its time limit and its process was stopped. "
             "Step 2 starts where IPOPT's step 1 ends.", "", *summary(results["rows"]), "",
             f"Verified COTs within {100 * SAME_COT:g} % of each other count as the same optimum.", "",
             "| step | transcription | N | solver | status | time (s) | iterations | COT | verified COT | "
             "dynamics residual |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    order = {step: i for i, step in enumerate(STEPS)}
    rows = sorted(results["rows"], key=lambda r: (order.get((r["experiment"], r["step"]), 99), r["transcription"],
                                                  r["N"], r["solver"]))
    for r in rows:
        lines.append(f"| {r['experiment']} {r['step']} | {r['transcription']} | {r['N']} | {r['solver']} | "
                     f"{r['status']} | {r['call_s']:.2f} | {_number(r['iterations'], 'd')} | "
                     f"{_number(r['cot'], '.4g')} | {_number(r.get('verified_cot'), '.4g')} | "
                     f"{_number(r.get('max_defect'), '.1e')} |")
    return "\n".join(lines) + "\n"


def summary(rows: list[dict], reference: str = "ipopt") -> list[str]:
    """Per solver: how many steps it solved, its time against ``reference``'s where both converged, its verified
    COT against ``reference``'s on :data:`COMPARED_STEPS`, and how the other solves ended; a Markdown table."""
    by_solver: dict[str, list[dict]] = {}
    for row in rows:
        by_solver.setdefault(row["solver"], []).append(row)
    theirs = {_step(row): row for row in by_solver.get(reference, []) if row["status"] == "converged"}
    lines = [f"| solver | converged | time against `{reference}` where both converged (median, range) | verified COT "
             f"against `{reference}` on forward step 2 and upward step 1 | how the others end |",
             "|---|---|---|---|---|"]
    ranked = sorted(by_solver.items(), key=lambda item: (item[0] != reference,
                                                         -sum(r["status"] == "converged" for r in item[1]), item[0]))
    for label, solved in ranked:
        both = [(row, theirs[_step(row)]) for row in solved if row["status"] == "converged" and _step(row) in theirs]
        ratios = [row["call_s"] / ref["call_s"] for row, ref in both]
        time_text = "—" if not ratios else "1×" if label == reference else (
            f"{statistics.median(ratios):.1f}× ({min(ratios):.1f}–{max(ratios):.1f}×)")
        changes = [row["verified_cot"] / ref["verified_cot"] - 1 for row, ref in both
                   if (row["experiment"], row["step"]) in COMPARED_STEPS and row.get("verified_cot")
                   and ref.get("verified_cot")]
        ends = Counter(row["status"] for row in solved if row["status"] != "converged")
        lines.append(f"| `{label}` | {len(solved) - sum(ends.values())} of {len(solved)} | {time_text} | "
                     f"{'—' if label == reference else _cot_changes(changes)} | "
                     f"{', '.join(f'{status} {count}' for status, count in sorted(ends.items())) or '—'} |")
    return lines


def _step(row: dict) -> tuple:
    """The step a row solved (its key without the solver)."""
    return _key(row)[1:]


def _cot_changes(changes: list[float]) -> str:
    """Relative COT differences as "the same on k, a % to b % on m"."""
    same = sum(abs(change) < SAME_COT for change in changes)
    other = sorted(change for change in changes if abs(change) >= SAME_COT)
    parts = [f"the same on {same}"] if same else []
    if other:
        span = f"{100 * other[0]:+.1f} %" + (f" to {100 * other[-1]:+.1f} %" if len(other) > 1 else "")
        parts.append(f"{span} on {len(other)}")
    return ", ".join(parts) or "none compared"


def _number(value, spec: str) -> str:
    return "—" if value is None else format(value, spec)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--solvers", help="comma-separated solver names or VARIANTS labels "
                        "(default: every registered solver and every variant)")
    parser.add_argument("--nodes", default=",".join(map(str, NODES)), help="comma-separated N values")
    parser.add_argument("--time-limit", type=float, default=60.0, help="seconds per solve")
    parser.add_argument("--max-iterations", type=int, default=3000)
    parser.add_argument("--out", default="solvers", help="file stem under benchmarks/results")
    parser.add_argument("--note", help="a line for the summary, e.g. what else ran on the machine")
    args = parser.parse_args()
    solvers = {name: (name, {}) for name in load_registry().names("solver")} | VARIANTS
    if args.solvers:
        solvers = {label: solvers.get(label, (label, {})) for label in args.solvers.split(",")}
    nodes = [int(n) for n in args.nodes.split(",")]
    OUT.mkdir(exist_ok=True)
    rows = run(solvers, nodes, args.time_limit, args.max_iterations, OUT / f"{args.out}.jsonl")
    results = {"machine": provenance(), "limits": {"time_limit_s": args.time_limit,
                                                "max_iterations": args.max_iterations},
               "note": args.note, "rows": rows}
    (OUT / f"{args.out}.json").write_text(json.dumps(results, indent=2))
    (OUT / f"{args.out}.md").write_text(markdown(results))


if __name__ == "__main__":
    main()
