"""What every reporter renders (:class:`gaitbench.contracts.Reporter`): the tables, figures and sections
:func:`gaitbench.reports.build_report` reads from a store once. It sits beside the contracts, which name it."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any


@dataclass
class GaitSection:
    gait: Any  # gaitbench.reports.gait.Gait
    figures: list
    animation: str
    dc_claim: dict | None = None  # claimed and verified ACOT of a D&C gait


@dataclass
class TrackingSection:
    case_key: str
    label: str
    summary: dict
    figures: list


@dataclass
class ReportData:
    """Everything a reporter renders: the tables (by CSV name), the figures and the gait and tracking sections."""

    store_dir: Path
    """The store as it was named: its directory, or its pack (a ``.tar.xz``)."""
    title: str
    cases: Any  # the prepared DataFrame
    runs: list[dict]
    tables: dict[str, Any]
    experiments: list[str]
    experiment_figures: dict[str, list] = field(default_factory=dict)
    """Per sweep experiment: the ACOT and completion-rate figures first (shown side by side), then the others."""
    gaits: list[GaitSection] = field(default_factory=list)
    gait_problems: list[str] = field(default_factory=list)
    energetics_figures: list = field(default_factory=list)
    tracking: list[TrackingSection] = field(default_factory=list)
