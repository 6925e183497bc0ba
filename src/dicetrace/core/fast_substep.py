"""The summary path of ``contact-substep``: ``run_roll_general`` without the trace.

``roll_summary_cs`` is ``loop.run_roll_general`` for integrator 4 with every
trace branch removed and the step called directly (``schemes.step_contact_substep``
inlined here) instead of through ``integrators.step`` → ``schemes.step_scheme``,
whose out-of-line calls pass ~11 arrays per macro step.  The arithmetic is the
same code in the same order: results are bit-identical to ``run_roll_general``
(tests/test_integrators.py::test_contact_substep_fast_path_identical).
"""

from __future__ import annotations

import math

import numpy as np

from dicetrace.core._jit import jit
from dicetrace.core.contacts import record_set
from dicetrace.core.model import (
    energy_dynamic,
    energy_stop,
    face_up,
    node_heights,
    node_velocities,
)
from dicetrace.core.schemes import step_contact_substep
from dicetrace.params import ENERGY_POINT_MASS
from dicetrace.status import Status

#: Same value as ``loop.E_BOUND_MARGIN`` (not imported: loop imports this module).
E_BOUND_MARGIN = 1e-7


@jit
def roll_summary_cs(ic, off0, kp, sets, set_steps):
    """``run_roll_general(ic, off0, kp, 4, sets, set_steps, <no trace>)``, bit for bit."""
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

    h = kp.dt_s
    maxn = int(kp.max_steps)
    status = Status.TIME_CAP
    n = 0
    half2 = kp.half_side_cm * kp.half_side_cm
    while n < maxn:
        n += 1
        contact, mask = step_contact_substep(X, U, L, W, off, F, uk, z, P, R, Rh, kp, h, contact)
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
                break
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
                need = e_approx - margin <= kp.e_stop
            if need:
                if not contact:
                    node_velocities(U, off, W[0], W[1], W[2], uk)
                e = energy_stop(uk, z, P, kp)
            else:
                e = kp.e_stop + 1.0
        else:
            e = energy_dynamic(U, W[0], W[1], W[2], z, kp) - e_rest
        if not math.isfinite(e):
            status = Status.NON_FINITE
            break
        if e <= kp.e_stop:
            status = Status.SETTLED
            break
    outcome = face_up(z) if status == Status.SETTLED else -1
    return status, n, outcome, nsets
