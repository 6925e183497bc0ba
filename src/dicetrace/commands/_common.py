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
import signal
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
            _silence(2)


#: Environment variables numba reads as it loads, with what they must be: an integer >= 1 (numba would warn
#: with a traceback's text for a word and keep its default, or fail to load for 0).
NUMBA_INT_ENV = ("NUMBA_NUM_THREADS",)


def check_environment() -> None:
    """Refuse (:class:`BadInput`, one line naming the variable) what numba would choke on in the environment."""
    for name in NUMBA_INT_ENV:
        text = os.environ.get(name)
        if text is None or not text.strip():
            continue
        try:
            ok = int(text.strip()) >= 1
        except ValueError:
            ok = False
        if not ok:
            raise BadInput(f"{name}={text!r} in the environment is not a number of threads (an integer >= 1): "
                           f"set one, or unset it (every core)")


def say(line: str) -> None:
    """Print ``line`` on standard error, if it can be: closed (``2>&-``), full (``/dev/full``) or gone, what a
    command says is lost, and never decides its exit code or what it writes."""
    _print_err(line)


def stderr_is_terminal() -> bool:
    """Whether standard error is a terminal (False when it is closed)."""
    try:
        return sys.stderr is not None and sys.stderr.isatty()
    except (AttributeError, OSError, ValueError):
        return False


def _silence(fd: int) -> None:
    """After a failed write to fd 1 or 2: point it at /dev/null, so that the interpreter's exit flush (which
    would otherwise fail again and exit 120) is quiet."""
    with contextlib.suppress(Exception):
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, fd)
        os.close(devnull)


def _silence_stdout() -> None:
    _silence(1)


def _settle_stderr() -> None:
    """Flush standard error as a command ends; a failure (a full device) silences it: see :func:`say`."""
    if sys.stderr is not None:
        try:
            sys.stderr.flush()
        except (OSError, ValueError):
            _silence(2)


def _flush_stdout() -> None:
    if sys.stdout is not None:
        sys.stdout.flush()


class _Interrupts:
    """While a command runs: Ctrl-C raises KeyboardInterrupt, as Python's own handler does, and is remembered
    (``seen``), so that an interrupt a library turned into another error (an extension module's ``ImportError:
    initialization failed``) still ends as one: one line, exit 130.  Only where Python's handler is in place, in
    the main thread; restored on exit."""

    #: The line a command printed on its own interrupt (:func:`say_interrupted`), for this run.
    said: str | None = None

    def __init__(self) -> None:
        self.seen = False
        self.installed = False
        _Interrupts.said = None

    def _handler(self, signum, frame) -> None:
        self.seen = True
        raise KeyboardInterrupt

    def __enter__(self) -> "_Interrupts":
        try:
            if signal.getsignal(signal.SIGINT) is signal.default_int_handler:
                signal.signal(signal.SIGINT, self._handler)
                self.installed = True
        except ValueError:  # not the main thread
            pass
        return self

    def __exit__(self, *exc) -> None:
        if self.installed:
            signal.signal(signal.SIGINT, signal.default_int_handler)


def say_interrupted(line: str) -> None:
    """Say on standard error what an interrupt leaves (a command's own line, e.g. what a scan kept), instead of
    :func:`run_app`'s plain ``dicetrace: interrupted``: still one line."""
    _Interrupts.said = line
    _print_err(line)


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

    try:  # whatever happens, standard error is settled: a full one never turns into exit 120
        with warnings.catch_warnings(), _Interrupts() as interrupts:  # the filters stay; only how a warning shows
            warnings.showwarning = show
            try:
                try:
                    check_environment()
                    with compile_notice():
                        rc = app(standalone_mode=False)
                except Exception:
                    if interrupts.seen:  # Ctrl-C inside an import (numba's, say) that turned it into an ImportError
                        raise KeyboardInterrupt from None
                    raise
                if rc == 130 and interrupts.seen:  # typer turns a command's KeyboardInterrupt into a silent exit 130
                    raise KeyboardInterrupt
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
                if _Interrupts.said is None:
                    _print_err("dicetrace: interrupted")
                sys.exit(130)
            except OSError as e:
                if isinstance(e, BrokenPipeError):
                    _silence_stdout()
                    error(f"cannot write standard output: {e.strerror or e}")
                where = f": {e.filename}" if e.filename else ""
                error(f"{e.strerror or e}{where}")
            except MemoryError as e:
                error(f"out of memory{': ' + str(e) if str(e) else ''}: use a smaller input (fewer ICs, a larger "
                      "--dt, a shorter --t-max)")
            except SystemExit:
                raise
            except Exception as e:  # a defect: one line, and the way to see its traceback
                if os.environ.get(DEBUG_ENV):
                    raise
                error(f"internal error ({type(e).__name__}: {one_line(e)[:300]}); run with {DEBUG_ENV}=1 for the "
                      "traceback and please report it", EXIT_INTERNAL)
        for text in held:
            _print_err(text)
    finally:
        _settle_stderr()
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
