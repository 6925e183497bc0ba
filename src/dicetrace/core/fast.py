"""The specialised summary kernel: semi-implicit Euler, point-mass stop test.

``roll_summary_sie`` computes exactly what ``loop.run_roll`` computes on its
summary path (no trace arrays) for the 2019 program's integrator and
stop-test energy, bit for bit: same status, steps, outcome and contact-set
sequence for every IC.  It is the kernel of ``simulate``, ``simulate_batch``
and ``scan`` for the ``seed`` preset (and for any preset with the point-mass
stop-test energy); ``tests/test_kernel_speed_equivalence.py`` holds it to the
general loop and to a frozen golden set.

Why it is faster (every item keeps the arithmetic of ``model`` and
``integrators`` operation for operation, see docs/model.md §5.5):

* **Mirror symmetry.**  Node 8−k is node k+1 reflected through the centre
  (``off[7-k] == -off[k]`` at the start), and every operation that moves an
  offset is odd: ``(x0·R0j + x1·R1j) + x2·R2j`` with x negated is exactly the
  negated result, because IEEE negation is exact and round-to-nearest is
  symmetric.  So ``off[7-k] == -off[k]`` holds bitwise for ever, and only
  nodes 1..4 are rotated; the others are copied negated.  The same argument
  gives ``x_{7-k} × ω == -(x_k × ω)`` for node velocities.
* **Free flight in registers.**  While no node is at or below the ground the
  forces are exactly zero, so a step is: U_z += g·h (the program's
  ``(0 + 8g)/8·h``), X += U·h, rotate by the cached R.  A run of such steps
  keeps the state in local scalars; the lowest node is ``X_z − max|x_kz|``
  exactly (rounding is monotonic), so contact is detected without building
  all eight heights.
* **The stop test in flight** is bounded below by ½(8|U|² + 16·a²|ω|²) +
  8|g|·X_z − E_rest (exact kinetic sum of a rigid cube, see run_roll) with a
  relative margin 1e-7, and the exact 24-term energy is evaluated only when
  that bound is within the margin of the threshold.  The bound falls by
  exactly 4(g·h)² per flight step, so after one evaluation the next ones are
  skipped for as many steps as half its slack allows (``_flight_countdown``).
  A conservative bound cannot change a decision.
* **Provably silent checks are skipped.**  A flight run whose magnitudes are
  below 1e100 with an orthonormal R cannot overflow before the time cap, so
  run_roll's non-finite test would pass at every step; and no node can reach
  the ground while X_z exceeds the offsets' length (``r_safe``).
* **Sparse contact sums.**  Nodes with zero normal force get exactly zero
  force (±0), and adding a signed zero changes a sequential sum only when
  every term is zero — so the force and torque sums run over the nodes in
  contact, and a torque component that comes out zero is recomputed over
  all eight nodes.  Friction skips the divisions u/σ where P = ±0 (the
  product is then the signed zero P·u) whenever σ is finite.
* **Rotation matrix** entries that the program computes twice are computed
  once: ``w_a·w_b/|ω|²`` is symmetric (IEEE multiplication commutes) and the
  skew term of R[b,a] is the exact negative of R[a,b]'s; ``s·0/|ω|`` is
  ``s·0``; the first step of LAPACK's scaled norm divides 0 by t.
* **No allocation per throw**: the caller passes scratch arrays (one set per
  block of ICs in ``run_batch``).

Every claim above is a statement about IEEE-754 double arithmetic with
round-to-nearest and no fused multiply-add (``_jit`` sets no fast-math);
``tests/test_kernel_speed_equivalence.py`` checks the result against the
general loop and the frozen golden set.
"""

from __future__ import annotations

import math

from dicetrace.core._jit import jit
from dicetrace.core.model import (
    FACE_OF_TOP4,
    spectral_norm_xy,
)
from dicetrace.params import ENERGY_POINT_MASS, FRICTION_SPECTRAL
from dicetrace.status import Status

#: Relative margin of the free-flight stop-test bound (the bound's own
#: rounding is ~1e-15 relative; the rigid-body drift of the offsets after
#: 10⁶ steps ~1e-10).
FLIGHT_BOUND_REL = 1e-7
FLIGHT_BOUND_ABS = 1e-6


@jit(inline="always")
def _norm3(w0, w1, w2):
    """``model.norm3`` (LAPACK's scaled 2-norm), scalar and inlined.

    The first component is specialised for scl = 0 (``0/t`` is exactly 0
    for t > 0, so s becomes exactly 1): one division fewer, same bits.
    """
    t = abs(w0)
    if t == 0.0:
        scl = 0.0
        s = 2.0
    elif t > 0.0:
        scl = t
        s = 1.0
    else:  # NaN: the general recurrence gives s = NaN, scl = 0
        scl = 0.0
        s = t
    t = abs(w1)
    if scl == t:
        s += 1.0
    elif scl < t:
        r = scl / t
        s *= r * r
        s += 1.0
        scl = t
    elif t != 0.0:
        r = t / scl
        s += r * r
    t = abs(w2)
    if scl == t:
        s += 1.0
    elif scl < t:
        r = scl / t
        s *= r * r
        s += 1.0
        scl = t
    elif t != 0.0:
        r = t / scl
        s += r * r
    return scl * math.sqrt(s)


@jit(inline="always")
def _rotation(w0, w1, w2, h):
    """``model.rotation_matrix`` as a tuple (ok, R00, R01, ..., R22).

    Entry (a, b) is ``(p + c·(e − p)) + s·wx/n`` with p = w_a·w_b/n²; the
    symmetric p and the antisymmetric skew term are shared between (a, b)
    and (b, a) (bitwise equal, see the module docstring).
    """
    n = _norm3(w0, w1, w2)
    n2 = n * n
    if n2 == 0.0:  # ω = 0, or |ω| < 1.5e-154 where n² underflows: no turn (see model)
        return False, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0
    th = n * h
    c = math.cos(th)
    s = math.sin(th)
    # the diagonal's skew term s·0/n: n > 0 here, so it is s·0 exactly (±0, NaN for NaN)
    d = s * 0.0
    p00 = w0 * w0 / n2
    p11 = w1 * w1 / n2
    p22 = w2 * w2 / n2
    p01 = w0 * w1 / n2
    p02 = w0 * w2 / n2
    p12 = w1 * w2 / n2
    r00 = (p00 + c * (1.0 - p00)) + d
    r11 = (p11 + c * (1.0 - p11)) + d
    r22 = (p22 + c * (1.0 - p22)) + d
    a01 = p01 + c * (0.0 - p01)
    a02 = p02 + c * (0.0 - p02)
    a12 = p12 + c * (0.0 - p12)
    b01 = s * -w2 / n  # R[0,1] skew: wx = -w2; R[1,0] has +w2
    b02 = s * w1 / n  # R[0,2]: wx = w1; R[2,0]: -w1
    b12 = s * -w0 / n  # R[1,2]: wx = -w0; R[2,1]: w0
    return True, r00, a01 + b01, a02 + b02, a01 - b01, r11, a12 + b12, a02 - b02, a12 - b12, r22


#: Magnitude below which a free-flight run cannot overflow (see roll_summary_sie).
TAME = 1e100
#: Flight steps at most between two evaluations of the stop-test bound.
COUNTDOWN_MAX = 4096


@jit(inline="always")
def _orthonormality_defect(R00, R01, R02, R10, R11, R12, R20, R21, R22):
    """max |RᵀR − I| over the entries (NaN for a non-finite R)."""
    d = abs(R00 * R00 + R10 * R10 + R20 * R20 - 1.0)
    d = max(d, abs(R01 * R01 + R11 * R11 + R21 * R21 - 1.0))
    d = max(d, abs(R02 * R02 + R12 * R12 + R22 * R22 - 1.0))
    d = max(d, abs(R00 * R01 + R10 * R11 + R20 * R21))
    d = max(d, abs(R00 * R02 + R10 * R12 + R20 * R22))
    d = max(d, abs(R01 * R02 + R11 * R12 + R21 * R22))
    if not math.isfinite(d):
        return math.inf
    return d + 1e-15  # the rounding of this very evaluation


@jit(inline="always")
def _flight_countdown(slack, scale, U2, duz, mg, h):
    """Flight steps after this one whose stop-test bound is surely still above threshold.

    In free flight the bound ½(8|U|² + 16a²|ω|²) + 8|g|·X_z decreases by exactly
    4(g·h)² per step in exact arithmetic; per step add the rounding of the U_z
    and X_z updates (1e-12 of the energy scale, ~100× the real figure) and the
    growth of the bound's own margin (1e-7·8|g|·|ΔX_z|), and use only half of
    the slack.
    """
    d = 4.0 * duz * duz * (1.0 + 1e-9) + 1e-12 * scale + FLIGHT_BOUND_REL * mg * 8.0 * abs(h) * (
        abs(U2) + COUNTDOWN_MAX * abs(duz)
    ) + 1e-9
    j = (slack - 1e-12 * scale) / (2.0 * d)
    if not (j >= 1.0):
        return 0
    if j >= COUNTDOWN_MAX:
        return COUNTDOWN_MAX
    return int(j)


@jit
def mirror_symmetric(off0):
    """Whether node 8−k is node k+1 negated, bitwise (the fast kernel's premise)."""
    for k in range(4):
        for j in range(3):
            if off0[7 - k, j] != -off0[k, j]:
                return False
    return True


@jit(inline="always")
def _record(n, mask, last_mask, sets, set_steps, nsets):
    """``contacts.record_set``: returns (nsets, last_mask, ok)."""
    if n >= 2 and mask != last_mask:
        if nsets >= sets.shape[0]:
            return nsets, last_mask, False
        sets[nsets] = mask
        set_steps[nsets] = n
        return nsets + 1, mask, True
    return nsets, last_mask, True


@jit
def roll_summary_sie(ic, off0, kp, sets, set_steps, off, F, uk, z, P):
    """One throw to rest, summary only: semi-implicit Euler, point-mass stop test.

    Parameters
    ----------
    ic : (6,) float64
        U (cm/s) and L (program convention, node-mass·cm²/s).
    off0 : (8, 3) float64
        Initial node offsets, cm; must be mirror-symmetric
        (``off0[7-k] == -off0[k]`` bitwise, see :func:`mirror_symmetric`).
    kp : KernelParams
        Must have ``energy_mode == ENERGY_POINT_MASS`` (checked by callers).
    sets, set_steps : (cap,) uint8, (cap,) int32
        Output contact-set sequence (as ``run_roll``).
    off, F, uk : (8, 3) float64;  z, P : (8,) float64
        Scratch (overwritten; no allocation here).

    Returns
    -------
    (status, steps, outcome, nsets), as ``loop.run_roll``.
    """
    h = kp.dt_s
    inertia = kp.inertia
    g8 = kp.g * 8.0
    k_ = kp.k
    gam = kp.gamma
    mu = kp.mu
    clamp = kp.clamp_normal
    spectral = kp.friction_mode == FRICTION_SPECTRAL
    vr2 = kp.v_reg_cm_s * kp.v_reg_cm_s
    e_stop = kp.e_stop
    e_rest = kp.e_rest
    mg = -kp.g
    half2 = kp.half_side_cm * kp.half_side_cm

    # --- initial state (run_roll's prologue) ---
    X0 = 0.0
    X1 = 0.0
    X2 = kp.z0_cm
    U0 = ic[0]
    U1 = ic[1]
    U2 = ic[2]
    L0 = ic[3]
    L1 = ic[4]
    L2 = ic[5]
    W0 = L0 / inertia
    W1 = L1 / inertia
    W2 = L2 / inertia
    for k in range(8):
        for j in range(3):
            off[k, j] = off0[k, j]
            F[k, j] = 0.0
            uk[k, j] = 0.0
        z[k] = X2 + off[k, 2]
        P[k] = 0.0
    # energy_dynamic at the start (blow-up reference)
    e = 0.5 * 8.0 * (U0 * U0 + U1 * U1 + U2 * U2)
    e += 0.5 * inertia * (W0 * W0 + W1 * W1 + W2 * W2)
    el = 0.0
    for k in range(8):
        e += mg * z[k]
        d = max(0.0, -z[k])
        el += d * d
    e0 = (e + 0.5 * k_ * el) - e_rest
    e_blow = (1.0 + kp.blowup_rel) * max(e0, 0.0) + kp.blowup_abs

    sets[0] = 0
    set_steps[0] = 0
    nsets = 1
    last_mask = 0

    # Step constants of the program's U update with zero force: (0 + 0)/8·h, (0 + 8g)/8·h.
    du_free = (0.0 + 0.0) / 8.0 * h
    duz_free = (0.0 + g8) / 8.0 * h

    rot_ok, R00, R01, R02, R10, R11, R12, R20, R21, R22 = _rotation(W0, W1, W2, h)

    maxn = int(kp.max_steps)
    status = Status.TIME_CAP
    n = 0
    pmask = 0  # nodes with a non-zero normal force at the last force evaluation
    sparse = False  # whether every other node's force is an exact zero
    contact = False  # forces are zero before the first step (program)
    while n < maxn:
        if not contact:
            # ---------------- free flight: a run of force-free steps in registers ----------------
            o00 = off[0, 0]
            o01 = off[0, 1]
            o02 = off[0, 2]
            o10 = off[1, 0]
            o11 = off[1, 1]
            o12 = off[1, 2]
            o20 = off[2, 0]
            o21 = off[2, 1]
            o22 = off[2, 2]
            o30 = off[3, 0]
            o31 = off[3, 1]
            o32 = off[3, 2]
            # free-flight constants of the stop-test bound (U0, U1, ω fixed)
            lsum = L0 + L1 + L2
            left = maxn - n  # steps this run may take at most
            # U0 += (0+0)/8·h is idempotent when that increment is a zero (h finite):
            # apply it once and step X0, X1 by constant increments.
            xy_const = du_free == 0.0
            if xy_const:
                U0 = U0 + du_free
                U1 = U1 + du_free
            dx0 = U0 * h
            dx1 = U1 * h
            kt_xy = U0 * U0 + U1 * U1
            krot = 16.0 * half2 * (W0 * W0 + W1 * W1 + W2 * W2)
            # "Tame" run: the magnitudes cannot reach overflow within `left` steps, so
            # run_roll's non-finite test passes at every step and is skipped; and the
            # lowest node is at most r_safe below the centre (offsets keep their length
            # up to the rounding of an orthonormal R), so heights are examined only
            # when X_z <= r_safe.
            tau = _orthonormality_defect(R00, R01, R02, R10, R11, R12, R20, R21, R22) if rot_ok else 0.0
            r2 = max(
                max(o00 * o00 + o01 * o01 + o02 * o02, o10 * o10 + o11 * o11 + o12 * o12),
                max(o20 * o20 + o21 * o21 + o22 * o22, o30 * o30 + o31 * o31 + o32 * o32),
            )
            drift = left * (1.5 * tau + 4.5e-16)
            tame = (
                drift < 0.25
                and max(max(abs(X0), abs(X1)), abs(X2)) < TAME
                and max(max(abs(U0), abs(U1)), abs(U2)) < TAME
                and max(abs(lsum), r2) < TAME
                and abs(h) < TAME
                and abs(duz_free) < TAME
            )
            r_safe = math.sqrt(r2) * (1.0 + 2.0 * drift + 1e-12) if tame else math.inf
            countdown = 0  # flight steps whose stop-test bound is implied by an earlier one
            done = False  # the step ended, fully handled here
            while True:
                n += 1
                if xy_const:
                    X0 = X0 + dx0
                    X1 = X1 + dx1
                else:
                    U0 = U0 + du_free
                    U1 = U1 + du_free
                    X0 = X0 + U0 * h
                    X1 = X1 + U1 * h
                U2 = U2 + duz_free
                X2 = X2 + U2 * h
                if rot_ok:
                    a0 = o00
                    a1 = o01
                    a2 = o02
                    o00 = (a0 * R00 + a1 * R10) + a2 * R20
                    o01 = (a0 * R01 + a1 * R11) + a2 * R21
                    o02 = (a0 * R02 + a1 * R12) + a2 * R22
                    a0 = o10
                    a1 = o11
                    a2 = o12
                    o10 = (a0 * R00 + a1 * R10) + a2 * R20
                    o11 = (a0 * R01 + a1 * R11) + a2 * R21
                    o12 = (a0 * R02 + a1 * R12) + a2 * R22
                    a0 = o20
                    a1 = o21
                    a2 = o22
                    o20 = (a0 * R00 + a1 * R10) + a2 * R20
                    o21 = (a0 * R01 + a1 * R11) + a2 * R21
                    o22 = (a0 * R02 + a1 * R12) + a2 * R22
                    a0 = o30
                    a1 = o31
                    a2 = o32
                    o30 = (a0 * R00 + a1 * R10) + a2 * R20
                    o31 = (a0 * R01 + a1 * R11) + a2 * R21
                    o32 = (a0 * R02 + a1 * R12) + a2 * R22
                if not (X2 > r_safe):
                    # lowest node height, exactly min_k z_k (z of node 8-k is X2 - x_kz)
                    zlow = X2 - max(max(abs(o02), abs(o12)), max(abs(o22), abs(o32)))
                    if zlow <= 0.0:
                        break  # a node at or below the ground: the general tail ends this step
                if not tame:
                    # non-finite check of run_roll: X_z + ΣU, ΣL + x_1x + x_8z (x_8z = -x_1z)
                    if not (math.isfinite(X2 + U0 + U1 + U2) and math.isfinite(lsum + o00 + -o02)):
                        status = Status.NON_FINITE
                        done = True
                        break
                if last_mask != 0 and n >= 2:  # record the empty set
                    if nsets >= sets.shape[0]:
                        status = Status.BUFFER_FULL
                        done = True
                        break
                    sets[nsets] = 0
                    set_steps[nsets] = n
                    nsets += 1
                    last_mask = 0
                # stop test, bounded below (see the module docstring)
                if countdown > 0:
                    countdown -= 1
                else:
                    ke = 8.0 * (kt_xy + U2 * U2) + krot
                    ep = 0.5 * ke + mg * (8.0 * X2)
                    scale = ep + abs(mg * 8.0 * X2) + e_rest
                    slack = ((ep - e_rest) - (FLIGHT_BOUND_REL * scale + FLIGHT_BOUND_ABS)) - e_stop
                    if not (slack > 0.0):
                        break  # near the threshold: the general tail evaluates it exactly
                    countdown = _flight_countdown(slack, scale, U2, duz_free, mg, h)
                if n >= maxn:
                    done = True
                    break
            # write the offsets back (mirror nodes negated)
            off[0, 0] = o00
            off[0, 1] = o01
            off[0, 2] = o02
            off[1, 0] = o10
            off[1, 1] = o11
            off[1, 2] = o12
            off[2, 0] = o20
            off[2, 1] = o21
            off[2, 2] = o22
            off[3, 0] = o30
            off[3, 1] = o31
            off[3, 2] = o32
            for k in range(4):
                off[7 - k, 0] = -off[k, 0]
                off[7 - k, 1] = -off[k, 1]
                off[7 - k, 2] = -off[k, 2]
            if done:
                break
        else:
            # ---------------- a step with contact forces ----------------
            n += 1
            if sparse:
                # Only the nodes with P != 0 carry force; the others' F are exact zeros,
                # which change a sequential sum only when every term is zero, and then
                # only its sign, which (s + 0.0) and (s + 8g) wash out.
                s0 = 0.0
                s1 = 0.0
                s2 = 0.0
                first = True
                for k in range(8):
                    if (pmask >> k) & 1:
                        if first:
                            s0 = F[k, 0]
                            s1 = F[k, 1]
                            s2 = F[k, 2]
                            first = False
                        else:
                            s0 += F[k, 0]
                            s1 += F[k, 1]
                            s2 += F[k, 2]
            else:
                s0 = F[0, 0]
                s1 = F[0, 1]
                s2 = F[0, 2]
                for k in range(1, 8):
                    s0 += F[k, 0]
                    s1 += F[k, 1]
                    s2 += F[k, 2]
            U0 = U0 + (s0 + 0.0) / 8.0 * h
            U1 = U1 + (s1 + 0.0) / 8.0 * h
            U2 = U2 + (s2 + g8) / 8.0 * h
            X0 = X0 + U0 * h
            X1 = X1 + U1 * h
            X2 = X2 + U2 * h
            # torque Σ F_k × x_k with the old offsets.  With `sparse`, over the nodes
            # with P != 0: equal to the full sum unless every term is zero, and then
            # the sparse sum is zero too, so a zero component is recomputed in full.
            t0 = 0.0
            t1 = 0.0
            t2 = 0.0
            if sparse:
                first = True
                for k in range(8):
                    if (pmask >> k) & 1:
                        f0 = F[k, 0]
                        f1 = F[k, 1]
                        f2 = F[k, 2]
                        x0 = off[k, 0]
                        x1 = off[k, 1]
                        x2 = off[k, 2]
                        c0 = f1 * x2 - f2 * x1
                        c1 = f2 * x0 - f0 * x2
                        c2 = f0 * x1 - f1 * x0
                        if first:
                            t0 = c0
                            t1 = c1
                            t2 = c2
                            first = False
                        else:
                            t0 += c0
                            t1 += c1
                            t2 += c2
            full = not sparse or t0 == 0.0 or t1 == 0.0 or t2 == 0.0
            for k in range(8 if full else 0):
                f0 = F[k, 0]
                f1 = F[k, 1]
                f2 = F[k, 2]
                x0 = off[k, 0]
                x1 = off[k, 1]
                x2 = off[k, 2]
                c0 = f1 * x2 - f2 * x1
                c1 = f2 * x0 - f0 * x2
                c2 = f0 * x1 - f1 * x0
                if k == 0:
                    t0 = c0
                    t1 = c1
                    t2 = c2
                else:
                    t0 += c0
                    t1 += c1
                    t2 += c2
            L0 = L0 + t0 * h
            L1 = L1 + t1 * h
            L2 = L2 + t2 * h
            W0 = L0 / inertia
            W1 = L1 / inertia
            W2 = L2 / inertia
            rot_ok, R00, R01, R02, R10, R11, R12, R20, R21, R22 = _rotation(W0, W1, W2, h)
            if rot_ok:
                for k in range(4):
                    a0 = off[k, 0]
                    a1 = off[k, 1]
                    a2 = off[k, 2]
                    b0 = (a0 * R00 + a1 * R10) + a2 * R20
                    b1 = (a0 * R01 + a1 * R11) + a2 * R21
                    b2 = (a0 * R02 + a1 * R12) + a2 * R22
                    off[k, 0] = b0
                    off[k, 1] = b1
                    off[k, 2] = b2
                    off[7 - k, 0] = -b0
                    off[7 - k, 1] = -b1
                    off[7 - k, 2] = -b2

        # ---------------- general tail of a step: heights, forces, checks, stop test ----------------
        below = False
        mask = 0
        for k in range(8):
            zk = X2 + off[k, 2]
            z[k] = zk
            if zk < 0.0:
                below = True
            if zk <= 0.0:
                mask |= 1 << k
        if below:
            # node velocities u_k = U + x_k × ω (node 8-k: U − (x_k × ω), bitwise)
            for k in range(4):
                x0 = off[k, 0]
                x1 = off[k, 1]
                x2 = off[k, 2]
                c0 = x1 * W2 - x2 * W1
                c1 = x2 * W0 - x0 * W2
                c2 = x0 * W1 - x1 * W0
                uk[k, 0] = U0 + c0
                uk[k, 1] = U1 + c1
                uk[k, 2] = U2 + c2
                uk[7 - k, 0] = U0 - c0
                uk[7 - k, 1] = U1 - c1
                uk[7 - k, 2] = U2 - c2
            # model.contact_forces
            pmask = 0
            for k in range(8):
                d = max(0.0, -z[k])
                p = k_ * d * (1.0 - gam * uk[k, 2])
                if clamp and p < 0.0:
                    p = 0.0
                P[k] = p
                F[k, 2] = p
                if p != 0.0:  # NaN included
                    pmask |= 1 << k
            sparse = True  # every node outside pmask gets F == ±0 exactly (set below otherwise)
            if spectral:
                sig = spectral_norm_xy(uk)
                if sig == 0.0:
                    for k in range(8):
                        F[k, 0] = 0.0
                        F[k, 1] = 0.0
                elif math.isfinite(sig):
                    # σ finite: every u is finite and |u/σ| <= ~1, so for P = ±0 the
                    # friction P·(u/σ) is the signed zero P·u: skip the divisions
                    for k in range(8):
                        pk = P[k]
                        if pk == 0.0:
                            F[k, 0] = -mu * (pk * uk[k, 0])
                            F[k, 1] = -mu * (pk * uk[k, 1])
                        else:
                            F[k, 0] = -mu * (pk * (uk[k, 0] / sig))
                            F[k, 1] = -mu * (pk * (uk[k, 1] / sig))
                else:  # overflowing velocities: the program's arithmetic, NaNs and all
                    sparse = False
                    for k in range(8):
                        F[k, 0] = -mu * (P[k] * (uk[k, 0] / sig))
                        F[k, 1] = -mu * (P[k] * (uk[k, 1] / sig))
            else:
                for k in range(8):
                    if P[k] == 0.0:
                        F[k, 0] = 0.0
                        F[k, 1] = 0.0
                    else:
                        sq = math.sqrt(uk[k, 0] * uk[k, 0] + uk[k, 1] * uk[k, 1] + vr2)
                        F[k, 0] = -mu * P[k] * uk[k, 0] / sq
                        F[k, 1] = -mu * P[k] * uk[k, 1] / sq
        else:
            for k in range(8):
                F[k, 0] = 0.0
                F[k, 1] = 0.0
                F[k, 2] = 0.0
                P[k] = 0.0
        contact = below
        if not (math.isfinite(X2 + U0 + U1 + U2) and math.isfinite(L0 + L1 + L2 + off[0, 0] + off[7, 2])):
            status = Status.NON_FINITE
            break
        nsets, last_mask, ok = _record(n, mask, last_mask, sets, set_steps, nsets)
        if not ok:
            status = Status.BUFFER_FULL
            break
        if contact:
            # model.energy_dynamic: the blow-up test
            e = 0.5 * 8.0 * (U0 * U0 + U1 * U1 + U2 * U2)
            e += 0.5 * inertia * (W0 * W0 + W1 * W1 + W2 * W2)
            el = 0.0
            for k in range(8):
                e += mg * z[k]
                d = max(0.0, -z[k])
                el += d * d
            if (e + 0.5 * k_ * el) - e_rest > e_blow:
                status = Status.BLOW_UP
                break
        else:
            # free flight ending at (or near) the ground: exact energy needs u_k
            for k in range(4):
                x0 = off[k, 0]
                x1 = off[k, 1]
                x2 = off[k, 2]
                c0 = x1 * W2 - x2 * W1
                c1 = x2 * W0 - x0 * W2
                c2 = x0 * W1 - x1 * W0
                uk[k, 0] = U0 + c0
                uk[k, 1] = U1 + c1
                uk[k, 2] = U2 + c2
                uk[7 - k, 0] = U0 - c0
                uk[7 - k, 1] = U1 - c1
                uk[7 - k, 2] = U2 - c2
        # model.energy_stop
        ke = 0.0
        for j in range(3):
            for k in range(8):
                ke += uk[k, j] * uk[k, j]
        sz = 0.0
        for k in range(8):
            sz += z[k]
        el = 0.0
        for k in range(8):
            d = max(0.0, -z[k])
            el += d * P[k]
        e = ((0.5 * ke + mg * sz) + 0.5 * el) - e_rest
        if not math.isfinite(e):
            status = Status.NON_FINITE
            break
        if e <= e_stop:
            status = Status.SETTLED
            break

    if status == Status.SETTLED:
        # model.face_up on the final heights (z is current: the tail ran this step)
        top = 0
        for k in range(8):
            rank = 0
            for m in range(8):
                if z[m] > z[k] or (z[m] == z[k] and m < k):
                    rank += 1
            if rank < 4:
                top |= 1 << k
        outcome = FACE_OF_TOP4[top]
    else:
        outcome = -1
    return status, n, outcome, nsets
