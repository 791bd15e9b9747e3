"""What a whole sweep took, read off its store: the record of a suite run once, on one commit, for the targets.

Run:    .venv/bin/python benchmarks/sweep_record.py STORE [--against EARLIER] [--record]

A sweep as long as ``thesis-all`` runs over several sessions (``gaitbench run --smallest-first``, then ``--resume``),
so its wall time is the sum of its runs' spans: each run from its start to its end, or, for a run that was stopped
(a session's end, a kill), to its last heartbeat or its last finished case, whichever is later. Beside it: the
cases the suite asks for and those stored, how many are complete and how many verified, the total case time, and
the commits and machines the cases ran on.

With ``--against EARLIER`` (a store or pack of the same suite, such as the committed snapshot) it also says how far
a sweep still running has come by the earlier sweep's measure: the share of the earlier sweep's case time that the
cases done took there, and, scaling by how much longer or shorter they took here, the whole sweep's case time and
wall time at this run's parallelism, an estimate. Cases are matched by experiment, method and N.

Printed as JSON. With ``--record`` the row goes into ``benchmarks/results/performance.json`` under ``sweeps``
(replacing the row of the same suite), which the targets in docs/performance.md cite; it is refused unless every
case of the suite is stored and all of them ran on one clean commit, the condition under which the sweep's
figures share one problem definition.
"""

from __future__ import annotations

import argparse
import json
import sys
from datetime import datetime
from pathlib import Path
from typing import Any

from gaitbench.run.store import ResultStore

PERFORMANCE = Path(__file__).parent / "results" / "performance.json"


def _time(text: str | None) -> datetime | None:
    return datetime.fromisoformat(text) if text else None


def run_span_s(run: dict[str, Any], cases: list[dict[str, Any]]) -> float:
    """Seconds from a run's start to its end; for a run without an end, to the later of its last heartbeat and its
    last finished case (what is known of when it stopped)."""
    start = _time(run["started_at"])
    ends = [_time(run["finished_at"])] if run["finished_at"] else [
        _time(run["heartbeat_at"]), *(_time(case["finished_at"]) for case in cases if case["run_id"] == run["run_id"])]
    end = max((moment for moment in ends if moment is not None), default=start)
    return (end - start).total_seconds()


def sweep_record(store_path: str | Path) -> dict[str, Any]:
    """The sweep's row: suite, cases asked for and stored, complete and verified walks, wall and case time, runs,
    commits and machines."""
    with ResultStore.open(store_path) as store:
        runs, cases = store.runs(), store.cases()
    if not runs:
        raise SystemExit(f"{store_path}: the store holds no run")
    suites = sorted({run["suite"] for run in runs})
    commits = sorted({(case["provenance"] or {}).get("git_commit") or "unknown" for case in cases})
    machines = sorted({f"{(case['provenance'] or {}).get('cpu', '?')} × {(case['provenance'] or {}).get('cpus', '?')}"
                       for case in cases})
    spans = [{"run_id": run["run_id"], "started_at": run["started_at"], "jobs": run["jobs"],
              "span_s": round(run_span_s(run, cases), 1),
              "cases_done": sum(case["run_id"] == run["run_id"] for case in cases)} for run in runs]
    complete = [case for case in cases if case["status"] == "solved" and case["stop_cause"] == "complete"]
    return {
        "suite": suites[0] if len(suites) == 1 else suites,
        "store": str(store_path),
        "cases_total": max(run["cases_total"] or 0 for run in runs),
        "cases": len(cases),
        "complete": len(complete),
        "verified": sum(bool(case["verified"]) for case in complete),
        "wall_s": round(sum(span["span_s"] for span in spans), 1),
        "case_time_s": round(sum(case["wall_time_s"] or 0.0 for case in cases), 1),
        "git_commits": commits,
        "one_clean_commit": len(commits) == 1 and commits[0] != "unknown" and not commits[0].endswith("+dirty"),
        "machines": machines,
        "runs": spans,
    }


def progress_against(row: dict[str, Any], store_path: str | Path, earlier_path: str | Path) -> dict[str, Any]:
    """How much of the sweep is done by ``earlier_path``'s case times, and the whole sweep's case and wall time
    projected from the cases done (their time here over their time there)."""
    def case_times(path: str | Path) -> dict[tuple, float]:
        with ResultStore.open(path) as store:
            return {(case["experiment"], case["method"], case["N"]): case["wall_time_s"] or 0.0
                    for case in store.cases()}

    here, there = case_times(store_path), case_times(earlier_path)
    done = [key for key in here if key in there]
    if not done:
        raise SystemExit(f"{earlier_path}: none of its cases is a case of {store_path} (by experiment, method, N)")
    if not sum(there[key] for key in done):
        raise SystemExit(f"{earlier_path}: its cases record no case time (wall_time_s) to measure progress by")
    share = sum(there[key] for key in done) / sum(there.values())
    ratio = sum(here[key] for key in done) / sum(there[key] for key in done)
    case_time_s = ratio * sum(there.values())
    parallelism = row["case_time_s"] / row["wall_s"] if row["wall_s"] else 1.0
    return {"against": str(earlier_path), "cases_matched": len(done), "work_done_share": round(share, 4),
            "case_time_ratio": round(ratio, 3), "projected_case_time_s": round(case_time_s),
            "projected_wall_s": round(case_time_s / parallelism)}


def record(row: dict[str, Any], performance: Path = PERFORMANCE) -> None:
    """Put ``row`` into ``performance.json``'s ``sweeps``, replacing the row of its suite; refused for a sweep that
    is not whole or not on one clean commit."""
    if row["cases"] < row["cases_total"]:
        raise SystemExit(f"{row['store']}: {row['cases']} of {row['cases_total']} cases stored; a sweep is recorded "
                         f"whole (gaitbench run SUITE --store STORE --resume does the rest)")
    if not row["one_clean_commit"]:
        raise SystemExit(f"{row['store']}: the cases ran on {', '.join(row['git_commits'])}; a sweep is recorded "
                         f"only when every case ran on one clean commit")
    document = json.loads(performance.read_text())
    document["sweeps"] = [old for old in document.get("sweeps", []) if old["suite"] != row["suite"]] + [row]
    performance.write_text(json.dumps(document, indent=1) + "\n")


def main(argv: list[str]) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("store", help="the sweep's results store (a directory or a pack)")
    parser.add_argument("--record", action="store_true", help="write the row into benchmarks/results/performance.json")
    parser.add_argument("--against", metavar="EARLIER",
                        help="an earlier store or pack of the suite: the share of its work done, and a projection")
    arguments = parser.parse_args(argv)
    row = sweep_record(arguments.store)
    progress = progress_against(row, arguments.store, arguments.against) if arguments.against else {}
    print(json.dumps(row | {"progress": progress} if progress else row, indent=1))
    if arguments.record:
        record(row)


if __name__ == "__main__":
    main(sys.argv[1:])
