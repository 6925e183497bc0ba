"""The ground force law (docs/model.md §4) is written once: every kernel path gives the same forces.

Paths that evaluate contact forces: ``forces.contact_forces`` on given
heights and velocities; ``forces.forces_at`` (the RK4 stages: scalar U and
ω); ``forces.eval_forces`` (the end of every step, on a state record); the
seed kernel's ``fast.forces_mirror`` (velocities of nodes 1..4 mirrored);
and the forces that each integrator's run loop records in a trace.  On
random states of both presets (nodes below and above the ground, nodes
rising faster than 1/γ, zero horizontal velocity, overflowing velocities)
they agree bit for bit with each other, and in value with a plain-Python
transcription of docs/model.md §4.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

from dicetrace.core import fast
from dicetrace.core.forces import contact_forces, eval_forces, forces_at, wrench_at
from dicetrace.core.model import node_heights, node_velocities
from dicetrace.core.schemes import step_of
from dicetrace.core.state import new_states
from dicetrace.ics import seed_slice
from dicetrace.integrators import INTEGRATORS
from dicetrace.params import FRICTION_SPECTRAL, NODE_SIGNS, convert_l, make_config
from dicetrace.simulate import Record, simulate

PRESETS = ("seed", "physical")
KP = {p: make_config(p).kernel_params() for p in PRESETS}


def reference_forces(z, uk, kp):
    """docs/model.md §4 in plain Python floats, in the documented order."""
    z, uk = np.asarray(z).tolist(), np.asarray(uk).tolist()
    P = []
    for k in range(8):
        d = max(0.0, -z[k])
        p = kp.k * d * (1.0 - kp.gamma * uk[k][2])
        if kp.clamp_normal and p < 0.0:
            p = 0.0
        P.append(p)
    F = [[0.0, 0.0, P[k]] for k in range(8)]
    if kp.friction_mode == FRICTION_SPECTRAL:
        a = b = c = 0.0
        for k in range(8):
            a += uk[k][0] * uk[k][0]
            b += uk[k][0] * uk[k][1]
            c += uk[k][1] * uk[k][1]
        hd = (a - c) / 2.0
        sig = math.sqrt((a + c) / 2.0 + math.sqrt(hd * hd + b * b))
        if sig != 0.0:
            for k in range(8):
                F[k][0] = -kp.mu * (P[k] * (uk[k][0] / sig))
                F[k][1] = -kp.mu * (P[k] * (uk[k][1] / sig))
    else:
        for k in range(8):
            if P[k] != 0.0:
                s = math.sqrt(uk[k][0] * uk[k][0] + uk[k][1] * uk[k][1] + kp.v_reg_cm_s * kp.v_reg_cm_s)
                F[k][0] = -kp.mu * P[k] * uk[k][0] / s
                F[k][1] = -kp.mu * P[k] * uk[k][1] / s
    return np.array(F), np.array(P)


def mirror_offsets(rotvec, half=1.0):
    """Cube offsets turned by a rotation vector, node 8−k exactly node k+1 negated."""
    from scipy.spatial.transform import Rotation

    rot = Rotation.from_rotvec(rotvec).as_matrix()
    off = np.empty((8, 3))
    for k in range(4):
        off[k] = (NODE_SIGNS[k] * half) @ rot.T
        off[7 - k] = -off[k]
    return off


def bits(a):
    return np.ascontiguousarray(a, dtype=np.float64).view(np.int64)


speed = st.one_of(st.just(0.0), st.floats(-500.0, 500.0), st.floats(-1e200, 1e200))
spin = st.one_of(st.just(0.0), st.floats(-300.0, 300.0))
states = st.tuples(
    st.sampled_from(PRESETS),
    st.floats(-0.3, 1.9),  # CM height: from all corners buried to all clear
    st.tuples(speed, speed, speed),
    st.tuples(spin, spin, spin),
    st.tuples(*(st.floats(-math.pi, math.pi),) * 3),
)


@pytest.mark.slow  # a thousand random states through every path: about 2.5 s
@settings(max_examples=1000, deadline=None)
@given(states)
@example(("seed", 0.99, (0.0, 0.0, 300.0), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0)))  # flat, rising: P < 0 in seed
@example(("physical", 0.99, (0.0, 0.0, 300.0), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0)))  # ... clamped in physical
@example(("seed", 0.98, (0.0, 0.0, -100.0), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0)))  # no horizontal velocity: σ = 0
@example(("seed", 0.9, (1e200, -1e200, 0.0), (0.0, 0.0, 0.0), (0.1, 0.2, 0.3)))  # σ overflows
@example(("physical", 1.5, (10.0, 0.0, -1.0), (5.0, 0.0, 0.0), (0.3, 0.0, 0.0)))  # in the air
@example(("seed", 0.0, (0.0, 0.0, -0.0), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0)))  # a -0 velocity
def test_every_path_gives_the_same_forces(case):
    preset, xz, U, W, rotvec = case
    kp = KP[preset]
    off = mirror_offsets(rotvec, kp.half_side_cm)
    z = np.empty(8)
    uk = np.zeros((8, 3))
    below, mask = node_heights(xz, off, z)
    node_velocities(*U, *W, off, uk)

    # the law on given heights and velocities
    F1, P1 = np.zeros((8, 3)), np.zeros(8)
    live = contact_forces(z, uk, kp, F1, P1)
    Fr, Pr = reference_forces(z, uk, kp)
    np.testing.assert_array_equal(P1, Pr)
    np.testing.assert_array_equal(F1, Fr)
    for k in range(8):
        if not (live >> k) & 1:
            assert F1[k, 0] == 0.0 and F1[k, 1] == 0.0 and P1[k] == 0.0

    # the RK4 stages (scalar U and ω) and the seed kernel (mirrored velocities)
    for path in (forces_at, fast.forces_mirror):
        F2, uk2, z2, P2 = np.zeros((8, 3)), np.zeros((8, 3)), np.zeros(8), np.zeros(8)
        if path is fast.forces_mirror and any(math.copysign(1.0, u) < 0 and u == 0.0 for u in U):
            # U − (x × ω) equals U + ((−x) × ω) unless U is −0 (then the two zeros may differ
            # in sign); the seed kernel never sees −0 there: every step adds +0 or more to U
            continue
        b2, m2, live2 = path(xz, *U, *W, off, kp, F2, uk2, z2, P2)
        assert (b2, m2) == (below, mask)
        np.testing.assert_array_equal(bits(z2), bits(z))
        if below:
            assert live2 == live
            np.testing.assert_array_equal(bits(uk2), bits(uk))
            np.testing.assert_array_equal(bits(P2), bits(P1))
            np.testing.assert_array_equal(bits(F2), bits(F1))

    # the end of every step, on a state record
    S = new_states(1)
    S["X"][0] = (0.3, -0.2, xz)
    S["U"][0] = U
    S["W"][0] = W
    S["off"][0] = off
    assert eval_forces(S[0], kp) == (below, mask)
    if below:
        np.testing.assert_array_equal(bits(S[0]["P"]), bits(P1))
        np.testing.assert_array_equal(bits(S[0]["F"]), bits(F1))
        # and its sums, as the RK4 stages take them (from 0.0, node 1 → 8)
        scratch = (np.zeros((8, 3)), np.zeros((8, 3)), np.zeros(8), np.zeros(8))
        c, *sums = wrench_at(xz, *U, *W, off, kp, *scratch)
        want = [0.0] * 6
        for k in range(8):
            a, x = F1[k].tolist(), off[k].tolist()
            for j in range(3):
                want[j] += a[j]
            want[3] += a[1] * x[2] - a[2] * x[1]
            want[4] += a[2] * x[0] - a[0] * x[2]
            want[5] += a[0] * x[1] - a[1] * x[0]
        assert c
        np.testing.assert_array_equal(sums, want)
    else:
        assert not S[0]["F"].any() and not S[0]["P"].any()


@pytest.mark.parametrize("preset", PRESETS)
@pytest.mark.parametrize("integrator", tuple(INTEGRATORS))
def test_every_scheme_records_the_law(integrator, preset):
    """The forces each run loop records at the end of a step are the law at that step's state, bit for bit
    (every scheme compiles with strict arithmetic, as this test's law does)."""
    assert not step_of(INTEGRATORS[integrator]).targetoptions.get("fastmath")
    ic = seed_slice(1.65, 3.9)
    if preset == "physical":
        ic = ic * np.array([1, 1, 1, -1, -1, -1])
    cfg = make_config(preset, integrator=integrator, t_max_s=0.25)
    kp = cfg.kernel_params()
    tr = simulate(ic, config=cfg, record=Record(states=True, energy=False, forces=True)).trace
    L = convert_l(np.concatenate([np.zeros((len(tr.L), 3)), tr.L], axis=1), cfg.preset.l_convention, "program")[:, 3:]
    seen = 0
    for n in range(1, len(tr.step)):
        z = np.empty(8)
        uk = np.zeros((8, 3))
        below, _ = node_heights(tr.cm_pos[n, 2], tr.node_offsets[n], z)
        if not below:
            assert not tr.forces[n].any()
            continue
        node_velocities(*tr.cm_vel[n], *(L[n] / kp.inertia), tr.node_offsets[n], uk)
        F, P = np.zeros((8, 3)), np.zeros(8)
        contact_forces(z, uk, kp, F, P)
        np.testing.assert_array_equal(bits(tr.forces[n]), bits(F), err_msg=f"{integrator}, step {n}")
        seen += 1
    assert seen > 5
