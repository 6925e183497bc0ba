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


#: The one step of every error-controlled scheme in the study (s): their tolerance is what the study varies.
ADAPTIVE_DT_S = (1e-3,)


def _fixed_step(color: str, study_dt_s: tuple[float, ...], quick_dt_s: tuple[float, ...]) -> StudyGrid:
    """The grid of a fixed-step scheme: its steps (full and ``--quick``), no tolerances."""
    return StudyGrid(color, study_dt_s, quick_dt_s)


def _error_controlled(color: str, study_tol: tuple[float, ...], quick_tol: tuple[float, ...],
                      study_graded: tuple[tuple[float, float], ...] = (),
                      quick_graded: tuple[tuple[float, float], ...] = ()) -> StudyGrid:
    """The grid of an error-controlled scheme: its tolerances (full and ``--quick``, uniform and loosening) at
    :data:`ADAPTIVE_DT_S`."""
    return StudyGrid(color, ADAPTIVE_DT_S, ADAPTIVE_DT_S, study_tol, quick_tol, study_graded, quick_graded)


#: The study's grid of each integrator of :data:`dicetrace.integrators.INTEGRATORS`, by name: colour, then the
#: steps (full, ``--quick``) of a fixed-step scheme or the tolerances (full, ``--quick``; then the loosening ones)
#: of an error-controlled one.
GRIDS: dict[str, StudyGrid] = {
    "semi-implicit-euler": _fixed_step(
        "tab:blue", (1e-3, 5e-4, 2.5e-4, 1.25e-4, 6.25e-5, 3.125e-5, 1.5625e-5, 7.8125e-6), (1e-3, 2.5e-4)),
    "forward-euler": _fixed_step("tab:red", (1e-3, 2.5e-4, 1e-4, 5e-5, 2.5e-5, 1.25e-5), (1e-4, 5e-5)),
    "verlet": _fixed_step("tab:green", (2e-3, 1e-3, 5e-4, 2.5e-4, 1.25e-4, 6.25e-5), (1e-3, 2.5e-4)),
    "rk4": _fixed_step("tab:purple", (2e-3, 1e-3, 5e-4, 2.5e-4, 1.25e-4, 6.25e-5), (1e-3, 2.5e-4)),
    "contact-substep": _fixed_step("tab:orange", (8e-3, 4e-3, 2e-3, 1e-3, 5e-4, 2.5e-4), (2e-3, 1e-3)),
    "contact-adaptive": _error_controlled("tab:brown", (1e-2, 1e-3, 1e-4, 1e-5, 1e-6, 1e-7, 1e-8), (1e-4, 1e-6),
                                          study_graded=((10.0, 2e-8),)),
    "contact-dop853": _error_controlled("tab:pink", (1e-4, 1e-5, 1e-6, 1e-7, 1e-8, 1e-9, 1e-10), (1e-6, 1e-8)),
    "contact-tsit5": _error_controlled("tab:olive", (1e-4, 1e-5, 1e-6, 1e-7, 1e-8, 1e-9), (1e-6, 1e-8),
                                       study_graded=((10.0, 2e-8), (10.0, 5e-8)), quick_graded=((10.0, 1e-6),)),
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


__all__ = ["StudyGrid", "GRIDS", "ADAPTIVE_DT_S", "grid", "color"]
