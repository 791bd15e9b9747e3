"""How much memory a case needs, estimated before it runs.

A size that cannot fit (``N = [100000]`` grew a worker to 7.6 GB in 90 s, still building) is refused when the suite
loads, or when ``gaitbench solve`` starts, instead of swapping or being killed hours later. The estimate is a law
fitted to measurements of one worker walking forward steps with IPOPT (``benchmarks/memory.py``; the numbers are in
docs/performance.md, "Memory"): the resident memory of the process once everything is imported, plus what the
walk's NLPs and their IPOPT solvers add, which grows linearly in N for a strategy that holds one NLP per step (in
N·steps for whole-walk, whose one NLP holds them all) and quadratically for decrease-and-conquer, whose N−3
sectional NLPs of 3 … N−1 nodes it keeps together.

The limit is the memory available on this machine (``psutil``), or :data:`MEMORY_LIMIT_ENV` where the cases run
elsewhere (a Dask cluster) or should stay under a cap.
"""

from __future__ import annotations

import math
import os
import re
from dataclasses import dataclass

MEMORY_LIMIT_ENV = "GAITBENCH_MEMORY_LIMIT"
"""A size (``64G``, ``512M``, or bytes) that replaces the available memory as the limit a case must fit in."""

BASE_MB = 150.0
"""A worker once gaitbench, CasADi and the plugins are imported, before it builds anything: 145–150 MB measured
(benchmarks/results/memory.jsonl)."""


@dataclass(frozen=True)
class MemoryLaw:
    """What a case's NLPs and their solvers add to :data:`BASE_MB`, in MB: a + b·n + c·n², n their node count."""

    constant_mb: float
    linear_mb: float
    quadratic_mb: float = 0.0

    def growth_mb(self, nodes: int) -> float:
        return self.constant_mb + self.linear_mb * nodes + self.quadratic_mb * nodes * nodes

    def describe(self) -> str:
        """``150 MB + 20 MB + 0.129 MB × N`` (with ``+ c MB × N²`` when quadratic)."""
        text = f"{BASE_MB:.0f} MB + {self.constant_mb:.3g} MB + {self.linear_mb:.3g} MB × N"
        return text + (f" + {self.quadratic_mb:.3g} MB × N²" if self.quadratic_mb else "")


LARGE_SOLVE_MB = {"hermite-simpson": 1.39e-5, "dmoc": 7.83e-6, "trapezoidal": 1.39e-5}
"""c of the c·n² that large step solves peak above the linear law fitted at N ≤ 400, by transcription: fitted to
one-phase walks at N = 1000 and 2000 (HS) and 1000, 1500, 2000 (DMOC). Large solves take longer, and their peak is
no longer the memory the walk ends with (HS N = 2000: 486 MB peak, 421 MB at the end). Trapezoidal was not measured
there: HS's, the larger."""

LAWS: dict[str, dict[str, MemoryLaw]] = {
    "one-phase": {
        "hermite-simpson": MemoryLaw(20.0, 0.129, LARGE_SOLVE_MB["hermite-simpson"]),
        "dmoc": MemoryLaw(17.9, 0.118, LARGE_SOLVE_MB["dmoc"]),
        "trapezoidal": MemoryLaw(11.7, 0.347, LARGE_SOLVE_MB["trapezoidal"]),
    },
    "warm-start": {
        "hermite-simpson": MemoryLaw(18.5, 0.256, LARGE_SOLVE_MB["hermite-simpson"]),
        "dmoc": MemoryLaw(19.2, 0.220, LARGE_SOLVE_MB["dmoc"]),
        "trapezoidal": MemoryLaw(12.4, 0.644, LARGE_SOLVE_MB["trapezoidal"]),
    },
    "decrease-and-conquer": {
        "hermite-simpson": MemoryLaw(17.2, 1.96, 0.0555),
        "dmoc": MemoryLaw(12.2, 2.32, 0.0515),
        "trapezoidal": MemoryLaw(16.6, 1.85, 0.153),
    },
    "whole-walk": {
        "hermite-simpson": MemoryLaw(9.1, 2.15, LARGE_SOLVE_MB["hermite-simpson"]),
        "dmoc": MemoryLaw(12.5, 1.05, LARGE_SOLVE_MB["dmoc"]),
        "trapezoidal": MemoryLaw(16.6, 0.255, LARGE_SOLVE_MB["trapezoidal"]),
    },
}
"""What each strategy's NLPs and their IPOPT solvers add to :data:`BASE_MB`, by transcription, n = N (N·steps for
whole-walk). a and b are fitted by least squares (``benchmarks/memory.py --fit``) to the peak resident memory of
walks of the forward experiment with IPOPT, 1 step (whole-walk: 2, 4 or 8): one-phase and warm-start at N = 50, 100,
200, 400, whole-walk at N·steps = 100, 200, 400, 800 (residuals within 6 %), with :data:`LARGE_SOLVE_MB` as c;
decrease-and-conquer's a, b, c at N = 20, 40, 60, 80 (residuals within 1.1 %; checked at N = 100, within 1 %), its
quadratic term being its N−3 sectional NLPs. Source: the rows of ``benchmarks/results/memory.jsonl``, each with the
gaitbench commit it was measured at (HS and trapezoidal at ff1d38c, DMOC after its cost rule changed; CasADi 3.8.2
with its IPOPT 3.14 and MUMPS, Linux x86-64), tabled in docs/performance.md, "Memory"."""

WHOLE_WALK = "whole-walk"
"""The strategy whose one NLP chains every step, so that its size is N·steps."""

STAND_IN_STRATEGY = "warm-start"
"""A strategy that was not measured (a third-party one) is estimated as this one: one step NLP at a time, the more
of the two such strategies measured."""


@dataclass(frozen=True)
class MemoryEstimate:
    """A case's estimated peak resident memory and the law it came from."""

    mb: float
    law: MemoryLaw
    nodes: int
    """The n the law was evaluated at: N, or N·steps for whole-walk."""
    basis: str
    """Which measurement the law is: ``one-phase dmoc``, or a stand-in for a plugin that was not measured."""


def estimate_case_memory(transcription: str, strategy: str, n_nodes: int, steps: int = 1) -> MemoryEstimate:
    """The peak resident memory of a worker walking one case.

    A strategy that was not measured is estimated as :data:`STAND_IN_STRATEGY`; a transcription that was not
    measured with the measured one that needs the most at this size: conservative stand-ins.
    """
    measured = strategy if strategy in LAWS else STAND_IN_STRATEGY
    laws = LAWS[measured]
    nodes = n_nodes * steps if strategy == WHOLE_WALK else n_nodes
    if transcription in laws:
        law, basis = laws[transcription], f"{measured} {transcription}"
    else:
        stand_in = max(laws, key=lambda name: laws[name].growth_mb(nodes))
        law, basis = laws[stand_in], f"{measured} {stand_in}, the most of the measured transcriptions"
    if measured != strategy:
        basis += f", standing in for {strategy}"
    return MemoryEstimate(BASE_MB + law.growth_mb(nodes), law, nodes, basis)


@dataclass(frozen=True)
class MemoryLimit:
    mb: float
    source: str
    """``available on this machine`` or ``set by GAITBENCH_MEMORY_LIMIT=64G``."""


def memory_limit() -> MemoryLimit:
    """The memory a case must fit in: :data:`MEMORY_LIMIT_ENV` if set, else what this machine has available.

    Raises ``ValueError`` for a :data:`MEMORY_LIMIT_ENV` that is not a size.
    """
    given = os.environ.get(MEMORY_LIMIT_ENV, "").strip()
    if given:
        return MemoryLimit(parse_size_mb(given), f"set by {MEMORY_LIMIT_ENV}={given}")
    import psutil

    return MemoryLimit(psutil.virtual_memory().available / 2**20, "available on this machine")


def parse_size_mb(text: str) -> float:
    """``64G``, ``64GB``, ``512M``, ``1.5T`` or a number of bytes, in MB (2**20 bytes)."""
    match = re.fullmatch(r"\s*(\d+(?:\.\d+)?)\s*([kKmMgGtT]?)(?:i?[bB])?\s*", text)
    if not match or float(match.group(1)) <= 0:
        raise ValueError(f"{MEMORY_LIMIT_ENV}={text!r} is not a size; expected e.g. 64G, 512M or a number of bytes")
    scale = {"": 2**-20, "k": 2**-10, "m": 1, "g": 2**10, "t": 2**20}[match.group(2).lower()]
    return float(match.group(1)) * scale


def largest_fitting_nodes(transcription: str, strategy: str, steps: int, limit_mb: float) -> int:
    """The largest N whose estimate stays within ``limit_mb`` (2 when none does: below the smallest step)."""
    low, high = 2, 3
    while estimate_case_memory(transcription, strategy, high, steps).mb <= limit_mb:
        low, high = high, high * 2
    while high - low > 1:
        middle = (low + high) // 2
        if estimate_case_memory(transcription, strategy, middle, steps).mb <= limit_mb:
            low = middle
        else:
            high = middle
    return low


def memory_problem(transcription: str, strategy: str, n_nodes: int, steps: int, what: str,
                   limit: MemoryLimit | None = None) -> str | None:
    """Why ``n_nodes`` cannot fit, or None if it can: the estimate, its law, the limit and how to fix it.

    ``what`` names the case in the message (``one-phase dmoc ipopt``).
    """
    limit = limit or memory_limit()
    estimate = estimate_case_memory(transcription, strategy, n_nodes, steps)
    if estimate.mb <= limit.mb:
        return None
    fits = largest_fitting_nodes(transcription, strategy, steps, limit.mb)
    law = estimate.law.describe() + (f", N × {steps} steps" if strategy == WHOLE_WALK else "")
    return (f"N = {n_nodes} does not fit in memory: {what} needs about {_size(estimate.mb)} per case (measured law "
            f"for {estimate.basis}: {law}; docs/performance.md, \"Memory\"), more than the {_size(limit.mb)} "
            f"{limit.source}. Lower N to at most {fits}, or, if the cases run where more memory is available, set "
            f"{MEMORY_LIMIT_ENV} to that size (e.g. {MEMORY_LIMIT_ENV}={_suggest(estimate.mb)})")


def jobs_that_fit(estimates_mb: list[float], jobs: int, limit: MemoryLimit | None = None) -> tuple[int, str | None]:
    """How many of ``jobs`` workers on this machine can run the cases whose estimates are ``estimates_mb``, and why
    fewer when fewer (None when all ``jobs`` fit).

    A run starts its cases largest N first, so its ``jobs`` largest cases run together; each case alone fits (a
    suite with one that does not is refused when it loads), so at least one worker always does.
    """
    largest = sorted(estimates_mb, reverse=True)[:jobs]
    if len(largest) < 2:
        return jobs, None
    limit = limit or memory_limit()
    if sum(largest) <= limit.mb:
        return jobs, None
    fitting = max([count for count in range(1, len(largest) + 1) if sum(largest[:count]) <= limit.mb], default=1)
    return fitting, (f"{jobs} workers would start the {len(largest)} largest cases together (largest N first), which "
                     f"need about {_size(sum(largest))} together, more than the {_size(limit.mb)} {limit.source}; "
                     f"{fitting} fit (set {MEMORY_LIMIT_ENV} if the workers run where more memory is available)")


def _size(mb: float) -> str:
    return f"{mb / 1024:.1f} GB" if mb >= 1024 else f"{mb:.0f} MB"


def _suggest(mb: float) -> str:
    return f"{math.ceil(mb / 1024)}G"
