"""The contact-set sequence (docs/model.md §8): recording it step by step, or from a height series.

The writeup calls it the "ground contact event sequence".

A contact set is an 8-bit mask, bit k = node k+1 at or below the ground
(absolute z ≤ 0).  The sequence starts with the empty set; after every step
from the second one on, up to and including the stopping step, the current
set is appended when it differs from the last recorded one (docs/model.md §8).
The same ``record_set`` serves the run loop, the specialised seed kernel
(``core.fast``) and ``contact_sets_from_heights`` (used on hand-built
height series in tests).

Exact contact events (docs/model.md §8.1): a contact scheme's sub-steps end
where a node enters or leaves the ground, so the set that holds *inside*
each sub-step is known exactly, with the time it began.  An events loop
(``loop.make_roll(events=True)``) records that sequence with
:func:`note_event` instead of the sets at output-step ends.
"""

from __future__ import annotations

import math

import numpy as np

from dicetrace.core._jit import jit
from dicetrace.core.inertia import omega


@jit(inline="always")
def contact_mask(z):
    """The contact set of the node heights ``z`` (8,): bit k set when node k+1 is at or below the ground."""
    mask = 0
    for k in range(8):
        if z[k] <= 0.0:
            mask |= 1 << k
    return mask


@jit(inline="always")
def record_set(n, mask, last_mask, sets, set_steps, nsets):
    """Append ``mask`` seen at step ``n`` if it is new.

    Returns (nsets, last_mask, ok); ok is False when the buffer is full.
    """
    if n >= 2 and mask != last_mask:
        if nsets >= sets.shape[0]:
            return nsets, last_mask, False
        sets[nsets] = mask
        set_steps[nsets] = n
        return nsets + 1, mask, True
    return nsets, last_mask, True


@jit
def contact_sets_from_heights(z_steps, sets, set_steps):
    """Contact-set sequence of a height series ``z_steps`` (nstep+1, 8).

    Row n holds the absolute node heights after n steps (row 0: initial
    state, never compared).  Returns the number of sets written (-1 if the
    buffers are too small).
    """
    if sets.shape[0] < 1:
        return -1
    sets[0] = 0
    set_steps[0] = 0
    nsets = 1
    last = 0
    for n in range(1, z_steps.shape[0]):
        nsets, last, ok = record_set(n, contact_mask(z_steps[n]), last, sets, set_steps, nsets)
        if not ok:
            return -1
    return nsets


@jit(inline="always")
def hermite_coefficients(z0, v0, z1, v1, h):
    """(a1, a2, a3): the cubic Hermite interpolant of a height over a (sub-)step of length h is
    p(θ) = z0 + a1·θ + a2·θ² + a3·θ³ for θ in [0, 1], with p(0) = z0, p(1) = z1 and slopes h·v0, h·v1
    (z0, z1: the heights at the ends; v0, v1: their time derivatives)."""
    hv0 = h * v0
    hv1 = h * v1
    return hv0, 3.0 * (z1 - z0) - 2.0 * hv0 - hv1, 2.0 * (z0 - z1) + hv0 + hv1


@jit(inline="always")
def hermite_value(z0, a1, a2, a3, t):
    """p(t) of the interpolant :func:`hermite_coefficients` describes (Horner's scheme)."""
    return z0 + t * (a1 + t * (a2 + t * a3))


@jit(inline="always")
def hermite_slope(a1, a2, a3, t):
    """p'(t) of the interpolant :func:`hermite_coefficients` describes."""
    return a1 + t * (2.0 * a2 + 3.0 * t * a3)


@jit(inline="always")
def node_vz(U, w0, w1, off, k):
    """The vertical velocity of node k: u_z = U_z + (x × ω)_z, with x its offset and ω (its first two components
    ``w0``, ``w1``; the cube's L / I, ``inertia.omega``)."""
    return U[2] + (off[k, 0] * w1 - off[k, 1] * w0)


@jit
def hermite_crossings(z0, v0, z1, v1, h, cmin, roots):
    """The sign changes of the cubic Hermite interpolant of a height over a sub-step, and its side at the start.

    z0, z1: the height at the ends of a sub-step of length h; v0, v1: its
    time derivatives.  Writes the fractions θ in (cmin, 1 − cmin) where the
    cubic changes sign, ascending, into ``roots`` (3,) and returns (count,
    below): ``below``, whether the height is negative just after ``cmin``.
    A crossing closer to the start than that is a node left on the ground
    to rounding by the cut before, no crossing (the sub-step driver ignores
    it too); one closer to the end is the cut itself, or a node crossing
    with it to rounding, and the next sub-step's start says where it went.
    The cubic is split at its turning points into monotone pieces; each piece
    with a sign change holds one root, found by bisection to rounding.  This
    finds a node that enters *and* leaves the ground inside one sub-step (both
    ends above it), which no sign change between the ends shows.
    """
    a1, a2, a3 = hermite_coefficients(z0, v0, z1, v1, h)
    # the turning points in (cmin, 1): roots of p'(θ) = a1 + 2·a2·θ + 3·a3·θ²
    br0 = cmin
    br1 = 1.0
    br2 = 1.0
    nb = 0
    qa = 3.0 * a3
    qb = 2.0 * a2
    if qa != 0.0:
        disc = qb * qb - 4.0 * qa * a1
        if disc > 0.0:
            sq = math.sqrt(disc)
            # the numerically stable pair of roots
            q = -0.5 * (qb + math.copysign(sq, qb))
            r1 = q / qa
            r2 = a1 / q if q != 0.0 else r1
            if r1 > r2:
                r1, r2 = r2, r1
            if cmin < r1 < 1.0:
                br1 = r1
                nb = 1
            if cmin < r2 < 1.0:
                if nb == 0:
                    br1 = r2
                else:
                    br2 = r2
                nb += 1
    elif qb != 0.0:
        r1 = -a1 / qb
        if cmin < r1 < 1.0:
            br1 = r1
            nb = 1
    # pieces [cmin, br1], [br1, br2], [br2, 1] (the last ones empty when there are fewer turning points)
    edges = (br0, br1, br2 if nb == 2 else 1.0, 1.0)
    n = 0
    p_lo = hermite_value(z0, a1, a2, a3, cmin)
    below = p_lo < 0.0
    if p_lo == 0.0:  # on the ground exactly at the cut-off: the side is the one it moves to
        below = hermite_slope(a1, a2, a3, cmin) < 0.0
    for j in range(nb + 1):
        lo = edges[j]
        hi = edges[j + 1]
        if hi <= lo:
            continue
        plo = hermite_value(z0, a1, a2, a3, lo)
        phi = hermite_value(z0, a1, a2, a3, hi)
        if (plo < 0.0) == (phi < 0.0):
            continue
        for _ in range(60):
            mid = 0.5 * (lo + hi)
            if mid <= lo or mid >= hi:
                break
            pm = hermite_value(z0, a1, a2, a3, mid)
            if (pm < 0.0) == (plo < 0.0):
                lo = mid
                plo = pm
            else:
                hi = mid
        if n < 3 and cmin < hi < 1.0 - cmin:
            roots[n] = hi
            n += 1
    return n, below


@jit
def hermite_root(z0, v0, z1, v1, h):
    """First root in (0, 1) of the cubic Hermite interpolant of a height: where the sub-step driver cuts.

    z0, z1: heights at the ends of a step of length h; v0, v1: their time
    derivatives.  (:func:`hermite_crossings` finds every crossing of the same
    cubic, for the exact events; this one only the first, as the cuts always
    have, so that a run with events is the same throw as one without.)  Returns the fraction θ, or -1 when the interpolant has no
    sign change (then the caller cuts at the linear estimate).  A coarse grid
    of eighths brackets the first sign change (the cubic may dip and
    return); Newton's method, kept inside the bracket (bisection when it
    would leave it), converges there to rounding in a few iterations.
    """
    if z0 == 0.0:
        return 0.0
    a1, a2, a3 = hermite_coefficients(z0, v0, z1, v1, h)
    lo = 0.0
    hi = 1.0
    plo = z0
    prev_t = 0.0
    prev_p = z0
    found = False
    for i in range(1, 9):
        t = i / 8.0
        p = hermite_value(z0, a1, a2, a3, t)
        if (p < 0.0) != (prev_p < 0.0):
            lo = prev_t
            hi = t
            plo = prev_p
            phi = p
            found = True
            break
        prev_t = t
        prev_p = p
    if not found:
        return -1.0
    # regula falsi start, then bracketed Newton
    t = lo + (hi - lo) * (plo / (plo - phi))
    for it in range(60):
        p = hermite_value(z0, a1, a2, a3, t)
        if p == 0.0:
            return t
        if (p < 0.0) == (plo < 0.0):
            lo = t
            plo = p
        else:
            hi = t
        dp = hermite_slope(a1, a2, a3, t)
        tn = 0.5 * (lo + hi)
        if dp != 0.0:
            tn = t - p / dp
            if not (lo < tn < hi):
                tn = 0.5 * (lo + hi)
        if abs(tn - t) <= 1e-15 or hi - lo < 1e-15:
            return tn
        t = tn
    return t


#: The most a cubic Hermite interpolant leaves the chord of its end values by its end slopes: |h10|, |h11| ≤ 4/27.
HERMITE_SLOPE_BOUND = 4.0 / 27.0


@jit
def note_substep_events(st, roots, t, hs, h, Xs, Us, Ls, offs, Xe, Ue, Le, offe, kp, cmin, sets, set_steps, ev_times):
    """Record the contact sets of one accepted sub-step of length hs that starts ``t`` s into the step.

    From its two ends (X, U, L and the offsets at the start ``*s`` and the
    end ``*e``): each node's height and vertical velocity give its cubic
    Hermite interpolant, whose crossings (:func:`hermite_crossings`) are the
    times at which it enters or leaves the ground.  The set just after the
    start is noted at ``t``, then every crossing in time order
    (``note_event``; nothing for a sub-step under twice the cut-off
    ``cmin``, as a free piece that ends where a node is found to reach the
    ground right after it starts), crossings less than ``cmin`` of the
    sub-step apart as one (nodes that cross together to rounding, as the
    four of a face landing flat).  A sub-step cut at a crossing has none
    inside it; one where a node enters and leaves again (a dip the cuts do
    not see: both ends lie above the ground) has two.  A node whose cubic
    cannot reach the ground (its end heights clear it by more than
    ``HERMITE_SLOPE_BOUND`` times its end slopes) is not searched.  Each
    node's crossings are kept in the scratch ``roots`` (8, 3) (the contact
    driver's work record: a GPU thread has it too).
    """
    if cmin >= 0.5:
        # shorter than twice the cut-off: nothing inside it can be resolved (the
        # start of the next sub-step says which set holds)
        return
    mask = 0
    crossing = False
    ws0, ws1, _ = omega(Ls[0], Ls[1], Ls[2], offs, kp)
    we0, we1, _ = omega(Le[0], Le[1], Le[2], offe, kp)
    for k in range(8):
        zs = Xs[2] + offs[k, 2]
        ze = Xe[2] + offe[k, 2]
        vs = node_vz(Us, ws0, ws1, offs, k)
        ve = node_vz(Ue, we0, we1, offe, k)
        reach = HERMITE_SLOPE_BOUND * hs * (abs(vs) + abs(ve))
        nk = 0
        if min(zs, ze) > reach:
            below = False
        elif max(zs, ze) < -reach:
            below = True
        else:
            nk, below = hermite_crossings(zs, vs, ze, ve, hs, cmin, roots[k])
        for j in range(nk, 3):
            roots[k, j] = 2.0  # none (past the sub-step's end)
        crossing = crossing or nk > 0
        if below:
            mask |= 1 << k
    note_event(st, t, h, mask, sets, set_steps, ev_times)
    while crossing:
        best = 2.0
        for k in range(8):
            if roots[k, 0] < best:
                best = roots[k, 0]
        if best >= 1.0:
            break
        for k in range(8):  # every crossing within cmin of the first: one event (each node's roots ascend)
            while roots[k, 0] <= best + cmin:
                roots[k, 0] = roots[k, 1]
                roots[k, 1] = roots[k, 2]
                roots[k, 2] = 2.0
                mask ^= 1 << k
        note_event(st, t + best * hs, h, mask, sets, set_steps, ev_times)


@jit(inline="always")
def note_event(st, t, h, mask, sets, set_steps, ev_times):
    """Record that the contact set ``mask`` holds from ``t`` s into the step being taken (``st.ev_step``), if it is new.

    Appends the set, the step it began in (1-based: ``ev_step`` + 1 for t in
    [0, h), more for a sub-step that a dense-output scheme runs past the
    step's end) and its time (s) at ``st.ev_n``; past the buffer's end only
    the count grows (the loop reports BUFFER_FULL).
    """
    if mask != st.ev_last:
        k = st.ev_n
        if k < sets.shape[0]:
            sets[k] = mask
            set_steps[k] = st.ev_step + 1 + int(t / h)
            ev_times[k] = st.ev_step * h + t
        st.ev_n = k + 1
        st.ev_last = mask
