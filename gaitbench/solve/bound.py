"""A physical lower bound on the ACOT of any walk of an experiment: what the energy it must gain costs at least.

Every step starts at a pose fixed by the footholds (the start pose, or the previous step's heel-strike pose) and ends
at its heel-strike pose, so the potential energies V at both ends are known; the kinetic energies are not, except at
the start of the walk (the experiment's start state). Over the swing of step i the stance foot is held, so the hip
motors' work is W_i = ΔE_i, the change of the mechanical energy. Push-off then adds E_PO,i ≥ 0 of kinetic energy and
heel strike, a plastic impact, loses L_i ≥ 0:

    W_i = (K_i,end − K_i,start) + (V_i,end − V_i,start),    K_i+1,start = K_i,end + E_PO,i − L_i,    K ≥ 0.

An objective whose charged powers add up to the net hip power τ_st q̇_st + τ_sw q̇_sw charges a step at least
w⁺ W_i⁺ + w⁻ W_i⁻ for its swing (∫ Σ_j charge(P_j) dt ≥ charge(∫ Σ_j P_j dt): net-power's ∫|P| ≥ |∫P|, actuator-work's
Σ_j |τ_j ω_j| ≥ |Σ_j τ_j ω_j|, with its weights) plus its event cost of E_PO,i. The least mean of the steps' COTs over
these linear relations is a small linear program, solved with HiGHS; every walk of the experiment costs at least its
optimum, whatever its transcription, grid or solver. ``push_off_cost = "thesis"`` charges push-off as the thesis's
(3.77) does, ½ m_stance |v_foot|², a fixed fraction of E_PO at each pose (:func:`push_off_ratios`).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np
from scipy.optimize import linprog

from gaitbench.model.energetics import average_cot
from gaitbench.model.experiment import Experiment
from gaitbench.model.mechanics import BipedModel
from gaitbench.problem.gait_problem import role_robot_vector
from gaitbench.problem.objective import NET_POWER, Objective

PUSH_OFF_COSTS = ("impulse", "thesis")
"""How push-off is charged: ``impulse``, its real kinetic-energy gain E_PO (the objectives' accounting); ``thesis``, the
thesis's (3.77) ½ m_stance |v_foot|² of the stance foot after the impulse."""

NO_BOUND_TOLERANCE = 1e-9
"""A walk bound at or below this ACOT is no bound: the walk needs no energy it does not already have."""


class NoBound(ValueError):
    """The objective prices something other than work, so the energy a walk must gain gives no bound under it."""


@dataclass(frozen=True)
class StepBound:
    """One step of the bound. ``cot`` is the step's COT in the LP's optimal walk: the split of the walk's bound over
    its steps (one of possibly several optimal splits). ``prefix_acot`` is the bound of the walk's first ``index``
    steps alone, the least ACOT a walk stopped after this step can have. A step has no useful bound of its own: from
    step 2 on, a push-off at the end of the step before can bring all the energy it needs, charged to that step."""

    index: int
    stance: int
    chord: float  # m, the step's D in COT = E / (M g D)
    potential_gain: float  # J, V at the heel-strike pose − V at the step's start pose
    push_off_ratio: float  # J charged per J of push-off energy: 1 (impulse) or the thesis's fraction at this pose
    hip_work: float  # J, W = ΔE of the swing in the LP's optimal walk
    push_off_energy: float  # J, E_PO in the LP's optimal walk
    cot: float
    prefix_acot: float


@dataclass(frozen=True)
class WalkBound:
    """The least ACOT any walk of ``experiment`` can have under ``objective``, and its steps."""

    experiment: str
    objective: str
    push_off_cost: str
    start_pose: str
    start_kinetic_energy: float  # J, the kinetic energy of the walk's start state, which the walk may spend
    acot: float
    steps: list[StepBound]

    @property
    def useful(self) -> bool:
        """False where the bound is 0: the walk can be done with the energy it has (flat ground, downhill)."""
        return self.acot > NO_BOUND_TOLERANCE

    @property
    def message(self) -> str | None:
        """Why there is no useful bound, or None where there is one."""
        if self.useful:
            return None
        return (f"{self.experiment} admits no useful bound under {self.objective}: a walk of it needs no energy beyond "
                "what it starts with and what it gains going down, so the bound is 0 for every step")

    def as_dict(self) -> dict:
        return {**{name: getattr(self, name) for name in ("experiment", "objective", "push_off_cost", "start_pose",
                                                          "start_kinetic_energy", "acot")},
                "useful": self.useful, "message": self.message, "steps": [asdict(step) for step in self.steps]}


def walk_bound(experiment: Experiment, objective: Objective = NET_POWER, push_off_cost: str = "impulse",
               start_pose: str = "on-ground", steps: int | None = None) -> WalkBound:
    """The bound over the first ``steps`` steps (all by default), walked from the start state in ``start_pose``.

    Raises :class:`NoBound` for an objective that does not charge the hip motors' work joule for joule, and
    ValueError for an unknown ``push_off_cost`` or a step whose chord the legs cannot span.
    """
    if push_off_cost not in PUSH_OFF_COSTS:
        raise ValueError(f"push_off_cost = {push_off_cost!r}: expected one of {', '.join(PUSH_OFF_COSTS)}")
    n = experiment.n_steps if steps is None else steps
    if not 1 <= n <= experiment.n_steps:
        raise ValueError(f"steps = {steps}: {experiment.name} has {experiment.n_steps} steps")
    positive_weight, negative_weight = work_weights(objective, experiment)
    model = BipedModel(experiment.robot, 2)
    start = experiment.start_state(start_pose)
    start_energy = float(model.kinetic_energy(start[:2], start[2:], experiment.stance_leg(1)))
    poses = [np.asarray(start[:2])] + [np.asarray(_heel_strike_pose(experiment, i)) for i in range(1, n + 1)]
    gains = np.array([model.potential_energy(poses[i], experiment.stance_leg(i))
                      - model.potential_energy(poses[i - 1], experiment.stance_leg(i)) for i in range(1, n + 1)])
    ratios = push_off_ratios(experiment, n) if push_off_cost == "thesis" else np.ones(n)
    event = np.array([_event_cost_per_joule(objective, ratio) for ratio in ratios])
    robot = experiment.robot
    chords = np.array([experiment.terrain.steps[i].D for i in range(n)])
    weights = robot.total_mass * robot.g * chords
    prefixes = []
    for k in range(1, n + 1):  # the walk's first k steps; the last is the whole walk
        lp = _BoundLP(gains[:k], start_energy, positive_weight, negative_weight, event[:k], weights[:k])
        solution = lp.solve()
        cots = lp.step_costs(solution) / weights[:k]
        prefixes.append(average_cot(cots))
    return WalkBound(
        experiment=experiment.name, objective=objective.describe(), push_off_cost=push_off_cost,
        start_pose=start_pose, start_kinetic_energy=start_energy, acot=average_cot(cots),
        steps=[StepBound(index=i + 1, stance=experiment.stance_leg(i + 1), chord=float(chords[i]),
                         potential_gain=float(gains[i]), push_off_ratio=float(ratios[i]),
                         hip_work=float(lp.work(solution)[i]), push_off_energy=float(lp.push_off(solution)[i]),
                         cot=float(cots[i]), prefix_acot=prefixes[i]) for i in range(n)])


def push_off_ratios(experiment: Experiment, steps: int | None = None) -> np.ndarray:
    """Per step, the thesis's push-off charge ½ m_stance |v_foot|² over the push-off's real kinetic-energy gain E_PO,
    at the step's heel-strike pose.

    The impulse λ acts along the stance leg on the 4-DOF robot whose stance foot is at rest: q̇⁺ = q̇ + M⁻¹ J λ with
    Jᵀq̇ = 0, so E_PO = ½ λ² Jᵀ M⁻¹ J and v_foot = (M⁻¹ J)_foot λ. Both are λ² times a function of the pose alone: the
    ratio is the same for every impulse and every rate before it, and is read from the model at λ = 1 from rest.
    """
    n = experiment.n_steps if steps is None else steps
    model = BipedModel(experiment.robot, 4)
    ratios = []
    for index in range(1, n + 1):
        stance = experiment.stance_leg(index)
        pose = np.r_[_heel_strike_pose(experiment, index), 0.0, 0.0]
        rates, gain = model.push_off(pose, np.zeros(4), 1.0, stance)
        stance_mass = experiment.robot.m1 if stance == 1 else experiment.robot.m2
        ratios.append(0.5 * stance_mass * float(rates[2] ** 2 + rates[3] ** 2) / float(gain))
    return np.array(ratios)


def work_weights(objective: Objective, experiment: Experiment) -> tuple[float, float]:
    """(w⁺, w⁻), what ``objective`` charges per joule of positive and of negative hip work at least; raises
    :class:`NoBound` unless its charged powers add up to the net hip power and it charges nothing else."""
    rng = np.random.default_rng(0)
    dq_st, dq_sw, tau_st, tau_sw = rng.normal(size=(4, 16))
    robot = role_robot_vector(experiment.robot, 1)
    powers = objective.powers(dq_st, dq_sw, tau_st, tau_sw)
    net = tau_st * dq_st + tau_sw * dq_sw
    if objective.smooth_rate(dq_st, dq_sw, tau_st, tau_sw, robot) is not None or not powers:
        raise NoBound(f"objective {objective.describe()!r} admits no useful bound: it charges a rate that is not "
                      "the hip motors' work, so the energy a walk must gain has no least price under it")
    if not np.allclose(np.sum(powers, axis=0), net, rtol=1e-12, atol=1e-12):
        raise NoBound(f"objective {objective.describe()!r} admits no useful bound: its charged powers do not add "
                      "up to the net hip power τ_st q̇_st + τ_sw q̇_sw")
    weights = (float(objective.positive_weight), float(objective.negative_weight))
    if min(weights) < 0:
        raise NoBound(f"objective {objective.describe()!r} admits no useful bound: it pays for work ({weights})")
    return weights


def _event_cost_per_joule(objective: Objective, ratio: float) -> float:
    """The objective's event cost of one joule of push-off energy charged as ``ratio`` joules; push-off energy is
    never negative, and the cost must be linear in it for the LP."""
    per_joule = objective.event_cost(ratio)
    if per_joule < 0 or not np.isclose(objective.event_cost(2 * ratio), 2 * per_joule):
        raise NoBound(f"objective {objective.describe()!r} admits no useful bound: its push-off cost is not "
                      "proportional to the push-off's energy")
    return per_joule


def _heel_strike_pose(experiment: Experiment, index: int) -> tuple[float, float]:
    try:
        return experiment.heel_strike_configuration(index)
    except ValueError as error:
        raise ValueError(f"step {index}: {error}") from None


class _BoundLP:
    """The LP over a walk of n steps. Variables, n each, in blocks: positive and negative hip work W⁺, W⁻, push-off
    energy E_PO, kinetic energy at the step's end (before push-off) and at its start (after heel strike); all ≥ 0."""

    BLOCKS = ("positive", "negative", "push_off", "end", "start")

    def __init__(self, gains: np.ndarray, start_energy: float, positive_weight: float, negative_weight: float,
                 event: np.ndarray, weights: np.ndarray) -> None:
        n = gains.size
        self.n, self.weights = n, weights
        self.cost = np.zeros((n, 5 * n))  # row i: step i's cost in J
        for i in range(n):
            self.cost[i, self._at("positive", i)] = positive_weight
            self.cost[i, self._at("negative", i)] = negative_weight
            self.cost[i, self._at("push_off", i)] = event[i]
        equalities, inequalities = [], []
        for i in range(n):  # W⁺ − W⁻ = K_end − K_start + ΔV
            row = np.zeros(5 * n)
            row[[self._at("positive", i), self._at("start", i)]] = 1.0
            row[[self._at("negative", i), self._at("end", i)]] = -1.0
            equalities.append((row, gains[i]))
        first = np.zeros(5 * n)
        first[self._at("start", 0)] = 1.0
        equalities.append((first, start_energy))
        for i in range(n - 1):  # K_start(i + 1) ≤ K_end(i) + E_PO(i): heel strike loses L ≥ 0
            row = np.zeros(5 * n)
            row[self._at("start", i + 1)] = 1.0
            row[[self._at("end", i), self._at("push_off", i)]] = -1.0
            inequalities.append(row)
        self.a_eq = np.array([row for row, _ in equalities])
        self.b_eq = np.array([value for _, value in equalities])
        self.a_ub = np.array(inequalities) if inequalities else None
        self.b_ub = np.zeros(len(inequalities)) if inequalities else None

    def _at(self, block: str, step: int) -> int:
        return self.BLOCKS.index(block) * self.n + step

    def _block(self, solution: np.ndarray, block: str) -> np.ndarray:
        start = self.BLOCKS.index(block) * self.n
        return solution[start:start + self.n]

    def solve(self) -> np.ndarray:
        """The variables minimising the mean of the steps' COTs."""
        c = (1.0 / (self.n * self.weights)) @ self.cost
        result = linprog(c, A_ub=self.a_ub, b_ub=self.b_ub, A_eq=self.a_eq, b_eq=self.b_eq, bounds=(0, None),
                         method="highs")
        if result.status != 0:  # the LP is feasible (no work, no push-off is a walk) and bounded below by 0
            raise RuntimeError(f"the bound's linear program failed: {result.message}")
        return result.x

    def step_costs(self, solution: np.ndarray) -> np.ndarray:
        return self.cost @ solution

    def work(self, solution: np.ndarray) -> np.ndarray:
        return self._block(solution, "positive") - self._block(solution, "negative")

    def push_off(self, solution: np.ndarray) -> np.ndarray:
        return self._block(solution, "push_off")
