"""A recording of a box or a loaded die draws that body: its box where its nodes are, its plates and pips on its
faces, and its node velocities from the full inertia tensor (read back from the .rrd file)."""

from __future__ import annotations

import numpy as np
import pytest

rr = pytest.importorskip("rerun")

from dicetrace.body import FACE_NODE_ROWS, NODE_SIGNS  # noqa: E402
from dicetrace.params import convert_l  # noqa: E402
from dicetrace.params import make_config  # noqa: E402
from dicetrace.simulate import Record, simulate  # noqa: E402
from dicetrace.sinks.rerun import (FACE_NORMALS, default_blueprint, encode_rrd, read_rrd, read_rrd_metadata,  # noqa: E402
                                   roll_logger)
from dicetrace.sinks.rerun_channels import node_velocities  # noqa: E402

from tests.sinks.test_rerun_sink import texts, values  # noqa: E402

#: A flat box (sides 2, 1.6, 1.2 cm) with a fifth of its mass near face 2: three distinct moments and an offset
#: centre of mass, so neither the cube's box nor ω = L / I would fit.
BODY = dict(half_extents_cm=(1.0, 0.8, 0.6), load_fraction=0.2, load_cm=(0.3, -0.6, 0.2))
IC = np.array([60.0, 40.0, 0.0, 20.0, -30.0, 10.0])


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    cfg = make_config("physical", t_max_s=3.0, **BODY)
    roll = simulate(IC, config=cfg, record=Record(states=True, energy=True))
    path = tmp_path_factory.mktemp("rrd") / "box.rrd"
    chans = frozenset({"velocities"})
    rr.set_strict_mode(True)  # a bad logging call raises instead of warning
    try:
        path.write_bytes(encode_rrd(roll_logger(roll, name="box", ic_label="a loaded box", channels=chans),
                                    default_blueprint(roll, chans)))
    finally:
        rr.set_strict_mode(False)
    return roll, read_rrd(path), read_rrd(path, static=True), read_rrd_metadata(path)


def _pose(temporal):
    from scipy.spatial.transform import Rotation

    faces = temporal["/world/die/faces"]
    q = values(faces, "Transform3D:quaternion", 4)[:, 0].astype(np.float64)
    return Rotation.from_quat(q).as_matrix(), values(faces, "Transform3D:translation", 3)[:, 0].astype(np.float64)


def test_the_box_has_the_bodys_extents_and_its_corners_are_the_nodes(recorded):
    roll, temporal, static, _ = recorded
    assert roll.status == "settled"
    half = values(static["/world/die/body"], "Boxes3D:half_sizes", 3)[0, 0].astype(np.float64)
    np.testing.assert_allclose(half, BODY["half_extents_cm"], rtol=1e-6)
    from scipy.spatial.transform import Rotation

    box = temporal["/world/die/body"]
    centers = values(box, "Boxes3D:centers", 3)[:, 0].astype(np.float64)
    rot = Rotation.from_quat(values(box, "Boxes3D:quaternions", 4)[:, 0].astype(np.float64)).as_matrix()
    corners = centers[:, None, :] + np.einsum("nij,kj->nki", rot, NODE_SIGNS * half)
    np.testing.assert_allclose(corners, roll.trace.node_pos, atol=2e-5)
    # the centre of mass is not the box's centre: the box is drawn where the nodes are, not around the point traced
    assert np.linalg.norm(centers - roll.trace.cm_pos, axis=1).min() > 0.1


def test_plates_and_pips_sit_on_the_boxs_faces_and_the_outcome_is_on_top(recorded):
    roll, temporal, static, _ = recorded
    plates = static["/world/die/faces"]
    c = values(plates, "Boxes3D:centers", 3)[0].astype(np.float64)
    ph = values(plates, "Boxes3D:half_sizes", 3)[0].astype(np.float64)
    rot, trans = _pose(temporal)
    world = trans[:, None, :] + np.einsum("nij,kj->nki", rot, c)
    face_mid = roll.trace.node_pos[:, FACE_NODE_ROWS, :].mean(axis=2)  # (n, 6, 3): the middle of each face
    normal_w = np.einsum("nij,kj->nki", rot, FACE_NORMALS)
    thick = ph[np.arange(6), np.abs(FACE_NORMALS).argmax(axis=1)]  # each plate's half thickness, along its normal
    np.testing.assert_allclose(world, face_mid + normal_w * thick[None, :, None], atol=2e-5)
    h = np.array(BODY["half_extents_cm"])
    for f in range(6):  # each plate inside its face
        axes = FACE_NORMALS[f] == 0
        assert (ph[f][axes] < h[axes]).all() and (ph[f][axes] > 0.5 * h[axes]).all()
    pips = static["/world/die/faces/pips"]
    pos = values(pips, "Ellipsoids3D:centers", 3)[0].astype(np.float64)
    face = np.array([int(t.split()[-1]) for t in texts(pips, "Ellipsoids3D:labels")])
    np.testing.assert_array_equal(np.bincount(face, minlength=7)[1:], [1, 2, 3, 4, 5, 6])
    z_end = trans[-1, 2] + pos @ rot[-1][2]
    assert set(face[z_end > np.sort(z_end)[-1 - roll.outcome] + 1e-6]) == {roll.outcome}


def test_node_velocities_follow_the_full_inertia_tensor(recorded):
    """The velocity channel against finite differences of the traced nodes in free flight: ω = R·I⁻¹·Rᵀ·L, not
    L / I (which misses them by far for this body)."""
    roll, temporal, _, meta = recorded
    nodes = roll.trace.node_pos
    vel = values(temporal["/world/die/velocities"], "Arrows3D:vectors", 3).reshape(-1, 8, 3) / meta["velocity_arrow_s"]
    first = int(np.flatnonzero((nodes[..., 2] <= 0).any(axis=1))[0])
    assert first > 20
    fd = (nodes[1:first] - nodes[: first - 1]) / roll.dt_s
    mid = 0.5 * (vel[1:first] + vel[: first - 1])  # the central difference's own time
    np.testing.assert_allclose(mid, fd, atol=2e-3 * np.abs(fd).max())
    iso = node_velocities(roll)
    assert np.allclose(iso, vel, atol=1e-3 * np.abs(fd).max())  # the file holds the kernel's formula
    tr = roll.trace
    l_prog = convert_l(np.c_[tr.cm_vel, tr.L], roll.config.preset.l_convention, "program")[:, 3:]
    mean_moment = np.trace(roll.config.preset.body.inertia) / 3.0
    naive = tr.cm_vel[:, None, :] + np.cross(tr.node_offsets, l_prog[:, None, :] / mean_moment)
    assert np.abs(naive[1:first] - fd).max() > 20 * np.abs(mid - fd).max()
