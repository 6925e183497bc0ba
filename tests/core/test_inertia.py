"""A die that is no uniform cube (``dicetrace.core.inertia``): ω = R·I_b⁻¹·Rᵀ·L along the whole flow.

Free flight against an independent integration of the rigid body's
equations; a box and a loaded die at rest on every face; what the bodies
do when thrown; the configurations that cannot follow such a body.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.spatial.transform import Rotation
from scipy.special import ellipj, ellipk

from dicetrace.body import FACE_AXES
from dicetrace.core.inertia import omega, orientation
from dicetrace.core.model import face_below, face_levels
from dicetrace.params import ConfigError, make_config
from dicetrace.simulate import Record, simulate, simulate_batch

BOX = dict(half_extents_cm=(1.0, 0.75, 0.5))
LOADED = dict(load_fraction=0.3, load_cm=(-0.9, 0.2, 0.1))


def _face_down(f):
    """The rotation that turns face f's outward normal to −z."""
    axis, sign = FACE_AXES[f - 1]
    n = np.zeros(3)
    n[axis] = sign
    rot, _ = Rotation.align_vectors([[0.0, 0.0, -1.0]], [n])
    return rot.as_matrix()


@pytest.mark.parametrize("body", [BOX, LOADED], ids=["box", "loaded"])
def test_orientation_and_omega_are_read_off_the_node_offsets(body):
    """R from the turned offsets is the rotation that turned them, and ω = R·I_b⁻¹·Rᵀ·L (numpy's inverse)."""
    cfg = make_config("physical", **body)
    kp = cfg.kernel_params()
    Ib = cfg.preset.body.inertia
    for R in Rotation.random(5, random_state=3).as_matrix():
        off = np.ascontiguousarray(cfg.preset.body.node_offsets_cm @ R.T)
        np.testing.assert_allclose(np.reshape(orientation(off, kp), (3, 3)), R, atol=1e-14)
        L = np.array([3.0, -7.0, 11.0])
        np.testing.assert_allclose(omega(*L, off, kp), R @ np.linalg.solve(Ib, R.T @ L), rtol=1e-12)


def test_the_cube_keeps_its_scalar_inertia():
    """A uniform cube's kernels divide by its scalar inertia, as the 2019 program does (the isotropic branch)."""
    for preset in ("seed", "physical"):
        kp = make_config(preset).kernel_params()
        assert kp.isotropic and kp.inv_mass_node == 11.0 / 16.0
        assert kp.ii_xx == kp.ii_yy == kp.ii_zz == 1.0 / kp.inertia and kp.ii_xy == kp.ii_xz == kp.ii_yz == 0.0
        assert omega(1.0, 2.0, 3.0, np.zeros((8, 3)), kp) == (1.0 / kp.inertia, 2.0 / kp.inertia, 3.0 / kp.inertia)


def test_a_box_in_free_flight_turns_as_jacobis_solution_and_flips_on_time():
    """Torque-free (g = 0, far above the ground), a box with three different moments I1 < I2 < I3 (half-extents
    1, 0.75, 0.5) started mid-flip, ω = (A1, 0, A3) in the body frame, has the exact solution

        ω = (A1·cn τ, A2·sn τ, A3·dn τ),  τ = λ·t,  λ = A3·√((I3 − I2)(I3 − I1) / (I1·I2)),
        k² = (I2 − I1)·I1·A1² / ((I3 − I2)·I3·A3²),  A2 = A1·√(I1·(I3 − I1) / (I2·(I3 − I2)))

    (Landau & Lifshitz, Mechanics §37).  With k² = 0.98 the intermediate axis turns over every 2K(k)/λ.  The
    body's ω follows it to 1e-7 of its size over 4 s; its intermediate axis flips when it says; its orientation
    is an independent DOP853 integration of R' = [ω]×·R; L and the rotational energy ½·ω·L are conserved."""
    cfg = make_config("physical", g=0.0, t_max_s=4.0, tol=1e-10, **BOX)
    Ib = cfg.preset.body.inertia
    I1, I2, I3 = np.diag(Ib)
    assert I1 < I2 < I3 and np.count_nonzero(Ib - np.diag(np.diag(Ib))) == 0
    m = 0.98
    A3 = 10.0
    A1 = A3 * math.sqrt(m * (I3 - I2) * I3 / ((I2 - I1) * I1))
    A2 = A1 * math.sqrt(I1 * (I3 - I1) / (I2 * (I3 - I2)))
    lam = A3 * math.sqrt((I3 - I2) * (I3 - I1) / (I1 * I2))
    L = Ib @ np.array([A1, 0.0, A3])  # physical L; the start orientation is the identity
    r = simulate(np.r_[0.0, 0.0, 0.0, L], config=cfg, record=Record(states=True, energy=True))
    tr = r.trace
    assert r.status == "time_cap"
    np.testing.assert_array_equal(tr.L, np.broadcast_to(L, tr.L.shape))
    er = tr.energy["kinetic_rotational"]
    assert er[0] == pytest.approx(0.5 * L @ np.linalg.solve(Ib, L), rel=1e-14)
    assert np.ptp(er) < 1e-10 * er[0]

    w_body = np.linalg.solve(Ib, np.einsum("nji,j->ni", tr.rotation, L).T).T  # I_b⁻¹·Rᵀ·L
    sn, cn, dn, _ = ellipj(lam * tr.t_s, m)
    np.testing.assert_allclose(w_body, np.c_[A1 * cn, A2 * sn, A3 * dn], atol=1e-7 * A1)
    # ω2 changes sign (after the start, where it is 0): the intermediate axis turns over
    flips = tr.t_s[1:][np.nonzero(np.diff(np.sign(w_body[1:, 1])))[0]]
    period = 2.0 * ellipk(m) / lam
    assert len(flips) == 2 and period > 1.0
    np.testing.assert_allclose(flips, [period, 2 * period], atol=cfg.numerics.dt_s)

    def rhs(t, y):
        R = y.reshape(3, 3)
        w = R @ np.linalg.solve(Ib, R.T @ L)
        return (np.array([[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]]) @ R).ravel()

    ref = solve_ivp(rhs, (0.0, tr.t_s[-1]), np.eye(3).ravel(), t_eval=tr.t_s, method="DOP853", rtol=1e-12, atol=1e-13)
    np.testing.assert_allclose(tr.rotation, ref.y.T.reshape(-1, 3, 3), atol=1e-8)


@pytest.mark.parametrize("body", [BOX, LOADED], ids=["box", "loaded"])
def test_a_body_at_rest_on_each_face_stays_there(body):
    """Set down (0.05 cm up, at rest) on face f, a box or a loaded die settles at once with face 7 − f up, on the
    threshold of the face it stands over (``face_below``, ``face_levels``: its rest energy and 80 % of its own tip
    barrier)."""
    base = make_config("physical", **body)
    heights = base.preset.body.face_heights_cm
    rest, stop = base.preset.face_energies()
    kp = base.kernel_params()
    for f in range(1, 7):
        R = _face_down(f)
        off = np.ascontiguousarray(base.preset.body.node_offsets_cm @ R.T)
        assert face_below(off, kp) == f
        assert face_levels(off, kp) == (rest[f - 1], stop[f - 1])
        cfg = make_config("physical", z0_cm=max(heights[f - 1], heights[2]) + 0.05, **body)
        r = simulate(np.zeros(6), config=cfg, orientation=R)
        assert (r.status, r.outcome) == ("settled", 7 - f)
    assert len(set(stop)) > 1  # the thresholds differ from face to face


def test_thrown_bodies_land_as_their_shape_and_load_say():
    """Thrown alike (120 random throws), a flat box (half-extents 1, 1, 0.6) lands mostly on its two large faces
    (3, 4), and a die loaded near face 1 shows face 6 (load down) more often than any other, well beyond a fair
    die's chance; every throw settles."""
    rng = np.random.default_rng(1)
    m = 120
    ics = np.c_[rng.uniform(-100.0, 100.0, (m, 3)), rng.uniform(-40.0, 40.0, (m, 3))]
    flat = simulate_batch(ics, preset="physical", half_extents_cm=(1.0, 1.0, 0.6))
    loaded = simulate_batch(ics, preset="physical", load_fraction=0.3, load_cm=(-0.9, 0.0, 0.0))
    for b in (flat, loaded):
        assert np.all(b.status_code == b.status_code[0]) and b.status[0] == "settled"
    nf = np.bincount(flat.outcome, minlength=7)[1:]
    nl = np.bincount(loaded.outcome, minlength=7)[1:]
    assert nf[2] + nf[3] > 0.5 * m  # a uniform share would be a third
    # face 6 up (the load's face down) the most often, more than three binomial σ above a fair die's m/6
    assert nl.argmax() == 5 and nl[5] > m / 6 + 3 * math.sqrt(m * (1 / 6) * (5 / 6))


def test_bodies_need_a_continuous_contact_integrator_and_the_rigid_energy():
    """The schemes that hold ω = L / I, and the point-mass energy, are refused for a box or a loaded die."""
    for integrator in ("semi-implicit-euler", "verlet", "rk4", "contact-substep", "contact-adaptive"):
        with pytest.raises(ConfigError, match="no uniform cube"):
            make_config("physical", integrator=integrator, **BOX)
    with pytest.raises(ConfigError, match="rigid energy"):
        make_config("seed", integrator="contact-tsit5", **LOADED)
    for integrator in ("contact-tsit5", "contact-dop853"):
        assert not make_config("physical", integrator=integrator, **LOADED).kernel_params().isotropic
    with pytest.raises(ConfigError, match="z0_cm"):
        make_config("physical", z0_cm=0.4, **BOX)
    assert math.isclose(make_config("physical", **BOX).preset.body.face_heights_cm[2], 0.5)


@pytest.mark.parametrize("tilt_deg, up", [(15.0, 6), (35.0, 4), (60.0, 4)])
def test_a_bar_tipped_past_its_balance_falls_over_and_one_short_of_it_stands(tilt_deg, up):
    """A long bar (5.3 × 2 × 2 cm) set down at rest on an edge of its end face, tilted by ``tilt_deg`` from upright:
    short of its balance angle (atan(1/2.65) = 20.7°) it rocks back onto its end (face 6 up); past it, it falls onto
    a long side (face 4 up), although its end face's four nodes stay the lowest up to a tilt of 69°: a stop test
    measured from the face of the four lowest nodes took the falling bar for one standing on its end."""
    cfg0 = make_config("physical", half_extents_cm=(2.65, 1.0, 1.0))
    # upright on face 1 (x down), then tipped about the body's y axis so that the edge x = −a, z = −c touches
    R = Rotation.from_euler("y", -(90.0 - tilt_deg), degrees=True).as_matrix()
    lowest = (cfg0.preset.body.node_offsets_cm @ R.T)[:, 2].min()
    face = face_below(np.ascontiguousarray(cfg0.preset.body.node_offsets_cm @ R.T), cfg0.kernel_params())
    assert face == (1 if tilt_deg < 20.7 else 3)
    cfg = make_config("physical", half_extents_cm=(2.65, 1.0, 1.0), z0_cm=-lowest + 1e-4)
    r = simulate(np.zeros(6), config=cfg, orientation=R)
    assert (r.status, r.outcome) == ("settled", up)
