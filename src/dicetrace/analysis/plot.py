"""Figures in the style of the 2019 writeup.

matplotlib is imported inside each function, so importing
:mod:`dicetrace.analysis` never needs it. Every function returns the
:class:`matplotlib.figure.Figure` and, given ``path``, saves it there (the
animation saves a GIF). Grids are indexed ``[i, j]`` with ``i`` along x, and
drawn with x to the right and y up.

Face colours follow the writeup: 1 blue, 2 green, 3 red, 4 magenta, 5 yellow,
6 black; 0 ("undefined") grey and -1 ("did not settle") white.
"""

from __future__ import annotations

import math
import os
from collections.abc import Iterable, Mapping, Sequence

import numpy as np

from .grouping import contact_sequence_text
from .wedge import ball_hill_separatrices, ball_hill_vector_field

__all__ = [
    "FACE_COLORS",
    "FACE_LABELS",
    "plot_outcome_map",
    "plot_zoom_series",
    "plot_settle_map",
    "animate_slices",
    "plot_contact_tree",
    "plot_ball_hill_phase_portrait",
]

#: Colour of each label (matplotlib colour names).
FACE_COLORS: dict[int, str] = {
    -1: "white",
    0: "grey",
    1: "blue",
    2: "green",
    3: "red",
    4: "magenta",
    5: "yellow",
    6: "black",
}
#: Legend text of each label.
FACE_LABELS: dict[int, str] = {
    -1: "did not settle",
    0: "undefined",
    1: "1",
    2: "2",
    3: "3",
    4: "4",
    5: "5",
    6: "6",
}
_ORDER = [-1, 0, 1, 2, 3, 4, 5, 6]


def _figure(ax=None, figsize=(5.5, 5.0)):
    import matplotlib.pyplot as plt  # matplotlib is slow to import: only when drawing

    if ax is not None:
        return ax.figure, ax
    fig, ax = plt.subplots(figsize=figsize)
    return fig, ax


def _save(fig, path):
    if path is not None:
        fig.savefig(os.fspath(path), dpi=fig.dpi)


def _cmap_norm():
    from matplotlib.colors import BoundaryNorm, ListedColormap  # matplotlib is slow to import: only when drawing

    cmap = ListedColormap([FACE_COLORS[k] for k in _ORDER])
    norm = BoundaryNorm(np.arange(-1.5, 7.0, 1.0), cmap.N)
    return cmap, norm


def _image_extent(shape, extent):
    """imshow extent with the grid nodes at pixel centres."""
    nx, ny = shape[:2]
    if extent is None:
        extent = ((0.0, nx - 1.0), (0.0, ny - 1.0))
    (x0, x1), (y0, y1) = extent
    hx = (x1 - x0) / max(nx - 1, 1) if nx > 1 else 1.0
    hy = (y1 - y0) / max(ny - 1, 1) if ny > 1 else 1.0
    return (x0 - hx / 2, x1 + hx / 2, y0 - hy / 2, y1 + hy / 2)


def _legend(ax, labels_present):
    from matplotlib.patches import Patch  # matplotlib is slow to import: only when drawing

    handles = [
        Patch(facecolor=FACE_COLORS[k], edgecolor="0.3", label=FACE_LABELS[k])
        for k in _ORDER
        if k in labels_present
    ]
    ax.legend(handles=handles, loc="upper left", bbox_to_anchor=(1.02, 1.0), frameon=False,
              title="outcome")


def plot_outcome_map(
    grid,
    *,
    extent: Sequence[tuple[float, float]] | None = None,
    ax=None,
    title: str | None = None,
    legend: bool = True,
    xlabel: str = "x",
    ylabel: str = "y",
    path: str | os.PathLike | None = None,
):
    """Outcome map of a 2-D label grid in the writeup's colours.

    Parameters
    ----------
    grid : array_like of int, shape (nx, ny)
        Labels -1..6.
    extent : [(x0, x1), (y0, y1)], optional
        Slice coordinates of the first/last nodes (default: indices).
    ax : matplotlib.axes.Axes, optional
        Draw into this axes (its figure is returned).
    title, xlabel, ylabel : str, optional
    legend : bool, optional
        Legend of the labels present.
    path : path-like, optional
        Save the figure (PNG, PDF, ... by extension).

    Returns
    -------
    matplotlib.figure.Figure
    """
    arr = np.asarray(grid)
    fig, ax = _figure(ax)
    cmap, norm = _cmap_norm()
    ax.imshow(arr.T, origin="lower", cmap=cmap, norm=norm, interpolation="nearest",
              extent=_image_extent(arr.shape, extent), aspect="auto")
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    if title:
        ax.set_title(title)
    if legend:
        _legend(ax, set(np.unique(arr).tolist()))
        fig.tight_layout()
    _save(fig, path)
    return fig


def plot_zoom_series(
    grids: Sequence,
    extents: Sequence[Sequence[tuple[float, float]]],
    *,
    titles: Sequence[str] | None = None,
    ncols: int | None = None,
    path: str | os.PathLike | None = None,
):
    """Successive zooms, each window framed by a white box in the previous panel.

    Parameters
    ----------
    grids : sequence of array_like, shape (nx, ny)
        Label grids, outermost first.
    extents : sequence of [(x0, x1), (y0, y1)]
        Window of each grid, slice units; each should lie inside the previous.
    titles : sequence of str, optional
    ncols : int, optional
        Panels per row (default: all in one row, at most 4).
    path : path-like, optional

    Returns
    -------
    matplotlib.figure.Figure
    """
    import matplotlib.pyplot as plt  # matplotlib is slow to import: only when drawing
    from matplotlib.patches import Rectangle

    n = len(grids)
    if n != len(extents):
        raise ValueError("grids and extents must have the same length")
    ncols = ncols or min(n, 4)
    nrows = math.ceil(n / ncols)
    fig, axes = plt.subplots(nrows, ncols, figsize=(3.6 * ncols + 1.2, 3.4 * nrows), squeeze=False)
    cmap, norm = _cmap_norm()
    present = set()
    for q, (g, ext) in enumerate(zip(grids, extents)):
        ax = axes[q // ncols][q % ncols]
        arr = np.asarray(g)
        present |= set(np.unique(arr).tolist())
        ax.imshow(arr.T, origin="lower", cmap=cmap, norm=norm, interpolation="nearest",
                  extent=_image_extent(arr.shape, ext), aspect="auto")
        if titles is not None:
            ax.set_title(titles[q])
        if q + 1 < n:
            (a0, a1), (b0, b1) = extents[q + 1]
            ax.add_patch(Rectangle((a0, b0), a1 - a0, b1 - b0, fill=False, edgecolor="white",
                                   linewidth=1.5))
    for q in range(n, nrows * ncols):
        axes[q // ncols][q % ncols].set_axis_off()
    _legend(axes[0][ncols - 1], present)
    fig.tight_layout()
    _save(fig, path)
    return fig


def plot_settle_map(
    grid,
    t_settle_s,
    *,
    extent: Sequence[tuple[float, float]] | None = None,
    ax=None,
    title: str | None = None,
    path: str | os.PathLike | None = None,
):
    """Outcome colours shaded by settle time (writeup section 5.6).

    Brightness falls with ``log10(t_settle_s)`` from full colour (fastest
    roll) to a quarter (slowest), so cell borders, where the die balances on
    an edge, show as dark seams. Face 6 is black and stays black.

    Parameters
    ----------
    grid : array_like of int, shape (nx, ny)
        Labels -1..6.
    t_settle_s : array_like of float, shape (nx, ny)
        Settle times, s (non-positive or non-finite values are drawn at the
        slowest shade).
    extent, ax, title, path
        As :func:`plot_outcome_map`.

    Returns
    -------
    matplotlib.figure.Figure
    """
    from matplotlib import cm  # matplotlib is slow to import: only when drawing
    from matplotlib.colors import LinearSegmentedColormap, Normalize, to_rgb

    arr = np.asarray(grid)
    t = np.asarray(t_settle_s, dtype=float)
    if t.shape != arr.shape:
        raise ValueError("grid and t_settle_s must have the same shape")
    ok = np.isfinite(t) & (t > 0)
    logt = np.full(t.shape, np.nan)
    logt[ok] = np.log10(t[ok])
    lo = np.nanmin(logt) if ok.any() else 0.0
    hi = np.nanmax(logt) if ok.any() else 1.0
    span = hi - lo if hi > lo else 1.0
    s = np.where(ok, (logt - lo) / span, 1.0)
    bright = 1.0 - 0.75 * s
    rgb = np.zeros(arr.shape + (3,))
    for k, c in FACE_COLORS.items():
        rgb[arr == k] = to_rgb(c)
    rgb *= bright[..., None]
    fig, ax = _figure(ax, figsize=(6.2, 5.0))
    ax.imshow(np.transpose(rgb, (1, 0, 2)), origin="lower", interpolation="nearest",
              extent=_image_extent(arr.shape, extent), aspect="auto")
    shade = LinearSegmentedColormap.from_list("settle", [(1, 1, 1), (0.25, 0.25, 0.25)])
    sm = cm.ScalarMappable(norm=Normalize(lo, hi), cmap=shade)
    fig.colorbar(sm, ax=ax, label="log10 settle time / s (brightness)")
    if title:
        ax.set_title(title)
    ax.set_xlabel("x")
    ax.set_ylabel("y")
    _save(fig, path)
    return fig


def animate_slices(
    grid3d,
    path: str | os.PathLike,
    *,
    extent: Sequence[tuple[float, float]] | None = None,
    z_values: Sequence[float] | None = None,
    axis: int = 2,
    fps: float = 4.0,
    title: str = "z = {z:.4g}",
):
    """Animate a 3-D label grid along its third axis as a GIF (writeup 6.1).

    Parameters
    ----------
    grid3d : array_like of int, shape (nx, ny, nz)
        Labels -1..6.
    path : path-like
        Output GIF.
    extent : [(x0, x1), (y0, y1)], optional
        Slice coordinates of each frame.
    z_values : sequence of float, optional
        Third coordinate of each frame (default: index).
    axis : int, optional
        Axis animated over (default 2).
    fps : float, optional
        Frames per second.
    title : str, optional
        Frame title, formatted with ``z``.

    Returns
    -------
    matplotlib.figure.Figure
        The figure after the last frame.
    """
    from matplotlib.animation import FuncAnimation, PillowWriter  # matplotlib is slow to import: only when drawing

    arr = np.moveaxis(np.asarray(grid3d), axis, 2)
    nz = arr.shape[2]
    zs = np.arange(nz) if z_values is None else np.asarray(z_values)
    fig, ax = _figure(None)
    cmap, norm = _cmap_norm()
    im = ax.imshow(arr[:, :, 0].T, origin="lower", cmap=cmap, norm=norm,
                   interpolation="nearest", extent=_image_extent(arr.shape, extent), aspect="auto")
    ttl = ax.set_title(title.format(z=zs[0]))
    _legend(ax, set(np.unique(arr).tolist()))
    fig.tight_layout()

    def update(k):
        im.set_data(arr[:, :, k].T)
        ttl.set_text(title.format(z=zs[k]))
        return im, ttl

    anim = FuncAnimation(fig, update, frames=nz, blit=False)
    anim.save(os.fspath(path), writer=PillowWriter(fps=fps))
    return fig


def _as_text(seq) -> str:
    return seq if isinstance(seq, str) else contact_sequence_text(seq)


def plot_contact_tree(
    sequences: Iterable,
    *,
    max_depth: int | None = None,
    min_count: int = 1,
    ax=None,
    title: str | None = None,
    path: str | os.PathLike | None = None,
):
    """Prefix tree of contact-set sequences.

    Each node is a contact set (node numbers, ``0`` the empty set) at its
    position in the sequence; rolls that share a prefix share the path. Edge
    width grows with the number of rolls through it, which is also written on
    the leaves.

    Parameters
    ----------
    sequences : iterable of str or array_like of uint8
        Contact sequences (text form ``"0-6-68-8"`` or node masks); a mapping
        ``sequence -> count`` is accepted too.
    max_depth : int, optional
        Cut the sequences after this many sets.
    min_count : int, optional
        Hide branches with fewer rolls.
    ax, title, path
        As :func:`plot_outcome_map`.

    Returns
    -------
    matplotlib.figure.Figure
    """
    if isinstance(sequences, Mapping):
        items = [(_as_text(k), int(v)) for k, v in sequences.items()]
    else:
        items = [(_as_text(s), 1) for s in sequences]
    counts: dict[tuple, int] = {}
    children: dict[tuple, list] = {(): []}
    for text, c in items:
        parts = tuple(text.split("-")) if text else ()
        if max_depth is not None:
            parts = parts[:max_depth]
        for d in range(1, len(parts) + 1):
            pre = parts[:d]
            if pre not in counts:
                counts[pre] = 0
                children.setdefault(pre, [])
                children[parts[: d - 1]].append(pre)
            counts[pre] += c
    # layout: leaves in DFS order, parents at the mean of their children
    pos: dict[tuple, tuple[float, float]] = {}
    leaf_y = [0]

    def place(node):
        kids = [k for k in sorted(children.get(node, []), key=lambda p: p[-1]) if counts[k] >= min_count]
        if not kids:
            y = leaf_y[0]
            leaf_y[0] += 1
        else:
            y = float(np.mean([place(k) for k in kids]))
        pos[node] = (len(node), y)
        return y

    for top in sorted(children[()], key=lambda p: p[-1]):
        if counts[top] >= min_count:
            place(top)
    fig, ax = _figure(ax, figsize=(1.0 + 1.1 * max([len(p) for p in pos] or [1]),
                                   1.0 + 0.32 * max(leaf_y[0], 1)))
    cmax = max(counts.values()) if counts else 1
    for node, (x, y) in pos.items():
        parent = node[:-1]
        if parent in pos:
            px, py = pos[parent]
            w = 0.8 + 4.0 * math.log1p(counts[node]) / math.log1p(cmax)
            ax.plot([px, x], [py, y], color="0.45", linewidth=w, zorder=1, solid_capstyle="round")
    for node, (x, y) in pos.items():
        ax.text(x, y, node[-1], ha="center", va="center", fontsize=8, zorder=3,
                bbox=dict(boxstyle="round,pad=0.25", facecolor="white", edgecolor="0.3"))
        leaf = not any(k in pos for k in children.get(node, []))
        if leaf:
            ax.text(x + 0.25, y, f"×{counts[node]}", ha="left", va="center", fontsize=7, color="0.3")
    ax.set_xlabel("position in contact sequence")
    ax.set_yticks([])
    for side in ("left", "right", "top"):
        ax.spines[side].set_visible(False)
    if pos:
        xs = [p[0] for p in pos.values()]
        ax.set_xlim(min(xs) - 0.5, max(xs) + 1.0)
        ax.set_ylim(-0.8, max(leaf_y[0] - 1, 0) + 0.8)
    if title:
        ax.set_title(title)
    fig.tight_layout()
    _save(fig, path)
    return fig


def plot_ball_hill_phase_portrait(
    *,
    g: float = 980.0,
    radius_cm: float = 1.0,
    theta_range: tuple[float, float] = (0.0, math.pi),
    omega_max: float | None = None,
    normalized: bool = True,
    ax=None,
    path: str | os.PathLike | None = None,
):
    """Phase portrait (theta, Omega) of the ball–hill model with its separatrices.

    Parameters
    ----------
    g, radius_cm : float, optional
        Gravity (cm/s^2) and hill radius (cm).
    theta_range : (float, float), optional
        Angles shown, rad.
    omega_max : float, optional
        Omega range ``[-omega_max, omega_max]``, rad/s; default
        ``1.6 sqrt(2 g / R)``.
    normalized : bool, optional
        Draw unit arrows (the writeup's normalised field, which is undefined
        at the saddle).
    ax, path
        As :func:`plot_outcome_map`.

    Returns
    -------
    matplotlib.figure.Figure
    """
    k = g / radius_cm
    wmax = omega_max if omega_max is not None else 1.6 * math.sqrt(2 * k)
    fig, ax = _figure(ax, figsize=(6.0, 4.6))
    th = np.linspace(theta_range[0], theta_range[1], 25)
    om = np.linspace(-wmax, wmax, 21)
    T, W = np.meshgrid(th, om)
    U, V = ball_hill_vector_field(T, W, g=g, radius_cm=radius_cm)
    # scale Omega' to the axes so that arrows show directions on the plot
    sx, sy = theta_range[1] - theta_range[0], 2 * wmax
    Un, Vn = U / sx, V / sy
    if normalized:
        nrm = np.hypot(Un, Vn)
        nrm[nrm == 0] = 1.0
        Un, Vn = Un / nrm, Vn / nrm
    ax.quiver(T, W, Un * sx, Vn * sy, angles="xy", color="0.55", width=0.003)
    seps = ball_hill_separatrices(g=g, radius_cm=radius_cm, theta_range=theta_range)
    for name, curve in seps.items():
        style = "-" if name.startswith("stable") else "--"
        ax.plot(curve[:, 0], curve[:, 1], style, color="red", linewidth=1.8,
                label=name.replace("_", " "))
    ax.plot([math.pi / 2], [0.0], "o", color="black", label="saddle (π/2, 0)")
    ax.set_xlim(*theta_range)
    ax.set_ylim(-wmax, wmax)
    ax.set_xlabel("θ / rad")
    ax.set_ylabel("Ω / (rad/s)")
    ax.legend(loc="upper right", fontsize=7)
    fig.tight_layout()
    _save(fig, path)
    return fig
