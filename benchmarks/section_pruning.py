"""Which of decrease-and-conquer's sectional solves its output depends on, and why failed sections fail.

Run:    OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/section_pruning.py EXPERIMENT TRANSCRIPTION N STEPS
        .venv/bin/python benchmarks/section_pruning.py --summarize benchmarks/results/section_pruning/*.json
Writes benchmarks/results/section_pruning/<experiment>-<transcription>-<N>-<steps>.json, per step:

- ``sections``: every sectional solve (k0, status, iterations) and, for a failed one, the constraint blocks it
  leaves violated (largest violation per block) at the point IPOPT stops at, and those its initial guess (the
  strategy's, slacks settled) violates;
- ``removable``: the converged sections whose omission (as if they had failed) leaves the chosen trajectory
  bit-identical, found by re-running the synthesis, completion and final choice without each in turn — what an
  oracle that knew every solution could prune, the ceiling for any exact rule;
- ``energy_flagged``: the sections an energy-bound rule would skip (the candidate rule of docs/decisions/
  0014-section-pruning.md): the completed candidate's COT with the section's own point costs replaced by the
  energy it must at least supply, max(0, V_end − V_start − K_start) / h, exceeds the chosen option's; and which
  of those the output does depend on (``energy_flagged_needed``), where skipping would have changed it;
- for each failed section, ``probes``: whether it is feasible after all — solved again from the complete Second Phase
  solution's tail (``sectional_guess = "complete"``), and IPOPT's feasibility problem (zero objective) from the same
  guess as the strategy's, with all its constraints and with one group relaxed (torque limits ×10; no lift-off; no
  clearance and leg-angle windows): which constraints a certificate of infeasibility would have to reason about; and
  ``reachability``: whether a sound certificate of the kind "the lift-off condition cannot be met from the section's
  start state" could exist in its cheapest form, each leg angle a continuous-time double integrator |q̈_i| ≤ A_i from
  the fixed start state to the fixed heel-strike pose in (N − k0) h, with A_i the torque limit's share alone (less
  than any sound bound: ``torque_only``) and with gravity and Coriolis at the velocities the torques could reach
  (``sampled``, still no upper bound); a certificate needs ``max_lift_off`` below the lift-off rate, and must not be
  met by any section that converges or is feasible after all (computed for every section);
- ``zero_cost_nodes``: synthesized nodes whose point cost is exactly 0, the only nodes where a section with no
  positive per-node bound could be ranked after the synthesized candidate.

The walk is the one the strategy solves on its own (IPOPT defaults); the replayed choice is checked against the
label the strategy recorded, so a replay that drifted from the strategy would stop the script.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import casadi as ca
import numpy as np
from dc_profile import ipopt_walk  # its sibling in benchmarks/

from gaitbench.contracts import WalkProblem
from gaitbench.model.energetics import candidate_cot
from gaitbench.model.mechanics import BipedModel, biped_functions
from gaitbench.plugins import load_registry
from gaitbench.problem.gait_problem import role_robot_vector, roles_to_legs
from gaitbench.solve.synthesis import synthesize

OUT = Path(__file__).parent / "results" / "section_pruning"


def choose(nodes, starts: list[int], n: int, mass: float, chord: float, g: float, max_checks: int):
    """The strategy's synthesis, completion and final choice by candidate COT: (label, chosen patch, candidate COTs,
    synthesis)."""
    import gaitbench_plugins.strategies.decrease_and_conquer as dc

    synthesis = synthesize(nodes.pcot, nodes.values, max_checks=max_checks)
    completed = nodes.completed(starts)
    options = {"synthesized": nodes.patch(synthesis.selection)}
    options |= {dc._label(start): completed.patch([j] * n) for j, start in enumerate(starts)}
    cots = {label: candidate_cot(patch.pcot, mass, chord, g) for label, patch in options.items()}
    label = min(cots, key=cots.get)
    return label, options[label], cots, synthesis


def without(nodes, j: int):
    """``nodes`` without candidate ``j``."""
    keep = [i for i in range(nodes.q.shape[0]) if i != j]
    return type(nodes)(nodes.q[keep], nodes.dq[keep], nodes.tau[keep], nodes.push_off[keep],
                       nodes.push_off_energy[keep], nodes.costs)


def same_patch(a, b) -> bool:
    return all(np.array_equal(getattr(a, name), getattr(b, name), equal_nan=True)
               for name in ("q", "dq", "tau", "push_off", "push_off_energy"))


def analyse(experiment_name: str, transcription: str, n_nodes: int, steps: int) -> dict:
    import gaitbench_plugins.strategies.decrease_and_conquer as dc

    problem = ipopt_walk(experiment_name, transcription, n_nodes, steps)
    strategy = load_registry().create("strategy", "decrease-and-conquer")
    record: dict = {"experiment": experiment_name, "transcription": transcription, "N": n_nodes, "steps": []}
    pending: dict = {"sections": []}
    solve_one, node_values_of = dc.SectionalSolves.solve_one, dc.NodeValues.__dict__["of"]
    solve_with_retries = dc.solve_with_retries

    def recorded_solve(*args, **kwargs):
        outcome = solve_with_retries(*args, **kwargs)
        if kwargs.get("phase") == "first" and outcome.solved:  # the First Phase the sections start from
            pending["first"] = outcome.trajectory
        return outcome

    def recorded_section(sections, task):
        k0, parameters, _ = task
        result = solve_one(sections, task)
        entry = {"k0": k0, "status": result.status.value, "iterations": result.iterations}
        if not result.converged:
            violations = sections.built[k0].nlp.block_violations(result.x, parameters)
            entry["violated"] = {name: value for name, value in violations.items() if value > 1e-6}
            at_guess = sections.built[k0].nlp.block_violations(sections.built[k0].settle_slacks(task[2], parameters),
                                                               parameters)
            entry["guess_violates"] = {name: value for name, value in at_guess.items() if value > 1e-6}
            pending.setdefault("failed", []).append((entry, sections.built[k0], task))
        pending["sections"].append(entry)
        return result

    def recorded_nodes(cls, candidates, starts, *args, **kwargs):
        nodes = node_values_of.__func__(cls, candidates, starts, *args, **kwargs)  # the classmethod's function
        pending.update(candidates=candidates, starts=list(starts), nodes=nodes)
        return nodes

    def on_step(step):
        if "nodes" not in pending:
            record["steps"].append({"index": step.index, "solved": False, "sections": pending["sections"]})
        else:
            record["steps"].append(step_record(problem, step, pending, strategy.max_checks))
            for entry, built, task in pending.get("failed", []):
                entry["probes"] = probes(problem, built, task, pending["candidates"][0])
            for entry in pending["sections"]:  # converged ones too: a certificate must pass every one of them
                entry["reachability"] = reachability(problem, step.index, pending["first"], entry["k0"])
        pending.clear()
        pending["sections"] = []

    dc.SectionalSolves.solve_one, dc.NodeValues.of = recorded_section, classmethod(recorded_nodes)
    dc.solve_with_retries = recorded_solve
    try:
        walk = strategy.solve(problem, on_step=on_step)
    finally:
        dc.SectionalSolves.solve_one, dc.NodeValues.of = solve_one, node_values_of
        dc.solve_with_retries = solve_with_retries
    record |= {"complete": walk.complete, "verified_acot": walk.acot}
    return record


RELAXATIONS = {"as posed": ((), 1.0), "torque limits x10": ((), 10.0), "no lift-off": (("lift_off",), 1.0),
               "no clearance, leg angles": (("clearance", "leg_angles"), 1.0)}
"""Feasibility probes of a failed section: constraint blocks dropped and the factor on the torque limits."""


def probes(problem: WalkProblem, built, task, complete) -> dict:
    """Whether a failed section is feasible after all (see the module's docstring)."""
    k0, parameters, guess = task
    nlp, h = built.nlp, problem.experiment.time_step(problem.n_nodes)
    tail = np.zeros(nlp.n_variables)  # TranscribedStep.initial_guess, from the complete solution's tail
    for name, values in built.discretization.guess(complete.seed((k0 - 1) * h), parameters).items():
        tail[nlp.variable_blocks[name]] = values
    again = problem.solver.solve(nlp, parameters, tail)
    result = {"complete_seed": {"status": again.status.value, "iterations": again.iterations}}
    casadi = nlp.casadi_problem()
    feasibility = ca.nlpsol("feasibility", "ipopt", {**casadi, "f": 0 * casadi["f"]},
                            {"print_time": 0, "ipopt.print_level": 0, "ipopt.sb": "yes", "ipopt.max_iter": 3000})
    for label, (blocks, torque_factor) in RELAXATIONS.items():
        lbx, ubx, lbg, ubg = nlp.lbx.copy(), nlp.ubx.copy(), nlp.lbg.copy(), nlp.ubg.copy()
        torques = nlp.variable_blocks["torques"]
        lbx[torques], ubx[torques] = lbx[torques] * torque_factor, ubx[torques] * torque_factor
        for block in blocks:
            if block in nlp.constraint_blocks:
                lbg[nlp.constraint_blocks[block]], ubg[nlp.constraint_blocks[block]] = -np.inf, np.inf
        feasibility(x0=guess, p=parameters, lbx=lbx, ubx=ubx, lbg=lbg, ubg=ubg)
        stats = feasibility.stats()
        result[label] = {"feasible_point_found": bool(stats["success"]), "iterations": int(stats["iter_count"])}
    return result


def reachability(problem: WalkProblem, index: int, first, k0: int) -> dict:
    """The double-integrator relaxation of a section's lift-off condition (see the module's docstring)."""
    experiment, n = problem.experiment, problem.n_nodes
    data = problem.step_data(index, np.r_[first.q[0], first.dq[0]])
    limits, h, stance, robot = problem.options.limits, data.time_step, data.stance, data.robot
    roles = role_robot_vector(robot, stance)
    alpha = np.arcsin(data.chord / (2 * robot.l))
    end_roles = np.array([data.slope - alpha, data.slope + alpha])
    model4, rates, impulse = biped_functions(4, 1), ca.SX.sym("rates", 2), ca.SX.sym("impulse")
    pose = ca.vertcat(end_roles, 0, 0)
    after, _ = model4.heel_strike(pose, model4.push_off(pose, ca.vertcat(rates, 0, 0), impulse, roles), roles)
    lift = (-np.sin(data.slope) * after[2] + np.cos(data.slope) * after[3]) / robot.l  # linear in (rates, impulse)
    gradient = np.array(ca.Function("g", [rates, impulse], [ca.jacobian(lift, ca.vertcat(rates, impulse))])(0, 0))
    offset = float(ca.Function("c", [rates, impulse], [lift])(0, 0))
    slope = roles_to_legs(gradient.ravel()[:2], stance)
    best_impulse = max(0.0, float(gradient.ravel()[2]) * limits.push_off_max)
    model, duration = BipedModel(robot, 2), (n - k0) * h
    poses, start_q, start_dq = first.q[k0 - 1:], first.q[k0 - 1], first.dq[k0 - 1]
    end_q = np.asarray(experiment.heel_strike_configuration(index))
    torque_only = np.min([limits.tau_max * np.abs(np.linalg.inv(np.asarray(model.mass_matrix(q, stance), float)))
                          .sum(axis=1) for q in poses], axis=0)
    sampled = np.zeros(2)
    for q in poses:
        for signs in np.array(np.meshgrid(*[(-1, 1)] * 4)).reshape(4, -1).T:
            dq = start_dq + duration * torque_only * signs[:2]
            accelerations = model.forward_dynamics(q, dq, limits.tau_max * signs[2:], stance)[0]
            sampled = np.maximum(sampled, np.abs(np.asarray(accelerations, float).ravel()[:2]))
    result = {"lift_off_rate": problem.options.lift_off_rate}
    for label, bound in (("torque_only", torque_only), ("sampled", sampled)):
        ranges = [_end_rate_range(start_dq[i], end_q[i] - start_q[i], duration, bound[i]) for i in range(2)]
        if None in ranges:
            result[label] = {"max_lift_off": None, "certifies": True}
            continue
        most = offset + best_impulse + sum(slope[i] * ranges[i][1 if slope[i] > 0 else 0] for i in range(2))
        result[label] = {"max_lift_off": most, "certifies": bool(most < problem.options.lift_off_rate)}
    return result


def _end_rate_range(rate: float, distance: float, duration: float, bound: float) -> tuple[float, float] | None:
    """The end rates of x'' ∈ [−bound, bound] that cover ``distance`` in ``duration`` from ``rate`` (bang-bang with one
    switch); None where the distance cannot be covered."""
    drift = (distance - rate * duration) / bound
    if abs(drift) > duration ** 2 / 2:
        return None
    return (rate - bound * (2 * np.sqrt(duration ** 2 / 2 - drift) - duration),
            rate + bound * (2 * np.sqrt(duration ** 2 / 2 + drift) - duration))


def step_record(problem: WalkProblem, step, pending: dict, max_checks: int) -> dict:
    experiment, n = problem.experiment, problem.n_nodes
    robot, chord = experiment.robot, experiment.terrain.steps[step.index - 1].D
    nodes, starts, candidates = pending["nodes"], pending["starts"], pending["candidates"]
    label, chosen, cots, synthesis = choose(nodes, starts, n, robot.total_mass, chord, robot.g, max_checks)
    if label != step.details["chosen"]:
        raise RuntimeError(f"step {step.index}: the replay chose {label}, the strategy {step.details['chosen']}")
    removable = [starts[j] + 1 for j in range(1, len(starts))
                 if same_patch(choose(without(nodes, j), starts[:j] + starts[j + 1:], n, robot.total_mass, chord,
                                      robot.g, max_checks)[1], chosen)]
    model, stance, h = BipedModel(robot, 2), step.stance, experiment.time_step(n)  # the swing's pinned model
    end_pose = np.asarray(experiment.heel_strike_configuration(step.index))
    v_end = model.potential_energy(end_pose, stance)
    flagged = []
    completed_pcot = nodes.completed(starts).pcot
    for j in range(1, len(starts)):
        first = candidates[j]
        must_gain = max(0.0, v_end - model.potential_energy(first.q[0], stance)
                        - model.kinetic_energy(first.q[0], first.dq[0], stance))
        bound = candidate_cot(np.r_[completed_pcot[j, :starts[j]], must_gain / h], robot.total_mass, chord, robot.g)
        if bound > cots[label]:
            flagged.append(starts[j] + 1)
    selection_pcot = nodes.pcot[synthesis.selection, np.arange(n)]
    return {"index": step.index, "solved": True, "sections": pending["sections"],
            "candidates": len(starts) - 1, "chosen": label, "selected": sorted({starts[j] + 1 for j in
                                                                              synthesis.selection if j}),
            "backtracks": synthesis.backtracks, "removable": removable, "energy_flagged": flagged,
            "energy_flagged_needed": [k0 for k0 in flagged if k0 not in removable],
            "zero_cost_nodes": int(np.sum(selection_pcot == 0.0))}


def summary_row(record: dict) -> str:
    rows = []
    for step in record["steps"]:
        sections = step["sections"]
        failed = [s for s in sections if s["status"] != "converged"]
        iterations = sum(s["iterations"] for s in sections)
        failed_iterations = sum(s["iterations"] for s in failed)
        blocks = sorted({name for s in failed for name in s.get("violated", {})})
        if not step["solved"]:
            rows.append(f"| {record['experiment']} {record['transcription']} N = {record['N']} | {step['index']} | "
                        f"{len(sections)} | step not solved | | | | {len(failed)} ({failed_iterations}/{iterations})"
                        f" | {', '.join(blocks)} |")
            continue
        rows.append(
            f"| {record['experiment']} {record['transcription']} N = {record['N']} | {step['index']} | "
            f"{len(sections)} | {step['chosen']} | {len(step['selected'])} | {len(step['removable'])} | "
            f"{len(step['energy_flagged'])} ({len(step['energy_flagged_needed'])}) | "
            f"{len(failed)} ({failed_iterations}/{iterations}) | {', '.join(blocks)} |")
    return "\n".join(rows)


def failed_row(record: dict) -> str | None:
    """Failed sections of the walk: how many, their iterations, and how many each probe shows feasible."""
    failed = [s for step in record["steps"] for s in step["sections"] if "probes" in s]
    if not failed:
        return None
    feasible = [s for s in failed if s["probes"]["complete_seed"]["status"] == "converged"
                or s["probes"]["as posed"]["feasible_point_found"]]
    rest = [s for s in failed if s not in feasible]
    counts = [sum(s["probes"][label]["feasible_point_found"] for s in rest) for label in list(RELAXATIONS)[1:]]
    certified = {label: [s for s in failed if s["reachability"][label]["certifies"]]
                 for label in ("torque_only", "sampled")}
    wrongly = {label: sum(s["reachability"][label]["certifies"] for step in record["steps"] for s in step["sections"]
                          if s["status"] == "converged" or s in feasible) for label in certified}
    return (f"| {record['experiment']} {record['transcription']} N = {record['N']} | {len(failed)} | "
            f"{sum(s['iterations'] for s in failed)} | {len(feasible)} ({sum(s['iterations'] for s in feasible)}) | "
            f"{len(rest)} | " + " | ".join(str(count) for count in counts) + " | " +
            " | ".join(f"{len(found)} ({sum(s['iterations'] for s in found)}; {wrongly[label]} feasible)"
                       for label, found in certified.items()) + " |")


def main(argv: list[str]) -> None:
    if argv[:1] == ["--summarize"]:
        records = [json.loads(Path(path).read_text()) for path in argv[1:]]
        print("| walk | step | sections | chosen | sections in synthesis | removable (oracle) | energy-flagged "
              "(of them needed) | failed (their iterations / all) | blocks failed sections violate |\n"
              "|---|---|---|---|---|---|---|---|---|")
        for record in records:
            print(summary_row(record))
        print("\n| walk | failed sections | their iterations | feasible after all (their iterations) | not shown "
              "feasible | of these, feasible with: " + " | ".join(list(RELAXATIONS)[1:]) + " | double integrator "
              "certifies, A = torque part (iterations; feasible sections it would also skip) | A = sampled |\n"
              "|---|---|---|---|---|---|---|---|---|---|")
        for row in filter(None, map(failed_row, records)):
            print(row)
        return
    experiment, transcription, n_nodes, steps = argv[0], argv[1], int(argv[2]), int(argv[3])
    record = analyse(experiment, transcription, n_nodes, steps)
    OUT.mkdir(parents=True, exist_ok=True)
    path = OUT / f"{experiment}-{transcription}-{n_nodes}-{steps}.json"
    path.write_text(json.dumps(record, indent=1) + "\n")
    print(summary_row(record))
    print(failed_row(record) or "no failed sections")


if __name__ == "__main__":
    main(sys.argv[1:])
