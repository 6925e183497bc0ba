"""``contact-tsit5``: contact-aware sub-stepping with Tsitouras' 5(4) pair (docs/model.md §9).

The driver of ``contact_substep`` (exact free flight, sub-steps cut where a
node enters or leaves the ground, error control, the friction law's
stability bound) on Tsit5 sub-steps (``erk``: order 5 with an embedded
order-4 estimate, first same as last, on the state with a unit quaternion).
In the die's contacts a sub-step is seldom as long as its error allows: it
ends at the friction law's stability bound or where a node enters or leaves
the ground.  Six stages then buy more than DOP853's twelve: at the accuracy
that decides a throw's outcome it needs less work.  With dense output
(``DENSE``): the last sub-step of a step runs its full length past the
step's end, the state at the end is Tsit5's continuous extension there
(``erk.dense_state``), and the next step goes on from the front.
"""

from __future__ import annotations

from dicetrace.core._jit import jit_fused, specialise
from dicetrace.core.schemes.contact_substep import EXACT_FLIGHT, drive  # noqa: F401 (the driver's free flight)
from dicetrace.core.schemes.erk import dense_keep, dense_state, tsit5_error, tsit5_substep

#: Largest λ_f·h of the friction law (Tsit5's interval on the negative real
#: axis reaches −3.51; a margin for the law's non-linearity and for λ_f, a
#: per-node bound, being no bound on the die's whole friction Jacobian: at 3.3
#: a late sub-step of a `physical` throw raised its energy, analysis/accuracy/TUNING.md §2).
FRICTION_THETA = 3.0
#: An impact's first sub-step, as ω·h with ω = √k.
H0 = 0.4

#: What ``drive`` is specialised on for this scheme (also what a benchmark's variants of it start from).
DRIVE_CONSTANTS = dict(
    SUBSTEP=tsit5_substep, ERROR=tsit5_error, ERR_EXP=1.0 / 5.0, THETA=FRICTION_THETA, H0=H0,
    DENSE=True, DENSE_KEEP=dense_keep, DENSE_STATE=dense_state,
)

step = jit_fused(
    specialise(
        drive, "step_tsit5", "contact-tsit5: ``contact_substep.drive`` on Tsit5 sub-steps (``erk``).",
        **DRIVE_CONSTANTS,
    )
)
