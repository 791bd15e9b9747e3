"""Walks read three ways: the verified COT, the same motion with the thesis's push-off term, and the thesis's reading.

Run:    OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/thesis_reading.py EXPERIMENT STRATEGY N STEPS [KEY=VALUE ...]
KEY=VALUE are problem options (``push_off_cost=thesis``, ``first_phase_cost=effort``) or ``quadrature=NAME`` for
Hermite–Simpson (``quadrature=nodal-simpson``). Prints one JSON line per step and one for the walk:

- ``cot``: the verified COT (fine-grid |hip power| of the interpolant, the push-off charged its kinetic-energy gain);
- ``cot_thesis_push_off``: the same hip energy with the push-off charged (3.77)'s ½ m_stance |v_foot|² instead;
- ``thesis_reading``: :func:`gaitbench.solve.thesis_reading.thesis_reading`, nodal powers and the thesis's push-off;
- ``objective_cot``: what the NLP's own objective says the step costs;
- for decrease-and-conquer, the same for the claimed patchwork (``claimed_*``) and the polished step (``polished_*``)
  with the iterations of the First Phase, the complete solve and the polish.
The docs/deviations.md figures on the thesis's reading and push-off term were measured with it.
"""

from __future__ import annotations

import json
import sys
import time

import numpy as np

from gaitbench.contracts import WalkProblem
from gaitbench.model.energetics import average_cot, cost_of_transport
from gaitbench.model.mechanics import BipedModel
from gaitbench.plugins import load_registry
from gaitbench.problem.gait_problem import ProblemOptions
from gaitbench.solve.thesis_reading import thesis_push_off_energy, thesis_reading
from gaitbench.walk_types import StepOutcome


def read_outcome(problem: WalkProblem, outcome: StepOutcome, model: BipedModel, prefix: str = "") -> dict:
    """The three readings of one solved outcome's trajectory."""
    trajectory, check = outcome.trajectory, outcome.verification
    data = problem.step_data(outcome.index, np.r_[trajectory.q[0], trajectory.dq[0]])
    robot = data.robot
    thesis_push_off = thesis_push_off_energy(trajectory, robot, model)
    return {f"{prefix}cot": check.cot, f"{prefix}objective_cot": check.objective_cot,
            f"{prefix}hip_energy": check.hip_energy, f"{prefix}push_off_energy": check.push_off_energy,
            f"{prefix}thesis_push_off_energy": thesis_push_off,
            f"{prefix}cot_thesis_push_off": float(cost_of_transport(check.hip_energy + thesis_push_off,
                                                                     robot.total_mass, data.chord, robot.g)),
            f"{prefix}thesis_reading": thesis_reading(trajectory, data, model).cot}


def measure(experiment_name: str, strategy: str, n_nodes: int, steps: int, settings: dict[str, str]) -> list[dict]:
    registry = load_registry()
    experiment = registry.create("experiment", experiment_name)
    quadrature = settings.pop("quadrature", None)
    transcription = registry.create("transcription", "hermite-simpson",
                                    **({"quadrature": quadrature} if quadrature else {}))
    options = ProblemOptions(limits=experiment.limits, **settings)
    problem = WalkProblem(experiment, transcription, registry.create("solver", "ipopt"), n_nodes, steps=steps,
                          options=options, objective=registry.create("objective", "net-power"))
    started = time.perf_counter()
    walk = registry.create("strategy", strategy).solve(problem)
    wall = time.perf_counter() - started
    model = BipedModel(experiment.robot, 4)
    rows = []
    for outcome in walk.steps:
        row = {"step": outcome.index, "status": outcome.status,
               "iterations": outcome.solver_result.iterations if outcome.solver_result else None}
        if outcome.solved:
            row |= read_outcome(problem, outcome, model, "claimed_" if strategy == "decrease-and-conquer" else "")
        if outcome.polished is not None and outcome.polished.solved:
            row |= read_outcome(problem, outcome.polished, model, "polished_")
            row |= {"first_phase_iterations": outcome.details["first_phase"]["iterations"],
                    "complete_iterations": outcome.details["complete"]["iterations"],
                    "complete_cot": outcome.details["complete"]["cot"],
                    "polished_iterations": outcome.polished.solver_result.iterations}
        rows.append(row)
    summary = {"experiment": experiment_name, "strategy": strategy, "N": n_nodes, "steps": steps,
               "settings": settings | ({"quadrature": quadrature} if quadrature else {}),
               "complete": walk.complete, "wall_s": round(wall, 1)}
    if walk.complete:
        for key in rows[0]:
            if key.endswith(("cot", "cot_thesis_push_off", "thesis_reading")) and all(
                    row.get(key) is not None for row in rows):
                summary[f"mean_{key}"] = average_cot([row[key] for row in rows])
    return [*rows, summary]


def main(argv: list[str]) -> None:
    experiment, strategy, n_nodes, steps, *pairs = argv
    settings = dict(pair.split("=", 1) for pair in pairs)
    for row in measure(experiment, strategy, int(n_nodes), int(steps), settings):
        print(json.dumps(row))


if __name__ == "__main__":
    main(sys.argv[1:])
