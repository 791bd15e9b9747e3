"""``gaitbench run`` and ``gaitbench runs``: run a suite into a store, and look at what a store holds."""

from __future__ import annotations

import os
import signal
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import click
from click.core import ParameterSource
from rich import box
from rich.console import Console
from rich.table import Table
from rich.text import Text

from gaitbench.cli.common import count, fmt
from gaitbench.cli.consistency_options import consistency_options, inconsistent_keys
from gaitbench.cli.run_progress import CaseProgress, StepsInFlight
from gaitbench.plugins import PLUGINS_DIR_ENV
from gaitbench.run.executors import EXECUTORS
from gaitbench.run.store import LOCK_TIMEOUT_S


@click.command("run")
@click.argument("suite_file", metavar="SUITE.toml", type=click.Path(exists=True, dir_okay=False, path_type=Path))
@click.option("--jobs", "-j", type=click.IntRange(min=1), default=1, show_default=True,
              help="Worker processes (local executor) or local Dask workers.")
@click.option("--executor", type=click.Choice(EXECUTORS), default="local", show_default=True,
              help="local: a pool of worker processes that can stop a hung case; dask: a Dask cluster; "
                   "inprocess: this process, for debugging (time limits reach the solver only).")
@click.option("--scheduler", metavar="ADDR", help="Address of an existing Dask scheduler, e.g. tcp://HOST:8786 "
              "(implies --executor dask); without it a local cluster of --jobs workers is started.")
@click.option("--store", "store_dir", type=click.Path(path_type=Path),
              help="Results directory [default: the suite's `output`]; not a pack, which is read-only.")
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
              help="With --resume, run again the complete walks that failed verification (the store's verified "
                   "flag is 0: `gaitbench verify --store` sets it for rows stored before it existed) or have no "
                   "ACOT: after a change to gaitbench that may verify them.")
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
    from gaitbench.run.pack_format import is_pack, refusal
    from gaitbench.run.runner import RunRefused, run_suite
    from gaitbench.run.store_schema import StoreError
    from gaitbench.run.suite import SuiteError, load_suite

    if state.plugin_dirs:  # through the environment, so worker processes load them too
        os.environ[PLUGINS_DIR_ENV] = os.pathsep.join(
            [*map(str, state.plugin_dirs), *filter(None, [os.environ.get(PLUGINS_DIR_ENV)])])
    if store_dir is not None and is_pack(store_dir):
        raise click.ClickException(refusal(store_dir))
    retries = [flag for flag, given in (("--retry-failed", retry_failed), ("--retry-incomplete", retry_incomplete),
                                        ("--retry-unverified", retry_unverified),
                                        ("--retry-inconsistent", retry_inconsistent)) if given]
    if retries and not resume:
        raise click.UsageError(f"{retries[0]} runs stored cases again, so it needs --resume (the store holding "
                               "them); add --resume")
    ignored = [flag for flag, given in (("--band", band is not None), ("--tolerance", tolerance is not None)) if given]
    if ignored and not retry_inconsistent:
        raise click.UsageError(f"{ignored[0]} sets the consistency check, which only --retry-inconsistent uses here")
    executor_given = click.get_current_context().get_parameter_source("executor") is ParameterSource.COMMANDLINE
    if scheduler and executor_given and executor != "dask":
        raise click.UsageError(f"--scheduler runs the cases on a Dask cluster; it cannot go with --executor "
                               f"{executor}")
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
    where = "--store" if store_dir else f"{suite_file}: [suite].output"
    store_dir = store_dir or suite.output
    if Path(store_dir).exists() and not Path(store_dir).is_dir():
        raise click.UsageError(f"{where}: {store_dir} is a file, not a results store's directory; name a directory")
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
                  f"{summary.skipped} already in the store, {summary.wall_time_s:.1f} s")
    console.print(f"store: {summary.store}")
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
    per experiment and method, how many walks are complete and how many of those passed verification, the lowest
    ACOT over the verified ones and its N, and why the others stopped."""
    from gaitbench.run.store import ResultStore

    keys = {case.key for case in suite.cases}
    with ResultStore.open(store_dir) as store:
        rows = [row for row in store.cases() if row["case_key"] in keys]
    order = {case.key: i for i, case in enumerate(suite.cases)}
    groups: dict[tuple[str, str], list[dict]] = {}
    for row in sorted(rows, key=lambda row: order[row["case_key"]]):
        groups.setdefault((row["experiment"], row["method"] or row["strategy"]), []).append(row)
    table = Table(title=f"{suite.name}: lowest ACOT over verified walks",
                  caption="done: complete walks; ok: those that passed verification, over which ACOT and N are taken",
                  caption_justify="left", box=box.SIMPLE_HEAD, title_justify="left", show_edge=False,
                  pad_edge=False, collapse_padding=True)
    longest = max((len(method) for _, method in groups), default=0)
    for column in ("experiment", "method", "done", "ok", "ACOT", "at N", "incomplete"):
        numeric = column in ("done", "ok", "ACOT", "at N")
        table.add_column(column, justify="right" if numeric else "left", overflow="fold", no_wrap=numeric,
                         min_width=min(20, longest) if column == "method" else None)  # "decrease-and-conquer"
    for (experiment, method), group in groups.items():
        complete = [row for row in group if row["status"] == "solved"]
        verified = [row for row in complete if row.get("verified") and row["acot"] is not None]
        best = min(verified, key=lambda row: row["acot"], default=None)
        causes: dict[str, int] = {}
        for row in group:
            if row not in complete:
                cause = row["stop_cause"] or row["status"]
                causes[cause] = causes.get(cause, 0) + 1
        table.add_row(experiment, method, f"{len(complete)} of {len(group)}", str(len(verified)),
                      fmt(best["acot"] if best else None, ".4f"), str(best["N"]) if best else "—",
                      ", ".join(f"{cause} ({n})" for cause, n in causes.items()) or "—")
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
