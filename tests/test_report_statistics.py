"""The report's statistics (gaitbench/reports/statistics.py): the bootstrap interval on paired sets with a known
answer, the paired savings, the spread over neighbouring N and the consistency check on hand-made cases, and the
selection of the inconsistent walks for solving again (`runs show --inconsistent`, `run --retry-inconsistent`)."""

from __future__ import annotations

import math
import textwrap

import numpy as np
import pandas as pd
import pytest
from click.testing import CliRunner

from gaitbench.reports import case_frame, statistics, tables

# --- the bootstrap interval --------------------------------------------------------------------------------------


def test_a_constant_saving_has_a_zero_width_interval():
    savings = np.full(17, 12.5)
    for statistic in (np.median, np.mean):
        assert statistics.bootstrap_ci(savings, statistic) == (12.5, 12.5)


def test_the_mean_interval_matches_the_normal_theory_and_a_shift_is_detected():
    rng = np.random.default_rng(7)
    noise = rng.normal(0.0, 2.0, 400)
    shifted = noise + 1.0
    low, high = statistics.bootstrap_ci(shifted, np.mean)
    half = 1.96 * shifted.std(ddof=1) / math.sqrt(len(shifted))  # ≈ 0.2: the bootstrap of a mean is this
    assert low < shifted.mean() < high
    assert (high - low) / 2 == pytest.approx(half, rel=0.1)
    assert low > 0  # a shift of half a standard deviation over 400 pairs is detected
    low, high = statistics.bootstrap_ci(noise[:20], np.median)
    assert low < 0 < high  # twenty pairs of pure noise: no saving either way
    assert statistics.bootstrap_ci(noise[:20], np.median) == (low, high)  # the fixed seed: reproducible
    assert all(math.isnan(value) for value in statistics.bootstrap_ci([], np.median))


# --- paired savings, spread and consistency on hand-made cases -----------------------------------------------------

def _cases(rows: list[dict]) -> pd.DataFrame:
    """Store rows (forward experiment, Hermite–Simpson, IPOPT, complete unless said) prepared as the report does."""
    base = {"experiment": "forward", "experiment_options": {}, "transcription": "hermite-simpson", "solver": "ipopt",
            "strategy": "one-phase", "status": "solved", "message": "", "claimed_acot": None,
            "strategy_details": None, "cot_min": 0.1, "cot_max": 0.2, "wall_time_s": 1.0, "iterations": 10,
            "max_defect": 1e-9, "max_resim_error": 1e-6, "walk_path": None, "tracking_path": None, "verified": 1}
    frame = pd.DataFrame([base | row for row in rows])
    frame["case_key"] = [f"k{i}" for i in range(len(frame))]
    return case_frame.prepare(frame)


def _dc(n: int, verified: float | None, status: str = "solved") -> dict:
    return {"method": "D&C-DC", "strategy": "decrease-and-conquer", "N": n, "acot": 0.01, "claimed_acot": 0.01,
            "status": status, "strategy_details": {"claimed_acot": 0.01, "verified_acot": verified}}


def test_paired_savings_over_the_n_where_both_walks_are_complete():
    op = {10: 0.40, 20: 0.50, 30: 0.30, 40: 0.60}
    rows = [{"method": "OP-DC", "N": n, "acot": acot} for n, acot in op.items()]
    rows += [_dc(n, 0.9 * acot) for n, acot in op.items() if n != 30]
    rows.append(_dc(30, 0.01, status="incomplete"))  # no verified walk at N = 30: no pair
    df = _cases(rows)
    info = case_frame.method_info(df)
    acot = tables.acot_table(df)
    minima = tables.method_minima(acot, info)
    # the minimum is over the N with a verified walk: D&C has none at N = 30
    assert minima.set_index("method")["N_verified"].to_dict() == {"OP-DC": 4, "D&C-DC": 3}
    savings = tables.savings_table(acot, info)
    paired = statistics.paired_savings(savings, minima)
    assert list(paired.columns) == statistics.PAIRED_SAVINGS_COLUMNS
    row = paired.set_index("baseline").loc["OP-DC"]
    assert row["pairs"] == 3
    # 10 % at every N: both summaries are 10 % exactly; three pairs are too few for an interval.
    assert row["median_percent"] == pytest.approx(10.0) and row["mean_percent"] == pytest.approx(10.0)
    assert statistics.MIN_PAIRS_FOR_CI > 3
    for column in ("median_ci_low", "median_ci_high", "mean_ci_low", "mean_ci_high"):
        assert math.isnan(row[column]), column
    more = {"OP-DC": {n: 0.5 for n in (10, 20, 30, 40, 50, 60)}}
    rows = [{"method": "OP-DC", "N": n, "acot": acot} for n, acot in more["OP-DC"].items()]
    rows += [_dc(n, 0.45) for n in more["OP-DC"]]
    five = _cases(rows)
    info5, acot5 = case_frame.method_info(five), tables.acot_table(five)
    wide = statistics.paired_savings(tables.savings_table(acot5, info5), tables.method_minima(acot5, info5))
    wide = wide.set_index("baseline").loc["OP-DC"]
    assert wide["pairs"] == 6 and wide[["median_ci_low", "median_ci_high"]].tolist() == pytest.approx([10.0, 10.0])
    # Minimum against minimum: D&C's 0.36 at N = 10 against OP-DC's 0.30 at N = 30, a loss.
    assert row["min_vs_min_percent"] == pytest.approx(100 * (0.30 - 0.36) / 0.30)
    # The thesis's forward minima: D&C-DC 0.0695 against OP-DC 0.3615 (thesis §5.2–5.5).
    assert row["published_min_vs_min_percent"] == pytest.approx(100 * (0.3615 - 0.0695) / 0.3615)
    # Beside the thesis's quoted range: its forward D&C-DC vs OP-DC row gets the same figures.
    published = statistics.with_paired_savings(tables.published_savings(savings, info), paired, info)
    quoted = published.set_index("comparison").loc["D&C-DC vs OP-DC"]
    assert (quoted["published_max_percent"], quoted["pairs"]) == (85.41, 3)
    assert quoted["median_percent"] == pytest.approx(10.0) and math.isnan(quoted["median_ci_low"])
    assert quoted["min_vs_min_percent"] == pytest.approx(row["min_vs_min_percent"])


def test_methods_under_another_objective_meet_neither_the_thesis_nor_the_other_objectives_baselines():
    """A store like thesis-forward-work (every method under actuator-work) beside net-power methods: the work
    methods are never matched with the thesis's net-power figures, each D&C method is paired with the One Phase and
    reference methods of its own objective, and no pair crosses objectives."""
    work = {"objective": "actuator-work"}
    rows = []
    for extra in ({}, work):
        rows += [{"method": "OP-DC", "N": 20, "acot": 0.40} | extra,
                 {"method": "reference", "N": 20, "acot": 0.42} | extra,
                 _dc(20, 0.36) | extra]
    info = case_frame.method_info(_cases(rows)).set_index("method")
    assert info.loc["OP-DC", "thesis_method"] == "OP-DC" and info.loc["D&C-DC", "thesis_method"] == "D&C-DC"
    assert info.loc["reference", "thesis_method"] == "SNOPT"
    for method in ("OP-DC [actuator-work]", "D&C-DC [actuator-work]", "reference [actuator-work]"):
        assert info.loc[method, "thesis_method"] is None, method
    assert info.loc["reference [actuator-work]", "label"] == "reference"
    assert sorted(tables.baselines(info.reset_index())) == sorted([
        ("forward", "D&C-DC", "OP-DC", "one-phase"), ("forward", "D&C-DC", "reference", "reference"),
        ("forward", "D&C-DC [actuator-work]", "OP-DC [actuator-work]", "one-phase"),
        ("forward", "D&C-DC [actuator-work]", "reference [actuator-work]", "reference")])


def test_the_spread_is_over_every_complete_walk_at_neighbouring_n():
    rows = [{"method": "OP-DC", "N": 10, "acot": 1.0}, {"method": "OP-DC", "N": 10, "acot": 1.2, "repetition": 1},
            {"method": "OP-DC", "N": 20, "acot": 1.1}, {"method": "OP-DC", "N": 30, "acot": 2.0},
            {"method": "OP-DC", "N": 20, "acot": 0.01, "status": "incomplete"}]  # not a walk: not in any spread
    df = _cases(rows)
    acot = tables.acot_table(df)
    spread = statistics.acot_spread(df, acot)
    assert list(spread.columns) == statistics.SPREAD_COLUMNS
    spread = spread.set_index("N")
    assert spread.loc[10, ["spread_walks", "spread_low", "spread_high", "spread_median"]].tolist() == pytest.approx(
        [3, 1.0, 1.2, 1.1])
    assert spread.loc[20, ["spread_walks", "spread_low", "spread_high", "spread_median"]].tolist() == pytest.approx(
        [4, 1.0, 2.0, 1.15])
    assert spread.loc[20, "spread_percent"] == pytest.approx(100 / 1.15)
    alone = statistics.acot_spread(df, acot, half_width=0).set_index("N")  # over the repetitions only
    assert alone.loc[10, ["spread_walks", "spread_low", "spread_high"]].tolist() == pytest.approx([2, 1.0, 1.2])
    assert alone.loc[30, "spread_percent"] == 0


def _consistency_cases() -> pd.DataFrame:
    """OP-DC: 3.0 at the coarse N = 10–30 (not checked), median 1.0 over N = 40–90, then 1.10 (inside 15 %), 1.30
    (alone outside, its second step the dear one), 1.0, 0.80 and 1.5 (two neighbours outside), and no complete walk
    at N = 150; 1.55 at N = 300, with no N near it. D&C-DC has no complete walk in the band: no reference, not
    checked."""
    ladder = {10: 3.0, 20: 3.0, 30: 3.0, 40: 1.0, 50: 1.0, 60: 0.9, 70: 1.1, 80: 1.0, 90: 1.0, 100: 1.10, 110: 1.30,
              120: 1.0, 130: 0.80, 140: 1.5, 300: 1.55}
    rows = [{"method": "OP-DC", "N": n, "acot": acot, "cot_steps": [1.0, 1.6] if n == 110 else [acot, acot]}
            for n, acot in ladder.items()]
    rows.append({"method": "OP-DC", "N": 150, "acot": 9.0, "status": "incomplete"})
    rows += [_dc(n, 5.0) for n in (10, 200)]
    return _cases(rows)


def test_the_consistency_check_lists_every_finer_n_outside_the_tolerance():
    df = _consistency_cases()
    acot = tables.acot_table(df)
    exceptions = statistics.consistency_exceptions(acot, df)
    assert list(exceptions.columns) == statistics.CONSISTENCY_COLUMNS
    found = {row.N: (row.ratio, row.isolated) for row in exceptions.itertuples()}
    assert found.keys() == {110, 130, 140, 300}
    assert found[300] == (pytest.approx(1.55), None)  # no neighbour: neither alone nor part of a drift
    assert found[110] == (pytest.approx(1.30), True)
    assert found[130] == (pytest.approx(0.80), False) and found[140] == (pytest.approx(1.5), False)
    row = exceptions.set_index("N").loc[110]
    assert (row["experiment"], row["method"], row["reference_median"], row["reference_N"]) == (
        "forward", "OP-DC", 1.0, "40–90")
    assert row["deviation_percent"] == pytest.approx(30.0)
    assert (row["dearest_step"], row["dearest_step_excess"]) == (2, pytest.approx(0.6))  # step 2: 1.6 against 1.0
    assert pd.isna(row["ground_at_dearest_step"])  # no ground was asked about
    grounds = statistics.consistency_exceptions(acot, df, ground=lambda name, step: f"{name} step {step}")
    assert grounds.set_index("N").loc[110, "ground_at_dearest_step"] == "forward step 2"
    key = df[(df["method"] == "OP-DC") & (df["N"] == 110)]["case_key"].iloc[0]
    assert row["case_keys"] == key
    assert statistics.inconsistent_keys(df, acot) == set(" ".join(exceptions["case_keys"]).split())
    # The tolerance and the band are parameters.
    assert statistics.consistency_exceptions(acot, df, tolerance=0.6).empty
    moved = statistics.consistency_exceptions(acot, df, band=(100, 120))  # median 1.10 over N = 100–120
    assert set(moved["N"]) == {130, 140, 300} and moved["reference_median"].iloc[0] == pytest.approx(1.10)


def test_a_cell_exactly_at_the_tolerance_is_inside_it_above_the_median_as_below():
    rows = [{"method": "OP-DC", "N": n, "acot": 0.40} for n in (40, 50, 60)]
    rows += [{"method": "OP-DC", "N": 100, "acot": 0.46}, {"method": "OP-DC", "N": 110, "acot": 0.34},
             {"method": "OP-DC", "N": 120, "acot": 0.47}]  # +15 %, −15 % (both inside), +17.5 % (outside)
    df = _cases(rows)
    assert list(statistics.consistency_exceptions(tables.acot_table(df), df)["N"]) == [120]


def test_a_baseline_without_a_positive_acot_gives_no_saving_and_leaves_the_statistics_finite():
    rows = [{"method": "OP-DC", "N": n, "acot": 0.0 if n == 10 else 0.5} for n in range(10, 80, 10)]
    rows += [_dc(n, 0.4) for n in range(10, 80, 10)]
    df = _cases(rows)
    info, acot = case_frame.method_info(df), tables.acot_table(df)
    minima = tables.method_minima(acot, info)
    savings = tables.savings_table(acot, info)
    assert savings.set_index("N").loc[10, "savings_percent"] != savings.set_index("N").loc[10, "savings_percent"]
    row = statistics.paired_savings(savings, minima).set_index("baseline").loc["OP-DC"]
    assert row["pairs"] == 6 and row["mean_percent"] == pytest.approx(20.0)
    assert (row["mean_ci_low"], row["mean_ci_high"]) == (pytest.approx(20.0), pytest.approx(20.0))
    assert math.isnan(row["min_vs_min_percent"])  # OP-DC's minimum is the 0.0 at N = 10


def test_a_walk_flagged_verified_without_a_verified_acot_is_listed_not_ranked():
    df = _cases([_dc(10, None), _dc(20, 0.4)])
    assert df.set_index("N")["ranked"].to_dict() == {10: False, 20: True}
    assert df.set_index("N").loc[10, "verification_failure"] == case_frame.NO_VERIFIED_ACOT
    assert tables.acot_table(df).set_index("N")["verified"].to_dict() == {10: 0, 20: 1}


def test_a_method_labelled_as_a_thesis_method_keeps_it_beside_another_that_runs_the_same():
    rows = [{"method": "OP-DC", "N": 10, "acot": 0.4}, {"method": "blended start", "N": 10, "acot": 0.3},
            {"method": "OP-DM", "N": 10, "acot": 0.4, "transcription": "dmoc"},
            {"method": "dmoc too", "N": 10, "acot": 0.4, "transcription": "dmoc"},
            {"method": "trapezoidal", "N": 10, "acot": 0.4, "transcription": "dmoc"}]
    info = case_frame.method_info(_cases(rows)).set_index("method")["thesis_method"]
    assert info["OP-DC"] == "OP-DC" and info["OP-DM"] == "OP-DM"
    assert info[["blended start", "dmoc too", "trapezoidal"]].isna().all()  # their guesses are taken by name
    alone = case_frame.method_info(_cases(rows[1:2])).set_index("method")["thesis_method"]
    assert alone["blended start"] == "OP-DC"  # unlabelled and alone: what it runs names it


# --- selecting the inconsistent walks for solving again ------------------------------------------------------------

SUITE = """\
    [suite]
    name = "ladder"
    output = "results/ladder"
    steps = 1

    [sweep]
    experiments = ["forward"]
    N = [40, 50, 60, 70, 80, 90, 100, 110]
    transcriptions = ["hermite-simpson"]
    solvers = ["ipopt"]
    strategies = ["one-phase"]
"""


class _Recording:
    """An executor that solves nothing: it records which cases it was given and returns a complete walk."""

    name, jobs = "recording", 1

    def __init__(self) -> None:
        self.ran: list[int] = []

    def run(self, cases):
        from gaitbench.run.runner import CaseOutcome

        for case in cases:
            self.ran.append(case.n_nodes)
            yield CaseOutcome(case, "solved", "", 1.0, {"acot": 0.31})


@pytest.fixture
def ladder(tmp_path):
    """The suite, and a store of its walks: ACOT 0.30 at every N but 0.60 at N = 110."""
    from gaitbench.run.runner import CaseOutcome, case_row
    from gaitbench.run.store import ResultStore
    from gaitbench.run.suite import load_suite

    path = tmp_path / "ladder.toml"
    path.write_text(textwrap.dedent(SUITE))
    suite = load_suite(path)
    with ResultStore.create(tmp_path / "store") as store:
        store.start_run({"run_id": "r1", "suite": "ladder", "started_at": "2026-01-01T00:00:00+00:00"})
        for case in suite.cases:
            acot = 0.60 if case.n_nodes == 110 else 0.30
            outcome = CaseOutcome(case, "solved", "", 1.0, {"acot": acot, "verified": True})
            store.record_case(case_row(outcome, "ladder", "r1"))
    return path, suite, tmp_path / "store"


def test_runs_show_lists_the_inconsistent_walks(ladder):
    from gaitbench.cli.main import main

    _, suite, store = ladder
    flagged = next(case.key for case in suite.cases if case.n_nodes == 110)
    result = CliRunner().invoke(main, ["runs", "show", str(store), "--inconsistent", "--wide"])
    assert result.exit_code == 0, result.output
    assert flagged in result.output and "0.6000" in result.output and "0.3000" not in result.output
    result = CliRunner().invoke(main, ["runs", "show", str(store), "--inconsistent", "--tolerance", "1.5"])
    assert result.exit_code == 0 and "0.6000" not in result.output
    result = CliRunner().invoke(main, ["runs", "show", str(store), "--inconsistent", "--band", "90-40"])
    assert result.exit_code == 2 and "'90-40' is not LOW-HIGH" in result.output


def test_the_report_lists_the_exceptions(ladder, tmp_path):
    from gaitbench.reports import write_report

    _, suite, store = ladder
    flagged = next(case.key for case in suite.cases if case.n_nodes == 110)
    html = write_report(store, tmp_path / "report").read_text()
    section = html[html.index('<section id="consistency">'):]
    section = section[:section.index("</section>")]
    assert "1 exception)" in section and flagged in section and 'id="tbl-consistency"' in section
    written = pd.read_csv(tmp_path / "report" / "consistency.csv")
    assert written[["N", "ratio"]].values.tolist() == [[110, pytest.approx(2.0)]]
    assert "Shaded: each method" in html and "N − 10 … N + 10" in html  # the ACOT caption says what its band is


def test_run_retry_inconsistent_solves_only_those_walks_again(ladder, monkeypatch):
    from gaitbench.cli import run_commands
    from gaitbench.cli.main import main
    from gaitbench.reports import build_report

    path, _, store = ladder
    executor = _Recording()
    monkeypatch.setattr(run_commands, "_executor", lambda *args: executor)
    result = CliRunner().invoke(main, ["run", str(path), "--store", str(store), "--resume", "--no-report"])
    assert result.exit_code == 0, result.output
    assert executor.ran == []  # --resume alone: every case is stored
    result = CliRunner().invoke(main, ["run", str(path), "--store", str(store), "--resume", "--retry-inconsistent",
                                       "--no-report"])
    assert result.exit_code == 0, result.output
    assert executor.ran == [110]
    assert build_report(store).tables["consistency"].empty  # its new row (0.31) replaced the old


def test_the_dearest_step_of_a_dc_exception_comes_from_its_verified_steps_not_a_patchworks_claims():
    """D&C-DC: median 1.0 over N = 40–90, then 1.4 at N = 110 with step 2 the dear one. A row stored before D&C
    walks chained verified motions (its per-step COTs, the patchwork's claims, do not average to its ACOT) has no
    dearest step."""
    def dc(n: int, acot: float, cot_steps: list[float]) -> dict:
        return _dc(n, acot) | {"acot": acot, "claimed_acot": 0.5 * acot, "cot_steps": cot_steps}

    rows = [dc(n, 1.0, [1.0, 1.0]) for n in range(40, 100, 10)]
    rows += [dc(110, 1.4, [1.0, 1.8]), dc(130, 1.4, [0.2, 0.3])]  # the second: a patchwork's claims
    df = _cases(rows)
    exceptions = statistics.consistency_exceptions(tables.acot_table(df), df).set_index("N")
    assert set(exceptions.index) == {110, 130}
    assert (exceptions.loc[110, "dearest_step"], exceptions.loc[110, "dearest_step_excess"]) == (2, pytest.approx(0.8))
    assert pd.isna(exceptions.loc[130, "dearest_step"])


def test_the_fewest_pairs_given_an_interval_get_one_narrower_than_their_range():
    """An interval that is only the savings' range says nothing a table of them does not: at the fewest pairs that
    get one, the median's interval of distinct savings lies strictly inside their range."""
    savings = np.linspace(-30.0, 40.0, statistics.MIN_PAIRS_FOR_CI)
    low, high = statistics.bootstrap_ci(savings, np.median)
    assert savings.min() < low < high < savings.max()
    fewer = savings[:-1]
    assert statistics.bootstrap_ci(fewer, np.median) == pytest.approx((fewer.min(), fewer.max()))

