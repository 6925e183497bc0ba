"""One step of each integrator.

Every step function has the same contract: on entry ``F``, ``P`` hold the
contact forces at the current state (``contact`` says whether any is
non-zero); on exit the state (X, U, L, W, off) has advanced by ``h`` and
``z``, ``F``, ``P`` (and ``uk`` where contact was found) are evaluated at the
new state.  Rotations are exact (Rodrigues), so the offsets stay rigid.
``R`` (3, 3) and ``Rh`` (3,) are per-throw scratch a scheme may keep between
calls: ``Rh[0]``, ``Rh[1]`` cache the free-flight rotation, ``Rh[2]`` is
contact-adaptive's proposed sub-step (start every throw at -1, 0, 0).

Returns ``(contact, mask)``: whether any node is strictly below the ground
(non-zero forces) and the bitmask of nodes at or below it.
"""

from __future__ import annotations

from dicetrace.core._jit import jit
from dicetrace.core.model import (
    apply_rotation,
    contact_forces,
    node_heights,
    node_velocities,
    rotation_matrix,
)
from dicetrace.core.schemes import step_scheme
from dicetrace.params import INTEGRATORS

# Kernel ids, read from the one integrator table (dicetrace.params.INTEGRATORS).
SEMI_IMPLICIT_EULER = INTEGRATORS["semi-implicit-euler"].kernel_id
FORWARD_EULER = INTEGRATORS["forward-euler"].kernel_id
VERLET = INTEGRATORS["verlet"].kernel_id
RK4 = INTEGRATORS["rk4"].kernel_id
CONTACT_SUBSTEP = INTEGRATORS["contact-substep"].kernel_id
CONTACT_ADAPTIVE = INTEGRATORS["contact-adaptive"].kernel_id  # the same step with error-controlled sub-steps (kp.tol > 0)


@jit
def eval_forces(X, U, W, off, kp, F, uk, z, P):
    """Heights, and forces where a node is below ground (else F = 0)."""
    below, mask = node_heights(X[2], off, z)
    if below:
        node_velocities(U, off, W[0], W[1], W[2], uk)
        contact_forces(z, uk, kp, F, P)
    else:
        for k in range(8):
            F[k, 0] = 0.0
            F[k, 1] = 0.0
            F[k, 2] = 0.0
            P[k] = 0.0
    return below, mask


@jit
def sum_forces(F):
    """Σ_k F_k, sequential node 1 → 8."""
    s0 = F[0, 0]
    s1 = F[0, 1]
    s2 = F[0, 2]
    for k in range(1, 8):
        s0 += F[k, 0]
        s1 += F[k, 1]
        s2 += F[k, 2]
    return s0, s1, s2


@jit
def sum_torques(F, off):
    """τ = Σ_k F_k × x_k (program convention), sequential node 1 → 8."""
    t0 = 0.0
    t1 = 0.0
    t2 = 0.0
    for k in range(8):
        f0 = F[k, 0]
        f1 = F[k, 1]
        f2 = F[k, 2]
        x0 = off[k, 0]
        x1 = off[k, 1]
        x2 = off[k, 2]
        c0 = f1 * x2 - f2 * x1
        c1 = f2 * x0 - f0 * x2
        c2 = f0 * x1 - f1 * x0
        if k == 0:
            t0 = c0
            t1 = c1
            t2 = c2
        else:
            t0 += c0
            t1 += c1
            t2 += c2
    return t0, t1, t2


@jit
def step_semi_implicit(X, U, L, W, off, F, uk, z, P, R, Rh, kp, h, contact):
    """The 2019 program's step (semi-implicit Euler), bit-faithful.

    U ← U + (ΣF + 8g)/8·h; X ← X + U·h; L ← L + τ·h; ω = L/I; rotate the
    offsets by the exact rotation for ω·h; evaluate forces.  While no node
    touched the ground the forces are exactly zero, so L, ω and R are reused
    (``Rh[0]`` caches the step R was built for; ``Rh[1]`` is 1 when ω ≠ 0).
    """
    if contact:
        s0, s1, s2 = sum_forces(F)
    else:
        s0 = 0.0
        s1 = 0.0
        s2 = 0.0
    g8 = kp.g * 8.0
    U[0] = U[0] + (s0 + 0.0) / 8.0 * h
    U[1] = U[1] + (s1 + 0.0) / 8.0 * h
    U[2] = U[2] + (s2 + g8) / 8.0 * h
    X[0] = X[0] + U[0] * h
    X[1] = X[1] + U[1] * h
    X[2] = X[2] + U[2] * h
    if contact:
        t0, t1, t2 = sum_torques(F, off)
        L[0] = L[0] + t0 * h
        L[1] = L[1] + t1 * h
        L[2] = L[2] + t2 * h
        W[0] = L[0] / kp.inertia
        W[1] = L[1] / kp.inertia
        W[2] = L[2] / kp.inertia
        Rh[0] = -1.0
    if Rh[0] != h:
        Rh[1] = 1.0 if rotation_matrix(W[0], W[1], W[2], h, R) else 0.0
        Rh[0] = h
    if Rh[1] != 0.0:
        apply_rotation(off, R)
    return eval_forces(X, U, W, off, kp, F, uk, z, P)


@jit
def step_forward_euler(X, U, L, W, off, F, uk, z, P, R, Rh, kp, h, contact):
    """Textbook forward Euler: every increment from the state at the start.

    X ← X + U·h; U ← U + a·h; offsets rotated exactly by the old ω·h;
    L ← L + τ·h.  Unstable on the contact spring (energy grows each contact).
    """
    if contact:
        s0, s1, s2 = sum_forces(F)
        t0, t1, t2 = sum_torques(F, off)
    else:
        s0 = 0.0
        s1 = 0.0
        s2 = 0.0
        t0 = 0.0
        t1 = 0.0
        t2 = 0.0
    X[0] = X[0] + U[0] * h
    X[1] = X[1] + U[1] * h
    X[2] = X[2] + U[2] * h
    U[0] = U[0] + s0 / 8.0 * h
    U[1] = U[1] + s1 / 8.0 * h
    U[2] = U[2] + (s2 / 8.0 + kp.g) * h
    if Rh[0] != h:
        Rh[1] = 1.0 if rotation_matrix(W[0], W[1], W[2], h, R) else 0.0
        Rh[0] = h
    if Rh[1] != 0.0:
        apply_rotation(off, R)
    if contact:
        L[0] = L[0] + t0 * h
        L[1] = L[1] + t1 * h
        L[2] = L[2] + t2 * h
        W[0] = L[0] / kp.inertia
        W[1] = L[1] / kp.inertia
        W[2] = L[2] / kp.inertia
        Rh[0] = -1.0
    return eval_forces(X, U, W, off, kp, F, uk, z, P)


@jit
def step(integ, X, U, L, W, off, F, uk, z, P, R, Rh, kp, h, contact):
    """Dispatch one step of integrator ``integ`` (ids in dicetrace.params.INTEGRATORS)."""
    if integ == SEMI_IMPLICIT_EULER:
        return step_semi_implicit(X, U, L, W, off, F, uk, z, P, R, Rh, kp, h, contact)
    elif integ == FORWARD_EULER:
        return step_forward_euler(X, U, L, W, off, F, uk, z, P, R, Rh, kp, h, contact)
    elif integ == VERLET or integ == RK4 or integ == CONTACT_SUBSTEP or integ == CONTACT_ADAPTIVE:
        # out of line (core.schemes): keeps this dispatch small enough for
        # LLVM to inline the program's step into the loop
        return step_scheme(integ, X, U, L, W, off, F, uk, z, P, R, Rh, kp, h, contact)
    # An id outside the table: signal with an impossible mask (the loop reports non_finite).
    return False, -1
