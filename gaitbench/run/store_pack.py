"""Packing a results store into one deterministic ``.tar.xz``, and unpacking one into a store that can be written.

:func:`pack_store` writes what :mod:`gaitbench.run.pack_format` describes: a consistent copy of the database
(SQLite's online backup, so a store a run is writing packs as it was at one moment, with the files of the cases
that moment held; the claims of live runs
dropped, since no run travels with the pack; one file in rollback-journal mode, compacted), each case's files
(every trajectory, or only those the caller names), and the manifest. Walks in flight (``checkpoints/``) are left
out: a pack is read, never resumed.

The same store packs to the same bytes: members in sorted order, modification time 0, owner 0 with no user names,
fixed permissions, one xz preset. So a pack can be rebuilt and compared, and a committed pack changes only when
the store does.
"""

from __future__ import annotations

import io
import json
import lzma
import os
import shutil
import sqlite3
import tarfile
import tempfile
from collections.abc import Collection
from contextlib import closing
from dataclasses import dataclass
from pathlib import Path

from gaitbench.run.pack_format import (
    MANIFEST,
    PACK_FORMAT,
    TRAJECTORY_MODES,
    TRAJECTORY_SUFFIX,
    PackError,
    extract,
    read_manifest,
)
from gaitbench.run.store import DATABASE, ResultStore
from gaitbench.run.store_files import CASES_DIR, holds_anything, remove, umask
from gaitbench.run.store_schema import failure_cause

XZ_PRESET = 9
"""xz's strongest standard preset: a pack is written once and read many times."""


@dataclass(frozen=True)
class PackSummary:
    """What :func:`pack_store` wrote."""

    path: Path
    cases: int
    files: int
    trajectories_kept: int
    trajectories_left_out: int
    size: int


def pack_store(store_dir: str | Path, out: str | Path, trajectories: str = "all",
               keep: Collection[str] = ()) -> PackSummary:
    """Pack the store at ``store_dir`` into ``out`` (a ``.tar.xz``, replaced as a whole when it exists).

    ``trajectories`` is ``all`` (every ``*.npz``) or ``report``: then only the trajectory files in ``keep``
    (paths relative to the store, as :func:`gaitbench.reports.report_trajectories` gives them). A
    :class:`~gaitbench.run.store_schema.StoreError` (one line) when the store cannot be read or ``out`` written.
    """
    if trajectories not in TRAJECTORY_MODES:
        raise ValueError(f"trajectories must be one of {', '.join(TRAJECTORY_MODES)}, not {trajectories!r}")
    out = Path(out)
    with ResultStore.open(store_dir) as store:
        directory, database = store.directory, store.database
    name = directory.resolve().name  # a pack's own name in the cache (gaitbench.run.pack_cache)
    source = read_manifest(directory)
    if trajectories == "all" and source is not None and source.get("trajectories") != "all":
        raise PackError(f"{store_dir}: holds only some trajectories (a pack made with --trajectories "
                        f"{source.get('trajectories')}); pack the whole store for --trajectories all")
    # the cases are those of the database's copy: a case a run records after it has no row in the pack, and every row
    # in it has its files (they are in place before the row is committed)
    copied, keys = _database_copy(database)
    files = {DATABASE: copied}
    kept = left_out = 0
    for key in keys:
        case_dir = directory / CASES_DIR / key
        if case_dir.is_symlink() or not case_dir.is_dir():
            continue
        for path in sorted(case_dir.iterdir()):
            relative = f"{CASES_DIR}/{key}/{path.name}"
            if path.is_symlink() or not path.is_file():
                continue
            if path.suffix == TRAJECTORY_SUFFIX:
                if trajectories != "all" and relative not in keep:
                    left_out += 1
                    continue
                kept += 1
            files[relative] = _read(path)
    cases = len(keys)
    files[MANIFEST] = (json.dumps({"gaitbench": "pack", "format": PACK_FORMAT, "store": name,
                                   "trajectories": trajectories, "cases": cases, "trajectories_kept": kept,
                                   "trajectories_left_out": left_out}, indent=1, sort_keys=True) + "\n").encode()
    _write_tar(out, name, files)
    return PackSummary(out, cases, len(files), kept, left_out, out.stat().st_size)


def _database_copy(database: Path) -> tuple[bytes, list[str]]:
    """The database as one file: an online backup (what the WAL holds merged in), claims dropped, compacted; and
    the case keys it holds, sorted."""
    with tempfile.TemporaryDirectory(prefix="gaitbench-pack-") as scratch:
        copy_path = Path(scratch) / DATABASE
        try:
            with closing(sqlite3.connect(f"{database.resolve().as_uri()}?mode=ro", uri=True)) as source, \
                    closing(sqlite3.connect(copy_path, isolation_level=None)) as copy:
                source.backup(copy)
                if copy.execute("SELECT 1 FROM sqlite_master WHERE type = 'table' AND name = 'claims'").fetchone():
                    copy.execute("DELETE FROM claims")
                copy.execute("PRAGMA journal_mode = DELETE")
                copy.execute("VACUUM")
                keys = sorted(key for (key,) in copy.execute("SELECT case_key FROM cases"))
        except sqlite3.Error as error:
            raise PackError(f"{database}: cannot copy the results store ({failure_cause(error)})") from None
        return copy_path.read_bytes(), keys


def _read(path: Path) -> bytes:
    try:
        return path.read_bytes()
    except OSError as error:
        raise PackError(f"{path}: cannot read it to pack it ({error.strerror or error})") from None


def _write_tar(out: Path, name: str, files: dict[str, bytes]) -> None:
    """``files`` under the top directory ``name`` as a deterministic xz tar at ``out``, written beside it first and
    renamed over it, so a failed pack leaves no half-written file."""
    try:
        out.parent.mkdir(parents=True, exist_ok=True)
        handle, staging = tempfile.mkstemp(prefix=f".{out.name}-", dir=out.parent)
    except OSError as error:
        raise PackError(f"{out}: cannot write the pack here ({error.strerror or error})") from None
    try:
        with os.fdopen(handle, "wb") as raw, lzma.open(raw, "wb", preset=XZ_PRESET) as xz, \
                tarfile.open(fileobj=xz, mode="w", format=tarfile.PAX_FORMAT) as tar:
            for relative in sorted(files):
                content = files[relative]
                member = tarfile.TarInfo(f"{name}/{relative}")
                member.size, member.mtime, member.mode = len(content), 0, 0o644
                member.uid = member.gid = 0
                member.uname = member.gname = ""
                tar.addfile(member, io.BytesIO(content))
        os.chmod(staging, 0o666 & ~umask())
        os.replace(staging, out)
    except OSError as error:
        raise PackError(f"{out}: cannot write the pack ({error.strerror or error})") from None
    finally:
        if os.path.exists(staging):
            os.unlink(staging)


def unpack_store(pack: str | Path, destination: str | Path) -> Path:
    """Unpack ``pack`` into the store directory ``destination`` (new or empty), as files that can be written: a
    store to run into, resume or re-verify. Returns ``destination``; :class:`PackError` when it holds anything."""
    destination = Path(destination)
    if destination.exists() and (not destination.is_dir() or holds_anything(destination)):
        raise PackError(f"{destination}: not empty; unpack into a new or empty directory")
    made = not destination.exists()
    try:
        extract(Path(pack), destination)
    except PackError:  # the directory was new or empty: nothing of it stays
        for entry in destination.iterdir() if destination.is_dir() else ():
            remove(entry)
        if made:
            shutil.rmtree(destination, ignore_errors=True)
        raise
    return destination

