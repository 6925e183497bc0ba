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
from dicetrace.core._jit import gpu_fence, jit
from dicetrace.core.forces import ended_forces, eval_forces, step_wrench, wrench_at
from dicetrace.core.inertia import omega
from dicetrace.core.model import node_heights
from dicetrace.core.free_flight import (
    free_advance,
    free_flight,
    free_flight_safe,
    free_min_height,
    locate_entry,
)
from dicetrace.core.state import (
    DRIVER_WORK,
    SUBSTEP_CAUSES,
    SUBSTEP_WORK,
    accept_substep,
    age_tolerance,
    begin_substeps,
    copy_motion,
    end_substeps,
    work_dtype,
)
from dicetrace.params import FRICTION_SPECTRAL

#: Largest RK4 sub-step for the friction law, in units of 1/λ_f (λ_f the
#: friction law's stiffness per unit effective mass; RK4 is stable to 2.78).
FRICTION_THETA = 1.0
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
def front_keep(wk, below, f0, f1, f2, t0, t1, t2, lam):
    """Keep what the front's next sub-step starts from: whether a node is below, the force sum and torque, λ_f."""
    wk.fr_below = below
    wk.fr_wrench[0] = f0
    wk.fr_wrench[1] = f1
    wk.fr_wrench[2] = f2
    wk.fr_wrench[3] = t0
    wk.fr_wrench[4] = t1
    wk.fr_wrench[5] = t2
    wk.fr_lam = lam


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

    Per unit effective mass (at most ``kp.inv_mass_node`` per node mass, the
    cube's 11/16): μ·P_k / max(|u_xy,k|,
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
            r = kp.mu * P[k] * kp.inv_mass_node / s
            if r > lam:
                lam = r
    return lam


@jit(inline="always")
def free_piece_events(st, wk, t, tau, h, hmax, kp, sets, set_steps, ev_times):
    """An events step's exact free flight of a piece of length tau from the sub-step start ``wk.sub_*``, ``t`` s into
    the step, with its contact events.

    A node can dip below the ground and out again inside a piece (the driver
    checks a piece's end only): that is the geometry of the flight, with no
    force, and it is recorded (``contacts.note_substep_events``).  The
    piece's start is kept in the sub-step end ``wk.new_*``, free between
    sub-steps (the next sub-step writes it before anything reads it).
    The flight is the driver's own free piece (``free_advance``) and the
    events are read off beside it, so the motion is the same as without
    events, bit for bit (strict arithmetic, ``core._jit``).
    """
    copy_motion(wk.sub_X, wk.sub_U, wk.sub_L, wk.sub_off, wk.new_X, wk.new_U, wk.new_L, wk.new_off)
    free_advance(wk.sub_X, wk.sub_U, st.W, wk.sub_off, kp, tau)
    # a piece of no length (the ground reached at its start) resolves nothing: its cut-off is infinite, said so
    # rather than left to a division by zero (infinite in the kernels, an exception in plain Python)
    cmin = MIN_CUT * hmax / tau if tau > 0.0 else math.inf
    note_substep_events(st, wk.ev_roots, t, tau, h, wk.new_X, wk.new_U, wk.new_L, wk.new_off, wk.sub_X, wk.sub_U,
                        wk.sub_L, wk.sub_off, kp, cmin, sets, set_steps, ev_times)


# ------------------------------------------------------------------ the controller (its state: st.h_next)


@jit(inline="always")
def impact_start(st, adaptive, h0):
    """An impact starts: the controller goes on from the impact's first sub-step h0 unless it proposes less."""
    if adaptive and (st.h_next <= 0.0 or st.h_next > h0):
        st.h_next = h0


@jit(inline="always")
def propose_substep(st, hcap, rest, adaptive, h0, lam, theta, overshoot):
    """The length of the next sub-step and what limits it: (hs, cause, limited, last).

    At most ``hcap``, or the controller's proposal ``st.h_next`` (``adaptive``),
    or ``theta``/λ_f (the friction law's stability bound, ``lam`` its
    stiffness); shortened to end the step where that is less than a rounding
    longer than ``rest`` (with ``overshoot``, a dense-output method's last
    sub-step may run past the end instead).  ``limited``: the sub-step is
    shorter than the controller proposed, which then does not shrink its
    next proposal; ``last``: it ends the step.
    """
    hs = hcap
    cause = CAUSE_CAP
    if adaptive:
        if st.h_next <= 0.0:
            st.h_next = h0
        if st.h_next < hs:
            hs = st.h_next
            cause = CAUSE_ERROR
    limited = hs < st.h_next
    if lam * hs > theta:
        hs = theta / lam
        limited = True
        cause = CAUSE_FRICTION
    last = False
    if hs >= rest * (1.0 - 1e-12) and not (overshoot and hs > rest * (1.0 + DENSE_SNAP)):
        hs = rest
        last = True
        limited = True
        cause = CAUSE_END
    return hs, cause, limited, last


@jit(inline="always")
def control_error(st, h, hs, err, err_exp, limited):
    """Accept a sub-step of length hs whose error estimate over the tolerance is ``err``, or reject it; either way
    propose the next sub-step in ``st.h_next`` (Hairer, Nørsett & Wanner I, II.4).  Returns whether it is accepted.

    No sub-step shorter than ``ADAPT_HMIN``·h is rejected.  The factor is
    0.9·err^(−err_exp), within [0.2, 4]; a ``limited`` sub-step (shorter than
    proposed for another reason) does not shrink the proposal.
    """
    if err == 0.0:
        fac = ADAPT_FAC_MAX
    elif err_exp == 0.25:  # 0.9·err^(-1/4) by two square roots (libm's pow cost 3 % of a throw)
        fac = ADAPT_SAFETY / math.sqrt(math.sqrt(err))
    else:
        fac = ADAPT_SAFETY * err ** (-err_exp)
    if err > 1.0 and hs > ADAPT_HMIN * h:
        st.h_next = hs * max(ADAPT_FAC_MIN, fac)
        st.substeps[CAUSE_REJECTED] += 1
        return False
    hn = hs * min(ADAPT_FAC_MAX, fac)
    if limited and hn < st.h_next:
        hn = st.h_next
    st.h_next = hn
    return True


# ------------------------------------------------------------------ the crossing locator


@jit(inline="always")
def first_crossing(Xs, Us, Ls, offs, Xe, Ue, Le, offe, kp, hs, cmin):
    """Where in a sub-step of length hs the first node enters or leaves the ground, as a fraction (2.0: none).

    From the sub-step's two ends (``*s``, ``*e``): a node whose height
    changed side is located on the cubic Hermite interpolant of its height
    (``contacts.hermite_root``; the linear estimate where the cubic has no
    sign change).  A crossing within ``cmin`` of the start (a node left on
    the ground to rounding by the previous cut) is no crossing: it is left
    out of the minimum, not allowed to veto the cut of another node's real
    crossing later in the sub-step (that veto hung on the sign of a 1e-16
    height and was contact-substep's 1e-12 outcome floor; tests/core).  The
    exact events inside an accepted sub-step are read off the same cubics
    (``contacts.note_substep_events``, :func:`free_piece_events`).
    """
    cut = 2.0
    for k in range(8):
        zs = Xs[2] + offs[k, 2]
        ze = Xe[2] + offe[k, 2]
        if (zs < 0.0) != (ze < 0.0) and zs != 0.0:
            # u_z = U_z + (x × ω)_z at both ends
            ws0, ws1, _ = omega(Ls[0], Ls[1], Ls[2], offs, kp)
            we0, we1, _ = omega(Le[0], Le[1], Le[2], offe, kp)
            vs = node_vz(Us, ws0, ws1, offs, k)
            ve = node_vz(Ue, we0, we1, offe, k)
            th = hermite_root(zs, vs, ze, ve, hs)
            if th < 0.0:
                th = zs / (zs - ze)
            if cmin < th < cut:
                cut = th
    return cut


# ------------------------------------------------------------------ free flight inside a step

#: What a free piece of a step is (:func:`free_piece`): the rest of the step, a piece that ends in the air, one
#: that ends where the lowest node reaches the ground.
PIECE_REST = 0
PIECE_AIR = 1
PIECE_ENTRY = 2


@jit(inline="always")
def free_piece(st, wk, kp, rest, hmax):
    """The next piece of exact free flight from the sub-step start ``wk.sub_*``: (kind, length, last).

    The whole ``rest`` of the step where no node can reach the ground in it
    (``PIECE_REST``); else a piece of at most ``hmax`` that ends in the air
    (``PIECE_AIR``; ``last``: it ends the step) or where the lowest node
    reaches the ground (``PIECE_ENTRY``, found on the exact flight).  The
    state is not moved.
    """
    Xw = wk.sub_X
    Uw = wk.sub_U
    offw = wk.sub_off
    if free_flight_safe(Xw, Uw, st.W, offw, kp, rest):
        return PIECE_REST, rest, True
    hs = hmax
    last = False
    if hs >= rest * (1.0 - 1e-12):
        hs = rest
        last = True
    m1 = free_min_height(Xw, Uw, st.W, offw, kp, hs)
    if m1 >= 0.0:
        return PIECE_AIR, hs, last
    return PIECE_ENTRY, locate_entry(Xw, Uw, st.W, offw, kp, hs, m1), False


# ------------------------------------------------------------------ dense output (its state: st.ahead, fr_*, dn_*)


@jit(inline="always")
def resume_front(st, wk, kp, h):
    """Go on from the front a dense-output step left in the sub-step start: (t, cached, below, force sum, torque).

    ``t``: how far into this step the front lies (``st.ahead``, now 0);
    ω follows the front's L; the forces there were kept (``front_keep``)
    and are the first sub-step's first stage, except at t = h, where the
    loop ends at once and the forces at the front are evaluated afresh.
    """
    t = st.ahead
    st.ahead = 0.0
    st.W[0], st.W[1], st.W[2] = omega(wk.sub_L[0], wk.sub_L[1], wk.sub_L[2], wk.sub_off, kp)
    w = wk.fr_wrench
    return t, t < h, wk.fr_below, w[0], w[1], w[2], w[3], w[4], w[5]


@jit(inline="always")
def substeps_end(st, wk, kp, t, h, cached, below):
    """The end of a step's sub-steps: the state back from the sub-step start, and what ``eval_forces`` returns there.

    A step whose sub-step budget ran out before its end is never returned
    silently shorter: its height is NaN, which the loop reports as
    ``non_finite``.  When the step ended on an accepted sub-step whose
    forces at the new state (the error estimate's evaluation, ``cached``;
    ``below``: whether a node was below there) are in the scratch, they are
    what ``eval_forces`` would compute again from the same X, U, ω and offsets.
    """
    if t < h:
        wk.sub_X[2] = math.nan
        cached = False
    end_substeps(st, wk, kp)
    if cached:
        return ended_forces(st, below)
    return eval_forces(st, kp)


# ------------------------------------------------------------------ the sub-step loop


def work_of(method: ModuleType):
    """The work record of the driver on the sub-step method ``method``: the sub-step start and end, the driver's
    own fields (``state.DRIVER_WORK``) and the method's (``method.WORK``)."""
    return work_dtype(SUBSTEP_WORK, DRIVER_WORK, method.WORK)



def make_drive(method: ModuleType, name: str, *, events: bool = False, cache: bool = True):
    """The contact step (``core.schemes.Scheme``) on the sub-step method ``method`` (``core.methods``), compiled as ``name``.

    The driver composes the parts above: free flight inside the step (:func:`free_piece`), the controller
    (:func:`propose_substep`, :func:`control_error`), the crossing locator (:func:`first_crossing`) and dense
    output (:func:`resume_front`, :func:`front_keep`, the method's ``dense_keep``/``dense_state``).  With
    ``kp.tol_growth`` > 0 a step that starts at time t weighs its sub-steps' error estimates by
    exp(−tol_growth·t) (``state.age_tolerance``).  Every sub-step is counted
    in ``st.substeps`` by what ended it (``state.SUBSTEP_CAUSES``).
    ``events``: the step of an events loop, ``drive(st, wk, kp, h, contact, sets,
    set_steps, ev_times)``, which records the exact contact events
    (``contacts.note_event``): the set inside every accepted sub-step (whose
    ends are the crossings), the empty set where a free flight starts.
    ``cache=False`` for a method module made at run time (``loop.make_roll``).
    """
    events_on = bool(events)
    dense = bool(method.DENSE)

    def drive(st, wk, kp, h, contact, *ev):
        grade = age_tolerance(st, kp, h, 1)  # the weight of this step's error estimates
        if dense and st.ahead > 0.0:
            if st.ahead > h:  # the step ends inside the sub-step the front came from: interpolate
                st.ahead -= h
                method.dense_state(st, wk, kp, 1.0 - st.ahead / wk.dn_h)
                return dense_end(st, kp)
        elif kp.isotropic and not contact and free_flight_safe(st.X, st.U, st.W, st.off, kp, h):
            if events_on:
                note_event(st, 0.0, h, 0, ev[0], ev[1], ev[2])
            free_flight(st, kp, h)
            return eval_forces(st, kp)
        Xw, Uw, Lw, offw, Xn, Un, Ln, offn = wk.sub_X, wk.sub_U, wk.sub_L, wk.sub_off, wk.new_X, wk.new_U, wk.new_L, wk.new_off
        hmax = h / max(kp.substeps, 1.0)
        adaptive = kp.tol > 0.0
        overshoot = dense and adaptive  # the step's end is interpolated: a sub-step may span several steps
        hcap = DENSE_CAP * h if overshoot else hmax
        h0 = method.H0 / math.sqrt(kp.k)
        # the state lives in the sub-step start during the step; a front left by the last step is there already
        resume = dense and st.ahead > 0.0
        st.rot_h = -1.0  # ω changes: the cached free-flight rotation is stale
        if resume:
            t, cached, c5, g0, g1, g2, q0, q1, q2 = resume_front(st, wk, kp, h)
        else:
            begin_substeps(st, wk)
            # in contact, the forces at the step's start are those the last step ended with: its first stage
            t, cached, c5 = 0.0, contact, contact
            g0, g1, g2, q0, q1, q2 = step_wrench(st, contact, True)
        nsub = 0
        entering = False
        ahead = False  # the last accepted sub-step ran past the end of the step (dense output)
        while t < h and nsub < MAX_SUBSTEPS:
            gpu_fence()  # a GPU reads its records again at each sub-step, not keeping them in registers (``core._jit``)
            nsub += 1
            rest = h - t
            if cached:  # the accepted sub-step's last force evaluation is this one's first
                cached = False
                below, f0, f1, f2, t0, t1, t2 = c5, g0, g1, g2, q0, q1, q2
            else:
                below, f0, f1, f2, t0, t1, t2 = wrench_at(Xw[2], Uw[0], Uw[1], Uw[2], st.W[0], st.W[1], st.W[2], offw,
                                                          kp, st.F, st.uk, st.z, st.P)
            if not below and not entering and kp.isotropic:
                # free flight, exact, until the end of the step or the next entry (a body that is no uniform cube
                # precesses in flight: the method integrates it)
                if events_on:
                    note_event(st, t, h, 0, ev[0], ev[1], ev[2])
                kind, tau, last = free_piece(st, wk, kp, rest, hmax)
                if events_on and kind != PIECE_REST:
                    free_piece_events(st, wk, t, tau, h, hmax, kp, ev[0], ev[1], ev[2])
                else:
                    free_advance(Xw, Uw, st.W, offw, kp, tau)
                if kind == PIECE_ENTRY:
                    t = t + tau
                    entering = True
                    impact_start(st, adaptive, h0)
                else:
                    t = h if last else t + tau
                continue
            entering = False
            # the first pass of a resumed step starts at the front, whose λ_f was kept there
            lam = wk.fr_lam if resume and nsub == 1 else friction_rate(st.z, st.uk, st.P, kp)
            hs, cause, limited, last = propose_substep(st, hcap, rest, adaptive, h0, lam, method.FRICTION_THETA, overshoot)
            method.substep(st, wk, kp, hs, f0, f1, f2, t0, t1, t2)
            cmin = MIN_CUT * hmax / hs
            cut = first_crossing(Xw, Uw, Lw, offw, Xn, Un, Ln, offn, kp, hs, cmin)
            if cut < 1.0:  # a node crossed the ground inside: the sub-step again, up to the first crossing
                hs = cut * hs
                last = False
                limited = True
                cause = CAUSE_CUT
                st.substeps[CAUSE_REDONE] += 1
                method.substep(st, wk, kp, hs, f0, f1, f2, t0, t1, t2)
            if adaptive:  # the estimate's derivative at the new state is the next sub-step's first stage
                wn0, wn1, wn2 = omega(Ln[0], Ln[1], Ln[2], offn, kp)
                c5, g0, g1, g2, q0, q1, q2 = wrench_at(Xn[2], Un[0], Un[1], Un[2], wn0, wn1, wn2, offn, kp, st.F, st.uk,
                                                       st.z, st.P)
                err = method.error(st, wk, kp, hs, g0, g1, g2, q0, q1, q2) * grade
                if not control_error(st, h, hs, err, method.ERR_EXP, limited):
                    nsub += 1
                    continue  # the scratch holds the rejected candidate's forces: the start is evaluated again
                cached = True
            if overshoot and not last and hs > rest:  # past the step's end: kept for the step ends inside it
                method.dense_keep(st, wk, hs)
                ahead = True
            if events_on:  # the sets inside the sub-step: below at its start, and every crossing inside
                note_substep_events(st, wk.ev_roots, t, hs, h, Xw, Uw, Lw, offw, Xn, Un, Ln, offn, kp, cmin, ev[0], ev[1], ev[2])
            accept_substep(st, wk, kp)
            st.substeps[cause] += 1
            if ahead:
                break
            t = h if last else t + hs
        if ahead:  # the front stays in the sub-step start; the state at the step's end is interpolated
            st.ahead = t + hs - h
            front_keep(wk, c5, g0, g1, g2, q0, q1, q2, friction_rate(st.z, st.uk, st.P, kp))
            method.dense_state(st, wk, kp, rest / hs)
            return dense_end(st, kp)
        return substeps_end(st, wk, kp, t, h, cached, c5)

    drive.__name__ = drive.__qualname__ = name
    drive.__doc__ = f"One contact-aware step on the sub-step method of ``{method.__name__}`` (``make_drive``)."
    return jit(drive, cache=cache)
