"""``gaitbench run`` and ``gaitbench runs``: run a suite into a store, and look at what a store holds."""

from __future__ import annotations

import os
import signal
from collections.abc import Iterator
from contextlib import ExitStack, contextmanager
from datetime import datetime, timezone
from pathlib import Path

import click
from rich import box
from rich.console import Console
from rich.table import Table
from rich.text import Text

from gaitbench.cli.common import count
from gaitbench.cli.run_progress import CaseProgress, StepsInFlight
from gaitbench.plugins import PLUGINS_DIR_ENV
from gaitbench.run.executors import EXECUTORS
from gaitbench.run.store import LOCK_TIMEOUT_S


def _band(ctx, param, value: str | None) -> tuple[int, int] | None:
    """``--band LOW-HIGH`` as (LOW, HIGH); None for the report's default."""
    if value is None:
        return None
    low, sep, high = value.partition("-")
    try:
        band = (int(low), int(high))
    except ValueError:
        band = None
    if not sep or band is None or band[0] > band[1]:
        raise click.BadParameter(f"{value!r} is not LOW-HIGH with LOW <= HIGH, e.g. 40-90")
    return band


def consistency_options(command):
    """``--band`` and ``--tolerance``: the consistency check's parameters (gaitbench.reports.statistics), whose
    defaults are the report's; resolved there, so that this module does not import pandas for ``--help``."""
    command = click.option("--tolerance", type=click.FloatRange(min=0, min_open=True), default=None,
                           show_default="0.15",
                           help="Consistency check: the largest relative distance of a finer N's ACOT from the "
                                "reference median.")(command)
    return click.option("--band", metavar="LOW-HIGH", callback=_band, default=None,
                        show_default="40-90",
                        help="Consistency check: the coarser N whose median ACOT is each experiment and method's "
                             "reference; every N above HIGH is checked.")(command)


def inconsistent_keys(store_dir: Path, band: tuple[int, int] | None, tolerance: float | None) -> set[str]:
    """The keys of the complete walks that fail the report's consistency check (``consistency.csv``)."""
    from gaitbench.reports import case_frame, statistics, tables
    from gaitbench.run.store import load_results

    band = band or statistics.CONSISTENCY_BAND
    tolerance = statistics.CONSISTENCY_TOLERANCE if tolerance is None else tolerance
    df = case_frame.prepare(load_results(store_dir))
    return statistics.inconsistent_keys(df, tables.acot_table(df), band=band, tolerance=tolerance)


@click.command("run")
@click.argument("suite_file", metavar="SUITE.toml", type=click.Path(exists=True, dir_okay=False, path_type=Path))
@click.option("--jobs", "-j", type=click.IntRange(min=1), default=1, show_default=True,
              help="Worker processes (local executor) or local Dask workers.")
@click.option("--executor", type=click.Choice(EXECUTORS), default="local", show_default=True,
              help="local: a pool of worker processes that can stop a hung case; dask: a Dask cluster; "
                   "inprocess: this process, for debugging (time limits reach the solver only).")
@click.option("--scheduler", metavar="ADDR", help="Address of an existing Dask scheduler, e.g. tcp://HOST:8786 "
              "(implies --executor dask); without it a local cluster of --jobs workers is started.")
@click.option("--store", "store_dir", type=click.Path(file_okay=False, path_type=Path),
              help="Results directory [default: the suite's `output`].")
@click.option("--method", "methods", multiple=True, metavar="LABEL",
              help="Run only this method's cases (repeatable), e.g. --method OP-DC --method 'D&C-DC' (quote a "
                   "label with & in a shell); a later run with --resume does the rest.")
@click.option("--resume", is_flag=True, help="Skip the cases the store already holds.")
@click.option("--retry-failed", is_flag=True,
              help="With --resume, run again the cases that errored, timed out or crashed.")
@click.option("--retry-incomplete", is_flag=True,
              help="With --resume, run again the cases whose walks stopped before their last step: after a "
                   "change to gaitbench that may take them further, or with a larger time limit (a walk stopped by "
                   "its limit goes on from the steps it solved). The new row replaces the old.")
@click.option("--retry-unverified", is_flag=True,
              help="With --resume, run again the complete walks that have no verified ACOT (a decrease-and-conquer "
                   "step whose polish failed): after a change to gaitbench that may verify them.")
@click.option("--retry-inconsistent", is_flag=True,
              help="With --resume, run again the complete walks whose ACOT fails the report's consistency check: "
                   "a finer N more than --tolerance from the method's median over --band (`gaitbench runs show "
                   "STORE --inconsistent` lists them): after a change to gaitbench that may take them to a better "
                   "optimum.")
@consistency_options
@click.option("--smallest-first", is_flag=True,
              help="Start cases smallest N first instead of largest first. Largest first ends a run soonest; "
                   "smallest first suits a sweep run over several sessions with --resume (the thesis suites' "
                   "reference column: hours per case from N = 100 on), whose tables then fill N by N.")
@click.option("--lock-timeout", type=click.FloatRange(min=0), default=LOCK_TIMEOUT_S, show_default=True,
              metavar="SECONDS", help="How long a store operation waits for the store's write lock (held by "
                                      "another run or program) before the run stops with an error.")
@click.option("--report/--no-report", "write_report", default=True, show_default=True,
              help="Write the HTML and CSV report (`gaitbench report`) to reports/<store name> at the end.")
@click.pass_obj
def run(state, suite_file: Path, jobs: int, executor: str, scheduler: str | None, store_dir: Path | None,
        methods: tuple[str, ...], resume: bool, retry_failed: bool, retry_incomplete: bool,
        retry_unverified: bool, retry_inconsistent: bool, band: tuple[int, int] | None, tolerance: float | None,
        smallest_first: bool, lock_timeout: float, write_report: bool) -> None:
    """Run every case of a suite and record each in the results store as it finishes.

    Cases start largest N first, so that the longest ones do not finish the run alone while other workers idle
    (--smallest-first for the other order).

    A run that is stopped (Ctrl-C, a kill, a crash, a store that fails) keeps every finished case; run again with
    --resume to do the rest. Runs started on the same store while one is running share its cases (no case is
    solved twice). The store is a new or empty directory, or a store: a directory with other files is refused.
    Exit status 1 if any case failed or the store cannot be used, 2 if the suite is invalid, 143 if stopped by
    SIGTERM (which, like Ctrl-C, stops the workers and keeps every finished case).
    """
    from gaitbench.run.executors import ExecutorError
    from gaitbench.run.runner import RunRefused, run_suite
    from gaitbench.run.store_schema import StoreError
    from gaitbench.run.suite import SuiteError, load_suite

    if state.plugin_dirs:  # through the environment, so worker processes load them too
        os.environ[PLUGINS_DIR_ENV] = os.pathsep.join(
            [*map(str, state.plugin_dirs), *filter(None, [os.environ.get(PLUGINS_DIR_ENV)])])
    try:
        suite = load_suite(suite_file)
    except SuiteError as error:  # the file names itself, the key and what was expected
        raise click.UsageError(str(error)) from None
    console = Console(stderr=True)
    for problem in suite.plugin_problems:  # as `gaitbench plugins` shows them: a missing plugin changes the run
        console.print(Text(f"warning: {problem.source}: {problem.message}", style="yellow"), soft_wrap=True)
    if methods:
        try:
            suite = suite.with_methods(methods)
        except ValueError as error:
            raise click.BadParameter(str(error), param_hint="--method") from None
    if scheduler:
        executor = "dask"
    if executor != "inprocess" and not scheduler:  # the workers start on this machine
        jobs = _jobs_that_help(jobs, suite, console)
    store_dir = store_dir or suite.output
    rerun: set[str] = set()
    if retry_inconsistent and Path(store_dir).exists():
        try:
            rerun = inconsistent_keys(Path(store_dir), band, tolerance)
        except StoreError as error:
            raise click.ClickException(str(error)) from None
    try:
        with CaseProgress(console, StepsInFlight(Path(store_dir), suite.cases)) as progress, _sigterm_unwinds():
            summary = run_suite(suite, store_dir, _executor(executor, jobs, scheduler), resume=resume,
                                retry_failed=retry_failed, retry_incomplete=retry_incomplete,
                                retry_unverified=retry_unverified, rerun=rerun, smallest_first=smallest_first,
                                lock_timeout=lock_timeout,
                                on_start=_warning_fewer_cases(jobs if not scheduler else 0, progress, console),
                                on_outcome=progress.advance, on_elsewhere=progress.elsewhere)
    except (RunRefused, StoreError, ExecutorError) as error:
        raise click.ClickException(str(error)) from None
    except Terminated as stop:
        console.print(f"stopped by SIGTERM; the finished cases are in {store_dir}: run again with --resume to do "
                      "the rest")
        raise SystemExit(stop.code) from None
    shared = f"{summary.elsewhere} solved by another run, " if summary.elsewhere else ""
    console.print(f"run {summary.run_id}: {summary.solved} solved, {summary.failed} failed, {shared}"
                  f"{summary.skipped} already in the store, {summary.wall_time_s:.1f} s; store: {summary.store}")
    try:
        Console().print(_suite_results(suite, store_dir))
    except StoreError as error:
        raise click.ClickException(str(error)) from None
    if write_report:
        from gaitbench.cli.report_command import default_report_dir, write_with_progress
        from gaitbench.reports import ReportError

        try:
            index = write_with_progress(store_dir, default_report_dir(store_dir), console)
        except ReportError as error:
            raise click.ClickException(str(error)) from None
        console.print(Text(f"report: {Path(index).resolve()}", style="bold"), soft_wrap=True)
    if summary.failed:
        raise SystemExit(1)


def _suite_results(suite, store_dir: Path) -> Table:
    """What the suite's walks came to, from the store (cases of earlier runs too, so a resumed run shows them all):
    per experiment and method, how many walks are complete, the lowest verified ACOT over those and its N, and why
    the others stopped."""
    from gaitbench.run.store import ResultStore

    keys = {case.key for case in suite.cases}
    with ResultStore.open(store_dir) as store:
        rows = [row for row in store.cases() if row["case_key"] in keys]
    order = {case.key: i for i, case in enumerate(suite.cases)}
    groups: dict[tuple[str, str], list[dict]] = {}
    for row in sorted(rows, key=lambda row: order[row["case_key"]]):
        groups.setdefault((row["experiment"], row["method"] or row["strategy"]), []).append(row)
    table = Table(title=f"{suite.name}: lowest verified ACOT over complete walks",
                  box=box.SIMPLE_HEAD, title_justify="left", show_edge=False, pad_edge=False)
    longest = max((len(method) for _, method in groups), default=0)
    for column in ("experiment", "method", "complete", "ACOT", "at N", "incomplete"):
        table.add_column(column, justify="right" if column in ("complete", "ACOT", "at N") else "left",
                         overflow="fold", no_wrap=column in ("complete", "ACOT", "at N"),
                         min_width=min(22, longest) if column == "method" else None)  # "decrease-and-conquer"
    for (experiment, method), group in groups.items():
        complete = [row for row in group if row["status"] == "solved"]
        best = min((row for row in complete if row["acot"] is not None), key=lambda row: row["acot"], default=None)
        causes: dict[str, int] = {}
        for row in group:
            if row not in complete:
                cause = row["stop_cause"] or row["status"]
                causes[cause] = causes.get(cause, 0) + 1
        table.add_row(experiment, method, f"{len(complete)} of {len(group)}",
                      _number(best["acot"] if best else None, ".4f") or "—", str(best["N"]) if best else "—",
                      ", ".join(f"{cause} ({count})" for cause, count in causes.items()) or "—")
    return table


class Terminated(SystemExit):
    """SIGTERM, raised where the run is, so that it unwinds (:func:`_sigterm_unwinds`)."""


@contextmanager
def _sigterm_unwinds() -> Iterator[None]:
    """SIGTERM stops the run as Ctrl-C does, unwinding: the finished cases recorded, the run closed in the store, the
    workers stopped and what they share with this process released (ended outright, the resource tracker warned of
    leaked semaphores). A second SIGTERM ends the process at once. Exit status 128 + SIGTERM, as a shell reports."""
    def stop(signum: int, frame) -> None:
        signal.signal(signal.SIGTERM, signal.SIG_DFL)
        raise Terminated(128 + signum)

    try:
        previous = signal.signal(signal.SIGTERM, stop)
    except ValueError:  # not the main thread (an embedding program's): its own handling stays
        yield
        return
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)


def _jobs_that_help(jobs: int, suite, console: Console) -> int:
    """``--jobs``, lowered with a warning line to the number of cases (more workers would only idle) and to what
    fits in this machine's memory (:func:`gaitbench.run.memory.jobs_that_fit`)."""
    from gaitbench.run.memory import jobs_that_fit

    if jobs > len(suite.cases) > 0:
        console.print(Text(f"warning: --jobs {jobs} lowered to {len(suite.cases)}: the suite has "
                           f"{count(len(suite.cases), 'case')}", style="yellow"), soft_wrap=True)
        jobs = len(suite.cases)
    fitting, why = jobs_that_fit([suite.memory_mb[case.key] for case in suite.cases if case.key in suite.memory_mb],
                                 jobs)
    if why is not None:
        console.print(Text(f"warning: --jobs {jobs} lowered to {fitting}: {why}", style="yellow"), soft_wrap=True)
    return fitting


def _warning_fewer_cases(jobs: int, progress: CaseProgress, console: Console):
    """``progress.start``, after the warning line that ``jobs`` workers are lowered to the cases left to run (the
    runner starts no more: a resumed run's few cases)."""
    def start(to_run: int, skipped: int) -> None:
        if 0 < to_run < jobs:
            console.print(Text(f"warning: --jobs {jobs} lowered to {to_run}: {to_run} of the suite's cases are left "
                               "to run", style="yellow"), soft_wrap=True)
        progress.start(to_run, skipped)

    return start


def _executor(name: str, jobs: int, scheduler: str | None):
    from gaitbench.run.executors import DaskExecutor, InProcessExecutor, LocalPoolExecutor

    if name == "dask":
        return DaskExecutor(scheduler, jobs)
    if name == "inprocess":
        return InProcessExecutor()
    return LocalPoolExecutor(jobs)


@click.group("runs")
def runs() -> None:
    """Look at results stores: their runs, their cases, exports for other tools, and merging stores."""


@runs.command("list")
@click.argument("stores", nargs=-1, type=click.Path(path_type=Path))
def runs_list(stores: tuple[Path, ...]) -> None:
    """List the runs of each STORE (default: every store under ./results), then the walks in flight: each case
    whose checkpoint holds solved steps, how many, the time spent on it, and whether a live run is solving it now
    or `gaitbench run --resume` would take it up from there."""
    from gaitbench.run.store import DATABASE, ResultStore, run_alive
    from gaitbench.run.store_schema import StoreError

    paths = list(stores) or sorted(path.parent for path in Path("results").glob(f"*/{DATABASE}"))
    if not paths:
        raise click.ClickException("no results stores under ./results; name a store directory")
    table = Table(title="runs")
    for column in ("store", "run", "suite", "executor", "jobs", "cases", "done", "failed", "skipped", "finished"):
        table.add_column(column)
    in_flight = Table(title="walks in flight")
    for column in ("store", "case", "steps saved", "time (h)", "last saved (UTC)", "now"):
        in_flight.add_column(column)
    for path in paths:
        try:
            with ResultStore.open(path) as store:
                runs_rows = store.runs()
                for row in runs_rows:
                    table.add_row(str(path), row["run_id"], row["suite"], row["executor"], str(row["jobs"]),
                                  str(row["cases_total"]), str(row["cases_done"]), str(row["cases_failed"] or 0),
                                  str(row["cases_skipped"]), row["finished_at"] or _unfinished(row, run_alive))
                for cells in walks_in_flight(path, runs_rows, store.live_claims()):
                    in_flight.add_row(str(path), *cells)
        except StoreError as error:
            raise click.ClickException(str(error)) from None
    Console().print(table)
    if in_flight.row_count:
        Console().print(in_flight)


def walks_in_flight(store_dir: Path, runs_rows: list[dict], live: set[str]) -> list[tuple[str, ...]]:
    """(case, steps saved, hours spent, when the last step was saved, solving or resumable) for each checkpoint of
    ``store_dir`` with a progress file: a step of an hour shows as a save time that stays put. A case is named by
    its label in the suite of the store's runs that holds it (the key where no run's suite file can still be
    read)."""
    from gaitbench.run.store import CHECKPOINTS_DIR
    from gaitbench.solve.checkpoint import progress_file, saved_progress

    directory = store_dir / CHECKPOINTS_DIR
    progress = saved_progress(directory)
    if not progress:
        return []
    labels = _case_labels({(row["suite_path"], row.get("suite_text")) for row in runs_rows if row.get("suite_path")})
    return [(labels.get(key, key), f"{saved.get('saved', '?')} of {saved.get('of') or '?'}",
             _number(saved.get("elapsed_s", 0.0) / 3600, ".2f"), _saved_at(progress_file(directory / key)),
             "solving" if key in live else "resumable")
            for key, saved in sorted(progress.items())]


def _saved_at(path: Path) -> str:
    """The time a progress file was last written, to the minute, in UTC; blank when it is gone."""
    try:
        return datetime.fromtimestamp(path.stat().st_mtime, timezone.utc).strftime("%Y-%m-%d %H:%M")
    except OSError:
        return ""


def _case_labels(suites: set[tuple[str, str | None]]) -> dict[str, str]:
    """Case key → label over the runs' suites, (path, text as the run recorded it): the recorded text names the
    cases that run had, wherever the file has gone since (a run recorded without it reads the file). A suite that
    cannot be read or expanded is skipped, not an error."""
    from gaitbench.run.suite import load_suite
    from gaitbench.run.suite_spec import SuiteError

    labels = {}
    for suite_path, text in sorted(suites, key=lambda suite: (suite[0], suite[1] or "")):
        try:
            labels.update({case.key: case.label for case in load_suite(suite_path, text=text).cases})
        except SuiteError:  # a suite whose plugins are gone only costs the label
            continue
    return labels


SHOW_COLUMNS = ("experiment", "N", "method", "status", "stop cause", "ACOT")
"""What `runs show` prints by default: readable at 80 columns. `--wide` adds :data:`WIDE_COLUMNS`."""

WIDE_COLUMNS = ("case", "experiment", "N", "method", "status", "stop cause", "stop step", "stop status", "ACOT",
                "claimed", "COT min", "COT max", "retries", "time (s)", "iterations", "message")
TEXT_COLUMNS = ("case", "experiment", "method", "status", "stop cause", "stop status", "message")


def _show_cells(row: dict) -> dict[str, str]:
    """One store row as the cells of every `runs show` column."""
    cells = {"case": row["case_key"], "experiment": row["experiment"], "N": str(row["N"]),
             "method": row["method"] or row["strategy"], "status": row["status"],
             "stop cause": row["stop_cause"] or "—", "stop step": _number(row["stop_step"], "d"),
             "stop status": row["stop_status"] or "", "retries": _number(row["retries"], "d"),
             "time (s)": _number(row["wall_time_s"], ".1f"), "iterations": _number(row["iterations"], "d"),
             "message": row["message"] or ""}
    for column, key in (("ACOT", "acot"), ("claimed", "claimed_acot"), ("COT min", "cot_min"), ("COT max", "cot_max")):
        cells[column] = _number(row[key], ".4f")
    return cells


@runs.command("show")
@click.argument("store_dir", metavar="STORE", type=click.Path(path_type=Path))
@click.argument("run_id", metavar="[RUN]", required=False)
@click.option("--wide", is_flag=True, help="Every column: case key, where and why each walk stopped, the claimed "
              "ACOT, per-step COT bounds, retries, time, iterations and the message (lines longer than 80 columns).")
@click.option("--experiment", "experiments", multiple=True, metavar="NAME",
              help="Only this experiment's cases (repeatable).")
@click.option("--method", "methods", multiple=True, metavar="LABEL",
              help="Only this method's cases: its suite label, or its strategy where it has none (repeatable).")
@click.option("--status", "statuses", multiple=True, metavar="STATUS",
              help="Only cases with this status: solved, incomplete, error, timeout, crashed (repeatable).")
@click.option("--inconsistent", is_flag=True,
              help="Only the complete walks that fail the report's consistency check (consistency.csv): a finer N "
                   "whose ACOT lies more than --tolerance from the method's median over --band. `gaitbench run "
                   "SUITE --resume --retry-inconsistent` solves them again.")
@consistency_options
def runs_show(store_dir: Path, run_id: str | None, wide: bool, experiments: tuple[str, ...],
              methods: tuple[str, ...], statuses: tuple[str, ...], inconsistent: bool, band: tuple[int, int] | None,
              tolerance: float | None) -> None:
    """Show the cases of STORE as a table: all of them, or those one RUN (an id or its prefix) computed, narrowed
    by --experiment, --method and --status.

    By default the table fits 80 columns: experiment, N, method, status, why the walk stopped (stop cause:
    complete, geometry, solver, verification, time_limit, error, crashed) and the verified ACOT. --wide shows
    everything else.
    """
    from gaitbench.run.store import ResultStore
    from gaitbench.run.store_schema import StoreError

    try:
        with ResultStore.open(store_dir) as store:
            rows = store.cases(store.resolve_run(run_id) if run_id else None)
        flagged = inconsistent_keys(store_dir, band, tolerance) if inconsistent else None
    except StoreError as error:
        raise click.ClickException(str(error)) from None
    rows = [row for row in rows if (flagged is None or row["case_key"] in flagged)
            and (not experiments or row["experiment"] in experiments)
            and (not methods or (row["method"] or row["strategy"]) in methods)
            and (not statuses or row["status"] in statuses)]
    columns = WIDE_COLUMNS if wide else SHOW_COLUMNS
    table = Table(title=f"{store_dir}" + (f" run {run_id}" if run_id else ""), box=box.SIMPLE_HEAD,
                  title_justify="left", show_edge=False, pad_edge=False)
    widths = {"method": 20, "ACOT": 6, "N": 3}  # "decrease-and-conquer" on one line, numbers whole
    for column in columns:
        table.add_column(column, justify="left" if column in TEXT_COLUMNS else "right", overflow="fold",
                         no_wrap=column in ("case", "N", "ACOT"), min_width=None if wide else widths.get(column))
    for row in rows:
        cells = _show_cells(row)
        table.add_row(*(cells[column] for column in columns))
    console = Console()
    if wide:  # every column at its natural width: long lines rather than squeezed cells
        console = Console(width=max(console.width, 240))
    console.print(table)


@runs.command("export")
@click.argument("store_dir", metavar="STORE", type=click.Path(path_type=Path))
@click.option("--format", "fmt", type=click.Choice(["csv", "parquet"]), default="csv", show_default=True)
@click.option("--out", type=click.Path(dir_okay=False, path_type=Path),
              help="Output file [default: STORE/cases.csv or STORE/cases.parquet].")
def runs_export(store_dir: Path, fmt: str, out: Path | None) -> None:
    """Export every case of STORE, one row per case (JSON columns as JSON text in CSV; text a spreadsheet would take
    for a formula, such as a label beginning with =, escaped with a leading ')."""
    import json

    from gaitbench.run.store import load_results
    from gaitbench.run.store_schema import JSON_COLUMNS, StoreError

    try:
        frame = load_results(store_dir)
    except StoreError as error:
        raise click.ClickException(str(error)) from None
    for column in JSON_COLUMNS:  # nested values as JSON text: one flat, typed table for CSV and Parquet alike
        frame[column] = frame[column].map(lambda value: None if value is None else json.dumps(value))
    out = out or Path(store_dir) / f"cases.{fmt}"
    try:
        if fmt == "csv":
            from gaitbench.reports.tables import spreadsheet_safe

            spreadsheet_safe(frame).to_csv(out, index=False)
        else:
            frame.to_parquet(out, index=False)
    except OSError as error:  # e.g. the default, inside a store in a read-only place
        raise click.ClickException(f"{out}: cannot write the export ({error.strerror or error}); "
                                   "choose another file with --out") from None
    Console(stderr=True).print(f"wrote {count(len(frame), 'case')} to {out}")


@runs.command("merge")
@click.argument("sources", metavar="SOURCE...", nargs=-1, required=True, type=click.Path(path_type=Path))
@click.option("--into", "destination", required=True, type=click.Path(file_okay=False, path_type=Path),
              help="The store to merge into (created if it does not exist).")
@click.option("--replace", is_flag=True, help="Where a case is in both stores with other results, take the "
              "source's (default: keep the destination's and list the case).")
def runs_merge(sources: tuple[Path, ...], destination: Path, replace: bool) -> None:
    """Copy the cases of each SOURCE store into the store --into, with their files and the runs that computed them.

    For a sweep run a part at a time on several machines or in several sessions (a suite's `--method` columns,
    say): merged, one `gaitbench report` covers it all. A case is the same walk in every store (its key), so a case
    the destination holds already is left alone; each copied case keeps its provenance (commit, machine, solver
    versions). Cases a live run on the destination is solving are left to it, and checkpoints of walks in flight
    are not copied: resume those on the store that holds them. The destination may be in use by `gaitbench run`.
    """
    from gaitbench.run.merge import describe, merge_store
    from gaitbench.run.store import ResultStore
    from gaitbench.run.store_schema import StoreError

    try:
        with ExitStack() as stack:
            opened = [stack.enter_context(ResultStore.open(source)) for source in sources]  # all, before writing
            into = stack.enter_context(ResultStore.create(destination))
            for source, store in zip(sources, opened, strict=True):
                click.echo(describe(merge_store(into, store, replace=replace), source, destination), err=True)
    except StoreError as error:
        raise click.ClickException(str(error)) from None


def _unfinished(run: dict, alive) -> str:
    if alive(run):
        return f"running (pid {run['pid']} on {run['host']})"
    return "not finished"


def _number(value, spec: str) -> str:
    return "" if value is None else format(value, spec)
