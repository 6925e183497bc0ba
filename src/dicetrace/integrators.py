"""The integrator table: one :class:`IntegratorSpec` per integrator, read by every layer.

Bottom layer (imports nothing of the package).  The kernels dispatch on
``kernel_id``; ``Numerics`` validates names against it; ``dt = "auto"`` reads
the stability bound.  What the studies show of an integrator (the accuracy
study's steps and tolerances, its plot colour) is theirs
(``dicetrace.studies.study_accuracy_grids``).  Adding an integrator is one
scheme file in ``dicetrace.core``, one row here, one row of the accuracy
study's grids, and its tests.
"""

from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass(frozen=True)
class IntegratorSpec:
    """Everything dicetrace knows about one integrator, in one place.

    Parameters
    ----------
    name
        The name users type (``--integrator``, ``integrator=``).
    kernel_id
        The integer that names it to the numba kernels (part of the kernel ABI).
    scheme
        The module of ``dicetrace.core.schemes`` whose ``step`` it runs
        (``dicetrace.core.loop`` compiles one run loop per scheme).
    order
        Classical order of accuracy on smooth segments.
    stability_bound
        Linear stability bound of ω·h on the undamped penalty spring
        (ω = √k per unit mass); 0 when the scheme has none (forward Euler
        amplifies every oscillation by √(1 + ω²h²) per step), infinite when it
        is A-stable (an implicit scheme; none in the table now).  For the
        sub-stepping schemes h is the sub-step.
    substepped
        Its contact steps are sub-steps of dt (``Numerics.substeps`` of them
        at most, or error-controlled): ``dt = auto`` applies the bound per
        sub-step.
    adaptive
        Error-controlled sub-steps (``Numerics.tol`` is its tolerance).
    summary
        One line for ``--help`` and the docs.
    """

    name: str
    kernel_id: int
    order: int
    stability_bound: float
    summary: str
    scheme: str
    substepped: bool = False
    adaptive: bool = False


_RK4_BOUND = 2.0 * math.sqrt(2.0)  # RK4's interval on the imaginary axis
#: Tsit5 is not strictly stable on the imaginary axis: |R(iy)| = 1 + O(y⁶), its own local error;
#: 1.29 is where one step amplifies an undamped oscillation by 1e-3 (beyond it the growth is steep).
_TSIT5_BOUND = 1.29

#: The integrators, by name.  A ``kernel_id`` is part of the kernel ABI and is never reused: id 7
#: belonged to ``contact-rosenbrock`` (removed, see ``REMOVED``), so the ids are not dense.
INTEGRATORS: dict[str, IntegratorSpec] = {
    s.name: s
    for s in (
        IntegratorSpec(
            "semi-implicit-euler", 0, 1, 2.0, "the 2019 program's scheme (default for seed)",
            scheme="semi_implicit_euler",
        ),
        IntegratorSpec(
            "forward-euler", 1, 1, 0.0, "textbook forward Euler (what the writeup says it used)",
            scheme="forward_euler",
        ),
        IntegratorSpec(
            "verlet", 2, 2, 2.0, "velocity Verlet",
            scheme="verlet",
        ),
        IntegratorSpec(
            "rk4", 3, 4, _RK4_BOUND, "classical Runge-Kutta on the Lie group (commutator-free)",
            scheme="rk4",
        ),
        IntegratorSpec(
            "contact-substep", 4, 4, _RK4_BOUND,
            "contact-aware RK4: exact free flight, kink-aligned sub-steps in contact",
            scheme="contact_substep",
            substepped=True,
        ),
        IntegratorSpec(
            "contact-adaptive", 5, 4, _RK4_BOUND,
            "contact-substep with error-controlled sub-steps (tolerance tol)",
            scheme="contact_substep",
            substepped=True,
            adaptive=True,
        ),
        IntegratorSpec(
            "contact-dop853", 6, 8, 5.96,
            "contact-adaptive's sub-stepping with the order-8 Dormand-Prince pair (DOP853)",
            scheme="contact_dop853",
            substepped=True,
            adaptive=True,
        ),
        IntegratorSpec(
            "contact-tsit5", 8, 5, _TSIT5_BOUND,
            "contact-adaptive's sub-stepping with Tsitouras' 5(4) pair (Tsit5): "
            "six stages, where the contact caps most sub-steps",
            scheme="contact_tsit5",
            substepped=True,
            adaptive=True,
        ),
    )
}


#: Integrators that dicetrace had and no longer has, with why: a name here is refused with that reason.
REMOVED: dict[str, str] = {
    "contact-rosenbrock": (
        "it was removed (linearly implicit, it cost 9-27x the explicit contact-dop853 at equal agreement at "
        "every friction regularisation measured; analysis/accuracy/TUNING.md §3)"
    ),
}


def unknown_integrator(name) -> str:
    """The message for an integrator name that is not in the table: why a removed one is gone, else the choices."""
    if isinstance(name, str) and name in REMOVED:
        return f"integrator {name!r}: {REMOVED[name]}; choose from {', '.join(INTEGRATORS)}"
    return f"unknown integrator {name!r} (choose from {', '.join(INTEGRATORS)})"


def get_integrator(name: str) -> IntegratorSpec:
    """The spec of integrator ``name`` (ValueError naming the choices, or why a removed one is gone)."""
    try:
        return INTEGRATORS[name]
    except (KeyError, TypeError):
        raise ValueError(unknown_integrator(name)) from None
