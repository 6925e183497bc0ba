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

Every file a study writes (figures, CSV tables, results JSON, REPORT.md) is
written under a hidden temporary name beside it and renamed into place once
complete (:func:`written`): a full disk or a kill never leaves a truncated
file under its final name, and a write that fails is one error naming the
file.
"""

from __future__ import annotations

import contextlib
import os
import uuid
from pathlib import Path

from dicetrace.sinks._common import OutputError, _reason

#: Default root of the studies' outputs, relative to the current folder.
RESULTS_ROOT = Path("dicetrace-results")
#: Marker file of a folder of committed results.
COMMITTED_MARKER = ".committed-results"
#: Default output folder of each command (``analyze`` writes all writeup studies into one, with REPORT.md).
DEFAULT_FOLDERS = {"analyze": "analysis", "accuracy": "accuracy", "stability": "stability", "friction": "friction",
                   "cuboids": "cuboids", "bars": "bars", "aspect": "aspect"}


def default_out(command: str) -> Path:
    """``./dicetrace-results/<folder>`` of the writeup studies (``analyze``) or of an integrator study
    (``accuracy``, ``stability``, ``friction``, ``cuboids``, ``bars``, ``aspect``)."""
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


@contextlib.contextmanager
def written(path, what: str = "output"):
    """Yield a temporary path to write ``path``'s content to; once the block completes it is synced and renamed
    onto ``path`` (which until then keeps its old content, or does not exist).

    The temporary file is hidden, beside ``path``, with its suffix (a writer
    that goes by the extension -- matplotlib, Pillow -- still knows the
    format); it is removed whatever happens.  An OS error while writing (a
    full disk) becomes an :class:`~dicetrace.sinks._common.OutputError` naming
    ``what`` and ``path``: ``cannot write figure 'out/figures/a.png': No
    space left on device``.
    """
    path = Path(path)
    tmp = path.with_name(f".{path.stem}.{os.getpid()}-{uuid.uuid4().hex[:8]}.tmp{path.suffix}")
    try:
        yield tmp
        fd = os.open(tmp, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)
        os.replace(tmp, path)
    except OSError as e:
        raise OutputError(f"cannot write {what} {str(path)!r}: {_reason(e)}") from None
    finally:
        with contextlib.suppress(OSError):
            tmp.unlink(missing_ok=True)


def label_axes(ax, *, xlabel: str, ylabel: str, title: str, legend: int | bool | None = 7,
               title_size: float | None = None) -> None:
    """Label one axes: x, y, title (at ``title_size``), and a legend of font size ``legend`` (True: the default size;
    None or 0: none)."""
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.set_title(title, **({} if title_size is None else {"fontsize": title_size}))
    if legend is True:
        ax.legend()
    elif legend:
        ax.legend(fontsize=legend)


def write_figure(fig, path, dpi: float) -> Path:
    """Save a matplotlib figure to ``path`` as a PNG at ``dpi`` through :func:`written` (whole or not at all), and
    close it."""
    import matplotlib.pyplot as plt  # matplotlib: only when drawing

    with written(path, "figure") as tmp:
        fig.savefig(tmp, dpi=dpi, format="png")
    plt.close(fig)
    return Path(path)


def write_text(path, text: str, what: str = "output") -> Path:
    """Write ``text`` to ``path`` through :func:`written`; returns ``path``."""
    with written(path, what) as tmp:
        tmp.write_text(text)
    return Path(path)
