"""Speed-ups must not change results: the ACOT of a fixed case set against a recorded baseline.

Run:    .venv/bin/python benchmarks/acot_regression.py            (compare; exit status 1 on any difference)
        .venv/bin/python benchmarks/acot_regression.py --record   (write the baseline; do this only before a change,
                        or after a change kept for what it does to the results, with --reason "one line why")
        .venv/bin/python benchmarks/acot_regression.py --record-band 6   (add the rounding band; same commit)
        .venv/bin/python benchmarks/acot_regression.py --solver-option nlp_scaling_obj_target_gradient=1
                        (what a solver option does to the results: the same comparison, with the option on every case)

The case set is ``benchmarks/suites/regression.toml``, solved in this process case by case with the suite
runner's own ``run_case`` and one build cache, as a suite's worker solves its cases, so every layer a suite run goes
through (builds, caches, strategies, verification) is exercised. A case differs when its status changes or when its
ACOT (the verified one for decrease-and-conquer) or its claimed ACOT moves by more than ``--tolerance``: IPOPT stops
at a KKT error of 1e-8, so a faster core that computes the same problem lands within about that of the same
optimum. Each comparison is appended to ``benchmarks/results/acot_regression.jsonl`` with the commit it ran at, so
the history of checks is kept.

Rounding band. These step problems do not determine their solution beyond rounding: the cost is the total
variation of mechanical energy, whose optima form a continuum (docs/deviations.md, "Net hip power"), and IPOPT's
path through it is chaotic. Perturbing every initial guess by one part in 10¹⁵ moves some one-phase ACOTs by
0.2 % and one part in 10¹³ by 4 % (docs/performance.md). So any change that alters floating-point rounding — a new
evaluation order of the same derivatives, another BLAS, another CPU — moves some cases by more than solver
tolerance while computing the same problem. ``--record-band K`` solves the baseline's own code K more times with
initial guesses perturbed at rounding level (relative noise ``--perturbation``, default 1e-14) and stores each
case's range of outcomes. A case that leaves its exact value but stays inside that range is reported as "within
the rounding band" and does not fail; one outside it, or with a status never seen in the band, fails.
"""

from __future__ import annotations

import argparse
import ast
import contextlib
import dataclasses
import json
import sys
import time
from pathlib import Path

import numpy as np

from gaitbench.problem.build_cache import BuildCache
from gaitbench.problem.transcription import TranscribedStep
from gaitbench.run.provenance import provenance
from gaitbench.run.runner import run_case
from gaitbench.run.suite import load_suite

HERE = Path(__file__).parent
SUITE = HERE / "suites" / "regression.toml"
BASELINE = HERE / "results" / "acot_baseline.json"
HISTORY = HERE / "results" / "acot_regression.jsonl"
COMPARED = ("acot", "claimed_acot")


def solve_cases(solver_options: dict | None = None) -> dict[str, dict]:
    """Every case's outcome under its key in the suite; ``solver_options`` are added to each case's solver (the
    rows keep the suite's keys, so they compare with the baseline)."""
    suite = load_suite(SUITE)
    rows = {}
    builds = BuildCache()
    for case in suite.cases:
        solved = case
        if solver_options:
            solver = dataclasses.replace(case.solver, options={**case.solver.options, **solver_options})
            solved = dataclasses.replace(case, solver=solver)
        outcome = run_case(solved, builds)
        rows[case.key] = {"case": case.label, "status": outcome.status, "message": outcome.message,
                          "wall_time_s": round(outcome.wall_time_s, 3),
                          **{name: outcome.metrics.get(name) for name in (*COMPARED, "iterations")}}
        print(f"{case.label:60s} {outcome.status:10s} acot={rows[case.key]['acot']} "
              f"({outcome.wall_time_s:.1f} s)", flush=True)
    return rows


@contextlib.contextmanager
def perturbed_guesses(scale: float, seed: int):
    """Every step's initial guess multiplied by (1 + ε), ε ~ N(0, scale²) per entry: a rounding-level nudge."""
    original = TranscribedStep.initial_guess
    rng = np.random.default_rng(seed)

    def initial_guess(self, data, seed=None):
        x = original(self, data, seed)
        return x * (1 + scale * rng.standard_normal(x.shape))

    TranscribedStep.initial_guess = initial_guess
    try:
        yield
    finally:
        TranscribedStep.initial_guess = original


def rounding_band(runs: list[dict[str, dict]]) -> dict[str, dict]:
    """Per case, the statuses and the [min, max] of each compared ACOT over the runs (exact and perturbed)."""
    band = {}
    for key in runs[0]:
        rows = [run[key] for run in runs]
        band[key] = {"statuses": sorted({row["status"] for row in rows})}
        for name in COMPARED:
            values = [row[name] for row in rows if row.get(name) is not None]
            band[key][name] = [min(values), max(values)] if values else None
    return band


def differences(baseline: dict[str, dict], current: dict[str, dict], tolerance: float,
                band: dict[str, dict] | None = None) -> tuple[list[str], list[str]]:
    """(failures, moves within the rounding band), each described; both empty when the results are unchanged."""
    found, within = [], []
    for key, before in baseline.items():
        after = current.get(key)
        if after is None:
            found.append(f"{before['case']}: missing from this run (the case set changed?)")
            continue
        allowed = (band or {}).get(key)
        if after["status"] != before["status"]:
            line = f"{before['case']}: status {before['status']} -> {after['status']} ({after['message']})"
            (within if allowed and after["status"] in allowed["statuses"] else found).append(line)
        for name in COMPARED:
            old, new = before.get(name), after.get(name)
            if old is None and new is None or old is not None and new is not None and abs(new - old) <= tolerance:
                continue
            line = f"{before['case']}: {name} {old} -> {new}"
            limits = allowed.get(name) if allowed else None
            inside = new is not None and limits is not None and limits[0] - tolerance <= new <= limits[1] + tolerance
            (within if inside else found).append(line + ("" if limits is None else
                                                         f" (band {limits[0]:.6g} … {limits[1]:.6g})"))
    return found, within


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--record", action="store_true", help="write the baseline instead of comparing")
    parser.add_argument("--reason", default=None, help="with --record: one line saying why the baseline moves "
                                                        "(kept in the baseline)")
    parser.add_argument("--record-band", type=int, metavar="K", default=0,
                        help="add to the baseline the rounding band of K perturbed runs (run at the baseline's code)")
    parser.add_argument("--perturbation", type=float, default=1e-14, help="relative size of the band's nudges")
    parser.add_argument("--tolerance", type=float, default=1e-6, help="largest accepted ACOT change")
    parser.add_argument("--solver-option", action="append", default=[], metavar="NAME=VALUE", type=solver_option,
                        help="add this option to every case's solver, to see how it moves the results "
                             "(repeatable; not with --record)")
    args = parser.parse_args(argv)
    solver_options = dict(args.solver_option)
    if solver_options and (args.record or args.record_band):
        parser.error("--solver-option measures an option against the baseline; it cannot record one")
    if not args.record and not BASELINE.exists():
        parser.error(f"no baseline at {BASELINE}: record one with --record on the commit before your change")
    if args.record_band:
        return record_band(args.record_band, args.perturbation)
    started = time.perf_counter()
    current = solve_cases(solver_options)
    wall = time.perf_counter() - started
    commit = provenance()["git_commit"]
    if args.record:
        reason = {"reason": args.reason} if args.reason else {}
        BASELINE.write_text(json.dumps({"commit": commit, **reason, "wall_time_s": wall, "cases": current},
                                       indent=2) + "\n")
        print(f"baseline of {len(current)} cases written to {BASELINE} ({wall:.0f} s)")
        return 0
    baseline = json.loads(BASELINE.read_text())
    found, within = differences(baseline["cases"], current, args.tolerance, baseline.get("rounding_band"))
    largest = max((abs(current[key][name] - row[name]) for key, row in baseline["cases"].items() if key in current
                   for name in COMPARED if row.get(name) is not None and current[key].get(name) is not None),
                  default=0.0)
    with HISTORY.open("a") as history:
        history.write(json.dumps({"commit": commit, "baseline_commit": baseline["commit"], "wall_time_s": wall,
                                  "baseline_wall_time_s": baseline["wall_time_s"], "largest_change": largest,
                                  **({"solver_options": solver_options} if solver_options else {}),
                                  "differences": found, "within_rounding_band": within}) + "\n")
    print(f"{len(current)} cases in {wall:.0f} s (baseline {baseline['wall_time_s']:.0f} s at "
          f"{baseline['commit'][:12]}); largest ACOT change {largest:.2e}")
    for line in within:
        print("within the rounding band:", line)
    for line in found:
        print("DIFFERENT:", line)
    if solver_options:
        lower, higher = directions(baseline["cases"], current, args.tolerance)
        print(f"with {solver_options}: ACOT lower in {lower} and higher in {higher} of {len(current)} cases "
              "(the verified ACOT; a case solved in only one run counts as neither)")
    return 1 if found else 0


def solver_option(text: str) -> tuple[str, object]:
    """NAME=VALUE, the value read as a Python literal (a number, True) or else kept as text."""
    name, sep, value = text.partition("=")
    if not sep or not name:
        raise argparse.ArgumentTypeError(f"{text!r} is not NAME=VALUE")
    try:
        return name, ast.literal_eval(value)
    except (ValueError, SyntaxError):
        return name, value


def directions(baseline: dict[str, dict], current: dict[str, dict], tolerance: float) -> tuple[int, int]:
    """How many cases' ACOT went down and up by more than ``tolerance``: whether a change finds better optima."""
    pairs = [(row["acot"], current[key]["acot"]) for key, row in baseline.items()
             if key in current and row["acot"] is not None and current[key]["acot"] is not None]
    return sum(new < old - tolerance for old, new in pairs), sum(new > old + tolerance for old, new in pairs)


def record_band(runs: int, scale: float) -> int:
    """Solve the case set ``runs`` times with perturbed guesses and store the band, with the exact baseline."""
    baseline = json.loads(BASELINE.read_text())
    started = time.perf_counter()
    outcomes = [baseline["cases"]]
    for seed in range(runs):
        print(f"perturbed run {seed + 1} of {runs} (relative {scale:g})", flush=True)
        with perturbed_guesses(scale, seed):
            outcomes.append(solve_cases())
    baseline["rounding_band"] = rounding_band(outcomes)
    baseline["rounding_band_settings"] = {"runs": runs, "perturbation": scale, "commit": provenance()["git_commit"],
                                          "wall_time_s": time.perf_counter() - started}
    BASELINE.write_text(json.dumps(baseline, indent=2) + "\n")
    moved = sum(band["acot"] is not None and band["acot"][1] - band["acot"][0] > 1e-6
                for band in baseline["rounding_band"].values())
    print(f"rounding band of {runs} perturbed runs written to {BASELINE}: {moved} of {len(outcomes[0])} cases move")
    return 0


if __name__ == "__main__":
    sys.exit(main())
