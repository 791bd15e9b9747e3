"""One-step gait problems as :class:`ReferenceProblem` s, for testing solver plugins on the NLPs they exist for.

An experiment's first step, Second Phase (4-DOF), by default on the upward slope (a step that costs real work),
from the transcription's standard initial guess. A small torque tie-break makes the optimum unique (the thesis's
cost alone has a flat set of optima, so solvers could legitimately stop at different points with the same cost);
``f_star`` is IPOPT's optimum, computed, not typed in.
"""

from __future__ import annotations

from functools import cache

from nlp_problems import ReferenceProblem

from gaitbench.gait_problem import ProblemOptions, StepData, StepStructure
from gaitbench.plugins import load_registry
from plugins.ipopt import Ipopt

TIE_BREAK = 1e-3
"""Weight of ∫τ² next to the cost of transport: enough to make the optimum unique, small against the COT."""


@cache
def gait_step(transcription: str, n_nodes: int, experiment_name: str = "upward-slope",
              phase: str = "second") -> ReferenceProblem:
    registry = load_registry()
    experiment = registry.create("experiment", experiment_name)
    geometry = experiment.terrain.steps[0]
    data = StepData(experiment.robot, experiment.stance_leg(1), experiment.initial_state[[0, 1, 4, 5]], geometry.D,
                    geometry.theta, experiment.time_step(n_nodes))
    options = ProblemOptions(limits=experiment.limits, torque_regularization=TIE_BREAK)
    built = registry.create("transcription", transcription).build(StepStructure(phase, n_nodes, options))
    parameters, x0 = data.parameter_vector(), built.initial_guess(data)
    reference = Ipopt().solve(built.nlp, parameters, x0)
    if not reference.converged:
        raise RuntimeError(f"IPOPT does not solve {experiment_name} step 1 ({transcription}, N={n_nodes}): "
                           f"{reference.message}")
    return ReferenceProblem(f"{experiment_name}-step-{transcription}-{n_nodes}", built.nlp, parameters, x0,
                            reference.objective, reference.x)
