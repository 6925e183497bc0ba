"""Rotations of the node offsets: the program's exact turn and the Lie-group helpers.

Two rotation formulas live here, each once:

* the **program's** turn by ω·h (docs/model.md §5.2), built from LAPACK's
  scaled norm |ω| (:func:`norm3`) in the Rodrigues form of the 2019
  program, bit for bit (§5.5); :func:`turn_by_omega` caches it between
  force-free steps, as the program's step reuses it;
* **rot9**, the same rotation in the form the RK4 schemes use (``1 − cos``
  as ``2·sin²(θ/2)``, a series at small angles, no libm call per sub-step),
  with products and applications of 9-tuples.

Matrices are 9-tuples in row order, acting on row vectors: ``x_new = x @ R``
turns x by −|ω|·h about the program's ω, which is the physical rotation.
"""

from __future__ import annotations

import math

from dicetrace.core._jit import jit

#: Below this rotation angle (rad) ``rot9`` evaluates sin and 1 − cos by series.
SMALL_ANGLE = 0.05

IDENTITY9 = (1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0)


@jit(inline="always")
def _dnrm2_step(scl, s, t):
    """One component of LAPACK's scaled accumulation: (scl, s) after |x| = t."""
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
    return scl, s


@jit(inline="always")
def norm3(w0, w1, w2):
    """|ω| by the scaled accumulation of LAPACK's ``dnrm2`` (as Octave computes it), bit for bit.

    The recurrence starts from scl = 0, s = 1; its first component is
    written out for scl = 0 (``0/t`` is exactly 0 for t > 0, so s becomes
    exactly 1): one division fewer, the same bits.
    """
    t = abs(w0)
    if t == 0.0:
        scl = 0.0
        s = 2.0
    elif t > 0.0:
        scl = t
        s = 1.0
    else:  # NaN: the recurrence gives s = NaN, scl = 0
        scl = 0.0
        s = t
    scl, s = _dnrm2_step(scl, s, abs(w1))
    scl, s = _dnrm2_step(scl, s, abs(w2))
    return scl * math.sqrt(s)


@jit(inline="always")
def program_rotation(w0, w1, w2, h):
    """The program's rotation for ω over h: (turns, R as a 9-tuple).

    R = P + cos θ·(E − P) + sin θ·[ω]× / |ω|, P = ωωᵀ/(|ω|·|ω|), θ = |ω|·h,
    entry (a, b) evaluated as ``(p + c·(e − p)) + s·wx/n`` (docs/model.md
    §5.5).  The symmetric p and the antisymmetric skew term are shared
    between (a, b) and (b, a): IEEE multiplication commutes and negation is
    exact, so the shared values are the program's bits.  The diagonal's
    skew term s·0/n is s·0 (n > 0 here).

    ``turns`` is False (R the identity) when ω = 0, or when |ω| < 1.5e-154
    so that |ω|² underflows to 0: the program then divides 0 by 0 and its
    state turns NaN; the turn, |ω|·h, is below 1e-150 rad, so "no turn" is
    exact to machine precision (found by hypothesis: L = (0, 0, 3.7e-293)).
    """
    n = norm3(w0, w1, w2)
    n2 = n * n
    if n2 == 0.0:
        return False, IDENTITY9
    th = n * h
    c = math.cos(th)
    s = math.sin(th)
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
    return True, (r00, a01 + b01, a02 + b02, a01 - b01, r11, a12 + b12, a02 - b02, a12 - b12, r22)


@jit(inline="always")
def turn(x0, x1, x2, R):
    """x @ R for one row vector, each component (x0·R0j + x1·R1j) + x2·R2j."""
    return (
        x0 * R[0] + x1 * R[3] + x2 * R[6],
        x0 * R[1] + x1 * R[4] + x2 * R[7],
        x0 * R[2] + x1 * R[5] + x2 * R[8],
    )


@jit(inline="always")
def apply9(src, R, dst):
    """dst[k] = src[k] @ R for the 8 offsets (dst may be src)."""
    for k in range(8):
        y0, y1, y2 = turn(src[k, 0], src[k, 1], src[k, 2], R)
        dst[k, 0] = y0
        dst[k, 1] = y1
        dst[k, 2] = y2


@jit(inline="always")
def load9(R):
    """A (9,) array as a 9-tuple."""
    return (R[0], R[1], R[2], R[3], R[4], R[5], R[6], R[7], R[8])


@jit(inline="always")
def turn_by_omega(st, h):
    """Turn the offsets by the program's rotation for the current ω over h.

    The matrix is cached in ``st.R`` for the step ``st.rot_h`` (a step that
    changes ω sets ``st.rot_h = -1``), as the program's force-free steps
    reuse it (docs/model.md §5.1).
    """
    if st.rot_h != h:
        ok, R = program_rotation(st.W[0], st.W[1], st.W[2], h)
        st.rot_ok = ok
        if ok:
            for i in range(9):
                st.R[i] = R[i]
        st.rot_h = h
    if st.rot_ok:
        apply9(st.off, load9(st.R), st.off)


@jit(inline="always")
def rot9(w0, w1, w2, h):
    """Exact rotation for the program's ω over time h, as the RK4 schemes build it.

    R = c·E + (1 − c)·aaᵀ + s·[a]× with a = ω/|ω|; 1 − c is computed as
    2·sin²(θ/2) (no cancellation at small θ), and below ``SMALL_ANGLE`` sin θ
    and 1 − cos θ by their series to rounding (the first omitted terms are
    below 1e-20): no libm call per sub-step.
    """
    n = math.sqrt(w0 * w0 + w1 * w1 + w2 * w2)
    if n == 0.0 or h == 0.0:
        return IDENTITY9
    a0 = w0 / n
    a1 = w1 / n
    a2 = w2 / n
    th = n * h
    if abs(th) < SMALL_ANGLE:
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
