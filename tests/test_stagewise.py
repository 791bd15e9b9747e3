"""The stage-wise form of a step NLP (gaitbench/problem/stagewise.py): the same problem, in FATROP's order."""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest
from gait_steps import gait_step

from gaitbench.problem.nlp import NLPBuilder
from gaitbench.problem.stagewise import stagewise, variable_stages


@pytest.mark.parametrize("transcription", ["hermite-simpson", "dmoc"])
def test_the_form_holds_the_nlp_at_its_optimum(transcription: str):
    """At IPOPT's optimum lifted, the stage-wise rows are the NLP's rows (the gaps closed), its objective the NLP's,
    its bounds the originals' with free copies; restricting gives back the point."""
    problem = gait_step(transcription, 10, "forward")
    nlp, p, x = problem.nlp, problem.parameters, problem.x_star
    form = stagewise(nlp)
    w = form.lift(x)
    np.testing.assert_array_equal(form.restrict(w), x)
    g = np.asarray(ca.Function("g", [form.nlp.x, form.nlp.p], [form.nlp.g])(w, p)).ravel()
    np.testing.assert_array_equal(g[form.rows], nlp.constraint_values(x, p))
    gaps = np.setdiff1d(np.arange(g.size), form.rows)
    assert gaps.size == sum(form.nx[1:]) and not g[gaps].any()
    assert (form.nlp.lbg[gaps] == 0).all() and (form.nlp.ubg[gaps] == 0).all()
    np.testing.assert_array_equal(form.nlp.lbg[form.rows], nlp.lbg)
    f = float(ca.Function("f", [form.nlp.x, form.nlp.p], [form.nlp.f])(w, p))
    assert f == float(nlp.functions.objective(x, p))
    np.testing.assert_array_equal(form.nlp.lbx[form.original], nlp.lbx)
    copies = np.setdiff1d(np.arange(w.size), form.original)
    assert np.isinf(form.nlp.lbx[copies]).all() and np.isinf(form.nlp.ubx[copies]).all()
    assert form.horizon == 9  # a stage per node


@pytest.mark.parametrize("transcription", ["hermite-simpson", "dmoc"])
def test_every_row_and_hessian_entry_stays_within_a_stage(transcription: str):
    """FATROP's pattern: a gap block reads (x_k, u_k) and is the identity in x_k+1; every other row and every Hessian
    entry of the Lagrangian lies within one stage's (x_k, u_k)."""
    form = stagewise(gait_step(transcription, 10, "forward").nlp)
    x, g = form.nlp.x, form.nlp.g
    column_stage = np.repeat(np.arange(form.horizon + 1), np.add(form.nx, form.nu))
    row_stage, identity = [], []
    for k in range(form.horizon + 1):
        gap = form.nx[k + 1] if k < form.horizon else 0
        row_stage += [k] * (gap + form.ng[k])
        identity += [True] * gap + [False] * form.ng[k]
    row_stage, identity = np.array(row_stage), np.array(identity)
    rows, columns = ca.jacobian_sparsity(g, x).get_triplet()
    rows, columns = np.array(rows), np.array(columns)
    assert row_stage.size == g.numel() and column_stage.size == x.numel()
    within = column_stage[columns] == row_stage[rows]
    next_state = identity[rows] & (column_stage[columns] == row_stage[rows] + 1)
    assert (within | next_state).all()
    lam = ca.SX.sym("lam", g.numel())
    hessian_rows, hessian_columns = ca.hessian(form.nlp.f + ca.dot(lam, g), x)[0].sparsity().get_triplet()
    assert (column_stage[hessian_rows] == column_stage[hessian_columns]).all()


def test_an_nlp_that_joins_its_first_and_last_nodes_is_refused():
    builder = NLPBuilder()
    states = builder.variable("states", (1, 8))
    builder.constrain("dynamics", states[1:] - states[:-1] ** 2)
    builder.constrain("periodic", states[-1] - states[0])
    nlp = builder.build(ca.SX.sym("p", 0), ca.sumsqr(states))
    assert list(variable_stages(nlp)) == list(range(8))
    with pytest.raises(ValueError, match="row 7 \\(block 'periodic'\\) joins stages 0 and 7"):
        stagewise(nlp)
    nlp.variable_shapes = {}
    with pytest.raises(ValueError, match="does not give the shapes of its variable blocks"):
        stagewise(nlp)
