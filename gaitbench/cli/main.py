"""The ``gaitbench`` command line: list plugins and inspect experiments.

The plugin registry is loaded only when a command needs it, so ``--help`` and ``--version`` stay instant and
never trip over a broken plugin. Plugin problems are warnings on stderr; stdout carries only the answer, so
``gaitbench plugins --json`` can be piped.
"""

from __future__ import annotations

import json
from pathlib import Path

import click
from rich.console import Console
from rich.table import Table
from rich.text import Text

from gaitbench._version import __version__
from gaitbench.plugins import (
    KINDS,
    PLUGINS_DIR_ENV,
    PluginConflictError,
    PluginDirectoryError,
    PluginRegistry,
    UnknownPluginError,
    load_registry,
)


class _State:
    """What the root command hands its subcommands: the plugin directories and, once loaded, the registry."""

    def __init__(self, plugin_dirs: tuple[Path, ...]) -> None:
        self.plugin_dirs = plugin_dirs
        self._registry: PluginRegistry | None = None

    @property
    def registry(self) -> PluginRegistry:
        if self._registry is None:
            try:
                self._registry = load_registry(self.plugin_dirs)
            except PluginDirectoryError as exc:
                raise click.UsageError(str(exc)) from None
            stderr = Console(stderr=True)
            for problem in self._registry.problems:
                _print(stderr, f"warning: {problem.source}: {problem.message}", "yellow")
        return self._registry


def _print(console: Console, message: str, style: str) -> None:
    """Print plain text: no markup parsing (paths and messages may contain brackets), no hard line wraps."""
    console.print(Text(message, style=style), soft_wrap=True)


EXIT_STATUS = """\b
Exit status:
  0  success
  1  the work failed or could not be done: a walk that did not
     complete, a robot that fell, a suite case that failed, a results
     store that cannot be used, a report that cannot be written
  2  usage error: an unknown command, option or plugin, a bad option
     value, an invalid suite file or walk file
Every error is one message on stderr, "Error: ...", after the
command's usage line for a usage error."""


@click.group(context_settings={"help_option_names": ["-h", "--help"]}, epilog=EXIT_STATUS)
@click.option(
    "--plugins-dir",
    "plugin_dirs",
    multiple=True,
    metavar="DIR",
    type=click.Path(path_type=Path),
    help=f"Also load every *.py file in DIR as a plugin (repeatable; see also ${PLUGINS_DIR_ENV}).",
)
@click.version_option(__version__, "--version", prog_name="gaitbench")
@click.pass_context
def main(ctx: click.Context, plugin_dirs: tuple[Path, ...]) -> None:
    """Benchmark energy-optimal walking gaits of a planar two-leg biped on shared, reproducible problems.

    Experiments, models, solvers and every other method are plugins, so a new method is compared with the
    thesis's methods on exactly the same problems.
    """
    ctx.obj = _State(plugin_dirs)


@main.command("plugins")
@click.option("--kind", type=click.Choice(sorted(KINDS)), help="Only list plugins of this kind.")
@click.option("--json", "as_json", is_flag=True, help="Print a JSON list (kind, name, module, description).")
@click.pass_obj
def plugins_command(state: _State, kind: str | None, as_json: bool) -> None:
    """List the loaded plugins and the module or file each comes from.

    Plugins that failed to load, and names registered twice, are reported as warnings on stderr.
    """
    found = state.registry.plugins(kind)
    if as_json:
        rows = [{"kind": p.kind, "name": p.name, "module": p.module, "description": p.description} for p in found]
        click.echo(json.dumps(rows, indent=2))
        return
    console = Console()
    if not found:
        _print(console, "No plugins found.", "")
        return
    table = Table("kind", "name")
    table.add_column("module", overflow="fold")  # a path cut short with an ellipsis would be useless
    table.add_column("description")
    for index, plugin in enumerate(found):
        first_of_kind = index == 0 or found[index - 1].kind != plugin.kind
        if first_of_kind and index:
            table.add_section()
        table.add_row(
            Text(plugin.kind if first_of_kind else "", style="bold"),
            Text(plugin.name, style="cyan"),
            Text(plugin.module),
            Text(plugin.description),
        )
    console.print(table)


@main.group()
def experiments() -> None:
    """Walking experiments: a robot, a terrain, an initial state and per-step timing."""


@experiments.command("list")
@click.pass_obj
def experiments_list(state: _State) -> None:
    """List the registered experiments."""
    found = state.registry.plugins("experiment")
    console = Console()
    if not found:
        _print(console, "No experiments registered.", "")
        return
    table = Table("name", "description")
    for plugin in found:
        table.add_row(Text(plugin.name, style="cyan"), Text(plugin.description))
    console.print(table)


@experiments.command("show")
@click.argument("name")
@click.pass_context
def experiments_show(ctx: click.Context, name: str) -> None:
    """Build experiment NAME and print its parameters, footholds and per-step feasibility."""
    state: _State = ctx.obj
    try:
        plugin = state.registry.get("experiment", name)
    except (UnknownPluginError, PluginConflictError) as exc:
        raise click.BadParameter(str(exc), param_hint="NAME") from None
    try:
        experiment = plugin.factory()
    except ValueError as exc:  # includes InvalidParameterError: a bad experiment definition, not a crash
        raise click.ClickException(f"experiment {name!r} is invalid: {exc}") from None
    from gaitbench.model.experiment import render_experiment  # pulls in the numerics; only this command needs it

    render_experiment(experiment, Console())


def _parse_options(pairs: tuple[str, ...], option: str) -> dict[str, object]:
    """KEY=VALUE pairs with numbers and true/false converted, for plugin factories."""
    options: dict[str, object] = {}
    for pair in pairs:
        key, sep, text = pair.partition("=")
        if not sep or not key:
            raise click.BadParameter(f"{pair!r} is not KEY=VALUE", param_hint=option)
        value: object = text
        for convert in (int, float):
            try:
                value = convert(text)
                break
            except ValueError:
                continue
        if text.lower() in ("true", "false"):
            value = text.lower() == "true"
        options[key.replace("-", "_")] = value
    return options


OPTION_OF_KIND = {"experiment": "'--experiment' / '-e'", "transcription": "'--transcription' / '-t'",
                  "solver": "'--solver' / '-s'", "strategy": "'--strategy' / '-S'", "objective": "'--objective'",
                  "controller": "'--controller'",
                  "observer": "'--observer'", "disturbance": "'--disturbance'"}
"""The option that names a plugin of each kind, for usage errors."""

OPTIONS_OF_KIND = {"solver": "'-o' / '--solver-option'", "strategy": "'-x' / '--strategy-option'",
                   "objective": "'--objective-option'",
                   "controller": "'-c' / '--controller-option'", "observer": "'--observer-option'",
                   "disturbance": "'--disturbance-option'"}
"""The option that passes a plugin's own options, for usage errors."""


def _create(ctx: click.Context, kind: str, name: str, *args, **options):
    """Build a plugin, or stop with a usage error that names what is available or what was wrong. ``args`` are what
    gaitbench passes the factory itself (a controller's model and reference); ``options`` are checked first
    (:func:`gaitbench.options.check_options`), as a suite's are."""
    from gaitbench.options import OptionError, check_options

    try:
        check_options(ctx.obj.registry.get(kind, name).factory, options, kind=kind, injected=len(args))
        return ctx.obj.registry.create(kind, name, *args, **options)
    except (UnknownPluginError, PluginConflictError) as exc:
        raise click.BadParameter(str(exc), param_hint=OPTION_OF_KIND.get(kind)) from None
    except OptionError as exc:
        raise click.BadParameter(f"{kind} {name!r}, option {exc.option}: {exc.message}",
                                 param_hint=OPTIONS_OF_KIND.get(kind)) from None
    except (TypeError, ValueError) as exc:
        raise click.BadParameter(f"cannot build {kind} {name!r} with options {options}: {exc}",
                                 param_hint=OPTION_OF_KIND.get(kind)) from None


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

    options = _parse_options(pairs, PROBLEM_OPTION_HINT)
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


@main.command("solve", cls=_SolveCommand)
@click.option("--experiment", "-e", "experiment_name", required=True, help="Experiment plugin, e.g. forward.")
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
    help="Write the result as JSON (trajectories beside it as .npz).",
)
@click.pass_context
def solve(
    ctx: click.Context,
    experiment_name: str,
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
    itself. The walk stops at the first step that fails, keeping what was solved. Exit status 1 if the walk is
    incomplete.
    """
    from dataclasses import replace

    from gaitbench.problem.gait_problem import ProblemOptions
    from gaitbench.solve.walk import WalkProblem

    overrides = _problem_options(problem_options, absolute_value=absolute_value,
                                 torque_regularization=torque_regularization)
    experiment = _create(ctx, "experiment", experiment_name)
    transcriber = _create(ctx, "transcription", transcription)
    solver = _create(ctx, "solver", solver_name, **_parse_options(solver_options, "--solver-option"))
    strategy = _create(ctx, "strategy", strategy_name, **_parse_options(strategy_options, "--strategy-option"))
    objective = _create(ctx, "objective", objective_name,
                        **_parse_options(objective_options, "--objective-option"))
    if steps is not None and steps > experiment.n_steps:
        raise click.BadParameter(f"{experiment_name} has {experiment.n_steps} steps", param_hint="--steps")
    _check_memory(transcription, strategy_name, n_nodes, steps or experiment.n_steps)
    options = replace(ProblemOptions(limits=experiment.limits), **overrides)
    console = Console()
    total = steps or experiment.n_steps
    with console.status(f"solving step 1 of {total}") as status:
        problem = WalkProblem(experiment, transcriber, solver, n_nodes, steps=steps, options=options,
                              objective=objective)
        walk = strategy.solve(problem, on_step=lambda outcome: status.update(step_status(outcome, total)))
    _print_walk(console, walk)
    if out is not None:
        path = walk.save(out)
        console.print(f"wrote {path}")
    if not walk.complete:
        ctx.exit(1)


@main.command("track")
@click.argument("result", type=click.Path(path_type=Path))
@click.option("--controller", default="thesis", show_default=True,
              help="Controller plugin: thesis, pfl, computed-torque, pd, ...")
@click.option("--observer", default="thesis", show_default=True,
              help="Observer plugin: thesis, velocity, disturbance, ideal, ...")
@click.option("--disturbance", default="friction", show_default=True, help="Disturbance plugin: friction, none, push.")
@click.option("--controller-option", "-c", "controller_options", multiple=True, metavar="KEY=VALUE",
              help="Passed to the controller, e.g. -c kp=400 -c kv=40 (repeatable).")
@click.option("--observer-option", "observer_options", multiple=True, metavar="KEY=VALUE",
              help="Passed to the observer, e.g. --observer-option l=300.")
@click.option("--disturbance-option", "disturbance_options", multiple=True, metavar="KEY=VALUE",
              help="Passed to the disturbance, e.g. --disturbance-option force=200.")
@click.option("--sample-rate", type=click.FloatRange(min=0, min_open=True), default=None, metavar="HZ",
              help="Sample the control law at HZ with a zero-order hold (default: continuous).")
@click.option("--steps", type=click.IntRange(min=1), default=None, help="Track only the first K steps.")
@click.option("--out", type=click.Path(path_type=Path), default=None,
              help="Write the result as JSON (time series beside it as .npz).")
@click.pass_context
def track(ctx: click.Context, result: Path, controller: str, observer: str, disturbance: str,
          controller_options: tuple[str, ...], observer_options: tuple[str, ...],
          disturbance_options: tuple[str, ...], sample_rate: float | None, steps: int | None,
          out: Path | None) -> None:
    """Track the walk in RESULT (a `solve --out` JSON, its .npz beside it) in closed loop.

    The reference is the transcription's own interpolant of each step; the robot runs under the controller, the
    observer's estimates and the disturbance over all stored steps, with push-off and heel strike between them.
    Prints per-step errors and the ACOT against the reference. Exit status 1 if the robot fell.
    """
    from gaitbench.control.tracking import TrackingInputError, load_reference
    from gaitbench.control.tracking import track as run_tracking

    try:
        reference = load_reference(result, ctx.obj.registry)
    except (TrackingInputError, UnknownPluginError, PluginConflictError) as exc:
        raise click.BadParameter(str(exc), param_hint="RESULT") from None
    options = {"controller": _parse_options(controller_options, "--controller-option"),
               "observer": _parse_options(observer_options, "--observer-option"),
               "disturbance": _parse_options(disturbance_options, "--disturbance-option")}
    model = reference.model
    plugins = {
        "controller": _create(ctx, "controller", controller, model, reference, **options["controller"]),
        "observer": _create(ctx, "observer", observer, model, **options["observer"]),
        "disturbance": _create(ctx, "disturbance", disturbance, reference.experiment, **options["disturbance"]),
    }
    names = {"controller": controller, "observer": observer, "disturbance": disturbance}
    configuration = {kind: {"name": names[kind], "options": options[kind]} for kind in names}
    console = Console()
    with console.status("tracking"):
        tracked = run_tracking(reference, plugins["controller"], plugins["observer"], plugins["disturbance"],
                               sample_rate=sample_rate, steps=steps, configuration=configuration)
    tracked.walk["source"] = str(result)
    _print_tracking(console, tracked)
    if out is not None:
        console.print(f"wrote {tracked.save(out)}")
    if tracked.fell:
        ctx.exit(1)


def step_status(outcome, total: int) -> str:
    """What the spinner of `solve` says once a step is done: the next step, or how the walk ended."""
    if not outcome.solved:
        return f"step {outcome.index} of {total} not solved: the walk stops"
    if outcome.index >= total:
        return f"all {total} steps solved"
    return f"solving step {outcome.index + 1} of {total}"


def _print_tracking(console: Console, tracked) -> None:
    data = tracked.as_dict()
    config = data["configuration"]
    rate = config["sample_rate"]
    table = Table(caption="largest |position error| and |velocity-estimation error| per leg",
                  title=f"{data['walk']['experiment']}: {config['controller']['name']} controller, "
                  f"{config['observer']['name']} observer, {config['disturbance']['name']} disturbance, "
                  + (f"sampled at {rate:g} Hz" if rate else "continuous"))
    for column in ("step", "e1 (rad)", "e2 (rad)", "q̃̇1 (rad/s)", "q̃̇2 (rad/s)", "COT ref", "COT"):
        table.add_column(column, justify="right")
    for step in data["steps"]:
        error, estimate = step["max_position_error"], step["max_velocity_error"]
        table.add_row(str(step["index"]), f"{error['leg1']:.1e}", f"{error['leg2']:.1e}", f"{estimate['leg1']:.1e}",
                      f"{estimate['leg2']:.1e}", _fmt(step["cot_reference"], ".4f"), _fmt(step["cot_tracked"], ".4f"))
    console.print(table)
    console.print(f"position error ≤ {data['max_position_error']:.2e} rad, velocity-estimation error ≤ "
                  f"{data['max_velocity_error']:.2e} rad/s")
    if data["walk"].get("trajectory") == "polished":
        console.print("reference: the verified trajectory, each step polished from the chosen patchwork")
    if data["acot_tracked"] is not None:
        console.print(f"ACOT tracked {data['acot_tracked']:.4f} against the reference's {data['acot_reference']:.4f} "
                      f"({data['acot_increase_percent']:+.2f} %) over {data['steps_tracked']} step(s); perfect "
                      f"tracking of the exact model would cost {data['acot_ideal']:.4f}")
    if data["torque_limit_exceeded"]:
        _print(console, f"torques reached {data['max_torque']:.0f} N·m, above the limit "
                        f"{data['torque_limit']:.0f} N·m (not enforced)", "yellow")
    if data["fall"]:
        fall = data["fall"]
        _print(console, f"fell in step {fall['step']} at t = {fall['time']:.4f} s: {fall['reason']}", "red")
    if data["failure"]:
        _print(console, f"simulation failed: {data['failure']}", "red")


def _print_walk(console: Console, walk) -> None:
    table = Table(title=f"{walk.experiment}: {walk.strategy}, {walk.transcription} + {walk.solver}, N = {walk.N}, "
                        f"objective {walk.objective}")
    for column in ("step", "stance", "status", "COT", "time (s)", "iterations", "max defect", "resim error"):
        table.add_column(column, justify="right" if column not in ("status",) else "left")
    for step in walk.steps:
        row = step.as_dict()
        cells = [
            _fmt(row[key], spec)
            for key, spec in (
                ("cot", ".4f"),
                ("solve_time_s", ".2f"),
                ("iterations", "d"),
                ("max_defect", ".1e"),
                ("resim_error", ".1e"),
            )
        ]
        table.add_row(str(step.index), f"Leg {step.stance}", step.status, *cells)
    console.print(table)
    if walk.complete:
        console.print(f"ACOT = {walk.acot:.4f} over {len(walk.steps)} steps ({walk.wall_time_s:.1f} s)")
    else:
        _print(console, f"incomplete walk: {walk.failure}", "red")
    details = walk.strategy_details
    if "claimed_acot" in details:
        verified = details["verified_acot"]
        failing = len(walk.steps) - details["steps_satisfying_dynamics"]
        console.print(f"claimed ACOT {_fmt(details['claimed_acot'], '.4f')}: {failing} of {len(walk.steps)} "
                      "chosen trajectories fail the dynamics (see max defect, resim error)")
        console.print(f"verified ACOT {_fmt(verified, '.4f')} (each step polished: re-solved from the chosen "
                      "trajectory)")


def _fmt(value, spec: str) -> str:
    return "—" if value is None else format(value, spec)


def _add_run_commands() -> None:
    """`run`, `runs` and `report` live in their own modules; registered here so `gaitbench --help` lists them."""
    from gaitbench.cli.report_command import report
    from gaitbench.cli.run_commands import run, runs

    main.add_command(run)
    main.add_command(runs)
    main.add_command(report)


_add_run_commands()
