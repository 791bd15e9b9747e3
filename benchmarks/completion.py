"""Do the walks complete? A completion table rendered from a results store, for the record in benchmarks/results/.

Run:    .venv/bin/gaitbench run benchmarks/suites/complete-walks.toml --jobs 2
        .venv/bin/python benchmarks/completion.py results/complete-walks --out benchmarks/results/complete_walks.md

Per experiment and method: how many walks walked every step, how many of those have a verified ACOT (a One Phase
walk's steps are each verified; a Decrease & Conquer walk's figure is its polished steps', so a polish that fails
leaves its walk complete but unverified), the N of those that stopped with the cause, step and status recorded by
the store, the solve retries the walks needed (docs/solvers.md, "Retries") and the steps solved
again after a dead end (back-ups, docs/deviations.md "Dead ends"). Then each method's lowest ACOT over N beside
the thesis's published minimum (the report's ``published_acot`` table, over the complete walks only), and D&C's
energy savings, verified and claimed, beside the published ranges. Then the retry ladder: per method and rung,
how often it was tried and converged and what it cost, the time of the tries that failed apart. Then the costly
steps: every verified step COT above :data:`COSTLY_STEP_COT` by experiment, method and step, and, for Decrease &
Conquer, how often its complete Second Phase solution (candidate k0 = 0, verified) lies below the polished step it
reported. Every figure is read from the store (the walk files for the last three); the table names the commits the
cases ran at.
"""

from __future__ import annotations

import argparse
import json
import re
from pathlib import Path

import pandas as pd

from gaitbench import load_results
from gaitbench.reports import tables
from gaitbench.reports.case_frame import method_info, prepare
from gaitbench.run.store import ResultStore


def completion_table(frame: pd.DataFrame) -> pd.DataFrame:
    """One row per experiment and method: walks, complete walks, retries, wall time, and the walks that stopped."""
    rows = []
    for (experiment, method), group in prepare(frame).groupby(["experiment", "method"], sort=True):
        complete = group["complete"]
        stopped = group[~complete].sort_values("N")
        rows.append({
            "experiment": experiment,
            "method": method,
            "walks": len(group),
            "complete": int(complete.sum()),
            "verified": int((complete & group["verified_acot"].notna()).sum()),
            "steps solved": int(group["steps_solved"].fillna(0).sum()),
            "retries": int(pd.to_numeric(group["retries"], errors="coerce").fillna(0).sum()),
            "back-ups": int(pd.to_numeric(group.get("back_ups"), errors="coerce").fillna(0).sum())
            if "back_ups" in group else 0,
            "case time (s)": round(float(group["wall_time_s"].sum()), 1),
            "stopped (N: cause at step, status)": "; ".join(
                f"{int(row.N)}: {row.stop_cause} at {_step(row.stop_step)}, "
                f"{row.stop_status if isinstance(row.stop_status, str) else row.status}"
                for row in stopped.itertuples()) or "—",
        })
    return pd.DataFrame(rows)


def minima_table(frame: pd.DataFrame) -> pd.DataFrame:
    """Per experiment and thesis method: the published minimum ACOT and its N beside ours (the One Phase and D&C
    methods; the thesis's SNOPT column has no counterpart in an IPOPT-only store)."""
    cases = prepare(frame)
    acot = tables.acot_table(cases)
    published = tables.published_comparison(tables.method_minima(acot, method_info(cases)))
    published = published[published["method"].notna()]
    return pd.DataFrame({
        "experiment": published["experiment"],
        "method": published["thesis_method"],
        "thesis: min ACOT (N)": [f"{a:.4f} ({int(n)})" for a, n in zip(published["published_acot"],
                                                                      published["published_N"], strict=True)],
        "ours: min ACOT (N)": [f"{a:.4f} ({int(n)})" if pd.notna(n) else "—"  # no verified walk of the method
                               for a, n in zip(published["acot"], published["N_at_min"], strict=True)],
        "difference": [f"{d:+.0f} %" if pd.notna(d) else "—" for d in published["difference_percent"]],
        "D&C's claimed ACOT there": [f"{c:.4f}" if pd.notna(c) else "—" for c in published["claimed_acot"]],
    })


def savings_summary_table(frame: pd.DataFrame) -> pd.DataFrame:
    """Per experiment, D&C method and baseline: D&C's energy saving over the N both completed, verified (the polished
    walks) and claimed (the patchwork's figure, as the thesis computes it), beside the range the thesis publishes."""
    cases = prepare(frame)
    info = method_info(cases)
    savings = tables.savings_table(tables.acot_table(cases), info)
    thesis = {(row.experiment, row.method): row.thesis_method for row in info.itertuples()}
    return summarize_savings(savings, tables.published_savings(savings, info), thesis)


def summarize_savings(savings: pd.DataFrame, published: pd.DataFrame,
                      thesis: dict[tuple[str, str], str]) -> pd.DataFrame:
    """:func:`savings_summary_table` from the report's ``savings`` and ``published_savings`` tables; ``thesis`` names
    each (experiment, method)'s thesis method, the label the published comparisons use."""
    quoted = {(row.experiment, row.comparison): row for row in published.itertuples()}
    rows = []
    for (experiment, method, baseline), group in savings.groupby(["experiment", "method", "baseline"], sort=True):
        verified, claimed = group["savings_percent"].dropna(), group["claimed_savings_percent"].dropna()
        source = quoted.get((experiment, f"{thesis.get((experiment, method))} vs {thesis.get((experiment, baseline))}"))
        rows.append({
            "experiment": experiment,
            "comparison": f"{method} vs {baseline}",
            "N compared": len(verified),
            "N with a saving": int((verified > 0).sum()),
            "verified saving: median (range)": f"{verified.median():+.1f} % ({verified.min():+.1f} … "
                                               f"{verified.max():+.1f})" if len(verified) else "—",
            "claimed saving: median": f"{claimed.median():+.1f} %" if len(claimed) else "—",
            "thesis: range": f"{source.published_min_percent:+.2f} … {source.published_max_percent:+.2f} %"
            if source is not None else "—",
        })
    return pd.DataFrame(rows)


COSTLY_STEP_COT = 3.0
"""A step COT above this is costly: several times a typical step's (0.03–0.9 on these terrains)."""


def read_walks(frame: pd.DataFrame, store: Path) -> dict[str, dict]:
    """Every case's walk file, read once for the tables that look into the steps, by its path in the store."""
    return {path: json.loads((store / path).read_text()) for path in frame["walk_path"] if isinstance(path, str)}


def step_cots(frame: pd.DataFrame, walks: dict[str, dict]) -> pd.DataFrame:
    """One row per solved step of every complete walk: its verified COT (a D&C step's polished one), for D&C the
    verified COT of its complete Second Phase solution, and which of the walk's last tries the step took (a back-up
    onto it, a coarse-grid rescue, a complete solution standing in for a failed polish)."""
    rows = []
    for case in prepare(frame).itertuples():
        if not isinstance(case.walk_path, str) or case.stop_cause != "complete":
            continue
        for step in walks[case.walk_path]["steps"]:
            details = step.get("details") or {}
            decrease_and_conquer = "polished" in details
            cot = (details["polished"].get("cot") if decrease_and_conquer else step.get("cot"))
            complete = (details.get("complete") or {}).get("cot") if decrease_and_conquer else None
            rows.append({"experiment": case.experiment, "method": case.method, "N": case.N, "step": step["index"],
                         "cot": cot, "complete_cot": complete, "backed_up": "backed_up_from" in details,
                         "rescued": "rescued_from" in details,
                         "stand_in": bool(decrease_and_conquer and details["polished"].get("stand_in"))})
    return pd.DataFrame(rows)


def costly_steps_table(steps: pd.DataFrame) -> pd.DataFrame:
    """Per experiment, method and step: the walks whose step COT is above :data:`COSTLY_STEP_COT`, with their N."""
    costly = steps[steps["cot"] > COSTLY_STEP_COT]
    rows = [{"experiment": experiment, "method": method, "step": int(step), "walks": len(group),
             "N": ", ".join(str(n) for n in sorted(group["N"])),
             "COT": f"{group['cot'].min():.2f}–{group['cot'].max():.2f}"}
            for (experiment, method, step), group in costly.groupby(["experiment", "method", "step"], sort=True)]
    return pd.DataFrame(rows, columns=["experiment", "method", "step", "walks", "N", "COT"])


def complete_candidate_summary(steps: pd.DataFrame) -> str:
    """How often D&C's complete Second Phase solution verifies below the polished step it reports."""
    dc = steps.dropna(subset=["complete_cot", "cot"])
    if dc.empty:
        return ""
    below = dc[dc["complete_cot"] < dc["cot"]]
    costly = dc[dc["cot"] > COSTLY_STEP_COT]
    costly_below = int((costly["complete_cot"] < costly["cot"]).sum())
    return (f"D&C's complete Second Phase solution (candidate k0 = 0, verified) lies below the polished step it "
            f"reports in {len(below)} of its {len(dc)} steps, and in {costly_below} of the {len(costly)} polished "
            f"steps above {COSTLY_STEP_COT:g}.")


def last_tries_summary(steps: pd.DataFrame) -> str:
    """How many steps of the complete walks needed each of the walk's last tries, and in how many walks."""
    parts = []
    for column, what in (("backed_up", "backed up (solved again after a dead end)"),
                         ("rescued", "rescued from a coarser grid"),
                         ("stand_in", "verified by the complete solution standing in for a failed polish")):
        took = steps[steps[column]]
        walks = len(took.groupby(["experiment", "method", "N"]))
        parts.append(f"{len(took)} step{'s' if len(took) != 1 else ''} {what} in {walks} "
                     f"walk{'s' if walks != 1 else ''}")
    return "Last tries in the complete walks: " + "; ".join(parts) + "."


FAILED_FIRST_ATTEMPT = "first attempt (failed)"


def ladder_tries(frame: pd.DataFrame, walks: dict[str, dict]) -> pd.DataFrame:
    """One row per try of a step that climbed the retry ladder, in every walk with a walk file: its failed first
    attempt, where recorded, and each rung after it (wherever a strategy nests them), with status and time."""
    rows = []
    for case in prepare(frame).itertuples():
        if not isinstance(case.walk_path, str):
            continue
        for details in _ladders(walks[case.walk_path].get("steps", [])):
            first = [{"remedy": FAILED_FIRST_ATTEMPT, **details["first_attempt"]}] if "first_attempt" in details else []
            tries = [*first, *details["retries"]]
            rows += [{"experiment": case.experiment, "method": case.method, "N": case.N, "remedy": entry["remedy"],
                      "converged": entry.get("status") == "converged", "time_s": entry.get("solve_time_s") or 0.0}
                     for entry in tries]
    return pd.DataFrame(rows, columns=["experiment", "method", "N", "remedy", "converged", "time_s"])


def _ladders(node):
    """Every dictionary below ``node`` that records a climbed retry ladder: a non-empty ``retries`` list of rungs,
    with the failed ``first_attempt`` where the strategy records it (One Phase does, a D&C step's does not)."""
    if isinstance(node, dict):
        retries = node.get("retries")
        if isinstance(retries, list) and retries and all(isinstance(entry, dict) and "remedy" in entry
                                                          for entry in retries):
            yield node
        for value in node.values():
            yield from _ladders(value)
    elif isinstance(node, list):
        for value in node:
            yield from _ladders(value)


def ladder_table(tries: pd.DataFrame) -> pd.DataFrame:
    """Per method and rung, in the order the rungs were first tried: how often it was tried and converged, and the
    time it took, in all and on the tries that failed (what a rung that seldom converges costs)."""
    rows = []
    for method, group in tries.groupby("method", sort=True):
        for remedy, rung in group.groupby("remedy", sort=False):
            rows.append({"method": method, "rung": remedy, "tried": len(rung),
                         "converged": "—" if remedy == FAILED_FIRST_ATTEMPT else int(rung["converged"].sum()),
                         "time (s)": f"{rung['time_s'].sum():,.0f}",
                         "of it failed (s)": f"{rung.loc[~rung['converged'], 'time_s'].sum():,.0f}"})
    return pd.DataFrame(rows, columns=["method", "rung", "tried", "converged", "time (s)", "of it failed (s)"])


def markdown_table(table: pd.DataFrame) -> str:
    lines = ["| " + " | ".join(table.columns) + " |", "|" + "---|" * len(table.columns)]
    lines += ["| " + " | ".join(str(value) for value in row) + " |" for row in table.itertuples(index=False)]
    return "\n".join(lines)


def _step(value) -> str:
    return "—" if pd.isna(value) else str(int(value))


def render(store: Path) -> str:
    """The completion record of ``store``: a store directory, or a pack of one (its walk headers are all it needs)."""
    frame = load_results(store)
    with ResultStore.open(store) as opened:
        directory = opened.directory  # a pack's unpacked copy
    commits = sorted({row.get("git_commit", "?") for row in frame["provenance"] if isinstance(row, dict)})
    table = completion_table(frame)
    total, complete = int(table["walks"].sum()), int(table["complete"].sum())
    verified = int(table["verified"].sum())
    lines = [
        f"# Completion: {directory.name}",
        "",
        f"{complete} of {total} walks complete ({100 * complete / total:.0f} %), {verified} of them with a verified "
        f"ACOT ({100 * verified / total:.0f} % of the walks). Rendered by `benchmarks/completion.py` from the store; "
        f"cases ran at {', '.join(commits)}.",
        "",
        markdown_table(table),
        "",
        "Lowest ACOT over N, complete walks only, beside the thesis's published minimum (§5.2–5.5). D&C's claimed",
        "ACOT is the synthesized patchwork's own figure at our minimum's N, the one the thesis reports; ours is the",
        "verified (polished) one (docs/deviations.md).",
        "",
        markdown_table(minima_table(frame)),
        "",
        "Energy savings of D&C against One Phase on the same transcription and against the reference column, at",
        "every N where both walks completed: verified (the polished walks) and claimed (the patchwork's own ACOT, the",
        "thesis's way), beside the range over N that the thesis publishes (thesis §5.2–5.5).",
        "",
        markdown_table(savings_summary_table(frame)),
        "",
    ]
    walks = read_walks(frame, directory)
    tries = ladder_tries(frame, walks)
    if not tries.empty:
        lines += ["The retry ladder (docs/solvers.md, \"Retries\"): per method, each step's failed first attempt "
                  "(where the walk records it: not in D&C's) and every rung tried after it, in the order first tried, "
                  "over all walks with a walk file; times are the solves' own.", "",
                  markdown_table(ladder_table(tries)), ""]
    steps = step_cots(frame, walks)
    if not steps.empty:
        lines += [f"Costly steps: verified step COTs above {COSTLY_STEP_COT:g} in complete walks (a D&C step's is its "
                  "polished one).", "", markdown_table(costly_steps_table(steps)), "",
                  complete_candidate_summary(steps), "", last_tries_summary(steps), ""]
    return "\n".join(lines)


def keep_notes(existing: str, rendered: str) -> str:
    """``rendered`` under the hand-written notes of ``existing``: its title and whatever precedes its rendered
    count line ("N of M walks complete"), so that a record kept by hand between snapshots survives a re-render."""
    count = re.compile(r"^\d+ of \d+ walks complete", re.MULTILINE)
    old, new = count.search(existing), count.search(rendered)
    return rendered if old is None or new is None else existing[:old.start()] + rendered[new.start():]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("store", type=Path)
    parser.add_argument("--out", type=Path,
                        help="write the table here, keeping the notes above an existing file's table (default: print)")
    args = parser.parse_args()
    text = render(args.store)
    if args.out:
        args.out.write_text(keep_notes(args.out.read_text(), text) if args.out.exists() else text)
    else:
        print(text)


if __name__ == "__main__":
    main()
