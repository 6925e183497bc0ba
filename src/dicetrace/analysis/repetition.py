"""Repetition: periodic structure in label grids (writeup section 5.1).

The writeup saw a periodic pattern of cells in one 2-D slice and asked
whether the repeated regions are different cells or slices of one cell. This
module finds the period vectors of a 2-D label grid from the autocorrelation
of the label indicators, and checks in a 3-D stack whether regions related by
a period vector are connected through the third dimension.
"""

from __future__ import annotations

import math
from collections.abc import Hashable, Iterable, Sequence

import numpy as np
import pandas as pd
from scipy import ndimage

from ._grid import as_label_grid, encode_labels
from .boundaries import boundary_mask
from .cells import cells_table, label_cells

__all__ = ["label_autocorrelation", "find_periods", "periodic_cells_connected", "texture_labels", "off_centre_max",
           "periods_rows", "stripe_spacing", "period_overlaps", "repetition_stats", "period_bootstrap"]

_PERIOD_COLUMNS = ["label", "di", "dj", "dx", "dy", "length", "strength", "n_overlap"]


def label_autocorrelation(
    grid,
    *,
    label: Hashable | None = None,
    exclude: Iterable[Hashable] = (),
) -> np.ndarray:
    """Normalised autocorrelation of label indicators, at every lag.

    Parameters
    ----------
    grid : array_like, shape (nx, ny)
        Label grid.
    label : hashable, optional
        Use the indicator of this label only. Default: all labels together,
        ``C(lag) = sum_l cov_l(lag) / sum_l var_l`` (the probability excess of
        finding the same label at distance ``lag``).
    exclude : iterable, optional
        Labels left out of the sum (their indicators are not used).

    Returns
    -------
    numpy.ndarray, shape (2 nx - 1, 2 ny - 1)
        ``C[di + nx - 1, dj + ny - 1]`` for lag ``(di, dj)`` in grid nodes;
        ``C = 1`` at lag 0, ``C ~= 1`` at a lag that maps the grid onto itself
        over the overlap (the indicators are centred on their global means, so
        a partial overlap can give ``C`` a percent or so above 1), ~0 for
        unrelated labels. Each lag is normalised by
        its overlap (``(nx - |di|)(ny - |dj|)`` nodes), so long lags are noisy.

    Notes
    -----
    Linear (not circular) correlation, by zero-padded FFT
    (Wiener–Khinchin theorem).
    """
    arr = as_label_grid(grid, ndim=(2,))
    codes, uniques = encode_labels(arr)
    integer = arr.dtype.kind in "iub"
    excl = set(exclude)
    if label is not None:
        chosen = [label]
    else:
        chosen = [u for u in uniques if u not in excl]
    nx, ny = arr.shape
    shape = (2 * nx, 2 * ny)
    num = np.zeros((2 * nx - 1, 2 * ny - 1))
    var = 0.0
    for u in chosen:
        if integer:
            ind = (codes == u).astype(float)
        else:
            i = uniques.index(u) if u in uniques else -1
            ind = (codes == i).astype(float)
        x = ind - ind.mean()
        v = float(np.mean(x * x))
        if v == 0:
            continue
        F = np.fft.rfft2(x, s=shape)
        r = np.fft.irfft2(F * np.conj(F), s=shape)
        r = np.fft.fftshift(r)[1:, 1:]  # lags -(n-1)..(n-1)
        num += r
        var += v
    di = nx - np.abs(np.arange(-(nx - 1), nx))
    dj = ny - np.abs(np.arange(-(ny - 1), ny))
    overlap = np.outer(di, dj).astype(float)
    if var == 0:
        return np.zeros_like(num)
    return num / overlap / var


def _canonical_sign(v: np.ndarray) -> np.ndarray:
    for c in v:
        if c != 0:
            return v if c > 0 else -v
    return v


def _gauss_reduce(u: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Lagrange–Gauss reduction of a 2-D integer lattice basis."""
    u, v = u.astype(np.int64), v.astype(np.int64)
    if u @ u > v @ v:
        u, v = v, u
    while True:
        m = int(np.rint((u @ v) / (u @ u)))
        v = v - m * u
        if v @ v >= u @ u:
            return u, v
        u, v = v, u


def find_periods(
    grid,
    *,
    label: Hashable | None = None,
    spacing: Sequence[float] | None = None,
    min_strength: float = 0.3,
    max_lag_fraction: float = 0.5,
    exclude: Iterable[Hashable] = (),
) -> pd.DataFrame:
    """Dominant period vectors of a 2-D label grid.

    Local maxima of :func:`label_autocorrelation` with strength at least
    ``min_strength`` (lag 0 excluded, ``|di| <= max_lag_fraction * nx``,
    ``|dj| <= max_lag_fraction * ny``) are candidate periods. The shortest
    candidate and the shortest candidate not parallel to it form a basis of
    the period lattice, which is then Lagrange–Gauss reduced (shortest, nearly
    orthogonal basis). Only one vector is returned for stripes whose
    second direction is not periodic within the window.

    Parameters
    ----------
    grid : array_like, shape (nx, ny)
        Label grid.
    label : hashable, optional
        Use one label's indicator (default: all labels together).
    spacing : (hx, hy), optional
        Grid spacing in slice units, to fill ``dx, dy``; default 1.
    min_strength : float, optional
        Smallest normalised autocorrelation accepted as a period, default 0.3.
        For i.i.d. random labels on an ``n x n`` grid the correlation at any
        lag with overlap ``m`` nodes is ~N(0, 1/m), far below 0.3 for
        ``m >~ 500``.
    max_lag_fraction : float, optional
        Largest lag searched, as a fraction of the grid side (default 0.5, so
        every lag has at least a quarter of the grid as overlap).
    exclude : iterable, optional
        Labels left out of the combined autocorrelation.

    Returns
    -------
    pandas.DataFrame
        Columns ``label`` (the ``label`` argument, ``None`` for all),
        ``di, dj`` (int, grid nodes), ``dx, dy`` (slice units), ``length``
        (slice units), ``strength`` (autocorrelation at the lag), and
        ``n_overlap`` (nodes behind it). 0 rows: no significant period.
    """
    arr = as_label_grid(grid, ndim=(2,))
    nx, ny = arr.shape
    C = label_autocorrelation(arr, label=label, exclude=exclude)
    hx, hy = (1.0, 1.0) if spacing is None else (float(spacing[0]), float(spacing[1]))
    mx = int(max_lag_fraction * nx)
    my = int(max_lag_fraction * ny)
    sub = C[nx - 1 - mx : nx + mx, ny - 1 - my : ny + my]
    peaks = (sub == ndimage.maximum_filter(sub, size=3, mode="constant", cval=-np.inf))
    peaks &= sub >= min_strength
    peaks[mx, my] = False
    cand = np.argwhere(peaks) - [mx, my]
    empty = pd.DataFrame({c: [] for c in _PERIOD_COLUMNS})
    if len(cand) == 0:
        return empty
    metric = np.array([hx, hy])
    lengths = np.linalg.norm(cand * metric, axis=1)
    strength = sub[cand[:, 0] + mx, cand[:, 1] + my]
    order = np.lexsort((-strength, lengths))
    cand = cand[order]
    v1 = cand[0]
    v2 = None
    for c in cand[1:]:
        if v1[0] * c[1] - v1[1] * c[0] != 0:
            v2 = c
            break
    basis = [v1] if v2 is None else list(_gauss_reduce(v1, v2))
    rows = []
    for v in basis:
        v = _canonical_sign(np.asarray(v))
        di, dj = int(v[0]), int(v[1])
        if abs(di) > nx - 1 or abs(dj) > ny - 1:
            continue
        rows.append(
            {
                "label": label,
                "di": di,
                "dj": dj,
                "dx": di * hx,
                "dy": dj * hy,
                "length": float(np.hypot(di * hx, dj * hy)),
                "strength": float(C[di + nx - 1, dj + ny - 1]),
                "n_overlap": int((nx - abs(di)) * (ny - abs(dj))),
            }
        )
    out = pd.DataFrame(rows, columns=_PERIOD_COLUMNS)
    return out.astype({"di": np.int64, "dj": np.int64, "n_overlap": np.int64})


def periodic_cells_connected(
    grid3d,
    period: Sequence[int],
    *,
    k: int = 0,
    label: Hashable | None = None,
    connectivity: str = "face",
) -> pd.DataFrame:
    """Are 2-D cells related by a period vector one 3-D cell?

    Each 2-D cell of slice ``k`` (stacking axis 2) is translated by
    ``period = (di, dj)``; its *partner* is the 2-D cell of the same label
    that receives most of its translated nodes. The pair is connected when
    both lie in one connected component of the 3-D grid.

    Parameters
    ----------
    grid3d : array_like, shape (nx, ny, nz)
        Label grid of a slice stack.
    period : (di, dj)
        Period vector in grid nodes (e.g. a row of :func:`find_periods`).
    k : int, optional
        Slice whose cells are tested, default 0.
    label : hashable, optional
        Test only cells of this label.
    connectivity : {"face", "full"}, optional
        For the 2-D cells and the 3-D components alike.

    Returns
    -------
    pandas.DataFrame
        Columns ``cell_id, label, partner_cell_id, overlap`` (fraction of the
        cell's in-window translated nodes that land in the partner),
        ``component_3d, partner_component_3d, connected`` (bool). Cells whose
        translate leaves the window or meets no cell of the same label are
        omitted.
    """
    arr = as_label_grid(grid3d, ndim=(3,))
    di, dj = (int(period[0]), int(period[1]))
    ids3, _ = label_cells(arr, connectivity=connectivity)
    sl = arr[:, :, k]
    ids2, _ = label_cells(sl, connectivity=connectivity)
    comp = ids3[:, :, k]
    nx, ny = sl.shape
    ii, jj = np.nonzero(np.ones_like(sl, dtype=bool))
    ti, tj = ii + di, jj + dj
    inside = (ti >= 0) & (ti < nx) & (tj >= 0) & (tj < ny)
    src = ids2[ii, jj]
    frame = pd.DataFrame({"cell_id": src, "inside": inside})
    n_inside = frame.groupby("cell_id")["inside"].sum()
    ii, jj, ti, tj, src = ii[inside], jj[inside], ti[inside], tj[inside], src[inside]
    same = sl[ii, jj] == sl[ti, tj]
    pairs = pd.DataFrame({"cell_id": src[same], "partner_cell_id": ids2[ti[same], tj[same]]})
    if label is not None:
        lab_of = pd.Series(sl[ii, jj][same])
        pairs = pairs[(lab_of == label).to_numpy()]
    cols = ["cell_id", "label", "partner_cell_id", "overlap", "component_3d",
            "partner_component_3d", "connected"]
    if pairs.empty:
        return pd.DataFrame({c: [] for c in cols})
    counts = pairs.groupby(["cell_id", "partner_cell_id"]).size().rename("n").reset_index()
    counts = counts.sort_values(["cell_id", "n"], ascending=[True, False])
    best = counts.drop_duplicates("cell_id").reset_index(drop=True)
    best["overlap"] = best["n"] / n_inside.loc[best["cell_id"]].to_numpy()
    # one representative node per 2-D cell
    flat = ids2.ravel()
    uniq, first = np.unique(flat, return_index=True)
    rep = dict(zip(uniq.tolist(), first.tolist()))
    comp_flat = comp.ravel()
    lab_flat = sl.ravel()
    best["label"] = [
        (lambda v: v.item() if isinstance(v, np.generic) else v)(lab_flat[rep[c]])
        for c in best["cell_id"]
    ]
    best["component_3d"] = [int(comp_flat[rep[c]]) for c in best["cell_id"]]
    best["partner_component_3d"] = [int(comp_flat[rep[c]]) for c in best["partner_cell_id"]]
    best["connected"] = best["component_3d"] == best["partner_component_3d"]
    return best[cols].astype({"cell_id": np.int64, "partner_cell_id": np.int64})


def texture_labels(grid: np.ndarray, sigma_nodes: float) -> np.ndarray:
    """1 where the smoothed density of cell borders is above its median, else 0."""
    dens = ndimage.gaussian_filter(boundary_mask(grid).astype(float), sigma_nodes)
    return (dens > np.median(dens)).astype(np.int64)


def off_centre_max(corr: np.ndarray, exclude_radius: int) -> float:
    """Largest autocorrelation away from the centre (beyond ``exclude_radius``, within half the lags)."""
    n0, n1 = (corr.shape[0] - 1) // 2, (corr.shape[1] - 1) // 2
    i, j = np.indices(corr.shape)
    far = (i - n0) ** 2 + (j - n1) ** 2 > exclude_radius**2
    inner = (np.abs(i - n0) <= n0 // 2) & (np.abs(j - n1) <= n1 // 2)
    return float(corr[far & inner].max())


def periods_rows(df, window: str, kind: str) -> list[dict]:
    """The rows of a :func:`find_periods` table as plain dicts, tagged with ``window`` and ``kind`` (the field)."""
    return [{"window": window, "field": kind, "di": int(r.di), "dj": int(r.dj), "dx": float(r.dx), "dy": float(r.dy),
             "length": float(r.length), "strength": float(r.strength)} for r in df.itertuples()]


def stripe_spacing(rows: list[dict]) -> float | None:
    """Distance between stripes: |v1 × v2| / |v1| for a 2-vector basis (v1 the shorter)."""
    if len(rows) < 2:
        return None
    v1 = np.array([rows[0]["dx"], rows[0]["dy"]])
    v2 = np.array([rows[1]["dx"], rows[1]["dy"]])
    return float(abs(v1[0] * v2[1] - v1[1] * v2[0]) / np.linalg.norm(v1))


def period_overlaps(g, h, win, period_xy, min_period_cell) -> list[dict]:
    """For each period vector (slice units) of a 3-D stack ``g`` (spacing ``h``, ranges ``win``): how many cells of
    slice z = 0 the shift maps onto themselves (overlap > 0.5, at least ``min_period_cell`` nodes) and how many of
    those are one 3-D cell with their image (:func:`periodic_cells_connected`).  Vectors shorter than 5 % of the
    window (the along-stripe vector of a stripe texture) or longer than the grid are skipped."""
    sizes = cells_table(g[:, :, 0]).set_index("cell_id")["size"]
    width = min(w[1] - w[0] for w in win[:2])
    res_p = []
    for v in period_xy:
        di, dj = int(round(v[0] / h[0])), int(round(v[1] / h[1]))
        if math.hypot(v[0], v[1]) < 0.05 * width or abs(di) >= g.shape[0] or abs(dj) >= g.shape[1]:
            continue  # the along-stripe vector of a stripe texture (a few nodes): not a repetition
        pc = periodic_cells_connected(g, (di, dj), k=0)
        pc["size"] = sizes.reindex(pc["cell_id"]).to_numpy()
        big_any = pc["size"] >= min_period_cell
        big = pc[big_any & (pc["overlap"] > 0.5)]
        res_p.append({
            "period": (float(v[0]), float(v[1])), "period_nodes": (di, dj),
            "n_cells_tested": int(len(pc)),
            "n_big_matched": int(len(big)),
            "min_cell_nodes": min_period_cell,
            "median_overlap_big": float(pc[big_any]["overlap"].median()) if big_any.any() else None,
            "frac_connected_big": float(big["connected"].mean()) if len(big) else None,
            "frac_connected_all": float(pc["connected"].mean()) if len(pc) else None,
        })
    return res_p


def repetition_stats(s) -> dict:
    """The repetition measures of study c on one map ``s`` (``labels``, ``spacing``): outcome autocorrelation and
    periods, and those of the texture (:func:`texture_labels`)."""
    g, h = s.labels, s.spacing
    res = g.shape[0]
    tex = texture_labels(g, max(1.0, 0.015 * (res - 1)))
    rows_tex = periods_rows(find_periods(tex, spacing=h, min_strength=0.1), "", "texture")
    rows_out = periods_rows(find_periods(g, spacing=h, min_strength=0.3), "", "outcome")
    return {
        "outcome_offcentre_max_corr": off_centre_max(label_autocorrelation(g), int(0.05 * res)),
        "n_outcome_periods": len(rows_out),
        "outcome_periods": [{k: r[k] for k in ("dx", "dy", "length", "strength")} for r in rows_out],
        "texture_offcentre_max_corr": off_centre_max(label_autocorrelation(tex), int(0.05 * res)),
        "texture_periods": [{k: r[k] for k in ("dx", "dy", "length", "strength")} for r in rows_tex],
        "texture_stripe_spacing": stripe_spacing(rows_tex),
    }


def _peak(c: np.ndarray) -> tuple[float, float, bool]:
    """Sub-node position of the maximum of a small correlation patch (offsets from its centre) by a parabola through
    the maximum and its two neighbours on each axis; ``interior``: the maximum is not on the patch's edge."""
    i, j = np.unravel_index(int(np.nanargmax(c)), c.shape)
    r0, r1 = (c.shape[0] - 1) // 2, (c.shape[1] - 1) // 2
    interior = 0 < i < c.shape[0] - 1 and 0 < j < c.shape[1] - 1

    def vertex(a, b, d):
        den = a - 2 * b + d
        return 0.5 * (a - d) / den if den < 0 else 0.0

    di = vertex(c[i - 1, j], c[i, j], c[i + 1, j]) if 0 < i < c.shape[0] - 1 else 0.0
    dj = vertex(c[i, j - 1], c[i, j], c[i, j + 1]) if 0 < j < c.shape[1] - 1 else 0.0
    return float(i - r0 + di), float(j - r1 + dj), bool(interior)


def period_bootstrap(grid, period: Sequence[int], *, tiles: int = 6, n_boot: int = 200, radius: int = 2,
                     rng: np.random.Generator | int = 0) -> dict:
    """Bootstrap error of a period vector ``(di, dj)`` (grid nodes) of a 2-D label grid.

    The label autocorrelation (as :func:`label_autocorrelation`: every label's centred indicator) at the lags within
    ``radius`` nodes of the period is summed tile by tile, the grid cut into ``tiles × tiles`` blocks by the position
    of the first node of each pair, so that a draw of tiles with replacement rebuilds it from blocks of the map
    (a block bootstrap: neighbouring nodes are correlated, blocks much less).  Each draw locates the correlation's
    peak to a fraction of a node (a parabola on each axis through the maximum and its neighbours).

    Returns ``di, dj`` (the peak of the whole grid, sub-node), ``di_stderr, dj_stderr`` (the draws' standard
    deviations), ``strength`` (the correlation at the integer peak), ``interior`` (the whole grid's peak is not on
    the edge of the searched box: a period found there) and ``interior_fraction`` (the share of draws whose peak is
    interior), ``n_boot`` and ``tiles``.
    """
    arr = as_label_grid(grid, ndim=(2,))
    codes, uniques = encode_labels(arr)
    nx, ny = arr.shape
    xs = [(codes == u).astype(float) for u in np.unique(codes)]
    xs = [x - x.mean() for x in xs]
    var = sum(float(np.mean(x * x)) for x in xs)
    p0, p1 = int(period[0]), int(period[1])
    size = 2 * int(radius) + 1
    ti = np.minimum(np.arange(nx) * tiles // nx, tiles - 1)
    tj = np.minimum(np.arange(ny) * tiles // ny, tiles - 1)
    tile_of = (ti[:, None] * tiles + tj[None, :])
    S = np.zeros((tiles * tiles, size, size))
    N = np.zeros((tiles * tiles, size, size))
    for a in range(size):
        for b in range(size):
            di, dj = p0 + a - radius, p1 + b - radius
            i0, i1 = max(0, -di), min(nx, nx - di)
            j0, j1 = max(0, -dj), min(ny, ny - dj)
            if i1 <= i0 or j1 <= j0:
                continue
            prod = sum(x[i0:i1, j0:j1] * x[i0 + di:i1 + di, j0 + dj:j1 + dj] for x in xs)
            t = tile_of[i0:i1, j0:j1].ravel()
            S[:, a, b] = np.bincount(t, weights=prod.ravel(), minlength=tiles * tiles)
            N[:, a, b] = np.bincount(t, minlength=tiles * tiles)

    def corr(w):
        num, cnt = np.tensordot(w, S, axes=1), np.tensordot(w, N, axes=1)
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.where(cnt > 0, num / cnt / max(var, 1e-300), np.nan)

    c0 = corr(np.ones(tiles * tiles))
    pi, pj, interior = _peak(c0)
    gen = np.random.default_rng(rng)
    draws = []
    for _ in range(int(n_boot)):
        w = np.bincount(gen.integers(0, tiles * tiles, tiles * tiles), minlength=tiles * tiles).astype(float)
        draws.append(_peak(corr(w)))
    d = np.array(draws, dtype=float)
    ii, jj = np.unravel_index(int(np.nanargmax(c0)), c0.shape)
    return {"di": p0 + pi, "dj": p1 + pj, "di_stderr": float(d[:, 0].std(ddof=1)) if len(d) > 1 else math.nan,
            "dj_stderr": float(d[:, 1].std(ddof=1)) if len(d) > 1 else math.nan, "strength": float(c0[ii, jj]),
            "interior": interior, "interior_fraction": float(d[:, 2].mean()) if len(d) else math.nan,
            "n_boot": int(n_boot), "tiles": int(tiles)}
