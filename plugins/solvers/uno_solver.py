"""Uno (SQP and interior-point methods from one set of ingredients) through unopy, with CasADi's exact derivatives.

Uno (https://github.com/cvanaret/Uno) calls Python for every function, gradient, sparse Jacobian and sparse
Lagrangian Hessian value; :class:`NLPEvaluator` takes them from CasADi, as for the ``cyipopt`` plugin. The unopy
model (sizes, bounds, sparsity structures) and the Uno solver with its options are built once per NLP and options
and kept in ``nlp.solver_cache``; a re-solve with new parameters only points the callbacks at a new evaluator and
sets the initial point.

Uno's own Lagrangian is σf − yᵀc (``unopy.MULTIPLIER_NEGATIVE``, its default), while CasADi's Hessian is that of
σf + λᵀg. The model is therefore declared ``unopy.MULTIPLIER_POSITIVE``: Uno then hands the Hessian callback λ in
CasADi's sign and reports its multipliers in CasADi's sign too (checked against IPOPT's on HS071 in
``tests/test_uno.py``). Left at Uno's default, the callback would get −λ, a Hessian with the constraints'
curvature reversed: HS071 then takes 59 iterations instead of 5, and with the ``ipopt`` preset every forward walk
(HS and DMOC, N = 20 and 50) stops at the iteration limit on step 2.
"""

from __future__ import annotations

import ctypes
import re
import sys
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import unopy

from gaitbench import Registration, hookimpl
from gaitbench.problem.nlp import NLP
from gaitbench.problem.scaling import SCALINGS, nominal_factors
from gaitbench.solve.evaluation import Deadline, NLPEvaluator, error_result, solver_result
from gaitbench.solve.silence import quiet_stderr
from gaitbench.solve.solver import options_key, set_typed_option
from gaitbench.solver_result import SolverResult, SolverStatus

PRESETS = ("ipopt", "filtersqp", "funnelsqp", "auto")
"""Uno's presets for NLPs with an exact Hessian (``filterslp`` drops the Hessian and is not offered)."""

CHOICES = {
    "QP_solver": ("BQPD", "HiGHS"),
    "LP_solver": ("BQPD", "HiGHS"),
    "linear_solver": ("MUMPS", "SSIDS"),
    "constraint_relaxation_strategy": ("feasibility_restoration",),
    "inequality_handling_method": ("inequality_constrained", "interior_point"),
    "hessian_model": ("exact", "LBFGS", "LSR1", "identity", "zero"),
    "inertia_correction_strategy": ("primal", "primal_dual", "none"),
    "globalization_mechanism": ("TR", "LS"),
    "globalization_strategy": ("merit_function", "fletcher_filter_method", "waechter_filter_method",
                               "funnel_method"),
}
"""The values of Uno's ingredient and subproblem-solver options that this wheel has (unopy 0.4.16, Uno 2.9.2:
BQPD and HiGHS for QPs and LPs, MUMPS and SSIDS as sparse indefinite solvers, no HSL). Uno crashes the process
(a segmentation fault, not an exception) on some other values, e.g. ``linear_solver="MA57"``, so they are checked
here when the solver is built."""

_LOGGERS = ("SILENT", "DISCRETE", "WARNING", "INFO", "DEBUG", "DEBUG2", "DEBUG3")
"""Uno's logger levels; ``print_level`` 0 and 1 log at INFO (kept, and printed at 1), k > 1 in more detail."""

_FAILURE_REASONS = (re.compile(r"An error occurred at the initial iterate: (.+)"),
                    re.compile(r"^\s*-\s.*\ds\s+(\S.*?)\s*$"))
"""Where Uno's log states why it failed: a line of its own at the initial point, or in a row of the iteration
table with no iterate (``-`` in every column but the time and the status) when an exception ended the solve."""


class _Log:
    """Uno's log, written through unopy's logger stream: printed at ``print_level`` 1 and more, and its end kept
    to name the reason of an algorithmic or evaluation error, which Uno's statuses alone do not."""

    def __init__(self, echo: bool) -> None:
        self.echo = echo
        self._tail: deque[str] = deque(maxlen=500)

    def write(self, text: str) -> None:
        self._tail.append(text)
        if self.echo:
            sys.stdout.write(text)

    def flush(self) -> None:
        if self.echo:
            sys.stdout.flush()

    def failure_reason(self) -> str | None:
        for line in reversed("".join(self._tail).splitlines()):
            for pattern in _FAILURE_REASONS:
                match = pattern.search(line)
                if match:
                    return match.group(1)
        return None


def gaitbench_status(optimization: unopy.OptimizationStatus, solution: unopy.SolutionStatus) -> SolverStatus:
    """gaitbench's status for Uno's pair (why it stopped, what the last iterate is).

    Only a feasible KKT point is converged. A Fritz John point (feasible, but no constraint qualification, so no
    KKT multipliers) and a small step at a feasible point are not optima gaitbench can report as converged, so
    they are errors, as are unboundedness, divergence, a small step at an infeasible point and Uno's algorithmic
    and evaluation errors. An infeasible stationary point (a stationary point of the constraint violation) is
    Uno's detection of local infeasibility.
    """
    if optimization == unopy.OptimizationStatus.ITERATION_LIMIT:
        return SolverStatus.ITERATION_LIMIT
    if optimization == unopy.OptimizationStatus.TIME_LIMIT:
        return SolverStatus.TIME_LIMIT
    if optimization != unopy.OptimizationStatus.SUCCESS:
        return SolverStatus.ERROR
    if solution == unopy.SolutionStatus.FEASIBLE_KKT_POINT:
        return SolverStatus.CONVERGED
    if solution == unopy.SolutionStatus.INFEASIBLE_STATIONARY_POINT:
        return SolverStatus.INFEASIBLE
    return SolverStatus.ERROR


class _Callbacks:
    """What Uno calls: the current solve's evaluator, writing into the arrays Uno passes, and the first failure.

    An exception in a callback is kept here and raised on to Uno, which treats it as an evaluation error (a
    shorter step, or a failed solve at the initial point); the termination callback then stops the solve at the
    end of the iteration, and the plugin reports the exception. The termination callback also checks the
    solve's deadline, which Uno's ``time_limit`` does as well, by its own clock: whichever stops the solve, once per
    iteration, the status is ``time_limit``.
    """

    def __init__(self, evaluator: NLPEvaluator) -> None:
        self.evaluator = evaluator
        self.error: Exception | None = None
        self.deadline = Deadline(None)
        self.timed_out = False
        self._jacobian_rows, self._jacobian_cols = evaluator.jacobian_pattern()
        self._hessian_rows, self._hessian_cols = evaluator.hessian_pattern()
        self.start(evaluator, self.deadline, np.ones(evaluator.n), np.ones(evaluator.m))

    def start(self, evaluator: NLPEvaluator, deadline: Deadline, d: np.ndarray, c: np.ndarray) -> None:
        """Point the callbacks at a new solve: its evaluator, deadline, and scale factors x = d x̃, g̃ = g / c."""
        self.evaluator = evaluator
        self.error = None
        self.deadline = deadline
        self.timed_out = False
        self.d, self.c = d, c
        self._jacobian_factors = d[self._jacobian_cols] / c[self._jacobian_rows]
        self._hessian_factors = d[self._hessian_rows] * d[self._hessian_cols]

    def _evaluate(self, evaluate: Callable, *args):
        try:
            return evaluate(*args)
        except Exception as error:
            self.error = self.error or error
            raise

    def objective(self, x: np.ndarray) -> float:
        return self._evaluate(self.evaluator.objective, self.d * x)

    def gradient(self, x: np.ndarray, out: np.ndarray) -> None:
        out[:] = self.d * self._evaluate(self.evaluator.gradient, self.d * x)

    def constraints(self, x: np.ndarray, out: np.ndarray) -> None:
        out[:] = self._evaluate(self.evaluator.constraints, self.d * x) / self.c

    def jacobian(self, x: np.ndarray, out: np.ndarray) -> None:
        out[:] = self._jacobian_factors * self._evaluate(self.evaluator.jacobian_values, self.d * x)

    def hessian(self, x: np.ndarray, objective_factor: float, multipliers: np.ndarray, out: np.ndarray) -> None:
        out[:] = self._hessian_factors * self._evaluate(self.evaluator.hessian_values, self.d * x, objective_factor,
                                                        multipliers / self.c)

    def terminate(self, *_iterate) -> bool:
        self.timed_out = self.deadline.expired()
        return self.error is not None or self.timed_out


@dataclass
class _Built:
    model: unopy.Model
    solver: unopy.UnoSolver
    callbacks: _Callbacks


class Uno:
    """Uno with the exact Hessian of the Lagrangian, evaluated from Python.

    ``preset`` is one of Uno's method presets: ``ipopt`` (line-search filter interior point with primal-dual
    inertia correction, MUMPS; the default), ``filtersqp`` (trust-region filter SQP, BQPD as QP solver),
    ``funnelsqp`` (the same with a funnel instead of a filter) or ``auto`` (Uno's choice by problem size: ``ipopt``
    from n + m = 2000 on). The default is chosen by measurement on forward walks
    (docs/decisions/0004-uno-default-preset.md): only ``ipopt`` completes them; the SQP presets stall or stop with
    algorithmic errors from step 2 on. ``max_iterations`` (Uno's ``max_iterations``), ``time_limit_s`` (``time_limit``,
    wall clock, checked once per iteration; ``None`` for no limit), ``tolerance`` (both ``primal_tolerance`` and
    ``dual_tolerance``: Uno stops when constraint violation, stationarity and complementarity are all below it) and
    ``print_level`` (0: Uno's logger ``SILENT``; 1: ``INFO``, the iteration log; 2 and more: ``DEBUG`` and beyond) are
    the options every gaitbench solver shares. ``scaling="nominal"`` solves the NLP scaled by
    :func:`gaitbench.problem.scaling.nominal_factors`
    (as the ``ipopt`` plugin's option does; the tolerances then hold in scaled units). Any other keyword is a Uno
    option set after the preset (https://unosolver.readthedocs.io, "Options"), for example
    ``linear_solver="SSIDS"``, ``globalization_mechanism="LS"`` or ``TR_radius=1``; an integer given for a real
    option is converted. An option Uno does not know, of the wrong type, or a subproblem solver or ingredient this
    build lacks (:data:`CHOICES`) is a ``ValueError`` when the solver is built; a value Uno rejects only while
    solving makes the solve return ERROR.

    ``multipliers`` are the constraint multipliers in CasADi's sign, ∇f + Jᵀλ_g + λ_x = 0 (see the module
    docstring), so they compare with the ``ipopt`` plugin's.
    """

    name = "uno"

    def __init__(self, max_iterations: int = 3000, time_limit_s: float | None = None, tolerance: float = 1e-8,
                 print_level: int = 0, preset: str = "ipopt", scaling: str = "none", **uno_options) -> None:
        if preset not in PRESETS:
            raise ValueError(f"preset = {preset!r}: expected one of {', '.join(PRESETS)}")
        if scaling not in SCALINGS:
            raise ValueError(f"scaling = {scaling!r}: expected one of {', '.join(SCALINGS)}")
        self.scaling = scaling
        options: dict = {"max_iterations": int(max_iterations), "primal_tolerance": float(tolerance),
                         "dual_tolerance": float(tolerance),
                         "logger": _LOGGERS[min(max(int(print_level), 1) + 2, len(_LOGGERS) - 1)]}
        if time_limit_s is not None:
            options["time_limit"] = float(time_limit_s)
        for option, value in uno_options.items():
            if option in CHOICES and value not in CHOICES[option]:
                raise ValueError(f"{option} = {value!r}: this Uno build offers {', '.join(CHOICES[option])}")
        options.update(uno_options)
        self.preset = preset
        self.time_limit_s = time_limit_s
        self.print_level = print_level
        self.options = options
        """The Uno options every solve is built with, set after the preset."""
        _configured_solver(preset, options)  # rejects unknown options and wrong types now

    def solve(self, nlp: NLP, parameters: np.ndarray, initial_guess: np.ndarray) -> SolverResult:
        """Solve from ``initial_guess``; exceptions (in unopy or in a callback) become an ERROR status."""
        x0 = np.asarray(initial_guess, dtype=float).ravel()
        deadline = Deadline(self.time_limit_s)
        try:
            if x0.size != nlp.n_variables:
                raise ValueError(f"the initial guess has {x0.size} values, the NLP {nlp.n_variables} variables")
            evaluator = NLPEvaluator(nlp, parameters)
            built = self._built(nlp, evaluator)
            deadline = Deadline(self.time_limit_s)  # timing the solve, not the first build, as the other plugins do
            if self.scaling == "nominal":
                factors = nominal_factors(nlp, x0, evaluator.p)
                d, c = factors.variables, factors.constraints
            else:
                d, c = np.ones(nlp.n_variables), np.ones(nlp.n_constraints)
            built.callbacks.start(evaluator, deadline, d, c)
            model = built.model
            model.set_variables_lower_bounds((nlp.lbx / d).tolist())
            model.set_variables_upper_bounds((nlp.ubx / d).tolist())
            if nlp.n_constraints > 0:
                model.set_constraints_lower_bounds((nlp.lbg / c).tolist())
                model.set_constraints_upper_bounds((nlp.ubg / c).tolist())
            model.set_initial_primal_iterate((x0 / d).tolist())
            log = _Log(echo=self.print_level > 0)
            built.solver.set_logger_stream(log)  # Uno's logger is global: set for every solve
            with quiet_stderr(self.print_level == 0):  # BQPD writes workspace warnings to standard error itself
                try:
                    result = built.solver.optimize(model)
                finally:
                    _flush_fortran_units()
            if built.callbacks.error is not None:
                raise built.callbacks.error
        except Exception as error:
            failure = error_result(error, x0, deadline)
            return replace(failure, message=f"Uno: {failure.message}")
        optimization, solution = result.optimization_status, result.solution_status
        status = gaitbench_status(optimization, solution)
        if optimization == unopy.OptimizationStatus.USER_TERMINATION and built.callbacks.timed_out:
            status = SolverStatus.TIME_LIMIT
        message = f"Uno: {optimization.name}, {solution.name}"
        if optimization in (unopy.OptimizationStatus.ALGORITHMIC_ERROR, unopy.OptimizationStatus.EVALUATION_ERROR):
            reason = log.failure_reason()
            message += f" ({reason})" if reason else ""
        return solver_result(status, message, d * np.asarray(result.primal_solution, dtype=float), evaluator,
                             int(result.number_iterations), deadline,
                             multipliers=np.asarray(result.constraint_dual_solution, dtype=float) / c)

    def prepare(self, nlp: NLP) -> None:
        """Build the unopy model and solver for ``nlp`` now (see :class:`gaitbench.contracts.Solver`, its optional
        ``prepare``)."""
        self._built(nlp, NLPEvaluator(nlp, np.zeros(nlp.p.numel())))

    def _built(self, nlp: NLP, evaluator: NLPEvaluator) -> _Built:
        key = options_key(self.name, self.options | {"preset": self.preset})
        if key not in nlp.solver_cache:
            callbacks = _Callbacks(evaluator)
            model = unopy.Model(unopy.PROBLEM_NONLINEAR, nlp.n_variables, nlp.lbx.tolist(), nlp.ubx.tolist(),
                                unopy.ZERO_BASED_INDEXING)
            model.set_objective(unopy.MINIMIZE, callbacks.objective, callbacks.gradient)
            if nlp.n_constraints > 0:
                rows, cols = evaluator.jacobian_pattern()
                model.set_constraints(nlp.n_constraints, callbacks.constraints, nlp.lbg.tolist(), nlp.ubg.tolist(),
                                      len(rows), rows.tolist(), cols.tolist(), callbacks.jacobian)
            rows, cols = evaluator.hessian_pattern()
            model.set_lagrangian_hessian(len(rows), unopy.LOWER_TRIANGLE, rows.tolist(), cols.tolist(),
                                         callbacks.hessian)
            model.set_lagrangian_sign_convention(unopy.MULTIPLIER_POSITIVE)
            solver = _configured_solver(self.preset, self.options)
            solver.set_termination_callback(callbacks.terminate)
            nlp.solver_cache[key] = _Built(model, solver, callbacks)
        return nlp.solver_cache[key]


def _fortran_flush() -> Callable[[], None]:
    """A function that flushes every unit of the libgfortran bundled in unopy's wheel (a no-op where it is not
    found). That library buffers BQPD's messages when they do not go to a terminal, and would otherwise write them
    when the process exits, after :func:`gaitbench.solve.silence.quiet_stderr` has restored standard error."""
    try:
        libraries = Path(unopy.__file__).resolve().parent.parent / "unopy.libs"
        flush = ctypes.CDLL(str(next(libraries.glob("libgfortran*.so*"))))._gfortran_flush_i4
    except (StopIteration, OSError, AttributeError):
        return lambda: None
    flush.argtypes = [ctypes.c_void_p]
    return lambda: flush(None)  # FLUSH with no unit: all units


_flush_fortran_units = _fortran_flush()


def _configured_solver(preset: str, options: dict) -> unopy.UnoSolver:
    """A fresh Uno solver with ``preset`` and then ``options``.

    Fresh, because a preset only sets the options it names: one set after another leaves the first one's other
    options behind. The ``preset`` option is set as well, so that Uno's solve, which applies that option's preset
    before the solver's options, starts from the same one.
    """
    solver = unopy.UnoSolver()
    if preset != "auto":
        solver.set_preset(preset)
    solver.set_option("preset", preset)
    for option, value in options.items():
        _set_option(solver, option, value)
    return solver


def _set_option(solver: unopy.UnoSolver, option: str, value) -> None:
    """Set one Uno option (an int for a real option is set again as a float); unopy raises KeyError for a name
    Uno does not know."""
    try:
        set_typed_option(solver.set_option, option, value, "Uno")
    except KeyError:
        raise ValueError(f"Uno has no option {option}") from None


@hookimpl
def register_solvers():
    return [Registration("uno", "Uno (SQP / interior point; ipopt preset by default) through unopy, exact Hessian "
                         "evaluated from Python", Uno)]
