"""Suite files: the shipped suites, every validation error, case expansion, and the energetics experiment."""

from __future__ import annotations

import dataclasses
import math
import os
import textwrap
from pathlib import Path

import pytest

from gaitbench.plugins import load_registry
from gaitbench.run.case import TrackingStage
from gaitbench.run.suite import SuiteError, load_suite
from gaitbench_plugins.experiments.energetics import energetics

ROOT = Path(__file__).resolve().parent.parent
SUITES = ROOT / "suites"
REGISTRY = load_registry()

THESIS_METHODS = ("OP-DC", "OP-DM", "D&C-DC", "D&C-DM", "reference")
EXPECTED_CASES = {
    "demo": 4 * 2,  # the four terrains × OP-DC and OP-DM at N = 30: `make run`
    "smoke": 8,  # 1 experiment × 2 N × (2 transcriptions × 1 solver × 2 strategies)
    "thesis-forward": 20 * 5,  # N = 10..200 step 10 × 5 methods
    "thesis-forward-work": 20 * 5,  # the same under actuator-work
    "thesis-downslope": 20 * 5,
    "thesis-upslope": 20 * 5,
    "thesis-stairs": 20 * 5,
    "thesis-all": 4 * 20 * 5,
    # Rm study 6·2·2·5·5 = 600, Rl study 6·2·2·5·5 = 600, minus the 2·2·2·5·5 = 200 bipeds in both.
    "thesis-energetics": 600 + 600 - 200,
}

BASE = """
[suite]
name = "t"

[sweep]
experiments = ["forward"]
N = [10, 20]
transcriptions = ["hermite-simpson", "dmoc"]
solvers = ["ipopt"]
strategies = ["one-phase", "decrease-and-conquer"]
"""


def _write(tmp_path: Path, text: str, name: str = "x.toml") -> Path:
    path = tmp_path / name
    path.write_text(textwrap.dedent(text))
    return path


def _load(tmp_path: Path, text: str):
    return load_suite(_write(tmp_path, text), REGISTRY)


def _error(tmp_path: Path, text: str) -> str:
    path = _write(tmp_path, text)
    with pytest.raises(SuiteError) as caught:
        load_suite(path, REGISTRY)
    message = str(caught.value)
    assert message.startswith(f"{path}: "), message
    return message


# The shipped suites


@pytest.mark.parametrize("name", sorted(EXPECTED_CASES))
def test_shipped_suite_loads_with_expected_case_count(name):
    path = SUITES / f"{name}.toml"
    suite = load_suite(path, REGISTRY)
    assert suite.name == name
    assert len(suite.cases) == EXPECTED_CASES[name]
    assert len({case.key for case in suite.cases}) == len(suite.cases)
    assert f"{EXPECTED_CASES[name]} cases" in path.read_text().split("\n[suite]")[0], "header states the count"
    assert suite.output == Path(f"results/{name}")
    for case in suite.cases:  # the reference column's sqp walks, and One Phase from two starts, take longer
        two_starts = case.strategy.options.get("start") == "best"
        expected = 21600 if case.method == "reference" else suite.time_limit_s * (2 if two_starts else 1)
        assert case.time_limit_s == expected, case.method


def test_every_shipped_suite_is_tested():
    assert {path.stem for path in SUITES.glob("*.toml")} == set(EXPECTED_CASES)


@pytest.mark.parametrize("name", ["thesis-forward", "thesis-forward-work", "thesis-downslope", "thesis-upslope",
                                  "thesis-stairs", "thesis-all"])
def test_thesis_suites_have_the_five_methods_over_n_10_to_200(name):
    suite = load_suite(SUITES / f"{name}.toml", REGISTRY)
    assert suite.methods == THESIS_METHODS
    assert sorted({case.n_nodes for case in suite.cases}) == list(range(10, 201, 10))
    reference = [case for case in suite.cases if case.method == "reference"]
    assert {(c.strategy.name, c.transcription.name, c.solver.name) for c in reference} == {
        ("one-phase", "hermite-simpson", "sqp")}
    assert reference[0].solver.options == {}
    starts = {(c.method, c.strategy.options.get("start", "blended")) for c in suite.cases if c.method in
              ("OP-DC", "OP-DM", "reference")}
    assert starts == {("OP-DC", "best"), ("OP-DM", "best"), ("reference", "blended")}
    dc = {(c.strategy.name, c.transcription.name) for c in suite.cases if c.method == "D&C-DM"}
    assert dc == {("decrease-and-conquer", "dmoc")}


def test_shipped_suites_keep_the_file_text():
    suite = load_suite(SUITES / "smoke.toml", REGISTRY)
    assert suite.text == (SUITES / "smoke.toml").read_text()
    assert suite.steps == 2 and suite.path == SUITES / "smoke.toml"


# Validation errors


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ('[suite]\nname = "t\n', ["line 2, column", "TOML syntax error"]),
        ("[sweep]\nN = [10]\n", ["missing required table [suite]"]),
        ('[suite]\ndescription = "d"\n[sweep]\n', ["[suite]: missing required key 'name'"]),
        (BASE.replace('name = "t"', 'name = "Thesis Forward"'), ["[suite].name", "[a-z0-9-]+", "'Thesis Forward'"]),
        (BASE.replace('name = "t"', 'name = "t"\nrepetitions = "2"'),
         ["[suite].repetitions: expected an integer, found a string '2'"]),
        (BASE.replace('name = "t"', 'name = "t"\ntime_limit_s = -1'),
         ["[suite].time_limit_s: expected a positive number, found an integer (-1)"]),
        (BASE.replace('name = "t"', 'name = "t"\nrepetition = 2'),
         ["[suite]: unknown key 'repetition' (did you mean 'repetitions'?); allowed: name, description"]),
        (BASE.replace("solvers =", "solvres ="),
         ["[sweep]: unknown key 'solvres' (did you mean 'solvers'?); allowed: experiments, N, transcriptions"]),
        (BASE + "[sweeps]\n", ["unknown table [sweeps]", "allowed: [suite], [sweep], [[exclude]], [[method]]"]),
        (BASE.replace("N = [10, 20]", "N = [1, 20]"), ["[sweep].N[0]: expected N ≥ 3", "found 1"]),
        (BASE.replace("N = [10, 20]", "N = [10, 20.5]"),
         ["[sweep].N[1]: expected an integer number of nodes per step, found a float (20.5)"]),
        (BASE.replace("N = [10, 20]", "N = 10"),
         ["[sweep].N: expected an array of integers or a table {start, stop, step}, found an integer (10)"]),
        (BASE.replace("N = [10, 20]", "N = { start = 20, stop = 10 }"), ["[sweep].N.stop: expected stop ≥ start"]),
        (BASE.replace("N = [10, 20]", "N = []"), ["[sweep].N: expected a non-empty array"]),
        (BASE.replace('solvers = ["ipopt"]', "solvers = []"),
         ["[sweep].solvers: expected a non-empty array of solvers, found []"]),
        (BASE.replace('solvers = ["ipopt"]', 'solvers = "ipopt"'),
         ["[sweep].solvers: expected an array of solvers, found a string 'ipopt'"]),
        (BASE.replace('solvers = ["ipopt"]', "solvers = [3]"),
         ["[sweep].solvers[0]: expected a plugin name or a table {name, options, grid, label}, found an integer"]),
        (BASE.replace('solvers = ["ipopt"]', 'solvers = [{ name = "ipopt", option = {} }]'),
         ["[sweep].solvers[0]: unknown key 'option' (did you mean 'options'?); allowed: name, options, grid"]),
        (BASE.replace('solvers = ["ipopt"]', 'solvers = ["ipopt", "ipopz"]'),
         ["[sweep].solvers[1]: unknown solver 'ipopz'; available: cyipopt, fatrop", "ipopt", "sqp"]),
        (BASE.replace('["forward"]', '["forwards"]'),
         ["[sweep].experiments[0]: unknown experiment 'forwards'; available:", "downward-slope", "forward"]),
        (BASE.replace('"one-phase", "decrease', '{ name = "one-phase", options = { phase = "third" } }, "decrease'),
         ["[sweep].strategies[0]: cannot build strategy 'one-phase' with phase='third'", "expected 'first'"]),
        (BASE.replace('"one-phase", "decrease', '{ name = "one-phase", options = { bogus = 1 } }, "decrease'),
         ["[sweep].strategies[0].options.bogus: strategy 'one-phase': unknown option 'bogus'; allowed: phase"]),
        (BASE.replace('["forward"]', '[{ name = "forward", options = { speed = 1 } }]'),
         ["[sweep].experiments[0].options.speed: experiment 'forward': unknown option 'speed'; it takes no options"]),
        (BASE.replace('name = "t"', 'name = "t"\nsteps = 12'),
         ["[suite].steps: steps = 12 exceeds the 11 steps of experiment 'forward'"]),
        (BASE.replace('name = "t"', 'name = "t"\nproblem_options = { absolute_valu = "smooth" }'),
         ["[suite].problem_options: unknown key 'absolute_valu' (did you mean 'absolute_value'?)",
          "smoothing_eps"]),
        (BASE.replace('name = "t"', 'name = "t"\nproblem_options = { limits = 1 }'),
         ["[suite].problem_options: unknown key 'limits'"]),
        (BASE.replace('name = "t"', 'name = "t"\nproblem_options = { absolute_value = "abs" }'),
         ["[suite].problem_options.absolute_value: expected 'slack' or 'smooth', found a string 'abs'"]),
        (BASE.replace('name = "t"', 'name = "t"\nproblem_options = { unilateral_contact = 1 }'),
         ["[suite].problem_options.unilateral_contact: expected true or false, found an integer (1)"]),
        (BASE.replace('name = "t"', 'name = "t"\nproblem_options = { clearance = "of" }'),
         ["[suite].problem_options.clearance: expected 'terrain', 'chord' or 'off', found a string 'of'"]),
        (BASE.replace('name = "t"', 'name = "t"\nproblem_options = { angle_bounds = "printed" }'),
         ["[suite].problem_options.angle_bounds: expected 'physical' or 'thesis', found a string 'printed'"]),
        (BASE.replace('name = "t"', 'name = "t"\nproblem_options = { start_pose = 1 }'),
         ["[suite].problem_options.start_pose: expected 'on-ground' or 'printed', found an integer (1)"]),
        (BASE.replace('name = "t"', 'name = "t"\nproblem_options = { lift_off = "no" }'),
         ["[suite].problem_options.lift_off: expected true or false, found a string 'no'"]),
        (BASE.replace('name = "t"', 'name = "t"\nproblem_options = { lift_off_rate = -0.1 }'),
         ["[suite].problem_options.lift_off_rate: expected a non-negative number, found a float (-0.1)"]),
        (BASE.replace('name = "t"', 'name = "t"\nproblem_options = { friction_coefficient = true }'),
         ["[suite].problem_options.friction_coefficient: expected a non-negative number, found a boolean (true)"]),
        (BASE.replace('name = "t"', 'name = "t"\nproblem_options = { friction_coefficient = "0.8" }'),
         ["[suite].problem_options.friction_coefficient: expected a non-negative number, found a string '0.8'"]),
        (BASE.replace('name = "t"', 'name = "t"\nplugins = ["no-such-dir"]'),
         ["[suite].plugins[0]: plugin directory 'no-such-dir'", "does not exist"]),
        (BASE + '[[exclude]]\nsolver = "ipopz"\n', ["[[exclude]][0].solver: 'ipopz' matches no case (a typo?)"]),
        (BASE + '[[exclude]]\ntranscription = ["dmoc", "dmco"]\n',  # one typo in an array is caught too
         ["[[exclude]][0].transcription: 'dmco' matches no case (a typo?)"]),
        (BASE + "[[exclude]]\nN = [10, 30]\nstrategy = 'warm-start'\n", ["[[exclude]][0].N: 30 matches no case"]),
        (BASE + '[[exclude]]\nsolvers = "ipopt"\n',
         ["[[exclude]][0]: unknown key 'solvers' (did you mean 'solver'?); allowed: experiment, N"]),
        (BASE + "[[exclude]]\nN = '10'\n", ["[[exclude]][0].N: expected an integer N or an array of them"]),
        (BASE + "[[exclude]]\n", ["[[exclude]][0]: an exclusion needs at least one key"]),
        (BASE + '[[exclude]]\nsolver = "ipopt"\n', ["[[exclude]]: the exclusions drop all 8 cases"]),
        (BASE + '[method]\nlabel = "x"\n', ["[[method]]: expected an array of tables ([[method]] headers)"]),
        (BASE + '[[method]]\nlabel = "x"\ntranscription = "dmoc"\nsolver = "ipopt"\nstrategy = "one-phase"\n',
         ["[sweep].transcriptions: give either [[method]] tables or the [sweep] lists"]),
        (BASE.split("transcriptions")[0] + '[[method]]\nlabel = "x"\ntranscription = "dmoc"\nsolver = "ipopt"\n',
         ["[[method]][0]: missing required key 'strategy'"]),
        (BASE.split("transcriptions")[0] + ('[[method]]\nlabel = "x"\ntranscription = "dmoc"\nsolver = "ipopt"\n'
                                            'strategy = "one-phase"\n') * 2,
         ["[[method]][1]: method label 'x' is used twice"]),
        (BASE.split("transcriptions")[0] + ('[[method]]\nlabel = "a"\ntranscription = "dmoc"\nsolver = "ipopt"\n'
                                            'strategy = "one-phase"\n[[method]]\nlabel = "b"\n'
                                            'transcription = "dmoc"\nsolver = "ipopt"\nstrategy = "one-phase"\n'),
         ["methods 'a' and 'b' are the same transcription, solver and strategy"]),
        (BASE.replace('solvers = ["ipopt"]', 'solvers = ["ipopt", "ipopt"]'),
         ["[sweep].solvers[1]: the same entry as [sweep].solvers[0]"]),
        (BASE.replace('solvers = ["ipopt"]', 'solvers = [{ name = "ipopt", grid = { tolerance = [] } }]'),
         ["[sweep].solvers[0].grid.tolerance: expected a non-empty array of values, found []"]),
        (BASE.replace('solvers = ["ipopt"]',
                      'solvers = [{ name = "ipopt", options = { tolerance = 1 }, grid = { tolerance = [2] } }]'),
         ["[sweep].solvers[0].grid.tolerance: 'tolerance' is given both in options and in grid"]),
        (BASE + "[tracking]\ncontroler = 'thesis'\n",
         ["[tracking]: unknown key 'controler' (did you mean 'controller'?)"]),
    ],
)
def test_validation_errors_name_the_file_the_key_and_the_fix(tmp_path, text, expected):
    message = _error(tmp_path, text)
    for fragment in expected:
        assert fragment in message, f"{fragment!r} not in {message!r}"


def _solver(entry: str) -> str:
    return BASE.replace('solvers = ["ipopt"]', f"solvers = [{entry}]")


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        (_solver('{ name = "ipopt", options = { bogus_option = 1 } }'),
         ["[sweep].solvers[0].options.bogus_option: solver 'ipopt': unknown option 'bogus_option'; allowed: "
          "max_iterations, time_limit_s, tolerance, print_level, scaling, section_options, or any IPOPT option"]),
        (_solver('{ name = "ipopt", options = { mu_stratgy = "adaptive" } }'),
         ["[sweep].solvers[0].options.mu_stratgy: solver 'ipopt': unknown option 'mu_stratgy' (did you mean "
          "'mu_strategy'"]),
        (_solver('{ name = "ipopt", options = { max_iterations = "many" } }'),
         ["[sweep].solvers[0].options.max_iterations: solver 'ipopt': expected an integer ≥ 1, found a string "
          "'many'"]),
        (_solver('{ name = "ipopt", grid = { max_iterations = [100, 0] } }'),
         ["[sweep].solvers[0].grid.max_iterations: solver 'ipopt': expected an integer ≥ 1, found an integer (0)"]),
        (_solver('{ name = "ipopt", options = { tolerance = 0 } }'),
         ["[sweep].solvers[0].options.tolerance: solver 'ipopt': expected a number > 0, found an integer (0)"]),
        (_solver('{ name = "ipopt", options = { time_limit_s = "1h" } }'),
         ["[sweep].solvers[0].options.time_limit_s: solver 'ipopt': expected a number > 0"]),
        (_solver('{ name = "ipopt", options = { print_level = 1.5 } }'),
         ["[sweep].solvers[0].options.print_level: solver 'ipopt': expected an integer ≥ 0, found a float (1.5)"]),
        (_solver('{ name = "ipopt", options = { max_iter = "many" } }'),
         ["[sweep].solvers[0].options.max_iter: solver 'ipopt': IPOPT's max_iter is integer: expected an integer"]),
        (_solver('{ name = "ipopt", options = { tol = -1 } }'),
         ["[sweep].solvers[0].options.tol: solver 'ipopt': IPOPT rejects tol = -1: it accepts 0 < tol"]),
        (_solver('{ name = "ipopt", options = { mu_strategy = "adaptiv" } }'),
         ["[sweep].solvers[0].options.mu_strategy: solver 'ipopt': IPOPT rejects mu_strategy = 'adaptiv': it "
          "accepts 'monotone' or 'adaptive'"]),
        (_solver('{ name = "ipopt", options = { scaling = "nominl" } }'),
         ["[sweep].solvers[0].options.scaling: solver 'ipopt': expected one of none, nominal"]),
        (_solver('{ name = "cyipopt", options = { bogus_option = 1 } }'),
         ["[sweep].solvers[0].options.bogus_option: solver 'cyipopt': unknown option 'bogus_option'", "IPOPT"]),
        (_solver('{ name = "cyipopt", options = { mu_strategy = "adaptiv" } }'),
         ["[sweep].solvers[0].options.mu_strategy: solver 'cyipopt': IPOPT rejects mu_strategy = 'adaptiv'"]),
        (_solver('{ name = "fatrop", options = { mu_inti = 0.1 } }'),
         ["[sweep].solvers[0].options.mu_inti: solver 'fatrop': unknown option 'mu_inti'; allowed: max_iterations",
          "stagewise, or any fatrop option"]),
        (_solver('{ name = "fatrop", options = { convexify_margin = "x" } }'),
         ["[sweep].solvers[0].options.convexify_margin: solver 'fatrop': fatrop takes a number, found a string"]),
        (_solver('{ name = "sqp", options = { qp_solvr = "piqp" } }'),
         ["[sweep].solvers[0].options.qp_solvr: solver 'sqp': unknown option 'qp_solvr' (did you mean "
          "'qp_solver'?); allowed: max_iterations"]),
        (_solver('{ name = "sqp", options = { second_order_correction = "yes" } }'),
         ["[sweep].solvers[0].options.second_order_correction: solver 'sqp': expected true or false, found a "
          "string 'yes'"]),
        (BASE.replace('"one-phase", "decrease', '{ name = "decrease-and-conquer", options = { workers = "two" } }, '
                                               '"decrease'),
         ["[sweep].strategies[0].options.workers: strategy 'decrease-and-conquer': expected an integer or one of "
          "'auto', found a string 'two'"]),
        (BASE.replace('"one-phase", "decrease', '{ name = "decrease-and-conquer", options = { worker = 2 } }, '
                                               '"decrease'),
         ["[sweep].strategies[0].options.worker: strategy 'decrease-and-conquer': unknown option 'worker' (did you "
          "mean 'workers'?); allowed: polish, sectional_guess, max_checks, workers, rescue"]),
        (BASE + "[tracking]\noptions = { gainz = 3 }\n",
         ["[tracking].options.gainz: unknown option 'gainz'; allowed: controller, observer, disturbance, "
          "sample_rate, steps, fall, rtol, atol"]),
        (BASE + "[tracking]\noptions = { controller = { kpp = 400 } }\n",
         ["[tracking].options.controller.kpp: controller 'thesis': unknown option 'kpp' (did you mean 'kp'?); "
          "allowed: kp, kv, contact_force"]),
        (BASE + "[tracking]\ndisturbance = 'push'\noptions = { disturbance = { force = 'strong' } }\n",
         ["[tracking].options.disturbance.force: disturbance 'push': expected a number, found a string 'strong'"]),
        (BASE + "[tracking]\noptions = { fall = { hip_fraction = 2 } }\n",
         ["[tracking].options.fall: hip_fraction = 2: expected a fraction in [0, 1)"]),
        (BASE + "[tracking]\noptions = { sample_rate = 0 }\n",
         ["[tracking].options.sample_rate: expected a number > 0, found an integer (0)"]),
        # a disturbance that cannot act on an experiment would fail every case after its walk was solved
        (BASE.replace('["forward"]', '[{ name = "energetics" }]') + "[tracking]\ncontroller = 'thesis'\n",
         ["[tracking].disturbance: 'friction' on experiment 'energetics': experiment 'energetics' has no friction "
          "parameters"]),
        (BASE.replace('name = "t"', 'name = "t"\nsteps = 2') + "[tracking]\ndisturbance = 'push'\n"
         "options = { disturbance = { step = 5 } }\n",
         ["[tracking].options.disturbance.step: step = 5: the suite walks 2 steps"]),
    ],
)
def test_options_are_checked_when_the_suite_loads(tmp_path, text, expected):
    message = _error(tmp_path, text)
    for fragment in expected:
        assert fragment in message, f"{fragment!r} not in {message!r}"


def test_options_the_plugins_accept_load(tmp_path):
    text = _solver('{ name = "ipopt", options = { linear_solver = "mumps", mu_strategy = "adaptive", '
                   'acceptable_tol = 1e-6, max_iterations = 500, time_limit_s = 60, print_level = 0, '
                   'section_options = { nlp_scaling_obj_target_gradient = 1 } } }, '
                   '{ name = "cyipopt", options = { tol = 1 } }, '
                   '{ name = "fatrop", options = { convexify_margin = 1e-3 } }')
    text += ("[tracking]\noptions = { controller = { kp = [900, 400] }, sample_rate = 1000, "
             "fall = { hip_fraction = 0.4 } }\n")
    assert len(_load(tmp_path, text).cases) == 2 * 3 * 2 * 2


def test_a_plugin_s_own_check_options_hook_is_asked_at_load(tmp_path, plugin_file):
    """A third-party solver that takes ``**options`` checks them itself; the suite names the key it refused."""
    directory = plugin_file("picky", """
        from gaitbench import Registration, hookimpl
        from gaitbench.options import OptionError, unknown_option


        class Picky:
            name = "picky"

            @classmethod
            def check_options(cls, options):
                for key, value in options.items():
                    if key != "depth":
                        raise unknown_option(key, ["depth"])
                    if value not in (1, 2):
                        raise OptionError(key, f"expected 1 or 2, found {value!r}")

            def __init__(self, **options):
                self.options = options


        @hookimpl
        def register_solvers():
            return [Registration("picky", "test solver", Picky)]
        """).parent
    registry = load_registry([directory])
    text = _solver('{ name = "picky", options = { depht = 1 } }')
    with pytest.raises(SuiteError, match=r"\[sweep\]\.solvers\[0\]\.options\.depht: solver 'picky': unknown option "
                                         r"'depht' \(did you mean 'depth'\?\); allowed: depth"):
        load_suite(_write(tmp_path, text), registry)
    with pytest.raises(SuiteError, match=r"solvers\[0\]\.grid\.depth: solver 'picky': expected 1 or 2, found 3"):
        load_suite(_write(tmp_path, _solver('{ name = "picky", grid = { depth = [1, 3] } }')), registry)
    assert len(load_suite(_write(tmp_path, _solver('{ name = "picky", options = { depth = 2 } }')), registry).cases)


def test_energetics_infeasible_grid_value_is_reported(tmp_path):
    text = BASE.replace('["forward"]', '[{ name = "energetics", grid = { step_length = [0.8, 2.5] } }]')
    message = _error(tmp_path, text)
    assert "[sweep].experiments[0]: cannot build experiment 'energetics' with step_length=2.5" in message
    assert "step_length = 2.5" in message


def test_missing_file_is_a_suite_error(tmp_path):
    with pytest.raises(SuiteError, match="cannot read the suite file"):
        load_suite(tmp_path / "absent.toml", REGISTRY)


# Expansion


def test_cases_come_in_file_order_with_defaults(tmp_path):
    suite = _load(tmp_path, BASE)
    assert [(case.n_nodes, case.method) for case in suite.cases[:4]] == [
        (10, "one-phase hermite-simpson ipopt"), (10, "decrease-and-conquer hermite-simpson ipopt"),
        (10, "one-phase dmoc ipopt"), (10, "decrease-and-conquer dmoc ipopt")]
    assert suite.output == Path("results/t") and suite.repetitions == 1 and suite.time_limit_s == 3600
    assert suite.steps is None and suite.tracking is None and suite.plugin_dirs == ()
    assert all(case.time_limit_s == 3600 and case.steps is None for case in suite.cases)


PERMUTABLE = """
[suite]
name = "p"
repetitions = 2
problem_options = { torque_regularization = 0.001, absolute_value = "slack" }

[sweep]
experiments = ["forward", "upward-slope"]
N = [10, 20, 30]
transcriptions = ["hermite-simpson", { name = "dmoc" }]
solvers = [{ name = "ipopt", options = { tolerance = 1e-6, max_iterations = 100 } }, "sqp"]
strategies = ["one-phase", "decrease-and-conquer"]

[[exclude]]
solver = "sqp"
strategy = "decrease-and-conquer"
"""

PERMUTED = """
[[exclude]]
strategy = "decrease-and-conquer"
solver = "sqp"

[sweep]
strategies = ["decrease-and-conquer", "one-phase"]
solvers = ["sqp", { options = { max_iterations = 100, tolerance = 1e-6 }, name = "ipopt" }]
transcriptions = [{ name = "dmoc" }, "hermite-simpson"]
N = [30, 10, 20]
experiments = ["upward-slope", "forward"]

[suite]
problem_options = { absolute_value = "slack", torque_regularization = 0.001 }
repetitions = 2
name = "p"
"""


def test_case_keys_do_not_depend_on_the_order_of_the_file(tmp_path):
    first = load_suite(_write(tmp_path, PERMUTABLE, "a.toml"), REGISTRY)
    second = load_suite(_write(tmp_path, PERMUTED, "b.toml"), REGISTRY)
    assert len(first.cases) == 2 * 3 * (8 - 2) * 2
    keys = [case.key for case in first.cases]
    assert len(set(keys)) == len(keys)
    assert set(keys) == {case.key for case in second.cases}
    assert keys != [case.key for case in second.cases]  # the order follows the file
    assert {case.repetition for case in first.cases} == {0, 1}


def test_exclusions_match_names_labels_lists_and_n(tmp_path):
    text = BASE.replace('solvers = ["ipopt"]', 'solvers = ["ipopt", { name = "sqp", label = "mine" }]')
    assert len(_load(tmp_path, text).cases) == 2 * 2 * 2 * 2
    excluded = _load(tmp_path, text + '[[exclude]]\nsolver = "mine"\nstrategy = "decrease-and-conquer"\n')
    assert len(excluded.cases) == 16 - 4
    assert not any(c.solver.name == "sqp" and c.strategy.name == "decrease-and-conquer" for c in excluded.cases)
    by_n = _load(tmp_path, text + '[[exclude]]\nN = [20]\ntranscription = ["dmoc", "hermite-simpson"]\n')
    assert len(by_n.cases) == 16 - 8
    by_method = _load(tmp_path, text + '[[exclude]]\nmethod = "one-phase dmoc mine"\n'
                                       '[[exclude]]\nexperiment = "forward"\nN = 10\nsolver = "sqp"\n')
    assert {c.method for c in by_method.cases if c.n_nodes == 20} == set(by_method.methods) - {"one-phase dmoc mine"}
    assert len(by_method.cases) == 16 - 2 - 3  # the two overlap in one case


def test_grids_expand_into_one_entry_per_combination(tmp_path):
    text = BASE.replace('solvers = ["ipopt"]', 'solvers = [{ name = "ipopt", options = { print_level = 0 }, '
                                               'grid = { tolerance = [1e-6, 1e-8], max_iterations = [50, 100] } }, '
                                               '{ name = "sqp", label = "s", grid = { hessian = ["exact", "bfgs"] } }]')
    suite = _load(tmp_path, text)
    solvers = {case.solver.describe() for case in suite.cases}
    assert len(solvers) == 4 + 2
    assert "ipopt(max_iterations=50, print_level=0, tolerance=1e-06)" in solvers
    assert "one-phase dmoc s(hessian=bfgs)" in suite.methods
    assert "one-phase dmoc ipopt(max_iterations=100, print_level=0, tolerance=1e-08)" in suite.methods
    assert len(suite.cases) == 2 * 2 * 2 * 6


def test_explicit_methods_carry_their_labels(tmp_path):
    text = BASE.split("transcriptions")[0] + """
        [[method]]
        label = "A"
        transcription = "dmoc"
        solver = { name = "ipopt", options = { tolerance = 1e-6 } }
        strategy = "one-phase"

        [[method]]
        transcription = "hermite-simpson"
        solver = { name = "ipopt", label = "fast", grid = { max_iterations = [10, 20] } }
        strategy = { name = "decrease-and-conquer", options = { polish = false } }

        [[method]]
        label = "G"
        transcription = "hermite-simpson"
        solver = { name = "sqp", grid = { hessian = ["exact", "bfgs"] } }
        strategy = "one-phase"
        """
    suite = _load(tmp_path, textwrap.dedent(text))
    assert suite.methods == (
        "A", "decrease-and-conquer(polish=False) hermite-simpson fast(max_iterations=10)",
        "decrease-and-conquer(polish=False) hermite-simpson fast(max_iterations=20)",
        "G(hessian=exact)", "G(hessian=bfgs)")
    first = suite.cases[0]
    assert (first.method, first.transcription.name, first.solver.options) == ("A", "dmoc", {"tolerance": 1e-6})
    assert len(suite.cases) == 2 * 5


def test_a_method_s_own_time_limit_replaces_the_suite_s_for_its_cases_alone(tmp_path):
    """The reference column's `sqp` walks at N >= 130 outgrow the 2 h that bound the IPOPT methods' cases."""
    text = BASE.split("transcriptions")[0].replace('name = "t"', 'name = "t"\ntime_limit_s = 60') + """
        [[method]]
        label = "fast"
        transcription = "dmoc"
        solver = "ipopt"
        strategy = "one-phase"

        [[method]]
        label = "slow"
        transcription = "hermite-simpson"
        solver = "sqp"
        strategy = "one-phase"
        time_limit_s = 600
        """
    suite = _load(tmp_path, textwrap.dedent(text))
    assert {case.method: case.time_limit_s for case in suite.cases} == {"fast": 60.0, "slow": 600.0}
    bad = textwrap.dedent(text).replace("time_limit_s = 600", "time_limit_s = 0")
    with pytest.raises(SuiteError, match=r"\[\[method\]\]\[1\]\.time_limit_s: expected a positive number"):
        _load(tmp_path, bad)


def test_n_range_is_inclusive(tmp_path):
    suite = _load(tmp_path, BASE.replace("N = [10, 20]", "N = { start = 10, stop = 30, step = 10 }"))
    assert sorted({case.n_nodes for case in suite.cases}) == [10, 20, 30]


def test_every_problem_option_is_accepted_with_an_allowed_value(tmp_path):
    from gaitbench.problem.gait_problem import OPTION_CHOICES, ProblemOptions
    from gaitbench.run.suite_schema import problem_option_kinds

    assert set(problem_option_kinds()) == {f for f in ProblemOptions.__dataclass_fields__ if f != "limits"}
    for name, choices in OPTION_CHOICES.items():
        for choice in choices:
            text = BASE.replace('name = "t"', f'name = "t"\nproblem_options = {{ {name} = "{choice}" }}')
            assert _load(tmp_path, text).cases[0].problem_options == {name: choice}
    overrides = ('{ clearance = "off", lift_off = false, lift_off_rate = 0.01, angle_bounds = "thesis", '
                 'start_pose = "printed", friction_coefficient = 0.8, unilateral_contact = true }')
    case = _load(tmp_path, BASE.replace('name = "t"', f'name = "t"\nproblem_options = {overrides}')).cases[0]
    assert case.problem_options == {"clearance": "off", "lift_off": False, "lift_off_rate": 0.01,
                                    "angle_bounds": "thesis", "start_pose": "printed", "friction_coefficient": 0.8,
                                    "unilateral_contact": True}


def test_suite_settings_reach_every_case(tmp_path):
    text = BASE.replace('name = "t"', 'name = "t"\noutput = "out/here"\ntime_limit_s = 60\nsteps = 3\n'
                                      'problem_options = { absolute_value = "smooth", smoothing_eps = 0.1 }')
    text += '[tracking]\ncontroller = "thesis"\noptions = { controller = { kp = 400 } }\n'
    suite = _load(tmp_path, text)
    assert suite.output == Path("out/here") and suite.steps == 3
    assert suite.tracking == TrackingStage(options={"controller": {"kp": 400}})
    case = suite.cases[0]
    assert (case.steps, case.time_limit_s, case.tracking) == (3, 60.0, suite.tracking)
    assert case.problem_options == {"absolute_value": "smooth", "smoothing_eps": 0.1}
    plain = _load(tmp_path, BASE)
    assert {c.key for c in suite.cases}.isdisjoint({c.key for c in plain.cases})


def test_plugin_directories_are_relative_to_the_suite_file(tmp_path):
    examples = ROOT / "examples" / "plugins"
    relative = os.path.relpath(examples, tmp_path)
    text = BASE.replace('name = "t"', f'name = "t"\nplugins = ["{relative}"]').replace(
        'solvers = ["ipopt"]', 'solvers = ["scipy-trust-constr"]')
    suite = load_suite(_write(tmp_path, text))  # the default registry loads the suite's plugin directory
    assert suite.plugin_dirs == (str(examples.resolve()),)
    assert all(case.plugin_dirs == suite.plugin_dirs for case in suite.cases)
    assert {case.solver.name for case in suite.cases} == {"scipy-trust-constr"}


def test_overlapping_grids_give_each_case_once(tmp_path):
    text = BASE.replace('["forward"]', '[{ name = "energetics", grid = { mass_ratio = [0.2, 0.3] } }, '
                                       '{ name = "energetics", grid = { mass_ratio = [0.3, 0.4] } }]')
    suite = _load(tmp_path, text)
    assert len(suite.cases) == 3 * 2 * 4


# The energetics experiment


def test_energetics_experiment_has_the_requested_ratios_and_a_feasible_walk():
    experiment = energetics(mass_ratio=0.25, length_ratio=0.4, speed=0.6, step_length=1.2, slope=-10, steps=5)
    robot = experiment.robot
    assert robot.m1 == robot.m2 == pytest.approx(0.25 * robot.M)
    assert robot.b / robot.l == pytest.approx(0.4) and robot.l == 1.0
    assert robot.total_mass == pytest.approx(80.0)
    assert experiment.n_steps == 5
    assert experiment.step_duration == pytest.approx(1.2 / (0.6 * math.sqrt(9.81)))
    assert all(check.ok for check in experiment.feasibility())
    q1, q2 = experiment.initial_state[:2]
    theta, alpha = math.radians(-10), math.asin(0.6)
    assert (q1, q2) == (pytest.approx(theta + alpha), pytest.approx(theta - alpha))
    assert experiment.initial_state[4] < 0 and experiment.initial_state[5] < 0
    # The start is the heel-strike configuration of an equal step, legs swapped.
    assert experiment.heel_strike_configuration(2) == (pytest.approx(q1), pytest.approx(q2))


def test_energetics_defaults_are_the_forward_robot():
    robot = energetics().robot
    assert (robot.M, robot.m1, robot.a) == (pytest.approx(40.0), pytest.approx(20.0), pytest.approx(0.5))


@pytest.mark.parametrize(
    ("options", "fragment"),
    [
        ({"mass_ratio": 0}, "mass_ratio = 0: Rm = m_leg / M must be positive"),
        ({"length_ratio": 1.0}, "length_ratio = 1.0: Rl = b / l must lie strictly between 0 and 1"),
        ({"speed": -0.4}, "speed = -0.4: must be positive"),
        ({"step_length": 2.0}, "step_length = 2.0: the chord must lie strictly between 0 and 2 leg lengths"),
        ({"slope": 95}, "slope = 95: expected degrees in (-90, 90)"),
        ({"steps": 0}, "steps = 0: expected a positive integer"),
        ({"speed": "fast"}, "speed = 'fast': expected a finite number"),
        ({"speed": 30.0}, "exceed the velocity limit"),
    ],
)
def test_energetics_rejects_invalid_options_clearly(options, fragment):
    with pytest.raises(ValueError) as caught:
        energetics(**options)
    assert fragment in str(caught.value)


def test_energetics_is_registered():
    experiment = REGISTRY.create("experiment", "energetics", step_length=0.5, steps=2)
    assert experiment.name == "energetics" and experiment.n_steps == 2


def test_thesis_forward_work_is_thesis_forward_under_actuator_work():
    work = load_suite(SUITES / "thesis-forward-work.toml", REGISTRY)
    thesis = load_suite(SUITES / "thesis-forward.toml", REGISTRY)
    assert {case.objective.name for case in work.cases} == {"actuator-work"}
    assert {case.objective.name for case in thesis.cases} == {"net-power"}
    strip = [dataclasses.replace(case, objective=thesis.cases[0].objective) for case in work.cases]
    assert {case.key for case in strip} == {case.key for case in thesis.cases}
    assert not {case.key for case in work.cases} & {case.key for case in thesis.cases}


def test_a_home_relative_output_is_the_home_directory_not_a_directory_named_tilde(tmp_path):
    suite = _load(tmp_path, BASE.replace('name = "t"', 'name = "t"\noutput = "~/gb-results/t"'))
    assert suite.output == Path.home() / "gb-results" / "t"


def test_steps_equal_to_the_whole_walk_are_the_whole_walk(tmp_path):
    """`steps = 11` on an 11-step experiment is the experiment's walk: the same cases, keys and report rows as no
    `steps` (a shortened walk is labelled and kept from the thesis's figures; the whole one must not be)."""
    whole = _load(tmp_path, BASE.replace('name = "t"', 'name = "t"\nsteps = 11'))
    default = load_suite(_write(tmp_path, BASE, "default.toml"), REGISTRY)
    assert [case.key for case in whole.cases] == [case.key for case in default.cases]
    assert {case.steps for case in whole.cases} == {None}
    assert {case.steps for case in _load(tmp_path, BASE.replace('name = "t"', 'name = "t"\nsteps = 2')).cases} == {2}

