"""The fractal-boundary test of Puy et al. (2021): boundary basin entropy in random balls against a smooth reference.

Puy, Daza, Wagemakers & Sanjuán (2021), "A test for fractal boundaries based
on the basin entropy", Commun. Nonlinear Sci. Numer. Simul. 95:105588; the
same test as Attractors.jl's ``basins_fractal_test``.  Look at the map
through a magnifier, a ball of radius ``eps`` nodes, dropped at random: over
the balls that hold two labels or more, the mean Gibbs entropy ``Sbb``
(nats) of a *smooth* boundary has a known value that depends only on the
dimension ``d`` of the map (a flat boundary cutting a ball at a random
offset: 0.5 in 1-D, 0.4395 in 2-D, ...), plus a small upward bias of the
discrete ball, ``0.224 eps**-1.006``.  A boundary with structure inside the
ball (fractal at that scale) gives a mean outside that band.  The verdict
is for the scale ``eps``: a smooth boundary can look fractal in large balls
and a fractal one smooth in small ones.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
from scipy import stats

from ._grid import as_label_grid, encode_labels

__all__ = ["FractalTestResult", "basins_fractal_test", "smooth_boundary_sbb"]

#: Sbb of a smooth boundary in a ball of dimension 1..5 (Puy et al. 2021, table 1).
SMOOTH_SBB = (0.499999, 0.4395093, 0.39609176, 0.36319428, 0.33722572)


def smooth_boundary_sbb(ndim: int) -> float:
    """Sbb of a smooth boundary in a ``ndim``-dimensional ball (Puy et al.; their fit beyond 5-D)."""
    if ndim < 1:
        raise ValueError(f"ndim must be >= 1, got {ndim}")
    return SMOOTH_SBB[ndim - 1] if ndim <= len(SMOOTH_SBB) else 0.898 * ndim**-0.4995


@dataclasses.dataclass(frozen=True)
class FractalTestResult:
    """Outcome of :func:`basins_fractal_test`.

    Attributes
    ----------
    verdict : {"fractal", "smooth"}
        At the scale ``eps``.
    Sbb, Sbb_stderr : float
        Mean entropy (nats) over the boundary balls, and its standard error.
    smooth_Sbb : float
        The smooth reference for this dimension.
    bias : float
        Upward bias of a discrete ball of radius ``eps`` (``0.224 eps**-1.006``).
    band : (float, float)
        The mean that counts as smooth: ``[smooth - z se, smooth + bias + z se]``.
    eps : float
    n_balls, n_tries : int
        Boundary balls kept, balls drawn.
    confidence : float
    """

    verdict: str
    Sbb: float
    Sbb_stderr: float
    smooth_Sbb: float
    bias: float
    band: tuple[float, float]
    eps: float
    n_balls: int
    n_tries: int
    confidence: float

    @property
    def fractal(self) -> bool:
        return self.verdict == "fractal"


def _ball_offsets(eps: float, ndim: int) -> np.ndarray:
    """Integer offsets of the window that holds any ball of radius ``eps`` around a point of the unit cell."""
    r = int(math.ceil(eps)) + 1
    axes = [np.arange(-r, r + 1)] * ndim
    return np.stack([a.ravel() for a in np.meshgrid(*axes, indexing="ij")], axis=1)


def basins_fractal_test(
    grid,
    *,
    eps: float = 20,
    n_balls: int = 1000,
    confidence: float = 0.6827,
    rng: np.random.Generator | int | None = 0,
    max_tries: int | None = None,
) -> FractalTestResult:
    """Whether a label grid's boundary is fractal at the scale ``eps`` (Puy et al. 2021).

    Parameters
    ----------
    grid : array_like, 1-D to 3-D
        Label grid (any hashable labels), equally spaced nodes.
    eps : float, optional
        Ball radius in grid nodes (Attractors.jl's default, 20).  The grid
        should be at least ~50 ``eps`` along each axis for enough balls.
    n_balls : int, optional
        Boundary balls to average (>= 100; default 1000).
    confidence : float, optional
        Two-sided confidence of the band around the smooth value, as a
        normal quantile times the standard error: 0.6827 (default) is one
        standard error, Attractors.jl's choice; 0.95 widens it to 1.96.
    rng : numpy Generator, seed or None
        Where the ball centres come from (seeded by default: reproducible).
    max_tries : int, optional
        Balls drawn at most (default ``200 * n_balls``); a grid with too
        little boundary raises ``ValueError``.

    Returns
    -------
    FractalTestResult
    """
    arr = as_label_grid(grid, ndim=(1, 2, 3))
    if not (eps >= 1):
        raise ValueError(f"eps must be >= 1 node, got {eps!r}")
    if int(n_balls) < 100:
        raise ValueError(f"n_balls must be >= 100 for the statistics, got {n_balls!r}")
    if not (0 < confidence < 1):
        raise ValueError(f"confidence must be in (0, 1), got {confidence!r}")
    if min(arr.shape) <= 2 * eps + 2:
        raise ValueError(f"the grid {arr.shape} is too small for balls of radius {eps} nodes")
    codes, uniques = encode_labels(arr)
    codes = codes - codes.min()
    nlab = int(codes.max()) + 1
    gen = np.random.default_rng(rng)
    max_tries = 200 * int(n_balls) if max_tries is None else int(max_tries)
    offsets = _ball_offsets(eps, arr.ndim)
    shape = np.array(arr.shape)
    ent: list[np.ndarray] = []
    kept = tries = 0
    batch = 512
    while kept < n_balls and tries < max_tries:
        m = min(batch, max_tries - tries)
        # centres uniform in [eps, n - 1 - eps] per axis: the whole ball inside the grid
        centre = eps + gen.random((m, arr.ndim)) * (shape - 1 - 2 * eps)
        base = np.floor(centre).astype(np.int64)
        nodes = base[:, None, :] + offsets[None, :, :]  # (m, W, d)
        inside = ((nodes - centre[:, None, :]) ** 2).sum(axis=2) <= eps * eps
        # the window reaches a node past the ball on each side, outside the grid for a fractional eps: those
        # nodes are masked out, so read them at the nearest edge node instead of past the end
        at = np.clip(nodes, 0, shape - 1)
        vals = codes[tuple(at[..., a] for a in range(arr.ndim))]  # (m, W)
        counts = np.zeros((m, nlab))
        np.add.at(counts, (np.repeat(np.arange(m), vals.shape[1]), vals.ravel()), inside.ravel())
        p = counts / counts.sum(axis=1, keepdims=True)
        with np.errstate(divide="ignore", invalid="ignore"):
            h = -np.where(p > 0, p * np.log(np.where(p > 0, p, 1.0)), 0.0).sum(axis=1)
        h = h[h > 1e-12]
        ent.append(h[: n_balls - kept])
        kept += len(ent[-1])
        tries += m
    if kept < n_balls:
        raise ValueError(f"only {kept} of {n_balls} balls of radius {eps} met a boundary in {tries} tries: "
                         "too little boundary for the test (a larger eps, or a finer grid)")
    h = np.concatenate(ent)
    mean = float(h.mean())
    se = float(h.std(ddof=1) / math.sqrt(len(h)))
    smooth = smooth_boundary_sbb(arr.ndim)
    bias = 0.224 * float(eps) ** -1.006
    z = float(stats.norm.ppf(0.5 + confidence / 2))
    band = (smooth - z * se, smooth + bias + z * se)
    verdict = "smooth" if band[0] <= mean <= band[1] else "fractal"
    return FractalTestResult(verdict, mean, se, smooth, bias, band, float(eps), kept, tries, float(confidence))
