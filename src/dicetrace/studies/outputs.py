"""Where study outputs go: a working folder by default, the committed results only by a full run.

Every study writes, unless told otherwise, into ``./dicetrace-results/<study>``
of the current folder (``dicetrace-results/`` is git-ignored).  A folder
holding a ``.committed-results`` marker (the repository's ``analysis/``) and
everything below it holds committed full-run results: only a full run, with
the default sizes and seeds, may write there, so a ``--quick`` or CI-sized run
can never overwrite them.  The commands that regenerate them are in
``analysis/README.md``::

    dicetrace analyze all --out analysis              # figures, results/*.json, REPORT.md
    dicetrace analyze accuracy --out analysis/accuracy
    dicetrace analyze stability --out analysis/accuracy
    dicetrace analyze friction --out analysis/accuracy
"""

from __future__ import annotations

import os
from pathlib import Path

#: Default root of the studies' outputs, relative to the current folder.
RESULTS_ROOT = Path("dicetrace-results")
#: Marker file of a folder of committed results.
COMMITTED_MARKER = ".committed-results"
#: Default output folder of each command (``analyze`` writes all writeup studies into one, with REPORT.md).
DEFAULT_FOLDERS = {"analyze": "analysis", "accuracy": "accuracy", "stability": "stability", "friction": "friction"}


def default_out(command: str) -> Path:
    """``./dicetrace-results/<folder>`` of the writeup studies (``analyze``) or of an integrator study
    (``accuracy``, ``stability``, ``friction``)."""
    return RESULTS_ROOT / DEFAULT_FOLDERS[command]


def committed_root(path) -> Path | None:
    """The folder of committed results that ``path`` is or lies in (holding the marker), or None."""
    p = Path(path).resolve()
    for d in (p, *p.parents):
        if (d / COMMITTED_MARKER).is_file():
            return d
    return None


def check_out(path, *, full: bool, why: str = "") -> Path:
    """``path`` if a run may write there: anywhere, except committed results for a run that is not ``full``.

    ``why`` names what makes the run not full (e.g. ``"--quick"``); ValueError otherwise.
    """
    root = committed_root(path)
    if root is not None and not full:
        raise ValueError(
            f"{str(path)!r} holds committed full-run results ({root / COMMITTED_MARKER}); a run with "
            f"{why or 'non-default sizes'} may not overwrite them: leave out --out (default "
            f"./{RESULTS_ROOT}/...) or pick another folder"
        )
    return Path(path)


def prepare_out(path, *, full: bool, why: str = "") -> Path:
    """:func:`check_out`, then the folder made and checked writable (ValueError naming the problem)."""
    out = check_out(path, full=full, why=why)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise ValueError(f"cannot create output folder {str(out)!r}: {e.strerror}") from None
    if not out.is_dir():
        raise ValueError(f"output path {str(out)!r} is not a folder")
    if not os.access(out, os.W_OK):
        raise ValueError(f"output folder {str(out)!r} is not writable")
    return out
