"""A walk verified as one motion: thresholds, the join check, the verified flag through the store and reports, and
`gaitbench verify` on walk files."""

import json

import numpy as np
import pandas as pd
import pytest
from click.testing import CliRunner

from gaitbench.acceptance import StepVerification, Thresholds, objective_gap, step_failures
from gaitbench.cli.main import main
from gaitbench.contracts import WalkProblem
from gaitbench.model.mechanics import BipedModel
from gaitbench.plugins import load_registry
from gaitbench.problem.trajectory import nodal_trajectory
from gaitbench.reports.case_frame import NOT_CHECKED, prepare
from gaitbench.reports.tables import acot_table, unverified_cases
from gaitbench.run.runner import walk_metrics
from gaitbench.solve.walk import next_step_state
from gaitbench.solve.walk_verification import solve_verified, verify_walk
from gaitbench.walk_types import StepOutcome, WalkResult

REGISTRY = load_registry()


@pytest.fixture(scope="module")
def forward():
    return REGISTRY.create("experiment", "forward")


def _check(cot=0.3, defect=1e-9, resim=1e-3, gap=0.0, objective=None) -> StepVerification:
    """A step's verification; with ``objective`` (the NLP's COT) its gap is computed from it."""
    if objective is not None:
        gap = objective_gap(cot, objective)
    return StepVerification(max_defect=defect, resim_error=resim, resim_max_error=resim, hip_energy=1.0,
                            push_off_energy=0.0, cot=cot, objective_cot=cot if objective is None else objective,
                            objective_gap=gap, objective_agrees=abs(gap) <= 0.05)


def _step(index: int, stance: int, start: np.ndarray, check: StepVerification) -> StepOutcome:
    """A step whose trajectory starts at ``start`` and rests there (no solve: only its ends matter to the joins)."""
    times = np.linspace(0.0, 0.3, 5)
    q, dq = np.tile(start[:2], (5, 1)), np.tile(start[2:], (5, 1))
    trajectory = nodal_trajectory(times, q, dq, np.zeros((5, 2)), 0.0, stance)
    model = BipedModel(REGISTRY.create("experiment", "forward").robot, 2)
    return StepOutcome(index, stance, "converged", "", None, trajectory, check,
                       next_state=next_step_state(model, trajectory))


def _walk(steps, n_nodes=20, requested=None) -> WalkResult:
    return WalkResult("forward", "hermite-simpson", "ipopt", "one-phase", n_nodes, "first",
                      requested or len(steps), list(steps))


def test_a_walk_whose_steps_join_is_verified_and_its_acot_is_the_mean(forward):
    start = forward.start_state("on-ground")
    first = _step(1, 1, start, _check(cot=0.2))
    second = _step(2, 2, first.next_state, _check(cot=0.4))
    verification = verify_walk(_walk([first, second]), start, forward.robot)
    assert verification.verified and verification.reasons == ()
    assert verification.acot == pytest.approx(0.3)
    assert verification.max_join_mismatch == 0.0 and verification.join_energy == 0.0


def test_a_walk_with_a_broken_join_fails_and_the_energy_that_appears_is_counted(forward):
    start = forward.start_state("on-ground")
    first = _step(1, 1, start, _check())
    kicked = first.next_state + np.array([0.0, 0.0, 0.05, -0.02])  # faster than the impact left the robot
    second = _step(2, 2, kicked, _check())
    verification = verify_walk(_walk([first, second]), start, forward.robot)
    assert not verification.verified
    assert verification.reasons == ("step 2: join mismatch 5.0e-02 > 1e-06",)
    model = BipedModel(forward.robot, 2)
    appeared = model.total_energy(kicked[:2], kicked[2:], 2) - model.total_energy(first.next_state[:2],
                                                                                  first.next_state[2:], 2)
    assert verification.steps[1].join_energy == pytest.approx(appeared)
    assert verification.max_join_mismatch == pytest.approx(0.05)


def test_the_join_is_checked_against_the_impact_of_the_step_s_own_end_not_what_the_strategy_handed_on(forward):
    start = forward.start_state("on-ground")
    first = _step(1, 1, start, _check())
    handed_on = first.next_state + np.array([0.3, -0.2, 1.0, 2.0])  # a strategy's wrong post-impact state
    second = _step(2, 2, handed_on, _check())
    first.next_state = handed_on  # and the step it started from says so
    verification = verify_walk(_walk([first, second]), start, forward.robot)
    assert not verification.verified and verification.max_join_mismatch == pytest.approx(2.0)


def test_step_one_must_start_from_the_walks_start_state(forward):
    start = forward.start_state("on-ground")
    moved = _step(1, 1, start + np.array([0.01, 0.0, 0.0, 0.0]), _check())
    assert "step 1: join mismatch" in verify_walk(_walk([moved]), start, forward.robot).reason


@pytest.mark.parametrize(("figures", "reason"), [
    ({"defect": 2e-6}, "dynamics defect"),
    ({"resim": 0.3}, "re-simulation error 0.3 > 0.25"),  # 5 / N at N = 20
    ({"gap": 0.11}, "objective gap +11.0% beyond ±10.0%"),  # max(10 %, 2 / N) at N = 20
])
def test_each_threshold_fails_a_step_beyond_it(figures, reason):
    failures = step_failures(_check(**figures), Thresholds.for_nodes(20))
    assert len(failures) == 1 and reason in failures[0]


def test_a_step_whose_re_simulation_fails_inside_it_fails_verification_and_says_so(forward, monkeypatch):
    """An integration that gives up inside the step returns the states it reached: the step is no motion the robot
    follows (its end error is infinite), not a crash of the whole case, nor an error of the states it did reach."""
    import gaitbench.model.simulate as simulate
    from gaitbench.solve.verify import verify_step

    problem = WalkProblem(forward, REGISTRY.create("transcription", "hermite-simpson"),
                          REGISTRY.create("solver", "ipopt"), 12, steps=1)
    state = problem.start_state()
    data = problem.step_data(1, state)
    built = problem.transcription.build(problem.structure("second"))
    times = np.arange(12) * data.time_step
    trajectory = nodal_trajectory(times, np.tile(state[:2], (12, 1)), np.tile(state[2:], (12, 1)), np.zeros((12, 2)),
                                  0.0, 1)
    integrate, calls = simulate.solve_ivp, []

    def gives_up_on_the_fifth_interval(*args, **kwargs):
        calls.append(1)
        result = integrate(*args, **kwargs)
        if len(calls) == 5:
            result.status, result.message = -1, "Required step size is less than spacing between numbers."
        return result

    monkeypatch.setattr(simulate, "solve_ivp", gives_up_on_the_fifth_interval)
    check = verify_step(built, built.variables(trajectory, data), data, trajectory, BipedModel(forward.robot, 4))
    assert check.resim_error == np.inf and check.resim_max_error == np.inf
    assert "re-simulation failed before the step's end" in step_failures(check, Thresholds.for_nodes(12))


def test_the_thresholds_scale_with_the_grid():
    coarse, fine = Thresholds.for_nodes(10), Thresholds.for_nodes(200)
    assert coarse.max_resim_error == pytest.approx(0.5) and fine.max_resim_error == pytest.approx(0.025)
    assert coarse.max_objective_gap == pytest.approx(0.2) and fine.max_objective_gap == pytest.approx(0.1)
    assert coarse.max_defect == fine.max_defect and coarse.max_join_mismatch == fine.max_join_mismatch
    assert step_failures(_check(resim=0.3), coarse) == [] and step_failures(_check(resim=0.03), fine)


def test_a_nearly_free_steps_gap_is_held_to_what_it_can_move_the_walks_figure_by(forward):
    """A downhill step at COT 0.01 whose objective misses it by 0.0025 (12.5 % against its own COT, floored at 0.02)
    passes in a walk of mean step COT 0.255 (1 % of that); a costly step 20 % off fails in the same walk."""
    start = forward.start_state("on-ground")
    free = _check(cot=0.01, objective=0.0075)
    assert step_failures(free, Thresholds.for_nodes(20))  # alone, against its own COT
    costly = _step(1, 1, start, _check(cot=0.5, objective=0.49))
    cheap = _step(2, 2, costly.next_state, free)
    verification = verify_walk(_walk([costly, cheap]), start, forward.robot)
    assert verification.verified, verification.reasons
    assert verification.steps[1].objective_gap == pytest.approx(0.0025 / 0.255)
    exploited = _step(1, 1, start, _check(cot=0.5, objective=0.4))
    cheap = _step(2, 2, exploited.next_state, free)
    verification = verify_walk(_walk([exploited, cheap]), start, forward.robot)
    assert verification.reasons == ("step 1: objective gap +20.0% beyond ±10.0%",)


def test_a_gap_judged_against_the_walk_says_so():
    failures = step_failures(_check(cot=0.01, objective=-0.02), Thresholds.for_nodes(20), walk_cot=0.2)
    assert failures == ["objective gap +15.0% of the walk's mean step COT beyond ±10.0%"]


def test_an_incomplete_walk_is_not_verified(forward):
    start = forward.start_state("on-ground")
    verification = verify_walk(_walk([_step(1, 1, start, _check())], requested=3), start, forward.robot)
    assert not verification.verified and verification.acot is None
    assert verification.reasons[0].startswith("incomplete walk")


def test_the_verified_flag_goes_to_the_store_and_only_verified_walks_are_ranked(forward):
    start = forward.start_state("on-ground")
    good = _walk([_step(1, 1, start, _check(cot=0.3))])
    bad = _walk([_step(1, 1, start, _check(cot=0.1, resim=0.4))])
    good.verification = verify_walk(good, start, forward.robot)
    bad.verification = verify_walk(bad, start, forward.robot)
    rows = []
    for key, walk in (("a", good), ("b", bad), ("c", good)):
        metrics = walk_metrics(walk)
        rows.append({"case_key": key, "method": "OP-DC", "experiment": "forward", "experiment_options": {},
                     "N": 20, "strategy": "one-phase", "transcription": "hermite-simpson", "solver": "ipopt",
                     "status": "solved", "message": "", "wall_time_s": 1.0, **metrics})
    rows[2]["verified"] = None  # a row stored before the flag existed
    assert rows[0]["verified"] is True and rows[1]["verified"] is False
    assert "re-simulation error 0.4" in rows[1]["verification_failure"]
    df = prepare(pd.DataFrame(rows))
    table = acot_table(df)
    assert table.loc[0, "solved"] == 3 and table.loc[0, "verified"] == 1
    assert table.loc[0, "acot"] == pytest.approx(0.3)  # not (0.3 + 0.1 + 0.3) / 3
    listed = unverified_cases(df)
    assert list(listed["case_key"]) == ["b", "c"]
    assert listed.loc[1, "verification_failure"] == NOT_CHECKED


def _solved_walk(tmp_path, forward):
    problem = WalkProblem(forward, REGISTRY.create("transcription", "hermite-simpson"),
                          REGISTRY.create("solver", "ipopt"), 10, steps=2)
    walk = solve_verified(REGISTRY.create("strategy", "one-phase"), problem)
    from gaitbench.solve.walk_file import write_walk

    return walk, write_walk(walk, tmp_path / "walk.json")


def test_gaitbench_verify_rechecks_a_walk_file_and_fails_one_whose_join_was_broken(tmp_path, forward):
    walk, path = _solved_walk(tmp_path, forward)
    assert walk.verified, walk.verification.reason
    header = json.loads(path.read_text())
    assert header["acot"] == pytest.approx(walk.acot) and header["verified"] is True
    result = CliRunner().invoke(main, ["verify", str(path), "--json"])
    assert result.exit_code == 0, result.output
    report = json.loads(result.output)
    assert report["verified"] and report["acot"] == pytest.approx(walk.acot, rel=1e-6)
    assert report["max_join_mismatch"] < 1e-9
    assert 0 < report["thesis_reading_acot"] == pytest.approx(walk.thesis_reading_acot)

    npz = path.parent / header["trajectories"]
    with np.load(npz) as stored:
        arrays = {key: stored[key] for key in stored.files}
    arrays["step02_q"] = arrays["step02_q"] + 0.01  # step 2 no longer starts where step 1 left the robot
    np.savez(npz, **arrays)
    result = CliRunner().invoke(main, ["verify", str(path), "--json"])
    assert result.exit_code == 1
    assert any(reason.startswith("step 2: join mismatch 1.0e-02") for reason in json.loads(result.output)["reasons"])
    text = CliRunner().invoke(main, ["verify", str(path)]).output
    assert "  ACOT " in text and "verified ACOT" not in text and "NOT verified" in text


def test_a_step_that_ends_off_its_foothold_fails_its_constraints_not_only_its_dynamics(tmp_path, forward):
    """Verification holds every constraint of the step, not its dynamics alone: a COT is divided by the step's
    length, which a step that never reaches its foothold has not walked. The cost's |P| slacks, which a trajectory
    read back does not carry, are no constraint of the motion."""
    from gaitbench.solve.walk_file import read_walk
    from gaitbench.solve.walk_verification import reverify

    walk, path = _solved_walk(tmp_path, forward)
    assert all(step.verification.max_violation < 1e-6 for step in walk.steps)
    assert all(step.verification.max_violation < 1e-6 for step in reverify(read_walk(path)).steps)
    npz = path.parent / json.loads(path.read_text())["trajectories"]
    with np.load(npz) as stored:
        arrays = {key: stored[key] for key in stored.files}
    arrays["step01_q"] = arrays["step01_q"].copy()
    arrays["step01_q"][-1] += 0.01  # the swing foot lands short of the foothold
    np.savez(npz, **arrays)
    check = reverify(read_walk(path)).steps[0].verification
    assert check.violated == "heel_strike_configuration" and check.max_violation > 1e-3
    failures = step_failures(check, Thresholds.for_nodes(10))
    assert any(f.startswith("constraint heel_strike_configuration violated by") for f in failures), failures


def test_variable_bounds_count_relative_to_the_bound_and_a_value_that_is_no_number_counts_worst(forward):
    from gaitbench.problem.gait_problem import StepStructure

    built = REGISTRY.create("transcription", "hermite-simpson").build(StepStructure("second", 6))
    nlp = built.nlp
    torques = nlp.variable_blocks["torques"]
    x = np.clip(np.zeros(nlp.n_variables), nlp.lbx, nlp.ubx)
    assert max(nlp.bound_violations(x).values()) == 0.0
    limit = nlp.ubx[torques][0]
    x[torques.start] = limit * (1 + 1e-9)  # as a solver keeps a large bound: within it, relatively
    assert nlp.bound_violations(x)["torques bounds"] == pytest.approx(1e-9, rel=1e-3)  # 1e-9 of it, not of 1
    x[torques.start] = limit * 1.01
    assert nlp.bound_violations(x)["torques bounds"] == pytest.approx(0.01)
    x[torques.start] = np.nan
    assert nlp.bound_violations(x)["torques bounds"] == np.inf


def test_a_claimed_acot_that_a_walk_file_before_format_2_stores_as_its_acot_is_a_note_not_a_failure(forward,
                                                                                                     tmp_path):
    from gaitbench.cli.verify_command import _report
    from gaitbench.solve.walk_file import WalkFile

    start = forward.start_state("on-ground")
    patchwork = _step(1, 1, start, _check(cot=0.5))
    patchwork.details = {"chosen": ["a", "b"]}
    patchwork.polished = _step(1, 1, start, _check(cot=0.2))
    second = _step(2, 2, patchwork.polished.next_state, _check(cot=0.4))
    walk = _walk([patchwork, second])
    walk.verification = verify_walk(walk, start, forward.robot)
    assert walk.verification.acot == pytest.approx(0.3) and walk.claimed_acot == pytest.approx(0.45)

    header = {"steps": [step.as_dict() for step in walk.steps]}
    assert WalkFile(tmp_path, 1, header, {}).acot_is_claimed and WalkFile(tmp_path, None, header, {}).acot_is_claimed
    assert not WalkFile(tmp_path, 2, header, {}).acot_is_claimed
    assert not WalkFile(tmp_path, 1, {"steps": [second.as_dict()]}, {}).acot_is_claimed

    old = _report(tmp_path, walk, 0.45, acot_is_claimed=True)
    assert old["verified"] and old["reasons"] == []
    assert old["notes"] == ["stored ACOT 0.4500 is the claimed patchwork ACOT: the walk file predates format 2, which "
                            "stores the verified ACOT as acot and the claim as claimed_acot"]
    assert _report(tmp_path, walk, 0.45)["reasons"] == ["stored ACOT 0.4500 is not the recomputed 0.3000"]
    assert _report(tmp_path, walk, 0.6, acot_is_claimed=True)["reasons"] == [
        "stored ACOT 0.6000 is not the recomputed 0.3000"]
    assert _report(tmp_path, walk, 0.3, acot_is_claimed=True)["notes"] == []


def test_a_walk_file_is_verified_by_the_nlp_it_was_solved_with_its_transcriptions_options_included(tmp_path,
                                                                                                       forward):
    """A walk solved under Hermite–Simpson's Simpson rule: re-verified from its file, its objective gap is the
    solve's, not that of the default Boole rule; a file written before the options were recorded takes them from
    the store's row."""
    from gaitbench.run.case import PluginChoice
    from gaitbench.solve.walk_assembly import assemble_walk
    from gaitbench.solve.walk_file import read_walk, write_walk
    from gaitbench.solve.walk_verification import reverify

    strategy, problem = assemble_walk(
        REGISTRY.create, 10, experiment=PluginChoice("forward"),
        transcription=PluginChoice("hermite-simpson", {"quadrature": "simpson"}), solver=PluginChoice("ipopt"),
        strategy=PluginChoice("one-phase"), objective=PluginChoice("net-power"), steps=1)
    walk = solve_verified(strategy, problem)
    path = write_walk(walk, tmp_path / "walk.json")
    assert json.loads(path.read_text())["transcription_options"] == {"quadrature": "simpson"}
    solved_gap = walk.steps[0].verification.objective_gap
    again = reverify(read_walk(path), REGISTRY)
    assert again.steps[0].verification.objective_gap == pytest.approx(solved_gap, abs=1e-9)
    old = read_walk(path)
    del old.header["transcription_options"]
    assert reverify(old, REGISTRY).steps[0].verification.objective_gap != pytest.approx(solved_gap, abs=1e-4)

    from gaitbench.run.store import ResultStore, case_file

    header = json.loads(path.read_text())
    del header["transcription_options"]
    files = {"walk.json": json.dumps(header).encode(), "walk.npz": (path.parent / "walk.npz").read_bytes()}
    with ResultStore.create(tmp_path / "store") as results:
        results.start_run({"run_id": "r1", "suite": "s", "started_at": "2026-01-01T00:00:00+00:00"})
        results.record_case({"case_key": "a" * 16, "run_id": "r1", "experiment": "forward", "N": 10,
                             "status": "solved", "acot": walk.acot, "walk_path": case_file("a" * 16, "walk.json"),
                             "transcription_options": {"quadrature": "simpson"}}, files)
    result = CliRunner().invoke(main, ["verify", "--store", str(tmp_path / "store"), "--json"])
    report = json.loads(result.output.splitlines()[0])
    assert report["steps"][0]["objective_gap"] == pytest.approx(solved_gap, abs=1e-9)


def test_gaitbench_verify_refuses_what_is_not_a_walk_file(tmp_path):
    (tmp_path / "x.json").write_text("{}")
    result = CliRunner().invoke(main, ["verify", str(tmp_path / "x.json")])
    assert result.exit_code == 2 and "not a walk result" in result.output


def _store_of_two(tmp_path, forward):
    """A store of the same solved walk twice, as cases aaaa… and bbbb…; the walk and the store's path."""
    from gaitbench.run.store import ResultStore, case_file

    walk, path = _solved_walk(tmp_path / "walk", forward)
    files = {name: (path.parent / name).read_bytes() for name in ("walk.json", "walk.npz")}
    store = tmp_path / "store"
    with ResultStore.create(store) as results:
        results.start_run({"run_id": "r1", "suite": "s", "started_at": "2026-01-01T00:00:00+00:00"})
        for key in ("a" * 16, "b" * 16):
            results.record_case({"case_key": key, "run_id": "r1", "experiment": "forward", "N": 10,
                                 "status": "solved", "acot": walk.acot, "walk_path": case_file(key, "walk.json")},
                                files)
    return walk, store


def test_gaitbench_verify_store_writes_each_walks_verdict_into_its_row(tmp_path, forward):
    from gaitbench.run.store import ResultStore, case_file

    walk, store = _store_of_two(tmp_path, forward)
    broken = store / case_file("b" * 16, "walk.npz")
    broken.write_bytes(b"not a zip")
    result = CliRunner().invoke(main, ["verify", "--store", str(store)])
    assert result.exit_code == 1, result.output  # one walk is not verified
    with ResultStore.open(store) as results:
        rows = {row["case_key"]: row for row in results.cases()}
    good, bad = rows["a" * 16], rows["b" * 16]
    assert good["verified"] == 1 and good["verification_failure"] is None
    assert good["thesis_reading_acot"] == pytest.approx(walk.thesis_reading_acot)
    assert good["max_join_mismatch"] < 1e-9
    assert bad["verified"] == 0 and bad["verification_failure"].startswith("walk file unreadable")


def test_a_walk_that_breaks_the_verifier_costs_the_other_walks_of_a_store_nothing(tmp_path, forward, monkeypatch):
    from gaitbench.run.store import ResultStore
    from gaitbench.solve import walk_verification

    walk, store = _store_of_two(tmp_path, forward)
    reverify = walk_verification.reverify

    def breaks_on_b(walk_file, registry=None):
        if "b" * 16 in str(walk_file.path):
            raise RuntimeError("a bug")
        return reverify(walk_file, registry)

    monkeypatch.setattr(walk_verification, "reverify", breaks_on_b)
    result = CliRunner().invoke(main, ["verify", "--store", str(store)])
    assert result.exit_code == 1 and "RuntimeError: a bug" in result.output, result.output
    with ResultStore.open(store) as results:
        rows = {row["case_key"]: row for row in results.cases()}
    assert rows["a" * 16]["verified"] == 1 and rows["b" * 16]["verified"] is None


def test_gaitbench_verify_store_leaves_a_walk_whose_plugin_is_not_installed_unjudged(tmp_path, forward):
    """A walk solved with a plugin this environment lacks is not a broken file: its row keeps the verdict it had,
    and the command says which plugin is missing and how to go on."""
    from gaitbench.run.store import ResultStore, case_file

    walk, path = _solved_walk(tmp_path / "walk", forward)
    header = json.loads((path.parent / "walk.json").read_text())
    files = {"walk.json": json.dumps(header | {"objective": "no-such-objective"}).encode(),
             "walk.npz": (path.parent / "walk.npz").read_bytes()}
    store, key = tmp_path / "store", "c" * 16
    with ResultStore.create(store) as results:
        results.start_run({"run_id": "r1", "suite": "s", "started_at": "2026-01-01T00:00:00+00:00"})
        results.record_case({"case_key": key, "run_id": "r1", "experiment": "forward", "N": 10, "status": "solved",
                             "acot": walk.acot, "walk_path": case_file(key, "walk.json"), "verified": 1}, files)
    result = CliRunner().invoke(main, ["verify", "--store", str(store)])
    assert result.exit_code == 1 and "not installed here" in result.output and "no-such-objective" in result.output
    with ResultStore.open(store) as results:
        (row,) = results.cases()
    assert row["verified"] == 1 and row["verification_failure"] is None
    alone = CliRunner().invoke(main, ["verify", str(store / case_file(key, "walk.json"))])
    assert alone.exit_code == 1 and "cannot be verified here" in alone.output


@pytest.mark.parametrize(("field", "value"), [
    ("N", "eight"), ("N", 8.5), ("phase", "third"), ("experiment_options", {"bogus": 1}),
    ("problem_options", {"clearance": "of"}), ("steps", None), ("steps", "abc"), ("steps[0]", [{}]),
    ("steps[0].stance", "x"), ("steps[0]", "N = 9"),
])
def test_a_walk_file_with_a_bad_header_value_is_refused_naming_the_field(tmp_path, forward, field, value):
    """Each gave a traceback (or, for N = 8.5, was read as 8): a walk file from another install whose experiment
    plugin changed its options is the realistic case."""
    _, path = _solved_walk(tmp_path, forward)
    header = json.loads(path.read_text())
    if field == "steps[0].stance":
        header["steps"][0]["stance"] = value
    elif value == "N = 9":  # a header whose N is not its trajectories' (8 nodes)
        header["N"] = 9
    else:
        header[field.partition("[")[0]] = value
    path.write_text(json.dumps(header))
    result = CliRunner().invoke(main, ["verify", str(path)])
    assert result.exit_code == 2 and f"{field}" in result.output and "Traceback" not in result.output, result.output
