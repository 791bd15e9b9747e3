"""``gaitbench runs pack`` and ``runs unpack``: a results store as one compressed file, and back
(:mod:`gaitbench.run.store_pack`). Every command that reads a store reads a pack directly."""

from __future__ import annotations

from pathlib import Path

import click

from gaitbench.cli.common import count


@click.command("pack")
@click.argument("store_dir", metavar="STORE", type=click.Path(path_type=Path))
@click.argument("out", metavar="OUT.tar.xz", type=click.Path(dir_okay=False, path_type=Path))
@click.option("--trajectories", type=click.Choice(["all", "report"]), default="all", show_default=True,
              help="all: every walk's trajectories, the whole store; report: only those the store's report draws "
                   "(each experiment's chosen gait and the tracking series), every row and walk header still in.")
def pack(store_dir: Path, out: Path, trajectories: str) -> None:
    """Pack the results store STORE into one deterministic .tar.xz file, OUT.tar.xz: its database, every case's
    walk file (walk.json) and the trajectories --trajectories names. The same store packs to the same bytes.

    `gaitbench report`, `runs list`, `runs show`, `runs export` and `verify --store` read the pack as they read a
    store; `gaitbench runs unpack` turns it back into a store that runs can write.
    """
    from gaitbench.reports import report_trajectories
    from gaitbench.run.pack_format import PACK_SUFFIX
    from gaitbench.run.store_pack import pack_store
    from gaitbench.run.store_schema import StoreError

    if not out.name.endswith(PACK_SUFFIX):
        raise click.BadParameter(f"{out}: a pack's name ends in {PACK_SUFFIX}", param_hint="OUT.tar.xz")
    try:
        keep = report_trajectories(store_dir) if trajectories == "report" else set()
        summary = pack_store(store_dir, out, trajectories, keep)
    except StoreError as error:
        raise click.ClickException(str(error)) from None
    left = f", {count(summary.trajectories_left_out, 'trajectory file')} left out" \
        if summary.trajectories_left_out else ""
    click.echo(f"packed {count(summary.cases, 'case')} of {store_dir} into {out} ({summary.size / 1e6:.2f} MB; "
               f"{count(summary.trajectories_kept, 'trajectory file')} in{left})", err=True)


@click.command("unpack")
@click.argument("pack_file", metavar="PACK", type=click.Path(dir_okay=False, path_type=Path))
@click.argument("destination", metavar="DIR", type=click.Path(file_okay=False, path_type=Path))
def unpack(pack_file: Path, destination: Path) -> None:
    """Unpack PACK (from `gaitbench runs pack`) into DIR, a new or empty directory: a store that `gaitbench run
    --store DIR`, `--resume` and `verify --store` can write. Reading a pack needs no unpacking."""
    from gaitbench.run.store_pack import unpack_store
    from gaitbench.run.store_schema import StoreError

    try:
        unpack_store(pack_file, destination)
    except StoreError as error:
        raise click.ClickException(str(error)) from None
    click.echo(f"unpacked {pack_file} into {destination}", err=True)
