"""Textbook forward Euler (the scheme the writeup describes, docs/model.md §6 and §9).

Every increment is taken from the state at the start of the step:
X ← X + U·h; U ← U + a·h; the offsets turn exactly by the old ω·h;
L ← L + τ·h.  Unstable on the contact spring (the energy grows at each contact).
"""

from __future__ import annotations

from dicetrace.core._jit import jit
from dicetrace.core.forces import eval_forces, step_wrench
from dicetrace.core.rotation import turn_by_omega
from dicetrace.core.state import NO_WORK, set_angular_momentum


#: A free flight of several steps is not crossed in one piece (the run loop steps through it).
EXACT_FLIGHT = False
#: No work area: the step keeps nothing between its stages.
WORK = NO_WORK


@jit
def step(st, wk, kp, h, contact):
    """One forward-Euler step of ``st`` (``core.schemes.Scheme``)."""
    s0, s1, s2, t0, t1, t2 = step_wrench(st, contact, False)
    X = st.X
    U = st.U
    X[0] = X[0] + U[0] * h
    X[1] = X[1] + U[1] * h
    X[2] = X[2] + U[2] * h
    U[0] = U[0] + s0 / 8.0 * h
    U[1] = U[1] + s1 / 8.0 * h
    U[2] = U[2] + (s2 / 8.0 + kp.g) * h
    turn_by_omega(st, h)
    if contact:
        L = st.L
        set_angular_momentum(st, L[0] + t0 * h, L[1] + t1 * h, L[2] + t2 * h, kp)
    return eval_forces(st, kp)
