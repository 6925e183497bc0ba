"""The explorer's work: outcome maps of views, one throw's details, saved scans — off the server's event loop.

Maps go through :func:`dicetrace.simulate.simulate_batch` (the batch kernel
that ``dicetrace scan`` uses, on the same grid points), in blocks of
``BLOCK`` ICs on one worker thread (numba's parallel regions use the cores
inside it; one map at a time so they never compete).  Every map request
carries a client id: a newer request from the same client cancels the older
one, which stops at its next block (or before it starts) with
:class:`Cancelled`.  Finished maps are cached by view.
"""

from __future__ import annotations

import re
import threading
from collections import OrderedDict
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from dicetrace.explore.view import View, ViewError

#: ICs per kernel call of a map (the granularity of cancellation).
BLOCK = 4096
#: Maps kept in the cache.
CACHE_SIZE = 48
#: A saved scan's name.
SCAN_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9._-]{0,63}$")


class Cancelled(Exception):
    """The map was superseded by a newer view before it was done."""


@dataclass
class OutcomeMap:
    """A computed view: ``outcome``, ``steps`` and ``status`` indexed [i, j] (i along x), and the axes."""

    view: View
    xs: np.ndarray
    ys: np.ndarray
    outcome: np.ndarray  # int8 (nx, ny)
    steps: np.ndarray  # int64 (nx, ny)
    status: np.ndarray  # int8 codes (nx, ny)
    wall_s: float

    def counts(self) -> dict[int, int]:
        vals, n = np.unique(self.outcome, return_counts=True)
        return {int(v): int(c) for v, c in zip(vals, n)}


class _Token:
    def __init__(self) -> None:
        self.cancelled = threading.Event()


def compute_map(view: View, cancelled: threading.Event | None = None, threads: int | None = None) -> OutcomeMap:
    """The outcome map of ``view`` (raises :class:`Cancelled` once ``cancelled`` is set)."""
    import time

    from dicetrace.simulate import simulate_batch

    t0 = time.perf_counter()
    grid = view.grid()
    cfg = view.config()
    conv = grid.slice.l_convention
    n = grid.size
    outcome = np.empty(n, np.int8)
    steps = np.empty(n, np.int64)
    status = np.empty(n, np.int8)
    for start in range(0, n, BLOCK):
        if cancelled is not None and cancelled.is_set():
            raise Cancelled()
        stop = min(n, start + BLOCK)
        blk = grid.block(start, stop)
        res = simulate_batch(blk.ics, config=cfg, l_convention=conv, threads=threads)
        outcome[start:stop], steps[start:stop], status[start:stop] = res.outcome, res.steps, res.status_code
    nx, ny = view.res
    axes = grid.axes()
    return OutcomeMap(view, axes[0], axes[1], outcome.reshape(nx, ny), steps.reshape(nx, ny),
                      status.reshape(nx, ny), time.perf_counter() - t0)


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


def throw_rrd(view: View, i: int, j: int) -> tuple[str, bytes, dict]:
    """The Rerun recording of grid point (i, j), made as ``dicetrace record`` makes one: (name, bytes, summary)."""
    from dicetrace.simulate import Record, simulate
    from dicetrace.sinks.rerun import encode_rrd_of

    coords, ic = point_ic(view, i, j)
    roll = simulate(ic, config=view.config(), record=Record(states=True, energy=True))
    name = throw_name(view, coords)
    label = f"{view.slice} slice at " + ", ".join(f"{a} = {c!r}" for a, c in zip("xyz", coords))
    data = encode_rrd_of(roll, name=name, ic_label=label)
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

    def _run_map(self, view: View, tok: _Token) -> OutcomeMap:
        try:
            m = compute_map(view, tok.cancelled, threads=self.threads)
        except Cancelled:
            with self._lock:
                self.cancelled_count += 1
            raise
        with self._lock:
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
