"""The whole-walk verification of a sweep run over several sessions, kept as one record and summed up.

Run:    gaitbench verify --store STORE --json | python benchmarks/verify_record.py add RECORD.jsonl
        python benchmarks/verify_record.py summary RECORD.jsonl

A sweep carried from session to session (benchmarks/snapshot_store.py) keeps only the trajectories its report draws,
so each session verifies the walks it solved before they leave the machine. ``add`` appends each verdict of
``gaitbench verify --json`` to the record as one compact line (the walk's case key, figures and reasons; not its
per-step table). ``summary`` reads the record, a walk verified in several sessions counting by its last line, and
prints as JSON, per strategy: the walks, how many are verified, the largest join mismatch, the energy appearing at
the joins, and the largest difference between a stored ACOT and the one recomputed from the trajectories; and every
walk that is not verified, with its reasons. ``--require-joins`` and ``--require-acot`` make it exit 1 unless every
walk's joins hold within :data:`~gaitbench.acceptance.MAX_JOIN_MISMATCH` and every stored ACOT is recomputed within
:data:`~gaitbench.acceptance.ACOT_RTOL` (of decrease and conquer's walks, with ``--strategy``), and ``--store`` unless
every complete walk of the sweep's store has a verdict in the record.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any, TextIO

from gaitbench.acceptance import ACOT_RTOL, MAX_JOIN_MISMATCH

KEPT = ("experiment", "strategy", "transcription", "N", "verified", "reasons", "acot", "stored_acot", "claimed_acot",
        "thesis_reading_acot", "max_join_mismatch", "join_energy", "max_resim_error", "max_defect")
"""The figures of a verdict the record keeps."""


def compact(verdict: dict[str, Any]) -> dict[str, Any]:
    """One verdict of ``gaitbench verify --json`` as a record line: its case key (the walk file's directory)."""
    return {"case": Path(verdict["walk"]).parent.name, **{key: verdict.get(key) for key in KEPT}}


def add(lines: TextIO, record: Path) -> int:
    """Append the verdicts read from ``lines`` to ``record``; how many."""
    verdicts = [compact(json.loads(line)) for line in lines if line.strip()]
    with record.open("a", encoding="utf-8") as out:
        for verdict in verdicts:
            out.write(json.dumps(verdict, sort_keys=True) + "\n")
    return len(verdicts)


def latest(record: Path) -> dict[str, dict[str, Any]]:
    """Each walk's last verdict in ``record``, by case key."""
    found: dict[str, dict[str, Any]] = {}
    for line in record.read_text(encoding="utf-8").splitlines():
        if line.strip():
            verdict = json.loads(line)
            found[verdict["case"]] = verdict
    return found


def acot_difference(verdict: dict[str, Any]) -> float | None:
    """|stored − recomputed| / recomputed ACOT; None where either is missing."""
    stored, recomputed = verdict.get("stored_acot"), verdict.get("acot")
    if stored is None or recomputed is None or recomputed == 0:
        return None
    return abs(stored - recomputed) / abs(recomputed)


def summary(verdicts: dict[str, dict[str, Any]]) -> dict[str, Any]:
    """Per strategy and in all: walks, verified, largest join mismatch, join energy and ACOT difference; the walks
    not verified with their reasons."""
    def figures(group: list[dict[str, Any]]) -> dict[str, Any]:
        mismatches = [v["max_join_mismatch"] for v in group if v.get("max_join_mismatch") is not None]
        differences = [d for v in group if (d := acot_difference(v)) is not None]
        return {"walks": len(group), "verified": sum(bool(v["verified"]) for v in group),
                "largest_join_mismatch": max(mismatches, default=None),
                "joins_unchecked": len(group) - len(mismatches),
                "largest_join_energy": max((v.get("join_energy") or 0.0 for v in group), default=None),
                "largest_acot_difference": max(differences, default=None),
                "acot_unchecked": len(group) - len(differences)}

    strategies = sorted({v["strategy"] for v in verdicts.values()})
    return {"all": figures(list(verdicts.values())),
            "by_strategy": {name: figures([v for v in verdicts.values() if v["strategy"] == name])
                            for name in strategies},
            "not_verified": {case: {"experiment": v["experiment"], "strategy": v["strategy"],
                                    "transcription": v["transcription"], "N": v["N"], "reasons": v["reasons"]}
                             for case, v in sorted(verdicts.items()) if not v["verified"]}}


def unrecorded(verdicts: dict[str, dict[str, Any]], store: Path, strategy: str | None) -> list[str]:
    """The complete walks of ``store`` (of ``strategy``) that have no verdict in the record."""
    from gaitbench.run.store import ResultStore

    with ResultStore.open(store) as results:
        keys = {row["case_key"] for row in results.cases() if row.get("status") == "solved" and row.get("walk_path")
                and (strategy is None or row.get("strategy") == strategy)}
    return sorted(keys - set(verdicts))


def acceptance_failures(verdicts: dict[str, dict[str, Any]], joins: bool, acot: bool) -> list[str]:
    """Every walk whose joins (``joins``) or stored ACOT (``acot``) the sweep's acceptance does not allow."""
    failures = []
    for case, verdict in sorted(verdicts.items()):
        mismatch, difference = verdict.get("max_join_mismatch"), acot_difference(verdict)
        if joins and not (mismatch is not None and mismatch <= MAX_JOIN_MISMATCH):
            failures.append(f"{case}: largest join mismatch {mismatch} (at most {MAX_JOIN_MISMATCH:g})")
        if acot and not (difference is not None and difference <= ACOT_RTOL):
            failures.append(f"{case}: stored ACOT {verdict.get('stored_acot')} against the recomputed "
                            f"{verdict.get('acot')} (within {ACOT_RTOL:.0%})")
    return failures


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    commands = parser.add_subparsers(dest="command", required=True)
    adding = commands.add_parser("add", help="append the verdicts of `gaitbench verify --json` (standard input)")
    adding.add_argument("record", type=Path)
    summing = commands.add_parser("summary", help="sum up the record (each walk's last verdict)")
    summing.add_argument("record", type=Path)
    summing.add_argument("--strategy", help="only the walks of this strategy (e.g. decrease-and-conquer)")
    summing.add_argument("--require-joins", action="store_true", help="exit 1 unless every join holds")
    summing.add_argument("--require-acot", action="store_true",
                         help="exit 1 unless every stored ACOT is recomputed within its tolerance")
    summing.add_argument("--store", type=Path, help="exit 1 unless every complete walk of this store (or pack), of "
                                                    "--strategy, has a verdict in the record")
    args = parser.parse_args()
    if args.command == "add":
        print(f"{args.record}: {add(sys.stdin, args.record)} verdicts added", file=sys.stderr)
        return
    verdicts = latest(args.record)
    if args.strategy:
        verdicts = {case: v for case, v in verdicts.items() if v["strategy"] == args.strategy}
    print(json.dumps(summary(verdicts), indent=1))
    failures = acceptance_failures(verdicts, args.require_joins, args.require_acot)
    if args.store is not None:
        failures += [f"{key}: a complete walk of {args.store} with no verdict in the record"
                     for key in unrecorded(verdicts, args.store, args.strategy)]
    for failure in failures:
        print(failure, file=sys.stderr)
    if failures:
        sys.exit(1)


if __name__ == "__main__":
    main()
