"""Integrators beyond the 2019 program's: velocity Verlet, Lie-group RK4 and a
contact-aware RK4 that sub-steps only near the ground.

The ODE (program sign convention, see ``model``; node mass 1, die mass 8,
isotropic inertia I so that ω = L / I)::

    X' = U                       U' = g·ẑ + Σ_k F_k / 8
    L' = τ = Σ_k F_k × x_k       x_k' = x_k × ω          (x_k: node offsets)

with F_k = F(z_k, u_k), z_k = X_z + x_k,z and u_k = U + x_k × ω.  The offsets
live on SO(3): every scheme here moves them only by exact rotation matrices
(Rodrigues; products of them), so the die stays rigid to rounding.  In free
flight ω is constant and the parabola is quadratic in t, so Verlet and RK4
are exact there.

Every ``step_*`` function follows the contract of
:mod:`dicetrace.core.integrators` (same arguments, same return value).

Notes
-----
* ``step_verlet``: velocity Verlet (kick–drift–kick) on R⁹ × SO(3); the drift
  rotates the offsets exactly by the half-step ω.  The forces depend on
  velocity (damping, friction), so the closing half-kick evaluates them at the
  *predicted* velocity U + h·a (and L + h·τ): with position-only forces this is
  plain velocity Verlet; with velocity-dependent forces it keeps order 2 (the
  textbook variant that reuses the half-step velocity is only order 1).
* ``step_rk4``: the commutator-free Lie-group RK4 of Celledoni, Marthinsen and
  Owren, "Commutator-free Lie group methods", Future Gener. Comput. Syst. 19
  (2003) 341–352, applied on R⁹ × SO(3) (on R⁹ it is classical RK4)::

      Y2 = exp(h/2·F1)·y      Y3 = exp(h/2·F2)·y     Y4 = exp(h·F3 − h/2·F1)·Y2
      y⁺ = exp(h/12·(−F1 + 2F2 + 2F3 + 3F4)) · exp(h/12·(3F1 + 2F2 + 2F3 − F4)) · y

  with F_i = ω at stage i.  Order 4 with contact torques (tests/test_integrators.py
  measures it).  Stability interval on the imaginary axis ≈ 2.83/ω.
* ``step_contact_substep``: the contact-aware scheme.  A step in which no
  node can reach the ground (a cheap bound: the CM height is concave in t)
  is the exact free flight.  Otherwise the step is split into RK4 sub-steps
  of at most dt / ``kp.substeps``, shortened further where the friction law
  is stiff (μ·P / v_reg per unit effective mass; stability), and every node
  that enters or leaves the ground inside a sub-step is located by the
  cubic Hermite interpolant of its height and the sub-step is cut there, so
  the kink of the penalty force (F ∝ max(0, −z)) always falls on a sub-step
  boundary.  Without that cut a kink costs RK4 its order (local error
  O(k·u·h²) per contact change); with it RK4 keeps order 4 on the
  bouncing-node test.
* ``contact-adaptive`` (``kp.tol > 0``): the same step with error-controlled
  sub-steps of at most dt.  RK4 with its last stage and the derivative at
  the new state (first same as last: it is the next sub-step's first stage,
  so the estimate costs no extra force evaluation) gives an embedded order-3
  solution (weights 1/6, 1/3, 1/3, 0, 1/6; it satisfies the four order-3
  conditions), hence the local error estimate h/6·(k₄ − k₅) for X, U and L.
  The norm is the largest of |e_X|/half and (|e_U| + √3·half·|e_L|/I) / v,
  v = |U| + √3·half·|ω| + √(|g|·half), over ``tol``; a sub-step with
  norm > 1 is rejected and the next one is h·max(0.2, 0.9·norm^(−1/4)),
  at most 4·h (Hairer, Nørsett & Wanner, *Solving ODEs I*, II.4).  Each
  impact starts from ω·h = 0.1 (ω = √k).  The kink cuts, the exact free
  flight and the friction bound stay as in contact-substep; the accepted
  step is order 4.
"""

from __future__ import annotations

import math

import numpy as np

from dicetrace.core._jit import jit
from dicetrace.core.model import (
    apply_rotation,
    friction_forces_inline,
    rotation_matrix,
)
from dicetrace.params import FRICTION_SPECTRAL

#: Radius of the die's circumsphere in half sides (√3).
CIRCUM = math.sqrt(3.0)
#: Relative margin of the free-flight test.
FREE_MARGIN = 1e-9
#: Largest RK4 sub-step for the friction law, in units of 1/λ_f (λ_f the
#: friction law's stiffness per unit effective mass; RK4 is stable to 2.78).
FRICTION_THETA = 1.0
#: Largest inverse effective mass of a node along the ground, 1/8 + 3·3/16 ...
#: bounded by 1/8 + |r|²/I with |r|² = 3 half², I = 16/3 half²: 11/16.
INV_MASS_NODE = 11.0 / 16.0
#: A sub-step is never cut shorter than this fraction of itself (a node that
#: sits on the ground to rounding would otherwise be chased forever).
MIN_CUT = 1e-6
#: Error control of ``contact-adaptive`` (kp.tol > 0): first sub-step of an
#: impact as ω·h with ω = √k; safety factor and bounds of the step-size ratio
#: (standard values, Hairer, Nørsett & Wanner I, II.4); no sub-step is
#: rejected below ADAPT_HMIN·dt.
ADAPT_H0 = 0.1
ADAPT_SAFETY = 0.9
ADAPT_FAC_MIN = 0.2
ADAPT_FAC_MAX = 4.0
ADAPT_HMIN = 1e-9
#: Below this rotation angle (rad) ``rot9`` evaluates sin and 1 − cos by series.
SMALL_ANGLE = 0.05
#: Most sub-steps in one macro step (a safety valve: beyond it the state is
#: set to NaN, which the loop reports as ``non_finite``).
MAX_SUBSTEPS = 100000


# --------------------------------------------------------------------------
# Rotations as 9-tuples (row-vector form: x_new = x @ R), no allocation.


@jit(inline="always")
def rot9(w0, w1, w2, h):
    """Exact rotation for the program's ω over time h, as a 9-tuple (row form).

    ``x @ R`` turns x by −|ω|·h about ω (program convention: the physical
    rotation).  R = c·E + (1 − c)·aaᵀ + s·[a]× with a = ω/|ω|; 1 − c is
    computed as 2·sin²(θ/2) (no cancellation at small θ).
    """
    n = math.sqrt(w0 * w0 + w1 * w1 + w2 * w2)
    if n == 0.0 or h == 0.0:
        return (1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0)
    a0 = w0 / n
    a1 = w1 / n
    a2 = w2 / n
    th = n * h
    if abs(th) < SMALL_ANGLE:
        # sin θ and 1 − cos θ by their series to rounding (|θ| < 0.05: the
        # first omitted terms are below 1e-20): no libm call per sub-step
        t2 = th * th
        s = th * (1.0 - t2 / 6.0 * (1.0 - t2 / 20.0 * (1.0 - t2 / 42.0 * (1.0 - t2 / 72.0))))
        C = 0.5 * t2 * (1.0 - t2 / 12.0 * (1.0 - t2 / 30.0 * (1.0 - t2 / 56.0 * (1.0 - t2 / 90.0))))
    else:
        s = math.sin(th)
        sh = math.sin(0.5 * th)
        C = 2.0 * sh * sh
    c = 1.0 - C
    return (
        c + C * a0 * a0,
        C * a0 * a1 - s * a2,
        C * a0 * a2 + s * a1,
        C * a0 * a1 + s * a2,
        c + C * a1 * a1,
        C * a1 * a2 - s * a0,
        C * a0 * a2 - s * a1,
        C * a1 * a2 + s * a0,
        c + C * a2 * a2,
    )


@jit(inline="always")
def mul9(A, B):
    """A·B (row form: x @ A @ B applies A first, then B)."""
    return (
        A[0] * B[0] + A[1] * B[3] + A[2] * B[6],
        A[0] * B[1] + A[1] * B[4] + A[2] * B[7],
        A[0] * B[2] + A[1] * B[5] + A[2] * B[8],
        A[3] * B[0] + A[4] * B[3] + A[5] * B[6],
        A[3] * B[1] + A[4] * B[4] + A[5] * B[7],
        A[3] * B[2] + A[4] * B[5] + A[5] * B[8],
        A[6] * B[0] + A[7] * B[3] + A[8] * B[6],
        A[6] * B[1] + A[7] * B[4] + A[8] * B[7],
        A[6] * B[2] + A[7] * B[5] + A[8] * B[8],
    )


@jit(inline="always")
def apply9(src, R, dst):
    """dst[k] = src[k] @ R for the 8 offsets (dst may be src)."""
    for k in range(8):
        x0 = src[k, 0]
        x1 = src[k, 1]
        x2 = src[k, 2]
        dst[k, 0] = x0 * R[0] + x1 * R[3] + x2 * R[6]
        dst[k, 1] = x0 * R[1] + x1 * R[4] + x2 * R[7]
        dst[k, 2] = x0 * R[2] + x1 * R[5] + x2 * R[8]


# --------------------------------------------------------------------------
# Forces.


@jit(inline="always")
def forces_s(Xz, U0, U1, U2, w0, w1, w2, off, kp, F, uk, z, P):
    """Heights z; when a node is strictly below the ground also uk, P, F.

    Returns (below, mask) as ``model.node_heights``.  The same arithmetic, in
    the same order, as ``model.node_heights``, ``model.node_velocities`` and
    ``model.contact_forces`` (bit for bit), written out so that no array
    crosses a call boundary: it runs four times per RK4 sub-step, and the
    reference counting of the arrays passed to those out-of-line helpers
    cost about as much as the arithmetic (cf4: 0.71 → 0.43 µs).
    """
    below = False
    mask = 0
    for k in range(8):
        zk = Xz + off[k, 2]
        z[k] = zk
        if zk < 0.0:
            below = True
        if zk <= 0.0:
            mask |= 1 << k
    if not below:
        return below, mask
    k_ = kp.k
    gam = kp.gamma
    clamp = kp.clamp_normal
    for k in range(8):
        x0 = off[k, 0]
        x1 = off[k, 1]
        x2 = off[k, 2]
        uk[k, 0] = U0 + (x1 * w2 - x2 * w1)
        uk[k, 1] = U1 + (x2 * w0 - x0 * w2)
        u2 = U2 + (x0 * w1 - x1 * w0)
        uk[k, 2] = u2
        d = max(0.0, -z[k])
        p = k_ * d * (1.0 - gam * u2)
        if clamp and p < 0.0:
            p = 0.0
        P[k] = p
        F[k, 2] = p
    friction_forces_inline(uk, kp, F, P)
    return below, mask


@jit(inline="always")
def wrench(X, U, W, off, kp, F, uk, z, P):
    """Contact force sum and torque at a state (array form of ``wrench_s``)."""
    return wrench_s(X[2], U[0], U[1], U[2], W[0], W[1], W[2], off, kp, F, uk, z, P)


@jit(inline="always")
def wrench_s(Xz, U0, U1, U2, w0, w1, w2, off, kp, F, uk, z, P):
    """Contact force sum and torque at a state (scratch: F, uk, z, P).

    Returns (below, f0, f1, f2, t0, t1, t2): whether a node is below the
    ground, Σ F_k and τ = Σ F_k × x_k (program convention).
    """
    below, mask = forces_s(Xz, U0, U1, U2, w0, w1, w2, off, kp, F, uk, z, P)
    if not below:
        return False, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0
    f0 = 0.0
    f1 = 0.0
    f2 = 0.0
    t0 = 0.0
    t1 = 0.0
    t2 = 0.0
    for k in range(8):
        if P[k] == 0.0 and F[k, 0] == 0.0 and F[k, 1] == 0.0:
            continue
        a0 = F[k, 0]
        a1 = F[k, 1]
        a2 = F[k, 2]
        x0 = off[k, 0]
        x1 = off[k, 1]
        x2 = off[k, 2]
        f0 += a0
        f1 += a1
        f2 += a2
        t0 += a1 * x2 - a2 * x1
        t1 += a2 * x0 - a0 * x2
        t2 += a0 * x1 - a1 * x0
    return True, f0, f1, f2, t0, t1, t2


@jit(inline="always")
def finish(X, U, W, off, kp, F, uk, z, P):
    """Evaluate z, F, P (and uk in contact) at the new state: the step contract's end."""
    below, mask = forces_s(X[2], U[0], U[1], U[2], W[0], W[1], W[2], off, kp, F, uk, z, P)
    if not below:
        for k in range(8):
            F[k, 0] = 0.0
            F[k, 1] = 0.0
            F[k, 2] = 0.0
            P[k] = 0.0
    return below, mask


@jit(inline="always")
def force_sums(F, off):
    """Σ F_k and τ = Σ F_k × x_k of already evaluated forces."""
    f0 = 0.0
    f1 = 0.0
    f2 = 0.0
    t0 = 0.0
    t1 = 0.0
    t2 = 0.0
    for k in range(8):
        a0 = F[k, 0]
        a1 = F[k, 1]
        a2 = F[k, 2]
        x0 = off[k, 0]
        x1 = off[k, 1]
        x2 = off[k, 2]
        f0 += a0
        f1 += a1
        f2 += a2
        t0 += a1 * x2 - a2 * x1
        t1 += a2 * x0 - a0 * x2
        t2 += a0 * x1 - a1 * x0
    return f0, f1, f2, t0, t1, t2


# --------------------------------------------------------------------------
# Free flight.


@jit(inline="always")
def free_flight_safe(X, U, W, off, kp, h):
    """True when no node can be below the ground at any time in [t, t + h].

    The CM height is concave in t (g < 0), so its minimum over the step is
    at an end; a node is at most min(√3·half, min_k(−x_k,z) + |ω|·h·√3·half)
    below the CM.  Also bounds the RK4 stage positions (which lie between the
    ends of the step for a free-flight step).
    """
    z0 = X[2]
    z1 = X[2] + U[2] * h + 0.5 * kp.g * h * h
    zlo = min(z0, z1)
    zmid = X[2] + 0.5 * h * U[2]  # RK4 stage 2 (stages 3, 4 are between the ends)
    if zmid < zlo:
        zlo = zmid
    if kp.g > 0.0:  # convexity fails: bound the vertex too
        zlo -= 0.5 * kp.g * h * h
    r = CIRCUM * kp.half_side_cm
    low = 0.0
    for k in range(8):
        if off[k, 2] < low:
            low = off[k, 2]
    wn = math.sqrt(W[0] * W[0] + W[1] * W[1] + W[2] * W[2])
    drop = -low + wn * h * r
    if drop > r:
        drop = r
    return zlo - drop > FREE_MARGIN * (1.0 + abs(zlo))


@jit(inline="always")
def free_flight(X, U, W, off, R, Rh, kp, h):
    """The exact free-flight step: parabola and the exact rotation by ω·h.

    R/Rh cache the rotation for step h (``Rh[0]`` the step it was built for,
    ``Rh[1]`` 1 when ω ≠ 0), as in the program's step.
    """
    hg = 0.5 * kp.g * h * h
    X[0] = X[0] + U[0] * h
    X[1] = X[1] + U[1] * h
    X[2] = X[2] + U[2] * h + hg
    U[2] = U[2] + kp.g * h
    if Rh[0] != h:
        Rh[1] = 1.0 if rotation_matrix(W[0], W[1], W[2], h, R) else 0.0
        Rh[0] = h
    if Rh[1] != 0.0:
        apply_rotation(off, R)


# --------------------------------------------------------------------------
# Forward-Euler-free schemes: Verlet and RK4.


@jit(inline="always")
def step_verlet(X, U, L, W, off, F, uk, z, P, R, Rh, kp, h, contact):
    """Velocity Verlet on R⁹ × SO(3) (order 2); see the module notes.

    U½ = U + h/2·a(y), L½ = L + h/2·τ(y); X ← X + h·U½; offsets rotated
    exactly by ω½·h (ω½ = L½/I); then a*, τ* at the new positions with the
    predicted velocities U + h·a, L + h·τ; U ← U½ + h/2·a*, L ← L½ + h/2·τ*.
    """
    if not contact and free_flight_safe(X, U, W, off, kp, h):
        free_flight(X, U, W, off, R, Rh, kp, h)
        return finish(X, U, W, off, kp, F, uk, z, P)
    I = kp.inertia
    g = kp.g
    hh = 0.5 * h
    if contact:
        f0, f1, f2, t0, t1, t2 = force_sums(F, off)
    else:
        f0 = 0.0
        f1 = 0.0
        f2 = 0.0
        t0 = 0.0
        t1 = 0.0
        t2 = 0.0
    a0 = f0 / 8.0
    a1 = f1 / 8.0
    a2 = f2 / 8.0 + g
    # predicted end-of-step velocities (for the velocity-dependent forces)
    up0 = U[0] + h * a0
    up1 = U[1] + h * a1
    up2 = U[2] + h * a2
    lp0 = L[0] + h * t0
    lp1 = L[1] + h * t1
    lp2 = L[2] + h * t2
    # kick
    U[0] = U[0] + hh * a0
    U[1] = U[1] + hh * a1
    U[2] = U[2] + hh * a2
    L[0] = L[0] + hh * t0
    L[1] = L[1] + hh * t1
    L[2] = L[2] + hh * t2
    # drift
    X[0] = X[0] + h * U[0]
    X[1] = X[1] + h * U[1]
    X[2] = X[2] + h * U[2]
    Rd = rot9(L[0] / I, L[1] / I, L[2] / I, h)
    apply9(off, Rd, off)
    # forces at the new positions, predicted velocities
    Xp = X  # positions are final
    Up = np.empty(3)
    Wp = np.empty(3)
    Up[0] = up0
    Up[1] = up1
    Up[2] = up2
    Wp[0] = lp0 / I
    Wp[1] = lp1 / I
    Wp[2] = lp2 / I
    below, f0, f1, f2, t0, t1, t2 = wrench(Xp, Up, Wp, off, kp, F, uk, z, P)
    # kick
    U[0] = U[0] + hh * (f0 / 8.0)
    U[1] = U[1] + hh * (f1 / 8.0)
    U[2] = U[2] + hh * (f2 / 8.0 + g)
    L[0] = L[0] + hh * t0
    L[1] = L[1] + hh * t1
    L[2] = L[2] + hh * t2
    W[0] = L[0] / I
    W[1] = L[1] / I
    W[2] = L[2] / I
    Rh[0] = -1.0
    return finish(X, U, W, off, kp, F, uk, z, P)


#: Rows of the scratch array ``S`` of ``cf4`` (33, 3): stage offsets, stage
#: X, U, ω; the result X, U, L, offsets; the start X, U, L, offsets.
S_ROWS = 33


@jit
def cf4(S, kp, h, f10, f11, f12, t10, t11, t12, F, uk, z, P):
    """One commutator-free Lie-group RK4 step of length h inside the scratch array S.

    ``S`` (33, 3): rows 22, 23, 24 and 25–32 hold the start X, U, L and
    offsets (left unchanged); the result goes to rows 11, 12, 13 and 14–21;
    rows 0–10 are stage scratch.  ``f1*``, ``t1*``: contact force sum and
    torque at the start.  (One array instead of thirteen: every array passed
    across a call boundary costs reference counting.)
    """
    work = S
    Xn = S[11]
    Un = S[12]
    Ln = S[13]
    offn = S[14:22]
    X = S[22]
    U = S[23]
    L = S[24]
    off = S[25:33]
    I = kp.inertia
    g = kp.g
    hh = 0.5 * h
    offs = work[0:8]
    # stage 1
    a10 = f10 / 8.0
    a11 = f11 / 8.0
    a12 = f12 / 8.0 + g
    w10 = L[0] / I
    w11 = L[1] / I
    w12 = L[2] / I
    R1 = rot9(w10, w11, w12, hh)
    # stage 2
    xs2 = X[2] + hh * U[2]
    u20 = U[0] + hh * a10
    u21 = U[1] + hh * a11
    u22 = U[2] + hh * a12
    w20 = (L[0] + hh * t10) / I
    w21 = (L[1] + hh * t11) / I
    w22 = (L[2] + hh * t12) / I
    apply9(off, R1, offs)
    c, f20, f21, f22, t20, t21, t22 = wrench_s(xs2, u20, u21, u22, w20, w21, w22, offs, kp, F, uk, z, P)
    a20 = f20 / 8.0
    a21 = f21 / 8.0
    a22 = f22 / 8.0 + g
    # stage 3
    xs2 = X[2] + hh * u22
    u30 = U[0] + hh * a20
    u31 = U[1] + hh * a21
    u32 = U[2] + hh * a22
    w30 = (L[0] + hh * t20) / I
    w31 = (L[1] + hh * t21) / I
    w32 = (L[2] + hh * t22) / I
    if w20 == w10 and w21 == w11 and w22 == w12:
        R2 = R1
    else:
        R2 = rot9(w20, w21, w22, hh)
        apply9(off, R2, offs)
    c, f30, f31, f32, t30, t31, t32 = wrench_s(xs2, u30, u31, u32, w30, w31, w32, offs, kp, F, uk, z, P)
    a30 = f30 / 8.0
    a31 = f31 / 8.0
    a32 = f32 / 8.0 + g
    # stage 4
    xs2 = X[2] + h * u32
    u40 = U[0] + h * a30
    u41 = U[1] + h * a31
    u42 = U[2] + h * a32
    w40 = (L[0] + h * t30) / I
    w41 = (L[1] + h * t31) / I
    w42 = (L[2] + h * t32) / I
    R4 = mul9(R1, rot9(w30 - 0.5 * w10, w31 - 0.5 * w11, w32 - 0.5 * w12, h))
    apply9(off, R4, offs)
    c, f40, f41, f42, t40, t41, t42 = wrench_s(xs2, u40, u41, u42, w40, w41, w42, offs, kp, F, uk, z, P)
    a40 = f40 / 8.0
    a41 = f41 / 8.0
    a42 = f42 / 8.0 + g
    # combine
    h6 = h / 6.0
    Xn[0] = X[0] + h6 * (U[0] + 2.0 * (u20 + u30) + u40)
    Xn[1] = X[1] + h6 * (U[1] + 2.0 * (u21 + u31) + u41)
    Xn[2] = X[2] + h6 * (U[2] + 2.0 * (u22 + u32) + u42)
    Un[0] = U[0] + h6 * (a10 + 2.0 * (a20 + a30) + a40)
    Un[1] = U[1] + h6 * (a11 + 2.0 * (a21 + a31) + a41)
    Un[2] = U[2] + h6 * (a12 + 2.0 * (a22 + a32) + a42)
    Ln[0] = L[0] + h6 * (t10 + 2.0 * (t20 + t30) + t40)
    Ln[1] = L[1] + h6 * (t11 + 2.0 * (t21 + t31) + t41)
    Ln[2] = L[2] + h6 * (t12 + 2.0 * (t22 + t32) + t42)
    # stage 4's derivatives, for the embedded error estimate (contact-adaptive)
    work[8, 0] = u40
    work[8, 1] = u41
    work[8, 2] = u42
    work[9, 0] = a40
    work[9, 1] = a41
    work[9, 2] = a42
    work[10, 0] = t40
    work[10, 1] = t41
    work[10, 2] = t42
    h12 = h / 12.0
    Ra = rot9(
        (3.0 * w10 + 2.0 * (w20 + w30) - w40),
        (3.0 * w11 + 2.0 * (w21 + w31) - w41),
        (3.0 * w12 + 2.0 * (w22 + w32) - w42),
        h12,
    )
    Rb = rot9(
        (-w10 + 2.0 * (w20 + w30) + 3.0 * w40),
        (-w11 + 2.0 * (w21 + w31) + 3.0 * w41),
        (-w12 + 2.0 * (w22 + w32) + 3.0 * w42),
        h12,
    )
    apply9(off, mul9(Ra, Rb), offn)


@jit(inline="always")
def step_rk4(X, U, L, W, off, F, uk, z, P, R, Rh, kp, h, contact):
    """Commutator-free Lie-group RK4 (order 4); see the module notes.

    A step in which no node can touch the ground (``free_flight_safe``) is
    computed in closed form; RK4 is exact there anyway.
    """
    if not contact and free_flight_safe(X, U, W, off, kp, h):
        free_flight(X, U, W, off, R, Rh, kp, h)
        return finish(X, U, W, off, kp, F, uk, z, P)
    if contact:
        f0, f1, f2, t0, t1, t2 = force_sums(F, off)
    else:
        f0 = 0.0
        f1 = 0.0
        f2 = 0.0
        t0 = 0.0
        t1 = 0.0
        t2 = 0.0
    S = np.empty((S_ROWS, 3))
    for j in range(3):
        S[22, j] = X[j]
        S[23, j] = U[j]
        S[24, j] = L[j]
    for k in range(8):
        for j in range(3):
            S[25 + k, j] = off[k, j]
    cf4(S, kp, h, f0, f1, f2, t0, t1, t2, F, uk, z, P)
    I = kp.inertia
    for j in range(3):
        X[j] = S[11, j]
        U[j] = S[12, j]
        L[j] = S[13, j]
        W[j] = L[j] / I
    for k in range(8):
        for j in range(3):
            off[k, j] = S[14 + k, j]
    Rh[0] = -1.0
    return finish(X, U, W, off, kp, F, uk, z, P)


# --------------------------------------------------------------------------
# The contact-aware scheme.


@jit
def hermite_root(z0, v0, z1, v1, h):
    """First root in (0, 1) of the cubic Hermite interpolant of a height.

    z0, z1: heights at the ends of a step of length h; v0, v1: their time
    derivatives.  Returns the fraction θ, or -1 when the interpolant has no
    sign change (then the caller cuts at the linear estimate).
    """
    # p(θ) = h00 z0 + h10 h v0 + h01 z1 + h11 h v1
    # bracketed Newton/bisection on [0, 1]
    lo = 0.0
    hi = 1.0
    plo = z0
    if plo == 0.0:
        return 0.0
    # locate a sign change on a coarse grid first (the cubic may dip and return)
    prev_t = 0.0
    prev_p = z0
    found = False
    for i in range(1, 9):
        t = i / 8.0
        t2 = t * t
        t3 = t2 * t
        p = (2 * t3 - 3 * t2 + 1) * z0 + (t3 - 2 * t2 + t) * h * v0 + (-2 * t3 + 3 * t2) * z1 + (t3 - t2) * h * v1
        if (p < 0.0) != (prev_p < 0.0):
            lo = prev_t
            hi = t
            plo = prev_p
            found = True
            break
        prev_t = t
        prev_p = p
    if not found:
        return -1.0
    for it in range(60):
        t = 0.5 * (lo + hi)
        t2 = t * t
        t3 = t2 * t
        p = (2 * t3 - 3 * t2 + 1) * z0 + (t3 - 2 * t2 + t) * h * v0 + (-2 * t3 + 3 * t2) * z1 + (t3 - t2) * h * v1
        if (p < 0.0) == (plo < 0.0):
            lo = t
            plo = p
        else:
            hi = t
        if hi - lo < 1e-15:
            break
    return 0.5 * (lo + hi)


@jit(inline="always")
def friction_rate(z, uk, P, kp):
    """Stiffness of the friction law near the current state, 1/s.

    Per unit effective mass (at most 11/16 per node mass): μ·P_k / max(|u_xy,k|,
    v_reg) for the per-node law.  0 for the program's law: −μ·P_k·u_k/σ is
    discontinuous where σ → 0 (no smooth stiffness to resolve), and every
    scheme chatters there with an amplitude ~ h·μ·P as the program does.
    """
    lam = 0.0
    if kp.friction_mode == FRICTION_SPECTRAL:
        return lam
    else:
        for k in range(8):
            if z[k] < 0.0 and P[k] > 0.0:
                s = math.sqrt(uk[k, 0] * uk[k, 0] + uk[k, 1] * uk[k, 1])
                s = max(s, kp.v_reg_cm_s)
                r = kp.mu * P[k] * INV_MASS_NODE / s
                if r > lam:
                    lam = r
    return lam


@jit(inline="always")
def free_min_height(X, U, W, off, kp, t):
    """Lowest node height after an exact free flight of length t (state unchanged)."""
    Rt = rot9(W[0], W[1], W[2], t)
    zc = X[2] + U[2] * t + 0.5 * kp.g * t * t
    m = math.inf
    for k in range(8):
        zk = zc + (off[k, 0] * Rt[2] + off[k, 1] * Rt[5] + off[k, 2] * Rt[8])
        if zk < m:
            m = zk
    return m


@jit(inline="always")
def free_advance(X, U, W, off, kp, t):
    """Exact free flight of length t (arbitrary t: no rotation cache)."""
    X[0] = X[0] + U[0] * t
    X[1] = X[1] + U[1] * t
    X[2] = X[2] + U[2] * t + 0.5 * kp.g * t * t
    U[2] = U[2] + kp.g * t
    apply9(off, rot9(W[0], W[1], W[2], t), off)


@jit
def locate_entry(X, U, W, off, kp, hs, m1):
    """Time in (0, hs] at which the lowest node of a free flight reaches the ground.

    The lowest-node height m(τ) is ≥ 0 at τ = 0 and m1 < 0 at hs; Illinois
    regula falsi on the exact free-flight heights, to ~1e-13·hs.
    """
    a = 0.0
    fa = free_min_height(X, U, W, off, kp, 0.0)
    if fa <= 0.0:
        return 0.0
    b = hs
    fb = m1
    side = 0
    c = b
    for it in range(100):
        c = (a * fb - b * fa) / (fb - fa)
        if not (a < c < b):
            c = 0.5 * (a + b)
        fc = free_min_height(X, U, W, off, kp, c)
        if fc < 0.0:
            b = c
            fb = fc
            if side == -1:
                fa *= 0.5
            side = -1
        else:
            a = c
            fa = fc
            if side == 1:
                fb *= 0.5
            side = 1
        if b - a <= 1e-13 * hs or fc == 0.0:
            break
    return b if fc < 0.0 else c


@jit(inline="always")
def step_contact_substep(X, U, L, W, off, F, uk, z, P, R, Rh, kp, h, contact):
    """Contact-aware RK4: exact free flight, sub-stepped and kink-aligned in contact.

    Free flight (no node below the ground) is integrated exactly, in pieces
    of at most dt / ``substeps`` near the ground; the moment the lowest node
    reaches the ground is found on the exact free-flight trajectory.  From
    there on, RK4 sub-steps of at most dt / ``substeps`` (shorter where the
    friction law is stiff, see :func:`friction_rate`), each cut where a node
    enters or leaves the ground (root of the cubic Hermite interpolant of its
    height), until no node is below the ground.  Order 4 in dt at fixed
    ``substeps``.

    With ``kp.tol > 0`` (``contact-adaptive``) the sub-steps are error
    controlled instead (see the module notes); ``Rh[2]`` carries the proposed
    sub-step from one call to the next.
    """
    if not contact and free_flight_safe(X, U, W, off, kp, h):
        free_flight(X, U, W, off, R, Rh, kp, h)
        return finish(X, U, W, off, kp, F, uk, z, P)
    I = kp.inertia
    hmax = h / max(kp.substeps, 1.0)
    adaptive = kp.tol > 0.0
    h0 = ADAPT_H0 / math.sqrt(kp.k)
    rn = CIRCUM * kp.half_side_cm
    vfloor = math.sqrt(abs(kp.g) * kp.half_side_cm)
    # the state lives in the scratch array during the step (see cf4)
    S = np.empty((S_ROWS, 3))
    Xn = S[11]
    Un = S[12]
    Ln = S[13]
    offn = S[14:22]
    Xw = S[22]
    Uw = S[23]
    Lw = S[24]
    offw = S[25:33]
    for j in range(3):
        Xw[j] = X[j]
        Uw[j] = U[j]
        Lw[j] = L[j]
    for k in range(8):
        for j in range(3):
            offw[k, j] = off[k, j]
    Rh[0] = -1.0  # ω changes: the cached free-flight rotation is stale
    t = 0.0
    nsub = 0
    entering = False
    cached = False
    c5 = False
    g0 = g1 = g2 = q0 = q1 = q2 = 0.0
    while t < h and nsub < MAX_SUBSTEPS:
        nsub += 1
        rest = h - t
        if cached:
            # the accepted sub-step's last force evaluation is this one's first
            cached = False
            below = c5
            f0 = g0
            f1 = g1
            f2 = g2
            t0 = q0
            t1 = q1
            t2 = q2
        else:
            below, f0, f1, f2, t0, t1, t2 = wrench(Xw, Uw, W, offw, kp, F, uk, z, P)
        if not below and not entering:
            # free flight, exact, until the end of the step or the next entry
            if free_flight_safe(Xw, Uw, W, offw, kp, rest):
                free_advance(Xw, Uw, W, offw, kp, rest)
                t = h
                break
            hs = hmax
            last = False
            if hs >= rest * (1.0 - 1e-12):
                hs = rest
                last = True
            m1 = free_min_height(Xw, Uw, W, offw, kp, hs)
            if m1 >= 0.0:
                free_advance(Xw, Uw, W, offw, kp, hs)
                t = h if last else t + hs
                continue
            tau = locate_entry(Xw, Uw, W, offw, kp, hs, m1)
            free_advance(Xw, Uw, W, offw, kp, tau)
            t = t + tau
            entering = True
            if adaptive and (Rh[2] <= 0.0 or Rh[2] > h0):
                Rh[2] = h0  # an impact starts: the step the controller starts from
            continue
        entering = False
        hs = hmax
        if adaptive:
            if Rh[2] <= 0.0:
                Rh[2] = h0
            if Rh[2] < hs:
                hs = Rh[2]
        limited = hs < Rh[2]
        lam = friction_rate(z, uk, P, kp)
        if lam * hs > FRICTION_THETA:
            hs = FRICTION_THETA / lam
            limited = True
        last = False
        if hs >= rest * (1.0 - 1e-12):
            hs = rest
            last = True
            limited = True
        cf4(S, kp, hs, f0, f1, f2, t0, t1, t2, F, uk, z, P)
        # nodes that changed side within the sub-step: cut at the first crossing
        cut = 2.0
        for k in range(8):
            zs = Xw[2] + offw[k, 2]
            ze = Xn[2] + offn[k, 2]
            if (zs < 0.0) != (ze < 0.0) and zs != 0.0:
                # u_z = U_z + (x × ω)_z at both ends
                vs = Uw[2] + (offw[k, 0] * (Lw[1] / I) - offw[k, 1] * (Lw[0] / I))
                ve = Un[2] + (offn[k, 0] * (Ln[1] / I) - offn[k, 1] * (Ln[0] / I))
                th = hermite_root(zs, vs, ze, ve, hs)
                if th < 0.0:
                    th = zs / (zs - ze)
                if th < cut:
                    cut = th
        if cut < 1.0 and cut * hs > MIN_CUT * hmax:
            hs = cut * hs
            last = False
            limited = True
            cf4(S, kp, hs, f0, f1, f2, t0, t1, t2, F, uk, z, P)
        if adaptive:
            # embedded order-3 estimate (FSAL): y4 - y3 = h/6·(k4 - k5), k5 the
            # derivative at the new state; scaled by the die's size and speed
            c5, g0, g1, g2, q0, q1, q2 = wrench_s(
                Xn[2], Un[0], Un[1], Un[2], Ln[0] / I, Ln[1] / I, Ln[2] / I, offn, kp, F, uk, z, P
            )
            h6 = hs / 6.0
            ex = h6 * math.sqrt(
                (S[8, 0] - Un[0]) ** 2 + (S[8, 1] - Un[1]) ** 2 + (S[8, 2] - Un[2]) ** 2
            )
            d0 = S[9, 0] - g0 / 8.0
            d1 = S[9, 1] - g1 / 8.0
            d2 = S[9, 2] - (g2 / 8.0 + kp.g)
            eu = h6 * math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
            el = (h6 / I) * math.sqrt((S[10, 0] - q0) ** 2 + (S[10, 1] - q1) ** 2 + (S[10, 2] - q2) ** 2)
            vs = (
                math.sqrt(Un[0] * Un[0] + Un[1] * Un[1] + Un[2] * Un[2])
                + rn * math.sqrt(Ln[0] * Ln[0] + Ln[1] * Ln[1] + Ln[2] * Ln[2]) / I
                + vfloor
            )
            err = max(ex / kp.half_side_cm, (eu + rn * el) / vs) / kp.tol
            # 0.9·err^(-1/4), by two square roots (libm's pow cost 3 % of a physical throw)
            fac = ADAPT_FAC_MAX if err == 0.0 else ADAPT_SAFETY / math.sqrt(math.sqrt(err))
            if err > 1.0 and hs > ADAPT_HMIN * h:
                Rh[2] = hs * max(ADAPT_FAC_MIN, fac)
                nsub += 1
                # the scratch now holds the rejected candidate's forces: redo the start
                continue
            hn = hs * min(ADAPT_FAC_MAX, fac)
            if limited and hn < Rh[2]:
                hn = Rh[2]
            Rh[2] = hn
            cached = True
        for j in range(3):
            Xw[j] = Xn[j]
            Uw[j] = Un[j]
            Lw[j] = Ln[j]
            W[j] = Lw[j] / I
        for k in range(8):
            for j in range(3):
                offw[k, j] = offn[k, j]
        t = h if last else t + hs
    if t < h:
        # the sub-step budget ran out before the end of the step: never return a
        # silently shorter step; the loop reports the NaN as "non_finite"
        Xw[2] = math.nan
    for j in range(3):
        X[j] = Xw[j]
        U[j] = Uw[j]
        L[j] = Lw[j]
        W[j] = L[j] / I
    for k in range(8):
        for j in range(3):
            off[k, j] = offw[k, j]
    return finish(X, U, W, off, kp, F, uk, z, P)


@jit
def step_scheme(integ, X, U, L, W, off, F, uk, z, P, R, Rh, kp, h, contact):
    """Dispatch the schemes of this module (ids 2, 3, 4 and 5 of params.INTEGRATORS; 5,
    contact-adaptive, is the contact-substep step with kp.tol > 0).

    Called out of line from ``integrators.step``: inlining these larger
    kernels into the dispatch roughly doubled the per-step cost of the
    program's scheme in the general loop (measured: 220 → 600 ns/step).
    Inside, the step functions and small helpers are inlined at numba's IR
    level (``inline="always"``): every call boundary that passes the ~11
    state arrays costs their reference counting, ~100–200 ns per step
    (measured: Verlet 530 → 220 ns/step, contact-substep 1.8 → 1.1 µs/step
    on the seed preset).  ``cf4``, ``hermite_root`` and ``locate_entry``
    stay out of line: inlining them multiplied the compile time by four.
    """
    if integ == 2:
        return step_verlet(X, U, L, W, off, F, uk, z, P, R, Rh, kp, h, contact)
    elif integ == 3:
        return step_rk4(X, U, L, W, off, F, uk, z, P, R, Rh, kp, h, contact)
    return step_contact_substep(X, U, L, W, off, F, uk, z, P, R, Rh, kp, h, contact)
