"""The built-in reporters: ``csv`` (every table of the report as a CSV file) and ``html`` (a self-contained page).

Both render the :class:`gaitbench.reports.ReportData` that :func:`gaitbench.reports.write_report` builds once from
a results store; a third-party reporter registers the same way and gets the same object.
"""

from __future__ import annotations

from pathlib import Path

from gaitbench import Registration, hookimpl


class CsvReporter:
    """Writes every table of the report as ``<name>.csv`` (columns in docs/reports.md)."""

    name = "csv"

    def write(self, report, out_dir: Path) -> list[Path]:
        from gaitbench.reports.csv_files import write_csv

        return write_csv(report.tables, out_dir)


def html_reporter():
    from gaitbench.reports.html import HtmlReporter

    return HtmlReporter()


@hookimpl
def register_reporters():
    return [
        Registration("csv", "Every table of the report (ACOT, savings, published values, failures, ...) as CSV",
                     CsvReporter),
        Registration("html", "Self-contained HTML page with the thesis's figures regenerated from the store",
                     html_reporter),
    ]
