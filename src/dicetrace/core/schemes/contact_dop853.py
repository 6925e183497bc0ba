"""``contact-dop853``: the contact driver on the DOP853 pair (docs/model.md §9).

The contact driver (``core.contact_driver``: exact free flight, sub-steps cut
where a node enters or leaves the ground, error control, the friction law's
stability bound) on DOP853 sub-steps (``core.methods.dop853``: order 8 with
its 5th- and 3rd-order error estimates).  No dense output.
"""

from __future__ import annotations

from dicetrace.core.contact_driver import make_drive, work_of
from dicetrace.core.methods import dop853

#: Free flight is exact (the parabola and the exact rotation): the run loop crosses a flight of several steps in one piece.
EXACT_FLIGHT = True
#: The driver's work area and the method's.
WORK = work_of(dop853)

#: One contact-aware step on DOP853 sub-steps (``core.schemes.Scheme``), and its events form.
step = make_drive(dop853, "step_dop853")
step_events = make_drive(dop853, "step_dop853_events", events=True)
