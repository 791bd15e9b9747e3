"""Step checkpoints: a walk stopped from outside resumes after the last step it solved.

A decrease-and-conquer walk at N = 200 takes hours. When its process is killed (a crashed worker, a machine
shut down, the end of a session), every step it had solved was lost, and the case started again from step 1. With a
checkpoint, the walk saves its solved steps after each one, and a later run of the same case continues from there.
Since each step depends only on the state the step before it left (DECISIONS §7), the resumed walk is the walk that
was not stopped.

The steps are kept as they are in memory (their solver results, verifications and trajectories with their
interpolants), pickled with cloudpickle because the interpolants are closures. A checkpoint is resumed only by the
same case under the same code (the runner's :func:`gaitbench.run.provenance.code_fingerprint`); any other is
discarded, so a walk never mixes steps solved by different code.
"""

from __future__ import annotations

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
    """The walk's solved steps (:class:`gaitbench.solve.walk.StepOutcome`), kept whole; this module does not look
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
        checkpoint.path.unlink(missing_ok=True)
        return checkpoint

    def save(self, steps: list[Any], backed_up: set[int], elapsed_s: float) -> None:
        """Keep ``steps`` (every one solved) for a resumed walk; written whole and then renamed, so that a kill
        during the write leaves the previous checkpoint."""
        self.steps, self.backed_up, self.elapsed_s = list(steps), set(backed_up), elapsed_s
        self.path.parent.mkdir(parents=True, exist_ok=True)
        staging = self.path.with_name(f".{self.path.name}.{os.getpid()}")
        staging.write_bytes(cloudpickle.dumps({"fingerprint": self.fingerprint, "steps": self.steps,
                                               "backed_up": sorted(self.backed_up), "elapsed_s": elapsed_s}))
        os.replace(staging, self.path)

    def discard(self) -> None:
        """Remove the saved steps: the walk's outcome is recorded, or it is to be solved from step 1."""
        self.path.unlink(missing_ok=True)
