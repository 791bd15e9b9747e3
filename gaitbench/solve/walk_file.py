"""The walk file: one solved walk on disk, and the only code that writes or parses one.

A walk file is a JSON header with one record per step (:meth:`WalkResult.as_dict`) and, beside it, an NPZ of the
step trajectories (``stepNN_t``, ``_q``, ``_dq``, ``_tau``, ``_tau_t``, ``_push_off``; a polished step's own under
``stepNN_polished_*``), named in the header under ``trajectories``. ``gaitbench solve --out`` and the suite runner
write it; ``gaitbench track`` and the reports read it.

Versions (``format_version`` in the header):

- 1: the header names everything the walk was solved under, so a reader rebuilds the same problem: the experiment
  and its options, the problem options, the strategy and its options.
- 2: decrease and conquer's patchworks are stored as their transcription's interpolant and read back through it
  (version 1 stored them as nodes with linear rates, and is read that way); the header also holds the objective's
  options (``objective_options``), the claimed ACOT, the verified flag and the whole-walk verification.
- none: files written before the format was versioned. They hold no experiment or strategy options, and are read
  with the defaults, as they always were.

A file with a version this gaitbench does not know is refused, naming the file and the version.
"""

from __future__ import annotations

import ast
import json
import math
import re
import zipfile
import zlib
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import asdict, dataclass, fields, replace
from pathlib import Path
from typing import Any

import numpy as np

from gaitbench.acceptance import StepVerification
from gaitbench.model.experiment import Experiment, Limits
from gaitbench.model.mechanics import BipedModel
from gaitbench.plugins import PluginBuildError, PluginRegistry, UnknownPluginError, load_registry
from gaitbench.problem.gait_problem import ProblemOptions, StepData, StepStructure, legs_to_roles
from gaitbench.problem.objective import NET_POWER, Objective
from gaitbench.problem.trajectory import Seed, StepTrajectory, nodal_trajectory
from gaitbench.problem.transcription import TranscribedStep
from gaitbench.solve.walk import next_step_state
from gaitbench.walk_types import StepOutcome, WalkResult

WALK_FORMAT_VERSION = 2
"""The version :func:`write_walk` writes; :func:`read_walk` reads it and every older one."""

POLISHED = "polished"
"""The middle of the NPZ names of a polished step's arrays: ``step01_polished_q`` beside ``step01_q``."""

REQUIRED_KEYS = ("experiment", "transcription", "solver", "strategy", "N", "phase", "steps")


class WalkFileError(ValueError):
    """A walk file that cannot be read (missing, unreadable, incomplete, or of an unknown version); the message names
    the file and the fix."""


def write_walk(walk: WalkResult, path: str | Path) -> Path:
    """Write ``walk`` as JSON at ``path``, its trajectories beside it as NPZ (named in the JSON); returns ``path``."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    arrays = {}
    for step in walk.steps:
        prefix = f"step{step.index:02d}"
        if step.trajectory is not None:
            arrays |= _trajectory_arrays(step.trajectory, prefix)
        if step.polished is not None and step.polished.trajectory is not None:
            arrays |= _trajectory_arrays(step.polished.trajectory, f"{prefix}_{POLISHED}")
    header = {"format_version": WALK_FORMAT_VERSION, **walk.as_dict()}
    if arrays:
        npz = path.with_suffix(".npz")
        np.savez_compressed(npz, **arrays)
        header["trajectories"] = npz.name
    path.write_text(json.dumps(header, indent=2, default=_json_default))
    return path


def _trajectory_arrays(trajectory: StepTrajectory, prefix: str) -> dict[str, np.ndarray]:
    return {
        f"{prefix}_t": trajectory.times,
        f"{prefix}_q": trajectory.q,
        f"{prefix}_dq": trajectory.dq,
        f"{prefix}_tau": trajectory.tau,
        f"{prefix}_tau_t": trajectory.control_times,
        f"{prefix}_push_off": np.array([trajectory.push_off]),
    }


def _json_default(value: Any) -> Any:
    if isinstance(value, (np.floating, np.integer)):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    raise TypeError(f"cannot serialize {type(value).__name__}")


@dataclass(frozen=True)
class WalkFile:
    """A walk file as stored: its header, each step's record, and the trajectories' arrays by NPZ name.

    The reports draw from the nodal arrays; :meth:`result` rebuilds the :class:`WalkResult`, with each step's
    trajectory interpolated by its transcription, for tracking.
    """

    path: Path
    version: int | None
    """``format_version``; None for a file written before the format was versioned."""
    header: dict[str, Any]
    arrays: dict[str, np.ndarray]

    @property
    def steps(self) -> list[dict[str, Any]]:
        return self.header["steps"]

    @property
    def acot_is_claimed(self) -> bool:
        """Whether the header's ``acot`` is decrease and conquer's claimed patchwork ACOT rather than a verified one:
        a file before version 2 that holds patchworks, written before the claim had a field of its own."""
        return (self.version or 0) < 2 and any(_patchwork(step) for step in self.steps)

    @property
    def experiment_options(self) -> dict[str, Any]:
        return dict(self.header.get("experiment_options") or {})

    @property
    def strategy_options(self) -> dict[str, Any]:
        return dict(self.header.get("strategy_options") or {})

    @property
    def transcription_options(self) -> dict[str, Any]:
        """The transcription's options (empty in files that predate their record: the suite's row has them)."""
        return dict(self.header.get("transcription_options") or {})

    def step_arrays(self, index: int, name: str = "") -> dict[str, np.ndarray]:
        """Step ``index``'s arrays (``name``: ``polished`` for its polished trajectory's), keyed ``t``, ``q``, ...;
        empty when the file holds none."""
        prefix = f"step{index:02d}" + (f"_{name}" if name else "") + "_"
        return {key[len(prefix):]: value for key, value in self.arrays.items() if key.startswith(prefix)
                and (name or not key[len(prefix):].startswith(f"{POLISHED}_"))}

    def experiment(self, registry: PluginRegistry | None = None,
                   unrecorded_options: dict[str, Any] | None = None) -> Experiment:
        """The experiment the walk was solved for, built with its options. A file written before the format was
        versioned records none: it is built with ``unrecorded_options`` where the caller knows them (a store row's),
        else with the defaults."""
        registry = registry or load_registry()
        from_caller = self.version is None and unrecorded_options is not None
        options = dict(unrecorded_options) if from_caller else self.experiment_options
        return registry.create("experiment", self.header["experiment"], **options)

    def objective(self, registry: PluginRegistry | None = None) -> Objective:
        """The objective the walk's COTs are measured in: from its name and options, or, in a file written before
        the options were recorded, from its description (``name(option=value, ...)``)."""
        registry = registry or load_registry()
        described = str(self.header.get("objective") or NET_POWER.name)
        name, _, listed = described.partition("(")
        options = self.header.get("objective_options")
        if options is None:
            options = {key.strip(): _literal(value.strip()) for key, _, value in
                       (item.partition("=") for item in listed.rstrip(")").split(",") if item.strip())}
        try:
            return registry.create("objective", name, **options)
        except (UnknownPluginError, PluginBuildError):
            raise  # the plugin is not installed here, or fails here: the file is fine, the environment is not
        except (LookupError, TypeError, ValueError) as exc:
            raise WalkFileError(f"{self.path}: objective {described!r} cannot be rebuilt ({exc})") from None

    def problem_options(self, experiment: Experiment) -> ProblemOptions:
        """The problem options the walk was solved under; an unversioned file's are taken as the defaults, as they
        always were."""
        stored = self.header.get("problem_options")
        if self.version is None or not stored:
            return ProblemOptions(limits=experiment.limits)
        known = {item.name for item in fields(ProblemOptions)}
        unknown = sorted(set(stored) - known)
        if unknown:
            raise WalkFileError(f"{self.path}: unknown problem options {', '.join(unknown)}")
        limits = dict(stored.get("limits") or {})
        if "angle_bounds" in limits:
            limits["angle_bounds"] = tuple(limits["angle_bounds"])
        return replace(ProblemOptions(limits=Limits(**limits)), **{k: v for k, v in stored.items() if k != "limits"})

    def result(self, registry: PluginRegistry | None = None) -> tuple[WalkResult, Experiment]:
        """The walk's solved steps (a prefix of the walk), each trajectory rebuilt with its transcription's
        interpolant from the stored nodal values, and the experiment it was solved for."""
        rerun = _rerun(self.path)
        if "trajectories" not in self.header:
            if not any(step.get("cot") is not None for step in self.header.get("steps") or []):
                failure = self.header.get("failure")
                raise WalkFileError(f"{self.path}: the walk has no solved step, nothing to rebuild"
                                    + (f" ({failure})" if failure else ""))
            raise WalkFileError(f"{self.path}: holds no trajectories (saved without its NPZ); {rerun}")
        registry = registry or load_registry()
        data = self.header
        with _field(self.path, "experiment_options"):
            experiment = self.experiment(registry)
        with _field(self.path, "problem_options"):
            options = self.problem_options(experiment)
        with _field(self.path, "transcription_options"):
            transcription = registry.create("transcription", data["transcription"], **self.transcription_options)
        with _field(self.path, "N"):
            n_nodes = data["N"]
            if not (isinstance(n_nodes, int) and not isinstance(n_nodes, bool) and n_nodes >= 3):
                raise ValueError(f"expected a whole number of nodes ≥ 3, found {n_nodes!r}")
        phase = data["phase"]
        if phase not in ("first", "second"):
            raise WalkFileError(f"{self.path}: phase: expected 'first' or 'second', found {phase!r}")
        records = _step_records(self.path, data.get("steps"))
        with _field(self.path, "problem_options"):  # the options are checked as the step's structure is made
            built = transcription.build(StepStructure(phase, n_nodes, options))
        model = BipedModel(experiment.robot, 4 if phase == "second" else 2)
        walk = WalkResult(experiment=data["experiment"], transcription=data["transcription"], solver=data["solver"],
                          strategy=data["strategy"], N=n_nodes, phase=phase,
                          requested_steps=int(data.get("requested_steps", len(records))),
                          wall_time_s=float(data.get("wall_time_s", 0.0)),
                          strategy_details=data.get("strategy_details", {}),
                          problem_options=asdict(options),
                          objective=data.get("objective", WalkResult.objective),
                          objective_options=dict(data.get("objective_options") or {}),
                          experiment_options=self.experiment_options, strategy_options=self.strategy_options,
                          transcription_options=self.transcription_options)
        npz = self.path.parent / data["trajectories"]
        with _field(self.path, "steps"):  # what the records checked above leave: figures that are no numbers
            for i, step in enumerate(records):
                arrays = self.step_arrays(step["index"])
                if "q" not in arrays or step.get("cot") is None:
                    break
                _check_nodes(npz, step, arrays, n_nodes, f"steps[{i}]")
                try:
                    if _patchwork(step) and (self.version or 0) < 2:  # stored as nodes
                        nodes = (np.asarray(arrays[key], dtype=float) for key in ("t", "q", "dq", "tau"))
                        trajectory = nodal_trajectory(*nodes, float(np.asarray(arrays["push_off"]).ravel()[0]),
                                                      int(step["stance"]))
                    else:
                        trajectory = _rebuild_trajectory(built, data["transcription"], experiment, step, arrays)
                except KeyError as exc:
                    raise WalkFileError(f"{npz}: step {step['index']} lacks {exc.args[0]!r}; {rerun}") from None
                outcome = StepOutcome(int(step["index"]), int(step["stance"]), step["status"], step["message"], None,
                                      trajectory, _verification(step), next_state=next_step_state(model, trajectory),
                                      details=step.get("details") or {})
                polished = outcome.details.get(POLISHED)
                own = self.step_arrays(outcome.index, POLISHED)
                if "q" in own and isinstance(polished, dict) and polished.get("cot") is not None:
                    _check_nodes(npz, step, own, n_nodes, f"steps[{i}].details.polished")
                    try:
                        polished_trajectory = _rebuild_trajectory(built, data["transcription"], experiment, step, own)
                    except KeyError as exc:
                        raise WalkFileError(f"{npz}: step {step['index']} lacks {POLISHED}_{exc.args[0]}; "
                                            f"{rerun}") from None
                    outcome.polished = StepOutcome(outcome.index, outcome.stance, polished["status"], "polished", None,
                                                   polished_trajectory, _verification(polished),
                                                   next_state=next_step_state(model, polished_trajectory))
                walk.steps.append(outcome)
        if not walk.steps:
            raise WalkFileError(f"{self.path}: no solved step ({data.get('failure')}); solve the walk again")
        return walk, experiment


def _patchwork(step: dict[str, Any]) -> bool:
    """Whether a step's record is one of decrease and conquer's patchworks (its details name the chosen sections)."""
    return "chosen" in (step.get("details") or {})


def read_walk(path: str | Path) -> WalkFile:
    """Parse the walk file at ``path`` and the NPZ beside it.

    Raises :class:`WalkFileError` naming the file and the fix when the JSON or its NPZ is missing, unreadable or not
    a walk, or when its format version is one this gaitbench does not know.
    """
    path = Path(path)
    rerun = _rerun(path)
    if not path.is_file():
        raise WalkFileError(f"{path}: no such result file; {rerun}")
    try:
        header = json.loads(path.read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise WalkFileError(f"{path}: not a readable walk result ({exc}); {rerun}") from None
    if not isinstance(header, dict):
        header = {}
    version = header.get("format_version")
    if version is not None and (isinstance(version, bool) or version not in range(1, WALK_FORMAT_VERSION + 1)):
        raise WalkFileError(f"{path}: walk file format version {version!r} is unknown to this gaitbench, which reads "
                            f"versions up to {WALK_FORMAT_VERSION}; read it with the gaitbench that wrote it, or "
                            f"{rerun}")
    missing = [key for key in REQUIRED_KEYS if key not in header]
    if missing:
        raise WalkFileError(f"{path}: not a walk result, missing {', '.join(missing)}; {rerun}")
    arrays: dict[str, np.ndarray] = {}
    if "trajectories" in header:
        try:
            npz = beside(path, header["trajectories"])
        except ValueError as exc:
            raise WalkFileError(f"{path}: trajectories: {exc}; {rerun}") from None
        if not npz.is_file():
            raise WalkFileError(f"{path}: its trajectories file {npz} is missing; keep the .npz beside the JSON or "
                                f"{rerun}")
        arrays = read_arrays(npz, rerun)
        problem = trajectory_problem(arrays)
        if problem:
            raise WalkFileError(f"{npz}: {problem}; {rerun}")
    return WalkFile(path, version, header, arrays)


def beside(path: Path, name: object) -> Path:
    """The file ``name`` (from the header of the file at ``path``) in ``path``'s directory, where the writers put
    it. Anything else (another directory, ``../../etc/passwd``, an absolute path, not a name) is refused with a
    ``ValueError``: a walk file from elsewhere must not make gaitbench open files outside its directory."""
    if not isinstance(name, str) or not name:
        raise ValueError(f"expected the name of a file beside it, got {name!r}")
    directory = path.parent.resolve()
    target = (directory / name).resolve()
    if not target.is_relative_to(directory) or target == directory:
        raise ValueError(f"{name!r} is outside the file's directory {directory}; only a file beside it is read")
    return target


def read_arrays(npz: Path, fix: str) -> dict[str, np.ndarray]:
    """Every array of the NPZ at ``npz``; a file that is not a whole NPZ of plain arrays (truncated, not a zip,
    pickled objects) is a :class:`WalkFileError` naming it and ``fix``."""
    if npz.is_file() and not zipfile.is_zipfile(npz):  # else NumPy would read it as a pickle, and advise so
        raise WalkFileError(f"{npz}: unreadable trajectories (not an NPZ archive); {fix}")
    try:
        with np.load(npz) as stored:
            return {key: stored[key] for key in stored.files}
    except (OSError, ValueError, EOFError, KeyError, zipfile.BadZipFile, zlib.error) as exc:
        why = "arrays of pickled objects" if "pickled" in str(exc) else f"{type(exc).__name__}: {exc}"
        raise WalkFileError(f"{npz}: unreadable trajectories ({why}); {fix}") from None


TRAJECTORY_ARRAYS = ("t", "q", "dq", "tau", "tau_t", "push_off")
"""The arrays of each stored trajectory, ``stepNN_<name>`` (``stepNN_polished_<name>`` for a polished one)."""

_TRAJECTORY_KEY = re.compile(rf"(step\d+(?:_{POLISHED})?)_({'|'.join(sorted(TRAJECTORY_ARRAYS, key=len)[::-1])})")


def trajectory_problem(arrays: dict[str, np.ndarray]) -> str | None:
    """What is wrong with a walk NPZ's trajectories, or None: each one whole (all of :data:`TRAJECTORY_ARRAYS`),
    finite numbers, ``t`` increasing, ``q`` and ``dq`` one row of 2 per time, ``tau`` one row of 2 per control time
    (one per node, or per interval), and one push-off."""
    groups: dict[str, dict[str, np.ndarray]] = {}
    for key, value in arrays.items():
        match = _TRAJECTORY_KEY.fullmatch(key)
        if match:
            groups.setdefault(match.group(1), {})[match.group(2)] = value
    for prefix, group in sorted(groups.items()):
        missing = [name for name in TRAJECTORY_ARRAYS if name not in group]
        if missing:
            return f"{prefix} lacks {', '.join(f'{prefix}_{name}' for name in missing)}"
        for name, value in group.items():
            if not np.issubdtype(value.dtype, np.number) or np.issubdtype(value.dtype, np.complexfloating):
                return f"{prefix}_{name} holds {value.dtype} values, not real numbers"
            if not np.all(np.isfinite(value)):
                return f"{prefix}_{name} holds {int(np.size(value) - np.isfinite(value).sum())} non-finite values"
        n, m = len(group["t"].reshape(-1)), len(group["tau_t"].reshape(-1))
        expected = {"t": (n,), "q": (n, 2), "dq": (n, 2), "tau_t": (m,), "tau": (m, 2), "push_off": (1,)}
        if n < 2 or m not in (n - 1, n) or any(group[name].shape != expected[name] for name in TRAJECTORY_ARRAYS):
            shapes = ", ".join(f"{name} {group[name].shape}" for name in TRAJECTORY_ARRAYS)
            return (f"{prefix}'s arrays do not fit together ({shapes}; expected t (n,) with n >= 2, q and dq (n, 2), "
                    "tau_t (m,) and tau (m, 2) with m = n or n - 1, push_off (1,))")
        if np.any(np.diff(group["t"]) <= 0):
            return f"{prefix}_t is not increasing"
    return None


def load_walk(path: str | Path, registry: PluginRegistry | None = None) -> tuple[WalkResult, Experiment]:
    """The walk in the file at ``path``, ready to track, and its experiment (:meth:`WalkFile.result`)."""
    return read_walk(path).result(registry)


def _literal(text: str) -> Any:
    """An option value as an objective's description prints it (``True``, ``0.25``, ``name``)."""
    try:
        return ast.literal_eval(text)
    except (ValueError, SyntaxError):
        return text


@contextmanager
def _field(path: Path, name: str) -> Iterator[None]:
    """A header field the walk cannot be rebuilt from, as a :class:`WalkFileError` naming it (a plugin this
    environment lacks is not the file's fault, and passes)."""
    try:
        yield
    except (UnknownPluginError, PluginBuildError, WalkFileError):  # the first two: the environment's, not the file's
        raise
    except (TypeError, ValueError, KeyError) as exc:
        raise WalkFileError(f"{path}: {name}: {exc}") from None


def _step_records(path: Path, steps: Any) -> list[dict]:
    """The header's step records, each checked for the fields the walk is rebuilt from."""
    if not isinstance(steps, list):
        raise WalkFileError(f"{path}: steps: expected an array of step records, found {_json_kind(steps)}")
    for i, step in enumerate(steps):
        if not isinstance(step, dict):
            raise WalkFileError(f"{path}: steps[{i}]: expected a step record (an object), found {_json_kind(step)}")
        for key, kind, allowed in (("index", int, None), ("stance", int, (1, 2)), ("status", str, None),
                                   ("message", str, None)):
            value = step.get(key)
            if not isinstance(value, kind) or isinstance(value, bool) or (allowed and value not in allowed):
                expected = "text" if kind is str else "1 or 2" if allowed else "a whole number"
                raise WalkFileError(f"{path}: steps[{i}].{key}: expected {expected}, found {value!r}")
    return steps


def _check_nodes(npz: Path, step: dict, arrays: dict[str, np.ndarray], n_nodes: int, where: str) -> None:
    """A step's stored trajectory has the walk's N nodes: a file whose header and NPZ disagree is refused, not read as
    a motion that fails its dynamics."""
    nodes = len(np.asarray(arrays["q"]))
    if nodes != n_nodes:
        raise WalkFileError(f"{npz}: {where} (step {step['index']}): its trajectory has {nodes} nodes, the walk's "
                            f"N is {n_nodes}; the walk file and its NPZ are of different walks")


def _json_kind(value: Any) -> str:
    return {type(None): "null", bool: "true/false", str: "text", list: "an array", dict: "an object"}.get(
        type(value), type(value).__name__)


def _rerun(path: Path) -> str:
    return f"write it with `gaitbench solve ... --out {path}`"


def _verification(step: dict) -> StepVerification:
    """A step's stored verification (a step record, or its ``details["polished"]``); figures a file written before
    they were recorded lacks are NaN (None for the objective's comparison and the other constraints')."""
    figures = {key: float(step[key]) if step.get(key) is not None else math.nan for key in (
        "max_defect", "resim_error", "resim_max_error", "hip_energy", "push_off_energy", "cot")}
    compared = {key: step.get(key) for key in ("objective_cot", "objective_gap", "objective_agrees", "violated")}
    violation = step.get("max_violation")
    return StepVerification(**figures, **compared, max_violation=None if violation is None else float(violation))


def _rebuild_trajectory(built: TranscribedStep, transcription: str, experiment: Experiment, step: dict,
                        arrays: dict[str, np.ndarray]) -> StepTrajectory:
    """The transcription's interpolant of stored nodal values: its variables are sampled from a seed that returns
    exactly the stored values where the transcription samples (nodes for states, the control grid for torques)."""
    index, stance = int(step["index"]), int(step["stance"])
    times, q, dq, tau, tau_t = (np.asarray(arrays[key], dtype=float) for key in ("t", "q", "dq", "tau", "tau_t"))
    push_off = float(np.asarray(arrays["push_off"]).ravel()[0])
    h = float(times[1] - times[0])
    geometry = experiment.terrain.steps[index - 1]
    data = StepData(experiment.robot, stance, np.r_[q[0], dq[0]], geometry.D, geometry.theta, h)
    p = data.parameter_vector()
    roles = [legs_to_roles(values, stance) for values in (q, dq, tau)]
    seed = _nodal_seed(times, *roles, tau_t)
    discretization = built.discretization
    interpolant = discretization.interpolant(discretization.guess(seed, p), p)
    trajectory = StepTrajectory(times=times, q=q, dq=dq, tau=tau, control_times=tau_t, push_off=push_off,
                                stance=stance, _interpolant=interpolant)
    mismatch = max(float(np.max(np.abs(np.r_[trajectory.state(t)] - np.r_[q[k], dq[k]])))
                   for k, t in enumerate(times))
    if mismatch > 1e-8 * (1 + float(np.max(np.abs(dq)))):
        raise WalkFileError(f"step {index}: the stored nodes do not fit the {transcription} transcription's "
                            f"interpolant (off by {mismatch:.1e}); was it saved by another transcription?")
    return trajectory


def _nodal_seed(times: np.ndarray, q: np.ndarray, dq: np.ndarray, tau: np.ndarray, tau_t: np.ndarray) -> Seed:
    """Stored values as a :data:`~gaitbench.problem.trajectory.Seed`: exact at nodes; torques linear between
    control times when there is one per node, constant per interval when there is one per interval (DMOC)."""
    h = float(times[1] - times[0])
    per_interval = len(tau_t) == len(times) - 1

    def seed(t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        k = int(round(t / h))
        if abs(t - k * h) <= 1e-9 * h and 0 <= k < len(times):
            angles, rates = q[k], dq[k]
        else:
            angles = np.array([np.interp(t, times, q[:, j]) for j in range(2)])
            rates = np.array([np.interp(t, times, dq[:, j]) for j in range(2)])
        if per_interval:
            torque = tau[int(np.clip(np.floor(t / h), 0, len(tau_t) - 1))]
        else:
            torque = np.array([np.interp(t, tau_t, tau[:, j]) for j in range(2)])
        return angles, rates, torque

    return seed
