"""Step checkpoints: a walk stopped from outside resumes after its last solved step, to the same walk."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from gaitbench.checkpoint import WalkCheckpoint, progress_file
from gaitbench.contracts import WalkProblem
from gaitbench.plugins import load_registry
from gaitbench.run.case import Case, PluginChoice
from gaitbench.run.executors import InProcessExecutor
from gaitbench.run.provenance import code_fingerprint
from gaitbench.run.runner import run_suite
from gaitbench.run.store import ResultStore, checkpoint_file, load_results
from gaitbench.solve.walk import walk_step_by_step
from gaitbench.walk_types import StepOutcome

REGISTRY = load_registry()
FINGERPRINT = {"case": "test", "code": "test"}


class Stopped(Exception):
    """What a kill is to the walk: it ends in the middle of a step, and nothing after that runs."""


class StoppedAtStep(WalkProblem):
    """The walk's process "killed" as step ``stop_at`` begins."""

    stop_at = 3

    def step_data(self, index, state):
        if index == self.stop_at:
            raise Stopped
        return super().step_data(index, state)


def _problem(strategy_problem=WalkProblem, steps: int = 3, **fields) -> WalkProblem:
    return strategy_problem(REGISTRY.create("experiment", "forward"), REGISTRY.create("transcription", "dmoc"),
                            REGISTRY.create("solver", "ipopt"), 8, steps=steps, **fields)


def test_a_checkpoint_is_resumed_only_by_its_case_and_code(tmp_path: Path) -> None:
    path = tmp_path / "walk"
    step = StepOutcome(1, 1, "converged", "", next_state=np.arange(4.0))
    WalkCheckpoint(path, FINGERPRINT).save([step], {1}, 12.5)
    resumed = WalkCheckpoint.open(path, FINGERPRINT)
    assert [s.index for s in resumed.steps] == [1] and resumed.backed_up == {1} and resumed.elapsed_s == 12.5
    np.testing.assert_array_equal(resumed.steps[0].next_state, np.arange(4.0))

    other = WalkCheckpoint.open(path, {"case": "test", "code": "other"})
    assert not other.steps and "other" in other.discarded and not path.exists()

    path.write_bytes(b"cut short by the kill")
    assert "unreadable" in WalkCheckpoint.open(path, FINGERPRINT).discarded and not path.exists()
    assert WalkCheckpoint.open(path, FINGERPRINT).discarded == ""  # nothing there: nothing to say


def test_a_stopped_walk_goes_on_after_its_saved_steps(tmp_path: Path) -> None:
    """Made-up steps: step 3 is a dead end until step 2 is backed up; the first run is stopped in step 4. The
    second keeps the backed-up step 2 and solves only steps 4 and 5."""
    problem = _problem(steps=5)
    solved, backed_up = [], []

    def outcome(index, state, ok=True):
        return StepOutcome(index, problem.experiment.stance_leg(index), "converged" if ok else "infeasible", "",
                           trajectory=SimpleNamespace(seed=lambda: None) if ok else None,
                           verification=SimpleNamespace(cot=0.1 * index, resim_error=0.0) if ok else None,
                           next_state=state + 1.0 if ok else None)

    def first_run(problem, index, state):
        if index == 4:
            raise Stopped
        solved.append(index)
        return outcome(index, state, ok=index != 3 or bool(backed_up))

    def back_up(problem, index, state, replaced):
        backed_up.append(index)
        return outcome(index, state)

    with pytest.raises(Stopped):
        walk_step_by_step(_with(problem, WalkCheckpoint(tmp_path / "walk", FINGERPRINT)), "test", first_run,
                          back_up=back_up)
    assert solved == [1, 2, 3, 3] and backed_up == [2]

    solved.clear()
    resumed = WalkCheckpoint.open(tmp_path / "walk", FINGERPRINT)
    assert [step.index for step in resumed.steps] == [1, 2, 3] and resumed.backed_up == {2}
    assert "backed_up_from" in resumed.steps[1].details
    walk = walk_step_by_step(_with(problem, resumed), "test", lambda p, i, s: solved.append(i) or outcome(i, s),
                             back_up=back_up)
    assert solved == [4, 5] and walk.complete
    assert walk.resumed["steps"] == 3 and walk.wall_time_s >= walk.resumed["elapsed_s"] > 0


def test_a_step_that_ends_after_the_deadline_is_not_saved_for_a_resume(tmp_path: Path, monkeypatch) -> None:
    """A step finished past the walk's deadline may have skipped starts or retries for time; a resumed walk with
    more time must solve it in full, so the checkpoint keeps only the steps finished in time."""
    problem = _problem(steps=3)
    late = {"now": False}
    monkeypatch.setattr(WalkProblem, "out_of_time", property(lambda self: late["now"]))

    def solve(problem, index, state):
        late["now"] = index == 2  # the deadline passes during step 2
        return StepOutcome(index, problem.experiment.stance_leg(index), "converged", "",
                           trajectory=SimpleNamespace(seed=lambda: None),
                           verification=SimpleNamespace(cot=0.1, resim_error=0.0), next_state=state + 1.0)

    walk_step_by_step(_with(problem, WalkCheckpoint(tmp_path / "walk", FINGERPRINT)), "test", solve)
    assert [step.index for step in WalkCheckpoint.open(tmp_path / "walk", FINGERPRINT).steps] == [1]


def _with(problem: WalkProblem, checkpoint: WalkCheckpoint) -> WalkProblem:
    from dataclasses import replace

    return replace(problem, checkpoint=checkpoint)


@pytest.mark.parametrize("strategy", ["one-phase", "decrease-and-conquer"])
def test_a_resumed_walk_is_the_walk_that_was_not_stopped(tmp_path: Path, strategy: str) -> None:
    whole = REGISTRY.create("strategy", strategy).solve(_problem())
    checkpoint = WalkCheckpoint(tmp_path / "walk", FINGERPRINT)
    with pytest.raises(Stopped):
        REGISTRY.create("strategy", strategy).solve(_problem(StoppedAtStep, checkpoint=checkpoint))
    resumed = WalkCheckpoint.open(tmp_path / "walk", FINGERPRINT)
    assert len(resumed.steps) == 2
    walk = REGISTRY.create("strategy", strategy).solve(_problem(checkpoint=resumed))
    assert walk.complete and walk.resumed["steps"] == 2
    assert [step.verification.cot for step in walk.steps] == [step.verification.cot for step in whole.steps]
    assert walk.strategy_details == whole.strategy_details
    np.testing.assert_array_equal(walk.steps[-1].trajectory.q, whole.steps[-1].trajectory.q)


def test_a_look_ahead_walk_starts_again_from_step_one(tmp_path: Path) -> None:
    """Its windows start from the previous window's later steps, which the checkpoint does not keep."""
    checkpoint = WalkCheckpoint(tmp_path / "walk", FINGERPRINT)
    checkpoint.save([StepOutcome(1, 1, "converged", "", next_state=np.zeros(4))], set(), 1.0)
    steps = []
    walk_step_by_step(_with(_problem(steps=2), checkpoint), "test",
                      lambda p, i, s: steps.append(i) or StepOutcome(i, 1, "infeasible", ""), resumable=False)
    assert steps == [1]


def _case(time_limit_s: float = 600) -> Case:
    return Case(PluginChoice("forward"), 8, PluginChoice("dmoc"), PluginChoice("ipopt"), PluginChoice("one-phase"),
                steps=3, method="OP-DM", time_limit_s=time_limit_s)


def _stopped_run(store: Path, case: Case, code: str | None = None) -> Path:
    """What a run killed in step 3 of ``case`` leaves in ``store``: its checkpoint of steps 1 and 2 (beside the
    database the run had created)."""
    ResultStore.create(store).close()
    path = store / checkpoint_file(case.key)
    checkpoint = WalkCheckpoint(path, {"case": case.key, "code": code or code_fingerprint()})
    with pytest.raises(Stopped):
        REGISTRY.create("strategy", "one-phase").solve(_problem(StoppedAtStep, checkpoint=checkpoint))
    return path


def _walk_file(store: Path, case: Case) -> dict:
    return json.loads((store / "cases" / case.key / "walk.json").read_text())


def test_the_runner_resumes_a_case_from_its_checkpoint_and_then_removes_it(tmp_path: Path) -> None:
    whole = REGISTRY.create("strategy", "one-phase").solve(_problem())
    case = _case()
    path = _stopped_run(tmp_path / "store", case)
    run_suite(SimpleNamespace(name="test", path=Path("t.toml"), text="", cases=[case]), tmp_path / "store",
              InProcessExecutor())
    row = load_results(tmp_path / "store").iloc[0]
    assert row["status"] == "solved" and row["acot"] == whole.acot
    assert _walk_file(tmp_path / "store", case)["resumed"]["steps"] == 2
    assert not path.exists() and not progress_file(path).exists()  # the walk is recorded whole


def test_the_runner_discards_another_code_s_checkpoint(tmp_path: Path) -> None:
    case = _case()
    _stopped_run(tmp_path / "store", case, code="another gaitbench")
    run_suite(SimpleNamespace(name="test", path=Path("t.toml"), text="", cases=[case]), tmp_path / "store",
              InProcessExecutor())
    resumed = _walk_file(tmp_path / "store", case)["resumed"]
    assert "steps" not in resumed and "another gaitbench" in resumed["discarded"]


def test_a_resumed_case_s_time_limit_counts_the_time_before_its_stop(tmp_path: Path) -> None:
    """The limit is the whole walk's: a walk stopped after its limit keeps its saved steps and solves no more."""
    case = _case(time_limit_s=5)
    path = _stopped_run(tmp_path / "store", case)
    saved = WalkCheckpoint.open(path, {"case": case.key, "code": code_fingerprint()})
    saved.save(saved.steps, saved.backed_up, elapsed_s=10.0)
    run_suite(SimpleNamespace(name="test", path=Path("t.toml"), text="", cases=[case]), tmp_path / "store",
              InProcessExecutor())
    row = load_results(tmp_path / "store").iloc[0]
    assert (row["status"], row["stop_cause"], row["stop_step"], row["steps_solved"]) == \
        ("incomplete", "time_limit", 3, 2)
    assert row["wall_time_s"] >= 10.0


def test_a_walk_stopped_by_its_time_limit_keeps_its_steps_for_a_run_with_a_larger_limit(tmp_path: Path) -> None:
    """The reference column's stairs walk at N = 130 spent its 2 h on 7 steps; with its checkpoint kept, a run
    with a larger limit and --retry-incomplete solves step 8 on, not steps 1-7 again."""
    whole = REGISTRY.create("strategy", "one-phase").solve(_problem())
    case = _case(time_limit_s=5)
    path = _stopped_run(tmp_path / "store", case)
    saved = WalkCheckpoint.open(path, {"case": case.key, "code": code_fingerprint()})
    saved.save(saved.steps, saved.backed_up, elapsed_s=10.0)
    suite = SimpleNamespace(name="test", path=Path("t.toml"), text="", cases=[case])
    run_suite(suite, tmp_path / "store", InProcessExecutor())
    assert load_results(tmp_path / "store").iloc[0]["stop_cause"] == "time_limit"
    assert path.exists() and progress_file(path).exists()  # kept beside the recorded row

    suite.cases = [replace(case, time_limit_s=600)]
    run_suite(suite, tmp_path / "store", InProcessExecutor(), resume=True, retry_incomplete=True)
    row = load_results(tmp_path / "store").iloc[0]
    assert row["status"] == "solved" and row["acot"] == whole.acot
    assert _walk_file(tmp_path / "store", case)["resumed"]["steps"] == 2  # steps 1 and 2 were not solved again
    assert not path.exists()  # recorded whole


def test_a_run_shows_the_steps_its_walks_in_flight_have_saved(tmp_path: Path) -> None:
    from gaitbench.checkpoint import remove_checkpoint, saved_progress
    from gaitbench.cli.run_progress import steps_in_flight

    step = StepOutcome(1, 1, "converged", "", next_state=np.zeros(4))
    WalkCheckpoint(tmp_path / "a1", FINGERPRINT).save([step, step], set(), 5.0, of=11)
    WalkCheckpoint(tmp_path / "b2", FINGERPRINT).save([step], set(), 1.0, of=11)  # another suite's walk
    progress = saved_progress(tmp_path)
    assert progress["a1"] == {"saved": 2, "of": 11, "elapsed_s": 5.0, "code": FINGERPRINT["code"]}
    labels = {"a1": "forward N=140 D&C-DM"}
    assert steps_in_flight(progress, labels) == "in flight: 2 of 11 steps (forward N=140 D&C-DM)"
    remove_checkpoint(tmp_path / "a1")
    assert sorted(path.name for path in tmp_path.iterdir()) == ["b2", "b2.json"]
    assert steps_in_flight(saved_progress(tmp_path), labels) == ""


def test_the_code_fingerprint_follows_the_source_that_solves_walks_not_the_commit(tmp_path, monkeypatch) -> None:
    """A documentation commit, or one to the command line or the reports, keeps a walk in flight resumable; an edit
    to the code that solves walks (the core, a built-in solver or other plugin) does not."""
    import gaitbench
    import gaitbench_plugins as builtin
    from gaitbench.run import provenance

    assert provenance._source_roots() == [Path(gaitbench.__file__).resolve().parent,
                                          Path(builtin.__file__).resolve().parent]
    core, plugins = tmp_path / "gaitbench", tmp_path / "plugins"
    for package in (core, plugins):
        (package / "sub").mkdir(parents=True)
        (package / "sub" / "module.py").write_text("X = 1\n")
    monkeypatch.setattr(provenance, "_source_roots", lambda: [core, plugins])
    fingerprint = provenance.code_fingerprint.__wrapped__
    before = fingerprint()
    (core / "README.md").write_text("a note")
    (tmp_path / "docs.md").write_text("a decision")
    for front_end in (core / "cli", core / "reports", plugins / "reporters"):  # they only show results
        front_end.mkdir()
        (front_end / "view.py").write_text("SHOWN = True\n")
    assert fingerprint() == before
    (plugins / "sub" / "module.py").write_text("X = 2\n")
    changed = fingerprint()
    assert changed != before
    (plugins / "sub" / "module.py").rename(plugins / "moved.py")  # the same text elsewhere is other code
    assert fingerprint() not in (before, changed)


def test_a_suites_own_plugins_are_part_of_what_a_walk_resumes_under(tmp_path, monkeypatch) -> None:
    """A plugin from a suite's plugin directory (or $GAITBENCH_PLUGINS_DIR) solves walks as much as a built-in one:
    editing it sends a stopped walk back to step 1; without such plugins the checkpoint's fingerprint is as it was."""
    from gaitbench.plugins import PLUGINS_DIR_ENV
    from gaitbench.run.provenance import plugins_fingerprint

    monkeypatch.delenv(PLUGINS_DIR_ENV, raising=False)
    assert plugins_fingerprint([]) is None  # only the built-in plugins here
    (tmp_path / "mine.py").write_text("STEP = 1\n")
    before = plugins_fingerprint([tmp_path])
    assert before is not None and plugins_fingerprint([tmp_path]) == before
    (tmp_path / "mine.py").write_text("STEP = 2\n")
    assert plugins_fingerprint([tmp_path]) != before
    monkeypatch.setenv(PLUGINS_DIR_ENV, str(tmp_path))
    assert plugins_fingerprint([]) == plugins_fingerprint([tmp_path])
    monkeypatch.delenv(PLUGINS_DIR_ENV)
    moved = tmp_path / "elsewhere"  # a store copied to another machine, its suite's plugins beside it
    moved.mkdir()
    (moved / "mine.py").write_text("STEP = 2\n")
    assert plugins_fingerprint([moved]) == plugins_fingerprint([tmp_path])
