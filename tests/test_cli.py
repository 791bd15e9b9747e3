"""The command line, driven through click's test runner with fake plugins only."""

from __future__ import annotations

import json
import sys
import types
from pathlib import Path

import pytest
from click.testing import CliRunner
from rich.cells import cell_len
from rich.console import Console

from gaitbench import __version__
from gaitbench.cli.main import main

BROKEN_PLUGIN = "raise ImportError('half-finished plugin')\n"


@pytest.fixture
def invoke():
    def run(*args: str, **kwargs):
        return CliRunner().invoke(main, list(args), **kwargs)

    return run


def test_plugins_json_lists_every_plugin_with_the_required_keys(invoke, fake_entry_points, experiment_plugin):
    fake_entry_points("ep_walks", experiment_plugin("flat", "hill"))
    fake_entry_points("ep_broken", BROKEN_PLUGIN)

    result = invoke("plugins", "--json")

    assert result.exit_code == 0, result.output
    rows = json.loads(result.stdout)  # problems must not leak into stdout
    assert rows == [
        {"kind": "experiment", "name": "flat", "module": "ep_walks", "description": "test experiment flat"},
        {"kind": "experiment", "name": "hill", "module": "ep_walks", "description": "test experiment hill"},
    ]
    assert "warning: entry point 'ep_broken' (ep_broken)" in result.stderr
    assert "half-finished plugin" in result.stderr


def test_plugins_dir_adds_a_plugin_visible_in_json(invoke, fake_entry_points, plugin_file, experiment_plugin):
    path = plugin_file("mine", experiment_plugin("my-walk"))

    result = invoke("--plugins-dir", str(path.parent), "plugins", "--json")

    assert result.exit_code == 0, result.output
    assert {"kind": "experiment", "name": "my-walk", "module": str(path.resolve()),
            "description": "test experiment my-walk"} in json.loads(result.stdout)


def test_plugins_kind_filters(invoke, fake_entry_points, experiment_plugin):
    fake_entry_points("ep_walks", experiment_plugin("flat"))

    solvers = json.loads(invoke("plugins", "--kind", "solver", "--json").stdout)
    experiments = json.loads(invoke("plugins", "--kind", "experiment", "--json").stdout)

    assert solvers == []
    assert [row["name"] for row in experiments] == ["flat"]


def test_plugins_table_shows_name_and_description_and_wide_the_module(invoke, fake_entry_points, experiment_plugin):
    fake_entry_points("ep_walks", experiment_plugin("flat"))

    result = invoke("plugins")
    wide = invoke("plugins", "--wide")

    assert result.exit_code == wide.exit_code == 0, result.output
    for text in ("experiment", "flat", "test experiment flat"):
        assert text in result.stdout and text in wide.stdout
    assert "ep_walks" not in result.stdout and "ep_walks" in wide.stdout  # the module: --wide's


def test_missing_plugins_dir_is_a_usage_error_naming_it(invoke, fake_entry_points, tmp_path):
    result = invoke("--plugins-dir", str(tmp_path / "nowhere"), "plugins")

    assert result.exit_code == 2
    assert "nowhere" in result.stderr


def test_experiments_list(invoke, fake_entry_points, experiment_plugin):
    fake_entry_points("ep_walks", experiment_plugin("flat", "hill"))

    result = invoke("experiments", "list")

    assert result.exit_code == 0, result.output
    assert "flat" in result.stdout and "test experiment hill" in result.stdout


def test_unknown_experiment_exits_2_listing_the_available_ones(
    invoke, fake_entry_points, plugin_file, experiment_plugin
):
    path = plugin_file("walks", experiment_plugin("flat", "hill"))

    result = invoke("--plugins-dir", str(path.parent), "experiments", "show", "fwd")

    assert result.exit_code == 2
    assert "unknown experiment 'fwd'; available: flat, hill" in result.output
    assert "Traceback" not in result.output
    assert isinstance(result.exception, SystemExit)


def test_a_solver_that_raises_stops_solve_with_one_line_naming_where(invoke, plugin_file):
    path = plugin_file("raiser", """
        from gaitbench import Registration, hookimpl

        class Raiser:
            name = "raiser"

            def solve(self, nlp, parameters, initial_guess):
                raise RuntimeError("solver plugin exploded")

        @hookimpl
        def register_solvers():
            return [Registration("raiser", "raises in solve", Raiser)]
    """)
    result = invoke("--plugins-dir", str(path.parent), "solve", "-e", "forward", "-s", "raiser", "--N", "5",
                    "--steps", "1")
    assert result.exit_code == 1 and "Traceback" not in result.output
    assert "RuntimeError: solver plugin exploded (at raiser.py:" in result.output


def test_show_renders_the_experiment_built_by_the_plugin(
    invoke, fake_entry_points, plugin_file, experiment_plugin, monkeypatch
):
    path = plugin_file("walks", experiment_plugin("flat"))
    rendered = []
    fake_module = types.ModuleType("gaitbench.model.experiment")
    fake_module.render_experiment = lambda experiment, console: rendered.append((experiment, console))
    monkeypatch.setitem(sys.modules, "gaitbench.model.experiment", fake_module)

    result = invoke("--plugins-dir", str(path.parent), "experiments", "show", "flat")

    assert result.exit_code == 0, result.output
    [(experiment, console)] = rendered
    assert experiment == "flat"  # what the fake plugin's factory returns
    assert isinstance(console, Console)


def test_invalid_experiment_exits_1_with_the_message(invoke, fake_entry_points, plugin_file):
    path = plugin_file(
        "bad",
        """
        from gaitbench import Registration, hookimpl
        from gaitbench.model.robot import RobotParameters

        @hookimpl
        def register_experiments():
            build = lambda: RobotParameters(m1=1, m2=1, M=1, l=-1, a=0.5)  # raises InvalidParameterError
            return [Registration("bad", "negative leg", build)]
        """,
    )

    result = invoke("--plugins-dir", str(path.parent), "experiments", "show", "bad")

    assert result.exit_code == 1
    assert "leg length must be positive" in result.stderr
    assert "Traceback" not in result.output


def test_help_and_version_do_not_load_plugins(invoke, fake_entry_points):
    fake_entry_points("ep_broken", BROKEN_PLUGIN)

    for args in (["--help"], ["plugins", "-h"], ["experiments", "--help"], ["experiments", "show", "--help"],
                 ["solve", "--help"]):
        result = invoke(*args)
        assert result.exit_code == 0, args
        assert "Usage:" in result.stdout
        assert "warning" not in result.stderr
    version = invoke("--version")
    assert version.exit_code == 0 and __version__ in version.stdout


# solve -p: the gait-problem options


def test_solve_help_lists_every_problem_option_and_its_values(invoke):
    from gaitbench.problem.gait_problem import OPTION_CHOICES
    from gaitbench.run.suite_schema import problem_option_kinds

    result = invoke("solve", "--help")
    assert result.exit_code == 0
    listed = result.stdout.split("Problem options (-p KEY=VALUE")[1]
    for name in problem_option_kinds():
        assert f"\n  {name} " in listed, name
    for name, choices in OPTION_CHOICES.items():
        line = next(line for line in listed.splitlines() if line.startswith(f"  {name} "))
        assert all(f"'{choice}'" in line for choice in choices), line
    assert "true or false (default true)" in listed  # lift_off


@pytest.mark.parametrize(
    ("args", "expected"),
    [
        (["-p", "clearance=of"], "clearance: expected 'terrain', 'chord' or 'off', found a string 'of'"),
        (["-p", "angle_bounds=box"], "angle_bounds: expected 'physical' or 'thesis', found a string 'box'"),
        (["-p", "start_pose=standing"], "start_pose: expected 'on-ground' or 'printed'"),
        (["-p", "absolute_value=abs"], "absolute_value: expected 'slack' or 'smooth'"),
        (["-p", "lift_off=1"], "lift_off: expected true or false, found an integer (1)"),
        (["-p", "lift-off=yes"], "lift_off: expected true or false, found a string 'yes'"),
        (["-p", "friction_coefficient=-0.5"], "friction_coefficient: expected a non-negative number, found a float"),
        (["-p", "torque_regularization=much"], "torque_regularization: expected a non-negative number"),
        (["-p", "clearnce=off"], "unknown key 'clearnce' (did you mean 'clearance'?); allowed: absolute_value"),
        (["-p", "limits=1"], "unknown key 'limits'"),
        (["-p", "clearance"], "'clearance' is not KEY=VALUE"),
        (["-p", "absolute_value=smooth", "--abs", "slack"], "absolute_value is given twice"),
    ],
)
def test_bad_problem_options_are_usage_errors_naming_the_key_and_the_allowed_values(invoke, args, expected):
    result = invoke("solve", "-e", "forward", *args)
    assert result.exit_code == 2
    assert "--problem-option" in result.stderr
    assert expected in " ".join(result.stderr.split()), result.stderr
    assert "Traceback" not in result.output


def test_problem_options_reach_the_walk_and_its_json(invoke, tmp_path):
    out = tmp_path / "walk.json"
    result = invoke("solve", "-e", "forward", "-t", "dmoc", "--N", "8", "--steps", "1", "-p", "clearance=chord",
                    "-p", "lift-off=false", "-p", "friction_coefficient=2", "--problem-option", "approach_rate=0.01",
                    "--abs", "slack", "--torque-regularization", "0.001", "--out", str(out))
    assert result.exit_code == 0, result.output
    options = json.loads(out.read_text())["problem_options"]
    assert {key: options[key] for key in ("clearance", "lift_off", "friction_coefficient", "approach_rate",
                                          "absolute_value", "torque_regularization", "start_pose")} == {
        "clearance": "chord", "lift_off": False, "friction_coefficient": 2, "approach_rate": 0.01,
        "absolute_value": "slack", "torque_regularization": 0.001, "start_pose": "on-ground"}
    assert options["limits"]["tau_max"] > 0  # the experiment's limits, recorded with the options


def test_compass_gait_optimum_with_scuffing_allowed_is_the_passive_gait(invoke, tmp_path):
    """The passive walker needs no energy, so the optimizer must find (close to) zero, with no tie-break, once the
    cost integrates the interpolant's own power (docs/deviations.md, Compass gait)."""
    out = tmp_path / "compass.json"
    result = invoke("solve", "-e", "compass-gait", "-t", "dmoc", "--N", "40", "--steps", "2",
                    "-p", "clearance=off", "--out", str(out))
    assert result.exit_code == 0, result.output
    data = json.loads(out.read_text())
    assert data["complete"] and data["acot"] < 1e-3
    assert all(step["push_off_impulse"] < 0.01 for step in data["steps"])


def test_hermite_simpson_finds_the_passive_gait_with_booles_rule_and_not_with_simpsons():
    """HS with the thesis's Simpson rule sees the power only at nodes and midpoints: the optimizer ends at torques whose
    power vanishes there (objective COT ~1e-4, verified 0.0045). Boole's rule on the interpolant's power finds the
    passive gait (measured 1.9e-9)."""
    from gaitbench.contracts import WalkProblem
    from gaitbench.plugins import load_registry
    from gaitbench.problem.gait_problem import ProblemOptions
    from gaitbench.solve.one_phase import OnePhase
    from gaitbench_plugins.solvers.ipopt import Ipopt
    from gaitbench_plugins.transcriptions.hermite_simpson import HermiteSimpson

    experiment = load_registry().create("experiment", "compass-gait")
    options = ProblemOptions(limits=experiment.limits, clearance="off")
    acots = {rule: OnePhase().solve(WalkProblem(experiment, HermiteSimpson(quadrature=rule), Ipopt(), 40, steps=2,
                                                options=options)).acot for rule in ("boole", "simpson")}
    assert acots["boole"] < 1e-3 < acots["simpson"]
    assert HermiteSimpson().quadrature == "boole"  # the default passes the check


# the spinner of solve


def test_the_solve_spinner_counts_the_steps_and_ends_on_the_walk(invoke, monkeypatch):
    """It used to end on "solving step 4 of 3": the step after the last."""
    from contextlib import contextmanager

    from gaitbench.cli import solve_command as cli

    shown = []

    class Status:
        def update(self, message):
            shown.append(message)

    @contextmanager
    def status(self, message, **kwargs):
        shown.append(message)
        yield Status()

    monkeypatch.setattr(cli.Console, "status", status)
    result = invoke("solve", "-e", "forward", "--N", "8", "--steps", "2")
    assert result.exit_code == 0, result.output
    assert shown == ["solving step 1 of 2", "solving step 2 of 2", "all 2 steps solved"]
    failed = types.SimpleNamespace(solved=False, index=2)
    assert cli.step_status(failed, 3) == "step 2 of 3 not solved: the walk stops"


# runs show at 80 columns


@pytest.fixture
def long_labelled_store(tmp_path):
    """Cases with the long default method labels, every kind of ending and a long message."""
    from gaitbench.run.store import ResultStore

    base = {"suite": "s", "run_id": "r1", "experiment_options": {}, "steps": 11, "transcription": "hermite-simpson",
            "solver": "ipopt", "strategy": "decrease-and-conquer", "repetition": 0, "wall_time_s": 123.4,
            "iterations": 4321, "retries": 2, "message": ""}
    rows = [
        {"experiment": "downward-slope", "method": "decrease-and-conquer hermite-simpson ipopt", "N": 200,
         "status": "solved", "stop_cause": "complete", "acot": 0.123456, "claimed_acot": 0.1,
         "verified": True},
        {"experiment": "upward-slope", "method": "one-phase hermite-simpson ipopt", "N": 110, "status": "incomplete",
         "stop_cause": "verification", "stop_step": 7, "stop_status": "converged",
         "message": "step 7: dynamics residual 3.2e-01 above the tolerance after 3 retries " * 2},
        {"experiment": "stairs", "method": "one-phase dmoc reference solver", "N": 20, "status": "timeout",
         "stop_cause": "time_limit", "message": "ran past 1.25 × its time limit"},
    ]
    with ResultStore.create(tmp_path / "store") as store:
        store.start_run({"run_id": "r1", "suite": "s", "started_at": "2026-01-01T00:00:00+00:00"})
        for i, row in enumerate(rows):
            store.record_case(base | row | {"case_key": f"{i:016x}"})
    return tmp_path / "store"


def test_runs_show_marks_an_unverified_walks_acot_and_refuses_a_filter_that_names_nothing(invoke, tmp_path):
    """An unverified walk's ACOT looked like a verified one's; a misspelt --method gave an empty table, read as "no
    such cases"."""
    from gaitbench.run.store import ResultStore

    with ResultStore.create(tmp_path / "store") as store:
        store.start_run({"run_id": "r1", "suite": "s", "started_at": "2026-01-01T00:00:00+00:00"})
        for key, verified in (("a" * 16, True), ("b" * 16, False)):
            store.record_case({"case_key": key, "run_id": "r1", "experiment": "forward", "N": 10, "method": "OP-DC",
                               "status": "solved", "acot": 0.25, "verified": verified,
                               "verification_failure": None if verified else "step 2: re-simulation error 0.9 > 0.5"})
        store.start_run({"run_id": "r2", "suite": "s", "started_at": "2026-01-02T00:00:00+00:00"})
        store.record_case({"case_key": "c" * 16, "run_id": "r2", "experiment": "stairs", "N": 10, "method": "OP-DC",
                           "status": "incomplete", "message": "step 3: infeasible", "verified": False,
                           "verification_failure": "incomplete walk (step 3: infeasible)"})
    shown = invoke("runs", "show", str(tmp_path / "store"))
    assert shown.exit_code == 0 and "0.2500" in shown.stdout and "(0.2500)" in shown.stdout
    assert "failed verification" in shown.stdout
    incomplete = invoke("runs", "show", str(tmp_path / "store"), "r2", "--wide")  # stored unverified for its stop
    assert "failed verification" not in incomplete.stdout and "not verified" not in incomplete.stdout
    assert invoke("runs", "show", str(tmp_path / "store"), "r2", "--experiment", "forward").exit_code == 0
    wide = invoke("runs", "show", str(tmp_path / "store"), "--wide")
    assert "not verified: step 2: re-simulation error 0.9 > 0.5" in " ".join(wide.stdout.split())
    for option, value in (("--method", "OP-DM"), ("--experiment", "fwd"), ("--status", "solvd")):
        refused = invoke("runs", "show", str(tmp_path / "store"), option, value)
        assert refused.exit_code == 2 and option in refused.stderr, refused.output
    assert "'OP-DC'" in invoke("runs", "show", str(tmp_path / "store"), "--method", "OP-DM").stderr


def test_runs_show_fits_80_columns_with_the_stop_cause(invoke, long_labelled_store, monkeypatch):
    monkeypatch.setenv("COLUMNS", "80")
    result = invoke("runs", "show", str(long_labelled_store))
    assert result.exit_code == 0, result.output
    lines = result.stdout.splitlines()
    assert max(len(line.rstrip()) for line in lines) <= 80, result.stdout
    assert "…" not in result.stdout  # nothing cut short
    text = " ".join(result.stdout.split())
    for expected in ("stop cause", "verification", "time_limit", "complete", "0.1235", "downward-slope",
                     "upward-slope", "decrease-and-conquer", "reference solver"):
        assert expected in text, expected
    assert "claimed" not in text and "message" not in text  # those are --wide's

    wide = invoke("runs", "show", str(long_labelled_store), "--wide")
    assert wide.exit_code == 0, wide.output
    header = next(line for line in wide.stdout.splitlines() if "experiment" in line)
    for column in ("case", "stop step", "stop status", "claimed", "COT min", "retries", "time (s)", "iterations",
                   "message"):
        assert column in header, column
    assert "0000000000000001" in wide.stdout and "dynamics residual 3.2e-01" in wide.stdout


# every table fits 80 columns without cutting a name


def fits_80_columns(output: str) -> None:
    assert max(cell_len(line.rstrip()) for line in output.splitlines()) <= 80, output  # terminal cells
    assert "…" not in output, output  # nothing cut short


def test_plugins_fit_80_columns_without_cutting_a_name(invoke, monkeypatch):
    """The built-in plugins, as a user sees them: "decrease-and-conquer" used to show as "decrease-and-conq…"."""
    monkeypatch.setenv("COLUMNS", "80")
    listed = json.loads(invoke("plugins", "--json").stdout)
    assert "decrease-and-conquer" in {plugin["name"] for plugin in listed}
    result = invoke("plugins")
    assert result.exit_code == 0, result.output
    fits_80_columns(result.stdout)
    tokens = set(result.stdout.split())
    assert {plugin["name"] for plugin in listed} <= tokens and {plugin["kind"] for plugin in listed} <= tokens
    assert "module" not in result.stdout.splitlines()[0]  # --wide's

    wide = invoke("plugins", "--wide")
    assert wide.exit_code == 0, wide.output
    assert "…" not in wide.stdout
    for plugin in listed:
        assert any(plugin["name"] in line and plugin["module"] in line and plugin["description"] in line
                   for line in wide.stdout.splitlines()), plugin


@pytest.fixture
def store_with_runs(tmp_path):
    """Runs as `gaitbench run` names them (time stamp and suite), one whose id does not end with its suite, one
    stopped, and a walk in flight."""
    from gaitbench.run.store import ResultStore

    runs = [("20261203-112256-energetics-sample", "energetics-sample", "2026-12-03T11:48:48+00:00"),
            ("20261202-122118-survey-small-n", "survey-small-n", "2026-12-02T12:44:36+00:00"),
            ("20261205-192450-thesis-all", "thesis-all", None),
            ("merged-by-hand", "thesis-all", "2026-12-06T09:26:21+00:00")]
    with ResultStore.create(tmp_path / "store") as store:
        for run_id, suite, finished in runs:
            started = store.start_run({"run_id": run_id, "suite": suite, "executor": "local", "jobs": 2,
                                       "cases_total": 160, "cases_skipped": 52, "started_at": "2026-12-01T00:00:00"})
            store.finish_run(started, finished) if finished else store.forget_run(started)
    checkpoints = tmp_path / "store" / "checkpoints"
    checkpoints.mkdir()
    (checkpoints / "0123456789abcdef.json").write_text('{"saved": 7, "of": 11, "elapsed_s": 720.0}')
    return tmp_path / "store"


def test_runs_list_fits_80_columns_without_cutting_a_name(invoke, store_with_runs, monkeypatch):
    """Every cell used to be cut at 80 columns ("resu…", "2026…")."""
    monkeypatch.setenv("COLUMNS", "80")
    result = invoke("runs", "list", str(store_with_runs))
    assert result.exit_code == 0, result.output
    fits_80_columns(result.stdout)
    lines = result.stdout.splitlines()
    for run_id in ("20261203-112256-energetics-sample", "20261202-122118-survey-small-n", "merged-by-hand"):
        assert any(line.startswith(run_id + " ") for line in lines), run_id  # whole, on one line
    assert any(line.startswith("suite thesis-all ") for line in lines)  # under the id that does not name it
    assert sum("thesis-all" in line for line in lines) == 2  # the other id names its suite
    assert str(store_with_runs) in "".join(result.stdout.split())  # whole, though folded when over 80 columns
    finished = next(line for line in lines if line.startswith("20261203-112256-energetics-sample"))
    assert finished.split()[1:] == ["160", "0", "0", "52", "2026-12-03", "11:48"]
    assert "not finished" in result.stdout and "fail, skip:" in result.stdout  # the legend of the short headers
    assert "0123456789abcdef" in result.stdout and "7 of 11" in result.stdout and "resumable" in result.stdout

    wide = invoke("runs", "list", "--wide", str(store_with_runs))
    assert wide.exit_code == 0, wide.output
    assert "…" not in wide.stdout
    header = next(line for line in wide.stdout.splitlines() if line.startswith("store"))
    assert header.split() == ["store", "run", "suite", "executor", "jobs", "cases", "done", "failed", "skipped",
                              "finished"]
    assert "2026-12-03T11:48:48+00:00" in wide.stdout


def test_the_solve_table_fits_80_columns_with_the_longest_status_and_the_claim():
    """Decrease and conquer's table has a column more; it used to cut "converg…" and "iterati…"."""
    from gaitbench.cli.solve_command import _print_walk

    steps = []
    for index, status in enumerate(("iteration_limit", "converged", "infeasible"), start=1):
        motion = types.SimpleNamespace(status=status, as_dict=lambda: {
            "cot": 1.2345, "solve_time_s": 1234.56, "iterations": 12345, "max_defect": 1.5e-10, "resim_error": 2e-3})
        steps.append(types.SimpleNamespace(index=index, stance=1 + index % 2, verified=motion,
                                           as_dict=lambda: {"cot": 0.0123}))
    walk = types.SimpleNamespace(experiment="downward-slope", strategy="decrease-and-conquer",
                                 transcription="hermite-simpson", solver="ipopt", N=200, objective="actuator-work",
                                 claimed_acot=0.0123, steps=steps, complete=False, failure="step 3: infeasible",
                                 verification=None, strategy_details={})
    console = Console(width=80, record=True)
    _print_walk(console, walk)
    output = console.export_text()
    fits_80_columns(output)
    for word in ("iteration_limit", "converged", "infeasible", "claimed", "12345", "1234.56", "decrease-and-conquer"):
        assert word in output, word


def test_the_run_summary_fits_80_columns(long_labelled_store):
    from gaitbench.cli.run_commands import _suite_results

    suite = types.SimpleNamespace(name="s", cases=[types.SimpleNamespace(key=f"{i:016x}") for i in range(3)])
    console = Console(width=80, record=True)
    console.print(_suite_results(suite, long_labelled_store))
    output = console.export_text()
    fits_80_columns(output)
    for word in ("downward-slope", "upward-slope", "decrease-and-conquer", "0.1235", "verification (1)",
                 "time_limit (1)"):
        assert word in output, word


# errors: one style, documented exit codes


@pytest.mark.parametrize(
    ("args", "code", "fragment"),
    [
        (["experiments", "show", "nope"], 2, "unknown experiment 'nope'; available:"),
        (["solve", "-e", "nope"], 2, "unknown experiment 'nope'"),
        (["solve", "-e", "forward", "-t", "hermite"], 2, "unknown transcription 'hermite'"),
        (["solve", "-e", "forward", "--steps", "99"], 2, "forward experiment has 11 steps"),
        (["solve", "-e", "forward", "-S", "decrease-and-conquer", "-x", "workers=0"], 2, "workers = 0"),
        # a value the plugin refuses is the options' flag's fault, not the plugin name's
        (["solve", "-e", "energetics", "--experiment-option", "step_length=2.5"], 2, "'--experiment-option'"),
        (["track", "{tmp}/missing.json"], 2, "no such result file"),
        (["track", "{tmp}/walk.json", "--observer", "nope"], 2, None),  # the file is checked first
        (["run", "{tmp}/bad.toml"], 2, "[sweep]: missing required key"),
        (["run", "{tmp}/bad.toml", "--retry-unverified"], 2, "--retry-unverified runs stored cases again, so it "
                                                             "needs --resume"),
        (["report", "{tmp}/nowhere", "--reporter", "nope"], 2, "unknown reporter 'nope'"),
        # flags that would be silently ignored
        (["run", "{tmp}/bad.toml", "--band", "40-90"], 2, "--band sets the consistency check"),
        (["run", "{tmp}/bad.toml", "--scheduler", "tcp://127.0.0.1:1", "--executor", "local"], 2,
         "cannot go with --executor local"),
        (["runs", "show", "{tmp}/nowhere", "--tolerance", "0.2"], 2, "only --inconsistent uses"),
        (["nocommand"], 2, "No such command"),
        (["runs", "show", "{tmp}/nowhere"], 1, "no results store here"),
        (["report", "{tmp}/nowhere"], 1, "no results store here"),
    ],
)
def test_errors_share_one_style_and_the_documented_exit_codes(invoke, tmp_path, args, code, fragment):
    """Usage errors (2): the usage line, then one "Error: ..." line. Failed work (1): the "Error: ..." line alone.
    Never a traceback, nothing on stdout."""
    (tmp_path / "bad.toml").write_text('[suite]\nname = "bad"\n[sweep]\nexperiments = ["forward"]\nN = [8]\n')
    (tmp_path / "walk.json").write_text("{}")
    result = invoke(*(arg.format(tmp=tmp_path) for arg in args))
    assert result.exit_code == code, result.output
    assert result.stdout == "" and "Traceback" not in result.output
    lines = result.stderr.splitlines()
    errors = [line for line in lines if line.startswith("Error: ")]
    assert len(errors) == 1 and not any(line.lower().startswith("error:") for line in lines if line not in errors)
    assert (lines[0].startswith("Usage: ")) == (code == 2), result.stderr
    if fragment:
        assert fragment in errors[0], errors[0]


def test_help_documents_the_exit_codes(invoke):
    result = invoke("--help")
    assert result.exit_code == 0
    text = " ".join(result.stdout.split())
    assert "Exit status:" in text and "0 success" in text
    assert "1 the work failed" in text and "2 usage error" in text
# solve -o / -x: plugin options are checked before anything is solved


@pytest.mark.parametrize(
    ("args", "expected"),
    [
        (["-o", "bogus_option=1"], "Error: Invalid value for '-o' / '--solver-option': solver 'ipopt', option "
                                   "bogus_option: unknown option 'bogus_option'; allowed: max_iterations, "
                                   "time_limit_s, tolerance, print_level, scaling, section_options, or any IPOPT "
                                   "option"),
        (["-o", "max_iterations=many"], "solver 'ipopt', option max_iterations: expected an integer ≥ 1, found a "
                                        "string 'many'"),
        (["-o", "mu_strategy=adaptiv"], "IPOPT rejects mu_strategy = 'adaptiv': it accepts 'monotone' or 'adaptive'"),
        (["-S", "decrease-and-conquer", "-x", "worker=2"],
         "Invalid value for '-x' / '--strategy-option': strategy 'decrease-and-conquer', option worker: unknown "
         "option 'worker' (did you mean 'workers'?)"),
    ],
)
def test_bad_plugin_options_are_refused_before_solving(invoke, args, expected):
    result = invoke("solve", "-e", "forward", "-t", "dmoc", "--N", "8", "--steps", "1", *args)
    assert result.exit_code == 2
    assert expected in " ".join(result.stderr.split()), result.stderr
    assert "Traceback" not in result.output and "ACOT" not in result.stdout


# wording: counts in the right number, no separator left dangling


def test_the_solve_summary_ends_on_its_verdict_and_counts_one_step_in_the_singular():
    from gaitbench.cli.solve_command import _print_walk

    def walk(verification):
        step = types.SimpleNamespace(index=1, stance=1, status="converged")
        step.verified = step  # no claim: the step reports its own motion
        step.as_dict = lambda: {"cot": 0.25, "solve_time_s": 1.5, "iterations": 40, "max_defect": 1e-9,
                                "resim_error": 1e-5}
        return types.SimpleNamespace(experiment="forward", strategy="one-phase", transcription="dmoc", solver="ipopt",
                                     N=10, objective="net-power", claimed_acot=None, steps=[step], complete=True,
                                     acot=0.25, wall_time_s=2.0, verification=verification,
                                     verified=bool(verification and verification.verified))

    def summary(verification) -> str:
        console = Console(width=200, record=True)
        _print_walk(console, walk(verification))
        return next(line for line in console.export_text().splitlines() if "ACOT =" in line)

    passed = types.SimpleNamespace(verified=True, reason="", steps=())
    assert summary(passed) == "verified ACOT = 0.2500 over 1 step (2.0 s)"
    failed = types.SimpleNamespace(verified=False, reason="step 1: defect 1e-2 above 1e-6", steps=())
    assert summary(failed) == "ACOT = 0.2500 over 1 step (2.0 s); NOT verified: step 1: defect 1e-2 above 1e-6"
    assert summary(None) == "ACOT = 0.2500 over 1 step (2.0 s)"  # never called verified unchecked


@pytest.mark.parametrize("command", ["solve", "track"])
def test_an_out_that_would_overwrite_its_own_arrays_or_the_input_is_refused_before_any_work(invoke, tmp_path,
                                                                                            command):
    """The arrays go beside the JSON as .npz: ``--out x.npz`` wrote them and then the JSON over them; ``track
    walk.json --out walk.json`` replaced the walk with its tracking. Both said "wrote" and exited 0."""
    walk = tmp_path / "walk.json"
    walk.write_text("{}")
    head = ["solve", "-e", "forward", "--N", "8", "--steps", "1"] if command == "solve" else ["track", str(walk)]
    (tmp_path / "file").write_text("")
    outs = [tmp_path / "x.npz", tmp_path, tmp_path / "file" / "x.json"]
    outs += [Path("/proc/gaitbench-walk.json")]  # a directory that takes no new file, whatever its permissions say
    if command == "track":
        outs += [walk, tmp_path / "walk.npz", tmp_path / "walk.tracking", tmp_path / "walk"]  # the last two: its .npz
    for out in outs:
        result = invoke(*head, "--out", str(out))
        assert result.exit_code == 2 and "--out" in result.stderr, (out, result.output)
    assert walk.read_text() == "{}"

