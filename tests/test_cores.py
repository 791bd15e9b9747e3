"""The ledger of busy cores: leases take what is free, give back what they no longer need, and a holder that dies
or a forked child that outlives a lease keeps nothing taken."""

from __future__ import annotations

import multiprocessing
import subprocess
import sys
import time
from pathlib import Path

import pytest

from gaitbench.cores import CORES_DIR_ENV, IdleCores


@pytest.fixture
def ledger(tmp_path: Path) -> IdleCores:
    return IdleCores(tmp_path / "cores", 3)


def test_leases_share_the_cores_and_give_back_what_they_no_longer_need(ledger: IdleCores) -> None:
    with ledger.occupy() as own, ledger.lease() as borrowed:
        assert own.count == 1
        assert borrowed.hold(5) == 2  # at most the cores not held, never more than the machine has
        with ledger.lease() as none_left:
            assert none_left.hold(1) == 0
        assert borrowed.hold(1) == 1  # one given back
        with ledger.lease() as other:
            assert other.hold(3) == 1
    with ledger.lease() as everything:
        assert everything.hold(3) == 3


def test_the_machine_ledger_counts_this_process_s_cores_in_a_shared_directory(monkeypatch, tmp_path) -> None:
    monkeypatch.setenv(CORES_DIR_ENV, str(tmp_path))
    machine = IdleCores.machine()
    assert machine.directory == tmp_path and machine.cores >= 1
    with pytest.raises(ValueError, match="cores = 0"):
        IdleCores(tmp_path, 0)


def test_a_ledger_that_cannot_be_written_lends_nothing(tmp_path: Path) -> None:
    blocked = tmp_path / "a file"
    blocked.write_text("not a directory")
    with IdleCores(blocked / "cores", 2).occupy() as lease:
        assert lease.count == 0


def test_a_holder_that_dies_keeps_no_core(ledger: IdleCores) -> None:
    holder = subprocess.Popen(
        [sys.executable, "-c", "import sys, time; from gaitbench.cores import IdleCores; "
         f"lease = IdleCores({str(ledger.directory)!r}, 3).lease(); print(lease.hold(2), flush=True); "
         "time.sleep(60)"], stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline().strip() == "2"
        with ledger.lease() as lease:
            assert lease.hold(3) == 1
    finally:
        holder.kill()
        holder.wait()
    with ledger.lease() as lease:
        assert lease.hold(3) == 3


def _sleep_forever() -> None:
    time.sleep(60)


@pytest.mark.skipif("fork" not in multiprocessing.get_all_start_methods(), reason="needs fork")
def test_a_forked_child_does_not_keep_a_core_given_back(ledger: IdleCores) -> None:
    """D&C's sectional workers are forked while the walk holds borrowed cores: they share the lock's descriptor."""
    lease = ledger.lease()
    assert lease.hold(3) == 3
    child = multiprocessing.get_context("fork").Process(target=_sleep_forever)
    child.start()
    try:
        lease.release()
        with ledger.lease() as again:
            assert again.hold(3) == 3
    finally:
        child.kill()
        child.join()
