"""The optional parts of the install, and the one-line refusal of a feature whose extra is missing.

``pip install dicetrace`` brings what ``simulate``, ``record`` and ``scan`` need.  The rest comes with an
extra (``pip install 'dicetrace[NAME]'``; ``all`` is every one but the GPU's):

``explore``   the live explorer and ``record --serve``: the web server (starlette, uvicorn) and Rerun's web
              viewer as rerun-notebook builds it (which brings Jupyter's kernel stack with it)
``jupyter``   ``Explorer.widget()``: the explorer as a notebook widget (anywidget), with ``explore``
``dask``      ``scan --dask`` / ``scan(dask=...)``: a Dask cluster (dask[distributed])
``analysis``  ``dicetrace analyze`` and ``analysis.label_cells``: scikit-image's labelling (one pass over all
              labels; ``benchmarks/bench_cells.py`` measures it against scipy's)
``cuda``      ``--device cuda``: numba-cuda and the CUDA 12 libraries (``cuda13`` for CUDA 13)

:func:`require` checks that a feature's modules can be imported and raises :class:`MissingExtra`, whose
message names the extra to install; the command line shows it as one line, exit code 2.
"""

from __future__ import annotations

import importlib.util

#: Each extra: the modules that must import for its features (top-level names).
EXTRAS: dict[str, tuple[str, ...]] = {
    "explore": ("starlette", "uvicorn", "rerun_notebook"),
    "jupyter": ("anywidget", "starlette", "uvicorn", "rerun_notebook"),
    "dask": ("dask", "distributed"),
    "analysis": ("skimage",),
}


class MissingExtra(ModuleNotFoundError):
    """A feature needs an extra that is not installed; the message names it and how to install it."""


def missing_modules(modules) -> list[str]:
    """Those of ``modules`` that cannot be imported here (not installed, or refused by an import hook)."""
    out = []
    for name in modules:
        try:
            found = importlib.util.find_spec(name) is not None
        except (ImportError, ValueError):
            found = False
        if not found:
            out.append(name)
    return out


def install_hint(extra: str) -> str:
    return f"pip install 'dicetrace[{extra}]'"


def require(extra: str, feature: str) -> None:
    """Raise :class:`MissingExtra` (``feature needs the EXTRA extra: pip install 'dicetrace[EXTRA]' (missing: ...)``)
    unless every module of ``extra`` can be imported."""
    missing = missing_modules(EXTRAS[extra])
    if missing:
        raise MissingExtra(f"{feature} needs the {extra} extra: {install_hint(extra)} (missing: {', '.join(missing)})",
                           name=missing[0])
