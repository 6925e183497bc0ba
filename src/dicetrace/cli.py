"""The ``dicetrace`` command: one sub-command per job.

Each sub-command lives in ``dicetrace.commands.<name>`` and registers itself
on ``app``.  Bad input is reported as one line on stderr with exit code 2
(see ``commands._common.fail``), never as a traceback.
"""

from __future__ import annotations

import typer

app = typer.Typer(
    name="dicetrace",
    help="Simulate, record, scan and analyse the chaos of a rolling die.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
)

_COMMANDS = ("record", "simulate", "scan", "accuracy", "analyze", "explore")


def _register() -> None:
    import importlib

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
    from dicetrace.commands._common import run_app

    run_app(app)


if __name__ == "__main__":
    main()
