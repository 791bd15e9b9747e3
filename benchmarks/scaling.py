"""A sweep's wall time on W workers, computed from its measured case times: a scaling model, not a run.

Run:    .venv/bin/python benchmarks/scaling.py STORE [--suite SUITE.toml] [--workers 2 8 32 128] [--out FILE.md]

For each W it computes the makespan of the runner's own schedule: the cases largest N first, suite order among
equal N (:func:`gaitbench.run.runner.largest_first`), each handed to the first worker that frees up, as the local
pool does. Beside it, the bound no schedule beats: the longest case, or the total case time over W, whichever is
larger.

On Dask a decrease-and-conquer case also fans its sectional solves out over every worker
(:mod:`gaitbench.run.dask_fan_out`), so the cluster's W cores share pieces of work, not whole cases. The model
splits each D&C case into its steps as its saved walk records them: per step a serial part (the First Phase, the
complete and the polishing solves, their ``solve_time_s``) and N − 3 sections, which share the rest of the case's
time equally (so builds, synthesis and verification count as section time: the fan-out's share is an upper bound).
The cases start as the runner starts them (largest first, at most W at once); a free core takes a waiting serial
part first (the case's own process, which holds no Dask thread while it walks, starts it at once), else the
section that has waited longest. Its bound is the longest case's critical path (serial parts, and each step's
sections W at a time), or the total over W.

The model takes each case's stored ``wall_time_s`` as what it costs on one worker. That holds where workers do
not share a core (a Dask worker per core); case times measured beside other work are inflated, and the store's
provenance says when. With ``--suite``, the suite's cases that the store does not hold yet are counted and named:
the model covers only what was measured.
"""

from __future__ import annotations

import argparse
import heapq
import json
import math
import sys
from collections import deque
from dataclasses import dataclass
from pathlib import Path

import pandas as pd

from gaitbench.run.store import ResultStore, load_results

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


@dataclass(frozen=True)
class CaseWork:
    """A case as pieces of work: per step, its serial seconds and its sections' seconds (none for a case that does
    not fan out, which is one serial piece)."""

    steps: tuple[tuple[float, tuple[float, ...]], ...]

    @property
    def total_s(self) -> float:
        return sum(serial + sum(sections) for serial, sections in self.steps)

    def critical_path(self, workers: int) -> float:
        """The case alone on ``workers`` cores: its serial parts, and each step's sections ``workers`` at a time."""
        return sum(serial + (math.ceil(len(sections) / workers) * max(sections) if sections else 0.0)
                   for serial, sections in self.steps)


def case_work(row: pd.Series, store: Path) -> CaseWork:
    """``row``'s case as pieces: a D&C walk split by its saved steps (see the module's docstring), any other case
    whole."""
    wall = float(row["wall_time_s"])
    walk_path = row.get("walk_path")
    if row.get("strategy") != "decrease-and-conquer" or not isinstance(walk_path, str):
        return CaseWork(((wall, ()),))
    if not (store / walk_path).exists():
        raise SystemExit(f"{store / walk_path}: a decrease-and-conquer walk's file is missing; its sections cannot be "
                         "modelled (pack the store with its walk files)")
    steps = [step.get("details") or {} for step in json.loads((store / walk_path).read_text())["steps"]]
    serial = [sum((details.get(part) or {}).get("solve_time_s") or 0.0
                  for part in ("first_phase", "complete", "polished")) for details in steps]
    sectioned = [details for details in steps if "candidates" in details]  # the steps that reached their sections
    count = int(row["N"]) - 3
    if not sectioned or count < 1:
        return CaseWork(((wall, ()),))
    section = max(wall - sum(serial), 0.0) / (len(sectioned) * count)
    return CaseWork(tuple((time, (section,) * count if "candidates" in details else ())
                          for time, details in zip(serial, steps, strict=True)))


def fanned_makespan(cases: list[CaseWork], workers: int) -> float:
    """When ``workers`` cores finish ``cases`` (in the runner's order, at most ``workers`` at once), each core
    taking a waiting serial part first, else the section that has waited longest: a step's sections are ready when
    its serial part ends."""
    serials: deque[tuple[int, int, float]] = deque()  # (case, step, seconds)
    sections_ready: deque[tuple[int, int, float]] = deque()
    remaining: dict[tuple[int, int], int] = {}  # sections of a step still running or waiting
    running: list[tuple[float, int, int, int, bool]] = []  # (ends at, sequence, case, step, is serial)
    upcoming, started, now, sequence = iter(range(len(cases))), 0, 0.0, 0

    def start_step(case: int, step: int) -> None:
        nonlocal started
        if step == len(cases[case].steps):  # the case is done: the runner hands out the next one
            started -= 1
            start_case()
        else:
            serials.append((case, step, cases[case].steps[step][0]))

    def start_case() -> None:
        nonlocal started
        while started < workers and (case := next(upcoming, None)) is not None:
            started += 1
            start_step(case, 0)

    start_case()
    while serials or sections_ready or running:
        while (serials or sections_ready) and len(running) < workers:
            serial = bool(serials)
            case, step, seconds = (serials or sections_ready).popleft()
            heapq.heappush(running, (now + seconds, sequence, case, step, serial))
            sequence += 1
        now, _, case, step, serial = heapq.heappop(running)
        if serial:
            sections = cases[case].steps[step][1]
            remaining[(case, step)] = len(sections)
            sections_ready.extend((case, step, seconds) for seconds in sections)
            if sections:
                continue
        else:
            remaining[(case, step)] -= 1
            if remaining[(case, step)]:
                continue
        del remaining[(case, step)]
        start_step(case, step + 1)
    return now


def fanned_scaling(cases: list[CaseWork], workers: tuple[int, ...] = WORKERS) -> list[Scaling]:
    """:func:`scaling` for a cluster on which D&C's sections fan out: ``cases`` in the runner's order."""
    total = sum(case.total_s for case in cases)
    return [Scaling(w, fanned_makespan(cases, w),
                    max(max((case.critical_path(w) for case in cases), default=0.0), total / w)) for w in workers]


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
    ordered = schedule_order(cases)
    with ResultStore.open(store) as opened:  # a pack's walk files are in its unpacked copy
        directory = opened.directory
    works = [case_work(row, directory) for _, row in ordered.iterrows()]
    fanned = fanned_scaling(works, workers)
    fanning = [(work, row) for work, (_, row) in zip(works, ordered.iterrows(), strict=True)
               if any(sections for _, sections in work.steps)]
    if fanning:
        work, row = max(fanning, key=lambda pair: pair[0].total_s)
        paths = ", ".join(f"{work.critical_path(w):,.0f} s on {w}" for w in workers)
        lines += [f"The longest case whose sections fan out, {row['method']} {row['experiment']} N = {row['N']}: "
                  f"{work.total_s:,.0f} s whole; alone on a cluster: {paths}.", ""]
    lines += ["| workers | whole cases (local pool) | its bound | sections fanned out (Dask) | its bound |",
              "|---|---|---|---|---|"]
    lines += [f"| {row.workers} | {row.makespan_s:,.0f} s | {row.bound_s:,.0f} s | {fan.makespan_s:,.0f} s | "
              f"{fan.bound_s:,.0f} s |" for row, fan in zip(rows, fanned, strict=True)]
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
