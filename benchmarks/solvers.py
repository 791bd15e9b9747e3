"""Every solver plugin on the same 4-DOF gait steps: status, time, iterations, verified COT and performance profiles.

Run: .venv/bin/python benchmarks/solvers.py [--time-limit S] [--solvers a,b] [--experiments a,b] [--steps 1,2,6]
[--transcriptions a,b] [--nodes 25,50,100] (writes benchmarks/results/solvers.jsonl, .json, .md and
solvers_profiles.svg). The problems are steps 1, 2 and 6 of every thesis experiment (:data:`EXPERIMENTS`), Second
Phase, with the thesis's cost and the walks' default problem options, each from the transcription's standard initial
guess, for ``hermite-simpson`` and ``dmoc`` at N = 25, 50, 100: 72 problems; the flags pick a subset. A later step
starts from the state where IPOPT's walk (with its retry ladder) leaves the robot, the same for every solver: the
late steps are where solvers that converge on a first step fail. Each solver runs with its defaults, and
:data:`VARIANTS` adds the named presets measured in docs/solvers.md. Every solve has the same time limit and
iteration limit and is one first attempt (no retry ladder); times are wall-clock seconds of the solve call
(including each solver's own build). A converged point is verified as a walk's step is (dynamics residual,
re-simulation, objective gap: :mod:`gaitbench.acceptance`), and only a verified solve counts as solved in the
Dolan–Moré profiles (:mod:`gaitbench.reports.profiles`) of time and of verified COT. Solves run one at a time in a
child process that is stopped at :func:`hard_limit` for solvers that cannot be interrupted (``killed`` rows). Rows
are appended to ``solvers.jsonl`` as they finish, and a rerun skips what is there.
"""

from __future__ import annotations

import argparse
import json
import multiprocessing
import resource
import statistics
import time
from collections import Counter
from concurrent.futures import TimeoutError as FutureTimeout
from pathlib import Path

import numpy as np
from pebble import ProcessPool

from gaitbench.plugins import load_registry
from gaitbench.reports.profiles import performance_ratios, profile, profile_svg
from gaitbench.run.provenance import provenance

EXPERIMENTS = ("forward", "downward-slope", "upward-slope", "stairs")
STEPS = (1, 2, 6)
TRANSCRIPTIONS = ("hermite-simpson", "dmoc")
NODES = (25, 50, 100)
VARIANTS = {"uno filtersqp": ("uno", {"preset": "filtersqp"}), "fatrop dense": ("fatrop", {"stagewise": False})}
"""Labelled solver settings measured beside each solver's defaults: Uno's SQP preset (the open SQP that
docs/decisions/0001-reference-column-sqp.md weighs for the reference column) and FATROP on the NLP as one dense
stage (its default until the stage-wise form became it)."""
OUT = Path(__file__).parent / "results"
UNCOMPARED_STEPS = (("forward", 1),)
"""Steps whose optima are not compared (summary, COT profile): forward step 1 starts at rest, where the thesis cost's
optimum is a continuum near zero and converged solvers end anywhere on it."""
SAME_COT = 5e-4
"""Relative difference of verified COTs counted as the same optimum in the summary."""
TIME_TAUS = (1.0, 2.0, 4.0, 8.0, 16.0)
COT_TAUS = (1 + SAME_COT, 1.05, 1.25, 2.0)
"""The τ at which the Markdown table reads each profile."""
PROFILE_FIGURE = "{stem}_profiles.svg"
CHAIN_LIMIT_S = 900.0
"""Hard limit on IPOPT's walk to a late step's start (a step that climbs the whole retry ladder takes minutes)."""


def hard_limit(time_limit_s: float) -> float:
    """When a solve's process is stopped: twice its own limit (build, verification, a solver late to check its
    clock) plus a margin."""
    return 2 * time_limit_s + 15


def start_states(experiment_name: str, transcription_name: str, n_nodes: int, steps: list[int]) -> dict[int, list]:
    """The state each of ``steps`` starts from: the experiment's start state, then IPOPT's walk with its retry
    ladder; a step the walk cannot reach is left out."""
    from gaitbench.solve.walk import solve_with_retries

    problem = _problem(experiment_name, transcription_name, n_nodes, max(steps))
    built = problem.transcription.build(problem.structure("second"))
    state, states = problem.start_state(), {}
    for index in range(1, max(steps) + 1):
        if index in steps:
            states[index] = [float(value) for value in state]
        if index == max(steps):
            break
        outcome = solve_with_retries(problem, index, built, problem.step_data(index, state))
        if outcome.next_state is None:
            break
        state = outcome.next_state
    return states


def _problem(experiment_name: str, transcription_name: str, n_nodes: int, steps: int):
    from gaitbench.contracts import WalkProblem

    registry = load_registry()
    return WalkProblem(registry.create("experiment", experiment_name),
                       registry.create("transcription", transcription_name), registry.create("solver", "ipopt"),
                       n_nodes, steps=steps)


def solve_one(label: str, solver_name: str, options: dict, experiment_name: str, step: int,
              transcription_name: str, n_nodes: int, start: list[float], time_limit_s: float,
              max_iterations: int) -> dict:
    """Build the step's NLP (afresh, so no solver reuses another solve's build) and solve it once from the state
    ``start``, then verify the result; runs in a child process so a solver that ignores its limit can be stopped."""
    import numpy as np

    from gaitbench.acceptance import Thresholds, step_failures
    from gaitbench.solve.walk import solve_and_verify

    problem = _problem(experiment_name, transcription_name, n_nodes, step)
    built = problem.transcription.build(problem.structure("second"))
    data = problem.step_data(step, np.asarray(start))
    solver = load_registry().create("solver", solver_name, time_limit_s=time_limit_s,
                                    max_iterations=max_iterations, **options)
    started, cpu_started = time.perf_counter(), cpu_seconds()
    outcome = solve_and_verify(problem, step, built, data, solver=solver)
    call_s, cpu_s = time.perf_counter() - started, cpu_seconds() - cpu_started
    result, verification = outcome.solver_result, outcome.verification
    failures = step_failures(verification, Thresholds.for_nodes(n_nodes)) if verification else None
    return {"solver": label, "experiment": experiment_name, "step": step, "transcription": transcription_name,
            "N": n_nodes, "variables": built.nlp.n_variables, "status": result.status.value,
            "message": result.message, "call_s": call_s, "cpu_s": cpu_s, "wall_time_s": result.wall_time_s,
            "function_time_s": result.function_time_s, "iterations": result.iterations, "cot": result.objective,
            "violation": result.constraint_violation,
            "verified_cot": verification.cot if verification else None,
            "max_defect": verification.max_defect if verification else None,
            "verified": failures == [], "verification_failures": failures}


def cpu_seconds() -> float:
    """CPU seconds this process and its finished children (an NL executable) have used: unlike wall time, not
    stretched by other processes on a shared machine."""
    own, children = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + children.ru_utime + children.ru_stime


def run(solvers: dict[str, tuple[str, dict]], problems: list[tuple], time_limit_s: float, max_iterations: int,
        log: Path, commit: str) -> list[dict]:
    """Every (problem, solver) not yet in ``log`` (JSON lines, appended as each finishes), then all rows;
    ``problems`` are (experiment, step, transcription, N), solved in that order, one solve at a time."""
    done = [json.loads(line) for line in log.read_text().splitlines()] if log.exists() else []
    seen = {_key(row) for row in done}
    todo = [(problem, label) for problem in problems for label in solvers if (label, *problem) not in seen]
    starts: dict[tuple, dict[int, list]] = {}
    with ProcessPool(max_workers=1, context=multiprocessing.get_context("spawn")) as pool:
        for (experiment, step, transcription, n_nodes), label in todo:
            walk = (experiment, transcription, n_nodes)
            if walk not in starts:
                steps = sorted({p[1] for p, _ in todo if (p[0], p[2], p[3]) == walk})
                starts[walk] = pool.schedule(start_states, (*walk, steps), timeout=CHAIN_LIMIT_S).result()
            if step not in starts[walk]:
                print(f"{experiment} {transcription} N={n_nodes}: IPOPT's walk does not reach step {step}; skipped",
                      flush=True)
                continue
            solver_name, options = solvers[label]
            where = {"solver": label, "experiment": experiment, "step": step, "transcription": transcription,
                     "N": n_nodes}
            future = pool.schedule(solve_one, (label, solver_name, options, experiment, step, transcription,
                                               n_nodes, starts[walk][step], time_limit_s, max_iterations),
                                   timeout=hard_limit(time_limit_s))
            try:
                row = future.result()
            except FutureTimeout:
                row = _failed(where, "killed", f"ignored its {time_limit_s:g} s time limit; stopped after "
                              f"{hard_limit(time_limit_s):g} s", hard_limit(time_limit_s))
            except Exception as error:  # the child died (a crash in a solver's library) or raised
                row = _failed(where, "crashed", f"{type(error).__name__}: {error}", None)
            row["commit"] = commit
            with log.open("a") as stream:
                stream.write(json.dumps(row) + "\n")
            print(json.dumps(row), flush=True)
            done.append(row)
    return done


def _failed(where: dict, status: str, message: str, call_s: float | None) -> dict:
    return where | {"variables": None, "status": status, "message": message, "call_s": call_s, "cpu_s": None,
                    "wall_time_s": None, "function_time_s": None, "iterations": None, "cot": None,
                    "violation": None, "verified_cot": None, "max_defect": None, "verified": False,
                    "verification_failures": None}


def _key(row: dict) -> tuple:
    return row["solver"], row["experiment"], row["step"], row["transcription"], row["N"]


def markdown(results: dict, figure: str = PROFILE_FIGURE.format(stem="solvers")) -> str:
    limits, machine = results["limits"], results["machine"]
    packages = ", ".join(f"{name} {ver}" for name, ver in machine["packages"].items() if ver)
    rows = results["rows"]
    lines = ["# Solvers on 4-DOF gait steps (steps 1, 2 and 6 of each experiment; thesis cost)", "",
             f"Machine: {machine['cpus']} CPUs ({machine.get('cpu', '?')}), {machine['platform']}, Python "
             f"{machine['python']}; gaitbench {machine['gaitbench']}, measured at "
             f"{', '.join(sorted({row.get('commit') or machine['git_commit'] for row in rows}))}; {packages}.", "",
             f"Problems: {_problem_set(rows)}; {len({_step(row) for row in rows})} problems × "
             f"{len({row['solver'] for row in rows})} solvers, {len(rows)} solves"
             + (f" (the last invocation: {results['run_wall_s'] / 60:.0f} min of wall time)."
                if results.get("run_wall_s") else "."),
             "", *([results["note"], ""] if results.get("note") else []),
             f"Limits per solve: {limits['time_limit_s']} s, {limits['max_iterations']} iterations. "
             "`COT` is the optimizer's objective at the returned point, `verified COT` the COT recomputed from the "
             "decoded trajectory of a converged solve, with its largest dynamics residual; `verified`: the solve "
             "passed the walks' verification (gaitbench/acceptance.py), or why not; time is the wall-clock time of "
             "the solve call, CPU the CPU time of its process and of the executable it ran (the profiles' measure, "
             "less stretched by other processes on a shared machine); `killed`: the solver ignored its time limit "
             "and its process was stopped. Steps 2 and 6 start where IPOPT's walk (with its retry ladder) leaves "
             "the robot.", "", *_load_note(rows, limits["time_limit_s"]), *summary(rows), "",
             f"Verified COTs within {100 * SAME_COT:g} % of each other count as the same optimum.", "",
             *profile_section(rows, figure), "",
             "| step | transcription | N | solver | status | time (s) | CPU (s) | iterations | COT | verified COT | "
             "dynamics residual | verified |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    order = {experiment: i for i, experiment in enumerate(EXPERIMENTS)}
    for r in sorted(rows, key=lambda r: (order.get(r["experiment"], 99), r["step"], r["transcription"], r["N"],
                                         r["solver"])):
        verdict = "yes" if r.get("verified") else "; ".join(r.get("verification_failures") or []) or "—"
        lines.append(f"| {r['experiment']} {r['step']} | {r['transcription']} | {r['N']} | {r['solver']} | "
                     f"{r['status']} | {_number(r['call_s'], '.2f')} | {_number(r.get('cpu_s'), '.2f')} | "
                     f"{_number(r['iterations'], 'd')} | "
                     f"{_number(r['cot'], '.4g')} | {_number(r.get('verified_cot'), '.4g')} | "
                     f"{_number(r.get('max_defect'), '.1e')} | {verdict} |")
    return "\n".join(lines) + "\n"


def _load_note(rows: list[dict], time_limit_s: float) -> list[str]:
    """How much of a core the solves got (their CPU time over their wall time, median over the rows that have
    both), and so what CPU time the wall-clock limit allowed; nothing when the solves had a core each."""
    shares = sorted(row["cpu_s"] / row["call_s"] for row in rows if row.get("cpu_s") and row.get("call_s"))
    share = statistics.median(shares) if shares else 1.0
    if share > 0.9:
        return []
    return [f"The solves got a median {100 * share:.0f} % of a core (CPU time over wall time; other processes "
            f"shared the machine), so the {time_limit_s:g} s wall-clock limit allowed about {share * time_limit_s:.0f}"
            " CPU seconds: `time_limit` and `killed` rows depend on that load, statuses of finished solves, "
            "iterations and COTs do not.", ""]


def _problem_set(rows: list[dict]) -> str:
    """The experiments, steps, transcriptions and N of ``rows``, each as a list."""
    def listed(field: str) -> str:
        return ", ".join(map(str, sorted({row[field] for row in rows}, key=str)))
    return (f"experiments {listed('experiment')}; steps {listed('step')}; {listed('transcription')}; "
            f"N = {', '.join(map(str, sorted({row['N'] for row in rows})))}")


def profiled_solvers(rows: list[dict]) -> tuple[list[str], list[str]]:
    """The solvers the profiles compare, and those left out: a solver (a variant, say) run on fewer than half the
    problems that the most-run solver ran would shrink the common problem set to its few."""
    counts = Counter(row["solver"] for row in rows)
    most = max(counts.values(), default=0)
    return (sorted(solver for solver, count in counts.items() if 2 * count >= most),
            sorted(solver for solver, count in counts.items() if 2 * count < most))


def profile_ratios(rows: list[dict]) -> tuple[int, int, dict[str, dict]]:
    """The Dolan–Moré ratios of time and of verified COT over the problems every profiled solver ran
    (:func:`profiled_solvers`; a solve counts when it converged and was verified; COT on every step but
    :data:`UNCOMPARED_STEPS`): the two problem counts and, per panel label, each solver's ratios."""
    solvers = profiled_solvers(rows)[0]
    by_key = {_key(row): row for row in rows}
    problems = sorted({_step(row) for row in rows if all((solver, *_step(row)) in by_key for solver in solvers)},
                      key=str)
    compared = [problem for problem in problems if (problem[0], problem[1]) not in UNCOMPARED_STEPS]

    def measures(field: str, among: list[tuple]) -> dict[str, list]:
        return {solver: [by_key[(solver, *problem)][field] if by_key[(solver, *problem)].get("verified") else None
                         for problem in among] for solver in solvers}

    return len(problems), len(compared), {
        "time ratio τ (CPU time / best CPU time on the problem)": performance_ratios(measures("cpu_s", problems)),
        "COT ratio τ (verified COT / best verified COT)": performance_ratios(measures("verified_cot", compared))}


def profile_section(rows: list[dict], figure: str = PROFILE_FIGURE.format(stem="solvers")) -> list[str]:
    """The profiles' figure and their values at a few τ, as Markdown lines."""
    n_time, n_cot, panels = profile_ratios(rows)
    time_ratios, cot_ratios = panels.values()
    left_out = profiled_solvers(rows)[1]
    omitted = (f" Left out, run on too few of the problems: {', '.join(f'`{solver}`' for solver in left_out)}."
               if left_out else "")
    lines = [f"Performance profiles (Dolan–Moré): the share of problems a solver solved (converged and verified) "
             f"within τ × the best solver's time ({n_time} problems that every solver ran), and within τ × the best "
             f"verified COT ({n_cot} of them, forward step 1 left out). A solver's curve starts at the share where "
             f"it was best and ends at the share it solved.{omitted}", "", f"![performance profiles]({figure})", "",
             "| solver | verified | " + " | ".join(f"time ≤ {tau:g}×" for tau in TIME_TAUS) + " | "
             + " | ".join(f"COT ≤ {tau:g}×" for tau in COT_TAUS) + " |",
             "|---|---|" + "---|" * (len(TIME_TAUS) + len(COT_TAUS))]
    solved = {solver: int(np.isfinite(ratios).sum()) for solver, ratios in time_ratios.items()}
    for solver in sorted(time_ratios, key=lambda solver: (-solved[solver], solver)):
        shares = [*profile(time_ratios[solver], TIME_TAUS), *profile(cot_ratios[solver], COT_TAUS)]
        lines.append(f"| `{solver}` | {solved[solver]} of {n_time} | "
                     + " | ".join(f"{100 * share:.0f} %" for share in shares) + " |")
    return lines


def summary(rows: list[dict], reference: str = "ipopt") -> list[str]:
    """Per solver: how many steps it solved and how many of those passed verification, its CPU time against
    ``reference``'s where both converged, its verified COT against ``reference``'s on every step but
    :data:`UNCOMPARED_STEPS`, and how the other solves ended; a Markdown table."""
    by_solver: dict[str, list[dict]] = {}
    for row in rows:
        by_solver.setdefault(row["solver"], []).append(row)
    theirs = {_step(row): row for row in by_solver.get(reference, []) if row["status"] == "converged"}
    lines = [f"| solver | converged | verified | CPU time against `{reference}` where both converged (median, range) "
             f"| verified COT against `{reference}` (all but forward step 1) | how the others end |",
             "|---|---|---|---|---|---|"]
    ranked = sorted(by_solver.items(), key=lambda item: (item[0] != reference,
                                                         -sum(r["status"] == "converged" for r in item[1]), item[0]))
    for label, solved in ranked:
        both = [(row, theirs[_step(row)]) for row in solved if row["status"] == "converged" and _step(row) in theirs]
        ratios = [_seconds(row) / _seconds(ref) for row, ref in both]
        time_text = "—" if not ratios else "1×" if label == reference else (
            f"{statistics.median(ratios):.1f}× ({min(ratios):.1f}–{max(ratios):.1f}×)")
        changes = [row["verified_cot"] / ref["verified_cot"] - 1 for row, ref in both
                   if (row["experiment"], row["step"]) not in UNCOMPARED_STEPS and row.get("verified_cot")
                   and ref.get("verified_cot")]
        ends = Counter(row["status"] for row in solved if row["status"] != "converged")
        lines.append(f"| `{label}` | {len(solved) - sum(ends.values())} of {len(solved)} | "
                     f"{sum(bool(row.get('verified')) for row in solved)} | {time_text} | "
                     f"{'—' if label == reference else _cot_changes(changes)} | "
                     f"{', '.join(f'{status} {count}' for status, count in sorted(ends.items())) or '—'} |")
    return lines


def _seconds(row: dict) -> float:
    """A solve's CPU time, or its wall time in rows recorded without it."""
    return row["cpu_s"] if row.get("cpu_s") is not None else row["call_s"]


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
    parser.add_argument("--experiments", default=",".join(EXPERIMENTS), help="comma-separated experiments")
    parser.add_argument("--steps", default=",".join(map(str, STEPS)), help="comma-separated step numbers")
    parser.add_argument("--transcriptions", default=",".join(TRANSCRIPTIONS), help="comma-separated transcriptions")
    parser.add_argument("--nodes", default=",".join(map(str, NODES)), help="comma-separated N values")
    parser.add_argument("--time-limit", type=float, default=20.0, help="seconds per solve")
    parser.add_argument("--max-iterations", type=int, default=3000)
    parser.add_argument("--out", default="solvers", help="file stem under benchmarks/results")
    parser.add_argument("--note", help="a line for the summary, e.g. what else ran on the machine")
    parser.add_argument("--render-only", action="store_true",
                        help="rewrite the .md and the figure from the recorded .json, solving nothing")
    args = parser.parse_args()
    if args.render_only:
        results = json.loads((OUT / f"{args.out}.json").read_text())
        results["note"] = args.note or results.get("note")
    else:
        solvers = {name: (name, {}) for name in load_registry().names("solver")} | VARIANTS
        if args.solvers:
            solvers = {label: solvers.get(label, (label, {})) for label in args.solvers.split(",")}
        problems = [(experiment, int(step), transcription, int(n_nodes)) for n_nodes in args.nodes.split(",")
                    for experiment in args.experiments.split(",") for step in args.steps.split(",")
                    for transcription in args.transcriptions.split(",")]
        machine = provenance()
        OUT.mkdir(exist_ok=True)
        log = OUT / f"{args.out}.jsonl"
        recorded = len(log.read_text().splitlines()) if log.exists() else 0
        started = time.perf_counter()
        rows = run(solvers, problems, args.time_limit, args.max_iterations, log, machine["git_commit"])
        results = {"machine": machine, "limits": {"time_limit_s": args.time_limit,
                                                  "max_iterations": args.max_iterations}, "note": args.note,
                   "run_wall_s": time.perf_counter() - started if len(rows) > recorded else None, "rows": rows}
    (OUT / f"{args.out}.json").write_text(json.dumps(results, indent=2))
    (OUT / f"{args.out}.md").write_text(markdown(results, PROFILE_FIGURE.format(stem=args.out)))
    (OUT / PROFILE_FIGURE.format(stem=args.out)).write_text(profile_svg(profile_ratios(results["rows"])[2]))


if __name__ == "__main__":
    main()
