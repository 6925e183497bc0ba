"""The explorer's work: outcome maps of views, one throw's details, saved scans — off the server's event loop.

Maps go through :func:`dicetrace.simulate.simulate_batch` (the batch kernel
that ``dicetrace scan`` uses, on the same grid points), in strips of whole
image rows of about ``BLOCK`` ICs, top first, on one worker thread (numba's
parallel regions use the cores inside it; one map at a time so they never
compete); a map being computed can be read as far as it is
(:meth:`Worker.progress`).  A refined map takes the results of the grid points
it shares with the view's coarser passes (:func:`compute_map`'s ``known``).
Every map request carries a client id: a newer request from the same client
cancels the older one, which stops at its next strip (or before it starts)
with :class:`Cancelled`.  Finished maps are cached by view.
"""

from __future__ import annotations

import re
import threading
from collections import OrderedDict
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from dicetrace.explore.view import View, ViewError

#: ICs per kernel call of a map, about (a strip of whole rows; the granularity of cancellation).  Each
#: call ends at a parallel barrier: on the loaded 2-core machine a 256² map in 4096-IC calls took
#: 1.8-1.9 s of CPU against 1.4-1.5 s in one call; in 8192-IC calls (8 strips of 32 rows) 1.6 s.
BLOCK = 8192
#: Maps kept in the cache.
CACHE_SIZE = 48
#: A saved scan's name.
SCAN_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9._-]{0,63}$")


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


class _Token:
    def __init__(self) -> None:
        self.cancelled = threading.Event()


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


def compute_map(view: View, cancelled: threading.Event | None = None, threads: int | None = None, *,
                known=(), on_strip=None) -> OutcomeMap:
    """The outcome map of ``view`` (raises :class:`Cancelled` once ``cancelled`` is set).

    It is computed in strips of whole image rows from the top, ``on_strip(map)``
    called after each.  ``known``: maps of the same view at other resolutions;
    where their grid points are this grid's (same coordinates, so the same ICs)
    their results are taken instead of being computed again.
    """
    import time

    from dicetrace.simulate import simulate_batch

    t0 = time.perf_counter()
    grid = view.grid()
    cfg = view.config()
    conv = grid.slice.l_convention
    nx, ny = view.res
    xs, ys = grid.axes()[:2]
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
    ics = grid.block(0, grid.size).ics.reshape(nx, ny, 6)
    rows = strip_rows(view)
    for row0 in range(0, ny, rows):
        if cancelled is not None and cancelled.is_set():
            raise Cancelled()
        row1 = min(ny, row0 + rows)
        js = slice(ny - row1, ny - row0)
        todo = ~have[:, js]
        if todo.any():
            res = simulate_batch(ics[:, js][todo], config=cfg, l_convention=conv, threads=threads)
            m.outcome[:, js][todo], m.steps[:, js][todo], m.status[:, js][todo] = res.outcome, res.steps, res.status_code
        m.rows_done = row1
        if on_strip is not None:
            on_strip(m)
    m.wall_s = time.perf_counter() - t0
    return m


def point_ic(view: View, i: int, j: int) -> tuple[tuple[float, ...], np.ndarray]:
    """Slice coordinates and the IC (in the preset's L convention) of grid point (i, j) of ``view``."""
    grid = view.grid()
    nx, ny = view.res
    if not (0 <= i < nx and 0 <= j < ny):
        raise ViewError("i,j", f"pixel ({i}, {j}) outside the {nx}×{ny} map")
    blk = grid.block(i * ny + j, i * ny + j + 1)
    coords = tuple(float(c) for c in blk.coords[0, : grid.ndim])
    cfg = view.config()
    ic = np.asarray(cfg.to_preset_convention(blk.ics, grid.slice.l_convention)[0], dtype=np.float64)
    return coords, ic


def throw_info(view: View, i: int, j: int) -> dict:
    """Hover info of grid point (i, j): slice coordinates, the 6-D IC, outcome, steps, settle time, contact sequence."""
    from dicetrace.simulate import simulate

    coords, ic = point_ic(view, i, j)
    cfg = view.config()
    roll = simulate(ic, config=cfg)
    return {
        "i": i,
        "j": j,
        "coords": dict(zip("xyz", coords)),
        "ic": dict(zip(("vx", "vy", "vz", "Lx", "Ly", "Lz"), (float(v) for v in ic))),
        "l_convention": cfg.preset.l_convention,
        "outcome": roll.outcome,
        "status": roll.status.label,
        "steps": roll.steps,
        "t_settle_s": roll.t_settle_s,
        "contact_sequence": roll.contact_sequence,
        "preset": cfg.preset.name,
        "integrator": cfg.numerics.integrator,
        "dt_s": cfg.numerics.dt_s,
    }


def throw_name(view: View, coords) -> str:
    """File stem of a throw, as ``dicetrace record`` names one given on a slice (``seed_x1.65_y3.9``)."""
    parts = [view.slice] + [f"{a}{c!r}" for a, c in zip("xyz", coords)]
    if view.preset != "seed":
        parts.append(view.preset)
    return "_".join(parts)


def throw_rrd(view: View, i: int, j: int, activate: bool = False) -> tuple[str, bytes, dict]:
    """The Rerun recording of grid point (i, j), made as ``dicetrace record`` makes one: (name, bytes, summary).

    ``activate``: record's blueprint is also made the active one, for Rerun's web viewer
    (:func:`dicetrace.sinks.rerun.encode_rrd`).
    """
    from dicetrace.simulate import Record, simulate
    from dicetrace.sinks.rerun import encode_rrd_of

    coords, ic = point_ic(view, i, j)
    roll = simulate(ic, config=view.config(), record=Record(states=True, energy=True))
    name = throw_name(view, coords)
    label = f"{view.slice} slice at " + ", ".join(f"{a} = {c!r}" for a, c in zip("xyz", coords))
    data = encode_rrd_of(roll, name=name, ic_label=label, activate=activate)
    return name, data, {"outcome": roll.outcome, "status": roll.status.label, "steps": roll.steps}


class Worker:
    """Runs maps (newest per client wins) and scans on one thread; throws on a small pool of their own."""

    def __init__(self, threads: int | None = None):
        self.threads = threads
        self._maps = ThreadPoolExecutor(max_workers=1, thread_name_prefix="dicetrace-explore-map")
        self._throws = ThreadPoolExecutor(max_workers=2, thread_name_prefix="dicetrace-explore-throw")
        self._lock = threading.Lock()
        self._latest: dict[str, tuple[tuple, _Token, Future]] = {}
        self._cache: OrderedDict[tuple, OutcomeMap] = OrderedDict()
        self._running: dict[tuple, OutcomeMap] = {}  # maps being computed, as far as they are
        self.cancelled_count = 0
        self.computed_count = 0

    def cached(self, view: View) -> OutcomeMap | None:
        with self._lock:
            m = self._cache.get(view.key())
            if m is not None:
                self._cache.move_to_end(view.key())
            return m

    def submit_map(self, view: View, client: str = "") -> Future:
        """A future of ``view``'s map; cancels this client's earlier map request if it is for another view."""
        key = view.key()
        with self._lock:
            hit = self._cache.get(key)
            prev = self._latest.get(client)
            if hit is not None:
                f: Future = Future()
                f.set_result(hit)
                if prev is not None and prev[0] != key:
                    self._cancel(prev)
                    del self._latest[client]
                return f
            if prev is not None:
                if prev[0] == key and not prev[2].done():
                    return prev[2]
                self._cancel(prev)
            tok = _Token()
            fut = self._maps.submit(self._run_map, view, tok)
            self._latest[client] = (key, tok, fut)
            return fut

    def _cancel(self, entry) -> None:
        _, tok, fut = entry
        if not fut.done():
            tok.cancelled.set()

    def progress(self, view: View) -> OutcomeMap | None:
        """``view``'s map as far as it is computed (complete once cached), or None before its first strip."""
        with self._lock:
            return self._running.get(view.key()) or self._cache.get(view.key())


    def _run_map(self, view: View, tok: _Token) -> OutcomeMap:
        def on_strip(m: OutcomeMap) -> None:
            with self._lock:
                self._running[view.key()] = m

        try:
            with self._lock:  # a coarser pass's points may be this grid's (compute_map takes those that are)
                known = list(self._cache.values())
            m = compute_map(view, tok.cancelled, threads=self.threads, known=known, on_strip=on_strip)
        except BaseException as e:
            with self._lock:
                self._running.pop(view.key(), None)
                self.cancelled_count += isinstance(e, Cancelled)
            raise
        with self._lock:
            self._running.pop(view.key(), None)
            self.computed_count += 1
            self._cache[view.key()] = m
            while len(self._cache) > CACHE_SIZE:
                self._cache.popitem(last=False)
        return m

    def submit_throw(self, fn, *args) -> Future:
        return self._throws.submit(fn, *args)

    def submit_scan(self, view: View, folder: Path, name: str) -> Future:
        return self._maps.submit(save_scan, view, folder, name, self.threads)

    def shutdown(self) -> None:
        with self._lock:
            for entry in self._latest.values():
                self._cancel(entry)
        self._maps.shutdown(wait=True, cancel_futures=True)
        self._throws.shutdown(wait=True, cancel_futures=True)


def scan_folder_for(out: Path, name: str) -> Path:
    """The folder ``out/name`` for a saved scan, refusing a name that could leave ``out``."""
    if not isinstance(name, str) or not SCAN_NAME.match(name) or name in (".", ".."):
        raise ViewError("name", "a scan name is 1-64 letters, digits, '.', '_' or '-', starting with a letter or digit")
    folder = (Path(out) / name).resolve()
    if folder.parent != Path(out).resolve():
        raise ViewError("name", f"{name!r} would leave the output folder")
    return folder


def save_scan(view: View, out: Path, name: str, threads: int | None = None) -> dict:
    """Write ``view`` as the dataset ``dicetrace scan`` would write, into ``out/name``; returns a summary."""
    from dicetrace.scan import scan

    folder = scan_folder_for(out, name)
    report = scan(view.grid(), folder, config=view.config(), threads=threads)
    return {"path": str(folder), "n_ics": report.n_ics, "chunks": report.n_chunks, "wall_s": report.wall_s}
