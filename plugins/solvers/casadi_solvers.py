"""CasADi's own NLP methods as solver plugins, so the benchmark can set them against IPOPT on the same NLPs.

Each is ``casadi.nlpsol`` with one of CasADi's plugins, built once per NLP and options and kept in
``nlp.solver_cache`` like the ``ipopt`` plugin. One is left:

- ``fatrop``: FATROP, an interior-point method for optimal control (IPOPT's algorithm on a stage-wise Riccati
  factorization), on the NLP rewritten in stage-wise form where it has one (the default, ``stagewise="auto"``)
  or as one dense stage (see :class:`Fatrop`).

Dense FATROP solves forward step 1 of the gait problems at N = 20, 20–150× slower than IPOPT, and fails the
harder steps without the torque tie-break. Stage-wise FATROP solves 8 of the solver benchmark's 18 gait steps
(N = 25 and 50; none at N = 100), at 3–23× IPOPT's time (docs/decisions/0005-casadi-solvers.md).
CasADi's ``sqpmethod``, ``feasiblesqpmethod`` and ``blocksqp`` were plugins here too and were removed (issue 22):
the first two reach no solution on forward step 1 with any option CasADi 3.8 offers, and blockSQP, without the
HSL solver its QP and restoration phase need, converges on 2 of the 18 steps and ignores its time limit
(docs/decisions/0005-casadi-solvers.md).

At ``print_level`` 0 standard output and error are discarded during build and solve (at the file-descriptor
level, so for the whole process while it lasts): CasADi's FATROP interface writes a warning per row its structure
detection refuses whatever the print options say, and the solve's message says why it failed anyway.
"""

from __future__ import annotations

import contextlib
import re
from abc import ABC, abstractmethod
from collections.abc import Iterator, Mapping
from typing import Any

import casadi as ca
import numpy as np

from gaitbench import Registration, hookimpl
from gaitbench.options import OptionError, unknown_option
from gaitbench.problem.nlp import NLP
from gaitbench.problem.stagewise import StagewiseForm, stagewise
from gaitbench.solve.evaluation import Deadline
from gaitbench.solve.silence import quiet_stderr, quiet_stdout
from gaitbench.solve.solver import options_key
from gaitbench.solver_result import SolverResult, SolverStatus


class CasadiMethod(ABC):
    """One ``casadi.nlpsol`` method; subclasses name it and map the shared options and its statuses.

    ``max_iterations``, ``time_limit_s`` (``None``: no limit), ``tolerance`` and ``print_level`` are the options
    every gaitbench solver shares; each subclass says which of the method's own options they become. Other
    keywords are the method's own options, passed unchanged. FATROP calls no ``iteration_callback`` and has no
    time option, so it cannot be stopped during a solve: a solve that ends after
    the time limit is reported as TIME_LIMIT with its point. A claimed convergence at a point where the
    NLP is not finite is an ERROR (FATROP reports success from a start where the objective is NaN).
    ``multipliers`` are CasADi's ``lam_g``.
    """

    name: str
    plugin: str
    """The ``casadi.nlpsol`` plugin."""
    statuses: dict[str, SolverStatus] = {}
    """The method's return statuses with a shared meaning; every other one is an error."""
    explanations: dict[str, str] = {}
    """What a terse return status means, appended to the message."""

    @classmethod
    def check_options(cls, options: Mapping[str, Any]) -> None:
        """The method's own options, by CasADi's list of them: a one-variable ``nlpsol`` is built with the options
        this solver would pass and solved once (FATROP checks its own options only then), and an unknown option or
        a value of the wrong type is refused (docs/plugins.md). Values within a type (a string option's choices)
        are the method's to check when it runs."""
        try:
            solver = cls(**options)
        except (TypeError, ValueError):
            return  # refused again, with its own message, when the suite builds it
        x = ca.SX.sym("x")
        try:
            with _quiet():
                ca.nlpsol("option_check", cls.plugin, {"x": x, "f": x**2}, solver.options)(x0=1.0)
        except RuntimeError as error:
            message = str(error)
            own = _signature_options(cls)
            refused = re.search(r"option not supported: (\w+)", message)
            if refused and refused.group(1) in options:
                raise unknown_option(refused.group(1), own, more=f", or any {cls.plugin} option") from None
            unknown = re.search(r"Unknown option: (\w+)", message)
            if unknown and unknown.group(1) in options:
                raise unknown_option(unknown.group(1), own, candidates=[*own, *ca.nlpsol_options(cls.plugin)],
                                     cutoff=0.75, more=f", or any {cls.plugin} option (casadi.doc_nlpsol("
                                                       f"'{cls.plugin}'))") from None
            illegal = re.search(r"Illegal type for (\w+): (\w+) cannot be cast to (\w+)", message)
            if illegal and illegal.group(1) in options:
                name, found, expected = illegal.groups()
                raise OptionError(name, f"{cls.plugin} takes {_CASADI_TYPES.get(expected, expected)}, found "
                                        f"{_CASADI_TYPES.get(found, found)}") from None

    def __init__(self, max_iterations: int = 3000, time_limit_s: float | None = None, tolerance: float = 1e-8,
                 print_level: int = 0, **method_options) -> None:
        self.time_limit_s = None if time_limit_s is None else float(time_limit_s)
        self.print_level = int(print_level)
        self.options: dict = {"error_on_fail": False, "record_time": True, "print_time": self.print_level > 0,
                              **self._method_options(int(max_iterations), float(tolerance), self.print_level,
                                                     method_options)}
        """The ``casadi.nlpsol`` options."""

    @abstractmethod
    def _method_options(self, max_iterations: int, tolerance: float, print_level: int, extra: dict) -> dict:
        """The method's own options for the shared ones, with ``extra`` (the other keywords) merged in."""

    def _return_status(self, stats: dict) -> str:
        return stats["return_status"]

    def _iterations(self, stats: dict) -> int:
        return int(stats["iter_count"])

    def solve(self, nlp: NLP, parameters: np.ndarray, initial_guess: np.ndarray) -> SolverResult:
        """Solve from ``initial_guess``; every failure, including exceptions inside CasADi, becomes a status."""
        p = np.asarray(parameters, dtype=float).ravel()
        x0 = np.asarray(initial_guess, dtype=float).ravel()
        deadline = Deadline(self.time_limit_s)
        try:
            solver = self._built(nlp)
            deadline = Deadline(self.time_limit_s)  # the limit covers the solve, as IPOPT's max_wall_time does
            with _quiet(self.print_level == 0):
                solution = solver(**self._arguments(nlp, p, x0))
            x, multipliers = self._solution(nlp, solution)
        except Exception as error:  # the Solver protocol reports failures, it never raises them
            return self._result(SolverStatus.ERROR, _casadi_message(error), nlp, p, x0, deadline)
        try:
            stats = solver.stats()
        except RuntimeError:  # CasADi leaves the return status unset when a method aborts mid-iteration
            return self._result(SolverStatus.ERROR, "stopped without a return status", nlp, p, x, deadline,
                                multipliers=multipliers)
        return_status = self._return_status(stats)
        status = self.statuses.get(return_status, SolverStatus.ERROR)
        message = return_status + self.explanations.get(return_status, "")
        if deadline.expired():
            status = SolverStatus.TIME_LIMIT
            message += (f" after {deadline.elapsed_s:.3g} s, past the time limit of {self.time_limit_s:g} s "
                        f"({self.plugin} cannot be stopped during a solve)")
        return self._result(status, message, nlp, p, x, deadline, stats, multipliers)

    def _arguments(self, nlp: NLP, p: np.ndarray, x0: np.ndarray) -> dict[str, np.ndarray]:
        """The built ``nlpsol``'s inputs for a solve of ``nlp`` from ``x0``."""
        return {"x0": x0, "p": p, "lbx": nlp.lbx, "ubx": nlp.ubx, "lbg": nlp.lbg, "ubg": nlp.ubg}

    def _solution(self, nlp: NLP, solution: dict) -> tuple[np.ndarray, np.ndarray]:
        """``nlp``'s x and constraint multipliers from the built ``nlpsol``'s outputs."""
        return (np.asarray(solution["x"], dtype=float).ravel(), np.asarray(solution["lam_g"], dtype=float).ravel())

    def _key(self) -> tuple:
        return options_key(self.name, self.options)

    def _built(self, nlp: NLP) -> ca.Function:
        key = self._key()
        if key not in nlp.solver_cache:
            with _quiet(self.print_level == 0):
                nlp.solver_cache[key] = self._nlpsol(nlp, self.options)
        return nlp.solver_cache[key]

    def _nlpsol(self, nlp: NLP, options: dict) -> ca.Function:
        return ca.nlpsol(self.name.replace("-", "_"), self.plugin, nlp.casadi_problem(), options)

    def _result(self, status: SolverStatus, message: str, nlp: NLP, p: np.ndarray, x: np.ndarray,
                deadline: Deadline, stats: dict | None = None, multipliers: np.ndarray | None = None) -> SolverResult:
        try:
            objective, violation = float(nlp.functions.objective(x, p)), nlp.violation(x, p)
        except Exception:  # a result must still be returned when x is unusable (e.g. the wrong size)
            objective = violation = float("nan")
        if status is SolverStatus.CONVERGED and not np.isfinite([objective, violation]).all():
            status, message = SolverStatus.ERROR, f"{message}, at a point where the NLP is not finite"
        stats = stats or {}
        return SolverResult(
            status=status, message=f"{self.name}: {message}", x=x, objective=objective,
            constraint_violation=violation, iterations=self._iterations(stats) if stats else 0,
            wall_time_s=deadline.elapsed_s,
            function_time_s=float(sum(value for key, value in stats.items() if key.startswith("t_wall_nlp_"))),
            evaluations={key.removeprefix("n_call_nlp_"): int(value) for key, value in stats.items()
                         if key.startswith("n_call_nlp_") and value > 0},
            multipliers=multipliers)


_CASADI_TYPES = {"OT_INT": "an integer", "OT_DOUBLE": "a number", "OT_BOOL": "true or false",
                 "OT_STRING": "a string", "OT_DICT": "a table", "OT_INTVECTOR": "an array of integers",
                 "OT_DOUBLEVECTOR": "an array of numbers", "OT_STRINGVECTOR": "an array of strings"}
"""CasADi's option types, as suite errors name them."""


def _signature_options(cls: type) -> list[str]:
    """The keyword options a solver class names in its signature (``**method_options`` aside)."""
    import inspect

    return [name for name, parameter in inspect.signature(cls).parameters.items()
            if parameter.kind is parameter.POSITIONAL_OR_KEYWORD or parameter.kind is parameter.KEYWORD_ONLY]


_LOCATION = re.compile(r"^\S+\.(?:cpp|hpp):\d+:\s*")


@contextlib.contextmanager
def _quiet(active: bool = True) -> Iterator[None]:
    """Standard output and error discarded while ``active`` (see the module docstring)."""
    with quiet_stdout(active), quiet_stderr(active):
        yield


def _casadi_message(error: BaseException) -> str:
    """A CasADi exception without its call trace: the lines that say what failed, without source locations."""
    lines = [_LOCATION.sub("", line.strip()) for line in str(error).splitlines()]
    kept = " ".join(line for line in lines if line and not line.startswith("Error in Function::")) or str(error)
    return f"{type(error).__name__}: {kept}"


_FATROP_FLAGS = ("Success", "MaxIterExceeded", "StopAtAcceptablePoint", "LocalInfeasibility", "LineSearchFailed",
                 "ErrorInStepComputation", "Unknown")
"""FATROP's IpSolverReturnFlag, by the number CasADi reports as ``stats["fatrop"]["return_flag"]``."""


class Fatrop(CasadiMethod):
    """FATROP: IPOPT's interior-point algorithm with a Riccati-based factorization for optimal control problems.

    FATROP exploits the stage structure of an OCP: variables ordered stage-wise [x₀, u₀, x₁, u₁, …], each
    stage's dynamics an explicit x_{k+1} = f(x_k, u_k) (identity in x_{k+1}), every other constraint depending on
    one stage only. The gait NLPs are none of these as built: their variables come in blocks (all positions, then
    all torques, ...), DMOC's dynamics are implicit in q_{k+1} and Hermite–Simpson's in the next state, and the
    push-off impulse and slacks enter the last node's rows. Three choices:

    - ``stagewise=True``: the NLP is rewritten in stage-wise form (:mod:`gaitbench.problem.stagewise`: each stage's
      own variables as controls, copies of earlier ones and of the global variables as states, gap-closing rows
      that carry the copies) and FATROP is given its structure (``N``, ``nx``, ``nu``, ``ng``); the solution is
      mapped back, so the result is the NLP's own. ``structure_detection="auto"`` instead leaves the structure to
      CasADi's detection, which misreads this form: kept for comparison, not for use.
    - ``stagewise=False``: with ``structure_detection="none"`` (default) the NLP is one stage with all
      variables as controls, which FATROP solves with a dense factorization (correct, without its speed-up).
      ``structure_detection="auto"`` (CasADi's detection, given which constraints are equalities) is for NLPs
      built stage-wise; on one that is not, every solve returns ERROR saying so.
    - ``stagewise="auto"`` (default): the stage-wise form where the NLP has one (the gait steps: variable blocks
      over a grid, rows and objective that join nearby stages only), the dense stage otherwise (textbook NLPs) or
      where a structure is given (``structure_detection``, ``N``, ...). Measured on the solver benchmark's 18 gait
      steps: stage-wise 8 converged, dense 2 (docs/decisions/0005-casadi-solvers.md).

    ``max_iterations`` is FATROP's ``max_iter`` less one (FATROP
    takes one iteration past its ``max_iter``), ``tolerance`` is ``tol``; ``print_level`` is FATROP's own but at
    least 5 when not 0, the first level at which FATROP prints its iterations. FATROP stops at an acceptable point
    (its ``acceptable_tol``/``acceptable_iter``, like IPOPT's) when it cannot reach ``tol``, which it often cannot
    on the gait steps (it has no NLP scaling): that is CONVERGED, as IPOPT's Solved_To_Acceptable_Level is.
    It cannot be stopped during a solve (no iteration callback and no time option). Other keywords are FATROP
    options (e.g. ``mu_init``, ``bound_push``, ``acceptable_iter``), except the interface's own: ``N``, ``nx``,
    ``nu``, ``ng`` (with ``structure_detection="manual"``), ``convexify_strategy``, ``convexify_margin``, ``debug``.
    """

    name = "fatrop"
    plugin = "fatrop"
    statuses = {"Success": SolverStatus.CONVERGED, "StopAtAcceptablePoint": SolverStatus.CONVERGED,
                "MaxIterExceeded": SolverStatus.ITERATION_LIMIT, "LocalInfeasibility": SolverStatus.INFEASIBLE}
    _INTERFACE_OPTIONS = ("N", "nx", "nu", "ng", "convexify_strategy", "convexify_margin", "debug")
    """Options of CasADi's FATROP interface (a manual structure, convexification); the rest are FATROP's."""
    _FORM = ("fatrop", "stage-wise form")
    """The key of an NLP's stage-wise form in its ``solver_cache``: built once, for every solver built on it."""

    def __init__(self, max_iterations: int = 3000, time_limit_s: float | None = None, tolerance: float = 1e-8,
                 print_level: int = 0, structure_detection: str = "none", stagewise: bool | str = "auto",
                 **fatrop_options) -> None:
        if not (isinstance(stagewise, bool) or stagewise == "auto"):
            raise TypeError(f"stagewise = {stagewise!r}: expected true, false or 'auto'")
        manual = bool(set(fatrop_options) & {"N", "nx", "nu", "ng"})
        if stagewise is True and (structure_detection not in ("none", "auto") or manual):
            raise ValueError("stagewise = true gives FATROP the structure itself: leave out N, nx, nu, ng and "
                             "structure_detection (or set it to 'auto')")
        self.structure_detection = structure_detection
        structure_given = structure_detection != "none" or manual
        self.stagewise: bool | str = False if stagewise == "auto" and structure_given else stagewise
        """True, False, or "auto": the stage-wise form where the NLP has one (a structure given by hand: dense)."""
        super().__init__(max_iterations, time_limit_s, tolerance, print_level, **fatrop_options)

    def _method_options(self, max_iterations: int, tolerance: float, print_level: int, extra: dict) -> dict:
        interface = {key: value for key, value in extra.items() if key in self._INTERFACE_OPTIONS}
        fatrop = {key: value for key, value in extra.items() if key not in self._INTERFACE_OPTIONS}
        fatrop = {"max_iter": max(max_iterations - 1, 0), "tol": tolerance,
                  "print_level": max(print_level, 5) if print_level > 0 else 0, **fatrop}
        return {"structure_detection": self.structure_detection, "fatrop": fatrop, **interface}

    def _key(self) -> tuple:
        return options_key(self.name, {**self.options, "stagewise": self.stagewise})

    def _form(self, nlp: NLP) -> StagewiseForm | None:
        """``nlp``'s stage-wise form, or None where it is solved as one dense stage."""
        if self.stagewise is False:
            return None
        if self._FORM not in nlp.solver_cache:
            try:
                nlp.solver_cache[self._FORM] = stagewise(nlp)
            except ValueError:
                if self.stagewise is True:
                    raise
                nlp.solver_cache[self._FORM] = None  # not an OCP on a grid (a textbook NLP): dense
        return nlp.solver_cache[self._FORM]

    def _nlpsol(self, nlp: NLP, options: dict) -> ca.Function:
        form = self._form(nlp)
        if form is not None:
            structure = form.structure() if self.structure_detection == "none" else {"equality": form.equality()}
            return ca.nlpsol(self.name, self.plugin, form.nlp.casadi_problem(), {**options, **structure})
        if self.structure_detection != "auto":
            return super()._nlpsol(nlp, options)
        try:  # CasADi's detection needs to know which constraints are equalities
            return super()._nlpsol(nlp, {**options, "equality": [bool(equal) for equal in nlp.lbg == nlp.ubg]})
        except RuntimeError as error:
            raise RuntimeError("structure detection failed: the NLP is not an OCP in stage-wise order (variables "
                               "[x_k, u_k] per stage, dynamics x_k+1 = f(x_k, u_k)); use stagewise=true. "
                               f"CasADi: {_casadi_message(error)}") from error

    def _arguments(self, nlp: NLP, p: np.ndarray, x0: np.ndarray) -> dict[str, np.ndarray]:
        form = self._form(nlp)
        if form is None:
            return super()._arguments(nlp, p, x0)
        return super()._arguments(form.nlp, p, form.lift(x0))

    def _solution(self, nlp: NLP, solution: dict) -> tuple[np.ndarray, np.ndarray]:
        x, multipliers = super()._solution(nlp, solution)
        form = self._form(nlp)
        if form is None:
            return x, multipliers
        return form.restrict(x), form.constraint_multipliers(multipliers)

    def _return_status(self, stats: dict) -> str:
        return _FATROP_FLAGS[int(stats["fatrop"]["return_flag"])]


@hookimpl
def register_solvers():
    return [
        Registration("fatrop", "FATROP through CasADi: interior point for OCPs, on the NLP in stage-wise form "
                               "where it has one (else one dense stage)", Fatrop),
    ]
