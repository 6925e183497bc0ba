"""The integrator schemes, one module each, and the lookup from the integrator table.

A row of the integrator table (``dicetrace.integrators.INTEGRATORS``) names
its scheme module here (``IntegratorSpec.scheme``); the module defines

``step(st, kp, h, contact) -> (contact, mask)``
    one step of length h of the state record ``st`` (``core.state``).  On
    entry ``st.F``, ``st.P`` hold the contact forces at the current state
    (``contact`` says whether any is non-zero); on exit the state (X, U, L,
    W, off) has advanced by h and ``st.z``, ``st.F``, ``st.P`` (and ``st.uk``
    where contact was found) are evaluated at the new state
    (``forces.eval_forces``).  Rotations are exact, so the offsets stay
    rigid.  Returns whether any node is strictly below the ground and the
    bitmask of nodes at or below it;

``EXACT_FLIGHT`` (optional, False when absent)
    True when the step integrates free flight exactly (the parabola and the
    exact rotation, ``core.free_flight``): the run loop then crosses a free
    flight of several whole steps in one piece (``core.loop``);

``summary(ic, off0, kp, sets, set_steps)``, ``summary_applies(kp, off0)`` (optional)
    a specialised summary kernel, bit-identical to the run loop's summary
    wherever ``summary_applies`` (``core.fast`` for ``semi_implicit_euler``);

``roll_trace, roll_summary, batch``
    its kernels, bound by the module's last line,
    ``roll_trace, roll_summary, batch = loop.scheme_kernels(sys.modules[__name__])``
    (``core.loop``; nothing compiles before a kernel's first call).

Adding an integrator: one module here, one row in the table, its tests.
"""

from __future__ import annotations

import importlib
from types import ModuleType


def scheme_module(spec) -> ModuleType:
    """The scheme module of the table row ``spec`` (imported on first use)."""
    return importlib.import_module(f"{__name__}.{spec.scheme}")


def step_of(spec):
    """The step function (a numba dispatcher) of the table row ``spec``."""
    return scheme_module(spec).step
