"""The ``dicetrace`` command: one sub-command per job, ``--version``, and how ``--help`` shows options.

Each sub-command lives in ``dicetrace.commands.<name>`` and registers itself
on ``app``.  Bad input is reported as one line on stderr with exit code 2
(see ``commands._common.fail``), never as a traceback.  ``--help`` shows no
type column where typer's default says nothing the help does not (``<bool>``
on a flag, ``<str>``, ``<path>``); numbers, choices and explicit metavars
stay.
"""

from __future__ import annotations

import importlib
import platform
from importlib import metadata

import typer
from typer.core import TyperGroup

import dicetrace
from dicetrace.commands._common import run_app

#: typer's default type labels that add nothing to an option's help (a flag's ``<bool>``, text, paths).
NOISE_TYPES = frozenset({"<bool>", "<str>", "<path>", "<list[str]>", "<list[path]>"})


def _no_type(ctx) -> str:
    return ""


def tidy_params(params, ctx) -> list:
    """Drop typer's uninformative type label from these options and arguments (``--help`` included); returns them."""
    for p in params:
        if hasattr(p, "display_type_rich") and p.display_type_rich(ctx) in NOISE_TYPES:  # an explicit metavar stays
            p.display_type_rich = _no_type  # this instance only: the label is display, not parsing
    return params


class _Group(TyperGroup):
    """The ``dicetrace`` group: its own and every sub-command's parameters shown without the noise labels."""

    def get_params(self, ctx):
        return tidy_params(super().get_params(ctx), ctx)

    def get_command(self, ctx, cmd_name):
        command = super().get_command(ctx, cmd_name)
        if command is not None:
            tidy_params(command.get_params(ctx), ctx)
        return command


app = typer.Typer(
    name="dicetrace",
    help="Simulate, record, scan and analyse the chaos of a rolling die.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
    cls=_Group,
)


def _versions() -> str:
    def v(dist: str) -> str:
        try:
            return metadata.version(dist)
        except metadata.PackageNotFoundError:
            return "missing"

    deps = ", ".join(f"{d} {v(d)}" for d in ("numba", "numpy", "rerun-sdk", "pyarrow"))
    return f"dicetrace {dicetrace.__version__} ({deps}; Python {platform.python_version()})"


def _print_version(value: bool) -> None:
    if value:
        print(_versions())
        raise typer.Exit()


@app.callback()
def _root(
    version: bool = typer.Option(
        False, "--version", help="Print the version (and those of numba, numpy, rerun-sdk, pyarrow) and exit.",
        is_eager=True, callback=_print_version,
    ),
) -> None:
    pass

_COMMANDS = ("record", "simulate", "scan", "accuracy", "analyze", "explore")


def _register() -> None:
    for name in _COMMANDS:
        try:
            mod = importlib.import_module(f"dicetrace.commands.{name}")
        except ModuleNotFoundError as e:  # a command module not written yet
            if e.name != f"dicetrace.commands.{name}":
                raise
            continue
        mod.register(app)


_register()


def main() -> None:
    run_app(app)


if __name__ == "__main__":
    main()
