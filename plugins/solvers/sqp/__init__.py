"""A line-search SQP whose quadratic subproblems go to any backend of the ``qpsolvers`` library.

Why: an active-set method with the exact Hessian converges superlinearly once it has found the active set, which
makes it the natural comparison for IPOPT's interior point on the gait NLPs, and routing every QP through
``qpsolvers`` lets one benchmark compare QP backends (interior point: Clarabel, PIQP; active set: DAQP, quadprog,
HiGHS; ADMM / proximal: OSQP, ProxQP) on exactly the subproblems an SQP produces.

Each iteration solves, at the current x with multipliers λ,

    min ½dᵀPd + ∇fᵀd   s.t.   lbg ≤ g + J d ≤ ubg,   lbx ≤ x + d ≤ ubx

in ``qpsolvers`` form: rows with lbg = ubg become ``A d = b``, every finite side of the other rows a row of
``G d ≤ h`` (upper sides as J, lower sides as −J), the bounds ``lb ≤ d ≤ ub`` (infinite entries stay infinite:
every installed backend accepts them, and PIQP mistakes 1e20 for a real bound). Sparse backends get SciPy CSC
matrices, dense-only ones (DAQP, quadprog) dense arrays; a problem with neither constraints nor bounds is the
Newton system, solved without a backend. The QP duals are the multiplier estimates, in CasADi's sign convention
∇f + Jᵀλ_g + λ_x = 0; the first ones are IPOPT's least-squares estimate for the equality rows.

P must be positive definite for every backend (strictly for quadprog and DAQP). With ``hessian="exact"`` it is the
Hessian H of the Lagrangian, convexified without an eigen-decomposition, each candidate tested by a sparse LDLᵀ
factorisation (:func:`.hessian.positive_definite`; the whole model stays sparse, the Hessian and Jacobian being
CasADi's):

1. H + δI, δ = max(δ₀, δ_LM), δ₀ = 1e-10·max(1, max|H|) lifting only exactly singular directions, and δ_LM the
   Levenberg–Marquardt damping below;
2. H + δI + ρ·max(1, max|H|)·Σ_W a_i a_iᵀ/‖a_i‖², ρ = 1, 10, …, 10⁴, the least that factorises, over a working
   set W of constraint normals a_i: the equality rows, the inequality rows that are violated, carry a multiplier
   or are within 1e-6 of a bound (nearness alone not once five QP steps in a row have left the row inside its
   bounds: off its bound the term damps every step towards it), and the variables at a bound. For a row active
   in the QP, a_iᵀd is fixed, so the added term is constant on the QP's feasible set: once W is the active set
   the step is the exact Newton step, and by Debreu's lemma such a ρ exists when H is positive definite on the
   null space of the active constraints.
   The multipliers of rows active in the QP are corrected by ρ·a_iᵀd/‖a_i‖², so they are those of H itself
   (a one-sided row whose corrected multiplier has the wrong sign is not active for H: its multiplier is zero);
3. failing that, the ρ = 100 augmentation plus a shift from max(δ, 1e-8·max(1, max|H|)) growing ×4 until the
   factorisation is positive definite, like IPOPT's inertia correction.

H is the Hessian of the Lagrangian at the iterate's multipliers, but for rows whose gradient nearly vanishes (norm
below 1e-2), whose multipliers it takes capped at 1e3 (:func:`.hessian.hessian_multipliers`): where a row's gradient
vanishes at an active point its multiplier grows as 1/‖∇c_i‖, and its curvature came to dominate H and pin the
iterate (the gait steps' clearance where the legs cross; docs/decisions/0006-sqp-clearance-saddle.md). The QP, the
merit's weights and the KKT test keep the multipliers as they are. Once the late-step crawl shows (below), such rows are
also posed in the QP at unit norm (:meth:`.linearization.Linearization.row_scale`), so that their QP duals are their
forces rather than ~1/‖∇g_i‖: PIQP failed nearly every QP with them unscaled.

δ_LM, with the ℓ1 merit: the shift of the last iteration times ½ when the full step's actual decrease of φ was at
least ¾ of its model's (−Dφ(d) − ½dᵀ(H + δI)d), times 1 down to ¼, times 4 below ¼ or when the full step was
rejected (from at least 1e-8·max(1, max|H|)). On the gait steps the Lagrangian is indefinite along the flat valleys
of the thesis cost. IPOPT's rule alone (start from a fraction of the last shift) cycles there: the shift falls until
a step is far too long, the violation rises, and the next Hessian needs a shift 1000× larger, for hundreds of
iterations. The ratio control follows what the model predicts instead.

After 20 consecutive iterations with δ at its floor, the variables H has no curvature in (the gait steps' power
slacks) lose δ and have their step bounded by 1 + |x_i| instead (:func:`.hessian.release_linear_variables`), when
P stays positive definite without it: along the cost's flat valleys their only curvature was δ, and the QP was
nearly unbounded there (docs/decisions/0003-sqp-late-step-crawl.md). From then on, too, each accepted point gets a
magical step on the NLP's slack pairs (:mod:`.slacks`): two linear variables that split one equality row, as the
gait steps' P = s⁺ − s⁻ does, are set to the cheapest values that satisfy the row given the rest of x, when that
does not raise φ. Those rows' weights follow multipliers of ~1e-6, so φ hardly sees the violation the long steps
leave on the bilinear powers (~1e-3), and without the reset the acceptable level was out of reach
(docs/decisions/0003-sqp-late-step-crawl.md). The walk's ``crawl-floor`` last resort (``crawl_shift_floor``) also
lowers δ₀ from then on, to 1e-12·max(1, max|H|), the crawl still counted from 1e-10's floor: max|H| is set by H's
largest entries, so 1e-10 of it can be the only curvature along a valley, and the steps along it the reduced gradient
over δ₀.

With ``hessian="bfgs"`` P is a dense damped BFGS matrix (Powell's damping keeps it positive definite), started at
the identity and rescaled by yᵀy/sᵀy at the first update; the Hessian is never evaluated.

Globalisation (``merit``):

- ``"l1"``: the exact penalty φ = f + Σ μ_i viol_i(g), with Powell's per-row weights μ_i = max(|λ_i|,
  (μ_i + |λ_i|)/2) as in SLSQP (raised uniformly when the step would not decrease φ by ½ max(dᵀHd, 0), as the
  Nocedal–Wright rule (18.36) raises a single penalty), and Armijo backtracking (halving) on the directional
  derivative ∇fᵀd − Σ μ_i (viol_i(g) − viol_i(g + J d)). Weights that follow each row's multiplier matter on the
  gait steps, whose rows differ by orders of magnitude in scale: a single penalty set by the largest multiplier
  all but stops progress in f. When the QP fails or its multipliers exceed 1e6 (a nearly inconsistent
  linearisation), the step comes from its elastic version (SNOPT's elastic mode, Fletcher's Sℓ1QP)
  min ½dᵀPd + ∇fᵀd + W·Σ(p + n) s.t. lbg ≤ g + J d − p + n ≤ ubg, the bounds, p, n ≥ 0, W = max(100, 10‖λ‖∞).
- ``"filter"``: the Wächter–Biegler filter line search on (θ = ‖viol(g)‖₁, f), with its switching condition, the
  Armijo condition on f for f-type steps and filter augmentation for h-type steps. A failed QP, multipliers above
  1e6 or a step length below the filter's minimum start the restoration phase.

After an elastic step the multipliers restart from least squares: the ones that made the QP fail would shape the
next Hessians. At a stationary point (KKT residual below ``tolerance``, after iteration 0) that is infeasible, one
Gauss–Newton projection onto the constraints (the restoration's QP below) is taken whole when it halves θ: at
such a point the QP steps slide along the continuum of optima and cut the violation by only a few per cent each.

Restoration phase (the filter's, and the ℓ1 merit's when even the elastic QP fails): Gauss–Newton steps on θ (the
elastic QP with P = I, no objective and W = 1e4, so the least-norm step that reduces the linearised violation most
— a well-conditioned QP whatever the Hessian), each with Armijo backtracking on θ, until θ is below 0.9 times its
value on entry and the point is acceptable to the filter, which holds the iterate restoration started from; the
multipliers then restart from least squares.

Both try one second-order correction against the Maratos effect when the full step is rejected and did not reduce θ:
the QP again, with the constraints linearised as g(x + d) − J d + J s, accepted on the test for α = 1.

INFEASIBLE (local infeasibility): x violates the constraints, and the restoration's QP (P = I, no objective)
predicts no decrease of θ (x is a stationary point of the violation) or no step along its direction reduces θ. The
ℓ1 merit's elastic QP, which still weighs the objective, only hands over to the restoration when it predicts no
decrease; the message names the backend status of the QP that failed.

Convergence: the violation (max-norm) below ``tolerance`` and the stationarity/complementarity residual below
``tolerance`` times IPOPT's dual scaling s_d, with the current multipliers or with the ones the QP at x has just
returned; or, as IPOPT's "acceptable" level, both below ``acceptable_tolerance`` for 15 consecutive iterations or
when the iteration cannot continue from such a point, which includes a QP step that is no descent direction of the
ℓ1 merit there (an exact QP step always is one: such a step is the QP's inexactness, finer than its accuracy).
Complementarity is IPOPT's product |μ_i|·d_i near a bound. A solve whose accepted steps, optimality or elastic,
change φ by no more than its rounding for 15 consecutive iterations cannot progress: it ends there, as ERROR short
of the acceptable level (the walk's retry ladder takes over), instead of taking such steps until its iteration
limit.

QP failures: PIQP, the default, stops at its iteration limit on some of the ill-conditioned convexified gait QPs.
Such a QP is tried again by PIQP without its Ruiz equilibration (``gaitbench.solve.qp.RETRY_SETTINGS``), then by
``fallback_qp_solver`` (Clarabel), before it counts as failed; once the late-step crawl shows, where PIQP fails QPs in
runs, the setting that solved the last such QP goes first. PIQP's proximal regularisation is kept at or above 1e-10,
below which its iterates diverge on these QPs, and its limit is 100 iterations (``backends._BACKEND_OPTIONS``,
``gaitbench.solve.qp.BACKEND_SETTINGS``; docs/decisions/0002-qp-backends.md).

Warm starts, through ``qpsolvers``: the previous step is passed as ``initvals`` to the backends whose ``qpsolvers``
interface uses it (OSQP, ProxQP, DAQP); ProxQP also receives the previous duals (its ``y`` and ``z`` keywords),
converted to this QP's row scale (:meth:`.linearization.Linearization.rescaled`).
Clarabel, PIQP, HiGHS and quadprog start cold (``qpsolvers`` ignores initial values for them, or warns), so they
are never given any.

Options on the command line: ``-s sqp -o qp_solver=daqp -o hessian=bfgs -o merit=filter -o qp_tolerance=1e-9``.

Modules: :mod:`.solver` is the plugin's face (the solve and the retry ladder's variants), :mod:`.options` its options,
which a solve reads, never the solver. One solve is a :class:`.run.Run`, built in layers, each class on the one
before: :mod:`.iterate` (the point, its multipliers, the KKT test and the result), :mod:`.subproblems` (the QPs of an
iteration), :mod:`.linesearch` (both globalisations), :mod:`.restoration`, :mod:`.run` (the outer loop). They use
:mod:`.linearization` (the QPs' ``qpsolvers`` form), :mod:`.backends` (the backend calls), :mod:`.hessian` (the
convexification and BFGS) and :mod:`.slacks` (the slack pairs' reset).
"""

from __future__ import annotations

from gaitbench import Registration, hookimpl
from gaitbench_plugins.solvers.sqp.solver import SQP

__all__ = ["SQP", "register_solvers"]


@hookimpl
def register_solvers():
    return [Registration("sqp", "line-search SQP (exact or BFGS Hessian, l1 merit or filter), QPs through "
                                "qpsolvers", SQP)]
