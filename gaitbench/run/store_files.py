"""The files a results store keeps beside its database, and which of them a run may delete.

A store writes only inside its own directory:

    cases/<case_key>/                a recorded case's files, and the marker ``.gaitbench-case`` naming the case
    .<case_key>-xxxxxxxx/            a case's files being written (staging): the marker first, then the files, then
                                     renamed to ``cases/<case_key>``
    checkpoints/<case_key>[.json]    a walk in flight's solved steps and its progress (gaitbench.checkpoint)
    checkpoints/.<name>.<pid>        a checkpoint file being written by process <pid>, then renamed over <name>

It deletes only what it can prove it wrote (:func:`leftovers`): a case or staging directory whose marker names the
case of its directory's name, a staging directory still empty (the kill came before its marker), and a checkpoint
file being written whose process is gone. A case directory without the marker (a store written before markers
existed, or a directory gaitbench never made) is never deleted; where a row names it, it is the case's files as
before, and replaced only when that case is recorded again.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import tempfile
from pathlib import Path

CASES_DIR = "cases"
CHECKPOINTS_DIR = "checkpoints"
CASE_MARKER = ".gaitbench-case"
"""The file in each case directory the store writes: JSON ``{"gaitbench": "case", "case_key": ...}``."""

_STAGING = re.compile(r"^\.(?P<key>[0-9a-f]{16})-[A-Za-z0-9_]+$")
_WRITING = re.compile(r"^\.[0-9a-f]{16}(\.json)?\.(?P<pid>[0-9]+)$")
"""A checkpoint or progress file being written (gaitbench.checkpoint's ``.<name>.<pid>``)."""


def case_file(case_key: str, name: str = "") -> str:
    """Where a case's files live, relative to the store directory (the form path columns hold)."""
    return f"{CASES_DIR}/{case_key}" + (f"/{name}" if name else "")


def checkpoint_file(case_key: str) -> str:
    """Where a case's walk keeps its solved steps while it runs, relative to the store directory."""
    return f"{CHECKPOINTS_DIR}/{case_key}"


def marked(directory: Path, case_key: str) -> bool:
    """Whether ``directory`` (not a link) holds the store's marker naming ``case_key``: the proof that a store wrote
    it, which is what lets a store delete it."""
    if directory.is_symlink() or not directory.is_dir():
        return False
    try:
        marker = json.loads((directory / CASE_MARKER).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return False
    return isinstance(marker, dict) and marker.get("gaitbench") == "case" and marker.get("case_key") == case_key


def place_case(store_dir: Path, case_key: str, files: dict[str, bytes], mode: int, replaceable: bool) -> None:
    """Write a case's ``files`` to ``cases/<case_key>`` as one directory (staged, marked, renamed into place), its
    permissions ``mode``. An earlier directory of the case is replaced when it carries the marker or
    ``replaceable`` (a row of the store names it); any other is refused (OSError), never deleted."""
    target = store_dir / case_file(case_key)
    if target.exists() or target.is_symlink():
        if not (marked(target, case_key) or (replaceable and target.is_dir() and not target.is_symlink())):
            raise FileExistsError(f"{target} exists but was not written by this store (it has no {CASE_MARKER}); "
                                  "move it away")
    staging = Path(tempfile.mkdtemp(prefix=f".{case_key}-", dir=store_dir))
    try:
        (staging / CASE_MARKER).write_text(json.dumps({"gaitbench": "case", "case_key": case_key}), encoding="utf-8")
        for name, content in files.items():
            if name != CASE_MARKER:
                (staging / name).write_bytes(content)
        staging.chmod(mode)  # mkdtemp's 0700 would hide the results from other users
        if target.exists():  # a retried case replaces its earlier files
            shutil.rmtree(target)
        target.parent.mkdir(exist_ok=True)
        os.replace(staging, target)
    finally:
        shutil.rmtree(staging, ignore_errors=True)


def case_files(store_dir: Path, case_key: str) -> dict[str, bytes]:
    """The files of one recorded case by name, without the store's marker."""
    directory = store_dir / case_file(case_key)
    if not directory.is_dir():
        return {}
    return {path.name: path.read_bytes() for path in sorted(directory.iterdir())
            if path.is_file() and path.name != CASE_MARKER}


def leftovers(store_dir: Path, named: set[str]) -> list[Path]:
    """What a killed run can leave that the store wrote and no row needs: marked staging directories (and empty
    ones), marked case directories that no row in ``named`` names, and checkpoint files being written by a process
    that is gone. Nothing without such proof."""
    found = []
    for path in _entries(store_dir):
        match = _STAGING.match(path.name)
        if match and not path.is_symlink() and path.is_dir() and (
                marked(path, match["key"]) or not any(path.iterdir())):
            found.append(path)
    found += [path for path in _entries(store_dir / CASES_DIR) if path.name not in named and marked(path, path.name)]
    for path in _entries(store_dir / CHECKPOINTS_DIR):
        match = _WRITING.match(path.name)
        if match and path.is_file() and not path.is_symlink() and not process_alive(int(match["pid"])):
            found.append(path)
    return found


def remove(path: Path) -> None:
    """Delete a path :func:`leftovers` found (a directory with all it holds)."""
    if path.is_dir() and not path.is_symlink():
        shutil.rmtree(path, ignore_errors=True)
    else:
        path.unlink(missing_ok=True)


def _entries(directory: Path) -> list[Path]:
    if directory.is_symlink() or not directory.is_dir():
        return []
    return sorted(directory.iterdir())


def process_alive(pid: int) -> bool:
    """Whether a process of this host has ``pid`` (a zombie is dead)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except OverflowError:  # a number no pid can be
        return False
    except PermissionError:  # another user's process
        return True
    try:
        return Path(f"/proc/{pid}/stat").read_text().rpartition(")")[2].split()[0] != "Z"
    except (OSError, IndexError):
        return True


def umask() -> int:
    """This process's umask, read without changing it where Linux tells it (changing it races other threads)."""
    try:
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith("Umask:"):
                return int(line.split()[1], 8)
    except (OSError, ValueError):
        pass
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def holds_anything(directory: Path) -> bool:
    """Whether ``directory`` has any entry (False when it cannot be read: mkdir and SQLite then say what is wrong)."""
    try:
        return next(directory.iterdir(), None) is not None
    except OSError:
        return False
