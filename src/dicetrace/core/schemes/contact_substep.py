"""``contact-substep`` and ``contact-adaptive``: the contact driver on the RK4 method (docs/model.md §9).

The contact driver (``core.contact_driver``: exact free flight, sub-steps cut
where a node enters or leaves the ground, the friction law's stability
bound) on commutator-free RK4 sub-steps (``core.methods.rk4``): at most
dt / ``substeps`` each (``contact-substep``), or error-controlled with the
embedded order-3 estimate (``contact-adaptive``, ``kp.tol > 0``).
"""

from __future__ import annotations

from dicetrace.core.contact_driver import make_drive, work_of
from dicetrace.core.methods import rk4

#: Free flight is exact (the parabola and the exact rotation): the run loop crosses a flight of several steps in one piece.
EXACT_FLIGHT = True
#: The driver's work area and the method's.
WORK = work_of(rk4)

#: One contact-aware step on RK4 sub-steps (``core.schemes.Scheme``), and its events form.
step = make_drive(rk4, "step_rk4")
step_events = make_drive(rk4, "step_rk4_events", events=True)
