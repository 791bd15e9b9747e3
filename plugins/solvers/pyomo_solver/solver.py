"""Running an AMPL-NL executable on the translated model: finding it, its option names, and reading back its status,
iterations and multipliers."""

from __future__ import annotations

import io
import os
import re
import subprocess
import tempfile
from pathlib import Path

import numpy as np
import pyomo.environ as pyo
from pyomo.common import Executable
from pyomo.common.log import LoggingIntercept
from pyomo.opt import TerminationCondition

from gaitbench.problem.nlp import NLP
from gaitbench.solve.evaluation import Deadline, NLPEvaluator, error_result, solver_result
from gaitbench.solve.solver import options_key
from gaitbench.solver_result import SolverResult, SolverStatus
from gaitbench_plugins.solvers.pyomo_solver.translation import PyomoNLP, translate

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
"""Executables that copy AMPL defined variables into every expression using them (see the package docstring);
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
