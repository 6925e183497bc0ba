"""``contact-tsit5``: the contact driver on Tsitouras' 5(4) pair with dense output (docs/model.md §9).

The contact driver (``core.contact_driver``: exact free flight, sub-steps cut
where a node enters or leaves the ground, error control, the friction law's
stability bound) on Tsit5 sub-steps (``core.methods.tsit5``): the last
sub-step of a step runs past its end and the state at the end is
interpolated (Tsit5's continuous extension); the next step goes on from the
front.  The `physical` preset's default integrator.
"""

from __future__ import annotations

from dicetrace.core.contact_driver import make_drive, work_of
from dicetrace.core.methods import tsit5

#: Free flight is exact (the parabola and the exact rotation): the run loop crosses a flight of several steps in one piece.
EXACT_FLIGHT = True
#: The driver's work area and the method's.
WORK = work_of(tsit5)

#: One contact-aware step on Tsit5 sub-steps (``core.schemes.Scheme``), and its events form.
step = make_drive(tsit5, "step_tsit5")
step_events = make_drive(tsit5, "step_tsit5_events", events=True)
