"""Built step NLPs kept for the walks that come next, owned by whoever runs those walks.

Building a step NLP (and its solver) costs more than solving it at small N, and decrease-and-conquer builds N−3
sectional problems per walk. A section of M nodes is the step structure of M nodes whatever the walk's N, so walks
that share a :class:`BuildCache` build only what the earlier ones have not. Its lifetime is its owner's: one walk by
default (:class:`~gaitbench.contracts.WalkProblem`), a worker process in a suite run (:mod:`gaitbench.run.executors`),
so a fresh cache is all a test or a benchmark needs to time a walk as a fresh process would.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

if TYPE_CHECKING:  # at run time only their methods are used: importing this costs no CasADi
    from gaitbench.problem.gait_problem import StepStructure
    from gaitbench.problem.transcription import Transcription


class BuildCache:
    """Transcription instances whose builds serve later walks: one per configuration."""

    def __init__(self) -> None:
        self._kept: list[Transcription] = []

    def builder(self, transcription: Transcription, structure: StepStructure) -> Transcription:
        """The kept instance that builds like ``transcription`` (``transcription`` itself the first time).

        Only the builds of ``structure``'s problem options and objective are kept (another experiment's limits
        make other structures), so the cache holds at most the builds of its largest walk per transcription: what
        that walk needed anyway.
        """
        builder = next((kept for kept in self._kept if kept.builds_like(transcription)), None)
        if builder is None:
            self._kept.append(builder := transcription)
        for kept in self._kept:
            kept.keep_builds(lambda built: (built.options, built.objective) == (structure.options, structure.objective))
        return builder
