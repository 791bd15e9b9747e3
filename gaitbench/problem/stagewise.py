"""A step NLP rewritten in the stage-wise form that optimal-control solvers factorize (FATROP's), and mapped back.

FATROP's Riccati recursion wants the variables as [x₀, u₀, x₁, u₁, …, x_N, u_N], stage k+1's states tied to stage k
by gap-closing rows x_{k+1} − f(x_k, u_k) = 0 (identity in x_{k+1}), every other row a function of one stage's
(x_k, u_k), and no Hessian entry between two stages. A transcription's NLP is none of this: its variables come in
blocks, its dynamics are implicit (a Hermite–Simpson defect joins nodes k and k+1, DMOC's momentum balance k−1, k and
k+1), and the push-off impulse and its slacks enter the last node's rows.

Rather than ask every transcription for a second NLP, :func:`stagewise` lifts the one it has. Each variable gets a
stage from its block's shape (:attr:`NLP.variable_shapes`): column c of a block with a column per grid node is stage
c; column c of a block with a column per interval is stage c + 1, the node that closes the interval, so that its
own variables are never carried; any other block (push-off impulse, DMOC's boundary velocities, slacks of the
push-off work) is global. Stage k's controls u_k are its own variables, the originals, with their bounds. Its
states x_k are copies: every global variable (bounded at stage 0 only) and each earlier stage's variable that a
row at stage k or later still reads. A row goes to the latest stage it touches and reads that stage's originals
and copies; the copies move by a shift register, x_{k+1} = (globals, and those of u_k and x_k still needed), so
the gap-closing rows are linear with the identity in x_{k+1}. For an implicit scheme this is the usual trick: the
next node's unknowns are controls, the collocation residual a stage constraint, the gap closed on a copy; global
quantities are states with identity dynamics. The objective is read the same way, each variable it couples
nonlinearly with another at the later one's stage; an objective coupling one variable with two stages is refused.

How far back a row reaches comes from the Jacobian's pattern, so the form is exact for any stage assignment; the
assignment only decides the size of the states. The form's x and g are the NLP's, permuted and lifted
(:meth:`StagewiseForm.lift`, :meth:`StagewiseForm.restrict`), so verification, re-simulation and the walk see the
transcription's own solution.
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np

from gaitbench.problem.nlp import NLP

MAX_WINDOW = 3
"""The most stages back one row may reach: an NLP whose rows join stages further apart (the first and last nodes
of a step, say) is not an optimal control problem in any useful stage-wise sense."""


@dataclass(frozen=True)
class StagewiseForm:
    """The stage-wise NLP with its stage sizes, and the maps between its vectors and the original NLP's."""

    nlp: NLP
    nx: tuple[int, ...]
    """States per stage, N + 1 stages (FATROP's ``nx``)."""
    nu: tuple[int, ...]
    ng: tuple[int, ...]
    """Rows per stage besides the gap-closing ones."""
    source: np.ndarray
    """The original variable each stage-wise variable is (a copy of)."""
    original: np.ndarray
    """Where each original variable sits in the stage-wise x: its control, or a global's state at stage 0."""
    rows: np.ndarray
    """Where each original constraint row sits in the stage-wise g."""

    @property
    def horizon(self) -> int:
        """N: the number of gap-closing blocks."""
        return len(self.nx) - 1

    def lift(self, x: np.ndarray) -> np.ndarray:
        """The stage-wise point of an original point: every copy set to its original."""
        return np.asarray(x, dtype=float).ravel()[self.source]

    def restrict(self, w: np.ndarray) -> np.ndarray:
        """The original point of a stage-wise one (the copies dropped)."""
        return np.asarray(w, dtype=float).ravel()[self.original]

    def constraint_multipliers(self, multipliers: np.ndarray) -> np.ndarray:
        """The original rows' multipliers among the stage-wise ones (the same rows, so the same sign)."""
        return np.asarray(multipliers, dtype=float).ravel()[self.rows]

    def structure(self) -> dict:
        """CasADi's FATROP options for a manually given structure."""
        return {"structure_detection": "manual", "N": self.horizon, "nx": list(self.nx), "nu": list(self.nu),
                "ng": list(self.ng)}

    def equality(self) -> list[bool]:
        """Which stage-wise rows are equalities: what CasADi's ``structure_detection="auto"`` needs."""
        return [bool(equal) for equal in self.nlp.lbg == self.nlp.ubg]


def variable_stages(nlp: NLP) -> np.ndarray:
    """Each variable's stage, −1 for a global: column c of a block with the most columns (n, the grid's nodes) is
    stage c, column c of a block with n − 1 (its intervals) stage c + 1, any other block global."""
    if set(nlp.variable_shapes) != set(nlp.variable_blocks):
        raise ValueError("the NLP does not give the shapes of its variable blocks, which say the grid's stages")
    n = max((columns for _, columns in nlp.variable_shapes.values()), default=0)
    stages = np.full(nlp.n_variables, -1, dtype=int)
    if n < 2:
        raise ValueError("the NLP has no block over a grid of two or more nodes to order by stage")
    for name, block in nlp.variable_blocks.items():
        rows, columns = nlp.variable_shapes[name]
        if columns in (n, n - 1):
            stages[block] = np.repeat(np.arange(columns) + (columns == n - 1), rows)
    return stages


def _pattern(expression: ca.SX, x: ca.SX) -> tuple[np.ndarray, np.ndarray]:
    rows, columns = ca.jacobian_sparsity(expression, x).get_triplet()
    return np.asarray(rows, dtype=int), np.asarray(columns, dtype=int)


def _row_stages(nlp: NLP, stages: np.ndarray, rows: np.ndarray, columns: np.ndarray,
                max_window: int) -> np.ndarray:
    """Each row's stage, the latest its variables are at (0 for rows of globals alone), checked against the window."""
    staged = stages[columns] >= 0
    latest = np.full(nlp.n_constraints, -1, dtype=int)
    earliest = np.full(nlp.n_constraints, np.iinfo(int).max, dtype=int)
    np.maximum.at(latest, rows, stages[columns])
    np.minimum.at(earliest, rows[staged], stages[columns][staged])
    reach = np.where(latest >= 0, latest - np.minimum(earliest, latest), 0)
    if reach.size and reach.max() > max_window:
        row = int(np.argmax(reach))
        block = next(name for name, part in nlp.constraint_blocks.items() if part.start <= row < part.stop)
        raise ValueError(f"the NLP is not stage-wise: row {row} (block {block!r}) joins stages {earliest[row]} and "
                         f"{latest[row]}, more than {max_window} apart")
    return np.maximum(latest, 0)


def _objective_stages(nlp: NLP, stages: np.ndarray, max_window: int) -> np.ndarray:
    """The stage at which the objective reads each variable. Variables it couples nonlinearly (a Hessian entry
    between them, directly or through others) are read together, at the latest stage of the group, the only one
    holding them all; any other variable at its own stage, a global at stage 0."""
    hessian_rows, hessian_columns = _pattern(ca.gradient(nlp.f, nlp.x), nlp.x)
    group = np.arange(stages.size)  # union-find over the couplings

    def root(variable: int) -> int:
        while group[variable] != variable:
            group[variable] = group[group[variable]]
            variable = group[variable]
        return variable

    for a, b in zip(hessian_rows.tolist(), hessian_columns.tolist(), strict=True):
        if a != b:
            group[root(a)] = root(b)
    roots = np.array([root(variable) for variable in range(stages.size)], dtype=int)
    latest, earliest = np.maximum(stages, 0), np.where(stages >= 0, stages, np.iinfo(int).max)
    np.maximum.at(latest, roots, latest.copy())
    np.minimum.at(earliest, roots, earliest.copy())
    reach = latest[roots] - np.minimum(earliest[roots], latest[roots])
    if reach.size and reach.max() > max_window:
        variable = int(np.argmax(reach))
        raise ValueError(f"the objective is not stage-wise: it couples variable {variable} with variables "
                         f"{reach[variable]} stages apart")
    return latest[roots]


def stagewise(nlp: NLP, max_window: int = MAX_WINDOW) -> StagewiseForm:
    """The stage-wise form of ``nlp`` (see the module docstring); ValueError says why an NLP has none."""
    stages = variable_stages(nlp)
    rows, columns = _pattern(nlp.g, nlp.x)
    row_stage = _row_stages(nlp, stages, rows, columns, max_window)
    reading = _objective_stages(nlp, stages, max_window)
    last = np.maximum(reading, stages)  # the last stage at which each variable is read
    np.maximum.at(last, columns, row_stage[rows])
    n_stages = int(stages.max()) + 1
    globals_ = np.flatnonzero(stages < 0)

    position = np.full((n_stages, nlp.n_variables), -1, dtype=int)
    states, controls, source, offset = [], [], [], 0
    for k in range(n_stages):
        carried = np.flatnonzero((stages >= 0) & (stages < k) & (last >= k))
        for part, group in ((np.concatenate([globals_, carried]), states), (np.flatnonzero(stages == k), controls)):
            position[k, part] = offset + np.arange(part.size)
            offset += part.size
            source.append(part)
            group.append(part)
    source = np.concatenate(source)
    original = np.where(stages >= 0, position[np.maximum(stages, 0), np.arange(nlp.n_variables)], position[0])
    w = ca.SX.sym("w", offset)

    def read(k: int, variables: np.ndarray) -> ca.SX:
        where = position[k, variables]
        assert (where >= 0).all(), "a row reads a variable its stage does not hold"
        return w[where.tolist()]

    g, lbg, ubg, placed, ng = [], [], [], np.empty(nlp.n_constraints, dtype=int), []
    count = 0
    for k in range(n_stages):
        if k + 1 < n_stages:  # x_{k+1} closes the gap to the originals and copies of stage k
            gap = states[k + 1]
            g.append(w[position[k + 1, gap].tolist()] - read(k, gap))
            lbg.append(np.zeros(gap.size))
            ubg.append(np.zeros(gap.size))
            count += gap.size
        own = np.flatnonzero(row_stage == k)
        used = np.unique(columns[np.isin(rows, own)])
        evaluate = ca.Function(f"stage_{k}", [nlp.x[used.tolist()], nlp.p], [nlp.g[own.tolist()]])
        g.append(evaluate(read(k, used), nlp.p))
        lbg.append(nlp.lbg[own])
        ubg.append(nlp.ubg[own])
        placed[own] = count + np.arange(own.size)
        count += own.size
        ng.append(own.size)
    in_objective = np.unique(_pattern(nlp.f, nlp.x)[1])
    objective = ca.Function("objective", [nlp.x[in_objective.tolist()], nlp.p], [nlp.f])
    where = position[reading[in_objective], in_objective]
    f = objective(w[where.tolist()], nlp.p)

    lbx, ubx = np.full(offset, -np.inf), np.full(offset, np.inf)
    lbx[original], ubx[original] = nlp.lbx, nlp.ubx
    stage_nlp = NLP(x=w, p=nlp.p, f=f, g=ca.vertcat(*g), lbx=lbx, ubx=ubx, lbg=np.concatenate(lbg),
                    ubg=np.concatenate(ubg), variable_blocks={}, constraint_blocks={})
    return StagewiseForm(nlp=stage_nlp, nx=tuple(part.size for part in states),
                         nu=tuple(part.size for part in controls), ng=tuple(ng), source=source, original=original,
                         rows=placed)
