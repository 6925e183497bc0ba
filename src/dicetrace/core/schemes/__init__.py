"""The integrator schemes, one module each, and the table that names them.

A row of the integrator table (``dicetrace.integrators.INTEGRATORS``) names
its scheme (``IntegratorSpec.scheme``); :data:`SCHEMES` maps that name to the
module, imported here.  A scheme module holds physics and numerics only:
what :class:`Scheme` lists (and :class:`EventsScheme`, :class:`SummaryScheme`
where they apply).  Its run loops and batch kernels are built from it by
``core.kernels.kernels_of`` (``core.loop``), and compiled on their first call.

=========================  ============================================================
scheme module              step
=========================  ============================================================
``semi_implicit_euler``    the 2019 program's step, bit-faithful (specialised summary
                           kernel ``core.fast``)
``forward_euler``          textbook forward Euler
``verlet``                 velocity Verlet on R⁹ × SO(3)
``rk4``                    commutator-free Lie-group RK4 (``core.methods.rk4``)
``contact_substep``        the contact driver (``core.contact_driver``) on RK4
                           sub-steps (``contact-substep``, ``contact-adaptive``)
``contact_tsit5``          the contact driver on Tsit5 sub-steps with dense output
``contact_dop853``         the contact driver on DOP853 sub-steps
=========================  ============================================================

Adding an integrator: one module here and its line in :data:`SCHEMES`, one row
in the integrator table, its tests.
"""

from __future__ import annotations

from types import ModuleType
from typing import Protocol, runtime_checkable

import numpy as np

from dicetrace.core.schemes import (
    contact_dop853,
    contact_substep,
    contact_tsit5,
    forward_euler,
    rk4,
    semi_implicit_euler,
    verlet,
)


@runtime_checkable
class Scheme(Protocol):
    """What a scheme module provides to the run loop (``core.loop.make_roll``).

    For developers: ``step`` is a numba function; the run loop calls it once
    per step of length h.
    """

    #: True when the step integrates free flight exactly (the parabola and the exact rotation,
    #: ``core.free_flight``): the run loop then crosses a free flight of several whole steps in one piece.
    EXACT_FLIGHT: bool
    #: The dtype of its work record (``core.state.work_dtype``): what it keeps between its stages and steps
    #: besides the motion.
    WORK: np.dtype

    def step(self, st, wk, kp, h, contact) -> tuple[bool, int]:
        """One step of length h of the motion record ``st`` in the work record ``wk`` (``core.state``).

        On entry ``st.F``, ``st.P`` hold the contact forces at the current
        state (``contact`` says whether any is non-zero); on exit the state
        (X, U, L, W, off) has advanced by h and ``st.z``, ``st.F``, ``st.P``
        (and ``st.uk`` where contact was found) are evaluated at the new state
        (``forces.eval_forces``).  Rotations are exact, so the offsets stay
        rigid.  Returns whether any node is strictly below the ground and the
        bitmask of nodes at or below it.
        """


@runtime_checkable
class EventsScheme(Scheme, Protocol):
    """A scheme with exact contact events (the contact schemes, docs/model.md §8.1)."""

    def step_events(self, st, wk, kp, h, contact, sets, set_steps, ev_times) -> tuple[bool, int]:
        """``step``, recording the contact sets inside its sub-steps with their times (``contacts.note_event``)."""


@runtime_checkable
class SummaryScheme(Scheme, Protocol):
    """A scheme with a specialised summary kernel, bit-identical to the run loop's summary where it applies."""

    def summary(self, ic, off0, kp, sets, set_steps, budget) -> tuple[int, int, int, int]:
        """One throw to rest, summary only (``core.fast.roll_summary_sie`` for the program's scheme); a throw not
        ended after ``budget`` steps stops as ``Status.RUNNING`` and keeps nothing (the run loop goes on from
        slices)."""

    def summary_applies(self, kp, off0) -> bool:
        """Whether :meth:`summary` computes this configuration's summaries."""


#: The scheme modules by the name the integrator table gives them.
SCHEMES: dict[str, ModuleType] = {
    m.__name__.rsplit(".", 1)[-1]: m
    for m in (semi_implicit_euler, forward_euler, verlet, rk4, contact_substep, contact_tsit5, contact_dop853)
}


def scheme_module(spec) -> ModuleType:
    """The scheme module of the integrator table's row ``spec``."""
    return SCHEMES[spec.scheme]


def step_of(spec):
    """The step function (a numba dispatcher) of the table row ``spec``."""
    return scheme_module(spec).step


def has_events(scheme: ModuleType) -> bool:
    """Whether the scheme module records exact contact events (:class:`EventsScheme`)."""
    return isinstance(scheme, EventsScheme)


def has_summary(scheme: ModuleType) -> bool:
    """Whether the scheme module has a specialised summary kernel (:class:`SummaryScheme`)."""
    return isinstance(scheme, SummaryScheme)
