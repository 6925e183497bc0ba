"""The run loop of a throw, written once and compiled per (scheme, trace or summary).

``_roll`` is the one loop: it steps the state until the stop test fires
(docs/model.md §5.3, §7) or the run fails (§10), records the contact-set
sequence (§8) and, in its tracing variant, the per-step channels.  For a
scheme whose free flight is exact (``EXACT_FLIGHT`` in its module: the
contact schemes), a free flight of several whole steps is crossed in one
piece (``_cross_flight``): the stop-test energy is conserved in it, so the
stop test cannot fire, and no contact set changes.  It is
never called itself: :func:`roll_kernel` specialises it at compile time
(``_jit.specialise``) on the step function of one scheme (``core.schemes``,
named by the integrator table) and on whether it may trace, so each
compiled loop calls its step directly and a summary loop has no trace code.
Kernels are built on first use: a command that runs one integrator compiles
(or loads from the cache) that integrator's loops only.

The entry points take an integrator's kernel id (``IntegratorSpec.kernel_id``):

``run_roll``
    one throw, through the tracing loop (with all trace arrays of zero rows
    it writes nothing and returns the summary).  One throw never needs the
    summary loop's speed, and the tracing loop is the cheaper compile: a
    single throw (``simulate``, ``dicetrace record``) compiles that loop only.
``run_summary``
    one throw through the summary loop, which hands configurations with a
    specialised kernel (``core.fast`` for the program's scheme) to it: what
    ``run_batch`` runs per IC (tests and benchmarks call it one by one).
``run_batch``
    many throws in parallel (``prange``), summaries only.
``run_roll_general``
    the tracing loop of any integrator, chosen at run time, callable from
    numba (tests and benchmarks compare the specialised paths with it).  It
    compiles every integrator's loop.

Trace layouts (row n = state after n steps, row 0 the initial state):
``tr_state`` (n+1, 33): X(3), U(3), L(3) (program convention), offsets (8×3);
``tr_force`` (n+1, 24): contact forces F_k at the end of the step;
``tr_energy`` (n+1, 6): stop-test energy, translational kinetic, rotational
kinetic, gravitational, elastic, total (see ``model.energy_parts``).
"""

from __future__ import annotations

import math

import numpy as np
from numba import prange

from dicetrace.core import fast
from dicetrace.core._jit import jit, jit_parallel, specialise
from dicetrace.core.free_flight import flight_steps, free_advance
from dicetrace.core.model import energy_dynamic, energy_parts, energy_stop, face_up, node_heights, node_velocities
from dicetrace.core.schemes import scheme_module
from dicetrace.core.state import STATE, after_step, age_tolerance, copy_motion, init_state, new_states, state_finite
from dicetrace.integrators import INTEGRATORS
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

_NO_ROWS = (np.zeros((0, STATE_COLS)), np.zeros((0, FORCE_COLS)), np.zeros((0, ENERGY_COLS)))


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
        parts = energy_parts(U[0], U[1], U[2], W[0], W[1], W[2], st.z, kp)
        if kp.energy_mode != ENERGY_POINT_MASS:
            tr_energy[n, 0] = parts[4] - kp.e_rest
        for j in range(5):
            tr_energy[n, 1 + j] = parts[j]


@jit(inline="always")
def _clears(e, kp):
    """The stop-test energy e (``rigid``: ``energy_dynamic`` − e_rest) clears the stop threshold by far more than rounding.

    The margin is ``E_BOUND_MARGIN`` relative to the energy's terms (all
    positive in free flight), as the point-mass bound's; False for NaN.
    """
    return e - kp.e_stop > E_BOUND_MARGIN * (abs(e) + kp.e_rest + abs(kp.e_stop)) + 1e-9


@jit
def _cross_flight(n, m, st, kp, h, tracing, tr_state, tr_force, tr_energy):
    """Steps n+1 … n+m of a free flight in one exact piece (``free_flight.free_advance`` over m·h).

    Returns what a step returns (no node below the ground, contact mask 0).
    A trace gets rows n+1 … n+m−1 as the exact flight's states at those
    step ends, each from the flight's start (row n+m is the loop's, as for
    any step): tracing writes, never steers, so a traced throw and its
    summary stay the same bit for bit.  The tolerance weight ages by m steps.
    """
    age_tolerance(st, kp, h, m)
    if tracing:
        # the flight's start, kept in the sub-step work area (free between steps without a front)
        copy_motion(st.X, st.U, st.L, st.off, st.sub_X, st.sub_U, st.sub_L, st.sub_off)
        for i in range(1, m + 1):
            if i > 1:
                copy_motion(st.sub_X, st.sub_U, st.sub_L, st.sub_off, st.X, st.U, st.L, st.off)
            free_advance(st.X, st.U, st.W, st.off, kp, i * h)
            if i < m:
                node_heights(st.X[2], st.off, st.z)
                _write_trace(n + i, st, kp, tr_state, tr_force, tr_energy)
    else:
        free_advance(st.X, st.U, st.W, st.off, kp, m * h)
    return node_heights(st.X[2], st.off, st.z)


@jit
def _never(kp, off0):
    return False


@jit
def _no_kernel(ic, off0, kp, sets, set_steps):
    return Status.NON_FINITE, 0, -1, 0


def _roll(ic, off0, kp, S, sets, set_steps, tr_state, tr_force, tr_energy):
    """Integrate one throw from ``ic`` until it settles (or fails).

    Compiled per scheme (the global ``STEP``) and per ``TRACE``; see the
    module docstring.  A summary variant hands the throw to the scheme's
    specialised kernel ``FAST`` where ``FAST_APPLIES(kp, off0)``.

    Parameters
    ----------
    ic : (6,) float64
        U (cm/s) and L (program convention, node-mass·cm²/s).
    off0 : (8, 3) float64
        Initial node offsets from the centre of mass, cm (the program: ±half
        on each axis); a rotated cube starts tilted.
    kp : KernelParams
    S : (1,) ``core.state.STATE``
        The throw's state (scratch, overwritten).
    sets, set_steps : (cap,) uint8, (cap,) int32
        Output: the contact-set sequence (bit k = node k+1 at or below the
        ground) and the step at which each set was first seen.
    tr_state, tr_force, tr_energy : float64 arrays with 0 or n+1 rows
        (ignored by a summary variant).

    Returns
    -------
    (status, steps, outcome, nsets)
        outcome is the face 1..6, 0 when the top four nodes are no face, and
        -1 unless the status is SETTLED.
    """
    st = S[0]
    if not TRACE and FAST_APPLIES(kp, off0):
        return FAST(ic, off0, kp, sets, set_steps)
    init_state(st, ic, off0, kp)
    X = st.X
    U = st.U
    L = st.L
    W = st.W
    off = st.off
    z = st.z

    sets[0] = 0
    set_steps[0] = 0
    nsets = 1
    last_mask = 0
    # The program starts out of contact (forces are zero before the first
    # step): the start's recorded set is empty.  Read from the array, not
    # written as the constant False, so that the step compiles for a plain
    # bool only, not also for the literal False (half a cold run's compile).
    contact = sets[0] != 0
    n = nsets - 1  # the start's row (0), likewise an int64, never the literal 0

    e_rest = kp.e_rest
    e0 = energy_dynamic(U[0], U[1], U[2], W[0], W[1], W[2], z, kp) - e_rest
    e_blow = (1.0 + kp.blowup_rel) * max(e0, 0.0) + kp.blowup_abs
    point_mass = kp.energy_mode == ENERGY_POINT_MASS
    tracing = TRACE and (tr_state.shape[0] > 0 or tr_force.shape[0] > 0 or tr_energy.shape[0] > 0)
    # nothing reads the forces or node velocities at a step's end: an interpolating scheme may skip them
    st.lazy = not tracing and not point_mass
    if tracing:
        _write_trace(n, st, kp, tr_state, tr_force, tr_energy)

    h = kp.dt_s
    maxn = int(kp.max_steps)
    status = Status.TIME_CAP
    half2 = kp.half_side_cm * kp.half_side_cm
    # whether the stop-test energy of a free state clears the stop threshold by far
    # more than rounding (``_clears``; at the start only where that energy is e0)
    clear = not point_mass and _clears(e0, kp)
    while n < maxn:
        m = 0
        if FLIGHT and clear and last_mask == 0 and st.ahead == 0.0:
            # A free flight conserves the stop-test energy: while it lasts the
            # stop test cannot fire and no contact set changes.  Cross it in
            # one exact piece.
            m = flight_steps(X, U, W, off, kp, h, maxn - n)
        if m > 1:
            contact, mask = _cross_flight(n, m, st, kp, h, tracing, tr_state, tr_force, tr_energy)
            n += m
        else:
            n += 1
            contact, mask = STEP(st, kp, h, contact)
        finite = state_finite(X[2], U[0], U[1], U[2], L[0], L[1], L[2], off[0, 0], off[7, 2])
        ended, status, nsets, last_mask = after_step(finite, n, mask, last_mask, sets, set_steps, nsets)
        if ended:
            break
        e_dyn = math.nan
        if contact:
            e_dyn = energy_dynamic(U[0], U[1], U[2], W[0], W[1], W[2], z, kp) - e_rest
            if e_dyn > e_blow:
                status = Status.BLOW_UP
                if tracing:  # the state is finite: keep it for inspection
                    _write_trace(n, st, kp, tr_state, tr_force, tr_energy)
                break
        # Stop test.  In free flight (no contact) the point-mass energy is
        # bounded below cheaply: Σ|u_k|² = 8|U|² + 16·h²|ω|² + rounding, so the
        # exact 24-term sum is needed only when that bound is near threshold.
        # ``clear``: the stop-test energy of a free state clears the threshold
        # by far more than rounding (computed alike whether or not tracing).
        clear = False
        if point_mass:
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
                    node_velocities(U[0], U[1], U[2], W[0], W[1], W[2], off, st.uk)
                e = energy_stop(st.uk, z, st.P, kp)
            else:
                e = kp.e_stop + 1.0
        else:
            e = e_dyn if contact else energy_dynamic(U[0], U[1], U[2], W[0], W[1], W[2], z, kp) - e_rest
            clear = not contact and _clears(e, kp)
        if tracing:
            _write_trace(n, st, kp, tr_state, tr_force, tr_energy)
        if not math.isfinite(e):
            status = Status.NON_FINITE
            break
        if e <= kp.e_stop:
            status = Status.SETTLED
            break
    outcome = face_up(z) if status == Status.SETTLED else -1
    return status, n, outcome, nsets


def _batch(ics, off0, kp, cap, states, status, steps, outcome, nsets, sets, set_steps):
    """``run_roll`` over many ICs in parallel (prange), summary path only.

    Compiled per scheme: ``ROLL`` its summary loop, ``FAST``/``FAST_APPLIES``
    the scheme's specialised kernel (decided once per call here).

    ``sets``/``set_steps`` are (m·cap,) with IC i owning [i·cap, (i+1)·cap).
    The ICs are cut into blocks of ``BATCH_BLOCK``; block b owns the state
    ``states[b]`` (never shared by two threads), and every IC runs the very
    same serial code from a fresh state, so results are bit-identical to a
    loop of ``run_roll`` whatever the number of threads, the scheduling or
    the caller's chunking.
    """
    m = ics.shape[0]
    nblk = (m + BATCH_BLOCK - 1) // BATCH_BLOCK
    fast = FAST_APPLIES(kp, off0)
    e0 = np.zeros((0, STATE_COLS))
    e1 = np.zeros((0, FORCE_COLS))
    e2 = np.zeros((0, ENERGY_COLS))
    for b in prange(nblk):
        i0 = b * BATCH_BLOCK
        i1 = min(m, i0 + BATCH_BLOCK)
        S = states[b : b + 1]
        for i in range(i0, i1):
            if fast:  # what ROLL would do, without the call through it
                s, n, o, ns = FAST(ics[i], off0, kp, sets[i * cap : (i + 1) * cap], set_steps[i * cap : (i + 1) * cap])
            else:
                s, n, o, ns = ROLL(ics[i], off0, kp, S, sets[i * cap : (i + 1) * cap], set_steps[i * cap : (i + 1) * cap], e0, e1, e2)
            status[i] = s
            steps[i] = n
            outcome[i] = o
            nsets[i] = ns


_SPECS_BY_ID = {s.kernel_id: s for s in INTEGRATORS.values()}
_KERNELS: dict = {}


def _spec(integ: int):
    try:
        return _SPECS_BY_ID[int(integ)]
    except KeyError:
        raise ValueError(f"no integrator has kernel id {integ!r} (see dicetrace.integrators.INTEGRATORS)") from None


#: The specialised summary kernels, by scheme: ``(applies, kernel)``, where ``kernel(ic, off0, kp, sets,
#: set_steps)`` is bit-identical to the run loop's summary whenever ``applies(kp, off0)`` (``core.fast``).
_FAST_SUMMARIES = {"semi_implicit_euler": (fast.applies, fast.roll_summary_sie)}


def _fast_summary(scheme: str, trace: bool):
    """(applies, kernel) of a scheme's specialised summary kernel; never for a tracing loop."""
    if trace or scheme not in _FAST_SUMMARIES:
        return _never, _no_kernel
    return _FAST_SUMMARIES[scheme]


def summary_loop(step, name: str, *, exact_flight: bool = True):
    """The summary run loop around a step function of one's own, as a template to compile (``_jit.jit``).

    What a benchmark or a test that varies a scheme runs its variant in:
    ``_roll`` specialised on ``step`` (the contract of ``core.schemes``),
    with no specialised kernel; ``exact_flight`` as a scheme module's
    ``EXACT_FLIGHT`` (False: every free flight is stepped step by step).
    """
    return specialise(_roll, name, STEP=step, FLIGHT=bool(exact_flight), TRACE=False, FAST_APPLIES=_never,
                      FAST=_no_kernel)


def roll_kernel(integ: int, trace: bool):
    """The run loop of integrator ``integ`` (kernel id), tracing or summary only (built on first use).

    Called as ``kernel(ic, off0, kp, S, sets, set_steps, tr_state, tr_force, tr_energy)``
    (see ``_roll``).  Integrators that share a scheme share the kernel.
    """
    scheme = _spec(integ).scheme
    key = ("roll", scheme, bool(trace))
    if key not in _KERNELS:
        mod = scheme_module(_spec(integ))
        applies, fast_kernel = _fast_summary(scheme, trace)
        name = f"roll_{scheme}_{'trace' if trace else 'summary'}"
        _KERNELS[key] = jit(
            specialise(_roll, name, STEP=mod.step, FLIGHT=getattr(mod, "EXACT_FLIGHT", False), TRACE=bool(trace),
                       FAST_APPLIES=applies, FAST=fast_kernel)
        )
    return _KERNELS[key]


def batch_kernel(integ: int):
    """The parallel batch kernel of integrator ``integ`` (kernel id), built on first use (see ``_batch``)."""
    scheme = _spec(integ).scheme
    key = ("batch", scheme)
    if key not in _KERNELS:
        applies, fast_kernel = _fast_summary(scheme, False)
        _KERNELS[key] = jit_parallel(
            specialise(_batch, f"batch_{scheme}", ROLL=roll_kernel(integ, False), FAST_APPLIES=applies,
                       FAST=fast_kernel)
        )
    return _KERNELS[key]


def run_roll(ic, off0, kp, integ, sets, set_steps, tr_state, tr_force, tr_energy, states=None):
    """Integrate one throw with integrator ``integ`` (kernel id) in its tracing loop; see ``_roll``.

    The trace arrays (float64, 0 or n+1 rows) get the channels that have
    rows; with none, only the summary is returned (the same arithmetic as
    the summary loop: tracing writes, never steers).  ``states``: a (1,)
    ``STATE`` array to run in (its final state, e.g. the sub-step counts,
    can then be read); a fresh one by default.
    """
    S = new_states(1) if states is None else states
    return roll_kernel(integ, True)(ic, off0, kp, S, sets, set_steps, tr_state, tr_force, tr_energy)


def run_summary(ic, off0, kp, integ, sets, set_steps):
    """One throw through integrator ``integ``'s summary loop (and its specialised kernel); see ``_roll``."""
    return roll_kernel(integ, False)(ic, off0, kp, new_states(1), sets, set_steps, _NO_ROWS[0], _NO_ROWS[1], _NO_ROWS[2])


def run_batch(ics, off0, kp, integ, cap, status, steps, outcome, nsets, sets, set_steps):
    """Summaries of many throws with integrator ``integ`` (kernel id), in parallel; see ``_batch``.

    ``off0`` (8, 3) are the initial node offsets shared by all ICs; outputs
    are written in place.
    """
    states = new_states(max(1, (len(ics) + BATCH_BLOCK - 1) // BATCH_BLOCK))
    batch_kernel(integ)(ics, off0, kp, cap, states, status, steps, outcome, nsets, sets, set_steps)


def _link(ic, off0, kp, integ, sets, set_steps, tr_state, tr_force, tr_energy):
    """One link of ``run_roll_general``: this integrator's tracing loop, or the next link."""
    if integ == KERNEL_ID:
        S = np.zeros(1, dtype=STATE)
        return ROLL(ic, off0, kp, S, sets, set_steps, tr_state, tr_force, tr_energy)
    return NEXT(ic, off0, kp, integ, sets, set_steps, tr_state, tr_force, tr_energy)


@jit
def _unknown_integrator(ic, off0, kp, integ, sets, set_steps, tr_state, tr_force, tr_energy):
    """The end of the chain: no integrator has this id (reported as a non-finite first step)."""
    sets[0] = 0
    set_steps[0] = 0
    return Status.NON_FINITE, 1, -1, 1


def _general_chain():
    fn = _unknown_integrator
    for spec in sorted(INTEGRATORS.values(), key=lambda s: -s.kernel_id):
        name = f"run_roll_general_{spec.name.replace('-', '_')}"
        fn = jit(specialise(_link, name, KERNEL_ID=spec.kernel_id, ROLL=roll_kernel(spec.kernel_id, True), NEXT=fn))
    return fn


#: ``run_roll_general(ic, off0, kp, integ, sets, set_steps, tr_state, tr_force, tr_energy)``:
#: the tracing loop of integrator ``integ``, chosen at run time (a chain of
#: specialised links, one per row of the integrator table); returns as ``_roll``.
run_roll_general = _general_chain()
