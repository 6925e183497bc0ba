"""``contact-rosenbrock``: contact-aware sub-stepping with a linearly implicit Rosenbrock–W pair (docs/model.md §9).

The driver of ``contact_substep`` (exact free flight, sub-steps cut where a
node enters or leaves the ground, error control) on sub-steps of ROS34PW2
(Rang & Angermann 2005: four stages, order 3, embedded order 2, L-stable,
stiffly accurate; a W-method, so it keeps order 3 with any approximation W
of the Jacobian).  It is the stiff scheme of the set: each sub-step solves
with I − γ·h·J, J the Jacobian of y' = f(y) at the sub-step start, so the
stiff, dissipative parts of the contact law (the regularised friction law's
μ·P/v_reg, the Hunt–Crossley damping) are damped, not followed: no
stability bound limits its sub-steps (``FRICTION_THETA`` is infinite), only
the error control.

The sub-step's state is that of ``erk``, y = (X, U, L, q) ∈ R¹³ with the
relative rotation q = 1 at the start; stages read R(q/|q|), the accepted
step normalises q and turns the offsets by it (the die stays rigid to
rounding).  J: the rows of X' = U and q' = ½·(0, ω)·q in closed form; the
rows of the force sum and torque by forward differences of the wrench in
X_z, U, L and the vector part of q (ten wrench evaluations; the forces do
not depend on X_x, X_y, nor on |q|).  The stage equations
(Hairer & Wanner, *Solving ODEs II*, IV.7)::

    (I − γhJ)·k_i = h·f(y₀ + Σ_{j<i} α_ij·k_j) + h·J·Σ_{j<i} γ_ij·k_j
    y₁ = y₀ + Σ b_i·k_i        error estimate Σ (b_i − b̂_i)·k_i

The error norm is ``rk4.error_norm`` (contact-adaptive's and DOP853's).
"""

from __future__ import annotations

import math

import numpy as np

from dicetrace.core._jit import jit_fused, specialise
from dicetrace.core.schemes.contact_substep import EXACT_FLIGHT, drive  # noqa: F401 (the driver's free flight)
from dicetrace.core.schemes.erk import (
    NY,
    ZERO,
    combine,
    derivative_row,
    stage_wrench,
    state_error_norm,
    substep_end,
    substep_start,
)
from dicetrace.core.schemes.rk4 import error_speed

#: ROS34PW2 (Rang & Angermann, BIT 45, 2005), in the classical form above.
ROS_STAGES = 4
ROS_GAMMA = 4.3586652150845900e-01
ROS_ALPHA = np.array([
    [0.0, 0.0, 0.0, 0.0],
    [8.7173304301691801e-01, 0.0, 0.0, 0.0],
    [8.4457060015369423e-01, -1.1299064236484185e-01, 0.0, 0.0],
    [0.0, 0.0, 1.0, 0.0],
])
ROS_GAMMAS = np.array([
    [0.0, 0.0, 0.0, 0.0],
    [-8.7173304301691801e-01, 0.0, 0.0, 0.0],
    [-9.0338057013044082e-01, 5.4180672388095326e-02, 0.0, 0.0],
    [2.4212380706095346e-01, -1.2232505839045147e+00, 5.4526025533510214e-01, 0.0],
])
ROS_B = np.array([2.4212380706095346e-01, -1.2232505839045147e+00, 1.5452602553351020e+00, 4.3586652150845900e-01])
ROS_BHAT = np.array([3.7810903145819369e-01, -9.6042292212423178e-02, 0.5, 2.1793326075422950e-01])
#: Weights of the error estimate, b − b̂.
ROS_E = ROS_B - ROS_BHAT
#: Relative size of a forward-difference step (√ of the double's epsilon).
FD_EPS = 1.4901161193847656e-08
#: No stability bound for the friction law (it is in the Jacobian), no limit on λ_f·h.
FRICTION_THETA = math.inf
#: An impact's first sub-step, as ω·h with ω = √k.
H0 = 0.1


@jit_fused
def lu_factor(a, piv):
    """LU factors of the 13×13 matrix ``a`` in place (Doolittle, partial pivoting); row swaps in ``piv``."""
    n = NY
    for c in range(n):
        p = c
        big = abs(a[c, c])
        for r in range(c + 1, n):
            v = abs(a[r, c])
            if v > big:
                big = v
                p = r
        piv[c] = p
        if p != c:
            for j in range(n):
                t = a[c, j]
                a[c, j] = a[p, j]
                a[p, j] = t
        d = a[c, c]
        if d == 0.0:
            continue  # singular: the solve gives non-finite numbers, which the loop reports
        for r in range(c + 1, n):
            m = a[r, c] / d
            if m != 0.0:
                a[r, c] = m
                for j in range(c + 1, n):
                    a[r, j] -= m * a[c, j]
            else:
                a[r, c] = 0.0


@jit_fused
def lu_solve(a, piv, b):
    """Solve (LU)·x = b in place with the factors of :func:`lu_factor`."""
    n = NY
    for c in range(n):
        p = piv[c]
        if p != c:
            t = b[c]
            b[c] = b[p]
            b[p] = t
    for r in range(1, n):
        s = b[r]
        for j in range(r):
            s -= a[r, j] * b[j]
        b[r] = s
    for r in range(n - 1, -1, -1):
        s = b[r]
        for j in range(r + 1, n):
            s -= a[r, j] * b[j]
        b[r] = s / a[r, r]


@jit_fused
def jacobian(st, kp, y0, f0, f1, f2, t0, t1, t2, J):
    """J = ∂f/∂y at the sub-step start y0 (q = 1), f0..t2 the contact force sum and torque there.

    Rows of X' = U and q' = ½·(0, ω)·q (ω = −L/I) in closed form; rows of
    U' = g + ΣF/8 and L' = τ by forward differences in X_z, U, L and the
    vector part of q (R(q/|q|) does not depend on |q|: the q_w column is 0).
    """
    I = kp.inertia
    for r in range(NY):
        for c in range(NY):
            J[r, c] = 0.0
    for j in range(3):
        J[j, 3 + j] = 1.0
    w0 = -y0[6] / I
    w1 = -y0[7] / I
    w2 = -y0[8] / I
    # ∂q'/∂q at q = (1, 0, 0, 0) and ∂q'/∂L = −(1/I)·∂q'/∂ω
    J[9, 10] = -0.5 * w0
    J[9, 11] = -0.5 * w1
    J[9, 12] = -0.5 * w2
    J[10, 9] = 0.5 * w0
    J[10, 11] = -0.5 * w2
    J[10, 12] = 0.5 * w1
    J[11, 9] = 0.5 * w1
    J[11, 10] = 0.5 * w2
    J[11, 12] = -0.5 * w0
    J[12, 9] = 0.5 * w2
    J[12, 10] = -0.5 * w1
    J[12, 11] = 0.5 * w0
    for j in range(3):
        J[10 + j, 6 + j] = -0.5 / I
    vs = error_speed(st.sub_U, st.sub_L, kp)
    y = st.rk_y
    for c in range(2, NY):
        if c == 9:
            continue
        if c == 2:
            scale = kp.half_side_cm
        elif c < 6:
            scale = vs
        elif c < 9:
            scale = I * vs / kp.half_side_cm
        else:
            scale = 1.0
        d = FD_EPS * max(abs(y0[c]), scale)
        for j in range(NY):
            y[j] = y0[j]
        y[c] = y0[c] + d
        d = y[c] - y0[c]  # the step as represented
        g0, g1, g2, q0, q1, q2 = stage_wrench(y, st.sub_off, kp, st.stage_off, st.F, st.uk, st.z, st.P)
        J[3, c] = (g0 - f0) / 8.0 / d
        J[4, c] = (g1 - f1) / 8.0 / d
        J[5, c] = (g2 - f2) / 8.0 / d
        J[6, c] = (q0 - t0) / d
        J[7, c] = (q1 - t1) / d
        J[8, c] = (q2 - t2) / d


@jit_fused
def ros_substep(st, kp, h, f0, f1, f2, t0, t1, t2):
    """One ROS34PW2 step from the sub-step start ``st.sub_*`` to ``st.new_*``.

    ``f*``, ``t*``: contact force sum and torque at the start.  Leaves the
    error estimate Σ (b_i − b̂_i)·k_i in ``st.rk_acc`` for :func:`ros_error`.
    """
    K = st.rk_k  # rows 0..3: the stages k_i; rows 4..7: f at the stage points
    y = st.rk_y
    y0 = st.rk_y0
    J = st.ros_j
    M = st.ros_lu
    piv = st.ros_piv
    b = st.rk_acc
    substep_start(st, y0)
    jacobian(st, kp, y0, f0, f1, f2, t0, t1, t2, J)
    gh = ROS_GAMMA * h
    for r in range(NY):
        for c in range(NY):
            M[r, c] = -gh * J[r, c]
        M[r, r] += 1.0
    lu_factor(M, piv)
    off = st.sub_off
    for i in range(ROS_STAGES):
        # stage point y_i = y0 + Σ_{j<i} α_ij·k_j and f(y_i)
        combine(ROS_ALPHA[i], i, K, y0, 1.0, y)
        if i == 0:
            derivative_row(K, 4, y, f0, f1, f2, t0, t1, t2, kp)
        else:
            g0, g1, g2, q0, q1, q2 = stage_wrench(y, off, kp, st.stage_off, st.F, st.uk, st.z, st.P)
            derivative_row(K, 4 + i, y, g0, g1, g2, q0, q1, q2, kp)
        # b = h·f(y_i) + h·J·Σ_{j<i} γ_ij·k_j (y, the stage point, is no longer needed)
        combine(ROS_GAMMAS[i], i, K, ZERO, 1.0, y)
        for r in range(NY):
            s = 0.0
            if i > 0:
                for c in range(NY):
                    s += J[r, c] * y[c]
            b[r] = h * (K[4 + i, r] + s)
        lu_solve(M, piv, b)
        for c in range(NY):
            K[i, c] = b[c]
    combine(ROS_B, ROS_STAGES, K, y0, 1.0, y)
    combine(ROS_E, ROS_STAGES, K, ZERO, 1.0, b)
    substep_end(st, y)


@jit_fused
def ros_error(st, kp, h, g0, g1, g2, q0, q1, q2):
    """Local error of the last :func:`ros_substep` over ``kp.tol`` (the embedded order-2 solution's distance)."""
    return state_error_norm(st.rk_acc, error_speed(st.new_U, st.new_L, kp), kp) / kp.tol


step = jit_fused(
    specialise(
        drive, "step_rosenbrock",
        "contact-rosenbrock: ``contact_substep.drive`` on ROS34PW2 sub-steps (linearly implicit).",
        SUBSTEP=ros_substep, ERROR=ros_error, ERR_EXP=1.0 / 3.0, THETA=FRICTION_THETA, H0=H0,
    )
)
