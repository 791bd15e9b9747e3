"""Resident memory of one case against N: the measurements behind ``gaitbench.run.memory``'s laws.

Run:    OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/memory.py [TRANSCRIPTION:STRATEGY:N[:STEPS] ...]
        OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/memory.py --fit

Each measurement is a fresh process that walks the first forward step (or STEPS steps) with IPOPT, as a suite
worker would. It records its resident memory once gaitbench and the plugins are imported (``base_mb``) and its peak
resident memory after the walk (``peak_mb``, ``ru_maxrss``). Rows are appended to
``benchmarks/results/memory.jsonl`` with the commit measured (``+dirty`` as a rule: the results file itself is being
appended); without arguments the grid :data:`FIT_NODES` is measured. ``--fit`` fits the
laws to the grid's rows (see :func:`fit`) and compares every other row (larger N, other strategies, several steps)
with what ``gaitbench.run.memory`` estimates for it.
"""

from __future__ import annotations

import json
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).parent
RESULTS = HERE / "results" / "memory.jsonl"
FIT_NODES = {"one-phase": (50, 100, 200, 400), "warm-start": (50, 100, 200, 400),
             "decrease-and-conquer": (20, 40, 60, 80), "whole-walk": (100, 200, 400, 800)}
"""The sizes the laws are fitted to, per strategy: N, or N·steps for whole-walk, whose one NLP chains the steps;
decrease-and-conquer at small N, where its N−3 sectional NLPs fit."""
WHOLE_WALK_SHAPES = ((50, 2), (50, 4), (100, 4), (100, 8))
"""(N, steps) of the whole-walk measurements: N·steps = 100, 200, 400, 800."""
TRANSCRIPTIONS = ("hermite-simpson", "dmoc", "trapezoidal")


def measure(transcription: str, strategy: str, n_nodes: int, steps: int = 1) -> dict:
    """Walk ``steps`` forward steps in this process and return its memory figures (call in a fresh process)."""
    import resource

    from gaitbench.contracts import WalkProblem
    from gaitbench.plugins import load_registry
    from gaitbench.run.provenance import git_commit

    registry = load_registry()
    experiment = registry.create("experiment", "forward")
    problem = WalkProblem(experiment, registry.create("transcription", transcription),
                          registry.create("solver", "ipopt"), n_nodes, steps=steps)
    base_mb = _resident_mb()
    started = time.perf_counter()
    walk = registry.create("strategy", strategy).solve(problem)
    return {"transcription": transcription, "strategy": strategy, "N": n_nodes, "steps": steps, "base_mb": base_mb,
            "peak_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024, "end_mb": _resident_mb(),
            "wall_s": time.perf_counter() - started, "complete": walk.complete, "commit": git_commit()}


def _resident_mb() -> float:
    return int(Path("/proc/self/statm").read_text().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 2**20


def _size(row: dict) -> int:
    """The n a law is evaluated at: N, or N·steps for whole-walk."""
    return row["N"] * row.get("steps", 1) if row["strategy"] == "whole-walk" else row["N"]


def _fitted(row: dict) -> bool:
    whole = row["strategy"] == "whole-walk"
    return (whole or row.get("steps", 1) == 1) and _size(row) in FIT_NODES.get(row["strategy"], ())


def fit(rows: list[dict]) -> dict[tuple[str, str], dict]:
    """``peak − base = a + b·n (+ c·n²)`` per (transcription, strategy) by least squares on the grid's rows, n = N
    (N·steps for whole-walk): linear for the strategies that hold one NLP per step (or one for the walk), quadratic
    for decrease-and-conquer, whose N−3 sectional NLPs of 3 … N−1 nodes add up to ~N²/2 nodes. With the median base
    and each point's relative residual."""
    import numpy as np

    groups: dict[tuple[str, str], list[dict]] = {}
    for row in filter(_fitted, rows):
        groups.setdefault((row["transcription"], row["strategy"]), []).append(row)
    laws = {}
    for key, group in groups.items():
        degree = 2 if key[1] == "decrease-and-conquer" else 1
        if len(group) <= degree:
            continue
        n = np.array([_size(row) for row in group], dtype=float)
        growth = np.array([row["peak_mb"] - row["base_mb"] for row in group])
        coefficients = np.polyfit(n, growth, degree)
        laws[key] = {"base_mb": statistics.median(row["base_mb"] for row in group),
                     "coefficients_mb": [float(c) for c in coefficients[::-1]], "N": [int(v) for v in n],
                     "residuals": [float(r) for r in (growth - np.polyval(coefficients, n)) / growth]}
    return laws


def large_solve_term(rows: list[dict], laws: dict[tuple[str, str], dict]) -> dict[str, float]:
    """Per transcription, the c of ``c·n²`` that one-phase peaks at N > 400 add to the linear law fitted below it
    (least squares through the origin of the excess against N²): large solves peak above the linear law."""
    terms = {}
    for transcription in TRANSCRIPTIONS:
        law = laws.get((transcription, "one-phase"))
        large = [row for row in rows if row["transcription"] == transcription and row["strategy"] == "one-phase"
                 and row.get("steps", 1) == 1 and row["N"] > max(FIT_NODES["one-phase"])]
        if law is None or not large:
            continue
        a, b = law["coefficients_mb"][:2]
        excess = [(row["N"], row["peak_mb"] - row["base_mb"] - a - b * row["N"]) for row in large]
        terms[transcription] = max(sum(e * n**2 for n, e in excess) / sum(n**4 for n, _ in excess), 0.0)
    return terms


def main(argv: list[str]) -> None:
    if argv[:1] == ["--child"]:
        transcription, strategy, n_nodes, *steps = argv[1].split(":")
        print(json.dumps(measure(transcription, strategy, int(n_nodes), *map(int, steps))))
        return
    if argv[:1] == ["--fit"]:
        from gaitbench.run.memory import estimate_case_memory

        rows = [json.loads(line) for line in RESULTS.read_text().splitlines() if line.strip()]
        for (transcription, strategy), law in fit(rows).items():
            terms = " + ".join(f"{c:.4g}" + ("" if power == 0 else " N" if power == 1 else f" N^{power}")
                               for power, c in enumerate(law["coefficients_mb"]))
            residuals = ", ".join(f"{r:+.1%}" for r in law["residuals"])
            print(f"{transcription:16} {strategy:21} base {law['base_mb']:.0f} MB, peak - base = {terms} MB "
                  f"(n = {law['N']}; residuals {residuals})")
        for transcription, c in large_solve_term(rows, fit(rows)).items():
            print(f"{transcription:16} large solves          + {c:.3g} N^2 MB (one-phase, N > 400)")
        for row in rows:
            if not _fitted(row):
                steps = row.get("steps", 1)
                estimate = estimate_case_memory(row["transcription"], row["strategy"], row["N"], steps)
                print(f"check: {row['transcription']} {row['strategy']} N = {row['N']}, {steps} step(s): "
                      f"measured {row['peak_mb']:.0f} MB, estimated {estimate.mb:.0f} MB "
                      f"({estimate.mb / row['peak_mb'] - 1:+.0%})")
        return
    env = {**os.environ, "OPENBLAS_NUM_THREADS": "1"}
    grid = [f"{t}:{strategy}:{n}" for strategy, nodes in FIT_NODES.items() if strategy != "whole-walk"
            for t in TRANSCRIPTIONS for n in nodes]
    grid += [f"{t}:whole-walk:{n}:{steps}" for t in TRANSCRIPTIONS for n, steps in WHOLE_WALK_SHAPES]
    for spec in argv or grid:
        child = subprocess.run([sys.executable, __file__, "--child", spec], capture_output=True, text=True, env=env)
        if child.returncode:
            print(f"{spec}: failed\n{child.stderr[-2000:]}", file=sys.stderr)
            continue
        row = json.loads(child.stdout.strip().splitlines()[-1])
        print(row, flush=True)
        with RESULTS.open("a") as out:
            out.write(json.dumps(row) + "\n")


if __name__ == "__main__":
    main(sys.argv[1:])
