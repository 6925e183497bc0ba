"""Synthetic basins with known answers, shared by the analysis tests.

Nothing here imports the simulator: these are analytic stand-ins for the
``classify(points) -> labels`` callables that the lead wires to the scanner.
"""

from __future__ import annotations

import numpy as np

NEWTON_ROOTS = np.exp(2j * np.pi * np.arange(3) / 3)


def grid_points(extent, shape):
    """Slice coordinates (n, d) of a grid, C order, first index fastest-varying last."""
    axes = [np.linspace(lo, hi, n) for (lo, hi), n in zip(extent, shape)]
    mesh = np.meshgrid(*axes, indexing="ij")
    return np.stack([m.ravel() for m in mesh], axis=1)


def sample_grid(classify, extent, shape):
    """Label grid of ``classify`` on the grid nodes (indexed [i, j(, k)])."""
    return np.asarray(classify(grid_points(extent, shape))).reshape(shape)


def newton_classify(points, *, iterations=60):
    """Basin (1, 2, 3) of Newton's method for z**3 - 1 from z = x + iy.

    Points where the iteration is not finite get label 0.
    """
    p = np.asarray(points, dtype=float)
    z = p[:, 0] + 1j * p[:, 1]
    with np.errstate(all="ignore"):
        for _ in range(iterations):
            z = z - (z**3 - 1) / (3 * z**2)
        d = np.abs(z[:, None] - NEWTON_ROOTS[None, :])
        lab = np.argmin(d, axis=1) + 1
    lab[~np.isfinite(z)] = 0
    return lab


def weierstrass(x, *, s=1.5, lam=3.0, nterms=None, xmax_res=1e-6):
    """Weierstrass function W(x) = sum_k lam**((s-2)k) sin(lam**k x).

    Its graph has box-counting dimension ``s`` (1 < s < 2, lam > 1):
    Kaplan, Mallet-Paret & Yorke (1984), Ergod. Th. Dynam. Sys. 4:261;
    Falconer, *Fractal Geometry*, ch. 11. Terms are kept down to wavelength
    ``xmax_res``.
    """
    x = np.asarray(x, dtype=float)
    if nterms is None:
        nterms = int(np.ceil(np.log(2 * np.pi / xmax_res) / np.log(lam))) + 2
    out = np.zeros_like(x)
    for k in range(nterms):
        out += lam ** ((s - 2) * k) * np.sin(lam**k * x)
    return out


def weierstrass_classify(points, *, s=1.5, lam=3.0):
    """Label 1 below the graph y = W(x), 2 above."""
    p = np.asarray(points, dtype=float)
    return np.where(p[:, 1] > weierstrass(p[:, 0], s=s, lam=lam), 2, 1)


def line_classify(points, *, normal=(np.cos(0.3), np.sin(0.3)), offset=0.6):
    """Half-plane labels 1 / 2 across the line normal . p = offset."""
    p = np.asarray(points, dtype=float)
    return np.where(p[:, :2] @ np.asarray(normal) > offset, 2, 1)


def sector_classify(points, *, centre=(0.3141592653589793, 0.2718281828459045),
                    angles=(0.2, 2.3, 4.1), labels=(1, 2, 3)):
    """Three sectors around ``centre``: one triple point, three straight rays.

    Sector q covers polar angles [angles[q], angles[q+1]) (mod 2 pi).
    """
    p = np.asarray(points, dtype=float)
    phi = np.mod(np.arctan2(p[:, 1] - centre[1], p[:, 0] - centre[0]) - angles[0], 2 * np.pi)
    edges = np.mod(np.asarray(angles) - angles[0], 2 * np.pi)
    q = np.searchsorted(edges, phi, side="right") - 1
    return np.asarray(labels)[q]


def near_miss_classify(points, *, centre=(0.5, 0.5), delta=1e-6, kappa=1000.0):
    """Two double points ``delta`` apart and no triple point.

    Label 1 for ``x < xc``; label 3 beyond the parabola
    ``x > xc + delta + kappa (y - yc)**2``; label 2 in between. The 1|2 line
    and the 2|3 parabola come within ``delta`` of each other at
    ``(xc, yc)`` but never meet: at scales above ``delta`` it looks like a
    triple point.
    """
    p = np.asarray(points, dtype=float)
    x, y = p[:, 0] - centre[0], p[:, 1] - centre[1]
    return np.where(x < 0, 1, np.where(x > delta + kappa * y**2, 3, 2))


def triadic_classify(points, *, max_iter=40):
    """Basins of the escape parity of x -> 3x mod 1 through the middle third.

    Label ``1 + (n mod 2)`` where ``n`` is the first iteration at which
    ``x_n`` lies in [1/3, 2/3); ``y`` is ignored. The basin boundary is
    C x R with C the middle-third Cantor set, so its box-counting dimension
    is 1 + ln 2 / ln 3 = 1.6309 and the uncertainty exponent is
    1 - ln 2 / ln 3 = 0.3691 (McDonald, Grebogi, Ott & Yorke 1985, Physica D
    17:125, section 2). Points that never escape get label 0.
    """
    x = np.mod(np.asarray(points, dtype=float)[:, 0], 1.0)
    lab = np.zeros(len(x), dtype=np.int64)
    for n in range(max_iter):
        esc = (lab == 0) & (x >= 1 / 3) & (x < 2 / 3)
        lab[esc] = 1 + n % 2
        x = np.mod(3 * x, 1.0)
    return lab


def triadic_extent(k):
    """Cell-centred x-extent of a 3**k-node grid: x_i = (i + 1/2) / 3**k."""
    h = 0.5 / 3**k
    return (h, 1 - h)


def lattice_grid(shape, a, b, *, radius=0.3, labels=(1, 2, 5)):
    """Label grid periodic under the integer lattice spanned by a and b.

    In fractional coordinates (u, v) of the node index in the basis (a, b):
    label labels[1] inside a disc of ``radius`` (fractional units) around the
    cell centre, labels[2] in the band 0.75 <= v mod 1 < 0.9, labels[0] elsewhere.
    """
    nx, ny = shape
    ii, jj = np.meshgrid(np.arange(nx), np.arange(ny), indexing="ij")
    M = np.column_stack([a, b]).astype(float)
    uv = np.linalg.solve(M, np.stack([ii.ravel(), jj.ravel()]).astype(float))
    u = np.mod(uv[0], 1.0).reshape(shape)
    v = np.mod(uv[1], 1.0).reshape(shape)
    out = np.full(shape, labels[0], dtype=np.int64)
    out[(u - 0.5) ** 2 + (v - 0.4) ** 2 < radius**2] = labels[1]
    out[(v >= 0.75) & (v < 0.9)] = labels[2]
    return out
