"""Several consecutive steps as one NLP: the whole walk, or a look-ahead window (docs/model.md §7).

Step j > 1 of a chain starts not from a parameter but from the push-off and heel-strike map of step j − 1's final
state and impulse, written symbolically into its parameters. Every step keeps its own transcription variables and
constraints (one built step NLP, called once per step), so each step of a chain is decoded and verified exactly as
a step solved alone.

The chain's parameters are its steps' parameter vectors laid end to end; only the first step's initial state is
used, the others are overwritten by the event map. So one chain NLP serves every window with the same length and
first stance leg, and a solver builds it once.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import casadi as ca
import numpy as np

from gaitbench.contracts import Solver, WalkProblem
from gaitbench.model.mechanics import biped_functions
from gaitbench.problem.gait_problem import N_STEP_PARAMETERS, PARAMETER_LAYOUT, StepData, legs_to_roles
from gaitbench.problem.nlp import NLP
from gaitbench.problem.trajectory import Seed
from gaitbench.problem.transcription import TranscribedStep
from gaitbench.solve.verify import verify_step
from gaitbench.solve.walk import next_step_state, solve_with_retries, solver_remedies, solver_variants, stopped_at
from gaitbench.walk_types import StepOutcome

INITIAL_STATE = PARAMETER_LAYOUT["initial_state"]


class WalkChain:
    """``count`` consecutive steps whose first has stance leg ``first_stance``, as one NLP over their variables.

    The objective is the mean of the steps' objectives (their mean COT when each step's objective is its COT).
    """

    def __init__(self, built: TranscribedStep, first_stance: int, count: int) -> None:
        step_nlp, discretization = built.nlp, built.discretization
        self.built, self.first_stance, self.count = built, first_stance, count
        x, p = step_nlp.x, step_nlp.p
        push_off = x[step_nlp.variable_blocks["push_off"]]
        step_function = ca.Function("step", [x, p], [step_nlp.f, step_nlp.g])
        end_state = ca.Function("end_state", [x, p], [discretization.positions[:, -1],
                                                      discretization.velocities[:, -1], push_off])
        n = step_nlp.n_variables
        variables = ca.SX.sym("chain", n * count)
        chain_parameters = ca.SX.sym("chain_p", N_STEP_PARAMETERS * count)
        self.slices = [slice(j * n, (j + 1) * n) for j in range(count)]
        objectives, constraints, step_parameters = [], [], []
        state = chain_parameters[INITIAL_STATE]
        for j, part in enumerate(self.slices):
            stance = self.stance(j)
            given = chain_parameters[j * N_STEP_PARAMETERS:(j + 1) * N_STEP_PARAMETERS]
            parameters = ca.vertcat(given[:INITIAL_STATE.start], state, given[INITIAL_STATE.stop:])
            step_parameters.append(parameters)
            f, g = step_function(variables[part], parameters)
            objectives.append(f)
            constraints.append(g)
            if j + 1 < count:
                robot = given[PARAMETER_LAYOUT["robot"]]
                state = _next_role_state(end_state(variables[part], parameters), robot, stance)
        self.nlp = NLP(x=variables, p=chain_parameters, f=sum(objectives) / count, g=ca.vertcat(*constraints),
                       lbx=np.tile(step_nlp.lbx, count), ubx=np.tile(step_nlp.ubx, count),
                       lbg=np.tile(step_nlp.lbg, count), ubg=np.tile(step_nlp.ubg, count),
                       variable_blocks={f"step{j + 1}": s for j, s in enumerate(self.slices)},
                       constraint_blocks=_repeat_blocks(step_nlp, count))
        self._step_parameters = ca.Function("step_parameters", [variables, chain_parameters], step_parameters)

    def stance(self, j: int) -> int:
        """Stance leg of the chain's step ``j`` (0-based): legs alternate."""
        return self.first_stance if j % 2 == 0 else 3 - self.first_stance

    def parameters(self, problem: WalkProblem, first: int, state: np.ndarray) -> np.ndarray:
        """The chain's parameter vector for steps ``first`` … ``first + count − 1`` from ``state`` (leg order)."""
        return np.concatenate([problem.step_data(first + j, state).parameter_vector() for j in range(self.count)])

    def steps(self, problem: WalkProblem, first: int, x: np.ndarray, p: np.ndarray) -> list[tuple[np.ndarray,
                                                                                              StepData]]:
        """Each step's variables and its data (its initial state from the chain at ``x``)."""
        values = self._step_parameters(x, p)
        values = values if isinstance(values, (list, tuple)) else [values]
        out = []
        for j, (part, parameters) in enumerate(zip(self.slices, values, strict=True)):
            state = legs_to_roles(np.asarray(parameters, dtype=float).ravel()[INITIAL_STATE], self.stance(j))
            out.append((np.asarray(x)[part], problem.step_data(first + j, state)))
        return out

    def guess(self, problem: WalkProblem, first: int, known: list[tuple[np.ndarray, Seed | None]]) -> np.ndarray:
        """The chain's initial guess: its leading steps from ``known`` (initial state in leg order, and a seed, or
        None for the blended guess from that state), the rest from the blended guess of the walk's start pose
        mirrored onto each step's stance leg."""
        nominal = problem.start_state()
        guesses = []
        for j in range(self.count):
            state, seed = known[j] if j < len(known) else (legs_to_roles(nominal, self.stance(j)), None)
            guesses.append(self.built.initial_guess(problem.step_data(first + j, state), seed))
        return np.concatenate(guesses)


@dataclass
class LookAhead:
    """One Phase with a receding horizon: step i is solved together with the next ``horizon − 1`` steps, and only
    step i is committed (docs/model.md §7). Each window starts from the previous window's later steps; its last step
    from the blended guess. A window that fails after the solver's continuations (when it ran out of iterations),
    remedies and last resorts falls back to step i alone, with the retry ladder, and says so in the step's details
    (unless ``fallback`` is off: then the failure is returned). Upward slope, HS, N = 150: the back-up window of
    steps 5–6 from step 5's trajectory reached IPOPT's 3000 iterations with both μ strategies, and converges in
    420 with μ₀ = 1e-3 (its last resort).

    Chains are built once per window length and first stance leg, and kept for the walk.
    """

    built: TranscribedStep
    horizon: int
    fallback: bool = True

    def __post_init__(self) -> None:
        self._chains: dict[tuple[int, int], WalkChain] = {}
        self._carried: list[tuple[np.ndarray, Seed]] = []
        """The last window's later steps (initial state, trajectory as a seed): the next window's start."""

    def solve_step(self, problem: WalkProblem, index: int, state: np.ndarray, seed: Seed | None = None) -> StepOutcome:
        """Step ``index`` from ``state``; ``seed`` starts it where the last window did not reach it (a back-up)."""
        count = min(self.horizon, problem.n_steps - index + 1)
        data = problem.step_data(index, state)
        if count == 1:  # the walk's last step: from the last window's solution of it, as a window would start
            return solve_with_retries(problem, index, self.built, data, seed=self.seed_for(state) or seed)
        chain = self._chain(data.stance, count)
        p = chain.parameters(problem, index, state)
        known = self._known(state)
        if seed is not None and known[0][1] is None:
            known[0] = (state, seed)
        guess = chain.guess(problem, index, known)
        started = time.perf_counter()
        outcome = self._commit(problem, index, chain, problem.solver, p, guess)
        attempts = [{"remedy": "none", **outcome.summary()}]
        seeded = any(seed is not None for _, seed in known)  # a step started from a trajectory, not blended
        for remedy, solver, start in ([] if outcome.solved else self._rungs(problem.solver, outcome, guess, seeded)):
            if problem.out_of_time:
                break  # the step alone below then ends with the walk's time limit too
            outcome = self._commit(problem, index, chain, solver, p, start)
            attempts.append({"remedy": remedy, **outcome.summary()})
            if outcome.solved:
                break
        window = {"horizon": count, "attempts": attempts, "time_s": time.perf_counter() - started}
        if not outcome.solved and self.fallback:
            self._carried = []
            outcome = solve_with_retries(problem, index, self.built, data)
            window["fallback"] = "step alone"
        outcome.details = {**outcome.details, "look_ahead": window}
        return outcome

    @staticmethod
    def _rungs(solver: Solver, failed: StepOutcome, guess: np.ndarray,
               seeded: bool) -> list[tuple[str, Solver, np.ndarray]]:
        """The window's retries after its ``failed`` first attempt, as (remedy, solver, start), in the step's
        ladder's order: when it ran out of iterations, the solver's continuations from its last iterate; then its
        remedies (with the seed remedies when the window starts from a trajectory) and last resorts from ``guess``.
        """
        stopped = stopped_at(failed)
        continued = [] if stopped is None else [(name, variant, stopped)
                                                for name, variant in solver_variants(solver, "continuations")]
        return continued + [(name, variant, guess) for name, variant in
                            [*solver_remedies(solver, seeded), *solver_variants(solver, "last_resorts")]]

    def _commit(self, problem: WalkProblem, index: int, chain: WalkChain, solver: Solver, p: np.ndarray,
                guess: np.ndarray) -> StepOutcome:
        """The window solved from ``guess``; step ``index`` decoded, verified and chained; the later steps kept as
        seeds."""
        result = solver.solve(chain.nlp, p, guess)
        stance = chain.stance(0)
        if not result.converged:
            return StepOutcome(index, stance, result.status.value,
                               f"look-ahead window of {chain.count} steps: {result.status.value}: {result.message}",
                               result)
        steps = chain.steps(problem, index, result.x, p)
        x, data = steps[0]
        trajectory = self.built.trajectory(x, data)
        model = problem.model("second")
        verification = verify_step(self.built, x, data, trajectory, model)
        self._carried = [(data_j.initial_state, self.built.trajectory(x_j, data_j).seed())
                         for x_j, data_j in steps[1:]]
        return StepOutcome(index, stance, result.status.value, result.message, result, trajectory, verification,
                           next_state=next_step_state(model, trajectory))

    def seed_for(self, state: np.ndarray) -> Seed | None:
        """The last window's solution of the step that starts at ``state``, if the window reached that far."""
        if self._carried and np.allclose(self._carried[0][0], state, atol=1e-6):
            return self._carried[0][1]
        return None

    def _known(self, state: np.ndarray) -> list[tuple[np.ndarray, Seed | None]]:
        """Step i from ``state``, seeded by the last window's solution of it when that started there."""
        seed = self.seed_for(state)
        return [(state, seed), *self._carried[1:]] if seed is not None else [(state, None)]

    def _chain(self, first_stance: int, count: int) -> WalkChain:
        key = (first_stance, count)
        if key not in self._chains:
            self._chains[key] = WalkChain(self.built, first_stance, count)
        return self._chains[key]


def _next_role_state(end, robot: ca.SX, stance: int) -> ca.SX:
    """(q_st, q_sw, q̇_st, q̇_sw) of the next step, in its roles: push-off, then heel strike, then the role swap.

    ``robot`` is the step's robot vector in role order (:func:`role_robot_vector`); the event maps take it in leg
    order, which for stance leg 2 has the two legs' masses and inertias exchanged back.
    """
    q_role, dq_role, impulse = end
    legs_robot = robot if stance == 1 else ca.vertcat(robot[1], robot[0], robot[2:5], robot[6], robot[5], robot[7])
    q_legs = q_role if stance == 1 else _swap(q_role)
    dq_legs = dq_role if stance == 1 else _swap(dq_role)
    functions = biped_functions(4, stance)
    q4, dq4 = ca.vertcat(q_legs, 0, 0), ca.vertcat(dq_legs, 0, 0)
    dq_push = functions.push_off(q4, dq4, impulse, legs_robot)
    dq_strike, _ = functions.heel_strike(q4, dq_push, legs_robot)
    # Leg order is unchanged by the strike; the next step's roles have the other leg standing.
    q_next, dq_next = q_legs, dq_strike[:2]
    return ca.vertcat(q_next, dq_next) if stance == 2 else ca.vertcat(_swap(q_next), _swap(dq_next))


def _swap(pair):
    return ca.vertcat(pair[1], pair[0])


def _repeat_blocks(step_nlp: NLP, count: int) -> dict[str, slice]:
    """Constraint blocks per step, named like ``step3.dynamics``."""
    m, blocks = step_nlp.n_constraints, {}
    for j in range(count):
        for name, block in step_nlp.constraint_blocks.items():
            blocks[f"step{j + 1}.{name}"] = slice(block.start + j * m, block.stop + j * m)
    return blocks
