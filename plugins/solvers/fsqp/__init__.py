"""Feasible SQP (FSQP), the thesis's Appendix D solver for the Discrete-Mechanics problems.

Why this method: every iterate satisfies the inequality constraints (joint, torque and velocity limits, foot
clearance), so even a run that is stopped early returns an admissible trajectory; and every subproblem is an
equality-constrained QP, i.e. one sparse KKT linear system, so no QP solver is needed. Equalities are handled by the
Mayne–Polak relaxation: each is oriented so that it is ≤ 0 at the start and is kept ≤ 0, while the exact penalty
F_c = f − c Σ_E c_j drives it to zero. Feasible descent directions follow Panier–Tits, and an arc search with a
second-order correction avoids the Maratos effect. H is a damped BFGS matrix or the convexified exact Hessian.

The steps follow the thesis's FSQP algorithm (§11.2), with its printed errors corrected:
Step 1 approximate active set with ε-halving, Step 2 least-squares multipliers and penalty update, Step 3 the
directions d0, d1 (or the d2/d3 combination) and the correction d̃, Step 4 the arc search, Step 5 BFGS. gaitbench's
``lbg ≤ g ≤ ubg, lbx ≤ x ≤ ubx`` becomes the thesis form: every finite one-sided bound of g or x is an inequality
row ``c_j(x) ≤ 0`` (the bounds of x are linear rows), every row with ``lbg == ubg`` (and every fixed variable) an
equality row, sign-oriented at the starting point. The deviations from the thesis that its literal form needs to
converge at all are listed in :class:`FSQP`; each was found on the Hock–Schittkowski problems of the test suite.
All linear algebra is sparse, except the BFGS matrix, dense n × n as in the thesis (a KKT matrix that is then mostly
dense is factorized densely).

That literal form (``subproblem="equality"``) stalls on the gait NLPs: its near-active set leaves out far bounds that
its steps then cross, and the arc search cuts every step to ~1e-9 (forward step 1, HS, N = 20: "no feasible descent
direction" at iteration 97, the equalities never below 1.09). The default ``subproblem="qp"`` keeps the family's
structure — a feasible start, feasible iterates, an exact penalty on the equalities, an arc search with a
second-order correction — with a QP over every linearised row (sparse, through ``qpsolvers``) for d0 and ``sqp``'s
convexified exact Hessian; see :class:`FSQP`.

Modules: :mod:`.solver` (the two phases of a solve), :mod:`.options`, :mod:`.progress` (a solve's limits and log),
:mod:`.feasibility` (phase 1), :mod:`.equality` and :mod:`.qp_subproblem` (the main phase, by subproblem), :mod:`.form`
(the NLP in the thesis's form), :mod:`.hessian`, :mod:`.qp` (the QPs through ``qpsolvers``), :mod:`.linalg` and
:mod:`.outcome`. The phases take the options and the solve's progress, never the solver.
"""

from __future__ import annotations

from gaitbench import Registration, hookimpl
from gaitbench_plugins.solvers.fsqp.outcome import IterationRecord
from gaitbench_plugins.solvers.fsqp.solver import FSQP

__all__ = ["FSQP", "IterationRecord", "register_solvers"]


@hookimpl
def register_solvers():
    return [Registration("fsqp", "Feasible SQP (thesis App. D): feasible iterates, arc search, BFGS or exact Hessian",
                         FSQP)]
