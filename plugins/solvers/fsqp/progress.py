"""What the phases of one FSQP solve share besides its options: the limits they stop at, the log of their iterations,
and the order in which the QP backends' settings are tried."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from gaitbench.solve.evaluation import Deadline
from gaitbench.solve.qp import RetryOrder
from gaitbench.solver_result import SolverStatus
from gaitbench_plugins.solvers.fsqp.outcome import IterationRecord


@dataclass
class Progress:
    """One solve's limits and log."""

    max_iterations: int
    time_limit_s: float | None
    deadline: Deadline
    print_level: int = 0
    log: list[IterationRecord] = field(default_factory=list)
    """The iterates of the solve, both phases, in order."""
    qp_order: RetryOrder = field(default_factory=RetryOrder)
    """Which settings each QP backend tries first (``qp.solve_qp``)."""

    def limit_reached(self, iteration: int) -> tuple[SolverStatus, str] | None:
        """The time or iteration limit with its message, once reached: checked first by every loop of the method."""
        if self.deadline.expired():
            return self.out_of_time()
        if iteration >= self.max_iterations:
            return SolverStatus.ITERATION_LIMIT, f"iteration limit of {self.max_iterations} reached"
        return None

    def out_of_time(self, where: str = "") -> tuple[SolverStatus, str]:
        """The time limit's status and message (``where``: the part of an iteration it stopped, if not its start)."""
        return SolverStatus.TIME_LIMIT, f"time limit of {self.time_limit_s} s reached{where}"

    def record(self, phase: str, iteration: int, merit: float, d0_norm: float, step: float, penalty: float,
               active: int, max_violation: float, direction: str, x: np.ndarray) -> None:
        """Log iteration ``iteration`` of ``phase`` in :attr:`log`, and print it at ``print_level ≥ 1``."""
        if self.print_level >= 1:
            if not self.log or self.log[-1].phase != phase:
                print(f"FSQP {phase} phase")
                label = "F_c" if phase == "main" else "½|c_I+|²"
                print(f"{'iter':>5} {label:>13} {'|d0|':>9} {'step':>9} {'c_k':>9} {'|J|':>5} {'max viol':>9}  dir")
            print(f"{iteration:>5} {merit:>13.6e} {d0_norm:>9.2e} {step:>9.2e} {penalty:>9.2e} {active:>5} "
                  f"{max_violation:>9.2e}  {direction}")
        self.log.append(IterationRecord(phase, iteration, merit, d0_norm, step, penalty, active, max_violation,
                                        direction, x.copy()))
