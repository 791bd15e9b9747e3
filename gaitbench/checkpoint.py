"""Step checkpoints: a walk stopped from outside resumes after the last step it solved.

A decrease-and-conquer walk at N = 200 takes hours. When its process is killed (a crashed worker, a machine
shut down, the end of a session), every step it had solved was lost, and the case started again from step 1. With a
checkpoint, the walk saves its solved steps after each one, and a later run of the same case continues from there.
Since each step depends only on the state the step before it left (docs/model.md §7), the resumed walk is the walk that
was not stopped.

The steps are kept as they are in memory (their solver results, verifications and trajectories with their
interpolants), pickled with cloudpickle because the interpolants are closures. A checkpoint is resumed only by the
same case under the same code (the runner's :func:`gaitbench.run.provenance.code_fingerprint`, a hash of the source
that solves walks, and :func:`~gaitbench.run.provenance.plugins_fingerprint`, the plugins from outside gaitbench);
any other is discarded, so a walk never mixes steps solved by different code.

Beside each checkpoint, a small JSON file (:func:`progress_file`) says how many of the walk's steps are saved, for a
progress display that should not unpickle whole walks to show it.
"""

from __future__ import annotations

import contextlib
import json
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import cloudpickle


@dataclass
class WalkCheckpoint:
    """The solved steps of one walk, saved at ``path`` after each step; ``fingerprint`` names the case and the
    code, so that only the same case under the same code resumes them."""

    path: Path
    fingerprint: dict[str, Any]
    steps: list[Any] = field(default_factory=list)
    """The walk's solved steps (:class:`gaitbench.walk_types.StepOutcome`), kept whole; this module does not look
    inside them, so that it stands below the walk that uses it."""
    backed_up: set[int] = field(default_factory=set)
    """Steps solved again after a dead end (each is backed up at most once, resumed or not)."""
    elapsed_s: float = 0.0
    """The walk's time before it was stopped: it counts toward the case's time limit and wall time."""
    discarded: str = ""
    """Why a checkpoint found at ``path`` was not resumed (another case or other code; unreadable); empty if none."""

    @classmethod
    def open(cls, path: str | Path, fingerprint: dict[str, Any]) -> WalkCheckpoint:
        """The checkpoint at ``path`` if it was saved by this ``fingerprint``, else an empty one (a mismatched or
        unreadable file is removed, and :attr:`discarded` says why)."""
        checkpoint = cls(Path(path), fingerprint)
        if not checkpoint.path.is_file():
            return checkpoint
        try:
            saved = cloudpickle.loads(checkpoint.path.read_bytes())
        except Exception as error:  # a file cut short by the kill it is there for, or from another Python
            checkpoint.discarded = f"unreadable ({type(error).__name__}: {error})"
        else:
            if not isinstance(saved, dict) or saved.get("fingerprint") != fingerprint:
                theirs = saved.get("fingerprint") if isinstance(saved, dict) else None
                checkpoint.discarded = f"saved by {theirs}, not by {fingerprint}"
            else:
                checkpoint.steps, checkpoint.backed_up = saved["steps"], set(saved["backed_up"])
                checkpoint.elapsed_s = float(saved["elapsed_s"])
                return checkpoint
        try:
            remove_checkpoint(checkpoint.path)
        except OSError as error:
            raise CheckpointError(f"{checkpoint.path}: cannot remove the checkpoint ({_reason(error)})") from None
        return checkpoint

    def save(self, steps: list[Any], backed_up: set[int], elapsed_s: float, of: int | None = None) -> None:
        """Keep ``steps`` (every one solved, of ``of`` the walk has) on disk for a resumed walk; the attributes stay
        what was opened. :class:`CheckpointError` where the file cannot be written (a full disk, a directory that
        cannot be written): the store failing, which ends the run rather than fails the case."""
        content = cloudpickle.dumps({"fingerprint": self.fingerprint, "steps": list(steps),
                                     "backed_up": sorted(backed_up), "elapsed_s": elapsed_s})
        try:
            _write_whole(self.path, content)
            _write_whole(progress_file(self.path), json.dumps({"saved": len(steps), "of": of, "elapsed_s": elapsed_s,
                                                               "code": self.fingerprint.get("code")}).encode())
        except OSError as error:
            raise CheckpointError(f"{self.path}: cannot save the walk's checkpoint ({_reason(error)})") from None


class CheckpointError(Exception):
    """A checkpoint that cannot be written or removed; the message names the file and the cause."""


def remove_checkpoint(path: str | Path) -> None:
    """Remove the checkpoint at ``path`` and its progress file: the walk's outcome is recorded, or it is to be
    solved from step 1."""
    Path(path).unlink(missing_ok=True)
    progress_file(Path(path)).unlink(missing_ok=True)


def progress_file(path: Path) -> Path:
    """The JSON file beside the checkpoint at ``path``: ``{"saved": steps saved, "of": the walk's steps,
    "elapsed_s": its time, "code": the code fingerprint that saved it}``."""
    return path.with_name(f"{path.name}.json")


def saved_progress(directory: str | Path) -> dict[str, dict[str, Any]]:
    """The progress files of the checkpoints in ``directory``, by checkpoint name (a store's: the case key); a
    file being replaced or cut short is left out."""
    found = {}
    for path in Path(directory).glob("*.json") if Path(directory).is_dir() else ():
        try:
            found[path.name.removesuffix(".json")] = json.loads(path.read_text())
        except (OSError, ValueError):
            continue
    return found


def _write_whole(path: Path, content: bytes) -> None:
    """Write ``.<name>.<pid>`` and then rename it, so that a kill during the write leaves the previous file; a
    write that fails (a full disk) removes its part-written file."""
    path.parent.mkdir(parents=True, exist_ok=True)
    staging = path.with_name(f".{path.name}.{os.getpid()}")
    try:
        staging.write_bytes(content)
        os.replace(staging, path)
    except BaseException:
        with contextlib.suppress(OSError):
            staging.unlink(missing_ok=True)
        raise


def _reason(error: OSError) -> str:
    return error.strerror or str(error)
