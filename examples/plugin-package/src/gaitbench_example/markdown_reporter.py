"""A reporter plugin: each method's minimum verified ACOT per experiment as a Markdown table, ``minima.md``.

A reporter gets the :class:`gaitbench.reports.ReportData` that ``gaitbench report`` builds once from a store (its
tables by CSV name, columns in gaitbench's docs/reports.md) and writes files into the report's directory; run it
with ``gaitbench report STORE --reporter example-markdown``.
"""

from __future__ import annotations

from pathlib import Path

from gaitbench import Registration, hookimpl

COLUMNS = (("experiment", "experiment"), ("method", "method"), ("min_acot", "minimum ACOT"), ("N_at_min", "at N"),
           ("N_solved", "N solved"), ("N_values", "N run"))
"""The columns of ``acot_minima`` shown, with their headers."""


class MarkdownReporter:
    """Writes ``minima.md``: one row per experiment and method, its lowest verified ACOT over N and where."""

    name = "example-markdown"

    def write(self, report, out_dir: Path) -> list[Path]:
        minima = report.tables["acot_minima"]
        lines = [f"# {report.title}", "", "| " + " | ".join(header for _, header in COLUMNS) + " |",
                 "|" + "|".join("---" for _ in COLUMNS) + "|"]
        for row in minima.itertuples(index=False):
            cells = [_cell(getattr(row, column)) for column, _ in COLUMNS]
            lines.append("| " + " | ".join(cells) + " |")
        if minima.empty:
            lines.append("")
            lines.append("No method of this store has a walk of a sweep experiment.")
        path = Path(out_dir) / "minima.md"
        path.write_text("\n".join(lines) + "\n")
        return [path]


def _cell(value) -> str:
    """A number to 4 decimals, a missing one (no verified walk) as a dash, Markdown's `|` escaped."""
    import pandas as pd

    if pd.isna(value):
        return "—"
    if isinstance(value, float):
        return f"{value:.4f}"
    return str(value).replace("|", "\\|")


@hookimpl
def register_reporters():
    return [Registration("example-markdown", "Each method's minimum ACOT as a Markdown table, minima.md (example "
                         "plugin package)", MarkdownReporter)]
