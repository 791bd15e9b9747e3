"""Speed-ups must not change results: the ACOT of a fixed case set against a recorded baseline.

Run:    .venv/bin/python benchmarks/acot_regression.py            (compare; exit status 1 on any difference)
        .venv/bin/python benchmarks/acot_regression.py --record   (write the baseline; do this only before a change)

The case set is ``benchmarks/suites/regression.toml``, solved in this process case by case with the suite
runner's own ``run_case``, so every layer a suite run goes through (builds, caches, strategies, verification) is
exercised. A case differs when its status changes or when its ACOT (the verified one for decrease-and-conquer) or
its claimed ACOT moves by more than ``--tolerance``: IPOPT stops at a KKT error of 1e-8, so a faster core that
computes the same problem lands within about that of the same optimum. Each comparison is appended to
``benchmarks/results/acot_regression.jsonl`` with the commit it ran at, so the history of checks is kept.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

from gaitbench.provenance import provenance
from gaitbench.runner import run_case
from gaitbench.suite import load_suite

HERE = Path(__file__).parent
SUITE = HERE / "suites" / "regression.toml"
BASELINE = HERE / "results" / "acot_baseline.json"
HISTORY = HERE / "results" / "acot_regression.jsonl"
COMPARED = ("acot", "claimed_acot")


def solve_cases() -> dict[str, dict]:
    suite = load_suite(SUITE)
    rows = {}
    for case in suite.cases:
        outcome = run_case(case)
        rows[case.key] = {"case": case.label, "status": outcome.status, "message": outcome.message,
                          "wall_time_s": round(outcome.wall_time_s, 3),
                          **{name: outcome.metrics.get(name) for name in (*COMPARED, "iterations")}}
        print(f"{case.label:60s} {outcome.status:10s} acot={rows[case.key]['acot']} "
              f"({outcome.wall_time_s:.1f} s)", flush=True)
    return rows


def differences(baseline: dict[str, dict], current: dict[str, dict], tolerance: float) -> list[str]:
    """Every case whose status or ACOT moved, described; empty when the results are unchanged."""
    found = []
    for key, before in baseline.items():
        after = current.get(key)
        if after is None:
            found.append(f"{before['case']}: missing from this run (the case set changed?)")
            continue
        if after["status"] != before["status"]:
            found.append(f"{before['case']}: status {before['status']} -> {after['status']} ({after['message']})")
        for name in COMPARED:
            old, new = before.get(name), after.get(name)
            if (old is None) != (new is None) or (old is not None and abs(new - old) > tolerance):
                found.append(f"{before['case']}: {name} {old} -> {new}")
    return found


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--record", action="store_true", help="write the baseline instead of comparing")
    parser.add_argument("--tolerance", type=float, default=1e-6, help="largest accepted ACOT change")
    args = parser.parse_args(argv)
    if not args.record and not BASELINE.exists():
        parser.error(f"no baseline at {BASELINE}: record one with --record on the commit before your change")
    started = time.perf_counter()
    current = solve_cases()
    wall = time.perf_counter() - started
    commit = provenance()["git_commit"]
    if args.record:
        BASELINE.write_text(json.dumps({"commit": commit, "wall_time_s": wall, "cases": current}, indent=2) + "\n")
        print(f"baseline of {len(current)} cases written to {BASELINE} ({wall:.0f} s)")
        return 0
    baseline = json.loads(BASELINE.read_text())
    found = differences(baseline["cases"], current, args.tolerance)
    largest = max((abs(current[key][name] - row[name]) for key, row in baseline["cases"].items() if key in current
                   for name in COMPARED if row.get(name) is not None and current[key].get(name) is not None),
                  default=0.0)
    with HISTORY.open("a") as history:
        history.write(json.dumps({"commit": commit, "baseline_commit": baseline["commit"], "wall_time_s": wall,
                                  "baseline_wall_time_s": baseline["wall_time_s"], "largest_change": largest,
                                  "differences": found}) + "\n")
    print(f"{len(current)} cases in {wall:.0f} s (baseline {baseline['wall_time_s']:.0f} s at "
          f"{baseline['commit'][:12]}); largest ACOT change {largest:.2e}")
    for line in found:
        print("DIFFERENT:", line)
    return 1 if found else 0


if __name__ == "__main__":
    sys.exit(main())
