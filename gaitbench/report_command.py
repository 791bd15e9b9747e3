"""`gaitbench report`: the HTML and CSV report of a results store (gaitbench/reports)."""

from __future__ import annotations

from pathlib import Path

import click


@click.command()
@click.argument("store", type=click.Path(path_type=Path))
@click.option("--out", "out_dir", type=click.Path(path_type=Path), default=None,
              help="Output directory (default: reports/<store directory name>).")
@click.option("--gait", "gait", default=None, metavar="CASE_KEY",
              help="Show this case's gait (a case key or a unique prefix) instead of each experiment's lowest-ACOT "
                   "solved case.")
@click.option("--reporter", "reporters", multiple=True, metavar="NAME",
              help="Reporter plugin to run (repeatable; default: csv and html). `gaitbench plugins --kind reporter` "
                   "lists them.")
def report(store: Path, out_dir: Path | None, gait: str | None, reporters: tuple[str, ...]) -> None:
    """Write the report of STORE (the directory given to `gaitbench run --store`): index.html with the thesis's
    figures regenerated, a CSV file per table (columns in docs/reports.md) and the figures as SVG."""
    import time

    from gaitbench.plugins import UnknownPluginError
    from gaitbench.reports import DEFAULT_REPORTERS, ReportError, write_report

    out_dir = out_dir if out_dir is not None else Path("reports") / store.resolve().name
    started = time.perf_counter()
    try:
        written = write_report(store, out_dir, gait=gait, reporters=reporters or DEFAULT_REPORTERS)
    except (ReportError, UnknownPluginError) as error:
        raise click.ClickException(str(error)) from None
    click.echo(f"report written to {written} ({time.perf_counter() - started:.1f} s)")
