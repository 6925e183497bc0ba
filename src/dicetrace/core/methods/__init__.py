"""The sub-step methods of the contact schemes: one explicit Runge–Kutta step each, and its error estimate.

A contact scheme (``core.schemes.contact_*``) is the generic contact driver
(``core.contact_driver.make_drive``: exact free flight, sub-steps cut where a
node enters or leaves the ground, the step-size controller, the friction
law's stability bound, dense output, exact events) on one of these methods:

================  =====================================  ===========================
method module     method                                  scheme
================  =====================================  ===========================
``rk4``           commutator-free Lie-group RK4 (cf4)     ``contact_substep``
``tsit5``         Tsitouras 5(4), continuous extension    ``contact_tsit5``
``dop853``        Dormand–Prince 8(5,3)                   ``contact_dop853``
================  =====================================  ===========================

A method module provides what :class:`SubstepMethod` lists.  The driver
closes over the module (numba compiles its names in as constants, and its
disk cache keys a module by name: ``core._jit``).
"""

from __future__ import annotations

from typing import Protocol, runtime_checkable


@runtime_checkable
class SubstepMethod(Protocol):
    """What a sub-step method module provides to the contact driver (``core.contact_driver.make_drive``).

    For developers: a new method is one module with these names, and one
    scheme module that makes its step with ``make_drive``.
    """

    #: The step-size exponent, 1 / (the error estimate's order + 1).
    ERR_EXP: float
    #: Largest λ_f·h of the friction law (λ_f its stiffness per unit effective mass).
    FRICTION_THETA: float
    #: An impact's first sub-step, as ω·h with ω = √k.
    H0: float
    #: Whether the method has a continuous extension: the last sub-step of a step then runs past the step's end.
    DENSE: bool
    #: The fields of its work area besides the sub-step start and end (``core.state.work_dtype``).
    WORK: list

    def substep(self, st, wk, kp, h, f0, f1, f2, t0, t1, t2) -> None:
        """One explicit step of length h from the sub-step start ``wk.sub_*`` to ``wk.new_*``; f, t: the contact
        force sum and torque at the start; ``st``'s forces and node arrays are stage scratch."""

    def error(self, st, wk, kp, h, g0, g1, g2, q0, q1, q2) -> float:
        """The last sub-step's local error estimate over ``kp.tol``; g, q: force sum and torque at its end."""

    def dense_keep(self, st, wk, h) -> None:
        """Keep what :meth:`dense_state` needs of the sub-step just computed (length h); a no-op without ``DENSE``."""

    def dense_state(self, st, wk, kp, theta) -> None:
        """The state at θ·h into the kept sub-step, written into ``st`` (only called with ``DENSE``)."""
