"""The run loop of a throw, written once and compiled per (scheme, trace or summary).

:func:`make_roll` builds the one loop: it steps the state until the stop
test fires (docs/model.md §5.3, §7) or the run fails (§10), records the
contact-set sequence (§8) and, in its tracing variant, the per-step
channels.  For a scheme whose free flight is exact (``EXACT_FLIGHT`` in its
module: the contact schemes), a free flight of several whole steps is
crossed in one piece (``_cross_flight``): the stop-test energy is conserved
in it, so the stop test cannot fire, and no contact set changes.

The loop is a closure over a scheme module (``core.schemes``) and a few
booleans, which numba compiles in as constants: each compiled loop calls its
scheme's step directly, and a summary loop has no trace code.
``core.kernels.kernels_of`` builds a scheme's loops and batch kernels
(:func:`make_roll`, :func:`make_batch`) once per process; nothing compiles
until a kernel's first call, so a command that runs one integrator compiles
(or loads from the cache) that integrator's loops only.  The entry points by
integrator (``run_roll``, ``run_summary``, ``run_batch``) are in
``core.kernels``; the GPU's are in ``core.gpu``, which compiles the same
functions for the device.

A run loop is ``roll(ic, off0, kp, S, Wk, out, resume, budget) -> (status,
steps, outcome, nsets)``: ``ic`` (6,) the IC, U (cm/s) and L (program
convention, node-mass·cm²/s); ``off0`` (8, 3) the initial node offsets from
the centre of mass, cm (the program: ±half on each axis; a rotated cube
starts tilted); ``kp`` the ``KernelParams``; ``S``, ``Wk`` (1,) arrays of
the throw's motion record and its scheme's work record (``core.state``);
``out`` a :class:`RollOut` (the contact sets, an events loop's times, the
trace rows).  ``outcome`` is the face 1..6, 0 when the top four nodes are no
face, and -1 unless the status is SETTLED.

Slices.  A loop takes at most ``budget`` steps per call: a throw not ended
then returns ``Status.RUNNING`` with the loop's own variables kept in its
motion record (``run_*``), and a call with ``resume`` goes on from there;
the throw is the same, bit for bit, however it is sliced (a free flight
crossed in one piece may run past the slice's end: it is never cut).  So
every kernel returns to Python within a bounded time, where Ctrl-C is seen
(``core.kernels.SLICE_STEPS``).

Trace layouts (row n = state after n steps, row 0 the initial state):
``tr_state`` (n+1, 33): X(3), U(3), L(3) (program convention), offsets (8×3);
``tr_force`` (n+1, 24): contact forces F_k at the end of the step;
``tr_energy`` (n+1, 6): stop-test energy, translational kinetic, rotational
kinetic, gravitational, elastic, total (see ``model.energy_parts``).
"""

from __future__ import annotations

import math
from types import ModuleType
from typing import NamedTuple

import numpy as np
from numba import prange

from dicetrace.core._jit import jit, jit_parallel
from dicetrace.core.contacts import note_event
from dicetrace.core.free_flight import flight_steps, free_advance
from dicetrace.core.model import (
    energy_dynamic,
    energy_parts,
    energy_stop,
    face_levels,
    node_heights,
    node_velocities,
    outcome_face,
)
from dicetrace.core.state import after_step, age_tolerance, copy_motion, init_state, state_finite
from dicetrace.params import ENERGY_POINT_MASS
from dicetrace.status import Status

STATE_COLS = 33
FORCE_COLS = 24
ENERGY_COLS = 6

# Relative safety margin of the free-flight energy bound (see _roll).  The
# bound is exact for a perfect cube; 1e-7 also covers offsets that drift from
# one over 10⁶ steps and tilted starts built from a rotation matrix accurate
# to 1e-9 (Config.initial_offsets accepts that much).  The margin decides
# when the exact energy is evaluated, never the result, and when a free
# flight may be crossed in one piece (the stop test cannot fire in it).
E_BOUND_MARGIN = 1e-7

#: ICs per work item of ``run_batch`` (a few ms of work: scheduling is free).
BATCH_BLOCK = 16

@jit
def _write_trace(n, st, kp, tr_state, tr_force, tr_energy):
    if tr_state.shape[0] > n:
        for j in range(3):
            tr_state[n, j] = st.X[j]
            tr_state[n, 3 + j] = st.U[j]
            tr_state[n, 6 + j] = st.L[j]
        for k in range(8):
            for j in range(3):
                tr_state[n, 9 + 3 * k + j] = st.off[k, j]
    if tr_force.shape[0] > n:
        for k in range(8):
            for j in range(3):
                tr_force[n, 3 * k + j] = st.F[k, j]
    if tr_energy.shape[0] > n:
        U = st.U
        W = st.W
        node_velocities(U[0], U[1], U[2], W[0], W[1], W[2], st.off, st.uk)
        if kp.energy_mode == ENERGY_POINT_MASS:
            tr_energy[n, 0] = energy_stop(st.uk, st.z, st.P, kp)
        parts = energy_parts(U[0], U[1], U[2], W[0], W[1], W[2], st.L[0], st.L[1], st.L[2], st.z, kp)
        if kp.energy_mode != ENERGY_POINT_MASS:
            tr_energy[n, 0] = parts[4] - kp.e_rest
        for j in range(5):
            tr_energy[n, 1 + j] = parts[j]


@jit(inline="always")
def events_after_step(finite, st, sets):
    """An events loop's checks after a step (what ``state.after_step`` does for the sampled sets):
    (ended, status), ended with NON_FINITE, or BUFFER_FULL when the events overflowed ``sets``."""
    if not finite:
        return True, Status.NON_FINITE
    if st.ev_n > sets.shape[0]:
        return True, Status.BUFFER_FULL
    return False, Status.TIME_CAP


@jit(inline="always")
def events_kept(st, n, status, set_steps):
    """The events an events loop returns when it stopped after step n: those that began up to that step.

    A dense-output scheme integrates ahead of the state, so events past the
    stop may have been recorded; they are dropped.  A full buffer keeps its
    count (more than it holds).
    """
    k = st.ev_n
    if status == Status.BUFFER_FULL:
        return k
    while k > 1 and set_steps[k - 1] > n:
        k -= 1
    return k


@jit(inline="always")
def _clears(e, kp):
    """The stop-test energy e (``rigid``: ``energy_dynamic`` − e_rest) clears the stop threshold by far more than rounding.

    The margin is ``E_BOUND_MARGIN`` relative to the energy's terms (all
    positive in free flight), as the point-mass bound's; False for NaN.
    """
    return e - kp.e_stop > E_BOUND_MARGIN * (abs(e) + kp.e_rest + abs(kp.e_stop)) + 1e-9


@jit(inline="always")
def stop_energy(st, kp, contact, e_dyn, tracing):
    """The stop-test energy after a step, whether it clears the threshold by far, and the threshold: (e, clear,
    threshold).

    ``e_dyn``: the dynamic energy the blow-up test computed (in contact).
    In free flight (no contact) the point-mass energy is bounded below
    cheaply: Σ|u_k|² = 8|U|² + 16·h²|ω|² + rounding, so the exact 24-term
    sum is needed only when that bound is near threshold (or a trace shows
    it).  ``clear``: the stop-test energy of a free state clears the
    threshold by far more than rounding (computed alike whether or not
    tracing), so that a free flight may be crossed in one piece.  A die
    that is no uniform cube is measured from the face it lies on, against
    that face's threshold (``model.face_levels``): the face its centre of mass stands over.
    """
    U = st.U
    W = st.W
    L = st.L
    z = st.z
    e_rest = kp.e_rest
    clear = False
    if kp.energy_mode == ENERGY_POINT_MASS:
        half2 = kp.half_side_cm * kp.half_side_cm
        need = True
        if not contact:
            ke = 8.0 * (U[0] * U[0] + U[1] * U[1] + U[2] * U[2]) + 16.0 * half2 * (
                W[0] * W[0] + W[1] * W[1] + W[2] * W[2]
            )
            sz = 0.0
            for k in range(8):
                sz += z[k]
            e_approx = (0.5 * ke + (-kp.g) * sz) - e_rest
            margin = E_BOUND_MARGIN * (0.5 * ke + abs(kp.g) * abs(sz) + e_rest) + 1e-9
            clear = e_approx - margin > kp.e_stop  # False for a NaN bound (overflow)
            need = tracing or not clear
        if need:
            if not contact:
                node_velocities(U[0], U[1], U[2], W[0], W[1], W[2], st.off, st.uk)
            e = energy_stop(st.uk, z, st.P, kp)
        else:
            e = kp.e_stop + 1.0
    else:
        e = e_dyn if contact else energy_dynamic(U[0], U[1], U[2], W[0], W[1], W[2], L[0], L[1], L[2], z, kp) - e_rest
        clear = not contact and _clears(e, kp)
        if not kp.isotropic:
            rest, threshold = face_levels(st.off, kp)
            return (e + e_rest) - rest, clear, threshold
    return e, clear, kp.e_stop


@jit
def _cross_flight(n, m, st, wk, kp, h, tracing, tr_state, tr_force, tr_energy):
    """Steps n+1 … n+m of a free flight in one exact piece (``free_flight.free_advance`` over m·h).

    Returns what a step returns (no node below the ground, contact mask 0).
    A trace gets rows n+1 … n+m−1 as the exact flight's states at those
    step ends, each from the flight's start (row n+m is the loop's, as for
    any step): tracing writes, never steers, so a traced throw and its
    summary stay the same bit for bit.  The tolerance weight ages by m steps.
    Only schemes whose free flight is exact cross one (``EXACT_FLIGHT``: the
    contact schemes, whose work record has the sub-step start).
    """
    age_tolerance(st, kp, h, m)
    if tracing:
        # the flight's start, kept in the sub-step work area (free between steps without a front)
        copy_motion(st.X, st.U, st.L, st.off, wk.sub_X, wk.sub_U, wk.sub_L, wk.sub_off)
        for i in range(1, m + 1):
            if i > 1:
                copy_motion(wk.sub_X, wk.sub_U, wk.sub_L, wk.sub_off, st.X, st.U, st.L, st.off)
            free_advance(st.X, st.U, st.W, st.off, kp, i * h)
            if i < m:
                node_heights(st.X[2], st.off, st.z)
                _write_trace(n + i, st, kp, tr_state, tr_force, tr_energy)
    else:
        free_advance(st.X, st.U, st.W, st.off, kp, m * h)
    return node_heights(st.X[2], st.off, st.z)


class RollOut(NamedTuple):
    """What a run loop writes (``make_roll``): the contact sets and, where asked for, events and trace rows.

    ``sets``, ``set_steps`` (cap,) uint8 and int32: the contact-set sequence
    (bit k = node k+1 at or below the ground) and the step at which each set
    was first seen; ``ev_times`` (cap,) float64: an events loop's time of
    each event (s), of length 0 for the other loops; ``tr_state``,
    ``tr_force``, ``tr_energy``: the trace channels, n+1 rows where asked for
    and 0 rows otherwise (a summary loop never touches them).
    """

    sets: np.ndarray
    set_steps: np.ndarray
    ev_times: np.ndarray
    tr_state: np.ndarray
    tr_force: np.ndarray
    tr_energy: np.ndarray


class BatchOut(NamedTuple):
    """What a batch kernel writes (``make_batch``), per throw i: its summary, and its contact sets (and events'
    times) in ``[i·cap, (i+1)·cap)`` of the flat ``sets``, ``set_steps`` (``ev_times``: of length 0 without events)."""

    status: np.ndarray
    steps: np.ndarray
    outcome: np.ndarray
    nsets: np.ndarray
    sets: np.ndarray
    set_steps: np.ndarray
    ev_times: np.ndarray


def make_roll(scheme: ModuleType, *, trace: bool, exact_flight: bool | None = None, events: bool = False,
              name: str | None = None, cache: bool = True):
    """The run loop of a throw on the step of the scheme module ``scheme`` (``core.schemes``), compiled.

    ``trace``: the tracing loop (it writes the trace arrays that have rows)
    or the summary loop (it never touches them).  ``exact_flight``: whether a
    free flight of several whole steps is crossed in one piece (default: the
    scheme's ``EXACT_FLIGHT``).  ``events``: an events loop (a contact
    scheme's, ``core.schemes.EventsScheme``), which records the exact contact
    events (docs/model.md §8.1) instead of the sets at output-step ends: the
    set inside every sub-step, the step it began in (1-based) and its time
    (s), up to the step the stop test fires on; more events than the buffer
    holds end as BUFFER_FULL.  These are closed over as constants
    (``core._jit``); a module made at run time (a benchmark's variant of a
    scheme) changes its cache key from one process to the next: build those
    with ``cache=False``.  The loop's arguments: the module's docstring.
    """
    trace = bool(trace)
    flight = bool(scheme.EXACT_FLIGHT if exact_flight is None else exact_flight)
    events = bool(events)

    def roll(ic, off0, kp, S, Wk, out, resume, budget):
        st = S[0]
        wk = Wk[0]
        sets, set_steps, ev_times = out.sets, out.set_steps, out.ev_times
        tr_state, tr_force, tr_energy = out.tr_state, out.tr_force, out.tr_energy
        X, U, L, W, off, z = st.X, st.U, st.L, st.W, st.off, st.z
        point_mass = kp.energy_mode == ENERGY_POINT_MASS
        tracing = trace and (tr_state.shape[0] > 0 or tr_force.shape[0] > 0 or tr_energy.shape[0] > 0)
        if resume:  # the throw goes on from where its last slice stopped
            n, nsets, last_mask = st.run_n, st.run_nsets, st.run_last
            contact, clear, e_blow = st.run_contact, st.run_clear, st.run_e_blow
        else:
            init_state(st, ic, off0, kp)
            nsets, last_mask, contact, n, e0, e_blow = start_run(st, kp, sets, set_steps)
            if events:
                ev_times[0] = 0.0
                st.ev_n = 1
            # nothing reads the forces or node velocities at a step's end: an interpolating scheme may skip them
            st.lazy = not tracing and not point_mass and kp.isotropic
            if tracing:
                _write_trace(n, st, kp, tr_state, tr_force, tr_energy)
            # whether the stop-test energy of a free state clears the stop threshold by far
            # more than rounding (``_clears``; at the start only where that energy is e0)
            clear = not point_mass and _clears(e0, kp)
        h = kp.dt_s
        maxn = int(kp.max_steps)
        stop = min(maxn, n + budget)  # this slice's last step
        status = Status.TIME_CAP
        while n < stop:
            if events:  # the step about to be taken
                st.ev_step = n
            m = 0
            if flight:
                if kp.isotropic and clear and last_mask == 0 and st.ahead == 0.0:
                    # A free flight conserves the stop-test energy: while it lasts the stop test cannot fire
                    # and no contact set changes.  Cross it in one exact piece (to the time cap, not the slice).
                    m = flight_steps(X, U, W, off, kp, h, maxn - n)
                if m > 1:
                    if events:
                        note_event(st, 0.0, h, 0, sets, set_steps, ev_times)
                    contact, mask = _cross_flight(n, m, st, wk, kp, h, tracing, tr_state, tr_force, tr_energy)
                    n += m
            if m <= 1:
                n += 1
                if events:
                    contact, mask = scheme.step_events(st, wk, kp, h, contact, sets, set_steps, ev_times)
                else:
                    contact, mask = scheme.step(st, wk, kp, h, contact)
            finite = state_finite(X[2], U[0], U[1], U[2], L[0], L[1], L[2], off[0, 0], off[7, 2])
            if events:
                ended, status = events_after_step(finite, st, sets)
                last_mask = mask
            else:
                ended, status, nsets, last_mask = after_step(finite, n, mask, last_mask, sets, set_steps, nsets)
            if ended:
                break
            e_dyn = math.nan
            if contact:
                e_dyn = energy_dynamic(U[0], U[1], U[2], W[0], W[1], W[2], L[0], L[1], L[2], z, kp) - kp.e_rest
                if e_dyn > e_blow:
                    status = Status.BLOW_UP
                    if tracing:  # the state is finite: keep it for inspection
                        _write_trace(n, st, kp, tr_state, tr_force, tr_energy)
                    break
            e, clear, threshold = stop_energy(st, kp, contact, e_dyn, tracing)
            if tracing:
                _write_trace(n, st, kp, tr_state, tr_force, tr_energy)
            if not math.isfinite(e):
                status = Status.NON_FINITE
                break
            if e <= threshold:
                status = Status.SETTLED
                break
        if status == Status.TIME_CAP and n < maxn:  # the slice ran out: keep what the next one goes on from
            keep_run(st, n, nsets, last_mask, contact, clear, e_blow)
            return Status.RUNNING, n, -1, nsets
        outcome = outcome_face(z, st.off, kp) if status == Status.SETTLED else -1
        if events:
            nsets = events_kept(st, n, status, set_steps)
        return status, n, outcome, nsets

    short = scheme.__name__.rsplit(".", 1)[-1]
    kind = "events" if events else "trace" if trace else "summary"
    roll.__name__ = roll.__qualname__ = name or f"roll_{short}_{kind}"
    roll.__doc__ = f"The {kind} run loop on ``{scheme.__name__}.step`` (``loop.make_roll``)."
    return jit(roll, cache=cache)


@jit(inline="always")
def start_run(st, kp, sets, set_steps):
    """A throw's start, after ``init_state``: the empty first contact set, and the loop's variables
    (nsets, last_mask, contact, n, e0, e_blow): e0 the start's dynamic energy, e_blow the blow-up bound."""
    sets[0] = 0
    set_steps[0] = 0
    nsets = 1
    last_mask = 0
    # The program starts out of contact (forces are zero before the first step): the start's recorded set is
    # empty.  Read from the array, not written as the constant False, so that the step compiles for a plain
    # bool only, not also for the literal False (half a cold run's compile).
    contact = sets[0] != 0
    n = nsets - 1  # the start's row (0), likewise an int64, never the literal 0
    U = st.U
    W = st.W
    e0 = energy_dynamic(U[0], U[1], U[2], W[0], W[1], W[2], st.L[0], st.L[1], st.L[2], st.z, kp) - kp.e_rest
    e_blow = (1.0 + kp.blowup_rel) * max(e0, 0.0) + kp.blowup_abs
    return nsets, last_mask, contact, n, e0, e_blow


@jit(inline="always")
def keep_run(st, n, nsets, last_mask, contact, clear, e_blow):
    """The run loop's variables, kept in the motion record at the end of a slice (``run_*``)."""
    st.run_n = n
    st.run_nsets = nsets
    st.run_last = last_mask
    st.run_contact = contact
    st.run_clear = clear
    st.run_e_blow = e_blow


def make_batch(scheme: ModuleType, loops: ModuleType, *, events: bool = False, name: str | None = None):
    """The parallel batch kernel of the scheme module ``scheme``: many throws, summaries only (``prange``).

    It runs ``loops.roll_summary`` (the scheme's summary loop, :func:`make_roll`)
    per IC, or ``scheme.summary`` directly where that applies (decided once
    per call; never to resume).  ``loops`` is the module that holds the
    scheme's run loops (``core.kernels.kernels_of``): the kernel closes over
    modules only, which numba's disk cache keys on by name (``core._jit``).
    The kernel, ``batch(ics, off0, kp, cap, S, Wk, out, resume, budget,
    fast_budget)``: throw i runs in its own motion and work records ``S[i]``,
    ``Wk[i]`` and writes ``out`` (:class:`BatchOut`), at most ``budget``
    steps (a throw not ended then is ``Status.RUNNING``, kept in its
    records); with ``resume`` every throw goes on from where its last slice
    stopped.  The specialised kernel, whose steps cost a fraction of the
    loop's, takes up to ``fast_budget`` steps; a throw it has not ended then
    (it keeps nothing) starts again in the run loop, which keeps its state.  Blocks of ``BATCH_BLOCK`` throws go
    to the threads, and every throw runs the very same serial code, so
    results are bit-identical to a loop of the single-throw loop whatever the
    number of threads, the scheduling or the caller's chunking.  ``events``:
    the batch of the events loop (``loops.roll_events``).
    """
    events = bool(events)
    use_summary = hasattr(scheme, "summary") and not events

    def batch(ics, off0, kp, cap, S, Wk, out, resume, budget, fast_budget):
        m = ics.shape[0]
        nblk = (m + BATCH_BLOCK - 1) // BATCH_BLOCK
        fast = use_summary and not resume and scheme.summary_applies(kp, off0)
        e0 = np.zeros((0, STATE_COLS))
        e1 = np.zeros((0, FORCE_COLS))
        e2 = np.zeros((0, ENERGY_COLS))
        # the outputs as local names: inside a prange body, numba 0.68 writes through a named tuple's field to a copy
        status, steps, outcome, nsets = out.status, out.steps, out.outcome, out.nsets
        sets, set_steps, ev_times = out.sets, out.set_steps, out.ev_times
        for b in prange(nblk):
            i0 = b * BATCH_BLOCK
            i1 = min(m, i0 + BATCH_BLOCK)
            for i in range(i0, i1):
                lo = i * cap
                hi = lo + cap
                s = Status.RUNNING
                if fast:  # what the summary loop would do, without the call through it
                    s, n, o, ns = scheme.summary(ics[i], off0, kp, sets[lo:hi], set_steps[lo:hi], fast_budget)
                if s == Status.RUNNING:  # a fresh throw the specialised kernel did not end (it keeps nothing), or any
                    ro = RollOut(sets[lo:hi], set_steps[lo:hi], ev_times[lo:hi], e0, e1, e2)
                    if events:
                        s, n, o, ns = loops.roll_events(ics[i], off0, kp, S[i : i + 1], Wk[i : i + 1], ro, resume, budget)
                    else:
                        s, n, o, ns = loops.roll_summary(ics[i], off0, kp, S[i : i + 1], Wk[i : i + 1], ro, resume,
                                                         budget)
                status[i] = s
                steps[i] = n
                outcome[i] = o
                nsets[i] = ns

    short = scheme.__name__.rsplit(".", 1)[-1]
    batch.__name__ = batch.__qualname__ = name or f"batch_{short}{'_events' if events else ''}"
    return jit_parallel(batch)
