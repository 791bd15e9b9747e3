"""The walk file (issue 25 item 5): one writer, one reader, a format version, and the options a walk was solved
under carried to whoever reads it (tracking, reports)."""

import json
import shutil
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from gaitbench.cli.main import main
from gaitbench.contracts import WalkProblem
from gaitbench.control.reference import load_reference
from gaitbench.control.tracking import track_walk
from gaitbench.plugins import load_registry
from gaitbench.problem.gait_problem import ProblemOptions
from gaitbench.solve.one_phase import OnePhase
from gaitbench.solve.walk_file import WALK_FORMAT_VERSION, WalkFileError, load_walk, read_walk, write_walk
from gaitbench_plugins.solvers.ipopt import Ipopt

REGISTRY = load_registry()
STORED = Path(__file__).parent / "data" / "unversioned-walk"
"""A walk of the thesis-all sweep (case 0cc039472f37dbc4: downward slope, One Phase, Hermite–Simpson, N = 10), written
before the format was versioned."""


@pytest.fixture(scope="module")
def walk():
    experiment = REGISTRY.create("experiment", "forward")
    options = replace(ProblemOptions(limits=experiment.limits), clearance="chord")
    dmoc = REGISTRY.create("transcription", "dmoc")
    result = OnePhase().solve(WalkProblem(experiment, dmoc, Ipopt(), 8, steps=1, options=options))
    assert result.complete, result.failure
    result.strategy_options = {"phase": "second"}
    return result


def test_a_walk_comes_back_as_it_was_written(walk, tmp_path):
    path = write_walk(walk, tmp_path / "walk.json")
    stored = read_walk(path)
    assert stored.version == WALK_FORMAT_VERSION == json.loads(path.read_text())["format_version"]
    assert stored.header["strategy"] == "one-phase" and stored.strategy_options == {"phase": "second"}
    loaded, experiment = load_walk(path, REGISTRY)
    assert stored.problem_options(experiment) == replace(ProblemOptions(limits=experiment.limits), clearance="chord")
    assert (loaded.experiment, loaded.strategy_options, loaded.problem_options) == (
        "forward", {"phase": "second"}, walk.problem_options)
    for original, copy in zip(walk.steps, loaded.steps, strict=True):
        np.testing.assert_array_equal(copy.trajectory.q, original.trajectory.q)
        np.testing.assert_array_equal(copy.trajectory.tau, original.trajectory.tau)
        assert copy.verification.cot == original.verification.cot
        np.testing.assert_allclose(copy.next_state, original.next_state, atol=1e-12)


def test_a_file_from_before_the_format_was_versioned_is_read_with_the_default_options(tmp_path):
    copy = tmp_path / "walk.json"
    shutil.copy(STORED / "walk.json", copy)
    shutil.copy(STORED / "walk.npz", tmp_path / "walk.npz")
    stored = read_walk(copy)
    assert stored.version is None and "format_version" not in stored.header
    assert stored.experiment_options == {} and stored.strategy_options == {}
    walk, experiment = load_walk(copy, REGISTRY)
    assert experiment.name == "downward-slope" and walk.experiment_options == {}
    assert stored.problem_options(experiment) == ProblemOptions(limits=experiment.limits)
    assert len(walk.steps) == len(stored.steps) and all(step.solved for step in walk.steps)
    assert [step.verification.cot for step in walk.steps] == [step["cot"] for step in stored.steps]


@pytest.mark.parametrize("version", [WALK_FORMAT_VERSION + 1, 0, "1", True])
def test_an_unknown_version_is_refused_naming_the_file_and_the_version(walk, tmp_path, version):
    path = write_walk(walk, tmp_path / "future.json")
    path.write_text(json.dumps(json.loads(path.read_text()) | {"format_version": version}))
    with pytest.raises(WalkFileError, match=rf"future\.json: walk file format version {version!r} is unknown"):
        read_walk(path)
    refused = CliRunner().invoke(main, ["track", str(path)])
    assert refused.exit_code == 2 and f"format version {version!r} is unknown" in refused.stderr


def test_an_experiment_that_fails_to_build_here_is_the_environment_s_fault_not_the_file_s(walk, tmp_path,
                                                                                           monkeypatch):
    """A plugin that raises while building (compass-gait's shooting that does not converge, a licence missing) is
    no broken walk file: ``verify --store`` must not record the walk as unreadable."""
    from gaitbench.plugins import PluginBuildError, PluginRegistry

    path = write_walk(walk, tmp_path / "walk.json")

    def fails(self, kind, name, *args, **kwargs):
        raise PluginBuildError(f"cannot build {kind} {name!r} (from here): RuntimeError: no licence")

    monkeypatch.setattr(PluginRegistry, "create", fails)
    with pytest.raises(PluginBuildError, match="no licence"):
        read_walk(path).result(REGISTRY)


def test_a_walk_solved_with_options_is_tracked_on_that_experiment(tmp_path):
    """`solve --experiment-option ... -p ...` writes the options into the file, and `track` rebuilds that
    experiment: the energetics biped with a heavier leg, not the default one."""
    out = tmp_path / "walk.json"
    solved = CliRunner().invoke(main, ["solve", "-e", "energetics", "--experiment-option", "mass_ratio=2",
                                       "--experiment-option", "steps=1", "-t", "dmoc", "--N", "8",
                                       "-p", "clearance=off", "-x", "phase=second", "--out", str(out)])
    assert solved.exit_code == 0, solved.output
    stored = read_walk(out)
    assert stored.experiment_options == {"mass_ratio": 2, "steps": 1}
    assert stored.strategy_options == {"phase": "second"}
    assert stored.header["problem_options"]["clearance"] == "off"
    chosen = REGISTRY.create("experiment", "energetics", mass_ratio=2, steps=1)
    reference = load_reference(out, REGISTRY)
    assert reference.experiment.robot == chosen.robot != REGISTRY.create("experiment", "energetics").robot
    assert reference.walk.problem_options["clearance"] == "off"
    tracked = track_walk(out, "thesis", "ideal", "none", registry=REGISTRY)
    assert tracked.walk["experiment_options"] == {"mass_ratio": 2, "steps": 1}
    assert not tracked.fell
    assert tracked.acot_reference == pytest.approx(stored.header["acot"], rel=1e-12)
    command = CliRunner().invoke(main, ["track", str(out), "--observer", "ideal", "--disturbance", "none"])
    assert command.exit_code == 0, command.output


@pytest.mark.parametrize("trajectories", ["../../../../etc/passwd", "/etc/passwd", "..", 7])
def test_trajectories_outside_the_walk_files_directory_are_refused(walk, tmp_path, trajectories):
    path = write_walk(walk, tmp_path / "cases" / "walk.json")
    path.write_text(json.dumps(json.loads(path.read_text()) | {"trajectories": trajectories}))
    with pytest.raises(WalkFileError, match=r"walk\.json: trajectories: .*only a file beside it|expected the name"):
        read_walk(path)
    refused = CliRunner().invoke(main, ["track", str(path)])
    assert refused.exit_code == 2, refused.output
    assert "trajectories:" in refused.stderr and "Traceback" not in refused.output


def _npz_broken(path: Path, how: str) -> None:
    """The walk's NPZ at ``path`` cut short, or rewritten with one array made non-finite or the wrong shape."""
    if how == "truncated":
        data = path.read_bytes()
        path.write_bytes(data[: len(data) // 2])
        return
    if how == "junk":  # NumPy reads what is no zip as a pickle, and advised loading it unsafely
        path.write_bytes(b"junk")
        return
    with np.load(path) as stored:
        arrays = {key: stored[key] for key in stored.files}
    if how == "nan":
        arrays["step01_dq"] = arrays["step01_dq"].copy()
        arrays["step01_dq"][3, 1] = np.nan
    elif how == "shape":
        arrays["step01_q"] = arrays["step01_q"][:-1]
    elif how == "missing":
        del arrays["step01_tau"]
    np.savez_compressed(path, **arrays)


@pytest.mark.parametrize(("how", "said"), [
    ("truncated", r"walk\.npz: unreadable trajectories \((not an NPZ archive|BadZipFile|EOFError|OSError)"),
    ("junk", r"walk\.npz: unreadable trajectories \(not an NPZ archive\)"),
    ("nan", r"walk\.npz: step01_dq holds 1 non-finite values"),
    ("shape", r"walk\.npz: step01's arrays do not fit together \(t \(\d+,\), q \(\d+, 2\)"),
    ("missing", r"walk\.npz: step01 lacks step01_tau;"),
])
def test_a_broken_npz_beside_a_walk_file_is_one_line_and_exit_2(walk, tmp_path, how, said):
    path = write_walk(walk, tmp_path / "walk.json")
    _npz_broken(path.with_suffix(".npz"), how)
    with pytest.raises(WalkFileError, match=said):
        read_walk(path)
    refused = CliRunner().invoke(main, ["track", str(path)])
    assert refused.exit_code == 2, refused.output
    assert "Traceback" not in refused.output
    lines = [line for line in refused.stderr.splitlines() if line.strip() and not line.startswith(("Usage:", "Try "))]
    assert any("walk.npz" in line for line in lines)


def test_every_committed_walk_file_passes_the_npz_checks(tmp_path, monkeypatch):
    """The checks refuse nothing gaitbench wrote: every walk of the committed packs whose trajectories they hold
    reads (the others are headers only: gaitbench.run.pack_format.left_out), the pack inside a sweep's carry file
    (benchmarks/snapshot_store.py) too."""
    import tarfile

    from gaitbench.run.pack_cache import unpacked
    from gaitbench.run.pack_format import left_out

    monkeypatch.delenv("GAITBENCH_CACHE", raising=False)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    packs = []
    for path in sorted((Path(__file__).parents[1] / "benchmarks/results").glob("*.tar.xz")):
        if path.name.endswith(".carry.tar.xz"):  # a carry holds its store's pack as store.tar.xz
            with tarfile.open(path, mode="r:xz") as carry:
                carry.extract("store.tar.xz", tmp_path / path.name.removesuffix(".tar.xz"))
            path = tmp_path / path.name.removesuffix(".tar.xz") / "store.tar.xz"
        packs.append(path)
    read = 0
    for store in map(unpacked, packs):
        for path in sorted(store.glob("cases/*/walk.json")):
            if left_out(store, path.relative_to(store).as_posix()) is None:
                read_walk(path)
                read += 1
    assert len(packs) >= 1 and read >= 4
