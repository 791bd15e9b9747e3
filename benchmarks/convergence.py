"""Convergence of the transcriptions against N: ACOT, the objective's agreement with the verified COT, and the
re-simulation error, with observed orders.

Run:    OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/convergence.py [--nodes 10 20 40 80 160]
        [--transcriptions hermite-simpson dmoc dmoc:quadrature=midpoint ...] [--experiment forward] [--steps 3]
        [--solver ipopt] [--summary-only]

One case per transcription and N: the experiment's first ``steps`` steps walked one phase (each step's 4-DOF
problem from the blended guess, from the previous step's heel strike) with the solver's default options, every
step verified as ``gaitbench solve`` verifies it. A transcription may carry options after a colon
(``dmoc:quadrature=midpoint`` is DMOC with its former midpoint-rule cost, one of the "before" rows). Each
case's row replaces the row of the same transcription, N, experiment and steps in
``benchmarks/results/convergence.json``, with the git commit and provenance of the run that produced it;
``convergence.md`` is rewritten from all rows. Re-run it whenever the step problem changes (constraints,
defaults): the summary says which commit each row comes from.

Observed orders are log-log slopes against h = T/(N − 1): of successive differences of the ACOT (a quantity whose
limit is unknown), and of the re-simulation error and the objective gap themselves (which tend to 0 for a
consistent scheme). They are only indicative here: the thesis's net-power cost has a continuum of optima, so the
solver may land on a different member of it at each N.
"""

from __future__ import annotations

import argparse
import json
import math
import time
from pathlib import Path

import numpy as np

from gaitbench.contracts import WalkProblem
from gaitbench.plugins import load_registry
from gaitbench.run.provenance import provenance
from gaitbench.solve.verify import OBJECTIVE_ATOL, OBJECTIVE_RTOL

HERE = Path(__file__).parent
RESULTS = HERE / "results" / "convergence.json"
SUMMARY = HERE / "results" / "convergence.md"
NODES = (10, 20, 40, 80, 160)
TRANSCRIPTIONS = ("hermite-simpson", "trapezoidal", "dmoc", "hermite-simpson:quadrature=boole",
                  "trapezoidal:quadrature=simpson", "dmoc:quadrature=simpson", "trapezoidal:quadrature=trapezoid",
                  "dmoc:quadrature=midpoint")
"""The three transcriptions with their default cost quadrature, then the alternative rules of docs/convergence.md:
Boole for Hermite–Simpson, Simpson for the other two, and the former rules of trapezoidal and DMOC (the
"before")."""
EXPERIMENT = "forward"
STEPS = 3


def parse_label(label: str) -> tuple[str, dict[str, str]]:
    """``name`` or ``name:key=value,key=value`` -> (name, options)."""
    name, _, options = label.partition(":")
    return name, dict(option.split("=", 1) for option in options.split(",") if option)


def run_case(registry, label: str, n_nodes: int, experiment_name: str, steps: int, solver_name: str) -> dict:
    name, options = parse_label(label)
    experiment = registry.create("experiment", experiment_name)
    problem = WalkProblem(experiment, registry.create("transcription", name, **options),
                          registry.create("solver", solver_name), n_nodes, steps=steps)
    started = time.perf_counter()
    walk = registry.create("strategy", "one-phase").solve(problem)
    wall = time.perf_counter() - started
    step_rows = []
    for step in walk.steps:
        check, result = step.verification, step.solver_result
        step_rows.append({
            "index": step.index, "status": step.status,
            "cot": check.cot if check else None,
            "objective_cot": check.objective_cot if check else None,
            "objective_gap": check.objective_gap if check else None,
            "objective_agrees": check.objective_agrees if check else None,
            "resim_error": check.resim_error if check else None,
            "resim_max_error": check.resim_max_error if check else None,
            "max_defect": check.max_defect if check else None,
            "iterations": result.iterations if result else None,
            "solve_time_s": result.wall_time_s if result else None,
        })
    solved = [row for row in step_rows if row["cot"] is not None]
    objective_acot = float(np.mean([row["objective_cot"] for row in solved])) if walk.complete else None
    return {
        "transcription": label, "N": n_nodes, "h": experiment.time_step(n_nodes), "experiment": experiment_name,
        "steps": steps, "solver": solver_name, "strategy": "one-phase", "complete": walk.complete,
        "failure": walk.failure, "acot": walk.acot, "objective_acot": objective_acot,
        "max_abs_gap": max((abs(row["objective_gap"]) for row in solved), default=None),
        "all_agree": all(row["objective_agrees"] for row in solved) if solved else None,
        "max_resim_error": max((row["resim_error"] for row in solved), default=None),
        "max_resim_max_error": max((row["resim_max_error"] for row in solved), default=None),
        "wall_time_s": wall, "step_results": step_rows, "git_commit": provenance()["git_commit"],
    }


def _key(row: dict) -> tuple:
    return row["transcription"], row["N"], row["experiment"], row["steps"], row.get("solver", "ipopt")


def observed_orders(hs: list[float], values: list[float | None], differences: bool) -> list[float | None]:
    """Log-log slopes against h between consecutive N: of |successive differences| (``differences``), whose
    i-th entry relates (N_i, N_i+1) to (N_i+1, N_i+2), or of the values themselves."""
    if differences:
        pairs = [(hs[i], None if values[i] is None or values[i + 1] is None else abs(values[i + 1] - values[i]))
                 for i in range(len(values) - 1)]
        hs, values = [h for h, _ in pairs], [d for _, d in pairs]
    orders = []
    for i in range(len(values) - 1):
        a, b = values[i], values[i + 1]
        if a is None or b is None or a <= 0 or b <= 0:
            orders.append(None)
        else:
            orders.append(math.log(a / b) / math.log(hs[i] / hs[i + 1]))
    return orders


def _number(value, spec: str = ".4f") -> str:
    return "—" if value is None else format(value, spec)


def write_summary(results: dict) -> None:
    rows = results["rows"]
    commits = sorted({row["git_commit"] or "unknown" for row in rows})
    lines = ["# Convergence against N: ACOT, objective against verified COT, re-simulation error", "",
             "Written by `benchmarks/convergence.py` from `convergence.json`; each row comes from the commit shown "
             f"(rows from {', '.join(f'`{c}`' for c in commits)}). One-phase walks, the solver's default options. "
             f"The objective agrees with the verified COT when |gap| ≤ {OBJECTIVE_RTOL:g}, the gap being "
             f"(COT − objective) / max(COT, {OBJECTIVE_ATOL / OBJECTIVE_RTOL:g}).", ""]
    cases = sorted({(row["experiment"], row["steps"], row.get("solver", "ipopt")) for row in rows})
    for experiment, steps, solver in cases:
        lines += [f"## {experiment}, {steps} steps, {solver}", "",
                  "| transcription | N | ACOT | objective ACOT | step COTs | max \\|gap\\| | all agree "
                  "| max resim error | wall (s) | commit |", "|---|---|---|---|---|---|---|---|---|---|"]
        group = [row for row in rows if (row["experiment"], row["steps"], row.get("solver", "ipopt"))
                 == (experiment, steps, solver)]
        labels = list(dict.fromkeys(row["transcription"] for row in group))
        for label in labels:
            for row in sorted((r for r in group if r["transcription"] == label), key=lambda r: r["N"]):
                cots = " / ".join(_number(step["cot"]) for step in row["step_results"])
                status = "" if row["complete"] else f" ({row['failure']})"
                lines.append(f"| {label} | {row['N']} | {_number(row['acot'])}{status} | "
                             f"{_number(row['objective_acot'])} | {cots} | {_number(row['max_abs_gap'], '.3f')} | "
                             f"{row['all_agree']} | {_number(row['max_resim_error'], '.2e')} | "
                             f"{row['wall_time_s']:.1f} | `{(row['git_commit'] or '?')[:9]}` |")
        lines += ["", "Observed orders (log-log slopes against h between consecutive N; for the ACOT, of its "
                  "successive differences):", "",
                  "| transcription | N | ACOT difference | order | max \\|gap\\| order | max resim error order |",
                  "|---|---|---|---|---|---|"]
        for label in labels:
            ordered = sorted((r for r in group if r["transcription"] == label), key=lambda r: r["N"])
            hs = [row["h"] for row in ordered]
            acots = [row["acot"] for row in ordered]
            differences = [None if a is None or b is None else abs(b - a)
                           for a, b in zip(acots, acots[1:], strict=False)]
            acot_orders = observed_orders(hs, acots, differences=True)
            gap_orders = observed_orders(hs, [row["max_abs_gap"] for row in ordered], differences=False)
            resim_orders = observed_orders(hs, [row["max_resim_error"] for row in ordered], differences=False)
            for i in range(1, len(ordered)):
                lines.append(f"| {label} | {ordered[i - 1]['N']}→{ordered[i]['N']} | "
                             f"{_number(differences[i - 1], '.2e')} | "
                             f"{_number(acot_orders[i - 2] if i >= 2 else None, '.2f')} | "
                             f"{_number(gap_orders[i - 1], '.2f')} | {_number(resim_orders[i - 1], '.2f')} |")
        lines.append("")
    SUMMARY.write_text("\n".join(lines))


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--nodes", type=int, nargs="+", default=list(NODES))
    parser.add_argument("--transcriptions", nargs="+", default=list(TRANSCRIPTIONS))
    parser.add_argument("--experiment", default=EXPERIMENT)
    parser.add_argument("--steps", type=int, default=STEPS)
    parser.add_argument("--solver", default="ipopt")
    parser.add_argument("--summary-only", action="store_true", help="rewrite convergence.md from the JSON only")
    args = parser.parse_args(argv)
    results = json.loads(RESULTS.read_text()) if RESULTS.exists() else {"rows": []}
    if not args.summary_only:
        registry = load_registry()
        for label in args.transcriptions:
            for n_nodes in args.nodes:
                row = run_case(registry, label, n_nodes, args.experiment, args.steps, args.solver)
                results["rows"] = [r for r in results["rows"] if _key(r) != _key(row)] + [row]
                results["provenance"] = provenance()
                RESULTS.parent.mkdir(parents=True, exist_ok=True)
                RESULTS.write_text(json.dumps(results, indent=1, default=float) + "\n")
                print(f"{label} N={n_nodes}: ACOT {_number(row['acot'])}, objective {_number(row['objective_acot'])}"
                      f", max |gap| {_number(row['max_abs_gap'], '.3f')}, resim "
                      f"{_number(row['max_resim_error'], '.2e')}, {row['wall_time_s']:.1f} s", flush=True)
    write_summary(results)


if __name__ == "__main__":
    main()
