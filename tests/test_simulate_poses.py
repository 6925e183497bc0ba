"""A full starting state per throw: ``simulate_batch(orientations=, heights_cm=)`` throws each die from its own pose,
exactly as ``simulate(orientation=, z0_cm=)`` throws it alone, and the tables keep the pose."""

from __future__ import annotations

import numpy as np
import pyarrow.parquet as pq
import pytest
from scipy.spatial.transform import Rotation

from dicetrace.ic_arrays import quaternions_xyzw, validate_orientations
from dicetrace.simulate import simulate, simulate_batch
from dicetrace.sinks.parquet import write_tables

BOX = dict(half_extents_cm=(1.0, 0.8, 0.6), load_fraction=0.2, load_cm=(0.3, -0.6, 0.2))


def _throws(m: int, seed: int):
    rng = np.random.default_rng(seed)
    ics = np.c_[rng.uniform(-100, 100, (m, 3)), rng.uniform(-40, 40, (m, 3))]
    return ics, Rotation.random(m, random_state=seed).as_quat(), rng.uniform(5.0, 20.0, m)


@pytest.mark.parametrize("body", [{}, BOX], ids=["cube", "loaded-box"])
def test_each_throw_is_the_single_throw_from_its_pose_bit_for_bit(body):
    ics, q, h = _throws(10, 3)
    b = simulate_batch(ics, preset="physical", orientations=q, heights_cm=h, threads=2, **body)
    assert (b.status == "settled").all()
    for i in range(len(ics)):
        r = simulate(ics[i], preset="physical", orientation=Rotation.from_quat(q[i]).as_matrix(), z0_cm=h[i], **body)
        assert (r.outcome, r.steps, int(r.status)) == (b.outcome[i], b.steps[i], b.status_code[i])
        np.testing.assert_array_equal(r.contact_sets, b.contact_sets(i))
    # the pose matters: from the preset's start the same ICs give other throws
    plain = simulate_batch(ics, preset="physical", **body)
    assert (plain.steps != b.steps).any()


def test_the_identity_pose_at_the_presets_height_is_the_plain_batch():
    ics, _, _ = _throws(6, 5)
    plain = simulate_batch(ics, preset="physical")
    posed = simulate_batch(ics, preset="physical", orientations=np.tile([0.0, 0.0, 0.0, 1.0], (6, 1)), heights_cm=15.0)
    for name in ("outcome", "steps", "status_code", "sets", "set_offsets"):
        np.testing.assert_array_equal(getattr(posed, name), getattr(plain, name))


def test_the_rolls_table_keeps_each_pose(tmp_path):
    ics, q, h = _throws(5, 7)
    b = simulate_batch(ics, preset="physical", orientations=q, heights_cm=h)
    paths = write_tables(tmp_path / "tables", b)
    t = pq.read_table(paths["rolls"])
    assert t.column_names[-5:] == ["qx", "qy", "qz", "qw", "z0_cm"]
    back = np.c_[[t.column(c).to_numpy() for c in ("qx", "qy", "qz", "qw")]].T
    np.testing.assert_allclose(Rotation.from_quat(back).as_matrix(), Rotation.from_quat(q).as_matrix(), atol=1e-15)
    np.testing.assert_array_equal(t.column("z0_cm").to_numpy(), h)
    assert (back[:, 3] >= 0).all()
    # each row keeps the very rotation its throw ran from, to the last bit (a quaternion read off that rotation
    # again, as the table once held, gives another rotation in its last bits for most throws)
    np.testing.assert_array_equal(validate_orientations(back, 5), validate_orientations(q, 5))
    # a row replays as the throw it records
    i = 3
    r = simulate(ics[i], preset="physical", orientation=Rotation.from_quat(back[i]).as_matrix(),
                 z0_cm=t.column("z0_cm")[i].as_py())
    assert (r.outcome, r.steps) == (t.column("outcome")[i].as_py(), t.column("steps")[i].as_py())
    assert "qx" not in simulate_batch(ics, preset="physical").to_arrow().column_names


def test_quaternions_and_matrices_round_trip():
    q = Rotation.random(50, random_state=1).as_quat(canonical=True)
    rot = validate_orientations(q, 50)
    np.testing.assert_allclose(validate_orientations(rot, 50), rot)
    np.testing.assert_allclose(quaternions_xyzw(rot), q, atol=1e-15)


@pytest.mark.parametrize("kwargs, message", [
    (dict(heights_cm=0.5), "throw 0 starts below the ground: its lowest node is at"),
    (dict(orientations=np.zeros((4, 3))), r"orientations must be \(4, 4\) quaternions x, y, z, w or \(4, 3, 3\)"),
    (dict(orientations=np.tile([0.0, 0.0, 0.0, 2.0], (4, 1))), "quaternion 0 has norm 2, not 1"),
    (dict(orientations=np.tile(np.diag([1.0, 1.0, -1.0]), (4, 1, 1))), "matrix 0 is not a rotation"),
    (dict(heights_cm=[10.0, np.nan, 10.0, 10.0]), "heights_cm must be finite"),
    (dict(heights_cm=[10.0, 10.0]), "heights_cm must be one number or 4 numbers"),
])
def test_bad_poses_are_refused_naming_the_problem(kwargs, message):
    ics, _, _ = _throws(4, 2)
    with pytest.raises(ValueError, match=message):
        simulate_batch(ics, preset="physical", **kwargs)
