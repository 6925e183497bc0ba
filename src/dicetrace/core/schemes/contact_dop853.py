"""``contact-dop853``: contact-aware sub-stepping with the DOP853 pair (docs/model.md §9).

The driver of ``contact_substep`` (exact free flight, sub-steps cut where a
node enters or leaves the ground, error control, the friction law's
stability bound) on DOP853 sub-steps (``erk``: Dormand–Prince order 8 with
its 5th- and 3rd-order error estimates, on the state with a unit
quaternion).  At the accuracies that decide a throw's outcome (local errors
near 1e-10) an order-8 pair takes steps several times longer than RK4; its
12 stages cost 2.4 RK4 steps.  No dense output.

This module is the driver's sub-step method (``contact_substep.make_drive``):
the names below are what the driver reads.
"""

from __future__ import annotations

import sys

from dicetrace.core import loop
from dicetrace.core.schemes.contact_substep import EXACT_FLIGHT, make_drive  # noqa: F401 (the driver's free flight)
from dicetrace.core.schemes.contact_substep import no_dense_keep as dense_keep  # noqa: F401
from dicetrace.core.schemes.contact_substep import no_dense_state as dense_state  # noqa: F401
from dicetrace.core.schemes.erk import dop853_error, dop853_substep

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

step = make_drive(sys.modules[__name__], "step_dop853")
step_events = make_drive(sys.modules[__name__], "step_dop853_events", events=True)


#: This scheme's run loops: tracing, summary (``core.loop``) and the parallel batch.
roll_trace, roll_summary, batch = loop.scheme_kernels(sys.modules[__name__])
#: Its events loop and batch (exact contact events, ``loop.event_kernels``).
roll_events, batch_events = loop.event_kernels(sys.modules[__name__])
