"""Shared CLI plumbing: one-line errors with exit code 2, IC parsing, atomic writes."""

from __future__ import annotations

import contextlib
import math
import os
import sys
import tempfile
from pathlib import Path

import typer

EXIT_BAD_INPUT = 2


class BadInput(Exception):
    """Bad user input: reported as one line, exit code 2."""


def fail(message: str) -> None:
    """Raise :class:`BadInput` (caught by :func:`run_app`)."""
    raise BadInput(message)


def _click_exceptions():
    """(UsageError, ClickException, Exit) classes of both click and typer's vendored click."""
    import click

    usage, cexc, exits = [click.exceptions.UsageError], [click.exceptions.ClickException], [click.exceptions.Exit]
    try:  # typer >= 0.20 vendors its own click
        from typer._click import exceptions as tce

        usage.append(tce.UsageError)
        cexc.append(tce.ClickException)
    except ImportError:  # pragma: no cover - older typer uses click itself
        pass
    exits.append(typer.Exit)
    return tuple(usage), tuple(cexc), tuple(exits)


def run_app(app: typer.Typer) -> None:
    """Run the typer app; bad input → ``dicetrace: error: ...`` and exit 2."""
    usage, cexc, exits = _click_exceptions()
    try:
        rc = app(standalone_mode=False)
    except (BadInput, ValueError) as e:  # ValueError: validation in params/ics/simulate
        print(f"dicetrace: error: {e}", file=sys.stderr)
        sys.exit(EXIT_BAD_INPUT)
    except usage as e:
        if type(e).__name__ == "NoArgsIsHelpError":  # bare `dicetrace`: help was printed
            sys.exit(0)
        print(f"dicetrace: error: {e.format_message()}", file=sys.stderr)
        sys.exit(EXIT_BAD_INPUT)
    except exits as e:
        sys.exit(getattr(e, "exit_code", 0))
    except cexc as e:
        print(f"dicetrace: error: {e.format_message()}", file=sys.stderr)
        sys.exit(getattr(e, "exit_code", 1) or 1)
    except (typer.Abort, KeyboardInterrupt):
        print("dicetrace: interrupted", file=sys.stderr)
        sys.exit(130)
    except OSError as e:
        where = f": {e.filename}" if e.filename else ""
        print(f"dicetrace: error: {e.strerror or e}{where}", file=sys.stderr)
        sys.exit(EXIT_BAD_INPUT)
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


def check_writable_file(path: Path) -> Path:
    """Fail (exit 2) unless ``path``'s folder exists or can be made, and is writable."""
    path = Path(path)
    parent = path.parent if str(path.parent) else Path(".")
    try:
        parent.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        fail(f"cannot create output folder {str(parent)!r}: {e.strerror}")
    if path.is_dir():
        fail(f"output path {str(path)!r} is a folder, expected a file")
    if not os.access(parent, os.W_OK):
        fail(f"output folder {str(parent)!r} is not writable")
    return path


@contextlib.contextmanager
def atomic_path(path: Path):
    """Yield a temporary path beside ``path``; rename it over ``path`` on success only.

    Nothing is left behind on failure, and an existing file is untouched
    until the new one is complete.
    """
    path = Path(path)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    os.close(fd)
    tmp = Path(tmp)
    umask = os.umask(0)
    os.umask(umask)
    os.chmod(tmp, 0o666 & ~umask)  # mkstemp makes 0600; give the file the usual mode
    try:
        yield tmp
        os.replace(tmp, path)
    finally:
        if tmp.exists():
            tmp.unlink()
