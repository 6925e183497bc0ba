"""The studies of dicetrace, in one place: the registry of their names and the modules that run them.

Every study starts the same way, ``dicetrace analyze NAME`` (:mod:`dicetrace.commands.analyze`).
A study module is named ``study_<name>`` (``dicetrace.studies.study_settle``; its
parts ``study_<name>_render`` ...): it samples, calls the measures of
:mod:`dicetrace.analysis` and renders; the measures themselves live in
``dicetrace.analysis`` (``dicetrace.analysis.settle``).  The other modules here are
the machinery the studies share (context, outputs, report, runner, text).

Two kinds, both shipped in the package and run from any folder:

- the **writeup studies** (the writeup's nine, the transient-chaos study j, the referee's
  items k, the converged maps l, the corner balance m, doubly transient chaos n and the border rates o, and p, q, r, s; ``dicetrace analyze NAME|all``), one module
  each, ``compute(ctx)`` then ``render(computed, out)`` (see
  :mod:`dicetrace.studies.context`); :func:`dicetrace.studies.runner.run`
  runs them and :mod:`dicetrace.studies.report` assembles ``REPORT.md``;
- the **integrator studies**, each run alone with options of its own: the work-precision study
  (:mod:`~dicetrace.studies.study_accuracy`, rendered by
  :mod:`~dicetrace.studies.study_accuracy_render`; ``dicetrace analyze accuracy``), the
  stable-step map (:mod:`~dicetrace.studies.study_stability`; ``dicetrace analyze stability``)
  and the friction-regularisation study (:mod:`~dicetrace.studies.study_friction`;
  ``dicetrace analyze friction``).

Where their outputs go (a working folder by default; the committed results
only on purpose) is :mod:`dicetrace.studies.outputs`.
"""

from __future__ import annotations

import importlib
from types import ModuleType

#: Prefix of a study's module name: study ``NAME`` is ``dicetrace.studies.study_NAME``.
MODULE_PREFIX = "study_"
#: The writeup studies, in run order (module ``dicetrace.studies.study_<name>``; their letters: ``LETTERS``).
WRITEUP_STUDIES = ("cells", "fractal", "repetition", "topology", "damping", "vertices", "settle", "wedge", "animation",
                   "transient", "referee", "converged", "corner", "doubly_transient",
                   "border_rates")
#: Letter of each writeup study (its figures' prefix) -> name.
LETTERS = dict(zip("abcdefghijklmno", WRITEUP_STUDIES))
#: Study p (one cell or many, repetition and topology on the converged die), registered apart from the tuple above.
WRITEUP_STUDIES += ("onecell_converged",)
LETTERS["p"] = "onecell_converged"
#: Study q (the sweeps of γ and k with certificates), registered apart from the tuple above.
WRITEUP_STUDIES += ("sweeps",)
LETTERS["q"] = "sweeps"
#: Study r (the hazard law of the edge saddle, measured), registered apart from the tuple above.
WRITEUP_STUDIES += ("hazard_law",)
LETTERS["r"] = "hazard_law"
#: Study s (the triple-point law, measured), registered apart from the tuple above.
WRITEUP_STUDIES += ("triple_law",)
LETTERS["s"] = "triple_law"
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
    "corner": "the corner balance: its two unstable rates, the faces around it, triple points of converged maps (4.3)",
    "doubly_transient": "doubly transient chaos measured as such: f(ε) local slopes and ε_c, settling hazards, λ₁ on "
                        "survivors",
    "border_rates": "border λ fitted near the border with a uniform tight tolerance, against each preset's edge saddle",
}
TITLES["onecell_converged"] = "one cell or many, repetition and topology on the converged die (writeup 5.1, 5.5, 5.7)"
TITLES["sweeps"] = "damping γ and ground stiffness k on three windows of the converged die, with certificates"
TITLES["hazard_law"] = "the hazard law of the edge saddle, κ_settle(t) = α(ε(t))·λ_edge, on 10⁵ throws per model"
TITLES["triple_law"] = "the triple-point law: opposite faces, spiral borders, the throws near a corner balance"
#: The integrator studies: each runs alone, with options of its own (``dicetrace analyze NAME``).
INTEGRATOR_STUDIES = ("accuracy", "stability", "friction", "cuboids", "bars", "aspect")
#: What each integrator study is about (the first line of its module's docstring).
INTEGRATOR_TITLES = {
    "accuracy": "the work-precision study of the integrators",
    "stability": "the map of the integrators' stable steps",
    "friction": "how near to Coulomb the physical die's friction can go: the regularisation study",
    "cuboids": "the physical die held to the measured face probabilities of real square cuboidal dice",
    "bars": "the two-dimensional limit: long bars against Pender & Uhrin's formula",
    "aspect": "the home window's border fraction f(ε) and α against the die's aspect ratio",
}
#: Every study's name.
STUDY_NAMES = WRITEUP_STUDIES + INTEGRATOR_STUDIES


def resolve(names) -> list[str]:
    """Writeup study names from names (a hyphen for an underscore: ``doubly-transient``), letters (``LETTERS``) or
    ``all`` (ValueError naming the choices)."""
    out: list[str] = []
    for n in names or ("all",):
        key = str(n).strip().lower()
        if key == "all":
            return list(WRITEUP_STUDIES)
        key = LETTERS.get(key, key).replace("-", "_")
        if key not in WRITEUP_STUDIES:
            raise ValueError(f"unknown study {n!r} (choose from all, {', '.join(WRITEUP_STUDIES)}, "
                             f"or a letter of {''.join(sorted(LETTERS))})")
        if key not in out:
            out.append(key)
    return out


def module_name(name: str) -> str:
    """The dotted name of study ``name``'s module (``dicetrace.studies.study_<name>``; ValueError naming the choices)."""
    if name not in STUDY_NAMES:
        raise ValueError(f"unknown study {name!r} (choose from {', '.join(STUDY_NAMES)})")
    return f"dicetrace.studies.{MODULE_PREFIX}{name}"


def study_module(name: str) -> ModuleType:
    """The module of study ``name`` (``dicetrace.studies.study_<name>``)."""
    return importlib.import_module(module_name(name))


__all__ = ["MODULE_PREFIX", "WRITEUP_STUDIES", "LETTERS", "TITLES", "INTEGRATOR_STUDIES", "INTEGRATOR_TITLES",
           "STUDY_NAMES", "resolve", "module_name", "study_module"]
