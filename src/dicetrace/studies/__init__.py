"""The studies of dicetrace, in one place: the registry of their names and the modules that run them.

Two kinds, both shipped in the package and run from any folder:

- the **writeup studies** (the writeup's nine, and the transient-chaos study j) (``dicetrace analyze NAME|all``), one module
  each, ``compute(ctx)`` then ``render(computed, out)`` (see
  :mod:`dicetrace.studies.context`); :func:`dicetrace.studies.runner.run`
  runs them and :mod:`dicetrace.studies.report` assembles ``REPORT.md``;
- the **integrator studies**: the work-precision study
  (:mod:`~dicetrace.studies.accuracy`, rendered by
  :mod:`~dicetrace.studies.accuracy_render`; ``dicetrace accuracy``) and the
  stable-step map (:mod:`~dicetrace.studies.stability`; ``dicetrace stability``).

Where their outputs go (a working folder by default; the committed results
only on purpose) is :mod:`dicetrace.studies.outputs`.
"""

from __future__ import annotations

import importlib
from types import ModuleType

#: The writeup studies, in run order (module ``dicetrace.studies.<name>``; letters a..l).
WRITEUP_STUDIES = ("cells", "fractal", "repetition", "topology", "damping", "vertices", "settle", "wedge", "animation",
                   "transient", "referee", "converged")
#: Letter of each writeup study (its figures' prefix) -> name.
LETTERS = dict(zip("abcdefghijkl", WRITEUP_STUDIES))
#: What each writeup study is about (the first line of its module's docstring, after the name).
TITLES = {
    "cells": "the cell structure of the home window and the zoom ladder (writeup 4.1)",
    "fractal": '"fractal" zoom series (writeup 5.3) and the measures of the boundaries',
    "repetition": "period vectors, and one cell or many? (writeup 5.1)",
    "topology": "the topology of throws in one cell (writeup 5.5)",
    "damping": "damping and chaos (writeup 5.2)",
    "vertices": "the vertex hunt (writeup 4.3 and 5.4)",
    "settle": "settle time at cell borders (writeup 4.1–4.2 and 5.6)",
    "wedge": "the ball–hill wedge (writeup 4.2 and appendix 8.1)",
    "animation": "the third slice axis as time (writeup 6.1)",
    "transient": "transient chaos of the discrete and the converged die: λ, κ and α, with convergence certificates",
    "referee": "every claim the referee marked, redone with controls, error bars and enough scales",
    "converged": "converged maps beside the discrete ones: every measure of a map, side by side, with certificates",
}
#: The integrator studies (their own commands).
INTEGRATOR_STUDIES = ("accuracy", "stability")
#: Every study's name.
STUDY_NAMES = WRITEUP_STUDIES + INTEGRATOR_STUDIES


def resolve(names) -> list[str]:
    """Writeup study names from names, letters (a..l) or ``all`` (ValueError naming the choices)."""
    out: list[str] = []
    for n in names or ("all",):
        key = str(n).strip().lower()
        if key == "all":
            return list(WRITEUP_STUDIES)
        key = LETTERS.get(key, key)
        if key not in WRITEUP_STUDIES:
            raise ValueError(f"unknown study {n!r} (choose from all, {', '.join(WRITEUP_STUDIES)}, or a..l)")
        if key not in out:
            out.append(key)
    return out


def study_module(name: str) -> ModuleType:
    """The module of study ``name`` (``dicetrace.studies.<name>``)."""
    if name not in STUDY_NAMES:
        raise ValueError(f"unknown study {name!r} (choose from {', '.join(STUDY_NAMES)})")
    return importlib.import_module(f"dicetrace.studies.{name}")


__all__ = ["WRITEUP_STUDIES", "LETTERS", "TITLES", "INTEGRATOR_STUDIES", "STUDY_NAMES", "resolve", "study_module"]
