"""Copy a results store that runs are still writing into one that can be carried to the next session, walks in flight
included.

The long sweeps (`thesis-all`'s decrease-and-conquer walks at N >= 150 take hours each) outlive a session, and a
session's machine does not outlive it. So the snapshot carries, beside every finished case, the step checkpoints of
the walks in flight. A later run of the same suite on that store with ``--resume``, under the same commit (a
checkpoint resumes only under the code that saved it, :mod:`gaitbench.checkpoint`), goes on from the last saved step
instead of step 1. What is committed is a pack (`gaitbench runs pack`, docs/results.md "Packed stores"), which reads
like a store but leaves the checkpoints out.

The database is copied with SQLite's online backup (consistent while runs write to it, WAL included); the copy
drops the claims, whose runs do not travel with it. Case directories no row names and checkpoints of cases that
have a row are left out, as the runner would remove them.

    python benchmarks/snapshot_store.py ~/stores/thesis-all ~/carry/thesis-all
"""

from __future__ import annotations

import argparse
import shutil
import sqlite3
import tempfile
from pathlib import Path

from gaitbench.run.store import CASES_DIR, CHECKPOINTS_DIR


def snapshot(source: Path, destination: Path) -> dict[str, int]:
    """Replace ``destination`` by a consistent copy of the store at ``source``; how many cases and checkpoints."""
    destination.parent.mkdir(parents=True, exist_ok=True)
    staging = Path(tempfile.mkdtemp(prefix=f".{destination.name}-", dir=destination.parent))
    try:
        database = staging / "results.sqlite"
        with sqlite3.connect(f"file:{source / 'results.sqlite'}?mode=ro", uri=True) as live, \
                sqlite3.connect(database) as copy:
            live.backup(copy)
            copy.execute("DELETE FROM claims")
            copy.commit()
            copy.execute("PRAGMA journal_mode = DELETE")  # one file to commit, no -wal beside it
            keys = {row[0] for row in copy.execute("SELECT case_key FROM cases")}
        with_files = sorted(key for key in keys if (source / CASES_DIR / key).is_dir())
        for key in with_files:
            shutil.copytree(source / CASES_DIR / key, staging / CASES_DIR / key)
        in_flight = 0
        for checkpoint in sorted((source / CHECKPOINTS_DIR).glob("*")):
            if checkpoint.name.split(".")[0] in keys:
                continue
            (staging / CHECKPOINTS_DIR).mkdir(exist_ok=True)
            shutil.copy2(checkpoint, staging / CHECKPOINTS_DIR / checkpoint.name)
            in_flight += checkpoint.suffix != ".json"
        if destination.exists():
            shutil.rmtree(destination)
        staging.rename(destination)
    finally:
        shutil.rmtree(staging, ignore_errors=True)
    return {"cases": len(keys), "case_dirs": len(with_files), "checkpoints": in_flight}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("source", type=Path, help="the live store (a run's --store or suite output)")
    parser.add_argument("destination", type=Path, help="where the copy goes (replaced)")
    args = parser.parse_args()
    counts = snapshot(args.source, args.destination)
    print(f"{args.destination}: {counts['cases']} cases ({counts['case_dirs']} with files), "
          f"{counts['checkpoints']} walks in flight")


if __name__ == "__main__":
    main()
