"""The NLP's CasADi expression graph as a Pyomo model, operation by operation, in time linear in the size of the graph
(see the package docstring for shared subexpressions and lifting)."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import casadi as ca
import numpy as np
import pyomo.environ as pyo
from pyomo.common.numeric_types import native_types
from pyomo.core.expr.visitor import StreamBasedExpressionVisitor

from gaitbench.problem.nlp import NLP


def _if(condition, then, otherwise):
    return pyo.Expr_if(IF=condition, THEN=then, ELSE=otherwise)


def _truth(a):
    """CasADi's logical operations treat any non-zero value as true and return 0 or 1."""
    return _if(a == 0, 0, 1)


_UNARY: dict[int, Callable] = {
    ca.OP_ASSIGN: lambda a: a,
    ca.OP_NEG: lambda a: -a,
    ca.OP_TWICE: lambda a: 2 * a,
    ca.OP_SQ: lambda a: a**2,
    ca.OP_INV: lambda a: 1 / a,
    ca.OP_SQRT: pyo.sqrt,
    ca.OP_EXP: pyo.exp,
    ca.OP_LOG: pyo.log,
    ca.OP_SIN: pyo.sin,
    ca.OP_COS: pyo.cos,
    ca.OP_TAN: pyo.tan,
    ca.OP_ASIN: pyo.asin,
    ca.OP_ACOS: pyo.acos,
    ca.OP_ATAN: pyo.atan,
    ca.OP_SINH: pyo.sinh,
    ca.OP_COSH: pyo.cosh,
    ca.OP_TANH: pyo.tanh,
    ca.OP_ASINH: pyo.asinh,
    ca.OP_ACOSH: pyo.acosh,
    ca.OP_ATANH: pyo.atanh,
    ca.OP_FABS: abs,
    ca.OP_FLOOR: pyo.floor,
    ca.OP_CEIL: pyo.ceil,
    ca.OP_SIGN: lambda a: _if(a > 0, 1, _if(a < 0, -1, 0)),
    ca.OP_NOT: lambda a: _if(a == 0, 1, 0),
}

_BINARY: dict[int, Callable] = {
    ca.OP_ADD: lambda a, b: a + b,
    ca.OP_SUB: lambda a, b: a - b,
    ca.OP_MUL: lambda a, b: a * b,
    ca.OP_DIV: lambda a, b: a / b,
    ca.OP_POW: lambda a, b: a**b,
    ca.OP_CONSTPOW: lambda a, b: a**b,
    ca.OP_FMIN: lambda a, b: _if(a <= b, a, b),
    ca.OP_FMAX: lambda a, b: _if(a >= b, a, b),
    ca.OP_LT: lambda a, b: _if(a < b, 1, 0),
    ca.OP_LE: lambda a, b: _if(a <= b, 1, 0),
    ca.OP_EQ: lambda a, b: _if(a == b, 1, 0),
    ca.OP_NE: lambda a, b: _if(a == b, 0, 1),
    ca.OP_AND: lambda a, b: _if(a == 0, 0, _truth(b)),
    ca.OP_OR: lambda a, b: _if(a == 0, _truth(b), 1),
    ca.OP_IF_ELSE_ZERO: lambda condition, value: _if(condition == 0, 0, value),
}

_REPEATED_ARGUMENTS = {ca.OP_SIGN, ca.OP_FMIN, ca.OP_FMAX}
"""Operations whose Pyomo form uses an argument more than once: it must be a named expression (or a leaf), not a
subtree written out twice."""

_LEAVES = (ca.OP_INPUT, ca.OP_OUTPUT, ca.OP_CONST)
"""Instructions that read an input, write an output or load a constant: no arithmetic to translate."""

_OP_NAMES = {getattr(ca, name): name for name in dir(ca) if name.startswith("OP_")}


class UnsupportedOperationError(ValueError):
    """A CasADi operation without an exact Pyomo (AMPL) equivalent, such as ``OP_ATAN2`` or ``OP_ERF``."""


@dataclass
class PyomoNLP:
    """The Pyomo model of an NLP: ``model.x`` in ``nlp.x`` order, ``model.p`` (mutable) in ``nlp.p`` order, and
    ``model.objective`` and ``model.g`` (indexed like ``nlp.g``; a row free on both sides is left out).

    ``lifted`` lists the auxiliary variables a lifted translation adds (``model.lifted``, defined by the equality
    constraints ``model.lifting``) with the expressions that define them, in evaluation order.
    """

    model: pyo.ConcreteModel
    lifted: list[tuple[pyo.Var, object]]

    def set_point(self, x: np.ndarray, p: np.ndarray) -> None:
        """Put ``x`` and ``p`` into the model, and the auxiliary variables at their defining values."""
        model = self.model
        for index, value in enumerate(x):
            model.x[index].set_value(float(value), skip_validation=True)
        for index, value in enumerate(p):
            model.p[index].set_value(float(value))
        evaluator = _Evaluator()
        for variable, definition in self.lifted:
            try:
                value = evaluator.value(definition)
            except (ArithmeticError, ValueError):  # undefined at this point: the solver starts it from 0
                value = None
            variable.set_value(value, skip_validation=True)

    def evaluate(self, x: np.ndarray, p: np.ndarray) -> tuple[float, np.ndarray]:
        """The Pyomo objective and constraint bodies at (x, p) (NaN for a row left out), in linear time."""
        self.set_point(x, p)
        evaluator = _Evaluator()
        g = np.full(len(self.model.g_index), np.nan)
        for index in self.model.g:
            g[index] = evaluator.value(self.model.g[index].body)
        return evaluator.value(self.model.objective.expr), g


class _Evaluator(StreamBasedExpressionVisitor):
    """Values of Pyomo expressions with each named expression evaluated once.

    ``pyomo.environ.value`` walks a shared subexpression again at every use, exponential in the depth of sharing.
    """

    def __init__(self) -> None:
        super().__init__()
        self.cache: dict = {}

    def value(self, expression) -> float:
        return self.walk_expression(expression)

    def initializeWalker(self, expression):
        if type(expression) in native_types:
            return False, expression
        if not expression.is_expression_type():
            return False, pyo.value(expression)
        return True, None

    def beforeChild(self, node, child, child_idx):
        if type(child) in native_types:
            return False, child
        if child.is_named_expression_type():
            return (False, self.cache[id(child)]) if id(child) in self.cache else (True, None)
        if not child.is_expression_type():
            return False, pyo.value(child)
        return True, None

    def exitNode(self, node, data):
        if node.is_named_expression_type():
            self.cache[id(node)] = data[0]
            return data[0]
        return node._apply_operation(data)


def translate(nlp: NLP, lift_threshold: int = 0) -> PyomoNLP:
    """The NLP as a Pyomo model, exactly, in time linear in the size of its CasADi graph.

    Shared subexpressions become named ``Expression`` s. With ``lift_threshold`` > 0, a shared subexpression that
    depends on x and whose tree (named subexpressions written out, lifted ones as single nodes) has more than
    ``lift_threshold`` nodes becomes an auxiliary variable instead. Raises :class:`UnsupportedOperationError`
    naming the first CasADi operation without a Pyomo equivalent.
    """
    function = ca.Function("nlp", [nlp.x, nlp.p], [nlp.f, nlp.g])
    n = function.n_instructions()
    ops = [function.instruction_id(k) for k in range(n)]
    unsupported = next((op for op in ops if op not in _UNARY and op not in _BINARY and op not in _LEAVES), None)
    if unsupported is not None:
        raise UnsupportedOperationError(
            f"CasADi operation {_OP_NAMES.get(unsupported, unsupported)} has no Pyomo equivalent: the pyomo solver "
            "cannot pass this NLP to an AMPL executable")

    # The virtual machine's work vector, resolved: each instruction's arguments as the instructions producing them.
    arguments: list[list[int]] = [[] for _ in range(n)]
    uses, depends_on_x = [0] * n, [False] * n
    slot_producer: dict[int, int] = {}
    results: list[tuple[int, int, int]] = []  # (output, nonzero, producing instruction)
    for k, op in enumerate(ops):
        if op == ca.OP_OUTPUT:
            output, nonzero = function.instruction_output(k)
            producer = slot_producer[function.instruction_input(k)[0]]
            results.append((output, nonzero, producer))
            uses[producer] += 1
            continue
        if op == ca.OP_INPUT:
            depends_on_x[k] = function.instruction_input(k)[0] == 0
        elif op != ca.OP_CONST:
            arguments[k] = [slot_producer[slot] for slot in function.instruction_input(k)]
            for argument in arguments[k]:
                uses[argument] += 2 if op in _REPEATED_ARGUMENTS else 1
            depends_on_x[k] = any(depends_on_x[argument] for argument in arguments[k])
        slot_producer[function.instruction_output(k)[0]] = k

    model = pyo.ConcreteModel(name="gaitbench_nlp")
    model.x = pyo.Var(range(nlp.n_variables))
    model.p = pyo.Param(range(nlp.p.numel()), mutable=True, initialize=0.0)
    model.shared = pyo.Expression(pyo.Any)
    model.lifted = pyo.Var(pyo.Any, dense=False)
    model.lifting = pyo.Constraint(pyo.Any)
    lifted = []
    expressions: list = [None] * n
    size = [1] * n  # nodes in the tree as ripopt expands it: named subexpressions written out, lifted ones not
    for k, op in enumerate(ops):
        if op == ca.OP_INPUT:
            source, nonzero = function.instruction_input(k)
            expressions[k] = model.x[nonzero] if source == 0 else model.p[nonzero]
            continue
        if op == ca.OP_CONST:
            expressions[k] = float(function.instruction_constant(k))
            continue
        if op == ca.OP_OUTPUT:
            continue
        values = [expressions[argument] for argument in arguments[k]]
        expression = (_UNARY[op] if len(values) == 1 else _BINARY[op])(*values)
        size[k] = 1 + sum(size[argument] if depends_on_x[argument] else 1 for argument in arguments[k])
        if uses[k] > 1 and depends_on_x[k] and 0 < lift_threshold < size[k]:
            model.lifting[k] = model.lifted[k] == expression
            lifted.append((model.lifted[k], expression))
            expression, size[k] = model.lifted[k], 1
        elif uses[k] > 1 and not isinstance(expression, float):
            model.shared[k] = expression
            expression = model.shared[k]
        expressions[k] = expression

    objective, g = 0.0, [0.0] * nlp.n_constraints
    g_rows = function.sparsity_out(1).row()
    for output, nonzero, producer in results:
        if output == 0:
            objective = expressions[producer]
        else:
            g[g_rows[nonzero]] = expressions[producer]
    for row, body in enumerate(g):
        if isinstance(body, float):  # a constant row (structural zeros included): a constraint needs an expression
            model.shared["constant", row] = body
            g[row] = model.shared["constant", row]
    model.objective = pyo.Objective(expr=objective, sense=pyo.minimize)
    model.g_index = pyo.Set(initialize=range(nlp.n_constraints))
    model.g = pyo.Constraint(model.g_index, rule=lambda _, i: _row(g[i], nlp.lbg[i], nlp.ubg[i]))
    model.dual = pyo.Suffix(direction=pyo.Suffix.IMPORT)
    for index in range(nlp.n_variables):
        model.x[index].setlb(_finite(nlp.lbx[index]))
        model.x[index].setub(_finite(nlp.ubx[index]))
    return PyomoNLP(model, lifted)



def _finite(bound: float) -> float | None:
    return None if math.isinf(bound) else float(bound)


def _row(body, lower: float, upper: float):
    if lower == upper:
        return body == float(lower)
    if math.isinf(lower) and math.isinf(upper):
        return pyo.Constraint.Skip
    return (_finite(lower), body, _finite(upper))
