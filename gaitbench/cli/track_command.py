"""``gaitbench track``: a walk file followed in closed loop by a controller, an observer and a disturbance
(:mod:`gaitbench.control`)."""

from __future__ import annotations

from pathlib import Path

import click
from rich.console import Console
from rich.table import Table

from gaitbench.cli.common import check_out, create, fmt, parse_options, print_plain
from gaitbench.plugins import PluginBuildError, PluginConflictError, UnknownPluginError


@click.command("track")
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

    The robot is the experiment the walk was solved for, with its options; the reference is the transcription's own
    interpolant of each step. The robot runs under the controller, the observer's estimates and the disturbance over
    all stored steps, with push-off and heel strike between them.
    Prints per-step errors and the ACOT against the reference. Exit status 1 if the robot fell.
    """
    from gaitbench.control.closed_loop import track as run_tracking
    from gaitbench.control.reference import TrackingInputError, load_reference
    from gaitbench.solve.walk_file import WalkFileError

    check_out(out, result)
    try:
        reference = load_reference(result, ctx.obj.registry)
    except (WalkFileError, TrackingInputError) as exc:
        raise click.BadParameter(str(exc), param_hint="RESULT") from None
    except (UnknownPluginError, PluginConflictError, PluginBuildError) as exc:  # named by the walk file
        raise click.BadParameter(f"{result}: was solved with a plugin not usable here: {exc}",
                                 param_hint="RESULT") from None
    if steps is not None and steps > len(reference.steps):
        raise click.BadParameter(f"{steps}: the walk in {result} has {len(reference.steps)} steps",
                                 param_hint="--steps")
    options = {"controller": parse_options(controller_options, "--controller-option"),
               "observer": parse_options(observer_options, "--observer-option"),
               "disturbance": parse_options(disturbance_options, "--disturbance-option")}
    model = reference.model
    plugins = {
        "controller": create(ctx, "controller", controller, model, reference, **options["controller"]),
        "observer": create(ctx, "observer", observer, model, **options["observer"]),
        "disturbance": create(ctx, "disturbance", disturbance, reference.experiment, **options["disturbance"]),
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
    if tracked.fell or tracked.failure:
        ctx.exit(1)



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
                      f"{estimate['leg2']:.1e}", fmt(step["cot_reference"], ".4f"), fmt(step["cot_tracked"], ".4f"))
    console.print(table)
    console.print(f"position error ≤ {data['max_position_error']:.2e} rad, velocity-estimation error ≤ "
                  f"{data['max_velocity_error']:.2e} rad/s")
    if data["walk"].get("trajectory") == "polished":
        console.print("reference: the verified trajectory, each step polished from the chosen patchwork")
    if data["acot_tracked"] is not None:
        increase = fmt(data["acot_increase_percent"], "+.2f", "n/a")  # n/a: a free reference
        console.print(f"ACOT tracked {data['acot_tracked']:.4f} against the reference's {data['acot_reference']:.4f} "
                      f"({increase} %) over {data['steps_tracked']} step(s); perfect tracking of the exact model "
                      f"would cost {data['acot_ideal']:.4f}")
    if data["torque_limit_exceeded"]:
        print_plain(console, f"torques reached {data['max_torque']:.0f} N·m, above the limit "
                        f"{data['torque_limit']:.0f} N·m (not enforced)", "yellow")
    if data["fall"]:
        fall = data["fall"]
        print_plain(console, f"fell in step {fall['step']} at t = {fall['time']:.4f} s: {fall['reason']}", "red")
    if data["failure"]:
        print_plain(console, f"simulation failed: {data['failure']}", "red")
