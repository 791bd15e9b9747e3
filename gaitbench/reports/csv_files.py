"""The report's tables as CSV files that open safely in a spreadsheet."""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import pandas as pd


def write_csv(tables: dict[str, pd.DataFrame], out_dir: str | Path) -> list[Path]:
    """Every table as ``out_dir/<name>.csv`` (header even when empty, text cells :func:`spreadsheet_safe`); returns
    the paths."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    paths = []
    for name, table in tables.items():
        path = out_dir / f"{name}.csv"
        spreadsheet_safe(table).to_csv(path, index=False)
        paths.append(path)
    return paths


FORMULA_STARTS = ("=", "+", "-", "@", "\t", "\r")
"""What makes a spreadsheet read a CSV cell as a formula (OWASP, "CSV Injection"): a label such as
``=HYPERLINK(...)`` in a suite would run as one in whoever opens the report's CSV."""

_NUMBER = re.compile(r"[+-]?(\d+(\.\d*)?|\.\d+)([eE][+-]?\d+)?|[+-]?(inf|nan)", re.IGNORECASE)


def spreadsheet_safe(frame: pd.DataFrame) -> pd.DataFrame:
    """``frame`` with every text cell that a spreadsheet would take for a formula prefixed with ``'``, the escape
    spreadsheets show as the text itself. Numbers stay numbers, negative ones included, in numeric columns and as
    text (``-0.5``)."""
    def escaped(value: Any) -> Any:
        if isinstance(value, str) and value.startswith(FORMULA_STARTS) and not _NUMBER.fullmatch(value):
            return "'" + value
        return value

    safe = frame.copy()
    for column in frame.columns:
        if pd.api.types.is_object_dtype(frame[column]) or pd.api.types.is_string_dtype(frame[column]):
            safe[column] = frame[column].map(escaped)
    return safe
