"""Exact free flight: the parabola, the exact rotation, and where a node reaches the ground.

While no node is below the ground the forces are zero, ω is constant and
the centre of mass follows a parabola, so a step is exact (docs/model.md
§9: the contact schemes integrate free flight in closed form).  Used by the
schemes of order ≥ 2 (``core.schemes``).
"""

from __future__ import annotations

import math

from dicetrace.core._jit import jit
from dicetrace.core.rotation import apply9, rot9, turn_by_omega

#: Radius of the die's circumsphere in half sides (√3).
CIRCUM = math.sqrt(3.0)
#: Relative margin of the free-flight test.
FREE_MARGIN = 1e-9


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
def parabola(X, U, kp, t):
    """The centre of mass over a free flight of length t: X += U·t + ½g·t², U_z += g·t."""
    X[0] = X[0] + U[0] * t
    X[1] = X[1] + U[1] * t
    X[2] = X[2] + U[2] * t + 0.5 * kp.g * t * t
    U[2] = U[2] + kp.g * t


@jit(inline="always")
def free_flight(st, kp, h):
    """The exact free-flight step of ``st``: parabola and the cached exact rotation by ω·h."""
    parabola(st.X, st.U, kp, h)
    turn_by_omega(st, h)


@jit(inline="always")
def free_advance(X, U, W, off, kp, t):
    """Exact free flight of length t (arbitrary t: no rotation cache)."""
    parabola(X, U, kp, t)
    apply9(off, rot9(W[0], W[1], W[2], t), off)


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
    fc = fa
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
def flight_steps(X, U, W, off, kp, h, mmax):
    """The most whole steps of length h, at most ``mmax``, over which no node can reach the ground.

    The largest m with :func:`free_flight_safe` over m·h (the test is
    monotone in its span: the lowest the CM gets only falls, the reach of
    the rotating nodes only grows), found by doubling then bisection; 0 when
    not even one step is safe.
    """
    lo = 0
    hi = 1
    while hi <= mmax and free_flight_safe(X, U, W, off, kp, hi * h):
        lo = hi
        hi *= 2
    # lo safe (or 0); hi not safe, or beyond mmax (never taken)
    hi = min(hi, mmax + 1)
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if free_flight_safe(X, U, W, off, kp, mid * h):
            lo = mid
        else:
            hi = mid
    return lo
