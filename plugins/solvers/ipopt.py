"""IPOPT (interior point, filter line search) through CasADi's ``nlpsol``, with CasADi's exact sparse Hessian.

The built ``nlpsol`` is kept in ``nlp.solver_cache`` under its options, so the steps of a walk — one NLP structure
re-solved with new parameters — pay for building (and differentiating) the problem only once.
"""

from __future__ import annotations

import functools
import html
import os
import re
import tempfile
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

import casadi as ca
import numpy as np

from gaitbench import Registration, hookimpl
from gaitbench.options import OptionError, describe, unknown_option
from gaitbench.problem.nlp import NLP
from gaitbench.problem.scaling import ScaledProblem, nominal_factors
from gaitbench.solve.silence import quiet_stdout
from gaitbench.solve.solver import SolverResult, SolverStatus, options_key

IPOPT_STATUSES = {
    "Solve_Succeeded": SolverStatus.CONVERGED,
    "Solved_To_Acceptable_Level": SolverStatus.CONVERGED,
    "Infeasible_Problem_Detected": SolverStatus.INFEASIBLE,
    "Maximum_Iterations_Exceeded": SolverStatus.ITERATION_LIMIT,
    "Maximum_CpuTime_Exceeded": SolverStatus.TIME_LIMIT,
    "Maximum_WallTime_Exceeded": SolverStatus.TIME_LIMIT,
}
"""IPOPT return statuses with a shared meaning; every other one (Restoration_Failed, Invalid_Number_Detected,
Diverging_Iterates, ...) is an error."""

_FUNCTIONS = ("f", "g", "grad_f", "jac_g", "hess_l")
"""The NLP callbacks IPOPT evaluates, named as in :class:`gaitbench.problem.nlp.NLPFunctions`."""

SCALINGS = ("none", "nominal")
"""``none``: IPOPT's own scaling only. ``nominal``: variables and constraint rows scaled first
(:mod:`gaitbench.problem.scaling`), from each solve's initial guess."""


IPOPT_OPTIONS_URL = "https://coin-or.github.io/Ipopt/OPTIONS.html"


@dataclass(frozen=True)
class IpoptOption:
    """One option IPOPT registers: its type (``real``, ``integer`` or ``string``) and what it accepts, in IPOPT's
    words (``0 < tol``; ``'monotone' or 'adaptive'``)."""

    name: str
    type: str
    accepts: str


@functools.cache
def ipopt_options() -> dict[str, IpoptOption]:
    """Every option of the IPOPT that CasADi loads, from IPOPT's own documentation of it.

    IPOPT prints that documentation (``print_options_documentation``, advanced options included) when it solves;
    a one-variable problem is solved once per process to get it. Empty if it cannot be read (an IPOPT older than
    3.14, without ``print_options_mode``), and then options are checked by :func:`casadi_ipopt_accepts` alone.
    """
    x = ca.SX.sym("x")
    handle, path = tempfile.mkstemp(prefix="gaitbench-ipopt-options-", suffix=".txt")
    os.close(handle)
    try:
        with quiet_stdout():
            solver = ca.nlpsol("ipopt_options", "ipopt", {"x": x, "f": x**2}, {
                "print_time": False, "ipopt": {
                    "print_options_documentation": "yes", "print_advanced_options": "yes",
                    "print_options_mode": "doxygen", "print_level": 0, "sb": "yes", "output_file": path,
                    "file_print_level": 5}})
            solver(x0=1.0)
            del solver  # closes IPOPT's output file
        text = open(path, encoding="utf-8", errors="replace").read()
    except (RuntimeError, OSError):
        return {}
    finally:
        os.unlink(path)
    return parse_ipopt_documentation(text)


def parse_ipopt_documentation(text: str) -> dict[str, IpoptOption]:
    """Options from IPOPT's doxygen-mode documentation: ``<strong>name</strong>`` blocks whose text says "this real
    option" and "The valid range ... is X", or lists "Possible values"."""
    options = {}
    for name, body in re.findall(r"<strong>(\w+)</strong>.*?<blockquote>(.*?)</blockquote>", text, re.S):
        kind = re.search(r"this (real|integer|string) option", body)
        if kind is None:
            continue
        if kind.group(1) == "string":
            values = re.findall(r"^ - (\S+?):", body, re.M)
            accepts = ("any string" if "*" in values or not values
                       else " or ".join(f"'{value}'" for value in values))
        else:
            valid = re.search(r"valid range for this \w+ option is (.*?) and its default", body, re.S)
            accepts = _plain(valid.group(1)) if valid else "a number"
        options[name] = IpoptOption(name, kind.group(1), accepts)
    return options


def _plain(fragment: str) -> str:
    """IPOPT's doxygen markup as text: ``10<sup>+20</sup>`` → ``1e+20``, ``&le;`` → ``≤``."""
    fragment = re.sub(r"10<sup>([+-]?\d+)</sup>", r"1e\1", fragment)
    return html.unescape(re.sub(r"<[^>]+>", "", fragment)).strip()


def casadi_ipopt_accepts(name: str, value: Any) -> bool:
    """Whether CasADi's IPOPT accepts ``name = value``: a one-variable ``nlpsol`` built with it, which IPOPT refuses
    at once for an unknown option, a wrong type or a value out of range."""
    x = ca.SX.sym("x")
    try:
        with quiet_stdout():  # IPOPT prints why it refuses
            ca.nlpsol("option_check", "ipopt", {"x": x, "f": x**2},
                      {"print_time": False, "ipopt": {"print_level": 0, "sb": "yes", name: value}})
    except RuntimeError:
        return False
    return True


def check_ipopt_options(options: Mapping[str, Any], own: tuple[str, ...],
                        accepts: Callable[[str, Any], bool]) -> None:
    """Raise :class:`~gaitbench.options.OptionError` for the first option of ``options`` (the keywords beyond the
    plugin's ``own``) that IPOPT does not know or does not accept; ``accepts`` asks the IPOPT that will solve."""
    known = ipopt_options()
    types = {"integer": ("an integer", lambda v: isinstance(v, int) and not isinstance(v, bool)),
             "real": ("a number", lambda v: isinstance(v, int | float) and not isinstance(v, bool)),
             "string": ("a string", lambda v: isinstance(v, str))}
    for name, value in options.items():
        if name in own:
            continue
        option = known.get(name)
        if known and option is None:
            raise unknown_option(name, own, candidates=[*own, *known], cutoff=0.75,
                                 more=f", or any IPOPT option ({IPOPT_OPTIONS_URL})")
        if option is not None:
            expected, ok = types[option.type]
            if not ok(value):
                raise OptionError(name, f"IPOPT's {name} is {option.type}: expected {expected} "
                                        f"({option.accepts}), found {describe(value)}")
        if not accepts(name, value):
            detail = f": it accepts {option.accepts}" if option is not None else f" (see {IPOPT_OPTIONS_URL})"
            raise OptionError(name, f"IPOPT rejects {name} = {value!r}{detail}")


class Ipopt:
    """IPOPT with the exact Hessian of the Lagrangian.

    ``max_iterations``, ``time_limit_s`` (IPOPT's ``max_wall_time``; ``None`` for no limit), ``tolerance``
    (``tol``) and ``print_level`` (0 silences IPOPT and CasADi's timing table) are the options every gaitbench
    solver shares. Any other keyword is passed to IPOPT unchanged, for example ``linear_solver="ma57"``,
    ``mu_strategy="adaptive"``, ``acceptable_tol=1e-6`` or ``hessian_approximation="limited-memory"``; see
    https://coin-or.github.io/Ipopt/OPTIONS.html. :meth:`check_options` asks IPOPT itself about each of them, so an
    option it does not know or accept is refused when a suite loads; built without that check, such an option makes
    every solve return ERROR.
    ``nlp_scaling_obj_target_gradient=1`` scales the step costs, whose gradients are tiny, up to a unit gradient:
    about half the iterations, but other optima (docs/performance.md, "Objective scaling"), so not a default.
    ``scaling="nominal"`` scales the variables and constraint rows as well (:mod:`gaitbench.problem.scaling`;
    measured in
    docs/performance.md, "Variable and constraint scaling").
    """

    name = "ipopt"
    own_options = ("max_iterations", "time_limit_s", "tolerance", "print_level", "scaling")
    """gaitbench's options; every other keyword is IPOPT's."""

    @classmethod
    def check_options(cls, options: Mapping[str, Any]) -> None:
        """Every IPOPT option known to the IPOPT CasADi loads and accepted by it (docs/plugins.md)."""
        if "scaling" in options and options["scaling"] not in SCALINGS:
            raise OptionError("scaling", f"expected one of {', '.join(SCALINGS)}, found {describe(options['scaling'])}")
        check_ipopt_options(options, cls.own_options, casadi_ipopt_accepts)

    def __init__(self, max_iterations: int = 3000, time_limit_s: float | None = None, tolerance: float = 1e-8,
                 print_level: int = 0, scaling: str = "none", **ipopt_options) -> None:
        if scaling not in SCALINGS:
            raise ValueError(f"scaling = {scaling!r}: expected one of {', '.join(SCALINGS)}")
        self.scaling = scaling
        self._arguments = dict(max_iterations=max_iterations, time_limit_s=time_limit_s, tolerance=tolerance,
                               print_level=print_level, scaling=scaling, **ipopt_options)
        ipopt = {"max_iter": max_iterations, "tol": tolerance, "print_level": print_level}
        if time_limit_s is not None:
            ipopt["max_wall_time"] = time_limit_s
        if print_level == 0:
            ipopt["sb"] = "yes"  # the banner, which print_level 0 alone still prints
        ipopt.update(ipopt_options)
        self.options: dict = {"ipopt": ipopt, "print_time": print_level > 0, "record_time": True,
                              "error_on_fail": False}
        """The ``casadi.nlpsol`` options this solver builds with."""

    def solve(self, nlp: NLP, parameters: np.ndarray, initial_guess: np.ndarray) -> SolverResult:
        """Solve from ``initial_guess``; every failure, including exceptions inside CasADi, becomes a status."""
        p = np.asarray(parameters, dtype=float).ravel()
        x0 = np.asarray(initial_guess, dtype=float).ravel()
        start = time.perf_counter()
        try:
            solver = self._solver(nlp)
            if self.scaling == "nominal":
                factors = nominal_factors(nlp, x0, p)
                d, c = factors.variables, factors.constraints
                solution = solver(x0=x0 / d, p=factors.parameters(p), lbx=nlp.lbx / d, ubx=nlp.ubx / d,
                                  lbg=nlp.lbg / c, ubg=nlp.ubg / c)
            else:
                d, c = 1.0, 1.0
                solution = solver(x0=x0, p=p, lbx=nlp.lbx, ubx=nlp.ubx, lbg=nlp.lbg, ubg=nlp.ubg)
            stats = solver.stats()
            x = d * np.asarray(solution["x"], dtype=float).ravel()
            # Evaluated here rather than taken from IPOPT, which reports f = 0 when it fails at the initial point.
            objective = float(nlp.functions.objective(x, p))
            violation = nlp.violation(x, p)
        except Exception as error:  # the Solver protocol reports failures, it never raises them
            return SolverResult(status=SolverStatus.ERROR, message=f"{type(error).__name__}: {error}", x=x0,
                                objective=float("nan"), constraint_violation=float("nan"), iterations=0,
                                wall_time_s=time.perf_counter() - start, function_time_s=0.0)
        return_status = stats["return_status"]
        return SolverResult(
            status=IPOPT_STATUSES.get(return_status, SolverStatus.ERROR),
            message=f"IPOPT: {return_status}",
            x=x,
            objective=objective,
            constraint_violation=violation,
            iterations=int(stats["iter_count"]),
            wall_time_s=float(stats["t_wall_total"]),
            function_time_s=float(sum(stats.get(f"t_wall_nlp_{name}", 0.0) for name in _FUNCTIONS)),
            evaluations={name: int(stats[f"n_call_nlp_{name}"]) for name in _FUNCTIONS
                         if f"n_call_nlp_{name}" in stats},
            multipliers=np.asarray(solution["lam_g"], dtype=float).ravel() / c,
        )

    def remedies(self) -> list[tuple[str, Ipopt]]:
        """Variants for the walk's retry ladder: adaptive μ (Mehrotra's probing), which converges on steps the
        monotone strategy declares infeasible (upward slope, HS N = 60 step 6; DMOC N = 30 step 2)."""
        if self._arguments.get("mu_strategy") == "adaptive":
            return []
        return [("adaptive-mu", Ipopt(**{**self._arguments, "mu_strategy": "adaptive"}))]

    def prepare(self, nlp: NLP) -> None:
        """Build the ``nlpsol`` for ``nlp`` now (see :meth:`gaitbench.solve.solver.Solver.prepare`)."""
        self._solver(nlp)

    def _solver(self, nlp: NLP) -> ca.Function:
        key = options_key("ipopt", self.options | {"scaling": self.scaling})
        if key not in nlp.solver_cache:
            options, problem = dict(self.options), nlp.functions
            if self.scaling == "nominal":
                problem = ScaledProblem(nlp)
            if self.scaling == "nominal" or nlp.interval_blocks:
                # The problem's own derivatives: for interval blocks the compiled per-interval ones, not the flat
                # graph's; scaled, those same derivatives rescaled entry by entry.
                options |= {"jac_g": problem.constraints_and_jacobian, "hess_lag": problem.hessian_lagrangian_upper}
            nlp.solver_cache[key] = ca.nlpsol("ipopt", "ipopt", problem.oracle, options)
        return nlp.solver_cache[key]


@hookimpl
def register_solvers():
    return [Registration("ipopt", "IPOPT interior point through CasADi nlpsol, exact Hessian", Ipopt)]
