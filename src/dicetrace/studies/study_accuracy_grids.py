"""The accuracy study's grid of each integrator (steps, tolerances) and its colour in the study's plots.

Presentation of the integrator studies, kept out of the integrator table
(:mod:`dicetrace.integrators`, which holds what the kernels and ``Numerics``
read): :func:`dicetrace.studies.study_accuracy.study_runs` reads the steps and
tolerances, the work-precision and stable-step plots the colours.  An
integrator added to the table needs a row here (a test checks that every
integrator has one).
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class StudyGrid:
    """What the integrator studies use of one integrator.

    Parameters
    ----------
    color
        Its colour in the studies' plots (matplotlib name).
    study_dt_s, quick_dt_s
        Steps of the work-precision study (full and ``--quick``), s; each
        divides the study's first-impact horizon grid of 8 ms.
    study_tol, quick_tol
        Tolerances of the study (adaptive schemes only).
    study_graded, quick_graded
        (tol_growth, tol) pairs of the study: tolerances that loosen over a
        throw (``Numerics.tol_growth``; adaptive schemes only).
    """

    color: str
    study_dt_s: tuple[float, ...]
    quick_dt_s: tuple[float, ...]
    study_tol: tuple[float, ...] = ()
    quick_tol: tuple[float, ...] = ()
    study_graded: tuple[tuple[float, float], ...] = ()
    quick_graded: tuple[tuple[float, float], ...] = ()


#: The study's grid of each integrator of :data:`dicetrace.integrators.INTEGRATORS`, by name.
GRIDS: dict[str, StudyGrid] = {
    "semi-implicit-euler": StudyGrid(
        "tab:blue",
        study_dt_s=(1e-3, 5e-4, 2.5e-4, 1.25e-4, 6.25e-5, 3.125e-5, 1.5625e-5, 7.8125e-6),
        quick_dt_s=(1e-3, 2.5e-4),
    ),
    "forward-euler": StudyGrid(
        "tab:red",
        study_dt_s=(1e-3, 2.5e-4, 1e-4, 5e-5, 2.5e-5, 1.25e-5),
        quick_dt_s=(1e-4, 5e-5),
    ),
    "verlet": StudyGrid(
        "tab:green",
        study_dt_s=(2e-3, 1e-3, 5e-4, 2.5e-4, 1.25e-4, 6.25e-5),
        quick_dt_s=(1e-3, 2.5e-4),
    ),
    "rk4": StudyGrid(
        "tab:purple",
        study_dt_s=(2e-3, 1e-3, 5e-4, 2.5e-4, 1.25e-4, 6.25e-5),
        quick_dt_s=(1e-3, 2.5e-4),
    ),
    "contact-substep": StudyGrid(
        "tab:orange",
        study_dt_s=(8e-3, 4e-3, 2e-3, 1e-3, 5e-4, 2.5e-4),
        quick_dt_s=(2e-3, 1e-3),
    ),
    "contact-adaptive": StudyGrid(
        "tab:brown",
        study_dt_s=(1e-3,),
        quick_dt_s=(1e-3,),
        study_tol=(1e-2, 1e-3, 1e-4, 1e-5, 1e-6, 1e-7, 1e-8),
        quick_tol=(1e-4, 1e-6),
        study_graded=((10.0, 2e-8),),
    ),
    "contact-dop853": StudyGrid(
        "tab:pink",
        study_dt_s=(1e-3,),
        quick_dt_s=(1e-3,),
        study_tol=(1e-4, 1e-5, 1e-6, 1e-7, 1e-8, 1e-9, 1e-10),
        quick_tol=(1e-6, 1e-8),
    ),
    "contact-tsit5": StudyGrid(
        "tab:olive",
        study_dt_s=(1e-3,),
        quick_dt_s=(1e-3,),
        study_tol=(1e-4, 1e-5, 1e-6, 1e-7, 1e-8, 1e-9),
        quick_tol=(1e-6, 1e-8),
        study_graded=((10.0, 2e-8), (10.0, 5e-8)),
        quick_graded=((10.0, 1e-6),),
    ),
}


def grid(integrator: str) -> StudyGrid:
    """The study's grid of ``integrator`` (ValueError naming the choices)."""
    try:
        return GRIDS[integrator]
    except KeyError:
        raise ValueError(f"no study grid for integrator {integrator!r} (have {', '.join(GRIDS)})") from None


def color(integrator: str) -> str:
    """The colour of ``integrator`` in the studies' plots."""
    return grid(integrator).color


__all__ = ["StudyGrid", "GRIDS", "grid", "color"]
