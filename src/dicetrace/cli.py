"""The ``dicetrace`` command: one sub-command per job, ``--version``, and how ``--help`` shows options.

Each sub-command lives in ``dicetrace.commands.<name>`` and registers itself
on ``app``.  Bad input is reported as one line on stderr with exit code 2
(see ``commands._common.fail``), never as a traceback; so is Ctrl-C, exit
130, from the first moment: a handler installed before anything heavy is
imported covers the loading of the modules (the console script and
``python -m dicetrace`` both import this module first, and ``import
dicetrace`` itself loads nothing heavy), then ``run_app`` takes over.  ``--help`` shows no
type column where typer's default says nothing the help does not (``<bool>``
on a flag, ``<str>``, ``<path>``); numbers, choices and explicit metavars
stay.  Each command's description is re-wrapped for the terminal's width when ``--help`` prints it
(:func:`reflow`): prose paragraphs flow as one text, and the rows of an indented table keep their
hanging indent.
"""

from __future__ import annotations

import os
import signal
import sys


def _interrupted_while_loading(signum, frame) -> None:  # runs in a subprocess of the tests (tests/test_main.py)
    """Ctrl-C while the command's modules load: one line and exit 130 at once (nothing has started, nothing is
    kept): not a traceback out of whichever import it interrupted."""
    try:
        os.write(2, b"dicetrace: interrupted\n")
    except OSError:  # standard error closed or full: the exit code says it
        pass
    os._exit(130)


def _catch_interrupts_while_loading() -> bool:
    """Install :func:`_interrupted_while_loading` for SIGINT, before the heavy imports below, where Python's own
    handler is in place in the main thread; True if installed (:func:`run_app` takes over once they are done)."""
    try:
        if signal.getsignal(signal.SIGINT) is signal.default_int_handler:
            signal.signal(signal.SIGINT, _interrupted_while_loading)
            return True
    except ValueError:  # not the main thread: imported, not run
        pass
    return False


def _occupy_closed_std_fds() -> None:
    """Open /dev/null on fds 0, 1 and 2 where they are closed (``2>&-``): otherwise the next file opened (a scan's
    lock, a chunk) would get that number, and whatever a library writes to standard error would land in it.  A
    closed standard error becomes a ``sys.stderr`` on /dev/null (None, ``print(file=sys.stderr)`` would write to
    standard output): what a command says there is dropped, and decides nothing.  A closed standard output stays
    None: output asked for there is refused (``sinks._common``), never dropped."""
    for fd in (0, 1, 2):
        try:
            os.fstat(fd)
        except OSError:
            if fd == 1:  # closed after Python started (its sys.stdout still names fd 1): closed to us too
                sys.stdout = None
            try:
                got = os.open(os.devnull, os.O_RDWR)
            except OSError:
                return
            if got != fd:  # a lower one was free after all: not ours to fill
                os.close(got)
    if sys.stderr is None:
        try:
            sys.stderr = open(2, "w", closefd=False, errors="backslashreplace")  # noqa: SIM115 (the process's own)
        except OSError:
            pass


_occupy_closed_std_fds()
_LOADING = _catch_interrupts_while_loading()

import importlib  # noqa: E402  (the imports after the handler: typer, rich, the commands' modules)
import inspect  # noqa: E402
import platform  # noqa: E402
import re  # noqa: E402
import textwrap  # noqa: E402
from importlib import metadata  # noqa: E402

import typer  # noqa: E402
from typer.core import TyperCommand, TyperGroup  # noqa: E402

import dicetrace  # noqa: E402
from dicetrace.commands._common import run_app  # noqa: E402

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


#: The fields of a table row before its last one: words each followed by two or more spaces.
_ROW_HEAD = re.compile(r"^(\s*(?:\S+(?: \S+)*\s{2,})+)(?=\S)")


def _wrap(text: str, width: int, first: str = "", rest: str = "") -> list[str]:
    return textwrap.wrap(text, width=width, initial_indent=first, subsequent_indent=rest,
                         break_long_words=False, break_on_hyphens=False) or [first.rstrip()]


def reflow(help_text: str, width: int) -> str:
    """``help_text`` laid out for ``width`` columns: its prose paragraphs (separated by blank lines) joined
    and wrapped at word boundaries, and the rows of a table (a paragraph whose lines are indented) each
    wrapped with a hanging indent under its last field.  The first paragraph is only joined: typer shows
    it as the command's title and wraps it itself."""
    paragraphs = inspect.cleandoc(help_text).split("\n\n")
    out = [" ".join(paragraphs[0].split())]
    width = max(width, 20)
    for para in paragraphs[1:]:
        lines = para.splitlines()
        if lines and all(ln[:1].isspace() for ln in lines):  # a table: one row a line
            rows = []
            for ln in lines:
                lead = ln[: len(ln) - len(ln.lstrip())]
                head = _ROW_HEAD.match(ln)
                if head and len(head.group(1)) <= width // 2:  # the last field hangs under its own start
                    rows += _wrap(ln[head.end(1):], width, head.group(1), " " * len(head.group(1)))
                else:
                    rows += _wrap(ln.lstrip(), width, lead, lead + "    ")
            out.append("\n".join(rows))
        else:
            out.append("\n".join(_wrap(" ".join(para.split()), width)))
    return "\n\n".join(out)


def _help_width() -> int:
    """The columns typer's help gives a command's description: the console's width less its padding of 1 a side."""
    from typer import rich_utils

    return rich_utils._get_rich_console().width - 2


class _Reflowed:
    """``format_help`` with the description re-wrapped for this terminal (:func:`reflow`)."""

    def format_help(self, ctx, formatter):
        original = self.help
        if original:
            self.help = reflow(original, _help_width())
        try:
            return super().format_help(ctx, formatter)
        finally:
            self.help = original


class _Command(_Reflowed, TyperCommand):
    """A ``dicetrace`` sub-command: typer's, its description re-wrapped for the terminal."""


class _Group(_Reflowed, TyperGroup):
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

_COMMANDS = ("record", "simulate", "throw", "scan", "accuracy", "analyze", "explore")


def _register() -> None:
    for name in _COMMANDS:
        try:
            mod = importlib.import_module(f"dicetrace.commands.{name}")
        except ModuleNotFoundError as e:  # a command module not written yet
            if e.name != f"dicetrace.commands.{name}":
                raise
            continue
        mod.register(app)
    for info in app.registered_commands:  # every sub-command's --help re-wrapped for the terminal
        if info.cls in (None, TyperCommand):
            info.cls = _Command


_register()
if _LOADING:  # loaded: Ctrl-C is KeyboardInterrupt again, which run_app turns into its one line
    signal.signal(signal.SIGINT, signal.default_int_handler)


def main() -> None:
    run_app(app)


if __name__ == "__main__":
    main()
