"""Running a suite: each case solved (anywhere), its outcome recorded in the store the moment it arrives.

:func:`run_case` is what a worker does with one case; it never raises, so a failing method, a broken plugin or
bad options become a recorded status. :func:`run_suite` hands the cases that are not yet in the store to an
executor (:mod:`gaitbench.run.executors`), claiming each as the executor takes it so that runs sharing a store never
solve a case twice, and records each outcome as it arrives. A case's walk saves its steps in the store's checkpoints
as it goes; a case stopped from outside (the run killed, its worker crashed or timed out) is resumed from them by
the next run that solves it.
"""

from __future__ import annotations

import tempfile
import time
import traceback
from collections.abc import Callable, Collection, Iterable, Iterator
from contextlib import suppress
from dataclasses import dataclass, field, replace
from datetime import datetime, timezone
from pathlib import Path
from typing import TYPE_CHECKING, Any

from gaitbench.checkpoint import CheckpointError, WalkCheckpoint, remove_checkpoint
from gaitbench.cores import IdleCores
from gaitbench.problem.build_cache import BuildCache
from gaitbench.run.case import Case
from gaitbench.run.provenance import code_fingerprint, plugins_fingerprint, provenance
from gaitbench.run.store import LOCK_TIMEOUT_S, BadRow, ResultStore, case_file, checkpoint_file
from gaitbench.run.store_schema import StoreError

if TYPE_CHECKING:
    from gaitbench.contracts import FanOut, Strategy, WalkProblem
    from gaitbench.plugins import PluginRegistry
    from gaitbench.walk_types import WalkResult

WALK_FILE = "walk.json"
TRACK_FILE = "track.json"


@dataclass
class CaseOutcome:
    """What a worker sends back for one case: plain data, so it crosses process and machine boundaries.

    ``metrics`` are store columns computed in the worker (:func:`walk_metrics`, :func:`tracking_metrics`);
    ``files`` are the saved walk (and tracking) by file name, written into the store beside the row.
    ``store_error`` says why the worker could not write to the store (its checkpoint): the run stops on it, and
    the case is not recorded.
    """

    case: Case
    status: str
    message: str
    wall_time_s: float
    metrics: dict[str, Any] = field(default_factory=dict)
    files: dict[str, bytes] = field(default_factory=dict)
    provenance: dict[str, Any] = field(default_factory=dict)
    store_error: str = ""

    @property
    def failed(self) -> bool:
        return self.status != "solved"


def run_case(case: Case, builds: BuildCache | None = None, fan_out: FanOut | None = None) -> CaseOutcome:
    """Solve one case's walk (and track it if the case asks), in this process, keeping what its strategy builds in
    ``builds`` for the next cases (a worker's) or, without it, for this case alone. ``fan_out``: the run's map over
    its workers, given to the walk (``WalkProblem.fan_out``)."""
    started = time.perf_counter()
    metrics: dict[str, Any] = {}
    files: dict[str, bytes] = {}
    walk = None
    try:
        walk = _solve_walk(case, builds or BuildCache(), fan_out)
        metrics |= walk_metrics(walk)
        files |= _walk_files(walk)
        status = "solved" if walk.complete else "incomplete"
        message = "" if walk.complete else (walk.failure or "the walk stopped early")
        if case.tracking is not None and walk.complete:
            tracking = _track(case, walk)
            metrics |= tracking_metrics(tracking)
            files |= _saved_files(tracking.save, TRACK_FILE)
    except CheckpointError as error:  # the store failing, not the case: the run stops on it
        return CaseOutcome(case, "error", str(error), time.perf_counter() - started, store_error=str(error))
    except Exception as error:  # a failing plugin is this case's result, not the run's end
        status, message = "error", describe_error(error)
    earlier = walk.resumed.get("elapsed_s", 0.0) if walk is not None else 0.0  # before a stop, from its checkpoint
    return CaseOutcome(case, status, message, earlier + time.perf_counter() - started, metrics, files, provenance())


def failed_outcome(case: Case, status: str, message: str, wall_time_s: float = 0.0) -> CaseOutcome:
    """The outcome of a case whose worker never answered (timeout, crash, lost connection)."""
    return CaseOutcome(case, status, message, wall_time_s)


def case_walk(case: Case, **walk: Any) -> tuple[Strategy, WalkProblem]:
    """The strategy and the walk problem of ``case``, its plugins built from its plugin directories, each solve
    limited to its share of the case's time limit; ``walk``: the problem's other fields (``builds``, ...). A worker
    that solves part of the case's walk (:mod:`gaitbench.fan_out`) rebuilds its problem here too."""
    from gaitbench.solve.walk_assembly import assemble_walk

    solver = case.solver
    if case.time_limit_s is not None:
        solver = replace(solver, options={"time_limit_s": case.solve_time_limit_s, **solver.options})
    return assemble_walk(
        _registry(case).create, case.n_nodes, experiment=case.experiment, transcription=case.transcription,
        solver=solver, strategy=case.strategy, objective=case.objective, steps=case.steps,
        problem_options=case.problem_options, **walk)


def _solve_walk(case: Case, builds: BuildCache, fan_out: FanOut | None = None) -> WalkResult:
    from gaitbench.solve.walk_verification import solve_verified

    plugins = plugins_fingerprint(case.plugin_dirs)
    checkpoint = None if case.checkpoint is None else WalkCheckpoint.open(
        case.checkpoint, {"case": case.key, "code": code_fingerprint(), **({"plugins": plugins} if plugins else {})})
    earlier = checkpoint.elapsed_s if checkpoint is not None else 0.0  # the time limit is the whole walk's
    deadline = None if case.time_limit_s is None else time.monotonic() + case.time_limit_s - earlier
    cores = IdleCores.machine()
    strategy, problem = case_walk(case, builds=builds, deadline=deadline, checkpoint=checkpoint, cores=cores,
                                  fan_out=fan_out)
    with cores.occupy():  # this case's core; the walk may borrow the idle others
        walk = solve_verified(strategy, problem)
    if checkpoint is not None and checkpoint.discarded:
        walk.resumed = {**walk.resumed, "discarded": checkpoint.discarded}
    return walk


def _track(case: Case, walk):
    from gaitbench.control.tracking import track_walk

    stage = case.tracking
    return track_walk(walk, controller=stage.controller, observer=stage.observer, disturbance=stage.disturbance,
                      options=stage.options, registry=_registry(case))


def _walk_files(walk) -> dict[str, bytes]:
    from gaitbench.solve.walk_file import write_walk

    return _saved_files(lambda path: write_walk(walk, path), WALK_FILE)


def _saved_files(save: Callable[[Path], Path], name: str) -> dict[str, bytes]:
    """The files ``save`` writes (JSON and its NPZ) at ``name``, read back as bytes for the trip to the store."""
    with tempfile.TemporaryDirectory(prefix="gaitbench-save-") as directory:
        save(Path(directory) / name)
        return {path.name: path.read_bytes() for path in Path(directory).iterdir()}


def _registry(case: Case) -> PluginRegistry:
    from gaitbench.plugins import load_registry

    return load_registry(case.plugin_dirs)


def describe_error(error: Exception) -> str:
    """The exception and the innermost frame it came from: enough to find the failing plugin."""
    frame = traceback.extract_tb(error.__traceback__)[-1] if error.__traceback__ else None
    where = f" (at {Path(frame.filename).name}:{frame.lineno} in {frame.name})" if frame else ""
    return f"{type(error).__name__}: {error}{where}"


def case_row(outcome: CaseOutcome, suite: str, run_id: str) -> dict[str, Any]:
    """The store row of an outcome: every parameter of the case, the status, the metrics, the provenance."""
    case = outcome.case
    row: dict[str, Any] = {
        "case_key": case.key, "run_id": run_id, "suite": suite, "method": case.method,
        "experiment": case.experiment.name, "experiment_options": case.experiment.options,
        "N": case.n_nodes, "steps": case.steps,
        "transcription": case.transcription.name, "transcription_options": case.transcription.options,
        "solver": case.solver.name, "solver_options": case.solver.options,
        "strategy": case.strategy.name, "strategy_options": case.strategy.options,
        "objective": case.objective.describe(),
        "problem_options": case.problem_options, "repetition": case.repetition, "time_limit_s": case.time_limit_s,
        "tracking_stage": case.tracking.as_dict() if case.tracking else None,
        "status": outcome.status, "message": outcome.message, "wall_time_s": outcome.wall_time_s,
        "provenance": outcome.provenance or None, "finished_at": _now(),
    }
    row |= outcome.metrics
    if outcome.status in RUN_FAILURE_CAUSES:  # the run failed, not the method: the walk's own record is moot
        row["stop_cause"] = RUN_FAILURE_CAUSES[outcome.status]
    for column, name in (("walk_path", WALK_FILE), ("tracking_path", TRACK_FILE)):
        if name in outcome.files:
            row[column] = case_file(case.key, name)
    return row


RUN_FAILURE_CAUSES = {"error": "error", "timeout": "time_limit", "crashed": "crashed"}
"""The ``stop_cause`` of a case the run lost (it raised, ran past its limit, or its worker died)."""


def resumable(outcome: CaseOutcome, row: dict[str, Any]) -> bool:
    """Whether the case's checkpoint stays after its row is recorded: the run lost the case, or its walk stopped
    at the case's time limit. Such a walk is the first steps of the walk that was not stopped (each step depends
    only on the state the one before left), so a later run with a larger limit and ``--retry-incomplete`` goes on
    from its steps instead of solving them again (the reference column's stairs walk at N = 130 had spent its
    2 h on 7 steps)."""
    return outcome.status in RUN_FAILURE_CAUSES or row.get("stop_cause") == "time_limit"


def stop_cause(status: str) -> str:
    """The ``stop_cause`` (gaitbench.run.store_schema.STOP_CAUSES) of a walk stopped by a step with this status.

    ``infeasible_geometry`` is checked before any solve; a solver's ``time_limit`` is the case's time limit passed
    to it; a step whose solve converged but that is not solved failed the verification after it; every other status
    (``infeasible``, ``iteration_limit``, ``error``, a plugin's own) is the solver's.
    """
    if status == "infeasible_geometry":
        return "geometry"
    if status == "time_limit":
        return "time_limit"
    if status == "converged" or "verif" in status:
        return "verification"
    return "solver"


def walk_stop(walk) -> dict[str, Any]:
    """Why and where a walk stopped (store columns ``stop_cause``, ``stop_step``, ``stop_status``), how many
    solve retries it took (``retries``: each step's ``details["retries"]``, a list; missing means none) and how many
    steps were solved again after a dead end (``back_ups``: steps with ``details["backed_up_from"]``)."""
    retries, back_ups = 0, 0
    for step in walk.steps:
        details = step.details if isinstance(step.details, dict) else {}
        recorded = details.get("retries")
        retries += len(recorded) if isinstance(recorded, list) else int(recorded or 0)
        back_ups += "backed_up_from" in details
    counts = {"retries": retries, "back_ups": back_ups}
    failed = next((step for step in walk.steps if not step.solved), None)
    if failed is not None:
        return {"stop_cause": stop_cause(failed.status), "stop_step": failed.index, "stop_status": failed.status,
                **counts}
    if walk.complete:
        return {"stop_cause": "complete", "stop_step": None, "stop_status": None, **counts}
    # Fewer steps than requested, each solved: the strategy ended the walk without a failing step to blame.
    return {"stop_cause": "solver", "stop_step": len(walk.steps) + 1, "stop_status": None, **counts}


def walk_metrics(walk) -> dict[str, Any]:
    """ACOT, per-step COT and its bounds, effort, verification and why the walk stopped, as store columns.

    The figures are those of the motions the walk reports (:attr:`StepOutcome.verified`; for decrease and conquer
    its polished or complete steps), never a patchwork's claim, which goes to ``claimed_acot``. Effort
    (``iterations``, ``solve_time_s``) is that of the solve that produced each step's reported trajectory
    (:attr:`StepOutcome.solver_result`); the case's ``wall_time_s`` counts every solve."""
    motions = [step.verified for step in walk.steps]
    cots = [motion.verification.cot if motion.verification else None for motion in motions]
    solved = [cot for cot in cots if cot is not None]
    results = [step.solver_result for step in walk.steps if step.solver_result is not None]
    checks = [motion.verification for motion in motions if motion.verification is not None]
    verification = walk.verification
    return {
        "acot": walk.acot,
        "claimed_acot": walk.claimed_acot,
        "thesis_reading_acot": walk.thesis_reading_acot,
        "cot_steps": cots,
        "cot_min": min(solved) if solved else None,
        "cot_max": max(solved) if solved else None,
        "steps_solved": sum(step.solved for step in walk.steps),
        "solve_time_s": sum(result.wall_time_s for result in results),
        "function_time_s": sum(result.function_time_s for result in results),
        "iterations": sum(result.iterations for result in results),
        "max_defect": max((check.max_defect for check in checks), default=None),
        "max_resim_error": max((check.resim_error for check in checks), default=None),
        "verified": None if verification is None else verification.verified,
        "verification_failure": None if verification is None else verification.reason,
        "max_join_mismatch": None if verification is None else verification.max_join_mismatch,
        "join_energy": None if verification is None else verification.join_energy,
        "strategy_details": walk.strategy_details or None,
        **walk_stop(walk),
    }


def tracking_metrics(tracking) -> dict[str, Any]:
    summary = tracking.as_dict()
    return {
        "max_position_error": summary.get("max_position_error"),
        "max_velocity_error": summary.get("max_velocity_error"),
        "acot_tracked": summary.get("acot_tracked"),
        "acot_increase_percent": summary.get("acot_increase_percent"),
        "fell": summary.get("fell"),
        "tracking": {key: value for key, value in summary.items() if not isinstance(value, list)},
    }


@dataclass(frozen=True)
class RunSummary:
    run_id: str
    store: Path
    total: int
    skipped: int
    solved: int
    failed: int
    wall_time_s: float
    elsewhere: int = 0
    """Cases of this run that another run sharing the store solved (or was solving when this one ended)."""


def run_suite(suite, store_dir: str | Path, executor, *, resume: bool = False, retry_failed: bool = False,
              retry_incomplete: bool = False, retry_unverified: bool = False, rerun: Collection[str] = (),
              smallest_first: bool = False, lock_timeout: float = LOCK_TIMEOUT_S,
              on_start: Callable[[int, int], None] | None = None,
              on_outcome: Callable[[CaseOutcome], None] | None = None,
              on_elsewhere: Callable[[Case], None] | None = None) -> RunSummary:
    """Run every case of ``suite`` that the store does not hold yet, recording each as it finishes.

    Without ``resume`` a store that already holds cases of this suite is refused (nothing is overwritten), unless
    another run is working on it now: then this run shares that work. Each case is claimed right before the
    executor starts it, so runs sharing a store split the cases between them; a case another live run has claimed
    or finished meanwhile is left to it (``on_elsewhere``). With ``resume``, finished cases are skipped (failed
    ones re-run with ``retry_failed``, stopped walks with ``retry_incomplete``, complete walks without a verified
    ACOT with ``retry_unverified``, and the stored cases whose keys are in ``rerun``), and a dead run's claims are
    taken over. Cases start largest N first (:func:`largest_first`), or smallest N first with ``smallest_first``.
    An executor with more ``jobs`` than cases to run gets as many as there are cases, unless its
    walks fan out over its workers (``fans_out``: Dask). ``on_start(to_run, skipped)`` and ``on_outcome(outcome)``
    feed a progress display.

    The first store error (a claim, a recording or a worker's checkpoint that cannot be written; a write lock held
    past ``lock_timeout`` seconds) stops the run with that :class:`StoreError`: the outcomes the executor already
    has are recorded first where the store still takes them, the walks in flight are stopped, and every walk not
    recorded keeps its checkpoint (under a local executor), from which ``--resume`` goes on.
    """
    started = time.perf_counter()
    with ResultStore.create(store_dir, lock_timeout=lock_timeout) as store:
        stored = store.case_runs()
        finished = store.finished_keys(retry_failed=retry_failed, retry_incomplete=retry_incomplete,
                                       retry_unverified=retry_unverified) - set(rerun)
        present = [case for case in suite.cases if case.key in finished]
        if present and not resume and not store.live_runs():
            raise RunRefused(
                f"{store.directory} already holds {len(present)} of the {len(suite.cases)} cases of this suite; "
                "pass --resume to run only the missing ones, or --store to write somewhere else"
            )
        _relabel(store, present)
        pending = [case for case in suite.cases if case.key not in finished]
        pending = sorted(pending, key=lambda case: case.n_nodes) if smallest_first else largest_first(pending)
        if 0 < len(pending) < executor.jobs and not getattr(executor, "fans_out", False):
            executor.jobs = len(pending)  # more workers would start only to idle (a resumed run's few cases)
        if getattr(executor, "local_files", False):  # its workers can write in the store's directory
            pending = [replace(case, checkpoint=str(store.directory / checkpoint_file(case.key))) for case in pending]
        run_id = store.start_run({"run_id": _run_stem(suite.name), "suite": suite.name,
                                  # absolute: `runs list` reads it from any directory to name the walks in flight
                                  "suite_path": str(Path(suite.path).resolve()), "suite_text": suite.text,
                                  "executor": executor.name, "jobs": executor.jobs,
                                  "cases_total": len(suite.cases), "cases_skipped": len(present),
                                  "started_at": _now(), "provenance": run_provenance(suite)})
        finished_at = None
        try:
            store.clean_leftovers(run_id)
            if on_start:
                on_start(len(pending), len(present))
            solved = failed = 0
            elsewhere: list[Case] = []

            def left(case: Case) -> None:
                elsewhere.append(case)
                if on_elsewhere:
                    on_elsewhere(case)

            with store.heartbeat(run_id):
                for outcome in executor.run(_claimed(store, run_id, pending, stored, left)):
                    if outcome.store_error:
                        raise StoreError(f"{store.directory}: the run stopped: {outcome.store_error}")
                    row = case_row(outcome, suite.name, run_id)
                    try:
                        recorded = store.record_case(row, outcome.files)
                    except BadRow as exc:  # the case's failure, not the store's
                        outcome = failed_outcome(outcome.case, "error", f"its result cannot be stored: {exc}",
                                                 outcome.wall_time_s)
                        row = case_row(outcome, suite.name, run_id)
                        recorded = store.record_case(row, outcome.files)
                    if not recorded:
                        outcome = replace(outcome, message=f"{outcome.message}; the complete walk stored before is "
                                                           "kept")
                    if outcome.case.checkpoint and not resumable(outcome, row):
                        _remove_checkpoint(store, outcome.case)  # its walk is recorded whole
                    solved += not outcome.failed
                    failed += outcome.failed
                    if on_outcome:
                        on_outcome(outcome)
            finished_at = _now()
        except StoreError:
            store.forget_run(run_id)  # the store failing: its claims die with this process (run_alive)
            raise
        except BaseException:
            with suppress(StoreError):  # the error on its way out is the one to report
                store.finish_run(run_id, None)  # a stopped run's claims go too; it stays unfinished
            raise
        store.finish_run(run_id, finished_at)
    return RunSummary(run_id, Path(store_dir), len(suite.cases), len(present), solved, failed,
                      time.perf_counter() - started, len(elsewhere))


def _remove_checkpoint(store: ResultStore, case: Case) -> None:
    try:
        remove_checkpoint(case.checkpoint)
    except OSError as error:
        raise StoreError(f"{store.directory}: cannot remove the checkpoint of case {case.key}, recorded "
                         f"({error.strerror or error})") from None


def run_provenance(suite) -> dict[str, Any]:
    """The run's provenance: this process's (:func:`gaitbench.run.provenance.provenance`) and the plugins that failed to
    load when the suite was loaded (``plugin_problems``, each ``{source, message}``; empty when all loaded)."""
    problems = [{"source": problem.source, "message": problem.message}
                for problem in getattr(suite, "plugin_problems", ())]
    return {**provenance(), "plugin_problems": problems}


def _claimed(store, run_id: str, cases: Iterable[Case], stored: dict[str, str],
             elsewhere: Callable[[Case], None]) -> Iterator[Case]:
    """The cases this run gets to solve, claimed one at a time as the executor takes them (so runs sharing the
    store split the work in largest-first order). A case a live run holds is looked at once more at the end, in
    case that run has died since; a case finished by another run is left to it."""
    held = []
    for case in cases:
        verdict = store.claim(case.key, run_id, stored.get(case.key))
        if verdict == "claimed":
            yield case
        elif verdict == "running":
            held.append(case)
        else:
            elsewhere(case)
    for case in held:
        if store.claim(case.key, run_id, stored.get(case.key)) == "claimed":
            yield case
        else:
            elsewhere(case)


def largest_first(cases: list[Case]) -> list[Case]:
    """The cases by N, largest first, in suite order among equal N: the order they are handed to the executor.

    A case's time grows steeply with N (decrease-and-conquer as N^2.4–2.6), and a pool handed the largest cases last
    idles at the end for up to the last case's time; largest first, the small cases fill the gaps at the end
    (longest-processing-time-first scheduling).
    """
    return sorted(cases, key=lambda case: -case.n_nodes)


def _run_stem(suite_name: str) -> str:
    """``<UTC time to the second>-<suite>``; the store adds ``-2``, ``-3``, ... for runs started within a second."""
    return f"{datetime.now(timezone.utc):%Y%m%d-%H%M%S}-{suite_name}"


class RunRefused(Exception):
    """A run that would mix with or overwrite stored results; the message says which flag to pass."""


def _relabel(store: ResultStore, present: list[Case]) -> None:
    """Give the stored cases a resumed suite skips the method labels it gives them now: a label is not part of a
    case's key, so a method renamed in the suite would otherwise split its column in the reports between the old
    name (the N stored before) and the new."""
    labels = {case.key: case.method for case in present}
    stored = {row["case_key"]: row["method"] for row in store.cases() if row["case_key"] in labels}
    renamed = {key: {"method": labels[key]} for key, method in stored.items() if method != labels[key]}
    if renamed:
        store.update_cases(renamed)


def _now() -> str:
    return datetime.now(timezone.utc).isoformat(timespec="seconds")
