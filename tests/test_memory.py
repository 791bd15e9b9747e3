"""Memory estimates: the laws against their measurements, the limit, and refusing sizes that cannot fit."""

from __future__ import annotations

import json
import textwrap
from pathlib import Path

import pytest
from click.testing import CliRunner

from gaitbench.cli.main import main
from gaitbench.plugins import load_registry
from gaitbench.run.memory import (
    MEMORY_LIMIT_ENV,
    MemoryLimit,
    estimate_case_memory,
    jobs_that_fit,
    largest_fitting_nodes,
    memory_limit,
    memory_problem,
    parse_size_mb,
)
from gaitbench.run.suite import SuiteError, load_suite

ROOT = Path(__file__).resolve().parent.parent
MEASURED = ROOT / "benchmarks" / "results" / "memory.jsonl"
REGISTRY = load_registry()

SUITE = """
[suite]
name = "big"
steps = 1
time_limit_s = 5  # were a refusal to fail, the walk would stop at once rather than run for an hour

[sweep]
experiments = ["forward"]
N = {N}
transcriptions = ["{transcription}"]
solvers = ["ipopt"]
strategies = ["{strategy}"]
"""


def _suite(tmp_path: Path, nodes: list[int], transcription: str = "dmoc", strategy: str = "one-phase") -> Path:
    path = tmp_path / "big.toml"
    path.write_text(textwrap.dedent(SUITE.format(N=nodes, transcription=transcription, strategy=strategy)))
    return path


def _measured() -> list[dict]:
    return [json.loads(line) for line in MEASURED.read_text().splitlines() if line.strip()]


def test_the_laws_reproduce_the_measurements_they_were_fitted_to():
    """Every measured case (benchmarks/results/memory.jsonl) is estimated within 10 %, or over-estimated."""
    rows = _measured()
    assert {(row["transcription"], row["strategy"]) for row in rows} >= {
        (t, s) for t in ("hermite-simpson", "dmoc", "trapezoidal")
        for s in ("one-phase", "warm-start", "decrease-and-conquer", "whole-walk")}
    for row in rows:
        estimate = estimate_case_memory(row["transcription"], row["strategy"], row["N"], row.get("steps", 1))
        assert estimate.mb >= 0.9 * row["peak_mb"], (row, estimate)
        assert estimate.mb <= 1.6 * row["peak_mb"], (row, estimate)


def test_decrease_and_conquer_grows_faster_and_whole_walk_counts_every_step():
    one_phase = estimate_case_memory("hermite-simpson", "one-phase", 200)
    sections = estimate_case_memory("hermite-simpson", "decrease-and-conquer", 200)
    assert sections.mb > 5 * one_phase.mb and sections.law.quadratic_mb > 0
    assert estimate_case_memory("dmoc", "whole-walk", 50, steps=4).nodes == 200
    assert estimate_case_memory("dmoc", "one-phase", 50, steps=4).nodes == 50


def test_a_plugin_that_was_not_measured_gets_a_conservative_stand_in():
    custom = estimate_case_memory("my-collocation", "one-phase", 300)
    assert custom.mb == max(estimate_case_memory(t, "one-phase", 300).mb
                            for t in ("hermite-simpson", "dmoc", "trapezoidal"))
    assert "the most of the measured" in custom.basis
    mine = estimate_case_memory("dmoc", "my-strategy", 300)
    assert mine.mb >= estimate_case_memory("dmoc", "one-phase", 300).mb


@pytest.mark.parametrize(("text", "mb"), [("64G", 65536), ("64GB", 65536), ("512M", 512), ("1.5T", 1.5 * 2**20),
                                          ("1073741824", 1024), ("2GiB", 2048)])
def test_memory_limit_sizes(text, mb):
    assert parse_size_mb(text) == pytest.approx(mb)


def test_memory_limit_is_the_environment_s_or_the_available_memory(monkeypatch):
    monkeypatch.setenv(MEMORY_LIMIT_ENV, "3G")
    assert memory_limit() == MemoryLimit(3072, f"set by {MEMORY_LIMIT_ENV}=3G")
    monkeypatch.setenv(MEMORY_LIMIT_ENV, "lots")
    with pytest.raises(ValueError, match="GAITBENCH_MEMORY_LIMIT='lots' is not a size; expected e.g. 64G"):
        memory_limit()
    monkeypatch.delenv(MEMORY_LIMIT_ENV)
    import psutil

    assert memory_limit().source == "available on this machine"
    assert memory_limit().mb == pytest.approx(psutil.virtual_memory().available / 2**20, rel=0.2)


def test_the_largest_n_that_fits_is_the_boundary():
    for strategy in ("one-phase", "decrease-and-conquer", "whole-walk"):
        fits = largest_fitting_nodes("hermite-simpson", strategy, 3, 4096)
        assert estimate_case_memory("hermite-simpson", strategy, fits, 3).mb <= 4096
        assert estimate_case_memory("hermite-simpson", strategy, fits + 1, 3).mb > 4096


def test_the_message_gives_the_estimate_the_limit_and_the_fix():
    limit = MemoryLimit(4096, "set by GAITBENCH_MEMORY_LIMIT=4G")
    assert memory_problem("dmoc", "one-phase", 1000, 1, "x", limit) is None
    message = memory_problem("dmoc", "one-phase", 100_000, 1, "'one-phase dmoc ipopt'", limit)
    fits = largest_fitting_nodes("dmoc", "one-phase", 1, 4096)
    estimate = estimate_case_memory("dmoc", "one-phase", 100_000)
    assert message == (
        f"N = 100000 does not fit in memory: 'one-phase dmoc ipopt' needs about {estimate.mb / 1024:.1f} GB per case "
        f"(measured law for one-phase dmoc: {estimate.law.describe()}; docs/performance.md, \"Memory\"), more than "
        f"the 4.0 GB set by GAITBENCH_MEMORY_LIMIT=4G. Lower N to at most {fits}, or, if the cases run where more "
        f"memory is available, set GAITBENCH_MEMORY_LIMIT to that size (e.g. GAITBENCH_MEMORY_LIMIT="
        f"{-(-estimate.mb // 1024):.0f}G)")


def test_workers_that_start_together_must_fit_together():
    limit = MemoryLimit(2048, "available on this machine")
    assert jobs_that_fit([1500, 400, 300], 2, limit) == (2, None)
    assert jobs_that_fit([1500, 1000], 1, limit) == (1, None)
    assert jobs_that_fit([300, 1500, 400, 200], 4, limit)[0] == 2  # the largest first: 1500 + 400 fit, + 300 not
    fitting, why = jobs_that_fit([1500, 1000, 300], 2, limit)
    assert fitting == 1 and why.startswith(
        "2 workers would start the 2 largest cases together (largest N first), which need about 2.4 GB together, "
        "more than the 2.0 GB available on this machine; 1 fit")


# At suite load and in `gaitbench solve`


def test_a_suite_with_a_size_that_cannot_fit_is_refused_when_it_loads(tmp_path, monkeypatch):
    monkeypatch.setenv(MEMORY_LIMIT_ENV, "4G")
    path = _suite(tmp_path, [10, 100_000])
    with pytest.raises(SuiteError) as caught:
        load_suite(path, REGISTRY)
    message = str(caught.value)
    assert message.startswith(f"{path}: [sweep].N: N = 100000 does not fit in memory: 'one-phase dmoc ipopt' needs "
                              "about ")
    assert "more than the 4.0 GB set by GAITBENCH_MEMORY_LIMIT=4G. Lower N to at most " in message

    sections = _suite(tmp_path, [20, 1000], strategy="decrease-and-conquer")
    with pytest.raises(SuiteError, match=r"N = 1000 does not fit in memory: 'decrease-and-conquer dmoc ipopt' .* "
                                          r"MB × N²"):
        load_suite(sections, REGISTRY)

    monkeypatch.setenv(MEMORY_LIMIT_ENV, "64G")
    assert len(load_suite(path, REGISTRY).cases) == 2


def test_a_size_no_machine_has_is_refused_against_the_available_memory(tmp_path, monkeypatch):
    monkeypatch.delenv(MEMORY_LIMIT_ENV, raising=False)
    with pytest.raises(SuiteError, match=r"N = 10000000 does not fit in memory: .* available on this machine"):
        load_suite(_suite(tmp_path, [10_000_000]), REGISTRY)


def test_a_bad_memory_limit_is_a_suite_error(tmp_path, monkeypatch):
    monkeypatch.setenv(MEMORY_LIMIT_ENV, "lots")
    with pytest.raises(SuiteError, match="GAITBENCH_MEMORY_LIMIT='lots' is not a size"):
        load_suite(_suite(tmp_path, [10]), REGISTRY)


def test_every_shipped_suite_fits_in_4_gb_per_case(monkeypatch):
    monkeypatch.setenv(MEMORY_LIMIT_ENV, "4G")
    for path in sorted((ROOT / "suites").glob("*.toml")):
        suite = load_suite(path, REGISTRY)
        assert set(suite.memory_mb) == {case.key for case in suite.cases}
        assert max(suite.memory_mb.values()) <= 4096


def test_solve_refuses_a_size_that_cannot_fit(monkeypatch):
    monkeypatch.setenv(MEMORY_LIMIT_ENV, "4G")
    result = CliRunner().invoke(main, ["solve", "-e", "forward", "-t", "dmoc", "--N", "100000", "--steps", "1"])
    assert result.exit_code == 2
    error = " ".join(result.stderr.split())
    assert "Invalid value for --N: N = 100000 does not fit in memory: one-phase dmoc needs about" in error
    assert "Lower N to at most" in error and "ACOT" not in result.stdout


def test_run_lowers_jobs_to_the_cases_and_to_what_fits_together_with_a_warning(tmp_path, monkeypatch):
    """--jobs 3 on 2 cases starts 2 workers at most, and 1 when two N = 8 cases (about 170 MB each) do not fit in
    300 MB together: each lowering is one warning line, and the run goes on."""
    monkeypatch.setenv(MEMORY_LIMIT_ENV, "300M")
    path = _suite(tmp_path, [8, 9], transcription="hermite-simpson")
    result = CliRunner().invoke(main, ["run", str(path), "--jobs", "3", "--no-report", "--store", str(tmp_path / "s")])
    warnings = [line for line in result.stderr.splitlines() if line.startswith("warning: --jobs")]
    assert warnings[0] == "warning: --jobs 3 lowered to 2: the suite has 2 cases"
    assert warnings[1].startswith("warning: --jobs 2 lowered to 1: 2 workers would start the 2 largest cases "
                                  "together (largest N first), which need about 3")
    assert len(warnings) == 2 and "Traceback" not in result.output
    from gaitbench.run.store import ResultStore

    with ResultStore.open(tmp_path / "s") as store:
        assert [run["jobs"] for run in store.runs()] == [1]


def test_a_resumed_run_starts_no_more_workers_than_cases_left(tmp_path, monkeypatch):
    monkeypatch.delenv(MEMORY_LIMIT_ENV, raising=False)
    store = tmp_path / "s"
    first = CliRunner().invoke(main, ["run", str(_suite(tmp_path, [8], transcription="hermite-simpson")),
                                      "--executor", "inprocess", "--no-report", "--store", str(store)])
    assert first.exit_code == 0, first.output
    path = _suite(tmp_path, [8, 9], transcription="hermite-simpson")
    result = CliRunner().invoke(main, ["run", str(path), "--resume", "--jobs", "2", "--no-report", "--store",
                                       str(store)])
    assert result.exit_code == 0, result.output
    warnings = [line for line in result.stderr.splitlines() if line.startswith("warning: --jobs")]
    assert warnings == ["warning: --jobs 2 lowered to 1: 1 of the suite's cases are left to run"]
    from gaitbench.run.store import ResultStore

    with ResultStore.open(store) as opened:
        assert [(run["executor"], run["jobs"]) for run in opened.runs()] == [("inprocess", 1), ("local", 1)]
