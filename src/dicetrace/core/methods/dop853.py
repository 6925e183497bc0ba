"""The DOP853 pair as a sub-step method (``core.methods.SubstepMethod``).

Dormand–Prince order 8 with its 5th- and 3rd-order error estimates, on the
state with a unit quaternion (``erk``).  At the accuracies that decide a
throw's outcome (local errors near 1e-10) an order-8 pair takes steps
several times longer than RK4; its 12 stages cost 2.4 RK4 steps.  No dense
output.  The scheme ``contact_dop853`` is the contact driver on this method.
"""

from __future__ import annotations

from dicetrace.core.methods.common import no_dense_keep, no_dense_state
from dicetrace.core.methods.erk import DOP853_STAGES, dop853_error, dop853_substep, erk_work

substep = dop853_substep
error = dop853_error
#: The step-size exponent, 1 / (the estimate's order + 1).
ERR_EXP = 1.0 / 8.0
#: Largest λ_f·h of the friction law (DOP853's interval on the negative real
#: axis reaches about −6; a margin for the law's non-linearity).
FRICTION_THETA = 3.0
#: An impact's first sub-step, as ω·h with ω = √k.
H0 = 0.3
DENSE = False
dense_keep = no_dense_keep
dense_state = no_dense_state
#: Its work area besides the sub-step start and end (``core.state``): the stages.
WORK = erk_work(DOP853_STAGES)
