"""Rerun compare recording: several throws side by side and their divergence from the first, on a log scale.

Entities (world frame: z up, cm):

``world/ground``               the ground plane (as in a single-throw recording)
Throws are numbered from 1, in the order given (the explorer's page numbers its picks the same way);
throw 1 is the reference.

``throws/<k>/body``            throw k's die, a solid box in its own colour (:data:`THROW_COLORS`, none
                               of them a face's): the rim around its face plates, so each die keeps its
                               faces and shows its throw
``throws/<k>/faces``           its six face plates in the writeup's colours, numbered on hover, and
``throws/<k>/faces/pips``      their pips, as in a single recording (one transform per step)
``throws/<k>/nodes``           its eight corner nodes in its colour, labelled 1..8 on hover
``throws/<k>/cm_path``         its centre-of-mass path so far
``divergence/log10/<k>``       log10 of the phase-space distance of throw k from throw 1 (k ≥ 2);
                               steps where the distance is exactly 0 are left out (no logarithm)
``divergence/distance/<k>``    the distance itself (dimensionless), every step
``divergence/position_cm/<k>`` |Δ centre of mass|, cm
``divergence/angle_rad/<k>``   rotation angle between the two orientations, rad
``summary``                    text document: each throw's IC, outcome and contact sequence

The distance (:func:`divergence`) is the max norm of four relative parts,
each scaled by throw 1's initial values: |Δx| / side, the rotation angle
between the orientations (rad), |ΔU| / |U₀| and |ΔL| / |L₀|.  At t = 0 the
positions and orientations agree, so for a throw whose IC is throw 1's
scaled by (1 + ε) (``--nudge ε``) it is exactly ε up to rounding.
Rerun 0.41 plots have no logarithmic axis, hence the log10 series.  A throw
that settles before another keeps its last state.

Layouts (:data:`LAYOUTS`): ``overlay`` (the default) draws each die where it is;
throw k's die is drawn :data:`SHRINK` smaller per k, so that where dice coincide
(a small nudge, before it grows) the first one is seen whole, with no flicker of
coincident surfaces (z-fighting).  ``side`` puts each throw beside the previous
one, left to right as the default camera sees them, so that every die is always seen.
"""

from __future__ import annotations

import numpy as np

from dicetrace.body import Body, rotations
from dicetrace.sinks.rerun import _log_trail, box_centers, encode_rrd, log_faces, log_ground, metadata_values
from dicetrace.sinks.rerun_view import framed_points, framing_eye, layout_blueprint, view_axes

# rerun is imported in the functions that log or lay out, not here: heavy at import, and it must not load before a
# streaming sink has set its log level (rerun_stream.quiet_sdk_logs)

#: One colour per throw (cycled): orange, cyan, pink, brown, lavender, tan.  None is a face plate's colour
#: (``dicetrace.sinks.rerun.FACE_COLORS``: blue, green, red, magenta, yellow, black), so a die's rim never
#: reads as a face: each is at least 38 CIELAB ΔE from every face colour and 32 from the others.
THROW_COLORS = np.array(
    [[255, 127, 14], [23, 190, 207], [227, 119, 194], [140, 86, 75], [180, 160, 240], [210, 180, 140]], dtype=np.uint8
)


def throw_color(k: int) -> tuple[int, int, int]:
    """The colour of the throw at index ``k`` (0: throw 1, the reference), cycled."""
    return tuple(int(c) for c in THROW_COLORS[k % len(THROW_COLORS)])


def _padded(roll, n: int) -> dict:
    """Throw's state arrays over rows 0..n-1, the last state repeated past its end."""
    tr = roll.trace
    rows = np.flatnonzero(tr.written & np.isfinite(tr.cm_pos).all(axis=1))
    take = np.minimum(np.arange(n), rows[-1])
    return {
        "cm": tr.cm_pos[take],
        "vel": tr.cm_vel[take],
        "L": tr.L[take],
        "off": tr.node_offsets[take],
        "quat": tr.quat_xyzw[take],
    }


def common_length(rolls) -> int:
    """Rows of the comparison: those of the longest throw (all share the time step)."""
    return max(int(np.flatnonzero(r.trace.written)[-1]) + 1 for r in rolls)


def rotation_angle(qa: np.ndarray, qb: np.ndarray) -> np.ndarray:
    """Angle (rad) of the rotation taking orientation ``qa`` to ``qb`` (quaternions xyzw, per row).

    From the relative quaternion q = conj(qa)·qb as 2·atan2(|q_xyz|, |q_w|):
    exactly 0 for equal inputs (an arccos of the trace would give ~1e-8).
    """
    va, wa = qa[:, :3], qa[:, 3]
    vb, wb = qb[:, :3], qb[:, 3]
    w = wa * wb + np.einsum("ni,ni->n", va, vb)
    v = wa[:, None] * vb - wb[:, None] * va - np.cross(va, vb)
    return 2.0 * np.arctan2(np.linalg.norm(v, axis=1), np.abs(w))


def divergence(ref: dict, other: dict, *, side_cm: float, u0: float, l0: float) -> dict:
    """Distance of ``other`` from ``ref`` per row: ``distance`` (max norm, see the module docstring) and its parts."""
    dpos = np.linalg.norm(other["cm"] - ref["cm"], axis=1)
    ang = rotation_angle(ref["quat"], other["quat"])
    dvel = np.linalg.norm(other["vel"] - ref["vel"], axis=1)
    dl = np.linalg.norm(other["L"] - ref["L"], axis=1)
    parts = np.stack([dpos / side_cm, ang, dvel / max(u0, 1e-300), dl / max(l0, 1e-300)])
    return {"distance": parts.max(axis=0), "position_cm": dpos, "angle_rad": ang}


def scaled_body(body: Body, scale: float) -> Body:
    """``body`` drawn ``scale`` times its size (each throw's die a little larger than the one before, so coinciding
    dice do not flicker): its half-extents and its load's place scaled alike."""
    return Body(tuple(scale * v for v in body.half_extents_cm), body.load_fraction,
                tuple(scale * v for v in body.load_cm))


def compare_series(rolls) -> tuple[np.ndarray, np.ndarray, list[dict]]:
    """(step, t_s, [divergence of each later throw from the first: throw 2, 3, ... from throw 1])."""
    n = common_length(rolls)
    dt = rolls[0].dt_s
    states = [_padded(r, n) for r in rolls]
    cfg = rolls[0].config
    side = 2.0 * max(cfg.preset.body.half_extents_cm)
    u0 = float(np.linalg.norm(rolls[0].ic[:3]))
    l0 = float(np.linalg.norm(rolls[0].ic[3:]))
    divs = [divergence(states[0], s, side_cm=side, u0=u0, l0=l0) for s in states[1:]]
    steps = np.arange(n, dtype=np.int64)
    return steps, steps * dt, divs


def compare_summary(rolls, labels) -> str:
    lines = ["# dicetrace: throws compared", "",
             "Divergence: max norm of |Δx|/side, rotation angle (rad), |ΔU|/|U₀|, |ΔL|/|L₀| "
             "(throw 1's initial values), against throw 1; plotted as log10.", "",
             "| throw | IC | outcome | status | steps | contact sequence |", "|---|---|---|---|---|---|"]
    for k, (r, lab) in enumerate(zip(rolls, labels)):
        lines.append(f"| {k + 1} | {lab} | {r.outcome} | {r.status} | {r.steps} | `{r.contact_sequence}` |")
    return "\n".join(lines)


#: Layouts of the dice: at their own positions (overlay), or each throw beside the previous one (side).
LAYOUTS = ("overlay", "side")
#: Throw k's die is drawn this much smaller per k (relative, up to :data:`MAX_SHRUNK` throws): where two dice
#: coincide (a small nudge, before it grows) the first one is seen whole instead of flickering surfaces.
SHRINK = 0.03
MAX_SHRUNK = 10
#: The centre-of-mass path's radius (throw 1, in half sides), and the factor per throw after it; the lift of throw
#: k's path per k, in half sides (overlay): where paths coincide each shows as a band around the next one.
PATH_RADIUS = 0.03
PATH_THIN = 0.6
PATH_LIFT = 0.02


def drawn_half(half: float, k: int) -> float:
    """The half side throw ``k``'s die is drawn with (see :data:`SHRINK`)."""
    return half * (1.0 - SHRINK * min(k, MAX_SHRUNK))


def layout_offsets(states, half: float, layout: str = "overlay") -> np.ndarray:
    """(throws, 3) display offsets of each throw's die: zero for ``overlay``; for ``side`` a row from left to
    right as the default camera sees it (horizontal, across its line of sight), spaced so that no two paths
    (dice included) ever touch."""
    n = len(states)
    if layout == "overlay":
        return np.zeros((n, 3))
    if layout != "side":
        raise ValueError(f"layout must be one of {', '.join(LAYOUTS)}, got {layout!r}")
    cm0 = states[0]["cm"]
    across = view_axes(cm0[-1, :2] - cm0[0, :2], half)[1]  # the camera's right: horizontal
    reach = [((s["cm"][:, None, :] + s["off"]) @ across) for s in states]  # every node's position across
    gap = 3.0 * half
    offsets, edge = [0.0], float(reach[0].max())
    for r in reach[1:]:
        shift = edge + gap - float(r.min())
        offsets.append(shift)
        edge = shift + float(r.max())
    return np.outer(offsets, across)


def log_compare(rec, rolls, labels, *, layout: str = "overlay") -> None:
    """Log the throws and their divergence into an open recording stream.

    Each die as in a single recording (face colours, pips, numbers and node labels on hover),
    its body (the rim around the face plates), nodes and path in the throw's colour; ``layout``:
    :data:`LAYOUTS`.  The divergence is always that of the real states, whatever the layout.
    """
    import rerun as rr  # rerun is slow to import: only when used

    body = rolls[0].config.preset.body
    half = max(body.half_extents_cm)
    steps, t_s, divs = compare_series(rolls)
    n = len(steps)

    def idx(st, t):
        return [rr.TimeColumn("step", sequence=st), rr.TimeColumn("sim_time", duration=t)]

    rec.log("/", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
    states = [_padded(r, n) for r in rolls]
    shifts = layout_offsets(states, half, layout)
    allxy = np.concatenate([(s["cm"][:, None, :] + s["off"] + o)[..., :2].reshape(-1, 2) for s, o in zip(states, shifts)])
    log_ground(rec, allxy, half, states[0]["cm"][-1, :2] + shifts[0][:2])
    rec.log("summary", rr.TextDocument(compare_summary(rolls, labels), media_type=rr.MediaType.MARKDOWN), static=True)

    for k, s in enumerate(states):
        color = throw_color(k)
        base = f"throws/{k + 1}"
        index = idx(steps, t_s)
        h = drawn_half(half, k)
        drawn = scaled_body(body, h / half)
        cm = s["cm"] + shifts[k]
        rec.log(f"{base}/body", rr.Boxes3D.from_fields(half_sizes=[drawn.half_extents_cm], colors=[color],
                                                       fill_mode="solid", labels=[f"throw {k + 1}"],
                                                       show_labels=False), static=True)
        centers = box_centers(drawn, cm, rotations(s["off"]))
        rec.send_columns(f"{base}/body", indexes=index,
                         columns=rr.Boxes3D.columns(centers=centers, quaternions=s["quat"]))
        log_faces(rec, f"{base}/faces", drawn, index, cm, s["quat"])
        rec.log(f"{base}/nodes", rr.Points3D.from_fields(radii=[0.07 * h], colors=[color],
                                                        labels=[str(j) for j in range(1, 9)], show_labels=False),
                static=True)
        nodes = cm[:, None, :] + s["off"] * (h / half)
        rec.send_columns(f"{base}/nodes", indexes=index,
                         columns=rr.Points3D.columns(positions=nodes.reshape(-1, 3)).partition(np.full(n, 8)))
        # coinciding paths would flicker: a later throw's path is thinner and lifted a little, drawn as a core
        # line of its colour inside the earlier ones (overlay; beside each other they never coincide)
        lift = np.array([0.0, 0.0, PATH_LIFT * half * min(k, MAX_SHRUNK)]) if layout == "overlay" else 0.0
        _log_trail(rec, rr, cm + lift, steps, t_s, None, entity=f"{base}/cm_path", color=color,
                   radius=PATH_RADIUS * half * PATH_THIN ** min(k, MAX_SHRUNK))

    for k, d in enumerate(divs, start=2):  # throw k (numbered from 1) against throw 1
        color = throw_color(k - 1)
        dist = d["distance"]
        pos = dist > 0
        rec.log(f"divergence/log10/{k}", rr.SeriesLines(names=[f"log10 distance, throw {k} vs 1"], colors=[color]),
                static=True)
        if pos.any():
            rec.send_columns(f"divergence/log10/{k}", indexes=idx(steps[pos], t_s[pos]),
                             columns=rr.Scalars.columns(scalars=np.log10(dist[pos])))
        for key in ("distance", "position_cm", "angle_rad"):
            rec.log(f"divergence/{key}/{k}", rr.SeriesLines(names=[f"{key}, throw {k} vs 1"], colors=[color]),
                    static=True)
            rec.send_columns(f"divergence/{key}/{k}", indexes=idx(steps, t_s), columns=rr.Scalars.columns(scalars=d[key]))


def compare_blueprint(rolls=None, layout: str = "overlay", aspect: float | None = None):
    """3-D view of all throws, the log10 divergence plot and the summary.

    With ``rolls``, the 3-D camera frames every die's resting place and path from its first bounce (as
    ``layout`` places them; :func:`dicetrace.sinks.rerun_view.framing_eye`, for a 3-D view of width/height
    ``aspect``, default :data:`~dicetrace.sinks.rerun_view.VIEW_ASPECT`), orbiting at their mean resting place.
    """
    import rerun.blueprint as rrb  # rerun is slow to import: only when used

    eye = None
    if rolls:
        half = max(rolls[0].config.preset.body.half_extents_cm)
        n = common_length(rolls)
        states = [_padded(r, n) for r in rolls]
        shifts = layout_offsets(states, half, layout)
        framed = [framed_points(s["cm"] + o, half) for s, o in zip(states, shifts)]  # each die's path and rest
        cm0 = states[0]["cm"]
        eye = framing_eye(np.concatenate([pts for pts, _ in framed] + [np.array([r for _, r in framed])]),
                          np.mean([r for _, r in framed], axis=0), cm0[-1, :2] - cm0[0, :2], half, aspect)
    view3d = rrb.Spatial3DView(origin="/", contents=["/world/**", "/throws/**"], name="throws", eye_controls=eye,
                               background=(250, 250, 250), line_grid=rrb.LineGrid3D(visible=False))
    div = rrb.TimeSeriesView(origin="/divergence/log10", name="log10 divergence from throw 1",
                             plot_legend=rrb.PlotLegend(corner="RightBottom"))
    pos = rrb.TimeSeriesView(origin="/divergence/position_cm", name="|Δ centre of mass| (cm)",
                             plot_legend=rrb.PlotLegend(corner="LeftTop"))
    right = rrb.Vertical(div, rrb.Tabs(pos, rrb.TextDocumentView(origin="/summary", name="summary")), row_shares=[3, 2])
    return layout_blueprint(rrb, view3d, right)


def compare_logger(rolls, labels, *, name: str = "dicetrace compare", layout: str = "overlay"):
    """``log(rec)`` of the compare recording (the file and the streaming sinks share it)."""
    import rerun as rr  # rerun is slow to import: only when used

    if layout not in LAYOUTS:
        raise ValueError(f"layout must be one of {', '.join(LAYOUTS)}, got {layout!r}")

    def log(rec) -> None:
        rec.send_recording_name(name)
        meta = metadata_values(rolls[0], labels[0])
        meta["n_throws"] = len(rolls)
        meta["layout"] = layout
        rec.send_property("dicetrace", rr.AnyValues(**meta))
        log_compare(rec, rolls, labels, layout=layout)

    return log


def encode_compare_rrd(rolls, labels, *, name: str = "dicetrace compare", application_id: str = "dicetrace",
                       layout: str = "overlay", aspect: float | None = None, activate: bool = False) -> bytes:
    """The bytes of the compare recording of ``rolls`` (throw 1, the first, the reference; ``layout``: :data:`LAYOUTS`;
    ``aspect``: as :func:`compare_blueprint`; ``activate``: as :func:`~dicetrace.sinks.rerun.encode_rrd`)."""
    return encode_rrd(compare_logger(rolls, labels, name=name, layout=layout), compare_blueprint(rolls, layout, aspect),
                      application_id=application_id, activate=activate)
