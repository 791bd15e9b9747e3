"""Interval blocks: constraints and derivatives assembled from compiled per-interval functions must equal those of
the flat expression graph they replace, and the compiled-function cache must fall back safely."""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest

from gaitbench.plugins import load_registry
from gaitbench.problem import compiled as compiled_module
from gaitbench.problem.gait_problem import ProblemOptions, StepStructure
from gaitbench.problem.nlp import NLPBuilder


def _dense(matrix) -> np.ndarray:
    return np.asarray(ca.densify(ca.DM(matrix)))


@pytest.mark.parametrize("transcription", ["hermite-simpson", "dmoc"])
@pytest.mark.parametrize("phase", ["first", "second"])
@pytest.mark.parametrize("absolute_value", ["slack", "smooth"])
@pytest.mark.parametrize("contact", [False, True], ids=["no-contact-rows", "contact-rows"])
def test_structured_functions_equal_the_flat_graph(transcription, phase, absolute_value, contact):
    transcription = load_registry().create("transcription", transcription)
    options = ProblemOptions(absolute_value=absolute_value, unilateral_contact=contact,
                             friction_coefficient=0.8 if contact else None)
    nlp = transcription.build(StepStructure(phase, 9, options)).nlp
    assert nlp.interval_blocks, "Hermite–Simpson declares its defects per interval, DMOC its interior momentum balance"
    if phase == "second":
        names = {block.function.name() for block in nlp.interval_blocks}
        assert ({"unilateral_contact", "friction_cone"} <= names) == contact, "one function of each node's variables"
    rng = np.random.default_rng(3)
    x, lam = rng.normal(size=nlp.n_variables), rng.normal(size=nlp.n_constraints)
    p = np.r_[20, 20, 40, 1, 0.5, 1.2, 1.2, 9.81, 0.2, -0.2, -1.1, -0.4, 0.4, 0.0, 0.09, 0.0]
    sigma = ca.SX.sym("sigma")
    multipliers = ca.SX.sym("lam", nlp.n_constraints)
    flat_hessian = ca.hessian(sigma * nlp.f + ca.dot(multipliers, nlp.g), nlp.x)[0]
    reference = {
        "g": ca.Function("g", [nlp.x, nlp.p], [nlp.g])(x, p),
        "jacobian": ca.Function("j", [nlp.x, nlp.p], [ca.jacobian(nlp.g, nlp.x)])(x, p),
        "hessian": ca.Function("h", [nlp.x, nlp.p, sigma, multipliers], [ca.tril(flat_hessian)])(x, p, 0.7, lam),
    }
    functions = nlp.functions
    structured = {
        "g": functions.constraints(x, p),
        "jacobian": functions.jacobian(x, p),
        "hessian": functions.hessian_lagrangian(x, p, 0.7, lam),
    }
    for name, value in structured.items():
        np.testing.assert_allclose(_dense(value), _dense(reference[name]), rtol=1e-12, atol=1e-12, err_msg=name)
    upper = functions.hessian_lagrangian_upper(x, p, 0.7, lam)
    np.testing.assert_allclose(_dense(upper), _dense(reference["hessian"]).T, rtol=1e-12, atol=1e-12)
    g, jacobian = functions.constraints_and_jacobian(x, p)
    np.testing.assert_allclose(_dense(g), _dense(reference["g"]), rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(_dense(jacobian), _dense(reference["jacobian"]), rtol=1e-12, atol=1e-12)


def test_interval_variables_must_be_decision_variables():
    builder = NLPBuilder()
    states = builder.variable("states", (2, 3))
    z = ca.SX.sym("z", 2)
    square = ca.Function("square", [z, ca.SX.sym("p", 1)], [z * z])
    builder.constrain_intervals(["ok"], square, [states], ca.SX.sym("p", 1))
    builder.constrain_intervals(["bad"], square, [2 * states], ca.SX.sym("p", 1))
    with pytest.raises(ValueError, match="bad.*decision-variable symbol"):
        builder.build(ca.SX.sym("p", 1), ca.sumsqr(states))


def test_a_variable_twice_in_one_interval_is_refused():
    builder = NLPBuilder()
    states = builder.variable("states", (2, 3))
    z = ca.SX.sym("z", 4)
    product = ca.Function("product", [z, ca.SX.sym("p", 1)], [z[0] * z[2]])
    builder.constrain_intervals(["twice"], product, [states, states], ca.SX.sym("p", 1))
    with pytest.raises(ValueError, match="twice.*appears twice"):
        builder.build(ca.SX.sym("p", 1), ca.sumsqr(states))


def test_compiled_function_matches_and_is_cached(tmp_path, monkeypatch):
    monkeypatch.setenv("GAITBENCH_CACHE", str(tmp_path))
    z = ca.SX.sym("z", 3)
    function = ca.Function("cache_probe", [z], [ca.sin(z) * z[0]])
    fast = compiled_module.compiled(function)
    if not isinstance(fast, ca.Function) or fast.class_name() != "External":
        pytest.skip("no working C compiler here")
    libraries = list((tmp_path / "compiled").glob("cache_probe-*.so"))
    assert len(libraries) == 1
    value = np.array([0.3, -1.2, 2.0])
    np.testing.assert_array_equal(np.asarray(fast(value)), np.asarray(function(value)))
    stamp = libraries[0].stat().st_mtime_ns
    compiled_module._LOADED.clear()  # a new process: only the disk cache remains
    compiled_module.compiled(function)  # found in the cache, not compiled again
    assert libraries[0].stat().st_mtime_ns == stamp


def test_without_a_compiler_the_function_is_interpreted(tmp_path, monkeypatch):
    monkeypatch.setenv("GAITBENCH_CACHE", str(tmp_path))
    monkeypatch.setenv("CC", "no-such-compiler-gaitbench")
    compiled_module._compiler.cache_clear()
    compiled_module._warn_once.cache_clear()
    try:
        z = ca.SX.sym("z", 2)
        function = ca.Function("no_compiler_probe", [z], [z * 2])
        with pytest.warns(RuntimeWarning, match="no C compiler"):
            assert compiled_module.compiled(function) is function
    finally:
        compiled_module._compiler.cache_clear()


def test_a_block_grows_by_parts_declared_one_after_another_and_its_interval_part_keeps_its_rows():
    builder = NLPBuilder()
    states = builder.variable("states", (1, 4))
    z, p = ca.SX.sym("z", 2), ca.SX.sym("p", 1)
    difference = ca.Function("difference", [z, p], [z[1] - z[0] - p])
    builder.constrain("other", states[0])
    builder.constrain("balance", states[0] - 1)
    builder.constrain_intervals(["balance"], difference, [states[:, :-1], states[:, 1:]], p)
    builder.constrain("balance", states[3] + 1)
    nlp = builder.build(p, ca.sumsqr(states))
    assert nlp.constraint_blocks["balance"] == slice(1, 6)
    (block,) = nlp.interval_blocks
    np.testing.assert_array_equal(block.rows[0], [[2, 3, 4]])
    x, parameter = np.array([1.0, 2.5, 4.5, 8.0]), np.array([0.5])
    np.testing.assert_allclose(np.asarray(nlp.functions.constraints(x, parameter)).ravel(),
                               [1.0, 0.0, 1.0, 1.5, 3.0, 9.0])


def test_columns_that_are_one_function_of_their_own_variables_become_a_block():
    builder = NLPBuilder()
    states = builder.variable("states", (2, 4))
    p = ca.SX.sym("p", 1)
    builder.constrain_columns("swing", ca.sin(states[0, :]) * states[1, :] - p, 0.0, np.inf)
    builder.constrain_columns("end", states[0, -1] ** 2)
    nlp = builder.build(p, ca.sumsqr(states))
    swing, end = nlp.interval_blocks
    np.testing.assert_array_equal(swing.variables, [[0, 2, 4, 6], [1, 3, 5, 7]])
    np.testing.assert_array_equal(swing.rows[0], [[0, 1, 2, 3]])
    np.testing.assert_array_equal(end.variables, [[6]])
    x, parameter = np.linspace(0.1, 0.8, 8), np.array([0.3])
    expected = np.r_[np.sin(x[0::2]) * x[1::2] - 0.3, x[6] ** 2]
    np.testing.assert_allclose(np.asarray(nlp.functions.constraints(x, parameter)).ravel(), expected)
    np.testing.assert_array_equal(nlp.lbg, [0, 0, 0, 0, 0])
    np.testing.assert_array_equal(nlp.ubg, [np.inf] * 4 + [0])


def test_columns_that_are_not_one_function_stay_plain_rows():
    builder = NLPBuilder()
    states = builder.variable("states", (1, 3))
    unlike = ca.horzcat(ca.sin(states[0]), ca.cos(states[1]), ca.sin(states[2]))
    builder.constrain_columns("unlike", unlike)
    builder.constrain_columns("sizes", ca.horzcat(states[0] * states[1], states[2] ** 2))
    builder.constrain_columns("none", ca.SX(1, 0))
    nlp = builder.build(ca.SX.sym("p", 1), ca.sumsqr(states))
    assert nlp.interval_blocks == ()
    assert nlp.constraint_blocks == {"unlike": slice(0, 3), "sizes": slice(3, 5), "none": slice(5, 5)}


def test_a_block_declared_again_after_another_is_refused():
    builder = NLPBuilder()
    states = builder.variable("states", (1, 2))
    builder.constrain("balance", states[0])
    builder.constrain("other", states[1])
    builder.constrain("balance", states[1])
    with pytest.raises(ValueError, match="'balance' declared twice apart"):
        builder.build(ca.SX.sym("p", 1), ca.sumsqr(states))


def test_an_interval_function_declared_anew_reuses_its_derivatives():
    """Each structure (each sectional problem of a walk) declares its interval function anew; its compiled
    derivatives must come from the first declaration, not be derived and hashed again."""
    from gaitbench.problem.nlp import _derived, _interval_hessian

    def declare():
        z, p = ca.SX.sym("z", 2), ca.SX.sym("p", 1)
        return ca.Function("reuse_probe", [z, p], [ca.sin(z[0]) * z[1] * p])

    derivations = []

    def counted_hessian(function):
        derivations.append(function.name())
        return _interval_hessian(function)

    first, second = _derived(declare(), counted_hessian), _derived(declare(), counted_hessian)
    assert derivations == ["reuse_probe"]
    assert first[0] is second[0]
    np.testing.assert_array_equal(first[1][0], second[1][0])


@pytest.mark.parametrize("transcription", ["hermite-simpson", "dmoc"])
def test_ipopt_on_the_compiled_oracle_takes_the_flat_problem_s_iterates(transcription):
    """The ipopt plugin's oracle evaluates g through the compiled interval functions: with the same derivatives,
    IPOPT must walk the same path as on the flat SX problem's g, to the same solution."""
    import casadi as ca

    from gaitbench.contracts import WalkProblem

    registry = load_registry()
    experiment = registry.create("experiment", "forward")
    solver = registry.create("solver", "ipopt")
    problem = WalkProblem(experiment, registry.create("transcription", transcription), solver, 12)
    data = problem.step_data(1, np.asarray(experiment.initial_state)[[0, 1, 4, 5]])
    built = problem.transcription.build(problem.structure("second"))
    nlp, p, x0 = built.nlp, data.parameter_vector(), built.initial_guess(data)
    assert isinstance(nlp.functions.oracle["g"], ca.MX)
    result = solver.solve(nlp, p, x0)
    derivatives = {"jac_g": nlp.functions.constraints_and_jacobian, "hess_lag": nlp.functions.hessian_lagrangian_upper}
    flat = ca.nlpsol("flat", "ipopt", nlp.casadi_problem(), solver.options | derivatives)
    reference = flat(x0=x0, p=p, lbx=nlp.lbx, ubx=nlp.ubx, lbg=nlp.lbg, ubg=nlp.ubg)
    assert result.converged
    assert result.iterations == flat.stats()["iter_count"]
    np.testing.assert_allclose(result.x, np.asarray(reference["x"]).ravel(), rtol=1e-9, atol=1e-9)
