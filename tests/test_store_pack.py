"""Packed results stores (gaitbench/run/store_pack.py, pack_format.py, pack_cache.py; `gaitbench runs pack`): a
store packs to the same bytes every time, comes back whole, is read directly by the commands that read a store,
and is refused by those that write one; a corrupt, foreign or hostile pack is one line naming it."""

from __future__ import annotations

import io
import json
import sqlite3
import tarfile
from pathlib import Path
from types import SimpleNamespace

import pytest
from click.testing import CliRunner

from gaitbench.cli.main import main
from gaitbench.cli.report_command import default_report_dir
from gaitbench.reports import build_report, report_trajectories, write_report
from gaitbench.run.pack_cache import unpacked
from gaitbench.run.pack_format import MANIFEST, PackError
from gaitbench.run.store import ResultStore
from gaitbench.run.store_pack import pack_store, unpack_store
from gaitbench.run.store_schema import StoreError


@pytest.fixture(autouse=True)
def _cache(tmp_path, monkeypatch):
    """Each test unpacks into its own cache (GAITBENCH_CACHE, which would take precedence, unset)."""
    monkeypatch.delenv("GAITBENCH_CACHE", raising=False)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))


@pytest.fixture(scope="module")
def store(tmp_path_factory) -> Path:
    """A real store of two walks, forward, One Phase DMOC, one step each, N = 8 and 10 (a few seconds)."""
    from gaitbench.run.case import Case, PluginChoice
    from gaitbench.run.executors import InProcessExecutor
    from gaitbench.run.runner import run_suite

    cases = [Case(PluginChoice("forward"), n, PluginChoice("dmoc"), PluginChoice("ipopt"),
                  PluginChoice("one-phase"), steps=1, method="OP-DM", time_limit_s=60) for n in (8, 10)]
    suite = SimpleNamespace(name="packed", path=Path("packed.toml"), text="# pack test suite", cases=cases)
    directory = tmp_path_factory.mktemp("store") / "packed"
    run_suite(suite, directory, InProcessExecutor())
    with ResultStore.open(directory) as opened:
        assert [row["status"] for row in opened.cases()] == ["solved", "solved"]
    return directory


def invoke(*args: str):
    return CliRunner().invoke(main, list(args))


def _text(result) -> str:
    """A command's output as one line (rich wraps it at the terminal's width)."""
    return " ".join(result.output.split())


def _files(directory: Path) -> dict[str, bytes]:
    return {path.relative_to(directory).as_posix(): path.read_bytes()
            for path in sorted(directory.rglob("*")) if path.is_file() and path.name != "results.sqlite"}


def _rows(directory: Path) -> list[dict]:
    with ResultStore.open(directory) as opened:
        return opened.cases()


def test_a_store_packs_to_the_same_bytes_and_comes_back_whole(store, tmp_path):
    first = pack_store(store, tmp_path / "a.tar.xz")
    second = pack_store(store, tmp_path / "elsewhere" / "b.tar.xz")
    assert first.path.read_bytes() == second.path.read_bytes()
    assert (first.cases, first.trajectories_kept, first.trajectories_left_out) == (2, 2, 0)

    with pytest.raises(PackError, match="not empty; unpack into a new or empty directory"):
        unpack_store(first.path, store)  # never over a store
    back = unpack_store(first.path, tmp_path / "back")
    assert json.loads((back / MANIFEST).read_text())["trajectories"] == "all"
    assert _files(back / "cases") == _files(store / "cases")  # every case file, markers included, byte for byte
    assert len(_files(store / "cases")) == 6
    assert _rows(back) == _rows(store)
    with tarfile.open(first.path) as tar:
        members = tar.getmembers()
    assert [member.name for member in members] == sorted(member.name for member in members)
    assert {(member.mtime, member.uid, member.gid, member.uname, member.gname) for member in members} == \
        {(0, 0, 0, "", "")}
    with sqlite3.connect(back / "results.sqlite") as connection:  # one file, no WAL beside it
        assert connection.execute("PRAGMA journal_mode").fetchone()[0] == "delete"


def test_report_and_runs_read_a_pack_as_they_read_the_store(store, tmp_path):
    pack = pack_store(store, tmp_path / "packed.tar.xz").path
    write_report(store, tmp_path / "from-store", reporters=("csv",))
    write_report(pack, tmp_path / "from-pack", reporters=("csv",))
    from_store, from_pack = _files(tmp_path / "from-store"), _files(tmp_path / "from-pack")
    assert from_store and from_pack == from_store

    built = build_report(pack)
    assert built.store_dir == pack and len(built.gaits) == 1 and not built.gait_problems
    assert default_report_dir(pack) == Path("reports/packed")  # the store's name, not the file's

    listed = invoke("runs", "list", str(pack))
    assert listed.exit_code == 0, listed.output
    assert "-packed" in listed.output  # the run, named after its suite
    shown = invoke("runs", "show", str(pack))
    assert shown.exit_code == 0 and shown.output.count("OP-DM") == 2, shown.output


def test_the_cache_unpacks_a_pack_once_read_only(store, tmp_path):
    pack = pack_store(store, tmp_path / "packed.tar.xz").path
    copy = tmp_path / "copy.tar.xz"
    copy.write_bytes(pack.read_bytes())
    directory = unpacked(pack)
    assert unpacked(copy) == directory and directory.name == "packed"  # keyed by content, not by name
    assert not any(path.stat().st_mode & 0o222 for path in directory.rglob("*") if path.is_file())
    assert (tmp_path / "cache" / "gaitbench" / "packs") in directory.parents


def test_commands_that_write_refuse_a_pack(store, tmp_path):
    pack = pack_store(store, tmp_path / "packed.tar.xz").path
    with pytest.raises(StoreError, match=r"packed\.tar\.xz: a packed results store, which is read-only; unpack it"):
        ResultStore.create(pack)
    suite = tmp_path / "suite.toml"
    suite.write_text('name = "s"\n[[experiments]]\nname = "forward"\nN = [8]\n')
    result = invoke("run", str(suite), "--store", str(pack), "--resume")
    assert result.exit_code == 1
    assert "a packed results store, which is read-only" in _text(result) and "Traceback" not in result.output

    verified = invoke("verify", "--store", str(pack))
    assert "verdicts not recorded" in _text(verified) and "is a pack" in _text(verified), verified.output


def test_a_walk_whose_trajectories_the_pack_left_out_says_so(store, tmp_path):
    keep = report_trajectories(store)
    assert len(keep) == 1  # the one gait the report draws: the lower ACOT of the two walks
    summary = pack_store(store, tmp_path / "report.tar.xz", "report", keep)
    assert (summary.trajectories_kept, summary.trajectories_left_out) == (1, 1)
    other = next(row["case_key"] for row in _rows(store) if f"cases/{row['case_key']}/walk.npz" not in keep)

    built = build_report(summary.path, gait=other)
    assert built.gaits == [] and len(built.gait_problems) == 1
    problem = built.gait_problems[0]
    assert "its trajectories are not in this pack of packed" in problem and "--trajectories all" in problem
    assert "\n" not in problem

    with pytest.raises(PackError, match=r"report\.tar\.xz: holds only some trajectories"):
        pack_store(summary.path, tmp_path / "not-whole.tar.xz")  # a pack cannot claim what it lacks

    verified = invoke("verify", "--store", str(summary.path))
    assert "1 stored walk not verified" in _text(verified) and "not in this pack" in _text(verified)
    assert verified.exit_code == 0, verified.output  # the walk it holds is verified


def _tar_xz(path: Path, members: list[tuple[tarfile.TarInfo, bytes]]) -> Path:
    with tarfile.open(path, "w:xz") as tar:
        for member, content in members:
            member.size = len(content)
            tar.addfile(member, io.BytesIO(content))
    return path


@pytest.mark.parametrize("name, kind", [("store/../../evil.txt", tarfile.REGTYPE), ("/tmp/evil.txt", tarfile.REGTYPE),
                                        ("store/link", tarfile.SYMTYPE), ("evil.txt", tarfile.REGTYPE)])
def test_a_member_outside_the_pack_or_not_a_plain_file_is_refused(tmp_path, name, kind):
    member = tarfile.TarInfo(name)
    member.type = kind
    member.linkname = "/etc/passwd" if kind == tarfile.SYMTYPE else ""
    manifest = tarfile.TarInfo(f"store/{MANIFEST}")
    pack = _tar_xz(tmp_path / "hostile.tar.xz", [(manifest, b'{"gaitbench": "pack", "format": 1}'), (member, b"x")])
    with pytest.raises(PackError, match=rf"hostile\.tar\.xz: refused member {name!r}"):
        unpacked(pack)
    assert not (tmp_path / "evil.txt").exists() and not list((tmp_path / "cache").rglob("evil.txt"))


def test_a_corrupt_or_foreign_pack_is_one_line_naming_it(store, tmp_path):
    truncated = tmp_path / "truncated.tar.xz"
    whole = pack_store(store, tmp_path / "whole.tar.xz").path.read_bytes()
    truncated.write_bytes(whole[:len(whole) // 2])
    (tmp_path / "garbage.tar.xz").write_bytes(b"not a pack at all")
    foreign = _tar_xz(tmp_path / "foreign.tar.xz", [(tarfile.TarInfo("photos/cat.jpg"), b"meow")])
    for pack, expected in ((truncated, "not a readable results pack"), (tmp_path / "garbage.tar.xz",
                                                                        "not a readable results pack"),
                           (foreign, f"not a gaitbench results pack (no {MANIFEST} in it)"),
                           (tmp_path / "missing.tar.xz", "no results pack here")):
        for command in (("runs", "list"), ("report",)):
            result = invoke(*command, str(pack))
            assert result.exit_code == 1, result.output
            assert result.output.startswith(f"Error: {pack}: {expected}"), result.output
            assert len(result.output.strip().splitlines()) == 1 and "Traceback" not in result.output


def test_a_case_recorded_while_the_store_is_packed_is_in_the_pack_whole_or_not_at_all(store, tmp_path, monkeypatch):
    """The pack's cases are those of the database's copy: one a run records after the store was opened for packing
    but before the copy is in it with its files (not a row without them); one recorded after the copy is not in
    it at all."""
    import shutil

    import gaitbench.run.store_pack as store_pack

    writing = tmp_path / "writing"
    shutil.copytree(store, writing)
    copy = store_pack._database_copy

    def record(key: str) -> None:
        with ResultStore.create(writing) as running:
            running.record_case({"case_key": key, "run_id": None, "status": "solved", "experiment": "forward",
                                 "walk_path": f"cases/{key}/walk.json"}, {"walk.json": b"{}"})

    def record_around_the_copy(database):
        record("b" * 16)
        taken = copy(database)
        record("c" * 16)
        return taken

    monkeypatch.setattr(store_pack, "_database_copy", record_around_the_copy)
    summary = pack_store(writing, tmp_path / "p.tar.xz")
    assert summary.cases == 3
    with tarfile.open(summary.path) as tar:
        names = tar.getnames()
    assert any(name.endswith(f"cases/{'b' * 16}/walk.json") for name in names)
    assert not any("c" * 16 in name for name in names)
    assert len(_rows(writing)) == 4  # the store itself has both
