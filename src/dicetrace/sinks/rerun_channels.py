"""Optional Rerun channels of one throw (``record --channels``): contact forces, penetration depths, node velocities.

Computed and logged only when asked; the default recording stays lean.

``forces``      ``world/die/forces/normal`` and ``world/die/forces/friction``:
                arrows at the nodes in contact (z ≤ 0) of the kernel's traced
                contact force (``Record(forces=True)``), split into its normal
                (z, the ground's normal) and friction (horizontal) parts;
                ``channels/force_normal/<k>`` the normal part of node k, every step
``penetration`` ``channels/penetration_cm/<k>``: depth of node k below the ground,
                max(0, −z), cm, every step
``velocities``  ``world/die/velocities``: an arrow per node of its velocity
                u_k = U + x_k × ω (the kernel's formula, program convention,
                ω = R·I⁻¹·Rᵀ·L_program, the cube's L_program / inertia), cm/s

Arrows are drawn at a fixed scale per recording, stored in the recording
property ``dicetrace`` as ``force_arrow_cm_per_unit`` and
``velocity_arrow_s`` (arrow length = value × scale).
"""

from __future__ import annotations

import numpy as np

from dicetrace.params import convert_l

# rerun is imported in the functions that log, not here: heavy at import, and it must not load before a streaming
# sink has set its log level (rerun_stream.quiet_sdk_logs)

CHANNELS = ("forces", "penetration", "velocities")
NORMAL_COLOR = (200, 30, 200)
FRICTION_COLOR = (0, 160, 200)
VELOCITY_COLOR = (90, 90, 220)


def parse_channels(text: str | None) -> frozenset:
    """``"forces,penetration"`` → a set of channel names; raises ValueError naming an unknown one."""
    if text is None:
        return frozenset()
    names = [t.strip() for t in text.split(",") if t.strip()]
    bad = [n for n in names if n not in CHANNELS and n != "all"]
    if bad or not names:
        raise ValueError(f"unknown channel {', '.join(map(repr, bad)) or repr(text)}: choose from {', '.join(CHANNELS)} or all")
    return frozenset(CHANNELS) if "all" in names else frozenset(names)


def node_velocities(roll) -> np.ndarray:
    """(n+1, 8, 3) node velocities u_k = U + x_k × ω, ω = R·I⁻¹·Rᵀ·L_program (the kernel's formula; the cube's
    L_program / inertia), cm/s."""
    tr = roll.trace
    cfg = roll.config
    ic_rows = np.concatenate([tr.cm_vel, tr.L], axis=1)
    l_prog = convert_l(ic_rows, cfg.preset.l_convention, "program")[:, 3:]
    w = cfg.preset.body.angular_velocity(l_prog, tr.rotation)
    return tr.cm_vel[:, None, :] + np.cross(tr.node_offsets, w[:, None, :])


def arrow_scales(roll, channels) -> dict:
    """Per-recording arrow scales: the largest arrow is about two die sides long."""
    half = max(roll.config.preset.body.half_extents_cm)
    out = {}
    if "forces" in channels and roll.trace.forces is not None:
        fmax = float(np.abs(roll.trace.forces[np.isfinite(roll.trace.forces)]).max(initial=0.0))
        out["force_arrow_cm_per_unit"] = 4.0 * half / fmax if fmax > 0 else 1.0
    if "velocities" in channels:
        v = node_velocities(roll)
        vmax = float(np.linalg.norm(v, axis=2)[np.isfinite(v).all(axis=2)].max(initial=0.0))
        out["velocity_arrow_s"] = 4.0 * half / vmax if vmax > 0 else 1.0
    return out


def log_channels(rec, roll, channels, rows, index, scales) -> None:
    """Log the asked-for channels for the trace ``rows`` (the same rows as the main recording)."""
    import rerun as rr  # rerun is slow to import: only when used

    tr = roll.trace
    nodes = (tr.cm_pos[:, None, :] + tr.node_offsets)[rows]
    nrow = len(nodes)
    if "forces" in channels:
        if tr.forces is None:
            raise ValueError("--channels forces needs a trace with forces: simulate(..., record=Record(forces=True))")
        F = tr.forces[rows]
        contact = nodes[..., 2] <= 0.0
        counts = contact.sum(axis=1)
        s = scales["force_arrow_cm_per_unit"]
        normal = np.zeros_like(F[contact])
        normal[:, 2] = F[contact][:, 2]
        friction = F[contact].copy()
        friction[:, 2] = 0.0
        for name, vec, color in (("normal", normal, NORMAL_COLOR), ("friction", friction, FRICTION_COLOR)):
            ent = f"world/die/forces/{name}"
            rec.log(ent, rr.Arrows3D.from_fields(colors=[color], radii=[0.02]), static=True)
            rec.send_columns(ent, indexes=index, columns=rr.Arrows3D.columns(
                origins=nodes[contact], vectors=vec * s).partition(counts))
        for k in range(8):
            rec.log(f"channels/force_normal/{k + 1}", rr.SeriesLines(names=[f"node {k + 1}"]), static=True)
            rec.send_columns(f"channels/force_normal/{k + 1}", indexes=index,
                             columns=rr.Scalars.columns(scalars=F[:, k, 2]))
    if "penetration" in channels:
        depth = np.maximum(0.0, -nodes[..., 2])
        for k in range(8):
            rec.log(f"channels/penetration_cm/{k + 1}", rr.SeriesLines(names=[f"node {k + 1}"]), static=True)
            rec.send_columns(f"channels/penetration_cm/{k + 1}", indexes=index,
                             columns=rr.Scalars.columns(scalars=depth[:, k]))
    if "velocities" in channels:
        v = node_velocities(roll)[rows]
        rec.log("world/die/velocities", rr.Arrows3D.from_fields(colors=[VELOCITY_COLOR], radii=[0.015]), static=True)
        rec.send_columns("world/die/velocities", indexes=index, columns=rr.Arrows3D.columns(
            origins=nodes.reshape(-1, 3), vectors=(v * scales["velocity_arrow_s"]).reshape(-1, 3)).partition(
            np.full(nrow, 8)))


def channel_views(channels) -> list:
    """Plot views of the asked-for scalar channels (for the default blueprint)."""
    import rerun.blueprint as rrb  # rerun is slow to import: only when used

    views = []
    if "penetration" in channels:
        views.append(rrb.TimeSeriesView(origin="/channels/penetration_cm", name="penetration depth (cm)"))
    if "forces" in channels:
        views.append(rrb.TimeSeriesView(origin="/channels/force_normal", name="normal force per node"))
    return views
