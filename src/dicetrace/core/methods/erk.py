"""Embedded explicit Runge–Kutta pairs on the die's state with a unit quaternion (docs/model.md §9).

The sub-step methods of the contact schemes ``contact_dop853`` (DOP853,
order 8) and ``contact_tsit5`` (Tsitouras 5(4)).  The state of a sub-step is y = (X, U, L, q) ∈ R¹³: centre of mass,
velocity, angular momentum (program convention) and a quaternion q that
rotates the sub-step's starting node offsets, q = 1 at the start::

    X' = U     U' = g·ẑ + Σ_k F_k / 8     L' = τ = Σ_k F_k × x_k
    q' = ½·(0, ω)·q,  ω = −I⁻¹·L (physical, world frame)   x_k = R(q/|q|)·x_k(0)

with I⁻¹ the cube's 1 / I, or a box's or loaded die's R·I_b⁻¹·Rᵀ at the
stage's orientation R = R(q)·R_s (R_s the sub-step start's, :func:`stage_omega`).

The quaternion's flow keeps |q| = 1 exactly, so any Runge–Kutta tableau
integrates it at its full order; the stages read R(q/|q|), and the accepted
step normalises q (a projection, which keeps the order) and sets the
offsets to R(q)·x_k(0): the die stays rigid to rounding whatever the error
of the step.  :func:`erk_substep` builds the sub-step of a
tableau: ns stages, a, b (the system is autonomous: no nodes c), closed
over so that they compile in as constants; :func:`erk_error1` and
:func:`erk_error2` the error estimates on its error weights (ns + 1
entries: the last weighs the derivative at the new state, which the driver
evaluates anyway as the next sub-step's first stage).  Error norm ``common.error_norm``, as
contact-adaptive's (position over the half side, velocity over
``error_speed``), with the rotation's error counted as the node
displacement it causes: :func:`erk_error1` for a pair with one
estimate e = b − b̂ (Tsit5), :func:`erk_error2` for DOP853's two
(e5, e3), combined as DOP853 does (Hairer, Nørsett & Wanner,
*Solving ODEs I*, II.10): err = e₅² / √(e₅² + 0.01·e₃²).
"""

from __future__ import annotations

import math

import numpy as np

from dicetrace.core._jit import gpu_fence, jit
from dicetrace.core.forces import acceleration, moment, node_friction, normal_force, wrench_at
from dicetrace.core.inertia import omega_in, orientation
from dicetrace.core.model import offset_cross_omega
from dicetrace.core.methods.common import error_norm, error_speed
from dicetrace.params import FRICTION_SPECTRAL

#: Components of the sub-step state y = (X, U, L, q).
NY = 13
ZERO = np.zeros(NY)

#: DOP853 (Hairer, Nørsett & Wanner), the coefficients as tabulated in scipy.integrate._ivp.dop853_coefficients.
DOP853_STAGES = 12
DOP853_A = np.array([
    [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
    [0.05260015195876773, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
    [0.0197250569845379, 0.0591751709536137, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
    [0.02958758547680685, 0.0, 0.08876275643042054, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
    [0.2413651341592667, 0.0, -0.8845494793282861, 0.924834003261792, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
    [0.037037037037037035, 0.0, 0.0, 0.17082860872947386, 0.12546768756682242, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
    [0.037109375, 0.0, 0.0, 0.17025221101954405, 0.06021653898045596, -0.017578125, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
    [0.03709200011850479, 0.0, 0.0, 0.17038392571223998, 0.10726203044637328, -0.015319437748624402, 0.008273789163814023, 0.0, 0.0, 0.0, 0.0, 0.0],
    [0.6241109587160757, 0.0, 0.0, -3.3608926294469414, -0.868219346841726, 27.59209969944671, 20.154067550477894, -43.48988418106996, 0.0, 0.0, 0.0, 0.0],
    [0.47766253643826434, 0.0, 0.0, -2.4881146199716677, -0.590290826836843, 21.230051448181193, 15.279233632882423, -33.28821096898486, -0.020331201708508627, 0.0, 0.0, 0.0],
    [-0.9371424300859873, 0.0, 0.0, 5.186372428844064, 1.0914373489967295, -8.149787010746927, -18.52006565999696, 22.739487099350505, 2.4936055526796523, -3.0467644718982196, 0.0, 0.0],
    [2.273310147516538, 0.0, 0.0, -10.53449546673725, -2.0008720582248625, -17.9589318631188, 27.94888452941996, -2.8589982771350235, -8.87285693353063, 12.360567175794303, 0.6433927460157636, 0.0],
])
DOP853_B = np.array([0.054293734116568765, 0.0, 0.0, 0.0, 0.0, 4.450312892752409, 1.8915178993145003, -5.801203960010585, 0.3111643669578199, -0.1521609496625161, 0.20136540080403034, 0.04471061572777259])
DOP853_E5 = np.array([0.01312004499419488, 0.0, 0.0, 0.0, 0.0, -1.2251564463762044, -0.4957589496572502, 1.6643771824549864, -0.35032884874997366, 0.3341791187130175, 0.08192320648511571, -0.022355307863886294, 0.0])
DOP853_E3 = np.array([-0.18980075407240762, 0.0, 0.0, 0.0, 0.0, 4.450312892752409, 1.8915178993145003, -5.801203960010585, -0.4226823213237919, -0.1521609496625161, 0.20136540080403034, 0.02265179219836082, 0.0])


#: Tsitouras' 5(4) pair (Ch. Tsitouras, "Runge–Kutta pairs of order 5(4) satisfying only the first
#: column simplifying assumption", Comput. Math. Appl. 62 (2011) 770–775), the coefficients as
#: tabulated in OrdinaryDiffEq.jl and diffrax.  Six stages per step; the seventh (A₇ = B) is the
#: derivative at the new state (first same as last).  TSIT5_E = b − b̂ on the seven stages.
TSIT5_STAGES = 6
TSIT5_A = np.array([
    [0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
    [0.161, 0.0, 0.0, 0.0, 0.0, 0.0],
    [-0.008480655492356989, 0.335480655492357, 0.0, 0.0, 0.0, 0.0],
    [2.8971530571054935, -6.359448489975075, 4.3622954328695815, 0.0, 0.0, 0.0],
    [5.325864828439257, -11.748883564062828, 7.4955393428898365, -0.09249506636175525, 0.0, 0.0],
    [5.86145544294642, -12.92096931784711, 8.159367898576159, -0.071584973281401, -0.028269050394068383, 0.0],
])
TSIT5_B = np.array([0.09646076681806523, 0.01, 0.4798896504144996, 1.379008574103742, -3.290069515436081, 2.324710524099774])
TSIT5_E = np.array([
    0.001780011052226, 0.000816434459657, -0.007880878010262, 0.144711007173263,
    -0.582357165452555, 0.458082105929187, -1.0 / 66.0,
])

#: Tsit5's continuous extension (order 4, Tsitouras 2011; the expanded coefficients as
#: OrdinaryDiffEq.jl tabulates them): the state at θ·h into a step is y0 + h·Σ b_i(θ)·k_i over
#: the seven stages, b_i(θ) = θ·(R[i,0] + θ·(R[i,1] + θ·(R[i,2] + θ·R[i,3]))); b_i(1) = B_i
#: (b_7(1) = 0), so θ = 1 is the step's own result.
TSIT5_DENSE = np.array([
    [1.0, -2.763706197274826, 2.9132554618219126, -1.0530884977290216],
    [0.0, 0.13169999999999998, -0.2234, 0.1017],
    [0.0, 3.9302962368947516, -5.941033872131505, 2.490627285651253],
    [0.0, -12.411077166933676, 30.33818863028232, -16.548102889244902],
    [0.0, 37.50931341651104, -88.1789048947664, 47.37952196281928],
    [0.0, -27.896526289197286, 65.09189467479366, -34.87065786149661],
    [0.0, 1.5, -4.0, 2.5],
])


@jit(inline="always")
def quat_matrix(q0, q1, q2, q3):
    """R(q/|q|) as its nine entries row by row (q = (w, x, y, z), any non-zero norm)."""
    n = q0 * q0 + q1 * q1 + q2 * q2 + q3 * q3
    s = 2.0 / n
    r00 = 1.0 - s * (q2 * q2 + q3 * q3)
    r01 = s * (q1 * q2 - q0 * q3)
    r02 = s * (q1 * q3 + q0 * q2)
    r10 = s * (q1 * q2 + q0 * q3)
    r11 = 1.0 - s * (q1 * q1 + q3 * q3)
    r12 = s * (q2 * q3 - q0 * q1)
    r20 = s * (q1 * q3 - q0 * q2)
    r21 = s * (q2 * q3 + q0 * q1)
    r22 = 1.0 - s * (q1 * q1 + q2 * q2)
    return r00, r01, r02, r10, r11, r12, r20, r21, r22


@jit(inline="always")
def quat_rotate(q0, q1, q2, q3, off, out):
    """out_k = R(q/|q|)·off_k for the eight nodes (q = (w, x, y, z), any non-zero norm)."""
    r00, r01, r02, r10, r11, r12, r20, r21, r22 = quat_matrix(q0, q1, q2, q3)
    for k in range(8):
        a = off[k, 0]
        b = off[k, 1]
        c = off[k, 2]
        out[k, 0] = r00 * a + r01 * b + r02 * c
        out[k, 1] = r10 * a + r11 * b + r12 * c
        out[k, 2] = r20 * a + r21 * b + r22 * c


@jit(inline="always")
def stage_omega(y, off, kp):
    """ω (program convention) at the stage point y of a sub-step that starts at the offsets ``off``: the cube's L / I;
    any other body's R·I_b⁻¹·Rᵀ·L with its orientation there R = R(q)·R_s (``inertia``)."""
    if kp.isotropic:
        I = kp.inertia
        return y[6] / I, y[7] / I, y[8] / I
    return body_stage_omega(y, off, kp)


@jit
def body_stage_omega(y, off, kp):
    """ω = R·I_b⁻¹·Rᵀ·L at the stage point y of a body that is not the uniform cube (:func:`stage_omega`), out of
    line for the compile time as ``inertia.body_omega`` is; the cube never calls it."""
    a00, a01, a02, a10, a11, a12, a20, a21, a22 = quat_matrix(y[9], y[10], y[11], y[12])
    s00, s01, s02, s10, s11, s12, s20, s21, s22 = orientation(off, kp)
    R = (a00 * s00 + a01 * s10 + a02 * s20, a00 * s01 + a01 * s11 + a02 * s21, a00 * s02 + a01 * s12 + a02 * s22,
         a10 * s00 + a11 * s10 + a12 * s20, a10 * s01 + a11 * s11 + a12 * s21, a10 * s02 + a11 * s12 + a12 * s22,
         a20 * s00 + a21 * s10 + a22 * s20, a20 * s01 + a21 * s11 + a22 * s21, a20 * s02 + a21 * s12 + a22 * s22)
    return omega_in(y[6], y[7], y[8], R, kp)


@jit(inline="always")
def stage_wrench(y, off, kp, offs, F, uk, z, P, w0, w1, w2):
    """Contact force sum and torque at the stage point y (sums from 0.0 over the nodes with a force); ω there
    (``w*``, :func:`stage_omega`).

    What ``quat_rotate`` then ``forces.wrench_at`` give, in the same
    arithmetic, bit for bit, for the per-node friction law: a node's height
    needs only the third row of R, so the other two rows are applied only to
    the nodes below the ground (at most four of eight, mostly one or two),
    and their velocities, forces and moments are summed as they are found
    (node 1 → 8), never stored.  The program's spectral law couples every
    node's velocity (σ): it goes through ``wrench_at`` with all offsets.
    """
    q0 = y[9]
    q1 = y[10]
    q2 = y[11]
    q3 = y[12]
    if kp.friction_mode == FRICTION_SPECTRAL:
        quat_rotate(q0, q1, q2, q3, off, offs)
        below, f0, f1, f2, t0, t1, t2 = wrench_at(y[2], y[3], y[4], y[5], w0, w1, w2, offs, kp, F, uk, z, P)
        return f0, f1, f2, t0, t1, t2
    r00, r01, r02, r10, r11, r12, r20, r21, r22 = quat_matrix(q0, q1, q2, q3)
    Xz = y[2]
    f0 = f1 = f2 = t0 = t1 = t2 = 0.0
    for k in range(8):
        a = off[k, 0]
        b = off[k, 1]
        c = off[k, 2]
        x2 = r20 * a + r21 * b + r22 * c
        zk = Xz + x2
        if not zk < 0.0:
            continue
        x0 = r00 * a + r01 * b + r02 * c
        x1 = r10 * a + r11 * b + r12 * c
        c0, c1, c2 = offset_cross_omega(x0, x1, x2, w0, w1, w2)
        u0 = y[3] + c0
        u1 = y[4] + c1
        u2 = y[5] + c2
        p = normal_force(zk, u2, kp)
        if p == 0.0:
            continue
        a0, a1 = node_friction(p, u0, u1, kp)
        c0, c1, c2 = moment(a0, a1, p, x0, x1, x2)
        f0 += a0
        f1 += a1
        f2 += p
        t0 += c0
        t1 += c1
        t2 += c2
    return f0, f1, f2, t0, t1, t2


@jit(inline="always")
def derivative_row(K, i, y, f0, f1, f2, t0, t1, t2, w0, w1, w2, kp):
    """Row i of the stage derivatives K at the point y, with force sum f, torque t and ω (program convention,
    :func:`stage_omega`) there."""
    a0, a1, a2 = acceleration(f0, f1, f2, kp)
    K[i, 0] = y[3]
    K[i, 1] = y[4]
    K[i, 2] = y[5]
    K[i, 3] = a0
    K[i, 4] = a1
    K[i, 5] = a2
    K[i, 6] = t0
    K[i, 7] = t1
    K[i, 8] = t2
    # q' = ½·(0, ω)·q with the physical ω, minus the program's
    w0 = -w0
    w1 = -w1
    w2 = -w2
    qw = y[9]
    qx = y[10]
    qy = y[11]
    qz = y[12]
    K[i, 9] = -0.5 * (w0 * qx + w1 * qy + w2 * qz)
    K[i, 10] = 0.5 * (qw * w0 + (w1 * qz - w2 * qy))
    K[i, 11] = 0.5 * (qw * w1 + (w2 * qx - w0 * qz))
    K[i, 12] = 0.5 * (qw * w2 + (w0 * qy - w1 * qx))


@jit(inline="always")
def combine(w, n, K, y0, h, y):
    """y = y0 + h·Σ_{j<n} w_j·K_j (zero weights skipped).

    The 13 sums are kept in scalars: accumulating into an array would go
    through memory at every term (the work arrays share one record, so the
    compiler cannot keep them in registers), which cost ~2/3 of a sub-step.
    """
    a0 = a1 = a2 = a3 = a4 = a5 = a6 = a7 = a8 = a9 = a10 = a11 = a12 = 0.0
    for j in range(n):
        a = w[j]
        if a != 0.0:
            a0 += a * K[j, 0]
            a1 += a * K[j, 1]
            a2 += a * K[j, 2]
            a3 += a * K[j, 3]
            a4 += a * K[j, 4]
            a5 += a * K[j, 5]
            a6 += a * K[j, 6]
            a7 += a * K[j, 7]
            a8 += a * K[j, 8]
            a9 += a * K[j, 9]
            a10 += a * K[j, 10]
            a11 += a * K[j, 11]
            a12 += a * K[j, 12]
    y[0] = y0[0] + h * a0
    y[1] = y0[1] + h * a1
    y[2] = y0[2] + h * a2
    y[3] = y0[3] + h * a3
    y[4] = y0[4] + h * a4
    y[5] = y0[5] + h * a5
    y[6] = y0[6] + h * a6
    y[7] = y0[7] + h * a7
    y[8] = y0[8] + h * a8
    y[9] = y0[9] + h * a9
    y[10] = y0[10] + h * a10
    y[11] = y0[11] + h * a11
    y[12] = y0[12] + h * a12


@jit(inline="always")
def substep_start(wk, y0):
    """y0 = (X, U, L, q = 1) from the sub-step start ``wk.sub_*``."""
    for j in range(3):
        y0[j] = wk.sub_X[j]
        y0[3 + j] = wk.sub_U[j]
        y0[6 + j] = wk.sub_L[j]
    y0[9] = 1.0
    y0[10] = 0.0
    y0[11] = 0.0
    y0[12] = 0.0


@jit(inline="always")
def substep_end(wk, y):
    """``wk.new_*`` from the step's result y: q normalised (in y), the offsets turned exactly by it."""
    qn = math.sqrt(y[9] * y[9] + y[10] * y[10] + y[11] * y[11] + y[12] * y[12])
    for c in range(9, NY):
        y[c] = y[c] / qn
    for j in range(3):
        wk.new_X[j] = y[j]
        wk.new_U[j] = y[3 + j]
        wk.new_L[j] = y[6 + j]
    quat_rotate(y[9], y[10], y[11], y[12], wk.sub_off, wk.new_off)


@jit(inline="always")
def state_error_norm(e, vs, kp):
    """``common.error_norm`` of an error vector e of y = (X, U, L, q) (Euclidean norm of each part; ω's as |e_L| / I)."""
    sx = e[0] * e[0] + e[1] * e[1] + e[2] * e[2]
    su = e[3] * e[3] + e[4] * e[4] + e[5] * e[5]
    sl = e[6] * e[6] + e[7] * e[7] + e[8] * e[8]
    sq = e[9] * e[9] + e[10] * e[10] + e[11] * e[11] + e[12] * e[12]
    return error_norm(math.sqrt(sx), math.sqrt(sq), math.sqrt(su), math.sqrt(sl) / kp.inertia, vs, kp)


def _named(fn, name: str, doc: str):
    fn.__name__ = fn.__qualname__ = name
    fn.__doc__ = doc
    return jit(fn)


def erk_substep(name: str, ns: int, a: np.ndarray, b: np.ndarray):
    """The sub-step of the tableau (``ns`` stages, ``a``, ``b``), compiled as ``name``.

    ``substep(st, wk, kp, h, f0, f1, f2, t0, t1, t2)``: one step from the
    sub-step start ``wk.sub_*`` to ``wk.new_*``; ``f*``, ``t*`` the contact
    force sum and torque at the start.  Leaves the stage derivatives in
    ``wk.rk_k`` (rows 0..ns−1) and the new state y in ``wk.rk_y`` (q
    normalised) for the error estimate (which overwrites ``wk.rk_y0`` and
    ``wk.rk_acc``).  The tableau is closed over, so numba compiles it in as
    constants.  On a GPU the stages are read back from the work record
    after each one (``_jit.gpu_fence``), not kept in registers.
    """

    def substep(st, wk, kp, h, f0, f1, f2, t0, t1, t2):
        K = wk.rk_k
        y = wk.rk_y
        y0 = wk.rk_y0
        off = wk.sub_off
        offs = wk.stage_off
        substep_start(wk, y0)
        w0, w1, w2 = stage_omega(y0, off, kp)
        derivative_row(K, 0, y0, f0, f1, f2, t0, t1, t2, w0, w1, w2, kp)
        gpu_fence()  # on a GPU each stage reads the stages before it from the work record again (``core._jit``)
        for i in range(1, ns):
            combine(a[i], i, K, y0, h, y)
            w0, w1, w2 = stage_omega(y, off, kp)
            g0, g1, g2, q0, q1, q2 = stage_wrench(y, off, kp, offs, st.F, st.uk, st.z, st.P, w0, w1, w2)
            derivative_row(K, i, y, g0, g1, g2, q0, q1, q2, w0, w1, w2, kp)
            gpu_fence()
        combine(b, ns, K, y0, h, y)
        substep_end(wk, y)
        gpu_fence()

    return _named(substep, name, erk_substep.__doc__)


def erk_error2(name: str, ns: int, e5: np.ndarray, e3: np.ndarray):
    """The error estimate of a pair with two embedded estimates (DOP853's ``e5``, ``e3``), compiled as ``name``.

    ``error(st, wk, kp, h, g0, g1, g2, q0, q1, q2)``: the local error of the last
    sub-step over ``kp.tol``; g, q the force sum and torque at the new state.
    """

    def error(st, wk, kp, h, g0, g1, g2, q0, q1, q2):
        K = wk.rk_k
        y = wk.rk_y
        w0, w1, w2 = stage_omega(y, wk.sub_off, kp)  # y: the new state, q from the sub-step start
        derivative_row(K, ns, y, g0, g1, g2, q0, q1, q2, w0, w1, w2, kp)
        err5 = wk.rk_acc
        err3 = wk.rk_y0  # the sub-step start is no longer needed
        combine(e5, ns + 1, K, ZERO, 1.0, err5)
        gpu_fence()  # on a GPU the second estimate reads the stages again (``core._jit``)
        combine(e3, ns + 1, K, ZERO, 1.0, err3)
        vs = error_speed(wk.new_U, wk.new_L, kp)
        k5 = state_error_norm(err5, vs, kp)
        k3 = state_error_norm(err3, vs, kp)
        r5 = abs(h) * k5
        r3 = abs(h) * k3
        if r5 == 0.0:
            return 0.0
        return r5 * r5 / math.sqrt(r5 * r5 + 0.01 * r3 * r3) / kp.tol

    return _named(error, name, erk_error2.__doc__)


def erk_error1(name: str, ns: int, e: np.ndarray):
    """The error estimate of a pair with one embedded estimate, e = b − b̂ (ns + 1 entries), compiled as ``name``.

    ``error(st, wk, kp, h, g0, g1, g2, q0, q1, q2)``: the local error of the last
    sub-step over ``kp.tol``.
    """

    def error(st, wk, kp, h, g0, g1, g2, q0, q1, q2):
        K = wk.rk_k
        y = wk.rk_y
        w0, w1, w2 = stage_omega(y, wk.sub_off, kp)  # y: the new state, q from the sub-step start
        derivative_row(K, ns, y, g0, g1, g2, q0, q1, q2, w0, w1, w2, kp)
        err = wk.rk_acc
        combine(e, ns + 1, K, ZERO, 1.0, err)
        vs = error_speed(wk.new_U, wk.new_L, kp)
        return abs(h) * state_error_norm(err, vs, kp) / kp.tol

    return _named(error, name, erk_error1.__doc__)


def erk_work(ns: int) -> list:
    """The work area of a pair of ``ns`` stages (besides the sub-step start and end, ``core.state``): the stage
    derivatives (ns + 1 rows: the last the derivative at the new state), the stage point, the sub-step's start and
    a weighted sum of stages (13 components each), and a stage's node offsets."""
    return [
        ("rk_k", np.float64, (ns + 1, NY)),
        ("rk_y", np.float64, NY),
        ("rk_y0", np.float64, NY),
        ("rk_acc", np.float64, NY),
        ("stage_off", np.float64, (8, 3)),
    ]


#: Tsit5's dense output keeps the starting offsets of the sub-step the step ends in, and the interpolation weights.
TSIT5_DENSE_WORK = [("dn_off", np.float64, (8, 3)), ("dn_w", np.float64, TSIT5_STAGES + 1)]

#: DOP853's sub-step and its error estimate (order 8; the estimate's exponent 1/8).
dop853_substep = erk_substep("dop853_substep", DOP853_STAGES, DOP853_A, DOP853_B)
dop853_error = erk_error2("dop853_error", DOP853_STAGES, DOP853_E5, DOP853_E3)

#: Tsit5's sub-step and its error estimate (order 5, estimate of order 4: the exponent 1/5).
tsit5_substep = erk_substep("tsit5_substep", TSIT5_STAGES, TSIT5_A, TSIT5_B)
tsit5_error = erk_error1("tsit5_error", TSIT5_STAGES, TSIT5_E)


@jit(inline="always")
def dense_keep(st, wk, h):
    """Keep what :func:`dense_state` needs of the sub-step just computed (length h) besides its stages.

    The stages stay in ``wk.rk_k`` (row 6: the derivative at the new state,
    from the error estimate) and the start in ``wk.rk_y0`` until the next
    sub-step; its starting offsets ``wk.sub_off`` are copied.
    """
    for k in range(8):
        for j in range(3):
            wk.dn_off[k, j] = wk.sub_off[k, j]
    wk.dn_h = h


@jit(inline="always")
def dense_state(st, wk, kp, theta):
    """X, U, L, ω and the offsets of ``st`` at θ·h into the kept sub-step (Tsit5's continuous extension).

    The quaternion is normalised and the offsets are its exact rotation of
    the sub-step's starting ones: the die stays rigid to rounding.  With
    ``st.lazy`` (a run loop that reads only the node heights at a step's
    end) only the offsets' z components are turned; the next step goes on
    from the front, never from these offsets.
    """
    w = wk.dn_w
    for i in range(TSIT5_STAGES + 1):
        w[i] = theta * (TSIT5_DENSE[i, 0] + theta * (TSIT5_DENSE[i, 1] + theta * (
            TSIT5_DENSE[i, 2] + theta * TSIT5_DENSE[i, 3])))
    y = wk.rk_acc
    combine(w, TSIT5_STAGES + 1, wk.rk_k, wk.rk_y0, wk.dn_h, y)
    qn = math.sqrt(y[9] * y[9] + y[10] * y[10] + y[11] * y[11] + y[12] * y[12])
    for j in range(3):
        st.X[j] = y[j]
        st.U[j] = y[3 + j]
        st.L[j] = y[6 + j]
    if kp.isotropic:
        for j in range(3):
            st.W[j] = y[6 + j] / kp.inertia
    else:  # ω at the interpolated orientation (not lazy: ``loop.make_roll`` reads every offset of such a body)
        st.W[0], st.W[1], st.W[2] = stage_omega(y, wk.dn_off, kp)
    if st.lazy:
        # only the heights are read at this step end: the offsets' third row (the rest of R unused)
        r = quat_matrix(y[9] / qn, y[10] / qn, y[11] / qn, y[12] / qn)
        r20, r21, r22 = r[6], r[7], r[8]
        off = wk.dn_off
        for k in range(8):
            st.off[k, 2] = r20 * off[k, 0] + r21 * off[k, 1] + r22 * off[k, 2]
    else:
        quat_rotate(y[9] / qn, y[10] / qn, y[11] / qn, y[12] / qn, wk.dn_off, st.off)
    st.rot_h = -1.0
