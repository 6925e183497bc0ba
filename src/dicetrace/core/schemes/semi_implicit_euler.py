"""The 2019 program's step, semi-implicit Euler (docs/model.md §5.1), bit-faithful.

U ← U + (ΣF + 8g)/8·h; X ← X + U·h; L ← L + τ·h; ω = L/I; the offsets turn
by the exact rotation for ω·h; the forces are evaluated at the new state.
While no node touched the ground the forces are exactly zero, so the sums
are skipped and L, ω and the rotation matrix are reused (``st.rot_h``).
Its summaries run the specialised kernel ``core.fast`` where that applies.
"""

from __future__ import annotations

from dicetrace.core import fast
from dicetrace.core._jit import jit
from dicetrace.core.forces import eval_forces, step_wrench
from dicetrace.core.model import program_kick_drift
from dicetrace.core.rotation import turn_by_omega
from dicetrace.core.state import NO_WORK, set_angular_momentum


#: A free flight of several steps is not crossed in one piece (the run loop steps through it).
EXACT_FLIGHT = False
#: No work area: the step keeps nothing between its stages.
WORK = NO_WORK


@jit
def step(st, wk, kp, h, contact):
    """One program step of ``st`` (``core.schemes.Scheme``)."""
    X = st.X
    U = st.U
    L = st.L
    s0, s1, s2, t0, t1, t2 = step_wrench(st, contact, False)
    U[0], U[1], U[2], X[0], X[1], X[2] = program_kick_drift(U[0], U[1], U[2], X[0], X[1], X[2], s0, s1, s2, kp, h)
    if contact:
        set_angular_momentum(st, L[0] + t0 * h, L[1] + t1 * h, L[2] + t2 * h, kp)
    turn_by_omega(st, h)
    return eval_forces(st, kp)


#: The specialised summary kernel (``core.fast``), bit-identical to the summary loop where it applies.
summary = fast.roll_summary_sie
summary_applies = fast.applies
