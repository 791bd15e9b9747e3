"""One-step gait problems as :class:`ReferenceProblem` s, for testing solver plugins on the NLPs they exist for.

An experiment's first step, Second Phase (4-DOF), by default on the upward slope (a step that costs real work),
from the transcription's standard initial guess. A small torque tie-break makes the optimum unique (the thesis's
cost alone has a flat set of optima, so solvers could legitimately stop at different points with the same cost);
``f_star`` is IPOPT's optimum, computed, not typed in.
"""

from __future__ import annotations

from functools import cache

from nlp_problems import ReferenceProblem

from gaitbench.plugins import load_registry
from gaitbench.problem.gait_problem import ProblemOptions, StepData, StepStructure
from gaitbench_plugins.solvers.ipopt import Ipopt

TIE_BREAK = 1e-3
"""Weight of ∫τ² next to the cost of transport: enough to make the optimum unique, small against the COT."""
FORMER_QUADRATURE = {"hermite-simpson": "simpson", "dmoc": "midpoint", "trapezoidal": "trapezoid"}
"""The hip-energy rules the transcriptions had before Boole's rule became their default (DMOC and trapezoidal
collocation first, Hermite–Simpson since 2026-12-02, whose former rule is Simpson's on nodes and midpoints). Tests
whose numbers were measured on those NLPs (iteration counts, a line search, the size of a translation) ask for them:
the Boole NLPs have five |P| splits per interval, degenerate together on intervals without torque, and some solvers
find them harder."""


@cache
def gait_step(transcription: str, n_nodes: int, experiment_name: str = "upward-slope",
              phase: str = "second", quadrature: str | None = None) -> ReferenceProblem:
    """``quadrature``: the transcription's hip-energy rule (its default unless given)."""
    registry = load_registry()
    experiment = registry.create("experiment", experiment_name)
    geometry = experiment.terrain.steps[0]
    data = StepData(experiment.robot, experiment.stance_leg(1), experiment.initial_state[[0, 1, 4, 5]], geometry.D,
                    geometry.theta, experiment.time_step(n_nodes))
    options = ProblemOptions(limits=experiment.limits, torque_regularization=TIE_BREAK)
    transcriber = registry.create("transcription", transcription, **({"quadrature": quadrature} if quadrature else {}))
    built = transcriber.build(StepStructure(phase, n_nodes, options))
    parameters, x0 = data.parameter_vector(), built.initial_guess(data)
    reference = Ipopt().solve(built.nlp, parameters, x0)
    if not reference.converged:
        raise RuntimeError(f"IPOPT does not solve {experiment_name} step 1 ({transcription}, N={n_nodes}): "
                           f"{reference.message}")
    label = f"{transcription}-{quadrature}" if quadrature else transcription
    return ReferenceProblem(f"{experiment_name}-step-{label}-{n_nodes}", built.nlp, parameters, x0,
                            reference.objective, reference.x)
