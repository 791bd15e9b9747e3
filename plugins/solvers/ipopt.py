"""IPOPT (interior point, filter line search) through CasADi's ``nlpsol``, with CasADi's exact sparse Hessian.

The built ``nlpsol`` is kept in ``nlp.solver_cache`` under its options, so the steps of a walk — one NLP structure
re-solved with new parameters — pay for building (and differentiating) the problem only once.
"""

from __future__ import annotations

import time
from collections.abc import Mapping
from typing import Any

import casadi as ca
import numpy as np

from gaitbench import Registration, hookimpl
from gaitbench.options import OptionError, describe
from gaitbench.problem.nlp import NLP
from gaitbench.problem.scaling import SCALINGS, ScaledProblem, nominal_factors
from gaitbench.solve.ipopt import IPOPT_STATUSES, SMALL_MU_INIT, check_ipopt_options
from gaitbench.solve.silence import quiet_stdout
from gaitbench.solve.solver import options_key
from gaitbench.solver_result import SolverResult, SolverStatus

SECTION_OPTIONS = {"mu_strategy": "adaptive", "mu_oracle": "quality-function"}
"""The IPOPT options of decrease and conquer's sectional NLPs unless ``section_options`` says otherwise: adaptive μ,
on 20 D&C walks at N = 12–40 37 % fewer iterations and verified ACOTs no worse on average
(docs/decisions/0015-ipopt-levers.md). ``section_options = {}`` solves the sections as the steps."""

_FUNCTIONS = ("f", "g", "grad_f", "jac_g", "hess_l")
"""The NLP callbacks IPOPT evaluates, named as in :class:`gaitbench.problem.nlp.NLPFunctions`."""


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
    ``section_options`` are IPOPT options for decrease and conquer's sectional NLPs only, over the others
    (:meth:`for_sections`); by default :data:`SECTION_OPTIONS`, adaptive μ.
    """

    name = "ipopt"
    own_options = ("max_iterations", "time_limit_s", "tolerance", "print_level", "scaling", "section_options")
    """gaitbench's options; every other keyword is IPOPT's."""

    @classmethod
    def check_options(cls, options: Mapping[str, Any]) -> None:
        """Every IPOPT option known to the IPOPT CasADi loads and accepted by it (docs/plugins.md)."""
        if "scaling" in options and options["scaling"] not in SCALINGS:
            raise OptionError("scaling", f"expected one of {', '.join(SCALINGS)}, found {describe(options['scaling'])}")
        check_ipopt_options(options, cls.own_options, casadi_ipopt_accepts)
        sections = options.get("section_options", {})
        if not isinstance(sections, Mapping):
            raise OptionError("section_options", f"expected a table of IPOPT options, found {describe(sections)}")
        try:
            check_ipopt_options(sections, (), casadi_ipopt_accepts)
        except OptionError as error:
            raise OptionError(f"section_options.{error.option}", error.message) from None

    def __init__(self, max_iterations: int = 3000, time_limit_s: float | None = None, tolerance: float = 1e-8,
                 print_level: int = 0, scaling: str = "none", section_options: Mapping[str, Any] | None = None,
                 **ipopt_options) -> None:
        if scaling not in SCALINGS:
            raise ValueError(f"scaling = {scaling!r}: expected one of {', '.join(SCALINGS)}")
        self.scaling = scaling
        self.section_options = dict(SECTION_OPTIONS if section_options is None else section_options)
        self._arguments = dict(max_iterations=max_iterations, time_limit_s=time_limit_s, tolerance=tolerance,
                               print_level=print_level, scaling=scaling, section_options=self.section_options,
                               **ipopt_options)
        self._sections: Ipopt | None = None
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

    def for_sections(self) -> Ipopt:
        """The solver of decrease and conquer's sectional NLPs: this one with ``section_options`` over its IPOPT
        options (:func:`gaitbench.solve.solver.section_solver`)."""
        if not self.section_options:
            return self
        if self._sections is None:
            self._sections = Ipopt(**{**self._arguments, **self.section_options, "section_options": {}})
        return self._sections

    def remedies(self) -> list[tuple[str, Ipopt]]:
        """Variants for the walk's retry ladder: adaptive μ (Mehrotra's probing), which converges on steps the
        monotone strategy declares infeasible (upward slope, HS N = 60 step 6; DMOC N = 30 step 2)."""
        if self._arguments.get("mu_strategy") == "adaptive":
            return []
        return [("adaptive-mu", Ipopt(**{**self._arguments, "mu_strategy": "adaptive"}))]

    def last_resorts(self) -> list[tuple[str, Ipopt]]:
        """A small initial barrier parameter (μ₀ = 1e-3 instead of 0.1), after the walk's other rungs: stairs, HS,
        N = 140, step 1 diverges from the blended guess with both μ strategies, and its First Phase too; with
        μ₀ = 1e-3 it converges in 447 iterations, but to a COT of 1.14 where the neighbouring N reach 0.39–0.72."""
        if "mu_init" in self._arguments:
            return []
        return [("small-mu-init", Ipopt(**{**self._arguments, "mu_init": SMALL_MU_INIT}))]

    def prepare(self, nlp: NLP) -> None:
        """Build the ``nlpsol`` for ``nlp`` now (see :class:`gaitbench.contracts.Solver`, its optional ``prepare``)."""
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
