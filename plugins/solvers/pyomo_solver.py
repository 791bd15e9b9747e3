"""Any AMPL-NL solver executable (ripopt, IPOPT, SNOPT, KNITRO, CONOPT, ...) on a gaitbench NLP, through Pyomo.

The thesis's SNOPT results, like most commercial NLP solvers, are reachable only through an executable that reads
AMPL ``.nl`` files. This plugin translates the NLP's CasADi expression graph into a Pyomo model operation by
operation — the same variables, bounds, objective and constraints, the parameters as mutable Pyomo ``Param`` s —
lets Pyomo write the ``.nl`` file and runs the executable on it. Out of the box that is ``ripopt``, the binary the
``pyomo-ripopt`` wheel bundles; ``-o executable=snopt`` runs the ``snopt`` on PATH instead.

The translation walks the algorithm of ``casadi.Function("nlp", [x, p], [f, g])`` instruction by instruction, like
CasADi's own virtual machine, so it takes time linear in the size of the graph. A subexpression the graph shares
becomes a named Pyomo ``Expression``, which Pyomo writes as an AMPL *defined variable* (written once, referenced
wherever it is used): gait NLPs share so much that their objective, written out as a tree, has ~7·10⁸ nodes.
ripopt 0.8 copies every defined variable into each expression that uses it and runs out of memory on such a
file, so for ripopt the largest shared subexpressions are *lifted* instead: each becomes an auxiliary variable
with an equality constraint defining it, an equivalent NLP with the same optimum and constraint multipliers.

The translated model is kept in ``nlp.solver_cache``, so re-solving with new parameters does not translate again
(the ``.nl`` file is still written for every solve: that is how the executable reads the problem).
"""

from __future__ import annotations

import io
import math
import os
import re
import subprocess
import tempfile
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import casadi as ca
import numpy as np
import pyomo.environ as pyo
from pyomo.common import Executable
from pyomo.common.log import LoggingIntercept
from pyomo.common.numeric_types import native_types
from pyomo.core.expr.visitor import StreamBasedExpressionVisitor
from pyomo.opt import TerminationCondition

from gaitbench import Registration, hookimpl
from gaitbench.problem.nlp import NLP
from gaitbench.solve.evaluation import Deadline, NLPEvaluator, error_result, solver_result
from gaitbench.solve.solver import SolverResult, SolverStatus, options_key

# ---------------------------------------------------------------------------------------------------------------
# CasADi SX graph → Pyomo expressions


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


# ---------------------------------------------------------------------------------------------------------------
# Running an AMPL executable


_OPTION_NAMES: dict[str, dict[str, str]] = {
    "ripopt": {"max_iterations": "max_iter", "time_limit_s": "max_wall_time", "tolerance": "tol",
               "print_level": "print_level"},
    "ipopt": {"max_iterations": "max_iter", "time_limit_s": "max_wall_time", "tolerance": "tol",
              "print_level": "print_level"},
    "snopt": {"max_iterations": "major_iterations_limit", "time_limit_s": "time_limit",
              "tolerance": "major_optimality_tolerance", "print_level": "outlev"},
    "knitro": {"max_iterations": "maxit", "time_limit_s": "maxtime_real", "tolerance": "opttol",
               "print_level": "outlev"},
    "conopt": {"max_iterations": "iterlim", "time_limit_s": "maxftime", "tolerance": "rtredg",
               "print_level": "outlev"},
}
"""Each known executable's AMPL names for the shared options (``knitroampl`` is ``knitro``). ripopt's are from its
``--help``; IPOPT's ``max_wall_time`` needs Ipopt ≥ 3.14; SNOPT's ``time_limit`` needs SNOPT ≥ 7.7; CONOPT's
``maxftime`` limits CPU seconds and ``rtredg`` is its reduced-gradient optimality tolerance."""

_DEFAULT_LIFT_THRESHOLDS = {"ripopt": 20}
"""Executables that copy AMPL defined variables into every expression using them (see the module docstring);
every other executable gets the exact translation (threshold 0). ripopt's 20 is measured on the upward-slope
gait steps with 20 nodes: both the DMOC and the Hermite–Simpson step then solve to IPOPT's optimum, in about 1 s and
2–3 s (71 and 344 auxiliary variables); from 50 up ripopt stops the DMOC step at another KKT point (f = 1.761
against 1.659) and gets slower as the trees it expands grow (Hermite–Simpson: 3 s at 50, 11 s at 1000)."""

_CASADI_SIGNED_DUALS = {"ripopt"}
"""Executables whose ``.sol`` multipliers follow CasADi's (and Ipopt's internal) sign, ∇f + Jᵀλ = 0. The others
follow AMPL's convention, a constraint's dual is ∂f*/∂(its bound) = -λ (AMPL's Ipopt negates its multipliers for
exactly this reason)."""

_ITERATION_PATTERNS = [
    re.compile(r"Number of Iterations\.*:\s*(\d+)"),  # IPOPT's (and ripopt's) final statistics
    re.compile(r"No\. of major iterations\s+(\d+)"),  # SNOPT's summary
    re.compile(r"(\d+)\s+(?:major\s+)?iterations\b", re.IGNORECASE),  # AMPL solve messages: "... after 8 iterations"
]

_UNKNOWN_OPTION = re.compile(r"unknown (?:option|keyword)\s*['\"]?([\w.]+)", re.IGNORECASE)

_INSTALL_HINT = ("Install one: `pip install pyomo-ripopt` (bundles ripopt; executable=ripopt), `idaes "
                 "get-extensions` (ipopt), or put an AMPL executable of snopt, ipopt, knitro or conopt on PATH, or "
                 "give an executable's full path as executable=/path/to/solver.")


def locate_executable(executable: str) -> str:
    """The path of an AMPL-NL solver executable, a name (looked up like Pyomo does) or a path.

    Raises ``ValueError`` saying where it was looked for and how to install one.
    """
    if os.sep in executable or (os.altsep and os.altsep in executable):
        path = Path(executable).expanduser()
        if path.is_file() and os.access(path, os.X_OK):
            return str(path)
        raise ValueError(f"pyomo: the AMPL-NL executable {executable!r} does not exist or is not executable "
                         f"(looked for: {path}). {_INSTALL_HINT}")
    searched = []
    if executable == "ripopt":
        try:
            import pyomo_ripopt  # noqa: F401  (registers SolverFactory("ripopt"): its binary, else PATH's)

            found = pyo.SolverFactory("ripopt").executable()
            searched.append("the ripopt binary bundled with pyomo-ripopt")
        except ImportError:
            found = None
            searched.append("the ripopt binary bundled with pyomo-ripopt (pyomo_ripopt is not installed)")
        if found:
            return str(found)
    found = Executable(executable).path()
    if found:
        return str(found)
    searched.append(f"{executable!r} on PATH and in Pyomo's executable directories")
    raise ValueError(f"pyomo: the AMPL-NL executable {executable!r} was not found (looked for: "
                     f"{'; '.join(searched)}). {_INSTALL_HINT}")


class PyomoSolver:
    """An AMPL-NL solver executable on the Pyomo translation of the NLP (exact; with lifted subexpressions for ripopt).

    ``executable`` (default ``"ripopt"``) is a name looked up on PATH (``ripopt`` first in the pyomo-ripopt wheel)
    or a path; the constructor raises ``ValueError`` when it is not found. ``max_iterations``, ``time_limit_s``,
    ``tolerance`` and ``print_level`` (0 silent; ≥ 1 passes the level to the executable and echoes its log) are
    the shared options, passed under the executable's own names for ripopt, ipopt, snopt, knitro/knitroampl and
    conopt (see ``_OPTION_NAMES``) and not passed to any other executable (give its own names instead). A time
    limit is also enforced from outside: an executable still running ``max(1 s, 1 %)`` past it is killed, and the
    result is TIME_LIMIT at the initial guess. ``lift_threshold`` (default: 20 for ripopt, 0 otherwise, see
    ``_DEFAULT_LIFT_THRESHOLDS``) is the tree size above which a shared subexpression becomes an auxiliary
    variable (see :func:`translate`); 0 keeps the exact NLP. Any other keyword is passed to the executable
    unchanged (booleans as yes/no), e.g. ``mu_strategy="monotone"`` for ripopt/ipopt or ``superbasics_limit=500``
    for snopt; an option the executable reports as unknown makes the result ERROR.

    ``iterations`` is parsed from the executable's log (IPOPT/ripopt statistics, SNOPT's major iterations, else
    the "N iterations" of its AMPL message; SNOPT without its summary reports minor iterations there), 0 when the
    log has none. ``function_time_s`` is 0 and ``evaluations`` empty: the NLP is evaluated inside the external
    process, which does not report it. ``multipliers`` are the ``.sol`` file's constraint duals in CasADi's sign
    convention (``lam_g``), 0 for a row free on both sides, ``None`` when the executable returns none.
    """

    name = "pyomo"

    def __init__(self, executable: str = "ripopt", max_iterations: int = 3000, time_limit_s: float | None = None,
                 tolerance: float = 1e-8, print_level: int = 0, lift_threshold: int | None = None,
                 **solver_options) -> None:
        self.executable = executable
        self.path = locate_executable(executable)
        self.kind = Path(executable).stem.lower().removesuffix("ampl")
        """The executable's family (``knitroampl`` → ``knitro``), which selects option names and conventions."""
        self.time_limit_s = time_limit_s
        self.print_level = print_level
        self.lift_threshold = _DEFAULT_LIFT_THRESHOLDS.get(self.kind, 0) if lift_threshold is None \
            else int(lift_threshold)
        shared = {"max_iterations": max_iterations, "time_limit_s": time_limit_s, "tolerance": tolerance,
                  "print_level": print_level}
        names = _OPTION_NAMES.get(self.kind, {})
        self.solver_options: dict = {names[key]: value for key, value in shared.items()
                                     if key in names and value is not None}
        """The options given to the executable, under its own names."""
        self.solver_options.update({key: ("yes" if value else "no") if isinstance(value, bool) else value
                                    for key, value in solver_options.items()})

    def solve(self, nlp: NLP, parameters: np.ndarray, initial_guess: np.ndarray) -> SolverResult:
        """Translate (once per NLP), write the ``.nl`` file, run the executable, read its ``.sol`` file."""
        deadline = Deadline(self.time_limit_s)
        x0 = np.asarray(initial_guess, dtype=float).ravel()
        try:
            evaluator = NLPEvaluator(nlp, parameters)
            if x0.size != nlp.n_variables:
                raise ValueError(f"the NLP has {nlp.n_variables} variables, the initial guess {x0.size} values")
            translation = self._translation(nlp)
            translation.set_point(x0, evaluator.p)
            return self._run(nlp, translation, x0, evaluator, deadline)
        except Exception as error:  # the Solver protocol reports failures, it never raises them
            return error_result(error, x0, deadline)

    def _translation(self, nlp: NLP) -> PyomoNLP:
        key = options_key(self.name, {"lift_threshold": self.lift_threshold})
        if key not in nlp.solver_cache:
            nlp.solver_cache[key] = translate(nlp, self.lift_threshold)
        return nlp.solver_cache[key]

    def _run(self, nlp: NLP, translation: PyomoNLP, x0: np.ndarray, evaluator: NLPEvaluator,
             deadline: Deadline) -> SolverResult:
        model = translation.model
        solver = pyo.SolverFactory("asl", solver=Path(self.path).name, executable=self.path)
        solver.options.update(self.solver_options)
        model.dual.clear()  # no multipliers of an earlier solve are taken for this one's
        pyomo_log = io.StringIO()
        with tempfile.TemporaryDirectory(prefix="gaitbench-pyomo-") as folder, LoggingIntercept(pyomo_log, "pyomo"):
            log_file = Path(folder) / "solver.log"
            try:
                results = solver.solve(model, tee=self.print_level > 0, load_solutions=False, logfile=str(log_file),
                                       timelimit=self.time_limit_s)
            except subprocess.TimeoutExpired:
                return solver_result(SolverStatus.TIME_LIMIT, f"pyomo/{self.executable}: killed at the time limit "
                                     f"({self.time_limit_s} s) without returning an iterate", x0, evaluator, 0,
                                     deadline)
            except Exception as error:  # Pyomo logged the executable's output: keep it in the message
                details = " ".join(pyomo_log.getvalue().split())
                raise RuntimeError(f"pyomo/{self.executable}: {error} {details}".strip()) from error
            log = log_file.read_text(errors="replace") if log_file.exists() else ""
            loaded = len(results.solution) > 0
            if loaded:
                model.solutions.load_from(results)
        condition = results.solver.termination_condition
        message = str(results.solver.message or "").replace("\\x3a", ":")
        status = self._status(condition, message, deadline)
        unknown = _UNKNOWN_OPTION.search(log)
        if unknown:
            status, message = SolverStatus.ERROR, f"{message}; unknown option {unknown.group(1)!r} (ignored)"
        x = x0
        if loaded:  # a variable the .nl file does not contain (in no expression) keeps its initial value
            x = np.array([x0[i] if model.x[i].value is None else model.x[i].value for i in range(x0.size)])
        return solver_result(status, f"pyomo/{self.executable}: {condition} {message}".strip(), x, evaluator,
                             _iterations(log), deadline, self._multipliers(model, nlp) if loaded else None)

    def _status(self, condition: TerminationCondition, message: str, deadline: Deadline) -> SolverStatus:
        if condition in (TerminationCondition.optimal, TerminationCondition.locallyOptimal,
                         TerminationCondition.globallyOptimal):
            return SolverStatus.CONVERGED
        if condition is TerminationCondition.infeasible:
            return SolverStatus.INFEASIBLE
        if condition in (TerminationCondition.maxIterations, TerminationCondition.maxEvaluations,
                         TerminationCondition.maxTimeLimit):
            # AMPL's solve_result_num has one range (400-499) for every limit: tell time from iterations.
            timed_out = condition is TerminationCondition.maxTimeLimit or "time" in message.lower()
            return SolverStatus.TIME_LIMIT if timed_out or deadline.expired() else SolverStatus.ITERATION_LIMIT
        return SolverStatus.ERROR

    def _multipliers(self, model: pyo.ConcreteModel, nlp: NLP) -> np.ndarray | None:
        duals = model.dual
        if nlp.n_constraints and not any(model.g[index] in duals for index in model.g):
            return None
        sign = 1.0 if self.kind in _CASADI_SIGNED_DUALS else -1.0
        multipliers = np.zeros(nlp.n_constraints)
        for index in model.g:
            multipliers[index] = sign * duals.get(model.g[index], 0.0)
        return multipliers


def _iterations(log: str) -> int:
    for pattern in _ITERATION_PATTERNS:
        found = pattern.findall(log)
        if found:
            return int(found[-1])
    return 0


@hookimpl
def register_solvers():
    return [Registration("pyomo", "any AMPL-NL executable (ripopt, ipopt, snopt, knitro, conopt) through Pyomo",
                         PyomoSolver)]
