"""Run a throw to rest: the summary path, the trace path and the batch.

``run_roll`` is the single loop behind everything: the summary of a throw
(status, steps, outcome, contact-set sequence) is always produced; the
per-step channels are written only into the trace arrays that the caller
passes with rows (zero-row arrays mean "not requested": nothing is computed
for them, and the compiled signature never changes).

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

from dicetrace.core._jit import jit, jit_parallel
from dicetrace.core.contacts import record_set
from dicetrace.core.fast import mirror_symmetric, roll_summary_sie
from dicetrace.core.fast_substep import roll_summary_cs
from dicetrace.core.integrators import CONTACT_ADAPTIVE, CONTACT_SUBSTEP, SEMI_IMPLICIT_EULER, step
from dicetrace.core.model import (
    energy_dynamic,
    energy_parts,
    energy_stop,
    face_up,
    node_heights,
    node_velocities,
)
from dicetrace.params import ENERGY_POINT_MASS
from dicetrace.status import Status

STATE_COLS = 33
FORCE_COLS = 24
ENERGY_COLS = 6

# Relative safety margin of the free-flight energy bound (see run_roll).  The
# bound is exact for a perfect cube; 1e-7 also covers offsets that drift from
# one over 10⁶ steps and tilted starts built from a rotation matrix accurate
# to 1e-9 (simulate.initial_offsets accepts that much).  The margin only
# decides when the exact energy is evaluated, never the result.
E_BOUND_MARGIN = 1e-7


@jit
def _write_trace(n, X, U, L, off, F, uk, z, P, W, kp, tr_state, tr_force, tr_energy, e_buf):
    if tr_state.shape[0] > n:
        for j in range(3):
            tr_state[n, j] = X[j]
            tr_state[n, 3 + j] = U[j]
            tr_state[n, 6 + j] = L[j]
        for k in range(8):
            for j in range(3):
                tr_state[n, 9 + 3 * k + j] = off[k, j]
    if tr_force.shape[0] > n:
        for k in range(8):
            for j in range(3):
                tr_force[n, 3 * k + j] = F[k, j]
    if tr_energy.shape[0] > n:
        node_velocities(U, off, W[0], W[1], W[2], uk)
        if kp.energy_mode == ENERGY_POINT_MASS:
            tr_energy[n, 0] = energy_stop(uk, z, P, kp)
        energy_parts(U, W[0], W[1], W[2], z, kp, e_buf)
        if kp.energy_mode != ENERGY_POINT_MASS:
            tr_energy[n, 0] = e_buf[4] - kp.e_rest
        for j in range(5):
            tr_energy[n, 1 + j] = e_buf[j]


@jit
def use_fast_path(integ, kp, off0):
    """Whether ``fast.roll_summary_sie`` computes this configuration's summaries.

    It covers the 2019 program's integrator (semi-implicit Euler) with the
    point-mass stop-test energy, either friction law and either normal-force
    rule (the ``seed`` preset and its parameter variations), from
    mirror-symmetric initial offsets (any start built as ±half·R is).
    """
    return integ == SEMI_IMPLICIT_EULER and kp.energy_mode == ENERGY_POINT_MASS and mirror_symmetric(off0)


@jit
def run_roll(ic, off0, kp, integ, sets, set_steps, tr_state, tr_force, tr_energy):
    """Integrate one throw from ``ic`` until it settles (or fails).

    The summary path (all trace arrays with zero rows) of configurations
    that ``use_fast_path`` accepts runs the specialised kernel
    ``fast.roll_summary_sie``, bit-identical to ``run_roll_general``;
    the summary path of ``contact-substep`` runs ``fast_substep.roll_summary_cs``
    (the same loop without trace branches or step dispatch, bit-identical);
    everything else runs ``run_roll_general``.  Arguments and results are
    those of ``run_roll_general``.
    """
    tracing = tr_state.shape[0] > 0 or tr_force.shape[0] > 0 or tr_energy.shape[0] > 0
    if not tracing and use_fast_path(integ, kp, off0):
        off = np.empty((8, 3))
        F = np.empty((8, 3))
        uk = np.empty((8, 3))
        z = np.empty(8)
        P = np.empty(8)
        return roll_summary_sie(ic, off0, kp, sets, set_steps, off, F, uk, z, P)
    if not tracing and (integ == CONTACT_SUBSTEP or integ == CONTACT_ADAPTIVE):
        return roll_summary_cs(ic, off0, kp, sets, set_steps)
    return run_roll_general(ic, off0, kp, integ, sets, set_steps, tr_state, tr_force, tr_energy)


@jit
def run_roll_general(ic, off0, kp, integ, sets, set_steps, tr_state, tr_force, tr_energy):
    """Integrate one throw from ``ic`` until it settles (or fails): the general loop.

    Parameters
    ----------
    ic : (6,) float64
        U (cm/s) and L (program convention, node-mass·cm²/s).
    off0 : (8, 3) float64
        Initial node offsets from the centre of mass, cm (the program: ±half
        on each axis, ``model.init_offsets``); a rotated cube starts tilted.
    kp : KernelParams
    integ : int
        Integrator id.
    sets, set_steps : (cap,) uint8, (cap,) int32
        Output: the contact-set sequence (bit k = node k+1 at or below the
        ground) and the step at which each set was first seen.
    tr_state, tr_force, tr_energy : float64 arrays with 0 or n+1 rows

    Returns
    -------
    (status, steps, outcome, nsets)
        outcome is the face 1..6, 0 when the top four nodes are no face, and
        -1 unless the status is SETTLED.
    """
    X = np.empty(3)
    U = np.empty(3)
    L = np.empty(3)
    W = np.empty(3)
    off = np.empty((8, 3))
    F = np.zeros((8, 3))
    uk = np.zeros((8, 3))
    z = np.empty(8)
    P = np.zeros(8)
    R = np.zeros((3, 3))
    Rh = np.array([-1.0, 0.0, 0.0])
    e_buf = np.zeros(5)

    X[0] = 0.0
    X[1] = 0.0
    X[2] = kp.z0_cm
    for j in range(3):
        U[j] = ic[j]
        L[j] = ic[3 + j]
        W[j] = L[j] / kp.inertia
    for k in range(8):
        for j in range(3):
            off[k, j] = off0[k, j]
    contact, mask0 = node_heights(X[2], off, z)
    contact = False  # forces are zero before the first step (program)

    sets[0] = 0
    set_steps[0] = 0
    nsets = 1
    last_mask = 0

    e_rest = kp.e_rest
    e0 = energy_dynamic(U, W[0], W[1], W[2], z, kp) - e_rest
    e_blow = (1.0 + kp.blowup_rel) * max(e0, 0.0) + kp.blowup_abs
    point_mass = kp.energy_mode == ENERGY_POINT_MASS
    tracing = tr_state.shape[0] > 0 or tr_force.shape[0] > 0 or tr_energy.shape[0] > 0
    if tracing:
        _write_trace(0, X, U, L, off, F, uk, z, P, W, kp, tr_state, tr_force, tr_energy, e_buf)

    h = kp.dt_s
    maxn = int(kp.max_steps)
    status = Status.TIME_CAP
    n = 0
    half2 = kp.half_side_cm * kp.half_side_cm
    while n < maxn:
        n += 1
        contact, mask = step(integ, X, U, L, W, off, F, uk, z, P, R, Rh, kp, h, contact)
        if mask < 0:
            status = Status.NON_FINITE
            break
        if not (
            math.isfinite(X[2] + U[0] + U[1] + U[2])
            and math.isfinite(L[0] + L[1] + L[2] + off[0, 0] + off[7, 2])
        ):
            status = Status.NON_FINITE
            break
        nsets, last_mask, ok = record_set(n, mask, last_mask, sets, set_steps, nsets)
        if not ok:
            status = Status.BUFFER_FULL
            break
        if contact:
            if energy_dynamic(U, W[0], W[1], W[2], z, kp) - e_rest > e_blow:
                status = Status.BLOW_UP
                if tracing:  # the state is finite: keep it for inspection
                    _write_trace(n, X, U, L, off, F, uk, z, P, W, kp, tr_state, tr_force, tr_energy, e_buf)
                break
        # Stop test.  In free flight (no contact) the point-mass energy is
        # bounded below cheaply: Σ|u_k|² = 8|U|² + 16·h²|ω|² + rounding, so the
        # exact 24-term sum is needed only when that bound is near threshold.
        if point_mass:
            need = True
            if not contact and not tracing:
                ke = 8.0 * (U[0] * U[0] + U[1] * U[1] + U[2] * U[2]) + 16.0 * half2 * (
                    W[0] * W[0] + W[1] * W[1] + W[2] * W[2]
                )
                sz = 0.0
                for k in range(8):
                    sz += z[k]
                e_approx = (0.5 * ke + (-kp.g) * sz) - e_rest
                margin = E_BOUND_MARGIN * (0.5 * ke + abs(kp.g) * abs(sz) + e_rest) + 1e-9
                need = e_approx - margin <= kp.e_stop
            if need:
                if not contact:
                    node_velocities(U, off, W[0], W[1], W[2], uk)
                e = energy_stop(uk, z, P, kp)
            else:
                e = kp.e_stop + 1.0
        else:
            e = energy_dynamic(U, W[0], W[1], W[2], z, kp) - e_rest
        if tracing:
            _write_trace(n, X, U, L, off, F, uk, z, P, W, kp, tr_state, tr_force, tr_energy, e_buf)
        if not math.isfinite(e):
            status = Status.NON_FINITE
            break
        if e <= kp.e_stop:
            status = Status.SETTLED
            break
    outcome = face_up(z) if status == Status.SETTLED else -1
    return status, n, outcome, nsets


#: ICs per work item of ``run_batch`` (a few ms of work: scheduling is free).
BATCH_BLOCK = 16


@jit_parallel
def run_batch(ics, off0, kp, integ, cap, status, steps, outcome, nsets, sets, set_steps):
    """``run_roll`` over many ICs in parallel (prange), summary path only.

    ``off0`` (8, 3) are the initial node offsets shared by all ICs.
    ``sets``/``set_steps`` are (m·cap,) with IC i owning [i·cap, (i+1)·cap).
    The ICs are cut into blocks of ``BATCH_BLOCK``; each block owns its
    scratch arrays (allocated here once per call, never shared by two
    threads), and every IC runs the very same serial code from a fresh
    state, so results are bit-identical to a loop of ``run_roll`` whatever
    the number of threads, the scheduling or the caller's chunking.
    """
    m = ics.shape[0]
    nblk = (m + BATCH_BLOCK - 1) // BATCH_BLOCK
    fast = use_fast_path(integ, kp, off0)
    s_off = np.empty((nblk, 8, 3))
    s_F = np.empty((nblk, 8, 3))
    s_uk = np.empty((nblk, 8, 3))
    s_z = np.empty((nblk, 8))
    s_P = np.empty((nblk, 8))
    e0 = np.zeros((0, STATE_COLS))
    e1 = np.zeros((0, FORCE_COLS))
    e2 = np.zeros((0, ENERGY_COLS))
    for b in prange(nblk):
        i0 = b * BATCH_BLOCK
        i1 = min(m, i0 + BATCH_BLOCK)
        for i in range(i0, i1):
            if fast:
                s, n, o, ns = roll_summary_sie(
                    ics[i], off0, kp, sets[i * cap : (i + 1) * cap], set_steps[i * cap : (i + 1) * cap],
                    s_off[b], s_F[b], s_uk[b], s_z[b], s_P[b],
                )
            elif integ == CONTACT_SUBSTEP or integ == CONTACT_ADAPTIVE:
                s, n, o, ns = roll_summary_cs(ics[i], off0, kp, sets[i * cap : (i + 1) * cap], set_steps[i * cap : (i + 1) * cap])
            else:
                s, n, o, ns = run_roll_general(
                    ics[i], off0, kp, integ, sets[i * cap : (i + 1) * cap], set_steps[i * cap : (i + 1) * cap], e0, e1, e2
                )
            status[i] = s
            steps[i] = n
            outcome[i] = o
            nsets[i] = ns
