"""Transcriptions: convergence order against an accurate reference, DMOC's energy behaviour, and IPOPT solves of the
forward experiment's first step with each scheme's trajectory and interpolant.

With its torques given, a transcription's "dynamics" and "initial_state" equations are square in its remaining
variables: the scheme is then an implicit integrator, solved here by Newton and compared with scipy's solution.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace
from functools import cache

import casadi as ca
import numpy as np
import pytest
from scipy.integrate import solve_ivp

from gaitbench.model.mechanics import BipedModel
from gaitbench.model.robot import RobotParameters
from gaitbench.plugins import load_registry
from gaitbench.problem.gait_problem import ProblemOptions, StepData, StepStructure
from gaitbench.problem.trajectory import locate_interval
from gaitbench.problem.transcription import TranscribedStep

ROBOT = RobotParameters(m1=20, m2=20, M=40, l=1, a=0.5)  # the forward experiment's robot
MODEL = BipedModel(ROBOT, 2)
INITIAL_STATE = np.array([0.2187, -0.2187, -1.0924, -0.3774])  # forward experiment, (q_st, q_sw, q̇_st, q̇_sw)
DURATION = 0.7343


def _nodes(n: int, h: float) -> np.ndarray:
    return np.arange(n) * h


def _midpoints(n: int, h: float) -> np.ndarray:
    return np.arange(n - 1) * h + h / 2


@dataclass(frozen=True)
class Scheme:
    """What fixing the torques leaves: the variable blocks the dynamics determine, and where torques are sampled."""

    state_blocks: tuple[str, ...]
    control_times: Callable[[int, float], np.ndarray]


# DMOC's torque on [t_k, t_{k+1}] is sampled at the midpoint: its forcing (h/2)(τ_{k−1} + τ_k) then matches the
# virtual work ∫ τ φ_k dt of the hat function φ_k at node k up to O(h³), like the interval average; left-end
# samples would be off by O(h²) per node and cost an order.
SCHEMES = {
    "hermite-simpson": Scheme(("states",), _nodes),
    "trapezoidal": Scheme(("states",), _nodes),
    "dmoc": Scheme(("positions", "start_velocity", "end_velocity"), _midpoints),
}

# Each block's values from node states X (4 × N, role order).
BLOCK_FROM_STATES = {
    "states": lambda x: x,
    "positions": lambda x: x[:2],
    "start_velocity": lambda x: x[2:, 0],
    "end_velocity": lambda x: x[2:, -1],
}


def affine_torque(t):
    t = np.asarray(t, dtype=float)
    return np.array([10.0 + 20.0 * t, -6.0 + 12.0 * t])


def sinusoidal_torque(t):
    t = np.asarray(t, dtype=float)
    return np.array([2.0 + 5.0 * np.sin(4.0 * t), -3.0 * np.cos(5.0 * t)])


def zero_torque(t):
    return np.zeros((2, np.size(t)))


TORQUES = {"affine": affine_torque, "sinusoidal": sinusoidal_torque}


@cache
def transcription(name: str):
    return load_registry().create("transcription", name)


@cache
def dynamics_solver(name: str, n: int) -> tuple[TranscribedStep, list[slice], ca.Function]:
    """Newton on the scheme's dynamics and initial-state equations, unknowns = its state blocks, p = (torques, p)."""
    built = transcription(name).build(StepStructure("first", n))
    nlp = built.nlp
    blocks = [nlp.variable_blocks[block] for block in SCHEMES[name].state_blocks]
    unknowns = ca.vertcat(*(nlp.x[block] for block in blocks))
    residual = ca.vertcat(*(nlp.g[nlp.constraint_blocks[block]] for block in ("dynamics", "initial_state")))
    torques = nlp.x[nlp.variable_blocks["torques"]]
    equations = ca.Function("equations", [unknowns, ca.vertcat(torques, nlp.p)], [residual])
    return built, blocks, ca.rootfinder("dynamics", "newton", equations, {"abstol": 1e-11})


def integrate(name: str, n: int, h: float, initial_state: np.ndarray, torque, guess: np.ndarray):
    """The scheme's nodal (q, q̇) (each N × 2) from ``initial_state`` under ``torque``; ``guess`` is 4 × N."""
    built, blocks, solver = dynamics_solver(name, n)
    p = StepData(ROBOT, 1, initial_state, chord=1.0, slope=0.0, time_step=h).parameter_vector()
    samples = torque(SCHEMES[name].control_times(n, h)).flatten(order="F")
    start = np.concatenate([np.ravel(BLOCK_FROM_STATES[b](guess), order="F") for b in SCHEMES[name].state_blocks])
    solution = np.asarray(solver(start, np.concatenate([samples, p]))).ravel()
    x = np.zeros(built.nlp.n_variables)
    x[built.nlp.variable_blocks["torques"]] = samples
    offsets = np.cumsum([block.stop - block.start for block in blocks])[:-1]
    for block, values in zip(blocks, np.split(solution, offsets), strict=True):
        x[block] = values
    q, dq, _, _ = built.discretization.decode(built.blocks(x), p)
    return q, dq


def _state_derivative(torque):
    return lambda t, x: np.concatenate([x[2:], MODEL.forward_dynamics(x[:2], x[2:], torque(t).ravel(), 1)[0]])


@cache
def reference(kind: str):
    return solve_ivp(_state_derivative(TORQUES[kind]), (0.0, DURATION), INITIAL_STATE, method="DOP853",
                     rtol=1e-12, atol=1e-12, dense_output=True).sol


def _order(steps: np.ndarray, errors: np.ndarray) -> float:
    return float(np.polyfit(np.log(steps), np.log(errors), 1)[0])


# Hermite–Simpson's controls are piecewise linear: against a curved torque its midpoint control is off by h²τ''/8
# and its states converge at second order only (measured 2.0 with the sinusoid). The affine torque, which its
# controls represent exactly, isolates the fourth order of the state discretization.
@pytest.mark.parametrize(("name", "kind", "lowest", "highest"), [
    ("hermite-simpson", "affine", 3.5, 4.6),
    ("trapezoidal", "affine", 1.7, 2.6),
    ("trapezoidal", "sinusoidal", 1.7, 2.6),
    ("dmoc", "affine", 1.7, 2.6),
    ("dmoc", "sinusoidal", 1.7, 2.6),
])
def test_final_state_converges_at_the_schemes_order(name, kind, lowest, highest):
    node_counts = (11, 21, 41, 81)
    steps = np.array([DURATION / (n - 1) for n in node_counts])
    solution = reference(kind)
    exact = solution(DURATION)
    errors = []
    for n, h in zip(node_counts, steps, strict=True):
        q, dq = integrate(name, n, h, INITIAL_STATE, TORQUES[kind], solution(_nodes(n, h)))
        errors.append([np.abs(q[-1] - exact[:2]).max(), np.abs(dq[-1] - exact[2:]).max()])
    errors = np.array(errors)
    orders = [_order(steps, errors[:, 0]), _order(steps, errors[:, 1])]
    message = f"{name} ({kind} torque): order {orders[0]:.2f} (q), {orders[1]:.2f} (q̇); errors {errors.tolist()}"
    assert all(lowest <= order <= highest for order in orders), message


HANGING = np.array([np.pi + 0.4, np.pi - 0.3, 0.0, 0.0])  # both legs below the pinned foot, at rest


def _chained_energy_error(h: float, n_chunks: int, n: int = 21) -> np.ndarray:
    """|E_k − E_0| at the nodes of DMOC without torque, chunk after chunk from each chunk's final (q_N, q̇_N).

    Chaining is exact: the end condition M(q_N) q̇_N = D2 L_d(q_{N−1}, q_N) and the next start condition
    M(q_N) q̇_N + D1 L_d(q_N, q_{N+1}) = 0 together are the discrete Euler–Lagrange equation at q_N.
    """
    state = HANGING
    energies = [MODEL.total_energy(state[:2], state[2:], 1)]
    for _ in range(n_chunks):
        q, dq = integrate("dmoc", n, h, state, zero_torque, np.repeat(state[:, None], n, axis=1))
        energies += [MODEL.total_energy(q[k], dq[k], 1) for k in range(1, n)]
        state = np.concatenate([q[-1], dq[-1]])
    return np.abs(np.array(energies) - energies[0])


def test_dmoc_energy_error_is_bounded_and_second_order_without_torque():
    """A variational integrator's energy error oscillates at O(h²) and does not drift.

    The walking step is too short to tell oscillation from drift, so the legs swing below the pinned foot for
    20 s, about ten periods of a regular (non-chaotic) motion.
    """
    coarse, fine = _chained_energy_error(0.05, 20), _chained_energy_error(0.025, 40)
    for errors in (coarse, fine):
        quarter = len(errors) // 4
        assert errors[-quarter:].max() <= 1.25 * errors[:quarter].max(), (
            f"energy error grows: {errors[:quarter].max():.3g} in the first quarter, "
            f"{errors[-quarter:].max():.3g} in the last"
        )
    assert 3.0 <= coarse.max() / fine.max() <= 5.0, f"energy error {coarse.max():.3g} → {fine.max():.3g} for h/2"


@cache
def forward_experiment():
    return load_registry().create("experiment", "forward")


@cache
def solve_forward_step(name: str, phase: str, n: int) -> tuple[TranscribedStep, StepData, np.ndarray, dict]:
    """IPOPT on the forward experiment's first step from the transcription's guess: (step, data, x, stats)."""
    experiment = forward_experiment()
    geometry = experiment.terrain.steps[0]
    data = StepData(experiment.robot, stance=1, initial_state=experiment.initial_state[[0, 1, 4, 5]],
                    chord=geometry.D, slope=geometry.theta, time_step=experiment.time_step(n))
    built = transcription(name).build(StepStructure(phase, n, ProblemOptions(limits=experiment.limits)))
    nlp = built.nlp
    solver = ca.nlpsol("s", "ipopt", nlp.casadi_problem(),
                       {"print_time": False, "ipopt": {"print_level": 0, "max_iter": 500, "sb": "yes"}})
    result = solver(x0=built.initial_guess(data), lbx=nlp.lbx, ubx=nlp.ubx, lbg=nlp.lbg, ubg=nlp.ubg,
                    p=data.parameter_vector())
    return built, data, np.asarray(result["x"]).ravel(), solver.stats()


@pytest.mark.parametrize("n", [21, 51, 101])
@pytest.mark.parametrize("phase", ["first", "second"])
@pytest.mark.parametrize("name", list(SCHEMES))
def test_ipopt_solves_the_forward_experiments_first_step(name, phase, n):
    built, data, x, stats = solve_forward_step(name, phase, n)
    assert "Solve_Succeeded" in stats["return_status"], (
        f"{name}, {phase} phase, N = {n}: {stats['return_status']} after {stats['iter_count']} iterations"
    )
    assert built.nlp.violation(x, data.parameter_vector()) < 1e-6
    trajectory = built.trajectory(x, data)
    heel_strike = forward_experiment().heel_strike_configuration(1)
    assert trajectory.duration == pytest.approx(forward_experiment().step_duration)
    np.testing.assert_allclose(trajectory.q[-1], heel_strike, atol=1e-8)
    np.testing.assert_allclose(trajectory.state(trajectory.duration)[0], heel_strike, atol=1e-6)


@pytest.mark.parametrize("name", list(SCHEMES))
def test_interpolant_matches_the_nodal_values(name):
    """At every node, reached from its own interval and from the one before, and at every control sample."""
    built, data, x, _ = solve_forward_step(name, "first", 21)
    trajectory = built.trajectory(x, data)
    for k, t in enumerate(trajectory.times):
        for at in {t, np.nextafter(t, -np.inf) if k else t}:
            q, dq = trajectory.state(at)
            np.testing.assert_allclose(q, trajectory.q[k], atol=1e-7, err_msg=f"q at node {k}, t = {at!r}")
            np.testing.assert_allclose(dq, trajectory.dq[k], atol=1e-7, err_msg=f"q̇ at node {k}, t = {at!r}")
    for j, t in enumerate(trajectory.control_times):
        np.testing.assert_allclose(trajectory.control(t), trajectory.tau[j], atol=1e-12)


def test_seeds_of_one_trajectory_share_their_samples_and_hand_out_copies():
    built, data, x, _ = solve_forward_step("dmoc", "first", 21)
    trajectory = built.trajectory(x, data)
    calls = []
    state = trajectory._interpolant.state
    trajectory._interpolant = replace(trajectory._interpolant, state=lambda t: calls.append(t) or state(t))
    h = data.time_step
    first = [trajectory.seed(2 * h)(k * h) for k in range(5)]
    again = trajectory.seed(2 * h)
    assert len(calls) == 5
    q, dq, tau = again(0.0)
    assert len(calls) == 5  # the same time: the kept sample
    expected_q, expected_dq = state(2 * h)
    np.testing.assert_array_equal(q, expected_q)
    np.testing.assert_array_equal(dq, expected_dq)
    q += 1.0
    first[0][1][:] = 0.0
    np.testing.assert_array_equal(again(0.0)[0], expected_q)  # changing a sample handed out changes no later one
    np.testing.assert_array_equal(again(0.0)[1], expected_dq)


def test_interval_lookup_matches_a_search_of_the_node_times():
    """The scalar lookup must pick the interval a search of the grid ``k * h`` picks, nodes included (a node opens
    the interval starting there), and clamp times outside the step."""
    rng = np.random.default_rng(3)
    for n_nodes in (3, 10, 30, 201):
        for h in (0.01, 0.7 / 29, 1 / 3, 0.123456789 / 7):
            grid = np.arange(n_nodes) * h
            times = np.r_[grid, rng.uniform(-0.1, 1.1 * n_nodes * h, 500), np.linspace(0, grid[-1], 5 * n_nodes)]
            for t in times:
                k = int(np.clip(np.searchsorted(grid, t, side="right") - 1, 0, n_nodes - 2))
                expected = (k, float(np.clip((t - grid[k]) / h, 0.0, 1.0)))
                assert locate_interval(float(t), h, n_nodes) == expected, (n_nodes, h, t)


@pytest.mark.parametrize(("name", "offered"), [("hermite-simpson", "simpson, boole, nodal-simpson"),
                                               ("dmoc", "boole, simpson, midpoint"),
                                               ("trapezoidal", "boole, simpson, trapezoid")])
def test_a_transcription_refuses_a_quadrature_it_does_not_offer_when_created(name, offered):
    registry = load_registry()
    with pytest.raises(ValueError, match=f"quadrature = 'gauss': expected one of {offered}$"):
        registry.create("transcription", name, quadrature="gauss")
    assert registry.create("transcription", name, quadrature="simpson").quadrature == "simpson"
