"""The kernels of a scheme, built once per process, and the entry points by integrator.

:func:`kernels_of` builds the compiled kernels of a scheme module
(``core.schemes``): its tracing and summary run loops and its parallel batch
kernel, and for a contact scheme its events loop and batch
(:class:`SchemeKernels`; ``core.loop.make_roll``, ``make_batch``).  Nothing
compiles there: numba compiles (or loads from its disk cache) each kernel
on its first call.  Integrators that share a scheme share its kernels.

The entry points take an integrator's kernel id (``IntegratorSpec.kernel_id``):

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
    (:func:`has_events` says which integrators have one).
"""

from __future__ import annotations

import functools
import sys
import threading
import types
from types import ModuleType
from typing import Protocol

import numpy as np

from dicetrace.core.loop import BATCH_BLOCK, ENERGY_COLS, FORCE_COLS, STATE_COLS, make_batch, make_roll
from dicetrace.core.schemes import has_events as _scheme_has_events
from dicetrace.core.schemes import scheme_module
from dicetrace.core.state import new_states
from dicetrace.integrators import INTEGRATORS

_SPECS_BY_ID = {s.kernel_id: s for s in INTEGRATORS.values()}
#: The trace arrays of a run that traces nothing (state, forces, energy: no rows), as a run loop takes them.
NO_TRACE = (np.zeros((0, STATE_COLS)), np.zeros((0, FORCE_COLS)), np.zeros((0, ENERGY_COLS)))
#: The event times of a loop that records no events (which takes and ignores them).
_NO_EVENTS = np.zeros(0)


class SchemeKernels(Protocol):
    """The compiled kernels of one scheme (:func:`kernels_of`); numba dispatchers, compiled on first call."""

    #: The scheme module they run (``core.schemes``).
    scheme: ModuleType
    #: The tracing run loop (``loop.make_roll(scheme, trace=True)``).
    roll_trace: object
    #: The summary run loop (``loop.make_roll(scheme, trace=False)``).
    roll_summary: object
    #: The parallel batch kernel of summaries (``loop.make_batch``).
    batch: object
    #: The events loop and its batch (contact schemes; None for the others).
    roll_events: object
    batch_events: object


#: The module namespaces of the built kernels: one per scheme, ``dicetrace.core.kernels.<scheme>``.
_BUILT: dict = {}
_BUILD_LOCK = threading.Lock()


def kernels_of(scheme: ModuleType) -> SchemeKernels:
    """The kernels of the scheme module ``scheme``, built on the first call for it and kept for the process.

    They are held in a module registered as ``dicetrace.core.kernels.<scheme>``
    (a namespace, made here): the batch kernel and the GPU's kernels call
    the run loops through it, and a closure over a module is what numba's
    disk cache can key on by name (``core._jit``), where one over a compiled
    function would never hit.
    """
    with _BUILD_LOCK:
        built = _BUILT.get(scheme)
        if built is None:
            built = _BUILT[scheme] = _build(scheme)
        return built


def _build(scheme: ModuleType) -> SchemeKernels:
    short = scheme.__name__.rsplit(".", 1)[-1]
    name = f"{__name__}.{short}"
    mod = types.ModuleType(name, f"The compiled kernels of the scheme ``{scheme.__name__}`` (``core.kernels.kernels_of``).")
    sys.modules[name] = mod
    mod.scheme = scheme
    mod.roll_trace = make_roll(scheme, trace=True)
    mod.roll_summary = make_roll(scheme, trace=False)
    mod.batch = make_batch(scheme, mod)
    events = _scheme_has_events(scheme)
    mod.roll_events = make_roll(scheme, trace=False, events=True) if events else None
    mod.batch_events = make_batch(scheme, mod, events=True) if events else None
    return mod


def spec_of(integ: int):
    """The integrator table's row with kernel id ``integ``."""
    try:
        return _SPECS_BY_ID[int(integ)]
    except KeyError:
        raise ValueError(f"no integrator has kernel id {integ!r} (see dicetrace.integrators.INTEGRATORS)") from None


def scheme_of(integ: int) -> ModuleType:
    """The scheme module of integrator ``integ`` (kernel id)."""
    return scheme_module(spec_of(integ))


def kernels_for(integ: int) -> SchemeKernels:
    """The kernels of integrator ``integ`` (kernel id): those of its scheme (:func:`kernels_of`)."""
    return kernels_of(scheme_of(integ))


def roll_kernel(integ: int, trace: bool):
    """The run loop of integrator ``integ`` (kernel id), tracing or summary only.

    Called as ``kernel(ic, off0, kp, S, sets, set_steps, tr_state, tr_force, tr_energy, ev_times)``
    (see ``core.loop.make_roll``).
    """
    k = kernels_for(integ)
    return k.roll_trace if trace else k.roll_summary


def batch_kernel(integ: int):
    """The parallel batch kernel of integrator ``integ`` (kernel id); see ``core.loop.make_batch``."""
    return kernels_for(integ).batch


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
    k = kernels_for(integ)
    if hasattr(k.scheme, "summary") and k.scheme.summary_applies(kp, off0):
        return k.scheme.summary(ic, off0, kp, sets, set_steps)
    return k.roll_summary(ic, off0, kp, new_states(1), sets, set_steps, *NO_TRACE, _NO_EVENTS)


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
    return _scheme_has_events(scheme_of(integ))


def _events_kernels(integ: int) -> SchemeKernels:
    """The kernels of integrator ``integ``, refused (ValueError) where it has no events loop."""
    if not has_events(integ):
        raise ValueError(f"integrator {spec_of(integ).name!r} has no exact contact events (only the contact schemes do)")
    return kernels_for(integ)


def run_events(ic, off0, kp, integ, sets, set_steps, ev_times, states=None):
    """One throw through integrator ``integ``'s events loop: (status, steps, outcome, nevents).

    ``sets``, ``set_steps``, ``ev_times`` (cap,) get the exact contact
    events (``core.loop.make_roll`` with ``events``).
    """
    S = new_states(1) if states is None else states
    return _events_kernels(integ).roll_events(ic, off0, kp, S, sets, set_steps, *NO_TRACE, ev_times)


def run_batch_events(ics, off0, kp, integ, cap, status, steps, outcome, nsets, sets, set_steps, ev_times):
    """:func:`run_batch` through the events loop: ``ev_times`` (m·cap,) float64 laid out as ``sets``."""
    _events_kernels(integ).batch_events(ics, off0, kp, cap, _block_states(len(ics)), status, steps, outcome, nsets,
                                       sets, set_steps, ev_times)
