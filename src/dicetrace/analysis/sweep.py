"""Chaos measures across a parameter sweep (e.g. damping, writeup section 5.2).

The writeup found that a higher damping coefficient gives a "less chaotic"
initial-condition space. :func:`chaos_sweep` makes that a table: for each
parameter value's label grid it computes the boundary fraction, the
uncertainty exponent, and the basin entropies, with error bars.
:func:`map_measures` is the fuller set of one map (study b's table).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Hashable, Iterable, Mapping, Sequence

import numpy as np
import pandas as pd

from ._grid import as_label_grid
from .boundaries import basin_entropy, boundary_dimension, boundary_mask
from .uncertainty import uncertainty_exponent, uncertainty_exponent_perturbation, uncertainty_exponent_resolution
from .wada import wada_grid_test, wada_merge_test

__all__ = ["chaos_measures", "chaos_sweep", "map_measures"]


def _blocks(arr: np.ndarray, n_blocks: int) -> list[np.ndarray]:
    out = []
    edges = [np.linspace(0, n, n_blocks + 1).astype(int) for n in arr.shape]
    for idx in np.ndindex(*(n_blocks,) * arr.ndim):
        sl = tuple(slice(e[i], e[i + 1]) for e, i in zip(edges, idx))
        out.append(arr[sl])
    return out


def chaos_measures(
    grid,
    *,
    box_sizes: Sequence[int] | None = None,
    entropy_box_size: int = 5,
    n_blocks: int = 2,
    n_boot: int = 200,
    rng: np.random.Generator | None = None,
    spacing: float = 1.0,
    exclude: Iterable[Hashable] = (),
) -> dict:
    """Chaos measures of one label grid, with error bars.

    Parameters
    ----------
    grid : array_like, 2-D or 3-D
        Label grid.
    box_sizes : sequence of int, optional
        Scales for the uncertainty exponent (see
        :func:`~dicetrace.analysis.uncertainty.uncertainty_exponent`).
    entropy_box_size : int, optional
        Box side for the basin entropy, grid nodes (default 5).
    n_blocks : int, optional
        Sub-grid error bars: the grid is cut into ``n_blocks`` per axis and the
        spread of each measure over the blocks, divided by
        ``sqrt(n_blocks**ndim)``, is reported (``*_block_stderr``).
    n_boot : int, optional
        Bootstrap resamples of the entropy boxes for ``Sb_stderr`` and
        ``Sbb_stderr``.
    rng : numpy.random.Generator, optional
        For the bootstrap.
    spacing : float, optional
        Grid spacing (slice units) for the uncertainty exponent's ``eps``.
    exclude : iterable, optional
        Labels ignored by the basin entropy.

    Returns
    -------
    dict
        ``boundary_fraction``, ``boundary_fraction_block_stderr``, ``alpha``,
        ``alpha_stderr`` (regression), ``alpha_block_stderr``, ``dimension``
        (``d - alpha``), ``Sb``, ``Sb_stderr``, ``Sbb``, ``Sbb_stderr``,
        ``fractal_boundary`` (``Sbb > ln 2``), ``n_labels``, ``n_nodes``.
    """
    arr = as_label_grid(grid)
    rng = np.random.default_rng() if rng is None else rng
    bf = float(boundary_mask(arr).mean())
    try:
        ue = uncertainty_exponent(arr, box_sizes=box_sizes, spacing=spacing)
        alpha, alpha_se, dim = ue.alpha, ue.alpha_stderr, ue.dimension
    except ValueError:  # no uncertain box at any size (a map of one outcome): α is undefined
        alpha = alpha_se = dim = math.nan
    be = basin_entropy(arr, entropy_box_size, exclude=exclude)
    ent = be.box_entropies
    boot_sb, boot_sbb = [], []
    for _ in range(int(n_boot)):
        sample = ent[rng.integers(0, len(ent), len(ent))]
        boot_sb.append(sample.mean())
        pos = sample[sample > 0]
        if len(pos):
            boot_sbb.append(pos.mean())
    blocks = _blocks(arr, int(n_blocks)) if n_blocks and n_blocks > 1 else []
    bf_b, al_b = [], []
    for b in blocks:
        bf_b.append(boundary_mask(b).mean())
        try:
            bs = None if box_sizes is None else [s for s in box_sizes if s < min(b.shape)]
            a = uncertainty_exponent(b, box_sizes=bs).alpha
            if np.isfinite(a):
                al_b.append(a)
        except ValueError:
            pass

    def sem(v):
        return float(np.std(v, ddof=1) / math.sqrt(len(v))) if len(v) > 1 else math.nan

    return {
        "boundary_fraction": bf,
        "boundary_fraction_block_stderr": sem(bf_b),
        "alpha": alpha,
        "alpha_stderr": alpha_se,
        "alpha_block_stderr": sem(al_b),
        "dimension": dim,
        "Sb": be.Sb,
        "Sb_stderr": float(np.std(boot_sb, ddof=1)) if len(boot_sb) > 1 else math.nan,
        "Sbb": be.Sbb,
        "Sbb_stderr": float(np.std(boot_sbb, ddof=1)) if len(boot_sbb) > 1 else math.nan,
        "fractal_boundary": be.fractal_boundary,
        "n_labels": be.n_labels,
        "n_nodes": int(arr.size),
    }


def chaos_sweep(
    grids: Mapping[object, np.ndarray],
    *,
    classifiers: Mapping[object, Callable[[np.ndarray], np.ndarray]] | None = None,
    points: np.ndarray | None = None,
    eps_list: Sequence[float] | None = None,
    rng: np.random.Generator | None = None,
    param_name: str = "param",
    **measure_kwargs,
) -> pd.DataFrame:
    """Tidy table of chaos measures, one row per parameter value.

    Parameters
    ----------
    grids : mapping
        Parameter value (e.g. damping ``gamma`` in s/cm) -> label grid.
    classifiers : mapping, optional
        Parameter value -> ``classify(points) -> labels``. With ``points``
        and ``eps_list`` adds ``alpha_perturbation`` and its stderr from
        :func:`~dicetrace.analysis.uncertainty.uncertainty_exponent_perturbation`.
    points : numpy.ndarray (n, d), optional
        Base points for the perturbation exponent, slice units.
    eps_list : sequence of float, optional
        Perturbation sizes, slice units.
    rng : numpy.random.Generator, optional
    param_name : str, optional
        Name of the parameter column (default ``"param"``).
    **measure_kwargs
        Passed to :func:`chaos_measures` (``box_sizes``, ``entropy_box_size``,
        ``n_blocks``, ``n_boot``, ``spacing``, ``exclude``).

    Returns
    -------
    pandas.DataFrame
        ``param_name`` then the keys of :func:`chaos_measures`, sorted by the
        parameter when it is sortable.
    """
    rng = np.random.default_rng() if rng is None else rng
    rows = []
    for value, grid in grids.items():
        row = {param_name: value}
        row.update(chaos_measures(grid, rng=rng, **measure_kwargs))
        if classifiers is not None and value in classifiers:
            if points is None or eps_list is None:
                raise ValueError("classifiers need points and eps_list")
            try:
                ue = uncertainty_exponent_perturbation(classifiers[value], points, eps_list, rng)
                row["alpha_perturbation"], row["alpha_perturbation_stderr"] = ue.alpha, ue.alpha_stderr
            except ValueError:  # no uncertain pair at any ε: α is undefined
                row["alpha_perturbation"] = row["alpha_perturbation_stderr"] = math.nan
        rows.append(row)
    out = pd.DataFrame(rows)
    try:
        out = out.sort_values(param_name).reset_index(drop=True)
    except TypeError:
        pass
    return out


def map_measures(w, s, classify, rng: np.random.Generator, *, perturb: bool, wada_grid: bool = True,
                 wada_levels: int = 12, wada_segments: int = 300, n_points: int = 4000,
                 eps_rel=np.logspace(-8, -2, 7), log: Callable[[str], None] | None = None) -> dict:
    """The measures of the map ``s`` of window ``w`` (study b's table: :func:`chaos_measures`, the box-counting
    dimension of its border, α from coarser grids, the Wada merge test), a sample with ``labels``, ``spacing``,
    ``window`` (ranges) and ``extent``.

    ``perturb``: also those that call ``classify`` — α by perturbation at ``n_points`` random points and ε =
    ``eps_rel`` × the window's width and, with ``wada_grid``, the Wada refinement (``wada_levels`` levels, at most
    ``wada_segments`` segments).  ``rng`` draws everything random, in that order; ``log`` hears of a perturbation
    fit that failed (fewer than two ε with a nonzero fraction: α is NaN then).
    """
    g = s.labels
    h = s.spacing[0]
    W = s.window[0][1] - s.window[0][0]
    row: dict = {"window": w, "ranges": s.window, "res": g.shape[0], "spacing": h}
    row.update(chaos_measures(g, spacing=h, n_blocks=4, n_boot=200, rng=rng))
    bd = boundary_dimension(g, method="mask")
    row["dim_mask"], row["dim_mask_stderr"] = bd.dimension, bd.stderr
    if (g.shape[0] - 1) % 4 == 0 and g.shape[0] >= 41:
        ur = uncertainty_exponent_resolution([g, g[::2, ::2], g[::4, ::4]], [h, 2 * h, 4 * h])
        row["alpha_res"], row["alpha_res_f"] = ur.alpha, ur.f
    labs = sorted(set(np.unique(g).tolist()) - {-1, 0})
    row["n_outcomes"] = len(labs)
    if len(labs) >= 3:
        wm = wada_merge_test(g, r_max=5, tol=0.01, exclude=(-1, 0))
        row["wada_merge_r"] = wm.r_wada
        row["wada_merge_far_r5"] = float(wm.far_fraction[-1])
        row["wada_merge_far_r1"] = float(wm.far_fraction[min(1, len(wm.far_fraction) - 1)])
        if perturb and wada_grid:
            wg = wada_grid_test(classify, g, s.extent, max_level=wada_levels, max_segments=wada_segments,
                                exclude=(-1, 0), rng=rng)
            row["wada_grid_G"] = float(wg.wada_fraction[-1])
            row["wada_grid_G_curve"] = wg.wada_fraction
            row["wada_grid_segments"] = wg.n_segments
            row["wada_grid_levels"] = int(wg.levels[-1])
            row["wada_grid_evals"] = wg.n_evals
            row["wada_grid_wada"] = wg.wada
    if perturb:
        npts = n_points
        rel = np.asarray(eps_rel, dtype=float)
        eps = W * rel
        lo = np.array([r[0] for r in s.window])
        hi = np.array([r[1] for r in s.window])
        pts = lo + rng.random((npts, 2)) * (hi - lo)
        try:
            up = uncertainty_exponent_perturbation(classify, pts, eps, rng)
            row["alpha_pert"], row["alpha_pert_stderr"] = up.alpha, up.alpha_stderr
            row["pert_f"] = up.f
        except ValueError as e:  # fewer than two eps with a nonzero fraction
            if log is not None:
                log(f"{w}: no perturbation fit ({e})")
            row["alpha_pert"], row["alpha_pert_stderr"] = math.nan, math.nan
            row["pert_f"] = np.full(len(eps), math.nan)
        row["pert_eps"], row["pert_n"] = eps, npts
        row["pert_eps_rel"] = rel
    return row
