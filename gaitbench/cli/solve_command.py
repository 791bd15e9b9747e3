"""``gaitbench solve``: one experiment's walk, solved with a strategy, verified step by step, and saved as a walk
file (:mod:`gaitbench.solve.walk_file`)."""

from __future__ import annotations

from pathlib import Path

import click
from rich import box
from rich.console import Console
from rich.table import Table

from gaitbench.cli.common import check_out, count, create, fmt, parse_options, print_plain


def _check_memory(transcription: str, strategy: str, n_nodes: int, steps: int) -> None:
    """A usage error when the walk cannot fit in memory (:mod:`gaitbench.run.memory`), before anything is built."""
    from gaitbench.run.memory import memory_problem

    try:
        problem = memory_problem(transcription, strategy, n_nodes, steps, what=f"{strategy} {transcription}")
    except ValueError as exc:  # a GAITBENCH_MEMORY_LIMIT that is not a size
        raise click.UsageError(str(exc)) from None
    if problem is not None:
        raise click.BadParameter(problem, param_hint="--N")


PROBLEM_OPTION_HINT = "'-p' / '--problem-option'"


class _SolveCommand(click.Command):
    """``solve``, whose help ends with the problem options and their values. They are read from the suite schema
    (the same checker a suite's ``problem_options`` uses) only when the help is shown, so the CLI stays quick to
    import."""

    def format_epilog(self, ctx: click.Context, formatter: click.HelpFormatter) -> None:
        from gaitbench.problem.gait_problem import ProblemOptions
        from gaitbench.run.suite_schema import problem_option_kinds

        defaults = ProblemOptions()
        rows = []
        for name, kind in problem_option_kinds().items():
            default = getattr(defaults, name)
            if default is None:
                shown = "unset: no constraint"
            else:
                shown = str(default).lower() if isinstance(default, bool) else default
            rows.append((name, f"{kind} (default {shown})"))
        with formatter.section("Problem options (-p KEY=VALUE, the keys of a suite's problem_options)"):
            formatter.write_dl(rows)
        super().format_epilog(ctx, formatter)


def _problem_options(pairs: tuple[str, ...], **flags: object) -> dict[str, object]:
    """The ``-p KEY=VALUE`` overrides of :class:`~gaitbench.problem.gait_problem.ProblemOptions`, checked as a suite's
    ``problem_options`` are; ``flags`` are the older single-option flags (None when not given)."""
    from gaitbench.run.suite_schema import problem_option_error

    options = parse_options(pairs, PROBLEM_OPTION_HINT)
    for name, value in flags.items():
        if value is None:
            continue
        if name in options and options[name] != value:
            raise click.BadParameter(f"{name} is given twice, as {options[name]!r} and {value!r} (its own flag)",
                                     param_hint=PROBLEM_OPTION_HINT)
        options[name] = value
    for name, value in options.items():
        problem = problem_option_error(name, value)
        if problem is not None:
            raise click.BadParameter(f"{name}: {problem}" if not problem.startswith("unknown") else problem,
                                     param_hint=PROBLEM_OPTION_HINT)
    return options


@click.command("solve", cls=_SolveCommand)
@click.option("--experiment", "-e", "experiment_name", required=True, help="Experiment plugin, e.g. forward.")
@click.option(
    "--experiment-option",
    "experiment_options",
    multiple=True,
    metavar="KEY=VALUE",
    help="Passed to the experiment, e.g. --experiment-option mass_ratio=0.3 for energetics (repeatable).",
)
@click.option("--transcription", "-t", default="hermite-simpson", show_default=True, help="Transcription plugin.")
@click.option("--solver", "-s", "solver_name", default="ipopt", show_default=True, help="Solver plugin.")
@click.option(
    "--N",
    "n_nodes",
    type=click.IntRange(min=3),
    default=50,
    show_default=True,
    help="Nodes (points) per step; h = step duration / (N - 1).",
)
@click.option("--steps", type=click.IntRange(min=1), default=None, help="Solve only the first K steps.")
@click.option(
    "--strategy",
    "-S",
    "strategy_name",
    default="one-phase",
    show_default=True,
    help="Strategy plugin: one-phase, warm-start, decrease-and-conquer, whole-walk, ...",
)
@click.option(
    "--strategy-option",
    "-x",
    "strategy_options",
    multiple=True,
    metavar="KEY=VALUE",
    help="Passed to the strategy, e.g. -x phase=first (one-phase on the 2-DOF problem), -x polish=false.",
)
@click.option(
    "--solver-option",
    "-o",
    "solver_options",
    multiple=True,
    metavar="KEY=VALUE",
    help="Passed to the solver, e.g. -o max_iterations=500 -o linear_solver=mumps (repeatable).",
)
@click.option(
    "--objective",
    "objective_name",
    default="net-power",
    show_default=True,
    help="Objective plugin: what each step minimises and every reported COT measures (net-power, the thesis's "
         "cost; actuator-work; torque-squared; `gaitbench plugins --kind objective`).",
)
@click.option(
    "--objective-option",
    "objective_options",
    multiple=True,
    metavar="KEY=VALUE",
    help="Passed to the objective, e.g. --objective-option margaria=true (repeatable).",
)
@click.option(
    "--problem-option",
    "-p",
    "problem_options",
    multiple=True,
    metavar="KEY=VALUE",
    help="Overrides a gait-problem option, as a suite's problem_options does (repeatable; the keys and values are "
         "listed below), e.g. -p clearance=off (scuffing allowed) -p lift_off=false.",
)
@click.option(
    "--abs",
    "--absolute-value",
    "absolute_value",
    type=click.Choice(["slack", "smooth"]),
    default=None,
    help="|hip power| in the NLP: exact slack split (default), or the thesis's sqrt(x^2 + eps^2). "
         "Same as -p absolute_value=...",
)
@click.option(
    "--torque-regularization",
    type=click.FloatRange(min=0),
    default=None,
    help="Tie-break rho * integral of |tau|^2 added to the energy, never to the reported COT (default 0). "
         "Same as -p torque_regularization=...",
)
@click.option(
    "--out",
    type=click.Path(path_type=Path),
    default=None,
    help="Write the walk file: JSON, trajectories beside it as .npz (gaitbench track reads it).",
)
@click.pass_context
def solve(
    ctx: click.Context,
    experiment_name: str,
    experiment_options: tuple[str, ...],
    transcription: str,
    solver_name: str,
    n_nodes: int,
    steps: int | None,
    strategy_name: str,
    strategy_options: tuple[str, ...],
    solver_options: tuple[str, ...],
    objective_name: str,
    objective_options: tuple[str, ...],
    problem_options: tuple[str, ...],
    absolute_value: str | None,
    torque_regularization: float | None,
    out: Path | None,
) -> None:
    """Solve an experiment's walk with a strategy, and verify every step.

    Step-by-step strategies solve each step from the heel-strike state of the previous one. Every reported step is
    checked: its largest dynamic defect, its re-simulation error, and its COT recomputed from the trajectory
    itself. A step the solver fails goes through the retry ladder, a coarse-grid rescue and, under One Phase, a
    back-up onto the step before; the walk stops at the first step none of them solves, keeping what was
    solved. The thresholds are judged on the whole walk at the end (joins included). Exit status 1 if the walk is
    incomplete or not verified.
    """
    from gaitbench.contracts import StepsOutOfRange
    from gaitbench.cores import IdleCores
    from gaitbench.run.case import PluginChoice
    from gaitbench.solve.walk_assembly import assemble_walk
    from gaitbench.solve.walk_file import write_walk
    from gaitbench.solve.walk_verification import solve_verified

    check_out(out)
    overrides = _problem_options(problem_options, absolute_value=absolute_value,
                                 torque_regularization=torque_regularization)
    cores = IdleCores.machine()
    try:
        strategy, problem = assemble_walk(
            lambda kind, name, **options: create(ctx, kind, name, **options), n_nodes,
            experiment=PluginChoice(experiment_name, parse_options(experiment_options, "--experiment-option")),
            transcription=PluginChoice(transcription),
            solver=PluginChoice(solver_name, parse_options(solver_options, "--solver-option")),
            strategy=PluginChoice(strategy_name, parse_options(strategy_options, "--strategy-option")),
            objective=PluginChoice(objective_name, parse_options(objective_options, "--objective-option")),
            steps=steps, problem_options=overrides, cores=cores)
    except StepsOutOfRange as exc:
        raise click.BadParameter(str(exc), param_hint="--steps") from None
    _check_memory(transcription, strategy_name, n_nodes, problem.n_steps)
    console = Console()
    total = problem.n_steps
    try:
        with console.status(f"solving step 1 of {total}") as status, cores.occupy():
            walk = solve_verified(strategy, problem,
                                  on_step=lambda outcome: status.update(step_status(outcome, total)))
    except Exception as exc:  # a plugin's fault, or gaitbench's: said in one line, as `gaitbench run` records it
        from gaitbench.run.runner import describe_error

        raise click.ClickException(f"the walk stopped on an error, not a failed step: {describe_error(exc)}") \
            from None
    _print_walk(console, walk)
    if out is not None:
        console.print(f"wrote {write_walk(walk, out)}")
    if not (walk.complete and walk.verified):
        ctx.exit(1)


def step_status(outcome, total: int) -> str:
    """What the spinner of `solve` says once a step is done: the next step, or how the walk ended."""
    if not outcome.solved:
        return f"step {outcome.index} of {total} not solved: the walk stops"
    if outcome.index >= total:
        return f"all {total} steps solved"
    return f"solving step {outcome.index + 1} of {total}"


def _print_walk(console: Console, walk) -> None:
    """One row per step, of the motion the walk reports (for decrease and conquer: its polished or complete step,
    with the patchwork's claimed COT beside it), then the verified ACOT and the verdict; the claim comes last.
    Columns: stance leg, solve time, iterations, largest dynamics defect, re-simulation error at the step's end."""
    claims = walk.claimed_acot is not None or any(step.verified is not step for step in walk.steps)
    table = Table(title=f"{walk.experiment}: {walk.strategy}, {walk.transcription} + {walk.solver}, N = {walk.N}, "
                        f"objective {walk.objective}", box=box.SIMPLE_HEAD, pad_edge=False, collapse_padding=True)
    columns = ["step", "leg", "status", "COT", *(["claimed"] if claims else []), "time s", "iter", "defect", "resim"]
    for column in columns:  # 75 columns with the longest status (iteration_limit) and the claim
        table.add_column(column, justify="left" if column == "status" else "right", no_wrap=True, overflow="fold")
    for step in walk.steps:
        motion = step.verified
        row = motion.as_dict()
        own = step.as_dict()
        cells = [fmt(row["cot"], ".4f"), *([fmt(own["cot"], ".4f")] if claims else []),
                 fmt(row["solve_time_s"], ".2f"), fmt(row["iterations"], "d"), fmt(row["max_defect"], ".1e"),
                 fmt(row["resim_error"], ".1e")]
        table.add_row(str(step.index), str(step.stance), motion.status, *cells)
    console.print(table)
    verification = walk.verification
    if walk.complete:
        figure = "verified ACOT" if walk.verified else "ACOT"
        summary = f"{figure} = {walk.acot:.4f} over {count(len(walk.steps), 'step')} ({walk.wall_time_s:.1f} s)"
        if verification is not None and not walk.verified:
            summary += f"; NOT verified: {verification.reason}"
        console.print(summary)
    else:
        print_plain(console, f"incomplete walk: {walk.failure}", "red")
    if verification is not None and verification.steps:
        console.print(f"largest join mismatch {verification.max_join_mismatch:.1e}, largest re-simulation error "
                      f"{verification.max_resim_error:.1e}")
    if claims and walk.claimed_acot is not None:
        details = walk.strategy_details
        failing = len(walk.steps) - details.get("steps_satisfying_dynamics", 0)
        console.print(f"claimed ACOT {walk.claimed_acot:.4f}: the chosen patchworks, not motions ({failing} of "
                      f"{len(walk.steps)} fail the dynamics); the table's COT is each step's polished or complete "
                      "motion")
