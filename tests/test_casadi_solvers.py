"""CasADi's own NLP methods as plugins: what each solves, the shared options, limits, reuse, FATROP's structure."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import casadi as ca
import numpy as np
import pytest
from gait_steps import gait_step
from nlp_problems import (
    ReferenceProblem,
    extended_rosenbrock,
    hs071,
    nonnegative_projection,
    projection_optimum,
    undefined_at_start,
)

from gaitbench.problem.nlp import NLP, NLPBuilder
from gaitbench.solver_result import SolverStatus
from gaitbench_plugins.solvers.casadi_solvers import CasadiMethod, Fatrop, register_solvers
from gaitbench_plugins.solvers.ipopt import Ipopt

METHODS = [Fatrop]


def _solve(method: type[CasadiMethod], problem: ReferenceProblem, x0: np.ndarray | None = None, **options):
    return method(**options).solve(problem.nlp, problem.parameters, problem.x0 if x0 is None else x0)


@pytest.mark.parametrize("method", METHODS, ids=lambda method: method.name)
def test_solves_hs071_to_its_published_optimum(method: type[CasadiMethod]):
    problem = hs071()
    result = _solve(method, problem)
    assert result.status is SolverStatus.CONVERGED, result.message
    assert abs(result.objective - problem.f_star) <= 1e-6 * problem.f_star
    assert result.constraint_violation <= 1e-7
    np.testing.assert_allclose(result.x, problem.x_star, atol=1e-6)
    np.testing.assert_allclose(result.multipliers, Ipopt().solve(problem.nlp, [], problem.x0).multipliers, atol=1e-6)


@pytest.mark.parametrize(("method", "return_status"), [
    (Fatrop, "MaxIterExceeded"),
], ids=["fatrop"])
def test_iteration_limit(method: type[CasadiMethod], return_status: str):
    """HS071 takes 5-8 iterations; FATROP is given max_iter one lower, as it takes one more."""
    result = _solve(method, hs071(), max_iterations=2)
    assert result.status is SolverStatus.ITERATION_LIMIT
    assert result.message == f"{method.name}: {return_status}"
    assert result.iterations == 2


@pytest.mark.parametrize("method", METHODS, ids=lambda method: method.name)
def test_tolerance_is_the_methods_convergence_tolerance(method: type[CasadiMethod]):
    problem = extended_rosenbrock(2)
    loose, tight = _solve(method, problem, tolerance=1e-2), _solve(method, problem, tolerance=1e-10)
    assert loose.converged and tight.converged
    assert loose.iterations < tight.iterations
    assert tight.objective < 1e-12 < loose.objective


@pytest.mark.parametrize("method", METHODS, ids=lambda method: method.name)
def test_time_limit_of_a_method_that_cannot_be_stopped_is_reported_with_its_point(method: type[CasadiMethod]):
    problem = hs071()
    result = _solve(method, problem, time_limit_s=1e-9)
    assert result.status is SolverStatus.TIME_LIMIT
    assert f"past the time limit of 1e-09 s ({method.plugin} cannot be stopped during a solve)" in result.message
    assert result.objective == pytest.approx(problem.f_star, rel=1e-6)  # it finished, after the limit
    assert _solve(method, problem, time_limit_s=60).converged


@pytest.mark.parametrize(("method", "message"), [
    (Fatrop, "fatrop: Success, at a point where the NLP is not finite"),
], ids=[method.name for method in METHODS])
def test_nan_at_the_starting_point_is_an_error(method: type[CasadiMethod], message: str):
    result = _solve(method, undefined_at_start())
    assert result.status is SolverStatus.ERROR
    assert result.message == message


@pytest.mark.parametrize("method", METHODS, ids=lambda method: method.name)
def test_bad_input_is_an_error_not_an_exception(method: type[CasadiMethod]):
    problem = hs071()
    result = method().solve(problem.nlp, problem.parameters, np.zeros(3))
    assert result.status is SolverStatus.ERROR
    assert result.message.startswith(f"{method.name}: RuntimeError: Input 0 (x0) has mismatching shape.")


@pytest.mark.parametrize("method", METHODS, ids=lambda method: method.name)
def test_built_once_per_nlp_and_options(method: type[CasadiMethod], monkeypatch: pytest.MonkeyPatch):
    builds = []
    nlpsol = ca.nlpsol
    monkeypatch.setattr(ca, "nlpsol", lambda *args: builds.append(args[1]) or nlpsol(*args))
    problem = nonnegative_projection(2.0)
    solver = method()
    for target in (2.0, -1.0, 3.0):
        result = solver.solve(problem.nlp, [target], problem.x0)
        f_star, x_star = projection_optimum(target)
        assert result.status is SolverStatus.CONVERGED, result.message
        assert result.objective == pytest.approx(f_star, abs=1e-6)
        np.testing.assert_allclose(result.x, x_star, atol=1e-6)
    assert builds == [method.plugin]
    method(max_iterations=50).solve(problem.nlp, [1.0], problem.x0)
    method(max_iterations=50).solve(problem.nlp, [1.0], problem.x0)
    assert builds == [method.plugin] * 2
    assert len([built for built in problem.nlp.solver_cache.values() if isinstance(built, ca.Function)]) == 2


def test_shared_options_map_to_each_methods_own():
    fatrop = Fatrop(max_iterations=7, tolerance=1e-5, mu_init=0.01, convexify_strategy="regularize").options
    assert fatrop["fatrop"] == {"max_iter": 6, "tol": 1e-5, "print_level": 0, "mu_init": 0.01}
    assert fatrop["convexify_strategy"] == "regularize"


def _stage_wise_ocp(n_stages: int = 10) -> NLP:
    """min Σuₖ² + v_N² for a cubic-spring double integrator driven from rest at p to position 0.2, built the way
    FATROP wants: variables [x₀, u₀, x₁, u₁, …, x_N], stage k's dynamics x_{k+1} − f(x_k, u_k) = 0 first, then
    that stage's other constraints."""
    b = NLPBuilder()
    p = ca.SX.sym("p", 2)
    states = [b.variable("x0", (2, 1))]
    controls = []
    for k in range(n_stages):
        controls.append(b.variable(f"u{k}", (1, 1), -1.0, 1.0))
        states.append(b.variable(f"x{k + 1}", (2, 1)))
        x, u, h = states[k], controls[k], 0.1
        b.constrain(f"dynamics{k}", states[k + 1] - ca.vertcat(x[0] + h * x[1], x[1] + h * (u - 0.1 * x[0] ** 3)))
        if k == 0:
            b.constrain("initial_state", x - p)
    b.constrain("final_position", states[-1][0] - 0.2)
    return b.build(p, sum(u ** 2 for u in controls) + states[-1][1] ** 2)


def test_fatrop_detects_the_stages_of_an_ocp_built_stage_wise():
    nlp = _stage_wise_ocp()
    x0, p = np.zeros(nlp.n_variables), np.zeros(2)
    reference = Ipopt().solve(_stage_wise_ocp(), p, x0)
    for structure_detection in ("auto", "none"):
        result = Fatrop(structure_detection=structure_detection).solve(nlp, p, x0)
        assert result.status is SolverStatus.CONVERGED, result.message
        assert result.objective == pytest.approx(reference.objective, rel=1e-8)
    stages = [solver.stats()["N"] for solver in nlp.solver_cache.values() if isinstance(solver, ca.Function)]
    assert stages == [10, 0]  # ten stages found, against one dense stage


def test_fatrop_structure_detection_on_a_gait_step_fails_with_the_reason():
    problem = gait_step("dmoc", 20)
    result = Fatrop(structure_detection="auto").solve(problem.nlp, problem.parameters, problem.x0)
    assert result.status is SolverStatus.ERROR
    assert result.message.startswith("fatrop: RuntimeError: structure detection failed: the NLP is not an OCP in "
                                     "stage-wise order")
    assert "Fatrop: specified structure of A does not correspond to what the interface can handle" in result.message


@pytest.mark.parametrize("transcription", ["hermite-simpson", "dmoc"])
def test_fatrop_stagewise_solves_the_forward_gait_step_to_ipopts_optimum(transcription: str):
    """The step NLP rewritten stage-wise (gaitbench/problem/stagewise.py), FATROP given its stages: forward step 1,
    N = 10, torque tie-break, from the standard guess. Measured: HS in 31 iterations at IPOPT's x to 1e-9; DMOC in 130,
    8e-7 below f*. The result is the NLP's own point: its objective and violation, its rows' multipliers."""
    problem = gait_step(transcription, 10, "forward")
    fatrop = Fatrop(stagewise=True)
    result = fatrop.solve(problem.nlp, problem.parameters, problem.x0)
    assert result.status is SolverStatus.CONVERGED, result.message
    assert result.x.shape == problem.x_star.shape and result.multipliers.shape == (problem.nlp.n_constraints,)
    assert result.constraint_violation <= 1e-7
    assert abs(result.objective - problem.f_star) <= 1e-5 * problem.f_star
    reference = Ipopt().solve(problem.nlp, problem.parameters, problem.x0)
    assert np.abs(result.multipliers - reference.multipliers).max() <= 1e-6 * np.abs(reference.multipliers).max()
    if transcription == "hermite-simpson":  # DMOC's optimum is flatter: another point, as low
        assert np.abs(result.x - problem.x_star).max() <= 1e-6 * np.abs(problem.x_star).max()
    assert problem.nlp.solver_cache[fatrop._key()].stats()["N"] == 9  # a stage per node, not one dense stage


def test_fatrop_stagewise_refuses_a_structure_of_its_own():
    with pytest.raises(ValueError, match="stagewise = true gives FATROP the structure itself"):
        Fatrop(stagewise=True, structure_detection="manual")
    with pytest.raises(TypeError, match="expected true, false or 'auto'"):
        Fatrop(stagewise="yes")


def test_fatrop_by_default_solves_a_gait_step_stage_wise_and_a_textbook_nlp_dense():
    """``stagewise="auto"``: the stage-wise form where the NLP has one, one dense stage where it has none or where
    the user gives a structure."""
    step, textbook = gait_step("dmoc", 10, "forward"), hs071()
    fatrop = Fatrop()
    assert fatrop.solve(step.nlp, step.parameters, step.x0).converged
    assert fatrop.solve(textbook.nlp, textbook.parameters, textbook.x0).converged
    assert step.nlp.solver_cache[fatrop._key()].stats()["N"] == 9  # a stage per node
    assert textbook.nlp.solver_cache[fatrop._key()].stats()["N"] == 0  # one dense stage
    assert Fatrop(structure_detection="auto").stagewise is False


def test_print_level_zero_is_silent_on_standard_output():
    """CasADi's FATROP interface prints a warning per row its structure detection refuses, whatever the print
    options say (on a gait step, which is not stage-wise as built); they are cut."""
    script = ("from gait_steps import gait_step; from gaitbench_plugins.solvers.casadi_solvers import Fatrop; "
              "p = gait_step('dmoc', 10); "
              "assert Fatrop(structure_detection='auto').solve(p.nlp, p.parameters, p.x0).status.name == 'ERROR'; "
              "print('done')")
    run = subprocess.run([sys.executable, "-c", script], cwd=Path(__file__).parent, capture_output=True, text=True)
    assert (run.returncode, run.stdout, run.stderr) == (0, "done\n", "")


@pytest.mark.parametrize(("method", "problem", "log_line"), [
    (Fatrop, hs071(), "iter    objective   inf_pr   inf_du"),
], ids=[method.name for method in METHODS])
def test_print_level_one_prints_the_iteration_log(method: type[CasadiMethod], problem: ReferenceProblem,
                                                  log_line: str, capfd: pytest.CaptureFixture):
    assert method(print_level=1).solve(problem.nlp, problem.parameters, problem.x0).converged
    assert log_line in capfd.readouterr().out


def test_registers_each_method_under_its_name():
    assert {registration.name: registration.factory for registration in register_solvers()} == {
        "fatrop": Fatrop}


@pytest.mark.parametrize("transcription", ["hermite-simpson", "dmoc"])
@pytest.mark.parametrize("method", METHODS, ids=lambda method: method.name)
def test_solves_the_forward_gait_step_to_ipopts_optimum(method: type[CasadiMethod], transcription: str):
    """Forward step 1 (4-DOF, N = 10, torque tie-break) from the transcription's standard guess; ``f_star`` is
    IPOPT's optimum from the same guess. Measured: within 4e-4 of it (docs/decisions/0005-casadi-solvers.md)."""
    problem = gait_step(transcription, 10, "forward")
    result = _solve(method, problem)
    assert result.status is SolverStatus.CONVERGED, result.message
    assert result.constraint_violation <= 1e-7
    assert abs(result.objective - problem.f_star) <= 1e-3 * problem.f_star
