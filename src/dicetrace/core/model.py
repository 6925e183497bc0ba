"""The body: node offsets, heights and velocities, energies and the face that comes up.

Everything here works in the 2019 program's sign convention for angular
momentum (docs/model.md §4: its L, ω and τ are the negatives of the
physical ones; node velocity u_k = U + x_k × ω).  The Python layer converts
a physical L at the boundary.

Arrays (node index k = 0..7 is node k+1 of the docs, docs/model.md §3):
``off`` (8, 3) node offsets from the centre of mass, cm; ``uk`` (8, 3) node
velocities, cm/s; ``z`` (8,) absolute node heights, cm; ``P`` (8,) normal
forces, node-mass·cm/s².

The arithmetic order follows docs/model.md §5.5 (sequential sums node
1 → 8, no fused multiply-add).  Do not "simplify" an expression here
without running ``tests/core/test_reference.py``.
"""

from __future__ import annotations

import math

import numpy as np

from dicetrace.core._jit import jit
from dicetrace.core.inertia import orientation, rotational_energy
from dicetrace.body import NODE_SIGNS, face_of_top4

# Face table (docs/model.md §3, ``dicetrace.body``): FACE_OF_TOP4[mask] for an 8-bit mask of the
# top four nodes (bit k = node k+1); 0 where the four nodes are no face.
FACE_OF_TOP4 = face_of_top4()


@jit
def init_offsets(half, off):
    for k in range(8):
        for j in range(3):
            off[k, j] = NODE_SIGNS[k, j] * half


@jit(inline="always")
def node_heights(Xz, off, z):
    """Absolute node heights; returns (any node strictly below ground, bitmask of z <= 0)."""
    below = False
    mask = 0
    for k in range(8):
        zk = Xz + off[k, 2]
        z[k] = zk
        if zk < 0.0:
            below = True
        if zk <= 0.0:
            mask |= 1 << k
    return below, mask


@jit(inline="always")
def offset_cross_omega(x0, x1, x2, w0, w1, w2):
    """x × ω for one offset (the program's u_k = U + x_k × ω)."""
    return x1 * w2 - x2 * w1, x2 * w0 - x0 * w2, x0 * w1 - x1 * w0


@jit(inline="always")
def node_velocities(U0, U1, U2, w0, w1, w2, off, uk):
    """u_k = U + x_k × ω (program convention)."""
    for k in range(8):
        c0, c1, c2 = offset_cross_omega(off[k, 0], off[k, 1], off[k, 2], w0, w1, w2)
        uk[k, 0] = U0 + c0
        uk[k, 1] = U1 + c1
        uk[k, 2] = U2 + c2


@jit(inline="always")
def energy_stop(uk, z, P, kp):
    """The program's stop-test energy (point-mass kinetic energy, docs/model.md §5.3).

    E = ((½·Σ|u_k|² + |g|·Σz_k) + ½·Σ d_k·P_k) − E_rest, kinetic sum over the
    24 squared components in column order (all x, then y, then z).
    """
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
    return ((0.5 * ke + (-kp.g) * sz) + 0.5 * el) - kp.e_rest


@jit(inline="always")
def energy_parts(U0, U1, U2, w0, w1, w2, l0, l1, l2, z, kp):
    """Energies with the inertia the dynamics use, node-mass·cm²/s².

    (translational kinetic ½·8|U|², rotational kinetic ½·ω·L (the cube's
    ½·I|ω|², ``inertia.rotational_energy``), gravitational Σ|g|·z_k, elastic
    ½·k·Σd_k², total).
    """
    et = 0.5 * 8.0 * (U0 * U0 + U1 * U1 + U2 * U2)
    er = rotational_energy(w0, w1, w2, l0, l1, l2, kp)
    eg = 0.0
    el = 0.0
    for k in range(8):
        eg += -kp.g * z[k]
        d = max(0.0, -z[k])
        el += d * d
    el *= 0.5 * kp.k
    return et, er, eg, el, et + er + eg + el


@jit(inline="always")
def energy_dynamic(U0, U1, U2, w0, w1, w2, l0, l1, l2, z, kp):
    """Total mechanical energy with the dynamics' inertia (the blow-up test, docs/model.md §10)."""
    e = 0.5 * 8.0 * (U0 * U0 + U1 * U1 + U2 * U2)
    e += rotational_energy(w0, w1, w2, l0, l1, l2, kp)
    el = 0.0
    for k in range(8):
        e += -kp.g * z[k]
        d = max(0.0, -z[k])
        el += d * d
    return e + 0.5 * kp.k * el


@jit(inline="always")
def top4_mask(z):
    """Bitmask of the four highest nodes (stable: ties keep node order)."""
    mask = 0
    for k in range(8):
        rank = 0
        for m in range(8):
            if z[m] > z[k] or (z[m] == z[k] and m < k):
                rank += 1
        if rank < 4:
            mask |= 1 << k
    return mask


@jit
def face_below(off, kp):
    """The face (1..6) the die stands over: the one its centre of mass's downward vertical leaves the box through.

    That face's basin: set down gently, a die rolls onto the face its centre's
    vertical pierces, and to leave it for another face its centre must pass
    over one of that face's edges, at least the edge's distance from the
    centre above the ground (docs/model.md §14).  ``off``: the node offsets
    (the orientation R, ``inertia.orientation``); the box's half-extents are
    1/(8·``kp.rh_*``) and its centre of mass ``kp.com_*`` (body frame).
    """
    R = orientation(off, kp)
    d0, d1, d2 = -R[6], -R[7], -R[8]  # the world's downward direction in the body frame: −(third row of R)
    best = math.inf
    face = 0
    if d0 != 0.0:
        t = ((0.125 / kp.rh_x if d0 > 0.0 else -0.125 / kp.rh_x) - kp.com_x) / d0
        if t < best:
            best, face = t, 6 if d0 > 0.0 else 1
    if d1 != 0.0:
        t = ((0.125 / kp.rh_y if d1 > 0.0 else -0.125 / kp.rh_y) - kp.com_y) / d1
        if t < best:
            best, face = t, 5 if d1 > 0.0 else 2
    if d2 != 0.0:
        t = ((0.125 / kp.rh_z if d2 > 0.0 else -0.125 / kp.rh_z) - kp.com_z) / d2
        if t < best:
            best, face = t, 4 if d2 > 0.0 else 3
    return np.int64(face)


@jit(inline="always")
def face_levels(off, kp):
    """The rest energy and the stop threshold of the face the die stands over (:func:`face_below`): a box's or a
    loaded die's differ from face to face (``Preset.face_energies``); the cube's are ``e_rest``, ``e_stop``."""
    if kp.isotropic:
        return kp.e_rest, kp.e_stop
    f = face_below(off, kp)
    if f == 1:
        return kp.e_rest1, kp.e_stop1
    if f == 2:
        return kp.e_rest2, kp.e_stop2
    if f == 3:
        return kp.e_rest3, kp.e_stop3
    if f == 4:
        return kp.e_rest4, kp.e_stop4
    if f == 5:
        return kp.e_rest5, kp.e_stop5
    return kp.e_rest6, kp.e_stop6


@jit(inline="always")
def outcome_face(z, off, kp):
    """The face that comes up: the cube's four highest nodes (0 when they are no face, docs/model.md §3), any
    other body's face opposite the one it stands over (:func:`face_below`)."""
    if kp.isotropic:
        return face_up(z)
    return np.int64(7) - face_below(off, kp)


@jit(inline="always")
def face_up(z):
    """Face value (1..6) of the four highest nodes, 0 when they are no face (docs/model.md §3)."""
    return np.int64(FACE_OF_TOP4[top4_mask(z)])


@jit(inline="always")
def program_kick_drift(U0, U1, U2, X0, X1, X2, s0, s1, s2, kp, h):
    """The program's velocity and position update: U += (ΣF + (0, 0, 8g))/8·h, then X += U·h."""
    U0 = U0 + (s0 + 0.0) / 8.0 * h
    U1 = U1 + (s1 + 0.0) / 8.0 * h
    U2 = U2 + (s2 + kp.g * 8.0) / 8.0 * h
    return U0, U1, U2, X0 + U0 * h, X1 + U1 * h, X2 + U2 * h
