"""Merging results stores: cases run apart (on another machine, in another session, a suite's column at a time)
gathered into one store, so that one report and one table cover the whole sweep.

A case is known by its key (:attr:`gaitbench.run.case.Case.key`), whatever store or suite computed it, so the
same case in two stores is the same walk. Each copied case keeps its row whole (its provenance: the commit, the
machine, the solver versions) and its files, and brings the run that computed it; a run id the destination already
uses for another run is given a suffix, as :meth:`ResultStore.start_run` does. A case the destination already
holds is left alone unless ``replace``, and a complete walk there is never replaced by one that is not; one
that a live run there has claimed is always left to that run.
Checkpoints of walks in flight are not merged: a walk is resumed on the store that holds it
(:mod:`gaitbench.checkpoint`).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from gaitbench.run.store import ResultStore
from gaitbench.run.store_files import case_files
from gaitbench.run.store_schema import RUN_COLUMNS, StoreError

_SAME_RUN = tuple(column for column in RUN_COLUMNS if column not in ("heartbeat_at", "finished_at"))
"""Two runs rows that agree on these are one run seen in two stores (a store copied while the run went on)."""


@dataclass
class MergeSummary:
    """The case keys of the source, sorted by what merging did with them, and the runs added (their ids here)."""

    copied: list[str] = field(default_factory=list)
    """Cases the destination did not hold."""
    replaced: list[str] = field(default_factory=list)
    """Cases it held otherwise, replaced by the source's (``replace``)."""
    same: list[str] = field(default_factory=list)
    """Cases it already held exactly so."""
    kept: list[str] = field(default_factory=list)
    """Cases it held otherwise and kept: without ``replace``, or where only the destination's walk is complete."""
    in_flight: list[str] = field(default_factory=list)
    """Cases a live run on the destination is solving now, or recorded while the merge went on: left to it."""
    runs: list[str] = field(default_factory=list)


def merge_store(destination: ResultStore, source: ResultStore, replace: bool = False) -> MergeSummary:
    """Copy into ``destination`` every case of ``source`` it lacks (every differing one too with ``replace``).

    Every file a copied row names is checked before anything is written, so a source with a missing file changes
    nothing (:class:`StoreError` naming the file).
    """
    if destination.directory.resolve() == source.directory.resolve():
        raise StoreError(f"{source.directory}: a store cannot be merged into itself")
    summary = MergeSummary()
    held = {row["case_key"]: row for row in destination.cases()}
    claimed = destination.live_claims()
    chosen = []
    for row in source.cases():
        key = row["case_key"]
        if key in claimed:
            summary.in_flight.append(key)
        elif key not in held:
            summary.copied.append(key)
            chosen.append(row)
        elif _without_run(held[key]) == _without_run(row):
            summary.same.append(key)
        elif replace and (row["status"] == "solved" or held[key]["status"] != "solved"):
            summary.replaced.append(key)
            chosen.append(row)
        else:
            summary.kept.append(key)
    for row in chosen:
        _check_files(source, row)
    run_ids = _merge_runs(destination, source, {row["run_id"] for row in chosen if row["run_id"]}, summary)
    for row in chosen:  # one case's files in memory at a time
        run_id = run_ids.get(row["run_id"], row["run_id"])
        try:
            files = case_files(source.directory, row["case_key"])
        except OSError as error:
            raise StoreError(f"{source.directory}: cannot read the files of case {row['case_key']} "
                             f"({error.strerror or error}); the cases before it were merged") from None
        before = held.get(row["case_key"])
        if not destination.record_case(row | {"run_id": run_id}, files,
                                       unchanged=(before["run_id"], before["finished_at"]) if before else (None, None)):
            _moved(summary, row["case_key"], summary.in_flight)  # a run recorded or claimed it meanwhile
    return summary


def _moved(summary: MergeSummary, key: str, to: list[str]) -> None:
    """Move ``key`` from the copied or replaced cases of ``summary`` to ``to``."""
    for done in (summary.copied, summary.replaced):
        if key in done:
            done.remove(key)
    to.append(key)


def _without_run(row: dict) -> dict:
    """A case row but for the id of its run, which merging may rename."""
    return {column: value for column, value in row.items() if column != "run_id"}


def _check_files(source: ResultStore, row: dict) -> None:
    """:class:`StoreError` if a file the source case's row names is missing."""
    for column in ("walk_path", "tracking_path"):
        if row[column] and not (source.directory / row[column]).is_file():
            raise StoreError(f"{source.directory / row[column]}: missing, but case {row['case_key']} names it in "
                             f"{column}; nothing was merged")


def _merge_runs(destination: ResultStore, source: ResultStore, needed: set[str],
                summary: MergeSummary) -> dict[str, str]:
    """Add the source runs that computed the copied cases; the new id of each renamed one."""
    held = {row["run_id"]: row for row in destination.runs()}
    renamed = {}
    for run in source.runs():
        run_id = run["run_id"]
        if run_id not in needed:
            continue
        if run_id in held and all(held[run_id][column] == run[column] for column in _SAME_RUN):
            continue
        added = destination.add_run(run)
        summary.runs.append(added)
        if added != run_id:
            renamed[run_id] = added
    return renamed


def describe(summary: MergeSummary, source: Path, destination: Path) -> str:
    """One paragraph for the command line: what was merged, and what was left and why."""
    parts = [f"{source} → {destination}: {len(summary.copied)} cases copied"]
    if summary.replaced:
        parts.append(f"{len(summary.replaced)} replaced")
    if summary.same:
        parts.append(f"{len(summary.same)} already there")
    if summary.runs:
        parts.append(f"{len(summary.runs)} runs added ({', '.join(summary.runs)})")
    text = ", ".join(parts)
    if summary.kept:
        text += (f"\n{len(summary.kept)} cases differ from the destination's and were kept as they were there "
                 f"(--replace takes the source's): {', '.join(summary.kept)}")
    if summary.in_flight:
        text += (f"\n{len(summary.in_flight)} cases are being solved by a run on the destination now and were "
                 f"left to it: {', '.join(summary.in_flight)}")
    return text
