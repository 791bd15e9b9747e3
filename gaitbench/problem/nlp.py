"""One solver-independent NLP: what every transcription produces and every solver consumes.

    minimize f(x, p)  subject to  lbg ≤ g(x, p) ≤ ubg,  lbx ≤ x ≤ ubx

``p`` carries everything that changes between solves of the same structure (initial state, step geometry,
time step, robot parameters), so a built NLP — and a solver built on it — is reused without rebuilding.
Exact sparse first and second derivatives come from CasADi, each built once, on first use. Constraint blocks that
repeat one small function over the grid's intervals (:class:`IntervalBlock`) get their values, Jacobian and Hessian
from that function and its derivatives, compiled and mapped over the intervals: the same numbers, without
evaluating or differentiating the flat graph for those rows.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from functools import cached_property

import casadi as ca
import numpy as np

from gaitbench.problem.compiled import compiled


@dataclass(frozen=True)
class IntervalBlock:
    """Constraint rows that are one function of each grid interval's own variables.

    Row ``rows[o][r, k]`` of g is output o, row r, of ``function(x[variables[:, k]], p)``: the transcription's
    defects on interval k, say. Knowing this, the Hessian of the Lagrangian is assembled from the compiled Hessian
    of one interval rather than derived from the whole flat expression graph, whose second derivatives through
    composed dynamics are what makes a collocation NLP slow (docs/performance.md).
    """

    function: ca.Function
    variables: np.ndarray  # (n_z, M) indices into x
    rows: tuple[np.ndarray, ...]  # per output of ``function``, (rows_o, M) indices into g


class NLPFunctions:
    """Callables over (x, p); ``hessian_lagrangian`` takes (x, p, σ_f, λ_g) and is lower-triangular.

    Each is built on first use: checking a solution needs only ``constraints``, and the symbolic Hessian of a
    large step costs seconds and a hundred megabytes that a solver building its own would pay twice.

    With interval blocks, ``constraints``, ``jacobian`` and the Hessians are MX functions: the flat graph's other
    rows, plus each block's compiled per-interval function (value, Jacobian, Hessian) mapped over its intervals,
    assembled into the same sparse matrices.
    """

    def __init__(self, x: ca.SX, p: ca.SX, f: ca.SX, g: ca.SX, blocks: Sequence[IntervalBlock] = ()) -> None:
        self._x, self._p, self._f, self._g = x, p, f, g
        self._blocks = tuple(blocks)
        structured = [rows.ravel() for block in self._blocks for rows in block.rows]
        self._flat_rows = np.setdiff1d(np.arange(g.numel()), np.concatenate(structured or [[]]).astype(int)).tolist()
        self._mx = (ca.MX.sym("x", x.numel()), ca.MX.sym("p", p.numel()), ca.MX.sym("sigma"),
                    ca.MX.sym("lam", g.numel()))

    @cached_property
    def objective(self) -> ca.Function:
        return ca.Function("f", [self._x, self._p], [self._f])

    @cached_property
    def constraints(self) -> ca.Function:
        if not self._blocks:
            return ca.Function("g", [self._x, self._p], [self._g])
        x, p, _, _ = self._mx
        flat = ca.Function("g_flat", [self._x, self._p], [self._g[self._flat_rows]])
        values, positions = [flat(x, p)], [np.asarray(self._flat_rows, dtype=int)]
        for block in self._blocks:
            mapped = compiled(block.function, differentiable=True).map(block.variables.shape[1])
            outputs = _as_list(mapped(*self._interval_inputs(block)))
            values.extend(ca.vec(output) for output in outputs)
            positions.extend(rows.ravel(order="F") for rows in block.rows)
        order = np.argsort(np.concatenate(positions))  # g's row i is the order[i]-th value
        return ca.Function("g", [x, p], [ca.vertcat(*values)[order.tolist()]])

    @cached_property
    def oracle(self) -> dict[str, ca.SX | ca.MX]:
        """The problem in ``casadi.nlpsol``'s dictionary form, g from :attr:`constraints`.

        With interval blocks it is an MX graph whose g calls the compiled interval functions: the values a solver
        evaluates at every trial point, at a fraction of the flat graph's cost, and a graph that ``nlpsol`` sets up
        in milliseconds rather than in a tenth of a second per step structure. Its results are the flat graph's
        (the same operations; ``tests/test_interval_blocks.py``)."""
        if not self._blocks:
            return {"x": self._x, "p": self._p, "f": self._f, "g": self._g}
        x, p, _, _ = self._mx
        return {"x": x, "p": p, "f": self.objective(x, p), "g": self.constraints(x, p)}

    @cached_property
    def gradient(self) -> ca.Function:
        return ca.Function("grad_f", [self._x, self._p], [ca.gradient(self._f, self._x)])

    @cached_property
    def jacobian(self) -> ca.Function:
        if not self._blocks:
            return ca.Function("jac_g", [self._x, self._p], [ca.jacobian(self._g, self._x)])
        x, p, _, _ = self._mx
        flat = ca.jacobian(self._g[self._flat_rows], self._x)
        rows, cols = flat.sparsity().get_triplet()
        values = [ca.Function("jac_flat", [self._x, self._p], [ca.vertcat(*flat.nonzeros())])(x, p)]
        rows, cols = [np.asarray(self._flat_rows, dtype=int)[rows]], [np.asarray(cols, dtype=int)]
        for block in self._blocks:
            local, (local_rows, local_cols) = _derived(block.function, _interval_jacobian)
            values.append(ca.vec(local.map(block.variables.shape[1])(*self._interval_inputs(block))))
            stacked = np.vstack(block.rows)  # rows of the stacked outputs, interval by interval
            rows.append(stacked[local_rows].ravel(order="F"))
            cols.append(block.variables[local_cols].ravel(order="F"))
        jacobian = _assemble(self._g.numel(), self._x.numel(), values, np.concatenate(rows), np.concatenate(cols))
        return ca.Function("jac_g", [x, p], [jacobian])

    @cached_property
    def constraints_and_jacobian(self) -> ca.Function:
        """(g, ∂g/∂x) in one call: the form ``nlpsol``'s ``jac_g`` option takes."""
        x, p, _, _ = self._mx
        return ca.Function("jac_g", [x, p], [self.constraints(x, p), self.jacobian(x, p)])

    @cached_property
    def hessian_lagrangian(self) -> ca.Function:
        return self._hessian(upper=False)

    @cached_property
    def hessian_lagrangian_upper(self) -> ca.Function:
        """The same Hessian as its upper triangle: the form ``nlpsol``'s ``hess_lag`` option takes."""
        return self._hessian(upper=True)

    def _interval_inputs(self, block: IntervalBlock, multipliers: ca.MX | None = None) -> list[ca.MX]:
        """Each interval's z (n_z × M), the parameters repeated, and with ``multipliers`` each output's λ."""
        x, p, _, _ = self._mx
        n_z, n_intervals = block.variables.shape
        inputs = [ca.reshape(x[block.variables.ravel(order="F").tolist()], n_z, n_intervals),
                  ca.repmat(p, 1, n_intervals)]
        if multipliers is not None:
            inputs += [ca.reshape(multipliers[r.ravel(order="F").tolist()], r.shape[0], n_intervals)
                       for r in block.rows]
        return inputs

    def _hessian(self, upper: bool) -> ca.Function:
        """∇²(σ f + λ·g) over (x, p, σ, λ), one triangle: the flat graph's part plus each interval block's."""
        sigma = ca.SX.sym("sigma")
        lam = ca.SX.sym("lam", self._g.numel())
        lagrangian = sigma * self._f + ca.dot(lam[self._flat_rows], self._g[self._flat_rows])
        flat = _triangle(ca.hessian(lagrangian, self._x)[0], upper)
        if not self._blocks:
            return ca.Function("hess_l", [self._x, self._p, sigma, lam], [flat])
        x, p, s, multipliers = self._mx
        rows, cols = flat.sparsity().get_triplet()
        values = [ca.Function("hess_flat", [self._x, self._p, sigma, lam], [ca.vertcat(*flat.nonzeros())])(
            x, p, s, multipliers)]
        rows, cols = [np.asarray(rows, dtype=int)], [np.asarray(cols, dtype=int)]
        for block in self._blocks:
            local, (local_rows, local_cols) = _derived(block.function, _interval_hessian)
            values.append(ca.vec(local.map(block.variables.shape[1])(*self._interval_inputs(block, multipliers))))
            a, b = block.variables[local_rows].ravel(order="F"), block.variables[local_cols].ravel(order="F")
            rows.append(np.minimum(a, b) if upper else np.maximum(a, b))  # folded into the triangle
            cols.append(np.maximum(a, b) if upper else np.minimum(a, b))
        n = self._x.numel()
        hessian = _assemble(n, n, values, np.concatenate(rows), np.concatenate(cols))
        return ca.Function("hess_l", [x, p, s, multipliers], [hessian])


def _as_list(outputs) -> list:
    return outputs if isinstance(outputs, list) else [outputs]


def _triangle(matrix, upper: bool):
    return ca.triu(matrix) if upper else ca.tril(matrix)


def _assemble(n_rows: int, n_cols: int, values: list[ca.MX], rows: np.ndarray, cols: np.ndarray) -> ca.MX:
    """The sparse matrix with entry (rows[i], cols[i]) += vertcat(values)[i], duplicates summed."""
    keys, position = np.unique(cols * n_rows + rows, return_inverse=True)  # column-major, CasADi's storage order
    pattern = ca.Sparsity.triplet(n_rows, n_cols, (keys % n_rows).tolist(), (keys // n_rows).tolist())
    summation = ca.DM(ca.Sparsity.triplet(len(keys), len(position), position.tolist(),
                                          list(range(len(position)))), 1.0)
    return ca.MX(pattern, ca.mtimes(summation, ca.vertcat(*values)))


def _interval_symbols(function: ca.Function) -> tuple[ca.SX, ca.SX, ca.SX]:
    """Symbols for one interval's (z, p) and its outputs stacked."""
    z, p = ca.SX.sym("z", function.size1_in(0)), ca.SX.sym("p", function.size1_in(1))
    return z, p, ca.vertcat(*_as_list(function(z, p)))


_DERIVED: dict[tuple[str, str], tuple[ca.Function, tuple[np.ndarray, np.ndarray]]] = {}
"""Interval derivatives already derived in this process, by derivation and the function's serialization."""


def _derived(function: ca.Function, derive) -> tuple[ca.Function, tuple[np.ndarray, np.ndarray]]:
    """``derive(function)``, once per process for each distinct interval function (by its serialization).

    Every build of a structure, and every sectional problem of a walk, declares the same interval function anew:
    differentiating it and hashing the derivative's C source again would cost more than the rest of the build."""
    key = (derive.__name__, function.serialize())
    if key not in _DERIVED:
        _DERIVED[key] = derive(function)
    return _DERIVED[key]


def _interval_jacobian(function: ca.Function) -> tuple[ca.Function, tuple[np.ndarray, np.ndarray]]:
    """∂g/∂z of one interval (outputs stacked) as the column of its nonzeros, compiled, with their positions."""
    z, p, outputs = _interval_symbols(function)
    jacobian = ca.jacobian(outputs, z)
    local_rows, local_cols = jacobian.sparsity().get_triplet()
    local = ca.Function(f"{function.name()}_jacobian", [z, p], [ca.vertcat(*jacobian.nonzeros())])
    return compiled(local), (np.asarray(local_rows, dtype=int), np.asarray(local_cols, dtype=int))


def _interval_hessian(function: ca.Function) -> tuple[ca.Function, tuple[np.ndarray, np.ndarray]]:
    """∇²_z λ·g(z, p) of one interval (outputs stacked, λ per output) as the column of its lower-triangle
    nonzeros, compiled, with their (row, col) positions in z."""
    z, p, outputs = _interval_symbols(function)
    lams = [ca.SX.sym(f"lam{o}", function.size1_out(o)) for o in range(function.n_out())]
    hessian = ca.tril(ca.hessian(ca.dot(ca.vertcat(*lams), outputs), z)[0])
    local_rows, local_cols = hessian.sparsity().get_triplet()
    local = ca.Function(f"{function.name()}_hessian", [z, p, *lams], [ca.vertcat(*hessian.nonzeros())])
    return compiled(local), (np.asarray(local_rows, dtype=int), np.asarray(local_cols, dtype=int))


@dataclass
class NLP:
    """Variables with bounds, parameters, objective and constraints, with named blocks for diagnostics."""

    x: ca.SX
    p: ca.SX
    f: ca.SX
    g: ca.SX
    lbx: np.ndarray
    ubx: np.ndarray
    lbg: np.ndarray
    ubg: np.ndarray
    variable_blocks: dict[str, slice]
    constraint_blocks: dict[str, slice]
    interval_blocks: tuple[IntervalBlock, ...] = ()
    variable_shapes: dict[str, tuple[int, int]] = field(default_factory=dict)
    """(rows, columns) of each variable block as declared: a column is a grid node or interval, which is how the
    stage-wise form (:mod:`gaitbench.problem.stagewise`) orders the variables by stage."""
    solver_cache: dict = field(default_factory=dict, repr=False)
    """Solvers keep their built instances here, keyed by their options, so re-solving costs no rebuild."""

    @property
    def n_variables(self) -> int:
        return self.x.numel()

    @property
    def n_constraints(self) -> int:
        return self.g.numel()

    @cached_property
    def functions(self) -> NLPFunctions:
        return NLPFunctions(self.x, self.p, self.f, self.g, self.interval_blocks)

    def casadi_problem(self) -> dict[str, ca.SX]:
        """The problem in the dictionary form of ``casadi.nlpsol``."""
        return {"x": self.x, "p": self.p, "f": self.f, "g": self.g}

    def constraint_values(self, x: np.ndarray, p: np.ndarray) -> np.ndarray:
        return np.asarray(self.functions.constraints(x, p)).ravel()

    def violation(self, x: np.ndarray, p: np.ndarray) -> float:
        """Largest violation of any constraint or variable bound (0 when feasible)."""
        g = self.constraint_values(x, p)
        worst = [np.max(self.lbg - g, initial=0.0), np.max(g - self.ubg, initial=0.0)]
        worst += [np.max(self.lbx - x, initial=0.0), np.max(x - self.ubx, initial=0.0)]
        return float(max(worst))

    def block_violations(self, x: np.ndarray, p: np.ndarray) -> dict[str, float]:
        """Largest violation per named constraint block: which physics a bad solution breaks."""
        g = self.constraint_values(x, p)
        excess = np.maximum(np.maximum(self.lbg - g, g - self.ubg), 0.0)
        return {name: float(np.max(excess[block], initial=0.0)) for name, block in self.constraint_blocks.items()}

    def bound_violations(self, x: np.ndarray) -> dict[str, float]:
        """Largest violation per variable block of its bounds (``"<block> bounds"``), relative to the bound where that
        is larger than 1, as solvers hold bounds (a torque limit of 3000 N·m is kept to 3000 (1 + ε))."""
        x = np.asarray(x, dtype=float)
        with np.errstate(invalid="ignore"):  # an infinite bound is never violated
            below = np.where(np.isfinite(self.lbx), (self.lbx - x) / np.maximum(1.0, np.abs(self.lbx)), 0.0)
            above = np.where(np.isfinite(self.ubx), (x - self.ubx) / np.maximum(1.0, np.abs(self.ubx)), 0.0)
        excess = np.maximum(np.maximum(below, above), 0.0)
        excess = np.where(np.isnan(x), np.inf, excess)
        return {f"{name} bounds": float(np.max(excess[block], initial=0.0))
                for name, block in self.variable_blocks.items()}


class NLPBuilder:
    """Collects named variable and constraint blocks while a transcription assembles its NLP."""

    def __init__(self) -> None:
        self._variables: list[tuple[str, ca.SX, np.ndarray, np.ndarray]] = []
        self._constraints: list[tuple[str, ca.SX, np.ndarray, np.ndarray]] = []
        self._interval_blocks: list[tuple[tuple[str, ...], ca.Function, ca.SX, tuple[int, ...]]] = []
        """(names, function, z, index in ``_constraints`` of each output's part) per interval declaration."""
        self._column_blocks: list[tuple[str, ca.SX, int]] = []
        """(name, expression, index in ``_constraints``) per :meth:`constrain_columns` declaration."""

    def variable(self, name: str, shape: tuple[int, int], lower=-np.inf, upper=np.inf) -> ca.SX:
        """A (rows × cols) block of decision variables, column-major, with scalar or per-row bounds."""
        symbol = ca.SX.sym(name, *shape)
        self._variables.append((name, symbol, _expand(lower, shape), _expand(upper, shape)))
        return symbol

    def variables(self, name: str) -> ca.SX:
        """A block declared earlier, by name."""
        return next(symbol for block, symbol, _, _ in self._variables if block == name)

    def constrain(self, name: str, expression, lower=0.0, upper=0.0) -> None:
        """Rows ``lower ≤ expression ≤ upper`` (column-major). Declared again right after itself, a block grows by
        the new part: a block whose rows come partly from an interval function and partly from elsewhere (DMOC's
        momentum balance, with different equations at the two end nodes) keeps one name."""
        expression = ca.vec(ca.SX(expression))
        n = expression.numel()
        self._constraints.append((name, expression, np.broadcast_to(lower, n).astype(float),
                                  np.broadcast_to(upper, n).astype(float)))

    def constrain_intervals(self, names: Sequence[str], function: ca.Function, variables: Sequence[ca.SX],
                            parameters: ca.SX) -> None:
        """Equality blocks ``names[o]`` = output o of ``function(z_k, p)`` over intervals k = 0 … M−1, where z_k
        stacks column k of each matrix in ``variables`` (decision-variable symbols, M columns each).

        The blocks are ordinary constraints (interval by interval, column-major like :meth:`constrain`), each
        possibly one part of a block declared in consecutive parts; declaring them this way also gives the NLP
        their per-interval structure (:class:`IntervalBlock`).
        """
        z = ca.vertcat(*variables)
        n_intervals = z.shape[1]
        outputs = _as_list(function.map(n_intervals)(z, ca.repmat(parameters, 1, n_intervals)))
        parts = []
        for name, output in zip(names, outputs, strict=True):
            parts.append(len(self._constraints))
            self.constrain(name, output)
        self._interval_blocks.append((tuple(names), function, z, tuple(parts)))

    def constrain_columns(self, name: str, expression, lower=0.0, upper=0.0) -> None:
        """Rows ``lower ≤ expression ≤ upper`` as :meth:`constrain`, where column k of the (rows × M) ``expression``
        is meant to be one function of its own decision variables for every k: a condition at each grid node, such
        as the ground reaction there, whose second derivatives through the dynamics are costly in the flat graph.

        :meth:`build` checks that it is (each column, its variables renamed alike, serializes to the same function)
        and then gives the NLP these rows' per-column structure (:class:`IntervalBlock`), so their derivatives come
        from one compiled function instead of the flat graph. Columns that are not one function stay plain rows:
        the same constraints either way."""
        expression = ca.SX(expression)
        self.constrain(name, expression, lower, upper)
        self._column_blocks.append((name, expression, len(self._constraints) - 1))

    def build(self, parameters: ca.SX, objective: ca.SX) -> NLP:
        x, lbx, ubx, variable_blocks, _ = _stack(self._variables, in_parts=False)
        g, lbg, ubg, constraint_blocks, part_rows = _stack(self._constraints, in_parts=True)
        interval_blocks = tuple(_interval_block(x, names, function, z, [part_rows[part] for part in parts])
                                for names, function, z, parts in self._interval_blocks)
        position = {x[i].element_hash(): i for i in range(x.numel())} if self._column_blocks else {}
        for name, expression, part in self._column_blocks:
            columns = _column_function(position, parameters, name, expression)
            if columns is not None:
                function, z = columns
                interval_blocks += (_interval_block(x, (name,), function, z, [part_rows[part]]),)
        return NLP(x=x, p=parameters, f=objective, g=g, lbx=lbx, ubx=ubx, lbg=lbg, ubg=ubg,
                   variable_blocks=variable_blocks, constraint_blocks=constraint_blocks,
                   interval_blocks=interval_blocks,
                   variable_shapes={name: symbol.shape for name, symbol, _, _ in self._variables})


def _interval_block(x: ca.SX, names: tuple[str, ...], function: ca.Function, z: ca.SX,
                    rows: list[slice]) -> IntervalBlock:
    """Locate an interval block's variables in x (each z entry is one of x's symbols); ``rows`` are its outputs'
    rows in g."""
    flat = ca.vec(z)
    if not all(flat[i].is_symbolic() for i in range(flat.numel())):
        raise ValueError(f"interval block {names}: every entry of its variables must be a decision-variable symbol")
    found, cols = ca.jacobian(flat, x).sparsity().get_triplet()
    if sorted(found) != list(range(flat.numel())):
        raise ValueError(f"interval block {names}: its variables are not all among the NLP's decision variables")
    index = np.empty(z.numel(), dtype=int)
    index[np.asarray(found)] = cols
    n_intervals = z.shape[1]
    index = index.reshape(z.shape[0], n_intervals, order="F")
    if any(len(set(column)) < len(column) for column in index.T):
        # The Hessian is folded entry by entry into the global triangle, which is exact only for distinct variables.
        raise ValueError(f"interval block {names}: a variable appears twice in one interval's variables")
    block_rows = tuple(np.arange(part.start, part.stop).reshape(-1, n_intervals, order="F") for part in rows)
    return IntervalBlock(function, index, block_rows)


def _column_function(position: dict[int, int], parameters: ca.SX, name: str,
                     expression: ca.SX) -> tuple[ca.Function, ca.SX] | None:
    """(f, z) with column k of ``expression`` = f(z[:, k], p) for every k, z's column k being the decision variables
    column k depends on, in x's order; ``None`` when the columns are not one such function.

    The test is exact: each column becomes a function of stand-in symbols for its own variables, and every
    column's function must serialize as the first one does, operation for operation."""
    n_columns = expression.shape[1]
    own = []
    for k in range(n_columns):
        symbols = [s for s in ca.symvar(expression[:, k]) if s.element_hash() in position]
        own.append(ca.vertcat(*sorted(symbols, key=lambda s: position[s.element_hash()])))
    n_z = own[0].numel() if own else 0
    if n_z == 0 or any(z.numel() != n_z for z in own):
        return None
    stand_in = ca.SX.sym("z", n_z)
    first = None
    for k, z in enumerate(own):
        function = ca.Function(name, [stand_in, parameters], [ca.substitute(expression[:, k], z, stand_in)])
        if first is None:
            first, reference = function, function.serialize()
        elif function.serialize() != reference:
            return None
    return first, ca.horzcat(*own)


def _expand(bound, shape: tuple[int, int]) -> np.ndarray:
    """Scalar, per-row (length rows) or full bounds, flattened column-major like ``ca.vec``."""
    rows, cols = shape
    bound = np.asarray(bound, dtype=float)
    if bound.ndim == 1 and bound.size == rows:
        bound = np.repeat(bound[:, None], cols, axis=1)
    return np.broadcast_to(bound, shape).flatten(order="F")


def _stack(blocks, in_parts: bool):
    """Blocks stacked in declaration order: (vector, lower, upper, name → slice, each declaration's slice).

    With ``in_parts``, a name declared in consecutive parts is one block; any other repeated name is an error."""
    if not blocks:
        return ca.SX(0, 1), np.zeros(0), np.zeros(0), {}, []
    expressions, lower, upper, names, parts, start, previous = [], [], [], {}, [], 0, None
    for name, expression, lo, hi in blocks:
        flat = ca.vec(expression)
        n = flat.numel()
        if name in names and not (in_parts and name == previous):
            raise ValueError(f"NLP block {name!r} declared twice" +
                             (" apart: declare a block's parts one after another" if in_parts else ""))
        names[name] = slice(names[name].start if name in names else start, start + n)
        parts.append(slice(start, start + n))
        start += n
        previous = name
        expressions.append(flat)
        lower.append(lo)
        upper.append(hi)
    return ca.vertcat(*expressions), np.concatenate(lower), np.concatenate(upper), names, parts
