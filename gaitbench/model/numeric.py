"""Fast repeated numeric evaluation of CasADi functions from Python.

Calling a ``casadi.Function`` with NumPy arrays converts every argument to a DM and every result back, about
0.1 ms per call whatever the arithmetic; an ODE right-hand side called tens of thousands of times per
re-simulation spends nearly all its time there. :class:`NumericFunction` evaluates through the function's
``buffer()`` interface instead: inputs and outputs are fixed NumPy arrays the function reads and writes in place,
about 8 µs per call, with the same arithmetic (the same CasADi virtual machine), hence the same numbers.
"""

from __future__ import annotations

import casadi as ca
import numpy as np


class NumericFunction:
    """A dense CasADi function evaluated on floats; outputs are fresh arrays (vectors flat, matrices 2-D).

    Not thread-safe: one instance owns one set of buffers.
    """

    def __init__(self, function: ca.Function) -> None:
        if not all(function.sparsity_in(i).is_dense() for i in range(function.n_in())):
            raise ValueError(f"{function.name()}: sparse inputs are not supported")
        if not all(function.sparsity_out(i).is_dense() for i in range(function.n_out())):
            function = _densified(function)
        self.name = function.name()
        self._buffer, self._evaluate = function.buffer()
        self._inputs = [np.zeros(function.nnz_in(i)) for i in range(function.n_in())]
        self._outputs = [np.zeros(function.nnz_out(i)) for i in range(function.n_out())]
        self._shapes = [function.size_out(i) for i in range(function.n_out())]
        for i, array in enumerate(self._inputs):
            self._buffer.set_arg(i, memoryview(array))
        for i, array in enumerate(self._outputs):
            self._buffer.set_res(i, memoryview(array))

    def __call__(self, *args) -> np.ndarray | tuple[np.ndarray, ...]:
        """The outputs at ``args`` (one per input, anything ``np.ravel`` takes; matrices column-major)."""
        if len(args) != len(self._inputs):
            raise TypeError(f"{self.name} takes {len(self._inputs)} arguments, {len(args)} given")
        for target, value in zip(self._inputs, args, strict=True):
            target[:] = np.ravel(value, order="F")
        self._evaluate()
        results = tuple(_shaped(output, shape) for output, shape in zip(self._outputs, self._shapes, strict=True))
        return results[0] if len(results) == 1 else results


def _densified(function: ca.Function) -> ca.Function:
    """The same function with structural zeros of its outputs stored, so every output is a full array."""
    inputs = function.sx_in() if function.is_a("SXFunction") else function.mx_in()
    outputs = [ca.densify(output) for output in function.call(inputs)]
    return ca.Function(function.name(), inputs, outputs)


def _shaped(values: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    if 1 in shape:
        return values.copy()
    return values.reshape(shape, order="F").copy()
