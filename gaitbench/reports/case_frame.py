"""The store's cases as every report table reads them: :func:`prepare` and the lookups built on its result.

:func:`prepare` takes the store's DataFrame (:func:`gaitbench.run.store.load_results`) and adds the columns the
tables and figures share; every function of :mod:`gaitbench.reports.tables` takes its result. Column names are
documented in docs/reports.md.

Which ACOT is "verified": the mean COT of the motions the walk reports, each recomputed from its trajectory: the
store's ``acot`` for One Phase and the other per-step strategies, and ``strategy_details.verified_acot`` for
Decrease & Conquer (its reported motions, the polish or the complete solution of each step; the store's ``acot``
holds the same figure in rows written since walk files record it, and the patchwork's claim in older rows). The
tables keep D&C's claim (``claimed_acot``) beside it.

Verified walks only: a case is complete when its status is ``solved`` (every requested step solved), and ranked
when it is complete and its walk passed the whole-walk verification (the store's ``verified`` flag:
:mod:`gaitbench.solve.walk_verification`; null in rows stored before the flag existed until ``gaitbench verify
--store`` checks them). Every ACOT, claim and per-step COT bound in the tables and figures is of ranked walks; a
complete walk that is not verified is listed in the unverified-walks table with its reason, and a walk that stopped
early contributes to the completion rate and the stop-cause table, its own figure appearing only as
``partial_acot`` in the per-case tables, under that name, never inside an ACOT average.
"""

from __future__ import annotations

import json
import math
from typing import Any

import numpy as np
import pandas as pd

from gaitbench.problem.objective import NET_POWER
from gaitbench.reports import thesis_values

DC_STRATEGY = "decrease-and-conquer"
ONE_PHASE = "one-phase"
REFERENCE_LABEL = "reference"
ENERGETICS = "energetics"
THESIS_TRANSCRIPTION = {"hermite-simpson": "DC", "dmoc": "DM"}
NOT_CHECKED = "not checked: stored before walks were verified as one motion; run `gaitbench verify --store STORE`"
"""The reason a complete walk whose row has no verified flag is not ranked."""
NO_VERIFIED_ACOT = "no verified ACOT recorded: run `gaitbench verify --store STORE`"
"""The reason a walk flagged verified is not ranked when its row holds no verified ACOT to rank it by."""
STATUS_CAUSES = {"solved": "complete", "timeout": "time_limit", "crashed": "crashed", "error": "error"}
"""Stop causes of stores that predate the ``stop_cause`` column, from the case's status."""


def prepare(cases: pd.DataFrame) -> pd.DataFrame:
    """The store's case rows with the columns every table uses.

    ``experiment`` becomes a label (the plugin name, with its options for parametrized experiments other than
    ``energetics``, and ``[K steps]`` where the suite walked only K), ``method`` falls back to
    strategy/transcription/solver when a case has no label and names its objective in brackets unless it is the
    thesis's ``net-power`` (``objective``; null in stores that predate it), so that no table sets numbers of
    different objectives side by side unnamed,
    ``store_acot`` keeps the store's ``acot`` and ``acot`` becomes the verified ACOT (see the module docstring).
    ``complete`` marks complete walks; ``acot``, ``claimed_acot``, ``cot_min`` and ``cot_max`` are kept only for them,
    and ``partial_acot`` holds the mean COT of the steps an incomplete walk solved. ``stop_cause`` is filled from the
    status where a store predates the column.
    """
    df = cases.copy()
    for column in ("steps", "stop_cause", "stop_step", "stop_status", "retries", "back_ups", "cot_steps",
                   "steps_solved", "objective", "verified", "verification_failure", "max_join_mismatch", "join_energy",
                   "thesis_reading_acot"):
        if column not in df.columns:
            df[column] = None
    if df.empty:
        for column in ("store_acot", "verified_acot", "is_dc", "experiment_name", "complete", "ranked",
                       "partial_acot"):
            df[column] = pd.Series(dtype=object)
        return df
    df["experiment_name"] = df["experiment"]
    df["experiment"] = [_experiment_label(name, options, steps) for name, options, steps in
                        zip(df["experiment"], df["experiment_options"], df["steps"], strict=True)]
    df["method"] = [method if isinstance(method, str) and method else
                    f"{strategy} {transcription} {solver}" for method, strategy, transcription, solver in
                    zip(df["method"], df["strategy"], df["transcription"], df["solver"], strict=True)]
    df["objective"] = [objective if isinstance(objective, str) and objective else NET_POWER.name
                       for objective in df["objective"]]
    df["method"] = [method if objective == NET_POWER.name else f"{method} [{objective}]"
                    for method, objective in zip(df["method"], df["objective"], strict=True)]
    df["is_dc"] = df["strategy"] == DC_STRATEGY
    df["store_acot"] = pd.to_numeric(df["acot"], errors="coerce")
    df["claimed_acot"] = pd.to_numeric(df["claimed_acot"], errors="coerce")
    verified = [parse_details(details).get("verified_acot") if is_dc else acot
                for details, is_dc, acot in zip(df["strategy_details"], df["is_dc"], df["store_acot"], strict=True)]
    df["verified_acot"] = pd.to_numeric(pd.Series(verified, index=df.index, dtype=object), errors="coerce")
    complete = df["status"] == "solved"
    df["complete"] = complete
    flags = pd.to_numeric(df["verified"], errors="coerce")
    figure = df["verified_acot"].notna()
    ranked = complete & (flags == 1) & figure
    df["ranked"] = ranked
    df["verification_failure"] = [
        None if not done or (flag == 1 and has_figure) else NO_VERIFIED_ACOT if flag == 1
        else reason if isinstance(reason, str) and reason else NOT_CHECKED
        for done, flag, has_figure, reason in zip(complete, flags, figure, df["verification_failure"], strict=True)]
    df["acot"] = df["verified_acot"].where(ranked)
    df["claimed_acot"] = df["claimed_acot"].where(ranked & df["is_dc"])
    df["thesis_reading_acot"] = pd.to_numeric(df["thesis_reading_acot"], errors="coerce").where(ranked)
    for column in ("cot_min", "cot_max", "wall_time_s", "iterations", "max_defect", "max_resim_error", "N",
                   "retries", "back_ups", "steps_solved", "max_join_mismatch", "join_energy"):
        df[column] = pd.to_numeric(df[column], errors="coerce")
    for column in ("cot_min", "cot_max"):  # a partial or unverified walk's bounds would pass for a verified one's
        df[column] = df[column].where(ranked)
    df["stop_step"] = pd.to_numeric(df["stop_step"], errors="coerce").astype("Int64")
    df["stop_cause"] = [cause if isinstance(cause, str) and cause else STATUS_CAUSES.get(status, "unrecorded")
                        for cause, status in zip(df["stop_cause"], df["status"], strict=True)]
    df["partial_acot"] = [math.nan if done or is_dc else _partial_acot(cots)
                          for done, is_dc, cots in zip(complete, df["is_dc"], df["cot_steps"], strict=True)]
    return df


def _partial_acot(cot_steps: Any) -> float:
    """Mean COT of the steps a walk solved before it stopped (NaN if none): the partial walk's own figure."""
    if isinstance(cot_steps, str):
        try:
            cot_steps = json.loads(cot_steps)
        except json.JSONDecodeError:
            return math.nan
    if not isinstance(cot_steps, list):
        return math.nan
    solved = [number(cot) for cot in cot_steps]
    solved = [cot for cot in solved if math.isfinite(cot)]
    return float(np.mean(solved)) if solved else math.nan


def _experiment_label(name: str, options: Any, steps: Any) -> str:
    """The experiment's name, with its options, and with the number of steps where the suite walked only those: a
    shortened walk is another problem than the experiment's whole walk, never averaged with it or set against the
    thesis's figures."""
    if name == ENERGETICS:
        return name
    label = name
    if options:
        label += "(" + ", ".join(f"{key}={value}" for key, value in sorted(dict(options).items())) + ")"
    walked = number(steps)
    return f"{label} [{int(walked)} step{'' if walked == 1 else 's'}]" if math.isfinite(walked) else label


def parse_details(value: Any) -> dict:
    """A case's ``strategy_details``, stored as JSON text or already parsed, as a dict ({} when unreadable)."""
    if isinstance(value, str):
        try:
            value = json.loads(value)
        except json.JSONDecodeError:
            return {}
    return value if isinstance(value, dict) else {}


def sweep_cases(df: pd.DataFrame) -> pd.DataFrame:
    """The cases of the per-experiment ACOT sweeps (everything but the energetics study)."""
    return df[df["experiment_name"] != ENERGETICS] if not df.empty else df


def experiments(df: pd.DataFrame) -> list[str]:
    """The sweep experiments in store order."""
    return list(dict.fromkeys(sweep_cases(df)["experiment"])) if not df.empty else []


def method_info(df: pd.DataFrame) -> pd.DataFrame:
    """One row per (experiment, method): its transcription, solver, strategy, objective, its label without the
    objective's brackets (``label``), and the thesis method it stands for: only under the thesis's own objective
    (``net-power``), since the published figures measure that cost and no other."""
    columns = ["experiment", "method", "transcription", "solver", "strategy", "objective", "label", "thesis_method"]
    sweep = sweep_cases(df)
    if sweep.empty:
        return pd.DataFrame(columns=columns)
    info = sweep.groupby(["experiment", "method"], sort=False)[["transcription", "solver", "strategy",
                                                                "objective"]].first()
    info = info.reset_index()
    info["label"] = [method.removesuffix(f" [{objective}]")
                     for method, objective in zip(info["method"], info["objective"], strict=True)]
    info["thesis_method"] = None
    for _, group in info[info["objective"] == NET_POWER.name].groupby("experiment", sort=False):
        # a method labelled with a thesis method's name stands for it; the others by what they run, where that
        # names one thesis method left untaken, and only one of them
        named = {index: _named_thesis_method(label) for index, label in group["label"].items()}
        guessed = {index: _guessed_thesis_method(row["strategy"], row["transcription"])
                   for index, row in group.iterrows() if named[index] is None}
        for choices in (named, guessed):
            taken = set(info.loc[group.index, "thesis_method"].dropna())
            counts = pd.Series([choice for choice in choices.values() if choice]).value_counts()
            for index, choice in choices.items():
                if choice and counts[choice] == 1 and choice not in taken:
                    info.loc[index, "thesis_method"] = choice
    return info[columns]


def _named_thesis_method(label: str) -> str | None:
    if label in thesis_values.METHODS:
        return label
    if label.lower() == REFERENCE_LABEL:
        return thesis_values.REFERENCE_METHOD
    return None


def _guessed_thesis_method(strategy: str, transcription: str) -> str | None:
    suffix = THESIS_TRANSCRIPTION.get(transcription)
    if suffix is None:
        return None
    if strategy == ONE_PHASE:
        return f"OP-{suffix}"
    if strategy == DC_STRATEGY:
        return f"D&C-{suffix}"
    return None


def number(value: Any) -> float:
    """``value`` as a float; NaN when it is missing or not a number (stored JSON holds either)."""
    try:
        return float(value) if value is not None else math.nan
    except (TypeError, ValueError):
        return math.nan
