"""What every plugin that runs IPOPT shares: the meaning of its return statuses and the check of its options.

Why here: the ``ipopt`` plugin (through CasADi) and the ``cyipopt`` plugin (IPOPT's C interface) reach the same IPOPT,
so they must read its statuses and refuse its options alike; plugins share code only through the core.
"""

from __future__ import annotations

import functools
import html
import os
import re
import tempfile
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

import casadi as ca

from gaitbench.options import OptionError, describe, unknown_option
from gaitbench.solve.silence import quiet_stdout
from gaitbench.solver_result import SolverStatus

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

SMALL_MU_INIT = 1e-3
"""IPOPT's initial barrier parameter in the ``small-mu-init`` last resort of the retry ladder (its default is 0.1):
both IPOPT plugins offer it."""

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
    3.14, without ``print_options_mode``), and then :func:`check_ipopt_options` relies on its ``accepts`` alone.
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
