"""``gaitbench verify``: walk files, or every walk of a results store, verified again as motions from their stored
trajectories (:func:`gaitbench.solve.walk_verification.reverify`), with the verdict and, for a store, the verified
flags written into its rows."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import click
from rich.console import Console

from gaitbench.acceptance import ACOT_RTOL
from gaitbench.cli.common import count, print_plain


@click.command("verify")
@click.argument("walks", nargs=-1, type=click.Path(path_type=Path))
@click.option("--store", type=click.Path(path_type=Path), default=None,
              help="Verify every stored walk of this results store and record the verdicts in its rows "
                   "(columns verified, verification_failure, max_join_mismatch, join_energy, max_defect, "
                   "max_resim_error, thesis_reading_acot). A pack (.tar.xz) is verified as far as it holds "
                   "trajectories, its verdicts printed, not recorded.")
@click.option("--json", "as_json", is_flag=True, help="Print one JSON object per walk instead of text.")
@click.pass_context
def verify(ctx: click.Context, walks: tuple[Path, ...], store: Path | None, as_json: bool) -> None:
    """Verify the walks in WALKS (walk files from `solve --out` or a store's cases/*/walk.json) as motions.

    Each step the walk reports (for decrease and conquer: its polished or complete motion, not the patchwork) is
    checked again from the saved trajectory: its dynamics defect, its re-simulation from its own start state under
    its own torques, and its COT recomputed on a fine grid. Then the joins: each step must start from the
    post-impact state (push-off and heel strike applied to the end) of the step before. The thresholds scale with
    N (docs/results.md, "Verified walks"). Prints the verified ACOT beside the stored one, the largest join mismatch
    and re-simulation error, and the verdict.

    Exit status 0 when every walk is verified, 1 when one is not (or its stored ACOT is off by more than 1 %),
    2 when a file cannot be read.
    """
    from gaitbench.plugins import PluginBuildError, UnknownPluginError
    from gaitbench.run.pack_format import is_pack
    from gaitbench.solve.walk_file import WalkFileError, read_walk
    from gaitbench.solve.walk_verification import reverify

    if not walks and store is None:
        raise click.UsageError("name walk files, or a store with --store")
    targets: list[tuple[Path, str | None, float | None, dict]] = [(path, None, None, {}) for path in walks]
    console, failed, updates, missing, broke = Console(), 0, {}, [], []
    packed = store is not None and is_pack(store)
    if store is not None:
        stored, absent, recorded = _stored_walks(store)
        targets += stored
        if absent:  # a pack of the report's trajectories: one line for all it cannot verify
            note = (f"{count(len(absent), 'stored walk')} not verified: {absent[0]}"
                    + (f" (and {len(absent) - 1} more like it)" if len(absent) > 1 else ""))
            click.echo(note, err=True) if as_json else print_plain(console, note, "yellow")
    for path, case_key, stored_acot, transcription_options in targets:
        try:
            walk_file = read_walk(path)
            # a walk file that predates its transcription's options: the store's row has them
            walk_file.header.setdefault("transcription_options", transcription_options)
            walk = reverify(walk_file, ctx.obj.registry)
        except (UnknownPluginError, PluginBuildError) as exc:  # the walk is fine; a plugin it names is not, here
            if case_key is None:
                raise click.ClickException(f"{path}: cannot be verified here: {exc}") from None
            missing.append(f"{path}: {exc}")
            failed += 1
            continue
        except WalkFileError as exc:
            if case_key is None:
                raise click.BadParameter(str(exc), param_hint="WALKS") from None
            report = _unreadable(path, exc)  # one broken file of a store is that walk's verdict, not the end
            report["notes"].append("a stored walk: restore its files, or solve it again with `gaitbench run SUITE "
                                   "--resume --retry-unverified`, which this verdict makes it eligible for")
        except Exception as exc:  # a walk that breaks the verifier must not cost the others their verdicts
            if case_key is None:
                raise
            broke.append(f"{path}: {type(exc).__name__}: {exc}")
            failed += 1
            continue
        else:
            stored_acot = walk_file.header.get("acot") if stored_acot is None else stored_acot
            report = _report(path, walk, stored_acot, walk_file.acot_is_claimed)
        failed += not report["verified"]
        if case_key is not None:
            updates[case_key] = _columns(report)
        if as_json:
            click.echo(json.dumps(report))
        else:
            _print(console, report)
    if missing:  # no verdict: the walk was not checked, and its row keeps the one it had
        note = (f"{count(len(missing), 'stored walk')} not verified, verdicts not recorded: a plugin they were solved "
                f"with is not installed here, or fails here; install it and run again. {missing[0]}"
                + (f" (and {len(missing) - 1} more)" if len(missing) > 1 else ""))
        click.echo(note, err=True) if as_json else print_plain(console, note, "yellow")
    if broke:  # a fault of gaitbench's, not of the walk: no verdict either way
        note = (f"{count(len(broke), 'stored walk')} not verified, verdicts not recorded: the verification failed "
                f"with an error, please report it. {broke[0]}" + (f" (and {len(broke) - 1} more)" if len(broke) > 1
                                                                  else ""))
        click.echo(note, err=True) if as_json else print_plain(console, note, "yellow")
    if packed and not as_json:
        console.print(f"verdicts not recorded: {store} is a pack, which is read-only; `gaitbench runs unpack` "
                      "makes a store that can record them")
    elif store is not None and not packed:
        from gaitbench.run.store import ResultStore, StoreError

        try:
            with ResultStore.create(store) as writable:
                changed = writable.update_cases(updates, recorded)
        except StoreError as exc:
            raise click.ClickException(str(exc)) from None
        if changed:
            note = (f"{count(len(changed), 'walk')} recorded again while being verified, verdicts not recorded "
                    f"({', '.join(changed)}): run `gaitbench verify --store {store}` again")
            click.echo(note, err=True) if as_json else print_plain(console, note, "yellow")
        if not as_json:
            console.print(f"recorded the verdicts of {count(len(updates) - len(changed), 'walk')} in {store}")
    if failed:
        ctx.exit(1)


def _stored_walks(store: Path) -> tuple[list[tuple[Path, str, Any, dict]], list[str],
                                        dict[str, tuple[str | None, str | None]]]:
    """The store's walks as (walk file, case key, stored ACOT, transcription options), why each walk whose
    trajectories its pack left out cannot be verified (:func:`gaitbench.run.pack_format.left_out`), and when each
    case was recorded, by which run (so that a verdict is not written onto a walk recorded again meanwhile)."""
    from gaitbench.run.pack_format import left_out
    from gaitbench.run.store import ResultStore, StoreError

    try:
        with ResultStore.open(store) as results:
            rows = [row for row in results.cases() if row.get("walk_path")]
            directory = results.directory
    except StoreError as exc:
        raise click.ClickException(str(exc)) from None
    walks, absent = [], []
    for row in rows:
        missing = left_out(directory, row["walk_path"])
        if missing:
            absent.append(missing)
        else:
            walks.append((directory / row["walk_path"], row["case_key"], row.get("acot"),
                          dict(row.get("transcription_options") or {})))
    return walks, absent, {row["case_key"]: (row.get("run_id"), row.get("finished_at")) for row in rows}


def _report(path: Path, walk, stored_acot: Any, acot_is_claimed: bool = False) -> dict[str, Any]:
    """The verdict on one walk as JSON-ready data; a stored ACOT more than :data:`ACOT_RTOL` from the recomputed
    one fails it, unless it is the claimed patchwork ACOT that a walk file before format 2 stores as its ACOT
    (``acot_is_claimed``), which a note says instead."""
    verification = walk.verification
    reasons, notes = list(verification.reasons), []
    stored = float(stored_acot) if isinstance(stored_acot, (int, float)) else None
    if stored is not None and verification.acot is not None and not _agrees(stored, verification.acot):
        if acot_is_claimed and walk.claimed_acot is not None and _agrees(stored, walk.claimed_acot):
            notes.append(f"stored ACOT {stored:.4f} is the claimed patchwork ACOT: the walk file predates format 2, "
                         f"which stores the verified ACOT as acot and the claim as claimed_acot")
        else:
            reasons.append(f"stored ACOT {stored:.4f} is not the recomputed {verification.acot:.4f}")
    return {"walk": str(path), "experiment": walk.experiment, "strategy": walk.strategy,
            "transcription": walk.transcription, "N": walk.N, "verified": not reasons, "reasons": reasons,
            "notes": notes,
            "acot": verification.acot, "stored_acot": stored, "claimed_acot": walk.claimed_acot,
            "thesis_reading_acot": walk.thesis_reading_acot,
            **{key: value for key, value in verification.as_dict().items()
               if key not in ("verified", "reason", "acot")}}


def _agrees(stored: float, recomputed: float) -> bool:
    return abs(stored - recomputed) <= ACOT_RTOL * abs(recomputed)


def _unreadable(path: Path, error: Exception) -> dict[str, Any]:
    """The verdict on a stored walk whose file cannot be read: not verified, and why."""
    return {"walk": str(path), "experiment": "?", "strategy": "?", "transcription": "?", "N": "?",
            "verified": False, "reasons": [f"walk file unreadable: {error}"], "notes": [], "acot": None,
            "stored_acot": None,
            "claimed_acot": None, "thesis_reading_acot": None, "max_join_mismatch": None, "join_energy": 0.0,
            "max_resim_error": None, "max_defect": None}


def _columns(report: dict[str, Any]) -> dict[str, Any]:
    """The store columns a walk's verdict fills: the flag, its reasons, the maxima of the steps it reports and the
    thesis's reading."""
    return {"verified": report["verified"], "verification_failure": "; ".join(report["reasons"]) or None,
            **{column: report[column] for column in ("max_join_mismatch", "join_energy", "max_defect",
                                                      "max_resim_error", "thesis_reading_acot")}}


def _print(console: Console, report: dict[str, Any]) -> None:
    def figure(value: Any, spec: str) -> str:
        return "-" if value is None else format(value, spec)

    verdict = "verified" if report["verified"] else "NOT verified: " + "; ".join(report["reasons"])
    console.print(f"{report['walk']}: {report['experiment']}, {report['strategy']}, {report['transcription']}, "
                  f"N = {report['N']}")
    label = "verified ACOT" if report["verified"] else "ACOT"  # never "verified" for a walk the verdict fails
    console.print(f"  {label} {figure(report['acot'], '.4f')} (stored {figure(report['stored_acot'], '.4f')}"
                  + (f", claimed {report['claimed_acot']:.4f}" if report["claimed_acot"] is not None else "") + ")")
    console.print(f"  largest join mismatch {figure(report['max_join_mismatch'], '.1e')}, energy appearing at the "
                  f"joins {report['join_energy']:.1f} J, largest re-simulation error "
                  f"{figure(report['max_resim_error'], '.1e')}")
    for note in report["notes"]:
        print_plain(console, f"  note: {note}", "")
    print_plain(console, f"  {verdict}", "" if report["verified"] else "red")
