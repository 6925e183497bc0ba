"""The contact driver: one macro step of a contact scheme, on any sub-step method (docs/model.md §9).

A step in which no node can reach the ground (a cheap bound: the CM height
is concave in t) is the exact free flight.  Otherwise the step is split into
sub-steps of the method (``core.methods``) of at most dt / ``kp.substeps``,
shortened further where the friction law is stiff (μ·P / v_reg per unit
effective mass; stability), and every node that enters or leaves the ground
inside a sub-step is located by the cubic Hermite interpolant of its height
and the sub-step is cut there, so the kink of the penalty force
(F ∝ max(0, −z)) always falls on a sub-step boundary.  Without that cut a
kink costs RK4 its order (local error O(k·u·h²) per contact change); with
it RK4 keeps order 4 on the bouncing-node test.

With ``kp.tol > 0`` the sub-steps are error-controlled, at most dt each: a
sub-step whose error estimate (the method's ``error``, first same as last:
the derivative at the new state is the next sub-step's first stage, so the
estimate costs no extra force evaluation) exceeds the tolerance is rejected
and the next one is h·max(0.2, 0.9·err^(−ERR_EXP)), at most 4·h (Hairer,
Nørsett & Wanner, *Solving ODEs I*, II.4).  Each impact starts from the
method's ω·h = ``H0`` (ω = √k).  The kink cuts, the exact free flight and
the friction bound stay; the proposed sub-step is carried from one step to
the next in ``st.h_next``.  A method with a continuous extension (``DENSE``)
lets the last sub-step of a step run past its end (dense output).

The schemes built on it (``core.schemes``): ``contact_substep`` (the RK4
method ``methods.rk4``; ``contact-adaptive`` is the same scheme with a
tolerance), ``contact_tsit5`` and ``contact_dop853``.
"""

from __future__ import annotations

import math
from types import ModuleType

from dicetrace.core.contacts import hermite_root, node_vz, note_event, note_substep_events
from dicetrace.core._jit import jit
from dicetrace.core.forces import ended_forces, eval_forces, step_wrench, wrench_at
from dicetrace.core.model import node_heights
from dicetrace.core.free_flight import (
    free_advance,
    free_flight,
    free_flight_safe,
    free_min_height,
    locate_entry,
)
from dicetrace.core.state import SUBSTEP_CAUSES, accept_substep, age_tolerance, begin_substeps, copy_motion, end_substeps
from dicetrace.params import FRICTION_SPECTRAL

#: Largest RK4 sub-step for the friction law, in units of 1/λ_f (λ_f the
#: friction law's stiffness per unit effective mass; RK4 is stable to 2.78).
FRICTION_THETA = 1.0
#: Largest inverse effective mass of a node along the ground, 1/8 + 3·3/16 ...
#: bounded by 1/8 + |r|²/I with |r|² = 3 half², I = 16/3 half²: 11/16.
INV_MASS_NODE = 11.0 / 16.0
#: A sub-step is never cut shorter than this fraction of dt / substeps (a node
#: that sits on the ground to rounding would otherwise be chased forever): a
#: crossing closer than that to the sub-step's start is ignored, and the cut
#: goes to the next node's crossing, if any.
MIN_CUT = 1e-6
#: Error control (kp.tol > 0): safety factor and bounds of the step-size ratio
#: (standard values, Hairer, Nørsett & Wanner I, II.4); no sub-step is
#: rejected below ADAPT_HMIN·dt.  An impact's first sub-step is the method's ``H0``.
ADAPT_SAFETY = 0.9
ADAPT_FAC_MIN = 0.2
ADAPT_FAC_MAX = 4.0
ADAPT_HMIN = 1e-9
#: Indices of ``STATE.substeps`` (``state.SUBSTEP_CAUSES``): what ended a sub-step.
CAUSE_ERROR = SUBSTEP_CAUSES.index("error")
CAUSE_CAP = SUBSTEP_CAUSES.index("cap")
CAUSE_FRICTION = SUBSTEP_CAUSES.index("friction")
CAUSE_END = SUBSTEP_CAUSES.index("end")
CAUSE_CUT = SUBSTEP_CAUSES.index("cut")
CAUSE_REJECTED = SUBSTEP_CAUSES.index("rejected")
CAUSE_REDONE = SUBSTEP_CAUSES.index("redone")
#: Dense output (``DENSE`` schemes): a sub-step that would overshoot the end of
#: the step by less than this fraction of what is left is shortened to end
#: there instead of leaving a front a rounding error ahead.
DENSE_SNAP = 1e-9
#: Dense output with error control: the longest sub-step, in steps (dt).  Where
#: the error allows sub-steps longer than dt (a die rocking or resting late in a
#: throw, its tolerance loosened by tol_growth) the steps in between are
#: interpolated; at 2 the bound ends 8 of ~510 sub-steps of a ``physical`` throw
#: (55 at 1), and Tsit5's ω·h on a resting die's 700 rad/s mode stays near 1.4.
DENSE_CAP = 2.0


#: Most sub-steps in one macro step (a safety valve: beyond it the state is
#: set to NaN, which the loop reports as ``non_finite``).
MAX_SUBSTEPS = 100000


@jit(inline="always")
def front_keep(st, below, f0, f1, f2, t0, t1, t2, lam):
    """Keep what the front's next sub-step starts from: whether a node is below, the force sum and torque, λ_f."""
    st.fr_below = below
    st.fr_wrench[0] = f0
    st.fr_wrench[1] = f1
    st.fr_wrench[2] = f2
    st.fr_wrench[3] = t0
    st.fr_wrench[4] = t1
    st.fr_wrench[5] = t2
    st.fr_lam = lam


@jit(inline="always")
def dense_end(st, kp):
    """What :func:`eval_forces` returns at an interpolated step end; only the heights when ``st.lazy``.

    A loop that sets ``st.lazy`` reads no force or node velocity at the
    step's end, and the next step goes on from the front with the forces
    kept there (``fr_*``): z, and whether a node is below, are all it needs.
    """
    if st.lazy:
        return node_heights(st.X[2], st.off, st.z)
    return eval_forces(st, kp)


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
    for k in range(8):
        if z[k] < 0.0 and P[k] > 0.0:
            s = math.sqrt(uk[k, 0] * uk[k, 0] + uk[k, 1] * uk[k, 1])
            s = max(s, kp.v_reg_cm_s)
            r = kp.mu * P[k] * INV_MASS_NODE / s
            if r > lam:
                lam = r
    return lam


@jit(inline="always")
def free_piece_events(st, t, tau, h, hmax, kp, sets, set_steps, ev_times):
    """An events step's exact free flight of a piece of length tau from the sub-step start ``st.sub_*``, ``t`` s into
    the step, with its contact events.

    A node can dip below the ground and out again inside a piece (the driver
    checks a piece's end only): that is the geometry of the flight, with no
    force, and it is recorded (``contacts.note_substep_events``).  The
    piece's start is kept in RK4 stage scratch, free between sub-steps.
    The flight is the driver's own free piece (``free_advance``) and the
    events are read off beside it, so the motion is the same as without
    events, bit for bit (strict arithmetic, ``core._jit``).
    """
    copy_motion(st.sub_X, st.sub_U, st.sub_L, st.sub_off, st.stage4_u, st.stage4_a, st.stage4_t, st.stage_off)
    free_advance(st.sub_X, st.sub_U, st.W, st.sub_off, kp, tau)
    # a piece of no length (the ground reached at its start) resolves nothing: its cut-off is infinite, said so
    # rather than left to a division by zero (infinite in the kernels, an exception in plain Python)
    cmin = MIN_CUT * hmax / tau if tau > 0.0 else math.inf
    note_substep_events(st, t, tau, h, st.stage4_u, st.stage4_a, st.stage4_t, st.stage_off, st.sub_X, st.sub_U,
                        st.sub_L, st.sub_off, kp.inertia, cmin, sets, set_steps, ev_times)


def make_drive(method: ModuleType, name: str, *, events: bool = False, cache: bool = True):
    """The contact-aware step (the contract of ``core.schemes``) on the sub-step method ``method``, compiled as ``name``.

    ``cache=False`` for a method module made at run time (see ``loop.make_roll``).
    ``events``: the step of an events loop, ``drive(st, kp, h, contact, sets,
    set_steps, ev_times)``, which records the exact contact events
    (``contacts.note_event``): the set inside every accepted sub-step (whose
    ends are the crossings), the empty set where a free flight starts.

    ``method`` is a module that defines the sub-step method: ``substep(st,
    kp, h, f0, f1, f2, t0, t1, t2)`` (one explicit step from the sub-step
    start ``st.sub_*`` to ``st.new_*``), ``error(st, kp, h, g0, g1, g2, q0,
    q1, q2)`` (its local error estimate over ``kp.tol``, given the force sum
    and torque at the new state), ``ERR_EXP`` (the step-size exponent,
    1 / (estimator order + 1)), ``FRICTION_THETA`` (the largest λ_f·h of the
    friction law), ``H0`` (an impact's first sub-step as ω·h) and ``DENSE``
    with ``dense_keep`` and ``dense_state``; with ``DENSE``, a pair with a
    continuous extension:
    the last error-controlled sub-step of the step is not shortened to end
    at h but runs past it; the state at h is interpolated in it and the
    integration front stays in ``st.sub_*`` (``st.ahead`` beyond the state)
    for the next step to go on from.

    With ``kp.tol_growth`` > 0 the tolerance loosens over the throw: a step
    that starts at time t weighs its sub-steps' error estimates by
    exp(−tol_growth·t) (``st.tol_weight``, 1 after ``init_state``, multiplied
    by every step while tol_growth > 0), never below kp.tol /
    ``TOL_LOOSEST`` (weight 1 and the same arithmetic, bit for bit, with
    tol_growth = 0).

    Free flight (no node below the ground) is integrated exactly, in pieces
    of at most dt / ``substeps`` near the ground; the moment the lowest node
    reaches the ground is found on the exact free-flight trajectory.  From
    there on, RK4 sub-steps of at most dt / ``substeps`` (shorter where the
    friction law is stiff, see :func:`friction_rate`), each cut where a node
    enters or leaves the ground (root of the cubic Hermite interpolant of its
    height), until no node is below the ground.  The sub-step method's
    order in dt at fixed ``substeps``; error-controlled sub-steps with
    ``kp.tol > 0``.  Every sub-step is counted in ``st.substeps`` by what
    ended it (``state.SUBSTEP_CAUSES``).
    """
    events_on = bool(events)

    def drive(st, kp, h, contact, *ev):
        W = st.W
        # the weight of this step's error estimates (the tolerance loosened by tol_growth)
        grade = age_tolerance(st, kp, h, 1)
        if method.DENSE and st.ahead > 0.0:
            if st.ahead > h:
                # the step ends inside the sub-step the front came from: interpolate
                st.ahead -= h
                method.dense_state(st, kp, 1.0 - st.ahead / st.dn_h)
                return dense_end(st, kp)
        elif not contact and free_flight_safe(st.X, st.U, W, st.off, kp, h):
            if events_on:
                note_event(st, 0.0, h, 0, ev[0], ev[1], ev[2])
            free_flight(st, kp, h)
            return eval_forces(st, kp)
        I = kp.inertia
        hmax = h / max(kp.substeps, 1.0)
        adaptive = kp.tol > 0.0
        hcap = hmax
        if method.DENSE and adaptive:
            hcap = DENSE_CAP * h  # the step's end is interpolated: a sub-step may span several steps
        h0 = method.H0 / math.sqrt(kp.k)
        # the state lives in the sub-step start during the step (see rk4.cf4); a
        # front left by the last step (dense output) is there already
        resume = method.DENSE and st.ahead > 0.0
        if not resume:
            begin_substeps(st)
        Xn = st.new_X
        Un = st.new_U
        Ln = st.new_L
        offn = st.new_off
        Xw = st.sub_X
        Uw = st.sub_U
        Lw = st.sub_L
        offw = st.sub_off
        F = st.F
        uk = st.uk
        z = st.z
        P = st.P
        st.rot_h = -1.0  # ω changes: the cached free-flight rotation is stale
        t = 0.0
        nsub = 0
        entering = False
        ahead = False  # the last accepted sub-step ran past the end of the step (dense output)
        # In contact, the forces at the step's start are those the last step ended
        # with (``eval_forces``, or the last sub-step's own evaluation): their sums
        # are the first sub-step's first stage, bit for bit (nodes without a force
        # hold exact zeros, which leave a sum from +0.0 unchanged).
        cached = contact
        c5 = contact
        if resume:
            # the sub-steps go on from the front, with the forces kept there
            t = st.ahead
            st.ahead = 0.0
            for j in range(3):
                W[j] = Lw[j] / I
            cached = t < h  # at t = h the loop ends at once: the forces at the front are evaluated afresh
            c5 = st.fr_below
            w = st.fr_wrench
            g0, g1, g2, q0, q1, q2 = w[0], w[1], w[2], w[3], w[4], w[5]
        else:
            g0, g1, g2, q0, q1, q2 = step_wrench(st, contact, True)
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
                below, f0, f1, f2, t0, t1, t2 = wrench_at(Xw[2], Uw[0], Uw[1], Uw[2], W[0], W[1], W[2], offw, kp, F, uk, z, P)
            if not below and not entering:
                # free flight, exact, until the end of the step or the next entry
                if events_on:
                    note_event(st, t, h, 0, ev[0], ev[1], ev[2])
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
                    if events_on:
                        free_piece_events(st, t, hs, h, hmax, kp, ev[0], ev[1], ev[2])
                    else:
                        free_advance(Xw, Uw, W, offw, kp, hs)
                    t = h if last else t + hs
                    continue
                tau = locate_entry(Xw, Uw, W, offw, kp, hs, m1)
                if events_on:
                    free_piece_events(st, t, tau, h, hmax, kp, ev[0], ev[1], ev[2])
                else:
                    free_advance(Xw, Uw, W, offw, kp, tau)
                t = t + tau
                entering = True
                if adaptive and (st.h_next <= 0.0 or st.h_next > h0):
                    st.h_next = h0  # an impact starts: the step the controller starts from
                continue
            entering = False
            hs = hcap
            cause = CAUSE_CAP
            if adaptive:
                if st.h_next <= 0.0:
                    st.h_next = h0
                if st.h_next < hs:
                    hs = st.h_next
                    cause = CAUSE_ERROR
            limited = hs < st.h_next
            if resume and nsub == 1:
                # the first pass of a resumed step starts at the front, whose λ_f
                # was kept there (the scratch holds the state's forces now)
                lam = st.fr_lam
            else:
                lam = friction_rate(z, uk, P, kp)
            if lam * hs > method.FRICTION_THETA:
                hs = method.FRICTION_THETA / lam
                limited = True
                cause = CAUSE_FRICTION
            last = False
            if hs >= rest * (1.0 - 1e-12) and not (method.DENSE and adaptive and hs > rest * (1.0 + DENSE_SNAP)):
                hs = rest
                last = True
                limited = True
                cause = CAUSE_END
            method.substep(st, kp, hs, f0, f1, f2, t0, t1, t2)
            # nodes that changed side within the sub-step: cut at the first crossing.
            # A crossing within MIN_CUT of the start (a node left on the ground to
            # rounding by the previous cut) is no crossing: it is left out of the
            # minimum, not allowed to veto the cut of another node's real crossing
            # later in the sub-step (that veto hung on the sign of a 1e-16 height
            # and was contact-substep's 1e-12 outcome floor; tests/core).
            cut = 2.0
            cmin = MIN_CUT * hmax / hs
            for k in range(8):
                zs = Xw[2] + offw[k, 2]
                ze = Xn[2] + offn[k, 2]
                if (zs < 0.0) != (ze < 0.0) and zs != 0.0:
                    # u_z = U_z + (x × ω)_z at both ends
                    vs = node_vz(Uw, Lw, offw, k, I)
                    ve = node_vz(Un, Ln, offn, k, I)
                    th = hermite_root(zs, vs, ze, ve, hs)
                    if th < 0.0:
                        th = zs / (zs - ze)
                    if cmin < th < cut:
                        cut = th
            if cut < 1.0:
                hs = cut * hs
                last = False
                limited = True
                cause = CAUSE_CUT
                st.substeps[CAUSE_REDONE] += 1
                method.substep(st, kp, hs, f0, f1, f2, t0, t1, t2)
            if adaptive:
                # embedded order-3 estimate (FSAL): y4 - y3 = h/6·(k4 - k5), k5 the
                # derivative at the new state; scaled by the die's size and speed
                c5, g0, g1, g2, q0, q1, q2 = wrench_at(
                    Xn[2], Un[0], Un[1], Un[2], Ln[0] / I, Ln[1] / I, Ln[2] / I, offn, kp, F, uk, z, P
                )
                err = method.error(st, kp, hs, g0, g1, g2, q0, q1, q2) * grade
                if err == 0.0:
                    fac = ADAPT_FAC_MAX
                elif method.ERR_EXP == 0.25:  # 0.9·err^(-1/4) by two square roots (libm's pow cost 3 % of a throw)
                    fac = ADAPT_SAFETY / math.sqrt(math.sqrt(err))
                else:
                    fac = ADAPT_SAFETY * err ** (-method.ERR_EXP)
                if err > 1.0 and hs > ADAPT_HMIN * h:
                    st.h_next = hs * max(ADAPT_FAC_MIN, fac)
                    st.substeps[CAUSE_REJECTED] += 1
                    nsub += 1
                    # the scratch now holds the rejected candidate's forces: redo the start
                    continue
                hn = hs * min(ADAPT_FAC_MAX, fac)
                if limited and hn < st.h_next:
                    hn = st.h_next
                st.h_next = hn
                cached = True
            if method.DENSE and adaptive and not last and hs > rest:
                # past the end of the step: keep this sub-step for the step ends inside it
                method.dense_keep(st, hs)
                ahead = True
            if events_on:
                # the sets inside the sub-step, from its start: the nodes below the ground there and
                # every crossing inside (a node that enters and leaves within it: the cuts see none)
                note_substep_events(st, t, hs, h, Xw, Uw, Lw, offw, Xn, Un, Ln, offn, I, cmin, ev[0], ev[1], ev[2])
            accept_substep(st, kp)
            st.substeps[cause] += 1
            if ahead:
                break
            t = h if last else t + hs
        if ahead:
            # the front stays in the sub-step start, with what its next sub-step
            # starts from; the state at the end of the step is interpolated in
            # the last sub-step
            st.ahead = t + hs - h
            front_keep(st, c5, g0, g1, g2, q0, q1, q2, friction_rate(z, uk, P, kp))
            method.dense_state(st, kp, rest / hs)
            return dense_end(st, kp)
        if t < h:
            # the sub-step budget ran out before the end of the step: never return a
            # silently shorter step; the loop reports the NaN as "non_finite"
            Xw[2] = math.nan
            cached = False
        end_substeps(st, kp)
        if cached:
            # the step ended on an accepted sub-step, whose forces at the new state
            # (the error estimate's evaluation) are in the scratch: what
            # eval_forces would compute again, from the same X, U, ω = L/I and offsets
            return ended_forces(st, c5)
        return eval_forces(st, kp)

    drive.__name__ = drive.__qualname__ = name
    drive.__doc__ = f"One contact-aware step on the sub-step method of ``{method.__name__}`` (``make_drive``)."
    return jit(drive, cache=cache)
