"""The Rerun sink: write a throw as .rrd, read it back (pyarrow only) and compare with the simulation."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pyarrow as pa
import pytest

rr = pytest.importorskip("rerun")

from dicetrace.ics import seed_slice  # noqa: E402
from dicetrace.simulate import Record, sets_to_text, simulate  # noqa: E402
from dicetrace.sinks.rerun import FACE_COLORS, default_blueprint, read_rrd, read_rrd_metadata, write_rrd  # noqa: E402

# Writeup's first topology IC (seed slice x = 1.65, y = 3.9) and its contact sequence in the program's text form.
SEQ_1_65_3_9 = "0-6-68-8-0-3-0-1-0-8-48-4-24-2-0-2-4-0-6-0-48-0-6"
RERUN_CLI = Path(sys.executable).parent / "rerun"


def values(table: pa.Table, column: str, width: int | None = None) -> np.ndarray:
    """A list<...> component column flattened to numpy: (rows, instances[, width])."""
    col = table.column(column).combine_chunks()
    lengths = col.value_lengths().to_numpy()
    flat = col.flatten()
    while pa.types.is_fixed_size_list(flat.type) or pa.types.is_list(flat.type):
        flat = flat.flatten()
    arr = flat.to_numpy(zero_copy_only=False)
    if width:
        arr = arr.reshape(-1, width)
    if (lengths == lengths[0]).all():
        return arr.reshape(len(lengths), lengths[0], *arr.shape[1:])
    return arr


def texts(table: pa.Table, column: str) -> list[str]:
    return [x for row in table.column(column).to_pylist() for x in row]


def sequence_from_events(steps, nodes, kinds) -> str:
    """Rebuild the contact-set sequence from per-node events: one new set per step with events."""
    sets, mask = [0], 0
    order = np.argsort(np.asarray(steps), kind="stable")
    steps = np.asarray(steps)[order]
    nodes = np.asarray(nodes)[order]
    kinds = np.asarray(kinds)[order]
    for s in np.unique(steps):
        for n, k in zip(nodes[steps == s], kinds[steps == s]):
            bit = 1 << (int(n) - 1)
            mask = mask | bit if k == "enter" else mask & ~bit
        sets.append(mask)
    return sets_to_text(sets)


def logged_events(temporal: dict) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(step, node, kind) parsed from the contact text log, e.g. "step 176: node 6 enters"."""
    log = temporal["/contacts"]
    steps, nodes, kinds = [], [], []
    for step, line in zip(log.column("step").to_pylist(), texts(log, "TextLog:text")):
        head, tail = line.split(": node ")
        node, verb = tail.split()
        assert head == f"step {step}"
        steps.append(step)
        nodes.append(int(node))
        kinds.append({"enters": "enter", "leaves": "leave"}[verb])
    return np.array(steps), np.array(nodes), np.array(kinds)


@pytest.fixture(scope="module")
def roll():
    return simulate(seed_slice(1.65, 3.9), record=Record(states=True, energy=True))


@pytest.fixture(scope="module")
def rrd(roll, tmp_path_factory):
    path = tmp_path_factory.mktemp("rrd") / "throw.rrd"
    rr.set_strict_mode(True)  # a bad logging call raises instead of warning
    try:
        write_rrd(roll, path, ic_label="seed slice at x = 1.65, y = 3.9")
    finally:
        rr.set_strict_mode(False)
    return path


@pytest.fixture(scope="module")
def temporal(rrd):
    return read_rrd(rrd)


@pytest.fixture(scope="module")
def static(rrd):
    return read_rrd(rrd, static=True)


def test_timelines_are_steps_and_sim_time(roll, temporal):
    nodes = temporal["/world/die/nodes"]
    np.testing.assert_array_equal(nodes.column("step").to_numpy(), np.arange(roll.steps + 1))
    sim_ns = nodes.column("sim_time").cast(pa.int64()).to_numpy()
    np.testing.assert_allclose(sim_ns * 1e-9, roll.trace.t_s, atol=1e-9)


def test_node_positions_equal_the_trace(roll, temporal):
    pos = values(temporal["/world/die/nodes"], "Points3D:positions", 3)
    assert pos.shape == (roll.steps + 1, 8, 3)
    # Rerun stores positions as float32: equal to the trace rounded to float32
    np.testing.assert_array_equal(pos, roll.trace.node_pos.astype(np.float32))


def test_nodes_red_exactly_while_in_contact(roll, temporal):
    colors = values(temporal["/world/die/nodes"], "Points3D:colors")  # 0xRRGGBBAA
    red = (colors >> 24) & 0xFF
    green = (colors >> 16) & 0xFF
    in_contact = roll.trace.node_pos[..., 2] <= 0.0
    assert in_contact.any() and (~in_contact).any()
    np.testing.assert_array_equal(red > 2 * green + 50, in_contact)


def test_box_pose_matches_the_centre_of_mass_and_has_unit_quaternions(roll, temporal):
    body = temporal["/world/die/body"]
    centers = values(body, "Boxes3D:centers", 3)[:, 0]
    np.testing.assert_array_equal(centers, roll.trace.cm_pos.astype(np.float32))
    q = values(body, "Boxes3D:quaternions", 4)[:, 0].astype(np.float64)
    np.testing.assert_allclose(np.linalg.norm(q, axis=1), 1.0, atol=1e-6)
    # the quaternion turns the body's node offsets into the traced ones
    from scipy.spatial.transform import Rotation

    body_offsets = roll.trace.node_offsets[0]
    rotated = np.einsum("nij,kj->nki", Rotation.from_quat(q).as_matrix(), body_offsets)
    np.testing.assert_allclose(rotated, roll.trace.node_offsets, atol=2e-6)


def _die_pose(temporal) -> tuple[np.ndarray, np.ndarray]:
    """World-from-body rotation matrices and translations of ``world/die/faces``' transform, per step."""
    from scipy.spatial.transform import Rotation

    faces = temporal["/world/die/faces"]
    q = values(faces, "Transform3D:quaternion", 4)[:, 0].astype(np.float64)
    return Rotation.from_quat(q).as_matrix(), values(faces, "Transform3D:translation", 3)[:, 0].astype(np.float64)


def test_face_plates_sit_on_their_faces_in_the_writeup_colours(roll, temporal, static):
    from dicetrace.sinks.rerun import FACE_NODES

    faces = static["/world/die/faces"]
    colors = np.array(faces.column("Boxes3D:colors").to_pylist()[0], dtype=np.uint64)
    rgb = np.stack([(colors >> 24) & 0xFF, (colors >> 16) & 0xFF, (colors >> 8) & 0xFF], axis=1)
    np.testing.assert_array_equal(rgb, FACE_COLORS)
    assert faces.column("Boxes3D:labels").to_pylist()[0] == ["1", "2", "3", "4", "5", "6"]
    assert faces.column("Boxes3D:show_labels").to_pylist()[0] == [False]  # drawn over everything: on hover only
    # static body-frame plates under the die's pose: in the world they sit on the traced faces
    rot, trans = _die_pose(temporal)
    np.testing.assert_array_equal(trans, roll.trace.cm_pos.astype(np.float32))
    body = values(faces, "Boxes3D:centers", 3)[0].astype(np.float64)
    centres = trans[:, None, :] + np.einsum("nij,kj->nki", rot, body)
    half = roll.config.preset.half_side_cm
    traced = roll.trace.node_offsets[:, FACE_NODES, :].mean(axis=2) * (np.linalg.norm(body, axis=1)[:, None] / half)
    np.testing.assert_allclose(centres, roll.trace.cm_pos[:, None, :] + traced, atol=1e-5)
    # at the end the plate of the outcome face is the highest one
    assert int(np.argmax(centres[-1, :, 2])) + 1 == roll.outcome


def test_pips_number_each_face_and_move_with_it(roll, temporal, static):
    """Face k carries k pips, flat on its plate, inside it; at rest the outcome face's pips are on top."""
    from dicetrace.sinks.rerun import FACE_NORMALS

    pips = static["/world/die/faces/pips"]  # a child of the plates: their transform carries it
    assert "/world/die/faces/pips" not in temporal
    pos = values(pips, "Ellipsoids3D:centers", 3)[0].astype(np.float64)
    sizes = values(pips, "Ellipsoids3D:half_sizes", 3)[0].astype(np.float64)
    face = np.array([int(t.split()[-1]) for t in texts(pips, "Ellipsoids3D:labels")])
    plates = static["/world/die/faces"]
    plate_c = values(plates, "Boxes3D:centers", 3)[0].astype(np.float64)
    plate_h = values(plates, "Boxes3D:half_sizes", 3)[0].astype(np.float64)
    np.testing.assert_array_equal(np.bincount(face, minlength=7)[1:], [1, 2, 3, 4, 5, 6])
    for k in range(1, 7):
        n = FACE_NORMALS[k - 1]
        on = pos[face == k]
        top = plate_c[k - 1] @ n + plate_h[k - 1] @ np.abs(n)  # the plate's outer surface along the normal
        np.testing.assert_allclose(on @ n, top, rtol=1e-6)  # centred on it: half in, half out
        thin = sizes[face == k] @ np.abs(n)
        assert (thin < 0.05 * roll.config.preset.half_side_cm).all()  # flat discs
        inplane = np.abs(on - np.outer(on @ n, n)) + (sizes[face == k] - np.outer(thin, np.abs(n)))
        assert (inplane <= plate_h[k - 1] + 1e-6).all(), f"face {k}: a pip reaches past its plate"
        assert len({tuple(p) for p in np.round(on, 6)}) == k  # k distinct pips
    rot, trans = _die_pose(temporal)
    world_z = trans[-1, 2] + pos @ rot[-1][2]
    assert set(face[world_z > trans[-1, 2] + 0.9 * roll.config.preset.half_side_cm]) == {roll.outcome}


def test_face_tables_agree_with_the_node_numbering():
    """Each face's four nodes are the corners on its outward normal, and opposite faces add up to 7."""
    from dicetrace.params import NODE_SIGNS
    from dicetrace.sinks.rerun import FACE_NODES, FACE_NORMALS

    for f in range(6):
        on_face = NODE_SIGNS @ FACE_NORMALS[f] == 1.0
        assert sorted(FACE_NODES[f]) == np.flatnonzero(on_face).tolist(), f"face {f + 1}"
        opposite = 6 - f - 1  # face 7 − (f+1)
        np.testing.assert_array_equal(FACE_NORMALS[opposite], -FACE_NORMALS[f])
    np.testing.assert_array_equal(FACE_NORMALS[2], [0, 0, -1])  # the program's start: face 3 down, face 4 up
    np.testing.assert_array_equal(FACE_NORMALS[3], [0, 0, 1])


def test_energies_equal_the_trace(roll, temporal):
    for key in ("kinetic_translational", "kinetic_rotational", "gravitational", "elastic", "total"):
        got = values(temporal[f"/energy/{key}"], "Scalars:scalars")[:, 0]
        np.testing.assert_array_equal(got, roll.trace.energy[key])
    got = values(temporal["/stop_test/energy"], "Scalars:scalars")[:, 0]
    np.testing.assert_array_equal(got, roll.trace.energy["stop_test"])
    # the margin view: log10 of the energy above the threshold, -3 once it is at or below it (the stop)
    margin = values(temporal["/stop_margin"], "Scalars:scalars")[:, 0]
    above = roll.trace.energy["stop_test"] - roll.config.preset.e_stop
    np.testing.assert_allclose(margin[above > 1e-3], np.log10(above[above > 1e-3]), rtol=1e-12)
    assert margin[-1] == -3.0 and (margin[:-1] > -3.0).all()  # the crossing is the last step, and only it


def test_contact_log_has_exactly_the_roll_events(roll, temporal):
    steps, nodes, kinds = logged_events(temporal)
    ev = roll.contact_events()
    np.testing.assert_array_equal(steps, ev["step"].to_numpy())
    np.testing.assert_array_equal(nodes, ev["node"].to_numpy())
    np.testing.assert_array_equal(kinds, ev["kind"].to_numpy())
    assert sequence_from_events(steps, nodes, kinds) == roll.contact_sequence == SEQ_1_65_3_9


def test_event_markers_sit_at_the_nodes_on_the_event_steps(roll, temporal):
    markers = temporal["/world/contact_events"]
    ev = roll.contact_events()
    ev_steps, ev_nodes, entered = ev["step"].to_numpy(), ev["node"].to_numpy(), (ev["kind"] == "enter").to_numpy()
    np.testing.assert_array_equal(markers.column("step").to_numpy(), np.unique(ev_steps))
    pos = values(markers, "Points3D:positions", 3)
    expected = roll.trace.node_pos[ev_steps, ev_nodes.astype(int) - 1].astype(np.float32)
    np.testing.assert_array_equal(pos.reshape(-1, 3), expected)
    # an entering node is at or below the ground at its event step, a leaving one above it
    np.testing.assert_array_equal(roll.trace.node_pos[ev_steps, ev_nodes.astype(int) - 1, 2] <= 0.0, entered)


def test_exact_contact_events_are_logged_at_their_times(tmp_path):
    """A throw with exact contact events (events=True): the contact log's sim_time is each event's own time,
    inside the step at whose end the change shows (not that step's end), and its step that step."""
    ev_roll = simulate(seed_slice(1.65, 3.9), preset="physical", events=True, record=Record(states=True))
    path = tmp_path / "events.rrd"
    write_rrd(ev_roll, path)
    log = read_rrd(path)["/contacts"]
    ev = ev_roll.contact_events()
    steps, nodes, kinds = logged_events({"/contacts": log})
    np.testing.assert_array_equal(steps, ev["step"].to_numpy())
    np.testing.assert_array_equal(nodes, ev["node"].to_numpy())
    np.testing.assert_array_equal(kinds, ev["kind"].to_numpy())
    t = log.column("sim_time").cast(pa.int64()).to_numpy() * 1e-9
    np.testing.assert_allclose(t, ev["t_s"].to_numpy(), rtol=0, atol=1e-9)  # rerun keeps durations in ns
    end = steps * ev_roll.dt_s
    assert np.all((t > end - ev_roll.dt_s) & (t <= end + 1e-9))
    assert np.mean(end - t > 1e-6) > 0.5  # most events fall well inside their step, not on its end


def test_cm_path_grows_to_the_final_position(roll, temporal):
    path = temporal["/world/cm_path"]
    strips = path.column("LineStrips3D:strips").to_pylist()
    lengths = [len(s[0]) for s in strips]
    assert lengths == sorted(lengths) and lengths[0] >= 2
    assert path.column("step").to_pylist()[-1] == roll.steps
    np.testing.assert_allclose(strips[-1][0][-1], roll.trace.cm_pos[-1], atol=1e-5)
    np.testing.assert_allclose(strips[-1][0][0], roll.trace.cm_pos[0], atol=1e-5)


def test_static_scene_summary_and_z_up(roll, static):
    doc = static["/summary"].column("TextDocument:text").to_pylist()[0][0]
    assert SEQ_1_65_3_9 in doc and "settled" in doc and f"outcome**: {roll.outcome}" in doc
    assert json.dumps(roll.config.as_dict()["preset"]["k"]) in doc
    assert "/world" in static and "ViewCoordinates:xyz" in static["/world"].column_names
    ground = static["/world/ground"]
    centre = np.array(ground.column("Boxes3D:centers").to_pylist()[0][0])
    half = np.array(ground.column("Boxes3D:half_sizes").to_pylist()[0][0])
    assert centre[2] + half[2] == pytest.approx(0.0, abs=1e-6)  # top face is the plane z = 0


def test_recording_metadata_has_config_ic_and_version(roll, rrd):
    import dicetrace

    meta = read_rrd_metadata(rrd)
    assert meta["dicetrace_version"] == dicetrace.__version__
    assert meta["config"] == json.loads(json.dumps(roll.config.as_dict()))
    assert meta["ic"] == roll.ic.tolist()
    assert (meta["outcome"], meta["status"], meta["steps"]) == (3, "settled", roll.steps)
    assert meta["contact_sequence"] == SEQ_1_65_3_9
    assert meta["ic_label"] == "seed slice at x = 1.65, y = 3.9"


def blueprint_rows(path) -> dict[str, dict]:
    """The blueprint store of ``path`` as {entity path: {component: value}} (row ids and log_time left out)."""
    from rerun.chunk import RrdReader

    reader = RrdReader(str(path))
    (store,) = reader.blueprints()
    rows: dict[str, dict] = {}
    for ch in reader.stream(store=store):
        for row in pa.Table.from_batches([ch.to_record_batch()]).to_pylist():
            rows.setdefault(ch.entity_path, {}).update(
                {k: v for k, v in row.items() if k not in ("rerun.controls.RowId", "log_time", "blueprint")}
            )
    return rows


def blueprint_views(rows: dict[str, dict]) -> dict[str, tuple[str, str]]:
    """{view entity: (class, space origin)} of a blueprint's views."""
    return {
        k: (v["ViewBlueprint:class_identifier"][0], v["ViewBlueprint:space_origin"][0])
        for k, v in rows.items()
        if "ViewBlueprint:class_identifier" in v
    }


# The view class that shows each archetype the sink logs.
VIEW_OF_ARCHETYPE = {
    "Points3D": "3D", "Boxes3D": "3D", "Ellipsoids3D": "3D", "Transform3D": "3D", "LineStrips3D": "3D",
    "ViewCoordinates": "3D",
    "Scalars": "TimeSeries", "SeriesLines": "TimeSeries", "TextLog": "TextLog", "TextDocument": "TextDocument",
}  # fmt: skip


def test_blueprint_shows_every_logged_entity_and_no_empty_view(rrd, temporal, static):
    """Each entity the recording logs lies under the origin of a view that can draw it, and each view has data."""
    rows = blueprint_rows(rrd)
    views = blueprint_views(rows)
    assert sorted(views.values()) == sorted(
        [("3D", "/world"), ("TimeSeries", "/energy"), ("TimeSeries", "/stop_test"), ("TextLog", "/contacts"),
         ("TextDocument", "/summary"), ("TimeSeries", "/stop_margin")]
    )  # fmt: skip

    def under(entity, origin):
        return entity == origin or entity.startswith(origin.rstrip("/") + "/")

    logged = {}
    for tables in (temporal, static):
        for entity, t in tables.items():
            logged.setdefault(entity, set()).update(c.split(":")[0] for c in t.column_names if ":" in c)
    assert {"/world/die/nodes", "/world/die/body", "/world/cm_path", "/energy/total", "/stop_test/threshold"} <= set(logged)
    for entity, archetypes in logged.items():
        for arch in archetypes:
            want = VIEW_OF_ARCHETYPE[arch]
            assert any(cls == want and under(entity, origin) for cls, origin in views.values()), (
                f"{entity} ({arch}) is in no {want} view of the blueprint"
            )
    for cls, origin in views.values():
        assert any(under(e, origin) for e in logged), f"the {cls} view of {origin} shows nothing that is logged"
    # every view shows its whole subtree, and the panels point at timelines the recording has
    assert all(rows[k + "/ViewContents"]["ViewContents:query"] == ["$origin/**"] for k in views)
    (log_view,) = [k for k, (cls, _) in views.items() if cls == "TextLog"]
    timelines = set(temporal["/contacts"].column_names) - {c for c in temporal["/contacts"].column_names if ":" in c}
    used = {c["timeline"] for c in rows[log_view + "/TextLogColumns"]["TextLogColumns:timeline_columns"]}
    assert used <= timelines == {"step", "sim_time"}
    assert rows["/time_panel"]["TimePanelBlueprint:timeline"] == ["step"]
    # the layout reaches every view from the viewport's root container
    import uuid

    todo = ["container/" + str(uuid.UUID(bytes=bytes(rows["/viewport"]["ViewportBlueprint:root_container"][0])))]
    reached = set()
    while todo:
        node = todo.pop()
        reached.add("/" + node)
        todo += rows.get("/" + node, {}).get("ContainerBlueprint:contents") or []
    assert set(views) <= reached


#: The 3-D view's vertical field of view in Rerun's viewer 0.41 (its default eye), degrees.
VIEWER_FOV_Y_DEG = 55.0


def in_camera(eye: dict, points: np.ndarray) -> np.ndarray:
    """``points`` in the blueprint camera's frame: (right, up, depth) per point, the eye's look direction as depth."""
    position = np.array(eye["EyeControls3D:position"][0])
    fwd = np.array(eye["EyeControls3D:look_target"][0]) - position
    fwd /= np.linalg.norm(fwd)
    right = np.cross(fwd, eye["EyeControls3D:eye_up"][0])
    right /= np.linalg.norm(right)
    up = np.cross(right, fwd)
    rel = points - position
    return np.stack([rel @ right, rel @ up, rel @ fwd], axis=-1)


def in_view(seen: np.ndarray, aspect: float, fill: float = 1.0) -> np.ndarray:
    """Which points (camera frame, :func:`in_camera`) a 3-D view of width/height ``aspect`` shows within ``fill`` of
    its half-widths: Rerun's field of view is vertical, the view shows ``aspect`` times as much across."""
    tan = np.tan(np.radians(VIEWER_FOV_Y_DEG) / 2) * fill
    return (seen[:, 2] > 0) & (np.abs(seen[:, 0]) <= tan * aspect * seen[:, 2]) & (np.abs(seen[:, 1]) <= tan * seen[:, 2])


def test_camera_frames_the_resting_die_and_its_path_large(roll, rrd):
    """The blueprint's camera (read from the .rrd) sees the resting die and the whole path from its first bounce,
    every node of it, in a 3-D view as narrow as the camera frames for (``VIEW_ASPECT``, width/height 0.6: the
    recording's 3-D view in a viewer window of about 800×900; at 1100×900 it is 0.82), and from as close as that
    allows: the resting die spans at least a sixth of that view's width (it was about a tenth, framing the whole
    drop from across the travel)."""
    from dicetrace.sinks.rerun_view import VIEW_ASPECT

    rows = blueprint_rows(rrd)
    (eye,) = [v for k, v in rows.items() if k.endswith("/EyeControls3D")]
    assert eye["EyeControls3D:eye_up"][0] == [0.0, 0.0, 1.0]
    half = roll.config.preset.half_side_cm
    tr = roll.trace
    nodes = tr.cm_pos[:, None, :] + tr.node_offsets
    first = int(np.flatnonzero(tr.cm_pos[:, 2] <= np.sqrt(3) * half)[0])  # the die may touch the ground from here
    assert 100 < first < roll.steps  # the drop is before it
    seen = in_camera(eye, nodes[first:].reshape(-1, 3))
    tan = np.tan(np.radians(VIEWER_FOV_Y_DEG) / 2)
    assert in_view(seen, VIEW_ASPECT).all(), "a node of the path from the first bounce is out of view"
    assert VIEW_ASPECT <= 0.82 * 0.9  # a viewer window of 1100×900 shows it with room
    rest = in_camera(eye, nodes[-1])
    xs, depth = rest[:, 0], rest[:, 2]
    size = (xs.max() - xs.min()) / (2 * tan * VIEW_ASPECT * depth.mean())  # of the view's width
    assert size > 1 / 6, f"the resting die spans {size:.3f} of the view's width"
    # the camera looks down, and orbits around the point of its axis at the resting die's depth
    centre = in_camera(eye, tr.cm_pos[-1][None, :])[0]
    target = in_camera(eye, np.array(eye["EyeControls3D:look_target"]))[0]
    assert target[2] == pytest.approx(centre[2], rel=1e-4)
    assert np.array(eye["EyeControls3D:position"][0])[2] > tr.cm_pos[-1, 2] + 2 * half


def test_ground_grid_is_one_line_per_die_side_across_the_ground_and_through_the_resting_place(roll, static):
    half = roll.config.preset.half_side_cm
    ground = static["/world/ground"]
    centre = np.array(ground.column("Boxes3D:centers").to_pylist()[0][0])
    extent = np.array(ground.column("Boxes3D:half_sizes").to_pylist()[0][0])
    strips = np.array(static["/world/ground/grid"].column("LineStrips3D:strips").to_pylist()[0], dtype=np.float64)
    assert strips.shape[1:] == (2, 3)
    z = strips[..., 2]
    assert (z > 0).all() and (z < 0.05 * half).all()  # on the ground's top face (z = 0), just above it
    rest = roll.trace.cm_pos[-1, :2]
    nodes = roll.trace.cm_pos[:, None, :2] + roll.trace.node_offsets[..., :2]
    for axis in (0, 1):  # lines of constant x, then of constant y
        lines = strips[strips[:, 0, axis] == strips[:, 1, axis]]
        at = np.sort(lines[:, 0, axis])
        np.testing.assert_allclose(np.diff(at), 2 * half, rtol=1e-6)  # one die side apart (float32 in the file)
        assert np.min(np.abs(at - rest[axis])) < 1e-5  # one through the resting place
        # across the whole ground, which holds every node of the throw
        assert at[0] - 2 * half < centre[axis] - extent[axis] and at[-1] + 2 * half > centre[axis] + extent[axis]
        assert centre[axis] - extent[axis] < nodes[..., axis].min() and nodes[..., axis].max() < centre[axis] + extent[axis]
        other = 1 - axis
        np.testing.assert_allclose(np.sort(lines[:, :, other], axis=1),
                                   np.tile([centre[other] - extent[other], centre[other] + extent[other]], (len(lines), 1)),
                                   rtol=1e-6, atol=1e-5)


@pytest.mark.skipif(not RERUN_CLI.exists() and shutil.which("rerun") is None, reason="rerun CLI not installed")
def test_rerun_rrd_verify_accepts_the_file(rrd):
    exe = str(RERUN_CLI) if RERUN_CLI.exists() else shutil.which("rerun")
    res = subprocess.run([exe, "rrd", "verify", str(rrd)], capture_output=True, text=True, timeout=120)
    assert res.returncode == 0, res.stderr


def test_write_is_atomic_on_error(roll, tmp_path, monkeypatch):
    import dicetrace.sinks.rerun as sink

    target = tmp_path / "keep.rrd"
    target.write_bytes(b"old contents")

    def boom(*a, **k):
        raise RuntimeError("disk on fire")

    monkeypatch.setattr(sink, "log_roll", boom)
    with pytest.raises(RuntimeError, match="disk on fire"):
        write_rrd(roll, target)
    assert target.read_bytes() == b"old contents"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["keep.rrd"]  # no temporary left


def test_needs_states_and_energy(tmp_path):
    r = simulate(seed_slice(1.65, 3.9), record=Record(states=True, energy=False))
    with pytest.raises(ValueError, match="states and energy"):
        write_rrd(r, tmp_path / "x.rrd")
    assert list(tmp_path.iterdir()) == []


def test_failed_run_is_still_recorded(tmp_path):
    # dt = 10 ms is far too coarse for k = 5e5: the energy blows up at the first contact
    r = simulate(seed_slice(1.65, 3.9), dt_s=0.01, record=Record(states=True, energy=True))
    assert r.status == "blow_up"
    path = write_rrd(r, tmp_path / "fail.rrd")
    t = read_rrd(path)
    pos = values(t["/world/die/nodes"], "Points3D:positions", 3)
    assert np.isfinite(pos).all() and 1 <= len(pos) <= r.steps + 1


def test_default_blueprint_without_roll_has_the_same_views_and_no_camera(rrd, tmp_path):
    """Without a roll the layout is the recording's one, only the 3-D camera is left to the viewer."""
    path = tmp_path / "bp.rbl"
    default_blueprint().save("dicetrace", path)
    alone, written = blueprint_rows(path), blueprint_rows(rrd)
    assert sorted(blueprint_views(alone).values()) == sorted(blueprint_views(written).values())
    assert not [k for k in alone if k.endswith("/EyeControls3D")]
    assert [k for k in written if k.endswith("/EyeControls3D")]
    assert alone["/time_panel"] == written["/time_panel"]


# -- compare recordings: several throws and their divergence -------------------------------------


def _scalars(temporal: dict, entity: str) -> tuple[np.ndarray, np.ndarray]:
    t = temporal[entity]
    return np.asarray(t.column("step").to_pylist()), values(t, "Scalars:scalars")[:, 0]


@pytest.fixture(scope="module")
def nudged(roll, tmp_path_factory):
    from dicetrace.sinks.rerun_compare import encode_compare_rrd

    eps = 1e-6
    other = simulate(roll.ic * (1 + eps), record=Record(states=True, energy=True))
    path = tmp_path_factory.mktemp("cmp") / "nudge.rrd"
    path.write_bytes(encode_compare_rrd([roll, other], ["a", "b"]))
    return eps, other, path


def test_compare_recording_holds_each_throw_in_its_colour_and_the_divergence(roll, nudged):
    eps, other, path = nudged
    temporal, static = read_rrd(path), read_rrd(path, static=True)
    colours = []
    for k, r in enumerate((roll, other), start=1):  # numbered from 1, as the explorer's page numbers its picks
        body = temporal[f"/throws/{k}/body"]
        centres = values(body, "Boxes3D:centers", 3)[:, 0]
        # Rerun stores positions as float32; a throw that settled first keeps its last state
        np.testing.assert_array_equal(centres[: r.steps + 1], r.trace.cm_pos[: r.steps + 1].astype(np.float32))
        assert (centres[r.steps + 1 :] == centres[r.steps]).all()
        colours.append(tuple(static[f"/throws/{k}/body"].column("Boxes3D:colors").to_pylist()[0]))
        assert f"/throws/{k}/cm_path" in temporal and f"/throws/{k}/nodes" in temporal
    assert colours[0] != colours[1]
    steps, dist = _scalars(temporal, "/divergence/distance/2")
    assert steps[0] == 0 and len(steps) == max(roll.steps, other.steps) + 1
    # at t = 0 positions and orientations agree; U and L differ by exactly the nudge (relative)
    assert dist[0] == pytest.approx(eps, rel=1e-8)
    lsteps, logd = _scalars(temporal, "/divergence/log10/2")
    np.testing.assert_allclose(logd, np.log10(dist[lsteps]))
    # the position part against the two simulations directly, while both still run
    n = min(roll.steps, other.steps) + 1
    _, dpos = _scalars(temporal, "/divergence/position_cm/2")
    np.testing.assert_allclose(dpos[:n], np.linalg.norm(roll.trace.cm_pos[:n] - other.trace.cm_pos[:n], axis=1))
    # chaos: the red-sea throw's 1e-6 nudge changes its contact sequence, the states end far apart
    assert roll.contact_sequence != other.contact_sequence
    assert dist.max() > 1e4 * eps


def _rgb(table: pa.Table, column: str) -> np.ndarray:
    packed = np.array(table.column(column).to_pylist()[0], dtype=np.uint64)
    return np.stack([(packed >> 24) & 0xFF, (packed >> 16) & 0xFF, (packed >> 8) & 0xFF], axis=1)


def _outer_reach(static: dict, base: str) -> tuple[float, float, float]:
    """A compare die's extents in its body frame, from the recording: (body half side, the plates' half width in
    their face, the farthest any plate or pip reaches out along a face normal)."""
    body = values(static[f"{base}/body"], "Boxes3D:half_sizes", 3)[0, 0].astype(np.float64)
    plates = static[f"{base}/faces"]
    pc = values(plates, "Boxes3D:centers", 3)[0].astype(np.float64)
    ph = values(plates, "Boxes3D:half_sizes", 3)[0].astype(np.float64)
    pips = static[f"{base}/faces/pips"]
    qc = values(pips, "Ellipsoids3D:centers", 3)[0].astype(np.float64)
    qh = values(pips, "Ellipsoids3D:half_sizes", 3)[0].astype(np.float64)
    reach = max((np.abs(pc) + ph).max(), (np.abs(qc) + qh).max())
    return float(body[0]), float(np.sort(ph, axis=1)[:, -1].max()), float(reach)


def test_compare_dice_keep_faces_and_pips_labels_on_hover_and_nest_without_z_fighting(roll, nudged):
    """Each compared die is a whole die (writeup colours, pips, moving with it), its throw shown by its rim, nodes
    and path; labels only on hover; and a later die fits strictly inside the earlier one, so where two coincide
    (a 1e-6 nudge, for most of the throw) the first is seen whole instead of two surfaces flickering."""
    from dicetrace.sinks.rerun_compare import throw_color

    eps, other, path = nudged
    temporal, static = read_rrd(path), read_rrd(path, static=True)
    extents = []
    for k, r in enumerate((roll, other)):
        base = f"/throws/{k + 1}"
        plates = static[f"{base}/faces"]
        np.testing.assert_array_equal(_rgb(plates, "Boxes3D:colors"), FACE_COLORS)
        assert plates.column("Boxes3D:labels").to_pylist()[0] == ["1", "2", "3", "4", "5", "6"]
        pips = static[f"{base}/faces/pips"]
        faces = [int(t.split()[-1]) for t in texts(pips, "Ellipsoids3D:labels")]
        np.testing.assert_array_equal(np.bincount(faces, minlength=7)[1:], [1, 2, 3, 4, 5, 6])
        # the plates (and their pips, a child) move with the throw's own die
        move = temporal[f"{base}/faces"]
        np.testing.assert_array_equal(values(move, "Transform3D:translation", 3)[: r.steps + 1, 0],
                                      r.trace.cm_pos[: r.steps + 1].astype(np.float32))
        np.testing.assert_array_equal(values(move, "Transform3D:quaternion", 4)[:, 0],
                                      values(temporal[f"{base}/body"], "Boxes3D:quaternions", 4)[:, 0])
        # labels on hover only, as in a single recording (a label is drawn over everything)
        for entity, arch in ((f"{base}/faces", "Boxes3D"), (f"{base}/faces/pips", "Ellipsoids3D"),
                             (f"{base}/nodes", "Points3D"), (f"{base}/body", "Boxes3D")):
            assert static[entity].column(f"{arch}:show_labels").to_pylist()[0] == [False], entity
        assert static[f"{base}/nodes"].column("Points3D:labels").to_pylist()[0] == [str(j) for j in range(1, 9)]
        assert tuple(_rgb(static[f"{base}/body"], "Boxes3D:colors")[0]) == throw_color(k)
        extents.append(_outer_reach(static, base))
    (b0, w0, r0), (b1, w1, r1) = extents
    margin = 0.005 * roll.config.preset.half_side_cm
    assert b1 < b0 - margin and w1 < w0 - margin and r1 < r0 - margin  # nested, never coplanar
    # coinciding paths: the later one thinner and lifted by a fixed amount, never the same surface
    paths = [static[f"/throws/{k}/cm_path"].column("LineStrips3D:radii").to_pylist()[0][0] for k in (1, 2)]
    assert paths[1] < 0.8 * paths[0]
    ends = [np.asarray(temporal[f"/throws/{k}/cm_path"].column("LineStrips3D:strips").to_pylist()[-1][0])
            for k in (1, 2)]
    np.testing.assert_allclose(ends[1][0] - ends[0][0], [0, 0, ends[1][0][2] - ends[0][0][2]])
    assert ends[1][0][2] - ends[0][0][2] > margin


def test_side_layout_puts_the_dice_apart_and_keeps_the_divergence(roll, nudged, tmp_path):
    from dicetrace.sinks.rerun_compare import encode_compare_rrd

    eps, other, overlay = nudged
    path = tmp_path / "side.rrd"
    path.write_bytes(encode_compare_rrd([roll, other], ["a", "b"], layout="side"))
    side, over = read_rrd(path), read_rrd(overlay)
    half = roll.config.preset.half_side_cm
    a = values(side["/throws/1/nodes"], "Points3D:positions", 3).astype(np.float64)
    b = values(side["/throws/2/nodes"], "Points3D:positions", 3).astype(np.float64)
    # every node of one die stays farther from every node of the other than a die's size, at every step
    gaps = np.linalg.norm(a[:, :, None, :] - b[:, None, :, :], axis=-1).min(axis=(1, 2))
    assert gaps.min() > 2 * half
    # the shift is a constant, horizontal, to the right as the recording's camera sees it (across its line of
    # sight: the dice side by side on the screen); the divergence is that of the real states
    shift = values(side["/throws/2/body"], "Boxes3D:centers", 3)[:, 0] - values(over["/throws/2/body"], "Boxes3D:centers", 3)[:, 0]
    np.testing.assert_allclose(shift, np.broadcast_to(shift[0], shift.shape), atol=1e-4)
    (eye,) = [v for k, v in blueprint_rows(path).items() if k.endswith("/EyeControls3D")]
    right, up, depth = (in_camera(eye, shift[0][None, :].astype(np.float64)) - in_camera(eye, np.zeros((1, 3))))[0]
    assert shift[0][2] == 0 and right > 2 * half and abs(depth) < 1e-3 * right
    # and the camera sees both dice at rest
    seen = in_camera(eye, np.concatenate([a[-1], b[-1]]))
    assert (np.abs(seen[:, :2]) <= np.tan(np.radians(VIEWER_FOV_Y_DEG) / 2) * seen[:, 2:3]).all()
    for key in ("distance", "log10"):
        np.testing.assert_array_equal(_scalars(side, f"/divergence/{key}/2")[1], _scalars(over, f"/divergence/{key}/2")[1])


def test_identical_throws_have_exactly_zero_divergence(roll, tmp_path):
    from dicetrace.sinks.rerun_compare import encode_compare_rrd

    twin = simulate(roll.ic.copy(), record=Record(states=True, energy=True))
    path = tmp_path / "twins.rrd"
    path.write_bytes(encode_compare_rrd([roll, twin], ["a", "a"]))
    temporal = read_rrd(path)
    _, dist = _scalars(temporal, "/divergence/distance/2")
    assert len(dist) == roll.steps + 1 and (dist == 0).all()
    assert "/divergence/log10/2" not in temporal  # log10(0): nothing to plot


def test_compare_blueprint_shows_the_throws_and_the_log_divergence():
    from dicetrace.sinks.rerun_compare import compare_blueprint

    bp = compare_blueprint()
    views = {type(v).__name__: v for v in _walk(bp.root_container)}
    assert "Spatial3DView" in views and "TimeSeriesView" in views


def test_compare_recording_numbers_its_throws_from_1_as_the_explorers_page_does(roll, nudged):
    """Issue 46 item 7: the page says "throw 1, throw 2 … divergence from throw 1"; the viewer said "throw 1 vs 0 …
    divergence from throw 0".  One numbering, from 1: the dice, their series, the plot's name, the summary."""
    eps, other, path = nudged
    temporal, static = read_rrd(path), read_rrd(path, static=True)
    assert {e.split("/")[2] for e in temporal if e.startswith("/throws/")} == {"1", "2"}
    assert static["/throws/1/body"].column("Boxes3D:labels").to_pylist()[0] == ["throw 1"]
    assert static["/throws/2/body"].column("Boxes3D:labels").to_pylist()[0] == ["throw 2"]
    assert [e for e in temporal if e.startswith("/divergence/")] and all(
        e.endswith("/2") for e in temporal if e.startswith("/divergence/"))
    names = {e: static[e].column("SeriesLines:names").to_pylist()[0][0] for e in static if e.startswith("/divergence/")}
    assert names["/divergence/log10/2"] == "log10 distance, throw 2 vs 1"
    assert all(n.endswith("throw 2 vs 1") for n in names.values()), names
    view_names = [v["ViewBlueprint:display_name"][0] for v in blueprint_rows(path).values() if "ViewBlueprint:display_name" in v]
    assert "log10 divergence from throw 1" in view_names and not [n for n in view_names if "throw 0" in n]
    summary = str(static["/summary"].to_pydict())
    assert "| 1 | a |" in summary and "| 2 | b |" in summary and "throw 0" not in summary


def _lab(rgb) -> np.ndarray:
    """sRGB (0..255) to CIELAB (D65): the colour distance a viewer sees (ΔE, CIE76)."""
    c = np.asarray(rgb, dtype=np.float64) / 255
    c = np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)
    xyz = c @ np.array([[0.4124, 0.3576, 0.1805], [0.2126, 0.7152, 0.0722], [0.0193, 0.1192, 0.9505]]).T
    xyz = xyz / np.array([0.95047, 1.0, 1.08883])
    f = np.where(xyz > 216 / 24389, np.cbrt(xyz), (24389 / 27 * xyz + 16) / 116)
    return np.stack([116 * f[..., 1] - 16, 500 * (f[..., 0] - f[..., 1]), 200 * (f[..., 1] - f[..., 2])], axis=-1)


def test_throw_colours_are_no_face_plates_colours_and_differ_from_each_other(roll, nudged):
    """Issue 46 item 10: a throw drawn blue made face 1 (a blue plate) hard to see in comparisons.  Every throw's
    colour is at least 30 ΔE (CIELAB) from every face colour and from the ground, and 25 from every other throw's
    (the old blue was 25 from face 1, its green 8 from face 2); the recording draws each die in its throw's."""
    from dicetrace.sinks.rerun import GROUND_COLOR
    from dicetrace.sinks.rerun_compare import THROW_COLORS, throw_color

    throws, faces = _lab(THROW_COLORS), _lab(FACE_COLORS)
    to_faces = np.linalg.norm(throws[:, None, :] - faces[None, :, :], axis=-1)
    assert to_faces.min() >= 30, np.round(to_faces, 1)
    assert np.linalg.norm(throws - _lab(GROUND_COLOR), axis=-1).min() >= 25
    pairs = np.linalg.norm(throws[:, None, :] - throws[None, :, :], axis=-1)[np.triu_indices(len(throws), 1)]
    assert pairs.min() >= 25, np.round(pairs, 1)
    _, _, path = nudged
    static = read_rrd(path, static=True)
    for k in (1, 2):
        assert tuple(_rgb(static[f"/throws/{k}/body"], "Boxes3D:colors")[0]) == throw_color(k - 1)


@pytest.mark.parametrize("aspect", [0.3, 0.6, 0.82, 1.6, 3.0])
def test_the_camera_frames_every_resting_die_for_the_views_aspect(roll, nudged, aspect, tmp_path):
    """Issue 46 item 6: the die was cut at the right edge of a view narrower than it is tall: the camera framed a
    square.  Rerun's field of view is vertical: a view of width/height ``aspect`` shows that much across.  For
    each aspect, every node of every resting die (one throw, and the dice of a comparison), and the path from
    the first bounce, lie within the frame's 90 % (FRAME_FILL), for a narrow, a portrait and a wide view alike."""
    from dicetrace.sinks.rerun import encode_rrd_of
    from dicetrace.sinks.rerun_compare import encode_compare_rrd
    from dicetrace.sinks.rerun_view import FRAME_FILL

    _, other, _ = nudged
    half = roll.config.preset.half_side_cm
    one, two = tmp_path / "one.rrd", tmp_path / "two.rrd"
    one.write_bytes(encode_rrd_of(roll, aspect=aspect))
    two.write_bytes(encode_compare_rrd([roll, other], ["a", "b"], aspect=aspect))
    for rolls, path in (([roll], one), ([roll, other], two)):
        (eye,) = [v for k, v in blueprint_rows(path).items() if k.endswith("/EyeControls3D")]
        for r in rolls:
            tr = r.trace
            nodes = tr.cm_pos[:, None, :] + tr.node_offsets
            first = int(np.flatnonzero(tr.cm_pos[:, 2] <= np.sqrt(3) * half)[0])
            rest = in_camera(eye, nodes[-1])
            assert in_view(rest, aspect, FRAME_FILL * 1.001).all(), f"a resting die's corner is out of the frame at {aspect}"
            assert in_view(in_camera(eye, tr.cm_pos[first:]), aspect, FRAME_FILL * 1.001).all()
        # and tight: no farther than that needs, some node of a resting die or of the path near the frame's edge
        framed = np.concatenate([in_camera(eye, (r.trace.cm_pos[:, None, :] + r.trace.node_offsets).reshape(-1, 3))
                                 [np.repeat(r.trace.cm_pos[:, 2] <= np.sqrt(3) * half, 8)] for r in rolls])
        tan = np.tan(np.radians(VIEWER_FOV_Y_DEG) / 2)
        reach = np.maximum(np.abs(framed[:, 0]) / (tan * aspect), np.abs(framed[:, 1]) / tan) / framed[:, 2]
        assert reach.max() > 0.75 * FRAME_FILL, f"the camera is farther than it needs: {reach.max():.3f}"


def _walk(node):
    for c in getattr(node, "contents", []) or []:
        yield c
        yield from _walk(c)


# -- optional channels (record --channels) --------------------------------------------------------

CHANNEL_ENTITIES = ("/world/die/forces/normal", "/world/die/forces/friction", "/world/die/velocities")


@pytest.fixture(scope="module")
def channelled(tmp_path_factory):
    from dicetrace.sinks.rerun import default_blueprint, encode_rrd, roll_logger
    from dicetrace.sinks.rerun_channels import CHANNELS

    r = simulate(seed_slice(1.65, 3.9), record=Record(states=True, energy=True, forces=True))
    path = tmp_path_factory.mktemp("ch") / "channels.rrd"
    chans = frozenset(CHANNELS)
    path.write_bytes(encode_rrd(roll_logger(r, name="ch", channels=chans), default_blueprint(r, chans)))
    return r, path


def test_the_default_recording_has_no_optional_channel(rrd):
    temporal = read_rrd(rrd)
    assert not [e for e in temporal if e in CHANNEL_ENTITIES or e.startswith("/channels")]
    assert "force_arrow_cm_per_unit" not in read_rrd_metadata(rrd)


def test_channels_hold_the_kernels_forces_depths_and_node_velocities(channelled):
    r, path = channelled
    temporal, meta = read_rrd(path), read_rrd_metadata(path)
    tr = r.trace
    nodes = tr.node_pos
    scale = meta["force_arrow_cm_per_unit"]
    for part, cols in (("normal", [2]), ("friction", [0, 1])):
        t = temporal[f"/world/die/forces/{part}"]
        steps = t.column("step").to_pylist()
        assert steps == list(range(r.steps + 1))
        vec = t.column("Arrows3D:vectors").to_pylist()
        org = t.column("Arrows3D:origins").to_pylist()
        n_arrows = 0
        for s, v, o in zip(steps, vec, org):
            contact = np.flatnonzero(nodes[s, :, 2] <= 0.0)
            assert len(v) == len(contact)
            n_arrows += len(v)
            if len(v):
                want = np.zeros((len(contact), 3))
                want[:, cols] = tr.forces[s, contact][:, cols]
                np.testing.assert_allclose(np.array(v) / scale, want, rtol=1e-6, atol=1e-6 * np.abs(tr.forces).max())
                np.testing.assert_allclose(o, nodes[s, contact], rtol=1e-6, atol=1e-5)
        assert n_arrows > 50  # node-steps in contact over the red-sea throw (87)
    # the normal force pushes up while a node is below ground (at least once), and is 0 off the ground
    fz = np.stack([values(temporal[f"/channels/force_normal/{k}"], "Scalars:scalars")[:, 0] for k in range(1, 9)], axis=1)
    np.testing.assert_array_equal(fz, tr.forces[:, :, 2])
    assert (fz[nodes[..., 2] > 0] == 0).all() and (fz > 0).any()
    depth = np.stack([values(temporal[f"/channels/penetration_cm/{k}"], "Scalars:scalars")[:, 0] for k in range(1, 9)], axis=1)
    np.testing.assert_array_equal(depth, np.maximum(0.0, -nodes[..., 2]))
    assert depth.max() > 0
    # node velocities against the traced node positions: finite differences in free flight (before the first impact)
    vel = values(temporal["/world/die/velocities"], "Arrows3D:vectors", 3).reshape(-1, 8, 3) / meta["velocity_arrow_s"]
    first = int(np.flatnonzero((nodes[..., 2] <= 0).any(axis=1))[0])
    fd = (nodes[1:first] - nodes[: first - 1]) / r.dt_s
    np.testing.assert_allclose(vel[1:first], fd, atol=0.01 * np.abs(fd).max())


def test_channels_blueprint_plots_the_depths():
    from dicetrace.sinks.rerun import default_blueprint

    def origins(bp):
        return {str(getattr(v, "origin", "")) for v in _walk(bp.root_container)}

    assert "/channels/penetration_cm" in origins(default_blueprint(None, {"penetration"}))
    assert "/channels/penetration_cm" not in origins(default_blueprint(None))
