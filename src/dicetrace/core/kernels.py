"""The kernels of an integrator, by its kernel id (``IntegratorSpec.kernel_id``), and the entry points.

Each row of the integrator table names a scheme module (``core.schemes``),
which binds its run loops (``core.loop.scheme_kernels``); integrators that
share a scheme share its kernels.

``run_roll``
    one throw, through the tracing loop (with all trace arrays of zero rows
    it writes nothing and returns the summary).  One throw never needs the
    summary loop's speed, and the tracing loop is the cheaper compile: a
    single throw (``simulate``, ``dicetrace record``) compiles that loop only.
``run_summary``
    one throw through the specialised summary kernel where one applies
    (``core.fast`` for the program's scheme), else the summary loop: what
    ``run_batch`` runs per IC (tests and benchmarks call it one by one).
``run_batch``
    many throws in parallel (``prange``), summaries only.
``run_events``, ``run_batch_events``
    one throw, or many in parallel, through a contact scheme's events loop:
    the exact contact events instead of the sets at output-step ends
    (``core.loop.event_kernels``; :func:`has_events` says which integrators
    have one).
"""

from __future__ import annotations

import numpy as np

from dicetrace.core.loop import BATCH_BLOCK, ENERGY_COLS, FORCE_COLS, STATE_COLS
from dicetrace.core.schemes import scheme_module
from dicetrace.core.state import new_states
from dicetrace.integrators import INTEGRATORS

_SPECS_BY_ID = {s.kernel_id: s for s in INTEGRATORS.values()}
#: The trace arrays of a run that traces nothing (state, forces, energy: no rows), as a run loop takes them.
NO_TRACE = (np.zeros((0, STATE_COLS)), np.zeros((0, FORCE_COLS)), np.zeros((0, ENERGY_COLS)))
#: The event times of a loop that records no events (which takes and ignores them).
_NO_EVENTS = np.zeros(0)


def spec_of(integ: int):
    """The integrator table's row with kernel id ``integ``."""
    try:
        return _SPECS_BY_ID[int(integ)]
    except KeyError:
        raise ValueError(f"no integrator has kernel id {integ!r} (see dicetrace.integrators.INTEGRATORS)") from None


def scheme_of(integ: int):
    """The scheme module of integrator ``integ`` (kernel id), imported on first use."""
    return scheme_module(spec_of(integ))


def roll_kernel(integ: int, trace: bool):
    """The run loop of integrator ``integ`` (kernel id), tracing or summary only.

    Called as ``kernel(ic, off0, kp, S, sets, set_steps, tr_state, tr_force, tr_energy, ev_times)``
    (see ``core.loop.make_roll``).
    """
    mod = scheme_of(integ)
    return mod.roll_trace if trace else mod.roll_summary


def batch_kernel(integ: int):
    """The parallel batch kernel of integrator ``integ`` (kernel id); see ``core.loop.make_batch``."""
    return scheme_of(integ).batch


def run_roll(ic, off0, kp, integ, sets, set_steps, tr_state, tr_force, tr_energy, states=None):
    """Integrate one throw with integrator ``integ`` (kernel id) in its tracing loop; see ``core.loop.make_roll``.

    The trace arrays (float64, 0 or n+1 rows) get the channels that have
    rows; with none, only the summary is returned (the same arithmetic as
    the summary loop: tracing writes, never steers).  ``states``: a (1,)
    ``STATE`` array to run in (its final state, e.g. the sub-step counts,
    can then be read); a fresh one by default.
    """
    S = new_states(1) if states is None else states
    return roll_kernel(integ, True)(ic, off0, kp, S, sets, set_steps, tr_state, tr_force, tr_energy, _NO_EVENTS)


def run_summary(ic, off0, kp, integ, sets, set_steps):
    """One throw through integrator ``integ``'s specialised summary kernel where it applies, else its summary loop.

    The choice the batch kernel makes (``core.loop.make_batch``).
    """
    mod = scheme_of(integ)
    if hasattr(mod, "summary") and mod.summary_applies(kp, off0):
        return mod.summary(ic, off0, kp, sets, set_steps)
    return mod.roll_summary(ic, off0, kp, new_states(1), sets, set_steps, *NO_TRACE, _NO_EVENTS)


def run_batch(ics, off0, kp, integ, cap, status, steps, outcome, nsets, sets, set_steps):
    """Summaries of many throws with integrator ``integ`` (kernel id), in parallel; see ``core.loop.make_batch``.

    ``off0`` (8, 3) are the initial node offsets shared by all ICs; outputs
    are written in place.
    """
    batch_kernel(integ)(ics, off0, kp, cap, _block_states(len(ics)), status, steps, outcome, nsets, sets, set_steps)


def _block_states(m: int):
    """The state records a batch kernel of m throws runs in: one per block of ``BATCH_BLOCK`` throws."""
    return new_states(max(1, (m + BATCH_BLOCK - 1) // BATCH_BLOCK))


def has_events(integ: int) -> bool:
    """Whether integrator ``integ`` (kernel id) has an events loop (the contact schemes: their sub-steps end at the crossings)."""
    return hasattr(scheme_of(integ), "roll_events")


def _events_scheme(integ: int):
    """The scheme module of integrator ``integ``, refused (ValueError) where it has no events loop."""
    if not has_events(integ):
        raise ValueError(f"integrator {spec_of(integ).name!r} has no exact contact events (only the contact schemes do)")
    return scheme_of(integ)


def run_events(ic, off0, kp, integ, sets, set_steps, ev_times, states=None):
    """One throw through integrator ``integ``'s events loop: (status, steps, outcome, nevents).

    ``sets``, ``set_steps``, ``ev_times`` (cap,) get the exact contact
    events (``core.loop.make_roll`` with ``events``).
    """
    S = new_states(1) if states is None else states
    return _events_scheme(integ).roll_events(ic, off0, kp, S, sets, set_steps, *NO_TRACE, ev_times)


def run_batch_events(ics, off0, kp, integ, cap, status, steps, outcome, nsets, sets, set_steps, ev_times):
    """:func:`run_batch` through the events loop: ``ev_times`` (m·cap,) float64 laid out as ``sets``."""
    _events_scheme(integ).batch_events(ics, off0, kp, cap, _block_states(len(ics)), status, steps, outcome, nsets,
                                       sets, set_steps, ev_times)
