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


def run_app(app: typer.Typer) -> None:
    """Run the typer app; bad input → ``dicetrace: error: ...`` and exit 2."""
    try:
        app(standalone_mode=False)
    except BadInput as e:
        print(f"dicetrace: error: {e}", file=sys.stderr)
        sys.exit(EXIT_BAD_INPUT)
    except ValueError as e:  # validation errors from params/ics/simulate
        print(f"dicetrace: error: {e}", file=sys.stderr)
        sys.exit(EXIT_BAD_INPUT)
    except typer.Abort:
        print("dicetrace: aborted", file=sys.stderr)
        sys.exit(130)
    except KeyboardInterrupt:
        print("dicetrace: interrupted", file=sys.stderr)
        sys.exit(130)
    except Exception as e:  # click usage errors and the like
        import click

        if isinstance(e, click.exceptions.UsageError):
            msg = e.format_message()
            print(f"dicetrace: error: {msg}", file=sys.stderr)
            sys.exit(EXIT_BAD_INPUT)
        if isinstance(e, click.exceptions.Exit):
            sys.exit(e.exit_code)
        if isinstance(e, OSError):
            print(f"dicetrace: error: {e.strerror or e}: {e.filename or ''}".rstrip(": "), file=sys.stderr)
            sys.exit(EXIT_BAD_INPUT)
        raise


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
    try:
        yield tmp
        os.replace(tmp, path)
    finally:
        if tmp.exists():
            tmp.unlink()
