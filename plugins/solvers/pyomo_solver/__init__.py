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

from gaitbench import Registration, hookimpl
from gaitbench_plugins.solvers.pyomo_solver.solver import PyomoSolver, locate_executable
from gaitbench_plugins.solvers.pyomo_solver.translation import PyomoNLP, UnsupportedOperationError, translate

__all__ = ["PyomoNLP", "PyomoSolver", "UnsupportedOperationError", "locate_executable", "register_solvers",
           "translate"]


@hookimpl
def register_solvers():
    return [Registration("pyomo", "any AMPL-NL executable (ripopt, ipopt, snopt, knitro, conopt) through Pyomo",
                         PyomoSolver)]
