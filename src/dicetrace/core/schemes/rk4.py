"""Commutator-free Lie-group RK4 (order 4, docs/model.md §9): one ``cf4`` step per step.

The method itself (``core.methods.rk4.cf4``) is also the sub-step method of
``contact_substep``.  In free flight ω is constant and the parabola
quadratic in t, so RK4 is exact there; such a step is computed in closed
form.
"""

from __future__ import annotations

from dicetrace.core._jit import jit
from dicetrace.core.forces import eval_forces, step_wrench
from dicetrace.core.free_flight import free_flight, free_flight_safe
from dicetrace.core.methods import rk4
from dicetrace.core.methods.rk4 import cf4
from dicetrace.core.state import SUBSTEP_WORK, accept_substep, begin_substeps, end_substeps, work_dtype

#: A free flight of several steps is not crossed in one piece (the run loop steps through it).
EXACT_FLIGHT = False
#: The sub-step start and end, and RK4's stage scratch.
WORK = work_dtype(SUBSTEP_WORK, rk4.WORK)


@jit
def step(st, wk, kp, h, contact):
    """One Lie-group RK4 step of ``st`` (``core.schemes.Scheme``)."""
    if not contact and free_flight_safe(st.X, st.U, st.W, st.off, kp, h):
        free_flight(st, kp, h)
        return eval_forces(st, kp)
    f0, f1, f2, t0, t1, t2 = step_wrench(st, contact, True)
    begin_substeps(st, wk)
    cf4(st, wk, kp, h, f0, f1, f2, t0, t1, t2)
    accept_substep(st, wk, kp)
    end_substeps(st, wk, kp)
    return eval_forces(st, kp)
