"""What a whole sweep took, read off its store: the record of a suite run once, on one commit, for the targets.

Run:    .venv/bin/python benchmarks/sweep_record.py STORE [--suite SUITE] [--against EARLIER] [--record]

A sweep as long as ``thesis-all`` runs over several sessions (``gaitbench run --smallest-first``, then ``--resume``),
so its wall time is the time during which at least one of its runs ran: the union of the runs' spans, each run
from its start to its end, or, for a run that was stopped (a session's end, a kill), to its last heartbeat or its
last finished case, whichever is later (runs at the same time, a column run on another machine and merged in, are
counted once). Beside it: the cases stored, how many are complete and how many verified, the total case time, and
the commits, machines and hosts they ran on. With ``--suite``, the cases are those of that suite file: every one
must be stored for the row to be recorded.

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
from datetime import datetime, timedelta
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


def union_s(spans: list[tuple[datetime, datetime]]) -> float:
    """Seconds covered by at least one of the (start, end) intervals."""
    covered, reach = 0.0, None
    for start, end in sorted(spans):
        if reach is None or start > reach:
            covered += (end - start).total_seconds()
            reach = end
        elif end > reach:
            covered += (end - reach).total_seconds()
            reach = end
    return covered


def sweep_record(store_path: str | Path, suite_path: str | Path | None = None) -> dict[str, Any]:
    """The sweep's row: suite, cases asked for and stored, complete and verified walks, wall and case time, runs,
    commits, machines and hosts. With ``suite_path``, only that suite's cases, all of which it asks for."""
    with ResultStore.open(store_path) as store:
        runs, cases = store.runs(), store.cases()
    if not runs:
        raise SystemExit(f"{store_path}: the store holds no run")
    cases_total = max(run["cases_total"] or 0 for run in runs)
    if suite_path is not None:
        from gaitbench.run.suite import load_suite

        asked = {case.key for case in load_suite(suite_path).cases}
        cases, cases_total = [case for case in cases if case["case_key"] in asked], len(asked)
    suites = sorted({run["suite"] for run in runs})
    commits = sorted({(case["provenance"] or {}).get("git_commit") or "unknown" for case in cases})
    machines = sorted({f"{(case['provenance'] or {}).get('cpu', '?')} × {(case['provenance'] or {}).get('cpus', '?')}"
                       for case in cases})
    spans = [{"run_id": run["run_id"], "started_at": run["started_at"], "host": run["host"], "jobs": run["jobs"],
              "span_s": round(run_span_s(run, cases), 1),
              "cases_done": sum(case["run_id"] == run["run_id"] for case in cases)} for run in runs]
    intervals = [(start, start + timedelta(seconds=span["span_s"]))
                 for span in spans if (start := _time(span["started_at"])) is not None]
    complete = [case for case in cases if case["status"] == "solved" and case["stop_cause"] == "complete"]
    return {
        "suite": suites[0] if len(suites) == 1 else suites,
        "store": str(store_path),
        "cases_total": cases_total,
        "cases": len(cases),
        "complete": len(complete),
        "verified": sum(bool(case["verified"]) for case in complete),
        "wall_s": round(union_s(intervals), 1),
        "case_time_s": round(sum(case["wall_time_s"] or 0.0 for case in cases), 1),
        "git_commits": commits,
        "one_clean_commit": len(commits) == 1 and commits[0] != "unknown" and not commits[0].endswith("+dirty"),
        "machines": machines,
        "hosts": sorted({run["host"] for run in runs if run["host"]}),
        "runs": spans,
        "checked_against_suite": suite_path is not None,
    }


def progress_against(row: dict[str, Any], store_path: str | Path, earlier_path: str | Path) -> dict[str, Any]:
    """How much of the sweep is done by ``earlier_path``'s case times, and the whole sweep's case and wall time
    projected from the cases done (their time here over their time there)."""
    def case_times(path: str | Path) -> dict[tuple, float]:
        """Each complete walk's case time: a crashed, stopped or timed-out case is not work done."""
        with ResultStore.open(path) as store:
            return {(case["experiment"], case["method"], case["N"]): case["wall_time_s"] or 0.0
                    for case in store.cases() if case["status"] == "solved"}

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
    is not whole (by its suite file), of several suites, or not on one clean commit."""
    if not isinstance(row["suite"], str):
        raise SystemExit(f"{row['store']}: holds runs of several suites ({', '.join(row['suite'])}); record one")
    if not row.get("checked_against_suite"):
        raise SystemExit(f"{row['store']}: name the suite file (--suite), whose every case must be stored")
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
    parser.add_argument("--suite", help="the suite file: count its cases only, and require every one for --record")
    parser.add_argument("--record", action="store_true", help="write the row into benchmarks/results/performance.json")
    parser.add_argument("--against", metavar="EARLIER",
                        help="an earlier store or pack of the suite: the share of its work done, and a projection")
    arguments = parser.parse_args(argv)
    row = sweep_record(arguments.store, arguments.suite)
    progress = progress_against(row, arguments.store, arguments.against) if arguments.against else {}
    print(json.dumps(row | {"progress": progress} if progress else row, indent=1))
    if arguments.record:
        record(row)


if __name__ == "__main__":
    main(sys.argv[1:])
