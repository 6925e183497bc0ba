"""Shared CLI plumbing: one-line errors with exit code 2, IC parsing, checked outputs.

Every failure a user can cause ends as exactly one line on stderr,
``dicetrace: error: ...`` naming the option or path, with exit code 2, and
nothing written.  Warnings of the libraries underneath are held back while
a command runs: printed (one line each) when it succeeds, dropped when it
fails (the error line says what went wrong).  dicetrace's own notices
(a damaged scan chunk recomputed) are printed at once.
"""

from __future__ import annotations

import contextlib
import math
import os
import sys
import warnings
from pathlib import Path

import typer

try:  # typer >= 0.20 vendors its own click
    from typer._click import exceptions as _typer_click
except ImportError:  # pragma: no cover - older typer uses click itself
    _typer_click = None
try:  # click itself: not a dependency of typer >= 0.20 (nor of the base install), but installed by others
    import click
except ImportError:
    click = None

from dicetrace.commands._compiling import compile_notice
from dicetrace.extras import MissingExtra
from dicetrace.sinks._common import OutputError, destination, output_folder, staged

EXIT_BAD_INPUT = 2
EXIT_NUMERICAL_FAILURE = 1  # a throw ended in a numerical failure (non_finite, blow_up): simulate, record, scan --strict
EXIT_INTERNAL = 70  # EX_SOFTWARE: a defect, not the user's input

#: Set to 1 to let an unexpected exception through with its traceback (for reporting a defect).
DEBUG_ENV = "DICETRACE_DEBUG"


class BadInput(Exception):
    """Bad user input: reported as one line, exit code 2."""


def fail(message: str) -> None:
    """Raise :class:`BadInput` (caught by :func:`run_app`)."""
    raise BadInput(message)


def one_line(text) -> str:
    """``text`` as one line (line breaks become spaces)."""
    return " ".join(str(text).replace("\r", "\n").split("\n")).strip()


def _click_exceptions():
    """(UsageError, ClickException, Exit) classes of both click and typer's vendored click."""
    usage, cexc, exits = [], [], []
    if click is not None:
        usage, cexc, exits = [click.exceptions.UsageError], [click.exceptions.ClickException], [click.exceptions.Exit]
    if _typer_click is not None:
        usage.append(_typer_click.UsageError)
        cexc.append(_typer_click.ClickException)
    exits.append(typer.Exit)
    return tuple(usage), tuple(cexc), tuple(exits)


def _immediate(category) -> bool:
    """dicetrace's own notices are shown as they happen."""
    try:
        from dicetrace.scan.folder import ScanWarning  # lazy: keeps `dicetrace --help` fast (imports numba)
    except ImportError:  # pragma: no cover
        return False
    return issubclass(category, ScanWarning)


def _print_err(line: str) -> None:
    if sys.stderr is not None:
        try:
            print(line, file=sys.stderr, flush=True)
        except (OSError, ValueError):
            pass


def _silence_stdout() -> None:
    """After a failed write to stdout: point fd 1 at /dev/null so that the interpreter's exit flush is quiet."""
    with contextlib.suppress(Exception):
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, 1)
        os.close(devnull)


def _flush_stdout() -> None:
    if sys.stdout is not None:
        sys.stdout.flush()


def run_app(app: typer.Typer) -> None:
    """Run the typer app; bad input → ``dicetrace: error: ...`` (one line) and exit 2."""
    usage, cexc, exits = _click_exceptions()
    held: list[str] = []

    def show(message, category, filename, lineno, file=None, line=None):
        text = f"dicetrace: warning: {one_line(message)}"
        if _immediate(category):
            _print_err(text)
        elif text not in held:
            held.append(text)

    def error(msg, code=EXIT_BAD_INPUT):
        with contextlib.suppress(Exception):
            _flush_stdout()
        _print_err(f"dicetrace: error: {one_line(msg)}")
        sys.exit(code)

    with warnings.catch_warnings():  # the filters stay as they are; only how a warning is shown changes
        warnings.showwarning = show
        try:
            with compile_notice():
                rc = app(standalone_mode=False)
            try:
                _flush_stdout()
            except OSError as e:  # stdout is a full device, a closed pipe, ...
                _silence_stdout()
                raise BadInput(f"cannot write standard output: {e.strerror or e}") from None
        except (BadInput, ValueError, MissingExtra) as e:  # ValueError: validation in params/ics/simulate (and OutputError)
            error(e)
        except usage as e:
            if type(e).__name__ == "NoArgsIsHelpError":  # bare `dicetrace`: help was printed
                sys.exit(0)
            error(e.format_message())
        except exits as e:
            sys.exit(getattr(e, "exit_code", 0))
        except cexc as e:
            error(e.format_message(), getattr(e, "exit_code", 1) or 1)
        except (typer.Abort, KeyboardInterrupt):
            _print_err("dicetrace: interrupted")
            sys.exit(130)
        except OSError as e:
            if isinstance(e, BrokenPipeError):
                _silence_stdout()
                error(f"cannot write standard output: {e.strerror or e}")
            where = f": {e.filename}" if e.filename else ""
            error(f"{e.strerror or e}{where}")
        except MemoryError as e:
            error(f"out of memory{': ' + str(e) if str(e) else ''}: use a smaller input (fewer ICs, a larger --dt, a shorter --t-max)")
        except SystemExit:
            raise
        except Exception as e:  # a defect: one line, and the way to see its traceback
            if os.environ.get(DEBUG_ENV):
                raise
            error(f"internal error ({type(e).__name__}: {one_line(e)[:300]}); run with {DEBUG_ENV}=1 for the "
                  "traceback and please report it", EXIT_INTERNAL)
    for text in held:
        _print_err(text)
    sys.exit(rc if isinstance(rc, int) else 0)


def parse_floats(text: str, n: int | None, what: str) -> list[float]:
    """Parse ``"a,b,c"`` into floats, checking the count and finiteness."""
    parts = [p.strip() for p in text.split(",")]
    try:
        vals = [float(p) for p in parts]
    except ValueError:
        fail(f"{what} must be comma-separated numbers, got {text!r}")
    if n is not None and len(vals) != n:
        fail(f"{what} needs {n} comma-separated numbers, got {len(vals)} in {text!r}")
    bad = [p for p, v in zip(parts, vals) if not math.isfinite(v)]
    if bad:
        fail(f"{what} has a non-finite value ({', '.join(bad)}) in {text!r}")
    return vals


def output_file(path, option: str, *, suffix: str | None = None, allow_stdout: bool = True, expected_bytes=None):
    """The checked :class:`~dicetrace.sinks._common.Destination` of an output option, or a one-line failure.

    Checked before any work: the folder exists or can be made and is
    writable (probed), the path is no folder, ``suffix`` is there for a
    regular file; a character device, a FIFO or ``-`` (standard output)
    are written directly.  Nothing is created.
    """
    try:
        return destination(path, what=option, suffix=suffix, allow_stdout=allow_stdout, expected_bytes=expected_bytes)
    except OutputError as e:
        fail(str(e))


def output_dir(path, option: str, *, expected_bytes=None) -> Path:
    """An output folder option checked before any work (exists or can be made; writable), or a one-line failure."""
    try:
        return output_folder(path, what=option, expected_bytes=expected_bytes)
    except OutputError as e:
        fail(str(e))


def check_writable_file(path: Path) -> Path:
    """Fail (exit 2) unless ``path`` can be written (see :func:`output_file`); nothing is created."""
    output_file(path, "output", allow_stdout=False)
    return Path(path)


@contextlib.contextmanager
def atomic_path(path: Path):
    """Yield a temporary path for ``path``; put it in place on success only (see ``dicetrace.sinks._common.staged``).

    Nothing is left behind on failure, and an existing file is untouched
    until the new one is complete.
    """
    with staged(path) as tmp:
        yield tmp
