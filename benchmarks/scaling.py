"""A sweep's wall time on W workers, computed from its measured case times: a scaling model, not a run.

Run:    .venv/bin/python benchmarks/scaling.py STORE [--suite SUITE.toml] [--workers 2 8 32 128] [--out FILE.md]

For each W it computes the makespan of the runner's own schedule: the cases largest N first, suite order among
equal N (:func:`gaitbench.run.runner.largest_first`), each handed to the first worker that frees up, as the local
pool and the Dask executor do. Beside it, the bound no schedule beats: the longest case, or the total case time
over W, whichever is larger. Past the W where the longest case dominates, more workers buy nothing: the next lever
is that case's own time (docs/performance.md).

The model takes each case's stored ``wall_time_s`` as what it costs on one worker. That holds where workers do
not share a core (a Dask worker per core); case times measured beside other work are inflated, and the store's
provenance says when. With ``--suite``, the suite's cases that the store does not hold yet are counted and named:
the model covers only what was measured.
"""

from __future__ import annotations

import argparse
import heapq
import sys
from dataclasses import dataclass
from pathlib import Path

import pandas as pd

from gaitbench.run.store import load_results

WORKERS = (2, 8, 32, 128)


@dataclass(frozen=True)
class Scaling:
    """The computed wall time of one worker count."""

    workers: int
    makespan_s: float
    bound_s: float

    @property
    def efficiency(self) -> float:
        """How close the schedule comes to its bound (1: nothing left to gain by packing)."""
        return self.bound_s / self.makespan_s if self.makespan_s > 0 else 1.0


def schedule_order(cases: pd.DataFrame) -> pd.DataFrame:
    """The cases in the order the runner hands them out: largest N first, store (suite) order among equal N."""
    return cases.assign(_order=range(len(cases))).sort_values(["N", "_order"], ascending=[False, True])


def makespan(times: list[float], workers: int) -> float:
    """When ``workers`` workers finish ``times``, each taking the next one as it frees up."""
    free = [0.0] * workers
    for time in times:
        heapq.heappush(free, heapq.heappop(free) + time)
    return max(free)


def scaling(cases: pd.DataFrame, workers: tuple[int, ...] = WORKERS) -> list[Scaling]:
    times = [float(t) for t in schedule_order(cases)["wall_time_s"]]
    return [Scaling(w, makespan(times, w), max(max(times, default=0.0), sum(times) / w)) for w in workers]


def missing_cases(store: Path, suite_file: Path) -> list[str]:
    """The suite's cases the store does not hold, described."""
    from gaitbench.run.suite import load_suite

    held = set(load_results(store)["case_key"])
    return [f"{case.method} {case.experiment.name} N = {case.n_nodes}" for case in load_suite(suite_file).cases
            if case.key not in held]


def report(store: Path, workers: tuple[int, ...], suite_file: Path | None) -> str:
    cases = load_results(store)
    cases = cases[pd.to_numeric(cases["wall_time_s"], errors="coerce").notna()]
    rows = scaling(cases, workers)
    longest = cases.loc[pd.to_numeric(cases["wall_time_s"]).idxmax()]
    total = float(pd.to_numeric(cases["wall_time_s"]).sum())
    lines = [f"# Scaling model: {store}", "",
             f"{len(cases)} measured cases, {total:,.0f} s of case time; the longest, {longest['method']} "
             f"{longest['experiment']} N = {longest['N']}, takes {float(longest['wall_time_s']):,.0f} s.", ""]
    if suite_file is not None:
        missing = missing_cases(store, suite_file)
        lines += [f"Not measured yet: {len(missing)} of the suite's cases (not in the model).", ""]
    lines += ["| workers | wall time (schedule) | bound (longest case, or total / workers) | efficiency |",
              "|---|---|---|---|"]
    lines += [f"| {row.workers} | {row.makespan_s:,.0f} s | {row.bound_s:,.0f} s | {row.efficiency:.0%} |"
              for row in rows]
    return "\n".join(lines) + "\n"


def main(argv: list[str]) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("store", type=Path)
    parser.add_argument("--suite", type=Path, help="count the suite's cases the store does not hold yet")
    parser.add_argument("--workers", type=int, nargs="+", default=list(WORKERS))
    parser.add_argument("--out", type=Path, help="write the table here as well")
    args = parser.parse_args(argv)
    text = report(args.store, tuple(args.workers), args.suite)
    print(text, end="")
    if args.out is not None:
        args.out.write_text(text)


if __name__ == "__main__":
    main(sys.argv[1:])
