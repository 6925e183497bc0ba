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
``run_events``
    one throw through a contact scheme's events loop: the exact contact
    events instead of the sets at output-step ends (:func:`has_events` says
    which integrators have one); ``run_batch`` runs many through it.

What a run keeps is a :class:`~dicetrace.saving.Record` (or None: the
summary): :func:`run_throw` and :func:`run_batch` choose their compiled loop
from it (the events loop where it asks for events: inside the loops that
choice is a constant compiled in, ``core._jit``), and :func:`roll_out_for`,
:func:`batch_out` make the outputs it asks for, as the named structures the
loops take (:class:`~dicetrace.core.loop.RollOut`,
:class:`~dicetrace.core.loop.BatchOut`).  An output not asked for is an array
of no rows there (event times of length 0, trace arrays of no rows): numba
types a loop's arguments once, and a loop tests their length, never their
presence, so the compiled loops stay as they are.
"""

from __future__ import annotations

import sys
import threading
import time
import types
from types import ModuleType
from typing import Protocol

import numba
import numpy as np

from dicetrace.core.loop import (
    BATCH_BLOCK,
    ENERGY_COLS,
    FORCE_COLS,
    STATE_COLS,
    BatchOut,
    RollOut,
    make_batch,
    make_roll,
)
from dicetrace.core.schemes import has_events as _scheme_has_events
from dicetrace.core.schemes import scheme_module
from dicetrace.core.state import new_states, new_work
from dicetrace.integrators import INTEGRATORS
from dicetrace.saving import Record, wants_events
from dicetrace.status import Status

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

    Called as ``kernel(ic, off0, kp, S, Wk, out, resume, budget)`` (``core.loop.make_roll``).
    """
    k = kernels_for(integ)
    return k.roll_trace if trace else k.roll_summary


def batch_kernel(integ: int):
    """The parallel batch kernel of integrator ``integ`` (kernel id); see ``core.loop.make_batch``."""
    return kernels_for(integ).batch


# ------------------------------------------------------------------ slices: every kernel returns within a bound

#: Steps of one throw per call of a kernel: a throw that has not ended then stops as ``Status.RUNNING`` with
#: its state kept, and the caller goes on with it in the next call.  Python runs between calls, so Ctrl-C
#: (KeyboardInterrupt) stops a run within one slice.  Above the default time cap's 60,000 steps of 1 ms: a
#: throw at the default settings never stops in the middle.
SLICE_STEPS = 1 << 16
#: The specialised summary kernel's slice, in ``SLICE_STEPS``: its steps cost a tenth of the run loop's or less
#: (``core.fast``), and a throw it has not ended then starts again in the run loop (it keeps nothing), so its
#: slice is long: only a throw past a time cap of some 4,000 s of 1 ms steps goes on in the run loop.
SUMMARY_SLICES = 64
#: The time one call of a batch kernel aims at (its throws are chosen from the last call's rate).
CALL_SECONDS = 0.25
#: Most throws in one call of a batch kernel, per numba thread (the state records of a call: a few MiB).
CALL_THROWS_PER_THREAD = 256


def new_roll_state(integ: int, n: int = 1):
    """The motion and work records ``(S, Wk)`` that ``n`` throws of integrator ``integ`` run in."""
    return new_states(n), new_work(kernels_for(integ).scheme.WORK, n)


def roll_out(sets, set_steps, ev_times=None, tr_state=None, tr_force=None, tr_energy=None) -> RollOut:
    """A run loop's outputs (:class:`~dicetrace.core.loop.RollOut`); absent channels are arrays of no rows."""
    return RollOut(sets, set_steps, _NO_EVENTS if ev_times is None else ev_times,
                   NO_TRACE[0] if tr_state is None else tr_state, NO_TRACE[1] if tr_force is None else tr_force,
                   NO_TRACE[2] if tr_energy is None else tr_energy)


def roll_out_for(cap: int, record: Record | None = None, rows: int = 0) -> RollOut:
    """Fresh outputs of a run loop for what ``record`` asks: ``cap`` contact sets (and their exact times where it
    asks for events) and ``rows`` rows of each trace channel it asks for (``rows=0``: a run that traces nothing)."""
    n = int(rows)
    chans = () if record is None else record.channels
    return roll_out(np.zeros(cap, np.uint8), np.zeros(cap, np.int32), np.zeros(cap) if wants_events(record) else None,
                    np.zeros((n, STATE_COLS)) if "states" in chans else None,
                    np.zeros((n, FORCE_COLS)) if "forces" in chans else None,
                    np.zeros((n, ENERGY_COLS)) if "energy" in chans else None)


def throw_out(out: BatchOut, i: int, cap: int) -> RollOut:
    """Throw i's part of a batch's outputs as a run loop's (views; no trace): what the batch kernel hands its loop."""
    lo, hi = i * cap, (i + 1) * cap
    return roll_out(out.sets[lo:hi], out.set_steps[lo:hi], out.ev_times[lo:hi] if len(out.ev_times) else None)


def _in_slices(kernel, ic, off0, kp, state, out: RollOut):
    """One throw through a run loop, slice by slice (``SLICE_STEPS`` steps each) until it ends."""
    S, Wk = state
    r = kernel(ic, off0, kp, S, Wk, out, False, SLICE_STEPS)
    while r[0] == Status.RUNNING:
        r = kernel(ic, off0, kp, S, Wk, out, True, SLICE_STEPS)
    return r


def run_roll(ic, off0, kp, integ, out: RollOut, state=None):
    """Integrate one throw with integrator ``integ`` (kernel id) in its tracing loop: (status, steps, outcome, nsets).

    ``out`` (:func:`roll_out`): the trace arrays (float64, 0 or n+1 rows)
    get the channels that have rows; with none, only the summary is returned
    (the same arithmetic as the summary loop: tracing writes, never steers).
    ``state``: the ``(S, Wk)`` records to run in (:func:`new_roll_state`; its
    final state, e.g. the sub-step counts ``S[0]["substeps"]``, can then be
    read); fresh ones by default.  Runs in slices of ``SLICE_STEPS`` steps.
    """
    return _in_slices(roll_kernel(integ, True), ic, off0, kp, state or new_roll_state(integ), out)


def run_summary(ic, off0, kp, integ, sets, set_steps):
    """One throw through integrator ``integ``'s specialised summary kernel where it applies, else its summary loop.

    The choice the batch kernel makes (``core.loop.make_batch``): a throw the
    specialised kernel does not end within a slice runs again in the loop.
    """
    k = kernels_for(integ)
    if hasattr(k.scheme, "summary") and k.scheme.summary_applies(kp, off0):
        r = k.scheme.summary(ic, off0, kp, sets, set_steps, SLICE_STEPS * SUMMARY_SLICES)
        if r[0] != Status.RUNNING:
            return r
    return _in_slices(k.roll_summary, ic, off0, kp, new_roll_state(integ), roll_out(sets, set_steps))


def has_events(integ: int) -> bool:
    """Whether integrator ``integ`` (kernel id) has an events loop (the contact schemes: their sub-steps end at the crossings)."""
    return _scheme_has_events(scheme_of(integ))


def _events_kernels(integ: int) -> SchemeKernels:
    """The kernels of integrator ``integ``, refused (ValueError) where it has no events loop."""
    if not has_events(integ):
        raise ValueError(f"integrator {spec_of(integ).name!r} has no exact contact events (only the contact schemes do)")
    return kernels_for(integ)


def run_events(ic, off0, kp, integ, out: RollOut, state=None):
    """One throw through integrator ``integ``'s events loop: (status, steps, outcome, nevents).

    ``out.sets``, ``out.set_steps``, ``out.ev_times`` (cap,) get the exact
    contact events (``core.loop.make_roll`` with ``events``).  In slices, as
    :func:`run_roll`.
    """
    return _in_slices(_events_kernels(integ).roll_events, ic, off0, kp, state or new_roll_state(integ), out)


def run_throw(ic, off0, kp, integ, out: RollOut, record: Record | None = None, state=None):
    """One throw's summary run as ``record`` asks: its exact contact events (:func:`run_events`) where it asks for
    them, else its contact sets at step ends (:func:`run_roll`, which traces what ``out`` has rows for).

    ``out``: :func:`roll_out_for` of the same ``record``.  Returns (status, steps, outcome, nsets).
    """
    run = run_events if wants_events(record) else run_roll
    return run(ic, off0, kp, integ, out, state)


def batch_out(m: int, cap: int, record: Record | None = None) -> BatchOut:
    """Fresh outputs of a batch kernel for ``m`` throws of ``cap`` sets each, and their exact times where ``record``
    asks for events (:class:`~dicetrace.core.loop.BatchOut`; a batch keeps no trace)."""
    return BatchOut(np.zeros(m, np.int8), np.zeros(m, np.int64), np.zeros(m, np.int8), np.zeros(m, np.int64),
                    np.zeros(m * cap, np.uint8), np.zeros(m * cap, np.int32),
                    np.zeros(m * cap) if wants_events(record) else _NO_EVENTS)


def _rows(out: BatchOut, a: int, b: int, cap: int) -> BatchOut:
    """Throws a..b of a batch's outputs (views)."""
    lo, hi = a * cap, b * cap
    ev = out.ev_times[lo:hi] if len(out.ev_times) else out.ev_times
    return BatchOut(out.status[a:b], out.steps[a:b], out.outcome[a:b], out.nsets[a:b], out.sets[lo:hi],
                    out.set_steps[lo:hi], ev)


def _taken(out: BatchOut, idx: np.ndarray, cap: int) -> BatchOut:
    """Copies of the throws ``idx``'s outputs, in that order (their sets so far included)."""
    cols = (idx[:, None] * cap + np.arange(cap)[None, :]).ravel()
    ev = out.ev_times[cols] if len(out.ev_times) else out.ev_times
    return BatchOut(out.status[idx], out.steps[idx], out.outcome[idx], out.nsets[idx], out.sets[cols],
                    out.set_steps[cols], ev)


def _put(out: BatchOut, idx: np.ndarray, cap: int, part: BatchOut) -> None:
    """Write ``part`` (from :func:`_taken`) back to the throws ``idx`` of ``out``."""
    cols = (idx[:, None] * cap + np.arange(cap)[None, :]).ravel()
    for name in ("status", "steps", "outcome", "nsets"):
        getattr(out, name)[idx] = getattr(part, name)
    out.sets[cols] = part.sets
    out.set_steps[cols] = part.set_steps
    if len(out.ev_times):
        out.ev_times[cols] = part.ev_times


def run_batch(ics, off0, kp, integ, cap, out: BatchOut, record: Record | None = None) -> None:
    """Every throw of ``ics`` to its end with integrator ``integ`` (kernel id), in parallel, written to ``out``.

    ``out`` (:func:`batch_out` of the same ``record``): throw i's summary and
    its contact sets in ``[i·cap, (i+1)·cap)`` (where ``record`` asks for
    events: the events loop's sets and their times).
    ``off0`` (8, 3) are the initial node offsets shared by all ICs.  The
    throws run in calls of the batch kernel (``core.loop.make_batch``) that
    each take about ``CALL_SECONDS`` (sized from the last call's rate, at most
    ``CALL_THROWS_PER_THREAD`` throws a thread), each throw at most
    ``SLICE_STEPS`` steps a call; those not ended go on, all together, in
    further calls.  Python runs between calls (Ctrl-C stops a batch within
    about a call).  Every throw runs the same serial code from a fresh
    state whatever the calls, so the results are those of one call.
    """
    events = wants_events(record)  # the one place a batch's kernel is chosen from the request
    k = _events_kernels(integ) if events else kernels_for(integ)
    kernel = k.batch_events if events else k.batch
    m = len(ics)
    threads = max(1, numba.get_num_threads())
    most = max(BATCH_BLOCK, CALL_THROWS_PER_THREAD * threads)
    S, Wk = new_states(min(m, most)), new_work(k.scheme.WORK, min(m, most))
    size = min(m, BATCH_BLOCK * threads)
    held = []  # (throw indices, their records) of throws not ended in their first call
    a = 0
    while a < m:
        b = min(m, a + size)
        t0 = time.perf_counter()
        kernel(ics[a:b], off0, kp, cap, S[: b - a], Wk[: b - a], _rows(out, a, b, cap), False, SLICE_STEPS,
               SLICE_STEPS * SUMMARY_SLICES)
        spent = time.perf_counter() - t0
        going = np.nonzero(out.status[a:b] == Status.RUNNING)[0]
        if going.size:
            held.append((a + going, S[going].copy(), Wk[going].copy()))
        # the next call's throws, from this one's rate (at most 4x more; a first call may have compiled)
        per = spent / (b - a)
        size = int(min(most, 4 * size, max(BATCH_BLOCK, CALL_SECONDS / per if per > 0 else most)))
        a = b
    for idx, Sh, Wh in held:
        part = _taken(out, idx, cap)
        while True:
            going = np.nonzero(part.status == Status.RUNNING)[0]
            if not going.size:
                break
            sub = _taken(part, going, cap)
            Sg, Wg = Sh[going], Wh[going]  # copies: the call moves them on, and they go back after it
            kernel(ics[idx[going]], off0, kp, cap, Sg, Wg, sub, True, SLICE_STEPS, 0)
            _put(part, going, cap, sub)
            Sh[going], Wh[going] = Sg, Wg
        _put(out, idx, cap, part)
