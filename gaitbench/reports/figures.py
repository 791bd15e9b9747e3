"""The report's figures, drawn with matplotlib (Agg backend) from the tables of :mod:`gaitbench.reports.tables`.

Every function returns a :class:`Figure` (an id, a title, a caption and the SVG text), or ``None`` when the data
for it are missing. The HTML reporter embeds the SVG (base64 ``<img>``) and writes it beside the page.
"""

from __future__ import annotations

import io
from dataclasses import dataclass

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402

from gaitbench.reports import thesis_values  # noqa: E402
from gaitbench.reports.statistics import SPREAD_HALF_WIDTH  # noqa: E402

plt.rcParams.update({"svg.fonttype": "none", "font.size": 9, "axes.grid": True, "grid.alpha": 0.3,
                     "figure.dpi": 100, "svg.hashsalt": "gaitbench"})

MINIMUM_COLOR = "red"


@dataclass
class Figure:
    id: str
    title: str
    caption: str
    svg: str

    @property
    def filename(self) -> str:
        return f"{self.id}.svg"


def subplots(*args, **kwargs):
    """``plt.subplots`` with the constrained layout, which makes room for a legend outside the axes."""
    return plt.subplots(*args, layout="constrained", **kwargs)


def legend_below(fig, ncol: int | None = None) -> None:
    """One legend for the whole figure, below its axes, their tick labels and axis labels: never on the data or a
    label. Entries of every axes, each label once, in order of appearance."""
    entries: dict[str, object] = {}
    for ax in fig.axes:
        for handle, label in zip(*ax.get_legend_handles_labels(), strict=True):
            if not label.startswith("_"):
                entries.setdefault(label, handle)
    if not entries:
        return
    longest = max(len(label) for label in entries)
    width = fig.get_figwidth()
    columns = ncol or max(1, min(len(entries), int(width * 12 // max(longest + 4, 1))))
    fig.legend(list(entries.values()), list(entries), loc="outside lower center", ncol=columns, fontsize=7,
               frameon=False)


def render(fig) -> str:
    """The figure as SVG text (text kept as text, so files stay small); closes the figure."""
    buffer = io.StringIO()
    fig.savefig(buffer, format="svg", bbox_inches="tight", metadata={"Date": None})
    plt.close(fig)
    return buffer.getvalue()


def slug(text: str) -> str:
    """An HTML-id-safe form of an experiment or method name."""
    out = "".join(ch if ch.isalnum() else "-" for ch in text.lower())
    while "--" in out:
        out = out.replace("--", "-")
    return out.strip("-") or "x"


def _thesis(experiment: str, role: str) -> str:
    name = thesis_values.figure(experiment, role)
    return f" Thesis counterpart: {name}." if name else ""


def _integer_n(ax) -> None:
    from matplotlib.ticker import MaxNLocator

    ax.xaxis.set_major_locator(MaxNLocator(integer=True))


def _by_method(data: pd.DataFrame) -> list[tuple[str, pd.DataFrame, str]]:
    """(method, its rows, its colour) in order of first appearance: one line per method in a figure."""
    methods = list(dict.fromkeys(data["method"]))
    colors = _colors(methods)
    return [(method, data[data["method"] == method], colors[method]) for method in methods]


def _colors(methods: list) -> dict:
    cycle = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    return {method: cycle[i % len(cycle)] for i, method in enumerate(methods)}


def acot_figure(acot: pd.DataFrame, experiment: str, spread: pd.DataFrame | None = None,
                half_width: int = SPREAD_HALF_WIDTH) -> Figure | None:
    """ACOT against N for every method, each method's minimum marked in red; D&C claims dashed. With ``spread``
    (:func:`gaitbench.reports.statistics.acot_spread`, computed with ``half_width``), a band per method from the
    lowest to the highest verified ACOT of its complete walks at N − half_width … N + half_width."""
    data = acot[acot["experiment"] == experiment]
    if data["acot"].notna().sum() == 0 and data["claimed_acot"].notna().sum() == 0:
        return None
    bands = None if spread is None else spread[spread["experiment"] == experiment]
    fig, ax = subplots(figsize=(7, 4))
    for method, rows, color in _by_method(data):
        best = rows[rows["is_minimum"]]
        lowest = "" if best.empty else f"; min {best['acot'].iloc[0]:.4f} at N = {int(best['N'].iloc[0])}"
        ax.plot(rows["N"], rows["acot"], "o-", color=color, label=f"{method} (verified{lowest})", ms=4)
        if bands is not None:
            band = bands[bands["method"] == method]
            ax.fill_between(band["N"], band["spread_low"], band["spread_high"], color=color, alpha=0.15, lw=0)
        if rows["claimed_acot"].notna().any():
            ax.plot(rows["N"], rows["claimed_acot"], "s--", color=color, alpha=0.7, ms=3,
                    label=f"{method} (claimed, patchwork)")
        if not best.empty:  # named in the legend: the minima often lie too close together for labels
            ax.plot(best["N"], best["acot"], "o", color=MINIMUM_COLOR, ms=9, mfc="none", mew=2)
    ax.plot([], [], "o", color=MINIMUM_COLOR, mfc="none", mew=2, label="minimum of each method")
    ax.set_xlabel("N (nodes per step)")
    _integer_n(ax)
    ax.set_ylabel("ACOT")
    ax.set_title(f"{experiment}: ACOT against N")
    legend_below(fig)
    band_text = "" if bands is None else (
        " Shaded: each method's spread, from the lowest to the highest verified ACOT of its complete walks at "
        f"N − {half_width} … N + {half_width} (repetitions included; acot_spread.csv): how far a figure moves between "
        "neighbouring grids of the same problem, i.e. with the optimizer's path rather than the method.")
    return Figure(f"fig-acot-{slug(experiment)}", f"ACOT against N: {experiment}",
                  "Average cost of transport of each method at each N, over its verified walks only (complete and "
                  "passing the whole-walk verification; dashed: the claimed ACOT of Decrease & Conquer's synthesized "
                  "trajectory). A gap: no verified walk at that N. Red circles: each method's minimum." + band_text
                  + _thesis(experiment, "acot"), render(fig))


def completion_figure(acot: pd.DataFrame, experiment: str) -> Figure | None:
    """The fraction of each method's walks that were complete, and that were also verified, against N: what the ACOT
    figure beside it rests on."""
    data = acot[acot["experiment"] == experiment]
    if data.empty:
        return None
    fig, ax = subplots(figsize=(7, 4))
    for method, rows, color in _by_method(data):
        cases = int(rows["cases"].sum())
        ax.plot(rows["N"], 100 * rows["completion_rate"], "o-", color=color, ms=4,
                label=f"{method}: complete ({int(rows['solved'].sum())} of {cases})")
        ax.plot(rows["N"], 100 * rows["verified"] / rows["cases"], "s--", color=color, ms=3,
                label=f"{method}: verified ({int(rows['verified'].sum())} of {cases})")
    ax.set_ylim(-5, 105)
    ax.set_xlabel("N (nodes per step)")
    _integer_n(ax)
    ax.set_ylabel("walks (%)")
    ax.set_title(f"{experiment}: complete and verified walks against N")
    legend_below(fig, ncol=2)
    return Figure(f"fig-completion-{slug(experiment)}", f"Completion rate against N: {experiment}",
                  "Solid: the share of each method's walks at each N that walked every requested step (complete); "
                  "dashed: the share that also passed the whole-walk verification (the legend counts both over all "
                  "N). Only the verified walks enter the ACOT beside it; why the others stopped is in the stop-cause "
                  "table, why complete ones failed verification in the list of unverified walks.", render(fig))


def cot_bounds_figure(acot: pd.DataFrame, experiment: str) -> Figure | None:
    """Lowest (solid) and highest (dashed) per-step COT of every method against N, on a log axis: a walk's cheapest
    step (near-passive) and its dearest differ by orders of magnitude."""
    data = acot[acot["experiment"] == experiment]
    if data["cot_min"].notna().sum() == 0:
        return None
    fig, ax = subplots(figsize=(7, 4))
    for method, rows, color in _by_method(data):
        ax.plot(rows["N"], rows["cot_min"], "v-", color=color, ms=4, label=f"{method} min")
        ax.plot(rows["N"], rows["cot_max"], "^--", color=color, ms=4, label=f"{method} max")
    ax.set_xlabel("N (nodes per step)")
    _integer_n(ax)
    ax.set_yscale("log", nonpositive="mask")
    ax.set_ylabel("per-step COT (log scale)")
    ax.set_title(f"{experiment}: minimum and maximum per-step COT")
    legend_below(fig, ncol=2)
    return Figure(f"fig-cot-bounds-{slug(experiment)}", f"Per-step COT bounds: {experiment}",
                  "Lowest and highest COT of a single step of the walk, per method and N, over the verified walks "
                  "(store columns cot_min, cot_max; for D&C its reported motions, the polish or the complete "
                  "solution of each step)."
                  + _thesis(experiment, "cot_bounds"), render(fig))


def savings_figure(savings: pd.DataFrame, experiment: str, paired: pd.DataFrame | None = None) -> Figure | None:
    """Energy savings of D&C against One Phase (same transcription) and against the reference solver. With
    ``paired`` (:func:`gaitbench.reports.statistics.paired_savings`), each pair's median saving over N as a dotted
    line and its bootstrap 95 % interval as a band."""
    data = savings[savings["experiment"] == experiment]
    if data.empty:
        return None
    if not (data["savings_percent"].notna() | data["claimed_savings_percent"].notna()).any():
        return None  # the missing N stay: a line breaks where a pair has no verified walk, as in the ACOT figure
    kinds = [kind for kind in ("one-phase", "reference") if (data["baseline_kind"] == kind).any()]
    if not kinds:
        return None
    fig, axes = subplots(1, len(kinds), figsize=(5 * len(kinds), 3.6), squeeze=False)
    colors = _colors(list(dict.fromkeys(zip(data["method"], data["baseline"], strict=True))))
    for ax, kind in zip(axes[0], kinds, strict=True):
        rows = data[data["baseline_kind"] == kind]
        for method, baseline in dict.fromkeys(zip(rows["method"], rows["baseline"], strict=True)):
            pair = rows[(rows["method"] == method) & (rows["baseline"] == baseline)]
            label, color = f"{method} vs {baseline}", colors[(method, baseline)]
            ax.plot(pair["N"], pair["savings_percent"], "o-", color=color, ms=4, label=f"{label} (verified)")
            ax.plot(pair["N"], pair["claimed_savings_percent"], "s--", color=color, ms=3, alpha=0.7,
                    label=f"{label} (claimed)")
            summary = None if paired is None else paired[(paired["experiment"] == experiment)
                                                         & (paired["method"] == method)
                                                         & (paired["baseline"] == baseline)]
            if summary is not None and not summary.empty and summary["pairs"].iloc[0] > 0:
                median = summary.iloc[0]
                interval = np.isfinite(median["median_ci_low"])  # none from too few pairs (statistics.MIN_PAIRS_FOR_CI)
                if interval:
                    ax.axhspan(median["median_ci_low"], median["median_ci_high"], color=color, alpha=0.12, lw=0)
                ax.axhline(median["median_percent"], color=color, ls=":", lw=1.2,
                           label=f"{label}: median {median['median_percent']:.1f} % " + (
                               f"[{median['median_ci_low']:.1f}, {median['median_ci_high']:.1f}]" if interval
                               else f"({int(median['pairs'])} pairs: no interval)"))
        ax.axhline(0, color="black", lw=0.8)
        ax.set_xlabel("N (nodes per step)")
        _integer_n(ax)
        ax.set_ylabel("energy savings (%)")
        ax.set_title("against One Phase" if kind == "one-phase" else "against the reference solver")
    legend_below(fig, ncol=2)
    roles = " and ".join(thesis_values.figure(experiment, role) or "" for role in ("savings_op", "savings_reference"))
    return Figure(f"fig-savings-{slug(experiment)}", f"Energy savings of Decrease & Conquer: {experiment}",
                  "S(N) = 100 (ACOT_baseline(N) − ACOT_D&C(N)) / ACOT_baseline(N) at each N where both methods have a "
                  "verified walk (a break in a line: an N where one has none). "
                  "Solid: D&C's verified ACOT; dashed: its claim, as the thesis computes it."
                  + ("" if paired is None else " Dotted: the median verified saving over N, shaded: its bootstrap 95 % "
                     "interval (savings_paired.csv).")
                  + (f" Thesis counterparts: {roles}." if roles.strip(" and") else ""), render(fig))


def energetics_figures(table: pd.DataFrame) -> list[Figure]:
    """COT against step length: one panel per fixed (other ratio, V) on flat ground, one curve per varied ratio;
    and the slope effect: COT against slope angle, one curve per step length."""
    solved = table[table["status"] == "solved"].dropna(subset=["acot"])
    if solved.empty:
        return []
    figures = []
    studies = (("mass_ratio", "length_ratio", "Rm", "Rl", "5.55–5.66"),
               ("length_ratio", "mass_ratio", "Rl", "Rm", "5.67–5.78"))
    flat = solved[np.isclose(solved["slope"], 0.0)]
    for varied, fixed, varied_symbol, fixed_symbol, thesis in studies:
        panels = flat.groupby([fixed, "speed"]).filter(lambda g, v=varied: g[v].nunique() > 1)
        keys = list(dict.fromkeys(zip(panels[fixed], panels["speed"], strict=True)))
        if not keys:
            continue
        fig, axes = subplots(1, len(keys), figsize=(4.2 * len(keys), 3.4), squeeze=False)
        for ax, (fixed_value, speed) in zip(axes[0], keys, strict=True):
            panel = panels[(panels[fixed] == fixed_value) & (panels["speed"] == speed)]
            for value, curve in panel.groupby(varied):
                curve = curve.groupby("step_length")["acot"].mean()
                ax.plot(curve.index, curve.values, "o-", ms=3, label=f"{varied_symbol}={value:g}")
            ax.set_xlabel("step length D (leg lengths)")
            ax.set_ylabel("COT")
            ax.set_title(f"{fixed_symbol}={fixed_value:g}, V={speed:g}, flat")
        legend_below(fig)
        figures.append(Figure(f"fig-energetics-{slug(varied_symbol)}", f"COT against step length for {varied_symbol}",
                              f"Average COT of the energetics bipeds against step length, one curve per "
                              f"{varied_symbol}, with {fixed_symbol} and V fixed per panel (flat ground). Thesis "
                              f"counterparts: Figs {thesis} (which plot COT against {varied_symbol}, one curve per D).",
                              render(fig)))
    sloped = solved.groupby(["mass_ratio", "length_ratio", "speed"]).filter(lambda g: g["slope"].nunique() > 1)
    if not sloped.empty:
        keys = list(dict.fromkeys(zip(sloped["mass_ratio"], sloped["length_ratio"], sloped["speed"], strict=True)))[:4]
        fig, axes = subplots(1, len(keys), figsize=(4.2 * len(keys), 3.4), squeeze=False)
        for ax, (rm, rl, speed) in zip(axes[0], keys, strict=True):
            panel = sloped[(sloped["mass_ratio"] == rm) & (sloped["length_ratio"] == rl) & (sloped["speed"] == speed)]
            for step_length, curve in panel.groupby("step_length"):
                curve = curve.groupby("slope")["acot"].mean()
                ax.plot(curve.index, curve.values, "o-", ms=3, label=f"D={step_length:g}")
            ax.set_xlabel("slope θ (deg)")
            ax.set_ylabel("COT")
            ax.set_title(f"Rm={rm:g}, Rl={rl:g}, V={speed:g}")
        legend_below(fig)
        figures.append(Figure("fig-energetics-slope", "Effect of the slope angle on COT",
                              "COT against slope angle for the first (Rm, Rl, V) combinations that vary it. Thesis "
                              "counterparts: Figs 5.57, 5.60, …, 5.78.", render(fig)))
    return figures


def tracking_figures(case_key: str, label: str, series: dict[str, np.ndarray], summary: dict) -> list[Figure]:
    """Desired against actual angles, position and velocity-estimation errors, ACOT under control."""
    figures = []
    key = slug(case_key)
    t = series.get("t")
    if t is not None and len(t):
        q, q_d = series["q"], series["q_desired"]
        fig, ax = subplots(figsize=(7, 3.4))
        for leg in (0, 1):
            ax.plot(t, q_d[:, leg], "--", label=f"q{leg + 1} desired")
            ax.plot(t, q[:, leg], "-", lw=0.8, label=f"q{leg + 1} actual")
        ax.set_xlabel("t (s)")
        ax.set_ylabel("angle (rad)")
        legend_below(fig, ncol=4)
        figures.append(Figure(f"fig-track-angles-{key}", f"Desired and actual angles: {label}",
                              "Leg angles of the reference and of the closed-loop robot (thesis Figs 5.6, 5.19, "
                              "5.32, 5.45).", render(fig)))
        fig, axes = subplots(1, 2, figsize=(9, 3.2))
        position = np.abs(q - q_d)
        velocity = np.abs(series["dq"] - series["dq_estimated"])
        for ax, values, what in ((axes[0], position, "|q − q_d| (rad)"), (axes[1], velocity, "|q̇ − q̂̇| (rad/s)")):
            for leg in (0, 1):
                ax.semilogy(t, np.maximum(values[:, leg], 1e-16), lw=0.8, label=f"leg {leg + 1}")
            ax.set_xlabel("t (s)")
            ax.set_ylabel(what)
        legend_below(fig)
        axes[0].set_title("position error")
        axes[1].set_title("velocity-estimation error")
        figures.append(Figure(f"fig-track-errors-{key}", f"Tracking errors: {label}",
                              "Position error and velocity-estimation error of each leg (thesis Figs 5.7–5.11 and "
                              "their analogues).", render(fig)))
    reference, tracked = summary.get("acot_reference"), summary.get("acot_tracked")
    if reference is not None and tracked is not None:
        polished = (summary.get("walk") or {}).get("trajectory") == "polished"
        fig, ax = subplots(figsize=(4, 3))
        ax.bar(["reference (polished)" if polished else "reference", "under control"], [reference, tracked],
               color=["tab:gray", "tab:blue"])
        ax.set_ylabel("ACOT")
        increase = summary.get("acot_increase_percent")
        if increase is not None:
            ax.set_title(f"increase {increase:+.2f} %")
        figures.append(Figure(f"fig-track-acot-{key}", f"ACOT under control: {label}",
                              "ACOT of the reference against the ACOT of the tracked walk (thesis: +0.5 % to +1.2 %, "
                              "§5.2–5.5)." + (" The reference is decrease and conquer's verified trajectory, each "
                                              "step polished, and its ACOT the verified one." if polished else ""),
                              render(fig)))
    return figures
