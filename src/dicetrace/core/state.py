"""The state of one throw: a motion record shared by every scheme, and a work record per scheme.

Kernels pass both by reference (numba passes a record as a pointer; its
fields are views without a reference count).  Loops take (1,) arrays of
each and index them, so that their owner is alive for the whole call; a
step is ``step(st, wk, kp, h, contact)`` with ``st`` the motion and ``wk``
the scheme's work record (``core.schemes.Scheme.WORK``).  A GPU thread keeps
both in its local memory, which the hardware interleaves across a warp: a
thread carries only what its scheme uses.

``MOTION`` (docs/model.md §5.1): the centre of mass X and its velocity U
(cm, cm/s), the angular momentum L and ω = L / I (program convention,
docs/model.md §4), the node offsets ``off`` (8, 3), the contact forces ``F``
(8, 3) and normal forces ``P`` (8,) of the last force evaluation with the
node velocities ``uk`` (8, 3) and heights ``z`` (8,) they were computed
from, and what a step keeps for the next one:

``R``, ``rot_h``, ``rot_ok``
    the cached program rotation (docs/model.md §5.2) for the step ``rot_h``
    (-1: none), and whether it turns at all (ω ≠ 0);
``h_next``
    the contact driver's proposed sub-step, s (0: none yet; its controller's state);
``ahead``
    how far a dense-output scheme's integration front lies beyond the
    state (s; 0: the front is the state; the front itself is in the work
    record);
``substeps``
    the sub-steps of a contact scheme in this throw, by what ended them
    (:data:`SUBSTEP_CAUSES`); zero for the other schemes;
``tol_weight``, ``tol_h``, ``tol_decay``
    an error-controlled scheme with ``tol_growth`` > 0: exp(−tol_growth·t)
    at the start of the next step (t its time in the throw, 1 at the
    start), kept as a product of exp(−tol_growth·h) per step of length h
    (``tol_decay``, computed again when the step's length ``tol_h``
    changes): one multiplication a step instead of an exponential;
``ev_step``, ``ev_n``, ``ev_last``
    exact contact events (an events loop, ``loop.make_roll(events=True)``):
    the index n of the step being taken (it starts at n·h, the time of the
    state), the events recorded so far (more than the buffer holds: it is
    full), the contact set of the last one (``contacts.note_event``);
``lazy``
    set by a run loop that reads neither the forces nor the node
    velocities at a step's end (a summary loop with the ``rigid`` stop-test
    energy): a scheme whose step ends on an interpolated state
    (``contact-tsit5``) then computes only the node heights there;
``run_*``
    the run loop's own variables between two slices of a throw (the steps
    taken, the sets recorded, the last contact set, whether the state is in
    contact, whether its energy clears the stop threshold by far, the
    blow-up bound): a loop that stops after a slice of steps
    (``Status.RUNNING``) goes on from them (``core.loop``).

Work records (:func:`work_dtype` of the parts a scheme uses):

``SUBSTEP_WORK``: ``sub_*``, ``new_*``
    the state at the start of a sub-step and at its end (the RK4 schemes
    and the contact driver);
``DRIVER_WORK``: ``fr_*``, ``dn_h``, ``ev_roots``
    the contact driver's: what a dense-output front's next sub-step starts
    from (whether a node is below the ground there, the force sum and
    torque, the friction law's stiffness), the length of the sub-step the
    front came from, and the crossings of each node's height inside a
    sub-step (scratch of ``contacts.note_substep_events``);
the sub-step methods' own (``core.methods``: RK4's stage offsets and
stage-4 derivatives, the Runge–Kutta pairs' stages and dense output).
"""

from __future__ import annotations

import math

import numpy as np

from dicetrace.core._jit import jit
from dicetrace.core.contacts import record_set
from dicetrace.core.inertia import omega
from dicetrace.params import TOL_LOOSEST
from dicetrace.status import Status

_F8 = np.float64

#: What ended each sub-step of a contact scheme (``contact_driver.make_drive``),
#: counted per throw in ``MOTION.substeps`` in this order: accepted sub-steps
#: whose length the error controller chose ("error"), that ran at the
#: longest sub-step dt / substeps ("cap"), that the friction law's stability
#: bound shortened ("friction"), that ended at the end of the macro step
#: ("end") or where a node enters or leaves the ground ("cut"); then the
#: attempts the error control rejected ("rejected") and those computed again,
#: shorter, because a node crossed the ground inside them ("redone").
SUBSTEP_CAUSES = ("error", "cap", "friction", "end", "cut", "rejected", "redone")
SUBSTEP_CAUSES_N = len(SUBSTEP_CAUSES)

MOTION = np.dtype(
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
        ("h_next", _F8),
        ("ahead", _F8),
        ("tol_weight", _F8),
        ("tol_h", _F8),
        ("tol_decay", _F8),
        ("run_e_blow", _F8),
        ("substeps", np.int64, SUBSTEP_CAUSES_N),
        ("ev_step", np.int64),
        ("ev_n", np.int64),
        ("ev_last", np.int64),
        ("run_n", np.int64),
        ("run_nsets", np.int64),
        ("run_last", np.int64),
        ("rot_ok", np.bool_),
        ("lazy", np.bool_),
        ("run_contact", np.bool_),
        ("run_clear", np.bool_),
    ],
    align=True,
)

#: The sub-step start and end (``begin_substeps``, ``accept_substep``, ``end_substeps``).
SUBSTEP_WORK = [
    ("sub_X", _F8, 3),
    ("sub_U", _F8, 3),
    ("sub_L", _F8, 3),
    ("sub_off", _F8, (8, 3)),
    ("new_X", _F8, 3),
    ("new_U", _F8, 3),
    ("new_L", _F8, 3),
    ("new_off", _F8, (8, 3)),
]
#: The contact driver's own (``core.contact_driver``): a dense-output front, the crossings' scratch.
DRIVER_WORK = [
    ("fr_wrench", _F8, 6),
    ("fr_lam", _F8),
    ("dn_h", _F8),
    ("ev_roots", _F8, (8, 3)),
    ("fr_below", np.bool_),
]


def work_dtype(*parts) -> np.dtype:
    """The aligned work record of the field lists ``parts`` (a scheme's ``WORK``); a one-byte record for none."""
    fields = [f for part in parts for f in part]
    return np.dtype(fields or [("none", np.int8)], align=True)


#: The work record of a scheme that keeps nothing between its stages (the program's step, forward Euler, Verlet).
NO_WORK = work_dtype()


def new_states(n: int = 1) -> np.ndarray:
    """``n`` motion records (the scratch a loop or a batch runs in): zeros, and a throw's start tolerance weight
    (``init_state`` sets everything a throw reads)."""
    S = np.zeros(n, dtype=MOTION)
    S["tol_weight"] = 1.0
    S["tol_h"] = -1.0
    S["tol_decay"] = 1.0
    return S


def new_work(work: np.dtype, n: int = 1) -> np.ndarray:
    """``n`` work records of the dtype ``work`` (a scheme's ``WORK``): zeros, scratch that a step writes before it reads."""
    return np.zeros(n, dtype=work)


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
    weight is a product of one ``tol_decay`` per step (see ``MOTION``).  Once
    it is below that floor it only ever gives the floor, and it ages no
    further: a free flight crossed in one piece of 10¹⁰ steps (a die that
    never lands) takes a few hundred multiplications, not 10¹⁰.
    """
    grade = 1.0
    if kp.tol_growth > 0.0:
        floor = min(1.0, kp.tol / TOL_LOOSEST)
        grade = max(st.tol_weight, floor)
        if h != st.tol_h:
            st.tol_h = h
            st.tol_decay = math.exp(-kp.tol_growth * h)
        for _ in range(steps):
            if st.tol_weight < floor:
                break
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
    start_nodes(off0, st.X[2], st.off, st.F, st.uk, st.z, st.P)
    st.W[0], st.W[1], st.W[2] = omega(st.L[0], st.L[1], st.L[2], st.off, kp)
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
    """L ← (l0, l1, l2) and ω = I⁻¹·L at the present offsets (``inertia.omega``; the cube: L / I); the cached
    rotation (for the old ω) is dropped."""
    st.L[0] = l0
    st.L[1] = l1
    st.L[2] = l2
    st.W[0], st.W[1], st.W[2] = omega(l0, l1, l2, st.off, kp)
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
def begin_substeps(st, wk):
    """Copy the state into the sub-step start (``wk.sub_*``)."""
    copy_motion(st.X, st.U, st.L, st.off, wk.sub_X, wk.sub_U, wk.sub_L, wk.sub_off)


@jit(inline="always")
def accept_substep(st, wk, kp):
    """The sub-step's result (``wk.new_*``) becomes the sub-step start; ω follows L."""
    copy_motion(wk.new_X, wk.new_U, wk.new_L, wk.new_off, wk.sub_X, wk.sub_U, wk.sub_L, wk.sub_off)
    st.W[0], st.W[1], st.W[2] = omega(wk.sub_L[0], wk.sub_L[1], wk.sub_L[2], wk.sub_off, kp)


@jit(inline="always")
def end_substeps(st, wk, kp):
    """Copy the sub-step start back into the state (ω follows L; the cached rotation is dropped)."""
    copy_motion(wk.sub_X, wk.sub_U, wk.sub_L, wk.sub_off, st.X, st.U, st.L, st.off)
    set_angular_momentum(st, st.L[0], st.L[1], st.L[2], kp)
