"""NumericFunction: buffer evaluation must give exactly what a plain CasADi call gives."""

import casadi as ca
import numpy as np
import pytest

from gaitbench.model.mechanics import biped_functions
from gaitbench.model.numeric import NumericFunction


@pytest.mark.parametrize("dof", [2, 4])
def test_forward_dynamics_bitwise_equal_to_a_casadi_call(dof):
    function = biped_functions(dof, 2).forward_dynamics
    fast = NumericFunction(function)
    rng = np.random.default_rng(dof)
    for _ in range(5):
        args = [rng.normal(size=dof), rng.normal(size=dof), rng.normal(size=2), rng.uniform(0.5, 2.0, size=8)]
        expected = [np.asarray(out).ravel() for out in function(*args)]
        got = fast(*args)
        for want, have in zip(expected, got, strict=True):
            assert np.array_equal(want, have)


def test_matrices_come_back_column_major_and_structural_zeros_are_filled():
    x = ca.SX.sym("x", 2)
    matrix = ca.SX(2, 2)  # lower triangle only: (0, 1) is a structural zero
    matrix[0, 0], matrix[1, 0], matrix[1, 1] = x[0], 2 * x[1], x[0] * x[1]
    function = ca.Function("f", [x], [matrix])
    assert not function.sparsity_out(0).is_dense()
    result = NumericFunction(function)([3.0, 5.0])
    assert np.array_equal(result, np.array([[3.0, 0.0], [10.0, 15.0]]))


def test_outputs_are_copies_and_argument_count_is_checked():
    x = ca.SX.sym("x", 2)
    fast = NumericFunction(ca.Function("f", [x], [2 * x]))
    first = fast([1.0, 2.0])
    fast([7.0, 7.0])
    assert np.array_equal(first, [2.0, 4.0])
    with pytest.raises(TypeError, match="takes 1 arguments"):
        fast([1.0, 2.0], [3.0])
