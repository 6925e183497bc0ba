"""The ground force law (docs/model.md §4), written once, and the force sums.

Every kernel path evaluates the contact forces through :func:`contact_forces`
(normal force with damping, the clamp of the ``physical`` preset, and
either friction law): the program's step (``schemes.semi_implicit_euler``
and its specialised kernel ``core.fast``), the RK4 stages and the end of
every step (:func:`forces_at`).  All of them are ``inline="always"``: they
run several times per step, and numba inlines them at the IR level.

Arithmetic order (docs/model.md §5.5): P_k = k·d_k·(1 − γ·u_z,k) with
d_k = max(0, −z_k); spectral friction F_xy = −μ·(P_k·(u_xy,k/σ)); per-node
friction F_xy = −μ·P_k·u_xy,k / sqrt(|u_xy,k|² + v_reg²).
"""

from __future__ import annotations

import math

from dicetrace.core._jit import jit
from dicetrace.core.contacts import contact_mask
from dicetrace.core.model import node_heights, node_velocities
from dicetrace.params import FRICTION_SPECTRAL

#: Bitmask of all eight nodes.
ALL_NODES = 0xFF


@jit(inline="always")
def normal_force(zk, uz, kp):
    """P = k·d·(1 − γ·u_z), d = max(0, −z): signed (the program) or clamped at 0 (``kp.clamp_normal``)."""
    d = max(0.0, -zk)
    p = kp.k * d * (1.0 - kp.gamma * uz)
    if kp.clamp_normal and p < 0.0:
        p = 0.0
    return p


@jit(inline="always")
def spectral_norm_xy(uk):
    """Largest singular value σ of the 8×2 matrix of horizontal node velocities.

    Closed form through the 2×2 Gram matrix [[a, b], [b, c]]:
    σ = sqrt((a + c)/2 + sqrt(((a − c)/2)² + b²)), sums node 1 → 8 (the
    program takes it from LAPACK's SVD, a few ulps away: docs/model.md §5.5).
    """
    a = 0.0
    b = 0.0
    c = 0.0
    for k in range(8):
        a += uk[k, 0] * uk[k, 0]
        b += uk[k, 0] * uk[k, 1]
        c += uk[k, 1] * uk[k, 1]
    hd = (a - c) / 2.0
    return math.sqrt((a + c) / 2.0 + math.sqrt(hd * hd + b * b))


@jit(inline="always")
def node_friction(p, u0, u1, kp):
    """The per-node law's friction (F_x, F_y) on a node with normal force p and horizontal velocity u."""
    s = math.sqrt(u0 * u0 + u1 * u1 + kp.v_reg_cm_s * kp.v_reg_cm_s)
    return -kp.mu * p * u0 / s, -kp.mu * p * u1 / s


@jit(inline="always")
def moment(a0, a1, a2, x0, x1, x2):
    """The torque F × x of a force a at the offset x (program convention, docs/model.md §5.5)."""
    return a1 * x2 - a2 * x1, a2 * x0 - a0 * x2, a0 * x1 - a1 * x0


@jit(inline="always")
def friction_forces(uk, kp, F, P):
    """Horizontal friction F_xy from the velocities uk and the normal forces P.

    Returns True when every node with P = ±0 got F_xy = ±0 exactly (always,
    except for the spectral law with a non-finite σ).  Spectral law, σ finite:
    for P = ±0 the product P·(u/σ) is the signed zero P·u (u is finite and
    σ > 0), so the division is skipped, bit for bit.
    """
    mu = kp.mu
    if kp.friction_mode == FRICTION_SPECTRAL:
        sig = spectral_norm_xy(uk)
        if sig == 0.0:
            for k in range(8):
                F[k, 0] = 0.0
                F[k, 1] = 0.0
            return True
        if math.isfinite(sig):
            for k in range(8):
                pk = P[k]
                if pk == 0.0:
                    F[k, 0] = -mu * (pk * uk[k, 0])
                    F[k, 1] = -mu * (pk * uk[k, 1])
                else:
                    F[k, 0] = -mu * (pk * (uk[k, 0] / sig))
                    F[k, 1] = -mu * (pk * (uk[k, 1] / sig))
            return True
        for k in range(8):  # overflowing velocities: the program's arithmetic, NaNs and all
            F[k, 0] = -mu * (P[k] * (uk[k, 0] / sig))
            F[k, 1] = -mu * (P[k] * (uk[k, 1] / sig))
        return False
    for k in range(8):
        if P[k] == 0.0:
            F[k, 0] = 0.0
            F[k, 1] = 0.0
        else:
            F[k, 0], F[k, 1] = node_friction(P[k], uk[k, 0], uk[k, 1], kp)
    return True


@jit(inline="always")
def contact_forces(z, uk, kp, F, P):
    """Ground forces F (8, 3) and normal forces P (8,) on every node from heights z and velocities uk.

    Returns the bitmask of the nodes whose force may be non-zero: those with
    P ≠ 0 (NaN included); every other node's F is an exact ±0.  All nodes
    when friction could not guarantee that (a non-finite σ).
    """
    live = 0
    for k in range(8):
        p = normal_force(z[k], uk[k, 2], kp)
        P[k] = p
        F[k, 2] = p
        if p != 0.0:  # NaN included
            live |= 1 << k
    if not friction_forces(uk, kp, F, P):
        live = ALL_NODES
    return live


@jit(inline="always")
def forces_at(Xz, U0, U1, U2, w0, w1, w2, off, kp, F, uk, z, P):
    """Heights z at a state; when a node is strictly below the ground also uk, P and F.

    Returns (below, mask, live): whether a node is strictly below the ground,
    the bitmask of nodes at or below it, and :func:`contact_forces`' mask
    (0, with F, P and uk untouched, when no node is below).
    """
    below, mask = node_heights(Xz, off, z)
    if not below:
        return below, mask, 0
    node_velocities(U0, U1, U2, w0, w1, w2, off, uk)
    return below, mask, contact_forces(z, uk, kp, F, P)


@jit(inline="always")
def eval_forces(st, kp):
    """z, F, P (and uk in contact) at the state of ``st``: the end of every step.

    Returns (contact, mask): whether any node is strictly below the ground
    (non-zero forces; otherwise F = P = 0) and the bitmask of nodes at or below it.
    """
    below, mask, live = forces_at(
        st.X[2], st.U[0], st.U[1], st.U[2], st.W[0], st.W[1], st.W[2], st.off, kp, st.F, st.uk, st.z, st.P
    )
    if not below:
        clear_forces(st)
    return below, mask


@jit(inline="always")
def clear_forces(st):
    """F = P = 0 on every node (no node below the ground)."""
    for k in range(8):
        st.F[k, 0] = 0.0
        st.F[k, 1] = 0.0
        st.F[k, 2] = 0.0
        st.P[k] = 0.0


@jit(inline="always")
def ended_forces(st, below):
    """What :func:`eval_forces` returns when the scratch already holds the forces at the state.

    ``below``: what :func:`forces_at` found there (when False, F and P are
    zeroed as eval_forces does); z must be the heights at the state.
    """
    if not below:
        clear_forces(st)
    return below, contact_mask(st.z)


@jit(inline="always")
def sum_wrench(F, off, nodes, from_zero):
    """Σ F_k and τ = Σ F_k × x_k (program convention) over the nodes in the bitmask ``nodes``.

    Sequential node 1 → 8.  ``from_zero``: the sums start at 0.0 (the RK4
    schemes); otherwise at the first node's term (the program's order; exact
    zeros of the other nodes then change a sum only in the sign of a zero).
    """
    f0 = 0.0
    f1 = 0.0
    f2 = 0.0
    t0 = 0.0
    t1 = 0.0
    t2 = 0.0
    first = not from_zero
    for k in range(8):
        if not (nodes >> k) & 1:
            continue
        a0 = F[k, 0]
        a1 = F[k, 1]
        a2 = F[k, 2]
        c0, c1, c2 = moment(a0, a1, a2, off[k, 0], off[k, 1], off[k, 2])
        if first:
            f0 = a0
            f1 = a1
            f2 = a2
            t0 = c0
            t1 = c1
            t2 = c2
            first = False
        else:
            f0 += a0
            f1 += a1
            f2 += a2
            t0 += c0
            t1 += c1
            t2 += c2
    return f0, f1, f2, t0, t1, t2


@jit(inline="always")
def acceleration(f0, f1, f2, kp):
    """The centre of mass's acceleration ΣF/8 + g·ẑ (die mass 8) from the force sum."""
    return f0 / 8.0, f1 / 8.0, f2 / 8.0 + kp.g


@jit(inline="always")
def step_wrench(st, contact, from_zero):
    """Σ F_k and τ of the forces in ``st`` (all nodes) when ``contact``, else zeros: a step's start."""
    if contact:
        return sum_wrench(st.F, st.off, ALL_NODES, from_zero)
    return 0.0, 0.0, 0.0, 0.0, 0.0, 0.0


@jit(inline="always")
def wrench_at(Xz, U0, U1, U2, w0, w1, w2, off, kp, F, uk, z, P):
    """Contact force sum and torque at a state (scratch F, uk, z, P), sums from 0.0.

    Returns (below, f0, f1, f2, t0, t1, t2).  Nodes with an exact zero force
    are left out of the sums (adding ±0 to a sum that starts at +0.0 never
    changes it).
    """
    below, mask, live = forces_at(Xz, U0, U1, U2, w0, w1, w2, off, kp, F, uk, z, P)
    if not below:
        return False, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0
    f0, f1, f2, t0, t1, t2 = sum_wrench(F, off, live, True)
    return True, f0, f1, f2, t0, t1, t2
