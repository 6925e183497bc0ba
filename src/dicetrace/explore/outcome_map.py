"""Outcome maps of the explorer's views: the map, and its computation a strip at a time.

A map (:class:`OutcomeMap`) holds the outcome, steps and status of every
grid point of a view.  :class:`MapBuild` computes it through
:func:`dicetrace.simulate.simulate_batch` (the batch kernel that ``dicetrace
scan`` uses, on the same grid points) in strips of whole image rows of about
``BLOCK`` ICs, top first, taking the results of the grid points it shares
with maps of the same view at other resolutions; any split into steps gives
the same map, bit for bit.  :func:`compute_map` runs one to the end; the
explorer's :class:`~dicetrace.explore.compute.Worker` runs many in turn.
"""

from __future__ import annotations

import threading
import time
from dataclasses import dataclass, replace

import numpy as np

from dicetrace.explore.view import View

#: ICs per kernel call of a map, about (a strip of whole rows; the granularity of cancellation).  Each
#: call ends at a parallel barrier: on the loaded 2-core machine a 256² map in 4096-IC calls took
#: 1.8-1.9 s of CPU against 1.4-1.5 s in one call; in 8192-IC calls (8 strips of 32 rows) 1.6 s.
BLOCK = 8192


class Cancelled(Exception):
    """The map was superseded by a newer view before it was done."""


@dataclass
class OutcomeMap:
    """A view's map: ``outcome``, ``steps`` and ``status`` indexed [i, j] (i along x), and the axes.

    While it computes, only the top ``rows_done`` rows of the image (j from
    ny − rows_done to ny − 1: y up) are final; the rest is ``UNSET``.
    """

    view: View
    xs: np.ndarray
    ys: np.ndarray
    outcome: np.ndarray  # int8 (nx, ny)
    steps: np.ndarray  # int64 (nx, ny)
    status: np.ndarray  # int8 codes (nx, ny)
    wall_s: float
    rows_done: int = 0
    reused: int = 0  # grid points taken from a coarser pass's map (the same ICs)

    def counts(self) -> dict[int, int]:
        vals, n = np.unique(self.outcome, return_counts=True)
        return {int(v): int(c) for v, c in zip(vals, n)}

    def strip(self, row0: int, row1: int) -> np.ndarray:
        """Image rows row0..row1 (0 at the top) as an outcome grid [i, j]."""
        ny = self.outcome.shape[1]
        return self.outcome[:, ny - row1 : ny - row0]


#: The outcome of a grid point not computed yet.
UNSET = -9


def strip_rows(view: View) -> int:
    """Image rows per block of a map (whole rows, about ``BLOCK`` grid points)."""
    return max(1, BLOCK // view.res[0])


def _nested_step(fine: np.ndarray, coarse: np.ndarray) -> int | None:
    """k when every k-th point of axis ``fine`` is, bit for bit, axis ``coarse`` (None if not)."""
    nf, nc = len(fine), len(coarse)
    if nc < 2 or (nf - 1) % (nc - 1):
        return None
    k = (nf - 1) // (nc - 1)
    return k if np.array_equal(fine[::k], coarse) else None


class MapBuild:
    """A map computed a piece at a time (:meth:`step`), in strips of whole image rows from the top.

    ``known``: maps of the same view at other resolutions; where their grid
    points are this grid's (same coordinates, so the same ICs) their results
    are taken instead of being computed again.  A step throws at most ``limit``
    ICs of the current strip; a strip's rows count as done (``map.rows_done``,
    ``on_strip(map)``) once all its ICs are thrown.  The ICs of a step are made
    as ``Grid.block`` makes them (the same coordinates, the same arithmetic), so
    any split into steps gives the same map, bit for bit.
    """

    def __init__(self, view: View, known=(), threads: int | None = None, on_strip=None, device: str = "cpu"):
        self.t0 = time.perf_counter()
        self.view, self.threads, self.on_strip, self.device = view, threads, on_strip, device
        self.grid = view.grid()
        self.cfg = view.config()
        nx, ny = view.res
        self.axes = self.grid.axes()
        xs, ys = self.axes[:2]
        m = OutcomeMap(view, xs, ys, np.full((nx, ny), UNSET, np.int8), np.zeros((nx, ny), np.int64),
                       np.zeros((nx, ny), np.int8), 0.0)
        have = np.zeros((nx, ny), bool)
        for other in known:
            kx, ky = _nested_step(xs, other.xs), _nested_step(ys, other.ys)
            if kx is None or ky is None or replace(other.view, res=view.res) != view:
                continue
            sel = (slice(None, None, kx), slice(None, None, ky))
            m.outcome[sel], m.steps[sel], m.status[sel] = other.outcome, other.steps, other.status
            have[sel] = True
        m.reused = int(have.sum())
        self.map, self.have = m, have
        self.todo = nx * ny - m.reused  # ICs to throw in all
        self.thrown = 0
        self.rows = strip_rows(view)
        self.row0 = 0
        self._strip: tuple[np.ndarray, np.ndarray] | None = None  # (i, j) of the current strip's ICs to throw
        self._pos = 0

    @property
    def done(self) -> bool:
        return self.row0 >= self.view.res[1]

    def _ics(self, ii: np.ndarray, jj: np.ndarray) -> np.ndarray:
        cols = [self.axes[0][ii], self.axes[1][jj]] + [self.axes[a][np.zeros_like(ii)] for a in range(2, self.grid.ndim)]
        return self.grid.slice.ics(np.stack(cols, axis=1)).reshape(len(ii), 6)

    def step(self, limit: int | None = None) -> int:
        """Throw up to ``limit`` (None: all) of the current strip's ICs still to throw; the number thrown."""
        # Deferred: simulate loads numba and the kernels, which the explorer's server does not need to start.
        from dicetrace.simulate import simulate_batch

        if self.done:
            return 0
        nx, ny = self.view.res
        row1 = min(ny, self.row0 + self.rows)
        if self._strip is None:
            ii, jl = np.nonzero(~self.have[:, ny - row1 : ny - self.row0])
            self._strip, self._pos = (ii, jl + (ny - row1)), 0
        ii, jj = self._strip
        n = len(ii) - self._pos if limit is None else min(len(ii) - self._pos, max(1, int(limit)))
        if n > 0:
            sel = slice(self._pos, self._pos + n)
            res = simulate_batch(self._ics(ii[sel], jj[sel]), config=self.cfg, l_convention=self.grid.slice.l_convention,
                                 threads=self.threads, device=self.device)
            m = self.map
            m.outcome[ii[sel], jj[sel]], m.steps[ii[sel], jj[sel]], m.status[ii[sel], jj[sel]] = (
                res.outcome, res.steps, res.status_code)
            self._pos += n
            self.thrown += n
        if self._pos >= len(ii):  # the strip is whole
            self.row0, self._strip = row1, None
            self.map.rows_done = row1
            if self.done:
                self.map.wall_s = time.perf_counter() - self.t0
            if self.on_strip is not None:
                self.on_strip(self.map)
        return n


def compute_map(view: View, cancelled: threading.Event | None = None, threads: int | None = None, *,
                known=(), on_strip=None, device: str = "cpu") -> OutcomeMap:
    """The outcome map of ``view`` (raises :class:`Cancelled` once ``cancelled`` is set), a strip a kernel call.

    It is computed in strips of whole image rows from the top, ``on_strip(map)``
    called after each; ``known`` as :class:`MapBuild`'s; ``device`` as
    :func:`~dicetrace.simulate.simulate_batch`'s (cpu, cuda, auto).
    """
    b = MapBuild(view, known, threads, on_strip, device)
    while not b.done:
        if cancelled is not None and cancelled.is_set():
            raise Cancelled()
        b.step()
    return b.map
