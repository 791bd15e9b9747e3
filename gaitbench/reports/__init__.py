"""Reports of a results store: HTML with the thesis's figures regenerated, and CSV files of every table.

``write_report(store_dir, out_dir)`` reads the store once (:func:`build_report`) and hands the result to each
reporter plugin (kind ``reporter``; built in: ``csv`` and ``html``, registered by
``plugins/reporters/csv_and_html.py``). A
reporter is any object with ``write(report: ReportData, out_dir: Path) -> list[Path]``
(:class:`gaitbench.contracts.Reporter`). docs/reports.md lists
every file, column and figure.
"""

from __future__ import annotations

import json
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING

from gaitbench.report_data import GaitSection, ReportData, TrackingSection

if TYPE_CHECKING:
    from gaitbench.plugins import PluginRegistry

DEFAULT_REPORTERS = ("csv", "html")

ProgressCallback = Callable[[str, int, int], None]
"""``progress(what, done, total)``: called as each part of a report starts (``what``, with ``done`` parts finished)
and once at the end; ``total`` grows as reading the store makes the parts known."""


class _Steps:
    """Counts the parts of a report and tells a :data:`ProgressCallback` which one is being worked on."""

    def __init__(self, callback: ProgressCallback | None, total: int = 0) -> None:
        self.callback, self.done, self.total = callback, 0, total
        self.current: str | None = None

    def add(self, parts: int) -> None:
        self.total += parts

    def start(self, what: str) -> None:
        """``what`` is being worked on now; the part before it is done."""
        if self.current is not None:
            self.done += 1
        self.current = what
        self._tell(what)

    def finish(self, what: str = "done") -> None:
        if self.current is not None:
            self.done += 1
        self.current = None
        self._tell(what)

    def _tell(self, what: str) -> None:
        if self.callback is not None:
            self.callback(what, self.done, max(self.total, self.done))


class ReportError(Exception):
    """A report that cannot be built (no store, an unknown ``--gait`` case); the message says why."""


class GaitNotFound(ReportError):
    """``gait`` names no case of the store, or several."""


def build_report(store_dir: str | Path, gait: str | None = None, registry: PluginRegistry | None = None,
                 progress: ProgressCallback | _Steps | None = None) -> ReportData:
    """Read the store and compute every table and figure of its report.

    ``gait`` is a case key (or a unique prefix) whose gait is shown; by default each sweep experiment's solved case
    with the lowest verified ACOT. ``progress(what, done, total)`` is told about each part as it is done.
    """
    from gaitbench.reports import case_frame
    from gaitbench.reports import figures as fig
    from gaitbench.reports import statistics as st
    from gaitbench.reports import tables as tb
    from gaitbench.reports.gait import animation_svg, gait_figures, load_gait
    from gaitbench.run.pack_format import is_pack, left_out
    from gaitbench.run.store import ResultStore, load_results
    from gaitbench.run.store_schema import StoreError
    from gaitbench.solve.walk_file import WalkFileError, beside, read_arrays

    own = not isinstance(progress, _Steps)
    steps = _Steps(progress) if own else progress
    steps.add(1)
    steps.start("reading the store")
    store_dir = Path(store_dir)
    try:
        raw = load_results(store_dir)
        with ResultStore.open(store_dir) as store:
            runs = store.runs()
            shown = store_dir if is_pack(store_dir) else store.directory  # a pack by its name, not its cache copy
            store_dir = store.directory
    except StoreError as error:
        raise ReportError(str(error)) from None
    df = case_frame.prepare(raw)
    info = case_frame.method_info(df)
    acot = tb.acot_table(df)
    minima = tb.method_minima(acot, info)
    savings = tb.savings_table(acot, info)
    spread = st.acot_spread(df, acot)
    energetics = tb.energetics_table(df)
    summaries = _track_summaries(store_dir, df)
    paired = st.paired_savings(savings, minima)
    tables = {
        "acot": acot, "acot_minima": minima, "cot_bounds": tb.cot_bounds(acot), "acot_spread": spread,
        "savings": savings, "savings_paired": paired,
        "consistency": st.consistency_exceptions(acot, df, ground=_stance_ground(registry, df)),
        "published_acot": tb.published_comparison(minima, _thesis_bounds(minima, registry)),
        "published_savings": st.with_paired_savings(tb.published_savings(savings, info), paired, info),
        "dc_claims": tb.dc_claims(df), "energetics": energetics, "tracking": tb.tracking_table(df, summaries),
        "stop_causes": tb.stop_causes(df), "unverified_cases": tb.unverified_cases(df),
        "failed_cases": tb.failed_cases(df),
        "case_commits": tb.case_commits(df), "provenance": tb.provenance_table(runs),
        "cases": tb.cases_table(df),
    }
    suites = sorted({run.get("suite") or "?" for run in runs})
    report = ReportData(store_dir=shown, title=f"gaitbench report: {', '.join(suites) or store_dir.name}",
                        cases=df, runs=runs, tables=tables, experiments=case_frame.experiments(df))
    steps.add(len(report.experiments) + 1)
    for experiment in report.experiments:
        steps.start(f"figures of {experiment}")
        made = [fig.acot_figure(acot, experiment, spread), fig.completion_figure(acot, experiment),
                fig.cot_bounds_figure(acot, experiment),
                fig.savings_figure(savings, experiment, paired)]
        report.experiment_figures[experiment] = [figure for figure in made if figure is not None]
    steps.start("energetics figures")
    report.energetics_figures = fig.energetics_figures(energetics)

    if gait is not None:
        matches = [key for key in df["case_key"] if key.startswith(gait)] if not df.empty else []
        if len(matches) != 1:
            problem = "matches several cases" if matches else "is not a case of this store"
            raise GaitNotFound(f"--gait {gait!r} {problem} ({store_dir})")
        chosen = {None: matches[0]}
    else:
        chosen = tb.chosen_gaits(df)
    if chosen:
        from gaitbench.plugins import load_registry

        registry = registry or load_registry()
    steps.add(len(chosen) + len(summaries))
    for key in chosen.values():
        case = df[df["case_key"] == key].iloc[0]
        steps.start(f"gait of {case['experiment']}, {case['method']}, N = {int(case['N'])}")
        if not isinstance(case["walk_path"], str):
            report.gait_problems.append(f"case {key}: no stored walk ({case['status']}: {case['message']})")
            continue
        absent = left_out(store_dir, case["walk_path"])
        if absent:
            report.gait_problems.append(f"case {key}: gait not shown ({absent})")
            continue
        try:
            loaded = load_gait(store_dir, case, registry)
        except Exception as error:  # a report shows what it can and says what it could not
            report.gait_problems.append(f"case {key}: gait not shown ({type(error).__name__}: {error})")
            continue
        if loaded.partial:
            loaded.notes.insert(0, _partial_note(case))
        elif loaded.verification_failure:
            loaded.notes.insert(0, f"Unverified walk: {loaded.verification_failure}. It is in no ranking of this "
                                   "report; what follows describes the motion, not a verified result.")
        claim = None
        if case["is_dc"]:
            claims = tables["dc_claims"]
            row = claims[claims["case_key"] == key]
            claim = row.iloc[0].to_dict() if not row.empty else None
        report.gaits.append(GaitSection(loaded, gait_figures(loaded), animation_svg(loaded, f"anim-{fig.slug(key)}"),
                                        claim))

    for key, summary in summaries.items():
        case = df[df["case_key"] == key].iloc[0]
        steps.start(f"tracking of {case['experiment']}, {case['method']}, N = {int(case['N'])}")
        label = f"{case['experiment']}, {case['method']}, N = {int(case['N'])} (case {key})"
        series = {}
        if summary.get("series"):
            try:  # a series that is gone, broken or points outside the store costs its figures, not the report
                npz_path = beside(store_dir / case["tracking_path"], summary["series"])
                if npz_path.is_file():
                    series = read_arrays(npz_path, "track the walk again")
            except (ValueError, WalkFileError) as error:
                report.gait_problems.append(f"case {key}: tracking series not shown ({error})")
        report.tracking.append(TrackingSection(key, label, summary, fig.tracking_figures(key, label, series, summary)))
    if own:
        steps.finish()
    return report


def report_trajectories(store_dir: str | Path) -> set[str]:
    """The trajectory files the default report of the store draws, relative to it: the walk NPZ of each chosen
    gait (:func:`gaitbench.reports.tables.chosen_gaits`) and each tracked case's series. What a pack made with
    ``--trajectories report`` keeps (:func:`gaitbench.run.store_pack.pack_store`)."""
    from gaitbench.reports import case_frame
    from gaitbench.reports import tables as tb
    from gaitbench.run.store import ResultStore, load_results

    with ResultStore.open(store_dir) as store:
        directory = store.directory
    df = case_frame.prepare(load_results(store_dir))
    drawn = set()
    for key in tb.chosen_gaits(df).values():
        walk_path = df.loc[df["case_key"] == key, "walk_path"].iloc[0]
        drawn.add(_named_beside(directory, walk_path, "trajectories"))
    for key, summary in _track_summaries(directory, df).items():
        tracking_path = df.loc[df["case_key"] == key, "tracking_path"].iloc[0]
        drawn.add(_named_beside(directory, tracking_path, "series", summary))
    return {path for path in drawn if path is not None}


def _named_beside(store_dir: Path, path: str, field: str, header: dict | None = None) -> str | None:
    """The file a stored JSON file names under ``field`` (beside it), relative to the store; None when it names
    none or one outside its directory."""
    from gaitbench.solve.walk_file import beside

    try:
        header = header if header is not None else json.loads((store_dir / path).read_text(encoding="utf-8"))
        if not isinstance(header, dict) or not header.get(field):
            return None
        return beside(store_dir / path, header[field]).relative_to(store_dir.resolve()).as_posix()
    except (OSError, ValueError):
        return None


def _thesis_bounds(minima, registry: PluginRegistry | None) -> dict:
    """The physical ACOT bounds of the thesis experiments this store holds, computed once each for the thesis
    comparison (:mod:`gaitbench.reports.bounds`)."""
    from gaitbench.reports import thesis_values
    from gaitbench.reports.bounds import experiment_bounds

    held = set(minima["experiment"]) if not minima.empty else set()
    names = [name for name in thesis_values.EXPERIMENTS if name in held]
    return experiment_bounds(names, registry) if names else {}


def _stance_ground(registry: PluginRegistry | None, df):
    """``ground(experiment, step)``: how the ground bends under that step's stance foot (``Terrain.bend``), or None
    for an experiment the registry cannot build; ``experiment`` is a report label (``forward [2 steps]``), built from
    the plugin name and options of the cases ``df`` that carry it."""
    from functools import cache

    from gaitbench.plugins import PluginConflictError, UnknownPluginError, load_registry

    built = {label: (name, options) for label, name, options in
             zip(df["experiment"], df["experiment_name"], df["experiment_options"], strict=True)} if len(df) else {}

    @cache
    def terrain(label: str):
        name, options = built.get(label, (label, None))
        try:
            return (registry or load_registry()).create("experiment", name, **dict(options or {})).terrain
        except (UnknownPluginError, PluginConflictError, TypeError, ValueError):
            return None

    def ground(experiment: str, step: int) -> str | None:
        found = terrain(experiment)
        return found.bend(step) if found is not None and 1 <= step <= len(found.steps) else None

    return ground


def _partial_note(case) -> str:
    """What a chosen gait that is not a complete walk shows, said before anything else about it."""
    import math

    where = f" at step {int(case['stop_step'])}" if not _missing(case["stop_step"]) else ""
    solved = 0 if _missing(case["steps_solved"]) else int(case["steps_solved"])
    figure = case["partial_acot"]
    mean = "" if _missing(figure) or math.isnan(figure) else f"; partial ACOT of those steps {figure:.4g}"
    return (f"Partial walk: it stopped{where} ({case['stop_cause']}; {case['status']}: {case['message']}) after "
            f"{solved} solved steps{mean}. It has no ACOT, and no partial figure enters any ACOT of this report.")


def _missing(value) -> bool:
    import pandas as pd

    return value is None or bool(pd.isna(value))


def _track_summaries(store_dir: Path, df) -> dict[str, dict]:
    summaries = {}
    if df.empty:
        return summaries
    for key, path in zip(df["case_key"], df["tracking_path"], strict=True):
        if isinstance(path, str) and (store_dir / path).is_file():
            try:
                summaries[key] = json.loads((store_dir / path).read_text())
            except (OSError, json.JSONDecodeError):
                continue
    return summaries


def write_report(store_dir: str | Path, out_dir: str | Path, gait: str | None = None,
                 reporters: Sequence[str] = DEFAULT_REPORTERS, registry: PluginRegistry | None = None,
                 progress: ProgressCallback | None = None) -> Path:
    """Write the report of the store at ``store_dir`` into ``out_dir`` with the named reporter plugins.

    Returns the HTML page (``out_dir/index.html``) when the ``html`` reporter ran, else ``out_dir``.
    Raises :class:`ReportError` for a missing store, an unknown ``gait`` case key or a report that cannot be written
    (a full disk). ``progress(what, done, total)`` is told about each part (tables, each experiment's figures, each
    gait and tracked case, each reporter) as it is done.
    """
    from gaitbench.plugins import load_registry

    registry = registry or load_registry()
    built = [registry.create("reporter", name) for name in reporters]
    steps = _Steps(progress, total=len(built))
    report = build_report(store_dir, gait=gait, registry=registry, progress=steps)
    out_dir = Path(out_dir)
    try:
        out_dir.mkdir(parents=True, exist_ok=True)
        for name, reporter in zip(reporters, built, strict=True):
            steps.start(f"writing {name}")
            reporter.write(report, out_dir)
    except OSError as error:  # a full disk, a place that cannot be written
        where = f": {error.filename}" if error.filename else ""
        advice = ("choose a directory with --out" if isinstance(error, FileExistsError | NotADirectoryError)
                  else "free some space or choose another directory with --out")
        raise ReportError(f"{out_dir}: cannot write the report ({error.strerror or error}{where}); {advice}") from None
    steps.finish()
    index = out_dir / "index.html"
    return index if "html" in reporters else out_dir
