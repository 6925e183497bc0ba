"""The default view of a Rerun recording: its blueprint and the 3-D camera that frames a throw.

:func:`default_blueprint` lays out a single throw's recording (:mod:`dicetrace.sinks.rerun`): the 3-D
view of the world beside the energy plots, the contact log and the summary (and the plots of the
optional channels, :mod:`dicetrace.sinks.rerun_channels`); :func:`layout_blueprint` is the layout it
shares with the compare recording (:mod:`dicetrace.sinks.rerun_compare`).

The 3-D camera (:func:`framing_eye`) looks back along the throw's travel from beyond the resting
place, and is placed by a linear programme (``scipy.optimize.linprog``) as close to the resting die
as keeps the path from its first bounce, with the whole die around every point, inside the view.
Rerun's field of view is vertical (55°): how much the view shows across depends on the view's own
width/height, its aspect, which a recording cannot know.  The camera frames for an aspect
(``aspect``, default :data:`VIEW_ASPECT`: the default layout's 3-D view in a viewer window as narrow
as about 800×900), so in any view at least that wide for its height every die is inside with a margin;
the explorer passes the aspect of the view its page shows.
The recording's own Rerun grid is off: the ground carries a grid of its own
(:func:`dicetrace.sinks.rerun.log_ground`).
"""

from __future__ import annotations

import numpy as np

from dicetrace.sinks.rerun_channels import channel_views

#: The 3-D view's vertical field of view in Rerun's viewer (0.41: 55°), and the share of it the framing fills.
VIEW_FOV_Y_DEG = 55.0
FRAME_FILL = 0.9
#: The default camera: its azimuth from the throw's travel, seen from beyond the resting place (deg), and elevation.
EYE_AZIMUTH_DEG = 35.0
EYE_ELEVATION_DEG = 30.0
#: Most path points the framing looks at (the path is subsampled above it).
FRAME_POINTS = 400
#: The width/height of the 3-D view the default camera frames for when the view's own is not known (a
#: recording opened in Rerun's viewer): the default layout's 3-D view (3/5 of the window's width, the height
#: less the viewer's bars) is 0.82 in a 1100×900 window (0.85 in the viewer's default 1600×1200), 0.67 at
#: 900×900, 0.6 at 800×900.  Narrower is safer, and draws the dice smaller in a wide window (a die is drawn at
#: the same size whatever the width: Rerun's field of view is vertical).
VIEW_ASPECT = 0.6
#: The aspects a camera may be framed for.
ASPECT_RANGE = (0.2, 5.0)


def check_aspect(aspect) -> float:
    """``aspect`` (None: :data:`VIEW_ASPECT`) as a float in :data:`ASPECT_RANGE`, or ValueError."""
    if aspect is None:
        return VIEW_ASPECT
    try:
        a = float(aspect)
    except (TypeError, ValueError):
        raise ValueError(f"aspect must be a number (the 3-D view's width/height), got {aspect!r}") from None
    if not ASPECT_RANGE[0] <= a <= ASPECT_RANGE[1]:  # NaN fails too
        raise ValueError(f"aspect must be in [{ASPECT_RANGE[0]:g}, {ASPECT_RANGE[1]:g}] (the 3-D view's "
                         f"width/height), got {aspect!r}")
    return a


def framed_points(cm: np.ndarray, half: float) -> tuple[np.ndarray, np.ndarray]:
    """What the default camera frames: (centre-of-mass points, the resting place), from one path.

    The path from the first row where the die may touch the ground (centre of mass within √3·half
    of it: the bounces, where the outcome is decided) to its end, and the resting place; the drop
    before the first bounce rises out of the frame.  A path that never comes down is framed whole.
    """
    cm = cm[np.isfinite(cm).all(axis=1)]
    near = np.flatnonzero(cm[:, 2] <= np.sqrt(3.0) * half + 1e-9)
    pts = cm[near[0]:] if len(near) else cm
    if len(pts) > FRAME_POINTS:
        pts = pts[np.linspace(0, len(pts) - 1, FRAME_POINTS).round().astype(int)]
    return pts, cm[-1]


def view_axes(travel: np.ndarray, half: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The default camera's (forward, right, up) unit vectors for a throw whose horizontal travel is ``travel``.

    It looks back along the travel from beyond the resting place, :data:`EYE_AZIMUTH_DEG` to the
    travel's right and :data:`EYE_ELEVATION_DEG` from above (a travel shorter than half a side: along +y).
    """
    norm = float(np.hypot(*travel))
    d = np.asarray(travel, dtype=float) / norm if norm > half else np.array([0.0, 1.0])
    az, el = np.radians(EYE_AZIMUTH_DEG), np.radians(EYE_ELEVATION_DEG)
    back = np.cos(az) * d + np.sin(az) * np.array([d[1], -d[0]])  # from the resting place towards the camera
    fwd = -np.array([back[0] * np.cos(el), back[1] * np.cos(el), np.sin(el)])
    right = np.cross(fwd, [0.0, 0.0, 1.0])
    right /= np.linalg.norm(right)
    return fwd, right, np.cross(right, fwd)


def framing_eye(points: np.ndarray, rest: np.ndarray, travel: np.ndarray, half: float, aspect: float | None = None):
    """The camera closest to ``rest`` that sees every point of ``points`` with the whole die around it.

    It looks from beyond the resting place back along the ``travel`` (horizontal, start to rest),
    :data:`EYE_AZIMUTH_DEG` to its side and :data:`EYE_ELEVATION_DEG` from above; its distance is
    the solution of a linear programme: every point's sphere of the die's circumradius lies within
    :data:`FRAME_FILL` of the view's field of view (:data:`VIEW_FOV_Y_DEG` up and down, and across
    as much as a view of width/height ``aspect`` shows, default :data:`VIEW_ASPECT`), as close to
    the resting die as that allows; a second one centres the view at that distance (the tightest
    side of the frame gets the most room).  It orbits around the point in front of it at the
    resting die's depth.
    """
    # rerun and scipy.optimize are imported here, not at the top: heavy at import (scipy.optimize ~0.3 s), and
    # rerun must not load before the caller has set its log level (rerun_stream.quiet_sdk_logs)
    import rerun.blueprint as rrb
    from scipy.optimize import linprog

    fwd, right, up = view_axes(travel, half)
    ky = np.tan(np.radians(VIEW_FOV_Y_DEG) / 2) * FRAME_FILL  # up and down: the vertical field of view
    kx = ky * check_aspect(aspect)  # across: as much as the view's width shows
    # for each point p and side a (slope k): a·(p - E) - k·fwd·(p - E) <= -rho_k, p's sphere of the die's
    # circumradius inside that side of the frustum (rho_k: the radius over the side plane's normal's cosine)
    sides = np.stack([right, -right, up, -up])
    ks = np.array([kx, kx, ky, ky])
    rhos = np.sqrt(3.0) * half * np.sqrt(1 + ks * ks)
    pts = np.vstack([points, rest[None, :]])
    a_ub = np.repeat(ks[:, None] * fwd[None, :] - sides, len(pts), axis=0)
    b_ub = np.concatenate([-(pts @ (a - k * fwd)) - rho for a, k, rho in zip(sides, ks, rhos)])
    res = linprog(-fwd, A_ub=a_ub, b_ub=b_ub, bounds=[(None, None)] * 3, method="highs")
    if res.status != 0:  # pragma: no cover - a bounded, feasible programme
        raise RuntimeError(f"framing the die: {res.message}")
    # then, as close as that, centred: the eye that gives the tightest side the most room, left/right and
    # up/down each (margins mh, mv: a frame filled one way may still have room the other way)
    closest = float(fwd @ (rest - res.x))
    n = len(pts)
    margins = np.zeros((4 * n, 2))
    margins[: 2 * n, 0] = margins[2 * n :, 1] = 1.0  # rows: right, left sides, then up, down
    a2 = np.vstack([np.hstack([a_ub, margins]), np.append(-fwd, [0.0, 0.0])[None, :]])
    b2 = np.append(b_ub, closest * (1 + 1e-9) + 1e-9 * half - float(fwd @ rest))
    res2 = linprog(np.array([0.0, 0.0, 0.0, -1.0, -1.0]), A_ub=a2, b_ub=b2,
                   bounds=[(None, None)] * 3 + [(0, None)] * 2, method="highs")
    eye = res2.x[:3] if res2.status == 0 else res.x
    target = eye + fwd * float(fwd @ (rest - eye))
    return rrb.EyeControls3D(position=eye, look_target=target, eye_up=[0.0, 0.0, 1.0])


def _eye_for(cm: np.ndarray, half: float, aspect: float | None = None):
    """The default camera of a throw whose centre of mass follows ``cm`` (:func:`framing_eye`, for a 3-D view of
    width/height ``aspect``); None without a path."""
    cm = cm[np.isfinite(cm).all(axis=1)]
    if len(cm) == 0:
        return None
    points, rest = framed_points(cm, half)
    return framing_eye(points, rest, cm[-1, :2] - cm[0, :2], half, aspect)


def default_blueprint(roll=None, channels=(), aspect: float | None = None):
    """3-D view of the world, energy plots, the contact log and the summary (and plots of scalar ``channels``).

    With a ``roll``, the 3-D camera frames its path, for a 3-D view of width/height ``aspect`` (default
    :data:`VIEW_ASPECT`).
    """
    import rerun.blueprint as rrb  # rerun only when a blueprint is made (heavy; its log level is set first)

    eye = None
    if roll is not None and roll.trace is not None and roll.trace.cm_pos is not None:
        eye = _eye_for(roll.trace.cm_pos, max(roll.config.preset.body.half_extents_cm), aspect)

    view3d = rrb.Spatial3DView(
        origin="/world",
        name="die",
        eye_controls=eye,
        background=(250, 250, 250),
        line_grid=rrb.LineGrid3D(visible=False),  # the ground has its own grid (log_ground)
    )
    energy = rrb.TimeSeriesView(
        origin="/energy",
        name="energy (node-mass·cm²/s²)",
        axis_x=rrb.TimeAxis(link="LinkToGlobal"),
        plot_legend=rrb.PlotLegend(corner="RightTop"),
    )
    stop = rrb.TimeSeriesView(origin="/stop_test", name="stop-test energy", plot_legend=rrb.PlotLegend(corner="RightTop"))
    right = rrb.Vertical(
        energy,
        stop,
        rrb.Tabs(
            rrb.TextLogView(
                origin="/contacts",
                name="contact events",
                columns=rrb.TextLogColumns(
                    timeline_columns=[rrb.encodings.TimelineColumn("sim_time")],
                    text_log_columns=[rrb.encodings.TextLogColumn("Body")],
                ),
            ),
            rrb.TextDocumentView(origin="/summary", name="summary"),
            rrb.TimeSeriesView(origin="/stop_margin", name="stop-test margin (log10)"),
            *channel_views(channels),
        ),
        row_shares=[3, 2, 3])
    return layout_blueprint(rrb, view3d, right)


def layout_blueprint(rrb, view3d, right):
    """dicetrace's layout: the 3-D view, ``right`` beside it; side panels collapsed, time following the end."""
    return rrb.Blueprint(rrb.Horizontal(view3d, right, column_shares=[3, 2]), rrb.BlueprintPanel(state="collapsed"),
                         rrb.SelectionPanel(state="collapsed"),
                         rrb.TimePanel(state="collapsed", timeline="step", play_state="following"), auto_views=False)
