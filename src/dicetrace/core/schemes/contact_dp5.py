"""``contact-dp5``: contact-aware sub-stepping with the Dormand–Prince 5(4) pair (docs/model.md §9).

The driver of ``contact_substep`` on Dormand–Prince 5(4) sub-steps
(``erk``, on the state with a unit quaternion): 6 force evaluations per
accepted sub-step (first same as last), order 5.
"""

from __future__ import annotations

from dicetrace.core._jit import jit, specialise
from dicetrace.core.schemes.contact_substep import drive
from dicetrace.core.schemes.erk import dp5_error, dp5_substep

#: Largest λ_f·h of the friction law (DP5 reaches about −3.3 on the negative real axis).
FRICTION_THETA = 1.5
#: An impact's first sub-step, as ω·h with ω = √k.
H0 = 0.2

step = jit(
    specialise(
        drive, "step_dp5", "contact-dp5: ``contact_substep.drive`` on Dormand–Prince 5(4) sub-steps (``erk``).",
        SUBSTEP=dp5_substep, ERROR=dp5_error, ERR_EXP=1.0 / 5.0, THETA=FRICTION_THETA, H0=H0,
    )
)
