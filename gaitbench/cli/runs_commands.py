"""``gaitbench runs``: look at what results stores hold (their runs, their cases, the walks in flight), export them
and merge them."""

from __future__ import annotations

from contextlib import ExitStack
from datetime import datetime, timezone
from pathlib import Path

import click
from rich import box
from rich.console import Console
from rich.table import Table

from gaitbench.cli.common import count, fmt, print_table
from gaitbench.cli.consistency_options import consistency_options, inconsistent_keys


@click.group("runs")
def runs() -> None:
    """Look at results stores: their runs, their cases, exports for other tools, merging stores, and packing a store
    into one file (which every command that reads a store reads as it is)."""


@runs.command("list")
@click.argument("stores", nargs=-1, type=click.Path(path_type=Path))
@click.option("--wide", is_flag=True, help="One table of every column: the store, the suite, the executor and its "
              "jobs, and the finish time to the second (lines longer than 80 columns).")
def runs_list(stores: tuple[Path, ...], wide: bool) -> None:
    """List the runs of each STORE (default: every store under ./results), then the walks in flight: each case
    whose checkpoint holds solved steps, how many, the time spent on it, and whether a live run is solving it now
    or `gaitbench run --resume` would take it up from there.

    By default each store gets its own tables, which fit 80 columns: a run's id ends with its suite's name (the
    suite is named under it where it does not), and its finish time is given to the minute in UTC. --wide shows
    the executor, the jobs and the finish time as recorded as well.
    """
    from gaitbench.run.liveness import run_alive
    from gaitbench.run.store import DATABASE, ResultStore
    from gaitbench.run.store_schema import StoreError

    paths = list(stores) or sorted(path.parent for path in Path("results").glob(f"*/{DATABASE}"))
    if not paths:
        raise click.ClickException("no results stores under ./results; name a store directory")
    listed = []
    for path in paths:
        try:
            with ResultStore.open(path) as store:
                runs_rows = store.runs()
                flying = walks_in_flight(store.directory, runs_rows, store.live_claims())
        except StoreError as error:
            raise click.ClickException(str(error)) from None
        listed.append((path, runs_rows, flying))
    console = Console()
    if wide:
        table = _table("runs", RUN_COLUMNS)
        in_flight = _table("walks in flight", ("store", *IN_FLIGHT_COLUMNS))
        for path, runs_rows, flying in listed:
            for row in runs_rows:
                cells = _run_cells(row, run_alive)
                table.add_row(str(path), *(cells[column] for column in RUN_COLUMNS[1:]))
            for cells in flying:
                in_flight.add_row(str(path), *cells)
        print_table(console, table, wide=True)
        if in_flight.row_count:
            print_table(console, in_flight, wide=True)
        return
    for path, runs_rows, flying in listed:
        table = _table(f"runs of {path}", [header for header, _ in NARROW_RUN_COLUMNS])
        table.caption, table.caption_justify = RUNS_LEGEND, "left"
        for row in runs_rows:
            cells = _run_cells(row, run_alive)
            table.add_row(*(cells[key] for _, key in NARROW_RUN_COLUMNS))
        print_table(console, table)
        if flying:
            in_flight = _table(f"walks in flight in {path}", IN_FLIGHT_COLUMNS)
            for cells in flying:
                in_flight.add_row(*cells)
            print_table(console, in_flight)


RUN_COLUMNS = ("store", "run", "suite", "executor", "jobs", "cases", "done", "failed", "skipped", "finished")
"""The columns of `runs list --wide`."""

NARROW_RUN_COLUMNS = (("run", "run with suite"), ("cases", "cases"), ("done", "done"), ("fail", "failed"),
                      ("skip", "skipped"), ("finished", "finished (UTC)"))
"""The columns of `runs list`, one table per store, as (header, cell): 80 columns wide with a run id of up to 37
characters; short headers, which :data:`RUNS_LEGEND` explains."""

RUNS_LEGEND = ("cases: the suite's; done, fail, skip: those the run solved, that failed, and that it found in the "
               "store; finished: in UTC")

IN_FLIGHT_COLUMNS = ("case", "steps saved", "time (h)", "last saved (UTC)", "now")
NUMBER_COLUMNS = ("jobs", "cases", "done", "failed", "fail", "skipped", "skip", "steps saved", "time (h)")


def _table(title: str, columns) -> Table:
    """A table in the style of `runs show`: a rule under the header, no frame, folding what does not fit (never
    cutting it short with an ellipsis)."""
    table = Table(title=title, box=box.SIMPLE_HEAD, title_justify="left", show_edge=False, pad_edge=False,
                  collapse_padding=True)
    for column in columns:  # names whole on one line, if any column has to wrap
        table.add_column(column, justify="right" if column in NUMBER_COLUMNS else "left", overflow="fold",
                         no_wrap=column in ("run", "case"))
    return table


def _run_cells(row: dict, alive) -> dict[str, str]:
    """One run of a store as the cells of every `runs list` column; "run with suite" names the suite under an id
    that does not end with it (gaitbench names a run by its start time and suite, "-2" for a second one)."""
    finished, run_id, suite = row["finished_at"], row["run_id"], row["suite"] or ""
    tail = run_id.split("-", 2)[-1]
    names_suite = tail == suite or tail.startswith(f"{suite}-")
    unfinished = _unfinished(row, alive)
    return {"run": run_id, "run with suite": run_id if names_suite else f"{run_id}\nsuite {suite}", "suite": suite,
            "executor": row["executor"] or "", "jobs": str(row["jobs"]), "cases": str(row["cases_total"]),
            "done": str(row["cases_done"]), "failed": str(row["cases_failed"] or 0),
            "skipped": str(row["cases_skipped"]), "finished": finished or unfinished,
            "finished (UTC)": _to_the_minute(finished) if finished else unfinished}


def _to_the_minute(stamp: str) -> str:
    """An ISO time stamp as ``2026-12-02 12:44`` in UTC; as it is where it is no ISO time."""
    try:
        moment = datetime.fromisoformat(stamp)
    except ValueError:
        return stamp
    if moment.tzinfo is not None:
        moment = moment.astimezone(timezone.utc)
    return moment.strftime("%Y-%m-%d %H:%M")


def walks_in_flight(store_dir: Path, runs_rows: list[dict], live: set[str]) -> list[tuple[str, ...]]:
    """(case, steps saved, hours spent, when the last step was saved, solving or resumable) for each checkpoint of
    ``store_dir`` with a progress file: a step of an hour shows as a save time that stays put. A case is named by
    its label in the suite of the store's runs that holds it (the key where no run's suite file can still be
    read)."""
    from gaitbench.checkpoint import progress_file, saved_progress
    from gaitbench.run.store import CHECKPOINTS_DIR

    directory = store_dir / CHECKPOINTS_DIR
    progress = saved_progress(directory)
    if not progress:
        return []
    from gaitbench.run.provenance import code_fingerprint

    labels = _case_labels({(row["suite_path"], row.get("suite_text")) for row in runs_rows if row.get("suite_path")})

    def state(key: str, saved: dict) -> str:  # a checkpoint resumes only under the code that saved it
        if key in live:
            return "solving"
        return "resumable" if saved.get("code") in (None, code_fingerprint()) else "saved by other code: from step 1"

    return [(labels.get(key, key), f"{saved.get('saved', '?')} of {saved.get('of') or '?'}",
             fmt(saved.get("elapsed_s", 0.0) / 3600, ".2f", ""), _saved_at(progress_file(directory / key)),
             state(key, saved))
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
                "verified", "claimed", "COT min", "COT max", "retries", "time (s)", "iterations", "message")
TEXT_COLUMNS = ("case", "experiment", "method", "status", "stop cause", "stop status", "verified", "message")


def _show_cells(row: dict) -> dict[str, str]:
    """One store row as the cells of every `runs show` column; ``verified`` is empty where the walk was never
    checked (not complete, or stored before verification)."""
    cells = {"case": row["case_key"], "experiment": row["experiment"], "N": str(row["N"]),
             "method": row["method"] or row["strategy"], "status": row["status"],
             "stop cause": row["stop_cause"] or "—", "stop step": fmt(row["stop_step"], "d", ""),
             "stop status": row["stop_status"] or "", "retries": fmt(row["retries"], "d", ""),
             "time (s)": fmt(row["wall_time_s"], ".1f", ""), "iterations": fmt(row["iterations"], "d", ""),
             "message": _message(row),
             "verified": {1: "yes", 0: "no"}.get(row["verified"], "") if _complete(row) else ""}
    for column, key in (("ACOT", "acot"), ("claimed", "claimed_acot"), ("COT min", "cot_min"), ("COT max", "cot_max")):
        cells[column] = fmt(row[key], ".4f", "")
    if _unverified(row) and cells["ACOT"]:
        cells["ACOT"] = f"({cells['ACOT']})"
    return cells


def _complete(row: dict) -> bool:
    return row["status"] == "solved"


def _unverified(row: dict) -> bool:
    """A complete walk that failed verification (an incomplete one is stored unverified too, for its stop)."""
    return _complete(row) and row.get("verified") == 0


def _message(row: dict) -> str:
    """The case's message, and why a complete walk failed verification."""
    failure = row.get("verification_failure") if _unverified(row) else None
    return "; ".join(part for part in (row["message"], failure and f"not verified: {failure}") if part)


@runs.command("show")
@click.argument("store_dir", metavar="STORE", type=click.Path(path_type=Path))
@click.argument("run_id", metavar="[RUN]", required=False)
@click.option("--wide", is_flag=True, help="Every column: case key, where and why each walk stopped, the claimed "
              "ACOT, per-step COT bounds, retries, time, iterations and the message (lines longer than 80 columns).")
@click.option("--experiment", "experiments", multiple=True, metavar="NAME",
              help="Only this experiment's cases (repeatable).")
@click.option("--method", "methods", multiple=True, metavar="LABEL",
              help="Only this method's cases: its suite label, or its strategy where it has none (repeatable).")
@click.option("--status", "statuses", multiple=True,
              type=click.Choice(["solved", "incomplete", "error", "timeout", "crashed"]),
              help="Only cases with this status (repeatable).")
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
    complete, geometry, solver, verification, time_limit, error, crashed) and the ACOT, in parentheses where the
    walk failed the whole-walk verification (reports rank verified walks only). --wide shows everything else, with
    a verified column and why a walk failed verification in its message.
    """
    from gaitbench.run.store import ResultStore
    from gaitbench.run.store_schema import StoreError

    if not inconsistent and (band is not None or tolerance is not None):
        raise click.UsageError("--band and --tolerance set the consistency check, which only --inconsistent uses")
    try:
        with ResultStore.open(store_dir) as store:
            stored = store.cases()
            rows = store.cases(store.resolve_run(run_id)) if run_id else stored
        flagged = inconsistent_keys(store_dir, band, tolerance) if inconsistent else None
    except StoreError as error:
        raise click.ClickException(str(error)) from None
    for option, wanted, held in (("--experiment", experiments, {row["experiment"] for row in stored}),
                                 ("--method", methods, {row["method"] or row["strategy"] for row in stored})):
        unknown = sorted(set(wanted) - held)
        if unknown:  # an empty table would read as "no such cases", not as a name that is not there
            raise click.BadParameter(f"{', '.join(map(repr, unknown))} is not in this store; it has "
                                     f"{', '.join(map(repr, sorted(held))) or 'no cases'}", param_hint=option)
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
    if any(_unverified(row) for row in rows):
        table.caption = "(ACOT): the walk failed verification" + ("" if wide else "; --wide says why")
    print_table(Console(), table, wide)


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
            from gaitbench.reports.csv_files import spreadsheet_safe

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
