"""dicetrace.body: the die's geometry and mass, written once, against geometry and mechanics done independently."""

from __future__ import annotations

import math

import numpy as np
import pytest

from dicetrace.body import FACE_AXES, FACE_NODE_MASK, FACE_NODES, FACE_NORMALS, MASS, NODE_SIGNS, Body, face_of_top4


def test_node_numbering_and_faces_are_the_programs():
    """node = 1 + 4[x>0] + 2[y>0] + [z>0]; the face table of docs/model.md §3; opposite faces add up to 7."""
    assert NODE_SIGNS[0].tolist() == [-1, -1, -1] and NODE_SIGNS[7].tolist() == [1, 1, 1]
    for k in range(8):
        assert k == 4 * (NODE_SIGNS[k, 0] > 0) + 2 * (NODE_SIGNS[k, 1] > 0) + (NODE_SIGNS[k, 2] > 0)
    assert FACE_NODES == {1: (1, 2, 3, 4), 2: (1, 2, 5, 6), 3: (1, 3, 5, 7), 4: (2, 4, 6, 8), 5: (3, 4, 7, 8),
                          6: (5, 6, 7, 8)}
    for f in range(1, 7):
        axis, sign = FACE_AXES[f - 1]
        assert FACE_AXES[7 - f - 1] == (axis, -sign)  # the opposite face
        assert FACE_NORMALS[f - 1, axis] == sign and np.abs(FACE_NORMALS[f - 1]).sum() == 1
        assert set(FACE_NODES[f]).isdisjoint(FACE_NODES[7 - f])
    table = face_of_top4()
    assert sorted(table[table > 0].tolist()) == [1, 2, 3, 4, 5, 6]
    assert all(table[m] == f for f, m in FACE_NODE_MASK.items())


def _sampled(body: Body, n: int = 400_000, seed: int = 2):
    """Centre of mass and inertia about it of the body, by Monte Carlo over the box's volume plus the load."""
    rng = np.random.default_rng(seed)
    h = np.asarray(body.half_extents_cm)
    x = rng.uniform(-1, 1, (n, 3)) * h
    w = body.load_fraction
    m = np.full(n, MASS * (1 - w) / n)
    pts = np.vstack([x, np.asarray(body.load_cm)[None]])
    mass = np.append(m, MASS * w)
    com = (mass[:, None] * pts).sum(0) / mass.sum()
    r = pts - com
    inertia = (mass[:, None, None] * ((r * r).sum(1)[:, None, None] * np.eye(3) - r[:, :, None] * r[:, None, :])).sum(0)
    return com, inertia


@pytest.mark.parametrize("body", [Body.cube(), Body((1.6, 1.0, 1.0)), Body((0.5, 1.2, 2.0)),
                                  Body((1.0, 1.0, 1.0), 0.25, (0.6, 0.0, 0.0)),
                                  Body((1.0, 1.2, 0.8), 0.3, (0.5, -0.4, 0.3))])
def test_mass_properties_are_the_boxs(body):
    """The centre of mass and the inertia tensor about it equal a direct sum over the box's volume and the load
    (Monte Carlo, to about three standard deviations of its sampling); the cube of half side 1 has (16/3)·E, as the program."""
    com, inertia = _sampled(body)
    np.testing.assert_allclose(body.com_cm, com, atol=4e-3 * max(body.half_extents_cm))  # ~3 sigma of the sampling
    np.testing.assert_allclose(body.inertia, inertia, rtol=0, atol=3e-3 * np.abs(inertia).max())
    assert np.allclose(body.inertia, body.inertia.T) and np.all(np.linalg.eigvalsh(body.inertia) > 0)
    np.testing.assert_allclose(body.node_offsets_cm.mean(0), -body.com_cm, atol=1e-15)  # the corners' mean is the box's centre


def test_the_cube_is_the_programs():
    b = Body.cube()
    assert b.is_cube and not Body((1, 1, 1.01)).is_cube and not Body((1, 1, 1), 0.1, (0, 0, 0.5)).is_cube
    np.testing.assert_array_equal(b.inertia, 16.0 / 3.0 * np.eye(3))
    np.testing.assert_array_equal(b.node_offsets_cm, NODE_SIGNS)
    np.testing.assert_allclose(b.tip_barriers_cm, math.sqrt(2) - 1)  # the edge the program's stop test uses


def test_face_heights_and_tip_barriers_of_a_loaded_die():
    """A load toward face 6 (+x) lowers the centre of mass over face 6 and raises it over face 1; face 6 down is
    the more stable: its barrier to the nearest edge is the larger (geometry done by hand)."""
    b = Body((1.0, 1.0, 1.0), 0.2, (0.5, 0.0, 0.0))  # centre of mass at x = +0.1
    np.testing.assert_allclose(b.face_heights_cm, [1.1, 1.0, 1.0, 1.0, 1.0, 0.9])
    # on face 6 (down at x = +1): height 0.9; nearest edges at a horizontal 1 (y, z): sqrt(0.81 + 1) - 0.9
    assert b.tip_barriers_cm[5] == pytest.approx(math.hypot(0.9, 1.0) - 0.9)
    # on face 3 (z down): height 1; nearest edge the one toward the load, at a horizontal 0.9
    assert b.tip_barriers_cm[2] == pytest.approx(math.hypot(1.0, 0.9) - 1.0)
    assert b.tip_barriers_cm[5] > b.tip_barriers_cm[0] > b.tip_barriers_cm[2]


@pytest.mark.parametrize("bad", [dict(half_extents_cm=(1, 1)), dict(half_extents_cm=(1, -1, 1)),
                                 dict(half_extents_cm=(1, 1, float("nan"))), dict(load_fraction=1.0),
                                 dict(load_fraction=-0.1), dict(load_fraction=0.1, load_cm=(2.0, 0, 0))])
def test_bad_bodies_are_refused(bad):
    with pytest.raises(ValueError):
        Body(**bad)
