"""How far a report's figures can be trusted: each cell's spread over neighbouring N, savings as a paired statistic
over N with a bootstrap confidence interval, and the consistency check that flags finer grids far from the coarser.

A minimum over N, and a saving computed from two minima, say as much about the optimizer's path as about the
methods: a finer grid of the same problem can land in a local optimum several times dearer. These statistics read
every N instead of one. They take the tables of :mod:`gaitbench.reports.tables` (and the prepared cases of
:mod:`gaitbench.reports.case_frame`); column names are documented in docs/reports.md.
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable

import numpy as np
import pandas as pd

from gaitbench.reports import thesis_values
from gaitbench.reports.case_frame import sweep_cases

SPREAD_HALF_WIDTH = 10
"""Δ of the spread window: a cell's spread is over every complete walk at N − Δ … N + Δ (the thesis's grid step)."""
CONSISTENCY_BAND = (40, 90)
"""The coarser N whose median ACOT is a method's reference in the consistency check."""
CONSISTENCY_TOLERANCE = 0.15
"""A finer N's ACOT more than this fraction away from the reference median is an exception."""
OWN_STEPS_RTOL = 1e-6
"""How closely a walk's stored per-step COTs must average to its ACOT to be taken as its own."""
BOOTSTRAP_RESAMPLES = 10_000
BOOTSTRAP_SEED = 0
CONFIDENCE = 0.95
MIN_PAIRS_FOR_CI = 6
"""Fewer paired savings than this get no interval: a percentile bootstrap over a few values only restates them. Up
to five, the median's "95 %" interval is their range (a resampled median of five is the smallest value in about
6 % of the resamples, more than the 2.5 % tail)."""

SPREAD_COLUMNS = ["experiment", "method", "N", "acot", "spread_walks", "spread_low", "spread_high", "spread_median",
                  "spread_percent"]
PAIRED_SAVINGS_COLUMNS = ["experiment", "method", "baseline", "baseline_kind", "pairs", "median_percent",
                          "median_ci_low", "median_ci_high", "mean_percent", "mean_ci_low", "mean_ci_high",
                          "min_vs_min_percent", "published_min_vs_min_percent"]
CONSISTENCY_COLUMNS = ["experiment", "method", "N", "acot", "reference_median", "reference_N", "ratio",
                       "deviation_percent", "isolated", "dearest_step", "dearest_step_excess", "ground_at_dearest_step",
                       "case_keys"]


# --- spread over neighbouring N ----------------------------------------------------------------------------------

def acot_spread(df: pd.DataFrame, acot: pd.DataFrame, half_width: int = SPREAD_HALF_WIDTH) -> pd.DataFrame:
    """Per experiment × method × N of the ACOT table: the lowest, highest and median verified ACOT of every complete
    walk at N − ``half_width`` … N + ``half_width`` (repetitions at one N included; ``half_width = 0`` gives the
    spread over repetitions alone), and that range as a percentage of the median."""
    if acot.empty:
        return pd.DataFrame(columns=SPREAD_COLUMNS)
    sweep = sweep_cases(df)
    walks = sweep[sweep["complete"].astype(bool) & sweep["acot"].notna()]
    by_method = {key: (group["N"].to_numpy(float), group["acot"].to_numpy(float))
                 for key, group in walks.groupby(["experiment", "method"], sort=False)}
    rows = []
    for row in acot.itertuples():
        n_values, values = by_method.get((row.experiment, row.method), (np.empty(0), np.empty(0)))
        window = values[np.abs(n_values - row.N) <= half_width]
        spread = {"spread_walks": len(window), "spread_low": math.nan, "spread_high": math.nan,
                  "spread_median": math.nan, "spread_percent": math.nan}
        if len(window):
            median = float(np.median(window))
            spread |= {"spread_low": float(window.min()), "spread_high": float(window.max()), "spread_median": median,
                       "spread_percent": 100 * float(window.max() - window.min()) / median}
        rows.append({"experiment": row.experiment, "method": row.method, "N": int(row.N), "acot": row.acot} | spread)
    return pd.DataFrame(rows, columns=SPREAD_COLUMNS)


# --- paired savings with a bootstrap confidence interval ---------------------------------------------------------

def bootstrap_ci(values, statistic: Callable[[np.ndarray], np.ndarray] = np.median,
                 resamples: int = BOOTSTRAP_RESAMPLES, confidence: float = CONFIDENCE,
                 seed: int = BOOTSTRAP_SEED) -> tuple[float, float]:
    """The percentile bootstrap interval of ``statistic`` over ``values``: ``resamples`` draws of len(values) values
    with replacement (numpy's default generator seeded with ``seed``, so a report is reproducible). ``statistic``
    takes an array of resamples and an ``axis`` keyword (np.median, np.mean). (NaN, NaN) for no values."""
    values = np.asarray(values, dtype=float)
    if values.size == 0:
        return math.nan, math.nan
    draws = np.random.default_rng(seed).integers(0, values.size, size=(resamples, values.size))
    estimates = statistic(values[draws], axis=1)
    tail = 100 * (1 - confidence) / 2
    low, high = np.percentile(estimates, [tail, 100 - tail])
    return float(low), float(high)


def paired_savings(savings: pd.DataFrame, minima: pd.DataFrame) -> pd.DataFrame:
    """Per D&C method × baseline: the savings at every N where both have a complete verified walk, summarised as
    median and mean with their bootstrap 95 % intervals over N (from :data:`MIN_PAIRS_FOR_CI` pairs on), beside the
    saving from the two minima (ours, and the thesis's from its published minima).

    The median is the headline: one N stuck in a local optimum moves a single saving by hundreds of percent, which
    moves the mean but not the median. The mean is kept beside it; where the two disagree, outliers decide the mean.
    """
    if savings.empty:
        return pd.DataFrame(columns=PAIRED_SAVINGS_COLUMNS)
    minimum = {(r.experiment, r.method): r.min_acot for r in minima.itertuples()}
    thesis = {(r.experiment, r.method): r.thesis_method for r in minima.itertuples()}
    rows = []
    for (experiment, method, baseline, kind), group in savings.groupby(
            ["experiment", "method", "baseline", "baseline_kind"], sort=False):
        paired = group["savings_percent"].to_numpy(float)
        paired = paired[np.isfinite(paired)]
        row = {"experiment": experiment, "method": method, "baseline": baseline, "baseline_kind": kind,
               "pairs": len(paired), "median_percent": math.nan, "median_ci_low": math.nan,
               "median_ci_high": math.nan, "mean_percent": math.nan, "mean_ci_low": math.nan,
               "mean_ci_high": math.nan,
               "min_vs_min_percent": _saving(minimum.get((experiment, baseline)), minimum.get((experiment, method))),
               "published_min_vs_min_percent": _published_saving(experiment, thesis.get((experiment, method)),
                                                                 thesis.get((experiment, baseline)))}
        if len(paired):
            row |= {"median_percent": float(np.median(paired)), "mean_percent": float(np.mean(paired))}
        if len(paired) >= MIN_PAIRS_FOR_CI:
            median_ci, mean_ci = bootstrap_ci(paired, np.median), bootstrap_ci(paired, np.mean)
            row |= {"median_ci_low": median_ci[0], "median_ci_high": median_ci[1],
                    "mean_ci_low": mean_ci[0], "mean_ci_high": mean_ci[1]}
        rows.append(row)
    return pd.DataFrame(rows, columns=PAIRED_SAVINGS_COLUMNS)


def _saving(baseline: float | None, candidate: float | None) -> float:
    """100 (baseline − candidate) / baseline, NaN where either is missing or the baseline is not positive."""
    if baseline is None or candidate is None or not (math.isfinite(baseline) and math.isfinite(candidate)) \
            or baseline <= 0:
        return math.nan
    return 100 * (baseline - candidate) / baseline


def _published_saving(experiment: str, method: str | None, baseline: str | None) -> float:
    """The thesis's minimum-against-minimum saving, from its published minimum ACOT of the two methods."""
    published = thesis_values.MINIMUM_ACOT.get(experiment, {})
    if method not in published or baseline not in published:
        return math.nan
    return _saving(published[baseline][0], published[method][0])


# --- consistency over N ------------------------------------------------------------------------------------------

def consistency_exceptions(acot: pd.DataFrame, df: pd.DataFrame | None = None,
                           band: tuple[int, int] = CONSISTENCY_BAND, tolerance: float = CONSISTENCY_TOLERANCE,
                           half_width: int = SPREAD_HALF_WIDTH,
                           ground: Callable[[str, int], str | None] | None = None) -> pd.DataFrame:
    """Every cell finer than ``band`` (N > band[1]) whose ACOT lies more than ``tolerance`` (a fraction) from the
    median ACOT of its experiment and method over the N in ``band``; a finer grid of the same problem should not
    cost much more or less than the coarser ones.

    ``isolated`` is true when every other cell of the method within ``half_width`` of N lies within the tolerance: a
    single N that fell into another optimum, rather than a drift over a range of N. From the prepared cases ``df``,
    when given: ``dearest_step``, the step whose COT lies furthest above the median COT of the same step over the
    band's walks, and by how much (``dearest_step_excess``), which locates the cost; and ``case_keys``, the complete
    walks of the cell: the cases to solve again. ``ground(experiment, step)``, when given, says how the ground
    bends under that step's stance foot (``ground_at_dearest_step``: a dip is where fine grids charge a detour that
    coarse ones step over). A method without a complete walk in the band has no reference and is not checked; a cell
    without a complete walk has no ACOT.
    """
    low, high = band
    rows = []
    keys = _cell_keys(df) if df is not None else {}
    steps = _cell_steps(df) if df is not None else {}
    for (experiment, method), group in acot.groupby(["experiment", "method"], sort=False):
        reference = group[(group["N"] >= low) & (group["N"] <= high)]["acot"].dropna()
        if reference.empty:
            continue
        median = float(reference.median())
        ratios = (group["acot"] / median).to_numpy(float)
        outside = np.round(np.abs(ratios - 1), 12) > tolerance  # rounded: as far above the median as below
        n_values = group["N"].to_numpy(int)
        for i in np.flatnonzero(outside & (n_values > high)):
            near = (np.abs(n_values - n_values[i]) <= half_width) & (np.arange(len(n_values)) != i)
            neighbours = ratios[near]
            neighbours = neighbours[np.isfinite(neighbours)]
            dearest, excess = _dearest_step(steps, experiment, method, int(n_values[i]), band)
            rows.append({"experiment": experiment, "method": method, "N": int(n_values[i]),
                         "acot": float(group["acot"].iloc[i]), "reference_median": median,
                         "reference_N": f"{low}–{high}", "ratio": float(ratios[i]),
                         "deviation_percent": 100 * float(ratios[i] - 1),
                         "isolated": (bool((np.abs(neighbours - 1) <= tolerance).all()) if len(neighbours)
                                      else None),  # no verified neighbour: neither isolated nor a drift
                         "dearest_step": dearest, "dearest_step_excess": excess,
                         "ground_at_dearest_step": ground(experiment, dearest) if ground and dearest else None,
                         "case_keys": " ".join(keys.get((experiment, method, int(n_values[i])), []))})
    table = pd.DataFrame(rows, columns=CONSISTENCY_COLUMNS)
    table["dearest_step"] = table["dearest_step"].astype("Int64")
    return table


def _cell_steps(df: pd.DataFrame) -> dict[tuple[str, str, int], np.ndarray]:
    """Each experiment × method × N's per-step COT, the mean over its complete walks whose stored per-step COTs are
    the walk's own: those that average to its ACOT. Decrease & Conquer rows stored before its walks chained verified
    motions hold the patchwork's claims there, which do not, and are left out."""
    sweep = sweep_cases(df)
    walks = sweep[sweep["complete"].astype(bool) & sweep["acot"].notna()]
    cells = {}
    for (experiment, method, n), group in walks.groupby(["experiment", "method", "N"], sort=False):
        per_walk = [cots for cots, acot in zip(map(_floats, group["cot_steps"]), group["acot"], strict=True)
                    if len(cots) and math.isclose(float(np.mean(cots)), acot, rel_tol=OWN_STEPS_RTOL)]
        if per_walk and all(len(cots) == len(per_walk[0]) for cots in per_walk):
            cells[(experiment, method, int(n))] = np.mean(per_walk, axis=0)
    return cells


def _floats(cot_steps) -> np.ndarray:
    """A row's per-step COTs; empty where the stored value is not a list (a malformed row is left out, not fatal)."""
    try:
        values = json.loads(cot_steps) if isinstance(cot_steps, str) else cot_steps
    except json.JSONDecodeError:
        return np.empty(0)
    return np.array([math.nan if v is None else float(v) for v in values], float) if isinstance(values, list) \
        else np.empty(0)


def _dearest_step(steps: dict[tuple[str, str, int], np.ndarray], experiment: str, method: str, n: int,
                  band: tuple[int, int]) -> tuple[int | None, float]:
    """The step (from 1) whose COT at ``n`` lies furthest above the same step's median over the band's N, and by
    how much; (None, NaN) where the cell or the band has no per-step COTs of the same walk length."""
    cell = steps.get((experiment, method, n))
    reference = [cots for (e, m, k), cots in steps.items() if (e, m) == (experiment, method)
                 and band[0] <= k <= band[1] and cell is not None and len(cots) == len(cell)]
    if cell is None or not reference:
        return None, math.nan
    excess = cell - np.nanmedian(reference, axis=0)
    if not np.isfinite(excess).any():
        return None, math.nan
    step = int(np.nanargmax(excess))
    return step + 1, float(excess[step])


def _cell_keys(df: pd.DataFrame) -> dict[tuple[str, str, int], list[str]]:
    """The case keys of the verified walks of each experiment × method × N: those whose ACOTs the cell averages."""
    sweep = sweep_cases(df)
    ranked = sweep[sweep["ranked"].astype(bool)] if not sweep.empty else sweep
    return {(experiment, method, int(n)): list(group["case_key"])
            for (experiment, method, n), group in ranked.groupby(["experiment", "method", "N"], sort=False)}


def inconsistent_keys(df: pd.DataFrame, acot: pd.DataFrame, band: tuple[int, int] = CONSISTENCY_BAND,
                      tolerance: float = CONSISTENCY_TOLERANCE) -> set[str]:
    """The case keys of every exception of :func:`consistency_exceptions`: the cases to solve again."""
    exceptions = consistency_exceptions(acot, df, band=band, tolerance=tolerance)
    return {key for keys in exceptions["case_keys"] for key in keys.split()}


PUBLISHED_SAVINGS_CI_COLUMNS = ["median_percent", "median_ci_low", "median_ci_high", "pairs", "min_vs_min_percent",
                                "published_min_vs_min_percent"]


def with_paired_savings(published: pd.DataFrame, paired: pd.DataFrame, info: pd.DataFrame) -> pd.DataFrame:
    """The published savings table (:func:`gaitbench.reports.tables.published_savings`) with our paired median
    saving, its bootstrap interval and the two minimum-against-minimum savings beside the thesis's quoted range."""
    thesis = {(r.experiment, r.method): r.thesis_method for r in info.itertuples()}
    by_comparison = {(r.experiment, f"{thesis.get((r.experiment, r.method))} vs "
                      f"{thesis.get((r.experiment, r.baseline))}"): r for r in paired.itertuples()}
    table = published.copy()
    for column in PUBLISHED_SAVINGS_CI_COLUMNS:
        table[column] = [getattr(by_comparison.get((experiment, comparison)), column, math.nan)
                         for experiment, comparison in zip(table["experiment"], table["comparison"], strict=True)]
    table["pairs"] = pd.to_numeric(table["pairs"], errors="coerce").astype("Int64")
    return table
