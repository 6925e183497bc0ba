"""The state of one throw: a numpy record that every kernel passes by reference.

One ``STATE`` record holds everything a step reads and writes, by name
(docs/model.md §5.1): the centre of mass X and its velocity U (cm, cm/s),
the angular momentum L and ω = L / I (program convention, docs/model.md §4),
the node offsets ``off`` (8, 3), the contact forces ``F`` (8, 3) and normal
forces ``P`` (8,) of the last force evaluation with the node velocities
``uk`` (8, 3) and heights ``z`` (8,) they were computed from, and what a
scheme keeps from one step to the next:

``R``, ``rot_h``, ``rot_ok``
    the cached program rotation (docs/model.md §5.2) for the step ``rot_h``
    (-1: none), and whether it turns at all (ω ≠ 0);
``h_next``
    contact-adaptive's proposed sub-step, s (0: none yet);
``sub_*``, ``new_*``, ``stage_off``, ``stage4_*``
    the work area of the RK4 schemes: the state at the start of a sub-step
    and at its end, the offsets of an RK4 stage and the derivatives of
    stage 4 (for the embedded error estimate).
``rk_k``, ``rk_y``, ``rk_y0``, ``rk_acc``
    the work area of the embedded Runge–Kutta pairs (``methods.erk``):
    stage derivatives, stage point, sub-step start of y = (X, U, L, q) and
    a weighted sum of stages.
``ahead``, ``fr_*``, ``dn_*``
    a scheme with dense output (``contact-tsit5``) lets its last sub-step
    of a step run past the step's end: ``ahead`` is how far the integration
    front (kept in ``sub_*``) lies beyond the state (s; 0: the front is the
    state), ``fr_*`` what the front's next sub-step starts from (whether a
    node is below the ground there, the force sum and torque, the friction
    law's stiffness), ``dn_*`` what the state at a step end inside the last
    sub-step is interpolated from with the stages in ``rk_k``, ``rk_y0``
    (the sub-step's starting offsets and length, and scratch weights).
``substeps``
    the sub-steps of a contact scheme in this throw, by what ended them
    (:data:`SUBSTEP_CAUSES`); zero for the other schemes.
``tol_weight``, ``tol_h``, ``tol_decay``
    an error-controlled scheme with ``tol_growth`` > 0: exp(−tol_growth·t)
    at the start of the next step (t its time in the throw, 1 at the
    start), kept as a product of exp(−tol_growth·h) per step of length h
    (``tol_decay``, computed again when the step's length ``tol_h``
    changes): one multiplication a step instead of an exponential.
``ev_step``, ``ev_n``, ``ev_last``, ``ev_roots``
    exact contact events (an events loop, ``loop.make_roll(events=True)``):
    the index n of the step being taken (it starts at n·h, the time of the
    state), the events recorded so far (more than the buffer holds: it is
    full), the contact set of the last one (``contacts.note_event``) and
    the crossings of each node's height inside a sub-step (scratch of
    ``contacts.note_substep_events``; in the record, so that a GPU thread
    has it too).
``lazy``
    set by a run loop that reads neither the forces nor the node
    velocities at a step's end (a summary loop with the ``rigid`` stop-test
    energy): a scheme whose step ends on an interpolated state
    (``contact-tsit5``) then computes only the node heights there.

A record costs no reference counting when it crosses a call (numba passes
a pointer; its fields are views without a reference count), unlike the
dozen separate arrays it replaces.  Kernels take the record as ``st``;
loops take a (1,) ``STATE`` array and index it, so that its owner is alive
for the whole call.
"""

from __future__ import annotations

import math

import numpy as np

from dicetrace.core._jit import jit
from dicetrace.core.contacts import record_set
from dicetrace.params import TOL_LOOSEST
from dicetrace.status import Status

_F8 = np.float64

#: What ended each sub-step of a contact scheme (``contact_driver.make_drive``),
#: counted per throw in ``STATE.substeps`` in this order: accepted sub-steps
#: whose length the error controller chose ("error"), that ran at the
#: longest sub-step dt / substeps ("cap"), that the friction law's stability
#: bound shortened ("friction"), that ended at the end of the macro step
#: ("end") or where a node enters or leaves the ground ("cut"); then the
#: attempts the error control rejected ("rejected") and those computed again,
#: shorter, because a node crossed the ground inside them ("redone").
SUBSTEP_CAUSES = ("error", "cap", "friction", "end", "cut", "rejected", "redone")
SUBSTEP_CAUSES_N = len(SUBSTEP_CAUSES)

STATE = np.dtype(
    [
        ("X", _F8, 3),
        ("U", _F8, 3),
        ("L", _F8, 3),
        ("W", _F8, 3),
        ("off", _F8, (8, 3)),
        ("F", _F8, (8, 3)),
        ("uk", _F8, (8, 3)),
        ("z", _F8, 8),
        ("P", _F8, 8),
        ("R", _F8, 9),
        ("rot_h", _F8),
        ("rot_ok", np.bool_),
        ("h_next", _F8),
        ("sub_X", _F8, 3),
        ("sub_U", _F8, 3),
        ("sub_L", _F8, 3),
        ("sub_off", _F8, (8, 3)),
        ("new_X", _F8, 3),
        ("new_U", _F8, 3),
        ("new_L", _F8, 3),
        ("new_off", _F8, (8, 3)),
        ("stage_off", _F8, (8, 3)),
        ("stage4_u", _F8, 3),
        ("stage4_a", _F8, 3),
        ("stage4_t", _F8, 3),
        ("rk_k", _F8, (13, 13)),
        ("rk_y", _F8, 13),
        ("rk_y0", _F8, 13),
        ("rk_acc", _F8, 13),
        ("ahead", _F8),
        ("fr_below", np.bool_),
        ("fr_wrench", _F8, 6),
        ("fr_lam", _F8),
        ("dn_off", _F8, (8, 3)),
        ("dn_h", _F8),
        ("dn_w", _F8, 7),
        ("substeps", np.int64, SUBSTEP_CAUSES_N),
        ("tol_weight", _F8),
        ("tol_h", _F8),
        ("tol_decay", _F8),
        ("ev_step", np.int64),
        ("ev_n", np.int64),
        ("ev_last", np.int64),
        ("ev_roots", _F8, (8, 3)),
        ("lazy", np.bool_),
    ],
    align=True,
)


def new_states(n: int = 1) -> np.ndarray:
    """``n`` state records (the scratch that a loop or a batch block owns): zeros, and a throw's start
    tolerance weight (``init_state`` sets everything a throw reads)."""
    S = np.zeros(n, dtype=STATE)
    S["tol_weight"] = 1.0
    S["tol_h"] = -1.0
    S["tol_decay"] = 1.0
    return S


@jit(inline="always")
def copy_motion(X, U, L, off, X_to, U_to, L_to, off_to):
    """Copy a motion (X, U, L and the offsets) from one part of the state record to another."""
    for j in range(3):
        X_to[j] = X[j]
        U_to[j] = U[j]
        L_to[j] = L[j]
    for k in range(8):
        for j in range(3):
            off_to[k, j] = off[k, j]


@jit(inline="always")
def age_tolerance(st, kp, h, steps):
    """Age the tolerance weight by ``steps`` steps of length h; returns the weight of the first.

    With ``kp.tol_growth`` > 0 an error-controlled step that starts at time t
    weighs its error estimates by exp(−tol_growth·t), never below kp.tol /
    ``TOL_LOOSEST`` (the loosest tolerance); 1 with tol_growth = 0.  The
    weight is a product of one ``tol_decay`` per step (see ``STATE``).
    """
    grade = 1.0
    if kp.tol_growth > 0.0:
        grade = max(st.tol_weight, min(1.0, kp.tol / TOL_LOOSEST))
        if h != st.tol_h:
            st.tol_h = h
            st.tol_decay = math.exp(-kp.tol_growth * h)
        for _ in range(steps):
            st.tol_weight *= st.tol_decay
    return grade


@jit(inline="always")
def start_nodes(off0, Xz, off, F, uk, z, P):
    """Offsets ``off0``, zero forces and node velocities, heights for the CM height Xz."""
    for k in range(8):
        for j in range(3):
            off[k, j] = off0[k, j]
            F[k, j] = 0.0
            uk[k, j] = 0.0
        z[k] = Xz + off[k, 2]
        P[k] = 0.0


@jit
def init_state(st, ic, off0, kp):
    """The program's start (docs/model.md §5.1): CM at (0, 0, z0), U and L from ``ic``,
    offsets ``off0``, zero forces and node velocities, heights, no cached rotation."""
    st.X[0] = 0.0
    st.X[1] = 0.0
    st.X[2] = kp.z0_cm
    for j in range(3):
        st.U[j] = ic[j]
        st.L[j] = ic[3 + j]
        st.W[j] = st.L[j] / kp.inertia
    start_nodes(off0, st.X[2], st.off, st.F, st.uk, st.z, st.P)
    st.rot_h = -1.0
    st.rot_ok = False
    st.h_next = 0.0
    st.ahead = 0.0
    st.tol_weight = 1.0
    st.tol_h = -1.0
    st.tol_decay = 1.0
    st.lazy = False
    st.ev_step = 0
    st.ev_n = 0
    st.ev_last = 0
    for j in range(SUBSTEP_CAUSES_N):
        st.substeps[j] = 0


@jit(inline="always")
def set_angular_momentum(st, l0, l1, l2, kp):
    """L ← (l0, l1, l2) and ω = L / I; the cached rotation (for the old ω) is dropped."""
    st.L[0] = l0
    st.L[1] = l1
    st.L[2] = l2
    st.W[0] = l0 / kp.inertia
    st.W[1] = l1 / kp.inertia
    st.W[2] = l2 / kp.inertia
    st.rot_h = -1.0


@jit(inline="always")
def state_finite(Xz, U0, U1, U2, L0, L1, L2, x1x, x8z):
    """The run loop's non-finite test (docs/model.md §10): X_z + ΣU and ΣL + x_1,x + x_8,z are finite."""
    return math.isfinite(Xz + U0 + U1 + U2) and math.isfinite(L0 + L1 + L2 + x1x + x8z)


@jit(inline="always")
def after_step(finite, n, mask, last_mask, sets, set_steps, nsets):
    """The checks that end a run after step n (docs/model.md §10, §8), shared by the run loop and ``core.fast``.

    ``finite``: :func:`state_finite` of the new state.  Records the contact
    set ``mask`` (``contacts.record_set``).  Returns (ended, status, nsets,
    last_mask): ``ended`` with NON_FINITE or BUFFER_FULL; otherwise status is
    TIME_CAP, how a run that goes on to the cap ends.
    """
    if not finite:
        return True, Status.NON_FINITE, nsets, last_mask
    nsets, last_mask, ok = record_set(n, mask, last_mask, sets, set_steps, nsets)
    if not ok:
        return True, Status.BUFFER_FULL, nsets, last_mask
    return False, Status.TIME_CAP, nsets, last_mask


@jit(inline="always")
def begin_substeps(st):
    """Copy the state into the sub-step start (``st.sub_*``)."""
    copy_motion(st.X, st.U, st.L, st.off, st.sub_X, st.sub_U, st.sub_L, st.sub_off)


@jit(inline="always")
def accept_substep(st, kp):
    """The sub-step's result (``st.new_*``) becomes the sub-step start; ω follows L."""
    copy_motion(st.new_X, st.new_U, st.new_L, st.new_off, st.sub_X, st.sub_U, st.sub_L, st.sub_off)
    for j in range(3):
        st.W[j] = st.sub_L[j] / kp.inertia


@jit(inline="always")
def end_substeps(st, kp):
    """Copy the sub-step start back into the state (ω follows L; the cached rotation is dropped)."""
    copy_motion(st.sub_X, st.sub_U, st.sub_L, st.sub_off, st.X, st.U, st.L, st.off)
    set_angular_momentum(st, st.L[0], st.L[1], st.L[2], kp)
