"""Sections warm-started from their neighbour: fewer iterations, and which optima?

Run:    OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/section_warm_start.py EXPERIMENT TRANSCRIPTION N STEP
        .venv/bin/python benchmarks/section_warm_start.py --summarize

Decrease and conquer solves the sections k0 = 2 … N − 2 of a step independently, each from the First Phase
trajectory's tail (the thesis's guess), which lets them fan out over workers. Section k0 + 1 is section k0 less its
first interval, so section k0's solution, one node on, is a guess close to it: this measures what that buys. Steps
1 … STEP − 1 are walked by decrease and conquer itself, so step STEP starts from the chained, verified post-impact
state, as in a sweep; its sections are then solved twice by the strategy's section solver (adaptive μ): each from
the First Phase tail, and in order of k0, each from the last converged section's solution (the first, and any
before a section converged, from the tail).

Appends a record to benchmarks/results/section_warm_start.jsonl: per mode the sections converged, iterations and CPU
seconds, and per section both objectives, so that which optima the warm start reaches can be read beside its speed.
``--summarize`` prints the records as the table of docs/decisions/0020-section-warm-start.md.
"""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path

import numpy as np
from dc_profile import ipopt_walk  # its sibling in benchmarks/

from gaitbench.contracts import WalkProblem
from gaitbench.plugins import load_registry
from gaitbench.problem.gait_problem import StepData, sectional_structure
from gaitbench.run.provenance import provenance
from gaitbench.solve.solver import prepare, section_solver
from gaitbench.solve.walk import solve_with_retries

OUT = Path(__file__).parent / "results" / "section_warm_start.jsonl"


def chained_step(experiment_name: str, transcription: str, n_nodes: int, step: int):
    """The walk problem and step ``step``'s data, from the post-impact state of decrease and conquer's step − 1."""
    problem = ipopt_walk(experiment_name, transcription, n_nodes, step)
    state = problem.start_state()
    if step > 1:
        before = ipopt_walk(experiment_name, transcription, n_nodes, step - 1)
        walk = load_registry().create("strategy", "decrease-and-conquer").solve(before)
        if not walk.complete:
            raise SystemExit(f"decrease and conquer did not walk steps 1–{step - 1}: {walk.failure}")
        state = walk.steps[-1].next_state
    return problem, problem.step_data(step, state)


def solve_sections(problem: WalkProblem, step: int, data: StepData) -> dict:
    """Every section of the step solved from the First Phase tail and from its converged neighbour."""
    first = solve_with_retries(problem, step, problem.transcription.build(problem.structure("first")), data,
                               phase="first")
    if not first.solved:
        raise SystemExit(f"step {step}: the First Phase failed: {first.message}")
    solver, h = section_solver(problem.solver), data.time_step
    starts = range(2, problem.n_nodes - 1)
    built = {k0: problem.transcription.build(sectional_structure(problem.structure("second"), k0)) for k0 in starts}
    tail = first.trajectory
    section_data = {k0: StepData(data.robot, data.stance, np.r_[tail.q[k0 - 1], tail.dq[k0 - 1]], data.chord,
                                 data.slope, h, data.previous_slope) for k0 in starts}
    for k0 in starts:
        prepare(solver, built[k0].nlp)

    modes: dict[str, list[dict]] = {"first-phase tail": [], "neighbour": []}
    last = None  # (k0, trajectory) of the last converged section in neighbour mode
    for k0 in starts:
        for mode in modes:
            if mode == "neighbour" and last is not None:
                seed = last[1].seed((k0 - last[0]) * h)
            else:
                seed = tail.seed((k0 - 1) * h)
            guess = built[k0].initial_guess(section_data[k0], seed)
            cpu = time.process_time()
            result = solver.solve(built[k0].nlp, section_data[k0].parameter_vector(), guess)
            modes[mode].append({"k0": k0, "status": result.status.value, "iterations": result.iterations,
                                "cpu_s": time.process_time() - cpu,
                                "objective": result.objective if result.converged else None})
            if mode == "neighbour" and result.converged:
                last = (k0, built[k0].trajectory(result.x, section_data[k0]))
    return modes


def summary(modes: dict[str, list[dict]]) -> dict:
    """Per mode: sections converged, iterations and CPU time; and how the objectives of the sections both modes
    solved compare: how many the warm start took lower or higher (beyond 1e-6 relative), and the sums."""
    table = {mode: {"converged": sum(row["status"] == "converged" for row in rows),
                    "sections": len(rows), "iterations": sum(row["iterations"] for row in rows),
                    "cpu_s": round(sum(row["cpu_s"] for row in rows), 2)} for mode, rows in modes.items()}
    pairs = [(a["objective"], b["objective"]) for a, b in zip(*modes.values(), strict=True)
             if a["objective"] is not None and b["objective"] is not None]
    scale = [max(abs(a), 1e-12) for a, _ in pairs]
    changes = [(b - a) / s for (a, b), s in zip(pairs, scale, strict=True)]
    table["objectives"] = {"both converged": len(pairs), "neighbour lower": sum(c < -1e-6 for c in changes),
                           "neighbour higher": sum(c > 1e-6 for c in changes),
                           "sum, first-phase tail": sum(a for a, _ in pairs),
                           "sum, neighbour": sum(b for _, b in pairs)}
    return table


def summary_table(records: list[dict]) -> str:
    """One row per step measured, and the totals."""
    lines = ["| step | iterations: tail, neighbour | CPU s: tail, neighbour | converged: tail, neighbour "
             "| objectives lower, higher |", "|---|---|---|---|---|"]
    total = dict.fromkeys(("ti", "ni", "tc", "nc", "tk", "nk", "lower", "higher"), 0.0)
    for record in records:
        tail, neighbour, objectives = (record["summary"][key] for key in ("first-phase tail", "neighbour",
                                                                           "objectives"))
        row = {"ti": tail["iterations"], "ni": neighbour["iterations"], "tc": tail["cpu_s"], "nc": neighbour["cpu_s"],
               "tk": tail["converged"], "nk": neighbour["converged"], "lower": objectives["neighbour lower"],
               "higher": objectives["neighbour higher"]}
        total = {key: total[key] + value for key, value in row.items()}
        name = f"{record['experiment']} {record['transcription']}, N = {record['N']}, step {record['step']}"
        lines.append(_row(name, row, tail["sections"]))
    lines.append(_row("all", total, None))
    return "\n".join(lines)


def _row(name: str, row: dict, sections: int | None) -> str:
    of = f" of {sections}" if sections else ""
    return (f"| {name} | {row['ti']:,.0f}, {row['ni']:,.0f} ({row['ni'] / row['ti'] - 1:+.0%}) | "
            f"{row['tc']:.1f}, {row['nc']:.1f} ({row['nc'] / row['tc'] - 1:+.0%}) | "
            f"{row['tk']:.0f}, {row['nk']:.0f}{of} | {row['lower']:.0f}, {row['higher']:.0f} |")


def main(argv: list[str]) -> None:
    if argv[:1] == ["--summarize"]:
        print(summary_table([json.loads(line) for line in OUT.read_text().splitlines() if line.strip()]))
        return
    experiment, transcription, n_nodes, step = argv[0], argv[1], int(argv[2]), int(argv[3])
    problem, data = chained_step(experiment, transcription, n_nodes, step)
    modes = solve_sections(problem, step, data)
    record = {"experiment": experiment, "transcription": transcription, "N": n_nodes, "step": step,
              "summary": summary(modes), "sections": modes, "provenance": provenance()}
    with OUT.open("a") as out:
        out.write(json.dumps(record) + "\n")
    print(json.dumps(record["summary"], indent=1))
    print(f"appended to {OUT}")


if __name__ == "__main__":
    main(sys.argv[1:])
