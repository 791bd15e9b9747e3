"""Dolan–Moré performance profiles: for each solver, the share of problems it solves within τ times the best.

Dolan and Moré, "Benchmarking optimization software with performance profiles", Math. Program. 91 (2002). Each
solver has one measure per problem (a solve's time, a verified COT: positive, lower is better) or none where it
failed. The ratio r_ps = m_ps / min_s m_ps is infinite where s failed; a problem no solver solved stays in the
count with every ratio infinite, so that a profile's height at τ → ∞ is the share of all problems the solver
solved. The profile is ρ_s(τ) = |{p : r_ps ≤ τ}| / |P|: ρ_s(1) is the share on which s was (jointly) best.
"""

from __future__ import annotations

import io
import math
from collections.abc import Mapping, Sequence

import numpy as np


def performance_ratios(measures: Mapping[str, Sequence[float | None]]) -> dict[str, np.ndarray]:
    """Each solver's ratio to the best measure on each problem; ``measures[solver][p]`` is None, NaN or ∞ where the
    solver failed on problem p. Every solver must have one entry per problem."""
    if not measures:
        return {}
    sizes = {len(values) for values in measures.values()}
    if len(sizes) != 1:
        raise ValueError(f"every solver needs one measure per problem; got {dict(_sizes(measures))}")
    table = np.array([[math.inf if value is None or not math.isfinite(value) else float(value) for value in values]
                      for values in measures.values()], dtype=float).reshape(len(measures), sizes.pop())
    if (table <= 0).any():
        solver, problem = np.argwhere(table <= 0)[0]
        raise ValueError(f"measures must be positive: solver {list(measures)[solver]!r}, problem {problem} has "
                         f"{table[solver, problem]:g}")
    best = table.min(axis=0)
    with np.errstate(invalid="ignore"):
        ratios = np.where(np.isfinite(table), table / best, math.inf)
    return dict(zip(measures, ratios, strict=True))


def _sizes(measures: Mapping[str, Sequence[float | None]]):
    return ((solver, len(values)) for solver, values in measures.items())


def profile(ratios: np.ndarray, taus: Sequence[float]) -> np.ndarray:
    """ρ(τ) for each τ: the share of problems whose ratio is at most τ."""
    ratios = np.asarray(ratios, dtype=float)
    if ratios.size == 0:
        return np.zeros(len(taus))
    return np.array([(ratios <= tau).mean() for tau in taus])


def largest_ratio(ratios: Mapping[str, np.ndarray]) -> float:
    """The largest finite ratio of any solver (1 when there is none): where every profile has reached its height."""
    finite = [float(value) for values in ratios.values() for value in values if math.isfinite(value)]
    return max(finite, default=1.0)


def _ticks(right: float) -> list[float]:
    """τ ticks up to ``right``: powers of two, and below 4 the fine ratios that tell near-ties apart."""
    powers = [2.0 ** k for k in range(int(math.log2(right)) + 1)]
    fine = [tick for tick in (1.05, 1.1, 1.25, 1.5) if tick <= right] if right < 4 else []
    return sorted({*powers, *fine})


def profile_svg(panels: Mapping[str, Mapping[str, np.ndarray]], title: str = "") -> str:
    """A figure of one panel per entry of ``panels`` (its x-axis label → each solver's ratios): every solver's
    profile as a step curve against τ on a log2 axis, from 1 to just past the panel's largest finite ratio; the SVG
    text."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    solvers = sorted({solver for ratios in panels.values() for solver in ratios})
    colors = dict(zip(solvers, plt.get_cmap("tab10").colors, strict=False))
    styles = dict(zip(solvers, [(0, ()), (0, (5, 2)), (0, (5, 2, 1, 2)), (0, (1, 1.5))] * 3, strict=False))
    with plt.rc_context({"svg.fonttype": "none", "svg.hashsalt": "gaitbench", "font.size": 9, "axes.grid": True,
                         "grid.alpha": 0.3}):
        figure, axes = plt.subplots(1, len(panels), figsize=(5.2 * len(panels), 4.0), squeeze=False)
        for axis, (label, ratios) in zip(axes[0], panels.items(), strict=True):
            right = max(2.0, 1.1 * largest_ratio(ratios))
            for solver, values in ratios.items():
                steps = np.sort(values[np.isfinite(values)])
                taus = np.concatenate([[1.0], steps, [right]])
                axis.step(taus, profile(values, taus), where="post", label=solver, color=colors[solver],
                          linestyle=styles[solver], linewidth=1.6)
            axis.set_xscale("log", base=2)
            axis.set_xlim(1.0, right)
            axis.set_xticks(_ticks(right), [f"{tick:g}" for tick in _ticks(right)])
            axis.minorticks_off()
            axis.set_ylim(0.0, 1.02)
            axis.set_xlabel(label)
            axis.set_ylabel("share of problems solved within τ × best")
        handles, labels = axes[0][0].get_legend_handles_labels()
        figure.legend(handles, labels, loc="lower center", ncol=min(len(solvers), 4), fontsize=8, frameon=False)
        if title:
            figure.suptitle(title)
        rows_of_legend = -(-len(solvers) // 4)
        figure.tight_layout(rect=(0, 0.05 * rows_of_legend + 0.02, 1, 1))
        buffer = io.StringIO()
        figure.savefig(buffer, format="svg", metadata={"Date": None})
        plt.close(figure)
    return buffer.getvalue()
