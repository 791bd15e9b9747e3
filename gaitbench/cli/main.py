"""The ``gaitbench`` command line: its root, listing plugins and inspecting experiments; ``solve``, ``track``,
``run``, ``runs`` and ``report`` live in their own modules.

The plugin registry is loaded only when a command needs it, so ``--help`` and ``--version`` stay instant and
never trip over a broken plugin. Plugin problems are warnings on stderr; stdout carries only the answer, so
``gaitbench plugins --json`` can be piped.
"""

from __future__ import annotations

import json
from pathlib import Path

import click
from rich import box
from rich.console import Console
from rich.table import Table
from rich.text import Text

from gaitbench._version import __version__
from gaitbench.cli.common import print_plain, print_table
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
                print_plain(stderr, f"warning: {problem.source}: {problem.message}", "yellow")
        return self._registry



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
@click.option("--wide", is_flag=True, help="Add the module or file each plugin comes from (lines longer than 80 "
              "columns).")
@click.pass_obj
def plugins_command(state: _State, kind: str | None, as_json: bool, wide: bool) -> None:
    """List the loaded plugins by kind, with their descriptions; --wide adds the module or file each comes from.

    Plugins that failed to load, and names registered twice, are reported as warnings on stderr.
    """
    found = state.registry.plugins(kind)
    if as_json:
        rows = [{"kind": p.kind, "name": p.name, "module": p.module, "description": p.description} for p in found]
        click.echo(json.dumps(rows, indent=2))
        return
    console = Console()
    if not found:
        print_plain(console, "No plugins found.", "")
        return
    table = Table(box=box.SIMPLE_HEAD, show_edge=False, pad_edge=False, collapse_padding=True)
    table.add_column("kind", no_wrap=True)
    table.add_column("name", no_wrap=True, min_width=max(len(plugin.name) for plugin in found))  # never cut short
    if wide:
        table.add_column("module", no_wrap=True)  # a path cut short would be useless
    table.add_column("description", overflow="fold")
    for index, plugin in enumerate(found):
        first_of_kind = index == 0 or found[index - 1].kind != plugin.kind
        if first_of_kind and index:
            table.add_section()
        table.add_row(
            Text(plugin.kind if first_of_kind else "", style="bold"),
            Text(plugin.name, style="cyan"),
            *([Text(plugin.module)] if wide else []),
            Text(plugin.description),
        )
    print_table(console, table, wide)


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
        print_plain(console, "No experiments registered.", "")
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
        state.registry.get("experiment", name)
    except (UnknownPluginError, PluginConflictError) as exc:
        raise click.BadParameter(str(exc), param_hint="NAME") from None
    try:
        experiment = state.registry.create("experiment", name)
    except ValueError as exc:  # includes InvalidParameterError: a bad experiment definition, not a crash
        raise click.ClickException(f"experiment {name!r} is invalid: {exc}") from None
    from gaitbench.model.experiment import render_experiment  # pulls in the numerics; only this command needs it

    render_experiment(experiment, Console())


def _add_commands() -> None:
    """The commands that live in their own modules; registered here so `gaitbench --help` lists them."""
    from gaitbench.cli.bound_command import bound
    from gaitbench.cli.pack_commands import pack, unpack
    from gaitbench.cli.report_command import report
    from gaitbench.cli.run_commands import run
    from gaitbench.cli.runs_commands import runs
    from gaitbench.cli.solve_command import solve
    from gaitbench.cli.track_command import track
    from gaitbench.cli.verify_command import verify

    for command in (solve, verify, bound, track, run, runs, report):
        main.add_command(command)
    runs.add_command(pack)
    runs.add_command(unpack)


_add_commands()
