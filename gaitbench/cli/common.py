"""What the command modules share: plain printing, KEY=VALUE plugin options, and building a plugin so that every
failure is a usage error naming the option to fix."""

from __future__ import annotations

from pathlib import Path

import click
from rich.console import Console
from rich.table import Table
from rich.text import Text

from gaitbench.plugins import PluginBuildError, PluginConflictError, UnknownPluginError


def print_plain(console: Console, message: str, style: str) -> None:
    """Print plain text: no markup parsing (paths and messages may contain brackets), no hard line wraps."""
    console.print(Text(message, style=style), soft_wrap=True)



def parse_options(pairs: tuple[str, ...], option: str) -> dict[str, object]:
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

OPTIONS_OF_KIND = {"experiment": "'--experiment-option'", "solver": "'-o' / '--solver-option'",
                   "strategy": "'-x' / '--strategy-option'",
                   "objective": "'--objective-option'",
                   "controller": "'-c' / '--controller-option'", "observer": "'--observer-option'",
                   "disturbance": "'--disturbance-option'"}
"""The option that passes a plugin's own options, for usage errors."""


def create(ctx: click.Context, kind: str, name: str, *args, **options):
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
    except PluginBuildError as exc:  # the plugin's own fault, whatever the options
        raise click.BadParameter(str(exc), param_hint=OPTION_OF_KIND.get(kind)) from None
    except (TypeError, ValueError) as exc:  # a value the plugin refuses: the options' flag, when there were any
        raise click.BadParameter(f"cannot build {kind} {name!r} with options {options}: {exc}",
                                 param_hint=(OPTIONS_OF_KIND if options else OPTION_OF_KIND).get(kind)) from None


def count(n: int, noun: str, plural: str | None = None) -> str:
    """``1 case``, ``2 cases``: a number with its noun in the right number."""
    return f"{n} {noun if n == 1 else plural or noun + 's'}"


def fmt(value, spec: str, missing: str = "—") -> str:
    """``value`` formatted by ``spec``, or ``missing`` for None."""
    return missing if value is None else format(value, spec)


def print_table(console: Console, table: Table, wide: bool = False) -> None:
    """Print ``table`` in the console's width, or with ``wide`` every column at its natural width: long lines rather
    than squeezed cells (what a command's ``--wide`` asks for)."""
    if wide:
        natural = console.measure(table, options=console.options.update(max_width=100_000)).maximum
        console = Console(file=console.file, width=max(console.width, natural))
    console.print(table)


def _unwritable(directory: Path) -> str | None:
    """Why no file can be made in ``directory``, found by making one (permissions alone miss read-only and special
    file systems); None when one can."""
    import tempfile

    try:
        with tempfile.TemporaryFile(dir=directory):
            return None
    except OSError as error:
        return error.strerror or str(error)


def check_out(out: Path | None, *keep: Path) -> None:
    """Refuse, before any work, an ``--out`` the result cannot be written to: a directory, a path ending in .npz
    (the trajectories go beside the JSON as .npz, and would be overwritten by it), one of the files ``keep`` (the
    input), one below a file, or one in a directory that takes no new file. Missing directories are made when the
    result is written."""
    if out is None:
        return
    problem = None
    if out.is_dir():
        problem = "is a directory; name a .json file in it"
    elif out.suffix == ".npz":
        problem = "ends in .npz, the name of the arrays written beside the JSON; name the .json file"
    elif any({out.resolve(), out.with_suffix(".npz").resolve()} & {path.resolve(), path.with_suffix(".npz").resolve()}
             for path in keep):  # the result's JSON or its arrays over the input's
        problem = "would overwrite the input or its arrays; name another file"
    elif (existing := next(parent for parent in out.resolve().parents if parent.exists())).is_file():
        problem = f"is below {existing}, a file"
    elif (refusal := _unwritable(existing)) is not None:
        problem = f"cannot be written: {existing} refuses new files ({refusal}); name a file elsewhere"
    if problem:
        raise click.BadParameter(f"{out} {problem}", param_hint="--out")
