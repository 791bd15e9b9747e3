"""``gaitbench bound``: the least ACOT any walk of an experiment can have, from the energy it must gain
(:mod:`gaitbench.solve.bound`)."""

from __future__ import annotations

import json

import click
from rich.console import Console
from rich.table import Table

from gaitbench.cli.common import create, parse_options, print_plain

PUSH_OFF_COSTS = ("impulse", "thesis")
"""The choices of ``--push-off-cost`` (:data:`gaitbench.solve.bound.PUSH_OFF_COSTS`, typed here so that the command's
help needs no numerics)."""
START_POSES = ("on-ground", "printed")
"""The choices of ``--start-pose`` (:data:`gaitbench.problem.gait_problem.START_POSES`)."""


@click.command("bound")
@click.option("--experiment", "-e", "experiment_name", required=True, help="Experiment plugin, e.g. upward-slope.")
@click.option("--experiment-option", "experiment_options", multiple=True, metavar="KEY=VALUE",
              help="Passed to the experiment (repeatable).")
@click.option("--objective", "objective_name", default="net-power", show_default=True,
              help="Objective plugin whose cost is bounded (`gaitbench plugins --kind objective`).")
@click.option("--objective-option", "objective_options", multiple=True, metavar="KEY=VALUE",
              help="Passed to the objective, e.g. --objective-option margaria=true (repeatable).")
@click.option("--push-off-cost", type=click.Choice(PUSH_OFF_COSTS), default="impulse", show_default=True,
              help="impulse: push-off costs the kinetic energy its impulse adds (the objectives' accounting); "
                   "thesis: the thesis's (3.77), 1/2 m_stance |v_foot|^2, 26-31 % of that at the thesis's poses.")
@click.option("--start-pose", type=click.Choice(START_POSES), default="on-ground", show_default=True,
              help="The pose step 1 starts from, as the problem option start_pose.")
@click.option("--steps", type=click.IntRange(min=1), default=None, help="Bound only the first K steps.")
@click.option("--json", "as_json", is_flag=True, help="Print the bound as JSON (the walk, then per step).")
@click.pass_context
def bound(ctx: click.Context, experiment_name: str, experiment_options: tuple[str, ...], objective_name: str,
          objective_options: tuple[str, ...], push_off_cost: str, start_pose: str, steps: int | None,
          as_json: bool) -> None:
    """The least ACOT that any walk of an experiment can have under an objective: a physical lower bound.

    Each step starts and ends at poses the footholds fix, so the potential energy it must gain is known. The hip
    motors pay for the change of the mechanical energy over each swing (|W| at least), push-off adds kinetic energy
    at its cost, heel strike only loses it, and the walk may spend the kinetic energy of its start state where it
    helps. The least mean COT over these energy balances is a small linear program; no transcription, grid or
    solver can beat it. Per step: the step's COT in that optimal walk, and the bound of the walk stopped after it.

    Flat ground and downhill walks need no energy they do not have (bound 0), and an objective that charges
    torque rather than work (torque-squared) has no such bound: the command says so instead of printing 0.
    """
    from gaitbench.solve.bound import NoBound, walk_bound

    experiment = create(ctx, "experiment", experiment_name, **parse_options(experiment_options, "--experiment-option"))
    objective = create(ctx, "objective", objective_name, **parse_options(objective_options, "--objective-option"))
    if steps is not None and steps > experiment.n_steps:
        raise click.BadParameter(f"{experiment_name} has {experiment.n_steps} steps", param_hint="--steps")
    try:
        result = walk_bound(experiment, objective, push_off_cost, start_pose, steps)
    except NoBound as error:
        if as_json:
            click.echo(json.dumps({"experiment": experiment.name, "objective": objective.describe(),
                                   "push_off_cost": push_off_cost, "start_pose": start_pose, "acot": None,
                                   "useful": False, "message": str(error), "steps": []}, indent=2))
        else:
            print_plain(Console(), str(error), "yellow")
        return
    except ValueError as error:  # a step whose chord the legs cannot span
        raise click.ClickException(f"{experiment_name}: {error}") from None
    if as_json:
        click.echo(json.dumps(result.as_dict(), indent=2))
        return
    _print_bound(Console(), result)


def _print_bound(console: Console, result) -> None:
    thesis = result.push_off_cost == "thesis"
    table = Table(title=f"{result.experiment}: least COT of any walk ({result.objective}, "
                        f"push-off {result.push_off_cost})")
    columns = ["step", "stance", "D (m)", "ΔV (J)", *(["PO J/J"] if thesis else []), "W (J)", "E_PO (J)", "COT",
               "to here"]
    for column in columns:
        table.add_column(column, justify="right")
    for step in result.steps:
        ratio = [f"{step.push_off_ratio:.3f}"] if thesis else []
        table.add_row(str(step.index), f"Leg {step.stance}", f"{step.chord:.3f}", f"{step.potential_gain:.1f}", *ratio,
                      f"{step.hip_work:.1f}", f"{step.push_off_energy:.1f}", f"{step.cot:.4f}",
                      f"{step.prefix_acot:.4f}")
    console.print(table)
    notes = [f"Start state's kinetic energy: {result.start_kinetic_energy:.1f} J ({result.start_pose} pose).",
             "ΔV: potential energy the step gains; W, E_PO, COT: hip work, push-off energy and COT of one optimal walk "
             "of the linear program; to here: the bound of the walk stopped after that step."]
    if thesis:
        notes.append("PO J/J: joules the thesis's 1/2 m_stance |v_foot|^2 charges per joule of push-off energy.")
    for note in notes:
        print_plain(console, note, "")
    if not result.useful:
        print_plain(console, result.message, "yellow")
        return
    print_plain(console, f"ACOT bound = {result.acot:.4f} over {len(result.steps)} steps: every walk of "
                f"{result.experiment} costs at least this under {result.objective}", "bold")
