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


HEADER_WORDS = {"acot": "ACOT", "cot": "COT", "ci": "CI", "id": "ID", "is": ""}
"""How a word of a column name reads in a header (``is_minimum`` reads "minimum")."""

HEADER_UNITS = {"percent": "(%)", "s": "(s)"}
"""A column name's last word that is its unit (``wall_time_s``: "wall time (s)")."""


def header(column: str) -> str:
    """The header of a CSV column in an HTML table: words, not snake_case (``claimed_acot_at_min``: "claimed ACOT at
    min"). The CSV files keep the names (docs/reports.md); each header's tooltip gives it."""
    words = str(column).split("_")
    unit = HEADER_UNITS.get(words[-1]) if len(words) > 1 else None
    words = [HEADER_WORDS.get(word, word) for word in (words[:-1] if unit else words)]
    text = " ".join(word for word in words if word).replace("push off", "push-off").replace("back ups", "back-ups")
    return f"{text} {unit}" if unit else text


def table_html(table: pd.DataFrame, table_id: str, highlight: str | None = None, empty: str = "No rows.") -> str:
    """A DataFrame as an escaped HTML table; rows where the boolean column ``highlight`` is true get a class. An
    empty one is the sentence ``empty``, which says why it is empty."""
    from markupsafe import escape

    if table.empty:
        return f'<p class="empty" id="{table_id}">{escape(empty)}</p>'
    head = "".join(f'<th title="{escape(str(column))}">{escape(header(column))}</th>' for column in table.columns)
    rows = []
    for _, row in table.iterrows():
        marked = highlight is not None and bool(row.get(highlight))
        cells = "".join(_cell(row[column]) for column in table.columns)
        rows.append(f'<tr class="minimum">{cells}</tr>' if marked else f"<tr>{cells}</tr>")
    kind = "data many" if len(table.columns) > MANY_COLUMNS else "data"
    return (f'<table id="{table_id}" class="{kind}"><thead><tr>{head}</tr></thead>'
            f"<tbody>{''.join(rows)}</tbody></table>")


MANY_COLUMNS = 14
"""A table with more columns than this is set smaller (class ``many``), so that it fits a narrow window without
scrolling sideways."""


EMPTY_TABLES = {
    "acot_minima": "No walk of this experiment's sweep is in the store.",
    "acot": "No walk of this experiment's sweep is in the store.",
    "stop_causes": "No case in the store.",
    "consistency": "No exceptions: no method has a finer N whose ACOT lies outside the tolerance.",
    "published_acot": "None of the thesis's experiments (forward, downward-slope, upward-slope, stairs) is in this "
                      "store, so there is no published figure to set ours beside.",
    "published_savings": "None of the thesis's experiments is in this store, so there is no published saving to set "
                         "ours beside.",
    "unverified_cases": "None: every complete walk passed the whole-walk verification.",
    "failed_cases": "None: every case's walk was solved to its last step.",
    "case_commits": "No case in the store.",
    "provenance": "The store records no run.",
}
"""Why each table of the page is empty, where one reason covers it (the savings' depends on the store:
:func:`empty_reason`)."""


def empty_reason(name: str, report, experiment: str | None = None) -> str:
    """Why the report's table ``name`` (of ``experiment``) has no rows, in a sentence."""
    if name in ("savings", "savings_paired"):
        from gaitbench.reports import case_frame
        from gaitbench.reports.tables import baselines

        cases = report.cases
        if experiment is not None and not cases.empty:
            cases = cases[cases["experiment"] == experiment]
        if cases.empty or not cases["is_dc"].any():
            return ("No decrease-and-conquer method in this store" + (" for this experiment" if experiment else "")
                    + ": a saving is decrease and conquer's against One Phase or the reference method.")
        pairs = [pair for pair in baselines(case_frame.method_info(report.cases)) if pair[0] == experiment]
        if not pairs:
            return ("No baseline for decrease and conquer: no One Phase method with its transcription and solver, "
                    "and no method labelled reference.")
        return "Decrease and conquer and its baselines were run at no N in common."
    if name == "consistency":
        low, high = statistics.CONSISTENCY_BAND
        acot = report.tables["acot"]
        references = acot[(acot["N"] >= low) & (acot["N"] <= high)].dropna(subset=["acot"])
        checked = acot[acot["N"] > high].merge(references[["experiment", "method"]].drop_duplicates())
        if checked.empty:
            return (f"Nothing to check: no method has both a verified walk at N = {low}–{high} (the reference) and "
                    f"a walk at an N above {high}.")
    return EMPTY_TABLES.get(name, "No rows.")


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
        environment.filters["header"] = header
        tables = report.tables

        def rows(name: str, experiment: str | None = None, columns: list[str] | None = None) -> pd.DataFrame:
            table = tables[name]
            if experiment is not None and "experiment" in table.columns:
                table = table[table["experiment"] == experiment]
            return table[columns] if columns else table

        def table(name: str, table_id: str, experiment: str | None = None, columns: list[str] | None = None,
                  highlight: str | None = None):
            from markupsafe import Markup

            shown = rows(name, experiment, columns)
            empty = empty_reason(name, report, experiment) if shown.empty else ""
            return Markup(table_html(shown, table_id, highlight, empty))

        df = report.cases
        counts = df["status"].value_counts().to_dict() if not df.empty else {}
        retries = int(df["retries"].sum()) if not df.empty else 0
        csv_files = sorted(path.name for path in out_dir.glob("*.csv"))
        html = environment.get_template("report.html.j2").render(
            report=report, table=table, rows=rows, counts=counts, total=len(df), retries=retries, csv_files=csv_files,
            commits=tables["case_commits"],
            generated=datetime.now(timezone.utc).isoformat(timespec="seconds"), thesis=thesis_values,
            figures_dir=FIGURES_DIR, has_dc=bool(len(tables["dc_claims"])),
            consistency_band=statistics.CONSISTENCY_BAND, consistency_tolerance=statistics.CONSISTENCY_TOLERANCE,
        )
        index = out_dir / "index.html"
        index.write_text(html)
        written.append(index)
        return written
