"""Rerun sink: one throw as a ``.rrd`` recording with a default blueprint.

Everything per step is logged as columns (``send_columns``) on two timelines,
``step`` (sequence: step n is the state after n steps, 0 the IC) and
``sim_time`` (duration, s), and everything constant once, as static data, in
the manner of rerun's ``imu_signals`` and ``clock`` examples.  There is no
per-step Python loop: a 3000-step throw is written in milliseconds.

Entities (world frame: z up, cm):

``world/ground``            static thin box whose top face is the plane z = 0
``world/die/body``          the die, a solid box (centre + quaternion per step)
``world/die/faces``         six thin coloured plates on the faces (1 blue, 2 green, 3 red,
                            4 magenta, 5 yellow, 6 black), static in the body frame under
                            the die's pose (a transform per step), numbered on hover
``world/die/faces/pips``    each face's number as white pips (1..6 dots, a real die's
                            layout): depth-tested, so a hidden face's pips are hidden
``world/die/nodes``         the eight corner nodes, labelled 1..8 (on hover); red while at
                            or below the ground (z ≤ 0), grey otherwise
``world/cm``                the centre of mass
``world/cm_path``           the centre-of-mass path so far (a growing line strip,
                            updated every ``trail_every`` steps)
``world/contact_events``    the node(s) that entered (red) or left (blue) contact
                            at the latest event step, at their positions then
``energy/<name>``           energies, node-mass·cm²/s² (translational and
                            rotational kinetic, gravitational, elastic, total)
``stop_test/energy``        the program's stop-test energy, with its threshold
``stop_margin``             log10 of the stop-test energy above the threshold (the crossing)
``contacts``                text log: one row per event, "step 176: node 6 enters", on
                            ``sim_time`` at the event's exact time where the throw
                            recorded exact contact events (``Record(events=True)``)
``summary``                 text document: IC, configuration, outcome, status,
                            contact sequence

Optional channels (forces, penetration depths, node velocities) are
logged only when asked: :mod:`dicetrace.sinks.rerun_channels`.  The same
``log(rec)`` (:func:`roll_logger`) feeds the file and the streaming sinks
(:mod:`dicetrace.sinks.rerun_stream`); several throws compared:
:mod:`dicetrace.sinks.rerun_compare`.  The default blueprint and the camera
that frames the throw: :mod:`dicetrace.sinks.rerun_view`.

The recording property ``dicetrace`` (``rec.send_property``) holds the
version, the full configuration (JSON), the IC and the summary:
:func:`read_rrd_metadata`.  Read a file back with ``rerun.chunk.RrdReader`` (needs only
pyarrow) or open it with the ``rerun`` viewer.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

import dicetrace
from dicetrace.ic_arrays import IC_FIELDS
from dicetrace.tables import node_events
from dicetrace.sinks._common import Destination, destination, write_bytes
from dicetrace import body as _body
from dicetrace.sinks.rerun_channels import arrow_scales, log_channels
from dicetrace.sinks.rerun_pips import log_pips
from dicetrace.sinks.rerun_view import default_blueprint

# rerun (and pyarrow, to read a file back) are imported in the functions that use them, not here: they are heavy
# at import, and rerun must not load before a streaming sink has set its log level (rerun_stream.quiet_sdk_logs)

#: Face colours of the writeup: 1 blue, 2 green, 3 red, 4 magenta, 5 yellow, 6 black (RGB).
FACE_COLORS = np.array(
    [[30, 90, 230], [20, 170, 60], [220, 30, 30], [210, 40, 210], [245, 215, 20], [15, 15, 15]],
    dtype=np.uint8,
)
#: Outward unit normal of each face in the body frame (face value 1..6 → row 0..5), and the corner nodes (0-based)
#: of each face in that order: the die's geometry, written once in ``dicetrace.body``.
FACE_NORMALS = _body.FACE_NORMALS
FACE_NODES = _body.FACE_NODE_ROWS

BODY_COLOR = (236, 230, 214)  # ivory
NODE_CONTACT_COLOR = (230, 20, 20)
NODE_FREE_COLOR = (150, 150, 150)
EVENT_ENTER_COLOR = (255, 40, 40)
EVENT_LEAVE_COLOR = (40, 110, 255)
GROUND_COLOR = (120, 150, 120)
#: The ground's grid lines (one per die side) and their height above the ground, in half sides.
GRID_COLOR = (95, 120, 95)
GRID_LIFT = 0.01
CM_COLOR = (255, 140, 0)

ENERGY_SERIES = (
    ("kinetic_translational", "kinetic (translational)", (31, 119, 180)),
    ("kinetic_rotational", "kinetic (rotational)", (255, 127, 14)),
    ("gravitational", "gravitational", (44, 160, 44)),
    ("elastic", "elastic (ground)", (214, 39, 40)),
    ("total", "total", (200, 200, 200)),
)

#: Largest number of updates of the growing centre-of-mass line strip.
MAX_TRAIL_UPDATES = 300


#: Peak memory of recording a throw, per step, in units of its trace arrays (the trace, the recording's per-step
#: arrays while logging, the encoded recording).
RECORD_MEMORY_FACTOR = 8.0


def recording_memory(cfg, n_throws: int = 1, forces: bool = False) -> tuple[int, int, int | None]:
    """What recording ``n_throws`` throws of configuration ``cfg`` may need, before any is simulated:
    (the time cap in steps, bytes of memory, bytes available now or None where unknown).

    The worst case is throws that run to the time cap: max_steps + 1 rows each, states and energies (and
    forces), times :data:`RECORD_MEMORY_FACTOR`.  ``dicetrace record`` refuses what needs more than is
    available, and so do the explorer's viewer throws and comparisons.
    """
    from dicetrace.memory import available_memory
    from dicetrace.simulate import Record, trace_bytes  # lazy: imports numba

    steps = cfg.numerics.max_steps
    need = trace_bytes(steps + 1, Record(states=True, energy=True, forces=forces)) * RECORD_MEMORY_FACTOR * n_throws
    return steps, int(need), available_memory()


def write_rrd(
    roll,
    path,
    *,
    name: str | None = None,
    ic_label: str | None = None,
    trail_every: int | None = None,
    application_id: str = "dicetrace",
) -> Path:
    """Write one throw as a Rerun recording with a default blueprint.

    Parameters
    ----------
    roll
        A :class:`dicetrace.simulate.Roll` whose trace holds states (node
        offsets, centre of mass, L) and energies:
        ``simulate(ic, record=Record(states=True, energy=True))``.
    path
        Output ``.rrd`` file, a character device or FIFO, or ``"-"`` for
        standard output (see :func:`dicetrace.sinks._common.destination`).
        The recording is encoded in memory first; a regular file is then
        written under a temporary name beside it and renamed when complete:
        an existing file is replaced only by a whole new one, and nothing is
        left behind on error (a full disk raises
        :class:`~dicetrace.sinks._common.OutputError` naming the path).
        A symbolic link is followed (its target is written).
    name
        Recording name shown by the viewer (default: the file's stem).
    ic_label
        How the IC was given, e.g. ``"seed slice x=1.65, y=3.9"`` (shown in
        the summary document).
    trail_every
        Steps between updates of the growing centre-of-mass line strip
        (default: the throw's steps / 300, at least 1).  Its cost grows as
        steps² / trail_every².
    application_id
        Rerun application id.

    Returns
    -------
    Path
        ``path``.
    """
    tr = roll.trace
    if tr is None or tr.node_offsets is None or tr.energy is None:
        raise ValueError("write_rrd needs a roll with states and energy: simulate(..., record=Record(states=True, energy=True))")
    dest = destination(path, what="recording", suffix=".rrd")
    name = name or Path(dest.given).stem or "dicetrace"
    data = encode_rrd_of(roll, name=name, ic_label=ic_label, trail_every=trail_every, application_id=application_id)
    write_bytes(dest, data)
    return Path(path) if not isinstance(path, Destination) else Path(dest.given)


def encode_rrd_of(
    roll,
    *,
    name: str = "dicetrace",
    ic_label: str | None = None,
    trail_every: int | None = None,
    application_id: str = "dicetrace",
    activate: bool = False,
    aspect: float | None = None,
) -> bytes:
    """The bytes of :func:`write_rrd`'s recording of ``roll`` (nothing is written); ``activate``: as :func:`encode_rrd`;
    ``aspect``: the width/height of the 3-D view its camera frames for (:func:`~dicetrace.sinks.rerun_view.default_blueprint`)."""
    tr = roll.trace
    if tr is None or tr.node_offsets is None or tr.energy is None:
        raise ValueError("write_rrd needs a roll with states and energy: simulate(..., record=Record(states=True, energy=True))")
    return encode_rrd(roll_logger(roll, name=name, ic_label=ic_label, trail_every=trail_every),
                      default_blueprint(roll, aspect=aspect), application_id=application_id, activate=activate)


def roll_logger(roll, *, name: str = "dicetrace", ic_label: str | None = None, trail_every: int | None = None,
                channels=frozenset()):
    """``log(rec)``: logs the whole recording of ``roll`` (name, property, data) into a stream.

    The one logging path of both the file (:func:`encode_rrd_of`) and the
    streaming sinks (:mod:`dicetrace.sinks.rerun_stream`): they carry the same content.
    ``channels``: optional channels (:mod:`dicetrace.sinks.rerun_channels`).
    """
    scales = {}
    if channels:
        scales = arrow_scales(roll, channels)

    def log(rec) -> None:
        rec.send_recording_name(name)
        rec.send_property("dicetrace", _rr().AnyValues(**metadata_values(roll, ic_label), **scales))
        log_roll(rec, roll, ic_label=ic_label, trail_every=trail_every, channels=channels, scales=scales)

    return log


def _rr():
    import rerun as rr  # rerun is slow to import: only when used

    return rr


#: Longest wait for rerun to finish encoding a recording in memory, s.
ENCODE_TIMEOUT_S = 600.0


def encode_rrd(log, blueprint, *, application_id: str = "dicetrace", activate: bool = False) -> bytes:
    """The bytes of a ``.rrd`` recording: ``log(rec)`` logs into a fresh stream with ``blueprint`` as its default.

    Encoded in memory (rerun's binary stream): all file writing is Python's own (a full disk raises,
    never a stuck background writer).  ``activate`` makes it the active blueprint too: Rerun's web
    viewer (0.41) lays out a recording opened by URL by its own heuristics otherwise.
    """
    rr = _rr()
    rec = rr.RecordingStream(application_id)
    stream = rec.binary_stream()
    try:
        rec.send_blueprint(blueprint, make_active=activate, make_default=True)
        log(rec)
        data = stream.read(flush=True, flush_timeout_sec=ENCODE_TIMEOUT_S)
    finally:
        try:
            rec.disconnect()
        except Exception:  # pragma: no cover - already failing; keep the first error
            pass
    return bytes(data or b"")


def metadata_values(roll, ic_label: str | None = None) -> dict:
    """The recording property ``dicetrace``: version, configuration, IC and summary (cf. the Parquet metadata)."""
    return {
        "dicetrace_version": dicetrace.__version__,
        "config_json": json.dumps(roll.config.as_dict(), sort_keys=True),
        "ic": [float(v) for v in roll.ic],
        "ic_label": ic_label or "",
        "l_convention": roll.config.preset.l_convention,
        "outcome": int(roll.outcome),
        "status": roll.status.label,
        "steps": int(roll.steps),
        "t_settle_s": float(roll.t_settle_s),
        "contact_sequence": roll.contact_sequence,
    }


def read_rrd_metadata(path) -> dict:
    """The ``dicetrace`` recording property of a file written by :func:`write_rrd` (config parsed from JSON)."""
    from rerun.chunk import RrdReader  # rerun is slow to import: only when used

    for ch in RrdReader(str(path)).stream():
        if ch.entity_path == "/__properties/dicetrace":
            row = {k: v[0] for k, v in ch.to_record_batch().to_pydict().items() if k != "rerun.controls.RowId"}
            out = {k: (v[0] if isinstance(v, list) and len(v) == 1 and k != "ic" else v) for k, v in row.items()}
            out["config"] = json.loads(out.pop("config_json"))
            return out
    raise ValueError(f"{path}: no dicetrace metadata")


def summary_markdown(roll, ic_label: str | None = None) -> str:
    """The summary document: IC, configuration, outcome, status, contact sequence."""
    cfg = roll.config
    lines = ["# dicetrace throw", ""]
    if ic_label:
        lines += [f"**IC**: {ic_label}", ""]
    lines += [
        "| " + " | ".join(IC_FIELDS) + " |",
        "|" + "---|" * 6,
        "| " + " | ".join(f"{v:.10g}" for v in roll.ic) + " |",
        "",
        "U in cm/s, L in node-mass·cm²/s "
        + ("(the 2019 program's sign convention)" if cfg.preset.l_convention == "program" else "(physical)"),
        "",
        f"- **outcome**: {roll.outcome} ({_outcome_text(roll.outcome)})",
        f"- **status**: {roll.status}",
        f"- **steps**: {roll.steps}, t_settle_s = {roll.t_settle_s:.6g}",
        f"- **contact sequence**: `{roll.contact_sequence}` ({roll.n_contact_changes} changes"
        + ("; exact contact events: the sets inside the sub-steps, logged at their times)"
           if roll.contact_times is not None else ")"),
        f"- **preset**: {cfg.preset.name}, integrator {cfg.numerics.integrator}, dt = {cfg.numerics.dt_s:g} s, "
        f"t_max = {cfg.numerics.t_max_s:g} s",
        f"- **dicetrace** {dicetrace.__version__}",
        "",
        "Configuration:",
        "",
        "```json",
        json.dumps(cfg.as_dict(), indent=1, sort_keys=True),
        "```",
    ]
    return "\n".join(lines)


def _outcome_text(outcome: int) -> str:
    if outcome > 0:
        return f"face {outcome} up"
    if outcome == 0:
        return "undefined: the top four nodes are no face"
    return "not settled"


def event_texts(steps, nodes, entered) -> list[str]:
    """Text-log lines of contact events, e.g. ``"step 176: node 6 enters"``."""
    return [f"step {int(s)}: node {int(n)} {'enters' if e else 'leaves'}" for s, n, e in zip(steps, nodes, entered)]


def log_roll(rec, roll, *, ic_label: str | None = None, trail_every: int | None = None, channels=frozenset(),
             scales=None) -> None:
    """Log one throw into an open recording stream (see the module docstring)."""
    import rerun as rr  # rerun is slow to import: only when used

    tr = roll.trace
    cfg = roll.config
    body = cfg.preset.body
    half = max(body.half_extents_cm)  # the die's scale: node and arrow sizes, the ground's extent
    # rows with a finite, written state (a numerical failure may end in NaN or unwritten rows)
    rows = tr.written & np.isfinite(tr.cm_pos).all(axis=1) & np.isfinite(tr.node_offsets).all(axis=(1, 2))
    steps = tr.step[rows].astype(np.int64)
    t_s = tr.t_s[rows].astype(np.float64)
    nrow = len(steps)
    if nrow == 0:
        raise ValueError("the trace holds no finite state to record")

    def idx(st, t):
        return [rr.TimeColumn("step", sequence=st), rr.TimeColumn("sim_time", duration=t)]

    index = idx(steps, t_s)
    cm = tr.cm_pos[rows]
    off = tr.node_offsets[rows]  # (nrow, 8, 3)
    nodes = cm[:, None, :] + off
    quat = tr.quat_xyzw[rows]
    energy = {key: np.asarray(v)[rows] for key, v in tr.energy.items()}

    # -- static: frame, ground, summary ------------------------------------------------------
    rec.log("world", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
    log_ground(rec, nodes[..., :2].reshape(-1, 2), half, cm[-1, :2])
    rec.log("summary", rr.TextDocument(summary_markdown(roll, ic_label), media_type=rr.MediaType.MARKDOWN), static=True)

    # -- the die: body box and face plates ---------------------------------------------------------
    rec.log(
        "world/die/body",
        rr.Boxes3D.from_fields(half_sizes=[body.half_extents_cm], colors=[BODY_COLOR], fill_mode="solid"),
        static=True,
    )
    rec.send_columns("world/die/body", indexes=index,
                     columns=rr.Boxes3D.columns(centers=box_centers(body, cm, tr.rotation[rows]), quaternions=quat))

    log_faces(rec, "world/die/faces", body, index, cm, quat)

    # -- nodes: red while in contact -------------------------------------------------------------
    rec.log(
        "world/die/nodes",
        rr.Points3D.from_fields(radii=[0.09 * half], labels=[str(k) for k in range(1, 9)], show_labels=False),
        static=True,
    )
    in_contact = nodes[..., 2] <= 0.0
    node_colors = np.where(in_contact[..., None], NODE_CONTACT_COLOR, NODE_FREE_COLOR).astype(np.uint8)
    rec.send_columns(
        "world/die/nodes",
        indexes=index,
        columns=rr.Points3D.columns(positions=nodes.reshape(-1, 3), colors=node_colors.reshape(-1, 3)).partition(
            np.full(nrow, 8)
        ),
    )

    # -- centre of mass and its path -----------------------------------------------------------
    rec.log("world/cm", rr.Points3D.from_fields(radii=[0.08 * half], colors=[CM_COLOR]), static=True)
    rec.send_columns("world/cm", indexes=index, columns=rr.Points3D.columns(positions=cm))
    _log_trail(rec, rr, cm, steps, t_s, trail_every)

    # -- energies ------------------------------------------------------------------------
    for key, label, color in ENERGY_SERIES:
        rec.log(f"energy/{key}", rr.SeriesLines(names=[label], colors=[color]), static=True)
        rec.send_columns(f"energy/{key}", indexes=index, columns=rr.Scalars.columns(scalars=energy[key]))
    rec.log("stop_test/energy", rr.SeriesLines(names=["stop-test energy"], colors=[(31, 119, 180)]), static=True)
    rec.send_columns("stop_test/energy", indexes=index, columns=rr.Scalars.columns(scalars=energy["stop_test"]))
    e_stop = float(cfg.preset.e_stop)
    rec.log(
        "stop_test/threshold",
        rr.SeriesLines(names=[f"threshold {e_stop:.1f}"], colors=[(214, 39, 40)], widths=[1.0]),
        static=True,
    )
    ends = np.array([steps[0], steps[-1]], dtype=np.int64)
    rec.send_columns(
        "stop_test/threshold", indexes=idx(ends, t_s[[0, -1]]), columns=rr.Scalars.columns(scalars=[e_stop, e_stop])
    )
    rec.log("stop_margin", rr.SeriesLines(names=["log10(E − threshold), −3 at or below it"]), static=True)
    # math.log10 (the C library's), not np.log10: numpy's vectorised log10 differs by an ulp between CPUs (its SIMD
    # loops), and a recording is the same bits on every machine (the golden files)
    margin = np.array([math.log10(v) for v in np.maximum(np.asarray(energy["stop_test"], float) - e_stop, 1e-3)])
    rec.send_columns("stop_margin", indexes=index, columns=rr.Scalars.columns(scalars=margin))

    # -- contact events: text log and markers --------------------------------------------------
    # the contacts table's events: on sim_time at the end of their step, or at their exact time where the throw
    # recorded exact contact events (the markers stay on their step: they show the nodes there)
    _, ev_steps, ev_t, ev_nodes, ev_enter = node_events(roll)
    if len(ev_steps):
        texts = event_texts(ev_steps, ev_nodes, ev_enter)
        rec.send_columns(
            "contacts",
            indexes=idx(ev_steps, ev_t),
            columns=rr.TextLog.columns(
                text=texts,
                level=np.where(ev_enter, "INFO", "DEBUG").tolist(),
                color=np.where(ev_enter[:, None], EVENT_ENTER_COLOR, EVENT_LEAVE_COLOR).astype(np.uint8),
            ),
        )
        # markers: one row per event step holding every node that changed then
        row_of_step = np.full(int(tr.step[-1]) + 1, -1, dtype=np.int64)
        row_of_step[steps] = np.arange(nrow)
        ok = (ev_steps <= tr.step[-1]) & (row_of_step[np.minimum(ev_steps, tr.step[-1])] >= 0)
        es, en, ee = ev_steps[ok], ev_nodes[ok].astype(np.int64), ev_enter[ok]
        uniq, counts = np.unique(es, return_counts=True)
        rec.log(
            "world/contact_events",
            rr.Points3D.from_fields(radii=[0.16 * half], show_labels=False),
            static=True,
        )
        rec.send_columns(
            "world/contact_events",
            indexes=idx(uniq, uniq * roll.dt_s),
            columns=rr.Points3D.columns(
                positions=nodes[row_of_step[es], en - 1, :],
                colors=np.where(ee[:, None], EVENT_ENTER_COLOR, EVENT_LEAVE_COLOR).astype(np.uint8),
                labels=[f"{n} {'in' if e else 'out'}" for n, e in zip(en, ee)],
            ).partition(counts),
        )
    else:
        rec.log("contacts", rr.TextLog("no contact events", level="DEBUG"), static=True)
    if channels:
        log_channels(rec, roll, channels, rows, index, scales or arrow_scales(roll, channels))


def log_ground(rec, xy: np.ndarray, half: float, anchor: np.ndarray) -> None:
    """The ground sized to what happens on it: a thin box whose top face is z = 0 under every point of ``xy``
    (and the origin) with 3 half sides to spare, and on it ``world/ground/grid``, a line every die side,
    one of them through ``anchor`` (the resting place) each way: the die's scale, across the whole ground."""
    import rerun as rr  # rerun is slow to import: only when used

    lo = np.minimum(xy.min(axis=0), -3 * half)
    hi = np.maximum(xy.max(axis=0), 3 * half)
    centre = 0.5 * (lo + hi)
    extent = 0.5 * (hi - lo) + 3.0 * half
    thick = 0.05 * half
    rec.log(
        "world/ground",
        rr.Boxes3D(
            centers=[[centre[0], centre[1], -thick]],
            half_sizes=[[extent[0], extent[1], thick]],
            colors=[GROUND_COLOR],
            fill_mode="solid",
        ),
        static=True,
    )
    side, z = 2.0 * half, GRID_LIFT * half
    g0, g1 = centre - extent, centre + extent
    strips = []
    for axis in (0, 1):
        other = 1 - axis
        first = anchor[axis] + side * np.ceil((g0[axis] - anchor[axis]) / side)
        for v in np.arange(first, g1[axis] + 1e-9 * side, side):
            a, b = np.zeros(3), np.zeros(3)
            a[axis] = b[axis] = v
            a[other], b[other] = g0[other], g1[other]
            a[2] = b[2] = z
            strips.append([a, b])
    rec.log("world/ground/grid", rr.LineStrips3D(strips, radii=rr.Radius.ui_points(1.0), colors=[GRID_COLOR]),
            static=True)


def box_centers(body, cm, rotation) -> np.ndarray:
    """The box's centre in the world (n, 3): the centre of mass ``cm`` less the centre of mass's offset in the body
    frame, turned by ``rotation`` (n, 3, 3); the centre of mass itself for a uniform die."""
    com = np.asarray(body.com_cm)
    if not com.any():
        return cm
    return cm - np.einsum("nij,j->ni", rotation, com)


def log_faces(rec, entity: str, body, index, cm, quat) -> None:
    """The die's six face plates (writeup colours, numbered on hover) and their pips at ``entity``.

    ``body``: the die's :class:`dicetrace.body.Body`.  Static in the body frame, whose origin is the centre of
    mass, carried by the die's pose: one transform per step (centre ``cm``, quaternion ``quat``, xyzw) on the
    ``index`` timelines.  The pips are the child ``entity/pips``.
    """
    import rerun as rr  # rerun is slow to import: only when used

    h = np.asarray(body.half_extents_cm)
    plate_t = 0.02 * float(h.min())
    # each plate: thin along its normal, 62 % of the face's extent along the face's two axes
    plate_half = np.where(FACE_NORMALS != 0, plate_t, 0.62 * h)
    out = np.abs(FACE_NORMALS) @ h  # the face's distance from the box's centre
    center = -np.asarray(body.com_cm)
    rec.log(
        entity,
        rr.Boxes3D.from_fields(
            centers=center + FACE_NORMALS * (out + plate_t)[:, None],
            half_sizes=plate_half,
            colors=FACE_COLORS,
            fill_mode="solid",
            labels=[str(v) for v in range(1, 7)],
            show_labels=False,  # on hover only: a label is drawn over everything, a hidden face's too
        ),
        static=True,
    )
    rec.send_columns(entity, indexes=index, columns=rr.Transform3D.columns(translation=cm, quaternion=quat))
    log_pips(rec, f"{entity}/pips", FACE_NORMALS, h, lift=out + 2 * plate_t, center=center)


def _log_trail(rec, rr, cm, steps, t_s, trail_every, *, entity: str = "world/cm_path", color=CM_COLOR,
               radius: float = 0.03) -> None:
    """The growing centre-of-mass line strip, updated every ``trail_every`` steps.

    Update u (at row r_u) holds the path sampled every ``trail_every`` rows up
    to r_u, and the exact point at r_u; its size grows as (rows / every)², so
    ``every`` defaults to rows / MAX_TRAIL_UPDATES.
    """
    nrow = len(steps)
    every = int(trail_every) if trail_every else max(1, -(-nrow // MAX_TRAIL_UPDATES))
    if every < 1:
        raise ValueError(f"trail_every must be >= 1, got {trail_every}")
    rows = np.arange(1, nrow, every)
    if rows.size == 0 or rows[-1] != nrow - 1:
        rows = np.append(rows, nrow - 1)
    rows = rows[rows >= 1]
    if rows.size == 0:
        return
    sampled = cm[::every]  # sampled[i] = cm[i*every]
    strips = []
    for r in rows:  # one strip per update (≤ MAX_TRAIL_UPDATES by default), not per step
        nfull = r // every + 1
        pts = sampled[:nfull]
        if (nfull - 1) * every != r:
            pts = np.concatenate([pts, cm[r : r + 1]])
        strips.append(pts)
    rec.log(entity, rr.LineStrips3D.from_fields(radii=[radius], colors=[color]), static=True)
    rec.send_columns(
        entity,
        indexes=[rr.TimeColumn("step", sequence=steps[rows]), rr.TimeColumn("sim_time", duration=t_s[rows])],
        columns=rr.LineStrips3D.columns(strips=strips),
    )


def read_rrd(path, *, static: bool = False) -> dict:
    """Read a recording's chunks back as one Arrow table per entity (needs only pyarrow).

    Parameters
    ----------
    path
        A ``.rrd`` file (its first recording store is read).
    static
        Return the static data instead of the temporal data.

    Returns
    -------
    dict
        Entity path (e.g. ``"/world/die/nodes"``) → ``pyarrow.Table``;
        temporal tables are sorted by the ``step`` timeline.  Component
        columns are named ``Archetype:field`` (``"Points3D:positions"``) and
        hold one list of instances per row.
    """
    import pyarrow as pa  # rerun (and its pyarrow) are slow to import: only when used
    from rerun.chunk import RrdReader

    parts: dict[str, list] = {}
    for ch in RrdReader(str(path)).stream():
        if ch.entity_path.startswith("/__properties") or bool(ch.is_static) != static:
            continue
        rb = ch.to_record_batch()
        keep = [n for n in rb.schema.names if n != "rerun.controls.RowId"]
        parts.setdefault(ch.entity_path, []).append(pa.Table.from_batches([rb]).select(keep))
    out = {}
    for entity, tables in parts.items():
        t = pa.concat_tables(tables, promote_options="default") if len(tables) > 1 else tables[0]
        if not static and "step" in t.column_names:
            t = t.sort_by("step")
        out[entity] = t
    return out
