"""Triple points of a 2-D outcome map and whether their throws pass near a corner balance.

The corner balance (:mod:`dicetrace.analysis.corner`) has two unstable
directions, so the throws that end on it form a set of codimension 2 in the
space of initial conditions; a generic 2-D slice crosses it at isolated
points where three faces meet, in three sectors.  Here:

* :func:`clean_junctions`: the nodes of a label grid where three outcomes
  meet (every two of them grid neighbours) with no fourth outcome, no
  undefined or unsettled throw nearby: the candidates;
* :func:`refine_triple`: :func:`~dicetrace.analysis.vertices.find_vertices`
  (recursive splitting of the squares that hold the three faces, each level
  sampled with the simulator) on a small window about a candidate, down to a
  tolerance; a ``"vertex"`` row is a point located to that tolerance;
* :func:`circle_sectors`: the outcomes on a circle about a point, their arcs
  (cyclic runs of one outcome) and each arc's border bisected in angle:
  three sectors on every circle of a shrinking series is what a triple point
  looks like;
* :func:`corner_distance`: how close a throw comes to a corner balance: per
  trace row, with the lowest node as the pivot, ``D² = α² + (|ω⊥|/λ)² +
  (|U|/(λ d))²`` (``α``: the tilt of the centre of mass from straight above
  the pivot; ``|ω⊥|``: the angular speed across the pivot–centre axis (a
  spin about it keeps the balance), ``|U|``: the centre's speed, turned
  into angles by the corner's rate ``λ`` and the half diagonal ``d``); 0 at
  the balance, 0.62 at rest on an edge, 0.96 at rest on a face.
"""

from __future__ import annotations

import math

import numpy as np

from .vertices import guarded_find_vertices

__all__ = ["clean_junctions", "refine_triple", "circle_sectors", "corner_distance", "arcs"]


def clean_junctions(labels: np.ndarray, *, radius: int = 2, min_share: float = 0.0, exclude=(-1, 0)) -> np.ndarray:
    """Grid indices (n, 2) of the boxes (lower-left node) where exactly three outcomes meet, clean around.

    A box of one grid interval is kept when its four nodes hold three
    outcomes, the ``(2·radius + 2)²`` nodes about it hold exactly those three,
    none of them in ``exclude``, every two of the three are grid neighbours
    there, and each holds at least ``min_share`` of those nodes (a sliver of
    a third face along a border is not a junction of three sectors).
    """
    g = np.asarray(labels)
    nx, ny = g.shape
    out = []
    for i in range(radius, nx - radius - 1):
        for j in range(radius, ny - radius - 1):
            box = g[i: i + 2, j: j + 2]
            if len(np.unique(box)) < 3:
                continue
            nb = g[i - radius: i + radius + 2, j - radius: j + radius + 2]
            labs, counts = np.unique(nb, return_counts=True)
            if len(labs) != 3 or any(v in exclude for v in labs.tolist()) or counts.min() < min_share * nb.size:
                continue
            pairs = set()
            for a, b in ((nb[:-1], nb[1:]), (nb[:, :-1], nb[:, 1:])):
                m = a != b
                pairs |= {tuple(sorted(p)) for p in zip(a[m].tolist(), b[m].tolist())}
            if len(pairs) == 3:
                out.append((i, j))
    return np.array(out, dtype=np.int64).reshape(-1, 2)


def refine_triple(classify, centre, half_width: float, *, tol: float, res: int = 5, max_squares: int = 64) -> dict:
    """Locate a triple point near ``centre`` with :func:`~dicetrace.analysis.vertices.guarded_find_vertices`.

    The window is the square of half side ``half_width`` about ``centre``;
    the rows of ``find_vertices`` with their status.  Returns the best row
    (``"vertex"`` first, then the deepest) with ``n_rows`` and the status
    counts, and ``evals`` (throws).
    """
    cx, cy = map(float, centre)
    h = float(half_width)
    try:
        df = guarded_find_vertices(classify, (cx - h, cx + h), (cy - h, cy + h), res, tol=tol,
                                   max_squares=max_squares, exclude=(-1, 0))
    except MemoryError as e:  # a root spread too wide at depth (find_vertices draws it on a dense image)
        return {"status": "memory", "error": str(e), "evals": 0, "status_counts": {}}
    counts = df["status"].value_counts().to_dict()
    if not len(df):
        return {"status": "none", "evals": int(df.attrs["n_evals"]), "status_counts": counts}
    df = df.assign(rank=(df["status"] != "vertex").astype(int), size=df[["size_x", "size_y"]].max(axis=1))
    best = df.sort_values(["rank", "depth", "size"], ascending=[True, False, True]).iloc[0]
    return {"status": str(best["status"]), "x": float(best["x"]), "y": float(best["y"]),
            "size": float(best["size"]), "depth": int(best["depth"]),
            "labels": [int(v) for v in best["labels"]], "n_squares": int(best["n_squares"]),
            "status_counts": {str(k): int(v) for k, v in counts.items()}, "evals": int(df.attrs["n_evals"]),
            "n_vertex": int(counts.get("vertex", 0))}


def arcs(labels) -> list[tuple]:
    """Cyclic runs of equal labels on a ring: (label, first index, last index), the first starting after a change."""
    lab = list(labels)
    n = len(lab)
    change = [i for i in range(n) if lab[i] != lab[i - 1]]
    if not change:
        return [(lab[0], 0, n - 1)]
    out = []
    for k, s in enumerate(change):
        e = change[(k + 1) % len(change)] - 1
        out.append((lab[s], s, e % n))
    return out


def circle_sectors(classify, centre, radius: float, *, n: int = 48, angle_tol: float = 1e-6) -> dict:
    """The outcomes on the circle of ``radius`` about ``centre``: arcs, and each arc's start bisected in angle.

    ``three_sectors``: exactly three arcs of three different faces (no
    undefined or unsettled throw).  ``borders``: angle (rad), half bracket,
    the labels either side.  ``evals``: throws.
    """
    cx, cy = map(float, centre)
    ang = np.linspace(0.0, 2 * math.pi, int(n), endpoint=False)
    pts = np.column_stack([cx + radius * np.cos(ang), cy + radius * np.sin(ang)])
    lab = [int(v) for v in np.asarray(classify(pts)).ravel()]
    evals = len(lab)
    runs = arcs(lab)
    borders = []
    if len(runs) > 1:
        for lb, s, _ in runs:
            a, b = float(ang[s - 1]), float(ang[s]) + (2 * math.pi if s == 0 else 0.0)
            la = lab[s - 1]
            while b - a > angle_tol:
                m = 0.5 * (a + b)
                lm = int(classify(np.array([[cx + radius * math.cos(m), cy + radius * math.sin(m)]]))[0])
                evals += 1
                if lm == la:
                    a = m
                else:
                    b, lb = m, lm
            borders.append({"angle": math.fmod(0.5 * (a + b), 2 * math.pi), "error": 0.5 * (b - a),
                            "from": la, "to": lb})
    faces = [r[0] for r in runs]
    three = len(runs) == 3 and len(set(faces)) == 3 and all(f > 0 for f in faces)
    return {"radius": float(radius), "n": int(n), "arcs": [[int(f), int(s), int(e)] for f, s, e in runs],
            "faces": faces, "n_arcs": len(runs), "three_sectors": bool(three), "borders": borders, "evals": evals}


def corner_distance(trace, rate: float, d: float, inertia: float, *, near: float = 0.05) -> dict:
    """How close a throw comes to a corner balance (module docstring): the minimum of ``D`` over the trace rows,
    where it is reached (time, pivot node, tilt, tilting and spin rates, centre speed) and the time spent with
    ``D < near``.

    Only the angular velocity across the pivot–centre axis counts (``omega``): a spin about that axis, ``spin``,
    neither tilts the die nor moves its centre, and a die spinning on its corner is still balanced on it.
    """
    ok = trace.written
    off = trace.node_offsets[ok]
    t = trace.t_s[ok]
    z = trace.cm_pos[ok][:, 2][:, None] + off[:, :, 2]
    low = np.argmin(z, axis=1)
    up = -off[np.arange(len(low)), low]
    axis = up / np.linalg.norm(up, axis=1)[:, None]
    alpha = np.arctan2(np.hypot(up[:, 0], up[:, 1]), up[:, 2])
    w = trace.L[ok] / inertia  # the sign convention does not matter for the magnitudes below
    spin = np.abs(np.einsum("ij,ij->i", w, axis))
    tilting = np.linalg.norm(w - np.einsum("ij,ij->i", w, axis)[:, None] * axis, axis=1)
    u = np.linalg.norm(trace.cm_vel[ok], axis=1)
    D = np.sqrt(alpha**2 + (tilting / rate) ** 2 + (u / (rate * d)) ** 2)
    i = int(np.argmin(D))
    dt = float(np.median(np.diff(t))) if len(t) > 1 else 0.0
    return {"d_min": float(D[i]), "t_min": float(t[i]), "node": int(low[i]) + 1, "tilt": float(alpha[i]),
            "omega": float(tilting[i]), "spin": float(spin[i]), "speed": float(u[i]),
            "t_near": float(dt * np.count_nonzero(D < near)), "height": float(z[i, low[i]])}
