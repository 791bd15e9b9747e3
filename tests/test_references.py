"""Every reference in the repository leads somewhere inside it.

Scans the tracked text files (code, docs, suites, report templates) for repository paths that do not exist, for
anchors into Markdown files that have no such heading, and for citations of material the repository does not hold:
the shared specification (``spec/``), its decision list ("DECISIONS §n"), its chapter digests ("ch4 §5.3") and
line numbers of a thesis text file ("L1234"). The thesis is cited by its own sections, equations and figures; the
project's modelling decisions are in docs/model.md. This file, which must name the patterns, is not scanned.
"""

from __future__ import annotations

import re
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

SCANNED_SUFFIXES = {".py", ".md", ".toml", ".j2", ".html", ".cfg", ".txt", ".yml", ".yaml"}
"""Text files a reader follows references from; results data (CSV, JSON) is not scanned."""

TOP_FOLDERS = ("docs", "gaitbench", "plugins", "benchmarks", "tests", "suites", "examples")

_PATH = re.compile(
    r"(?<![\w./-])(?:\.\./)*(?P<path>(?:" + "|".join(TOP_FOLDERS) + r")/[\w./-]*[\w/])(?:#(?P<anchor>[\w-]+))?"
)
_NAMED_SECTION = re.compile(
    r"(?P<path>(?:" + "|".join(TOP_FOLDERS) + r")/[\w./-]+\.md),\s+(?:the [^\"]{0,40})?\\?\"(?P<name>[^\"\\]+)\\?\""
)
"""A section cited by name, as in: docs/solvers.md, "Retries"."""
_MARKDOWN_LINK = re.compile(r"\]\((?P<target>[^)\s#]+)(?:#(?P<anchor>[^)\s]+))?\)")
_OUTSIDE = (
    (re.compile(r"DECISIONS\s*§"), "cites DECISIONS §n, which is not in the repository (use docs/model.md)"),
    (re.compile(r"(?<![\w/])spec/"), "points into spec/, which is not in the repository"),
    (re.compile(r"seed/thesis|thesis\.txt"), "points to a thesis text file, which is not in the repository"),
    (re.compile(r"(?<![\w-])L\d{3,5}(?:\s*[–-]\s*L?\d{3,5})?\b"),
     "cites a line of a thesis text file (cite the thesis's section, equation or figure)"),
    (re.compile(r"\bch[2-5][ab]?(?:-[a-z-]+\.md)? §|\bdigest ch|\(digest\b|\bdigest's\b"),
     "cites a chapter digest, which is not in the repository (cite the thesis's own section)"),
    (re.compile(r"/work/|\.\./shared"), "points to a path outside the repository"),
)


def tracked_text_files(root: Path = ROOT) -> list[Path]:
    """The tracked files with a scanned suffix (committed results under benchmarks/results/ and this file excluded)."""
    names = subprocess.run(["git", "ls-files"], cwd=root, check=True, capture_output=True, text=True).stdout
    return [root / name for name in names.splitlines()
            if Path(name).suffix in SCANNED_SUFFIXES and not name.startswith("benchmarks/results/")
            and (root / name).is_file() and (root / name) != Path(__file__).resolve()]


def _slug(heading: str) -> str:
    """GitHub's anchor for a Markdown heading."""
    text = re.sub(r"[^\w\- ]", "", heading.strip().lower())
    return text.replace(" ", "-")


def _headings(markdown: Path) -> list[str]:
    return [line.lstrip("#").strip() for line in markdown.read_text(encoding="utf-8").splitlines()
            if line.startswith("#")]


def _sections(markdown: Path) -> list[str]:
    """What a citation by name may point at: headings, a table row's first cell, a bold lead-in."""
    sections = _headings(markdown)
    for line in markdown.read_text(encoding="utf-8").splitlines():
        if line.startswith("|"):
            sections.append(line.strip("|").split("|")[0].strip())
        elif line.strip().startswith(("**", "- **")):
            sections.append(line.strip().lstrip("-* ").split("**")[0])
    return sections


def _anchors(markdown: Path) -> set[str]:
    return {_slug(heading) for heading in _headings(markdown)}


def _check_target(root: Path, target: Path, anchor: str | None, shown: str) -> str | None:
    if any(ch in shown for ch in "*{}<>"):
        return None
    if not target.exists():
        return f"{shown} does not exist"
    if anchor and target.suffix == ".md" and anchor not in _anchors(target):
        return f"{shown} has no heading #{anchor}"
    return None


def bad_references(path: Path, root: Path = ROOT) -> list[str]:
    """Each reference in ``path`` that leads nowhere, as 'file:line: reason'."""
    problems = []
    relative = path.relative_to(root)
    in_code_block = False
    for number, line in enumerate(path.read_text(encoding="utf-8", errors="replace").splitlines(), start=1):
        where = f"{relative}:{number}"
        for pattern, reason in _OUTSIDE:
            if pattern.search(line):
                problems.append(f"{where}: {reason}: {line.strip()[:120]}")
        if path.suffix == ".md" and line.lstrip().startswith("```"):
            in_code_block = not in_code_block
        if in_code_block:
            continue  # example commands and output name files of the reader's own
        for match in _PATH.finditer(line):
            if path.suffix == ".py" and line[:match.start()].endswith(("\"", "'")):
                continue  # a path as data (a test's own file), not a reference
            token = re.match(r"[^\s`)\]'\"]*", line[match.start():]).group()
            if any(ch in token for ch in "*{<"):
                continue  # a pattern of paths, not one path
            shown = match.group("path").rstrip(".")
            problem = _check_target(root, root / shown, match.group("anchor"), shown)
            if problem:
                problems.append(f"{where}: {problem}")
        for match in _NAMED_SECTION.finditer(line):
            target = root / match.group("path")
            name = " ".join(match.group("name").split())
            if target.exists() and not any(section.startswith(name) for section in _sections(target)):
                problems.append(f"{where}: {match.group('path')} has no section \"{name}\"")
        if path.suffix == ".md":
            for match in _MARKDOWN_LINK.finditer(line):
                target = match.group("target")
                if re.match(r"[a-z]+:", target):
                    continue
                resolved = (path.parent / target).resolve()
                problem = _check_target(root, resolved, match.group("anchor"), target)
                if problem:
                    problems.append(f"{where}: link {problem}")
    return problems


def test_every_reference_leads_inside_the_repository():
    files = tracked_text_files()
    assert len(files) > 200, "the scan found too few files to mean anything"
    problems = [problem for path in files for problem in bad_references(path)]
    assert not problems, "\n".join(problems)


@pytest.mark.parametrize("text, reason", [
    ("see `docs/no-such-page.md`", "does not exist"),
    ("loaded by plugins/solvers/missing_module.py", "does not exist"),
    ("[the page](solvers.md#no-such-heading)", "no heading"),
    ("see docs/solvers.md#no-such-heading", "no heading"),
    ("[relative](no-such-file.md)", "does not exist"),
    ('(docs/solvers.md, "The crawl floor")', "no section"),
    ("as DECISIONS §4 settles", "DECISIONS"),
    ("the digest `spec/thesis/ch2.md`", "spec/"),
    ("read seed/thesis.txt", "thesis text file"),
    ("the observer diverges (ch4 §5.3)", "chapter digest"),
    ("the weights (L9350–9366)", "line of a thesis"),
])
def test_a_planted_bad_reference_fails(tmp_path, text, reason):
    (tmp_path / "docs").mkdir()
    (tmp_path / "docs" / "solvers.md").write_text("# Solvers\n\n## Retries\n", encoding="utf-8")
    planted = tmp_path / "docs" / "planted.md"
    planted.write_text(f"# Planted\n\n{text}\n", encoding="utf-8")
    problems = bad_references(planted, root=tmp_path)
    assert len(problems) == 1 and reason in problems[0], problems


def test_good_references_pass(tmp_path):
    (tmp_path / "docs").mkdir()
    (tmp_path / "docs" / "solvers.md").write_text("# Solvers\n\n## Retries and limits\n", encoding="utf-8")
    page = tmp_path / "docs" / "page.md"
    page.write_text("# Page\n\nSee `docs/solvers.md`, [retries](solvers.md#retries-and-limits), "
                    "docs/solvers.md#retries-and-limits, docs/solvers.md, \"Retries\", the thesis's (3.77) and §5.2, "
                    "`benchmarks/results/sqp_*.json` and `docs/decisions/<name>.md`.\n", encoding="utf-8")
    assert bad_references(page, root=tmp_path) == []
