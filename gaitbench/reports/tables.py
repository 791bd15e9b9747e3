"""Every table of a report, computed with pandas from the results store (no plotting, no files).

Every function takes the store's cases as :func:`gaitbench.reports.case_frame.prepare` returns them; that module says
which ACOT the tables call verified, and why they average complete walks only. Column names are documented in
docs/reports.md.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from typing import TYPE_CHECKING, Any

import pandas as pd

from gaitbench.reports import thesis_values
from gaitbench.reports.case_frame import (
    DC_STRATEGY,
    ENERGETICS,
    ONE_PHASE,
    REFERENCE_LABEL,
    number,
    parse_details,
    sweep_cases,
)

if TYPE_CHECKING:
    from gaitbench.reports.bounds import ExperimentBounds

ENERGETICS_OPTIONS = ("mass_ratio", "length_ratio", "speed", "step_length", "slope")

ACOT_COLUMNS = ["experiment", "method", "N", "cases", "solved", "verified", "completion_rate", "acot", "claimed_acot",
                "thesis_reading_acot", "cot_min",
                "cot_max", "wall_time_s", "iterations", "retries", "max_defect", "max_resim_error", "is_minimum"]
MINIMA_COLUMNS = ["experiment", "method", "thesis_method", "min_acot", "N_at_min", "claimed_acot_at_min",
                  "thesis_reading_at_min", "N_values", "N_solved", "N_verified"]
COT_BOUNDS_COLUMNS = ["experiment", "method", "N", "cot_min", "cot_max", "acot"]
SAVINGS_COLUMNS = ["experiment", "method", "baseline", "baseline_kind", "N", "acot", "baseline_acot",
                   "savings_percent", "claimed_acot", "claimed_savings_percent"]
PUBLISHED_COLUMNS = ["experiment", "thesis_method", "method", "published_acot", "published_N", "acot", "N_at_min",
                     "N_verified", "difference", "difference_percent", "claimed_acot", "claimed_difference",
                     "thesis_reading_acot", "bound_acot", "published_below_bound", "thesis_push_off_bound_acot",
                     "published_below_thesis_push_off_bound", "verdict", "source"]
PUBLISHED_SAVINGS_COLUMNS = ["experiment", "comparison", "published_min_percent", "published_min_N",
                             "published_max_percent", "published_max_N", "min_percent", "min_N", "max_percent",
                             "max_N", "claimed_max_percent", "claimed_max_N", "source"]
DC_CLAIMS_COLUMNS = ["experiment", "method", "N", "case_key", "status", "claimed_acot", "verified_acot", "ranked",
                     "difference_percent", "steps", "steps_satisfying_dynamics", "max_defect", "max_resim_error",
                     "candidates", "backtracks"]
ENERGETICS_COLUMNS = ["method", "N", *ENERGETICS_OPTIONS, "status", "acot", "claimed_acot", "cot_min", "cot_max",
                      "case_key"]
TRACKING_COLUMNS = ["experiment", "method", "N", "case_key", "max_position_error", "max_velocity_error",
                    "acot_reference", "acot_tracked", "acot_increase_percent", "fell", "published_increase_percent",
                    "published_position_error", "published_velocity_error"]
STOP_CAUSE_COLUMNS = ["experiment", "method", "stop_cause", "cases", "N", "stop_steps", "stop_statuses", "retries",
                      "back_ups"]
UNVERIFIED_COLUMNS = ["case_key", "experiment", "method", "N", "unranked_acot", "verification_failure",
                      "max_join_mismatch", "join_energy", "max_resim_error", "max_defect"]
FAILED_COLUMNS = ["case_key", "experiment", "method", "N", "status", "stop_cause", "stop_step", "stop_status",
                  "message", "steps_solved", "partial_acot", "retries", "wall_time_s"]
PROVENANCE_COLUMNS = ["run_id", "item", "value"]
COMMIT_COLUMNS = ["git_commit", "cases", "methods", "first_finished", "last_finished"]
CASES_COLUMNS = ["case_key", "run_id", "experiment", "method", "N", "steps", "transcription", "solver", "strategy",
                 "objective",
                 "repetition", "status", "message", "acot", "claimed_acot", "cot_min", "cot_max", "steps_solved",
                 "stop_cause", "stop_step", "stop_status", "retries", "partial_acot", "wall_time_s", "solve_time_s",
                 "iterations", "max_defect", "max_resim_error", "walk_path", "tracking_path"]
STOP_CAUSE_ORDER = ("complete", "geometry", "solver", "verification", "time_limit", "error", "crashed", "unrecorded")
"""The store's stop causes (gaitbench.run.store_schema.STOP_CAUSES) in report order; ``unrecorded``: an incomplete
walk stored before the store had a ``stop_cause`` column."""


# --- ACOT, minima, COT bounds ------------------------------------------------------------------------------------

def acot_table(df: pd.DataFrame) -> pd.DataFrame:
    """ACOT per experiment × method × N (mean over the verified walks among the repetitions), the completion rate,
    how many complete walks passed verification, per-step COT bounds and verification figures of the verified
    walks, effort over every case, and whether this N gives the method's minimum ACOT (the first N reaching it, as
    the thesis quotes)."""
    sweep = sweep_cases(df)
    if sweep.empty:
        return pd.DataFrame(columns=ACOT_COLUMNS)
    complete, ranked = sweep["complete"].astype(bool), sweep["ranked"].astype(bool)
    solved = sweep.assign(is_solved=complete, is_ranked=ranked, ranked_defect=sweep["max_defect"].where(ranked),
                          ranked_resim=sweep["max_resim_error"].where(ranked))
    grouped = solved.groupby(["experiment", "method", "N"], sort=False)
    table = grouped.agg(cases=("case_key", "size"), solved=("is_solved", "sum"), verified=("is_ranked", "sum"),
                        acot=("acot", "mean"),
                        claimed_acot=("claimed_acot", "mean"), thesis_reading_acot=("thesis_reading_acot", "mean"),
                        cot_min=("cot_min", "min"),
                        cot_max=("cot_max", "max"), wall_time_s=("wall_time_s", "mean"),
                        iterations=("iterations", "mean"), retries=("retries", "sum"),
                        max_defect=("ranked_defect", "max"), max_resim_error=("ranked_resim", "max")).reset_index()
    table["completion_rate"] = table["solved"] / table["cases"]
    table["retries"] = table["retries"].astype(int)
    table["verified"] = table["verified"].astype(int)
    table = table.sort_values(["experiment", "method", "N"], kind="stable",
                              key=lambda column: column.map(_order(sweep, column.name)))
    table["N"] = table["N"].astype(int)
    table["is_minimum"] = False
    for _, group in table.groupby(["experiment", "method"], sort=False):
        values = group["acot"]
        if values.notna().any():
            table.loc[values.idxmin(), "is_minimum"] = True
    return table[ACOT_COLUMNS].reset_index(drop=True)


def _order(df: pd.DataFrame, column: str):
    if column == "N":
        return lambda value: value
    order = {value: i for i, value in enumerate(dict.fromkeys(df[column]))}
    return lambda value: order.get(value, len(order))


def method_minima(acot: pd.DataFrame, info: pd.DataFrame | None = None) -> pd.DataFrame:
    """Each method's minimum ACOT over N and the (first) N at which it is reached."""
    rows = []
    thesis = {} if info is None else {(r.experiment, r.method): r.thesis_method for r in info.itertuples()}
    for (experiment, method), group in acot.groupby(["experiment", "method"], sort=False):
        best = group[group["is_minimum"]]
        row = {"experiment": experiment, "method": method, "thesis_method": thesis.get((experiment, method)),
               "min_acot": math.nan, "N_at_min": None, "claimed_acot_at_min": math.nan,
               "thesis_reading_at_min": math.nan, "N_values": len(group), "N_solved": int((group["solved"] > 0).sum()),
               "N_verified": int((group["verified"] > 0).sum())}
        if not best.empty:
            row |= {"min_acot": float(best["acot"].iloc[0]), "N_at_min": int(best["N"].iloc[0]),
                    "claimed_acot_at_min": float(best["claimed_acot"].iloc[0]),
                    "thesis_reading_at_min": float(best["thesis_reading_acot"].iloc[0])}
        rows.append(row)
    return _integers(pd.DataFrame(rows, columns=MINIMA_COLUMNS), "N_at_min")


def cot_bounds(acot: pd.DataFrame) -> pd.DataFrame:
    """The lowest and highest per-step COT of each method at each N (the thesis's Figs 5.3, 5.16, 5.29, 5.42)."""
    return acot[COT_BOUNDS_COLUMNS].copy()


# --- energy savings ----------------------------------------------------------------------------------------------

def savings_percent(reference: Any, candidate: Any) -> Any:
    """S = 100 (ACOT_ref − ACOT_D&C) / ACOT_ref, element-wise; NaN where either is missing or the reference is not
    positive (no share of it can be saved)."""
    reference = pd.to_numeric(reference, errors="coerce") if isinstance(reference, pd.Series) else reference
    reference = reference.where(reference > 0) if isinstance(reference, pd.Series) else \
        reference if reference > 0 else math.nan
    return 100.0 * (reference - candidate) / reference


def baselines(info: pd.DataFrame) -> list[tuple[str, str, str, str]]:
    """(experiment, D&C method, baseline method, kind) pairs: each D&C method against One Phase with the same
    transcription, solver and objective (kind ``one-phase``) and against the suite's ``reference`` method under the
    same objective (kind ``reference``): a saving between two cost measures means nothing."""
    pairs = []
    for (experiment, _), group in info.groupby(["experiment", "objective"], sort=False):
        is_reference = group["label"].str.lower() == REFERENCE_LABEL
        for row in group[group["strategy"] == DC_STRATEGY].itertuples():
            same = group[(group["strategy"] == ONE_PHASE) & (group["transcription"] == row.transcription)
                         & (group["solver"] == row.solver) & ~is_reference]
            if not same.empty:
                pairs.append((experiment, row.method, same["method"].iloc[0], ONE_PHASE))
            for reference in group.loc[is_reference, "method"]:
                pairs.append((experiment, row.method, reference, REFERENCE_LABEL))
    return pairs


def savings_table(acot: pd.DataFrame, info: pd.DataFrame) -> pd.DataFrame:
    """Energy savings of every D&C method against its baselines at each N both were run at (verified ACOT, and the
    thesis's way, from the D&C claim)."""
    frames = []
    for experiment, method, baseline, kind in baselines(info):
        ours = acot[(acot["experiment"] == experiment) & (acot["method"] == method)]
        theirs = acot[(acot["experiment"] == experiment) & (acot["method"] == baseline)]
        merged = ours[["N", "acot", "claimed_acot"]].merge(
            theirs[["N", "acot"]].rename(columns={"acot": "baseline_acot"}), on="N", how="inner")
        merged.insert(0, "experiment", experiment)
        merged.insert(1, "method", method)
        merged.insert(2, "baseline", baseline)
        merged.insert(3, "baseline_kind", kind)
        merged["savings_percent"] = savings_percent(merged["baseline_acot"], merged["acot"])
        merged["claimed_savings_percent"] = savings_percent(merged["baseline_acot"], merged["claimed_acot"])
        frames.append(merged)
    if not frames:
        return pd.DataFrame(columns=SAVINGS_COLUMNS)
    return pd.concat(frames, ignore_index=True)[SAVINGS_COLUMNS]


# --- the thesis's published values -------------------------------------------------------------------------------

def published_comparison(minima: pd.DataFrame, bounds: Mapping[str, ExperimentBounds] | None = None) -> pd.DataFrame:
    """Each thesis method's published minimum ACOT (and its N) beside ours, with the differences, and the
    experiment's physical lower bounds (:mod:`gaitbench.reports.bounds`) with a flag where the published figure lies
    below one. An experiment absent from ``bounds`` gets no bound and no flag."""
    bounds = bounds or {}
    rows = []
    for experiment, published in thesis_values.MINIMUM_ACOT.items():
        ours = minima[minima["experiment"] == experiment]
        if ours.empty:
            continue
        for thesis_method, (value, n_published) in published.items():
            match = ours[ours["thesis_method"] == thesis_method]
            row = {"experiment": experiment, "thesis_method": thesis_method, "method": None,
                   "published_acot": value, "published_N": n_published, "acot": math.nan, "N_at_min": None,
                   "difference": math.nan, "difference_percent": math.nan, "claimed_acot": math.nan,
                   "claimed_difference": math.nan, "thesis_reading_acot": math.nan,
                   **_bound_cells(value, bounds.get(experiment)),
                   "source": f"thesis {thesis_values.MINIMUM_ACOT_SOURCES[experiment]}"}
            if not match.empty:
                m = match.iloc[0]
                ours_acot, claimed = m["min_acot"], m["claimed_acot_at_min"]
                row |= {"method": m["method"], "acot": ours_acot, "N_at_min": m["N_at_min"],
                        "N_verified": m.get("N_verified"), "difference": ours_acot - value,
                        "difference_percent": 100 * (ours_acot - value) / value, "claimed_acot": claimed,
                        "claimed_difference": claimed - value, "thesis_reading_acot": m["thesis_reading_at_min"]}
            row["verdict"] = verdict(row)
            rows.append(row)
    return _integers(pd.DataFrame(rows, columns=PUBLISHED_COLUMNS), "N_at_min", "N_verified")


REPRODUCED_WITHIN = 0.10
"""A published figure is reproduced when our verified minimum lies within 10 % of it."""


def verdict(row: Mapping[str, Any]) -> str:
    """One cell of the thesis comparison in words: the published figure below the physical bound (no motion can
    cost that little; said apart when only the thesis's own push-off term, which counts less than the push-off's
    energy, would allow it), reproduced (our verified minimum within :data:`REPRODUCED_WITHIN`), or not reproduced,
    with what we measured instead."""
    if row.get("published_below_bound") is True:
        below = f"published figure below the physical bound {row['bound_acot']:.4f}: no walk can cost that little"
        if row.get("published_below_thesis_push_off_bound") is False:
            return (f"{below} with its push-off charged at the energy the push-off gives the robot; the thesis's "
                    f"push-off term (3.77) would allow down to {row['thesis_push_off_bound_acot']:.4f}")
        return below
    if row.get("method") is None:
        return "not run in this store"
    ours = row.get("acot")
    if ours is None or not math.isfinite(ours):
        return "not reproduced: no verified walk of this method"
    if abs(ours - row["published_acot"]) <= REPRODUCED_WITHIN * row["published_acot"]:
        return "reproduced"
    reading, claimed = row.get("thesis_reading_acot"), row.get("claimed_acot")
    measured = [f"our verified minimum {ours:.4f} ({row['difference_percent']:+.1f} %)"]
    if claimed is not None and math.isfinite(claimed):
        measured.append(f"claimed {claimed:.4f}")
    if reading is not None and math.isfinite(reading):
        measured.append(f"read the thesis's way {reading:.4f}")
    return "not reproduced: " + ", ".join(measured)


def _bound_cells(published: float, bounds: ExperimentBounds | None) -> dict[str, Any]:
    """The bounds and whether ``published`` lies below each (None, not "no", where a bound is of no use, NaN, or
    there are no bounds)."""
    impulse, thesis = (math.nan, math.nan) if bounds is None else (bounds.impulse, bounds.thesis_push_off)
    return {"bound_acot": impulse, "published_below_bound": None if math.isnan(impulse) else bool(published < impulse),
            "thesis_push_off_bound_acot": thesis,
            "published_below_thesis_push_off_bound": None if math.isnan(thesis) else bool(published < thesis)}


def published_savings(savings: pd.DataFrame, info: pd.DataFrame) -> pd.DataFrame:
    """The published range of savings (min and max over N, with their N) beside ours."""
    thesis = {(r.experiment, r.method): r.thesis_method for r in info.itertuples()}
    rows = []
    for experiment, quoted in thesis_values.SAVINGS.items():
        for (dc, base), ((low, n_low), (high, n_high)) in quoted.items():
            row = {"experiment": experiment, "comparison": f"{dc} vs {base}", "published_min_percent": low,
                   "published_min_N": n_low, "published_max_percent": high, "published_max_N": n_high,
                   "min_percent": math.nan, "min_N": None, "max_percent": math.nan, "max_N": None,
                   "claimed_max_percent": math.nan, "claimed_max_N": None,
                   "source": f"thesis {thesis_values.SAVINGS_SOURCES[experiment]}"}
            ours = savings[(savings["experiment"] == experiment)
                           & (savings["method"].map(lambda m, e=experiment: thesis.get((e, m))) == dc)
                           & (savings["baseline"].map(lambda m, e=experiment: thesis.get((e, m))) == base)]
            if ours.empty and not (info["experiment"] == experiment).any():
                continue
            values = ours.dropna(subset=["savings_percent"])
            if not values.empty:
                low_row = values.loc[values["savings_percent"].idxmin()]
                high_row = values.loc[values["savings_percent"].idxmax()]
                row |= {"min_percent": low_row["savings_percent"], "min_N": int(low_row["N"]),
                        "max_percent": high_row["savings_percent"], "max_N": int(high_row["N"])}
            claimed = ours.dropna(subset=["claimed_savings_percent"])
            if not claimed.empty:
                best = claimed.loc[claimed["claimed_savings_percent"].idxmax()]
                row |= {"claimed_max_percent": best["claimed_savings_percent"], "claimed_max_N": int(best["N"])}
            rows.append(row)
    return _integers(pd.DataFrame(rows, columns=PUBLISHED_SAVINGS_COLUMNS), "min_N", "max_N", "claimed_max_N")


# --- D&C claimed against verified --------------------------------------------------------------------------------

def dc_claims(df: pd.DataFrame) -> pd.DataFrame:
    """Every D&C case: the claimed ACOT (patchwork) beside that of the motions the walk reports (each step verified
    on its own), whether the walk as a whole passed verification (``ranked``), and how many chosen trajectories
    satisfy the dynamics."""
    rows = []
    for _, case in df[df["is_dc"]].iterrows() if not df.empty else []:
        details = parse_details(case["strategy_details"])
        claimed = number(details.get("claimed_acot", case["claimed_acot"]))
        verified = number(details.get("verified_acot"))
        rows.append({"experiment": case["experiment"], "method": case["method"], "N": int(case["N"]),
                     "case_key": case["case_key"], "status": case["status"], "claimed_acot": claimed,
                     "verified_acot": verified, "ranked": bool(case["ranked"]),
                     "difference_percent": 100 * (verified - claimed) / claimed if claimed else math.nan,
                     "steps": len(details.get("chosen", [])) or None,
                     "steps_satisfying_dynamics": details.get("steps_satisfying_dynamics"),
                     "max_defect": case["max_defect"], "max_resim_error": case["max_resim_error"],
                     "candidates": details.get("candidates"), "backtracks": details.get("backtracks")})
    return _integers(pd.DataFrame(rows, columns=DC_CLAIMS_COLUMNS), "steps", "steps_satisfying_dynamics",
                     "candidates", "backtracks")


def _integers(table: pd.DataFrame, *columns: str) -> pd.DataFrame:
    """Integer columns that may hold missing values (pandas' nullable Int64, written to CSV without ``.0``)."""
    for column in columns:
        table[column] = pd.to_numeric(table[column], errors="coerce").astype("Int64")
    return table


# --- energetics, tracking, failures, provenance ------------------------------------------------------------------

def energetics_table(df: pd.DataFrame) -> pd.DataFrame:
    """Energetics-study cases with their biped and gait parameters (Rm, Rl, V, D, θ) as columns."""
    if df.empty:
        return pd.DataFrame(columns=ENERGETICS_COLUMNS)
    study = df[df["experiment_name"] == ENERGETICS]
    rows = []
    for _, case in study.iterrows():
        options = case["experiment_options"] if isinstance(case["experiment_options"], dict) else {}
        defaults = {"mass_ratio": 0.5, "length_ratio": 0.5, "speed": 0.4, "step_length": 0.8, "slope": 0.0}
        rows.append({"method": case["method"], "N": int(case["N"]),
                     **{key: float(options.get(key, defaults[key])) for key in ENERGETICS_OPTIONS},
                     "status": case["status"], "acot": case["acot"], "claimed_acot": case["claimed_acot"],
                     "cot_min": case["cot_min"], "cot_max": case["cot_max"], "case_key": case["case_key"]})
    return pd.DataFrame(rows, columns=ENERGETICS_COLUMNS)


def tracking_table(df: pd.DataFrame, summaries: dict[str, dict]) -> pd.DataFrame:
    """Tracked cases: errors, ACOT under control against the reference, the thesis's published figures beside.

    ``summaries`` maps case keys to their track.json contents (for ``acot_reference``); the store's columns are
    used where a summary lacks a figure.
    """
    rows = []
    tracked = df[df["tracking_path"].notna()] if not df.empty else df
    for _, case in tracked.iterrows():
        summary = summaries.get(case["case_key"], {})
        published = thesis_values.TRACKING.get(case["experiment"])
        rows.append({"experiment": case["experiment"], "method": case["method"], "N": int(case["N"]),
                     "case_key": case["case_key"],
                     "max_position_error": summary.get("max_position_error", case.get("max_position_error")),
                     "max_velocity_error": summary.get("max_velocity_error", case.get("max_velocity_error")),
                     "acot_reference": summary.get("acot_reference"),
                     "acot_tracked": summary.get("acot_tracked", case.get("acot_tracked")),
                     "acot_increase_percent": summary.get("acot_increase_percent",
                                                          case.get("acot_increase_percent")),
                     "fell": bool(summary.get("fell", case.get("fell"))),
                     "published_increase_percent": published[3] if published else None,
                     "published_position_error": published[1] if published else None,
                     "published_velocity_error": published[2] if published else None})
    return pd.DataFrame(rows, columns=TRACKING_COLUMNS)


def stop_causes(df: pd.DataFrame) -> pd.DataFrame:
    """How many walks of each experiment and method ended for each cause (``complete`` included), at which N and
    steps, with which raw statuses, and the solve retries and dead-end back-ups they took."""
    if df.empty:
        return pd.DataFrame(columns=STOP_CAUSE_COLUMNS)
    rows = []
    for (experiment, method, cause), group in df.groupby(["experiment", "method", "stop_cause"], sort=False):
        rows.append({"experiment": experiment, "method": method, "stop_cause": cause, "cases": len(group),
                     "N": _listed(group["N"].dropna().astype(int)),
                     "stop_steps": _listed(group["stop_step"].dropna().astype(int)),
                     "stop_statuses": _listed(group["stop_status"].dropna()),
                     "retries": int(group["retries"].sum()), "back_ups": int(group["back_ups"].fillna(0).sum())})
    table = pd.DataFrame(rows, columns=STOP_CAUSE_COLUMNS)
    causes = {cause: i for i, cause in enumerate(STOP_CAUSE_ORDER)}
    table["_cause"] = table["stop_cause"].map(lambda cause: causes.get(cause, len(causes)))
    table = table.sort_values(["experiment", "method", "_cause"], kind="stable",
                              key=lambda column: column if column.name == "_cause" else
                              column.map(_order(df, column.name)))
    return table.drop(columns="_cause").reset_index(drop=True)


def _listed(values: pd.Series) -> str:
    """Distinct values, sorted, as text (``"8, 10"``); empty when there are none."""
    return ", ".join(str(value) for value in sorted(set(values)))


def unverified_cases(df: pd.DataFrame) -> pd.DataFrame:
    """Every complete walk that is not ranked, with why it failed verification (or that it was never checked) and
    the figure it would have had (``unranked_acot``), so that no walk leaves the ranking unseen."""
    if df.empty:
        return pd.DataFrame(columns=UNVERIFIED_COLUMNS)
    unranked = df[df["complete"].astype(bool) & ~df["ranked"].astype(bool)]
    return unranked.assign(unranked_acot=unranked["verified_acot"])[UNVERIFIED_COLUMNS].reset_index(drop=True)


def failed_cases(df: pd.DataFrame) -> pd.DataFrame:
    """Every case that did not solve, with its status, why and where its walk stopped, and its partial figure."""
    if df.empty:
        return pd.DataFrame(columns=FAILED_COLUMNS)
    failed = df[df["status"] != "solved"]
    return _integers(failed[FAILED_COLUMNS].reset_index(drop=True), "steps_solved", "retries")


def case_commits(df: pd.DataFrame) -> pd.DataFrame:
    """The code each case was solved by: one row per commit (``unknown`` where a case's provenance names none), most
    cases first. Figures are comparable as one benchmark only where they share a row: cases solved by other code
    may have solved another problem."""
    if df.empty:
        return pd.DataFrame(columns=COMMIT_COLUMNS)
    provenances = df["provenance"] if "provenance" in df else [None] * len(df)
    commits = [(provenance.get("git_commit") if isinstance(provenance, dict) else None) or "unknown"
               for provenance in provenances]
    frame = df.assign(git_commit=commits)
    rows = [{"git_commit": commit, "cases": len(group), "methods": ", ".join(sorted(set(group["method"]))),
             "first_finished": group["finished_at"].min(), "last_finished": group["finished_at"].max()}
            for commit, group in frame.groupby("git_commit", sort=False)]
    rows.sort(key=lambda row: (-row["cases"], row["git_commit"]))
    return pd.DataFrame(rows, columns=COMMIT_COLUMNS)


def provenance_table(runs: Iterable[dict]) -> pd.DataFrame:
    """Run by run: suite, executor, times, the machine and versions it ran with (``packages.NAME`` rows) and the
    plugins that failed to load (``plugin_problems``, one row each, or ``none``)."""
    rows = []
    for run in runs:
        run_id = run.get("run_id")
        for item in ("suite", "suite_path", "executor", "jobs", "cases_total", "cases_skipped", "cases_done",
                     "cases_failed", "started_at", "finished_at"):
            rows.append({"run_id": run_id, "item": item, "value": run.get(item)})
        provenance = run.get("provenance") or {}
        for key, value in provenance.items():
            if isinstance(value, dict):
                rows.extend({"run_id": run_id, "item": f"{key}.{name}", "value": version}
                            for name, version in value.items())
            elif key == "plugin_problems":  # plugins that failed to load when the run started, one row each
                rows.extend({"run_id": run_id, "item": key, "value": f"{problem['source']}: {problem['message']}"}
                            for problem in value)
                if not value:
                    rows.append({"run_id": run_id, "item": key, "value": "none"})
            elif isinstance(value, list):  # the CPU's vector extensions
                rows.append({"run_id": run_id, "item": key, "value": " ".join(map(str, value))})
            else:
                rows.append({"run_id": run_id, "item": key, "value": value})
    return pd.DataFrame(rows, columns=PROVENANCE_COLUMNS)


def cases_table(df: pd.DataFrame) -> pd.DataFrame:
    """Every stored case, its parameters and scalar results (verified ``acot``; see the module docstring)."""
    if df.empty:
        return pd.DataFrame(columns=CASES_COLUMNS)
    return _integers(df[CASES_COLUMNS].reset_index(drop=True), "steps_solved", "retries")


def chosen_gaits(df: pd.DataFrame) -> dict[str, str]:
    """Per sweep experiment, the key of the solved case with the lowest verified ACOT that has a stored walk."""
    sweep = sweep_cases(df)
    if sweep.empty:
        return {}
    candidates = sweep[(sweep["status"] == "solved") & sweep["acot"].notna() & sweep["walk_path"].notna()]
    chosen = {}
    for experiment, group in candidates.groupby("experiment", sort=False):
        chosen[experiment] = group.loc[group["acot"].idxmin(), "case_key"]
    return chosen
