"""The angular velocity of the die from its angular momentum: ω = I⁻¹·L, with the body's own inertia tensor.

A uniform cube's inertia is isotropic, ω = L / I, the division the 2019 program
makes (bit for bit: ``kp.isotropic``).  Any other body (``dicetrace.body``: a
box, a loaded die) has ω = R·I_b⁻¹·Rᵀ·L, with I_b⁻¹ its inverse inertia tensor
in the body frame (``kp.ii_*``) and R its orientation, read off the node
offsets: column j of R is Σ_k s_kj·x_k / (8·h_j) (s_kj = ``body.NODE_SIGNS``,
h_j the half-extent along body axis j), exact for rigid offsets because the
signs of each axis sum to zero over the eight corners.  Program convention
for L and ω (docs/model.md §4), as everywhere in the kernels.
"""

from __future__ import annotations

from dicetrace.core._jit import jit


@jit(inline="always")
def orientation(off, kp):
    """R (9-tuple, row by row) of the body whose node offsets are ``off`` (8, 3): column j is body axis j in the world."""
    r00 = r01 = r02 = r10 = r11 = r12 = r20 = r21 = r22 = 0.0
    for k in range(8):
        sx = 1.0 if k & 4 else -1.0
        sy = 1.0 if k & 2 else -1.0
        sz = 1.0 if k & 1 else -1.0
        x0 = off[k, 0]
        x1 = off[k, 1]
        x2 = off[k, 2]
        r00 += sx * x0
        r10 += sx * x1
        r20 += sx * x2
        r01 += sy * x0
        r11 += sy * x1
        r21 += sy * x2
        r02 += sz * x0
        r12 += sz * x1
        r22 += sz * x2
    return (r00 * kp.rh_x, r01 * kp.rh_y, r02 * kp.rh_z,
            r10 * kp.rh_x, r11 * kp.rh_y, r12 * kp.rh_z,
            r20 * kp.rh_x, r21 * kp.rh_y, r22 * kp.rh_z)


@jit(inline="always")
def omega_in(l0, l1, l2, R, kp):
    """ω = R·I_b⁻¹·Rᵀ·L for the orientation R (9-tuple) and the body's inverse inertia ``kp.ii_*``."""
    r00, r01, r02, r10, r11, r12, r20, r21, r22 = R
    a0 = r00 * l0 + r10 * l1 + r20 * l2  # Rᵀ·L: L in the body frame
    a1 = r01 * l0 + r11 * l1 + r21 * l2
    a2 = r02 * l0 + r12 * l1 + r22 * l2
    b0 = kp.ii_xx * a0 + kp.ii_xy * a1 + kp.ii_xz * a2
    b1 = kp.ii_xy * a0 + kp.ii_yy * a1 + kp.ii_yz * a2
    b2 = kp.ii_xz * a0 + kp.ii_yz * a1 + kp.ii_zz * a2
    return (r00 * b0 + r01 * b1 + r02 * b2,
            r10 * b0 + r11 * b1 + r12 * b2,
            r20 * b0 + r21 * b1 + r22 * b2)


@jit(inline="always")
def omega(l0, l1, l2, off, kp):
    """ω of the angular momentum (l0, l1, l2) for the body whose node offsets are ``off``: L / I for the cube."""
    if kp.isotropic:
        return l0 / kp.inertia, l1 / kp.inertia, l2 / kp.inertia
    return body_omega(l0, l1, l2, off, kp)


@jit
def body_omega(l0, l1, l2, off, kp):
    """ω = R·I_b⁻¹·Rᵀ·L of a body that is not the uniform cube, R read off its offsets ``off``.

    Out of line, unlike the rest of the kernels' arithmetic: every run loop of a contact scheme calls it at
    several sites, and inlined at each (numba's ``inline="always"``) it was a large share of the loops' compile
    time; the cube never takes this branch, and the arithmetic is the same either way.
    """
    return omega_in(l0, l1, l2, orientation(off, kp), kp)


@jit(inline="always")
def rotational_energy(w0, w1, w2, l0, l1, l2, kp):
    """½·ω·I·ω = ½·ω·L: the cube's ½·I·|ω|² (its arithmetic), any other body's ½·ω·L."""
    if kp.isotropic:
        return 0.5 * kp.inertia * (w0 * w0 + w1 * w1 + w2 * w2)
    return 0.5 * (w0 * l0 + w1 * l1 + w2 * l2)
