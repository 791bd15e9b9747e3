"""The HTML page of a report: one self-contained ``index.html`` (figures embedded as base64 SVG, the animation as
inline SVG and a small inline script, no network) and the figures beside it in ``figures/``."""

from __future__ import annotations

import base64
import math
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from gaitbench.reports import statistics, thesis_values
from gaitbench.reports.figures import slug

TEMPLATES = Path(__file__).parent / "templates"
FIGURES_DIR = "figures"


def format_value(value: Any) -> str:
    """Numbers to 4 significant digits (small ones in scientific notation), missing values (None, NaN, pandas' NA
    and NaT) as an em dash."""
    if value is None or (isinstance(value, float) and math.isnan(value)) or value is pd.NA or value is pd.NaT:
        return "—"
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, float):
        if value == 0:
            return "0"
        if abs(value) < 1e-3 or abs(value) >= 1e5:
            return f"{value:.3e}"
        return f"{value:.4g}"
    return str(value)


def table_html(table: pd.DataFrame, table_id: str, highlight: str | None = None) -> str:
    """A DataFrame as an escaped HTML table; rows where the boolean column ``highlight`` is true get a class."""
    from markupsafe import escape

    if table.empty:
        return f'<p class="empty" id="{table_id}">(no rows)</p>'
    # Long column names may break after an underscore, so a wide table wraps within the page instead of overflowing.
    head = "".join(f"<th>{str(escape(str(column))).replace('_', '_<wbr>')}</th>" for column in table.columns)
    rows = []
    for _, row in table.iterrows():
        marked = highlight is not None and bool(row.get(highlight))
        cells = "".join(_cell(row[column]) for column in table.columns)
        rows.append(f'<tr class="minimum">{cells}</tr>' if marked else f"<tr>{cells}</tr>")
    return (f'<table id="{table_id}" class="data"><thead><tr>{head}</tr></thead>'
            f"<tbody>{''.join(rows)}</tbody></table>")


def _cell(value: Any) -> str:
    """A table cell. Numbers and short words (case keys, statuses) never break (class ``nobreak``); longer text
    breaks between words, and inside one only where it must."""
    from markupsafe import escape

    text = format_value(value)
    number = isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, bool)
    word = len(text) <= 24 and not any(character.isspace() for character in text)
    return f'<td class="nobreak">{escape(text)}</td>' if number or word else f"<td>{escape(text)}</td>"


def figure_src(svg: str) -> str:
    return "data:image/svg+xml;base64," + base64.b64encode(svg.encode()).decode()


class HtmlReporter:
    """Writes ``index.html`` and ``figures/*.svg``."""

    name = "html"

    def write(self, report, out_dir: Path) -> list[Path]:
        import jinja2

        out_dir = Path(out_dir)
        figures_dir = out_dir / FIGURES_DIR
        figures_dir.mkdir(parents=True, exist_ok=True)
        written = []
        all_figures = [f for figures in report.experiment_figures.values() for f in figures]
        all_figures += [f for section in report.gaits for f in section.figures]
        all_figures += report.energetics_figures + [f for section in report.tracking for f in section.figures]
        for figure in all_figures:
            path = figures_dir / figure.filename
            path.write_text(figure.svg)
            written.append(path)
        environment = jinja2.Environment(loader=jinja2.FileSystemLoader(TEMPLATES),
                                         autoescape=jinja2.select_autoescape(["html", "j2"]))
        environment.filters["fmt"] = format_value
        environment.filters["slug"] = slug
        environment.filters["src"] = figure_src
        tables = report.tables

        def rows(name: str, experiment: str | None = None, columns: list[str] | None = None) -> pd.DataFrame:
            table = tables[name]
            if experiment is not None and "experiment" in table.columns:
                table = table[table["experiment"] == experiment]
            return table[columns] if columns else table

        def table(name: str, table_id: str, experiment: str | None = None, columns: list[str] | None = None,
                  highlight: str | None = None):
            from markupsafe import Markup

            return Markup(table_html(rows(name, experiment, columns), table_id, highlight))

        df = report.cases
        counts = df["status"].value_counts().to_dict() if not df.empty else {}
        retries = int(df["retries"].sum()) if not df.empty else 0
        csv_files = sorted(path.name for path in out_dir.glob("*.csv"))
        html = environment.get_template("report.html.j2").render(
            report=report, table=table, rows=rows, counts=counts, total=len(df), retries=retries, csv_files=csv_files,
            generated=datetime.now(timezone.utc).isoformat(timespec="seconds"), thesis=thesis_values,
            figures_dir=FIGURES_DIR, has_dc=bool(len(tables["dc_claims"])),
            consistency_band=statistics.CONSISTENCY_BAND, consistency_tolerance=statistics.CONSISTENCY_TOLERANCE,
        )
        index = out_dir / "index.html"
        index.write_text(html)
        written.append(index)
        return written
