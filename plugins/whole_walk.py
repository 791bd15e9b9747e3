"""The whole-walk strategy: all H steps of an experiment in one NLP, linked through push-off and heel strike.

The thesis optimizes step by step, each step greedily from where the previous one ended. Here the walk's ACOT is
minimized as a whole: step i's initial state is not a parameter but the push-off and heel-strike map of step
i − 1's final state and impulse, written symbolically into step i's parameters. Every step keeps its own
transcription variables and constraints (one built step NLP, called H times), so the result is directly
comparable with the per-step strategies and is verified step by step in the same way. It is the reference they
are measured against.
"""

from __future__ import annotations

import time
from collections.abc import Callable

import casadi as ca
import numpy as np

from gaitbench import Registration, hookimpl
from gaitbench.gait_problem import PARAMETER_LAYOUT, StepData, legs_to_roles, role_robot_vector
from gaitbench.mechanics import biped_functions
from gaitbench.nlp import NLP
from gaitbench.verify import verify_step
from gaitbench.walk import StepOutcome, WalkProblem, WalkResult, next_step_state

INITIAL_STATE = PARAMETER_LAYOUT["initial_state"]


class WholeWalk:
    """Options: ``guess`` ("blended", the default: every step from the blended guess of DECISIONS §7, the
    experiment's initial state mirrored for Leg-2 stance steps; "one-phase": start from the One Phase walk, a
    feasible point of this NLP, so the optimizer improves on it)."""

    name = "whole-walk"

    def __init__(self, guess: str = "blended") -> None:
        if guess not in ("one-phase", "blended"):
            raise ValueError(f"guess = {guess!r}: expected 'one-phase' or 'blended'")
        self.guess = guess

    def solve(self, problem: WalkProblem, on_step: Callable[[StepOutcome], None] | None = None) -> WalkResult:
        started = time.perf_counter()
        walk = problem.result(self.name)
        for check in problem.feasibility()[: problem.n_steps]:
            if not check.ok:
                walk.steps.append(StepOutcome(check.step, problem.experiment.stance_leg(check.step),
                                              "infeasible_geometry", "; ".join(check.problems)))
                walk.wall_time_s = time.perf_counter() - started
                return walk
        built = problem.transcription.build(problem.structure("second"))
        chain = WalkChain(problem, built.nlp, built.discretization)
        guess, guess_details = self._initial_guess(problem, built, chain)
        result = problem.solver.solve(chain.nlp, np.zeros(0), guess)
        walk.strategy_details = {"guess": self.guess, **guess_details, "solver": result.summary(),
                                 "variables": chain.nlp.n_variables, "constraints": chain.nlp.n_constraints}
        if not result.converged:
            walk.steps.append(StepOutcome(1, problem.experiment.stance_leg(1), result.status.value,
                                          f"whole walk: {result.status.value}: {result.message}", result))
            walk.wall_time_s = time.perf_counter() - started
            return walk
        model = problem.model("second")
        for index, (x, data) in enumerate(chain.steps(result.x), start=1):
            trajectory = built.trajectory(x, data)
            verification = verify_step(built, x, data, trajectory, model)
            outcome = StepOutcome(index, data.stance, result.status.value, result.message, None, trajectory,
                                  verification, next_state=next_step_state(model, trajectory))
            walk.steps.append(outcome)
            if on_step:
                on_step(outcome)
        walk.wall_time_s = time.perf_counter() - started
        return walk

    def _initial_guess(self, problem: WalkProblem, built, chain: WalkChain) -> tuple[np.ndarray, dict]:
        if self.guess == "one-phase":
            from plugins.one_phase import OnePhase

            baseline = OnePhase().solve(problem)
            if baseline.complete:
                x = np.concatenate([built.initial_guess(step_data, step.trajectory.seed())
                                    for step, step_data in zip(baseline.steps, chain.nominal_data(baseline),
                                                               strict=True)])
                return x, {"guess_acot": baseline.acot}
            return chain.blended_guess(built), {"guess_acot": None, "guess_failure": baseline.failure}
        return chain.blended_guess(built), {}


class WalkChain:
    """The H-step NLP: one step NLP per step, each step's initial state the event map of the previous step."""

    def __init__(self, problem: WalkProblem, step_nlp: NLP, discretization) -> None:
        self.problem = problem
        self.step_nlp = step_nlp
        experiment, h = problem.experiment, problem.experiment.time_step(problem.n_nodes)
        x, p = step_nlp.x, step_nlp.p
        push_off = x[step_nlp.variable_blocks["push_off"]]
        step_function = ca.Function("step", [x, p], [step_nlp.f, step_nlp.g])
        end_state = ca.Function("end_state", [x, p], [discretization.positions[:, -1],
                                                      discretization.velocities[:, -1], push_off])
        n = step_nlp.n_variables
        variables = ca.SX.sym("walk", n * problem.n_steps)
        self.slices = [slice(i * n, (i + 1) * n) for i in range(problem.n_steps)]
        robot = experiment.robot
        state = ca.DM(legs_to_roles(problem.start_state(), experiment.stance_leg(1)))
        objectives, constraints, self.parameters = [], [], []
        for i, part in enumerate(self.slices, start=1):
            geometry = experiment.terrain.steps[i - 1]
            stance = experiment.stance_leg(i)
            parameters = ca.vertcat(role_robot_vector(robot, stance), state, geometry.D, geometry.theta, h,
                                    experiment.terrain.ground_behind(i))
            self.parameters.append(parameters)
            f, g = step_function(variables[part], parameters)
            objectives.append(f)
            constraints.append(g)
            # Roles alternate; after the last step the next state is unused but the map is the same.
            state = _next_role_state(end_state(variables[part], parameters), robot, stance, 3 - stance)
        self.nlp = NLP(x=variables, p=ca.SX.sym("p", 0), f=sum(objectives) / problem.n_steps,
                       g=ca.vertcat(*constraints), lbx=np.tile(step_nlp.lbx, problem.n_steps),
                       ubx=np.tile(step_nlp.ubx, problem.n_steps), lbg=np.tile(step_nlp.lbg, problem.n_steps),
                       ubg=np.tile(step_nlp.ubg, problem.n_steps),
                       variable_blocks={f"step{i + 1}": s for i, s in enumerate(self.slices)},
                       constraint_blocks=_repeat_blocks(step_nlp, problem.n_steps))
        self._parameters = ca.Function("parameters", [variables], self.parameters)

    def steps(self, x: np.ndarray) -> list[tuple[np.ndarray, StepData]]:
        """Each step's variables and its data (initial state in leg order, from the chain at ``x``)."""
        values = self._parameters(x)
        values = values if isinstance(values, (list, tuple)) else [values]
        experiment, out = self.problem.experiment, []
        for i, (part, p) in enumerate(zip(self.slices, values, strict=True), start=1):
            p = np.asarray(p, dtype=float).ravel()
            stance = experiment.stance_leg(i)
            state = legs_to_roles(p[INITIAL_STATE], stance)
            out.append((np.asarray(x)[part], self.problem.step_data(i, state)))
        return out

    def nominal_data(self, walk: WalkResult) -> list[StepData]:
        """The step data of a solved step-by-step walk (its initial states), for seeding this NLP from it."""
        state = self.problem.start_state()
        data = []
        for step in walk.steps:
            data.append(self.problem.step_data(step.index, state))
            state = step.next_state
        return data

    def blended_guess(self, built) -> np.ndarray:
        experiment = self.problem.experiment
        nominal = self.problem.start_state()
        guesses = []
        for i in range(1, self.problem.n_steps + 1):
            stance = experiment.stance_leg(i)
            guesses.append(built.initial_guess(self.problem.step_data(i, legs_to_roles(nominal, stance))))
        return np.concatenate(guesses)


def _next_role_state(end, robot, stance: int, next_stance: int) -> ca.SX:
    """(q_st, q_sw, q̇_st, q̇_sw) of the next step: push-off, then heel strike, in the next step's roles."""
    q_role, dq_role, impulse = end
    q_legs = _swap(q_role) if stance == 2 else q_role
    dq_legs = _swap(dq_role) if stance == 2 else dq_role
    functions = biped_functions(4, stance)
    parameters = ca.DM(robot.vector())
    q4, dq4 = ca.vertcat(q_legs, 0, 0), ca.vertcat(dq_legs, 0, 0)
    dq_push = functions.push_off(q4, dq4, impulse, parameters)
    dq_strike, _ = functions.heel_strike(q4, dq_push, parameters)
    q_next, dq_next = q_legs, dq_strike[:2]
    if next_stance == 2:
        q_next, dq_next = _swap(q_next), _swap(dq_next)
    return ca.vertcat(q_next, dq_next)


def _swap(pair):
    return ca.vertcat(pair[1], pair[0])


def _repeat_blocks(step_nlp: NLP, n_steps: int) -> dict[str, slice]:
    """Constraint blocks per step, named like ``step3.dynamics``."""
    m, blocks = step_nlp.n_constraints, {}
    for i in range(n_steps):
        for name, block in step_nlp.constraint_blocks.items():
            blocks[f"step{i + 1}.{name}"] = slice(block.start + i * m, block.stop + i * m)
    return blocks


@hookimpl
def register_strategies():
    return [Registration("whole-walk", "All H steps in one NLP linked through push-off and heel strike: the "
                         "walk's ACOT optimized as a whole (reference for the per-step strategies)", WholeWalk)]
