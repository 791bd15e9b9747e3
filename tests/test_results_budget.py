"""benchmarks/results/ stays small enough to version: at most :data:`MAX_FILES` tracked files and :data:`MAX_BYTES`.

Results too big for it (a whole results store with every walk's trajectories) are committed as a pack of what the
docs cite (`gaitbench runs pack`, docs/results.md "Packed stores") and kept whole in git history. Inside a git
checkout the budget counts the tracked files (what a clone carries); elsewhere (an sdist, an unpacked archive)
every file under the directory.
"""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "benchmarks" / "results"

MAX_FILES = 60
MAX_BYTES = 20_000_000
SHOWN = 5
"""How many of the biggest files a failure names."""


def results_files(root: Path = ROOT, results: Path = RESULTS) -> list[Path]:
    """The files under ``results``: tracked ones in a git checkout, all of them otherwise."""
    git = shutil.which("git")
    if git and (root / ".git").exists():
        listed = subprocess.run([git, "ls-files", "-z", "--", str(results.relative_to(root))], cwd=root,
                                capture_output=True, check=True).stdout.decode()
        return [root / name for name in listed.split("\0") if name]
    return [path for path in results.rglob("*") if path.is_file()]


def over_budget(files: list[Path], max_files: int = MAX_FILES, max_bytes: int = MAX_BYTES) -> list[str]:
    """What is over the budget, each line naming the biggest files; empty when within it."""
    sizes = sorted(((path.stat().st_size if path.is_file() else 0, path) for path in files), reverse=True)
    total = sum(size for size, _ in sizes)
    biggest = ", ".join(f"{path.relative_to(ROOT) if path.is_relative_to(ROOT) else path} ({size / 1e6:.2f} MB)"
                        for size, path in sizes[:SHOWN])
    problems = []
    if len(files) > max_files:
        problems.append(f"benchmarks/results holds {len(files)} files, more than {max_files}; biggest: {biggest}")
    if total > max_bytes:
        problems.append(f"benchmarks/results holds {total / 1e6:.1f} MB, more than {max_bytes / 1e6:g} MB; "
                        f"biggest: {biggest}")
    return problems


def test_benchmarks_results_stays_within_its_budget():
    files = results_files()
    assert len(files) >= 10, f"found only {len(files)} files under {RESULTS}: the listing is broken"
    problems = over_budget(files)
    assert not problems, "\n".join(problems) + "\nkeep what the docs cite; pack a store (`gaitbench runs pack`)"


def test_the_budget_names_the_biggest_offenders(tmp_path):
    small, big = tmp_path / "small.json", tmp_path / "big.npz"
    small.write_bytes(b"x" * 10)
    big.write_bytes(b"x" * 3000)
    problems = over_budget([small, big], max_files=1, max_bytes=1000)
    assert len(problems) == 2
    assert all(f"{big} (0.00 MB), {small}" in problem for problem in problems)
    assert "2 files, more than 1" in problems[0] and "more than 0.001 MB" in problems[1]
    assert over_budget([small, big]) == []
