"""The consistency check's options, shared by ``gaitbench run --retry-inconsistent`` and ``gaitbench runs show
--inconsistent``: which stored walks a finer grid made dearer than the method's coarser N
(:mod:`gaitbench.reports.statistics`)."""

from __future__ import annotations

from pathlib import Path

import click


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
