"""The main job (`make run`): the demo suite, its result table and report, and runs that never touch tracked files."""

from __future__ import annotations

import re
import shutil
import subprocess
import textwrap
from pathlib import Path

import pytest
from click.testing import CliRunner

from gaitbench.cli.main import main
from gaitbench.cli.report_command import default_report_dir
from gaitbench.plugins import load_registry
from gaitbench.run.suite import load_suite

ROOT = Path(__file__).resolve().parent.parent
TERRAINS = {"forward", "downward-slope", "upward-slope", "stairs"}
GIT = shutil.which("git")


def _in_git_checkout() -> bool:
    return GIT is not None and subprocess.run([GIT, "-C", str(ROOT), "rev-parse", "--git-dir"],
                                              capture_output=True).returncode == 0


needs_git = pytest.mark.skipif(not _in_git_checkout(), reason="needs git and a git checkout of gaitbench")


def test_demo_suite_walks_the_four_terrains_whole_at_small_n():
    suite = load_suite(ROOT / "suites" / "demo.toml", load_registry())
    assert {case.experiment.name for case in suite.cases} == TERRAINS
    assert set(suite.methods) == {"OP-DC", "OP-DM"}
    assert len(suite.cases) == 8 and {case.n_nodes for case in suite.cases} == {30}
    assert all(case.steps is None for case in suite.cases)  # whole walks: every step of each experiment
    assert {case.strategy.name for case in suite.cases} == {"one-phase"}
    assert suite.tracking is None  # the minute goes to the walks and the report


def test_make_run_runs_the_demo_suite_and_resumes():
    """`make run` is the README's main job: it solves the demo suite (its report is written by `gaitbench run`);
    with --resume a second `make run` reuses the stored walks instead of refusing a store that holds them."""
    makefile = (ROOT / "Makefile").read_text()
    recipe = re.search(r"^run:.*\n((?:\t.*\n)+)", makefile, re.MULTILINE)
    assert recipe, "Makefile has no run target"
    commands = recipe.group(1)
    assert "gaitbench run suites/demo.toml" in commands and "--resume" in commands
    assert "--no-report" not in commands


@needs_git
def test_default_outputs_are_ignored_by_git():
    """Walks (`solve --out out/...`), stores (a suite's results/<name>) and reports (reports/<store name>)."""
    report = default_report_dir(ROOT / "results" / "demo") / "index.html"
    paths = ["out/fw.json", "results/demo/results.sqlite", str(report)]
    checked = subprocess.run([GIT, "-C", str(ROOT), "check-ignore", "--no-index", *paths], capture_output=True,
                             text=True)
    assert sorted(checked.stdout.split()) == sorted(paths), checked.stdout
    tracked = subprocess.run([GIT, "-C", str(ROOT), "ls-files", "out", "results", "reports"], capture_output=True,
                             text=True, check=True).stdout
    assert tracked == "", f"tracked files where runs write: {tracked}"


TINY_SUITE = """
[suite]
name = "tiny"
steps = 1
time_limit_s = 120

[sweep]
experiments = ["forward"]
N = [8]

[[method]]
label = "OP-DC"
transcription = "hermite-simpson"
solver = "ipopt"
strategy = "one-phase"
"""


@needs_git
def test_running_a_suite_twice_leaves_tracked_files_alone(tmp_path, monkeypatch):
    """A copy of the tracked files (as committed, with this tree's .gitignore) runs a one-case suite the way
    `make run` does, twice: both runs print the result table and the report's path, and `git status` stays
    clean."""
    copy = tmp_path / "clone"
    files = subprocess.run([GIT, "-C", str(ROOT), "ls-files", "-z"], capture_output=True, check=True).stdout
    for name in filter(None, files.decode().split("\0")):
        source = ROOT / name
        if source.is_file():
            (copy / name).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(source, copy / name)
    (copy / "suites" / "tiny.toml").write_text(textwrap.dedent(TINY_SUITE))
    git = [GIT, "-C", str(copy), "-c", "user.name=t", "-c", "user.email=t@example.org"]
    subprocess.run([GIT, "init", "-q", str(copy)], check=True)
    subprocess.run([*git, "add", "-A"], check=True)
    subprocess.run([*git, "commit", "-q", "-m", "copy"], check=True)
    monkeypatch.chdir(copy)
    for attempt in ("first", "second"):
        result = CliRunner().invoke(main, ["run", "suites/tiny.toml", "--executor", "inprocess", "--resume"])
        assert result.exit_code == 0, (attempt, result.output)
        assert re.search(r"forward\s+OP-DC\s+1 of 1\s+1\s+\d\.\d{4}\s+8", result.stdout), (attempt, result.stdout)
        reported = re.search(r"report: (\S+)", result.stderr)
        assert reported and Path(reported.group(1)) == copy / "reports" / "tiny" / "index.html", result.stderr
        assert Path(reported.group(1)).is_file()
        status = subprocess.run([*git, "status", "--porcelain", "--untracked-files=all"], capture_output=True,
                                text=True, check=True).stdout
        assert status == "", f"{attempt} run changed the checkout:\n{status}"
    assert "1 case already in the store is skipped" in result.stderr
    # the run's summary ends with its time, the store on a line of its own (no "; " left at a wrapped line's end)
    assert re.search(r"^run \S+: 0 solved, 0 failed, 1 already in the store, [\d.]+ s$", result.stderr, re.M)
    assert re.search(r"^store: \S+$", result.stderr, re.M)
