"""The die's pips: each face's number as 1..6 dots in a real die's layout, drawn as flat discs.

Rerun draws labels on top of everything, so a face number given as a label
shows through the die onto the faces turned towards the camera.  Solid
ellipsoids are depth-tested like the box: a hidden face's pips are hidden with their face.
:func:`pip_offsets` places them in the body frame, just outside the face
plates; the recording (:mod:`dicetrace.sinks.rerun`) logs them once, static,
under the transform that carries the plates with the die.
"""

from __future__ import annotations

import numpy as np

# rerun is imported in the functions that log, not here: heavy at import, and it must not load before a streaming
# sink has set its log level (rerun_stream.quiet_sdk_logs)

#: Pip positions of each face value (row 0 = face 1) on a square of side 2, in the
#: face's two in-plane axes (u, v): the standard layout (1 centre; 2 and 3 a diagonal;
#: 4 the corners; 5 the corners and the centre; 6 two rows of three).
PIP_LAYOUT = (
    ((0, 0),),
    ((-1, -1), (1, 1)),
    ((-1, -1), (0, 0), (1, 1)),
    ((-1, -1), (-1, 1), (1, -1), (1, 1)),
    ((-1, -1), (-1, 1), (0, 0), (1, -1), (1, 1)),
    ((-1, -1), (-1, 0), (-1, 1), (1, -1), (1, 0), (1, 1)),
)

#: Pip colour: white, against every face colour (the darkest, face 6, is black).
PIP_COLOR = (255, 255, 255)
#: Pip radius and half-thickness, in units of the die's half side.
PIP_RADIUS = 0.13
PIP_THICKNESS = 0.015


def pip_offsets(normals, half, lift, spread: float = 0.4, center=(0.0, 0.0, 0.0)) -> tuple[np.ndarray, np.ndarray]:
    """Body-frame positions of all 21 pips and the face value (1..6) of each.

    ``normals``: the outward unit normal of each face (row 0 = face 1, along a
    body axis); ``half``: the half side (cm), or the box's three half-extents;
    the pips of a face lie in the plane at ``lift`` (cm, one for all faces or
    one per face) from the box's centre along its normal, ``spread`` times the
    half-extent from the face's centre line along each of its two axes;
    ``center``: the box's centre in the frame the positions are given in (the
    die's frame is centred on its centre of mass).
    """
    normals = np.asarray(normals, dtype=np.float64)
    h = np.broadcast_to(np.asarray(half, dtype=np.float64), (3,))
    lifts = np.broadcast_to(np.asarray(lift, dtype=np.float64), (len(normals),))
    c = np.asarray(center, dtype=np.float64)
    pos, face = [], []
    for f, n in enumerate(normals):
        axis = int(np.flatnonzero(n)[0])
        a_u, a_v = [a for a in range(3) if a != axis]
        u, v = np.eye(3)[[a_u, a_v]]
        for a, b in PIP_LAYOUT[f]:
            pos.append(c + lifts[f] * n + spread * (a * h[a_u] * u + b * h[a_v] * v))
            face.append(f + 1)
    return np.array(pos), np.array(face, dtype=np.int64)


def log_pips(rec, entity: str, normals, half, lift, center=(0.0, 0.0, 0.0)) -> None:
    """Log the pips once, static, at ``entity`` (a child of the plates' entity: it moves with their transform).

    Each pip is a flat solid disc (an ellipsoid thin along its face's normal) whose centre is
    ``lift`` from the die's centre: it stands out of its plate by about its thickness, not more,
    so it does not show past the die's edge while its face is turned away.
    """
    import rerun as rr  # rerun is slow to import: only when used

    pos, face = pip_offsets(normals, half, lift, center=center)
    normal = np.abs(np.asarray(normals, dtype=np.float64))[face - 1]
    h = np.broadcast_to(np.asarray(half, dtype=np.float64), (3,))
    # a round pip, its radius set by the face's shorter side, thin along the normal (the thickness the cube's)
    side = np.array([min(h[a] for a in range(3) if not normal[i, a]) for i in range(len(face))])
    half_sizes = np.where(normal > 0, PIP_THICKNESS * float(h.min()), PIP_RADIUS * side[:, None])
    rec.log(
        entity,
        rr.Ellipsoids3D.from_fields(centers=pos, half_sizes=half_sizes, colors=[PIP_COLOR], fill_mode="solid",
                                    labels=[f"face {v}" for v in face], show_labels=False),
        static=True,
    )
