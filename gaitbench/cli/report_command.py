"""`gaitbench report`: the HTML and CSV report of a results store (gaitbench/reports)."""

from __future__ import annotations

from pathlib import Path

import click
from rich.console import Console

REPORTS_DIR = Path("reports")
"""Where reports go by default, ``reports/<store directory name>`` under the current directory (ignored by git in
a clone, so that running a suite never changes tracked files)."""


def default_report_dir(store: str | Path) -> Path:
    """``reports/<name>``: the store directory's name, or its pack's without ``.tar.xz``."""
    from gaitbench.run.pack_format import PACK_SUFFIX

    return REPORTS_DIR / Path(store).resolve().name.removesuffix(PACK_SUFFIX)


def write_with_progress(store: str | Path, out_dir: Path, console: Console, **options) -> Path:
    """:func:`gaitbench.reports.write_report` with a progress bar on ``console`` when it is a terminal (the part
    being written, the parts done, the time taken); returns what it returns."""
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

    from gaitbench.reports import write_report

    with Progress(TextColumn("report"), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn(),
                  TextColumn("{task.description}"), console=console, transient=True,
                  disable=not console.is_terminal) as progress:  # a log gets no bar, nor its blank line
        task = progress.add_task("reading the store", total=None)

        def show(what: str, done: int, total: int) -> None:
            progress.update(task, description=what, completed=done, total=total, refresh=True)  # each part seen

        return write_report(store, out_dir, progress=show, **options)


@click.command()
@click.argument("store", type=click.Path(path_type=Path))
@click.option("--out", "out_dir", type=click.Path(path_type=Path), default=None,
              help=f"Output directory (default: {REPORTS_DIR}/<store directory name>).")
@click.option("--gait", "gait", default=None, metavar="CASE_KEY",
              help="Show this case's gait (a case key or a unique prefix) instead of each experiment's lowest-ACOT "
                   "solved case.")
@click.option("--reporter", "reporters", multiple=True, metavar="NAME",
              help="Reporter plugin to run (repeatable; default: csv and html). `gaitbench plugins --kind reporter` "
                   "lists them.")
@click.pass_obj
def report(state, store: Path, out_dir: Path | None, gait: str | None, reporters: tuple[str, ...]) -> None:
    """Write the report of STORE (the directory given to `gaitbench run --store`, or a pack of it from `gaitbench
    runs pack`): index.html with the thesis's figures regenerated, a CSV file per table (columns in
    docs/reports.md) and the figures as SVG."""
    import time

    from gaitbench.plugins import PluginConflictError, UnknownPluginError
    from gaitbench.reports import DEFAULT_REPORTERS, GaitNotFound, ReportError

    out_dir = out_dir if out_dir is not None else default_report_dir(store)
    started = time.perf_counter()
    try:
        written = write_with_progress(store, out_dir, Console(stderr=True), gait=gait,
                                      reporters=reporters or DEFAULT_REPORTERS, registry=state.registry)
    except (UnknownPluginError, PluginConflictError) as error:
        raise click.BadParameter(str(error), param_hint="'--reporter'") from None
    except GaitNotFound as error:
        raise click.BadParameter(str(error), param_hint="'--gait'") from None
    except ReportError as error:
        raise click.ClickException(str(error)) from None
    click.echo(f"report written to {written} ({time.perf_counter() - started:.1f} s)")
