"""Commutator-free Lie-group RK4 (order 4, docs/model.md §9), and its stage machinery ``cf4``.

Celledoni, Marthinsen and Owren, "Commutator-free Lie group methods",
Future Gener. Comput. Syst. 19 (2003) 341–352, applied on R⁹ × SO(3) (on
R⁹ it is classical RK4)::

    Y2 = exp(h/2·F1)·y      Y3 = exp(h/2·F2)·y     Y4 = exp(h·F3 − h/2·F1)·Y2
    y⁺ = exp(h/12·(−F1 + 2F2 + 2F3 + 3F4)) · exp(h/12·(3F1 + 2F2 + 2F3 − F4)) · y

with F_i = ω at stage i.  The ODE (program sign convention, node mass 1,
die mass 8, isotropic inertia I so that ω = L / I)::

    X' = U                       U' = g·ẑ + Σ_k F_k / 8
    L' = τ = Σ_k F_k × x_k       x_k' = x_k × ω          (x_k: node offsets)

Order 4 with contact torques (tests/core/test_integrators.py measures it);
stability interval on the imaginary axis ≈ 2.83/ω.  In free flight ω is
constant and the parabola quadratic in t, so RK4 is exact there; such a
step is computed in closed form (``schemes.rk4``).

This module is the sub-step method of ``contact_substep`` and
``contact-adaptive`` (``core.methods.SubstepMethod``; the names at its end
are what the contact driver reads): ``cf4`` with its embedded order-3
estimate; the plain ``rk4`` scheme takes one ``cf4`` step per step.
"""

from __future__ import annotations

import math

import numpy as np

from dicetrace.core._jit import jit
from dicetrace.core.forces import acceleration, wrench_at
from dicetrace.core.methods.common import error_norm, error_speed, no_dense_keep, no_dense_state
from dicetrace.core.rotation import apply9, mul9, rot9

_F8 = np.float64


@jit(inline="always")
def stage_point(Xz, U, L, c, uz, a0, a1, a2, t0, t1, t2, I):
    """The point y + c·k of an explicit stage: CM height X_z + c·u_z, velocity U + c·a, ω = (L + c·τ)/I."""
    return (
        Xz + c * uz,
        U[0] + c * a0,
        U[1] + c * a1,
        U[2] + c * a2,
        (L[0] + c * t0) / I,
        (L[1] + c * t1) / I,
        (L[2] + c * t2) / I,
    )


@jit
def cf4(st, wk, kp, h, f10, f11, f12, t10, t11, t12):
    """One commutator-free Lie-group RK4 step of length h from the sub-step start of ``st``.

    Reads ``wk.sub_X``, ``sub_U``, ``sub_L``, ``sub_off`` (left unchanged);
    writes the result to ``wk.new_X``, ``new_U``, ``new_L``, ``new_off`` and
    stage 4's derivatives to ``wk.stage4_u``, ``stage4_a``, ``stage4_t`` (for
    the embedded error estimate of contact-adaptive); ``wk.stage_off``,
    ``F``, ``uk``, ``z``, ``P`` are stage scratch.  ``f1*``, ``t1*``: contact
    force sum and torque at the start.
    """
    X = wk.sub_X
    U = wk.sub_U
    L = wk.sub_L
    off = wk.sub_off
    offs = wk.stage_off
    F = st.F
    uk = st.uk
    z = st.z
    P = st.P
    I = kp.inertia
    hh = 0.5 * h
    # stage 1
    a10, a11, a12 = acceleration(f10, f11, f12, kp)
    w10 = L[0] / I
    w11 = L[1] / I
    w12 = L[2] / I
    R1 = rot9(w10, w11, w12, hh)
    # stage 2
    xs2, u20, u21, u22, w20, w21, w22 = stage_point(X[2], U, L, hh, U[2], a10, a11, a12, t10, t11, t12, I)
    apply9(off, R1, offs)
    c, f20, f21, f22, t20, t21, t22 = wrench_at(xs2, u20, u21, u22, w20, w21, w22, offs, kp, F, uk, z, P)
    a20, a21, a22 = acceleration(f20, f21, f22, kp)
    # stage 3
    xs2, u30, u31, u32, w30, w31, w32 = stage_point(X[2], U, L, hh, u22, a20, a21, a22, t20, t21, t22, I)
    if w20 == w10 and w21 == w11 and w22 == w12:
        R2 = R1
    else:
        R2 = rot9(w20, w21, w22, hh)
        apply9(off, R2, offs)
    c, f30, f31, f32, t30, t31, t32 = wrench_at(xs2, u30, u31, u32, w30, w31, w32, offs, kp, F, uk, z, P)
    a30, a31, a32 = acceleration(f30, f31, f32, kp)
    # stage 4
    xs2, u40, u41, u42, w40, w41, w42 = stage_point(X[2], U, L, h, u32, a30, a31, a32, t30, t31, t32, I)
    R4 = mul9(R1, rot9(w30 - 0.5 * w10, w31 - 0.5 * w11, w32 - 0.5 * w12, h))
    apply9(off, R4, offs)
    c, f40, f41, f42, t40, t41, t42 = wrench_at(xs2, u40, u41, u42, w40, w41, w42, offs, kp, F, uk, z, P)
    a40, a41, a42 = acceleration(f40, f41, f42, kp)
    # combine
    Xn = wk.new_X
    Un = wk.new_U
    Ln = wk.new_L
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
    wk.stage4_u[0] = u40
    wk.stage4_u[1] = u41
    wk.stage4_u[2] = u42
    wk.stage4_a[0] = a40
    wk.stage4_a[1] = a41
    wk.stage4_a[2] = a42
    wk.stage4_t[0] = t40
    wk.stage4_t[1] = t41
    wk.stage4_t[2] = t42
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
    apply9(off, mul9(Ra, Rb), wk.new_off)


@jit(inline="always")
def cf4_error(st, wk, kp, h, g0, g1, g2, q0, q1, q2):
    """Local error of the last ``cf4`` step over ``kp.tol`` (contact-adaptive's estimate).

    RK4 with its last stage and the derivative at the new state (force sum
    g, torque q there; first same as last) gives an embedded order-3
    solution (weights 1/6, 1/3, 1/3, 0, 1/6), hence the estimate
    h/6·(k₄ − k₅) for X, U and L.  The norm is the largest of |e_X|/half and
    (|e_U| + √3·half·|e_L|/I) / :func:`error_speed`.
    """
    I = kp.inertia
    Un = wk.new_U
    Ln = wk.new_L
    u4 = wk.stage4_u
    a4 = wk.stage4_a
    t4 = wk.stage4_t
    h6 = h / 6.0
    ex = h6 * math.sqrt((u4[0] - Un[0]) ** 2 + (u4[1] - Un[1]) ** 2 + (u4[2] - Un[2]) ** 2)
    d0 = a4[0] - g0 / 8.0
    d1 = a4[1] - g1 / 8.0
    d2 = a4[2] - (g2 / 8.0 + kp.g)
    eu = h6 * math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
    el = (h6 / I) * math.sqrt((t4[0] - q0) ** 2 + (t4[1] - q1) ** 2 + (t4[2] - q2) ** 2)
    return error_norm(ex, 0.0, eu, el, error_speed(Un, Ln, kp), kp) / kp.tol


#: The sub-step method (``core.methods.SubstepMethod``): commutator-free RK4 with its embedded order-3
#: estimate; no continuous extension.
substep = cf4
error = cf4_error
#: The step-size exponent, 1 / (the estimate's order + 1).
ERR_EXP = 0.25
#: Largest λ_f·h of the friction law (RK4 is stable to 2.78; 1 keeps a margin).
FRICTION_THETA = 1.0
#: An impact's first sub-step, as ω·h with ω = √k.
H0 = 0.1
DENSE = False
dense_keep = no_dense_keep
dense_state = no_dense_state
#: Its work area besides the sub-step start and end (``core.state``): a stage's offsets and stage 4's derivatives.
WORK = [
    ("stage_off", _F8, (8, 3)),
    ("stage4_u", _F8, 3),
    ("stage4_a", _F8, 3),
    ("stage4_t", _F8, 3),
]
