"""Variable and constraint scaling: the scaled problem is the original one in other units, so IPOPT on it must reach
the same optima, with the multipliers of the original constraints."""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest
from nlp_problems import STANDARD_PROBLEMS, ReferenceProblem, hs071

from gaitbench.plugins import load_registry
from gaitbench.problem.gait_problem import ProblemOptions, StepStructure
from gaitbench.problem.scaling import ScaledProblem, ScaleFactors, nominal_factors
from gaitbench_plugins.solvers.ipopt import Ipopt


def _dense(matrix) -> np.ndarray:
    return np.asarray(ca.densify(ca.DM(matrix)))


def _step_nlp(transcription: str):
    structure = StepStructure("second", 9, ProblemOptions())
    return load_registry().create("transcription", transcription).build(structure).nlp


STEP_PARAMETERS = np.r_[20, 20, 40, 1, 0.5, 1.2, 1.2, 9.81, 0.2, -0.2, -1.1, -0.4, 0.4, 0.0, 0.09, 0.0]


@pytest.mark.parametrize("case", ["hs071", "hermite-simpson", "dmoc"])
def test_scaled_functions_are_the_original_ones_in_scaled_units(case):
    nlp, p = (hs071().nlp, np.zeros(0)) if case == "hs071" else (_step_nlp(case), STEP_PARAMETERS)
    rng = np.random.default_rng(7)
    d = np.exp(rng.normal(scale=2.0, size=nlp.n_variables))
    c = np.exp(rng.normal(scale=2.0, size=nlp.n_constraints))
    x_scaled, lam_scaled = rng.normal(size=nlp.n_variables), rng.normal(size=nlp.n_constraints)
    sigma, x = 0.7, d * x_scaled
    scaled, parameters = ScaledProblem(nlp), ScaleFactors(d, c).parameters(p)
    functions = nlp.functions

    g, jacobian = scaled.constraints_and_jacobian(x_scaled, parameters)
    np.testing.assert_allclose(_dense(g).ravel(), _dense(functions.constraints(x, p)).ravel() / c, rtol=1e-12)
    expected_jacobian = _dense(functions.jacobian(x, p)) / c[:, None] * d[None, :]
    np.testing.assert_allclose(_dense(jacobian), expected_jacobian, rtol=1e-12, atol=1e-300)
    hessian = scaled.hessian_lagrangian_upper(x_scaled, parameters, sigma, lam_scaled)
    original = _dense(functions.hessian_lagrangian_upper(x, p, sigma, lam_scaled / c))
    np.testing.assert_allclose(_dense(hessian), d[:, None] * original * d[None, :], rtol=1e-12, atol=1e-300)
    assert ca.DM(hessian).sparsity() == ca.DM(functions.hessian_lagrangian_upper(x, p, sigma, lam_scaled)).sparsity()
    oracle = ca.Function("oracle", [scaled.oracle["x"], scaled.oracle["p"]], [scaled.oracle["f"]])
    assert float(oracle(x_scaled, parameters)) == pytest.approx(float(functions.objective(x, p)), rel=1e-12)


@pytest.mark.parametrize("transcription", ["hermite-simpson", "dmoc"])
def test_nominal_factors_give_blocks_their_guess_magnitude_and_rows_a_unit_gradient(transcription):
    registry = load_registry()
    from gaitbench.contracts import WalkProblem

    experiment = registry.create("experiment", "forward")
    problem = WalkProblem(experiment, registry.create("transcription", transcription),
                          registry.create("solver", "ipopt"), 12)
    data = problem.step_data(1, np.asarray(experiment.initial_state)[[0, 1, 4, 5]])
    built = problem.transcription.build(problem.structure("second"))
    nlp, p, x0 = built.nlp, data.parameter_vector(), built.initial_guess(data)
    factors = nominal_factors(nlp, x0, p)
    for name, block in nlp.variable_blocks.items():
        magnitude = np.max(np.abs(x0[block]))
        assert np.all(factors.variables[block] == (magnitude if magnitude > 0 else 1.0)), name
    scaled_jacobian = _dense(nlp.functions.jacobian(x0, p)) * factors.variables / factors.constraints[:, None]
    row_norms = np.max(np.abs(scaled_jacobian), axis=1)
    np.testing.assert_allclose(row_norms[row_norms > 0], 1.0, rtol=1e-12)
    assert len(set(factors.constraints.round(12))) > 10, "the rows of a gait step are not all alike"


@pytest.mark.parametrize("problem", STANDARD_PROBLEMS, ids=lambda problem: problem.name)
def test_ipopt_with_nominal_scaling_reaches_the_published_optimum(problem: ReferenceProblem):
    result = Ipopt(scaling="nominal").solve(problem.nlp, problem.parameters, problem.x0)
    assert result.converged, result.message
    assert abs(result.objective - problem.f_star) <= 1e-6 * max(1.0, abs(problem.f_star))
    # IPOPT's tolerances (and its bound relaxation) hold in the scaled units: a row scaled by c is met to c·tol.
    nlp, factors = problem.nlp, nominal_factors(problem.nlp, problem.x0, problem.parameters)
    g = nlp.constraint_values(result.x, problem.parameters)
    assert np.max(np.r_[(nlp.lbg - g) / factors.constraints, (g - nlp.ubg) / factors.constraints,
                        (nlp.lbx - result.x) / factors.variables, (result.x - nlp.ubx) / factors.variables,
                        0.0]) <= 1e-7
    if problem.x_star is not None:
        np.testing.assert_allclose(result.x, problem.x_star, atol=1e-6)
    reference = Ipopt().solve(problem.nlp, problem.parameters, problem.x0)
    np.testing.assert_allclose(result.multipliers, reference.multipliers, rtol=1e-5, atol=1e-7)


def test_scaled_and_unscaled_solvers_are_kept_apart():
    problem = hs071()
    Ipopt().solve(problem.nlp, problem.parameters, problem.x0)
    Ipopt(scaling="nominal").solve(problem.nlp, problem.parameters, problem.x0)
    assert len(problem.nlp.solver_cache) == 2


def test_an_unknown_scaling_names_the_choices():
    with pytest.raises(ValueError, match="scaling = 'unit': expected one of none, nominal"):
        Ipopt(scaling="unit")
