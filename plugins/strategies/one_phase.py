"""The One Phase strategy (:class:`gaitbench.solve.one_phase.OnePhase`), registered as ``one-phase``."""

from __future__ import annotations

from gaitbench import Registration, hookimpl
from gaitbench.solve.one_phase import OnePhase


@hookimpl
def register_strategies():
    return [Registration("one-phase", "Each step's 4-DOF problem solved directly from the blended guess "
                         "(the thesis's One Phase baseline)", OnePhase)]
