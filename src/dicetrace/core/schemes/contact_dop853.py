"""``contact-dop853``: contact-aware sub-stepping with the DOP853 pair (docs/model.md §9).

The driver of ``contact_substep`` (exact free flight, sub-steps cut where a
node enters or leaves the ground, error control, the friction law's
stability bound) on DOP853 sub-steps (``erk``: Dormand–Prince order 8 with
its 5th- and 3rd-order error estimates, on the state with a unit
quaternion).  At the accuracies that decide a throw's outcome (local errors
near 1e-10) an order-8 pair takes steps several times longer than RK4; its
12 stages cost 2.4 RK4 steps.
"""

from __future__ import annotations

from dicetrace.core._jit import jit_fused, specialise
from dicetrace.core.schemes.contact_substep import EXACT_FLIGHT, drive  # noqa: F401 (the driver's free flight)
from dicetrace.core.schemes.erk import dop853_error, dop853_substep

#: Largest λ_f·h of the friction law (DOP853's interval on the negative real
#: axis reaches about −6; a margin for the law's non-linearity).
FRICTION_THETA = 3.0
#: An impact's first sub-step, as ω·h with ω = √k.
H0 = 0.3

step = jit_fused(
    specialise(
        drive, "step_dop853", "contact-dop853: ``contact_substep.drive`` on DOP853 sub-steps (``erk``).",
        SUBSTEP=dop853_substep, ERROR=dop853_error, ERR_EXP=1.0 / 8.0, THETA=FRICTION_THETA, H0=H0,
    )
)
