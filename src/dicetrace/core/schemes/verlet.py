"""Velocity Verlet (kick–drift–kick) on R⁹ × SO(3), order 2 (docs/model.md §9).

U½ = U + h/2·a(y), L½ = L + h/2·τ(y); X ← X + h·U½; the offsets turn
exactly by ω½·h (ω½ = L½/I); then a*, τ* at the new positions with the
predicted velocities U + h·a, L + h·τ; U ← U½ + h/2·a*, L ← L½ + h/2·τ*.
The forces depend on velocity (damping, friction), so the closing half-kick
evaluates them at the *predicted* velocity: with position-only forces this
is plain velocity Verlet, with velocity-dependent forces it keeps order 2
(the textbook variant that reuses the half-step velocity is only order 1).
A step in which no node can touch the ground is the exact free flight.
"""

from __future__ import annotations

from dicetrace.core._jit import jit
from dicetrace.core.forces import acceleration, eval_forces, step_wrench, wrench_at
from dicetrace.core.free_flight import free_flight, free_flight_safe
from dicetrace.core.rotation import apply9, rot9
from dicetrace.core.methods.rk4 import stage_point
from dicetrace.core.state import NO_WORK, set_angular_momentum


#: A free flight of several steps is not crossed in one piece (the run loop steps through it).
EXACT_FLIGHT = False
#: No work area: the step keeps nothing between its stages.
WORK = NO_WORK


@jit
def step(st, wk, kp, h, contact):
    """One velocity-Verlet step of ``st`` (``core.schemes.Scheme``)."""
    X = st.X
    U = st.U
    L = st.L
    if not contact and free_flight_safe(X, U, st.W, st.off, kp, h):
        free_flight(st, kp, h)
        return eval_forces(st, kp)
    I = kp.inertia
    hh = 0.5 * h
    f0, f1, f2, t0, t1, t2 = step_wrench(st, contact, True)
    a0, a1, a2 = acceleration(f0, f1, f2, kp)
    # predicted end-of-step velocities (for the velocity-dependent forces)
    _, up0, up1, up2, wp0, wp1, wp2 = stage_point(X[2], U, L, h, U[2], a0, a1, a2, t0, t1, t2, I)
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
    apply9(st.off, rot9(L[0] / I, L[1] / I, L[2] / I, h), st.off)
    # forces at the new positions, predicted velocities
    below, f0, f1, f2, t0, t1, t2 = wrench_at(X[2], up0, up1, up2, wp0, wp1, wp2, st.off, kp, st.F, st.uk, st.z, st.P)
    a0, a1, a2 = acceleration(f0, f1, f2, kp)
    # kick
    U[0] = U[0] + hh * a0
    U[1] = U[1] + hh * a1
    U[2] = U[2] + hh * a2
    set_angular_momentum(st, L[0] + hh * t0, L[1] + hh * t1, L[2] + hh * t2, kp)
    return eval_forces(st, kp)
