"""The die model: node forces, exact rotation, energies, face lookup.

Everything here works in the 2019 program's sign convention for angular
momentum (its L, ω and τ are the negatives of the physical ones; node
velocity u_k = U + x_k × ω, torque τ = Σ F_k × x_k, and a step rotates the
offsets by −|ω|·dt about ω — which is the physical rotation).  The Python
layer converts a physical L at the boundary.

Arrays (node index k = 0..7 is node k+1 of the docs):
``off`` (8, 3) node offsets from the centre of mass, cm;
``uk`` (8, 3) node velocities, cm/s; ``z`` (8,) absolute node heights, cm;
``F`` (8, 3) contact forces, node-mass·cm/s².

The arithmetic order follows docs/model.md §5.5 ("bit-level arithmetic"):
sequential sums node 1 → 8, no fused multiply-add, the program's Rodrigues
form.  Do not "simplify" an expression here without running
``tests/core/test_reference.py``.
"""

from __future__ import annotations

import math

import numpy as np

from dicetrace.core._jit import jit
from dicetrace.params import FRICTION_SPECTRAL, NODE_SIGNS

# Face table: FACE_OF_TOP4[mask] for an 8-bit mask of the top four nodes
# (bit k = node k+1); 0 where the four nodes are no face.
_FACES = {1: (1, 2, 3, 4), 2: (1, 2, 5, 6), 3: (1, 3, 5, 7), 4: (2, 4, 6, 8), 5: (3, 4, 7, 8), 6: (5, 6, 7, 8)}
FACE_OF_TOP4 = np.zeros(256, dtype=np.int8)
for _face, _nodes in _FACES.items():
    FACE_OF_TOP4[sum(1 << (n - 1) for n in _nodes)] = _face

@jit
def init_offsets(half, off):
    for k in range(8):
        for j in range(3):
            off[k, j] = NODE_SIGNS[k, j] * half


@jit
def norm3(w0, w1, w2):
    """2-norm with the scaled accumulation of Octave/LAPACK (bit-faithful)."""
    scl = 0.0
    s = 1.0
    for i in range(3):
        if i == 0:
            t = abs(w0)
        elif i == 1:
            t = abs(w1)
        else:
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


@jit
def rotation_matrix(w0, w1, w2, h, R):
    """Fill R so that ``x_row @ R`` turns x by −|ω|·h about ω (program form).

    R = P + cos θ·(E − P) + sin θ·[ω]× / |ω|, P = ωωᵀ/(|ω|·|ω|), θ = |ω|·h.
    Returns False (R untouched) when ω = 0, or when |ω| < 1.5e-154 so that
    |ω|² underflows to 0: the program then divides 0 by 0 and its state turns
    NaN; the turn, |ω|·dt, is below 1e-150 rad, so "no turn" is exact to
    machine precision (found by hypothesis: L = (0, 0, 3.7e-293)).
    """
    n = norm3(w0, w1, w2)
    n2 = n * n
    if n2 == 0.0:
        return False
    th = n * h
    c = math.cos(th)
    s = math.sin(th)
    w = (w0, w1, w2)
    for a in range(3):
        for b in range(3):
            p = w[a] * w[b] / n2
            e = 1.0 if a == b else 0.0
            if a == b:
                wx = 0.0
            elif a == 0 and b == 1:
                wx = -w2
            elif a == 0 and b == 2:
                wx = w1
            elif a == 1 and b == 0:
                wx = w2
            elif a == 1 and b == 2:
                wx = -w0
            elif a == 2 and b == 0:
                wx = -w1
            else:
                wx = w0
            R[a, b] = (p + c * (e - p)) + s * wx / n
    return True


@jit
def apply_rotation(off, R):
    """off[k] ← off[k] (row) · R, each component (x0R0j + x1R1j) + x2R2j."""
    for k in range(8):
        x0 = off[k, 0]
        x1 = off[k, 1]
        x2 = off[k, 2]
        for j in range(3):
            off[k, j] = (x0 * R[0, j] + x1 * R[1, j]) + x2 * R[2, j]


@jit
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


@jit
def node_velocities(U, off, w0, w1, w2, uk):
    """u_k = U + x_k × ω (program convention)."""
    for k in range(8):
        x0 = off[k, 0]
        x1 = off[k, 1]
        x2 = off[k, 2]
        uk[k, 0] = U[0] + (x1 * w2 - x2 * w1)
        uk[k, 1] = U[1] + (x2 * w0 - x0 * w2)
        uk[k, 2] = U[2] + (x0 * w1 - x1 * w0)


@jit
def contact_forces(z, uk, kp, F, P):
    """Ground forces on every node from heights z and velocities uk.

    Normal plus damping P_k = k·d_k·(1 − γ·u_z,k), d_k = max(0, −z_k): signed
    in the program (``clamp_normal = 0``), clamped at 0 otherwise.  Friction:
    program (spectral): F_xy = −μ·(P_k·(u_xy,k/σ)), σ the largest singular
    value of the 8×2 horizontal-velocity matrix (closed form via its 2×2 Gram
    matrix; see docs/model.md §5.5 on LAPACK's last bits); per-node (physical):
    F_xy = −μ·P_k·u_xy,k / sqrt(|u_xy,k|² + v_reg²).
    """
    k_ = kp.k
    gam = kp.gamma
    clamp = kp.clamp_normal
    for k in range(8):
        d = max(0.0, -z[k])
        p = k_ * d * (1.0 - gam * uk[k, 2])
        if clamp and p < 0.0:
            p = 0.0
        P[k] = p
        F[k, 2] = p
    friction_forces(uk, kp, F, P)


@jit
def spectral_norm_xy(uk):
    """Largest singular value σ of the 8×2 matrix of horizontal node velocities.

    Closed form through the 2×2 Gram matrix [[a, b], [b, c]]:
    σ = sqrt((a + c)/2 + sqrt(((a − c)/2)² + b²)), sums node 1 → 8.
    """
    a = 0.0
    b = 0.0
    c = 0.0
    for k in range(8):
        a += uk[k, 0] * uk[k, 0]
        b += uk[k, 0] * uk[k, 1]
        c += uk[k, 1] * uk[k, 1]
    hd = (a - c) / 2.0
    return math.sqrt((a + c) / 2.0 + math.sqrt(hd * hd + b * b))


def _friction_forces(uk, kp, F, P):
    """Horizontal friction F_xy from velocities uk and the normal forces P (see contact_forces)."""
    mu = kp.mu
    if kp.friction_mode == FRICTION_SPECTRAL:
        sig = spectral_norm_xy(uk)
        if sig == 0.0:
            for k in range(8):
                F[k, 0] = 0.0
                F[k, 1] = 0.0
        else:
            for k in range(8):
                F[k, 0] = -mu * (P[k] * (uk[k, 0] / sig))
                F[k, 1] = -mu * (P[k] * (uk[k, 1] / sig))
    else:
        vr2 = kp.v_reg_cm_s * kp.v_reg_cm_s
        for k in range(8):
            if P[k] == 0.0:
                F[k, 0] = 0.0
                F[k, 1] = 0.0
            else:
                s = math.sqrt(uk[k, 0] * uk[k, 0] + uk[k, 1] * uk[k, 1] + vr2)
                F[k, 0] = -mu * P[k] * uk[k, 0] / s
                F[k, 1] = -mu * P[k] * uk[k, 1] / s


#: ``_friction_forces`` compiled as a call (general loop) and inlined at numba
#: IR level (the RK4 sub-steps of ``schemes``, where the call costs ~35 %).
friction_forces = jit(_friction_forces)
friction_forces_inline = jit(inline="always")(_friction_forces)


@jit
def energy_stop(uk, z, P, kp):
    """The program's stop-test energy (point-mass kinetic energy).

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


@jit
def energy_parts(U, w0, w1, w2, z, kp, out):
    """Energies with the inertia the dynamics use, node-mass·cm²/s².

    out = (translational kinetic ½·8|U|², rotational kinetic ½·I|ω|²,
    gravitational Σ|g|·z_k, elastic ½·k·Σd_k², total).
    """
    et = 0.5 * 8.0 * (U[0] * U[0] + U[1] * U[1] + U[2] * U[2])
    er = 0.5 * kp.inertia * (w0 * w0 + w1 * w1 + w2 * w2)
    eg = 0.0
    el = 0.0
    for k in range(8):
        eg += -kp.g * z[k]
        d = max(0.0, -z[k])
        el += d * d
    el *= 0.5 * kp.k
    out[0] = et
    out[1] = er
    out[2] = eg
    out[3] = el
    out[4] = et + er + eg + el


@jit
def energy_dynamic(U, w0, w1, w2, z, kp):
    """Total mechanical energy with the dynamics' inertia (for the blow-up test)."""
    e = 0.5 * 8.0 * (U[0] * U[0] + U[1] * U[1] + U[2] * U[2])
    e += 0.5 * kp.inertia * (w0 * w0 + w1 * w1 + w2 * w2)
    el = 0.0
    for k in range(8):
        e += -kp.g * z[k]
        d = max(0.0, -z[k])
        el += d * d
    return e + 0.5 * kp.k * el


@jit
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
def face_up(z):
    """Face value (1..6) of the four highest nodes, 0 when they are no face."""
    return FACE_OF_TOP4[top4_mask(z)]
