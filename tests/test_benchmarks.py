"""The ACOT regression check must fail on a changed result, and its case set must stay a valid suite."""

import importlib.util
import json
import math
import sys
from pathlib import Path

import pytest

from gaitbench.run.case import Case, PluginChoice
from gaitbench.run.runner import largest_first
from gaitbench.run.suite import load_suite

BENCHMARKS = Path(__file__).parents[1] / "benchmarks"


def _benchmark(name: str):
    """benchmarks/<name>.py, loaded as a module (the benchmarks are scripts, not a package); registered in
    ``sys.modules``, under a name no installed module has, because a dataclass of theirs looks its module up there."""
    spec = importlib.util.spec_from_file_location(f"benchmark_{name}", BENCHMARKS / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    spec.loader.exec_module(module)
    return module


def _regression_module():
    return _benchmark("acot_regression")


def _row(acot, status="solved", claimed=None):
    return {"case": "c", "status": status, "message": "", "acot": acot, "claimed_acot": claimed}


def test_differences_flag_status_acot_and_missing_cases():
    check = _regression_module()
    baseline = {"a": _row(0.05), "b": _row(0.07, claimed=0.06), "c": _row(None, "incomplete")}
    assert check.differences(baseline, {"a": _row(0.05 + 1e-9), "b": _row(0.07, claimed=0.06),
                                        "c": _row(None, "incomplete")}, 1e-6) == ([], [])
    found, within = check.differences(baseline, {"a": _row(0.0501), "b": _row(0.07, "incomplete", 0.06)}, 1e-6)
    assert within == []
    assert any("acot 0.05 -> 0.0501" in line for line in found)
    assert any("status solved -> incomplete" in line for line in found)
    assert any("missing" in line for line in found)
    assert check.differences({"b": _row(0.07, claimed=0.06)}, {"b": _row(0.07, claimed=None)}, 1e-6)[0]


def test_rounding_band_admits_only_what_perturbed_runs_of_the_baseline_reached():
    check = _regression_module()
    baseline = {"a": _row(0.05), "b": _row(None, "incomplete")}
    perturbed = [{"a": _row(0.052), "b": _row(0.3)}, {"a": _row(0.049), "b": _row(None, "incomplete")}]
    band = check.rounding_band([baseline, *perturbed])
    assert band["a"]["acot"] == [0.049, 0.052] and band["b"]["statuses"] == ["incomplete", "solved"]
    found, within = check.differences(baseline, {"a": _row(0.051), "b": _row(0.3)}, 1e-6, band)
    assert found == [] and len(within) == 3  # a moved inside its band; b flipped status (and ACOT) as when nudged
    found, within = check.differences(baseline, {"a": _row(0.06), "b": _row(None, "error")}, 1e-6, band)
    assert len(found) == 2 and within == []
    assert any("band 0.049" in line for line in found)


def test_solver_options_are_read_as_literals_and_their_effect_counted_by_direction():
    check = _regression_module()
    assert check.solver_option("nlp_scaling_obj_target_gradient=1") == ("nlp_scaling_obj_target_gradient", 1)
    assert check.solver_option("mu_strategy=adaptive") == ("mu_strategy", "adaptive")
    baseline = {"a": _row(0.05), "b": _row(0.07), "c": _row(0.3), "d": _row(None, "incomplete")}
    current = {"a": _row(0.04), "b": _row(0.07 + 1e-9), "c": _row(0.31), "d": _row(0.2)}
    assert check.directions(baseline, current, 1e-6) == (1, 1)  # b unchanged, d solved in one run only


def test_baseline_covers_the_regression_suite():
    check = _regression_module()
    suite = load_suite(check.SUITE)
    baseline = json.loads(check.BASELINE.read_text())["cases"]
    assert {case.key for case in suite.cases} == set(baseline)


def _performance_module(monkeypatch):
    """benchmarks/performance.py, which imports its sibling performance_summary as a script run from there would."""
    monkeypatch.syspath_prepend(str(BENCHMARKS))
    return _benchmark("performance")


def test_suite_extrapolation_fits_each_experiment_and_method_on_its_own(monkeypatch):
    performance = _performance_module(monkeypatch)
    laws = {("forward", "OP-DC"): (0.01, 1.0), ("stairs", "OP-DC"): (0.002, 2.0), ("stairs", "reference"): (0.5, 1.5)}
    sample = [{"experiment": experiment, "method": method, "N": n, "status": "solved", "wall_s": a * n**b}
              for (experiment, method), (a, b) in laws.items() for n in (10, 20, 30)]
    fit = performance.extrapolate(sample, range(10, 201, 10), jobs=2)
    expected = {f"{experiment} {method}": sum(a * n**b for n in range(10, 201, 10))
                for (experiment, method), (a, b) in laws.items()}
    for label, total in expected.items():
        assert abs(fit["methods"][label]["suite_case_time_s"] - total) < 1e-6 * total
    assert abs(fit["wall_s_lower_bound"] - sum(expected.values()) / 2) < 1e-6 * sum(expected.values())


def test_a_sampled_suite_keeps_its_methods_and_gives_ipopt_the_options(tmp_path, monkeypatch):
    performance = _performance_module(monkeypatch)
    text = performance.sampled_suite("thesis-all", (50, 100), 900, performance.OBJECTIVE_SCALING)
    sample = tmp_path / "sample.toml"
    sample.write_text(text)
    suite = load_suite(sample)
    assert {case.n_nodes for case in suite.cases} == {50, 100}
    assert {case.time_limit_s for case in suite.cases} == {900}
    solvers = {case.method: case.solver for case in suite.cases}
    assert set(solvers) == {"OP-DC", "OP-DM", "D&C-DC", "D&C-DM", "reference"}
    for method, solver in solvers.items():
        if method == "reference":
            assert solver.name == "sqp" and solver.options == {}
        else:
            assert solver.name == "ipopt" and solver.options == performance.OBJECTIVE_SCALING


def test_the_rest_of_thesis_all_and_thesis_forward_are_its_cases_split_without_overlap(tmp_path, monkeypatch):
    performance = _performance_module(monkeypatch)
    rest = tmp_path / "rest.toml"
    rest.write_text(performance.sampled_suite("thesis-all", (50,), 3600,
                                              experiments=("downward-slope", "upward-slope", "stairs")))
    forward = performance.suite_cases("thesis-forward", (50,), performance.IPOPT_METHODS, None)
    whole = performance.suite_cases("thesis-all", (50,), performance.IPOPT_METHODS, None)
    keys = [case.key for case in load_suite(rest).with_methods(performance.IPOPT_METHODS).cases]
    assert len(keys) == 12 and sorted(keys + [case.key for case in forward]) == sorted(case.key for case in whole)


def test_the_list_schedule_packs_the_measured_case_times_in_either_order(monkeypatch):
    performance = _performance_module(monkeypatch)
    cases = [Case(PluginChoice("forward"), n, PluginChoice("hermite-simpson"), PluginChoice("ipopt"),
                  PluginChoice("one-phase"), method="OP") for n in (10, 20, 30)]
    measured = [{"experiment": "forward", "method": "OP", "N": n, "wall_s": t}
                for n, t in ((10, 1.0), (20, 2.0), (30, 10.0))]
    # suite order: worker A runs 1 s then 10 s while B runs 2 s; largest first: A runs 10 s, B 2 s then 1 s
    assert performance.list_schedule(measured, 2, cases) == 11.0
    assert performance.list_schedule(measured, 2, largest_first(cases)) == 10.0
    assert performance.list_schedule(measured, 1, largest_first(cases)) == 13.0


def test_the_recorded_summary_is_the_rendering_of_the_recorded_results(monkeypatch):
    performance = _performance_module(monkeypatch)
    from performance_summary import summary_markdown

    results = json.loads(performance.RESULTS.read_text())
    assert summary_markdown(results) == performance.SUMMARY.read_text()


def _scaling_module():
    return _benchmark("scaling")


def test_the_scaling_model_schedules_as_the_runner_hands_out_cases():
    import pandas as pd

    model = _scaling_module()
    # largest N first, store order among equal N: 5, 4, 3, 3, 3 on two workers finish at 10 (bound 9: 18 / 2)
    cases = pd.DataFrame({"N": [10, 30, 20, 10, 10], "wall_time_s": [3.0, 5.0, 4.0, 3.0, 3.0],
                          "key": ["a", "b", "c", "d", "e"]})
    assert list(model.schedule_order(cases)["key"]) == ["b", "c", "a", "d", "e"]
    two, eight = model.scaling(cases, (2, 8))
    assert (two.makespan_s, two.bound_s) == (10.0, 9.0)
    assert (eight.makespan_s, eight.bound_s, eight.efficiency) == (5.0, 5.0, 1.0)  # the longest case bounds it


def test_the_fanned_out_model_shares_the_cores_between_sections_and_reads_d_and_c_walks(tmp_path):
    import pandas as pd

    model = _scaling_module()
    # a D&C case (1 s serial, then 4 sections of 1 s) beside a 3 s case on 2 cores: the sections take the core the
    # serial part frees at 1 s, then both cores from 3 s: done at 4 s, the bound (8 s of work over 2 cores)
    dc, whole = model.CaseWork(((1.0, (1.0,) * 4),)), model.CaseWork(((3.0, ()),))
    two, = model.fanned_scaling([dc, whole], (2,))
    assert (two.makespan_s, two.bound_s) == (4.0, 4.0)
    assert dc.critical_path(2) == 3.0 and model.fanned_makespan([dc, whole], 1) == 8.0
    times = [5.0, 4.0, 3.0, 3.0, 3.0]  # cases that do not fan out: the local pool's schedule
    assert model.fanned_makespan([model.CaseWork(((t, ()),)) for t in times], 2) == model.makespan(times, 2)

    walk = {"steps": [{"details": {"first_phase": {"solve_time_s": 1.0}, "complete": {"solve_time_s": 1.0},
                                   "polished": {"solve_time_s": 1.0}, "candidates": 3}}] * 2}
    (tmp_path / "walk.json").write_text(json.dumps(walk))
    row = pd.Series({"strategy": "decrease-and-conquer", "N": 5, "wall_time_s": 10.0, "walk_path": "walk.json"})
    # 2 × 3 s serial; the other 4 s shared by 2 steps × (N − 3) sections
    assert model.case_work(row, tmp_path).steps == ((3.0, (1.0, 1.0)), (3.0, (1.0, 1.0)))
    assert model.case_work(row.drop("walk_path"), tmp_path).steps == ((10.0, ()),)


def _completion_module():
    return _benchmark("completion")


def test_costly_steps_and_the_complete_candidate_are_counted_from_the_step_cots():
    import pandas as pd

    completion = _completion_module()
    steps = pd.DataFrame([
        {"experiment": "stairs", "method": "OP-DC", "N": 190, "step": 8, "cot": 5.7, "complete_cot": None},
        {"experiment": "stairs", "method": "OP-DC", "N": 150, "step": 8, "cot": 3.2, "complete_cot": None},
        {"experiment": "stairs", "method": "OP-DC", "N": 150, "step": 7, "cot": 0.03, "complete_cot": None},
        {"experiment": "upward-slope", "method": "D&C-DM", "N": 140, "step": 2, "cot": 10.5, "complete_cot": 0.67},
        {"experiment": "upward-slope", "method": "D&C-DM", "N": 140, "step": 3, "cot": 0.5, "complete_cot": 0.7},
        {"experiment": "upward-slope", "method": "D&C-DM", "N": 140, "step": 4, "cot": 0.5, "complete_cot": 0.4},
    ])
    table = completion.costly_steps_table(steps)
    assert table.to_dict("records") == [
        {"experiment": "stairs", "method": "OP-DC", "step": 8, "walks": 2, "N": "150, 190", "COT": "3.20–5.70"},
        {"experiment": "upward-slope", "method": "D&C-DM", "step": 2, "walks": 1, "N": "140", "COT": "10.50–10.50"}]
    assert "below the polished step it reports in 2 of its 3 steps, and in 1 of the 1 polished steps above 3" in \
        completion.complete_candidate_summary(steps)
    steps["backed_up"] = [True, False, False, False, False, False]
    steps["rescued"] = [True, True, False, False, False, False]
    steps["stand_in"] = [False, False, False, False, True, True]
    assert completion.last_tries_summary(steps) == (
        "Last tries in the complete walks: 1 step backed up (solved again after a dead end) in 1 walk; 2 steps "
        "rescued from a coarser grid in 2 walks; 2 steps verified by the complete solution standing in for a failed "
        "polish in 1 walk.")


def test_a_carried_store_keeps_its_finished_cases_its_walks_in_flight_and_its_package_versions(tmp_path):
    from gaitbench.run.case import Case, PluginChoice
    from gaitbench.run.runner import CaseOutcome, case_row
    from gaitbench.run.store import ResultStore

    module = _benchmark("snapshot_store")

    def case(n_nodes):
        return Case(PluginChoice("forward"), n_nodes, PluginChoice("hermite-simpson"), PluginChoice("ipopt"),
                    PluginChoice("decrease-and-conquer"), steps=11, method="D&C-DC")

    finished, in_flight = case(150), case(200)
    live = tmp_path / "live"
    with ResultStore.create(live) as store:  # left open: a run that has not yet let go of it
        store.start_run({"run_id": "r1", "suite": "s", "started_at": "now"})
        store.record_case(case_row(CaseOutcome(finished, "solved", "", 1.0, {"acot": 0.3}), "s", "r1"),
                          {"walk.json": b"{}", "walk.npz": b"not drawn by the report"})
        assert store.claim(in_flight.key, "r1", None) == "claimed"
        (live / "checkpoints").mkdir()
        for key in (finished.key, in_flight.key):  # the finished case's as a time limit leaves it, for the retry
            (live / "checkpoints" / key).write_bytes(b"steps")
            (live / "checkpoints" / f"{key}.json").write_text("{}")
        (live / "checkpoints" / f".{in_flight.key}.123").write_bytes(b"half written")
        carry = tmp_path / "carry" / "live.tar.xz"
        assert module.save(live, carry) == {"cases": 1, "checkpoints": 2}
    restored = tmp_path / "restored"
    assert module.restore(carry, restored) == {"cases": 1, "checkpoints": 2, "differing": []}
    assert sorted(path.name for path in (restored / "checkpoints").iterdir()) == sorted(
        [in_flight.key, f"{in_flight.key}.json", finished.key, f"{finished.key}.json"])
    assert (restored / "checkpoints" / in_flight.key).read_bytes() == b"steps"
    assert not list(restored.rglob("walk.npz"))  # a report-only carry: no trajectory the report does not draw
    assert (tmp_path / "restored.constraints.txt").read_text() == module.installed_versions()
    with ResultStore.create(restored) as copy:  # a resumed run opens it for writing
        assert copy.finished_keys() == {finished.key}
        assert copy.claim(in_flight.key, "r2", None) == "claimed"  # the claim stayed with the live store
    assert module.differing_versions("numpy==2.0\ncasadi==3.6\n", "numpy==2.0\n") == ["casadi 3.6 -> not installed"]

def test_savings_are_summarized_verified_and_claimed_beside_the_published_range():
    import pandas as pd

    completion = _completion_module()
    savings = pd.DataFrame({
        "experiment": ["forward"] * 3, "method": ["D&C-DC"] * 3, "baseline": ["OP-DC"] * 3, "N": [10, 20, 30],
        "savings_percent": [5.0, -2.0, 12.0], "claimed_savings_percent": [20.0, 30.0, None]})
    published = pd.DataFrame({"experiment": ["forward"], "comparison": ["D&C-DC vs OP-DC"],
                              "published_min_percent": [12.24], "published_max_percent": [85.41]})
    thesis = {("forward", "D&C-DC"): "D&C-DC", ("forward", "OP-DC"): "OP-DC"}
    assert completion.summarize_savings(savings, published, thesis).to_dict("records") == [{
        "experiment": "forward", "comparison": "D&C-DC vs OP-DC", "N compared": 3, "N with a saving": 2,
        "verified saving: median (range)": "+5.0 % (-2.0 … +12.0)", "claimed saving: median": "+25.0 %",
        "thesis: range": "+12.24 … +85.41 %"}]


def test_the_retry_ladder_is_tabulated_per_method_and_rung_in_the_order_first_tried():
    import pandas as pd

    completion = _completion_module()
    walk_steps = [
        {"details": {"first_attempt": {"status": "error", "solve_time_s": 4.0},
                     "retries": [{"remedy": "filter", "status": "iteration_limit", "solve_time_s": 50.0},
                                 {"remedy": "clarabel", "status": "converged", "solve_time_s": 30.0}]}},
        {"details": {"retries": []}},  # a step that needed no retry
        {"details": {"rescued_from": {"first_attempt": {"status": "error", "solve_time_s": 1.0},
                                      "retries": [{"remedy": "clarabel", "status": "error", "solve_time_s": 5.0}]}}},
        {"details": {"retries": [{"remedy": "adaptive-mu", "status": "converged", "solve_time_s": 2.0}]}},
    ]
    ladders = list(completion._ladders(walk_steps))
    assert [len(ladder["retries"]) for ladder in ladders] == [2, 1, 1]
    tries = pd.DataFrame([
        {"method": "reference", "remedy": "first attempt (failed)", "converged": False, "time_s": 4.0},
        {"method": "reference", "remedy": "filter", "converged": False, "time_s": 50.0},
        {"method": "reference", "remedy": "clarabel", "converged": True, "time_s": 30.0},
        {"method": "reference", "remedy": "clarabel", "converged": False, "time_s": 5.0},
        {"method": "D&C-DC", "remedy": "adaptive-mu", "converged": True, "time_s": 2.0},
    ])
    assert completion.ladder_table(tries).to_dict("records") == [
        {"method": "D&C-DC", "rung": "adaptive-mu", "tried": 1, "converged": 1, "time (s)": "2",
         "of it failed (s)": "0"},
        {"method": "reference", "rung": "first attempt (failed)", "tried": 1, "converged": "—", "time (s)": "4",
         "of it failed (s)": "4"},
        {"method": "reference", "rung": "filter", "tried": 1, "converged": 0, "time (s)": "50",
         "of it failed (s)": "50"},
        {"method": "reference", "rung": "clarabel", "tried": 2, "converged": 1, "time (s)": "35",
         "of it failed (s)": "5"}]


def test_a_re_rendered_completion_record_keeps_its_notes():
    completion = _completion_module()
    existing = "# Completion: s (in progress)\n\nChanges:\n- a note\n\n3 of 4 walks complete (75 %).\n\nold table\n"
    rendered = "# Completion: s\n\n4 of 4 walks complete (100 %).\n\nnew table\n"
    assert completion.keep_notes(existing, rendered) == \
        "# Completion: s (in progress)\n\nChanges:\n- a note\n\n4 of 4 walks complete (100 %).\n\nnew table\n"
    assert completion.keep_notes("no table yet\n", rendered) == rendered


def _solvers_module():
    return _benchmark("solvers")


def _solve(solver, experiment, step, status, seconds, cot=None, verified=None):
    return {"solver": solver, "experiment": experiment, "step": step, "transcription": "dmoc", "N": 25,
            "status": status, "call_s": 2 * seconds, "cpu_s": seconds, "verified_cot": cot,
            "verified": cot is not None if verified is None else verified}


def test_the_solver_summary_compares_time_and_optimum_with_ipopt_where_both_converged():
    solvers = _solvers_module()
    rows = [_solve("ipopt", "forward", 1, "converged", 1.0, 1e-4), _solve("ipopt", "forward", 2, "converged", 2.0, 1.0),
            _solve("ipopt", "upward-slope", 1, "iteration_limit", 5.0),
            _solve("sqp", "forward", 1, "converged", 3.0, 9e-4, verified=False),
            _solve("sqp", "forward", 2, "converged", 8.0, 0.95),
            _solve("sqp", "upward-slope", 1, "time_limit", 60.0)]
    table = solvers.summary(rows)
    assert table[2] == "| `ipopt` | 2 of 3 | 2 | 1× | — | iteration_limit 1 |"
    # forward step 1's COTs (a continuum of optima near zero) are not compared; step 2 is 5 % lower
    assert table[3] == "| `sqp` | 2 of 3 | 1 | 3.5× (3.0–4.0×) | -5.0 % on 1 | time_limit 1 |"


def test_the_solver_profiles_count_verified_solves_on_the_problems_every_solver_ran():
    solvers = _solvers_module()
    rows = [_solve("ipopt", "forward", 1, "converged", 1.0, 1e-4), _solve("sqp", "forward", 1, "converged", 2.0, 1e-5),
            _solve("ipopt", "forward", 2, "converged", 2.0, 1.0),
            _solve("sqp", "forward", 2, "converged", 1.0, 0.5, verified=False),
            _solve("ipopt", "stairs", 6, "converged", 1.0, 1.0)]  # sqp did not run it: left out
    n_time, n_cot, panels = solvers.profile_ratios(rows)
    time_ratios, cot_ratios = panels.values()
    assert (n_time, n_cot) == (2, 1)
    assert time_ratios["ipopt"].tolist() == [1.0, 1.0] and time_ratios["sqp"].tolist() == [2.0, float("inf")]
    assert cot_ratios["ipopt"].tolist() == [1.0] and cot_ratios["sqp"].tolist() == [float("inf")]  # not forward 1


def test_the_recorded_solver_table_is_the_rendering_of_the_recorded_results():
    solvers = _solvers_module()
    results = json.loads((BENCHMARKS / "results" / "solvers.json").read_text())
    assert solvers.markdown(results) == (BENCHMARKS / "results" / "solvers.md").read_text()


def test_every_mutant_of_the_mutation_check_names_text_that_occurs_once_in_its_file():
    """A mutant whose text the code no longer has (or has twice) would test nothing: the list must follow the code."""
    mutation = _benchmark("mutation")
    root = BENCHMARKS.parent
    names = [mutant.name for mutant in mutation.MUTANTS]
    assert len(set(names)) == len(names)
    for mutant in mutation.MUTANTS:
        text = (root / mutant.path).read_text()
        assert text.count(mutant.original) == 1, mutant.name
        assert mutant.replacement != mutant.original
    assert all((root / test).is_file() for test in mutation.FAST_TESTS)


def _sweep_store(path, commits):
    """A store of two runs of suite ``s``: r1 finished after an hour, r2 stopped (no end) after its last case; one
    complete verified case per commit in ``commits``, the first by r1, the rest by r2."""
    from gaitbench.run.store import ResultStore

    with ResultStore.create(path) as store:
        store.add_run({"run_id": "r1", "suite": "s", "cases_total": len(commits), "jobs": 2,
                       "started_at": "2026-01-01T00:00:00+00:00", "finished_at": "2026-01-01T01:00:00+00:00"})
        store.add_run({"run_id": "r2", "suite": "s", "cases_total": len(commits), "jobs": 2,
                       "started_at": "2026-01-02T00:00:00+00:00", "heartbeat_at": "2026-01-02T00:10:00+00:00"})
        for i, commit in enumerate(commits):
            store.record_case({"case_key": f"{i:016x}", "suite": "s", "run_id": "r1" if i == 0 else "r2",
                               "experiment": "forward", "method": "m", "N": 10 * (i + 1), "experiment_options": {},
                               "steps": 11, "transcription": "dmoc", "solver": "ipopt", "strategy": "one-phase",
                               "repetition": 0, "message": "",
                               "status": "solved", "stop_cause": "complete", "verified": i % 2 == 0,
                               "wall_time_s": 100.0, "provenance": {"git_commit": commit, "cpu": "x", "cpus": 2},
                               "finished_at": f"2026-01-0{1 + min(i, 1)}T00:{20 * i:02d}:00+00:00"})


def test_a_sweep_over_sessions_adds_its_runs_spans_and_is_recorded_only_whole_on_one_commit(tmp_path):
    module = _benchmark("sweep_record")
    _sweep_store(tmp_path / "one", ["a" * 40] * 3)
    row = module.sweep_record(tmp_path / "one")
    # r1 ended at its finished_at (3,600 s); r2 has no end: its last case (00:40) is later than its heartbeat
    assert row["wall_s"] == 3600 + 2400
    assert (row["cases"], row["complete"], row["verified"], row["case_time_s"]) == (3, 3, 2, 300.0)
    assert row["one_clean_commit"] and [run["cases_done"] for run in row["runs"]] == [1, 2]
    performance = tmp_path / "performance.json"
    performance.write_text(json.dumps({"steps": [], "sweeps": [{"suite": "s", "wall_s": 1}]}))
    with pytest.raises(SystemExit, match="name the suite file"):
        module.record(row, performance)  # without its suite, "every case stored" is the runs' word only
    row |= {"checked_against_suite": True}
    module.record(row, performance)
    assert json.loads(performance.read_text())["sweeps"] == [json.loads(json.dumps(row))]

    _sweep_store(tmp_path / "two", ["a" * 40, "b" * 40, "a" * 40])
    mixed = module.sweep_record(tmp_path / "two") | {"checked_against_suite": True}
    assert not mixed["one_clean_commit"]
    with pytest.raises(SystemExit, match="ran on a{40}, b{40}"):
        module.record(mixed, performance)
    with pytest.raises(SystemExit, match="3 of 4 cases stored"):
        module.record(row | {"cases_total": 4}, performance)


def test_runs_at_the_same_time_are_counted_once_and_a_suite_file_says_which_cases_the_sweep_needs(tmp_path):
    """A column run beside the main run (another machine, merged in) overlaps it: the sweep's wall time is the time
    during which any run ran. With --suite, the cases are that suite's, all of which --record needs."""
    from gaitbench.run.store import ResultStore

    module = _benchmark("sweep_record")
    _sweep_store(tmp_path / "store", ["a" * 40] * 3)
    with ResultStore.create(tmp_path / "store") as store:  # from 00:30 on day 1, half an hour past r1's end
        store.add_run({"run_id": "r3", "suite": "s", "cases_total": 3, "jobs": 1, "host": "elsewhere",
                       "started_at": "2026-01-01T00:30:00+00:00", "finished_at": "2026-01-01T01:30:00+00:00"})
    row = module.sweep_record(tmp_path / "store")
    assert row["wall_s"] == 5400 + 2400  # day 1: 00:00 to 01:30 once, not 3,600 + 3,600
    assert "elsewhere" in row["hosts"]
    suite = tmp_path / "s.toml"
    suite.write_text('[suite]\nname = "s"\n[sweep]\nexperiments = ["forward"]\nN = [10]\n'
                     'transcriptions = ["dmoc"]\nsolvers = ["ipopt"]\nstrategies = ["one-phase"]\n')
    against = module.sweep_record(tmp_path / "store", suite)
    assert (against["cases_total"], against["cases"]) == (1, 0)  # its one case is not among the hand-made ones
    with pytest.raises(SystemExit, match="0 of 1 cases stored"):
        module.record(against, tmp_path / "performance.json")


def test_a_sweep_s_progress_is_measured_by_an_earlier_sweep_s_case_times(tmp_path):
    module = _benchmark("sweep_record")
    _sweep_store(tmp_path / "earlier", ["a" * 40] * 4)  # N = 10 … 40, 100 s each
    _sweep_store(tmp_path / "now", ["b" * 40] * 2)  # N = 10, 20 done
    from gaitbench.run.store import ResultStore

    with ResultStore.create(tmp_path / "earlier") as store:  # the earlier N = 40 took 500 s: 800 s in all
        store.update_cases({"0000000000000003": {"wall_time_s": 500.0}})
    row = module.sweep_record(tmp_path / "now")
    progress = module.progress_against(row, tmp_path / "now", tmp_path / "earlier")
    assert (progress["cases_matched"], progress["work_done_share"], progress["case_time_ratio"]) == (2, 0.25, 1.0)
    assert progress["projected_case_time_s"] == 800
    assert progress["projected_wall_s"] == 800 * 4800 / 200  # 200 s of case time in 3,600 + 1,200 s of wall time
    with ResultStore.create(tmp_path / "now") as store:  # a crashed case is no work done
        store.update_cases({"0000000000000001": {"status": "crashed"}})
    assert module.progress_against(row, tmp_path / "now", tmp_path / "earlier")["cases_matched"] == 1
    _sweep_store(tmp_path / "other", ["a" * 40])
    with ResultStore.create(tmp_path / "other") as store:
        store.update_cases({"0000000000000000": {"method": "another"}})
    with pytest.raises(SystemExit, match="none of its cases"):
        module.progress_against(row, tmp_path / "now", tmp_path / "other")


def test_the_start_sample_pairs_each_method_with_its_blended_twin_on_verified_figures(tmp_path):
    from gaitbench.run.store import ResultStore

    module = _benchmark("start_sample")
    rows = [("OP-DC", 0.28, True), ("OP-DC blended", 0.30, True), ("OP-DM", 0.35, False), ("OP-DM blended", 0.40, True)]
    with ResultStore.create(tmp_path / "store") as store:
        store.add_run({"run_id": "r1", "suite": "start-sample", "started_at": "2026-01-01T00:00:00+00:00"})
        for i, (method, acot, verified) in enumerate(rows):
            store.record_case({"case_key": f"{i:016x}", "suite": "start-sample", "run_id": "r1", "experiment": "stairs",
                               "method": method, "N": 60, "experiment_options": {}, "steps": 11,
                               "transcription": "dmoc", "solver": "ipopt", "strategy": "one-phase", "repetition": 0,
                               "message": "", "status": "solved", "stop_cause": "complete", "acot": acot,
                               "verified": verified, "wall_time_s": 10.0 * (i + 1)})
    pairs = module.paired(tmp_path / "store").set_index("method")
    assert list(pairs.index) == ["OP-DC", "OP-DM"]
    assert pairs.loc["OP-DC", "change"] == pytest.approx(0.28 / 0.30 - 1)
    assert not pairs.loc["OP-DM", "verified_walk_best"]
    assert math.isnan(pairs.loc["OP-DM", "acot_best"]) and math.isnan(pairs.loc["OP-DM", "change"])


def test_a_solver_run_on_few_of_the_problems_is_left_out_of_the_profiles_not_the_problems():
    solvers = _solvers_module()
    rows = [_solve(solver, "forward", step, "converged", 1.0, 1.0) for solver in ("ipopt", "sqp") for step in (1, 2, 6)]
    rows.append(_solve("sqp dense", "forward", 1, "killed", 20.0))  # a variant run on one problem of three
    assert solvers.profiled_solvers(rows) == (["ipopt", "sqp"], ["sqp dense"])
    n_time, _, panels = solvers.profile_ratios(rows)
    assert n_time == 3 and set(next(iter(panels.values()))) == {"ipopt", "sqp"}
    assert "Left out, run on too few of the problems: `sqp dense`." in solvers.profile_section(rows)[0]


def test_the_verification_record_keeps_each_walks_last_verdict_and_checks_joins_and_acot(tmp_path):
    import io

    module = _benchmark("verify_record")

    def verdict(key, strategy="decrease-and-conquer", verified=True, mismatch=0.0, stored=0.30, acot=0.30):
        return json.dumps({"walk": f"store/cases/{key}/walk.json", "experiment": "forward", "strategy": strategy,
                           "transcription": "dmoc", "N": 20, "verified": verified,
                           "reasons": [] if verified else ["step 2: join mismatch 1.0e-02 > 1e-06"],
                           "acot": acot, "stored_acot": stored, "max_join_mismatch": mismatch, "join_energy": 0.0,
                           "steps": [{"index": 1}]})

    record = tmp_path / "verify.jsonl"
    assert module.add(io.StringIO(verdict("a", verified=False, mismatch=1e-2) + "\n" + verdict("b") + "\n"),
                      record) == 2
    assert module.add(io.StringIO(verdict("a") + "\n" + verdict("c", "one-phase", stored=0.31)), record) == 2
    lines = record.read_text().splitlines()
    assert len(lines) == 4 and "steps" not in json.loads(lines[0]) and json.loads(lines[0])["case"] == "a"
    latest = module.latest(record)
    assert sorted(latest) == ["a", "b", "c"] and latest["a"]["verified"]  # its verdict of the later session
    summed = module.summary(latest)
    assert summed["all"]["walks"] == 3 and summed["all"]["verified"] == 3
    assert summed["by_strategy"]["one-phase"]["largest_acot_difference"] == pytest.approx(0.01 / 0.30)
    dc = {case: v for case, v in latest.items() if v["strategy"] == "decrease-and-conquer"}
    assert module.acceptance_failures(dc, joins=True, acot=True) == []
    failures = module.acceptance_failures(latest, joins=True, acot=True)
    assert len(failures) == 1 and failures[0].startswith("c: stored ACOT 0.31")

    from gaitbench.run.store import ResultStore

    store = tmp_path / "store"
    with ResultStore.create(store) as results:
        results.start_run({"run_id": "r1", "suite": "s", "started_at": "now"})
        for key, strategy in (("a", "decrease-and-conquer"), ("b", "decrease-and-conquer"),
                              ("d", "decrease-and-conquer"), ("e", "one-phase")):
            results.record_case({"case_key": key, "run_id": "r1", "experiment": "forward", "N": 20,
                                 "strategy": strategy, "status": "solved", "walk_path": f"cases/{key}/walk.json"},
                                {"walk.json": b"{}"})
    assert module.unrecorded(dc, store, "decrease-and-conquer") == ["d"]  # solved, never verified into the record
    assert module.unrecorded(latest, store, None) == ["d", "e"]

