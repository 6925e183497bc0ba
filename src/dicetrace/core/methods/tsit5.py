"""Tsitouras' 5(4) pair as a sub-step method (``core.methods.SubstepMethod``), with its continuous extension.

Six stages (``erk``: order 5 with an embedded order-4 estimate, first same
as last, on the state with a unit quaternion).  In the die's contacts a
sub-step is seldom as long as its error allows: it ends at the friction
law's stability bound or where a node enters or leaves the ground.  Six
stages then buy more than DOP853's twelve: at the accuracy that decides a
throw's outcome it needs less work.  With dense output (``DENSE``): the last
sub-step of a step runs its full length past the step's end, the state at
the end is Tsit5's continuous extension there (``erk.dense_state``), and the
next step goes on from the front.  The scheme ``contact_tsit5`` is the
contact driver on this method.
"""

from __future__ import annotations

from dicetrace.core.methods.erk import (  # noqa: F401
    TSIT5_DENSE_WORK,
    TSIT5_STAGES,
    dense_keep,
    dense_state,
    erk_work,
    tsit5_error,
    tsit5_substep,
)

substep = tsit5_substep
error = tsit5_error
#: The step-size exponent, 1 / (the estimate's order + 1).
ERR_EXP = 1.0 / 5.0
#: Largest λ_f·h of the friction law (Tsit5's interval on the negative real
#: axis reaches −3.51; a margin for the law's non-linearity and for λ_f, a
#: per-node bound, being no bound on the die's whole friction Jacobian: at 3.3
#: a late sub-step of a `physical` throw raised its energy, analysis/accuracy/TUNING.md §2).
FRICTION_THETA = 3.0
#: An impact's first sub-step, as ω·h with ω = √k.
H0 = 0.4
#: The last sub-step of a step runs past its end; the end is interpolated (``dense_keep``, ``dense_state``).
DENSE = True
#: Its work area besides the sub-step start and end (``core.state``): the stages, and what dense output keeps.
WORK = erk_work(TSIT5_STAGES) + TSIT5_DENSE_WORK
