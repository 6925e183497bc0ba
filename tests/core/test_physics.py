"""Physics that does not depend on the 2019 program: closed forms and invariants."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from dicetrace.params import make_config
from dicetrace.simulate import (
    Record,
    contact_sequence_from_heights,
    sets_to_text,
    simulate,
    text_to_sets,
)

G = -980.0
DT = 1e-3
IC_SPIN = np.array([30.0, -20.0, 150.0, 40.0, -75.0, 120.0])


def _first_contact(roll):
    z = roll.trace.node_pos[:, :, 2]
    return int(np.argmax((z <= 0).any(axis=1)))


def test_free_fall_parabola():
    """Until contact the centre of mass follows the parabola.

    Semi-implicit Euler (the program's step: velocity first, then position
    with the new velocity) gives exactly X_n = X_0 + n·dt·U_0 + g·dt²·n(n+1)/2,
    which differs from X_0 + U_0·t + ½·g·t² by ½·g·dt·t (first order).
    """
    roll = simulate(IC_SPIN, record=Record(states=True, energy=False))
    n_c = _first_contact(roll)
    assert n_c > 100
    n = np.arange(n_c)
    t = n * DT
    x0 = np.array([0.0, 0.0, 15.0])
    u0 = IC_SPIN[:3]
    discrete = x0 + np.outer(n * DT, u0)
    discrete[:, 2] += G * DT**2 * n * (n + 1) / 2
    np.testing.assert_allclose(roll.trace.cm_pos[:n_c], discrete, rtol=0, atol=1e-11)
    parabola = x0 + np.outer(t, u0)
    parabola[:, 2] += 0.5 * G * t**2
    err = np.abs(roll.trace.cm_pos[:n_c, 2] - parabola[:, 2])
    np.testing.assert_allclose(err, 0.5 * abs(G) * DT * t, rtol=1e-9, atol=1e-11)
    # velocity: U_n = U_0 + n·g·dt exactly in x, y and to rounding in z
    np.testing.assert_allclose(roll.trace.cm_vel[:n_c, 2], u0[2] + n * G * DT, atol=1e-11)
    # angular momentum is constant in flight (no torque): bit for bit
    assert (roll.trace.L[:n_c] == IC_SPIN[3:]).all()


def test_free_fall_parabola_converges_first_order():
    """Halving dt halves the deviation from the parabola at a fixed time."""
    errs = []
    for dt in (4e-3, 2e-3, 1e-3, 5e-4):
        cfg = make_config("seed", dt_s=dt)
        roll = simulate(IC_SPIN, config=cfg, record=Record(states=True, energy=False))
        n = int(round(0.1 / dt))
        t = n * dt
        errs.append(abs(roll.trace.cm_pos[n, 2] - (15.0 + IC_SPIN[2] * t + 0.5 * G * t * t)))
    ratios = np.array(errs[:-1]) / np.array(errs[1:])
    np.testing.assert_allclose(ratios, 2.0, rtol=1e-6)


def test_free_flight_energy_closed_form():
    """In flight the program's stop-test energy falls by exactly ½·M·(g·dt)² a step.

    With U_{n+1} = U_n + g·dt and Z_{n+1} = Z_n + U_{n+1}·dt:
    ½M(U_{n+1}² − U_n²) + M|g|(Z_{n+1} − Z_n) = −½M(g·dt)², M = 8.
    Rotational energy is constant (ω constant, the offsets rigid).
    """
    roll = simulate(IC_SPIN, record=Record(states=True, energy=True))
    n_c = _first_contact(roll)
    e = roll.trace.energy["stop_test"][: n_c]
    np.testing.assert_allclose(np.diff(e), -0.5 * 8 * (G * DT) ** 2, rtol=0, atol=1e-8)
    rot = roll.trace.energy["kinetic_rotational"][:n_c]
    assert np.ptp(rot) == 0.0


def _pairwise(off):
    i, j = np.triu_indices(8, 1)
    return np.linalg.norm(off[:, i, :] - off[:, j, :], axis=-1)


def test_rigidity_over_1e5_free_flight_steps():
    """All 28 pairwise node distances hold to 1e-9 after 10⁵ exact rotations."""
    cfg = make_config("seed", t_max_s=100.0, z0_cm=1e7)  # falls 4.9e6 cm in 100 s: no contact
    ic = np.array([1.0, 2.0, 3.0, 2500.0, -1700.0, 900.0])  # |ω| ≈ 600 rad/s
    roll = simulate(ic, config=cfg, record=Record(states=True, energy=False))
    assert roll.status == "time_cap" and roll.steps == 100_000 and roll.outcome == -1
    d = _pairwise(roll.trace.node_offsets[[0, -1]])
    np.testing.assert_allclose(d[1], d[0], rtol=0, atol=1e-9)
    # and the orientation stays a rotation: |q| = 1
    q = roll.trace.quat_xyzw[-1]
    assert abs(np.linalg.norm(q) - 1) < 1e-12
    rot = roll.trace.rotation[-1]
    np.testing.assert_allclose(rot @ rot.T, np.eye(3), atol=1e-9)


def test_flat_drop_without_spin_lands_on_face_3():
    """Dropped flat (identity orientation: face 3 down, 4 up) with no spin: shows 4.

    All four bottom nodes touch at the same step, as one contact set {1,3,5,7}.
    """
    roll = simulate(np.zeros(6))
    assert roll.status == "settled"
    assert roll.outcome == 4
    assert roll.contact_sequence.startswith("0-1357")
    # no horizontal motion ever: friction sees σ = 0 (program: no friction)
    roll = simulate(np.zeros(6), record=Record(states=True, energy=False))
    assert np.abs(roll.trace.cm_pos[:, :2]).max() == 0.0


# --- contact-set extraction on hand-built height series -------------------------


def _heights(rows):
    """Height series from lists of nodes (1..8) in contact at each step."""
    z = np.ones((len(rows), 8))
    for n, nodes in enumerate(rows):
        for node in nodes:
            z[n, node - 1] = -0.01 if node % 2 else 0.0  # z = 0 counts as contact
    return z


@pytest.mark.parametrize(
    "rows, text, steps",
    [
        # nothing ever touches: only the initial empty set
        ([[], [], [], []], "0", [0]),
        # one node enters at step 2, leaves at step 4
        ([[], [], [6], [6], [], []], "0-6-0", [0, 2, 4]),
        # simultaneous changes: {6} → {6,8} → {8} → {} → {1,3,5,7} at once
        ([[], [], [6], [6, 8], [8], [], [1, 3, 5, 7]], "0-6-68-8-0-1357", [0, 2, 3, 4, 5, 6]),
        # step 1 is never compared (the program starts at step 2): {6} seen only
        # at step 1 is lost, and the set of step 2 is recorded at step 2
        ([[], [6], [6, 8], [8], [], [1, 3, 5, 7], [1, 3, 5, 7]], "0-68-8-0-1357", [0, 2, 3, 4, 5]),
        # no duplicates: a set held over many steps is recorded once
        ([[]] + [[2, 4]] * 5 + [[2]] * 3, "0-24-2", [0, 2, 6]),
        # swap in one step: {3} → {5} (one enters, one leaves together)
        ([[], [], [3], [5], [5]], "0-3-5", [0, 2, 3]),
    ],
)
def test_contact_sets_from_heights(rows, text, steps):
    sets, set_steps = contact_sequence_from_heights(_heights(rows))
    assert sets_to_text(sets) == text
    assert list(set_steps) == steps
    # never two equal neighbours
    assert all(a != b for a, b in zip(sets[:-1], sets[1:]))


@pytest.mark.slow  # about a second
def test_text_round_trip():
    for combo in itertools.combinations(range(256), 2):
        arr = np.array((0,) + combo, dtype=np.uint8)
        assert (text_to_sets(sets_to_text(arr)) == arr).all()
    assert sets_to_text(np.arange(256, dtype=np.uint8)).split("-")[255] == "12345678"


def test_sequence_in_roll_matches_heights():
    """The simulator's sequence equals the extraction applied to its own trace."""
    roll = simulate(IC_SPIN, record=Record(states=True, energy=False))
    sets, set_steps = contact_sequence_from_heights(roll.trace.node_pos[:, :, 2])
    assert (sets == roll.contact_sets).all()
    assert (set_steps == roll.contact_steps).all()


FACE_NORMALS = {1: (-1, 0, 0), 2: (0, -1, 0), 3: (0, 0, -1), 4: (0, 0, 1), 5: (0, 1, 0), 6: (1, 0, 0)}


def _face_down(face):
    """World-from-body rotation that puts ``face`` on the ground, exactly.

    A signed permutation matrix (entries 0, ±1), so the node offsets stay
    exactly ±1: the program's spectral-norm friction gives full Coulomb force
    to velocities of 1e-16 cm/s, so a 1-ulp tilt from an inexact rotation
    grows into a visible rocking (measured: 0.09 cm for a cos/sin-built
    quarter turn).
    """
    n = np.array(FACE_NORMALS[face], dtype=float)
    down = np.array([0.0, 0.0, -1.0])
    if np.array_equal(n, down):
        return np.eye(3)
    if np.array_equal(n, -down):
        return np.diag([1.0, -1.0, -1.0])  # half turn about x
    axis = np.cross(n, down)  # quarter turn about axis takes n to down
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    rot = np.eye(3) + k + k @ k  # Rodrigues with sin = 1, cos = 0
    assert np.array_equal(rot @ n, down)
    return rot


@pytest.mark.parametrize("face_down", [1, 2, 3, 4, 5, 6])
def test_flat_die_stays_on_its_face(face_down):
    """Laid flat 0.5 cm above its resting height, at rest: it settles on that face.

    The face up is 7 − face down (opposite faces add up to 7), the die never
    tilts (all four bottom nodes share one height), and it does not slide.
    """
    cfg = make_config("seed", z0_cm=1.5)
    roll = simulate(np.zeros(6), config=cfg, orientation=_face_down(face_down), record=Record(states=True, energy=False))
    assert roll.status == "settled"
    assert roll.outcome == 7 - face_down
    z = roll.trace.node_pos[:, :, 2]
    bottom = np.argsort(z[0])[:4]
    assert np.ptp(z[:, bottom], axis=1).max() < 1e-9  # no tilt
    assert np.abs(roll.trace.cm_pos[:, :2]).max() < 1e-9  # no slide
    # rests at the penalty spring's static depth, |g|/k per node (to within the bounce)
    assert abs(z[-1, bottom].mean()) < 5 * 980.0 / 5e5 + 0.05
