"""What the sub-step methods share: the error norm of a sub-step, and the dense output of a method without one."""

from __future__ import annotations

import math

from dicetrace.core._jit import jit
from dicetrace.core.free_flight import CIRCUM


@jit(inline="always")
def error_speed(U, L, kp):
    """The speed that scales velocity errors: |U| + √3·half·|ω| + √(|g|·half)."""
    rn = CIRCUM * kp.half_side_cm
    return (
        math.sqrt(U[0] * U[0] + U[1] * U[1] + U[2] * U[2])
        + rn * math.sqrt(L[0] * L[0] + L[1] * L[1] + L[2] * L[2]) / kp.inertia
        + math.sqrt(abs(kp.g) * kp.half_side_cm)
    )


@jit(inline="always")
def error_norm(ex, eq, eu, el, vs, kp):
    """The contact schemes' error norm of a sub-step, before ``kp.tol``.

    The largest of the position error over the half side, ``ex / half``, plus
    the corner displacement of a rotation error ``eq`` (a quaternion error
    turns the die by 2·eq and moves a corner by 2·√3·half·eq), and the
    velocity error ``(eu + √3·half·el) / vs``: ``eu`` of U, ``el`` of ω
    (|e_L| / I), ``vs`` the speed of :func:`error_speed`.
    """
    rn = CIRCUM * kp.half_side_cm
    return max(ex / kp.half_side_cm + 2.0 * CIRCUM * eq, (eu + rn * el) / vs)


@jit(inline="always")
def no_dense_keep(st, wk, h):
    """``dense_keep`` of a sub-step method without a continuous extension: nothing to keep."""


@jit(inline="always")
def no_dense_state(st, wk, kp, theta):
    """``dense_state`` of a sub-step method without a continuous extension: never called."""
