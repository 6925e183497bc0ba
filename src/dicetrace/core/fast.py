"""The specialised summary kernel of the `seed` preset: semi-implicit Euler, point-mass stop test.

``roll_summary_sie`` computes exactly what the run loop (``core.loop``)
computes on its summary path for the 2019 program's integrator
(``schemes.semi_implicit_euler``) and stop-test energy, bit for bit: same
status, steps, outcome and contact-set sequence for every IC.  The run loop
hands it the summaries of every configuration it :func:`applies` to (the
``seed`` preset and any preset with the point-mass stop-test energy);
``tests/core/test_kernel_speed_equivalence.py`` holds it to the general
loop and to a frozen golden set.

It is a different algorithm over the same model: the forces
(``forces.contact_forces``), the program's rotation (``rotation``), the
energies, the face lookup (``model``) and the contact-set record
(``contacts``) are the shared kernels, inlined.  What is specialised
(every item keeps the arithmetic operation for operation, docs/model.md
§5.5):

* **Mirror symmetry.**  Node 8−k is node k+1 reflected through the centre
  (``off[7-k] == -off[k]`` at the start), and every operation that moves an
  offset is odd: ``(x0·R0j + x1·R1j) + x2·R2j`` with x negated is exactly the
  negated result, because IEEE negation is exact and round-to-nearest is
  symmetric.  So ``off[7-k] == -off[k]`` holds bitwise for ever, and only
  nodes 1..4 are rotated; the others are copied negated.  Node velocities
  follow as ``U − (x_k × ω)`` for node 8−k: equal to ``U + (x_{7-k} × ω)``
  bit for bit as long as no component of U is −0 (a zero cross product may
  differ in its sign, which only a −0 in U would show), and U carries no −0
  after the first step (every step adds +0 or more to it).
* **Free flight in registers.**  While no node is at or below the ground the
  forces are exactly zero, so a step is: U_z += g·h (the program's
  ``(0 + 8g)/8·h``), X += U·h, rotate by the cached R.  A run of such steps
  keeps the state in local scalars; the lowest node is ``X_z − max|x_kz|``
  exactly (rounding is monotonic), so contact is detected without building
  all eight heights.
* **The stop test in flight** is bounded below by ½(8|U|² + 16·a²|ω|²) +
  8|g|·X_z − E_rest (exact kinetic sum of a rigid cube, see the run loop)
  with a relative margin 1e-7, and the exact 24-term energy is evaluated
  only when that bound is within the margin of the threshold.  The bound
  falls by exactly 4(g·h)² per flight step, so after one evaluation the next
  ones are skipped for as many steps as half its slack allows
  (``_flight_countdown``).  A conservative bound cannot change a decision.
* **Provably silent checks are skipped.**  A flight run whose magnitudes are
  below 1e100 with an orthonormal R cannot overflow before the time cap, so
  the loop's non-finite test would pass at every step; and no node can reach
  the ground while X_z exceeds the offsets' length (``r_safe``).
* **Sparse contact sums.**  Nodes outside the live mask of
  ``forces.contact_forces`` carry an exact zero force (±0), and adding a
  signed zero changes a sequential sum only when every term is zero — so the
  force and torque sums run over the live nodes, and a torque component
  that comes out zero is recomputed over all eight nodes.
* **Its own scratch.**  The node arrays are fresh allocations (five per
  throw, ~1 % of a throw's cost) on the CPU and local arrays on the GPU,
  not views into the run loop's state record: the compiler then knows they
  do not alias, which measured 15–20 % faster here.  The kernel itself,
  :func:`roll_summary_sie_in`, takes them as arguments.

Every claim above is a statement about IEEE-754 double arithmetic with
round-to-nearest and no fused multiply-add (``_jit`` sets no fast-math).
"""

from __future__ import annotations

import math

import numpy as np

from dicetrace.core._jit import jit
from dicetrace.core.contacts import record_set
from dicetrace.core.forces import ALL_NODES, contact_forces, sum_wrench
from dicetrace.core.model import (
    energy_dynamic,
    energy_stop,
    face_up,
    node_heights,
    offset_cross_omega,
    program_kick_drift,
)
from dicetrace.core.rotation import program_rotation, turn
from dicetrace.core.state import after_step, start_nodes, state_finite
from dicetrace.params import ENERGY_POINT_MASS
from dicetrace.status import Status

#: Relative margin of the free-flight stop-test bound (the bound's own
#: rounding is ~1e-15 relative; the rigid-body drift of the offsets after
#: 10⁶ steps ~1e-10).
FLIGHT_BOUND_REL = 1e-7
FLIGHT_BOUND_ABS = 1e-6
#: Magnitude below which a free-flight run cannot overflow (see roll_summary_sie).
TAME = 1e100
#: Flight steps at most between two evaluations of the stop-test bound.
COUNTDOWN_MAX = 4096


@jit(inline="always")
def _orthonormality_defect(R):
    """max |RᵀR − I| over the entries of the 9-tuple R (inf for a non-finite R)."""
    R00, R01, R02, R10, R11, R12, R20, R21, R22 = R
    d = abs(R00 * R00 + R10 * R10 + R20 * R20 - 1.0)
    d = max(d, abs(R01 * R01 + R11 * R11 + R21 * R21 - 1.0))
    d = max(d, abs(R02 * R02 + R12 * R12 + R22 * R22 - 1.0))
    d = max(d, abs(R00 * R01 + R10 * R11 + R20 * R21))
    d = max(d, abs(R00 * R02 + R10 * R12 + R20 * R22))
    d = max(d, abs(R01 * R02 + R11 * R12 + R21 * R22))
    if not math.isfinite(d):
        return math.inf
    return d + 1e-15  # the rounding of this very evaluation


@jit(inline="always")
def _flight_countdown(slack, scale, U2, duz, mg, h):
    """Flight steps after this one whose stop-test bound is surely still above threshold.

    In free flight the bound ½(8|U|² + 16a²|ω|²) + 8|g|·X_z decreases by exactly
    4(g·h)² per step in exact arithmetic; per step add the rounding of the U_z
    and X_z updates (1e-12 of the energy scale, ~100× the real figure) and the
    growth of the bound's own margin (1e-7·8|g|·|ΔX_z|), and use only half of
    the slack.
    """
    d = 4.0 * duz * duz * (1.0 + 1e-9) + 1e-12 * scale + FLIGHT_BOUND_REL * mg * 8.0 * abs(h) * (
        abs(U2) + COUNTDOWN_MAX * abs(duz)
    ) + 1e-9
    j = (slack - 1e-12 * scale) / (2.0 * d)
    if not (j >= 1.0):
        return 0
    if j >= COUNTDOWN_MAX:
        return COUNTDOWN_MAX
    return int(j)


@jit
def mirror_symmetric(off0):
    """Whether node 8−k is node k+1 negated, bitwise (the fast kernel's premise)."""
    for k in range(4):
        for j in range(3):
            if off0[7 - k, j] != -off0[k, j]:
                return False
    return True


@jit
def applies(kp, off0):
    """Whether ``roll_summary_sie`` computes this configuration's summaries.

    It covers the 2019 program's integrator (the scheme that names it) with
    the point-mass stop-test energy, either friction law and either
    normal-force rule (the ``seed`` preset and its parameter variations),
    from mirror-symmetric initial offsets (any start built as ±half·R is).
    """
    return kp.energy_mode == ENERGY_POINT_MASS and mirror_symmetric(off0)


@jit(inline="always")
def _sq3(x):
    return x[0] * x[0] + x[1] * x[1] + x[2] * x[2]


@jit(inline="always")
def _put_mirrored(off, k, x):
    """Node k+1's offset x, and node 8−k's −x."""
    off[k, 0] = x[0]
    off[k, 1] = x[1]
    off[k, 2] = x[2]
    off[7 - k, 0] = -x[0]
    off[7 - k, 1] = -x[1]
    off[7 - k, 2] = -x[2]


@jit(inline="always")
def _mirror_velocities(off, U0, U1, U2, W0, W1, W2, uk):
    """u_k = U + x_k × ω from nodes 1..4; node 8−k gets U − (x_k × ω), bitwise the same."""
    for k in range(4):
        c0, c1, c2 = offset_cross_omega(off[k, 0], off[k, 1], off[k, 2], W0, W1, W2)
        uk[k, 0] = U0 + c0
        uk[k, 1] = U1 + c1
        uk[k, 2] = U2 + c2
        uk[7 - k, 0] = U0 - c0
        uk[7 - k, 1] = U1 - c1
        uk[7 - k, 2] = U2 - c2


@jit(inline="always")
def forces_mirror(Xz, U0, U1, U2, W0, W1, W2, off, kp, F, uk, z, P):
    """``forces.forces_at`` for mirror-symmetric offsets (velocities of nodes 1..4 mirrored)."""
    below, mask = node_heights(Xz, off, z)
    if not below:
        return below, mask, 0
    _mirror_velocities(off, U0, U1, U2, W0, W1, W2, uk)
    return below, mask, contact_forces(z, uk, kp, F, P)


@jit(inline="always")
def _flight_tame(left, tau, X0, X1, X2, U0, U1, U2, lsum, r2, h, duz_free):
    """Whether a run of at most ``left`` flight steps is "tame", and how high the centre must be for no node to
    reach the ground: (tame, r_safe).

    Tame: the magnitudes cannot reach overflow within ``left`` steps, so the
    loop's non-finite test passes at every step and is skipped; and the
    lowest node is at most r_safe below the centre (offsets keep their
    length, at most √``r2``, up to the rounding of an orthonormal R), so
    heights are examined only when X_z <= r_safe (r_safe infinite for a run
    that is not tame).  ``tau``: the orthonormality defect of the rotation
    a step applies (:func:`_orthonormality_defect`; 0 for none); ``lsum``:
    L0 + L1 + L2.
    """
    drift = left * (1.5 * tau + 4.5e-16)
    tame = (
        drift < 0.25
        and max(max(abs(X0), abs(X1)), abs(X2)) < TAME
        and max(max(abs(U0), abs(U1)), abs(U2)) < TAME
        and max(abs(lsum), r2) < TAME
        and abs(h) < TAME
        and abs(duz_free) < TAME
    )
    r_safe = math.sqrt(r2) * (1.0 + 2.0 * drift + 1e-12) if tame else math.inf
    return tame, r_safe


@jit(inline="always")
def _flight_slack(u2sum, krot, X2, mg, e_rest, e_stop):
    """How far the stop-test bound of a flight step clears the threshold, and the energy scale: (slack, scale).

    The bound (see the module docstring) is within its margin of the
    threshold where ``slack`` is not positive (the general tail then
    evaluates the exact energy).  ``u2sum``: |U|² (its horizontal part as
    at the run's start); ``krot``: 16·half²·|ω|²; ``mg``: −g.
    """
    ke = 8.0 * u2sum + krot
    ep = 0.5 * ke + mg * (8.0 * X2)
    scale = ep + abs(mg * 8.0 * X2) + e_rest
    return ((ep - e_rest) - (FLIGHT_BOUND_REL * scale + FLIGHT_BOUND_ABS)) - e_stop, scale


@jit(inline="always")
def _flight_run(n, maxn, X0, X1, X2, U0, U1, U2, L0, L1, L2, W0, W1, W2, rot_ok, R, off, kp, du_free, duz_free,
                sets, set_steps, nsets, last_mask):
    """A run of force-free steps in registers, from step n, while no node is at or below the ground.

    The free-flight part of :func:`roll_summary_sie_in` (see the module
    docstring): steps until a node reaches the ground, the stop-test bound
    comes near the threshold (the general tail then takes that step), or the
    run ends (step ``maxn``: the time cap or the end of the slice, a
    non-finite state, a full buffer: ``done``).  Moves the
    state and the offsets (written back to ``off``, mirror nodes negated)
    and records the contact sets.  Returns (n, X, U, nsets, last_mask,
    status, done); ``status`` says why a ``done`` run ended (TIME_CAP at the
    cap).
    """
    h = kp.dt_s
    mg = -kp.g
    e_stop = kp.e_stop
    e_rest = kp.e_rest
    half2 = kp.half_side_cm * kp.half_side_cm
    status = Status.TIME_CAP
    # nodes 1..4 (the others are their negatives)
    o00 = off[0, 0]
    o01 = off[0, 1]
    o02 = off[0, 2]
    o10 = off[1, 0]
    o11 = off[1, 1]
    o12 = off[1, 2]
    o20 = off[2, 0]
    o21 = off[2, 1]
    o22 = off[2, 2]
    o30 = off[3, 0]
    o31 = off[3, 1]
    o32 = off[3, 2]
    # free-flight constants of the stop-test bound (U0, U1, ω fixed)
    lsum = L0 + L1 + L2
    left = maxn - n  # steps this run may take at most
    # U0 += (0+0)/8·h is idempotent when that increment is a zero (h finite):
    # apply it once and step X0, X1 by constant increments.
    xy_const = du_free == 0.0
    if xy_const:
        U0 = U0 + du_free
        U1 = U1 + du_free
    dx0 = U0 * h
    dx1 = U1 * h
    kt_xy = U0 * U0 + U1 * U1
    krot = 16.0 * half2 * (W0 * W0 + W1 * W1 + W2 * W2)
    tau = _orthonormality_defect(R) if rot_ok else 0.0
    r2 = max(
        max(o00 * o00 + o01 * o01 + o02 * o02, o10 * o10 + o11 * o11 + o12 * o12),
        max(o20 * o20 + o21 * o21 + o22 * o22, o30 * o30 + o31 * o31 + o32 * o32),
    )
    tame, r_safe = _flight_tame(left, tau, X0, X1, X2, U0, U1, U2, lsum, r2, h, duz_free)
    countdown = 0  # flight steps whose stop-test bound is implied by an earlier one
    done = False  # the step ended, fully handled here
    while True:
        n += 1
        if xy_const:
            X0 = X0 + dx0
            X1 = X1 + dx1
        else:
            U0 = U0 + du_free
            U1 = U1 + du_free
            X0 = X0 + U0 * h
            X1 = X1 + U1 * h
        U2 = U2 + duz_free
        X2 = X2 + U2 * h
        if rot_ok:
            o00, o01, o02 = turn(o00, o01, o02, R)
            o10, o11, o12 = turn(o10, o11, o12, R)
            o20, o21, o22 = turn(o20, o21, o22, R)
            o30, o31, o32 = turn(o30, o31, o32, R)
        if not (X2 > r_safe):
            # lowest node height, exactly min_k z_k (z of node 8-k is X2 - x_kz)
            zlow = X2 - max(max(abs(o02), abs(o12)), max(abs(o22), abs(o32)))
            if zlow <= 0.0:
                break  # a node at or below the ground: the general tail ends this step
        if not tame:
            # the loop's non-finite check: X_z + ΣU, ΣL + x_1x + x_8z (x_8z = -x_1z)
            if not state_finite(X2, U0, U1, U2, L0, L1, L2, o00, -o02):
                status = Status.NON_FINITE
                done = True
                break
        nsets, last_mask, ok = record_set(n, 0, last_mask, sets, set_steps, nsets)
        if not ok:
            status = Status.BUFFER_FULL
            done = True
            break
        # stop test, bounded below (see the module docstring)
        if countdown > 0:
            countdown -= 1
        else:
            slack, scale = _flight_slack(kt_xy + U2 * U2, krot, X2, mg, e_rest, e_stop)
            if not (slack > 0.0):
                break  # near the threshold: the general tail evaluates it exactly
            countdown = _flight_countdown(slack, scale, U2, duz_free, mg, h)
        if n >= maxn:
            done = True
            break
    # write the offsets back (mirror nodes negated)
    _put_mirrored(off, 0, (o00, o01, o02))
    _put_mirrored(off, 1, (o10, o11, o12))
    _put_mirrored(off, 2, (o20, o21, o22))
    _put_mirrored(off, 3, (o30, o31, o32))
    return n, X0, X1, X2, U0, U1, U2, nsets, last_mask, status, done


@jit
def roll_summary_sie(ic, off0, kp, sets, set_steps, budget):
    """One throw to rest, summary only: semi-implicit Euler, point-mass stop test.

    :func:`roll_summary_sie_in` in node arrays of its own: fresh
    allocations, not the run loop's state record, so that the compiler
    knows they do not alias one another (measured 15-20 % faster than views
    into a record).  Arguments and result as there.
    """
    off = np.empty((8, 3))
    F = np.empty((8, 3))
    uk = np.empty((8, 3))
    z = np.empty(8)
    P = np.empty(8)
    return roll_summary_sie_in(ic, off0, kp, sets, set_steps, budget, off, F, uk, z, P)


@jit(inline="always")
def roll_summary_sie_in(ic, off0, kp, sets, set_steps, budget, off, F, uk, z, P):
    """One throw to rest, summary only: semi-implicit Euler, point-mass stop test, in the given node arrays.

    The one source of the kernel: the CPU's :func:`roll_summary_sie` runs it
    in fresh arrays, the GPU's (``core.gpu``) in per-thread local arrays.

    Arguments and result as the run loop's (``core.loop``), where it applies
    (:func:`applies`: ``off0`` mirror-symmetric bitwise, the point-mass
    stop-test energy); ``off``, ``F``, ``uk`` (8, 3) and ``z``, ``P`` (8,)
    are scratch (overwritten; never views of one another).  A throw not
    ended after ``budget`` steps stops there as ``Status.RUNNING`` and keeps
    nothing: the caller runs it again through the run loop, which can go on
    from a slice (the same throw, bit for bit).
    """
    h = kp.dt_s
    inertia = kp.inertia
    e_stop = kp.e_stop
    e_rest = kp.e_rest

    # --- initial state (the run loop's prologue, ``state.init_state``) ---
    X0 = 0.0
    X1 = 0.0
    X2 = kp.z0_cm
    U0 = ic[0]
    U1 = ic[1]
    U2 = ic[2]
    L0 = ic[3]
    L1 = ic[4]
    L2 = ic[5]
    W0 = L0 / inertia
    W1 = L1 / inertia
    W2 = L2 / inertia
    start_nodes(off0, X2, off, F, uk, z, P)
    e0 = energy_dynamic(U0, U1, U2, W0, W1, W2, L0, L1, L2, z, kp) - e_rest
    e_blow = (1.0 + kp.blowup_rel) * max(e0, 0.0) + kp.blowup_abs

    sets[0] = 0
    set_steps[0] = 0
    nsets = 1
    last_mask = 0

    # Step constants of the program's U update with zero force: (0 + 0)/8·h, (0 + 8g)/8·h.
    du_free = (0.0 + 0.0) / 8.0 * h
    duz_free = (0.0 + kp.g * 8.0) / 8.0 * h

    rot_ok, R = program_rotation(W0, W1, W2, h)

    maxn = int(kp.max_steps)
    lim = min(maxn, budget)
    status = Status.TIME_CAP
    n = 0
    live = ALL_NODES  # nodes whose force may be non-zero at the last force evaluation
    contact = False  # forces are zero before the first step (program)
    while n < lim:
        if not contact:
            # ---------------- free flight: a run of force-free steps in registers ----------------
            n, X0, X1, X2, U0, U1, U2, nsets, last_mask, status, done = _flight_run(
                n, lim, X0, X1, X2, U0, U1, U2, L0, L1, L2, W0, W1, W2, rot_ok, R, off, kp, du_free, duz_free,
                sets, set_steps, nsets, last_mask)
            if done:
                break
        else:
            # ---------------- a step with contact forces ----------------
            n += 1
            # Σ F and τ = Σ F × x with the old offsets, over the live nodes: equal to the
            # sums over all nodes, except that a zero torque component may differ in the
            # sign of the zero, so it is recomputed over all nodes.
            s0, s1, s2, t0, t1, t2 = sum_wrench(F, off, live, False)
            if live != ALL_NODES and (t0 == 0.0 or t1 == 0.0 or t2 == 0.0):
                t0, t1, t2 = sum_wrench(F, off, ALL_NODES, False)[3:]
            U0, U1, U2, X0, X1, X2 = program_kick_drift(U0, U1, U2, X0, X1, X2, s0, s1, s2, kp, h)
            L0 = L0 + t0 * h
            L1 = L1 + t1 * h
            L2 = L2 + t2 * h
            W0 = L0 / inertia
            W1 = L1 / inertia
            W2 = L2 / inertia
            rot_ok, R = program_rotation(W0, W1, W2, h)
            if rot_ok:
                for k in range(4):
                    _put_mirrored(off, k, turn(off[k, 0], off[k, 1], off[k, 2], R))

        # ---------------- general tail of a step: heights, forces, checks, stop test ----------------
        below, mask, live = forces_mirror(X2, U0, U1, U2, W0, W1, W2, off, kp, F, uk, z, P)
        if not below:
            for k in range(8):
                F[k, 0] = 0.0
                F[k, 1] = 0.0
                F[k, 2] = 0.0
                P[k] = 0.0
        contact = below
        finite = state_finite(X2, U0, U1, U2, L0, L1, L2, off[0, 0], off[7, 2])
        ended, status, nsets, last_mask = after_step(finite, n, mask, last_mask, sets, set_steps, nsets)
        if ended:
            break
        if contact:
            if energy_dynamic(U0, U1, U2, W0, W1, W2, L0, L1, L2, z, kp) - e_rest > e_blow:
                status = Status.BLOW_UP
                break
        else:
            # free flight ending at (or near) the ground: the exact energy needs u_k
            _mirror_velocities(off, U0, U1, U2, W0, W1, W2, uk)
        e = energy_stop(uk, z, P, kp)
        if not math.isfinite(e):
            status = Status.NON_FINITE
            break
        if e <= e_stop:
            status = Status.SETTLED
            break
    if status == Status.TIME_CAP and n < maxn:  # stopped at the budget
        return Status.RUNNING, n, -1, nsets
    # the heights are current: the tail ran this step
    outcome = face_up(z) if status == Status.SETTLED else -1
    return status, n, outcome, nsets
