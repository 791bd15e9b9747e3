"""Carry a results store that runs are still writing to the next session's machine as one file: its finished
cases, its walks in flight and the package versions they were solved with.

The long sweeps (`thesis-all`'s decrease-and-conquer walks at N >= 150 take hours each) outlive a session, and a
session's machine may not outlive it: only what is committed reaches the next one. ``save`` writes one
``.tar.xz`` holding

- ``store.tar.xz``: a pack of the store (`gaitbench runs pack`, docs/results.md "Packed stores"): every row and
  walk header, and the trajectories ``--trajectories`` names (``report``, the default: those the store's report
  draws, small enough to commit; a store restored from a ``report`` carry can only be carried that way again);
- ``checkpoints/``: the step checkpoints a pack leaves out, of the walks in flight and of those a time limit or a
  crash stopped (kept for ``--retry-incomplete`` and ``--retry-failed``), so that ``gaitbench run --resume`` on the
  restored store goes on from their last saved step instead of step 1;
- ``constraints.txt``: the versions of the packages installed beside the gaitbench that runs this script (``pip
  freeze``). A checkpoint resumes only under the same code and solver versions (docs/results.md), and a sweep
  meant to share one problem definition keeps its solvers too: install the next machine's environment with
  ``pip install -c constraints.txt -e .``.

``restore`` makes a store that runs can write from such a file, writes the constraints beside it
(``STORE.constraints.txt``), and warns of every package installed here at another version (a checkpoint resumes
only under the versions that saved it); to install them first, ``tar -xJf CARRY.tar.xz constraints.txt`` needs no
gaitbench.

Stop the runs on the store first (SIGTERM: they record what they finished and keep their checkpoints); a copy of a
store still being written holds the cases finished at one moment, and a walk that finishes during the copy is lost
to it.

    python benchmarks/snapshot_store.py save ~/stores/thesis-all carry/thesis-all.tar.xz
    python benchmarks/snapshot_store.py restore carry/thesis-all.tar.xz ~/stores/thesis-all
"""

from __future__ import annotations

import argparse
import io
import shutil
import sys
import tarfile
import tempfile
from importlib.metadata import distributions
from pathlib import Path

from gaitbench.cli.common import count
from gaitbench.run.store import CHECKPOINTS_DIR, ResultStore
from gaitbench.run.store_pack import pack_store, unpack_store
from gaitbench.run.store_schema import StoreError

PACK, CONSTRAINTS = "store.tar.xz", "constraints.txt"
NOT_PINNED = {"gaitbench", "pip", "setuptools", "wheel", "distribute"}
"""Packages no constraint is written for, as ``pip freeze`` leaves them out: the project, and what installs it."""


def installed_versions() -> str:
    """The packages of this interpreter's environment as pip constraints (``name==version``, one a line, sorted),
    gaitbench itself and the installer's own packages left out: what ``pip freeze`` lists, read without pip."""
    pins = {f"{dist.metadata['Name']}=={dist.version}" for dist in distributions()
            if dist.metadata["Name"] and dist.metadata["Name"].lower() not in NOT_PINNED}
    return "".join(f"{pin}\n" for pin in sorted(pins, key=str.lower))


def save(store_dir: Path, carry: Path, trajectories: str = "report") -> dict[str, int]:
    """Write the carry file of ``store_dir`` to ``carry`` (replaced); how many cases and checkpoints it holds."""
    from gaitbench.reports import report_trajectories

    with tempfile.TemporaryDirectory(prefix="gaitbench-carry-") as scratch:
        keep = report_trajectories(store_dir) if trajectories == "report" else set()
        summary = pack_store(store_dir, Path(scratch) / PACK, trajectories, keep)
        carry.parent.mkdir(parents=True, exist_ok=True)
        staging = carry.with_name(f".{carry.name}.partial")
        in_flight = 0
        with tarfile.open(staging, mode="w:xz") as tar:
            tar.add(Path(scratch) / PACK, arcname=PACK)
            for checkpoint in sorted((store_dir / CHECKPOINTS_DIR).glob("*")):
                # every one: a walk's in flight, or one a time limit or a crash stopped, kept for the retry (what the
                # runner no longer needs it removes itself); files being written start with "."
                if checkpoint.name.startswith("."):
                    continue
                tar.add(checkpoint, arcname=f"{CHECKPOINTS_DIR}/{checkpoint.name}")
                in_flight += checkpoint.suffix != ".json"
            pins = installed_versions().encode()
            member = tarfile.TarInfo(CONSTRAINTS)
            member.size = len(pins)
            tar.addfile(member, io.BytesIO(pins))
        staging.replace(carry)
    return {"cases": summary.cases, "checkpoints": in_flight}


def restore(carry: Path, store_dir: Path) -> dict[str, int]:
    """Make the store ``store_dir`` (new or empty) from ``carry``, its checkpoints included, and write the
    constraints to ``STORE.constraints.txt``; how many cases and checkpoints it holds, and the packages installed
    here at another version than the carried one."""
    with tempfile.TemporaryDirectory(prefix="gaitbench-carry-") as scratch, \
            tarfile.open(carry, mode="r:xz") as tar:
        names = set(tar.getnames())
        if not {PACK, CONSTRAINTS} <= names:
            raise tarfile.TarError(f"it holds no {' and no '.join(sorted({PACK, CONSTRAINTS} - names))}")
        tar.extractall(scratch, **({"filter": "data"} if hasattr(tarfile, "data_filter") else {}))
        unpack_store(Path(scratch) / PACK, store_dir)
        checkpoints = sorted((Path(scratch) / CHECKPOINTS_DIR).glob("*"))
        if checkpoints:
            (store_dir / CHECKPOINTS_DIR).mkdir(exist_ok=True)
        for checkpoint in checkpoints:
            shutil.copy2(checkpoint, store_dir / CHECKPOINTS_DIR / checkpoint.name)
        pins = (Path(scratch) / CONSTRAINTS).read_text()
        store_dir.with_name(f"{store_dir.name}.constraints.txt").write_text(pins)
    with ResultStore.open(store_dir) as store:
        cases = len(store.finished_keys())
    return {"cases": cases, "checkpoints": sum(path.suffix != ".json" for path in checkpoints),
            "differing": differing_versions(pins, installed_versions())}


def differing_versions(carried: str, installed: str) -> list[str]:
    """The packages whose version here is not the carried one (``name carried -> here``): under those the walks in
    flight start again from step 1, and the sweep mixes solver versions."""
    def pins(text: str) -> dict[str, str]:
        return dict(line.split("==", 1) for line in text.splitlines() if "==" in line)

    carried_pins, installed_pins = pins(carried), pins(installed)
    return [f"{name} {version} -> {installed_pins.get(name, 'not installed')}"
            for name, version in sorted(carried_pins.items()) if installed_pins.get(name) != version]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    commands = parser.add_subparsers(dest="command", required=True)
    saving = commands.add_parser("save", help="write the carry file of a store")
    saving.add_argument("store", type=Path, help="the store (a run's --store or suite output)")
    saving.add_argument("carry", type=Path, help="the carry file to write (.tar.xz, replaced)")
    saving.add_argument("--trajectories", choices=["report", "all"], default="report",
                        help="the trajectories to keep, as `gaitbench runs pack --trajectories` (default: report)")
    restoring = commands.add_parser("restore", help="make a store from a carry file")
    restoring.add_argument("carry", type=Path, help="the carry file")
    restoring.add_argument("store", type=Path, help="the store to make (a new or empty directory)")
    args = parser.parse_args()
    try:
        if args.command == "save":
            counts = save(args.store, args.carry, args.trajectories)
            print(f"{args.carry}: {count(counts['cases'], 'case')}, {count(counts['checkpoints'], 'walk')} to go "
                  f"on with ({args.carry.stat().st_size / 1e6:.2f} MB)")
            return
        counts = restore(args.carry, args.store)
    except tarfile.TarError as error:
        sys.exit(f"error: {args.carry}: not a carry file of snapshot_store.py save ({error})")
    except (StoreError, OSError) as error:
        sys.exit(f"error: {error}")
    pins = args.store.with_name(args.store.name + ".constraints.txt")
    print(f"{args.store}: {count(counts['cases'], 'case')}, {count(counts['checkpoints'], 'walk')} to go on with; "
          f"the package versions they ran with: {pins}")
    if counts["differing"]:
        print(f"warning: {count(len(counts['differing']), 'package')} here not at the carried version "
              f"({', '.join(counts['differing'])}): the walks to go on with would start again from step 1; install "
              f"with `pip install -c {pins} -e .`", file=sys.stderr)


if __name__ == "__main__":
    main()
